"""Synthetic BSDF tables with exact hemispherical truth, in the sampling geometries instruments write.

Truth: f(β) = ρ/π (1 − b|β|²)(1 + a cos 2φ) + A exp(−Δx²/2σx² − Δy²/2σy²), Δ = β − (sin θi, 0), φ the azimuth of β
about the normal. The body integrates to ρ(1 − b/2) exactly (the cos 2φ term to 0); the lobe's integral over the
unit disk is computed on a fine polar grid about its centre (Gauss–Legendre in r: converged to 1e-10 for these
widths). Angles in degrees; the source at φi = 180°, so the specular direction is at φs = 0.

An off-axis lobe (a tilted or misaligned sample, an oblique grating order): the lobe's centre is moved from the
specular point by (``dx``, ``dy``) [direction cosines], then centre and axes are turned about the normal by ``phi_c``
[deg], and the axes about the centre by ``rot`` [deg]; Δ is then measured along the lobe's own axes. The defaults
(all 0) are the lobe about the specular point with axes along and across the plane of incidence.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from bsdfkit.measurement.table import RecordDirections, RecordsOrigin, records_dataset
from bsdfkit.reduction.tis import polar_grid


@dataclass(frozen=True)
class Truth:
    rho: float = 0.6
    b: float = 0.3
    a: float = 0.0  # anisotropy of the body (cos 2φ)
    A: float = 3.0  # lobe peak [1/sr]
    sx: float = 0.06  # lobe widths [direction cosines]
    sy: float = 0.06
    phi_c: float = 0.0  # azimuth [deg] by which the lobe (centre and axes) is turned about the normal
    dx: float = 0.0  # offset of the lobe's centre from the specular point [direction cosines], before phi_c
    dy: float = 0.0
    rot: float = 0.0  # rotation [deg] of the lobe's axes about its centre (after phi_c)

    def center(self, theta_i: float) -> tuple[float, float]:
        """The lobe's centre (βx, βy) [direction cosines]."""
        u, v = float(np.sin(np.radians(theta_i))) + self.dx, self.dy
        c, s = np.cos(np.radians(self.phi_c)), np.sin(np.radians(self.phi_c))
        return c * u - s * v, s * u + c * v

    def lobe(self, theta_i: float, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        """The lobe alone [1/sr] at β = (bx, by)."""
        cx, cy = self.center(theta_i)
        t = np.radians(self.phi_c + self.rot)
        ex, ey = bx - cx, by - cy
        dx, dy = np.cos(t) * ex + np.sin(t) * ey, -np.sin(t) * ex + np.cos(t) * ey
        return self.A * np.exp(-dx * dx / (2 * self.sx ** 2) - dy * dy / (2 * self.sy ** 2))

    def f(self, theta_i: float, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        r2 = bx * bx + by * by
        phi = np.arctan2(by, bx)
        body = self.rho / np.pi * (1 - self.b * r2) * (1 + self.a * np.cos(2 * phi))
        return body + self.lobe(theta_i, bx, by)

    @functools.cache  # noqa: B019 (a frozen truth: asked for again by many tests)
    def tis(self, theta_i: float) -> float:
        # 1024 x 600 nodes: within 5e-14 of a 2048 x 1200 grid (4x the cost) for every truth of the tests, lobes
        # 0.02-0.15 wide, at 0-89 deg; 512 x 400 is 1.6e-9 off
        x0, y0 = self.center(theta_i)
        g = polar_grid((x0, y0), 1024, 600)
        bx, by = x0 + g.r * np.cos(g.psi), y0 + g.r * np.sin(g.psi)
        return self.rho * (1 - self.b / 2) + float(g.w @ self.lobe(theta_i, bx, by))


def _circle(theta_i: float, chi_deg: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """(θs, φs) along the great circle through the specular direction, rotated by χ about it (χ = 0: in-plane)."""
    ti = np.radians(theta_i)
    s0 = np.array([np.sin(ti), 0.0, np.cos(ti)])
    e1 = np.array([np.cos(ti), 0.0, -np.sin(ti)])
    e2 = np.array([0.0, 1.0, 0.0])
    e = np.cos(np.radians(chi_deg)) * e1 + np.sin(np.radians(chi_deg)) * e2
    t = np.radians(np.arange(-180.0, 180.0, step))
    d = np.cos(t)[:, None] * s0 + np.sin(t)[:, None] * e
    d = d[d[:, 2] > np.cos(np.radians(88.0))]
    th = np.degrees(np.arccos(np.clip(d[:, 2], -1, 1)))
    ph = np.mod(np.degrees(np.arctan2(d[:, 1], d[:, 0])), 360.0)
    return th, np.where(th < 1e-9, 0.0, ph)


def directions(geometry: str, theta_i: float, *, c_step: float = 30.0, c_offset: float = 0.0,
               theta_step: float = 2.5, theta_max: float = 85.0, grid_step: tuple[float, float] = (5.0, 10.0),
               patch: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(θs, φs) [deg] of one geometry: grid, cplanes, multiplane, one_arc, two_arcs, phi90.

    The keywords change the layout (their defaults are the layouts the existing tests use): ``c_step`` [deg], the
    azimuth between C-planes (a divisor of 180), ``c_offset`` [deg] the first plane's azimuth, ``theta_step`` and
    ``theta_max`` [deg] the polar step and last θs of a C-plane; ``grid_step`` [deg] the (θs, φs) steps of a grid,
    ``patch`` its fine patch about the specular point.
    """
    if geometry == "grid":  # θs × φs, the nadir once per azimuth, finer near specular
        th, ph = np.meshgrid(np.arange(0.0, 86.0, grid_step[0]), np.arange(0.0, 360.0, grid_step[1]), indexing="ij")
        th, ph = th.ravel(), ph.ravel()
        if not patch:
            keep = np.unique(np.round(np.stack([th, np.where(th == 0, -1, ph)], 1), 6), axis=0, return_index=True)[1]
            return th[np.sort(keep)], ph[np.sort(keep)]
        # a patch of 0.015 steps in direction cosines (about 0.9 deg) within 0.15 of the specular point
        px, py = np.meshgrid(np.arange(-10, 11) * 0.015, np.arange(-10, 11) * 0.015, indexing="ij")
        bx, by = px.ravel() + np.sin(np.radians(theta_i)), py.ravel()
        ok = (np.hypot(bx, by) < np.sin(np.radians(85.0))) & (np.hypot(bx, by) > 1e-9)
        th = np.concatenate([th, np.degrees(np.arcsin(np.hypot(bx[ok], by[ok])))])
        ph = np.concatenate([ph, np.mod(np.degrees(np.arctan2(by[ok], bx[ok])), 360.0)])
        key = np.unique(np.round(np.stack([th, np.where(th == 0, -1, ph)], 1), 6), axis=0, return_index=True)[1]
        keep = np.sort(np.concatenate([key, np.flatnonzero(th == 0)]))
        keep = np.unique(keep)
        return th[keep], ph[keep]
    if geometry == "cplanes":  # planes through the normal at C = 0, 30, ..., 150 deg, the nadir in every plane
        g = np.arange(-theta_max, theta_max + 0.1 * theta_step, theta_step)
        planes = c_offset + np.arange(0.0, 180.0 - 1e-9, c_step)
        th = np.concatenate([np.abs(g) for _ in planes])
        ph = np.concatenate([np.where(g >= 0, c, c + 180.0) for c in planes])
        return th, np.mod(ph, 360.0)
    if geometry == "multiplane":  # planes through the specular direction at χ = 0, 45, 90, 135 deg
        parts = [_circle(theta_i, chi, 2.5) for chi in (0.0, 45.0, 90.0, 135.0)]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    if geometry == "one_arc":
        g = np.arange(-85.0, 85.1, 2.5)
        return np.abs(g), np.where(g >= 0, 0.0, 180.0)
    if geometry == "two_arcs":
        a = directions("one_arc", theta_i)
        p = _circle(theta_i, 90.0, 2.5)
        return np.concatenate([a[0], p[0]]), np.concatenate([a[1], p[1]])
    if geometry == "phi90":  # the in-plane arc plus a φs = 90/270 deg arc through the normal
        a = directions("one_arc", theta_i)
        g = np.arange(-85.0, 85.1, 5.0)
        g = g[g != 0]
        return np.concatenate([a[0], np.abs(g)]), np.concatenate([a[1], np.where(g > 0, 90.0, 270.0)])
    raise ValueError(geometry)


def table(truth: Truth, geometry: str, incidences: tuple[float, ...], side: str = "reflection",
          relative_std: float = 0.01, noise: float = 0.0, seed: int = 0, **layout):
    """A one-wavelength (550 nm) dataset of ``truth`` sampled in ``geometry`` at ``incidences`` (``layout``: the
    keywords of :func:`directions`)."""
    rng = np.random.default_rng(seed)
    ti, th, ph = [], [], []
    for t in incidences:
        a, b = directions(geometry, t, **layout)
        ti += [t] * a.size
        th.append(a)
        ph.append(b)
    th, ph, ti = np.concatenate(th), np.concatenate(ph), np.asarray(ti)
    bx = np.sin(np.radians(th)) * np.cos(np.radians(ph))
    by = np.sin(np.radians(th)) * np.sin(np.radians(ph))
    f = np.array([truth.f(t, x, y) for t, x, y in zip(ti, bx, by)])
    f = f * (1 + noise * rng.standard_normal(f.size))
    return records_dataset(RecordDirections(ti, np.full(ti.size, 180.0), th, ph, [side] * ti.size), [550.0],
                           f[:, None], relative_std * np.abs(f)[:, None], RecordsOrigin(f"synthetic-{geometry}"))
