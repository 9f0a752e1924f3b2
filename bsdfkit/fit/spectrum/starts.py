"""Start values of the spectrum fits, from the data alone: peak, FWHM and asymmetry of a band, the two-band
split (pump maximum, valley, phosphor maximum) and the multi-start points of the shoulder and ``two-band-wide``
models. Wavelengths in nm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bsdfkit.core.errors import FitError
from bsdfkit.core.spectra import FWHM_PER_SIGMA, split_gaussian
from bsdfkit.fit.least_squares import Parameter
from bsdfkit.fit.spectrum.models import DEFAULT_SPLIT_NM, PHOSPHOR2_FWHM_NM, SIDE_OFFSET_MAX_NM
from bsdfkit.reduction.spectrum_metrics import half_maximum_crossings, peak_wavelength

#: Two-band refusals (:func:`find_two_band_split`): the pump maximum below :data:`DEFAULT_SPLIT_NM` must reach
#: this fraction of the spectrum's maximum, and the phosphor maximum above the valley must reach this fraction
#: of the maximum and exceed the valley by :data:`PHOSPHOR_MIN_RISE` (relative to the valley value).
PUMP_MIN_FRACTION: float = 0.02
PHOSPHOR_MIN_FRACTION: float = 0.05
PHOSPHOR_MIN_RISE: float = 0.10


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


@dataclass(frozen=True)
class TwoBandSplit:
    """Where a pump + phosphor spectrum separates (wavelengths in nm, values in input units)."""

    pump_peak_nm: float
    pump_value: float
    valley_nm: float
    valley_value: float
    phosphor_peak_nm: float
    phosphor_value: float


def _pump_and_valley(wl: np.ndarray, y: np.ndarray, below: np.ndarray, top: float) -> tuple[int, int]:
    """Indices of the pump maximum and of the valley after it in the smoothed spectrum ``y``, or (−1, −1).

    The pump is the largest local maximum among ``below`` (the samples under :data:`DEFAULT_SPLIT_NM`) that
    reaches :data:`PUMP_MIN_FRACTION` of ``top`` and that the spectrum falls from by ≥ 10 % before 560 nm; the
    valley is the first local minimum after it, else the smallest value up to 560 nm."""
    for j in sorted(below[1:], key=lambda j: -y[j]):
        if not (y[j] >= y[j - 1] and y[j] >= y[j + 1]) or y[j] < PUMP_MIN_FRACTION * top:
            continue
        after = np.flatnonzero((wl > wl[j]) & (wl <= 560.0))
        dips = [int(k) for k in after[:-1] if y[k] <= y[k - 1] and y[k] < y[k + 1] and y[k] <= 0.9 * y[j]]
        if dips:  # the pump's decay ends at the first local minimum after it
            return int(j), dips[0]
        if after.size and y[after].min() <= 0.9 * y[j] and y[after[-1]] > y[after].min():
            return int(j), int(after[np.argmin(y[after])])
        if after.size and y[after].min() <= 0.9 * y[j]:  # falls and stays down: no phosphor (checked below)
            return int(j), int(after[-1])
    return -1, -1


def find_two_band_split(wavelength_nm: np.ndarray, values: np.ndarray, region: np.ndarray | None = None, *,
                        label: str = "") -> TwoBandSplit:
    """Pump maximum, valley and phosphor maximum of a phosphor-converted spectrum, or a refusal.

    The pump maximum is the largest local maximum below :data:`DEFAULT_SPLIT_NM` (500 nm) that reaches
    :data:`PUMP_MIN_FRACTION` of the spectrum's maximum and that the spectrum falls from by ≥ 10 % before
    560 nm; the valley is the first local minimum after it (or the smallest value up to 560 nm); the phosphor
    maximum is the largest sample above the valley. Values are smoothed over ±2 samples for the search
    (noise); the reported maxima are those of the data: the largest sample within ±2 samples refined by the
    local quadratic through it and its neighbours (:func:`bsdfkit.reduction.spectrum_metrics.peak_wavelength`).

    Parameters
    ----------
    wavelength_nm : ndarray
        Wavelengths [nm], increasing.
    values : ndarray
        Spectral values at ``wavelength``, any unit.
    region : ndarray of bool, optional
        Samples to search (True = use); None for all.
    label : str, optional
        Prefix of the error messages (the spectrum's name).

    Returns
    -------
    TwoBandSplit
        Pump maximum, valley and phosphor maximum: wavelengths [nm] and values in the unit of ``values``.

    Raises
    ------
    FitError
        No pump (the maximum below 500 nm is under :data:`PUMP_MIN_FRACTION` of the spectrum's maximum, or lies
        on the 500 nm edge, i.e. the spectrum still rises there), or no phosphor band (nothing above the valley
        reaches :data:`PHOSPHOR_MIN_FRACTION` of the maximum and rises :data:`PHOSPHOR_MIN_RISE` above the
        valley): a single-colour LED is not a two-band spectrum.
    """
    wl = np.asarray(wavelength_nm, dtype=float)
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
    i_pump, i_valley = _pump_and_valley(wl, y, below, top)
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


def _shoulder_starts(peak: float, fwhm: float, amp: float, alpha: float, shape: float) -> list[list[float]]:
    """Start points of a line + side-band fit (main: peak, FWHM, α, shape, amplitude; side: offset, FWHM,
    amplitude, α): a broad side band half a width out on the long side under a symmetric line, and a side band
    one width out on either side of a line with the measured asymmetry. The fit has local minima; the
    batch solves all starts at once and keeps the lowest cost."""
    side = min(fwhm, 0.9 * SIDE_OFFSET_MAX_NM)
    return [[peak, fwhm, 0.0, shape, 0.8 * amp, 0.7 * side, 2.0 * fwhm, 0.3 * amp, 0.0],
            [peak, fwhm, alpha, shape, 0.9 * amp, side, side, 0.2 * amp, 0.0],
            [peak, fwhm, alpha, shape, 0.9 * amp, -side, side, 0.2 * amp, 0.0]]


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
