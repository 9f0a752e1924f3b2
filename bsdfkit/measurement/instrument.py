"""Goniometer geometry: detector solid angle and aperture quadrature.

The detector is a circular aperture of radius ``a`` at distance ``d`` from the sample (§2 of the power-budget
paper, [Power-budget]: a ≤ 12.7 mm, d = 886 mm). A beam that is wholly inside the detector's field of view is
assumed ("over-filled field of view"), so BSDF = P_s / (P_i Ω cos θs) holds ([ASTM-E2387]; why, in
docs/raw-format.md "Measurement equation").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.quadrature import gauss_legendre


@dataclass(frozen=True)
class Instrument:
    """Geometry of a goniometer's detection arm (lengths in mm)."""

    detector_distance_mm: float
    aperture_diameter_mm: float
    beam_diameter_mm: float

    def __post_init__(self) -> None:
        for name in ("detector_distance_mm", "aperture_diameter_mm", "beam_diameter_mm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValidationError("instrument geometry must be positive and finite", field=name,
                                      expected="a positive number of mm", got=value)
        if self.aperture_diameter_mm >= 2 * self.detector_distance_mm:
            raise ValidationError("aperture too large for its distance", field="aperture_diameter_mm",
                                  expected="diameter < 2 × detector distance", got=self.aperture_diameter_mm)

    @property
    def solid_angle_sr(self) -> float:
        """Exact solid angle of the aperture seen from the sample, sr."""
        return float(aperture_solid_angle(self.detector_distance_mm, self.aperture_diameter_mm / 2))

    @property
    def half_angle_rad(self) -> float:
        """Half-angle subtended by the aperture, rad: atan(a/d)."""
        return float(np.arctan2(self.aperture_diameter_mm / 2, self.detector_distance_mm))


def aperture_solid_angle(distance: ArrayLike, radius: ArrayLike) -> NDArray[np.float64]:
    """Exact solid angle of a circular aperture of radius ``a`` on axis at distance ``d``.

    Ω = 2π(1 − cos(atan(a/d))) = 2π(1 − d/√(d² + a²)), written as 2π a² / (√(d²+a²)(√(d²+a²) + d))
    to avoid cancellation for small a/d (docs/raw-format.md "Measurement equation"). Units: sr; ``d`` and
    ``a`` in the same unit.

    Parameters
    ----------
    distance : float or array_like
        Distance ``d`` from the sample to the aperture, on its axis [mm] (any length unit, that of ``radius``).
    radius : float or array_like
        Aperture radius ``a`` [mm] (the unit of ``distance``).

    Returns
    -------
    ndarray
        Solid angle Ω [sr], broadcast over ``distance`` and ``radius``.
    """
    d = np.asarray(distance, dtype=np.float64)
    a = np.asarray(radius, dtype=np.float64)
    r = np.hypot(d, a)
    return 2.0 * np.pi * a * a / (r * (r + d))


def aperture_solid_angle_small(distance: ArrayLike, radius: ArrayLike) -> NDArray[np.float64]:
    """Small-angle form Ω ≈ π a²/d²; over-estimates the exact Ω by ≈ (3/4)(a/d)² relative.

    Parameters
    ----------
    distance : float or array_like
        Distance ``d`` from the sample to the aperture, on its axis [mm] (any length unit, that of ``radius``).
    radius : float or array_like
        Aperture radius ``a`` [mm] (the unit of ``distance``).

    Returns
    -------
    ndarray
        Approximate solid angle Ω [sr], broadcast over ``distance`` and ``radius``.
    """
    d = np.asarray(distance, dtype=np.float64)
    a = np.asarray(radius, dtype=np.float64)
    return np.pi * a * a / (d * d)


def sample_direction(theta: ArrayLike, phi: ArrayLike) -> NDArray[np.float64]:
    """Unit vector (sinθ cosφ, sinθ sinφ, cosθ) for angles in radians; shape (..., 3).

    Parameters
    ----------
    theta : float or array_like
        Polar angle from the sample normal (z) [rad].
    phi : float or array_like
        Azimuth from x [rad]; broadcast with ``theta``.

    Returns
    -------
    ndarray
        Unit direction vectors [-], shape ``broadcast(theta, phi).shape + (3,)``.
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(phi, dtype=np.float64))
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


@dataclass(frozen=True)
class ApertureQuadrature:
    """Nodes on the detector aperture as directions, with solid-angle weights summing to Ω.

    ``directions`` has shape (..., n_nodes, 3) in the frame of the scattering hemisphere (z = normal on the
    detector's side); ``weights`` (n_nodes,) in sr.
    """

    directions: NDArray[np.float64]
    weights: NDArray[np.float64]


def aperture_quadrature(
    theta_s: ArrayLike, phi_s: ArrayLike, instrument: Instrument, n_radial: int = 4, n_azimuth: int = 12
) -> ApertureQuadrature:
    """Directions through a polar Gauss–Legendre grid on the aperture disk, for detector centres (θs, φs).

    A point at radius ρ, angle ψ on the aperture plane (distance d, normal = centre direction) is seen in
    direction (d·ĉ + ρ cosψ û + ρ sinψ v̂)/r with r = √(d² + ρ²) and solid-angle element dΩ = d dA / r³,
    so Σ w = 2π(1 − d/√(d²+a²)) = Ω up to quadrature error (≈1e-12 with the defaults). Angles in radians.

    Parameters
    ----------
    theta_s : float or array_like
        Polar angle of each detector centre from the sample normal [rad].
    phi_s : float or array_like
        Azimuth of each detector centre [rad]; broadcast with ``theta_s``.
    instrument : Instrument
        Detector distance and aperture diameter [mm].
    n_radial : int, optional
        Gauss–Legendre nodes along the aperture radius.
    n_azimuth : int, optional
        Equally spaced nodes in azimuth on the aperture.

    Returns
    -------
    ApertureQuadrature
        ``directions`` (..., n_radial·n_azimuth, 3) unit vectors [-] and ``weights`` (n_radial·n_azimuth,)
        [sr], the same for every centre.
    """
    d = instrument.detector_distance_mm
    a = instrument.aperture_diameter_mm / 2
    x, wx = gauss_legendre(n_radial)
    rho = 0.5 * a * (x + 1.0)
    w_rho = 0.5 * a * wx * rho  # ρ dρ
    psi = (np.arange(n_azimuth) + 0.5) * (2 * np.pi / n_azimuth)
    rr, pp = np.meshgrid(rho, psi, indexing="ij")
    ww = np.broadcast_to(w_rho[:, None] * (2 * np.pi / n_azimuth), rr.shape)
    r = np.hypot(d, rr)
    weights = (ww * d / r**3).ravel()

    centre = sample_direction(theta_s, phi_s)
    # Orthonormal basis perpendicular to each centre direction; e_theta / e_phi are smooth except at the
    # pole, where any perpendicular pair is fine.
    theta = np.asarray(theta_s, dtype=np.float64)
    phi = np.asarray(phi_s, dtype=np.float64)
    e_theta = np.stack([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), -np.sin(theta)], axis=-1)
    e_phi = np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=-1)
    off_u = (rr * np.cos(pp)).ravel()
    off_v = (rr * np.sin(pp)).ravel()
    vec = (d * centre[..., None, :] + off_u[:, None] * e_theta[..., None, :]
           + off_v[:, None] * e_phi[..., None, :])
    vec /= np.linalg.norm(vec, axis=-1, keepdims=True)
    return ApertureQuadrature(directions=vec, weights=weights)
