"""Parametric spectrum and BSDF models as pure JAX functions (no xarray, no I/O, no global state).

Units, everywhere in this module:

* wavelengths, peak positions and widths in **nm**;
* angles in **radians** (degrees exist only at the user-facing boundaries: ``bsdfkit.fit.least_squares.fit_bsdf`` and
  the CLI);
* BSDF values in **sr⁻¹**; direction cosines β are dimensionless.

Geometry (Harvey–Shack direction-cosine space, [Harvey-Shack]; docs/exports.md §1): a direction (θ, φ) has direction
cosines β = (sin θ cos φ, sin θ sin φ); the projected solid angle is cos θ dΩ = dβx dβy, so the total
integrated scatter (TIS) of a BSDF f is ∫∫_{|β|≤1} f dβx dβy. The source sits at azimuth φi = π
(180°), so the specular (reflection) or direct (transmission, angles from the back normal) direction is
at φ = 0 and β0 = (sin θi, 0).

Every model is written so that its value *and* its gradient with respect to every parameter stay finite
at the edges of the parameter domain (zero widths, ABg exponent g → 0, B → 0, |β − β0| = 0), using the
"double-where" idiom: the unsafe branch is fed a harmless dummy argument so that its (discarded)
derivative cannot produce NaN.

The spectrum and lobe models are ``jax.jit`` functions: called outside a trace (NumPy data, a simulation, a
table's values) each runs as one compiled program per argument shape instead of one per elementwise operation
(40 calls of ``split_gaussian_spectrum`` on new shapes: 0.8 s against 4.5 s with JAX's persistent cache filled,
2.1 s against 25 s without it, the same bits); inside a trace the call is inlined.
"""
from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from bsdfkit.core.hemisphere import unit_disk_reach
from bsdfkit.core.quadrature import gauss_legendre
from bsdfkit.core.spectra import C_FWHM

__all__ = [
    "C_FWHM",
    "gaussian_spectrum",
    "split_gaussian_spectrum",
    "two_band_spectrum",
    "lambert",
    "direction_cosines",
    "specular_direction_cosines",
    "delta_beta_squared",
    "delta_beta",
    "gaussian_lobe",
    "abg",
    "harvey_shack",
    "lambert_gaussian",
    "lambert_abg",
    "tis_lambert",
    "tis_gaussian_lobe_unclipped",
    "tis_gaussian_lobe",
    "tis_abg_normal_incidence",
    "tis_abg",
    "tis_lambert_gaussian",
    "tis_lambert_abg",
]

#: Floor of the ABg denominator B + |β−β0|^g. Only reached when B → 0 exactly on the specular
#: direction, where the model is infinite; the floor keeps the value finite (and representable in
#: float32 as well as float64) instead of returning inf.
ABG_DENOMINATOR_FLOOR: float = 1e-30


#: Cap of (offset/width)² in the Gaussian shapes: exp(−C·1e4) and exp(−1e4/2) are exactly 0 in float32
#: and float64, so capping changes no value but keeps every derivative finite far out in the tails.
_RATIO_SQ_CAP = 1e4


def _tiny_width(*arrays) -> jnp.ndarray:
    """√(smallest normal) of the working dtype: below it a width is treated as exactly zero, because
    width² or width³ would underflow inside the derivatives."""
    return jnp.sqrt(jnp.finfo(jnp.result_type(*arrays, float)).tiny)


@partial(jax.jit, static_argnames=("cap",))
def ratio_squared(offset: ArrayLike, width: ArrayLike, cap: float = _RATIO_SQ_CAP) -> jnp.ndarray:
    """min((offset/width)², cap) with the width → 0 limit (0 on the peak, the cap elsewhere) taken
    safely: value and derivatives stay finite for any width ≥ 0, including 0 and subnormal widths.

    Parameters
    ----------
    offset : array_like
        Numerator, in any unit (the unit of ``width``).
    width : array_like
        Denominator, ≥ 0, in the unit of ``offset``.
    cap : float, optional
        Upper limit of the result [-].

    Returns
    -------
    jax.Array
        min((offset/width)², cap) [-], broadcast over ``offset`` and ``width``.
    """
    offset = jnp.asarray(offset)
    width = jnp.asarray(width)
    ok = width > _tiny_width(offset, width)
    safe_width = jnp.where(ok, width, 1.0)
    big = jnp.abs(offset) >= safe_width * math.sqrt(cap)
    safe_offset = jnp.where(big, 0.0, offset)
    ratio_sq = (safe_offset / safe_width) ** 2
    limit = jnp.where(offset == 0, 0.0, cap)
    return jnp.where(ok & ~big, ratio_sq, jnp.where(ok, cap, limit))


def _offset_over_width_squared(offset: ArrayLike, width: ArrayLike) -> jnp.ndarray:
    return ratio_squared(offset, width, _RATIO_SQ_CAP)


def _log1p_ratio_squared(offset: ArrayLike, width: ArrayLike) -> jnp.ndarray:
    """ln(1 + (offset/width)²) for width ≥ 0, finite with finite derivatives except the true limit
    width = 0, offset ≠ 0 (+inf). Large ratios use 2 ln|offset| − 2 ln width + ln(1 + (width/offset)²)."""
    offset = jnp.abs(jnp.asarray(offset))
    width = jnp.asarray(width)
    ok = width > _tiny_width(offset, width)
    safe_width = jnp.where(ok, width, 1.0)
    small = offset <= safe_width
    off_small = jnp.where(small, offset, 0.0)
    near = jnp.log1p((off_small / safe_width) ** 2)
    off_large = jnp.where(small, 1.0, offset)
    far = 2.0 * (jnp.log(off_large) - jnp.log(safe_width)) + jnp.log1p((safe_width / off_large) ** 2)
    limit = jnp.where(offset == 0, 0.0, jnp.inf)
    return jnp.where(ok, jnp.where(small, near, far), limit)


def _safe_sqrt(x: ArrayLike) -> jnp.ndarray:
    """√x with a zero (not infinite) derivative at x = 0."""
    x = jnp.asarray(x)
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


# ------------------------------------------------------------------------------------------------
# Spectrum models
# ------------------------------------------------------------------------------------------------
@jax.jit
def gaussian_spectrum(wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike) -> jnp.ndarray:
    """Relative Gaussian spectrum with peak 1: S(λ) = exp(−C((λ − λp)/Δλ)²), C = 4 ln 2.

    Eq. (2) of the cylindrical-module paper ("Impact of the geometrical and optical parameters on the
    performance of a cylindrical remote phosphor LED"); with C = 4 ln 2 the width Δλ is the true full
    width at half maximum. Identical to colour-science 0.4.7 ``sd_gaussian_fwhm`` ([colour-science]).

    Parameters
    ----------
    wavelength_nm, peak_nm, fwhm_nm : array_like
        λ, λp and Δλ [nm] (broadcast together). Δλ = 0 gives a unit spike at λ = λp and 0 elsewhere;
        values below ~1e-308 are exactly 0 (the exponent is capped where exp underflows anyway).

    Returns
    -------
    jax.Array
        Relative spectral value in [0, 1] [-].
    """
    z2 = _offset_over_width_squared(jnp.asarray(wavelength_nm) - peak_nm, fwhm_nm)
    return jnp.exp(-C_FWHM * z2)


@jax.jit
def split_gaussian_spectrum(
    wavelength_nm: ArrayLike, peak_nm: ArrayLike, fwhm_nm: ArrayLike, alpha: ArrayLike
) -> jnp.ndarray:
    """Asymmetric ("split", "modified") Gaussian with peak 1, eq. (3) of the cylindrical-module paper.

    S(λ) = exp(−C((λ − λp) / (Δλ(1 + sign(λ − λp)·α)))²), C = 4 ln 2.

    The half width is Δλ(1 − α)/2 on the short-wavelength side and Δλ(1 + α)/2 on the long side, so the
    full width at half maximum is Δλ for every α and the peak stays at λp (docs/fitting.md §1).
    α ∈ (−1, 1); at α = ±1 one side collapses to a step (value 0 there, still finite).

    Parameters
    ----------
    wavelength_nm, peak_nm, fwhm_nm : array_like
        λ, λp, Δλ [nm] (broadcast together).
    alpha : array_like
        Asymmetry constant α [-]. Table 2 of the paper: α = −0.12 for the phosphor band.

    Returns
    -------
    jax.Array
        Relative spectral value in [0, 1] [-].
    """
    offset = jnp.asarray(wavelength_nm) - peak_nm
    width = fwhm_nm * (1.0 + jnp.sign(offset) * alpha)
    return jnp.exp(-C_FWHM * _offset_over_width_squared(offset, width))


def two_band_spectrum(
    wavelength_nm: ArrayLike,
    blue_peak_nm: ArrayLike,
    blue_fwhm_nm: ArrayLike,
    blue_amplitude: ArrayLike,
    yellow_peak_nm: ArrayLike,
    yellow_fwhm_nm: ArrayLike,
    yellow_alpha: ArrayLike,
    yellow_amplitude: ArrayLike,
) -> jnp.ndarray:
    """Phosphor-converted white: blue pump Gaussian (eq. 2) + yellow split Gaussian (eq. 3).

    S(λ) = a_b·S_blue(λ; λp1, Δλ1) + a_y·S_yellow(λ; λp2, Δλ2, α), the linear combination of §4.2 of the
    cylindrical-module paper (there a_b = A1 and a_y = A2 in W/nm). Wavelengths and widths in nm; the
    result has the unit of the amplitudes.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths λ [nm].
    blue_peak_nm, blue_fwhm_nm : array_like
        Peak λp1 and FWHM Δλ1 of the blue pump band [nm].
    blue_amplitude : array_like
        Blue amplitude a_b (e.g. [W/nm]).
    yellow_peak_nm, yellow_fwhm_nm : array_like
        Peak λp2 and FWHM Δλ2 of the yellow phosphor band [nm].
    yellow_alpha : array_like
        Asymmetry α of the yellow band [-] (see :func:`split_gaussian_spectrum`).
    yellow_amplitude : array_like
        Yellow amplitude a_y, in the unit of ``blue_amplitude``.

    Returns
    -------
    jax.Array
        S(λ) in the unit of the amplitudes.
    """
    return blue_amplitude * gaussian_spectrum(wavelength_nm, blue_peak_nm, blue_fwhm_nm) + (
        yellow_amplitude * split_gaussian_spectrum(wavelength_nm, yellow_peak_nm, yellow_fwhm_nm, yellow_alpha)
    )


# ------------------------------------------------------------------------------------------------
# Geometry
# ------------------------------------------------------------------------------------------------
def direction_cosines(theta: ArrayLike, phi: ArrayLike) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Direction cosines β = (sin θ cos φ, sin θ sin φ) of a direction (θ, φ) in radians.

    Parameters
    ----------
    theta : array_like
        Polar angle from the normal [rad].
    phi : array_like
        Azimuth [rad].

    Returns
    -------
    bx, by : jax.Array
        Direction cosines βx, βy [-].
    """
    theta = jnp.asarray(theta)
    phi = jnp.asarray(phi)
    s = jnp.sin(theta)
    return s * jnp.cos(phi), s * jnp.sin(phi)


def specular_direction_cosines(theta_i: ArrayLike) -> tuple[jnp.ndarray, jnp.ndarray]:
    """β0 = (sin θi, 0): the specular (or direct-transmission) direction for a source at φi = π.

    θi in radians. For transmission the angles are measured from the back normal and the straight-through
    direction has the same β0.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad].

    Returns
    -------
    b0x, b0y : jax.Array
        Direction cosines of the specular direction [-]; b0y is 0.
    """
    theta_i = jnp.asarray(theta_i)
    return jnp.sin(theta_i), jnp.zeros_like(theta_i)


@jax.jit
def delta_beta_squared(theta_i: ArrayLike, theta_s: ArrayLike, phi_s: ArrayLike) -> jnp.ndarray:
    """|β − β0|² for incidence θi (source at φi = π) and scatter direction (θs, φs), all in radians.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad] (source at φi = π).
    theta_s : array_like
        Scatter polar angle from the normal (the back normal in transmission) [rad].
    phi_s : array_like
        Scatter azimuth [rad], 0 on the specular side.

    Returns
    -------
    jax.Array
        |β − β0|² [-].
    """
    bx, by = direction_cosines(theta_s, phi_s)
    b0x, b0y = specular_direction_cosines(theta_i)
    return (bx - b0x) ** 2 + (by - b0y) ** 2


def delta_beta(theta_i: ArrayLike, theta_s: ArrayLike, phi_s: ArrayLike) -> jnp.ndarray:
    """|β − β0| (dimensionless, in [0, 2]) with a finite derivative on the specular direction.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad] (source at φi = π).
    theta_s : array_like
        Scatter polar angle from the normal (the back normal in transmission) [rad].
    phi_s : array_like
        Scatter azimuth [rad], 0 on the specular side.

    Returns
    -------
    jax.Array
        |β − β0| [-].
    """
    return _safe_sqrt(delta_beta_squared(theta_i, theta_s, phi_s))


# ------------------------------------------------------------------------------------------------
# BSDF models (sr⁻¹)
# ------------------------------------------------------------------------------------------------
def lambert(rho: ArrayLike) -> jnp.ndarray:
    """Lambertian BSDF f = ρ/π in sr⁻¹ for a diffuse reflectance (or transmittance) ρ (docs/fitting.md §5).

    Parameters
    ----------
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].

    Returns
    -------
    jax.Array
        BSDF value [1/sr], broadcast over the arguments.
    """
    return jnp.asarray(rho) / jnp.pi


@jax.jit
def gaussian_lobe(dbeta: ArrayLike, amplitude: ArrayLike, sigma: ArrayLike) -> jnp.ndarray:
    """Gaussian lobe in direction cosines: f = A·exp(−|β − β0|²/(2σ²)) (docs/fitting.md §5).

    Parameters
    ----------
    dbeta : array_like
        |β − β0| [-].
    amplitude : array_like
        Peak value A [1/sr].
    sigma : array_like
        Lobe width σ in direction cosines [-]; σ = 0 gives a spike (A on specular, 0 elsewhere).

    Returns
    -------
    jax.Array
        BSDF value [1/sr].
    """
    return amplitude * jnp.exp(-0.5 * _offset_over_width_squared(dbeta, sigma))


@jax.jit
def abg(dbeta: ArrayLike, A: ArrayLike, B: ArrayLike, g: ArrayLike) -> jnp.ndarray:
    """ABg scatter model f = A/(B + |β − β0|^g) in sr⁻¹ ([TracePro-UM], [OpticStudio-Help]; docs/fitting.md §5).

    Peak A/B on specular, knee at |β − β0| ≈ B^{1/g}, far-field log–log slope −g. Defined for A ≥ 0,
    B ≥ 0, g ≥ 0. Edge handling: |β−β0|^g is evaluated as exp(g ln|β−β0|) only where |β−β0| > 0
    (0^g := 0 for g > 0 and 1 for g = 0, the g → 0 limit), and the denominator is floored at
    :data:`ABG_DENOMINATOR_FLOOR` so B → 0 on specular gives a large finite value, never inf/NaN.

    Parameters
    ----------
    dbeta : array_like
        |β − β0| [-].
    A : array_like
        Numerator A [1/sr], ≥ 0.
    B : array_like
        Knee constant B [-], ≥ 0.
    g : array_like
        Far-field slope exponent g [-], ≥ 0.

    Returns
    -------
    jax.Array
        BSDF value [1/sr], broadcast over the arguments.
    """
    dbeta = jnp.asarray(dbeta)
    g = jnp.asarray(g)
    pos = dbeta > 0
    log_d = jnp.log(jnp.where(pos, dbeta, 1.0))
    d_pow_g = jnp.where(pos, jnp.exp(g * log_d), jnp.where(g > 0, 0.0, 1.0))
    return A / jnp.maximum(B + d_pow_g, ABG_DENOMINATOR_FLOOR)


def harvey_shack(dbeta: ArrayLike, b0: ArrayLike, L: ArrayLike, S: ArrayLike) -> jnp.ndarray:
    """Three-parameter Harvey–Shack (FRED) form f = b0·(1 + (|β − β0|/L)²)^{S/2} in sr⁻¹.

    b0 is the specular value (sr⁻¹), L the shoulder (roll-off) in direction cosines, S the far-field
    log–log slope (negative) ([FRED]); equal to ABg with g = −S, B = L^g, A = b0·L^g
    for g = 2 (docs/fitting.md §5). L → 0 gives b0 on specular and the power-law limit 0 (S < 0) elsewhere.

    Parameters
    ----------
    dbeta : array_like
        |β − β0| [-].
    b0 : array_like
        Specular value [1/sr].
    L : array_like
        Shoulder (roll-off) in direction cosines [-], ≥ 0.
    S : array_like
        Far-field log–log slope [-] (negative).

    Returns
    -------
    jax.Array
        BSDF value [1/sr], broadcast over the arguments.
    """
    log_term = _log1p_ratio_squared(dbeta, L)
    finite = jnp.isfinite(log_term)
    safe_log = jnp.where(finite, log_term, 0.0)
    # (1 + z²)^{S/2} → 0 for S < 0, 1 for S = 0 when z² → ∞ (L → 0 off specular).
    inf_limit = jnp.where(S < 0, 0.0, jnp.where(S == 0, 1.0, jnp.inf))
    return b0 * jnp.where(finite, jnp.exp(0.5 * S * safe_log), inf_limit)


def lambert_gaussian(
    theta_i: ArrayLike,
    theta_s: ArrayLike,
    phi_s: ArrayLike,
    rho: ArrayLike,
    A: ArrayLike,
    sigma: ArrayLike,
) -> jnp.ndarray:
    """Lambert + Gaussian lobe: f = ρ/π + A·exp(−|β − β0|²/(2σ²)) in sr⁻¹.

    Angles θi, θs, φs in radians (source at φi = π, specular at φs = 0); ρ dimensionless, A in sr⁻¹,
    σ in direction cosines.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad] (source at φi = π).
    theta_s : array_like
        Scatter polar angle from the normal (the back normal in transmission) [rad].
    phi_s : array_like
        Scatter azimuth [rad], 0 on the specular side.
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].
    A : array_like
        Lobe peak value [1/sr].
    sigma : array_like
        Lobe width σ in direction cosines [-].

    Returns
    -------
    jax.Array
        BSDF value [1/sr], broadcast over the arguments.
    """
    d2 = delta_beta_squared(theta_i, theta_s, phi_s)
    return lambert(rho) + A * jnp.exp(-0.5 * _offset_over_width_squared(_safe_sqrt(d2), sigma))


def lambert_abg(
    theta_i: ArrayLike,
    theta_s: ArrayLike,
    phi_s: ArrayLike,
    rho: ArrayLike,
    A: ArrayLike,
    B: ArrayLike,
    g: ArrayLike,
) -> jnp.ndarray:
    """Lambert + ABg: f = ρ/π + A/(B + |β − β0|^g) in sr⁻¹ (angles in radians, see :func:`abg`).

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad] (source at φi = π).
    theta_s : array_like
        Scatter polar angle from the normal (the back normal in transmission) [rad].
    phi_s : array_like
        Scatter azimuth [rad], 0 on the specular side.
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].
    A : array_like
        ABg numerator [1/sr].
    B : array_like
        ABg knee constant [-], ≥ 0.
    g : array_like
        ABg slope exponent [-], ≥ 0.

    Returns
    -------
    jax.Array
        BSDF value [1/sr], broadcast over the arguments.
    """
    return lambert(rho) + abg(delta_beta(theta_i, theta_s, phi_s), A, B, g)


# ------------------------------------------------------------------------------------------------
# Total integrated scatter, TIS = ∫∫_{|β|≤1} f dβx dβy (dimensionless)
# ------------------------------------------------------------------------------------------------
def tis_lambert(rho: ArrayLike) -> jnp.ndarray:
    """TIS of the Lambert term: ∫∫_{|β|≤1} ρ/π dβ = ρ (exact).

    Parameters
    ----------
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    return jnp.asarray(rho)


def tis_gaussian_lobe_unclipped(A: ArrayLike, sigma: ArrayLike) -> jnp.ndarray:
    """Closed-form TIS 2πσ²A of a Gaussian lobe lying entirely inside the unit disk (docs/fitting.md §5).

    Exact only when the lobe does not reach |β| = 1 (|β0| + several σ < 1); use
    :func:`tis_gaussian_lobe` otherwise.

    Parameters
    ----------
    A : array_like
        Lobe peak value [1/sr].
    sigma : array_like
        Lobe width σ in direction cosines [-].

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    return 2.0 * jnp.pi * jnp.asarray(sigma) ** 2 * A


def _psi_grid(n_psi: int) -> jnp.ndarray:
    # The ψ-integrands are smooth and 2π-periodic: the trapezoid rule on a uniform grid converges
    # geometrically, far faster than any non-periodic rule.
    return jnp.arange(n_psi) * (2.0 * jnp.pi / n_psi)


def _radial_limit(b0: ArrayLike, psi: jnp.ndarray) -> jnp.ndarray:
    """t_max(ψ) ≥ 0 with |β0 + t(cos ψ, sin ψ)| = 1 for β0 = (b0, 0), |b0| < 1 (edge of the unit disk)."""
    return unit_disk_reach(b0 * jnp.cos(psi), b0**2, jnp)


@partial(jax.jit, static_argnames=("n_psi",))
def tis_gaussian_lobe(theta_i: ArrayLike, A: ArrayLike, sigma: ArrayLike, n_psi: int = 1024) -> jnp.ndarray:
    """Exact TIS of a Gaussian lobe clipped by the unit disk (θi in radians, σ in direction cosines).

    In polar coordinates (t, ψ) centred on β0 = (sin θi, 0) the radial integral is analytic:
    TIS = ∫₀^{2π} ∫₀^{t_max(ψ)} A e^{−t²/2σ²} t dt dψ = A σ² ∫₀^{2π} (1 − e^{−t_max(ψ)²/2σ²}) dψ,
    t_max(ψ) = −β0·u + √((β0·u)² + 1 − |β0|²), u = (cos ψ, sin ψ). The ψ integral uses the periodic
    trapezoid rule with ``n_psi`` nodes (spectrally accurate; 1024 nodes give ~1e-12 relative for
    sin θi ≤ 0.99). Reduces to 2πσ²A when the lobe is far from the disk edge.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad].
    A : array_like
        Lobe peak value [1/sr].
    sigma : array_like
        Lobe width σ in direction cosines [-].
    n_psi : int, optional
        Number of azimuthal trapezoid nodes.

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    psi = _psi_grid(n_psi)
    b0 = jnp.sin(jnp.asarray(theta_i))[..., None]
    t_max = _radial_limit(b0, psi)
    sigma = jnp.asarray(sigma)
    inner = -jnp.expm1(-0.5 * _offset_over_width_squared(t_max, sigma[..., None]))
    return jnp.asarray(A) * sigma**2 * jnp.sum(inner, axis=-1) * (2.0 * jnp.pi / n_psi)


def tis_abg_normal_incidence(A: float, B: float, g: float) -> float:
    """Closed-form ABg TIS at normal incidence (β0 = 0), docs/fitting.md §5.

    TIS = 2πA ∫₀¹ β/(B + β^g) dβ = (πA/B)·₂F₁(1, 2/g; 1 + 2/g; −1/B); g = 2 → πA ln(1 + 1/B);
    g → 0 → πA/(B + 1). Evaluated with :func:`scipy.special.hyp2f1` (NumPy, not traced by JAX: JAX's
    hyp2f1 loses accuracy for arguments z ≪ −1, i.e. small B). Arguments: A in sr⁻¹, B ≥ 0, g ≥ 0.

    Parameters
    ----------
    A : float
        ABg numerator [1/sr].
    B : float
        ABg knee constant [-]; > 0 unless g = 0.
    g : float
        ABg slope exponent [-], ≥ 0.

    Returns
    -------
    float
        Total integrated scatter at θi = 0 [-].
    """
    from scipy.special import hyp2f1

    A, B, g = float(A), float(B), float(g)
    if g == 0.0:
        return math.pi * A / (B + 1.0)
    if g == 2.0:
        return math.pi * A * math.log1p(1.0 / B)
    return math.pi * A / B * float(hyp2f1(1.0, 2.0 / g, 1.0 + 2.0 / g, -1.0 / B))


def _abg_radial_integral(t_max: jnp.ndarray, B: jnp.ndarray, g: jnp.ndarray, n_panels: int,
                         n_nodes: int) -> jnp.ndarray:
    """∫₀^{t_max} t/(B + t^g) dt by composite Gauss–Legendre in v = ln t over [ln t_max − 60, ln t_max].

    In v the integrand e^{2v}/(B + e^{gv}) is smooth (nearest complex pole at distance π/g from the real
    axis), so panels of width 2 with 16 nodes are accurate to ~1e-12 for g ≤ 3. The neglected piece
    below t_max·e^{−60} is < (t_max e^{−60})²/(2B) ≈ 4e-53/B, i.e. nil for B ≥ 1e-30.
    """
    span = 60.0
    nodes, weights = gauss_legendre(n_nodes)
    width = span / n_panels
    starts = -span + width * np.arange(n_panels)
    # Offsets from ln t_max (≤ 0) and weights of all panels, flattened.
    v_rel = (starts[:, None] + 0.5 * width * (nodes[None, :] + 1.0)).ravel()
    w = np.tile(0.5 * width * weights, n_panels)
    log_tmax = jnp.log(jnp.maximum(t_max, 1e-300))[..., None]
    v = log_tmax + jnp.asarray(v_rel)
    denom = jnp.maximum(B[..., None] + jnp.exp(g[..., None] * v), ABG_DENOMINATOR_FLOOR)
    return jnp.sum(jnp.asarray(w) * jnp.exp(2.0 * v) / denom, axis=-1)


def tis_abg(
    theta_i: ArrayLike,
    A: ArrayLike,
    B: ArrayLike,
    g: ArrayLike,
    n_psi: int = 512,
    n_panels: int = 30,
    n_nodes: int = 16,
) -> jnp.ndarray:
    """Exact numerical TIS of an ABg lobe clipped by the unit disk (θi in radians; A sr⁻¹; B, g ≥ 0).

    TIS = ∫₀^{2π} ∫₀^{t_max(ψ)} A t/(B + t^g) dt dψ in polar coordinates centred on β0, with a log-spaced
    radius because the integrand peaks sharply at t ≲ B^{1/g} (docs/fitting.md §5); periodic trapezoid in ψ, composite
    Gauss–Legendre in ln t. Agrees with :func:`tis_abg_normal_incidence` at θi = 0.

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad].
    A : array_like
        ABg numerator [1/sr].
    B : array_like
        ABg knee constant [-], ≥ 0.
    g : array_like
        ABg slope exponent [-], ≥ 0.
    n_psi : int, optional
        Number of azimuthal trapezoid nodes.
    n_panels : int, optional
        Number of Gauss–Legendre panels in ln t (over 60 natural-log units).
    n_nodes : int, optional
        Gauss–Legendre nodes per panel.

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    psi = _psi_grid(n_psi)
    b0 = jnp.sin(jnp.asarray(theta_i))[..., None]
    t_max = _radial_limit(b0, psi)
    B = jnp.broadcast_to(jnp.asarray(B)[..., None], t_max.shape)
    g = jnp.broadcast_to(jnp.asarray(g)[..., None], t_max.shape)
    radial = _abg_radial_integral(t_max, B, g, n_panels, n_nodes)
    return jnp.asarray(A) * jnp.sum(radial, axis=-1) * (2.0 * jnp.pi / n_psi)


def tis_lambert_gaussian(theta_i: ArrayLike, rho: ArrayLike, A: ArrayLike, sigma: ArrayLike) -> jnp.ndarray:
    """TIS of :func:`lambert_gaussian`: ρ + clipped Gaussian lobe (θi in radians).

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad].
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].
    A : array_like
        Lobe peak value [1/sr].
    sigma : array_like
        Lobe width σ in direction cosines [-].

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    return tis_lambert(rho) + tis_gaussian_lobe(theta_i, A, sigma)


def tis_lambert_abg(theta_i: ArrayLike, rho: ArrayLike, A: ArrayLike, B: ArrayLike, g: ArrayLike) -> jnp.ndarray:
    """TIS of :func:`lambert_abg`: ρ + clipped ABg lobe (θi in radians).

    Parameters
    ----------
    theta_i : array_like
        Angle of incidence from the sample normal [rad].
    rho : array_like
        Diffuse reflectance or transmittance ρ [-].
    A : array_like
        ABg numerator [1/sr].
    B : array_like
        ABg knee constant [-], ≥ 0.
    g : array_like
        ABg slope exponent [-], ≥ 0.

    Returns
    -------
    jax.Array
        Total integrated scatter [-], broadcast over the arguments.
    """
    return tis_lambert(rho) + tis_abg(theta_i, A, B, g)
