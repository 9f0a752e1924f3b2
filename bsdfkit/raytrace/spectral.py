"""The tracer's spectral mode: the plate spectral model, spectra on the bin grid and the kernel's tables.

The plate spectral model (issue 17, Build 2) is an xarray dataset with dims ``side`` = ("reflection",
"transmission") (reflection = back into the cavity), ``incidence`` [deg], ``excitation`` [nm] and ``emission``
[nm] holding

* ``elastic_tis(side, incidence, excitation)`` [1]: power scattered at the incident wavelength per incident
  power, per hemisphere (bibs at pump wavelengths, yiys at converted ones, eqs. (7) and (13) of [Power-budget]);
* ``converted_tis(side, incidence, excitation)`` [1]: converted POWER out per incident power, per hemisphere;
* ``emission_pdf(excitation, emission)`` [1/nm]: photon-number pdf of the converted light, each row summing to 1
  on the uniform emission grid (Σ p Δλ = 1), zero rows where nothing converts.

The tracer works on the emission grid: a ray carries a bin index k (wavelength λ_k, width Δλ). TIS and pdf rows
at λ_k are interpolated linearly in excitation wavelength (held at the end values outside the excitation grid),
and in θi by the kernel like the two-wavelength plate's.

Photon bookkeeping. The photon yield of a conversion at λ_k on one side is
Y = converted_tis · λ̃_k / λ_k with λ̃_k = 1 / Σ_j p_kj Δλ / λ_j the photon-weighted harmonic mean emission
wavelength (a power C spread as photons with pdf p carries C·λ̃/λ_k photons per incident photon, eq. (16) of
[Power-budget]). The kernel chooses elastic back/forward and converted back/forward with probabilities
∝ (elastic_R, elastic_T, Y_R, Y_T), multiplies the ray weight by their sum S (photons kept per incident photon)
and, at a conversion, draws the new bin from p_k and scales the weight by λ_k/λ_new (the photon keeps its
number, its energy changes). The expected converted power is exactly converted_tis, a ray's photon weight never
grows (S ≤ 1 is required of the model) and the power lost at a conversion, w·S·(1 − λ_k/λ_new), is the Stokes
loss, booked on its own ledger line.

Emission conditioned on the excitation (issue 27). A converted photon cannot leave with more energy than it
was absorbed with, beyond what the lattice lends it thermally. The pdf row at the excitation bin k (the data's
row where the excitation scan measured one, interpolated between its excitations) is therefore weighted below
the excitation wavelength by the Boltzmann factor B_kj = exp(−(hc/λ_j − hc/λ_k)/(k_B T)) (1 for λ_j ≥ λ_k) at
the plate temperature T (``temperature_K`` of the scene's top, default :data:`PLATE_TEMPERATURE_K`) and
renormalised per row: p'_kj = p_kj B_kj / Σ_j p_kj B_kj. The photon yield Y of each cell is the data's (the
quantum yield is kept, photons are only moved to longer wavelengths), so the converted power becomes
Y·λ_k/λ̃'_k; the anti-Stokes share of row k is Σ_{j<k} p'_kj Δλ (:func:`anti_stokes_share`). The kernel draws
the new bin from the alias table of row k of p' (a K × K table gathered by the ray's bin: no branch, no loop).

Angular distributions are those of the scene's two-wavelength plate (Lambertian without one): elastic light in
the pump band (λ_k within :data:`~bsdfkit.core.conventions.MODULE_BLUE_BAND_NM` by default) scatters back like
bibs, elastic light elsewhere like yiys, converted light like biys; the model's incidence grid is the kernel's,
each grid point taking the plate's distribution at the nearest plate incidence.
"""
from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM, SIDES, WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.core.spectra import band_mask, gaussian, photon_pdf_from_power
from bsdfkit.io import netcdf
from bsdfkit.raytrace.plate import (
    BACK_BIBS,
    BACK_YIYS,
    CHANNELS,
    PhosphorPlate,
    PlateChannel,
    PlateTables,
    plate_tables,
)

FORMAT = "bsdfkit-plate-spectral-model"
#: Tolerances: pdf rows sum to 1, photons kept per incident photon ≤ 1, bin widths equal.
_PDF_TOL = 1e-6
_PHOTON_TOL = 1e-9
_GRID_TOL = 1e-6
#: A measured model may give out more photons than it receives by this many standard uncertainties (noise); such
#: cells are scaled down to exactly one photon out per photon in (and listed), beyond it the model is refused.
NOISE_SIGMA = 3.0
#: Largest bin count (the alias tables hold K² entries per model).
MAX_BINS = 1024
#: Default plate temperature [K] of the thermal (anti-Stokes) tail: 40 °C, the upper bound of the phosphor
#: temperature during the module measurements (§5 of "Power and photon budget of a remote phosphor LED module").
PLATE_TEMPERATURE_K = 313.15
#: columns of :attr:`SpectralTables.tis`, photons out per incident photon: at the incident wavelength (elastic) or
#: converted, each reflected (backward) or transmitted (forward)
PHOTON_CHANNELS = ("elastic_reflection", "elastic_transmission", "converted_reflection", "converted_transmission")
ELASTIC_R, ELASTIC_T, CONVERTED_R, CONVERTED_T = range(len(PHOTON_CHANNELS))
#: codes of :attr:`SpectralTables.band`: the module's blue and yellow bands, and neither
BANDS = ("blue", "yellow", "other")
BAND_BLUE, BAND_YELLOW, BAND_OTHER = range(len(BANDS))
#: Second radiation constant c₂ = hc/k_B [nm·K] (CODATA 2018, exact).
C2_NM_K = 1.438776877e7


@dataclass(frozen=True, eq=False)
class SpectralPlateModel:
    """A validated plate spectral model (see the module docstring); arrays are float64, angles in degrees.

    ``elastic_tis`` and ``converted_tis`` have shape (2, incidences, excitations) in :data:`SIDES` order,
    ``emission_pdf`` (excitations, emissions) in 1/nm.
    """

    incidence_deg: np.ndarray
    excitation_nm: np.ndarray
    emission_nm: np.ndarray
    elastic_tis: np.ndarray
    converted_tis: np.ndarray
    emission_pdf: np.ndarray
    name: str = ""
    source: str | None = field(default=None)
    capped: tuple[tuple[float, float, float], ...] = ()

    @property
    def step_nm(self) -> float:
        return float(self.emission_nm[1] - self.emission_nm[0])

    def to_dataset(self) -> xr.Dataset:
        """The model as the contract dataset (``side``, ``incidence``, ``excitation``, ``emission``).

        Returns
        -------
        xarray.Dataset
            ``elastic_tis`` and ``converted_tis`` [-] on (side, incidence, excitation), ``emission_pdf`` [1/nm] on
            (excitation, emission); coordinates incidence [deg], excitation and emission [nm].
        """
        dims = ("side", "incidence", "excitation")
        return xr.Dataset(
            {"elastic_tis": (dims, self.elastic_tis, {"units": "1"}),
             "converted_tis": (dims, self.converted_tis, {"units": "1", "long_name": "converted power / incident"}),
             "emission_pdf": (("excitation", "emission"), self.emission_pdf,
                              {"units": "1/nm", "long_name": "photon-number pdf of the converted light"})},
            coords={"side": list(SIDES), "incidence": ("incidence", self.incidence_deg, {"units": "degree"}),
                    "excitation": ("excitation", self.excitation_nm, {"units": "nm"}),
                    "emission": ("emission", self.emission_nm, {"units": "nm"})},
            attrs={"format": FORMAT, "name": self.name},
        )

    def save(self, path: str | Path, force: bool = False) -> Path:
        """Write the model as netCDF, atomically (an existing file is kept unless ``force``).

        Parameters
        ----------
        path : str or Path
            The netCDF file to write.
        force : bool
            Replace an existing file.

        Returns
        -------
        Path
            The file written.
        """
        return netcdf.save(self.to_dataset(), path, force)


def spectral_model_from_dataset(ds: xr.Dataset, source: str | Path | None = None) -> SpectralPlateModel:
    """Validate a plate spectral model dataset (module docstring); errors name ``source`` and the variable.

    Parameters
    ----------
    ds : xarray.Dataset
        The model dataset.
    source : str or Path, optional
        Its file, named in errors.

    Returns
    -------
    SpectralPlateModel
        The validated model (TIS [-], incidences [deg], wavelengths [nm], emission pdf [1/nm]).
    """
    where = None if source is None else str(source)
    for name in ("elastic_tis", "converted_tis", "emission_pdf"):
        if name not in ds:
            raise InputError("missing variable of the plate spectral model", file=where, field=name,
                             expected="elastic_tis, converted_tis and emission_pdf", got=sorted(ds.data_vars))
    for name in ("side", "incidence", "excitation", "emission"):
        if name not in ds.coords:
            raise InputError("missing coordinate of the plate spectral model", file=where, field=name,
                             expected="side, incidence [deg], excitation [nm], emission [nm]")
    if sorted(str(s) for s in ds["side"].values) != sorted(SIDES):
        raise ValidationError("wrong sides", file=where, field="side", expected=list(SIDES),
                              got=[str(s) for s in ds["side"].values])
    ds = ds.sel(side=list(SIDES))
    try:
        tis = {n: ds[n].transpose("side", "incidence", "excitation").values.astype(np.float64)
               for n in ("elastic_tis", "converted_tis")}
        pdf = ds["emission_pdf"].transpose("excitation", "emission").values.astype(np.float64)
    except ValueError as exc:
        raise ValidationError("wrong dimensions", file=where, field="elastic_tis",
                              expected="elastic/converted_tis(side, incidence, excitation), "
                                       "emission_pdf(excitation, emission)", got=str(exc)) from None
    inc = ds["incidence"].values.astype(np.float64)
    exc_nm = ds["excitation"].values.astype(np.float64)
    em = ds["emission"].values.astype(np.float64)
    for name, grid, lo, hi in (("incidence", inc, 0.0, 90.0), ("excitation", exc_nm, *WAVELENGTH_RANGE_NM),
                               ("emission", em, *WAVELENGTH_RANGE_NM)):
        if grid.size < 1 or not np.all(np.isfinite(grid)) or np.any(np.diff(grid) <= 0) or grid[0] < lo \
                or grid[-1] > hi:
            raise ValidationError("coordinate must increase strictly within its range", file=where, field=name,
                                  expected=f"values in [{lo:g}, {hi:g}]", got=grid.tolist())
    if em.size < 2 or em.size > MAX_BINS or np.ptp(np.diff(em)) > _GRID_TOL * (em[1] - em[0]):
        raise ValidationError("the emission grid must be uniform", file=where, field="emission",
                              expected=f"2 to {MAX_BINS} equally spaced wavelengths", got=em.tolist())
    for name, values in (*tis.items(), ("emission_pdf", pdf)):
        if not np.all(np.isfinite(values)) or values.min() < 0:
            raise ValidationError("values must be finite and >= 0", file=where, field=name,
                                  got=float(np.nanmin(values)) if np.isfinite(values).any() else "NaN")
    step = em[1] - em[0]
    rows = pdf.sum(axis=1) * step
    converting = tis["converted_tis"].sum(axis=(0, 1)) > 0
    bad = (np.abs(rows - 1.0) > _PDF_TOL) & (converting | (rows > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise ValidationError("emission pdf row does not integrate to 1 (Σ p Δλ)", file=where,
                              field=f"emission_pdf[excitation={exc_nm[k]:g} nm]",
                              expected="1 (or a zero row where nothing converts)", got=float(rows[k]))
    std = {n: (ds[f"{n}_std"].transpose("side", "incidence", "excitation").values.astype(np.float64)
               if f"{n}_std" in ds else np.zeros_like(tis[n])) for n in ("elastic_tis", "converted_tis")}
    model = SpectralPlateModel(inc, exc_nm, em, tis["elastic_tis"], tis["converted_tis"], pdf,
                               name=str(ds.attrs.get("name", "")), source=where)
    return _checked_photons(model, std["elastic_tis"], std["converted_tis"], where)


def _harmonic_emission_nm(pdf: np.ndarray, emission_nm: np.ndarray, step: float) -> np.ndarray:
    """λ̃ = 1 / Σ_j p_j Δλ / λ_j per row (nan for zero rows): photons per converted power, times hc."""
    inv = (pdf * step / emission_nm).sum(axis=-1)
    with np.errstate(divide="ignore"):
        return np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), np.nan)


def _photon_tis(elastic: np.ndarray, converted: np.ndarray, pdf: np.ndarray, emission_nm: np.ndarray,
                excitation_nm: np.ndarray, step: float) -> np.ndarray:
    """(2 sides, …, 2 kinds) photons out per incident photon: elastic and converted (Y) on each side."""
    ratio = np.nan_to_num(_harmonic_emission_nm(pdf, emission_nm, step) / excitation_nm)
    return np.stack([elastic, converted * ratio], axis=-1)


def _checked_photons(model: SpectralPlateModel, elastic_std: np.ndarray, converted_std: np.ndarray,
                     where) -> SpectralPlateModel:
    """The model with photons out per photon in ≤ 1 everywhere: cells above 1 within :data:`NOISE_SIGMA` standard
    uncertainties (``*_std`` variables of a measured model) are scaled down to 1 and listed in ``capped`` as
    (incidence, excitation, photons out per photon in); beyond that the model is refused."""
    ratio = np.nan_to_num(_harmonic_emission_nm(model.emission_pdf, model.emission_nm, model.step_nm)
                          / model.excitation_nm)
    kept = (model.elastic_tis + model.converted_tis * ratio).sum(axis=0)  # (incidence, excitation)
    sigma = np.sqrt((elastic_std ** 2 + (converted_std * ratio) ** 2).sum(axis=0))
    over = kept > 1.0 + _PHOTON_TOL
    bad = over & (kept - 1.0 > NOISE_SIGMA * sigma)
    if bad.any():
        i, k = np.unravel_index(int(np.argmax(np.where(bad, kept, 0.0))), kept.shape)
        raise ValidationError("the plate gives out more photons than it receives", file=where,
                              field=f"converted_tis[incidence={model.incidence_deg[i]:g}, "
                                    f"excitation={model.excitation_nm[k]:g}]",
                              expected=f"elastic + converted photons per incident photon <= 1 (within "
                                       f"{NOISE_SIGMA:g} standard uncertainties)", got=float(kept[i, k]))
    if not over.any():
        return model
    scale = np.where(over, 1.0 / kept, 1.0)[None]
    capped = tuple((float(model.incidence_deg[i]), float(model.excitation_nm[k]), float(kept[i, k]))
                   for i, k in zip(*np.nonzero(over)))
    return replace(model, elastic_tis=model.elastic_tis * scale, converted_tis=model.converted_tis * scale,
                   capped=capped)


def load_spectral_model(path: str | Path) -> SpectralPlateModel:
    """Read a plate spectral model written by :meth:`SpectralPlateModel.save` (or any dataset of the contract).

    Parameters
    ----------
    path : str or Path
        The netCDF file.

    Returns
    -------
    SpectralPlateModel
        The validated model.
    """
    return spectral_model_from_dataset(netcdf.load(path), source=path)


def spectral_plate_from_two_colour(plate: PhosphorPlate, wavelength_nm: Sequence[float], emission_spectrum,
                                   pump_band_nm: tuple[float, float] = MODULE_BLUE_BAND_NM,
                                   name: str = "") -> SpectralPlateModel:
    """The spectral model of a two-wavelength plate: one emission spectrum times one absorption per incidence.

    At pump wavelengths (inside ``pump_band_nm``) the elastic TIS is bibs and the converted TIS biys (power);
    elsewhere the elastic TIS is yiys and nothing converts. ``emission_spectrum`` is the converted light's POWER
    spectrum on ``wavelength_nm`` (uniform grid, any scale), which is also the model's excitation and emission
    grid. With no emission inside the pump band this model and the two-wavelength plate trace the same blue and
    yellow powers (the equivalence of issue 17).

    Parameters
    ----------
    plate : PhosphorPlate
        The two-wavelength plate.
    wavelength_nm : sequence of float
        Uniform wavelength grid [nm].
    emission_spectrum : array_like
        Power spectrum of the converted light on ``wavelength_nm``, any scale.
    pump_band_nm : tuple of float
        (low, high) of the pump band [nm].
    name : str
        Model name (default: the plate's).

    Returns
    -------
    SpectralPlateModel
        The validated model.
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    pump = band_mask(wl, pump_band_nm)
    inc = np.asarray(plate.theta_i_deg, dtype=np.float64)

    def tis(channel: str) -> np.ndarray:  # (incidence,)
        return np.asarray(plate.channel(channel).tis, dtype=np.float64)

    elastic = np.stack([np.where(pump[None, :], tis(f"bibs_{s}")[:, None], tis(f"yiys_{s}")[:, None])
                        for s in SIDES])
    converted = np.stack([np.where(pump[None, :], tis(f"biys_{s}")[:, None], 0.0) for s in SIDES])
    row = photon_pdf_from_power(wl, emission_spectrum)
    pdf = np.where(pump[:, None], row[None, :], 0.0)
    ds = SpectralPlateModel(inc, wl, wl, elastic, converted, pdf, name=name or plate.name).to_dataset()
    return spectral_model_from_dataset(ds)


# ---- spectra on the bin grid ------------------------------------------------------------------------------------
def bin_edges(centres_nm: np.ndarray) -> np.ndarray:
    """Edges [nm] of the uniform bins centred on ``centres_nm`` (K + 1 values).

    Parameters
    ----------
    centres_nm : ndarray
        Uniformly spaced bin centres [nm].

    Returns
    -------
    ndarray
        Bin edges [nm].
    """
    step = centres_nm[1] - centres_nm[0]
    return np.concatenate([centres_nm - step / 2.0, [centres_nm[-1] + step / 2.0]])


def bin_powers(wavelength_nm: np.ndarray, values: np.ndarray, centres_nm: np.ndarray) -> np.ndarray:
    """∫ S dλ over each bin of the grid (S piecewise linear between its samples, 0 outside them).

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths of S, increasing [nm].
    values : ndarray
        Spectral density S at those wavelengths (any unit per nm).
    centres_nm : ndarray
        Uniform bin centres [nm].

    Returns
    -------
    ndarray
        ∫ S dλ per bin (the unit of S times nm).
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    s = np.asarray(values, dtype=np.float64)
    edges = np.clip(bin_edges(centres_nm), wl[0], wl[-1])
    # trapezoids on the union of the samples and the bin edges: exact for a piecewise-linear S
    fine = np.union1d(wl, edges)
    s_fine = np.interp(fine, wl, s)
    cum_fine = np.concatenate([[0.0], np.cumsum(0.5 * (s_fine[1:] + s_fine[:-1]) * np.diff(fine))])
    return np.diff(np.interp(edges, fine, cum_fine))


def gaussian_led_spectrum(peak_nm: float, fwhm_nm: float) -> tuple[np.ndarray, np.ndarray]:
    """A Gaussian LED spectrum (eq. (2) of [Cylindrical-module]) sampled every FWHM/200 over ±4 FWHM.

    Parameters
    ----------
    peak_nm : float
        Peak wavelength [nm].
    fwhm_nm : float
        Full width at half maximum [nm], > 0.

    Returns
    -------
    wavelength : ndarray, shape (1601,)
        Sample wavelengths [nm].
    spectrum : ndarray, shape (1601,)
        Relative spectrum, 1 at the peak [-].
    """
    wl = np.linspace(peak_nm - 4.0 * fwhm_nm, peak_nm + 4.0 * fwhm_nm, 1601)
    return wl, gaussian(wl, peak_nm, fwhm_nm)


# ---- kernel tables -------------------------------------------------------------------------------------------------
def alias_table(pdf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Walker's alias tables (Vose's construction) of each row of ``pdf`` (rows of K weights, any scale).

    Sampling: i = ⌊u₁K⌋, then i if u₂ < prob[i] else alias[i]. A zero row gets the uniform table (unused).
    The construction (a Python loop, ~0.4 s for 200 rows of 401) is cached per process by the table's bytes:
    a scene's tables are built for its compilation, its kernel parameters and its result.

    Parameters
    ----------
    pdf : ndarray
        (rows, K) non-negative weights.

    Returns
    -------
    prob : ndarray
        (rows, K) acceptance probabilities [-].
    alias : ndarray
        (rows, K) alias indices (int32).
    """
    pdf = np.ascontiguousarray(pdf, dtype=np.float64)
    prob, alias = _alias_rows(pdf.shape, pdf.tobytes())
    return prob.copy(), alias.copy()


@functools.lru_cache(maxsize=8)
def _alias_rows(shape: tuple[int, int], data: bytes) -> tuple[np.ndarray, np.ndarray]:
    pdf = np.frombuffer(data, dtype=np.float64).reshape(shape)
    rows, K = pdf.shape
    prob = np.ones((rows, K))
    alias = np.tile(np.arange(K, dtype=np.int32), (rows, 1))
    for r in range(rows):
        total = pdf[r].sum()
        if not total > 0:
            continue
        q = pdf[r] * K / total
        small = [i for i in range(K) if q[i] < 1.0]
        large = [i for i in range(K) if q[i] >= 1.0]
        while small and large:
            s, g = small.pop(), large.pop()
            prob[r, s] = q[s]
            alias[r, s] = g
            q[g] = q[g] + q[s] - 1.0
            (small if q[g] < 1.0 else large).append(g)
        for i in small + large:  # rounding leftovers
            prob[r, i] = 1.0
    return prob, alias


def model_on_bins(model: SpectralPlateModel, plate: PhosphorPlate | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """elastic, converted (2, I, K) and pdf (K, K) at the emission bins: linear in excitation wavelength; below the
    excitation grid the first excitation's values; above it, with a two-wavelength ``plate``, its yiys TIS (at the
    model's incidences, linear in θi) and no conversion — the light the plate emits, not measured by an excitation
    scan — else the last excitation's values.

    Parameters
    ----------
    model : SpectralPlateModel
        The plate's spectral model.
    plate : PhosphorPlate, optional
        A two-wavelength plate for the bins above the excitation grid.

    Returns
    -------
    elastic, converted : ndarray
        (2 sides, I incidences, K bins) TIS [-].
    pdf : ndarray
        (K excitation, K emission) emission pdf [1/nm].
    """
    lam = model.emission_nm
    x = model.excitation_nm
    if x.size == 1:
        idx0 = np.zeros(lam.size, int)
        t = np.zeros(lam.size)
    else:
        idx0 = np.clip(np.searchsorted(x, lam, side="right") - 1, 0, x.size - 2)
        t = np.clip((lam - x[idx0]) / (x[idx0 + 1] - x[idx0]), 0.0, 1.0)
    idx1 = np.minimum(idx0 + 1, x.size - 1)

    def interp(a):  # along the last axis (excitation)
        return (1.0 - t) * a[..., idx0] + t * a[..., idx1]

    elastic, converted = interp(model.elastic_tis), interp(model.converted_tis)
    above = lam > x[-1]
    if plate is not None and above.any():
        src = np.asarray(plate.theta_i_deg, dtype=np.float64)
        for b, side in enumerate(SIDES):
            yiys = np.interp(model.incidence_deg, src, np.asarray(plate.channel(f"yiys_{side}").tis, dtype=float))
            elastic[b][:, above] = yiys[:, None]
        converted[:, :, above] = 0.0
    pdf = (1.0 - t)[:, None] * model.emission_pdf[idx0] + t[:, None] * model.emission_pdf[idx1]
    norm = pdf.sum(axis=1) * model.step_nm
    converting = converted.sum(axis=(0, 1)) > 0
    if np.any(converting & ~(norm > 0)):
        k = int(np.argmax(converting & ~(norm > 0)))
        raise ValidationError("light converts at a wavelength whose emission pdf is zero", file=model.source,
                              field=f"emission_pdf[{lam[k]:g} nm]", expected="a pdf row where converted_tis > 0")
    pdf = np.where(norm[:, None] > 0, pdf / np.where(norm > 0, norm, 1.0)[:, None], 0.0)
    return elastic, converted, pdf


def _thermal_exponent(excitation_nm, emission_nm, temperature_K: float) -> np.ndarray:
    """(hc/λ_em − hc/λ_ex)/(k_B T) where λ_em < λ_ex, else 0 (excitations, emissions) [1]: minus the log of the
    Boltzmann weight B of emission below the excitation wavelength; ``temperature_K`` [K] > 0."""
    if not (np.isfinite(temperature_K) and temperature_K > 0):
        raise ValidationError("plate temperature must be positive", field="top.temperature_K",
                              expected="a temperature > 0 K", got=temperature_K)
    ex = np.asarray(excitation_nm, dtype=np.float64)[:, None]
    em = np.asarray(emission_nm, dtype=np.float64)[None, :]
    return np.where(em < ex, np.clip(C2_NM_K / temperature_K * (1.0 / em - 1.0 / ex), 0.0, None), 0.0)


def conditional_emission_pdf(pdf: np.ndarray, lam_nm: np.ndarray, temperature_K: float) -> np.ndarray:
    """Rows of ``pdf`` (excitation bin k = row k, on the bins ``lam`` [nm]) weighted by the Boltzmann factor
    B = exp(−(hc/λ_em − hc/λ_ex)/(k_B T)) below the excitation wavelength (1 above) and renormalised to their own
    sums (zero rows stay zero): the emission pdf given the excitation bin [1/nm].

    The weights are formed in log space relative to each row's largest, so a row whose whole emission lies far
    below its excitation (or a very cold plate) keeps its sum instead of underflowing to zero.

    Parameters
    ----------
    pdf : ndarray
        (K, K) emission pdf, row = excitation bin [1/nm].
    lam_nm : ndarray
        Bin centres [nm].
    temperature_K : float
        Plate temperature [K], > 0.

    Returns
    -------
    ndarray
        (K, K) conditional emission pdf [1/nm].
    """
    pdf = np.asarray(pdf, dtype=np.float64)
    positive = pdf > 0
    with np.errstate(divide="ignore"):
        log_w = np.where(positive, np.log(np.where(positive, pdf, 1.0)), -np.inf) \
            - _thermal_exponent(lam_nm, lam_nm, temperature_K)
    top = log_w.max(axis=1, keepdims=True)
    weighted = np.where(positive, np.exp(log_w - np.where(np.isfinite(top), top, 0.0)), 0.0)
    old, new = pdf.sum(axis=1), weighted.sum(axis=1)
    scale = np.where(new > 0, old / np.where(new > 0, new, 1.0), 0.0)
    return weighted * scale[:, None]


def anti_stokes_share(pdf: np.ndarray) -> np.ndarray:
    """Per excitation bin k (rows of a pdf on its own bins), the probability that a converted photon leaves in a
    bin shorter than k: Σ_{j<k} p_kj / Σ_j p_kj [1] (0 for zero rows).

    Parameters
    ----------
    pdf : ndarray
        (K, K) emission pdf on its own bins, row = excitation bin.

    Returns
    -------
    ndarray
        (K,) probabilities [-].
    """
    below = np.tril(pdf, -1).sum(axis=1)
    total = pdf.sum(axis=1)
    return np.where(total > 0, below / np.where(total > 0, total, 1.0), 0.0)


def shape_plate_on_grid(plate: PhosphorPlate | None, incidence_deg: np.ndarray) -> PhosphorPlate:
    """The plate whose angular distributions the spectral kernel samples, on the model's incidence grid.

    Each grid point takes the distributions of the nearest incidence of ``plate`` (Lambertian without a plate);
    the TIS are the plate's, interpolated linearly in θi (only the shapes are used in spectral mode).

    Parameters
    ----------
    plate : PhosphorPlate or None
        The two-wavelength plate, or None (Lambertian).
    incidence_deg : ndarray
        The model's incidence grid [deg].

    Returns
    -------
    PhosphorPlate
        The plate on that grid.
    """
    base = plate if plate is not None else PhosphorPlate.constant({c: 0.0 for c in CHANNELS})
    src = np.asarray(base.theta_i_deg, dtype=float)
    grid = tuple(float(v) for v in incidence_deg)
    near = [int(np.argmin(np.abs(src - g))) for g in grid]
    channels = {}
    for c in CHANNELS:
        ch = base.channel(c)
        tis = tuple(float(v) for v in np.interp(grid, src, np.asarray(ch.tis, dtype=float)))
        channels[c] = PlateChannel(tis, tuple(ch.distributions[n] for n in near))
    return PhosphorPlate(theta_i_deg=grid, name=base.name, notes=base.notes, **channels)


@dataclass(frozen=True, eq=False)
class SpectralTables:
    """Numeric tables of the spectral kernel (NumPy).

    ``lam`` (K,) bin centres [nm]; ``photon_scale`` λ_k / λ_K−1 (photon tallies are in units of photons of a
    unit-weight ray at the longest bin); ``band`` (K,) :data:`BAND_BLUE`, :data:`BAND_YELLOW` or :data:`BAND_OTHER`;
    ``elastic_shape`` (K,) the backward channel whose distribution elastic light takes (``plate.BACK_BIBS`` or
    ``BACK_YIYS``); ``tis`` (G·K, 4) photons per incident photon in :data:`PHOTON_CHANNELS` order at (incidence g,
    bin k) → row g·K + k;
    ``alias_prob``, ``alias_index`` (K·K,) the emission rows' alias tables; ``led_cdf`` (K,) cumulative LED
    bin powers; ``plate`` the angular tables on the model's incidence grid (None for an exit top);
    ``emission_pdf`` (K, K) the conditional emission pdf p' the alias tables sample (module docstring) and
    ``temperature_K`` [K] its plate temperature.
    """

    lam: np.ndarray
    photon_scale: np.ndarray
    band: np.ndarray
    elastic_shape: np.ndarray
    tis: np.ndarray | None
    alias_prob: np.ndarray | None
    alias_index: np.ndarray | None
    led_power: np.ndarray
    led_cdf: np.ndarray
    plate: PlateTables | None
    grid_deg: np.ndarray | None
    extrapolated_nm: tuple[float, ...] = ()
    capped: tuple[tuple[float, float, float], ...] = ()
    yiys_nm: tuple[float, ...] = ()
    emission_pdf: np.ndarray | None = None
    temperature_K: float = PLATE_TEMPERATURE_K


def led_bin_power(spectrum: tuple[np.ndarray, np.ndarray], lam_nm: np.ndarray, source: str | None = None) -> np.ndarray:
    """Fractions of the LED power in each bin; refuses a spectrum with more than 0.1 % outside the grid.

    Parameters
    ----------
    spectrum : tuple of ndarray
        (wavelength [nm], power spectrum [any scale]) of the LEDs.
    lam_nm : ndarray
        Bin centres [nm].
    source : str, optional
        The scene file, named in errors.

    Returns
    -------
    ndarray
        (K,) fractions of the LED power [-], summing to 1.
    """
    wl, values = spectrum
    if np.any(np.asarray(values) < 0):
        raise ValidationError("LED spectrum has negative power", file=source, field="leds.spectrum",
                              expected="values >= 0", got=float(np.min(values)))
    p = bin_powers(wl, values, lam_nm)
    total = float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(wl)))
    if not total > 0 or p.sum() < (1.0 - 1e-3) * total:
        edges = bin_edges(lam_nm)
        raise ValidationError("LED spectrum reaches outside the spectral grid", file=source, field="leds.spectrum",
                              expected=f"its power within {edges[0]:g}-{edges[-1]:g} nm",
                              got=f"{100 * (1 - p.sum() / total) if total > 0 else 100:.2g} % outside")
    return p / p.sum()


def spectral_tables(model: SpectralPlateModel | None, plate: PhosphorPlate | None, lam_nm: np.ndarray,
                    led_spectrum: tuple[np.ndarray, np.ndarray], *, source: str | None = None,
                    temperature_K: float = PLATE_TEMPERATURE_K) -> SpectralTables:
    """The kernel tables of a spectral scene: bins ``lam`` (the model's emission grid), plate (or exit top), the
    emission conditioned on the excitation bin at the plate temperature ``temperature_K`` [K] (module docstring).

    Bins in the module's blue band (:data:`MODULE_BLUE_BAND_NM`, also the pump band whose elastic light takes the
    bibs distribution) count as blue, those in :data:`MODULE_YELLOW_BAND_NM` as yellow.

    Parameters
    ----------
    model : SpectralPlateModel or None
        The plate's spectral model; None for an exit top.
    plate : PhosphorPlate or None
        The two-wavelength plate (angular shapes; yiys above the excitation grid).
    lam_nm : ndarray
        Bin centres [nm].
    led_spectrum : tuple of ndarray
        (wavelength [nm], power spectrum [any scale]) of the LEDs.
    source : str, optional
        The scene file, named in errors.
    temperature_K : float
        Plate temperature [K].

    Returns
    -------
    SpectralTables
        The kernel's tables.
    """
    lam_nm = np.asarray(lam_nm, dtype=np.float64)
    blue, yellow = MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM
    band = np.where(band_mask(lam_nm, blue), BAND_BLUE,
                    np.where(band_mask(lam_nm, yellow), BAND_YELLOW, BAND_OTHER)).astype(np.int32)
    shape = np.where(band_mask(lam_nm, blue), BACK_BIBS, BACK_YIYS).astype(np.int32)
    led = led_bin_power(led_spectrum, lam_nm, source)
    cdf = np.cumsum(led)
    cdf[-1] = 1.0
    tis = prob = index = tabs = grid = cond = None
    extrapolated: tuple[float, ...] = ()
    from_plate: tuple[float, ...] = ()
    if model is not None:
        elastic, converted, pdf = model_on_bins(model, plate)
        ph = _photon_tis(elastic, converted, pdf[None, None], lam_nm, lam_nm, model.step_nm)  # (2, I, K, 2)
        # rows (g, k) → PHOTON_CHANNELS (ph: side (SIDES order: reflection, transmission), g, k, elastic/converted)
        tis = np.stack([ph[0, :, :, 0], ph[1, :, :, 0], ph[0, :, :, 1], ph[1, :, :, 1]], axis=-1).reshape(-1, 4)
        # the model has ≤ 1 photon out per photon in at its excitations; interpolation between two excitations
        # can exceed it by rounding-level amounts (the harmonic mean of a mixed pdf row is not linear): cap
        total = tis.sum(axis=1)
        tis = tis / np.maximum(total, 1.0)[:, None]
        cond = conditional_emission_pdf(pdf, lam_nm, temperature_K)  # the photon yields above keep the data's rows
        p, a = alias_table(cond * model.step_nm)
        prob, index = p.reshape(-1), a.reshape(-1).astype(np.int32)
        grid = model.incidence_deg
        if grid.size == 1:  # one incidence: constant in θi (as plate_tables does)
            grid = np.array([grid[0], grid[0] + 1.0])
            tis = np.concatenate([tis, tis])
        tabs = plate_tables(shape_plate_on_grid(plate, grid))
        x = model.excitation_nm
        extrapolated = tuple(float(v) for v in lam_nm[(lam_nm < x[0]) | ((lam_nm > x[-1]) & (plate is None))])
        from_plate = tuple(float(v) for v in lam_nm[(lam_nm > x[-1]) & (plate is not None)])
    return SpectralTables(lam=lam_nm, photon_scale=lam_nm / lam_nm[-1], band=band, elastic_shape=shape, tis=tis,
                          alias_prob=prob, alias_index=index, led_power=led, led_cdf=cdf, plate=tabs, grid_deg=grid,
                          extrapolated_nm=extrapolated, capped=() if model is None else model.capped,
                          yiys_nm=from_plate, emission_pdf=cond, temperature_K=float(temperature_K))


def surface_reflectance_on_bins(spectrum: tuple[np.ndarray, np.ndarray], lam_nm: np.ndarray, field_name: str,
                                source: str | None = None) -> np.ndarray:
    """A surface's reflectance ρ(λ) at the bin centres (linear interpolation; the bins must be inside).

    Parameters
    ----------
    spectrum : tuple of ndarray
        (wavelength [nm], reflectance [-]).
    lam_nm : ndarray
        Bin centres [nm].
    field_name : str
        The scene key, named in errors.
    source : str, optional
        The spectrum file, named in errors.

    Returns
    -------
    ndarray
        Reflectance at the bin centres [-].
    """
    wl, rho = spectrum
    if lam_nm[0] < wl[0] or lam_nm[-1] > wl[-1]:
        raise ValidationError("the reflectance spectrum does not cover the spectral grid", file=source,
                              field=field_name, expected=f"{lam_nm[0]:g}-{lam_nm[-1]:g} nm",
                              got=f"{wl[0]:g}-{wl[-1]:g} nm")
    return np.interp(lam_nm, wl, rho)
