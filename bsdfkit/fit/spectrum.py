"""LED and phosphor spectrum fitting, measured-vs-fitted metrics, batch fits, and the two-band reconstruction.

* :func:`fit_spectrum` / :func:`fit_spectra` fit one model to one spectrum or to a batch (one compiled kernel
  per model and pass). Models: eq. (2) (``gaussian``) and eq. (3) (``split-gaussian``) of the
  cylindrical-module paper, fitted by the recipe of docs/fitting.md §2 (normalise by the maximum, start at
  the argmax and the half-maximum crossings, α = 0 first, then α free); the LED line shapes of
  :mod:`bsdfkit.models.led` (``ohno2005``, ``split-pseudo-voigt``, ``split-pearson7``, one pass from the
  measured peak, FWHM and asymmetry) and those lines with a split-Gaussian side band (``pseudo-voigt-shoulder``,
  ``pearson7-shoulder``: the shoulder of InGaN LEDs; three start points solved in one batch); and the pump +
  phosphor sums ``two-band`` (pump Gaussian + phosphor split Gaussian, the paper's §4.2 components) and
  ``two-band-led`` (pump Gaussian line + side band, phosphor split Gaussian) and ``two-band-wide`` (that pump,
  phosphor split Gaussian + Gaussian: a second phosphor such as a red nitride band, or the long tail of one;
  three start points from the measured phosphor band, :func:`_phosphor_pair_starts`), whose split between pump
  and phosphor is found from the data (:func:`find_two_band_split`). Every reported component peak is the
  maximum of the fitted component curve, not a parameter.
* :func:`analyse_spectra` is the batch front-end of ``bsdfkit fit spectrum``: it fits many spectra (different
  grids allowed: padded and masked), optionally every single-band model with the best chosen by AICc or BIC
  (``model="best"``), and returns one record per spectrum with the measured metrics
  (:mod:`bsdfkit.reduction.spectrum_metrics`), the same metrics of the fitted curve, their differences and a
  ``warnings`` list (R² < 0, parameters at a bound, no convergence, fitted peak/FWHM far from the measured).
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
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from bsdfkit.core.conventions import MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM, SPECTRUM_CRITERIA
from bsdfkit.core.errors import BsdfkitError, FitError, InputError, NumericalError, ValidationError
from bsdfkit.core.jaxconfig import jitted, x64
from bsdfkit.core.spectra import FWHM_PER_SIGMA, split_gaussian
from bsdfkit.fit import lm
from bsdfkit.fit.least_squares import FitOptions, Parameter, least_squares
from bsdfkit.models.registry import SPECTRUM_MODELS as _REGISTERED_SPECTRUM_MODELS
from bsdfkit.models.registry import pump_two_band, pump_two_band_led
from bsdfkit.reduction.colorimetry import check_power_spectrum, check_wavelengths_nm
from bsdfkit.reduction.spectral import band_sum
from bsdfkit.reduction.spectrum_metrics import half_maximum_crossings, peak_wavelength, spectrum_metrics

if TYPE_CHECKING:
    from colour import SpectralDistribution

__all__ = [
    "SPECTRUM_MODELS",
    "SINGLE_BAND_MODELS",
    "TWO_BAND_MODELS",
    "CRITERIA",
    "BLUE_BAND_NM",
    "YELLOW_BAND_NM",
    "MAX_CONDITION",
    "TwoBandSplit",
    "find_two_band_split",
    "fit_spectrum",
    "fit_spectra",
    "information_criteria",
    "analyse_spectra",
    "spectrum_model_values",
    "band_integral",
    "TwoBandGains",
    "two_band_gains",
    "reconstruct_two_band_spectrum",
]

#: Single-band line shapes; ``model="best"`` of :func:`analyse_spectra` chooses among them.
SINGLE_BAND_MODELS = ("gaussian", "split-gaussian", "ohno2005", "split-pseudo-voigt", "split-pearson7",
                      "pseudo-voigt-shoulder", "pearson7-shoulder")
#: Single-band models with a split-Gaussian side band (InGaN LEDs have a shoulder ~10-15 nm above their peak).
SHOULDER_MODELS = ("pseudo-voigt-shoulder", "pearson7-shoulder")
#: Bound [nm] of the side band's offset from the main peak.
SIDE_OFFSET_MAX_NM: float = 40.0
#: Retries of a batch after a degenerate member made :func:`least_squares` raise (:func:`_solve`), and the
#: condition-number limit of those batch solves: near 1/ε, where inverting JᵀJ itself can fail; the usual
#: limit (``FitOptions.max_condition``) is applied per spectrum afterwards.
MAX_BATCH_RETRIES: int = 6
LENIENT_MAX_CONDITION: float = 1e15
#: Iterations of each start point in the first round of a multi-start fit (:func:`_solve_multistart`).
MULTISTART_ROUND1_MAXITER: int = 40
#: Smallest side-band FWHM [nm] and largest |α| of the side band: with them each half width is ≥ 1 nm, so the
#: band cannot collapse into a spike between samples (all-zero or collinear Jacobian columns: a singular fit).
SIDE_FWHM_MIN_NM: float = 8.0
SIDE_ALPHA_MAX: float = 0.75
#: Largest |α| of the main line of the shoulder models.
SHOULDER_ALPHA_MAX: float = 0.9
#: Largest side-band FWHM [nm]: a band much wider than the spectrum is a flat offset whose width and asymmetry
#: the data cannot separate (a singular fit).
SIDE_FWHM_MAX_NM: float = 120.0
#: Pump + phosphor sums, fitted jointly with a data-derived split (:func:`find_two_band_split`).
TWO_BAND_MODELS = ("two-band", "two-band-led", "two-band-wide")
#: Two-band models whose pump is a line with a side band.
PUMP_SIDE_MODELS = ("two-band-led", "two-band-wide")
SPECTRUM_MODELS = SINGLE_BAND_MODELS + TWO_BAND_MODELS
#: Information criteria for ``model="best"``.
CRITERIA = SPECTRUM_CRITERIA

#: Band limits (nm, inclusive) of the §4.2 reconstruction in the cylindrical-module paper (defined once, in
#: :mod:`bsdfkit.core.conventions`).
BLUE_BAND_NM: tuple[float, float] = MODULE_BLUE_BAND_NM
YELLOW_BAND_NM: tuple[float, float] = MODULE_YELLOW_BAND_NM

#: Largest accepted 2-norm condition number of the 2×2 band-sum matrix. With flux uncertainties of
#: ~1 % (Table 1 of the paper: simulation vs measurement differ by 4 %), κ = 1e3 already allows the
#: gains to be wrong by a factor of ~10; beyond that the blue and yellow spectra are not separable.
MAX_CONDITION: float = 1e3

#: The paper's blue/yellow limit [nm]: the pump peak must lie below it (:func:`find_two_band_split`).
DEFAULT_SPLIT_NM: float = 500.0

#: Two-band refusals (:func:`find_two_band_split`): the pump maximum below :data:`DEFAULT_SPLIT_NM` must reach
#: this fraction of the spectrum's maximum, and the phosphor maximum above the valley must reach this fraction
#: of the maximum and exceed the valley by :data:`PHOSPHOR_MIN_RISE` (relative to the valley value).
PUMP_MIN_FRACTION: float = 0.02
PHOSPHOR_MIN_FRACTION: float = 0.05
PHOSPHOR_MIN_RISE: float = 0.10
#: The pump peak may move this far [nm] from the measured pump maximum during a two-band fit; its FWHM is
#: bounded by :data:`PUMP_MAX_FWHM_NM` (InGaN pumps have 15-35 nm), so it cannot absorb the phosphor band.
PUMP_PEAK_WINDOW_NM: float = 10.0
PUMP_MAX_FWHM_NM: float = 40.0
#: ``two-band-led``: smallest FWHM [nm] of the pump line and of its side band (no spikes between samples).
PUMP_MIN_FWHM_NM: float = 2.0
#: ``two-band-led``: the pump's side band (the InGaN shoulder, cf. the ``*-shoulder`` models) lies up to this far
#: [nm] above the pump line; further out it would take over the phosphor's rising edge.
PUMP_SIDE_OFFSET_MAX_NM: float = 20.0
#: ``two-band-wide``: the phosphor's second band (a Gaussian) lies within this distance [nm] of the first (a split
#: Gaussian) and has an FWHM [nm] in this range (narrower would be a spike, wider a flat offset).
PHOSPHOR2_OFFSET_MAX_NM: float = 200.0
PHOSPHOR2_FWHM_NM: tuple[float, float] = (10.0, 200.0)

#: Warning of :func:`analyse_spectra` below this R² (R² < 0 always gets its own warning).
WARN_R2: float = 0.9
#: Warnings of :func:`analyse_spectra` when the fitted curve's peak or FWHM is this far from the measured one:
#: 0.5 nm is half the 1 nm sampling of the Benkner spectra, 5 % the FWHM precision a line-shape comparison needs
#: (the AICc-best model meets both on every single-band LED of docs/fitting.md §10.6; the Gaussian misses the FWHM
#: by 16-37 %).
WARN_PEAK_NM: float = 0.5
WARN_FWHM_RELATIVE: float = 0.05


# ------------------------------------------------------------------------------------------------
# Model functions (module level: hashable static arguments of the compiled solver)
# ------------------------------------------------------------------------------------------------
# The model functions are the registry's (:mod:`bsdfkit.models.registry`); module-level names for the solver.
_FUNCTIONS = {name: m.function for name, m in _REGISTERED_SPECTRUM_MODELS.items()}
_gaussian = _FUNCTIONS["gaussian"]
_split_gaussian = _FUNCTIONS["split-gaussian"]
_two_band = _FUNCTIONS["two-band"]
_two_band_led = _FUNCTIONS["two-band-led"]
_two_band_wide = _FUNCTIONS["two-band-wide"]


# Two-band fits in relative coordinates: x = {"wl": λ, "pump": measured pump peak, "valley": split} (per point,
# constant per spectrum), θ[0] = pump peak − pump and θ[k] = phosphor peak − valley, so that bounds shared by a
# batch hold each component on its own side of its own spectrum's valley.
def _two_band_rel(theta, x):
    return _two_band(_absolute(theta, x, 3), x["wl"])


def _two_band_led_rel(theta, x):
    return _two_band_led(_absolute(theta, x, 6), x["wl"])


def _two_band_wide_rel(theta, x):
    return _two_band_wide(_absolute(theta, x, 6), x["wl"])


def _absolute(theta, x, k_phosphor):
    shift = jnp.zeros_like(theta).at[0].set(x["pump"][0]).at[k_phosphor].set(x["valley"][0])
    return theta + shift


_RELATIVE = {"two-band": (_two_band_rel, 3), "two-band-led": (_two_band_led_rel, 6),
             "two-band-wide": (_two_band_wide_rel, 6)}


def _parameters(model: str, lo: float, hi: float, split_nm: float = DEFAULT_SPLIT_NM) -> tuple[Parameter, ...]:
    """Parameters and bounds (natural parameters, absolute peaks). A single band's peak may lie up to one span
    outside the grid (truncated spectra)."""
    span = hi - lo
    peak = dict(lower=lo - span, upper=hi + span, unit="nm")
    width = dict(lower=0.0, unit="nm")
    alpha = dict(lower=-1.0, upper=1.0, unit="1")
    amp = dict(lower=0.0, unit="input units")
    if model.startswith("two-band"):
        blue = [Parameter("blue_peak_nm", lo, split_nm, "nm"), Parameter("blue_fwhm_nm", 0.0, split_nm - lo, "nm")]
        blue.append(Parameter("blue_amplitude", **amp))
        if model in PUMP_SIDE_MODELS:
            blue += [Parameter("blue_side_offset_nm", 0.0, PUMP_SIDE_OFFSET_MAX_NM, "nm"),
                     Parameter("blue_side_fwhm_nm", PUMP_MIN_FWHM_NM, PUMP_MAX_FWHM_NM, "nm"),
                     Parameter("blue_side_amplitude", **amp)]
        yellow = [Parameter("yellow_peak_nm", split_nm, hi + span, "nm"), Parameter("yellow_fwhm_nm", **width),
                  Parameter("yellow_alpha", **alpha)]
        yellow.append(Parameter("yellow_amplitude", **amp))
        if model == "two-band-wide":
            yellow += [Parameter("phosphor2_offset_nm", -PHOSPHOR2_OFFSET_MAX_NM, PHOSPHOR2_OFFSET_MAX_NM, "nm"),
                       Parameter("phosphor2_fwhm_nm", PHOSPHOR2_FWHM_NM[0], PHOSPHOR2_FWHM_NM[1], "nm"),
                       Parameter("phosphor2_amplitude", **amp)]
        return tuple(blue + yellow)
    head = (Parameter("peak_nm", **peak), Parameter("fwhm_nm", **width))
    tail = (Parameter("amplitude", **amp),)
    if model in ("gaussian", "ohno2005"):
        return head + tail
    if model == "split-gaussian":
        return head + (Parameter("alpha", **alpha),) + tail
    side = (Parameter("side_offset_nm", -SIDE_OFFSET_MAX_NM, SIDE_OFFSET_MAX_NM, "nm"),
            Parameter("side_fwhm_nm", SIDE_FWHM_MIN_NM, SIDE_FWHM_MAX_NM, "nm"), Parameter("side_amplitude", **amp),
            Parameter("side_alpha", -SIDE_ALPHA_MAX, SIDE_ALPHA_MAX, "1"))
    if model in SHOULDER_MODELS:
        # Line + side band: a main line narrower than ~2 samples, or one-sided (|α| → 1), leaves parameters the
        # data cannot separate (a singular fit); the side band takes what such a line would describe.
        head = (head[0], Parameter("fwhm_nm", PUMP_MIN_FWHM_NM, math.inf, "nm"))
        alpha = dict(lower=-SHOULDER_ALPHA_MAX, upper=SHOULDER_ALPHA_MAX, unit="1")
    if model.startswith("split-pseudo-voigt") or model == "pseudo-voigt-shoulder":
        main = head + (Parameter("alpha", **alpha), Parameter("eta", 0.0, 1.0, "1")) + tail
        return main + side if model.endswith("shoulder") else main
    if model.startswith("split-pearson7") or model == "pearson7-shoulder":
        main = head + (Parameter("alpha", **alpha), Parameter("shape_m", 0.5, 1000.0, "1")) + tail
        return main + side if model.endswith("shoulder") else main
    raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS), got=model)


def _relative_parameters(model: str) -> tuple[Parameter, ...]:
    """Parameters of the relative two-band functions (peaks as offsets from the pump maximum / the valley)."""
    names = [p.name for p in _parameters(model, 380.0, 780.0)]
    out = []
    for p in _parameters(model, 380.0, 780.0):
        if p.name == "blue_peak_nm":
            out.append(Parameter("blue_peak_nm", -PUMP_PEAK_WINDOW_NM, PUMP_PEAK_WINDOW_NM, "nm"))
        elif p.name == "blue_fwhm_nm":
            low = PUMP_MIN_FWHM_NM if model in PUMP_SIDE_MODELS else 0.0
            out.append(Parameter("blue_fwhm_nm", low, PUMP_MAX_FWHM_NM, "nm"))
        elif p.name == "yellow_peak_nm":
            out.append(Parameter("yellow_peak_nm", 0.0, math.inf, "nm"))
        else:
            out.append(p)
    assert [p.name for p in out] == names
    return tuple(out)


def spectrum_model_values(model: str, params: dict[str, float], wavelength: np.ndarray) -> np.ndarray:
    """Evaluate a fitted spectrum model (parameter names as in :func:`fit_spectrum`) at λ [nm]."""
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    wl = np.asarray(wavelength, dtype=float)
    names = [p.name for p in _parameters(model, float(wl.min()), float(wl.max()) + 1.0)]
    missing = [n for n in names if n not in params]
    if missing:
        raise ValidationError("missing model parameters", field="params", expected=", ".join(names), got=missing)
    theta = np.array([params[n] for n in names], dtype=float)
    with x64():
        return np.asarray(jitted(_FUNCTIONS[model])(jnp.asarray(theta), jnp.asarray(wl)))


# ------------------------------------------------------------------------------------------------
# Initial values
# ------------------------------------------------------------------------------------------------
def _peak_and_fwhm(wl: np.ndarray, y: np.ndarray, region: np.ndarray,
                   with_alpha: bool = False) -> tuple[float, ...]:
    """(peak λ, FWHM, peak value[, α]) of y restricted to ``region`` (boolean), FWHM from half-max crossings,
    α = (right − left half width)/(sum) when both crossings exist (else 0)."""
    idx = np.flatnonzero(region)
    if idx.size < 3:
        raise FitError("fewer than 3 samples in a band used to initialise the fit")
    w, v = wl[idx], y[idx]
    i = int(np.argmax(v))
    if not v[i] > 0:
        raise FitError(f"no positive signal between {w[0]:g} and {w[-1]:g} nm")
    left, right = half_maximum_crossings(w, v)  # nan for a side without a crossing
    step = float(np.median(np.diff(w)))
    alpha = 0.0
    if math.isfinite(left) and math.isfinite(right):
        fwhm = right - left
        if fwhm > 0:
            alpha = float(np.clip(((right - w[i]) - (w[i] - left)) / fwhm, -0.9, 0.9))
    elif math.isfinite(left) or math.isfinite(right):
        # Truncated band: mirror the one half width we have.
        fwhm = 2.0 * abs((left if math.isfinite(left) else right) - w[i])
    else:
        fwhm = 0.5 * (w[-1] - w[0])
    out = (float(w[i]), max(fwhm, step), float(v[i]))
    return out + (alpha,) if with_alpha else out


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
# Two-band split from the data
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TwoBandSplit:
    """Where a pump + phosphor spectrum separates (wavelengths in nm, values in input units)."""

    pump_peak_nm: float
    pump_value: float
    valley_nm: float
    valley_value: float
    phosphor_peak_nm: float
    phosphor_value: float


def find_two_band_split(wavelength: np.ndarray, values: np.ndarray, region: np.ndarray | None = None, *,
                        label: str = "") -> TwoBandSplit:
    """Pump maximum, valley and phosphor maximum of a phosphor-converted spectrum, or a refusal.

    The pump maximum is the largest local maximum below :data:`DEFAULT_SPLIT_NM` (500 nm) that reaches
    :data:`PUMP_MIN_FRACTION` of the spectrum's maximum and that the spectrum falls from by ≥ 10 % before
    560 nm; the valley is the first local minimum after it (or the smallest value up to 560 nm); the phosphor
    maximum is the largest sample above the valley. Values are smoothed over ±2 samples for the search
    (noise); the reported maxima are those of the data: the largest sample within ±2 samples refined by the
    local quadratic through it and its neighbours (:func:`bsdfkit.reduction.spectrum_metrics.peak_wavelength`).

    Raises
    ------
    FitError
        No pump (the maximum below 500 nm is under :data:`PUMP_MIN_FRACTION` of the spectrum's maximum, or lies
        on the 500 nm edge, i.e. the spectrum still rises there), or no phosphor band (nothing above the valley
        reaches :data:`PHOSPHOR_MIN_FRACTION` of the maximum and rises :data:`PHOSPHOR_MIN_RISE` above the
        valley): a single-colour LED is not a two-band spectrum.
    """
    wl = np.asarray(wavelength, dtype=float)
    y_all = np.asarray(values, dtype=float)
    keep = np.ones(wl.shape, bool) if region is None else np.asarray(region, bool)
    wl, y_raw = wl[keep], y_all[keep]
    prefix = f"{label}: " if label else ""
    if wl.size < 5:
        raise FitError(f"{prefix}two-band fit needs at least 5 samples")
    kernel = np.ones(5) / 5.0
    y = np.convolve(np.pad(y_raw, 2, mode="edge"), kernel, mode="valid")
    top = float(np.max(y))
    if not top > 0:
        raise FitError(f"{prefix}spectrum has no positive value")
    below = np.flatnonzero(wl < DEFAULT_SPLIT_NM)
    if below.size < 3:
        raise FitError(f"{prefix}refusing two-band fit: no pump band, the data start at {wl[0]:g} nm (a pump "
                       f"peak below {DEFAULT_SPLIT_NM:g} nm is needed)")
    # Pump: the largest local maximum below 500 nm that the spectrum falls from by ≥ 10 % before 560 nm.
    i_pump, i_valley = -1, -1
    for j in sorted(below[1:], key=lambda j: -y[j]):
        if not (y[j] >= y[j - 1] and y[j] >= y[j + 1]) or y[j] < PUMP_MIN_FRACTION * top:
            continue
        after = np.flatnonzero((wl > wl[j]) & (wl <= 560.0))
        dips = [int(k) for k in after[:-1] if y[k] <= y[k - 1] and y[k] < y[k + 1] and y[k] <= 0.9 * y[j]]
        if dips:  # the pump's decay ends at the first local minimum after it
            i_pump, i_valley = int(j), dips[0]
            break
        if after.size and y[after].min() <= 0.9 * y[j] and y[after[-1]] > y[after].min():
            i_pump, i_valley = int(j), int(after[np.argmin(y[after])])
            break
        if after.size and y[after].min() <= 0.9 * y[j]:  # falls and stays down: no phosphor (checked below)
            i_pump, i_valley = int(j), int(after[-1])
            break
    if i_pump < 0:
        largest = float(np.max(y[below]))
        raise FitError(f"{prefix}refusing two-band fit: no pump band below {DEFAULT_SPLIT_NM:g} nm (no local "
                       f"maximum there reaching {PUMP_MIN_FRACTION:.0%} of the spectrum's maximum and followed by "
                       f"a valley; largest value there {largest / top:.1%} of the maximum); this looks like a "
                       f"single-colour LED with its peak at {wl[int(np.argmax(y))]:g} nm, fit a single-band model")
    rest = np.flatnonzero(wl > wl[i_valley])
    if rest.size == 0:
        raise FitError(f"{prefix}refusing two-band fit: no phosphor band (no data above {wl[i_valley]:g} nm)")
    i_ph = int(rest[np.argmax(y[rest])])
    valley, phosphor = float(y[i_valley]), float(y[i_ph])
    if phosphor < PHOSPHOR_MIN_FRACTION * top or phosphor < (1.0 + PHOSPHOR_MIN_RISE) * max(valley, 0.0) \
            or i_ph == rest[0]:
        raise FitError(f"{prefix}refusing two-band fit: no phosphor band above the pump at {wl[i_pump]:g} nm "
                       f"(beyond {wl[i_valley]:g} nm the spectrum reaches only {phosphor / top:.1%} of the "
                       f"maximum and rises {(phosphor / valley - 1) if valley > 0 else 0:.0%} above its valley); "
                       "this looks like a single-colour LED, fit a single-band model")
    # Positions reported on the data samples (the smoothing only guided the search).
    def local_max(i: int) -> int:
        lo, hi = max(i - 2, 0), min(i + 3, y_raw.size)
        return lo + int(np.argmax(y_raw[lo:hi]))

    def vertex(i: int) -> tuple[float, float]:
        # the local quadratic through the maximum sample and its neighbours (as the measured peak of
        # spectrum_metrics): on a 5 nm grid the maximum sample alone can be 2.5 nm off the peak
        j = local_max(i)
        if 0 < j < y_raw.size - 1:
            return peak_wavelength(wl[j - 1:j + 2], y_raw[j - 1:j + 2])
        return float(wl[j]), float(y_raw[j])

    (pump_nm, pump_value), (phosphor_nm, phosphor_value) = vertex(i_pump), vertex(i_ph)
    return TwoBandSplit(pump_nm, pump_value, float(wl[i_valley]), float(y_raw[i_valley]), phosphor_nm,
                        phosphor_value)


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


def _nm_grid(wavelength: np.ndarray) -> np.ndarray:
    """:func:`_validated_grid` of a grid that must be in nm (µm or m values are refused)."""
    wl = _validated_grid(wavelength)
    check_wavelengths_nm(wl, "wavelength")
    return wl


def _validated_grids(wavelength: np.ndarray, n_batch: int) -> np.ndarray:
    """(batch, n) grids in nm: one grid broadcast, or one strictly increasing grid per spectrum."""
    wl = np.asarray(wavelength, dtype=float)
    if wl.ndim == 1:
        return np.broadcast_to(_nm_grid(wl), (n_batch, wl.size))
    if wl.ndim != 2 or wl.shape[0] != n_batch:
        raise InputError("wavelength must be (n,) or (batch, n)", field="wavelength",
                         expected=f"(n,) or ({n_batch}, n)", got=wl.shape)
    for row in wl:
        _nm_grid(row)
    return wl


def _solve(function, wl, y, m, p0, parameters, *, sigma, options, labels, model_name, collect):
    """:func:`least_squares` over a batch. Returns (result or None, errors: index → one-line message).

    Without ``collect`` any degenerate member raises :class:`FitError` as :func:`least_squares` does. With
    ``collect`` one degenerate spectrum must not take the others with it (:func:`least_squares` raises for the
    whole batch): the batch is solved with the condition-number refusal relaxed to "numerically singular"
    (:data:`LENIENT_MAX_CONDITION`) and the usual check is redone per spectrum on the returned covariance (Jacobi
    equilibrated, as :func:`least_squares` does on JᵀJ, so the condition numbers agree within a factor of
    about p² by van der Sluis). A spectrum that still makes the batch raise is named by the error (internal
    labels), recorded, and its row replaced by a copy of a healthy one, so the retry keeps the batch shape and
    the compiled kernel (at most :data:`MAX_BATCH_RETRIES` retries; after that, or on an error naming no
    spectrum, the spectra are fitted one at a time)."""
    kwargs = dict(batch_dim="spectrum", model_name=model_name)
    n = y.shape[0]

    def run(idx, opts, names):
        x = wl[idx] if not isinstance(wl, dict) else {k: v[idx] for k, v in wl.items()}
        s = None if sigma is None else sigma[idx]
        return least_squares(function, x, y[idx], _inside(p0[idx], parameters), parameters, sigma=s,
                             mask=m[idx], batch_labels=names, options=opts, **kwargs)

    every = np.arange(n)
    if not collect:
        return run(every, options, [labels[i] for i in every]), {}
    lenient = replace(options, max_condition=LENIENT_MAX_CONDITION)
    internal = [f"#{i}" for i in every]
    source = every.copy()
    errors: dict[int, str] = {}
    result = None
    for _ in range(MAX_BATCH_RETRIES + 1):
        try:
            with np.errstate(invalid="ignore", divide="ignore"):  # variances of degenerate members: flagged below
                result = run(source, lenient, internal)
            break
        except FitError as exc:
            named = re.match(r"#(\d+): (.*)", str(exc))
            healthy = [j for j in every if j not in errors and (not named or j != int(named.group(1)))]
            if not named or not healthy:
                break
            k = int(named.group(1))
            errors[k] = f"{labels[k]}: {named.group(2)}" if labels[k] else named.group(2)
            source[k] = healthy[0]
        except np.linalg.LinAlgError:
            break
    if result is not None:
        flagged = _degenerate(result, labels, options.max_condition)
        errors.update({k: v for k, v in flagged.items() if k not in errors})
        return result, errors
    rows, errors = {}, {}
    for b in every:
        try:
            rows[int(b)] = run(np.array([b]), options, [labels[b]])
        except FitError as exc:
            errors[int(b)] = str(exc)
    if not rows:
        return None, errors
    alive = np.array(sorted(rows))
    return _expand(xr.concat([rows[int(b)] for b in alive], dim="spectrum"), alive, n), errors


def _degenerate(result: xr.Dataset, labels: Sequence[str], max_condition: float) -> dict[int, str]:
    """Spectra whose covariance (Jacobi-equilibrated) has a condition number above ``max_condition``."""
    names = [str(n) for n in result.parameter.values]
    errors = {}
    for b, cov in enumerate(result.covariance.values):
        d = np.sqrt(np.abs(np.diagonal(cov)))
        if not (np.all(np.isfinite(cov)) and np.all(np.diagonal(cov) > 0)):
            errors[b] = f"{labels[b]}: singular JᵀJ: the data do not constrain the parameters"
            continue
        ev, evec = np.linalg.eigh(cov / np.outer(d, d))
        cond = ev[-1] / ev[0] if ev[0] > 0 else math.inf
        if not cond <= max_condition:
            weak = [names[k] for k in np.argsort(-np.abs(evec[:, -1])) if abs(evec[k, -1]) > 0.3]
            errors[b] = (f"{labels[b]}: singular JᵀJ (condition number {cond:.3g} > {max_condition:.3g}): "
                         f"{', '.join(weak)} not separately determined by these data")
    return errors


def _fit_batch(wl2, y, m, model, *, sigma, options, split_nm, labels, collect):
    """Core of :func:`fit_spectra` on (batch, n) grids. Returns (Dataset on normalised data or None, errors,
    splits) where errors maps a spectrum index to a one-line message."""
    n_batch = y.shape[0]
    peak_values = np.max(np.where(m, y, -np.inf), axis=1)
    if not np.all(peak_values > 0):
        b = int(np.argmax(~(peak_values > 0)))
        raise FitError(f"{labels[b] or 'spectrum'}: no positive value to normalise by")
    scale = peak_values[:, None]
    y_n = y / scale
    s_n = None if sigma is None else np.broadcast_to(np.asarray(sigma, dtype=float), y.shape) / scale
    used = np.where(m, wl2, np.nan)
    lo, hi = float(np.nanmin(used)), float(np.nanmax(used))
    common = dict(sigma=s_n, options=options, labels=labels, collect=collect)
    errors: dict[int, str] = {}
    splits: dict[int, TwoBandSplit] = {}

    if model in ("gaussian", "split-gaussian"):
        p0 = np.array([_peak_and_fwhm(wl2[b], y_n[b], m[b]) for b in range(n_batch)])
        wl_in = wl2[0] if np.all(wl2 == wl2[0]) else wl2  # 1-D grid as before: identical numbers
        wl_use = np.broadcast_to(wl_in, y.shape)
        first, errors = _solve(_gaussian, wl_use, y_n, m, p0, _parameters("gaussian", lo, hi),
                               model_name="gaussian", **common)
        result = first
        if model == "split-gaussian" and first is not None:
            p1 = np.stack([first.peak_nm.values, first.fwhm_nm.values, np.zeros(n_batch),
                           first.amplitude.values], axis=1)
            alive = np.array([b for b in range(n_batch) if b not in errors])
            result, more = _solve(_split_gaussian, wl_use[alive], y_n[alive], m[alive], p1[alive],
                                  _parameters(model, lo, hi), model_name=model,
                                  **{**common, "sigma": None if s_n is None else s_n[alive],
                                     "labels": [labels[b] for b in alive]})
            errors.update({int(alive[k]): v for k, v in more.items()})
            result = _expand(result, alive, n_batch)
    elif model in SHOULDER_MODELS:
        result, errors = _fit_multistart(wl2, y_n, m, model, _parameters(model, lo, hi), common)
    elif model in SINGLE_BAND_MODELS:
        rows = []
        for b in range(n_batch):
            peak, fwhm, amp, alpha = _peak_and_fwhm(wl2[b], y_n[b], m[b], with_alpha=True)
            if model == "ohno2005":
                rows.append([peak, fwhm, amp])
            else:
                rows.append([peak, fwhm, alpha, 0.5 if model == "split-pseudo-voigt" else 2.0, amp])
        result, errors = _solve(_FUNCTIONS[model], wl2, y_n, m, np.array(rows), _parameters(model, lo, hi),
                                model_name=model, **common)
    else:
        result, errors, splits = _fit_two_band(wl2, y_n, m, model, split_nm=split_nm, common=common)

    if result is None:
        return None, errors, splits
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
    result["normalisation"] = (("spectrum",), scale[:, 0], {"long_name": "maximum the data were divided by"})
    result.attrs["model"] = model
    result.attrs["normalisation"] = "fitted on values / max(values); amplitudes rescaled to input units"
    if model == "split-gaussian":
        result.attrs["passes"] = "alpha fixed at 0, then alpha free (docs/fitting.md §2)"
    return result, errors, splits


def _shoulder_starts(peak: float, fwhm: float, amp: float, alpha: float, shape: float) -> list[list[float]]:
    """Start points of a line + side-band fit (main: peak, FWHM, α, shape, amplitude; side: offset, FWHM,
    amplitude, α): a broad side band half a width out on the long side under a symmetric line, and a side band
    one width out on either side of a line with the measured asymmetry. The fit has local minima; the
    batch solves all starts at once and keeps the lowest cost."""
    side = min(fwhm, 0.9 * SIDE_OFFSET_MAX_NM)
    return [[peak, fwhm, 0.0, shape, 0.8 * amp, 0.7 * side, 2.0 * fwhm, 0.3 * amp, 0.0],
            [peak, fwhm, alpha, shape, 0.9 * amp, side, side, 0.2 * amp, 0.0],
            [peak, fwhm, alpha, shape, 0.9 * amp, -side, side, 0.2 * amp, 0.0]]


def _fit_multistart(wl2, y_n, m, model, parameters, common):
    """Shoulder models: every spectrum from each of :func:`_shoulder_starts`; see :func:`_solve_multistart`."""
    shape = 0.5 if model.startswith("pseudo-voigt") else 2.0
    starts = np.array([_shoulder_starts(*_peak_and_fwhm(wl2[b], y_n[b], m[b], with_alpha=True)[:4], shape)
                       for b in range(y_n.shape[0])]).transpose(1, 0, 2)
    return _solve_multistart(_FUNCTIONS[model], wl2, y_n, m, starts, parameters, common, model)


def _solve_multistart(function, x, y_n, m, starts: np.ndarray, parameters, common, model_name):
    """Solve every spectrum from each of ``starts`` (shape (k, batch, p)) and keep the lowest cost.

    Two rounds on the same compiled kernel (the batch keeps its k × batch shape): every start runs for at most
    :data:`MULTISTART_ROUND1_MAXITER` iterations; the best start of each spectrum then continues from where it
    stopped with the full iteration limit (the batch padded with copies of one healthy spectrum, whose results
    are discarded). The first round is short because the host loop lasts as long as its slowest fit. Returns
    (result, errors)."""
    k_starts, n_batch = starts.shape[:2]

    def tile(a):
        return np.concatenate([a] * k_starts, axis=0)

    sub = {**common, "labels": list(common["labels"]) * k_starts,
           "sigma": None if common["sigma"] is None else tile(common["sigma"])}
    x_t = {k: tile(v) for k, v in x.items()} if isinstance(x, dict) else tile(x)
    options = sub.pop("options")
    short = replace(options, maxiter=min(options.maxiter, MULTISTART_ROUND1_MAXITER))
    first, errors = _solve(function, x_t, tile(y_n), tile(m), starts.reshape(k_starts * n_batch, -1), parameters,
                           model_name=model_name, options=short, **sub)
    if first is None:
        return None, {b: errors.get(b, "fit failed") for b in range(n_batch)}
    cost = first.cost.values.reshape(k_starts, n_batch)
    failed = np.array([[k * n_batch + b in errors for b in range(n_batch)] for k in range(k_starts)])
    cost = np.where(failed | ~np.isfinite(cost), np.inf, cost)
    pick = np.argmin(cost, axis=0)
    names = [str(n) for n in first.parameter.values]
    best = np.stack([first[n].values for n in names], axis=1)[pick * n_batch + np.arange(n_batch)]
    dead = np.all(failed, axis=0)
    best[dead] = starts[0][dead]  # all starts failed: rerun the first (its error is reported anyway)
    # The padding rows (kept so that the kernel is reused) repeat the healthiest spectrum, not each spectrum:
    # a degenerate spectrum then fails once in this round, not k times.
    healthy = np.flatnonzero(~dead)
    donor = int(healthy[np.argmin(np.min(cost, axis=0)[healthy])]) if healthy.size else 0

    def continue_from(src: np.ndarray, start: np.ndarray):
        """The rows ``src`` of the batch from ``start[src]`` with the full iteration limit."""
        x_s = {k: v[src] for k, v in x.items()} if isinstance(x, dict) else x[src]
        sub_s = {**sub, "labels": [common["labels"][i] for i in src],
                 "sigma": None if common["sigma"] is None else common["sigma"][src]}
        return _solve(function, x_s, y_n[src], m[src], start[src], parameters, model_name=model_name,
                      options=options, **sub_s)

    result, errors2 = continue_from(np.concatenate([np.arange(n_batch), np.full((k_starts - 1) * n_batch, donor)]),
                                    best)
    if result is None:
        return None, {b: errors2.get(b, errors.get(b, "fit failed")) for b in range(n_batch)}
    chosen = result.isel(spectrum=np.arange(n_batch))
    # A spectrum whose best start ends degenerate (a side band gone to zero height: its position and width no
    # longer matter) continues from its next-best start instead, in a batch of the same shape (same kernel).
    order = np.argsort(cost, axis=0)
    rank = np.zeros(n_batch, dtype=int)
    round1 = np.stack([first[n].values for n in names], axis=1)
    for _ in range(k_starts - 1):
        retry = [b for b in range(n_batch) if b in errors2 and not dead[b] and rank[b] + 1 < k_starts
                 and math.isfinite(cost[order[rank[b] + 1, b], b])]
        if not retry:
            break
        for b in retry:
            rank[b] += 1
            pick[b] = order[rank[b], b]
        src = np.array([b if b in retry else donor for b in range(n_batch)] + [donor] * ((k_starts - 1) * n_batch))
        again, errors3 = continue_from(src, round1[pick * n_batch + np.arange(n_batch)])
        if again is None:
            break
        fixed = [b for b in retry if b not in errors3]
        chosen = xr.concat([again.isel(spectrum=b) if b in fixed else chosen.isel(spectrum=b) for b in range(n_batch)],
                           dim="spectrum", data_vars="all", coords="minimal", compat="override")
        for b in retry:
            if b in fixed:
                errors2.pop(b)
            else:
                errors2[b] = errors3[b]
    chosen["iterations"] = chosen["iterations"] + first.iterations.values[pick * n_batch + np.arange(n_batch)]
    chosen.attrs["starts"] = (f"{k_starts} start points per spectrum, {short.maxiter} iterations each; the lowest "
                              "cost continued to convergence (the next lowest if that ended degenerate)")
    out_errors = {b: errors[b] for b in range(n_batch) if dead[b]}
    out_errors.update({b: errors2[b] for b in range(n_batch) if b in errors2 and b not in out_errors})
    return chosen, out_errors


def _expand(result, alive: np.ndarray, n_batch: int):
    """Put the rows of a fit of ``alive`` spectra back on the full batch (NaN rows for the others)."""
    if result is None or alive.size == n_batch:
        return result
    template = result.isel(spectrum=0)
    rows = []
    k = 0
    for b in range(n_batch):
        if k < alive.size and alive[k] == b:
            rows.append(result.isel(spectrum=k))
            k += 1
        else:
            rows.append(xr.full_like(template, np.nan, dtype=float).assign(
                converged=template.converged & False, at_bound=template.at_bound & False))
    return xr.concat(rows, dim="spectrum", data_vars="all", coords="minimal", compat="override")


def _fit_two_band(wl2, y_n, m, model, *, split_nm, common):
    """Two-band fit with a per-spectrum split: pump maximum and valley from :func:`find_two_band_split` (or the
    valley fixed at ``split_nm``), components held on their side of their own spectrum's valley."""
    n_batch = y_n.shape[0]
    labels = common["labels"]
    errors: dict[int, str] = {}
    splits: dict[int, TwoBandSplit] = {}
    for b in range(n_batch):
        try:
            if split_nm is None:
                splits[b] = find_two_band_split(wl2[b], y_n[b], m[b], label=labels[b])
            else:
                region = m[b] & (wl2[b] < split_nm)
                if np.count_nonzero(region) < 3 or np.count_nonzero(m[b] & (wl2[b] >= split_nm)) < 3:
                    raise FitError(f"{labels[b] + ': ' if labels[b] else ''}fewer than 3 samples on one side "
                                   f"of the split at {split_nm:g} nm")
                pk, _, pv = _peak_and_fwhm(wl2[b], y_n[b], region)
                yk, _, yv = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] >= split_nm))
                i_split = int(np.argmin(np.abs(wl2[b] - split_nm)))
                splits[b] = TwoBandSplit(pk, pv, float(split_nm), float(y_n[b, i_split]), yk, yv)
        except FitError as exc:
            if not common["collect"]:
                raise
            errors[b] = str(exc)
    alive = np.array(sorted(splits), dtype=int)
    if alive.size == 0:
        return None, errors, splits
    rows = []
    for b in alive:
        s = splits[int(b)]
        bp, bw, ba = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] < s.valley_nm))
        yp, yw, ya = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] >= s.valley_nm))
        bw = min(bw, 0.75 * PUMP_MAX_FWHM_NM)
        # Phosphor asymmetry free from α = 0 in one pass: an α = 0 pass first lets the symmetric phosphor tail
        # swallow a small pump (warm whites), after which the pump has no influence left.
        rows.append(([bp - s.pump_peak_nm, bw, ba], [max(yp - s.valley_nm, 1.0), yw, 0.0, ya]))
    x = {"wl": wl2[alive],
         "pump": np.broadcast_to(np.array([splits[int(b)].pump_peak_nm for b in alive])[:, None],
                                 (alive.size, wl2.shape[1])),
         "valley": np.broadcast_to(np.array([splits[int(b)].valley_nm for b in alive])[:, None],
                                   (alive.size, wl2.shape[1]))}
    sub = {**common, "labels": [labels[b] for b in alive],
           "sigma": None if common["sigma"] is None else common["sigma"][alive]}
    function = _RELATIVE[model][0]
    if model == "two-band":
        p0 = np.array([pump + phosphor for pump, phosphor in rows])
        result, more = _solve(function, x, y_n[alive], m[alive], p0, _relative_parameters(model), model_name=model,
                              **sub)
    else:
        # Pump line + side band (offset, FWHM, height fraction) from three starts; the lowest cost is kept.
        pump_starts = ((5.0, 15.0, 0.3), (10.0, 25.0, 0.3), (15.0, 30.0, 0.2))
        if model == "two-band-wide":
            extra = [_phosphor_pair_starts(wl2[b], y_n[b], m[b], splits[int(b)]) for b in alive]
            starts = np.array([[pump[:2] + [(1.0 - f) * pump[2], off, wid, f * pump[2]] + ph
                                for (pump, _), ex in zip(rows, extra) for ph in [ex[k]]]
                               for k, (off, wid, f) in enumerate(pump_starts)])
        else:
            starts = np.array([[pump[:2] + [(1.0 - f) * pump[2], off, wid, f * pump[2]] + phosphor
                                for pump, phosphor in rows]
                               for off, wid, f in pump_starts])
        result, more = _solve_multistart(function, x, y_n[alive], m[alive], starts, _relative_parameters(model),
                                         sub, model)
    errors.update({int(alive[k]): v for k, v in more.items()})
    if result is None:
        return None, errors, splits
    # Back to absolute peaks: blue_peak_nm = pump maximum + offset, yellow_peak_nm = valley + offset.
    pump_ref = np.array([splits[int(b)].pump_peak_nm for b in alive])
    valley = np.array([splits[int(b)].valley_nm for b in alive])
    for name, ref in (("blue_peak_nm", pump_ref), ("yellow_peak_nm", valley)):
        attrs = dict(result[name].attrs)
        result[name] = result[name] + ref
        attrs.update(lower=float(attrs["lower"]), upper=float(attrs["upper"]),
                     note="bounds relative to the spectrum's " + ("pump maximum" if name.startswith("blue")
                                                                  else "valley"))
        result[name].attrs = attrs
    result["split_nm"] = (("spectrum",), valley, {"units": "nm", "long_name": "valley between pump and phosphor"})
    return _expand(result, alive, n_batch), errors, splits


def _phosphor_pair_starts(wl: np.ndarray, y: np.ndarray, mask: np.ndarray, split: TwoBandSplit) -> list[list[float]]:
    """Three start points of the ``two-band-wide`` phosphor (split Gaussian: peak − valley, FWHM, α, amplitude;
    Gaussian: offset, FWHM, amplitude) from the measured phosphor band beyond the valley.

    (1) The split Gaussian on the band's maximum with its measured half widths, the Gaussian on the centroid and
    spread of what that leaves (a second phosphor: green plateau + red band); (2) the two at the band's centroid
    ∓ a quarter of its spread; (3) as (1) with the roles swapped."""
    region = mask & (wl > split.valley_nm)
    w, v = wl[region], np.clip(y[region], 0.0, None)
    peak, fwhm, amp, alpha = _peak_and_fwhm(wl, y, region, with_alpha=True)
    # eq. (3) in NumPy: a JAX call here would compile its operations once per spectrum length
    first = amp * split_gaussian(w, peak, fwhm, alpha)
    rest = np.clip(v - first, 0.0, None)

    def centre_spread(weights):
        area = np.trapezoid(weights, w)
        if not area > 0:
            return peak, fwhm
        c = np.trapezoid(w * weights, w) / area
        sd = math.sqrt(max(np.trapezoid((w - c) ** 2 * weights, w) / area, 1.0))
        return float(c), float(np.clip(FWHM_PER_SIGMA * sd, *PHOSPHOR2_FWHM_NM))

    c_rest, f_rest = centre_spread(rest)
    c_all, f_all = centre_spread(v)
    lo_fwhm = PHOSPHOR2_FWHM_NM[0]
    v_at = lambda x: float(np.interp(x, w, v))  # noqa: E731
    q = 0.25 * f_all
    return [
        [peak - split.valley_nm, fwhm, alpha, 0.9 * amp, c_rest - peak, f_rest, max(float(rest.max()), 0.05 * amp)],
        [c_all - q - split.valley_nm, max(f_all / 2, lo_fwhm), 0.0, 0.6 * v_at(c_all - q), 2 * q,
         max(f_all / 2, lo_fwhm), 0.6 * v_at(c_all + q)],
        [c_rest - split.valley_nm, f_rest, 0.0, max(float(rest.max()), 0.05 * amp), peak - c_rest,
         max(fwhm, lo_fwhm), 0.9 * amp],
    ]


def fit_spectra(
    wavelength: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float | None = None,
) -> xr.Dataset:
    """Fit a spectrum model to a batch of spectra (one compiled kernel per model and pass).

    Parameters
    ----------
    wavelength
        Grid [nm], shape (n,) shared by the batch or (batch, n) one per spectrum (pad shorter spectra with
        increasing wavelengths and mask the padding), strictly increasing (any spacing).
    values
        Spectra, shape (batch, n), any unit (relative or W/nm).
    model
        'gaussian' (eq. 2 of the cylindrical-module paper: peak_nm, fwhm_nm, amplitude),
        'split-gaussian' (eq. 3: peak_nm, fwhm_nm, alpha, amplitude), 'ohno2005' (peak_nm, fwhm_nm, amplitude),
        'split-pseudo-voigt' (peak_nm, fwhm_nm, alpha, eta, amplitude), 'split-pearson7' (peak_nm, fwhm_nm,
        alpha, shape_m, amplitude) — see :mod:`bsdfkit.models.led`; 'pseudo-voigt-shoulder' /
        'pearson7-shoulder' (that line plus a split-Gaussian side band: side_offset_nm from the peak,
        side_fwhm_nm, side_amplitude, side_alpha; fitted from three starts); 'two-band' (pump eq. 2 + phosphor
        eq. 3 jointly: blue_peak_nm, blue_fwhm_nm, blue_amplitude, yellow_peak_nm, yellow_fwhm_nm, yellow_alpha,
        yellow_amplitude) or 'two-band-led' (pump = Gaussian line + Gaussian side band: adds
        blue_side_offset_nm, blue_side_fwhm_nm, blue_side_amplitude after blue_amplitude) or 'two-band-wide'
        (that pump; phosphor split Gaussian + Gaussian: adds phosphor2_offset_nm from yellow_peak_nm,
        phosphor2_fwhm_nm, phosphor2_amplitude after yellow_amplitude). Every ``fwhm_nm`` is
        the true FWHM of that shape [nm] (of the main line for the models with a side band).
    sigma
        Standard uncertainties of ``values`` (same units), broadcast to ``values``; None = unweighted.
    mask
        Boolean, True = use the sample (e.g. restrict to a band); broadcast to ``values``.
    options
        :class:`bsdfkit.fit.least_squares.FitOptions` (default: absolute residuals, linear loss).
    split_nm
        Two-band only. None (default): each spectrum's split is its valley between pump and phosphor
        (:func:`find_two_band_split`, which refuses spectra without a pump or a phosphor band). A number [nm]:
        that split for every spectrum (the pump maximum is then the largest value below it).

    Returns
    -------
    xarray.Dataset over ``spectrum`` (see :func:`bsdfkit.fit.least_squares.least_squares`); amplitudes are in the
    units of ``values``. Two-band results also hold ``split_nm`` (the valley used).

    Raises
    ------
    FitError
        A degenerate fit of any member, or (two-band) a spectrum without pump or phosphor band.
    ValidationError
        Wavelengths not in nm (:func:`bsdfkit.reduction.colorimetry.check_wavelengths_nm`).
    """
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    options = options or FitOptions()
    y = np.asarray(values, dtype=float)
    if y.ndim != 2:
        raise InputError("spectra must have shape (batch, n)", field="values", expected="(batch, n)", got=y.shape)
    wl2 = _validated_grids(wavelength, y.shape[0])
    if y.shape[1] != wl2.shape[1]:
        raise InputError("spectra must have shape (batch, n) matching the wavelength grid", field="values",
                         expected=f"(batch, {wl2.shape[1]})", got=y.shape)
    m = np.ones(y.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y.shape)
    finite_used = np.where(m, y, 0.0)
    if not np.all(np.isfinite(finite_used)):
        i, j = np.argwhere(~np.isfinite(finite_used))[0]
        raise InputError("spectral value is not finite", field=f"values[{i}, {j}] at {wl2[i, j]:g} nm",
                         got=float(y[i, j]))
    labels = [f"spectrum {b}" for b in range(y.shape[0])] if y.shape[0] > 1 else [""]
    result, _, _ = _fit_batch(wl2, y, m, model, sigma=sigma, options=options, split_nm=split_nm, labels=labels,
                              collect=False)
    return result


def fit_spectrum(
    wavelength: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float | None = None,
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
# Batch analysis: measured metrics beside fitted ones, model selection, warnings
# ------------------------------------------------------------------------------------------------
def information_criteria(cost: float, n_points: int, n_parameters: int) -> dict[str, float]:
    """AICc and BIC of a least-squares fit with Gaussian errors of unknown variance.

    With RSS = 2·cost and k = n_parameters + 1 (the variance): AIC = n·ln(RSS/n) + 2k,
    AICc = AIC + 2k(k + 1)/(n − k − 1), BIC = n·ln(RSS/n) + k·ln n. Only differences between models fitted to
    the same data matter.
    """
    n, k = int(n_points), int(n_parameters) + 1
    rss = 2.0 * float(cost)
    if not (rss > 0 and n > k + 1):
        return {"aicc": math.nan, "bic": math.nan}
    base = n * math.log(rss / n)
    return {"aicc": base + 2 * k + 2 * k * (k + 1) / (n - k - 1), "bic": base + k * math.log(n)}


def _pad_spectra(spectra: Sequence[tuple[np.ndarray, np.ndarray]], ranges) -> tuple[np.ndarray, ...]:
    """(batch, n) grids, values and masks from spectra of different lengths: padded past their last
    wavelength (+1 nm steps) with masked zeros."""
    n = max(np.asarray(w).size for w, _ in spectra)
    wl2 = np.empty((len(spectra), n))
    y2 = np.zeros((len(spectra), n))
    m2 = np.zeros((len(spectra), n), bool)
    for b, (w, v) in enumerate(spectra):
        w = _validated_grid(w)
        v = np.asarray(v, dtype=float)
        if v.shape != w.shape:
            raise InputError("values do not match the wavelength grid", field=f"values[{b}]",
                             expected=str(w.shape), got=v.shape)
        k = w.size
        wl2[b, :k], y2[b, :k] = w, v
        wl2[b, k:] = w[-1] + np.arange(1, n - k + 1)
        lo, hi = ranges[b] if ranges[b] is not None else (-math.inf, math.inf)
        m2[b, :k] = (w >= lo) & (w <= hi)
        if np.count_nonzero(m2[b]) < 3:
            raise InputError("fewer than 3 samples in the fit range", field=f"range of spectrum {b}",
                             expected="≥ 3 samples", got=(lo, hi))
    return wl2, y2, m2


#: Points of the fine grid on which fitted curves are measured (peak, FWHM): ~0.05 nm over 400 nm.
FINE_POINTS = 8192


@partial(jax.jit, static_argnames=("function",), compiler_options=lm.SMALL_KERNEL_OPTIONS)
def _evaluate(theta, x, function):
    """function(θ_b, x_b) for every spectrum b of a batch (one compilation per model and shape)."""
    return jax.vmap(function)(theta, x)


_PUMPS = {"two-band": pump_two_band, "two-band-led": pump_two_band_led, "two-band-wide": pump_two_band_led}


def _curves(model: str, ds: xr.Dataset, wl2: np.ndarray, m2: np.ndarray) -> dict[str, np.ndarray]:
    """Fitted curves of every spectrum of a batch on its fine grid (``fine``, :data:`FINE_POINTS` over its fit
    range) and on its samples (``data``); for two-band models also the pump and phosphor components."""
    names = [str(n) for n in ds.parameter.values]
    theta = np.stack([ds[n].values for n in names], axis=1)
    theta = np.where(np.isfinite(theta), theta, 1.0)  # failed fits: any finite row (their curves are unused)
    lo = np.array([row[mask].min() for row, mask in zip(wl2, m2)])
    hi = np.array([row[mask].max() for row, mask in zip(wl2, m2)])
    fine = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, FINE_POINTS)[None, :]
    x = np.concatenate([fine, wl2], axis=1)
    with x64():
        values = np.asarray(_evaluate(jnp.asarray(theta), jnp.asarray(x), function=_FUNCTIONS[model]))
        out = {"fine_wl": fine, "fine": values[:, :FINE_POINTS], "data": values[:, FINE_POINTS:]}
        if model in _PUMPS:
            pump = np.asarray(_evaluate(jnp.asarray(theta), jnp.asarray(x), function=_PUMPS[model]))
            out["pump_fine"], out["pump_data"] = pump[:, :FINE_POINTS], pump[:, FINE_POINTS:]
    return out


_METRIC_KEYS = ("peak_nm", "fwhm_nm", "centroid_nm", "dominant_wavelength_nm", "purity")


def _finite_or_none(v) -> float | None:
    return float(v) if v is not None and math.isfinite(float(v)) else None


def _row_record(ds: xr.Dataset, b: int, model: str, curves: dict[str, np.ndarray], wl: np.ndarray,
                mask: np.ndarray, measured: dict[str, Any], colorimetry: bool) -> dict[str, Any]:
    """Record of spectrum ``b`` of a batch result (see :func:`analyse_spectra`). The fitted curve is measured
    like the data: peak and FWHM on the fine grid, centroid and colour on the data's own samples."""
    row = ds.isel(spectrum=b)
    names = [str(n) for n in ds.parameter.values]
    params = {n: float(row[n]) for n in names}
    fine_wl, fine = curves["fine_wl"][b], curves["fine"][b]
    dense = spectrum_metrics(fine_wl, fine, colorimetry=False)
    fitted: dict[str, Any] = {"peak_nm": dense.peak_nm, "fwhm_nm": dense.fwhm_nm}
    if colorimetry:
        on_grid = spectrum_metrics(wl[mask], curves["data"][b][mask])
        fitted.update(centroid_nm=on_grid.centroid_nm, dominant_wavelength_nm=on_grid.dominant_wavelength_nm,
                      purity=on_grid.purity)
    fitted = {k: _finite_or_none(v) for k, v in fitted.items()}
    diff = {k: (None if measured.get(k) is None or fitted.get(k) is None else fitted[k] - measured[k])
            for k in _METRIC_KEYS if k in fitted}
    at_bound = [n for n, hit in zip(names, row.at_bound.values) if bool(hit)]
    record = {
        "model": model, "params": params, "std": {n: float(row[f"{n}_std"]) for n in names},
        "r2": float(row.r2), "rms": float(row.rms), "converged": bool(row.converged),
        "iterations": int(row.iterations), "n_points": int(row.n_points), "at_bound": at_bound,
        "criteria": information_criteria(float(row.cost), int(row.n_points), len(names)),
        "fitted": fitted, "difference": diff,
    }
    if model in TWO_BAND_MODELS:
        components = {}
        for part in ("pump", "phosphor"):
            if part == "pump":
                on_fine, on_data = curves["pump_fine"][b], curves["pump_data"][b]
            else:
                on_fine, on_data = fine - curves["pump_fine"][b], curves["data"][b] - curves["pump_data"][b]
            m = spectrum_metrics(fine_wl, on_fine, colorimetry=False) if np.max(on_fine) > 0 else None
            components[part] = {"peak_nm": None if m is None else m.peak_nm,
                                "fwhm_nm": None if m is None else _finite_or_none(m.fwhm_nm),
                                "power": float(np.trapezoid(on_data[mask], wl[mask]))}
        total = sum(c["power"] for c in components.values())
        for c in components.values():
            c["power_fraction"] = c["power"] / total if total > 0 else None
        record["components"] = components
        record["split_nm"] = float(row.split_nm)
    return record


def _warnings(record: dict[str, Any], measured: dict[str, Any]) -> list[str]:
    out = []
    if not record["converged"]:
        out.append(f"did not converge ({record['iterations']} iterations, the limit); parameters are the last "
                   "iterate")
    if record["r2"] < 0:
        out.append(f"R² = {record['r2']:.3f} < 0: the model describes this spectrum worse than its mean")
    elif record["r2"] < WARN_R2:
        out.append(f"R² = {record['r2']:.3f} < {WARN_R2:g}: the model describes this spectrum poorly")
    for name in record["at_bound"]:
        out.append(f"{name} ended on its bound ({record['params'][name]:.6g}); the model may not describe "
                   "this spectrum")
    split = record.get("measured_split")
    if split and record.get("components", {}).get("pump", {}).get("peak_nm") is not None:
        d_pump = record["components"]["pump"]["peak_nm"] - split["pump_peak_nm"]
        if abs(d_pump) > WARN_PEAK_NM:
            out.append(f"fitted pump peak {record['components']['pump']['peak_nm']:.2f} nm is {d_pump:+.2f} nm from "
                       f"the measured pump maximum {split['pump_peak_nm']:.2f} nm (the pump shape does not match"
                       + ("; try two-band-led or two-band-wide)" if record["model"] == "two-band" else ")"))
    if record["model"] in SINGLE_BAND_MODELS:
        d_peak, d_fwhm = record["difference"]["peak_nm"], record["difference"]["fwhm_nm"]
        if d_peak is not None and abs(d_peak) > WARN_PEAK_NM:
            out.append(f"fitted peak {record['fitted']['peak_nm']:.2f} nm is {d_peak:+.2f} nm from the measured "
                       f"{measured['peak_nm']:.2f} nm")
        if d_fwhm is not None and measured.get("fwhm_nm") and abs(d_fwhm) > WARN_FWHM_RELATIVE * measured["fwhm_nm"]:
            out.append(f"fitted FWHM {record['fitted']['fwhm_nm']:.2f} nm differs from the measured "
                       f"{measured['fwhm_nm']:.2f} nm by {d_fwhm / measured['fwhm_nm']:+.0%}")
    return out


def analyse_spectra(
    spectra: Sequence[tuple[np.ndarray, np.ndarray]],
    model: str = "best",
    *,
    ranges: Sequence[tuple[float, float] | None] | None = None,
    labels: Sequence[str] | None = None,
    criterion: str = "aicc",
    candidates: Sequence[str] = SINGLE_BAND_MODELS,
    options: FitOptions | None = None,
    split_nm: float | None = None,
) -> list[dict[str, Any]]:
    """Fit many spectra in one batch per model and report measured and fitted metrics side by side.

    Parameters
    ----------
    spectra
        (wavelength [nm], values) pairs; grids may differ (they are padded and masked into one batch, so each
        model is compiled once for all of them).
    model
        One of :data:`SPECTRUM_MODELS`, or 'best': every model of ``candidates`` is fitted and the one with the
        lowest ``criterion`` is reported (all candidates' criteria, R², peak and FWHM are in ``candidates``).
    ranges
        Per spectrum (lo, hi) [nm] inclusive fit range, or None for all samples.
    labels
        Names used in messages (default "spectrum 0", ...).
    criterion
        'aicc' or 'bic' (:func:`information_criteria`).
    candidates
        Models tried by 'best' (single-band models by default).
    options
        :class:`~bsdfkit.fit.least_squares.FitOptions`.
    split_nm
        Two-band: None = split at each spectrum's valley (:func:`find_two_band_split`), or a fixed split [nm].

    Returns
    -------
    One dict per spectrum, in order: ``measured`` (:func:`bsdfkit.reduction.spectrum_metrics.spectrum_metrics`
    of the data in the fit range: peak_nm, fwhm_nm, centroid_nm, dominant_wavelength_nm, purity), ``model``,
    ``params``, ``std``, ``r2``, ``rms``, ``converged``, ``iterations``, ``n_points``, ``at_bound``, ``criteria``
    (aicc, bic), ``fitted`` (the same metrics of the fitted curve), ``difference`` (fitted − measured),
    ``warnings`` (list of one-line strings, empty when nothing is suspicious) and, for two-band models,
    ``components`` (pump and phosphor peak_nm, fwhm_nm, power [input units·nm], power_fraction) and
    ``split_nm``. A spectrum whose fit failed or was refused has ``error`` (one line) instead of the fit keys,
    among them implausible spectra (:func:`bsdfkit.reduction.colorimetry.check_power_spectrum` without the
    colorimetric sample count: wavelengths not in nm, negative power beyond the noise) and fewer samples in the
    fit range than a model's parameters + 2.
    """
    if model != "best" and model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model",
                              expected="best | " + " | ".join(SPECTRUM_MODELS), got=model)
    if criterion not in CRITERIA:
        raise ValidationError("unknown information criterion", field="criterion", expected=" | ".join(CRITERIA),
                              got=criterion)
    for c in candidates:
        if c not in SPECTRUM_MODELS:
            raise ValidationError("unknown candidate model", field="candidates",
                                  expected=" | ".join(SPECTRUM_MODELS), got=c)
    if not spectra:
        raise InputError("no spectra to fit", field="spectra")
    options = options or FitOptions()
    n_batch = len(spectra)
    ranges = list(ranges) if ranges is not None else [None] * n_batch
    labels = list(labels) if labels is not None else [f"spectrum {b}" for b in range(n_batch)]
    wl2, y2, m2 = _pad_spectra(spectra, ranges)

    records: list[dict[str, Any]] = []
    models_to_fit = list(candidates) if model == "best" else [model]
    n_parameters = {name: len(_parameters(name, 380.0, 780.0)) for name in models_to_fit}
    fewest = min(n_parameters.values()) + 2  # AICc needs n > p + 2 (p counting the variance)
    for b in range(n_batch):
        w, v = wl2[b][m2[b]], y2[b][m2[b]]
        rec: dict[str, Any] = {"range_nm": None if ranges[b] is None else [float(r) for r in ranges[b]]}
        try:
            # a spectral power in nm (one line per implausible spectrum: sign errors, noise, µm or m values)
            check_wavelengths_nm(spectra[b][0], "wavelength")
            check_power_spectrum(spectra[b][0], spectra[b][1], "values", colorimetry=False)
            if w.size < fewest:
                raise ValidationError("too few samples in the fit range", field="values",
                                      expected=f"at least {fewest} for a {min(n_parameters, key=n_parameters.get)} "
                                               "fit (its parameters + 2)", got=w.size)
            measured = spectrum_metrics(w, v).as_dict()
            rec["measured"] = {k: _finite_or_none(measured[k]) for k in _METRIC_KEYS}
        except BsdfkitError as exc:
            rec["error"] = f"{labels[b]}: {exc}"
        records.append(rec)
    alive_all = np.array([b for b in range(n_batch) if "error" not in records[b]], dtype=int)
    per_model: dict[str, dict[int, dict[str, Any]]] = {}
    for name in models_to_fit:
        per_model[name] = {}
        too_few = [b for b in alive_all if np.count_nonzero(m2[b]) < n_parameters[name] + 2]
        for b in too_few:
            per_model[name][int(b)] = {"error": f"{labels[b]}: too few samples in the fit range for a {name} fit "
                                                f"(at least {n_parameters[name] + 2}, got {np.count_nonzero(m2[b])})"}
        alive = np.array([b for b in alive_all if b not in too_few], dtype=int)
        if alive.size == 0:
            continue
        ds, errors, splits = _fit_batch(wl2[alive], y2[alive], m2[alive], name, sigma=None, options=options,
                                        split_nm=split_nm, labels=[labels[b] for b in alive], collect=True)
        if ds is None:
            for k, b in enumerate(alive):
                per_model[name][int(b)] = {"error": errors.get(k, f"{labels[b]}: fit failed")}
            continue
        curves = _curves(name, ds, wl2[alive], m2[alive])
        for k, b in enumerate(alive):
            b = int(b)
            if k in errors:
                per_model[name][b] = {"error": errors[k]}
                continue
            per_model[name][b] = _row_record(ds, k, name, curves, wl2[b], m2[b], records[b]["measured"],
                                             colorimetry=len(models_to_fit) == 1)
            per_model[name][b]["_k"] = k
            if k in splits:
                per_model[name][b]["measured_split"] = {
                    "pump_peak_nm": splits[k].pump_peak_nm, "valley_nm": splits[k].valley_nm,
                    "phosphor_peak_nm": splits[k].phosphor_peak_nm}
        per_model[name]["_ds"], per_model[name]["_curves"] = ds, curves

    for b in alive_all:
        b = int(b)
        rec = records[b]
        results = {name: per_model[name][b] for name in models_to_fit}
        if model == "best":
            ok = {n: r for n, r in results.items() if "error" not in r and math.isfinite(r["criteria"][criterion])}
            rec["criterion"] = criterion
            rec["candidates"] = {
                n: ({"error": r["error"]} if "error" in r else
                    {criterion: r["criteria"][criterion], **{c: r["criteria"][c] for c in CRITERIA},
                     "r2": r["r2"], "peak_nm": r["fitted"]["peak_nm"], "fwhm_nm": r["fitted"]["fwhm_nm"],
                     "warnings": len(_warnings(r, rec["measured"]))})
                for n, r in results.items()}
            if not ok:
                rec["error"] = "; ".join(r["error"] for r in results.values() if "error" in r) or \
                    f"{labels[b]}: no candidate model could be fitted"
                continue
            best = min(ok, key=lambda n: ok[n]["criteria"][criterion])
            # Colorimetry of the chosen curve only (the candidates report peak, FWHM and criteria).
            chosen = _row_record(per_model[best]["_ds"], ok[best]["_k"], best, per_model[best]["_curves"], wl2[b],
                                 m2[b], rec["measured"], colorimetry=True)
        else:
            chosen = results[model]
            if "error" in chosen:
                rec["error"] = chosen["error"]
                continue
        rec.update({k: v for k, v in chosen.items() if not k.startswith("_")})
        rec["warnings"] = _warnings(chosen, rec["measured"])
    return records


# ------------------------------------------------------------------------------------------------
# Two-band reconstruction (§4.2 of the cylindrical-module paper)
# ------------------------------------------------------------------------------------------------
def band_integral(wavelength: np.ndarray, values: np.ndarray, band_nm: tuple[float, float]) -> float:
    """Σ values(λi)·Δλi over lo ≤ λi ≤ hi (inclusive), the band sum of §4.2 of the cylindrical-module paper.

    λ in nm; Δλi are the sample spacings (central differences): :func:`bsdfkit.reduction.spectral.band_sum` on a
    validated grid. Result in value-unit·nm (W for W/nm).
    """
    wl = _nm_grid(wavelength)
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
    wl = _nm_grid(wavelength)
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
