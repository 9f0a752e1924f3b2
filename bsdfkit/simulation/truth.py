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
def split_gaussian(wavelength_nm: ArrayLike, peak_nm: float, fwhm_nm: float, alpha: float = 0.0) -> NDArray[np.float64]:
    """Eqs. (2)-(3) of [Cylindrical-module]: the registry's split Gaussian
    (:func:`bsdfkit.models.functions.split_gaussian_spectrum`) in float64 NumPy.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].
    peak_nm : float
        Peak wavelength [nm].
    fwhm_nm : float
        Full width at half maximum [nm].
    alpha : float, optional
        Asymmetry of the two halves [-].

    Returns
    -------
    ndarray
        Relative spectral power, 1 at the peak [-].
    """
    with x64():
        return np.asarray(split_gaussian_spectrum(jnp.asarray(wavelength_nm, dtype=jnp.float64), peak_nm, fwhm_nm,
                                                  alpha))


def smoothstep(x: ArrayLike) -> NDArray[np.float64]:
    """C¹ ramp: 0 for x ≤ 0, 3x² − 2x³ on [0, 1], 1 for x ≥ 1.

    Parameters
    ----------
    x : array_like
        Position on the ramp [-].

    Returns
    -------
    ndarray
        Ramp value in [0, 1] [-].
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def xenon_lamp(wavelength_nm: ArrayLike) -> NDArray[np.float64]:
    """Relative spectral power of a collimated Xe arc: a 6000 K Planck shape, 1 at 560 nm.

    A smooth stand-in for a real lamp; real Xe lines lie mostly above 800 nm, outside the 380–780 nm grid.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].

    Returns
    -------
    ndarray
        Relative spectral power, 1 at 560 nm [-].
    """
    lam = np.asarray(wavelength_nm, dtype=np.float64) * 1e-9
    c2 = 1.438776877e-2  # second radiation constant, m·K
    planck = lam**-5 / np.expm1(c2 / (lam * 6000.0))
    ref = 560e-9**-5 / np.expm1(c2 / (560e-9 * 6000.0))
    return planck / ref


def bandpass_filter(wavelength_nm: ArrayLike, low_nm: float, high_nm: float,
                    edge_nm: float = 3.0) -> NDArray[np.float64]:
    """Interference filter transmittance: flat 0.9 inside, smooth edges of width ``edge`` nm, exactly 0 outside.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].
    low_nm : float
        Lower edge of the pass band [nm].
    high_nm : float
        Upper edge of the pass band [nm].
    edge_nm : float, optional
        Width of each smooth edge [nm].

    Returns
    -------
    ndarray
        Transmittance in [0, 0.9] [-].
    """
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    return 0.9 * smoothstep((lam - low_nm) / edge_nm) * smoothstep((high_nm - lam) / edge_nm)


def longpass_filter(wavelength_nm: ArrayLike, cut_on_nm: float, edge_nm: float = 5.0) -> NDArray[np.float64]:
    """Cut-on filter transmittance: exactly 0 below ``cut_on`` nm, 0.92 above ``cut_on + edge``.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].
    cut_on_nm : float
        Wavelength below which nothing passes [nm].
    edge_nm : float, optional
        Width of the rising edge [nm].

    Returns
    -------
    ndarray
        Transmittance in [0, 0.92] [-].
    """
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    return 0.92 * smoothstep((lam - cut_on_nm) / edge_nm)


def monochromator_slit(wavelength_nm: ArrayLike, center_nm: float, fwhm_nm: float,
                       peak: float = 0.5) -> NDArray[np.float64]:
    """Slit function of a grating monochromator with equal entrance and exit slits: a triangle of full width
    at half maximum ``fwhm`` nm about ``center``, exactly 0 beyond ±fwhm; ``peak`` is its throughput.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].
    center_nm : float
        Centre wavelength [nm].
    fwhm_nm : float
        Full width at half maximum of the triangle [nm].
    peak : float, optional
        Throughput at the centre [-].

    Returns
    -------
    ndarray
        Throughput [-].
    """
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    return peak * np.clip(1.0 - np.abs(lam - center_nm) / fwhm_nm, 0.0, None)


def emission_shape(wavelength_nm: ArrayLike, peak_nm: float = 596.7, fwhm_nm: float = 154.3, alpha: float = -0.12,
                   onset_nm: tuple[float, float] = (470.0, 500.0)) -> NDArray[np.float64]:
    """Unnormalised phosphor emission: eq. (3) split Gaussian × smooth onset (0 below onset_nm[0]).

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength [nm].
    peak_nm : float, optional
        Peak wavelength of the split Gaussian [nm].
    fwhm_nm : float, optional
        Its full width at half maximum [nm].
    alpha : float, optional
        Its asymmetry [-].
    onset_nm : tuple of float, optional
        Start and end of the smooth onset [nm].

    Returns
    -------
    ndarray
        Unnormalised relative spectral power [-].
    """
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    onset = smoothstep((lam - onset_nm[0]) / (onset_nm[1] - onset_nm[0]))
    return split_gaussian(lam, peak_nm, fwhm_nm, alpha) * onset


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


LOBE_FIELDS = ("rho", "A", "sigma", "kappa", "lambda_ref")
CONVERSION_FIELDS = ("T", "epsilon")


def _interp_table(theta_i_deg: tuple[float, ...], table: tuple, theta_i: float, kind: type, names: tuple[str, ...]):
    """Parameters of ``table`` (one entry per tabulated incidence) linearly interpolated at θi (radians),
    clamped at the ends."""
    return kind(**{k: float(np.interp(np.degrees(theta_i), theta_i_deg, [getattr(p, k) for p in table]))
                   for k in names})


def lobe_bsdf(p: LobeParams, theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
    """ρ/π + A·exp(−|β − β0|²/(2σ²)) [1/sr] for unit ``directions`` (..., 3), β0 = (sin θi, 0), θi in radians.

    Parameters
    ----------
    p : LobeParams
        Lambertian ρ [-], lobe height A [1/sr] and width σ [-] (direction cosines).
    theta_i : float
        Angle of incidence from the sample normal [rad].
    directions : ndarray, shape (..., 3)
        Unit scatter vectors, z ≥ 0 [-].

    Returns
    -------
    ndarray
        BSDF [1/sr].
    """
    dbeta2 = (directions[..., 0] - np.sin(theta_i)) ** 2 + directions[..., 1] ** 2
    return p.rho / np.pi + p.A * np.exp(-dbeta2 / (2 * p.sigma**2))


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
    def lobe(self, interaction: str, side: str, theta_i: float) -> LobeParams:
        """Elastic parameters of ``interaction`` ("bibs"|"yiys") at incidence θi (radians).

        Parameters
        ----------
        interaction : {"bibs", "yiys"}
            Elastic interaction: blue in, blue out or yellow in, yellow out.
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        LobeParams
            Parameters interpolated at θi (clamped at the table's ends).
        """
        return _interp_table(self.theta_i_deg, getattr(self, interaction)[side], theta_i, LobeParams, LOBE_FIELDS)

    def conversion(self, side: str, theta_i: float) -> ConversionParams:
        """Converted (biys) parameters T and ε at incidence θi.

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        ConversionParams
            Parameters interpolated at θi (clamped at the table's ends).
        """
        return _interp_table(self.theta_i_deg, self.biys[side], theta_i, ConversionParams, CONVERSION_FIELDS)

    # -- spectral factors --------------------------------------------------------------------------
    def emission_density(self, wavelength_nm: ArrayLike) -> NDArray[np.float64]:
        """e(λ) in 1/nm, normalised to ∫ e dλ = 1 over the yellow band 470–740 nm (fine grid).

        Parameters
        ----------
        wavelength_nm : array_like
            Wavelength [nm].

        Returns
        -------
        ndarray
            Emission density e(λ) [1/nm].
        """
        em = self.emission
        fine = np.linspace(*CONVERSION_BAND_NM, 27001)
        shape = lambda lam: emission_shape(lam, em["peak"], em["fwhm"], em["alpha"],  # noqa: E731
                                           (em["onset_start"], em["onset_end"]))
        norm = band_sum(fine, shape(fine), CONVERSION_BAND_NM)
        return shape(wavelength_nm) / norm

    def excitation(self, wavelength_nm: ArrayLike) -> NDArray[np.float64]:
        """Relative conversion efficiency g(λi): 1 inside the excitation band, 0 outside.

        Parameters
        ----------
        wavelength_nm : array_like
            Incident (excitation) wavelength [nm].

        Returns
        -------
        ndarray
            g(λi), 0 or 1 [-].
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        lo, hi = self.excitation_band_nm
        return ((lam >= lo) & (lam <= hi)).astype(np.float64)

    # -- angular parts -----------------------------------------------------------------------------
    def elastic_angular(self, interaction: str, side: str, theta_i: float,
                        directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """Wavelength-independent part of the elastic BSDF (1/sr) for unit ``directions`` (..., 3), z ≥ 0.

        Parameters
        ----------
        interaction : {"bibs", "yiys"}
            Elastic interaction: blue in, blue out or yellow in, yellow out.
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (..., 3)
            Unit scatter vectors in the frame of ``side``, z ≥ 0 [-].

        Returns
        -------
        ndarray
            BSDF [1/sr].
        """
        return lobe_bsdf(self.lobe(interaction, side, theta_i), theta_i, directions)

    def elastic_spectral(self, interaction: str, side: str, theta_i: float,
                         wavelength_nm: ArrayLike) -> NDArray[np.float64]:
        """Wavelength factor m(λ) = 1 + κ(λ − λref)/100 nm of the elastic BSDF.

        Parameters
        ----------
        interaction : {"bibs", "yiys"}
            Elastic interaction: blue in, blue out or yellow in, yellow out.
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        wavelength_nm : array_like
            Wavelength [nm].

        Returns
        -------
        ndarray
            m(λ) [-].
        """
        p = self.lobe(interaction, side, theta_i)
        return 1.0 + p.kappa * (np.asarray(wavelength_nm, dtype=np.float64) - p.lambda_ref) / 100.0

    def conversion_angular(self, side: str, theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """T/π · (1 + ε(cos θs − 2/3)) in 1/sr (multiply by e(λs) for the bi-spectral BSDF in 1/(sr nm)).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (..., 3)
            Unit scatter vectors in the frame of ``side``, z ≥ 0 [-].

        Returns
        -------
        ndarray
            Angular factor [1/sr].
        """
        p = self.conversion(side, theta_i)
        return p.T / np.pi * (1.0 + p.epsilon * (directions[..., 2] - 2.0 / 3.0))

    def donaldson(self, side: str, theta_i: float, directions: NDArray[np.float64],
                  wavelength_i_nm: NDArray[np.float64], wavelength_nm: NDArray[np.float64]) -> NDArray[np.float64]:
        """Bi-spectral BSDF matrix q_λ(λi → λs) in 1/(sr·nm), shape (..., n_λi, n_λs), on matching grids.

        Converted part g(λi)·f_conv·e(λs); the elastic part sits on the diagonal as f(λ)/Δλ, the discrete form
        of f(λ)·δ(λi − λs), so that Σ_λi q_λ E Δλi reproduces f(λs) E(λs) (eq. (2) of the power-budget paper).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (..., 3)
            Unit scatter vectors in the frame of ``side``, z ≥ 0 [-].
        wavelength_i_nm : ndarray, shape (n_λi,)
            Incident wavelength grid [nm].
        wavelength_nm : ndarray, shape (n_λs,)
            Scattered wavelength grid [nm].

        Returns
        -------
        ndarray
            Bi-spectral BSDF, shape (..., n_λi, n_λs) [1/(sr nm)].
        """
        lam_i = np.asarray(wavelength_i_nm, dtype=np.float64)
        lam = np.asarray(wavelength_nm, dtype=np.float64)
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

    def scattered_power(self, side: str, theta_i: float, directions: NDArray[np.float64], weights: NDArray[np.float64],
                        wavelength_nm: NDArray[np.float64], incident: NDArray[np.float64]) -> NDArray[np.float64]:
        """Spectral power through the apertures (n_pos, n_λ) for the incident spectral power ``incident``.

        ``directions``/``weights`` are the aperture quadrature (weights include cos θs), θi in radians: the
        elastic part P_i(λ)·m(λ)·∫f, the converted part Φ_exc·e(λ)·∫f_conv with Φ_exc the excited power.

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (n_pos, n_dir, 3)
            Quadrature directions over each aperture, unit vectors in the frame of ``side`` [-].
        weights : ndarray, shape (n_pos, n_dir)
            Projected-solid-angle weights of the directions (cos θs included) [sr].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).

        Returns
        -------
        ndarray
            Scattered spectral power, shape (n_pos, n_λ), in the unit of ``incident``.
        """
        lam = wavelength_nm
        s_b = (self.elastic_angular("bibs", side, theta_i, directions) * weights).sum(-1)
        s_y = (self.elastic_angular("yiys", side, theta_i, directions) * weights).sum(-1)
        s_c = (self.conversion_angular(side, theta_i, directions) * weights).sum(-1)
        elastic_b = self.elastic_spectral("bibs", side, theta_i, lam)
        elastic_y = self.elastic_spectral("yiys", side, theta_i, lam)
        blue = lam < self.elastic_split_nm
        elastic = incident * np.where(blue, elastic_b * s_b[:, None], elastic_y * s_y[:, None])
        phi_exc = np.trapezoid(incident * self.excitation(lam), lam)
        converted = phi_exc * self.emission_density(lam) * s_c[:, None]
        return elastic + converted

    def elastic_interaction(self, wavelength_nm: ArrayLike) -> NDArray[np.str_]:
        """Which elastic parameter set applies at each wavelength: "bibs" below the split, "yiys" above.

        Parameters
        ----------
        wavelength_nm : array_like
            Wavelength [nm].

        Returns
        -------
        ndarray
            Interaction name per wavelength, ``"bibs"`` or ``"yiys"``.
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        return np.where(lam < self.elastic_split_nm, "bibs", "yiys")

    # -- exact integrals ---------------------------------------------------------------------------
    def lobe_tis(self, interaction: str, side: str, theta_i: float, n_psi: int = 4096) -> float:
        """Exact hemispherical integral of the Gaussian lobe, clipped by the unit disk |β| ≤ 1.

        In polar coordinates (t, ψ) centred on β0 the radial integral is analytic:
        ∫₀^{t_max} A e^{−t²/2σ²} t dt = Aσ²(1 − e^{−t_max²/2σ²}), t_max(ψ) = −b·u + √((b·u)² + 1 − |b|²).
        The remaining ψ integral is periodic and smooth, so the midpoint rule converges exponentially.

        Parameters
        ----------
        interaction : {"bibs", "yiys"}
            Elastic interaction: blue in, blue out or yellow in, yellow out.
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        n_psi : int, optional
            Number of azimuth nodes of the midpoint rule.

        Returns
        -------
        float
            Lobe TIS [-] (fraction of the incident power).
        """
        p = self.lobe(interaction, side, theta_i)
        return clipped_gaussian_lobe_tis(p.A, p.sigma, theta_i, n_psi)

    def elastic_tis(self, interaction: str, side: str, theta_i: float) -> float:
        """TIS of the wavelength-independent elastic part: ρ + lobe (fraction of incident power).

        Parameters
        ----------
        interaction : {"bibs", "yiys"}
            Elastic interaction: blue in, blue out or yellow in, yellow out.
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        float
            TIS [-] (fraction of the incident power).
        """
        return self.lobe(interaction, side, theta_i).rho + self.lobe_tis(interaction, side, theta_i)

    def to_dict(self) -> dict:
        """The fields as plain dicts, tuples and numbers (:meth:`from_dict` reads them back)."""
        return asdict(self)

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text, keys sorted."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict) -> "PhosphorPlateTruth":
        """The truth from :meth:`to_dict`'s form (e.g. read from JSON).

        Parameters
        ----------
        data : dict
            Fields of the dataclass, parameters as dicts.

        Returns
        -------
        PhosphorPlateTruth
        """
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
    (:func:`bsdfkit.models.functions.tis_gaussian_lobe`) in float64, as a Python float.

    Parameters
    ----------
    A : float
        Lobe height [1/sr].
    sigma : float
        Lobe width in direction cosines [-].
    theta_i : float
        Angle of incidence from the sample normal [rad].
    n_psi : int, optional
        Number of azimuth nodes of the midpoint rule.

    Returns
    -------
    float
        TIS of the lobe [-] (fraction of the incident power).
    """
    with x64():
        return float(tis_gaussian_lobe(theta_i, A, sigma, n_psi))


def weighted_mean(wavelength_nm: NDArray[np.float64], values: NDArray[np.float64], weight: NDArray[np.float64],
                  band_nm: tuple[float, float]) -> float:
    """⟨values⟩ weighted by ``weight`` over ``band`` (eq. (5) of the power-budget paper, trapezoid rule).

    Parameters
    ----------
    wavelength_nm : ndarray
        Wavelength grid [nm].
    values : ndarray
        Values on the grid.
    weight : ndarray
        Weights on the grid (e.g. an incident spectrum, any scale).
    band_nm : tuple of float
        Lower and upper wavelength of the band [nm].

    Returns
    -------
    float
        Weighted mean, in the unit of ``values``.
    """
    # the band sum of the reductions, so that the truth and the measurement integrate the same way
    return band_sum(wavelength_nm, values * weight, band_nm) / band_sum(wavelength_nm, weight, band_nm)


def exact_tis_table(truth: PhosphorPlateTruth, theta_i_deg: float, wavelength_nm: NDArray[np.float64],
                    blue_incident: NDArray[np.float64], yellow_incident: NDArray[np.float64]) -> dict[str, float]:
    """Exact TIS (percent of incident power) of every interaction at one incidence.

    Uses the paper's definitions: bibs = ⟨q⟩ over the blue band weighted by the blue incident spectrum
    (eqs. 5, 7); yiys the same over 470–740 nm with the yellow incident spectrum (eq. 8); biys = the bi-spectral
    BSDF averaged over the excitation spectrum and integrated over 470–740 nm (eqs. 10–13). Keys as in Table 2.

    Parameters
    ----------
    truth : PhosphorPlateTruth
        The plate.
    theta_i_deg : float
        Angle of incidence [deg].
    wavelength_nm : ndarray, shape (n_λ,)
        Wavelength grid [nm].
    blue_incident : ndarray, shape (n_λ,)
        Blue incident spectral power [W/nm] (any scale).
    yellow_incident : ndarray, shape (n_λ,)
        Yellow incident spectral power [W/nm] (any scale).

    Returns
    -------
    dict of str to float
        TIS in percent of the incident power [%], keys of Table 2 and the blue and yellow losses.
    """
    th = np.radians(theta_i_deg)
    out: dict[str, float] = {}
    for tag, side in (("B", "reflection"), ("F", "transmission")):
        m_b = weighted_mean(wavelength_nm, truth.elastic_spectral("bibs", side, th, wavelength_nm), blue_incident,
                            EXCITATION_BAND_NM)
        out[f"{tag}_bibs"] = 100 * m_b * truth.elastic_tis("bibs", side, th)
        g = weighted_mean(wavelength_nm, truth.excitation(wavelength_nm), blue_incident, EXCITATION_BAND_NM)
        out[f"{tag}_biys"] = 100 * g * truth.conversion(side, th).T
        m_y = weighted_mean(wavelength_nm, truth.elastic_spectral("yiys", side, th, wavelength_nm), yellow_incident,
                            CONVERSION_BAND_NM)
        out[f"{tag}_yiys"] = 100 * m_y * truth.elastic_tis("yiys", side, th)
    out["blue_losses"] = 100 - out["B_bibs"] - out["F_bibs"] - out["B_biys"] - out["F_biys"]
    out["yellow_losses"] = 100 - out["B_yiys"] - out["F_yiys"]
    return out


# ------------------------------------------------------------------- excitation-emission (spectral) truth
@dataclass(frozen=True)
class ExcitationEmissionTruth:
    """Truth of a synthetic phosphor plate whose response depends on the excitation wavelength.

    A documented synthetic model (not a fit to a measured plate) in the factorised (Kasha–Vavilov) form
    f_conv(ω; λi → λs) = g(ω)·a(λi)·e(λs) of a bi-spectral BSDF. Per incident photon at λi:

    * it is absorbed by the phosphor with probability a(λi), the excitation (absorption) spectrum
      a(λ) = a_max / (1 + exp((λ − λ_edge)/w)): strong in the UV-blue, falling through 480-530 nm. Shape
      after the excitation spectrum of the CL-830 plate (§4, Fig. 5 of [Power-budget]: excitation most
      efficient near 460 nm, emission starting near 470 nm, "the excitation and emission spectra clearly
      overlap", with low absorption in the overlap region, §4.2);
    * an absorbed photon is re-emitted with the quantum yield η (0.80: the photon ratio of §6 of
      [Power-budget]) at a wavelength drawn from the photon-number emission pdf e(λs) [1/nm], the same for
      every λi (Kasha's rule). The emitted power spectrum ∝ e(λs)/λs is the split Gaussian of eq. (3) of
      [Cylindrical-module] (Table 2 there: 596.7 nm, FWHM 154.3 nm, α = −0.12) times a smooth onset that is
      exactly zero below 470 nm ([Power-budget] §4.2), so the photon pdf is ∝ λs·(that shape);
      converted photons leave into ``side`` with the share T of :class:`ConversionParams` (T_R + T_T = 1)
      and the nearly Lambertian shape (1 + ε(cos θs − 2/3))/π;
    * a photon that is not absorbed is scattered elastically with the ``elastic`` lobes (ρ/π + Gaussian lobe
      in β, :class:`LobeParams`, κ unused), which hold at zero absorption: f_el(λ) = (1 − a(λ))·f_0.

    Hence per unit incident power at λi: elastic TIS (1 − a)·(ρ + lobe TIS), converted power TIS
    a·η·T·λi·∫e(λs)/λs dλs, photons per incident photon a·η·T ≤ η < 1. ``emission_range_nm`` is the grid on
    which e integrates to 1 (the spectrometer's).
    """

    name: str
    theta_i_deg: tuple[float, ...]
    elastic: dict[str, tuple[LobeParams, ...]]
    conversion: dict[str, tuple[ConversionParams, ...]]
    quantum_yield: float = 0.80
    absorption_max: float = 0.85
    absorption_edge_nm: float = 500.0
    absorption_width_nm: float = 12.0
    emission: dict[str, float] = field(default_factory=lambda: {"peak": 596.7, "fwhm": 154.3, "alpha": -0.12,
                                                               "onset_start": 470.0, "onset_end": 510.0})
    emission_range_nm: tuple[float, float] = (380.0, 780.0)

    def __post_init__(self) -> None:
        if not 0.0 < self.quantum_yield < 1.0:
            raise ValidationError("quantum yield out of range", field="quantum_yield", expected="0 < η < 1",
                                  got=self.quantum_yield)
        if not 0.0 <= self.absorption_max < 1.0:
            raise ValidationError("absorption out of range", field="absorption_max", expected="0 ≤ a_max < 1",
                                  got=self.absorption_max)
        for t in zip(*(self.conversion[s] for s in SIDES)):
            if abs(sum(p.T for p in t) - 1.0) > 1e-12:
                raise ValidationError("converted-photon shares must sum to 1 over the sides", field="conversion.T",
                                      expected="T_reflection + T_transmission = 1", got=[p.T for p in t])

    def __hash__(self) -> int:  # dict fields: hash the JSON form
        return hash(self.to_json())

    # -- spectral factors --------------------------------------------------------------------------
    def absorption(self, wavelength_nm: ArrayLike) -> NDArray[np.float64]:
        """a(λ): probability that an incident photon at λ is absorbed by the phosphor [1].

        Parameters
        ----------
        wavelength_nm : array_like
            Wavelength [nm].

        Returns
        -------
        ndarray
            Absorption probability a(λ) [-].
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        return self.absorption_max / (1.0 + np.exp((lam - self.absorption_edge_nm) / self.absorption_width_nm))

    def _emission_shape(self, wavelength: ArrayLike) -> NDArray[np.float64]:
        em = self.emission
        lam = np.asarray(wavelength, dtype=np.float64)
        lo, hi = self.emission_range_nm
        inside = (lam >= lo) & (lam <= hi)
        return np.where(inside, lam * emission_shape(lam, em["peak"], em["fwhm"], em["alpha"],
                                                     (em["onset_start"], em["onset_end"])), 0.0)

    def emission_pdf(self, wavelength_nm: ArrayLike) -> NDArray[np.float64]:
        """e(λ) [1/nm]: photon-number pdf of the converted light, ∫ e dλ = 1 over ``emission_range_nm``.

        Parameters
        ----------
        wavelength_nm : array_like
            Wavelength [nm].

        Returns
        -------
        ndarray
            Photon-number pdf e(λ) [1/nm].
        """
        fine = np.linspace(*self.emission_range_nm, 40001)
        return self._emission_shape(wavelength_nm) / band_sum(fine, self._emission_shape(fine), self.emission_range_nm)

    # -- angular parts -----------------------------------------------------------------------------
    def lobe(self, side: str, theta_i: float) -> LobeParams:
        """Elastic parameters at zero absorption, at incidence θi (radians).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        LobeParams
            Parameters interpolated at θi (clamped at the table's ends).
        """
        return _interp_table(self.theta_i_deg, self.elastic[side], theta_i, LobeParams, LOBE_FIELDS)

    def share(self, side: str, theta_i: float) -> ConversionParams:
        """Share T of the converted photons leaving into ``side`` and its shape factor ε, at θi (radians).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        ConversionParams
            Parameters interpolated at θi (clamped at the table's ends).
        """
        return _interp_table(self.theta_i_deg, self.conversion[side], theta_i, ConversionParams, CONVERSION_FIELDS)

    def elastic_angular(self, side: str, theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """f_0 [1/sr]: the elastic BSDF at zero absorption for unit ``directions`` (..., 3).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (..., 3)
            Unit scatter vectors in the frame of ``side``, z ≥ 0 [-].

        Returns
        -------
        ndarray
            BSDF f_0 [1/sr].
        """
        return lobe_bsdf(self.lobe(side, theta_i), theta_i, directions)

    def conversion_angular(self, side: str, theta_i: float, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """T/π·(1 + ε(cos θs − 2/3)) [1/sr]: angular density of the converted photons (integrates to T).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (..., 3)
            Unit scatter vectors in the frame of ``side``, z ≥ 0 [-].

        Returns
        -------
        ndarray
            Angular density [1/sr].
        """
        p = self.share(side, theta_i)
        return p.T / np.pi * (1.0 + p.epsilon * (directions[..., 2] - 2.0 / 3.0))

    def elastic_tis_at_zero_absorption(self, side: str, theta_i: float) -> float:
        """ρ + clipped lobe TIS of f_0 [1].

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].

        Returns
        -------
        float
            TIS [-] (fraction of the incident power).
        """
        p = self.lobe(side, theta_i)
        return p.rho + clipped_gaussian_lobe_tis(p.A, p.sigma, theta_i)

    # -- the goniometer signal ---------------------------------------------------------------------
    def scattered_power(self, side: str, theta_i: float, directions: NDArray[np.float64], weights: NDArray[np.float64],
                        wavelength_nm: NDArray[np.float64], incident: NDArray[np.float64]) -> NDArray[np.float64]:
        """Spectral power through the apertures (n_pos, n_λ) for the incident spectral power ``incident``.

        ``directions``/``weights`` are the aperture quadrature (weights include cos θs), θi in radians.
        Elastic: P_i(λ)(1 − a(λ))·∫f_0; converted: η Σ_λi P_i a λi Δλi · e(λs)/λs · ∫g, in the same units.

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        directions : ndarray, shape (n_pos, n_dir, 3)
            Quadrature directions over each aperture, unit vectors in the frame of ``side`` [-].
        weights : ndarray, shape (n_pos, n_dir)
            Projected-solid-angle weights of the directions (cos θs included) [sr].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).

        Returns
        -------
        ndarray
            Scattered spectral power, shape (n_pos, n_λ), in the unit of ``incident``.
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        s_el = (self.elastic_angular(side, theta_i, directions) * weights).sum(-1)
        s_c = (self.conversion_angular(side, theta_i, directions) * weights).sum(-1)
        elastic = incident * (1.0 - self.absorption(lam)) * s_el[:, None]
        photons_absorbed = np.trapezoid(incident * self.absorption(lam) * lam, lam)  # × 1/(hc), cancels below
        converted = self.quantum_yield * photons_absorbed * (self.emission_pdf(lam) / lam) * s_c[:, None]
        return elastic + converted

    # -- exact values for an incident spectrum -----------------------------------------------------
    def elastic_tis(self, side: str, theta_i: float, wavelength_nm: NDArray[np.float64],
                    incident: NDArray[np.float64]) -> float:
        """Elastic TIS [1] for the incident spectrum (any scale): ⟨1 − a⟩·(ρ + lobe TIS).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).

        Returns
        -------
        float
            TIS [-] (fraction of the incident power).
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        band = (float(lam[0]), float(lam[-1]))
        mean = band_sum(lam, incident * (1.0 - self.absorption(lam)), band) / band_sum(lam, incident, band)
        return mean * self.elastic_tis_at_zero_absorption(side, theta_i)

    def converted_density(self, side: str, theta_i: float, wavelength_nm: NDArray[np.float64],
                          incident: NDArray[np.float64]) -> NDArray[np.float64]:
        """Converted spectral power leaving into ``side`` per unit incident power [1/nm], on ``wavelength``.

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).

        Returns
        -------
        ndarray
            Converted spectral power per incident power [1/nm].
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        band = (float(lam[0]), float(lam[-1]))
        absorbed = band_sum(lam, incident * self.absorption(lam) * lam, band) / band_sum(lam, incident, band)
        return self.quantum_yield * absorbed * self.share(side, theta_i).T * self.emission_pdf(lam) / lam

    def converted_tis(self, side: str, theta_i: float, wavelength_nm: NDArray[np.float64],
                      incident: NDArray[np.float64], band_nm: tuple[float, float] | None = None) -> float:
        """Converted power leaving into ``side`` per incident power [1] (within ``band``, default all).

        Parameters
        ----------
        side : {"reflection", "transmission"}
            Scattering side.
        theta_i : float
            Angle of incidence from the sample normal [rad].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).
        band_nm : tuple of float, optional
            Lower and upper wavelength of the band [nm]; the whole grid by default.

        Returns
        -------
        float
            Converted power per incident power [-].
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        band_nm = band_nm or (float(lam[0]), float(lam[-1]))
        return band_sum(lam, self.converted_density(side, theta_i, lam, incident), band_nm)

    def photon_yield(self, wavelength_nm: NDArray[np.float64], incident: NDArray[np.float64]) -> float:
        """Converted photons (both sides) per incident photon [1]: η⟨a⟩ with photon weights, ≤ η.

        Parameters
        ----------
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        incident : ndarray, shape (n_λ,)
            Incident spectral power on ``wavelength``, in any unit (e.g. [W/nm], or [counts/s] per pixel).

        Returns
        -------
        float
            Converted photons per incident photon [-].
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        band = (float(lam[0]), float(lam[-1]))
        return (self.quantum_yield * band_sum(lam, incident * lam * self.absorption(lam), band)
                / band_sum(lam, incident * lam, band))

    def two_colour_tis_percent(self, theta_i_deg: float, wavelength_nm: NDArray[np.float64], blue: NDArray[np.float64],
                               yellow: NDArray[np.float64]) -> dict[str, float]:
        """Exact TIS of the two-wavelength interactions (percent, keys of Table 2 of [Power-budget]) for the
        blue and yellow incident spectra, as the measurement equation defines them: bibs the blue-weighted mean
        of P_s/P_i over 450-470 nm (eq. 5); biys the converted power in 470-740 nm (eq. 13); yiys the
        yellow-weighted mean of P_s/P_i over the pixels of 470-740 nm that carry yellow light (eq. 8), which
        includes the light the yellow beam's short-wave part converts.

        Parameters
        ----------
        theta_i_deg : float
            Angle of incidence [deg].
        wavelength_nm : ndarray, shape (n_λ,)
            Wavelength grid [nm].
        blue : ndarray, shape (n_λ,)
            Blue incident spectral power [W/nm] (any scale).
        yellow : ndarray, shape (n_λ,)
            Yellow incident spectral power [W/nm] (any scale).

        Returns
        -------
        dict of str to float
            TIS in percent of the incident power [%], keys of Table 2 and the blue and yellow losses.
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        th = np.radians(theta_i_deg)
        whole = (float(lam[0]), float(lam[-1]))
        lit = np.where(yellow > 1e-3 * yellow.max(), 1.0, 0.0)  # calibration's incident_valid threshold
        yellow_share = band_sum(lam, yellow * lit, CONVERSION_BAND_NM) / band_sum(lam, yellow, whole)
        out: dict[str, float] = {}
        for tag, side in (("B", "reflection"), ("F", "transmission")):
            t0 = self.elastic_tis_at_zero_absorption(side, th)
            out[f"{tag}_bibs"] = 100 * t0 * weighted_mean(lam, 1.0 - self.absorption(lam), blue, EXCITATION_BAND_NM)
            out[f"{tag}_biys"] = 100 * self.converted_tis(side, th, lam, blue, CONVERSION_BAND_NM)
            elastic = band_sum(lam, yellow * lit * (1.0 - self.absorption(lam)), CONVERSION_BAND_NM) * t0
            converted = band_sum(lam, self.converted_density(side, th, lam, yellow) * lit, CONVERSION_BAND_NM)
            out[f"{tag}_yiys"] = 100 * (elastic / band_sum(lam, yellow, whole) + converted) / yellow_share
        out["blue_losses"] = 100 - out["B_bibs"] - out["F_bibs"] - out["B_biys"] - out["F_biys"]
        out["yellow_losses"] = 100 - out["B_yiys"] - out["F_yiys"]
        return out

    def to_dict(self) -> dict:
        """The fields as plain dicts, tuples and numbers (:meth:`from_dict` reads them back)."""
        return asdict(self)

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text, keys sorted."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict) -> "ExcitationEmissionTruth":
        """The truth from :meth:`to_dict`'s form (e.g. read from JSON).

        Parameters
        ----------
        data : dict
            Fields of the dataclass, parameters as dicts.

        Returns
        -------
        ExcitationEmissionTruth
        """
        try:
            return cls(
                name=data["name"], theta_i_deg=tuple(float(t) for t in data["theta_i_deg"]),
                elastic={s: tuple(LobeParams(**p) for p in data["elastic"][s]) for s in SIDES},
                conversion={s: tuple(ConversionParams(**p) for p in data["conversion"][s]) for s in SIDES},
                quantum_yield=float(data["quantum_yield"]), absorption_max=float(data["absorption_max"]),
                absorption_edge_nm=float(data["absorption_edge_nm"]),
                absorption_width_nm=float(data["absorption_width_nm"]), emission=dict(data["emission"]),
                emission_range_nm=tuple(data["emission_range_nm"]),
            )
        except (KeyError, TypeError) as exc:
            raise ValidationError("truth description incomplete", field="truth",
                                  expected="an ExcitationEmissionTruth", got=str(exc)) from None


#: Either truth model: both give the goniometer signal through ``scattered_power``.
TruthModel = PhosphorPlateTruth | ExcitationEmissionTruth
