"""LED and phosphor spectrum fitting, and the two-band spectrum reconstruction.

* :func:`fit_spectrum` / :func:`fit_spectra` fit eq. (2) (Gaussian), eq. (3) (split Gaussian) or their
  sum ("two-band": blue pump Gaussian + yellow phosphor split Gaussian, fitted jointly) of the
  cylindrical-module paper to measured spectra, following the recipe of docs/metrology.md §6: normalise
  by the maximum, start the peak at the argmax and the FWHM at the half-maximum crossings, fit with
  α = 0 first and free α in a second pass (the σ–α correlation otherwise slows convergence).
* :func:`two_band_gains` and :func:`reconstruct_two_band_spectrum` implement §4.2 of the same paper:
  the blue and yellow radiant fluxes of a two-wavelength simulation are redistributed over normalised
  blue and yellow spectra by solving

      Φ_blue   = A1·Σ_{λi∈blue band} S_blue(λi)Δλi   + A2·Σ_{λi∈blue band} S_yellow(λi)Δλi
      Φ_yellow = A1·Σ_{λi∈yellow band} S_blue(λi)Δλi + A2·Σ_{λi∈yellow band} S_yellow(λi)Δλi

  for the gains A1, A2 (W/nm); the absolute spectral flux is A1·S_blue + A2·S_yellow. The paper's band
  limits are 380–500 nm (blue) and 501–780 nm (yellow), both inclusive; they are parameters here.
  (The printed equation is garbled by text extraction; the system above follows from the paper's
  definitions: each band flux is the band sum of the linear combination.)

Wavelengths in nm throughout. Spectra cross the API as NumPy arrays (fitting) or
:class:`colour.SpectralDistribution` (reconstruction output).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np
import xarray as xr

from bsdfkit.core.errors import FitError, InputError, NumericalError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit.least_squares import FitOptions, Parameter, least_squares
from bsdfkit.models import functions as models
from bsdfkit.reduction.spectral import band_sum

if TYPE_CHECKING:
    from colour import SpectralDistribution

__all__ = [
    "SPECTRUM_MODELS",
    "BLUE_BAND_NM",
    "YELLOW_BAND_NM",
    "MAX_CONDITION",
    "fit_spectrum",
    "fit_spectra",
    "spectrum_model_values",
    "band_integral",
    "TwoBandGains",
    "two_band_gains",
    "reconstruct_two_band_spectrum",
]

SPECTRUM_MODELS = ("gaussian", "split-gaussian", "two-band")

#: Band limits (nm, inclusive) of the §4.2 reconstruction in the cylindrical-module paper.
BLUE_BAND_NM: tuple[float, float] = (380.0, 500.0)
YELLOW_BAND_NM: tuple[float, float] = (501.0, 780.0)

#: Largest accepted 2-norm condition number of the 2×2 band-sum matrix. With flux uncertainties of
#: ~1 % (Table 1 of the paper: simulation vs measurement differ by 4 %), κ = 1e3 already allows the
#: gains to be wrong by a factor of ~10; beyond that the blue and yellow spectra are not separable.
MAX_CONDITION: float = 1e3

#: Default split (nm) between the pump and phosphor regions when initialising a two-band fit.
DEFAULT_SPLIT_NM: float = 500.0


# ------------------------------------------------------------------------------------------------
# Model functions (module level: hashable static arguments of the compiled solver)
# ------------------------------------------------------------------------------------------------
def _gaussian(theta, wavelength):
    return theta[2] * models.gaussian_spectrum(wavelength, theta[0], theta[1])


def _split_gaussian(theta, wavelength):
    return theta[3] * models.split_gaussian_spectrum(wavelength, theta[0], theta[1], theta[2])


def _two_band_symmetric(theta, wavelength):
    return models.two_band_spectrum(wavelength, theta[0], theta[1], theta[2], theta[3], theta[4], 0.0, theta[5])


def _two_band(theta, wavelength):
    return models.two_band_spectrum(
        wavelength, theta[0], theta[1], theta[2], theta[3], theta[4], theta[5], theta[6]
    )


def _parameters(model: str, lo: float, hi: float, split_nm: float = DEFAULT_SPLIT_NM) -> tuple[Parameter, ...]:
    """Parameters and bounds. A single band's peak may lie up to one span outside the grid (truncated
    spectra); in two-band fits each component is held on its side of ``split_nm`` so the pump Gaussian
    cannot wander into the phosphor band (and vice versa), with a pump FWHM below the pump region width."""
    span = hi - lo
    peak = dict(lower=lo - span, upper=hi + span, unit="nm")
    width = dict(lower=0.0, unit="nm")
    alpha = dict(lower=-1.0, upper=1.0, unit="1")
    amp = dict(lower=0.0, unit="input units")
    if model.startswith("two-band"):
        blue = (Parameter("blue_peak_nm", lo, split_nm, "nm"), Parameter("blue_fwhm_nm", 0.0, split_nm - lo, "nm"),
                Parameter("blue_amplitude", **amp))
        yellow_peak = Parameter("yellow_peak_nm", split_nm, hi + span, "nm")
        if model == "two-band-symmetric":
            return blue + (yellow_peak, Parameter("yellow_fwhm_nm", **width), Parameter("yellow_amplitude", **amp))
        return blue + (yellow_peak, Parameter("yellow_fwhm_nm", **width), Parameter("yellow_alpha", **alpha),
                       Parameter("yellow_amplitude", **amp))
    if model == "gaussian":
        return (Parameter("peak_nm", **peak), Parameter("fwhm_nm", **width), Parameter("amplitude", **amp))
    return (Parameter("peak_nm", **peak), Parameter("fwhm_nm", **width), Parameter("alpha", **alpha),
            Parameter("amplitude", **amp))


_FUNCTIONS = {
    "gaussian": _gaussian,
    "split-gaussian": _split_gaussian,
    "two-band-symmetric": _two_band_symmetric,
    "two-band": _two_band,
}


def spectrum_model_values(model: str, params: dict[str, float], wavelength: np.ndarray) -> np.ndarray:
    """Evaluate a fitted spectrum model (parameter names as in :func:`fit_spectrum`) at λ in nm."""
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    wl = np.asarray(wavelength, dtype=float)
    names = [p.name for p in _parameters(model, float(wl.min()), float(wl.max()) + 1.0)]
    theta = np.array([params[n] for n in names], dtype=float)
    with x64():
        return np.asarray(_FUNCTIONS[model](jnp.asarray(theta), jnp.asarray(wl)))


# ------------------------------------------------------------------------------------------------
# Initial values
# ------------------------------------------------------------------------------------------------
def _half_max_crossings(wl: np.ndarray, y: np.ndarray, i_peak: int) -> tuple[float | None, float | None]:
    """Wavelengths where y falls to half of y[i_peak] left and right of it (linear interpolation)."""
    half = 0.5 * y[i_peak]
    left = right = None
    below = np.flatnonzero(y[:i_peak] <= half)
    if below.size:
        j = below[-1]
        left = float(np.interp(half, [y[j], y[j + 1]], [wl[j], wl[j + 1]])) if y[j + 1] != y[j] else float(wl[j])
    below = np.flatnonzero(y[i_peak:] <= half)
    if below.size:
        j = i_peak + below[0]
        right = float(np.interp(half, [y[j], y[j - 1]], [wl[j], wl[j - 1]])) if y[j - 1] != y[j] else float(wl[j])
    return left, right


def _peak_and_fwhm(wl: np.ndarray, y: np.ndarray, region: np.ndarray) -> tuple[float, float, float]:
    """(peak λ, FWHM, peak value) of y restricted to ``region`` (boolean), FWHM from half-max crossings."""
    idx = np.flatnonzero(region)
    if idx.size < 3:
        raise FitError("fewer than 3 samples in a band used to initialise the fit")
    w, v = wl[idx], y[idx]
    i = int(np.argmax(v))
    if not v[i] > 0:
        raise FitError(f"no positive signal between {w[0]:g} and {w[-1]:g} nm")
    left, right = _half_max_crossings(w, v, i)
    step = float(np.median(np.diff(w)))
    if left is not None and right is not None:
        fwhm = right - left
    elif left is not None or right is not None:
        # Truncated band: mirror the one half width we have.
        fwhm = 2.0 * abs((left if left is not None else right) - w[i])
    else:
        fwhm = 0.5 * (w[-1] - w[0])
    return float(w[i]), max(fwhm, step), float(v[i])


def _inside(p0: np.ndarray, parameters: tuple[Parameter, ...]) -> np.ndarray:
    """Move data-derived start values strictly inside their bounds (a peak on the grid edge, say)."""
    out = np.array(p0, dtype=float)
    for k, p in enumerate(parameters):
        if math.isfinite(p.lower) and math.isfinite(p.upper):
            pad = 1e-6 * (p.upper - p.lower)
        else:
            finite = [abs(b) for b in (p.lower, p.upper) if math.isfinite(b)]
            pad = 1e-9 * max(finite + [1.0])
        out[:, k] = np.clip(out[:, k], p.lower + pad, p.upper - pad)
    return out


# ------------------------------------------------------------------------------------------------
# Fitting front-ends
# ------------------------------------------------------------------------------------------------
def _validated_grid(wavelength: np.ndarray) -> np.ndarray:
    wl = np.asarray(wavelength, dtype=float)
    if wl.ndim != 1 or wl.size < 3:
        raise InputError("wavelength grid must be 1-D with at least 3 samples", field="wavelength",
                         got=wl.shape)
    if not np.all(np.isfinite(wl)):
        raise InputError("wavelength is not finite", field="wavelength", got=float(wl[~np.isfinite(wl)][0]))
    if not np.all(np.diff(wl) > 0):
        k = int(np.argmax(~(np.diff(wl) > 0))) + 1
        raise InputError("wavelengths must increase strictly", field=f"wavelength[{k}]",
                         expected=f"> {wl[k - 1]:g}", got=float(wl[k]))
    return wl


def fit_spectra(
    wavelength: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float = DEFAULT_SPLIT_NM,
) -> xr.Dataset:
    """Fit a spectrum model to a batch of spectra on one wavelength grid (one compiled, vmapped solve).

    Parameters
    ----------
    wavelength
        Grid in nm, shape (n,), strictly increasing (any spacing).
    values
        Spectra, shape (batch, n), any unit (relative or W/nm).
    model
        'gaussian' (eq. 2 of the cylindrical-module paper: peak_nm, fwhm_nm, amplitude),
        'split-gaussian' (eq. 3: peak_nm, fwhm_nm, alpha, amplitude) or 'two-band' (eq. 2 + eq. 3
        jointly: blue_peak_nm, blue_fwhm_nm, blue_amplitude, yellow_peak_nm, yellow_fwhm_nm,
        yellow_alpha, yellow_amplitude).
    sigma
        Standard uncertainties of ``values`` (same units), broadcast to ``values``; None = unweighted.
    mask
        Boolean, True = use the sample (e.g. restrict to a band); broadcast to ``values``.
    options
        :class:`bsdfkit.fit.least_squares.FitOptions` (default: absolute residuals, linear loss).
    split_nm
        Two-band only: wavelength separating the pump region (below) from the phosphor region (at and
        above) when initialising the two components (default 500 nm, the paper's blue/yellow limit).

    Returns
    -------
    xarray.Dataset over ``spectrum`` (see :func:`bsdfkit.fit.least_squares.least_squares`); amplitudes are in the
    units of ``values``, FWHMs are true full widths at half maximum in nm.
    """
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    options = options or FitOptions()
    wl = _validated_grid(wavelength)
    y = np.asarray(values, dtype=float)
    if y.ndim != 2 or y.shape[1] != wl.size:
        raise InputError("spectra must have shape (batch, n) matching the wavelength grid", field="values",
                         expected=f"(batch, {wl.size})", got=y.shape)
    m = np.ones(y.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y.shape)
    finite_used = np.where(m, y, 0.0)
    if not np.all(np.isfinite(finite_used)):
        i, j = np.argwhere(~np.isfinite(finite_used))[0]
        raise InputError("spectral value is not finite", field=f"values[{i}, {j}] at {wl[j]:g} nm",
                         got=float(y[i, j]))
    peak_values = np.max(np.where(m, y, -np.inf), axis=1)
    if not np.all(peak_values > 0):
        b = int(np.argmax(~(peak_values > 0)))
        raise FitError(f"spectrum {b} has no positive value to normalise by")
    scale = peak_values[:, None]
    y_n = y / scale
    s_n = None if sigma is None else np.broadcast_to(np.asarray(sigma, dtype=float), y.shape) / scale

    labels = [f"spectrum {b}" for b in range(y.shape[0])] if y.shape[0] > 1 else [""]
    used = wl[m.any(axis=0)]
    lo, hi = float(used[0]), float(used[-1])
    n_batch = y.shape[0]
    if model in ("gaussian", "split-gaussian"):
        p0 = np.array([_peak_and_fwhm(wl, y_n[b], m[b]) for b in range(n_batch)])
        first = least_squares(_gaussian, wl, y_n, _inside(p0, _parameters("gaussian", lo, hi)),
                              _parameters("gaussian", lo, hi), sigma=s_n, mask=m,
                              options=options, batch_dim="spectrum", batch_labels=labels, model_name="gaussian")
        result = first
        if model == "split-gaussian":
            p1 = np.stack([first.peak_nm.values, first.fwhm_nm.values, np.zeros(n_batch),
                           first.amplitude.values], axis=1)
            result = least_squares(_split_gaussian, wl, y_n, _inside(p1, _parameters(model, lo, hi)),
                                   _parameters(model, lo, hi), sigma=s_n,
                                   mask=m, options=options, batch_dim="spectrum", batch_labels=labels, model_name=model)
    else:
        rows = []
        for b in range(n_batch):
            bp, bw, ba = _peak_and_fwhm(wl, y_n[b], m[b] & (wl < split_nm))
            yp, yw, ya = _peak_and_fwhm(wl, y_n[b], m[b] & (wl >= split_nm))
            rows.append([bp, bw, ba, yp, yw, ya])
        p0 = np.array(rows)
        par = _parameters("two-band-symmetric", lo, hi, split_nm)
        first = least_squares(_two_band_symmetric, wl, y_n, _inside(p0, par), par,
                              sigma=s_n, mask=m, options=options, batch_dim="spectrum", batch_labels=labels,
                              model_name="two-band (alpha = 0 pass)")
        names = [p.name for p in _parameters("two-band-symmetric", lo, hi, split_nm)]
        cols = [first[n].values for n in names]
        p1 = np.stack(cols[:5] + [np.zeros(n_batch)] + cols[5:], axis=1)
        par = _parameters(model, lo, hi, split_nm)
        result = least_squares(_two_band, wl, y_n, _inside(p1, par), par, sigma=s_n, mask=m,
                               options=options, batch_dim="spectrum", batch_labels=labels, model_name=model)

    # Undo the normalisation of the amplitudes (value, std and covariance).
    names = list(result.parameter.values)
    factors = np.ones((n_batch, len(names)))
    for k, name in enumerate(names):
        if name.endswith("amplitude"):
            factors[:, k] = scale[:, 0]
            result[name] = result[name] * scale[:, 0]
            result[f"{name}_std"] = result[f"{name}_std"] * scale[:, 0]
            result[name].attrs["units"] = result[f"{name}_std"].attrs["units"] = "input units"
    result["covariance"] = result["covariance"] * (factors[:, :, None] * factors[:, None, :])
    result.attrs["model"] = model
    result.attrs["normalisation"] = "fitted on values / max(values); amplitudes rescaled to input units"
    if model != "gaussian":
        result.attrs["passes"] = "alpha fixed at 0, then alpha free (docs/metrology.md §6 (ii))"
    return result


def fit_spectrum(
    wavelength: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float = DEFAULT_SPLIT_NM,
) -> xr.Dataset:
    """Fit one spectrum; see :func:`fit_spectra` for the models and arguments (λ in nm).

    Returns a Dataset of scalars: each parameter and its ``_std``, ``covariance``, ``r2``, ``rms``,
    ``iterations`` and ``converged``.
    """
    y = np.asarray(values, dtype=float)
    if y.ndim != 1:
        raise InputError("a single spectrum must be 1-D", field="values", got=y.shape)
    # 1-D sigma/mask broadcast against the (1, n) batch.
    ds = fit_spectra(wavelength, y[None, :], model, sigma=sigma, mask=mask, options=options, split_nm=split_nm)
    return ds.isel(spectrum=0)


# ------------------------------------------------------------------------------------------------
# Two-band reconstruction (§4.2 of the cylindrical-module paper)
# ------------------------------------------------------------------------------------------------
def band_integral(wavelength: np.ndarray, values: np.ndarray, band_nm: tuple[float, float]) -> float:
    """Σ values(λi)·Δλi over lo ≤ λi ≤ hi (inclusive), the band sum of §4.2 of the cylindrical-module paper.

    λ in nm; Δλi are the sample spacings (central differences): :func:`bsdfkit.reduction.spectral.band_sum` on a
    validated grid. Result in value-unit·nm (W for W/nm).
    """
    wl = _validated_grid(wavelength)
    lo, hi = band_nm
    if not lo < hi:
        raise ValidationError("empty band", field="band_nm", expected="lower < upper", got=band_nm)
    return band_sum(wl, values, band_nm)


@dataclass(frozen=True)
class TwoBandGains:
    """Solution of the §4.2 system: gains A1 (blue) and A2 (yellow) in W/nm, and the matrix's condition."""

    a1_W_per_nm: float
    a2_W_per_nm: float
    condition: float
    matrix_nm: tuple[tuple[float, float], tuple[float, float]]


def two_band_gains(
    wavelength: np.ndarray,
    s_blue: np.ndarray,
    s_yellow: np.ndarray,
    flux_blue_W: float,
    flux_yellow_W: float,
    *,
    blue_band_nm: tuple[float, float] = BLUE_BAND_NM,
    yellow_band_nm: tuple[float, float] = YELLOW_BAND_NM,
    max_condition: float = MAX_CONDITION,
) -> TwoBandGains:
    """Gains A1, A2 (W/nm) of §4.2 of the cylindrical-module paper.

    Solves Φ_blue = A1·Σ_blue S_blue Δλ + A2·Σ_blue S_yellow Δλ and
    Φ_yellow = A1·Σ_yellow S_blue Δλ + A2·Σ_yellow S_yellow Δλ, band sums over the inclusive limits
    ``blue_band_nm`` (default 380–500 nm) and ``yellow_band_nm`` (default 501–780 nm).

    Parameters
    ----------
    wavelength
        Grid in nm.
    s_blue, s_yellow
        Normalised (peak 1) blue and yellow spectra on that grid (dimensionless).
    flux_blue_W, flux_yellow_W
        Band radiant fluxes in W (Table 1 of the paper, simulation: 0.058 W and 0.472 W).
    max_condition
        Refuse matrices with a larger 2-norm condition number (default :data:`MAX_CONDITION`).

    Raises
    ------
    NumericalError
        Near-singular system (condition number above ``max_condition``) or a negative gain (a negative
        spectral flux is unphysical: the spectra do not fit the band fluxes).
    """
    wl = _validated_grid(wavelength)
    sb = np.asarray(s_blue, dtype=float)
    sy = np.asarray(s_yellow, dtype=float)
    for name, arr in (("s_blue", sb), ("s_yellow", sy)):
        if arr.shape != wl.shape:
            raise InputError("spectrum does not match the wavelength grid", field=name,
                             expected=str(wl.shape), got=arr.shape)
        if not np.all(np.isfinite(arr)):
            raise InputError("spectrum value is not finite", field=name)
    for name, val in (("flux_blue_W", flux_blue_W), ("flux_yellow_W", flux_yellow_W)):
        if not (math.isfinite(val) and val >= 0):
            raise ValidationError("band flux must be finite and ≥ 0", field=name, got=val)
    matrix = np.array(
        [
            [band_integral(wl, sb, blue_band_nm), band_integral(wl, sy, blue_band_nm)],
            [band_integral(wl, sb, yellow_band_nm), band_integral(wl, sy, yellow_band_nm)],
        ]
    )
    cond = float(np.linalg.cond(matrix)) if np.all(np.isfinite(matrix)) else math.inf
    if not cond <= max_condition:
        raise NumericalError(
            f"two-band system is near-singular (condition number {cond:.3g} > {max_condition:.3g}); "
            "the blue and yellow spectra are not separable with bands "
            f"{blue_band_nm[0]:g}-{blue_band_nm[1]:g} nm and {yellow_band_nm[0]:g}-{yellow_band_nm[1]:g} nm"
        )
    a1, a2 = np.linalg.solve(matrix, np.array([flux_blue_W, flux_yellow_W], dtype=float))
    if a1 < 0 or a2 < 0:
        raise NumericalError(f"two-band gains are negative (A1 = {a1:.4g}, A2 = {a2:.4g} W/nm): the spectra "
                             "cannot reproduce these band fluxes with non-negative spectral flux")
    return TwoBandGains(float(a1), float(a2), cond,
                        ((float(matrix[0, 0]), float(matrix[0, 1])), (float(matrix[1, 0]), float(matrix[1, 1]))))


def reconstruct_two_band_spectrum(
    wavelength: np.ndarray,
    s_blue: np.ndarray,
    s_yellow: np.ndarray,
    flux_blue_W: float,
    flux_yellow_W: float,
    *,
    blue_band_nm: tuple[float, float] = BLUE_BAND_NM,
    yellow_band_nm: tuple[float, float] = YELLOW_BAND_NM,
    max_condition: float = MAX_CONDITION,
    name: str = "two-band reconstruction",
) -> SpectralDistribution:
    """Absolute spectral radiant flux Φ_e,λ = A1·S_blue + A2·S_yellow in W/nm (§4.2, cylindrical-module paper).

    Arguments as :func:`two_band_gains` (bands 380–500 nm and 501–780 nm by default, λ in nm). Returns a
    :class:`colour.SpectralDistribution` on the input grid; its band sums reproduce the two fluxes.
    """
    import colour

    gains = two_band_gains(wavelength, s_blue, s_yellow, flux_blue_W, flux_yellow_W,
                           blue_band_nm=blue_band_nm, yellow_band_nm=yellow_band_nm,
                           max_condition=max_condition)
    wl = np.asarray(wavelength, dtype=float)
    flux = gains.a1_W_per_nm * np.asarray(s_blue, float) + gains.a2_W_per_nm * np.asarray(s_yellow, float)
    return colour.SpectralDistribution(flux, wl, name=name)
