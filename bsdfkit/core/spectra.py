"""Spectral formulas used by more than one layer: Gaussian line shapes, band sums, mean wavelength, photons.

One home for each formula (issue #28): the reductions, the fits' start heuristics, the tracer's spectra and the
scene reader all call these. NumPy, float64. The JAX versions of the line shapes, which need finite gradients
at zero width (:func:`bsdfkit.models.functions.gaussian_spectrum` and
:func:`~bsdfkit.models.functions.split_gaussian_spectrum`), take :data:`C_FWHM` from here.

Wavelengths, peaks and widths in nm; band limits inclusive.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.errors import InputError, NumericalError, ValidationError

__all__ = [
    "PLANCK_H",
    "LIGHT_C",
    "C_FWHM",
    "FWHM_PER_SIGMA",
    "Band",
    "gaussian",
    "split_gaussian",
    "band_mask",
    "band_sum",
    "mean_wavelength_nm",
    "photon_pdf_from_power",
]

PLANCK_H = 6.62607015e-34  # J s (exact, SI 2019)
LIGHT_C = 299_792_458.0  # m/s (exact)

#: C = 4 ln 2 of eqs. (2)–(3) of the cylindrical-module paper: with it Δλ is the true FWHM.
C_FWHM: float = 4.0 * math.log(2.0)
#: FWHM / σ of a Gaussian, √(8 ln 2) = 2.35482…
FWHM_PER_SIGMA: float = math.sqrt(8.0 * math.log(2.0))

#: A wavelength band (low, high) in nm, limits inclusive.
Band = tuple[float, float]


def gaussian(wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike) -> NDArray[np.float64]:
    """Relative Gaussian spectrum with peak 1, S(λ) = exp(−C((λ − λp)/Δλ)²) with C = 4 ln 2 (eq. (2) of the
    cylindrical-module paper; Δλ is the true FWHM) [1].

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths at which to evaluate [nm].
    peak_nm : array_like
        Peak wavelength λp [nm].
    fwhm_nm : array_like
        Full width at half maximum Δλ [nm]; broadcast with ``wavelength`` and ``peak_nm``.

    Returns
    -------
    ndarray
        S(λ), 1 at the peak [-].
    """
    return np.exp(-C_FWHM * ((wavelength_nm - peak_nm) / fwhm_nm) ** 2)


def split_gaussian(wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike, alpha: ArrayLike
                   ) -> NDArray[np.float64]:
    """Asymmetric Gaussian of eq. (3) of the cylindrical-module paper [1]: the width Δλ(1 + sign(λ − λp)·α) on
    each side of the peak (the total FWHM stays Δλ), α in (−1, 1).

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths at which to evaluate [nm].
    peak_nm : array_like
        Peak wavelength λp [nm].
    fwhm_nm : array_like
        Total full width at half maximum Δλ [nm].
    alpha : array_like
        Asymmetry α in (−1, 1) [-]; positive widens the long-wavelength side.

    Returns
    -------
    ndarray
        S(λ), 1 at the peak [-].
    """
    offset = wavelength_nm - peak_nm
    return np.exp(-C_FWHM * (offset / (fwhm_nm * (1.0 + np.sign(offset) * alpha))) ** 2)


def band_mask(wavelength_nm: NDArray[np.float64], band_nm: Band) -> NDArray[np.bool_]:
    """The samples inside the closed ``band`` [nm] (1e-9 nm slack for grids built by float steps).

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths [nm].
    band_nm : tuple of float
        (low, high) limits [nm], inclusive, low ≤ high.

    Returns
    -------
    ndarray of bool
        True where ``wavelength`` lies in the band, shaped like ``wavelength``.

    Raises
    ------
    InputError
        If high < low or a limit is NaN.
    """
    lo, hi = band_nm
    if not hi >= lo:  # [λ, λ] is the band of one wavelength (a monochrome scan); NaN edges are refused
        raise InputError("empty wavelength band", field="band", expected="(low, high) with low <= high", got=band_nm)
    return (wavelength_nm >= lo - 1e-9) & (wavelength_nm <= hi + 1e-9)


def band_sum(wavelength_nm: NDArray[np.float64], values: NDArray[np.float64], band_nm: Band) -> float:
    """Σ_band values(λ)·Δλ with Δλ the central-difference sample spacing (:func:`numpy.gradient`), band closed:
    the sums of eqs. (4)-(16) of the power-budget paper and §4.2 of the cylindrical-module paper.

    Each sample stands for the bin of width Δλ around it (a spectrometer pixel, a tracer bin), so the sums of
    adjacent bands add up; inside the grid the weights equal the trapezoid rule's.

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths [nm], increasing, at least 2 samples.
    values : ndarray
        Spectral density at each sample, same shape as ``wavelength`` (e.g. [W/nm]).
    band_nm : tuple of float
        (low, high) limits [nm], inclusive.

    Returns
    -------
    float
        The band integral, in the unit of ``values`` times nm (e.g. [W]).
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    inside = band_mask(wl, band_nm)
    return float(np.sum(np.asarray(values, dtype=np.float64)[inside] * np.gradient(wl)[inside]))


def mean_wavelength_nm(wavelength_nm: NDArray[np.float64], values: NDArray[np.float64], band_nm: Band | None = None
                       ) -> float:
    """Power-weighted mean (centroid) wavelength λ̄ = Σ S λ Δλ / Σ S Δλ [nm] over ``band`` (None: the whole grid),
    by the sums of :func:`band_sum` (eqs. (14)-(16) of the power-budget paper).

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths [nm], increasing.
    values : ndarray
        Spectral power density S at each sample (any unit, e.g. [W/nm]).
    band_nm : tuple of float, optional
        (low, high) limits [nm], inclusive; None for the whole grid.

    Returns
    -------
    float
        Mean wavelength λ̄ [nm].

    Raises
    ------
    NumericalError
        If the spectrum carries no positive power in the band.
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    band_nm = (float(wl[0]), float(wl[-1])) if band_nm is None else band_nm
    total = band_sum(wl, values, band_nm)
    if not total > 0:
        raise NumericalError("spectrum carries no power in the band", field="band", got=band_nm)
    return band_sum(wl, np.asarray(values, dtype=np.float64) * wl, band_nm) / total


def photon_pdf_from_power(wavelength_nm: NDArray[np.float64], power: NDArray[np.float64], band_nm: Band | None = None
                          ) -> NDArray[np.float64]:
    """Photon-number pdf [1/nm] of a power spectrum, p ∝ S(λ)·λ with Σ p Δλ = 1.

    ``band`` None: a uniform grid, summed with its step over every sample (the tracer's bins); a band [nm]: any
    grid, normalised by :func:`band_sum` over that band (a measured emission spectrum).

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths [nm], increasing.
    power : ndarray
        Spectral power density S at each sample (any unit, e.g. [W/nm]).
    band_nm : tuple of float, optional
        (low, high) normalisation band [nm], inclusive; None for a uniform grid normalised over every sample.

    Returns
    -------
    ndarray
        Photon-number pdf at each sample [1/nm] (nonzero outside ``band`` too, where S is).

    Raises
    ------
    ValidationError
        If the spectrum has no positive power.
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    photons = np.asarray(power, dtype=np.float64) * wl
    total = photons.sum() * (wl[1] - wl[0]) if band_nm is None else band_sum(wl, photons, band_nm)
    if not total > 0:
        raise ValidationError("emission spectrum has no power", field="emission_spectrum", expected="some S > 0")
    return photons / total
