"""``trace(scene, rays, seed)``: run the compiled kernel chunk by chunk and close the energy ledger."""
from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import replace

import jax
import numpy as np

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.raytrace import kernel
from bsdfkit.raytrace.effects import Effects, kernel_params, scene_effects
from bsdfkit.raytrace.scene import Scene
from bsdfkit.raytrace.tallies import FixedSum, TraceResult, mean_and_se, non_uniformity, ratio_and_se

MAX_RAYS = 2 ** 31  # ray indices are 31-bit counters of the random-number generator


def trace(
    scene: Scene,
    rays: int,
    seed: int = 0,
    *,
    chunk: int | None = None,
    lanes: int | None = None,
    effects: Effects | None = None,
    full_kernel: bool = False,
    progress: Callable[[int], None] | None = None,
) -> TraceResult:
    """Trace ``rays`` rays through ``scene`` with random numbers keyed by ``seed``.

    ``chunk`` (default ``scene.trace.chunk``) rays are traced per compiled call and ``lanes`` (default
    ``scene.trace.lanes``) at once; neither changes the result. ``full_kernel=True`` traces with every
    optional branch compiled in (same physics, for benchmarks and tests); ``effects`` overrides the
    compiled configuration entirely. ``progress(done)`` is called after every chunk.
    """
    if not isinstance(rays, int) or isinstance(rays, bool) or not 1 <= rays < MAX_RAYS:
        raise ValidationError("ray count out of range", field="rays", expected=f"an integer in [1, {MAX_RAYS})",
                              got=rays)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2 ** 63:
        raise ValidationError("seed out of range", field="seed", expected="an integer in [0, 2**63)", got=seed)
    chunk = int(chunk or scene.trace.chunk)
    lanes = int(lanes or scene.trace.lanes)
    if chunk < 1 or lanes < 1:
        raise ValidationError("chunk and lanes must be positive", field="chunk", expected=">= 1",
                              got=(chunk, lanes))
    chunk = min(chunk, rays, kernel.MAX_CHUNK)
    lanes = min(lanes, 1 << max(chunk - 1, 1).bit_length())  # no more lanes than the next power of 2 ≥ chunk
    eff = effects or scene_effects(scene, full=full_kernel)
    if eff.plate_lobe and scene.trace.max_events >= 2 ** 22:
        raise ValidationError("lobe sampling needs fewer events per ray for its random-number counter",
                              file=scene.path, field="trace.max_events", expected="< 2**22",
                              got=scene.trace.max_events)

    if eff.termination == "roulette" and 1.0 + scene.trace.roulette_threshold * scene.trace.max_events \
            >= kernel.MAX_RAY_TALLY:
        raise ValidationError("roulette threshold x max_events too large for the exact tallies",
                              file=scene.path, field="trace.max_events",
                              expected=f"roulette_threshold * max_events < {kernel.MAX_RAY_TALLY - 1:g}",
                              got=scene.trace.roulette_threshold * scene.trace.max_events)

    t0 = time.perf_counter()
    ncol, nsq = len(kernel.COLUMNS), len(kernel.SQUARES)
    sums = [FixedSum(kernel.SCALE_SUM, kernel.LIMB) for _ in range(ncol)] + \
        [FixedSum(kernel.SCALE_SQUARE, kernel.LIMB) for _ in range(nsq)]
    counts = [0] * len(kernel.COUNTERS)
    arrays = {"map": None, "histogram": None, "budget": None}
    with x64():
        params = jax.tree_util.tree_map(jax.numpy.asarray, kernel_params(scene, eff))
        key_words = jax.random.key_data(jax.random.key(seed)).astype(jax.numpy.uint32)
        compiled = compiled_kernel(eff, lanes, _signature(params))
        compile_s = time.perf_counter() - t0
        done = 0
        while done < rays:
            n_valid = min(chunk, rays - done)
            out = jax.device_get(compiled(params, key_words, np.uint32(done), np.int32(n_valid)))
            for acc, h, lo in zip(sums, out["hi"].tolist(), out["lo"].tolist()):
                acc.add(h, lo)
            counts = [a + b for a, b in zip(counts, out["counts"].tolist())]
            for name in arrays:
                if out[name].size:
                    add = out[name].astype(object)
                    arrays[name] = add if arrays[name] is None else arrays[name] + add
            done += n_valid
            if progress is not None:
                progress(done)
    elapsed = time.perf_counter() - t0
    return _result(scene, rays, seed, chunk, lanes, eff, sums, counts, arrays, elapsed, compile_s)


def _signature(params) -> tuple:
    leaves, treedef = jax.tree_util.tree_flatten(params)
    return treedef, tuple((tuple(x.shape), str(x.dtype)) for x in leaves)


@functools.lru_cache(maxsize=16)
def compiled_kernel(effects: Effects, lanes: int, signature: tuple):
    """The kernel compiled for ``effects``, the lane count and a parameter signature (cached).

    Must be called inside :func:`bsdfkit.core.jaxconfig.x64`. Sweeping numbers (reflectance, height, plate TIS)
    keeps the signature, so a sweep compiles once per distinct :class:`Effects`.
    """
    treedef, shapes = signature
    abstract = jax.tree_util.tree_unflatten(treedef, [jax.ShapeDtypeStruct(s, d) for s, d in shapes])
    return kernel.trace_chunk_jit.lower(abstract, jax.ShapeDtypeStruct((2,), "uint32"),
                                        jax.ShapeDtypeStruct((), "uint32"), jax.ShapeDtypeStruct((), "int32"),
                                        effects=effects, lanes=lanes).compile()


def _result(scene, rays, seed, chunk, lanes, eff, sums, counts, arrays, elapsed, compile_s) -> TraceResult:
    n = rays
    scale = scene.leds.power_W / n  # W per unit ray weight
    ncol = len(kernel.COLUMNS)
    col = {name: sums[i].fraction for i, name in enumerate(kernel.COLUMNS)}
    sq = {name: sums[ncol + i].fraction for i, name in enumerate(kernel.SQUARES)}
    balance = sum(col.values())
    ledger_error = float(abs(n - balance) / n)
    ext_b, ext_y = col["extracted_blue"], col["extracted_yellow"]
    ler, se_ler = mean_and_se(ext_b + ext_y, sq["total"], n)
    ybr, se_ybr = ratio_and_se(ext_y, ext_b, sq["yellow"], sq["blue"], sq["blue_yellow"], n)
    _, se_b = mean_and_se(ext_b, sq["blue"], n)
    _, se_y = mean_and_se(ext_y, sq["yellow"], n)
    absorbed_names = {"absorbed_wall": "wall", "absorbed_base": "base", "absorbed_leds": "leds",
                      "absorbed_plate": "plate"}
    power = scene.leds.power_W
    std_err = {"LER": se_ler, "YBR": se_ybr, "blue": se_b * power, "yellow": se_y * power, "total": se_ler * power}
    for c, short in absorbed_names.items():
        std_err[f"absorbed_{short}"] = mean_and_se(col[c], sq[c], n)[1] * power
    fp = kernel.FIXED_POINT

    def fixed_to_w(a):
        return np.array([float(v) for v in a], dtype=float) / fp * scale

    irradiance = nu = hist = budget = None
    R = scene.cavity.radius_mm
    if arrays["map"] is not None:
        bins = eff.map_bins
        area = (2.0 * R / bins) ** 2
        irradiance = fixed_to_w(arrays["map"]).reshape(bins, bins) / area
        nu = non_uniformity(irradiance)
    if arrays["histogram"] is not None:
        hist = fixed_to_w(arrays["histogram"]).reshape(2, eff.histogram_bins)
    if arrays["budget"] is not None:
        budget = fixed_to_w(arrays["budget"]).reshape(eff.budget_bins, len(kernel.BUDGET_COLUMNS))
    return TraceResult(
        rays=rays, seed=seed, chunk=chunk, lanes=lanes,
        emitted=power,
        extracted={"blue": float(ext_b) * scale, "yellow": float(ext_y) * scale,
                   "total": float(ext_b + ext_y) * scale},
        absorbed={short: float(col[c]) * scale for c, short in absorbed_names.items()},
        roulette=float(col["roulette"]) * scale, discarded=float(col["discarded"]) * scale,
        truncated=float(col["truncated"]) * scale,
        ledger_error=ledger_error, LER=ler, YBR=ybr, std_err=std_err,
        interactions=int(counts[kernel.CNT_EVENTS]), plate_interactions=int(counts[kernel.CNT_PLATE]),
        clamped_interactions=int(counts[kernel.CNT_CLAMP]),
        irradiance=irradiance, non_uniformity=nu, incidence_histogram=hist, budget=budget, radius_mm=R,
        elapsed_s=elapsed, compile_s=compile_s, effects=eff,
    )


def threshold_bias(scene: Scene, rays: int, seed: int, thresholds, **kwargs) -> list[dict]:
    """LER with the per-ray flux threshold Th vs the unbiased (roulette) LER at the same seed.

    Returns one row per Th: ``{"Th", "LER", "LER_roulette", "bias", "se_roulette", "discarded"}``.
    """
    ref = trace(scene, rays, seed, **kwargs)
    rows = []
    for th in thresholds:
        sc = replace(scene, trace=replace(scene.trace, termination="threshold", threshold=float(th)))
        r = trace(sc, rays, seed, **kwargs)
        rows.append({"Th": float(th), "LER": r.LER, "LER_roulette": ref.LER, "bias": r.LER - ref.LER,
                     "se_roulette": ref.std_err["LER"], "discarded": r.discarded / r.emitted})
    return rows
