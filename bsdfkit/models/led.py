"""LED emission line shapes as pure JAX functions (no I/O, no global state, nothing above ``bsdfkit.models``).

A measured LED line has a sharper top and wider wings than a Gaussian of the same FWHM, so a Gaussian fitted
to it over the whole spectrum comes out too wide (docs/fitting.md §10). The shapes here have that freedom:

* :func:`ohno2005_spectrum`: Ohno's LED model (Ohno 2005, Opt. Eng. 44(11) 111302), S = (g + 2g⁵)/3 with
  g = exp(−((λ − λp)/w)²); identical to colour-science's ``colour.colorimetry.sd_single_led_Ohno2005``, whose
  ``half_spectral_width`` is w (not the FWHM: FWHM = :data:`OHNO2005_FWHM_PER_WIDTH`·w).
* :func:`split_pseudo_voigt_spectrum`: η·Lorentzian + (1 − η)·Gaussian sharing a half width that differs
  left and right of the peak (Δλ(1 − α)/2 below, Δλ(1 + α)/2 above, as eq. (3) of the cylindrical-module
  paper). Both parts are ½ at that half width, so the FWHM is exactly Δλ and the peak exactly λp for every
  η ∈ [0, 1] and α ∈ (−1, 1).
* :func:`split_pearson7_spectrum`: (1 + (2^{1/m} − 1)z²)^{−m}, z = (λ − λp)/h with the same split half
  widths h; m → ∞ is the Gaussian, m = 1 the Lorentzian. FWHM exactly Δλ, peak exactly λp.

Units: wavelengths, peaks and widths in nm; the shapes are dimensionless with peak value 1. Value and
gradient stay finite for widths → 0 (a unit spike) and α → ±1 (a step), using the double-where idiom of
:mod:`bsdfkit.models.functions`. The three shapes are ``jax.jit`` functions, as the models there are: on data
outside a trace each runs as one compiled program per argument shape.
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from bsdfkit.models.functions import ratio_squared

__all__ = [
    "OHNO2005_FWHM_PER_WIDTH",
    "ohno2005_spectrum",
    "ohno2005_fwhm_spectrum",
    "split_pseudo_voigt_spectrum",
    "split_pearson7_spectrum",
]


def _ohno_half_max_g() -> float:
    """Root g* ∈ (0, 1) of (g + 2g⁵)/3 = ½ (Newton from g = 0.7; f is monotonic and convex there)."""
    g = 0.7
    for _ in range(60):
        g -= (g + 2.0 * g**5 - 1.5) / (1.0 + 10.0 * g**4)
    return g


#: FWHM of Ohno's LED model in units of its width parameter w: 2·√(−ln g*), (g* + 2g*⁵)/3 = ½ (≈ 1.6151).
OHNO2005_FWHM_PER_WIDTH: float = 2.0 * math.sqrt(-math.log(_ohno_half_max_g()))

# Cap of the squared normalised offset. Gaussian-type terms: exp(−1e4·c) is 0 anyway. Lorentzian-type terms
# (pseudo-Voigt, Pearson VII) keep their power-law tails up to |z| = 1e8, i.e. values down to ~1e−16.
_GAUSS_CAP = 1e4
_POWER_CAP = 1e16


def _split_half_width(offset: jnp.ndarray, fwhm: ArrayLike, alpha: ArrayLike) -> jnp.ndarray:
    """Half width at half maximum on the side of ``offset``: Δλ(1 + sign(offset)·α)/2."""
    return 0.5 * fwhm * (1.0 + jnp.sign(offset) * alpha)


@jax.jit
def ohno2005_spectrum(wavelength_nm: ArrayLike, peak_nm: ArrayLike, half_spectral_width_nm: ArrayLike) -> jnp.ndarray:
    """Ohno (2005) single-LED model, S = (g + 2g⁵)/3 with g = exp(−((λ − λp)/w)²), peak value 1.

    Same definition and argument meaning as colour-science's ``sd_single_led_Ohno2005(peak_wavelength,
    half_spectral_width)``.

    Parameters
    ----------
    wavelength_nm, peak_nm
        λ and λp [nm].
    half_spectral_width_nm
        w [nm] ("half spectral width" Δλ0.5 in colour-science). The FWHM is ``OHNO2005_FWHM_PER_WIDTH``·w
        (≈ 1.6151·w). w = 0 gives a unit spike at λp.

    Returns
    -------
    Dimensionless relative spectral value in [0, 1].
    """
    z2 = ratio_squared(jnp.asarray(wavelength_nm) - peak_nm, half_spectral_width_nm, _GAUSS_CAP)
    return (jnp.exp(-z2) + 2.0 * jnp.exp(-5.0 * z2)) / 3.0


def ohno2005_fwhm_spectrum(wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike) -> jnp.ndarray:
    """:func:`ohno2005_spectrum` parameterised by its true FWHM Δλ [nm] (w = Δλ / OHNO2005_FWHM_PER_WIDTH).

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelength λ [nm].
    peak_nm : array_like
        Peak wavelength λp [nm].
    fwhm_nm : array_like
        Full width at half maximum Δλ [nm].

    Returns
    -------
    jax.Array
        Relative spectral value, 1 at the peak [-].
    """
    return ohno2005_spectrum(wavelength_nm, peak_nm, jnp.asarray(fwhm_nm) / OHNO2005_FWHM_PER_WIDTH)


@jax.jit
def split_pseudo_voigt_spectrum(
    wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike, alpha: ArrayLike, eta: ArrayLike
) -> jnp.ndarray:
    """Split pseudo-Voigt line, peak value 1: S = η/(1 + z²) + (1 − η)·exp(−ln 2·z²), z = (λ − λp)/h.

    h = Δλ(1 − α)/2 below the peak and Δλ(1 + α)/2 above it, so S = ½ at λp − Δλ(1 − α)/2 and
    λp + Δλ(1 + α)/2: the FWHM is Δλ for every α and η.

    Parameters
    ----------
    wavelength_nm, peak_nm, fwhm_nm
        λ, λp and Δλ [nm].
    alpha
        Asymmetry α ∈ (−1, 1) [1]; α > 0 widens the long-wavelength side.
    eta
        Lorentzian fraction η ∈ [0, 1] [1] (0: split Gaussian, eq. (3) of the cylindrical-module paper).

    Returns
    -------
    Dimensionless relative spectral value (≤ 1).
    """
    offset = jnp.asarray(wavelength_nm) - peak_nm
    h = _split_half_width(offset, fwhm_nm, alpha)
    gauss = jnp.exp(-math.log(2.0) * ratio_squared(offset, h, _GAUSS_CAP))
    lorentz = 1.0 / (1.0 + ratio_squared(offset, h, _POWER_CAP))
    return eta * lorentz + (1.0 - eta) * gauss


@jax.jit
def split_pearson7_spectrum(
    wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike, alpha: ArrayLike, m: ArrayLike
) -> jnp.ndarray:
    """Split Pearson VII line, peak value 1: S = (1 + (2^{1/m} − 1)·z²)^{−m}, z = (λ − λp)/h.

    h as in :func:`split_pseudo_voigt_spectrum` (FWHM exactly Δλ, peak λp). m = 1 is a Lorentzian, m → ∞ a
    Gaussian; m > ½ for a finite area.

    Parameters
    ----------
    wavelength_nm, peak_nm, fwhm_nm
        λ, λp and Δλ [nm].
    alpha
        Asymmetry α ∈ (−1, 1) [1].
    m
        Shape exponent m > 0 [1].

    Returns
    -------
    Dimensionless relative spectral value in [0, 1].
    """
    offset = jnp.asarray(wavelength_nm) - peak_nm
    h = _split_half_width(offset, fwhm_nm, alpha)
    m = jnp.asarray(m)
    c = jnp.expm1(math.log(2.0) / m)  # 2^{1/m} − 1
    return jnp.exp(-m * jnp.log1p(c * ratio_squared(offset, h, _POWER_CAP)))
