"""Truth models for synthetic samples and light sources of the virtual goniometer.

The bundled ``measurements/cl830-synthetic`` data set stands in for the Intematix CL830 remote-phosphor plate
of the power-budget paper. Its truth is a frozen description (:class:`PhosphorPlateTruth`) with

* an elastic part per interaction (``bibs`` for blue light, ``yiys`` for yellow light) and side: a Lambertian
  body plus a Gaussian lobe in Harvey–Shack direction cosines, f = ρ/π + A·exp(−|β−β0|²/(2σ²)), times a mild
  linear wavelength factor m(λ) = 1 + κ(λ − λref)/100 nm;
* a wavelength-converting part (``biys``): a nearly Lambertian bi-spectral BSDF
  q_λ(λi→λs) = T/π · e(λs) · (1 + ε(cos θs − 2/3)) for λi in the excitation band, with ∫ e dλ = 1 over the
  paper's yellow band (470–740 nm). ∫(cos θ − 2/3) cos θ dΩ = 0, so ε changes the shape, not the TIS.

The emission e(λ) is the asymmetric Gaussian of eq. (3) of the cylindrical-module paper (Table 2: 596.7 nm,
FWHM 154.3 nm, α = −0.12) times a smooth onset that is exactly zero below 470 nm, so the blue band carries
only elastic light (the power-budget paper, §4.2: "the emission starts approximately at 470 nm").

Angles are radians inside; the frame is the sample frame with the source at φi = 180°, so β0 = (sin θi, 0)
for reflection and for transmission through the plate (transmitted angles measured from the back normal).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Literal

import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.conventions import CONVERSION_BAND_NM, EXCITATION_BAND_NM, SIDES
from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.models.functions import split_gaussian_spectrum, tis_gaussian_lobe
from bsdfkit.reduction.spectral import band_sum

Side = Literal["reflection", "transmission"]


# --------------------------------------------------------------------------------------------- spectra
def split_gaussian(wavelength: ArrayLike, peak: float, fwhm: float, alpha: float = 0.0) -> NDArray[np.float64]:
    """Eqs. (2)-(3) of [Cylindrical-module]: the registry's split Gaussian
    (:func:`bsdfkit.models.functions.split_gaussian_spectrum`) in float64 NumPy."""
    with x64():
        return np.asarray(split_gaussian_spectrum(jnp.asarray(wavelength, dtype=jnp.float64), peak, fwhm, alpha))


def smoothstep(x: ArrayLike) -> NDArray[np.float64]:
    """C¹ ramp: 0 for x ≤ 0, 3x² − 2x³ on [0, 1], 1 for x ≥ 1."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def xenon_lamp(wavelength: ArrayLike) -> NDArray[np.float64]:
    """Relative spectral power of a collimated Xe arc: a 6000 K Planck shape, 1 at 560 nm.

    A smooth stand-in for a real lamp; real Xe lines lie mostly above 800 nm, outside the 380–780 nm grid.
    """
    lam = np.asarray(wavelength, dtype=np.float64) * 1e-9
    c2 = 1.438776877e-2  # second radiation constant, m·K
    planck = lam**-5 / np.expm1(c2 / (lam * 6000.0))
    ref = 560e-9**-5 / np.expm1(c2 / (560e-9 * 6000.0))
    return planck / ref


def bandpass_filter(wavelength: ArrayLike, low: float, high: float, edge: float = 3.0) -> NDArray[np.float64]:
    """Interference filter transmittance: flat 0.9 inside, smooth edges of width ``edge`` nm, exactly 0 outside."""
    lam = np.asarray(wavelength, dtype=np.float64)
    return 0.9 * smoothstep((lam - low) / edge) * smoothstep((high - lam) / edge)


def longpass_filter(wavelength: ArrayLike, cut_on: float, edge: float = 5.0) -> NDArray[np.float64]:
    """Cut-on filter transmittance: exactly 0 below ``cut_on`` nm, 0.92 above ``cut_on + edge``."""
    lam = np.asarray(wavelength, dtype=np.float64)
    return 0.92 * smoothstep((lam - cut_on) / edge)


def emission_shape(wavelength: ArrayLike, peak: float = 596.7, fwhm: float = 154.3, alpha: float = -0.12,
                   onset_nm: tuple[float, float] = (470.0, 500.0)) -> NDArray[np.float64]:
    """Unnormalised phosphor emission: eq. (3) split Gaussian × smooth onset (0 below onset_nm[0])."""
    lam = np.asarray(wavelength, dtype=np.float64)
    onset = smoothstep((lam - onset_nm[0]) / (onset_nm[1] - onset_nm[0]))
    return split_gaussian(lam, peak, fwhm, alpha) * onset


# ------------------------------------------------------------------------------------------ the truth
@dataclass(frozen=True)
class LobeParams:
    """Elastic BSDF f = ρ/π + A exp(−|β−β0|²/(2σ²)) at one incidence and side; κ is the % per 100 nm slope."""

    rho: float
    A: float
    sigma: float
    kappa: float = 0.0
    lambda_ref: float = 460.0


@dataclass(frozen=True)
class ConversionParams:
    """Converted (biys) part at one incidence and side: TIS T and the non-Lambertian shape factor ε."""

    T: float
    epsilon: float = 0.0


@dataclass(frozen=True)
class PhosphorPlateTruth:
    """Truth BSDF of a synthetic phosphor plate, tabulated at incidences ``theta_i_deg``.

    Parameters at other incidences are linearly interpolated (clamped at the ends). ``bibs``/``yiys`` map
    side → tuple of :class:`LobeParams` (one per incidence), ``biys`` side → tuple of :class:`ConversionParams`.
    """

    name: str
    theta_i_deg: tuple[float, ...]
    bibs: dict[str, tuple[LobeParams, ...]]
    yiys: dict[str, tuple[LobeParams, ...]]
    biys: dict[str, tuple[ConversionParams, ...]]
    excitation_band_nm: tuple[float, float] = (440.0, 475.0)
    elastic_split_nm: float = 472.5
    emission: dict[str, float] = field(default_factory=lambda: {"peak": 596.7, "fwhm": 154.3, "alpha": -0.12,
                                                               "onset_start": 470.0, "onset_end": 500.0})

    def __hash__(self) -> int:  # dict fields: hash the JSON form
        return hash(self.to_json())

    # -- parameters --------------------------------------------------------------------------------
    def _interp(self, table: tuple, theta_i: float, name: str) -> float:
        values = [getattr(p, name) for p in table]
        return float(np.interp(np.degrees(theta_i), self.theta_i_deg, values))

    def lobe(self, interaction: str, side: str, theta_i: float) -> LobeParams:
        """Elastic parameters of ``interaction`` ("bibs"|"yiys") at incidence θi (radians)."""
        table = getattr(self, interaction)[side]
        return LobeParams(**{k: self._interp(table, theta_i, k) for k in ("rho", "A", "sigma", "kappa", "lambda_ref")})

    def conversion(self, side: str, theta_i: float) -> ConversionParams:
        table = self.biys[side]
        return ConversionParams(T=self._interp(table, theta_i, "T"), epsilon=self._interp(table, theta_i, "epsilon"))

    # -- spectral factors --------------------------------------------------------------------------
    def emission_density(self, wavelength: ArrayLike) -> NDArray[np.float64]:
        """e(λ) in 1/nm, normalised to ∫ e dλ = 1 over the yellow band 470–740 nm (fine grid)."""
        em = self.emission
        fine = np.linspace(*CONVERSION_BAND_NM, 27001)
        shape = lambda lam: emission_shape(lam, em["peak"], em["fwhm"], em["alpha"],  # noqa: E731
                                           (em["onset_start"], em["onset_end"]))
        norm = band_sum(fine, shape(fine), CONVERSION_BAND_NM)
        return shape(wavelength) / norm

    def excitation(self, wavelength: ArrayLike) -> NDArray[np.float64]:
        """Relative conversion efficiency g(λi): 1 inside the excitation band, 0 outside."""
        lam = np.asarray(wavelength, dtype=np.float64)
        lo, hi = self.excitation_band_nm
        return ((lam >= lo) & (lam <= hi)).astype(np.float64)

    # -- angular parts -----------------------------------------------------------------------------
    @staticmethod
    def _dbeta2(theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        return (directions[..., 0] - np.sin(theta_i)) ** 2 + directions[..., 1] ** 2

    def elastic_angular(self, interaction: str, side: str, theta_i: float,
                        directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """Wavelength-independent part of the elastic BSDF (1/sr) for unit ``directions`` (..., 3), z ≥ 0."""
        p = self.lobe(interaction, side, theta_i)
        return p.rho / np.pi + p.A * np.exp(-self._dbeta2(theta_i, directions) / (2 * p.sigma**2))

    def elastic_spectral(self, interaction: str, side: str, theta_i: float,
                         wavelength: ArrayLike) -> NDArray[np.float64]:
        p = self.lobe(interaction, side, theta_i)
        return 1.0 + p.kappa * (np.asarray(wavelength, dtype=np.float64) - p.lambda_ref) / 100.0

    def conversion_angular(self, side: str, theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """T/π · (1 + ε(cos θs − 2/3)) in 1/sr (multiply by e(λs) for the bi-spectral BSDF in 1/(sr nm))."""
        p = self.conversion(side, theta_i)
        return p.T / np.pi * (1.0 + p.epsilon * (directions[..., 2] - 2.0 / 3.0))

    def donaldson(self, side: str, theta_i: float, directions: NDArray[np.float64], wavelength_i: NDArray[np.float64],
                  wavelength: NDArray[np.float64]) -> NDArray[np.float64]:
        """Bi-spectral BSDF matrix q_λ(λi → λs) in 1/(sr·nm), shape (..., n_λi, n_λs), on matching grids.

        Converted part g(λi)·f_conv·e(λs); the elastic part sits on the diagonal as f(λ)/Δλ, the discrete form
        of f(λ)·δ(λi − λs), so that Σ_λi q_λ E Δλi reproduces f(λs) E(λs) (eq. (2) of the power-budget paper).
        """
        lam_i = np.asarray(wavelength_i, dtype=np.float64)
        lam = np.asarray(wavelength, dtype=np.float64)
        conv = self.conversion_angular(side, theta_i, directions)[..., None, None]
        out = conv * self.excitation(lam_i)[:, None] * self.emission_density(lam)[None, :]
        if lam_i.shape == lam.shape and np.allclose(lam_i, lam):
            blue = lam < self.elastic_split_nm
            f_b = (self.elastic_angular("bibs", side, theta_i, directions)[..., None]
                   * self.elastic_spectral("bibs", side, theta_i, lam))
            f_y = (self.elastic_angular("yiys", side, theta_i, directions)[..., None]
                   * self.elastic_spectral("yiys", side, theta_i, lam))
            diag = np.where(blue, f_b, f_y) / np.gradient(lam)
            idx = np.arange(lam.size)
            out[..., idx, idx] += diag
        return out

    def elastic_interaction(self, wavelength: ArrayLike) -> NDArray[np.str_]:
        """Which elastic parameter set applies at each wavelength: "bibs" below the split, "yiys" above."""
        lam = np.asarray(wavelength, dtype=np.float64)
        return np.where(lam < self.elastic_split_nm, "bibs", "yiys")

    # -- exact integrals ---------------------------------------------------------------------------
    def lobe_tis(self, interaction: str, side: str, theta_i: float, n_psi: int = 4096) -> float:
        """Exact hemispherical integral of the Gaussian lobe, clipped by the unit disk |β| ≤ 1.

        In polar coordinates (t, ψ) centred on β0 the radial integral is analytic:
        ∫₀^{t_max} A e^{−t²/2σ²} t dt = Aσ²(1 − e^{−t_max²/2σ²}), t_max(ψ) = −b·u + √((b·u)² + 1 − |b|²).
        The remaining ψ integral is periodic and smooth, so the midpoint rule converges exponentially.
        """
        p = self.lobe(interaction, side, theta_i)
        return clipped_gaussian_lobe_tis(p.A, p.sigma, theta_i, n_psi)

    def elastic_tis(self, interaction: str, side: str, theta_i: float) -> float:
        """TIS of the wavelength-independent elastic part: ρ + lobe (fraction of incident power)."""
        return self.lobe(interaction, side, theta_i).rho + self.lobe_tis(interaction, side, theta_i)

    def to_dict(self) -> dict:
        return asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict) -> "PhosphorPlateTruth":
        try:
            return cls(
                name=data["name"],
                theta_i_deg=tuple(float(t) for t in data["theta_i_deg"]),
                bibs={s: tuple(LobeParams(**p) for p in data["bibs"][s]) for s in SIDES},
                yiys={s: tuple(LobeParams(**p) for p in data["yiys"][s]) for s in SIDES},
                biys={s: tuple(ConversionParams(**p) for p in data["biys"][s]) for s in SIDES},
                excitation_band_nm=tuple(data["excitation_band_nm"]),
                elastic_split_nm=float(data["elastic_split_nm"]),
                emission=dict(data["emission"]),
            )
        except (KeyError, TypeError) as exc:
            raise ValidationError("truth description incomplete", field="truth", expected="a PhosphorPlateTruth",
                                  got=str(exc)) from None


def clipped_gaussian_lobe_tis(A: float, sigma: float, theta_i: float, n_psi: int = 4096) -> float:
    """TIS of a Gaussian lobe clipped by the unit disk (θi in radians): the registry's formula
    (:func:`bsdfkit.models.functions.tis_gaussian_lobe`) in float64, as a Python float."""
    with x64():
        return float(tis_gaussian_lobe(theta_i, A, sigma, n_psi))


def weighted_mean(wavelength: NDArray[np.float64], values: NDArray[np.float64], weight: NDArray[np.float64],
                  band: tuple[float, float]) -> float:
    """⟨values⟩ weighted by ``weight`` over ``band`` (eq. (5) of the power-budget paper, trapezoid rule)."""
    # the band sum of the reductions, so that the truth and the measurement integrate the same way
    return band_sum(wavelength, values * weight, band) / band_sum(wavelength, weight, band)


def exact_tis_table(truth: PhosphorPlateTruth, theta_i_deg: float, wavelength: NDArray[np.float64],
                    blue_incident: NDArray[np.float64], yellow_incident: NDArray[np.float64]) -> dict[str, float]:
    """Exact TIS (percent of incident power) of every interaction at one incidence.

    Uses the paper's definitions: bibs = ⟨q⟩ over the blue band weighted by the blue incident spectrum
    (eqs. 5, 7); yiys the same over 470–740 nm with the yellow incident spectrum (eq. 8); biys = the bi-spectral
    BSDF averaged over the excitation spectrum and integrated over 470–740 nm (eqs. 10–13). Keys as in Table 2.
    """
    th = np.radians(theta_i_deg)
    out: dict[str, float] = {}
    for tag, side in (("B", "reflection"), ("F", "transmission")):
        m_b = weighted_mean(wavelength, truth.elastic_spectral("bibs", side, th, wavelength), blue_incident,
                            EXCITATION_BAND_NM)
        out[f"{tag}_bibs"] = 100 * m_b * truth.elastic_tis("bibs", side, th)
        g = weighted_mean(wavelength, truth.excitation(wavelength), blue_incident, EXCITATION_BAND_NM)
        out[f"{tag}_biys"] = 100 * g * truth.conversion(side, th).T
        m_y = weighted_mean(wavelength, truth.elastic_spectral("yiys", side, th, wavelength), yellow_incident,
                            CONVERSION_BAND_NM)
        out[f"{tag}_yiys"] = 100 * m_y * truth.elastic_tis("yiys", side, th)
    out["blue_losses"] = 100 - out["B_bibs"] - out["F_bibs"] - out["B_biys"] - out["F_biys"]
    out["yellow_losses"] = 100 - out["B_yiys"] - out["F_yiys"]
    return out
