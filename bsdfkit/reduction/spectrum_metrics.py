"""Metrics of a measured emission spectrum computed from the data alone (no model): peak, centroid, FWHM,
dominant wavelength and excitation purity.

* **Peak** λp: vertex of the parabola through the maximum sample and its two neighbours (local quadratic, any
  spacing); the sample itself if the maximum is on the edge of the range.
* **FWHM**: distance between the half-maximum crossings nearest the peak on either side, each linearly
  interpolated between the two samples that bracket half of the maximum sample. A side without a crossing
  (a line truncated by the range) gives ``nan`` for the FWHM and that half width.
* **Centroid** λc = ΣλSΔλ / ΣSΔλ over the whole grid, the power-weighted mean wavelength of the photon budget
  (:func:`bsdfkit.core.spectra.mean_wavelength_nm`; the values as given, negative noise included).
* **Dominant wavelength** λd and **excitation purity** pe: ``colour.dominant_wavelength`` and
  ``colour.excitation_purity`` (CIE 1931 2°) of the chromaticity (:func:`bsdfkit.reduction.colorimetry.
  chromaticity_xy`) against a white point, equal-energy illuminant E (x = y = 1/3) by default, on the
  spectral locus of the CMFs interpolated to 0.1 nm (λd resolution 0.1 nm). For purple chromaticities colour
  returns the complementary wavelength as a negative λd.

Wavelengths in nm throughout; values in any radiometric unit (only their shape matters).
"""
from __future__ import annotations

import functools
import math
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from bsdfkit.core.errors import BsdfkitError, InputError, NumericalError
from bsdfkit.core.spectra import mean_wavelength_nm
from bsdfkit.reduction.colorimetry import CMFS_NAME, chromaticity_xy

__all__ = [
    "WHITE_POINT_E",
    "SpectrumMetrics",
    "peak_wavelength",
    "half_maximum_crossings",
    "centroid_wavelength",
    "dominant_wavelength_purity",
    "spectrum_metrics",
]

#: Equal-energy white point (CIE 1931 x, y), the usual reference for the dominant wavelength of LEDs.
WHITE_POINT_E: tuple[float, float] = (1.0 / 3.0, 1.0 / 3.0)


@dataclass(frozen=True)
class SpectrumMetrics:
    """Data-derived metrics of one spectrum (wavelengths in nm, purity dimensionless)."""

    peak_nm: float
    peak_value: float
    centroid_nm: float
    fwhm_nm: float
    half_max_left_nm: float
    half_max_right_nm: float
    dominant_wavelength_nm: float | None
    purity: float | None

    def as_dict(self) -> dict[str, float | None]:
        """The metrics as a dict, field name → value (wavelengths [nm], ``peak_value`` in the spectrum's unit,
        ``purity`` [-]).

        Returns
        -------
        dict of str to float or None
            One entry per field.
        """
        return asdict(self)


def _grid(wavelength, values) -> tuple[np.ndarray, np.ndarray]:
    wl = np.asarray(wavelength, dtype=float)
    y = np.asarray(values, dtype=float)
    if wl.ndim != 1 or wl.shape != y.shape or wl.size < 3:
        raise InputError("spectrum must be two 1-D arrays of equal length ≥ 3", field="values",
                         expected=f"shape {wl.shape}", got=y.shape)
    if not (np.all(np.isfinite(wl)) and np.all(np.isfinite(y))):
        raise InputError("spectrum is not finite", field="values")
    if not np.all(np.diff(wl) > 0):
        raise InputError("wavelengths must increase strictly", field="wavelength")
    if not np.max(y) > 0:
        raise NumericalError("spectrum has no positive value; its metrics are undefined")
    return wl, y


def peak_wavelength(wavelength_nm, values) -> tuple[float, float]:
    """(λp [nm], S(λp)) from the local quadratic: the vertex of the parabola through the maximum sample and its
    two neighbours (any spacing); the maximum sample itself on the range's edge or for a flat top.

    For a smooth top the error is far below the spacing; on an asymmetric cusp (a split Gaussian) the vertex
    leans towards the broader side by up to ~|α| × the local spacing.

    Parameters
    ----------
    wavelength_nm : array_like
        Sample wavelengths [nm], 1-D, strictly increasing, at least 3.
    values : array_like
        Spectral values at ``wavelength``, any radiometric unit, some positive.

    Returns
    -------
    peak : float
        Peak wavelength λp [nm].
    value : float
        The parabola's value at λp, in the unit of ``values``.

    Raises
    ------
    InputError
        If the arrays are not 1-D of equal length ≥ 3, not finite, or the wavelengths do not increase.
    NumericalError
        If no value is positive.
    """
    wl, y = _grid(wavelength_nm, values)
    i = int(np.argmax(y))
    if i == 0 or i == wl.size - 1:
        return float(wl[i]), float(y[i])
    x0, x2 = wl[i - 1] - wl[i], wl[i + 1] - wl[i]
    y0, y1, y2 = y[i - 1], y[i], y[i + 1]
    # Parabola y1 + b·x + a·x² through (x0, y0), (0, y1), (x2, y2); vertex at −b/(2a).
    d0, d2 = (y0 - y1) / x0, (y2 - y1) / x2
    a = (d2 - d0) / (x2 - x0)
    if not a < 0:
        return float(wl[i]), float(y1)
    b = d0 - a * x0
    shift = float(np.clip(-b / (2.0 * a), x0, x2))
    return float(wl[i] + shift), float(y1 + b * shift + a * shift**2)


def half_maximum_crossings(wavelength_nm, values, level: float | None = None) -> tuple[float, float]:
    """(left, right) wavelengths [nm] where the spectrum crosses ``level`` (default: half the maximum
    sample) nearest the maximum, linearly interpolated; ``nan`` for a side without a crossing.

    Parameters
    ----------
    wavelength_nm : array_like
        Sample wavelengths [nm], 1-D, strictly increasing, at least 3.
    values : array_like
        Spectral values at ``wavelength``, any radiometric unit, some positive.
    level : float, optional
        Crossing level in the unit of ``values``; None for half the maximum sample.

    Returns
    -------
    left, right : float
        Crossing wavelengths [nm] below and above the maximum; nan where there is none.

    Raises
    ------
    InputError
        If the arrays are not 1-D of equal length ≥ 3, not finite, or the wavelengths do not increase.
    NumericalError
        If no value is positive.
    """
    wl, y = _grid(wavelength_nm, values)
    i = int(np.argmax(y))
    half = 0.5 * y[i] if level is None else float(level)
    left = right = math.nan
    below = np.flatnonzero(y[:i] <= half)
    if below.size:
        j = below[-1]
        left = float(np.interp(half, [y[j], y[j + 1]], [wl[j], wl[j + 1]])) if y[j + 1] != y[j] else float(wl[j])
    below = np.flatnonzero(y[i:] <= half)
    if below.size:
        j = i + below[0]
        right = float(np.interp(half, [y[j], y[j - 1]], [wl[j], wl[j - 1]])) if y[j - 1] != y[j] else float(wl[j])
    return left, right


def centroid_wavelength(wavelength_nm, values) -> float:
    """λc = ΣλSΔλ / ΣSΔλ [nm] over the whole grid: :func:`bsdfkit.core.spectra.mean_wavelength_nm`.

    Parameters
    ----------
    wavelength_nm : array_like
        Sample wavelengths [nm], 1-D, strictly increasing, at least 3.
    values : array_like
        Spectral values at ``wavelength``, any radiometric unit, some positive.

    Returns
    -------
    float
        Centroid wavelength λc [nm].

    Raises
    ------
    InputError
        If the arrays are not 1-D of equal length ≥ 3, not finite, or the wavelengths do not increase.
    NumericalError
        If no value is positive.
    """
    return mean_wavelength_nm(*_grid(wavelength_nm, values))


@functools.lru_cache(maxsize=1)
def _locus_cmfs():
    """CIE 1931 2° CMFs interpolated by colour onto 360-780 nm at 0.1 nm: colour places λd on the nearest
    CMF sample of the spectral locus, so this sets λd's resolution to 0.1 nm (1 nm with the tabulated CMFs)."""
    import colour

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    fine = np.arange(3600, 7801) / 10.0  # exact tenths of a nanometre
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        values = np.asarray(cmfs.copy().interpolate(colour.SpectralShape(360.0, 780.0, 1.0))[fine])
    return colour.MultiSpectralDistributions(values, fine, labels=cmfs.labels, name=f"{cmfs.name}, 0.1 nm")


def dominant_wavelength_purity(wavelength_nm, values,
                               white_point: tuple[float, float] = WHITE_POINT_E) -> tuple[float, float]:
    """(λd [nm], excitation purity [1]) of the spectrum's CIE 1931 chromaticity against ``white_point``.

    Returns (nan, nan) when colour-science cannot place the chromaticity (e.g. the white point itself).

    Parameters
    ----------
    wavelength_nm : array_like
        Sample wavelengths [nm], 1-D, strictly increasing, at least 3.
    values : array_like
        Spectral values at ``wavelength``, any radiometric unit, some positive.
    white_point : tuple of float, optional
        CIE 1931 (x, y) of the reference white [-].

    Returns
    -------
    dominant : float
        Dominant wavelength λd [nm], negative (complementary) for purple chromaticities.
    purity : float
        Excitation purity [-].
    """
    import colour

    wl, y = _grid(wavelength_nm, values)
    xy = np.array(chromaticity_xy(colour.SpectralDistribution(y, wl, name="spectrum")))
    cmfs = _locus_cmfs()
    xy_n = np.asarray(white_point, dtype=float)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        # colour notes that the 0.1 nm CMFs are "not uniform" (float steps) and re-aligns its D65: harmless here
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        wl_d = float(np.asarray(colour.dominant_wavelength(xy, xy_n, cmfs)[0]))
        purity = float(np.asarray(colour.excitation_purity(xy, xy_n, cmfs)))
    return (wl_d if math.isfinite(wl_d) else math.nan), (purity if math.isfinite(purity) else math.nan)


def spectrum_metrics(wavelength_nm, values, *, colorimetry: bool = True,
                     white_point: tuple[float, float] = WHITE_POINT_E) -> SpectrumMetrics:
    """All metrics of the module docstring for one spectrum (λ [nm], values in any unit).

    Parameters
    ----------
    wavelength_nm
        Sample wavelengths [nm], strictly increasing.
    values
        Spectral values at those wavelengths [any unit].
    colorimetry
        Also compute the dominant wavelength and purity (CIE 1931 2°; NaN when colour cannot be computed for this
        spectrum, e.g. no light in 360-830 nm); else None.
    white_point
        CIE 1931 (x, y) of the reference white for λd and purity (default illuminant E).

    Returns
    -------
    SpectrumMetrics
        Peak, centroid, half-maximum crossings and FWHM [nm], peak value, and (with ``colorimetry``) λd [nm] and
        purity [-].
    """
    wl, y = _grid(wavelength_nm, values)
    peak, peak_value = peak_wavelength(wl, y)
    left, right = half_maximum_crossings(wl, y)
    dominant = purity = None
    if colorimetry:
        try:
            dominant, purity = dominant_wavelength_purity(wl, y, white_point)
        except BsdfkitError:  # no colour for this spectrum (e.g. outside 360-830 nm): the other metrics stand
            dominant = purity = math.nan
    return SpectrumMetrics(peak_nm=peak, peak_value=peak_value, centroid_nm=centroid_wavelength(wl, y),
                           fwhm_nm=right - left, half_max_left_nm=left, half_max_right_nm=right,
                           dominant_wavelength_nm=dominant, purity=purity)
