"""A plain vectorised NumPy tracer with the same physics as the JAX kernel (baseline and cross-check).

Same geometry, sampling formulas, implicit capture, plate rules (TIS linear in θi, clamped outside the
grid) and Russian roulette as :mod:`bsdfkit.raytrace.kernel`, written the obvious NumPy way: all live rays
of a batch advance one interaction per step and dead rays are compacted away. Random numbers come from
``numpy.random.Generator(PCG64(seed))`` in draw order, so results depend on the batch size (unlike the
kernel); the estimates agree with the kernel's within their standard errors.

Covered: LED-disk sources (Lambertian or cos^m), diffuse/specular cavity, exit, diffuser or phosphor top
with Lambertian plate distributions, roulette or threshold termination. Not covered (raises): ray-file
sources and Lambert+Gaussian or tabulated plate distributions.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from bsdfkit.core.errors import ValidationError
from bsdfkit.raytrace.effects import top_plate
from bsdfkit.raytrace.oracles.radiosity import require_two_colours
from bsdfkit.raytrace.plate import BIBS_R, BIBS_T, BIYS_R, BIYS_T, YIYS_R, YIYS_T, PlateTables, plate_tables
from bsdfkit.raytrace.scene import Leds, Scene, TraceOptions


@dataclass(frozen=True)
class ReferenceResult:
    """Powers as fractions of the emitted power, plus counts and timing."""

    rays: int
    extracted_blue: float
    extracted_yellow: float
    absorbed: dict
    roulette: float
    discarded: float
    truncated: float
    interactions: int
    elapsed_s: float
    se_LER: float

    @property
    def LER(self) -> float:
        return self.extracted_blue + self.extracted_yellow

    @property
    def ledger_error(self) -> float:
        total = (self.extracted_blue + self.extracted_yellow + sum(self.absorbed.values()) + self.roulette
                 + self.discarded + self.truncated)
        return abs(1.0 - total)

    @property
    def interactions_per_s(self) -> float:
        return self.interactions / self.elapsed_s


def _onb(nx, ny, nz):
    sign = np.where(nz >= 0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


def trace_numpy(scene: Scene, rays: int, seed: int = 0, batch: int = 100_000) -> ReferenceResult:
    """Trace ``rays`` rays through ``scene`` with NumPy (see module docstring).

    Parameters
    ----------
    scene : Scene
        A two-colour scene with LED disks and an exit, Lambertian or Lambertian-plate top.
    rays : int
        Number of rays to trace.
    seed : int
        Seed of NumPy's PCG64 generator.
    batch : int
        Rays traced per vectorised batch.

    Returns
    -------
    ReferenceResult
        The tallies as fractions of the emitted power [-], and the run time.
    """
    require_two_colours(scene, "the NumPy reference")
    if scene.leds.ray_file is not None:
        raise ValidationError("the NumPy reference does not read ray files", field="leds.ray_file",
                              expected="LED disks", got=scene.leds.ray_file)
    tab = None
    if scene.top.kind != "exit":
        tab = plate_tables(top_plate(scene))
        if tab.has_lobe or tab.has_table:
            raise ValidationError("the NumPy reference samples Lambertian plate distributions only",
                                  field="top.plate", expected="lambertian distributions", got="lobe/tabulated")
    rng = np.random.Generator(np.random.PCG64(seed))
    sums = dict(eb=0.0, ey=0.0, wall=0.0, base=0.0, leds=0.0, plate=0.0, rr=0.0, disc=0.0, trunc=0.0)
    s1 = s2 = 0.0
    interactions = 0
    t0 = time.perf_counter()
    done = 0
    while done < rays:
        n = min(batch, rays - done)
        done += n
        ext, count = _trace_batch(scene, tab, rng, n, sums)
        interactions += count
        s1 += ext.sum()
        s2 += (ext * ext).sum()
    elapsed = time.perf_counter() - t0
    nr = rays
    se = math.sqrt(max(s2 / nr - (s1 / nr) ** 2, 0.0) / max(nr - 1, 1))
    return ReferenceResult(
        rays=rays, extracted_blue=sums["eb"] / nr, extracted_yellow=sums["ey"] / nr,
        absorbed={"wall": sums["wall"] / nr, "base": sums["base"] / nr, "leds": sums["leds"] / nr,
                  "plate": sums["plate"] / nr},
        roulette=sums["rr"] / nr, discarded=sums["disc"] / nr, truncated=sums["trunc"] / nr,
        interactions=interactions, elapsed_s=elapsed, se_LER=se,
    )


def _trace_batch(scene: Scene, tab: PlateTables | None, rng: np.random.Generator, n: int,
                 sums: dict[str, float]) -> tuple[np.ndarray, int]:
    """Emit ``n`` rays and follow them until every one ends, adding to ``sums``: returns each ray's extracted
    weight and the number of interactions."""
    x, y, z, dx, dy, dz = _emit(rng, scene.leds, n)
    w = np.ones(n)
    colour = np.zeros(n, dtype=np.int8)
    events = np.zeros(n, dtype=np.int64)
    ext = np.zeros(n)  # per-ray extracted, for the standard error
    idx = np.arange(n)
    interactions = 0
    led = scene.led_surface  # wall, base, LED surface: reflectance and specular fraction by surface index
    rho = np.array([scene.wall.reflectance, scene.base.reflectance, led.reflectance])
    specular = np.array([scene.wall.specular_fraction, scene.base.specular_fraction, led.specular_fraction])
    while idx.size:
        interactions += idx.size
        x, y, z, on_top, on_base, on_wall, on_led = _next_surface((x, y, z), (dx, dy, dz), scene)
        cav = ~on_top
        # cavity reflection
        surf = np.where(on_wall, 0, np.where(on_led, 2, 1))
        w_ref = w * rho[surf]
        absorbed = np.where(cav, w - w_ref, 0.0)
        sums["wall"] += absorbed[on_wall].sum()
        sums["base"] += absorbed[on_base & ~on_led].sum()
        sums["leds"] += absorbed[on_led].sum()
        u = rng.random((4, idx.size))
        ndx, ndy, ndz = _reflect(x, y, (dx, dy, dz), cav & (u[0] < specular[surf]), on_wall, u, scene.cavity.radius_mm)
        new_w = np.where(cav, w_ref, 0.0)
        alive = cav.copy()
        if tab is None:
            e = np.where(on_top, w, 0.0)
            ext[idx] += e
            sums["eb"] += e.sum()
        else:
            w_out, forward, new_col = _plate(tab, dz, w, colour, u[0])
            sums["plate"] += np.where(on_top, w - w_out, 0.0).sum()
            e = np.where(on_top & forward, w_out, 0.0)
            ext[idx] += e
            sums["eb"] += e[new_col == 0].sum()
            sums["ey"] += e[new_col == 1].sum()
            back = on_top & ~forward & (w_out > 0)
            colour = np.where(on_top, new_col, colour)
            new_w = np.where(back, w_out, new_w)
            alive |= back
            st, ct, ph = np.sqrt(u[1]), np.sqrt(1.0 - u[1]), 2 * np.pi * u[2]
            ndx = np.where(on_top, st * np.cos(ph), ndx)
            ndy = np.where(on_top, st * np.sin(ph), ndy)
            ndz = np.where(on_top, -ct, ndz)
        alive &= new_w > 0
        events[idx] += 1
        new_w, alive = _terminate(scene.trace, new_w, alive, u[3], events[idx], sums)
        keep = np.flatnonzero(alive)
        idx = idx[keep]
        x, y, z, w, colour = x[keep], y[keep], z[keep], new_w[keep], colour[keep]
        dx, dy, dz = ndx[keep], ndy[keep], ndz[keep]
    return ext, interactions


def _emit(rng: np.random.Generator, leds: Leds, n: int) -> tuple[np.ndarray, ...]:
    """Start points and directions of ``n`` rays from the LED disks (cos^m θ intensity)."""
    centres = np.asarray(leds.centres())
    m = leds.cos_exponent
    i = rng.integers(0, centres.shape[0], n)
    r = leds.emitter_radius_mm * np.sqrt(rng.random(n))
    phi = 2 * np.pi * rng.random(n)
    x = centres[i, 0] + r * np.cos(phi)
    y = centres[i, 1] + r * np.sin(phi)
    z = np.zeros(n)
    cos_t = (1.0 - rng.random(n)) ** (1.0 / (m + 1.0))
    sin_t = np.sqrt(np.maximum(1.0 - cos_t ** 2, 0.0))
    psi = 2 * np.pi * rng.random(n)
    return x, y, z, sin_t * np.cos(psi), sin_t * np.sin(psi), cos_t


def _next_surface(position: tuple[np.ndarray, ...], direction: tuple[np.ndarray, ...], scene: Scene):
    """The point where each ray meets the cavity next and masks of the surface: (x, y, z, top, base, wall, LED)."""
    (x, y, z), (dx, dy, dz) = position, direction
    R, H = scene.cavity.radius_mm, scene.cavity.height_mm
    leds = scene.leds
    k = leds.grid
    a = dx * dx + dy * dy
    b = x * dx + y * dy
    c = x * x + y * y - R * R
    sq = np.sqrt(np.maximum(b * b - a * c, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_wall = np.where(b > 0, -c / (b + sq), (sq - b) / a)
        t_wall = np.where(a > 0, np.maximum(t_wall, 0.0), np.inf)
        t_top = np.where(dz > 0, (H - z) / dz, np.inf)
        t_base = np.where(dz < 0, -z / dz, np.inf)
    on_top = t_top <= np.minimum(t_wall, t_base)
    on_base = ~on_top & (t_base <= t_wall)
    on_wall = ~(on_top | on_base)
    t = np.where(on_top, t_top, np.where(on_base, t_base, t_wall))
    x, y, z = x + t * dx, y + t * dy, z + t * dz
    rr = np.hypot(x, y)
    snap = np.where(on_wall & (rr > 0), R / np.where(rr > 0, rr, 1.0), 1.0)
    x, y = x * snap, y * snap
    z = np.where(on_top, H, np.where(on_base, 0.0, np.clip(z, 0.0, H)))
    half = (k - 1) / 2.0
    cx = (np.clip(np.round(x / leds.pitch_mm + half), 0, k - 1) - half) * leds.pitch_mm
    cy = (np.clip(np.round(y / leds.pitch_mm + half), 0, k - 1) - half) * leds.pitch_mm
    on_led = on_base & ((x - cx) ** 2 + (y - cy) ** 2 <= leds.emitter_radius_mm ** 2)
    return x, y, z, on_top, on_base, on_wall, on_led


def _reflect(x, y, direction: tuple[np.ndarray, ...], mirror, on_wall, u, R: float) -> tuple[np.ndarray, ...]:
    """Directions after a cavity reflection at (x, y): Lambertian (uniforms 1, 2) about the normal, or the mirror
    direction where ``mirror``."""
    dx, dy, dz = direction
    nx = np.where(on_wall, -x / R, 0.0)
    ny = np.where(on_wall, -y / R, 0.0)
    nz = np.where(on_wall, 0.0, 1.0)
    st, ct, ph = np.sqrt(u[1]), np.sqrt(1.0 - u[1]), 2 * np.pi * u[2]
    (t1x, t1y, t1z), (t2x, t2y, t2z) = _onb(nx, ny, nz)
    lx, ly = st * np.cos(ph), st * np.sin(ph)
    ndx = lx * t1x + ly * t2x + ct * nx
    ndy = lx * t1y + ly * t2y + ct * ny
    ndz = lx * t1z + ly * t2z + ct * nz
    kk = 2.0 * (dx * nx + dy * ny + dz * nz)
    ndx = np.where(mirror, dx - kk * nx, ndx)
    ndy = np.where(mirror, dy - kk * ny, ndy)
    ndz = np.where(mirror, dz - kk * nz, ndz)
    return ndx, ndy, ndz


def _plate(tab: PlateTables, dz, w, colour, u0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plate channel of every ray as if it met the plate (uniform ``u0``; the caller keeps those that do):
    the weight kept, forward, and the new colour."""
    theta = np.arccos(np.clip(dz, 0.0, 1.0))
    g = tab.grid
    thc = np.clip(theta, g[0], g[-1])
    j = np.clip(np.searchsorted(g, thc, side="right") - 1, 0, g.size - 2)
    tt = (thc - g[j]) / (g[j + 1] - g[j])
    tis = (1 - tt)[:, None] * tab.tis[j] + tt[:, None] * tab.tis[j + 1]
    yellow = colour == 1
    probs = np.stack([np.where(yellow, tis[:, YIYS_R], tis[:, BIBS_R]),
                      np.where(yellow, tis[:, YIYS_T], tis[:, BIBS_T]),
                      np.where(yellow, 0.0, tis[:, BIYS_R]), np.where(yellow, 0.0, tis[:, BIYS_T])])
    S = probs.sum(axis=0)
    v = u0 * S
    cum = np.cumsum(probs, axis=0)
    outcome = (v >= cum[0]).astype(int) + (v >= cum[1]) + (v >= cum[2])
    return w * S, outcome % 2 == 1, np.where(yellow | (outcome >= 2), 1, 0).astype(np.int8)


def _terminate(trace: TraceOptions, new_w, alive, u3, events, sums: dict[str, float]):
    """Roulette (uniform ``u3``) or threshold, then the event cap; returns the weights and which rays live on."""
    if trace.termination == "roulette":
        tau = trace.roulette_threshold
        low = alive & (new_w < tau)
        survive = u3 * tau < new_w
        killed = low & ~survive
        sums["rr"] += np.where(killed, new_w, np.where(low, new_w - tau, 0.0)).sum()
        new_w = np.where(low, np.where(survive, tau, 0.0), new_w)
        alive &= ~killed
    else:
        low = alive & (new_w < trace.threshold)
        sums["disc"] += new_w[low].sum()
        alive &= ~low
    capped = alive & (events >= trace.max_events)
    sums["trunc"] += new_w[capped].sum()
    return new_w, alive & ~capped
