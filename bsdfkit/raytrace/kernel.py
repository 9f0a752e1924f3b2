"""The Monte Carlo kernel: trace one chunk of rays through the cavity (JAX, specialised by :class:`Effects`).

Algorithm (the ray-level form of Fig. 6 of the cylindrical-module paper, [Cylindrical-module]), batch-synchronous
over wide lanes: a call emits its whole chunk (vectorised), then each ``lax.while_loop`` iteration (1) refills
empty lanes with the next emitted rays, (2) applies ``substeps`` interactions to every lane (move to the next
surface, interact), (3) retires finished rays by adding their per-ray tallies to exact fixed-point sums
(below). When the chunk is exhausted and few lanes are live, the live lanes are compacted into a narrower
state for the tail. Because every random number is keyed by (seed, ray, event) (:mod:`bsdfkit.raytrace.sampling`),
results do not depend on ``lanes``, ``substeps``, the chunk size or the device a chunk runs on.

Weights. A ray is emitted with weight 1 (one ray's share of the source power). At a cavity surface of
reflectance ρ the weight becomes wρ and w − wρ is tallied as absorbed by that surface ("implicit capture").
At a plate the channel is drawn with probabilities TIS_c/S (S = sum of the TIS of the ray's colour at its
incidence), the weight becomes wS and w − wS is tallied as absorbed by the plate; a forward channel is
tallied as extracted (blue or yellow) and ends the ray. At an exit top the whole weight is extracted.

Termination. ``roulette``: when w < τ (``roulette_threshold``) the ray survives with probability p = w/τ
and then carries w = τ; the tally ``roulette`` collects w for a killed ray and −(τ − w) for a survivor,
whose expectation is zero (unbiased). ``threshold``: the paper's flux threshold Th applied per ray: when
w < Th the ray is dropped and w is tallied as ``discarded`` (biased low). A ray still live after
``max_events`` interactions is retired with its weight tallied as ``truncated``. Per ray therefore
1 = extracted + absorbed + roulette + discarded + truncated, up to float64 rounding.

Plate rules. θi = arccos(dz) of the ray meeting the plate. Outside the plate's measured grid θi is clamped to
the nearest measured incidence (counted when ``plate_clamp``). TIS are interpolated linearly in θi between
grid points j, j+1 (weight t). The angular distribution of the chosen backward channel c is that of grid
point j with probability (1 − t)TIS_c,j / ((1 − t)TIS_c,j + t·TIS_c,j+1), else of j+1, which is linear
interpolation of the BSDF in θi. Within a Lambert+Gaussian distribution the lobe is chosen with its
TIS share A·L/(ρ + A·L) at the grid incidence (L the lobe's integral over the unit disk), with
β0 = (dx, dy) (the specular direction's tangential part, |β0| = sin θi); lobe samples outside the unit
disk are redrawn. Forward channels end the ray outside the module, so their directions are not sampled.

Spectral mode (``effects.spectral``, :mod:`bsdfkit.raytrace.spectral`). ``colour`` is a wavelength bin k of the
plate spectral model's grid, drawn at emission from the LED's bin powers. At the plate the channel (elastic R/T,
converted R/T) is drawn with probabilities ∝ the photons each gives out per incident photon (interpolated
linearly in θi like the TIS above), the weight becomes wS (S their sum ≤ 1) and a conversion draws the new bin from
the alias table of the emission row of k and scales the weight by λ_k/λ_new: the photon keeps its number, and
wS − w_out is tallied as the Stokes loss (net: an anti-Stokes conversion, within the thermal tail of the
emission table, adds a negative term; the photons converted, those converted to a shorter bin and the power the
latter created are tallied on their own, outside the ledgers). Every loss is also tallied in photons (weight ×
λ/λ_max of the bin the ray has at that moment); a ray's extracted weight is deposited into its bin's spectrum
sums when it retires.
Per ray 1 = extracted + absorbed + stokes + roulette + discarded + truncated in power, and the same without the
Stokes term in photons.

Sums. When a ray retires, its per-ray tallies x (float64, in ray weights; only the columns the effects can
fill) are rounded to integers X = rint(x·2⁴⁰) (its squares/products for the standard errors to rint(x²·2³²)),
split exactly into 31-bit limbs X = hi·2³¹ + lo (both integer-valued doubles, |hi|, lo < 2³¹), summed over
the lanes in float64 (every partial sum an integer below 2⁵³, so exact in any order) and added to int64
totals. All of this is exact integer arithmetic: the totals do not depend on lanes, chunking or order, and
a trace is bit-for-bit reproducible for any chunk size. (float64 limbs rather than int64 because XLA:CPU
has no vectorised float → int64 conversion.) The rounding is ≤ 2⁻⁴¹ ≈ 4.5·10⁻¹³ of a ray weight per tally,
far below the 10⁻⁹ ledger tolerance.
Array tallies (map, histogram, budget) are int64 fixed point in units of 2⁻³² ray weights per deposit,
likewise exact. Magnitudes: |x| ≤ 1 + τ·max_events (roulette adds at most τ per event), required < 2¹⁵
(checked by the tracer), so |X| < 2⁶² for sums and squares.
"""
from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from bsdfkit.raytrace import geometry, sampling
from bsdfkit.raytrace.effects import SURFACE_BASE, SURFACE_LEDS, SURFACE_WALL, Effects, KernelParams, PlateParams
from bsdfkit.raytrace.plate import (
    BACK_BIBS,
    BACK_BIYS,
    BACK_YIYS,
    BIBS_R,
    BIBS_T,
    BIYS_R,
    BIYS_T,
    CHANNELS,
    TABULATED,
    YIYS_R,
    YIYS_T,
)
from bsdfkit.raytrace.spectral import (
    BAND_BLUE,
    BAND_OTHER,
    BAND_YELLOW,
    CONVERTED_R,
    CONVERTED_T,
    ELASTIC_R,
    ELASTIC_T,
    PHOTON_CHANNELS,
)

# per-ray float64 tallies, accumulated in lanes and summed when the ray retires
COLUMNS = ("extracted_blue", "extracted_yellow", "absorbed_wall", "absorbed_base", "absorbed_leds",
           "absorbed_plate", "roulette", "discarded", "truncated",
           # spectral mode only: power extracted outside both bands, Stokes loss, and the ledger in photons
           "extracted_other", "stokes", "photons_extracted", "photons_wall", "photons_base", "photons_leds",
           "photons_plate", "photons_roulette", "photons_discarded", "photons_truncated",
           # spectral plate only, outside the ledgers: photons converted, of them to a shorter wavelength than they
           # were absorbed at (anti-Stokes), and the power those anti-Stokes conversions created (≥ 0)
           "photons_converted", "photons_anti_stokes", "anti_stokes_gain")
EXT_B, EXT_Y, ABS_WALL, ABS_BASE, ABS_LED, ABS_PLATE, ROULETTE, DISCARDED, TRUNCATED = range(9)
(EXT_O, STOKES, PH_EXT, PH_WALL, PH_BASE, PH_LED, PH_PLATE, PH_ROULETTE, PH_DISCARDED,
 PH_TRUNCATED, PH_CONVERTED, PH_ANTI_STOKES, ANTI_STOKES_GAIN) = range(9, len(COLUMNS))
#: the power ledger's columns (the photon columns close their own ledger)
POWER_COLUMNS = COLUMNS[:11]
#: ray colours of the two-wavelength mode (the spectral mode's colour is a wavelength bin)
BLUE, YELLOW = 0, 1
# per-ray integer counters
COUNTERS = ("interactions", "plate_interactions", "clamped")
CNT_EVENTS, CNT_PLATE, CNT_CLAMP = range(len(COUNTERS))
# per-ray products summed for standard errors (pairs of COLUMNS indices; "total" is blue + yellow)
SQUARES = ("total", "blue", "yellow", "blue_yellow", "absorbed_wall", "absorbed_base", "absorbed_leds",
           "absorbed_plate")
# interaction-budget columns
BUDGET_COLUMNS = ("extracted_blue", "extracted_yellow", "absorbed_cavity", "absorbed_plate", "other")
#: fixed-point scales: per-ray tallies (2⁻⁴⁰ ray weights), their squares (2⁻³²) and array tallies (2⁻³²)
SCALE_SUM = 2.0 ** 40
SCALE_SQUARE = 2.0 ** 32
FIXED_POINT = 2.0 ** 32
#: per-ray tallies must stay below this magnitude for the fixed-point sums of squares to fit in int64
MAX_RAY_TALLY = 2.0 ** 15
LIMB = 31
#: rays per kernel call; keeps every per-lane limb sum below 2⁵³
MAX_CHUNK = 2 ** 22
#: Irradiance sub-maps: ray r (global index) is tallied on sub-map r mod MAP_PARTS, so the map comes as MAP_PARTS
#: independent maps of interleaved rays (their sum is the map). Two halves give the split-half non-uniformity and
#: the pairs its σ (:func:`bsdfkit.raytrace.tallies.converged_non_uniformity`); independent of chunks and devices.
MAP_PARTS = 16
#: interactions per iteration of the outer loop (between refill and retirement)
SUBSTEPS = 2
#: tail compaction: each level has 1/TAIL_SHRINK of the lanes of the previous one, at most TAIL_LEVELS levels
TAIL_SHRINK = 16
TAIL_LEVELS = 2
MIN_TAIL_LANES = 64
#: XLA compile options of the kernel. LLVM prefers 256-bit vectors on x86 even where AVX-512 is present; the
#: kernel is element-wise over wide lanes, so 512-bit vectors cut its CPU time by ~20 % (docs/tracer.md, Speed).
#: Same results bit for bit; ignored by other backends and by CPUs without AVX-512.
COMPILER_OPTIONS = {"xla_cpu_prefer_vector_width": 512}


def _fixed(w):
    return jnp.round(w * FIXED_POINT).astype(jnp.int64)


def emission(params: KernelParams, key_words, ray, effects: Effects):
    """Start points and directions of rays ``ray`` (global indices, uint32), event 0; in spectral mode also
    their wavelength bins.

    Parameters
    ----------
    params : KernelParams
        Numeric kernel inputs from :func:`bsdfkit.raytrace.effects.kernel_params` (lengths [mm]).
    key_words : jax.Array
        The two uint32 words of the seed's key (counter-based random numbers).
    ray : jax.Array
        Global ray indices (uint32).
    effects : Effects
        Static kernel configuration.

    Returns
    -------
    tuple of jax.Array
        x, y, z [mm] and dx, dy, dz [-]; in spectral mode also the wavelength bin index (int32).
    """
    dt = effects.dtype
    u = sampling.event_uniforms(key_words, ray, jnp.zeros_like(ray), dt, 6 if effects.spectral else 5)
    if effects.spectral:  # the ray's wavelength bin, drawn from the LED's bin powers (word 5)
        cdf = params.spectral.led_cdf
        k = jnp.clip(jnp.searchsorted(cdf, u[5].astype(jnp.float64), side="right"), 0, cdf.shape[0] - 1)
        return emission_geometry(params, u, effects) + (k.astype(jnp.int32),)
    return emission_geometry(params, u, effects)


def emission_geometry(params: KernelParams, u, effects: Effects):
    """Start points and directions from the emission uniforms ``u`` (words 0-4).

    Parameters
    ----------
    params : KernelParams
        Numeric kernel inputs (lengths [mm]).
    u : list of jax.Array
        Uniforms in [0, 1) of the emission event; words 0-4 are used [-].
    effects : Effects
        Static kernel configuration.

    Returns
    -------
    tuple of jax.Array
        x, y, z [mm] and the unit direction dx, dy, dz [-].
    """
    dt = effects.dtype
    if effects.source == "rayfile":
        rays = params.rays
        idx = jnp.clip(jnp.searchsorted(rays.cdf, u[0].astype(jnp.float64), side="right"), 0, rays.cdf.shape[0] - 1)
        o = rays.origin[idx]
        d = rays.direction[idx]
        return o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2]
    k = params.led_grid
    count = k * k
    i = jnp.minimum(jnp.floor(u[0] * count).astype(jnp.int32), count - 1)
    half = (k - 1).astype(dt) / 2.0
    cx = ((i // k).astype(dt) - half) * params.pitch
    cy = ((i % k).astype(dt) - half) * params.pitch
    r = params.emitter_radius * jnp.sqrt(u[1])
    c_phi, s_phi = sampling.cos_sin_turn(u[2])
    x = cx + r * c_phi
    y = cy + r * s_phi
    sin_t, cos_t, c_psi, s_psi = sampling.cos_power_angles(u[3], u[4], params.cos_exponent)
    z = jnp.zeros_like(x)
    return x, y, z, sin_t * c_psi, sin_t * s_psi, cos_t


def _pick(table, idx):
    """``table[idx]`` along the first axis; small tables by a static chain of selects.

    XLA's CPU gather is a generic scalar loop; for the few incidence angles of a plate a chain of
    ``where`` is several times faster and vectorises.
    """
    if table.shape[0] > 16:
        return table[idx]
    shape = idx.shape + (1,) * (table.ndim - 1)
    out = jnp.broadcast_to(table[0], idx.shape + table.shape[1:])
    for g in range(1, table.shape[0]):
        out = jnp.where((idx == g).reshape(shape), table[g], out)
    return out


class _Hit(NamedTuple):
    """Every lane's next surface: the ray's counter and event, the event's uniforms ``u``, the point hit and
    masks (live lanes only) of the surface it lies on."""

    ray: jax.Array
    event: jax.Array
    u: list
    x: jax.Array
    y: jax.Array
    z: jax.Array
    top: jax.Array
    wall: jax.Array
    base: jax.Array  # the base outside the LEDs
    led: jax.Array
    cav: jax.Array  # wall or base (LEDs included)


class _Cavity(NamedTuple):
    """A cavity reflection of every lane: the weight reflected and absorbed, and the new direction."""

    w_ref: jax.Array
    absorbed: jax.Array
    dx: jax.Array
    dy: jax.Array
    dz: jax.Array


class _Outcome(NamedTuple):
    """What the surface hit did to every lane, before termination: the weight extracted and the bin (colour) it
    left in, the ray's new weight, liveness, colour and direction, and the plate's absorption and Stokes loss."""

    ext_w: jax.Array
    ext_colour: jax.Array
    new_w: jax.Array
    alive: jax.Array
    new_colour: jax.Array
    dx: jax.Array
    dy: jax.Array
    dz: jax.Array
    plate_abs: jax.Array
    stokes: jax.Array | None


class _Tallies:
    """The per-ray tallies of the lanes during one interaction, added to in place: ``acc`` (:data:`COLUMNS`; a
    column the effects do not fill is None and ignores additions) and ``cnt`` (:data:`COUNTERS`)."""

    def __init__(self, lane):
        self.acc, self.cnt = list(lane["acc"]), list(lane["cnt"])
        self.zero = jnp.zeros_like(lane["w"])

    def add(self, col: int, value) -> None:
        if self.acc[col] is not None:
            self.acc[col] = self.acc[col] + value

    def count(self, counter: int, mask) -> None:
        self.cnt[counter] = self.cnt[counter] + mask.astype(jnp.int32)


def _plate_interaction(params: KernelParams, key_words, hit: _Hit, lane, effects: Effects):
    """Plate interaction of rays hitting the top (``hit.top``): returns weights, absorbed weights, forward,
    colours, directions, clamping and the Stokes loss (spectral mode; None otherwise)."""
    P = params.plate
    w, colour = lane["w"], lane["colour"]
    with jax.named_scope("plate"):
        t, j, clamped = _plate_incidence(P, key_words, lane["dz"], hit.top, effects)
        if effects.spectral:
            w_out, absorbed, stokes, forward, new_colour, channel, g = _spectral_channel(params, key_words, hit.u, w,
                                                                                          colour, t, j)
        else:
            w_out, forward, new_colour, channel, g = _plate_channel(P, key_words, hit.u, w, colour, t, j, effects)
            absorbed = w - w_out
            stokes = None
        nx, ny, nz = _backward_direction(P, key_words, hit, lane, hit.top & ~forward, channel, g, effects)
    return w_out, absorbed, forward, new_colour, nx, ny, nz, clamped, stokes


def _plate_incidence(P: PlateParams, key_words, dz, live, effects: Effects):
    """θi of rays meeting the plate on its incidence grid: interval j and weight t (linear in θi, θi clamped to
    the grid), and the lanes outside the measured range (None unless ``effects.plate_clamp``)."""
    grid = P.grid
    G = grid.shape[0]
    theta = jnp.arccos(jnp.clip(dz, 0.0, 1.0))
    lo, hi = P.range[0], P.range[1]
    clamped = live & ((theta < lo) | (theta > hi)) if effects.plate_clamp else None
    th = jnp.clip(theta, grid[0], grid[G - 1])
    j = jnp.zeros(th.shape, jnp.int32)
    for g in range(1, G - 1):
        j = j + (th >= grid[g]).astype(jnp.int32)
    g0, g1 = _pick(grid, j), _pick(grid, j + 1)
    t, j = sampling.materialise(key_words, [((th - g0) / (g1 - g0)).astype(jnp.float64), j])
    return t, j, clamped


def _plate_channel(P: PlateParams, key_words, u, w, colour, t, j, effects: Effects):
    """Two-wavelength plate: weight, forward, new colour, backward channel and grid point of rays of ``colour``
    at grid interval j (weight t); the channel drawn with probabilities TIS_c/S (uniform 0) and the grid point
    whose distribution is used with the channel's TIS share (uniform 4)."""
    T0 = [_pick(P.tis[:, c], j) for c in range(len(CHANNELS))]
    T1 = [_pick(P.tis[:, c], j + 1) for c in range(len(CHANNELS))]
    tis = [(1.0 - t) * a + t * b for a, b in zip(T0, T1)]
    # outcomes in PHOTON_CHANNELS order: R and T of the ray's elastic channel, then biys R and T (blue rays only)
    if effects.conversion:
        with jax.named_scope("phosphor_conversion"):
            yellow = colour == YELLOW
            zero = jnp.zeros_like(t)
            probs = [jnp.where(yellow, tis[YIYS_R], tis[BIBS_R]), jnp.where(yellow, tis[YIYS_T], tis[BIBS_T]),
                     jnp.where(yellow, zero, tis[BIYS_R]), jnp.where(yellow, zero, tis[BIYS_T])]
    else:
        probs = [tis[BIBS_R], tis[BIBS_T]]
    S = sum(probs)
    w_out = w * S
    v = u[0].astype(jnp.float64) * S
    edges = []
    acc = jnp.zeros_like(S)
    for pr in probs[:-1]:
        acc = acc + pr
        edges.append(acc)
    outcome = sum((v >= e).astype(jnp.int32) for e in edges)
    forward = (outcome == ELASTIC_T) | (outcome == CONVERTED_T)
    if effects.conversion:
        converted = outcome >= CONVERTED_R
        new_colour = jnp.where((colour == YELLOW) | converted, YELLOW, BLUE).astype(jnp.int32)
        channel = jnp.where(colour == YELLOW, BACK_YIYS, jnp.where(converted, BACK_BIYS, BACK_BIBS))
        q0 = jnp.where(channel == BACK_BIBS, T0[BIBS_R], jnp.where(channel == BACK_BIYS, T0[BIYS_R], T0[YIYS_R]))
        q1 = jnp.where(channel == BACK_BIBS, T1[BIBS_R], jnp.where(channel == BACK_BIYS, T1[BIYS_R], T1[YIYS_R]))
    else:
        new_colour = colour
        channel = jnp.full_like(outcome, BACK_BIBS)
        q0, q1 = T0[BIBS_R], T1[BIBS_R]
    # grid point whose angular distribution is used (linear interpolation of the BSDF in θi)
    q0 = (1.0 - t) * q0
    q1 = t * q1
    g = jnp.where(u[4].astype(jnp.float64) * (q0 + q1) < q0, j, j + 1)
    # computed once (see sampling.materialise): every later plate quantity depends on these
    return sampling.materialise(
        key_words, [w_out, forward, new_colour.astype(jnp.int32), channel.astype(jnp.int32), g])


def _backward_direction(P: PlateParams, key_words, hit: _Hit, lane, backward, channel, g, effects: Effects):
    """Direction of a backward-scattered ray: the distribution of backward channel ``channel`` (:data:`BACK_BIBS`,
    :data:`BACK_BIYS` or :data:`BACK_YIYS`) at grid point ``g`` (Lambertian, tabulated or Lambert + lobe;
    uniforms 1, 2 and 5)."""
    dt = effects.dtype
    u = hit.u
    with jax.named_scope("plate"):
        def per_channel(table):  # table (G, 3, ...) → value at (g, channel) per lane
            rows = _pick(table, g)  # (L, 3, ...)
            shape = channel.shape + (1,) * (rows.ndim - 2)
            return jnp.where((channel == BACK_BIBS).reshape(shape), rows[:, BACK_BIBS],
                             jnp.where((channel == BACK_BIYS).reshape(shape), rows[:, BACK_BIYS],
                                       rows[:, BACK_YIYS]))

        sin_t, cos_t, c_phi, s_phi = sampling.lambertian_angles(u[1], u[2])
        nx = sin_t * c_phi
        ny = sin_t * s_phi
        nz = -cos_t
        if effects.plate_table:
            with jax.named_scope("table_sampling"):
                is_table = per_channel(P.kind) == TABULATED
                s = sampling.table_s(u[1].astype(jnp.float64), per_channel(P.s_nodes),
                                     per_channel(P.f_nodes), per_channel(P.cdf)).astype(dt)
                ts, tc = jnp.sqrt(s), jnp.sqrt(1.0 - s)
                nx = jnp.where(is_table, ts * c_phi, nx)
                ny = jnp.where(is_table, ts * s_phi, ny)
                nz = jnp.where(is_table, -tc, nz)
        if effects.plate_lobe:
            with jax.named_scope("lobe_sampling"):
                use_lobe = backward & (u[5].astype(jnp.float64) < per_channel(P.lobe_share))
                bx, by, ok = sampling.lobe_beta(key_words, hit.ray, hit.event, use_lobe, lane["dx"], lane["dy"],
                                                per_channel(P.sigma), dt)
                bz = -jnp.sqrt(jnp.maximum(1.0 - bx * bx - by * by, 0.0))
                nx = jnp.where(ok, bx, nx)
                ny = jnp.where(ok, by, ny)
                nz = jnp.where(ok, bz, nz)
        return nx, ny, nz


def _spectral_channel(params: KernelParams, key_words, u, w, k, t, j):
    """Spectral plate: channel, new bin and weight of rays in bin ``k`` at grid interval j (weight t).

    Channels elastic R/T and converted R/T are chosen with probabilities ∝ their photon TIS (interpolated
    linearly in θi), the weight becomes wS (S their sum: photons kept per incident photon, ≤ 1); a conversion
    draws the new bin from the alias table of row k (uniforms 6 and 7) and scales the weight by λ_k/λ_new
    (same photon, new energy). Returns (w_out, absorbed, (stokes, photons converted, photons converted to a shorter
    bin, power created by those), forward, new bin, backward channel, grid point).
    """
    sp = params.spectral
    K = sp.lam.shape[0]
    with jax.named_scope("spectral_conversion"):
        T0 = sp.tis[j * K + k]  # (L, 4): PHOTON_CHANNELS
        T1 = sp.tis[(j + 1) * K + k]
        probs = [(1.0 - t) * T0[:, c] + t * T1[:, c] for c in range(len(PHOTON_CHANNELS))]
        S = sum(probs)
        v = u[0].astype(jnp.float64) * S
        edges = [probs[0], probs[0] + probs[1], probs[0] + probs[1] + probs[2]]
        outcome = sum((v >= e).astype(jnp.int32) for e in edges)  # the PHOTON_CHANNELS index
        forward = (outcome == ELASTIC_T) | (outcome == CONVERTED_T)
        converted = outcome >= CONVERTED_R
        i = jnp.minimum(jnp.floor(u[6].astype(jnp.float64) * K).astype(jnp.int32), K - 1)
        cell = k * K + i
        drawn = jnp.where(u[7].astype(jnp.float64) < sp.alias_prob[cell], i, sp.alias_index[cell])
        new_k = jnp.where(converted, drawn, k).astype(jnp.int32)
        w_kept = w * S
        w_out = jnp.where(converted, w_kept * (sp.lam[k] / sp.lam[new_k]), w_kept)
        channel = jnp.where(converted, BACK_BIYS, sp.elastic_shape[k]).astype(jnp.int32)
        q0, q1 = ((jnp.where(outcome == ELASTIC_R, T[:, ELASTIC_R],
                             jnp.where(outcome == ELASTIC_T, T[:, ELASTIC_T],
                                       jnp.where(outcome == CONVERTED_R, T[:, CONVERTED_R], T[:, CONVERTED_T]))))
                  for T in (T0, T1))
        q0 = (1.0 - t) * q0
        q1 = t * q1
        g = jnp.where(u[4].astype(jnp.float64) * (q0 + q1) < q0, j, j + 1)
        w_kept, w_out, forward, new_k, channel, g = sampling.materialise(
            key_words, [w_kept, w_out, forward, new_k, channel, g])
    anti = converted & (new_k < k)
    conversions = (w_kept - w_out, jnp.where(converted, w_kept * sp.photon_scale[k], 0.0),
                   jnp.where(anti, w_kept * sp.photon_scale[k], 0.0), jnp.where(anti, w_out - w_kept, 0.0))
    return w_out, w - w_kept, conversions, forward, new_k, channel, g


def interaction(params: KernelParams, key_words, start_u, lane, arrays, effects: Effects):
    """One interaction of every live lane (the body of the kernel; also used by the benchmark).

    ``lane``: dict of per-lane arrays (ids, live, px … dz, w, colour, acc, cnt); ``arrays``: (map, histogram,
    budget) int64 tallies. Returns the updated (lane, arrays); lanes not live are left unchanged.

    Parameters
    ----------
    params : KernelParams
        Numeric kernel inputs from :func:`bsdfkit.raytrace.effects.kernel_params` (lengths [mm]).
    key_words : jax.Array
        The two uint32 words of the seed's key (counter-based random numbers).
    start_u : jax.Array
        First ray index of the chunk (uint32).
    lane : dict
        Per-lane state arrays.
    arrays : tuple of jax.Array
        (map, histogram, budget) int64 fixed-point tallies.
    effects : Effects
        Static kernel configuration.

    Returns
    -------
    lane : dict
        Updated per-lane state.
    arrays : tuple of jax.Array
        Updated (map, histogram, budget).
    """
    dt = effects.dtype
    hit = _next_hit(params, key_words, start_u, lane, effects)
    cavity = _cavity(params, key_words, hit, lane, effects)
    tallies = _Tallies(lane)
    ph_in = _tally_cavity(params, hit, lane["colour"], cavity.absorbed, tallies, effects)
    budget_cav = jnp.where(hit.cav, cavity.absorbed, tallies.zero)
    n_plate = tallies.cnt[CNT_PLATE]
    if effects.top == "exit":
        out = _Outcome(jnp.where(hit.top, lane["w"], tallies.zero), lane["colour"],
                       jnp.where(hit.cav, cavity.w_ref, tallies.zero), hit.cav, lane["colour"], cavity.dx, cavity.dy,
                       cavity.dz, tallies.zero, None)
    else:
        out = _plate_top(params, key_words, hit, lane, cavity, tallies, ph_in, effects)
    ext_b, ext_y, ext_o, ph_out = _extracted(params, out, tallies, effects)
    new_w, alive, other = _terminate(params, hit.u, lane["live"], out.alive & (out.new_w > 0), out.new_w, ph_out,
                                     tallies, effects)
    new_map, new_hist, new_budget = arrays
    if effects.irradiance_map:
        new_map = _map_tally(params, hit, lane["w"], new_map, effects)
    if effects.incidence_histogram:
        new_hist = _histogram_tally(params, hit.top, lane, new_hist, effects)
    if effects.interaction_budget:
        new_budget = _budget_tally(new_budget, n_plate, lane["live"], (ext_b, ext_y, budget_cav, out.plate_abs, other),
                                   ext_o, out.stokes, effects)
    lane = dict(ids=lane["ids"], live=alive, px=hit.x, py=hit.y, pz=hit.z, dx=out.dx.astype(dt),
                dy=out.dy.astype(dt), dz=out.dz.astype(dt), w=new_w, colour=out.new_colour.astype(jnp.int32),
                acc=tallies.acc, cnt=tallies.cnt)
    return lane, (new_map, new_hist, new_budget)


def _next_hit(params: KernelParams, key_words, start_u, lane, effects: Effects) -> _Hit:
    """The surface every lane's ray meets next, and the uniforms of this event."""
    dt = effects.dtype
    R, H = params.radius, params.height
    live = lane["live"]
    ray = start_u + jnp.where(live, lane["ids"], 0).astype(jnp.uint32)
    event = lane["cnt"][CNT_EVENTS] + 1
    n_u = (8 if effects.spectral else 6) if effects.top == "plate" else 4
    u = sampling.event_uniforms(key_words, ray, event, dt, n_u)
    surf, x, y, z = sampling.materialise(key_words, geometry.next_hit(*(lane[k] for k in ("px", "py", "pz", "dx",
                                                                                            "dy", "dz")), R, H))
    top = live & (surf == geometry.TOP)
    wall = live & (surf == geometry.WALL)
    base_any = live & (surf == geometry.BASE)
    led = base_any & geometry.on_led(x, y, params.led_grid.astype(dt), params.pitch,
                                     params.emitter_radius)
    return _Hit(ray, event, u, x, y, z, top, wall, base_any & ~led, led, wall | base_any)


def _cavity(params: KernelParams, key_words, hit: _Hit, lane, effects: Effects) -> _Cavity:
    """Reflection at the cavity surfaces (wall, base, LEDs): weight wρ, Lambertian or mirror direction."""
    dt = effects.dtype
    wall, led, u, colour = hit.wall, hit.led, hit.u, lane["colour"]
    if effects.surface_spectra:  # reflectance per colour (two-wavelength) or per bin (spectral): row s·C + colour
        with jax.named_scope("surface_spectra"):
            C = params.rho_table.shape[0] // 3
            s_idx = jnp.where(wall, SURFACE_WALL, jnp.where(led, SURFACE_LEDS, SURFACE_BASE))
            rho = params.rho_table[s_idx * C + colour]
    else:
        rho = jnp.where(wall, params.rho[SURFACE_WALL],
                        jnp.where(led, params.rho[SURFACE_LEDS], params.rho[SURFACE_BASE]))
    w_ref = lane["w"] * rho
    absorbed = lane["w"] - w_ref
    inv_r = 1.0 / params.radius
    nx = jnp.where(wall, -hit.x * inv_r, 0.0).astype(dt)
    ny = jnp.where(wall, -hit.y * inv_r, 0.0).astype(dt)
    nz = jnp.where(wall, 0.0, 1.0).astype(dt)
    sin_t, cos_t, c_phi, s_phi = sampling.materialise(key_words, list(sampling.lambertian_angles(u[1], u[2])))
    # materialised: XLA contracts a·b + c into FMAs within a fusion, so the rounding of the direction must not
    # depend on what else (mirror, plate) is fused with it: every effects set traces the same paths
    cdx, cdy, cdz = sampling.materialise(key_words, list(sampling.local_to_world_cs(sin_t, cos_t, c_phi, s_phi, nx,
                                                                                   ny, nz)))
    if effects.specular:
        with jax.named_scope("specular_reflection"):
            spec = jnp.where(wall, params.spec[SURFACE_WALL],
                             jnp.where(led, params.spec[SURFACE_LEDS], params.spec[SURFACE_BASE]))
            mirror = u[0].astype(jnp.float64) < spec
            mdx, mdy, mdz = sampling.mirror(lane["dx"], lane["dy"], lane["dz"], nx, ny, nz)
            cdx = jnp.where(mirror, mdx, cdx)
            cdy = jnp.where(mirror, mdy, cdy)
            cdz = jnp.where(mirror, mdz, cdz)
    return _Cavity(w_ref, absorbed, cdx, cdy, cdz)


def _tally_cavity(params: KernelParams, hit: _Hit, colour, absorbed, tallies: _Tallies, effects: Effects):
    """Tally the weight the cavity surfaces absorbed; returns the photons per unit weight of the bin each ray
    arrived in (spectral mode; None otherwise)."""
    zero = tallies.zero
    tallies.add(ABS_WALL, jnp.where(hit.wall, absorbed, zero))
    tallies.add(ABS_BASE, jnp.where(hit.base, absorbed, zero))
    tallies.add(ABS_LED, jnp.where(hit.led, absorbed, zero))
    if not effects.spectral:
        return None
    ph_in = params.spectral.photon_scale[colour]
    tallies.add(PH_WALL, jnp.where(hit.wall, absorbed * ph_in, zero))
    tallies.add(PH_BASE, jnp.where(hit.base, absorbed * ph_in, zero))
    tallies.add(PH_LED, jnp.where(hit.led, absorbed * ph_in, zero))
    return ph_in


def _plate_top(params: KernelParams, key_words, hit: _Hit, lane, cavity: _Cavity, tallies: _Tallies, ph_in,
               effects: Effects) -> _Outcome:
    """The plate on top: rays meeting it are extracted (forward) or scattered back (or absorbed); the others
    keep their cavity reflection."""
    top, zero = hit.top, tallies.zero
    w_out, p_abs, forward, p_colour, pdx, pdy, pdz, clamped, stokes = _plate_interaction(params, key_words, hit,
                                                                                         lane, effects)
    plate_abs = jnp.where(top, p_abs, zero)
    tallies.add(ABS_PLATE, plate_abs)
    if effects.spectral:
        stokes, ph_conv, ph_anti, gain = (jnp.where(top, v, zero) for v in stokes)
        tallies.add(STOKES, stokes)
        tallies.add(PH_PLATE, plate_abs * ph_in)
        tallies.add(PH_CONVERTED, ph_conv)
        tallies.add(PH_ANTI_STOKES, ph_anti)
        tallies.add(ANTI_STOKES_GAIN, gain)
    ext_w = jnp.where(top & forward, w_out, zero)
    back = top & ~forward & (w_out > 0)
    new_w = jnp.where(hit.cav, cavity.w_ref, jnp.where(back, w_out, zero))
    alive = hit.cav | back
    new_colour = jnp.where(top, p_colour, lane["colour"])
    ndx = jnp.where(top, pdx, cavity.dx)
    ndy = jnp.where(top, pdy, cavity.dy)
    ndz = jnp.where(top, pdz, cavity.dz)
    tallies.count(CNT_PLATE, top)
    if effects.plate_clamp:
        tallies.count(CNT_CLAMP, clamped)
    return _Outcome(ext_w, p_colour, new_w, alive, new_colour, ndx, ndy, ndz, plate_abs, stokes)


def _extracted(params: KernelParams, out: _Outcome, tallies: _Tallies, effects: Effects):
    """Tally the extracted weight by band: returns (blue, yellow, outside both bands or None, photons per unit
    weight of the ray's new bin from here on or None)."""
    zero, ext_w, ext_colour = tallies.zero, out.ext_w, out.ext_colour
    ext_o = ph_out = None
    if effects.spectral:  # bands of the bin extracted in; photons of the ray's (new) bin from here on
        band = params.spectral.band[ext_colour]
        ph_out = params.spectral.photon_scale[out.new_colour]
        ext_b = jnp.where(band == BAND_BLUE, ext_w, zero)
        ext_y = jnp.where(band == BAND_YELLOW, ext_w, zero)
        ext_o = jnp.where(band == BAND_OTHER, ext_w, zero)
        tallies.add(EXT_O, ext_o)
        tallies.add(PH_EXT, ext_w * params.spectral.photon_scale[ext_colour])
    elif effects.conversion:
        ext_b = jnp.where(ext_colour == BLUE, ext_w, zero)
        ext_y = jnp.where(ext_colour == BLUE, zero, ext_w)
    else:
        ext_b, ext_y = ext_w, zero
    tallies.add(EXT_B, ext_b)
    tallies.add(EXT_Y, ext_y)
    return ext_b, ext_y, ext_o, ph_out


def _terminate(params: KernelParams, u, live, alive, new_w, ph_out, tallies: _Tallies, effects: Effects):
    """Roulette or threshold on the new weights, then the event cap: returns (weight, alive, weight removed)."""
    zero = tallies.zero
    other = zero
    if effects.termination == "roulette":
        tau = params.roulette_threshold
        low = alive & (new_w < tau)
        survive = u[3].astype(jnp.float64) * tau < new_w
        killed = low & ~survive
        rr = jnp.where(killed, new_w, jnp.where(low, new_w - tau, zero))
        tallies.add(ROULETTE, rr)
        if effects.spectral:
            tallies.add(PH_ROULETTE, rr * ph_out)
        other = other + rr
        new_w = jnp.where(low, jnp.where(survive, tau, zero), new_w)
        alive = alive & ~killed
    else:
        low = alive & (new_w < params.threshold)
        dropped = jnp.where(low, new_w, zero)
        tallies.add(DISCARDED, dropped)
        if effects.spectral:
            tallies.add(PH_DISCARDED, dropped * ph_out)
        other = other + dropped
        new_w = jnp.where(low, zero, new_w)
        alive = alive & ~low
    tallies.count(CNT_EVENTS, live)
    capped = alive & (tallies.cnt[CNT_EVENTS] >= params.max_events)
    trunc = jnp.where(capped, new_w, zero)
    tallies.add(TRUNCATED, trunc)
    if effects.spectral:
        tallies.add(PH_TRUNCATED, trunc * ph_out)
    other = other + trunc
    return new_w, alive & ~capped, other


def _map_tally(params: KernelParams, hit: _Hit, w, new_map, effects: Effects):
    """Deposit the weight of the rays meeting the top into the irradiance sub-map of each ray."""
    with jax.named_scope("irradiance_map"):
        part = (hit.ray % jnp.uint32(MAP_PARTS)).astype(jnp.int32) * (effects.map_bins ** 2)
        idx = geometry.map_index(hit.x, hit.y, params.radius, effects.map_bins) + part
        return new_map.at[jnp.where(hit.top, idx, new_map.shape[0])].add(_fixed(w), mode="drop")


def _histogram_tally(params: KernelParams, top, lane, new_hist, effects: Effects):
    """Deposit the weight of the rays meeting the top into the histogram of their incidence (per band)."""
    with jax.named_scope("incidence_histogram"):
        theta = jnp.arccos(jnp.clip(lane["dz"], 0.0, 1.0))
        hb = effects.histogram_bins
        colour = lane["colour"]
        # light outside both bands is binned with yellow (BAND_OTHER → BAND_YELLOW)
        hue = jnp.minimum(params.spectral.band[colour], BAND_YELLOW) if effects.spectral else colour
        b = jnp.clip(jnp.floor(theta / (jnp.pi / 2) * hb), 0, hb - 1).astype(jnp.int32) + hue * hb
        return new_hist.at[jnp.where(top, b, new_hist.shape[0])].add(_fixed(lane["w"]), mode="drop")


def _budget_tally(new_budget, n_plate, live, parts, ext_o, stokes, effects: Effects):
    """Deposit this interaction's :data:`BUDGET_COLUMNS` ``parts`` into the row of the plate interactions the ray
    had before it (the last row collects the rest)."""
    with jax.named_scope("interaction_budget"):
        k = jnp.minimum(n_plate, effects.budget_bins - 1) * len(BUDGET_COLUMNS)
        sink = jnp.where(live, 0, new_budget.shape[0])
        ext_b, ext_y, cav, plate_abs, other = parts
        if effects.spectral:  # light outside both bands with yellow, the Stokes loss with the plate's
            ext_y = ext_y + ext_o
            plate_abs = plate_abs if stokes is None else plate_abs + stokes
        for c, val in enumerate((ext_b, ext_y, cav, plate_abs, other)):
            new_budget = new_budget.at[k + c + sink].add(_fixed(val), mode="drop")
        return new_budget


def active_columns(effects: Effects) -> tuple[bool, ...]:
    """Which per-ray tallies of :data:`COLUMNS` the compiled kernel carries (the others are always zero).

    Parameters
    ----------
    effects : Effects
        Static kernel configuration.

    Returns
    -------
    tuple of bool
        One flag per entry of :data:`COLUMNS`.
    """
    plate, roulette, sp = effects.top == "plate", effects.termination == "roulette", effects.spectral
    on = {"extracted_blue": True, "extracted_yellow": effects.conversion or sp, "absorbed_wall": True,
          "absorbed_base": True, "absorbed_leds": True, "absorbed_plate": plate,
          "roulette": roulette, "discarded": not roulette, "truncated": True,
          "extracted_other": sp, "stokes": sp and plate, "photons_extracted": sp, "photons_wall": sp,
          "photons_base": sp, "photons_leds": sp, "photons_plate": sp and plate, "photons_roulette": sp and roulette,
          "photons_discarded": sp and not roulette, "photons_truncated": sp, "photons_converted": sp and plate,
          "photons_anti_stokes": sp and plate, "anti_stokes_gain": sp and plate}
    return tuple(on[c] for c in COLUMNS)


def trace_chunk(params: KernelParams, key_words, start, n_valid, *, effects: Effects, lanes: int,
                chunk: int | None = None, substeps: int = SUBSTEPS):
    """Trace rays ``start … start + n_valid − 1`` (``n_valid`` ≤ ``chunk``) and return their summed tallies.

    ``start`` and ``n_valid`` are traced values; ``chunk`` (static, default ``lanes``) is the number of
    emissions computed up front, so one compiled kernel serves every chunk of at most that size.

    Batch-synchronous: each iteration of the loop refills empty lanes with the next emitted rays, applies
    ``substeps`` interactions to every lane (a lane whose ray ends mid-iteration idles until the next
    refill) and then retires finished rays into exact integer sums. Once the chunk is exhausted and few rays
    are live, the live lanes are compacted into a narrower state (``lanes``/16, then /256) so the tail of long
    paths does not pay for empty lanes. None of this changes a ray's random numbers or its tallies.

    Returns a dict of int64 arrays: ``hi``, ``lo`` limbs of the fixed-point sums of :data:`COLUMNS` then
    :data:`SQUARES`; ``counts`` (sums of :data:`COUNTERS`); ``map`` (bins²,), ``histogram`` (2·bins,),
    ``budget`` (bins·5,) fixed point (empty when not compiled in); in spectral mode ``spectrum`` (2K,): the
    extracted weight per bin and its square, fixed point, deposited when the ray retires (a ray is extracted at
    most once, in one bin, so the per-bin sums of squares give exact per-ray variances), and ``emitted`` (K,)
    rays emitted per bin (counts); and ``iterations`` of the loop.

    Parameters
    ----------
    params : KernelParams
        Numeric kernel inputs from :func:`bsdfkit.raytrace.effects.kernel_params` (lengths [mm]).
    key_words : jax.Array
        The two uint32 words of the seed's key (counter-based random numbers).
    start : int or jax.Array
        Global index of the chunk's first ray.
    n_valid : int or jax.Array
        Rays of the chunk to trace, at most ``chunk``.
    effects : Effects
        Static kernel configuration.
    lanes : int
        Width of the lane state (static).
    chunk : int, optional
        Emissions computed up front (static); default ``lanes``.
    substeps : int
        Interactions per loop iteration (static).

    Returns
    -------
    dict
        Name → int64 array, as described above.
    """
    C = int(chunk or lanes)
    start_u = jnp.asarray(start, jnp.uint32)
    n_valid = jnp.asarray(n_valid, jnp.int32)  # ≤ min(chunk, MAX_CHUNK) (exactness of the limb sums)
    # every emission of the chunk, computed once (vectorised) before the loop
    with jax.named_scope("emission"):
        emitted = emission(params, key_words, start_u + jnp.arange(C, dtype=jnp.uint32), effects)
    if effects.spectral:
        K = params.spectral.lam.shape[0]
        valid = jnp.arange(C) < n_valid
        emitted_bins = jnp.zeros(K, jnp.int64).at[jnp.where(valid, emitted[6], K)].add(1, mode="drop")
    else:
        K = 0
        emitted_bins = jnp.zeros(0, jnp.int64)

    def body(s):
        # (1) refill empty lanes with the next rays of the chunk
        lane, nxt = _refill(s, emitted, n_valid, C, effects)
        live, ids = lane["live"], lane["ids"]
        arrays = (s["map"], s["hist"], s["budget"])
        # (2) several interactions of every lane per iteration
        if substeps == 1:
            lane, arrays = interaction(params, key_words, start_u, lane, arrays, effects)
        else:
            lane, arrays = lax.fori_loop(0, substeps, lambda _, carry: interaction(params, key_words, start_u, *carry,
                                                                                   effects), (lane, arrays))
        new_map, new_hist, new_budget = arrays
        alive, acc, cnt = lane["live"], lane["acc"], lane["cnt"]
        # (3) retire finished rays
        with jax.named_scope("retire"):
            retire = live & ~alive
            hi, lo, counts = _retire_sums(acc, cnt, retire)
            spectrum = _retire_spectrum(s["spectrum"], acc, lane["colour"], retire) if effects.spectral \
                else s["spectrum"]
        return dict(
            next=nxt, it=s["it"] + 1,
            lanes=dict(ray=jnp.where(alive, ids, -1), px=lane["px"], py=lane["py"], pz=lane["pz"], dx=lane["dx"],
                       dy=lane["dy"], dz=lane["dz"], w=lane["w"], colour=lane["colour"], acc=acc, cnt=cnt),
            hi=s["hi"] + hi, lo=s["lo"] + lo, counts=s["counts"] + counts, map=new_map, hist=new_hist,
            budget=new_budget, spectrum=spectrum,
        )

    # the widths the tail is compacted into (each level is its own loop over the same body)
    widths = _tail_widths(lanes)
    final = _initial_state(lanes, K, effects)
    for level, width in enumerate(widths):
        if level:
            final = _compact(final, width)
        narrower = widths[level + 1] if level + 1 < len(widths) else 0

        def cond(s, narrower=narrower):
            n_live = jnp.sum(s["lanes"]["ray"] >= 0, dtype=jnp.int32)
            return (s["next"] < n_valid) | (n_live > narrower)

        final = lax.while_loop(cond, body, final)
    return {"hi": final["hi"], "lo": final["lo"], "counts": final["counts"], "map": final["map"],
            "histogram": final["hist"], "budget": final["budget"], "spectrum": final["spectrum"],
            "emitted": emitted_bins, "iterations": final["it"]}


def _tail_widths(lanes: int) -> list[int]:
    """The lane counts of the loop levels of :func:`trace_chunk`: ``lanes``, then each 1/:data:`TAIL_SHRINK` of
    the previous while at least :data:`MIN_TAIL_LANES`, at most :data:`TAIL_LEVELS` levels."""
    widths = [lanes]
    while widths[-1] // TAIL_SHRINK >= MIN_TAIL_LANES and len(widths) < TAIL_LEVELS:
        widths.append(widths[-1] // TAIL_SHRINK)
    return widths


def _retire_spectrum(spectrum, acc, colour, retire):
    """Deposit the extracted weight of the retiring rays (and its square) into their bins' spectrum sums."""
    K = spectrum.shape[0] // 2
    with jax.named_scope("extracted_spectrum"):
        ext = acc[EXT_B] + acc[EXT_Y] + acc[EXT_O]
        b = jnp.where(retire & (ext != 0), colour, 2 * K)
        return spectrum.at[b].add(_fixed(ext), mode="drop").at[b + K].add(_fixed(ext * ext), mode="drop")


def _initial_state(lanes: int, K: int, effects: Effects) -> dict:
    """The loop state of :func:`trace_chunk` before the first ray: ``lanes`` empty lanes, zero sums and tallies
    (``K`` wavelength bins)."""
    W, dt = lanes, effects.dtype
    ncol, ncnt, nsq = len(COLUMNS), len(COUNTERS), len(SQUARES)
    nmap = MAP_PARTS * effects.map_bins ** 2 if effects.irradiance_map else 0
    nhist = 2 * effects.histogram_bins if effects.incidence_histogram else 0
    nbud = effects.budget_bins * len(BUDGET_COLUMNS) if effects.interaction_budget else 0
    zf = jnp.zeros(W, dt)
    return dict(
        next=jnp.int32(0), it=jnp.int32(0),
        lanes=dict(ray=jnp.full(W, -1, jnp.int32), px=zf, py=zf, pz=zf, dx=zf, dy=zf, dz=zf,
                   w=jnp.zeros(W, jnp.float64), colour=jnp.zeros(W, jnp.int32),
                   acc=[jnp.zeros(W, jnp.float64) if a else None for a in active_columns(effects)],
                   cnt=[jnp.zeros(W, jnp.int32) for _ in range(ncnt)]),
        hi=jnp.zeros(ncol + nsq, jnp.int64), lo=jnp.zeros(ncol + nsq, jnp.int64),
        counts=jnp.zeros(ncnt, jnp.int64),
        map=jnp.zeros(nmap, jnp.int64), hist=jnp.zeros(nhist, jnp.int64), budget=jnp.zeros(nbud, jnp.int64),
        spectrum=jnp.zeros(2 * K, jnp.int64),
    )


def _refill(s, emitted, n_valid, C: int, effects: Effects):
    """The lanes of loop state ``s`` with the empty ones refilled by the next of the ``C`` emitted rays (of which
    ``n_valid`` are traced): returns the lane dict of :func:`interaction` and the next ray to emit."""
    ln = s["lanes"]
    empty = ln["ray"] < 0
    rank = jnp.cumsum(empty, dtype=jnp.int32) - 1
    new_id = s["next"] + rank
    take = empty & (new_id < n_valid)
    src = jnp.clip(new_id, 0, C - 1)
    ids = jnp.where(take, new_id, ln["ray"])
    live = ids >= 0
    px, py, pz, dx, dy, dz = (jnp.where(take, e[src], ln[k]) for e, k in zip(emitted, ("px", "py", "pz", "dx",
                                                                                        "dy", "dz")))
    w = jnp.where(take, 1.0, ln["w"])
    colour = jnp.where(take, emitted[6][src] if effects.spectral else 0, ln["colour"])
    acc = [None if a is None else jnp.where(take, 0.0, a) for a in ln["acc"]]
    cnt = [jnp.where(take, 0, c) for c in ln["cnt"]]
    nxt = jnp.minimum(s["next"] + jnp.sum(empty, dtype=jnp.int32), n_valid)
    lane = dict(ids=ids, live=live, px=px, py=py, pz=pz, dx=dx, dy=dy, dz=dz, w=w, colour=colour, acc=acc, cnt=cnt)
    return lane, nxt


def _retire_sums(acc, cnt, retire):
    """Exact sums over the retiring lanes: integer-valued float64 limbs (all partial sums < 2⁵³)."""
    ncol = len(COLUMNS)
    zero = None
    total = acc[EXT_B] if acc[EXT_Y] is None else acc[EXT_B] + acc[EXT_Y]
    if acc[EXT_O] is not None:
        total = total + acc[EXT_O]
    sq = {"total": total, "blue": acc[EXT_B] if acc[EXT_Y] is not None else None,
          "yellow": acc[EXT_Y], "blue_yellow": None if acc[EXT_Y] is None else acc[EXT_B] * acc[EXT_Y],
          "absorbed_wall": acc[ABS_WALL], "absorbed_base": acc[ABS_BASE], "absorbed_leds": acc[ABS_LED],
          "absorbed_plate": acc[ABS_PLATE]}
    values = [(a, SCALE_SUM) for a in acc]
    for name in SQUARES:
        v = sq[name]
        if name in ("yellow", "absorbed_wall", "absorbed_base", "absorbed_leds", "absorbed_plate", "total",
                    "blue") and v is not None:
            v = v * v
        values.append((v, SCALE_SQUARE))
    his, los = [], []
    for v, scale in values:
        if v is None:
            his.append(zero)
            los.append(zero)
            continue
        X = jnp.where(retire, jnp.rint(v * scale), 0.0)  # integer-valued doubles, |X| < 2⁶²
        h = jnp.floor(X * 2.0 ** -LIMB)  # |h| < 2³¹
        his.append(jnp.sum(h))
        los.append(jnp.sum(X - h * 2.0 ** LIMB))  # in [0, 2³¹)
    if acc[EXT_Y] is None:  # no yellow: the blue square is the total's
        i_total, i_blue = ncol + SQUARES.index("total"), ncol + SQUARES.index("blue")
        his[i_blue], los[i_blue] = his[i_total], los[i_total]
    f0 = jnp.zeros((), jnp.float64)
    hi = jnp.stack([f0 if v is None else v for v in his]).astype(jnp.int64)
    lo = jnp.stack([f0 if v is None else v for v in los]).astype(jnp.int64)
    counts = jnp.stack([jnp.sum(jnp.where(retire, c, 0)) for c in cnt]).astype(jnp.int64)
    return hi, lo, counts


def _compact(s, L: int):
    """The live lanes of loop state ``s`` moved into a state of ``L`` lanes (all live rays fit)."""
    ln = s["lanes"]
    live = ln["ray"] >= 0
    (idx,) = jnp.nonzero(live, size=L, fill_value=0)
    keep = jnp.arange(L) < jnp.sum(live, dtype=jnp.int32)
    new = jax.tree_util.tree_map(lambda a: a[idx], ln)
    new["ray"] = jnp.where(keep, new["ray"], -1)
    return dict(s, lanes=new)


trace_chunk_jit = partial(jax.jit, static_argnames=("effects", "lanes", "chunk", "substeps"),
                          compiler_options=COMPILER_OPTIONS)(trace_chunk)
