"""The Monte Carlo kernel: trace one chunk of rays through the cavity (JAX, specialised by :class:`Effects`).

Algorithm (the ray-level form of Fig. 6 of the cylindrical-module paper, [Cylindrical-module]). ``lanes``
rays are in flight; each ``lax.while_loop`` iteration (1) refills empty lanes with the next rays of the chunk (emission
precomputed in a rolling buffer of 4·lanes rays), (2) moves every live ray to its next surface and
applies one interaction, (3) retires finished rays by adding their per-ray tallies to exact fixed-point
sums (below). The loop ends when the chunk is exhausted and no lane is live. Because every random number is keyed by
(seed, ray, event) (:mod:`bsdfkit.raytrace.sampling`), results do not depend on ``lanes`` or the chunk size.

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

Sums. When a ray retires, its per-ray tallies x (float64, in ray weights) are rounded to integers
X = rint(x·2⁴⁰) (its squares/products for the standard errors to rint(x²·2³²)), split exactly into 31-bit
limbs X = hi·2³¹ + lo (both integer-valued doubles) and added to per-lane accumulators; at the end of the
chunk each lane's limb sums are converted to int64 and summed. Every partial sum is an integer below 2⁵³
(|hi|, lo < 2³¹ and at most 2²² rays per lane per chunk), so all of this is exact integer arithmetic:
the totals do not depend on lanes, chunking or order, and a trace is bit-for-bit reproducible for any chunk
size. The rounding is ≤ 2⁻⁴¹ ≈ 4.5·10⁻¹³ of a ray weight per tally, far below the 10⁻⁹ ledger tolerance.
Array tallies (map, histogram, budget) are int64 fixed point in units of 2⁻³² ray weights per deposit,
likewise exact. Magnitudes: |x| ≤ 1 + τ·max_events (roulette adds at most τ per event), required < 2¹⁵
(checked by the tracer), so |X| < 2⁶² for sums and squares.
"""
from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
from jax import lax

from bsdfkit.raytrace import geometry, sampling
from bsdfkit.raytrace.effects import Effects

# per-ray float64 tallies, accumulated in lanes and summed when the ray retires
COLUMNS = ("extracted_blue", "extracted_yellow", "absorbed_wall", "absorbed_base", "absorbed_leds",
           "absorbed_plate", "roulette", "discarded", "truncated")
EXT_B, EXT_Y, ABS_WALL, ABS_BASE, ABS_LED, ABS_PLATE, ROULETTE, DISCARDED, TRUNCATED = range(len(COLUMNS))
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


def _fixed(w):
    return jnp.round(w * FIXED_POINT).astype(jnp.int64)


def emission(params, key_words, ray, effects: Effects):
    """Start points and directions of rays ``ray`` (global indices, uint32), event 0."""
    dt = effects.dtype
    u = sampling.event_uniforms(key_words, ray, jnp.zeros_like(ray), dt, 5)
    if effects.source == "rayfile":
        idx = jnp.clip(jnp.searchsorted(params["ray_cdf"], u[0].astype(jnp.float64), side="right"), 0,
                       params["ray_cdf"].shape[0] - 1)
        o = params["ray_origin"][idx]
        d = params["ray_direction"][idx]
        return o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2]
    k = params["led_grid"]
    count = k * k
    i = jnp.minimum(jnp.floor(u[0] * count).astype(jnp.int32), count - 1)
    half = (k - 1).astype(dt) / 2.0
    cx = ((i // k).astype(dt) - half) * params["pitch"]
    cy = ((i % k).astype(dt) - half) * params["pitch"]
    r = params["emitter_radius"] * jnp.sqrt(u[1])
    phi = sampling.TWO_PI * u[2]
    x = cx + r * jnp.cos(phi)
    y = cy + r * jnp.sin(phi)
    sin_t, cos_t, psi = sampling.cos_power_angles(u[3], u[4], params["cos_exponent"])
    z = jnp.zeros_like(x)
    return x, y, z, sin_t * jnp.cos(psi), sin_t * jnp.sin(psi), cos_t


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


def _plate_interaction(params, key_words, ray, event, u, x, y, dx, dy, dz, w, colour, live, effects: Effects):
    """Plate interaction of rays hitting the top: returns weights, colours, directions and tallies."""
    dt = effects.dtype
    P = params["plate"]
    grid = P["grid"]
    G = grid.shape[0]
    with jax.named_scope("plate"):
        theta = jnp.arccos(jnp.clip(dz, 0.0, 1.0))
        lo, hi = P["range"][0], P["range"][1]
        clamped = live & ((theta < lo) | (theta > hi)) if effects.plate_clamp else None
        th = jnp.clip(theta, grid[0], grid[G - 1])
        j = jnp.zeros(th.shape, jnp.int32)
        for g in range(1, G - 1):
            j = j + (th >= grid[g]).astype(jnp.int32)
        g0, g1 = _pick(grid, j), _pick(grid, j + 1)
        t = ((th - g0) / (g1 - g0)).astype(jnp.float64)
        T0 = [_pick(P["tis"][:, c], j) for c in range(6)]
        T1 = [_pick(P["tis"][:, c], j + 1) for c in range(6)]
        tis = [(1.0 - t) * a + t * b for a, b in zip(T0, T1)]
        if effects.conversion:
            with jax.named_scope("phosphor_conversion"):
                yellow = colour == 1
                zero = jnp.zeros_like(t)
                probs = [jnp.where(yellow, tis[4], tis[0]), jnp.where(yellow, tis[5], tis[1]),
                         jnp.where(yellow, zero, tis[2]), jnp.where(yellow, zero, tis[3])]
        else:
            probs = [tis[0], tis[1]]
        S = sum(probs)
        w_out = w * S
        absorbed = w - w_out
        v = u[0].astype(jnp.float64) * S
        edges = []
        acc = jnp.zeros_like(S)
        for pr in probs[:-1]:
            acc = acc + pr
            edges.append(acc)
        outcome = sum((v >= e).astype(jnp.int32) for e in edges)
        forward = (outcome % 2) == 1
        if effects.conversion:
            new_colour = jnp.where((colour == 1) | (outcome >= 2), 1, 0).astype(jnp.int32)
            channel = jnp.where(colour == 1, 2, jnp.where(outcome >= 2, 1, 0))
            q0 = jnp.where(channel == 0, T0[0], jnp.where(channel == 1, T0[2], T0[4]))
            q1 = jnp.where(channel == 0, T1[0], jnp.where(channel == 1, T1[2], T1[4]))
        else:
            new_colour = colour
            channel = jnp.zeros_like(outcome)
            q0, q1 = T0[0], T1[0]
        # grid point whose angular distribution is used (linear interpolation of the BSDF in θi)
        q0 = (1.0 - t) * q0
        q1 = t * q1
        g = jnp.where(u[4].astype(jnp.float64) * (q0 + q1) < q0, j, j + 1)

        def per_channel(table):  # table (G, 3, ...) → value at (g, channel) per lane
            rows = _pick(table, g)  # (L, 3, ...)
            shape = channel.shape + (1,) * (rows.ndim - 2)
            return jnp.where((channel == 0).reshape(shape), rows[:, 0],
                             jnp.where((channel == 1).reshape(shape), rows[:, 1], rows[:, 2]))

        sin_t, cos_t, phi = sampling.lambertian_angles(u[1], u[2])
        nx = sin_t * jnp.cos(phi)
        ny = sin_t * jnp.sin(phi)
        nz = -cos_t
        backward = live & ~forward
        if effects.plate_table:
            with jax.named_scope("table_sampling"):
                is_table = per_channel(P["kind"]) == 2
                s = sampling.table_s(u[1].astype(jnp.float64), per_channel(P["s_nodes"]),
                                     per_channel(P["f_nodes"]), per_channel(P["cdf"])).astype(dt)
                ts, tc = jnp.sqrt(s), jnp.sqrt(1.0 - s)
                nx = jnp.where(is_table, ts * jnp.cos(phi), nx)
                ny = jnp.where(is_table, ts * jnp.sin(phi), ny)
                nz = jnp.where(is_table, -tc, nz)
        if effects.plate_lobe:
            with jax.named_scope("lobe_sampling"):
                use_lobe = backward & (u[5].astype(jnp.float64) < per_channel(P["lobe_share"]))
                bx, by, ok = sampling.lobe_beta(key_words, ray, event, use_lobe, dx, dy, per_channel(P["sigma"]), dt)
                bz = -jnp.sqrt(jnp.maximum(1.0 - bx * bx - by * by, 0.0))
                nx = jnp.where(ok, bx, nx)
                ny = jnp.where(ok, by, ny)
                nz = jnp.where(ok, bz, nz)
    return w_out, absorbed, forward, new_colour, nx, ny, nz, clamped


def trace_chunk(params, key_words, start, n_valid, *, effects: Effects, lanes: int):
    """Trace rays ``start … start + n_valid − 1`` and return their summed tallies.

    ``start`` and ``n_valid`` are traced values, so one compiled kernel serves every chunk size; memory is
    bounded by ``lanes`` (live rays plus a rolling buffer of 4·lanes precomputed emissions).

    Returns a dict of int64 arrays: ``hi``, ``lo`` limbs of the fixed-point sums of :data:`COLUMNS` then
    :data:`SQUARES`; ``counts`` (sums of :data:`COUNTERS`); ``map`` (bins²,), ``histogram`` (2·bins,),
    ``budget`` (bins·5,) fixed point (empty when not compiled in); and ``iterations`` of the while loop.
    """
    dt = effects.dtype
    L = lanes
    R, H = params["radius"], params["height"]
    start_u = jnp.asarray(start, jnp.uint32)
    n_valid = jnp.asarray(n_valid, jnp.int32)  # ≤ MAX_CHUNK (exactness of the per-lane limb sums)
    B = 4 * L
    buffer_ids = jnp.arange(B, dtype=jnp.uint32)

    def emit_block(first):
        return emission(params, key_words, start_u + first.astype(jnp.uint32) + buffer_ids, effects)

    ncol, ncnt, nsq = len(COLUMNS), len(COUNTERS), len(SQUARES)
    scales = jnp.asarray([SCALE_SUM] * ncol + [SCALE_SQUARE] * nsq, jnp.float64)
    nmap = effects.map_bins ** 2 if effects.irradiance_map else 0
    nhist = 2 * effects.histogram_bins if effects.incidence_histogram else 0
    nbud = effects.budget_bins * len(BUDGET_COLUMNS) if effects.interaction_budget else 0
    zf = jnp.zeros(L, dt)
    state = dict(
        next=jnp.int32(0), it=jnp.int32(0),
        buf_start=jnp.int32(0), buf=emit_block(jnp.int32(0)),
        ray=jnp.full(L, -1, jnp.int32),
        px=zf, py=zf, pz=zf, dx=zf, dy=zf, dz=zf,
        w=jnp.zeros(L, jnp.float64), colour=jnp.zeros(L, jnp.int32),
        acc=tuple(jnp.zeros(L, jnp.float64) for _ in range(ncol)),
        cnt=tuple(jnp.zeros(L, jnp.int32) for _ in range(ncnt)),
        hi=jnp.zeros((ncol + nsq, L), jnp.float64), lo=jnp.zeros((ncol + nsq, L), jnp.float64),
        counts=jnp.zeros((ncnt, L), jnp.int64),
        map=jnp.zeros(nmap, jnp.int64), hist=jnp.zeros(nhist, jnp.int64), budget=jnp.zeros(nbud, jnp.int64),
    )

    def cond(s):
        return (s["next"] < n_valid) | jnp.any(s["ray"] >= 0)

    def step(lane, arrays):
        """One interaction of every live lane (stage (2))."""
        ids, live, px, py, pz, dx, dy, dz, w, colour = (lane[k] for k in ("ids", "live", "px", "py", "pz", "dx",
                                                                           "dy", "dz", "w", "colour"))
        acc, cnt = list(lane["acc"]), list(lane["cnt"])
        ray = start_u + jnp.where(live, ids, 0).astype(jnp.uint32)
        event = cnt[CNT_EVENTS] + 1
        u = sampling.event_uniforms(key_words, ray, event, dt, 6 if effects.top == "plate" else 4)
        surf, x, y, z = geometry.next_hit(px, py, pz, dx, dy, dz, R, H)
        top = live & (surf == geometry.TOP)
        wall = live & (surf == geometry.WALL)
        base_any = live & (surf == geometry.BASE)
        led = base_any & geometry.on_led(x, y, params["led_grid"].astype(dt), params["pitch"],
                                         params["emitter_radius"])
        base = base_any & ~led
        cav = wall | base_any

        # cavity surfaces
        rho = jnp.where(wall, params["rho"][0], jnp.where(led, params["rho"][2], params["rho"][1]))
        w_ref = w * rho
        absorbed = w - w_ref
        inv_r = 1.0 / R
        nx = jnp.where(wall, -x * inv_r, 0.0).astype(dt)
        ny = jnp.where(wall, -y * inv_r, 0.0).astype(dt)
        nz = jnp.where(wall, 0.0, 1.0).astype(dt)
        sin_t, cos_t, phi = sampling.lambertian_angles(u[1], u[2])
        cdx, cdy, cdz = sampling.local_to_world(sin_t, cos_t, phi, nx, ny, nz)
        if effects.specular:
            with jax.named_scope("specular_reflection"):
                spec = jnp.where(wall, params["spec"][0], jnp.where(led, params["spec"][2], params["spec"][1]))
                mirror = u[0].astype(jnp.float64) < spec
                mdx, mdy, mdz = sampling.mirror(dx, dy, dz, nx, ny, nz)
                cdx = jnp.where(mirror, mdx, cdx)
                cdy = jnp.where(mirror, mdy, cdy)
                cdz = jnp.where(mirror, mdz, cdz)

        zero = jnp.zeros_like(w)
        acc[ABS_WALL] = acc[ABS_WALL] + jnp.where(wall, absorbed, zero)
        acc[ABS_BASE] = acc[ABS_BASE] + jnp.where(base, absorbed, zero)
        acc[ABS_LED] = acc[ABS_LED] + jnp.where(led, absorbed, zero)
        budget_cav = jnp.where(cav, absorbed, zero)

        # top
        n_plate = cnt[CNT_PLATE]
        if effects.top == "exit":
            ext_w = jnp.where(top, w, zero)
            ext_colour = colour
            new_w = jnp.where(cav, w_ref, zero)
            alive = cav
            new_colour = colour
            ndx, ndy, ndz = cdx, cdy, cdz
            plate_abs = zero
        else:
            w_out, p_abs, forward, p_colour, pdx, pdy, pdz, clamped = _plate_interaction(
                params, key_words, ray, event, u, x, y, dx, dy, dz, w, colour, top, effects)
            plate_abs = jnp.where(top, p_abs, zero)
            acc[ABS_PLATE] = acc[ABS_PLATE] + plate_abs
            ext_w = jnp.where(top & forward, w_out, zero)
            ext_colour = p_colour
            back = top & ~forward & (w_out > 0)
            new_w = jnp.where(cav, w_ref, jnp.where(back, w_out, zero))
            alive = cav | back
            new_colour = jnp.where(top, p_colour, colour)
            ndx = jnp.where(top, pdx, cdx)
            ndy = jnp.where(top, pdy, cdy)
            ndz = jnp.where(top, pdz, cdz)
            cnt[CNT_PLATE] = cnt[CNT_PLATE] + top.astype(jnp.int32)
            if effects.plate_clamp:
                cnt[CNT_CLAMP] = cnt[CNT_CLAMP] + clamped.astype(jnp.int32)
        ext_b = jnp.where(ext_colour == 0, ext_w, zero)
        ext_y = jnp.where(ext_colour == 0, zero, ext_w)
        acc[EXT_B] = acc[EXT_B] + ext_b
        acc[EXT_Y] = acc[EXT_Y] + ext_y
        alive = alive & (new_w > 0)

        # termination
        other = zero
        if effects.termination == "roulette":
            tau = params["roulette_threshold"]
            low = alive & (new_w < tau)
            survive = u[3].astype(jnp.float64) * tau < new_w
            killed = low & ~survive
            rr = jnp.where(killed, new_w, jnp.where(low, new_w - tau, zero))
            acc[ROULETTE] = acc[ROULETTE] + rr
            other = other + rr
            new_w = jnp.where(low, jnp.where(survive, tau, zero), new_w)
            alive = alive & ~killed
        else:
            low = alive & (new_w < params["threshold"])
            dropped = jnp.where(low, new_w, zero)
            acc[DISCARDED] = acc[DISCARDED] + dropped
            other = other + dropped
            new_w = jnp.where(low, zero, new_w)
            alive = alive & ~low
        cnt[CNT_EVENTS] = cnt[CNT_EVENTS] + live.astype(jnp.int32)
        capped = alive & (cnt[CNT_EVENTS] >= params["max_events"])
        trunc = jnp.where(capped, new_w, zero)
        acc[TRUNCATED] = acc[TRUNCATED] + trunc
        other = other + trunc
        alive = alive & ~capped

        new_map, new_hist, new_budget = arrays
        if effects.irradiance_map:
            with jax.named_scope("irradiance_map"):
                idx = geometry.map_index(x, y, R, effects.map_bins)
                new_map = new_map.at[jnp.where(top, idx, nmap)].add(_fixed(w), mode="drop")
        if effects.incidence_histogram:
            with jax.named_scope("incidence_histogram"):
                theta = jnp.arccos(jnp.clip(dz, 0.0, 1.0))
                hb = effects.histogram_bins
                b = jnp.clip(jnp.floor(theta / (jnp.pi / 2) * hb), 0, hb - 1).astype(jnp.int32) + colour * hb
                new_hist = new_hist.at[jnp.where(top, b, nhist)].add(_fixed(w), mode="drop")
        if effects.interaction_budget:
            with jax.named_scope("interaction_budget"):
                k = jnp.minimum(n_plate, effects.budget_bins - 1) * len(BUDGET_COLUMNS)
                sink = jnp.where(live, 0, nbud)
                for c, val in enumerate((ext_b, ext_y, budget_cav, plate_abs, other)):
                    new_budget = new_budget.at[k + c + sink].add(_fixed(val), mode="drop")
        lane = dict(ids=ids, live=alive, px=x, py=y, pz=z, dx=ndx.astype(dt), dy=ndy.astype(dt), dz=ndz.astype(dt),
                    w=new_w, colour=new_colour.astype(jnp.int32), acc=acc, cnt=cnt)
        return lane, (new_map, new_hist, new_budget)

    def body(s):
        # (1) refill empty lanes with the next rays of the chunk, from the rolling emission buffer, which is
        # regenerated from ray ``next`` on whenever the next L rays are not all in it
        refresh = s["next"] + L > s["buf_start"] + B
        buf_start, buf = lax.cond(refresh, lambda: (s["next"], emit_block(s["next"])),
                                  lambda: (s["buf_start"], s["buf"]))
        ex, ey, ez, edx, edy, edz = buf
        empty = s["ray"] < 0
        rank = jnp.cumsum(empty, dtype=jnp.int32) - 1
        new_id = s["next"] + rank
        take = empty & (new_id < n_valid)
        src = jnp.clip(new_id - buf_start, 0, B - 1)
        ids = jnp.where(take, new_id, s["ray"])
        live = ids >= 0
        px = jnp.where(take, ex[src], s["px"])
        py = jnp.where(take, ey[src], s["py"])
        pz = jnp.where(take, ez[src], s["pz"])
        dx = jnp.where(take, edx[src], s["dx"])
        dy = jnp.where(take, edy[src], s["dy"])
        dz = jnp.where(take, edz[src], s["dz"])
        w = jnp.where(take, 1.0, s["w"])
        colour = jnp.where(take, 0, s["colour"])
        acc = [jnp.where(take, 0.0, a) for a in s["acc"]]
        cnt = [jnp.where(take, 0, c) for c in s["cnt"]]
        nxt = jnp.minimum(s["next"] + jnp.sum(empty, dtype=jnp.int32), n_valid)
        lane = dict(ids=ids, live=live, px=px, py=py, pz=pz, dx=dx, dy=dy, dz=dz, w=w, colour=colour, acc=acc,
                    cnt=cnt)
        arrays = (s["map"], s["hist"], s["budget"])
        lane, arrays = step(lane, arrays)
        new_map, new_hist, new_budget = arrays
        alive, acc, cnt = lane["live"], lane["acc"], lane["cnt"]

        # (3) retire finished rays
        retire = live & ~alive
        with jax.named_scope("retire"):
            total = acc[EXT_B] + acc[EXT_Y]
            values = jnp.stack(list(acc) + [total * total, acc[EXT_B] * acc[EXT_B], acc[EXT_Y] * acc[EXT_Y],
                                            acc[EXT_B] * acc[EXT_Y]] + [acc[c] * acc[c] for c in
                                                                        (ABS_WALL, ABS_BASE, ABS_LED, ABS_PLATE)])
            X = jnp.where(retire[None, :], jnp.rint(values * scales[:, None]), 0.0)  # integer-valued doubles
            h = jnp.floor(X * 2.0 ** -LIMB)
            hi = s["hi"] + h
            lo = s["lo"] + (X - h * 2.0 ** LIMB)
            counts = s["counts"] + jnp.where(retire[None, :], jnp.stack(cnt), 0).astype(jnp.int64)
        return dict(
            next=nxt, it=s["it"] + 1, buf_start=buf_start, buf=buf, ray=jnp.where(alive, ids, -1),
            px=lane["px"], py=lane["py"], pz=lane["pz"], dx=lane["dx"], dy=lane["dy"], dz=lane["dz"],
            w=lane["w"], colour=lane["colour"], acc=tuple(acc), cnt=tuple(cnt), hi=hi, lo=lo, counts=counts,
            map=new_map, hist=new_hist, budget=new_budget,
        )

    final = lax.while_loop(cond, body, state)
    return {"hi": jnp.sum(final["hi"].astype(jnp.int64), axis=1), "lo": jnp.sum(final["lo"].astype(jnp.int64), axis=1),
            "counts": jnp.sum(final["counts"], axis=1), "map": final["map"],
            "histogram": final["hist"], "budget": final["budget"], "iterations": final["it"]}


trace_chunk_jit = partial(jax.jit, static_argnames=("effects", "lanes"))(trace_chunk)
