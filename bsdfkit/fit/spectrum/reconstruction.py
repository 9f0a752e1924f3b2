"""The two-band reconstruction of §4.2 of the cylindrical-module paper: band sums, the 2×2 system for the
gains A1 (blue) and A2 (yellow) [W/nm], and the absolute module spectrum A1·S_blue + A2·S_yellow.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bsdfkit.core.conventions import MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM
from bsdfkit.core.errors import InputError, NumericalError, ValidationError
from bsdfkit.fit.spectrum.solver import _nm_grid
from bsdfkit.reduction.spectral import band_sum

if TYPE_CHECKING:
    from colour import SpectralDistribution


#: Band limits (nm, inclusive) of the §4.2 reconstruction in the cylindrical-module paper (defined once, in
#: :mod:`bsdfkit.core.conventions`).
BLUE_BAND_NM: tuple[float, float] = MODULE_BLUE_BAND_NM
YELLOW_BAND_NM: tuple[float, float] = MODULE_YELLOW_BAND_NM

#: Largest accepted 2-norm condition number of the 2×2 band-sum matrix. With flux uncertainties of
#: ~1 % (Table 1 of the paper: simulation vs measurement differ by 4 %), κ = 1e3 already allows the
#: gains to be wrong by a factor of ~10; beyond that the blue and yellow spectra are not separable.
MAX_CONDITION: float = 1e3


def band_integral(wavelength_nm: np.ndarray, values: np.ndarray, band_nm: tuple[float, float]) -> float:
    """Σ values(λi)·Δλi over lo ≤ λi ≤ hi (inclusive), the band sum of §4.2 of the cylindrical-module paper.

    λ in nm; Δλi are the sample spacings (central differences): :func:`bsdfkit.reduction.spectral.band_sum` on a
    validated grid. Result in value-unit·nm (W for W/nm).

    Parameters
    ----------
    wavelength_nm : ndarray
        Grid [nm], strictly increasing.
    values : ndarray
        Spectral values on the grid (e.g. [W/nm]).
    band_nm : tuple of float
        (low, high) band [nm], inclusive, low < high.

    Returns
    -------
    float
        The band sum, in the unit of ``values`` times nm (e.g. [W]).

    Raises
    ------
    ValidationError
        If the band is empty or the grid is not in nm.
    """
    wl = _nm_grid(wavelength_nm)
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
    wavelength_nm: np.ndarray,
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
    wavelength_nm : ndarray
        Grid [nm], strictly increasing.
    s_blue, s_yellow : ndarray
        Normalised (peak 1) blue and yellow spectra on that grid [-].
    flux_blue_W, flux_yellow_W : float
        Band radiant fluxes [W], ≥ 0 (Table 1 of the paper, simulation: 0.058 W and 0.472 W).
    blue_band_nm, yellow_band_nm : tuple of float, optional
        (low, high) limits of the blue and yellow bands [nm], inclusive.
    max_condition : float, optional
        Refuse matrices with a larger 2-norm condition number [-] (default :data:`MAX_CONDITION`).

    Returns
    -------
    TwoBandGains
        Gains A1, A2 [W/nm], the matrix's condition number [-] and its band sums [nm].

    Raises
    ------
    NumericalError
        Near-singular system (condition number above ``max_condition``) or a negative gain (a negative
        spectral flux is unphysical: the spectra do not fit the band fluxes).
    """
    wl = _nm_grid(wavelength_nm)
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
    wavelength_nm: np.ndarray,
    s_blue: np.ndarray,
    s_yellow: np.ndarray,
    flux_blue_W: float,
    flux_yellow_W: float,
    *,
    bands_nm: tuple[tuple[float, float], tuple[float, float]] = (BLUE_BAND_NM, YELLOW_BAND_NM),
    max_condition: float = MAX_CONDITION,
    name: str = "two-band reconstruction",
) -> SpectralDistribution:
    """Absolute spectral radiant flux Φ_e,λ = A1·S_blue + A2·S_yellow [W/nm] (§4.2, cylindrical-module paper).

    The gains are those of :func:`two_band_gains`, so the band sums of the result reproduce the two fluxes.

    Parameters
    ----------
    wavelength_nm : ndarray
        Grid [nm], strictly increasing.
    s_blue, s_yellow : ndarray
        Normalised (peak 1) blue and yellow spectra on that grid [-].
    flux_blue_W, flux_yellow_W : float
        Band radiant fluxes [W], ≥ 0.
    bands_nm : tuple of two (low, high) tuples, optional
        Blue and yellow band limits [nm], inclusive (default 380–500 nm and 501–780 nm).
    max_condition : float, optional
        Refuse gain matrices with a larger 2-norm condition number [-] (default :data:`MAX_CONDITION`).
    name : str, optional
        Name of the returned distribution.

    Returns
    -------
    colour.SpectralDistribution
        Φ_e,λ [W/nm] on the input grid.

    Raises
    ------
    NumericalError
        As :func:`two_band_gains`: a near-singular system or a negative gain.
    """
    import colour

    gains = two_band_gains(wavelength_nm, s_blue, s_yellow, flux_blue_W, flux_yellow_W,
                           blue_band_nm=bands_nm[0], yellow_band_nm=bands_nm[1],
                           max_condition=max_condition)
    wl = np.asarray(wavelength_nm, dtype=float)
    flux = gains.a1_W_per_nm * np.asarray(s_blue, float) + gains.a2_W_per_nm * np.asarray(s_yellow, float)
    return colour.SpectralDistribution(flux, wl, name=name)
