"""Coordinate frames of a scattering measurement and of the ray-tracer tables, with exact inverses.

All functions are vectorised over leading axes, work in float64 and take **radians** (degrees are only
used at the user boundary: CLI, file readers/writers, :mod:`bsdfkit.tables.export`). Unit vectors carry their
three components in the last axis.

Frames (docs/exports.md §1; sources in docs/references.md)
----------------------------------------------------------
**Sample frame.** z = surface normal on the side of the scattered light, x and y in the surface plane.
The source lies at azimuth φi = π by default, so the specular direction lies at φs = 0:

    ω(θ, φ) = (sin θ cos φ, sin θ sin φ, cos θ)                                             (1)

For *transmission* the scattered light leaves through the back face; its angles are measured from the
back normal. The transmission frame is the reflection frame mirrored in the surface plane,
(x, y, z) → (x, y, −z): x and y (hence β and the azimuths) are shared by both sides and the
direct-transmission direction of a plate in air has the same β0 as the specular reflection
(the plate displaces the beam without deviating it). The mirrored frame is left-handed; for
plane-symmetric data this is immaterial, for asymmetric BTDF tables it fixes the sense of azimuth (see
docs/exports.md).

**Instrument frame** (goniometer of §2 of [Power-budget], sample rotated about a vertical axis). Lab y_L
vertical = rotation axis of the sample stage and of the detector arm; the source is fixed at
s_L = (0, 0, 1) (unit vector from the sample to the source). The sample is rotated by θr about y_L, so its
axes in the lab are x_s = (cos θr, 0, −sin θr), y_s = (0, 1, 0), n = (sin θr, 0, cos θr). The detector arm
sits at azimuth γ (about y_L, measured from the source direction) and elevation ε:
d_L = (sin γ cos ε, sin ε, cos γ cos ε). Then θi = θr, φi = π and

    d = (cos ε sin(γ − θr), sin ε, cos ε cos(γ − θr))                                       (2)

in the (front) sample frame; d_z < 0 is the transmission hemisphere. In-plane (ε = 0) the signed
scatter angle is γ − θr and the specular direction is at γ = 2θr.

**Harvey–Shack (direction-cosine) frame** ([Harvey-Shack]; as in [TracePro-UM] and [OpticStudio-Help]).
β = (ω_x, ω_y), the projection of the scattered unit vector on the surface plane; β0 = the projection of the specular
direction = sin θi (cos(φi + π), sin(φi + π)) = (sin θi, 0) for φi = π, for reflection and for
transmission through a plate in air. Polar coordinates of β − β0:

    ρ = |β − β0| ∈ [0, 2],   ψ = atan2((β − β0)_y, (β − β0)_x) ∈ [0, 2π)                     (3)

(ψ from the sample +x axis, counter-clockwise seen from +z). Only |β| ≤ 1 are directions; the inverse
is ω = (β_x, β_y, +√(1 − |β|²)). Projected solid angle: cos θ dΩ = dβ_x dβ_y (docs/exports.md §3).

**Specular-centred (Zemax) frame** ([Zemax-BSDF]). With the specular (or
direct-transmission) unit vector r0, e1 = unit(n − (n·r0) r0) points from r0 toward the normal and
e2 = r0 × e1 (right-handed, azimuth counter-clockwise):

    radial = angle(ω, r0),   azimuth = atan2(ω·e2, ω·e1) ∈ [0, 2π)                          (4)

For r0 = (sin θ0, 0, cos θ0): e1 = (−cos θ0, 0, sin θ0), e2 = (0, −1, 0), i.e.
azimuth = atan2(−ω_y, −ω_x cos θ0 + ω_z sin θ0), the mapping of Ansys' converter ([Ansys-OA]).
At θ0 = 0 e1 is undefined; the sample x axis is used (e1 = x, e2 = y; a convention, [Zemax-BSDF] leaves it
open). Note that the limit θ0 → 0⁺ of e1 is −x (the normal lies on the source side of the specular direction), so the
azimuth origin turns by π exactly at normal incidence; rotationally symmetric normal-incidence data are
unaffected.

Numerics
--------
Polar angles are computed as ``atan2(sqrt(x² + y²), z)`` instead of ``acos(z)``: identical to
``acos(clip(z, −1, 1))`` for unit vectors, but accurate to rounding near the pole and the antipode where
``acos`` loses half the digits. Where the azimuth is undefined (pole θ = 0, antipode θ = π, ρ = 0,
radial = 0 or π) it is returned as 0. In the Harvey–Shack inverse, ω_z = √(1 − |β|²) is
ill-conditioned at grazing angles (δω_z ≈ ε_machine / ω_z); |β| beyond 1 by more than
:data:`BETA_TOLERANCE` is an error, smaller excursions (rounding) are clamped onto the horizon.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import ValidationError

__all__ = [
    "BETA_TOLERANCE",
    "SIDES",
    "InstrumentGeometry",
    "SampleGeometry",
    "angles_from_direction",
    "beta0",
    "beta_from_direction",
    "direction_from_angles",
    "direction_from_beta",
    "direction_from_harvey_shack",
    "direction_from_specular",
    "harvey_shack_from_direction",
    "instrument_from_sample",
    "sample_from_instrument",
    "specular_axes",
    "specular_direction",
    "specular_from_direction",
    "to_side_frame",
]

"""The two scattering sides, in the order used for the ``side`` dimension."""

BETA_TOLERANCE: float = 1e-9
"""|β| may exceed 1 by this much (rounding) before :func:`direction_from_beta` refuses it."""

_TWO_PI = 2.0 * np.pi


def _f64(x: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(x, dtype=np.float64)


def _wrap_2pi(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Map angles to [0, 2π) (``mod`` can return exactly 2π for tiny negative inputs)."""
    wrapped = np.mod(angle, _TWO_PI)
    return np.where(wrapped >= _TWO_PI, 0.0, wrapped)


def _wrap_pi(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """Map angles to (−π, π]."""
    return np.pi - _wrap_2pi(np.pi - angle)


def _check_side(side: str) -> str:
    if side not in SIDES:
        raise ValidationError("unknown scattering side", field="side", expected=" or ".join(SIDES), got=side)
    return side


# --------------------------------------------------------------------------------------------------
# sample (θ, φ) <-> unit vectors
# --------------------------------------------------------------------------------------------------
def direction_from_angles(theta: ArrayLike, phi: ArrayLike) -> NDArray[np.float64]:
    """Unit vector ω = (sin θ cos φ, sin θ sin φ, cos θ), eq. (1); θ ∈ [0, π] covers both hemispheres.

    Parameters
    ----------
    theta : float or ndarray
        Polar angle from the +z normal, in [0, π] [rad].
    phi : float or ndarray
        Azimuth from the +x axis, counter-clockwise [rad].

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector ω [-].
    """
    theta, phi = np.broadcast_arrays(_f64(theta), _f64(phi))
    sin_t = np.sin(theta)
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), np.cos(theta)], axis=-1)


def angles_from_direction(direction: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`direction_from_angles`: (θ ∈ [0, π], φ ∈ [0, 2π)).

    θ = atan2(√(x² + y²), z) (the clamped ``acos`` without its precision loss at the poles);
    φ = atan2(y, x) mod 2π, set to 0 at the pole and the antipode where it is undefined.
    The input need not be normalised.

    Parameters
    ----------
    direction : array_like, shape (..., 3)
        Vector, not necessarily normalised [-].

    Returns
    -------
    theta : ndarray
        Polar angle from +z, in [0, π] [rad].
    phi : ndarray
        Azimuth, in [0, 2π) [rad].
    """
    v = _f64(direction)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    s = np.hypot(x, y)
    theta = np.arctan2(s, z)
    phi = np.where(s > 0.0, _wrap_2pi(np.arctan2(y, x)), 0.0)
    return theta, phi


def to_side_frame(direction: ArrayLike, side: str) -> NDArray[np.float64]:
    """Front-sample-frame vector → frame of ``side`` (and back: the map is its own inverse).

    Reflection: unchanged. Transmission: (x, y, z) → (x, y, −z), the mirrored back frame of the module
    docstring, in which transmitted light has z ≥ 0 and θ is measured from the back normal.

    Parameters
    ----------
    direction : array_like, shape (..., 3)
        Vector in the front sample frame (or in the frame of ``side``) [-].
    side : {"reflection", "transmission"}
        Scattering side whose frame is wanted.

    Returns
    -------
    ndarray, shape (..., 3)
        The vector in the other frame [-].
    """
    v = _f64(direction).copy()
    if _check_side(side) == "transmission":
        v[..., 2] = -v[..., 2]
    return v


# --------------------------------------------------------------------------------------------------
# instrument <-> sample (instrument frame of the module docstring)
# --------------------------------------------------------------------------------------------------
class SampleGeometry(NamedTuple):
    """Incidence and scatter angles in the sample frame (radians); θs is measured in the frame of its side."""

    theta_i: NDArray[np.float64]
    phi_i: NDArray[np.float64]
    theta_s: NDArray[np.float64]
    phi_s: NDArray[np.float64]
    transmission: NDArray[np.bool_]


class InstrumentGeometry(NamedTuple):
    """Goniometer angles of the instrument frame of the module docstring (radians)."""

    theta_r: NDArray[np.float64]
    gamma: NDArray[np.float64]
    epsilon: NDArray[np.float64]


def sample_from_instrument(theta_r: ArrayLike, gamma: ArrayLike, epsilon: ArrayLike) -> SampleGeometry:
    """Sample-stage rotation θr, detector azimuth γ and elevation ε → sample-frame angles.

    Instrument frame: θi = θr, φi = π, d = (cos ε sin(γ − θr), sin ε, cos ε cos(γ − θr)) (eq. 2).
    ``transmission`` is d_z < 0 (the grazing plane d_z = 0 counts as reflection); θs, φs are then the
    angles of (d_x, d_y, |d_z|) in the transmission frame (θs from the back normal).

    Parameters
    ----------
    theta_r : float or ndarray
        Sample-stage rotation, equal to the angle of incidence [rad].
    gamma : float or ndarray
        Detector azimuth of the goniometer arm [rad].
    epsilon : float or ndarray
        Detector elevation above the plane of incidence [rad].

    Returns
    -------
    SampleGeometry
        θi, φi, θs, φs [rad] and the transmission flag (broadcast shape).
    """
    theta_r, gamma, epsilon = np.broadcast_arrays(_f64(theta_r), _f64(gamma), _f64(epsilon))
    delta = gamma - theta_r
    cos_e = np.cos(epsilon)
    d = np.stack([cos_e * np.sin(delta), np.sin(epsilon), cos_e * np.cos(delta)], axis=-1)
    transmission = d[..., 2] < 0.0
    d[..., 2] = np.abs(d[..., 2])
    theta_s, phi_s = angles_from_direction(d)
    return SampleGeometry(theta_r.copy(), np.full_like(theta_r, np.pi), theta_s, phi_s, transmission)


def instrument_from_sample(
    theta_i: ArrayLike, theta_s: ArrayLike, phi_s: ArrayLike, transmission: ArrayLike = False
) -> InstrumentGeometry:
    """Inverse of :func:`sample_from_instrument` (the instrument always has φi = π).

    With d the front-frame scatter vector (z negated for transmission):
    θr = θi, ε = atan2(d_y, √(d_x² + d_z²)) ∈ [−π/2, π/2], γ = θr + atan2(d_x, d_z) wrapped to (−π, π].
    At ε = ±π/2 (detector at the zenith of the arm) γ is undefined and returned as θr.

    Parameters
    ----------
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    theta_s : float or ndarray
        Scatter polar angle from the normal of its side [rad].
    phi_s : float or ndarray
        Scatter azimuth in the sample frame [rad].
    transmission : bool or ndarray of bool, optional
        True where the scatter direction is on the transmission side.

    Returns
    -------
    InstrumentGeometry
        θr, γ and ε [rad] (broadcast shape).
    """
    theta_i, theta_s, phi_s, transmission = np.broadcast_arrays(
        _f64(theta_i), _f64(theta_s), _f64(phi_s), np.asarray(transmission, dtype=bool)
    )
    d = direction_from_angles(theta_s, phi_s)
    d[..., 2] = np.where(transmission, -d[..., 2], d[..., 2])
    epsilon = np.arctan2(d[..., 1], np.hypot(d[..., 0], d[..., 2]))
    gamma = _wrap_pi(theta_i + np.arctan2(d[..., 0], d[..., 2]))
    return InstrumentGeometry(theta_i.copy(), gamma, epsilon)


# --------------------------------------------------------------------------------------------------
# sample <-> Harvey-Shack
# --------------------------------------------------------------------------------------------------
def specular_direction(theta_i: ArrayLike, phi_i: ArrayLike = np.pi) -> NDArray[np.float64]:
    """Unit vector r0 of the specular reflection (and of direct transmission through a plate in air).

    For a source at (θi, φi) the specular direction is (θi, φi + π) in the frame of either side:
    r0 = (sin θi cos(φi + π), sin θi sin(φi + π), cos θi) = (sin θi, 0, cos θi) for φi = π.

    Parameters
    ----------
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector r0 [-].
    """
    theta_i, phi_i = np.broadcast_arrays(_f64(theta_i), _f64(phi_i))
    # φi − π rather than φi + π: the same direction, and exactly 0 for the default φi = π
    return direction_from_angles(theta_i, phi_i - np.pi)


def beta0(theta_i: ArrayLike, phi_i: ArrayLike = np.pi) -> NDArray[np.float64]:
    """β0 = tangential projection of the specular direction = sin θi (cos(φi + π), sin(φi + π)).

    Parameters
    ----------
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    ndarray, shape (..., 2)
        Direction cosines β0 of the specular direction [-].
    """
    return specular_direction(theta_i, phi_i)[..., :2]


def beta_from_direction(direction: ArrayLike) -> NDArray[np.float64]:
    """β = (ω_x, ω_y) for a unit vector in the frame of its side (Harvey–Shack frame, eq. (3)).

    Parameters
    ----------
    direction : array_like, shape (..., 3)
        Unit vector in the frame of its side [-].

    Returns
    -------
    ndarray, shape (..., 2)
        Direction cosines β [-].
    """
    return _f64(direction)[..., :2].copy()


def direction_from_beta(beta: ArrayLike) -> NDArray[np.float64]:
    """Unit vector (β_x, β_y, √(1 − |β|²)) on the scattering side (z ≥ 0).

    Raises :class:`~bsdfkit.core.errors.ValidationError` where |β| > 1 + :data:`BETA_TOLERANCE` (no direction);
    smaller excursions are rounding and are put on the horizon.

    Parameters
    ----------
    beta : array_like, shape (..., 2)
        Direction cosines (β_x, β_y) with |β| ≤ 1 [-].

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector with z ≥ 0 [-].
    """
    b = _f64(beta)
    norm2 = b[..., 0] ** 2 + b[..., 1] ** 2
    worst = float(np.max(norm2, initial=0.0))
    if not np.all(np.isfinite(norm2)) or worst > (1.0 + BETA_TOLERANCE) ** 2:
        raise ValidationError(
            "direction cosines outside the unit disk", field="beta", expected="|beta| <= 1",
            got=float(np.sqrt(worst)) if np.isfinite(worst) else "non-finite",
        )
    scale = np.where(norm2 > 1.0, 1.0 / np.sqrt(np.maximum(norm2, 1.0)), 1.0)
    bx, by = b[..., 0] * scale, b[..., 1] * scale
    z = np.sqrt(np.maximum(0.0, (1.0 - np.hypot(bx, by)) * (1.0 + np.hypot(bx, by))))
    return np.stack([bx, by, z], axis=-1)


def harvey_shack_from_direction(
    direction: ArrayLike, theta_i: ArrayLike, phi_i: ArrayLike = np.pi
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(ρ = |β − β0|, ψ = azimuth of β − β0 ∈ [0, 2π)) of a unit vector in the frame of its side, eq. (3).

    ψ is measured from the sample +x axis, counter-clockwise; it is 0 where ρ = 0 (the specular point).
    Valid for reflection and for transmission through a plate in air (same β0).

    Parameters
    ----------
    direction : array_like, shape (..., 3)
        Unit vector in the frame of its side [-].
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    rho : ndarray
        Distance |β − β0| in direction-cosine space [-].
    psi : ndarray
        Azimuth of β − β0 from the sample +x axis, in [0, 2π) [rad].
    """
    d = beta_from_direction(direction) - beta0(theta_i, phi_i)
    rho = np.hypot(d[..., 0], d[..., 1])
    psi = np.where(rho > 0.0, _wrap_2pi(np.arctan2(d[..., 1], d[..., 0])), 0.0)
    return rho, psi


def direction_from_harvey_shack(
    rho: ArrayLike, psi: ArrayLike, theta_i: ArrayLike, phi_i: ArrayLike = np.pi
) -> NDArray[np.float64]:
    """Inverse of :func:`harvey_shack_from_direction`: β = β0 + ρ(cos ψ, sin ψ), then
    :func:`direction_from_beta` (raises where |β| > 1).

    Parameters
    ----------
    rho : float or ndarray
        Distance |β − β0| in direction-cosine space [-].
    psi : float or ndarray
        Azimuth of β − β0 from the sample +x axis [rad].
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector with z ≥ 0 [-].
    """
    rho, psi = _f64(rho), _f64(psi)
    b0 = beta0(theta_i, phi_i)
    beta = b0 + np.stack([rho * np.cos(psi), rho * np.sin(psi)], axis=-1)
    return direction_from_beta(beta)


# --------------------------------------------------------------------------------------------------
# sample <-> specular-centred (Zemax)
# --------------------------------------------------------------------------------------------------
def specular_axes(
    theta_i: ArrayLike, phi_i: ArrayLike = np.pi
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(e1, e2, r0) of the specular-centred frame, eq. (4).

    e1 = unit(n − (n·r0) r0) = (−cos θi cos(φi + π), −cos θi sin(φi + π), sin θi) for θi > 0;
    e1 = x and e2 = y where sin θi = 0 (normal incidence, the convention of the module docstring); e2 = r0 × e1.

    Parameters
    ----------
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    e1, e2, r0 : ndarray, shape (..., 3)
        Orthonormal axes of the specular-centred frame [-].
    """
    theta_i, phi_i = np.broadcast_arrays(_f64(theta_i), _f64(phi_i))
    r0 = specular_direction(theta_i, phi_i)
    az = phi_i - np.pi
    cos_t, sin_t = np.cos(theta_i), np.sin(theta_i)
    e1 = np.stack([-cos_t * np.cos(az), -cos_t * np.sin(az), sin_t], axis=-1)
    at_normal = (sin_t == 0.0)[..., None]
    e1 = np.where(at_normal, np.array([1.0, 0.0, 0.0]), e1)
    e2 = np.cross(r0, e1)
    e2 = np.where(at_normal, np.array([0.0, 1.0, 0.0]), e2)
    return e1, e2, r0


def specular_from_direction(
    direction: ArrayLike, theta_i: ArrayLike, phi_i: ArrayLike = np.pi
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(radial ∈ [0, π], azimuth ∈ [0, 2π)) of a unit vector about the specular direction, eq. (4).

    radial = atan2(|(ω·e1, ω·e2)|, ω·r0) (the angle between ω and r0, accurate at 0 and π);
    azimuth = atan2(ω·e2, ω·e1) mod 2π, 0 where radial is 0 or π. Azimuth 0 points from the specular
    direction toward the surface normal ([Zemax-BSDF]).

    Parameters
    ----------
    direction : array_like, shape (..., 3)
        Unit vector in the frame of its side [-].
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    radial : ndarray
        Angle between the vector and the specular direction, in [0, π] [rad].
    azimuth : ndarray
        Azimuth about the specular direction, in [0, 2π) [rad].
    """
    v = _f64(direction)
    e1, e2, r0 = specular_axes(theta_i, phi_i)
    x = np.sum(v * e1, axis=-1)
    y = np.sum(v * e2, axis=-1)
    z = np.sum(v * r0, axis=-1)
    s = np.hypot(x, y)
    radial = np.arctan2(s, z)
    azimuth = np.where(s > 0.0, _wrap_2pi(np.arctan2(y, x)), 0.0)
    return radial, azimuth


def direction_from_specular(
    radial: ArrayLike, azimuth: ArrayLike, theta_i: ArrayLike, phi_i: ArrayLike = np.pi
) -> NDArray[np.float64]:
    """Inverse of :func:`specular_from_direction`:
    ω = sin(radial) cos(azimuth) e1 + sin(radial) sin(azimuth) e2 + cos(radial) r0.

    The result may lie below the horizon (ω_z < 0) for large radial angles; callers that need the
    scattering hemisphere test ω_z themselves.

    Parameters
    ----------
    radial : float or ndarray
        Angle from the specular direction [rad].
    azimuth : float or ndarray
        Azimuth about the specular direction, 0 toward the normal [rad].
    theta_i : float or ndarray
        Angle of incidence from the sample normal [rad].
    phi_i : float or ndarray, optional
        Azimuth of the source in the sample frame [rad]; π (the instrument's) by default.

    Returns
    -------
    ndarray, shape (..., 3)
        Unit vector in the frame of its side [-].
    """
    radial, azimuth = _f64(radial), _f64(azimuth)
    e1, e2, r0 = specular_axes(theta_i, phi_i)
    sin_r = np.sin(radial)[..., None]
    return (
        sin_r * np.cos(azimuth)[..., None] * e1
        + sin_r * np.sin(azimuth)[..., None] * e2
        + np.cos(radial)[..., None] * r0
    )
