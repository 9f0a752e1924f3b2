"""Ray–cavity geometry (pure JAX functions on arrays of rays).

Frame (docs/tracer.md): cavity axis z; base z = 0 (normal +z into the cavity); wall r = R for 0 < z < H
(inward normal −(x, y, 0)/R); top z = H (cavity-side normal −z). Rays start inside and are traced from
surface to surface, so every ray has exactly one next hit.
"""
from __future__ import annotations

import jax.numpy as jnp

WALL, BASE, TOP = 0, 1, 2


def distances_to_surfaces(px, py, pz, dx, dy, dz, radius, height):
    """Distances t along (dx, dy, dz) from (px, py, pz) to the wall, base and top (∞ if not ahead).

    Wall: |p_xy + t d_xy|² = R² ⇔ A t² + 2B t + C = 0 with A = |d_xy|², B = p_xy·d_xy, C = |p_xy|² − R²
    (C ≤ 0 inside). The exit root is t = (−B + √(B² − AC))/A, evaluated as −C/(B + √(B² − AC)) when
    B > 0 to avoid cancellation. Planes: t = (H − z)/dz for dz > 0, t = −z/dz for dz < 0.

    Parameters
    ----------
    px, py, pz : jax.Array
        Ray positions in the cavity frame [mm].
    dx, dy, dz : jax.Array
        Unit ray directions [-].
    radius : float or jax.Array
        Cavity radius R [mm].
    height : float or jax.Array
        Cavity height H [mm].

    Returns
    -------
    t_wall, t_base, t_top : jax.Array
        Distances to the wall, the base and the top plane [mm]; ∞ where the surface is not ahead.
    """
    inf = jnp.asarray(jnp.inf, dtype=px.dtype)
    a = dx * dx + dy * dy
    b = px * dx + py * dy
    c = px * px + py * py - radius * radius
    sq = jnp.sqrt(jnp.maximum(b * b - a * c, 0.0))
    a_safe = jnp.where(a > 0, a, 1.0)
    t_wall = jnp.where(b > 0, -c / jnp.where(b + sq > 0, b + sq, 1.0), (sq - b) / a_safe)
    t_wall = jnp.where(a > 0, jnp.maximum(t_wall, 0.0), inf)
    dz_safe = jnp.where(dz != 0, dz, 1.0)
    t_top = jnp.where(dz > 0, (height - pz) / dz_safe, inf)
    t_base = jnp.where(dz < 0, -pz / dz_safe, inf)
    return t_wall, t_base, t_top


def next_hit(px, py, pz, dx, dy, dz, radius, height):
    """The next surface (WALL, BASE or TOP) and the hit point, snapped onto that surface.

    Parameters
    ----------
    px, py, pz : jax.Array
        Ray positions in the cavity frame [mm].
    dx, dy, dz : jax.Array
        Unit ray directions [-].
    radius : float or jax.Array
        Cavity radius R [mm].
    height : float or jax.Array
        Cavity height H [mm].

    Returns
    -------
    surface : jax.Array
        WALL, BASE or TOP (int32).
    x, y, z : jax.Array
        Hit point on that surface [mm].
    """
    t_wall, t_base, t_top = distances_to_surfaces(px, py, pz, dx, dy, dz, radius, height)
    on_top = t_top <= jnp.minimum(t_wall, t_base)
    on_base = (~on_top) & (t_base <= t_wall)
    on_wall = ~(on_top | on_base)
    t = jnp.where(on_top, t_top, jnp.where(on_base, t_base, t_wall))
    x = px + t * dx
    y = py + t * dy
    z = pz + t * dz
    r = jnp.sqrt(x * x + y * y)
    snap = jnp.where(on_wall & (r > 0), radius / jnp.where(r > 0, r, 1.0), 1.0)
    x = x * snap
    y = y * snap
    z = jnp.where(on_top, height, jnp.where(on_base, 0.0, jnp.clip(z, 0.0, height))).astype(px.dtype)
    surface = jnp.where(on_top, TOP, jnp.where(on_base, BASE, WALL)).astype(jnp.int32)
    return surface, x, y, z


def on_led(x, y, grid, pitch, emitter_radius):
    """True where (x, y) on the base lies on one of the k × k LED disks (nearest-centre test).

    Parameters
    ----------
    x, y : jax.Array
        Points on the base [mm].
    grid : int or jax.Array
        LEDs per side k [-].
    pitch : float or jax.Array
        LED centre spacing [mm].
    emitter_radius : float or jax.Array
        Radius of each LED disk [mm].

    Returns
    -------
    jax.Array
        Boolean, True on an LED disk.
    """
    half = (grid - 1) / 2.0
    ix = jnp.clip(jnp.round(x / pitch + half), 0, grid - 1)
    iy = jnp.clip(jnp.round(y / pitch + half), 0, grid - 1)
    cx = (ix - half) * pitch
    cy = (iy - half) * pitch
    return (x - cx) ** 2 + (y - cy) ** 2 <= emitter_radius * emitter_radius


def map_index(x, y, radius, bins):
    """Flat index iy·bins + ix of the square bin of side 2R/bins (over [−R, R]²) containing (x, y).

    Parameters
    ----------
    x, y : jax.Array
        Points [mm].
    radius : float or jax.Array
        Cavity radius R [mm].
    bins : int
        Bins per side of the map [-].

    Returns
    -------
    jax.Array
        Flat bin index (int32), clipped into the map.
    """
    ix = jnp.clip(jnp.floor((x + radius) / (2.0 * radius) * bins), 0, bins - 1).astype(jnp.int32)
    iy = jnp.clip(jnp.floor((y + radius) / (2.0 * radius) * bins), 0, bins - 1).astype(jnp.int32)
    return iy * bins + ix
