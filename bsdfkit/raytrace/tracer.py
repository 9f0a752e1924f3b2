"""``trace(scene, rays, seed)``: run the compiled kernel chunk by chunk and close the energy ledger."""
from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from fractions import Fraction
from typing import Any, NamedTuple

import jax
import numpy as np

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.raytrace import kernel, sampling
from bsdfkit.raytrace.effects import Effects, KernelParams, kernel_params, scene_effects
from bsdfkit.raytrace.programs import cached_program
from bsdfkit.raytrace.scene import (
    Scene,
    check_termination,
    check_work,
    map_symmetry,
    scene_spectral_tables,
    spectral_grid,
)
from bsdfkit.raytrace.tallies import (
    FixedSum,
    SpectralResult,
    TraceResult,
    map_fields,
    mean_and_se,
    ratio_and_se,
    spectral_ledger,
)

MAX_RAYS = 2 ** 31  # ray indices are 31-bit counters of the random-number generator


def trace(
    scene: Scene,
    rays: int,
    seed: int = 0,
    *,
    chunk: int | None = None,
    lanes: int | None = None,
    width: int | None = None,
    effects: Effects | None = None,
    full_kernel: bool = False,
    progress: Callable[[int], None] | None = None,
) -> TraceResult:
    """Trace ``rays`` rays through ``scene`` with random numbers keyed by ``seed``.

    ``chunk`` (default ``scene.trace.chunk``, at most rays / devices) rays are emitted and traced per device
    and compiled call, ``lanes`` (default ``scene.trace.lanes``) at once; every local JAX device traces its
    own chunk in parallel (:func:`compiled_kernel`). ``width`` (default :func:`emission_width` of the chunk)
    is the kernel's static emission count; a larger power of two lets traces of different lengths share one
    compiled kernel (it costs the unused emissions of each call). None of this changes the result.
    ``full_kernel=True``
    traces with every optional branch compiled in (same physics, for benchmarks and tests); ``effects``
    overrides the compiled configuration entirely. ``progress(done)`` is called after every chunk.

    Parameters
    ----------
    scene : Scene
        The parsed scene.
    rays : int
        Number of rays to trace.
    seed : int
        Seed of the random numbers.
    chunk : int, optional
        Rays per device and compiled call.
    lanes : int, optional
        Rays traced at once.
    width : int, optional
        Static emission count of the kernel.
    effects : Effects, optional
        Compiled configuration, replacing the scene's.
    full_kernel : bool
        Compile every optional branch in.
    progress : callable, optional
        Called with the number of rays done after every chunk.

    Returns
    -------
    TraceResult
        Powers [W], LER and YBR with standard errors, and the enabled tallies.
    """
    chunk, lanes, width, n_dev = _sizes(scene, rays, seed, chunk, lanes, width)
    check_termination(scene.wall, scene.base, scene.leds, scene.top, scene.trace, scene.path)  # replace()d scenes
    check_work(scene, rays)
    eff = effects or scene_effects(scene, full=full_kernel)
    _check_effects(scene, eff)
    t0 = time.perf_counter()
    ncol, nsq = len(kernel.COLUMNS), len(kernel.SQUARES)
    sums = [FixedSum(kernel.SCALE_SUM, kernel.LIMB) for _ in range(ncol)] + \
        [FixedSum(kernel.SCALE_SQUARE, kernel.LIMB) for _ in range(nsq)]
    counts = [0] * len(kernel.COUNTERS)
    arrays = {"map": None, "histogram": None, "budget": None, "spectrum": None, "emitted": None}
    with x64():
        params = jax.tree_util.tree_map(jax.numpy.asarray, kernel_params(scene, eff))
        key_words = jax.random.key_data(jax.random.key(seed)).astype(jax.numpy.uint32)
        compiled = compiled_kernel(eff, lanes, width, _signature(params), n_dev)
        leaves = tuple(jax.tree_util.tree_leaves(params))
        compile_s = time.perf_counter() - t0
        starts = list(range(0, rays, chunk))
        # one call traces n_dev chunks, one per device; a call is dispatched before the previous one is read
        calls = [starts[i:i + n_dev] for i in range(0, len(starts), n_dev)]
        pending: list = []

        def absorb(launched, finished) -> None:
            nonlocal counts
            out = jax.device_get(launched)
            for acc, h, lo in zip(sums, out["hi"].sum(axis=0).tolist(), out["lo"].sum(axis=0).tolist()):
                acc.add(h, lo)  # int64 sums over a few devices of limb sums < 2⁵³: exact
            counts = [a + b for a, b in zip(counts, out["counts"].sum(axis=0).tolist())]
            for name in arrays:
                if out[name].size:
                    add = out[name].astype(object).sum(axis=0)
                    arrays[name] = add if arrays[name] is None else arrays[name] + add
            if progress is not None:
                progress(finished)

        for group in calls:
            first = np.asarray(group + [rays] * (n_dev - len(group)), np.uint32)
            n_valid = np.asarray([min(chunk, rays - g) for g in group] + [0] * (n_dev - len(group)), np.int32)
            pending.append((compiled(leaves, key_words, first, n_valid), min(group[-1] + chunk, rays)))
            if len(pending) == 2:
                absorb(*pending.pop(0))
        for item in pending:
            absorb(*item)
    run = _Run(rays, seed, chunk, lanes, time.perf_counter() - t0, compile_s)
    return _result(scene, run, eff, sums, counts, arrays)


def _sizes(scene: Scene, rays: int, seed: int, chunk: int | None, lanes: int | None,
           width: int | None) -> tuple[int, int, int, int]:
    """The checked sizes of a trace: rays per chunk, lanes, emission width and local devices (:func:`trace`)."""
    if not isinstance(rays, int) or isinstance(rays, bool) or not 1 <= rays < MAX_RAYS:
        raise ValidationError("ray count out of range", field="rays", expected=f"an integer in [1, {MAX_RAYS})",
                              got=rays)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2 ** 63:
        raise ValidationError("seed out of range", field="seed", expected="an integer in [0, 2**63)", got=seed)
    # None means the scene's value; 0 or a negative number is an error, never silently the default
    chunk = int(scene.trace.chunk if chunk is None else chunk)
    lanes = int(scene.trace.lanes if lanes is None else lanes)
    for name, value in (("chunk", chunk), ("lanes", lanes)):
        if value < 1:
            raise ValidationError(f"{name} must be positive", field=name, expected=">= 1", got=value)
    if chunk > kernel.MAX_CHUNK:
        raise ValidationError("chunk too large for the kernel's counters", field="chunk",
                              expected=f"<= MAX_CHUNK ({kernel.MAX_CHUNK})", got=chunk)
    n_dev = len(jax.local_devices())  # chunks run in parallel on every local device (CPU devices: see below)
    chunk = min(chunk, -(-rays // n_dev), kernel.MAX_CHUNK)
    if width is None:
        width = emission_width(chunk)  # emissions per kernel call (static): a power of two, ≥ chunk
    elif not isinstance(width, int) or isinstance(width, bool) or width < chunk or width & (width - 1) \
            or width > kernel.MAX_CHUNK:
        raise ValidationError("emission width must be a power of two, at least the chunk", field="width",
                              expected=f"a power of two in [{chunk}, {kernel.MAX_CHUNK}]", got=width)
    return chunk, min(lanes, width), width, n_dev


def _check_effects(scene: Scene, eff: Effects) -> None:
    """The limits the compiled effects set on the scene: lobe sampling's counter, the exact tallies' magnitude."""
    limit = 2 ** 32 // sampling.LOBE_ATTEMPTS  # events whose attempt counter event·LOBE_ATTEMPTS + a fits in 32 bits
    if eff.plate_lobe and scene.trace.max_events >= limit:
        raise ValidationError("lobe sampling needs fewer events per ray for its random-number counter",
                              file=scene.path, field="trace.max_events", expected=f"< 2**{limit.bit_length() - 1}",
                              got=scene.trace.max_events)
    # a spectral ray's power weight can grow by λ_max/λ_min at anti-Stokes conversions (its photons cannot)
    lam = spectral_grid(scene) if eff.spectral else None
    growth = float(lam[-1] / lam[0]) if eff.spectral else 1.0
    if eff.termination == "roulette" and growth * (1.0 + scene.trace.roulette_threshold * scene.trace.max_events) \
            >= kernel.MAX_RAY_TALLY:
        raise ValidationError("roulette threshold x max_events too large for the exact tallies",
                              file=scene.path, field="trace.max_events",
                              expected=f"roulette_threshold * max_events < {kernel.MAX_RAY_TALLY - 1:g}",
                              got=scene.trace.roulette_threshold * scene.trace.max_events)


class _Run(NamedTuple):
    """How a trace ran: its rays, seed, chunk and lanes, and its wall-clock and compile times [s]."""

    rays: int
    seed: int
    chunk: int
    lanes: int
    elapsed: float
    compile_s: float


def common_chunk(scene: Scene, rays: Sequence[int]) -> int:
    """Rays per device and call that let traces of ``scene`` (and of scenes of the same sizes) of each ray count
    in ``rays`` run on one compiled kernel: the chunk :func:`trace` gives the smallest of them.

    :func:`trace` cuts each trace into chunks of at most rays / devices and compiles its kernel for that
    chunk's emission width, so a study at half the device's rays would load a second kernel (about 1 s from
    the persistent cache, 10 s compiled). Chunks never change a result.

    Parameters
    ----------
    scene : Scene
        The scene (its ``[trace] chunk`` is the largest chunk).
    rays : sequence of int
        The ray counts of the traces [-].

    Returns
    -------
    int
        Rays per device and call [-], for :func:`trace`'s ``chunk``.
    """
    return _sizes(scene, min(rays), 0, None, None, None)[0]


def emission_width(chunk: int) -> int:
    """Static emission count of the compiled kernel for chunks of ``chunk`` rays: the next power of two
    (at least 1024), so traces of different lengths share a few compiled kernels.

    Parameters
    ----------
    chunk : int
        Rays per chunk.

    Returns
    -------
    int
        A power of two, at least 1024.
    """
    return max(1024, 1 << max(chunk - 1, 1).bit_length())


def _signature(params: KernelParams) -> tuple:
    """The tree structure of ``params`` and the (shape, dtype) of its leaves: what a compiled kernel depends on."""
    leaves, treedef = jax.tree_util.tree_flatten(params)
    return treedef, tuple((tuple(x.shape), str(x.dtype)) for x in leaves)


@functools.lru_cache(maxsize=32)
def compiled_kernel(effects: Effects, lanes: int, width: int, signature: tuple, n_devices: int = 1):
    """The kernel compiled for ``effects``, the lane count, the emission width and a parameter signature
    (cached per process; with JAX's persistent compilation cache on, across processes too).

    One program for ``n_devices`` local devices (``jax.shard_map``): call it with ``starts`` and ``n_valid`` of
    shape (n_devices,), one chunk per device; every output gets a leading device axis. The devices run their
    chunks independently (no communication), so a second CPU device (``--xla_force_host_platform_device_count``,
    set by the command line) or a second GPU doubles the throughput with a single compilation.
    Must be called inside :func:`bsdfkit.core.jaxconfig.x64`. Sweeping numbers (reflectance, height, plate TIS)
    keeps the signature, so a sweep compiles once per distinct :class:`Effects`. With JAX's persistent
    compilation cache on, the traced program is kept on disk too (:mod:`bsdfkit.raytrace.programs`).

    Parameters
    ----------
    effects : Effects
        Static kernel configuration.
    lanes : int
        Rays traced at once per device.
    width : int
        Static emission count per chunk.
    signature : tuple
        Tree structure and (shape, dtype) of every leaf of the kernel parameters.
    n_devices : int
        Local devices the program spans.

    Returns
    -------
    callable
        The compiled program ``(leaves, key_words, starts, n_valid) → dict of arrays``; ``leaves`` is the tuple
        of the parameters' leaves (``jax.tree_util.tree_leaves``): the exported program's calling convention
        holds no :class:`KernelParams` (``jax.export`` serialises only the pytree types it knows).
    """
    treedef, shapes = signature
    mesh = jax.sharding.Mesh(np.asarray(jax.local_devices()[:n_devices]), ("chunks",))
    replicated = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    split = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("chunks"))

    def per_device(leaves, key_words, starts, n_valid):
        params = jax.tree_util.tree_unflatten(treedef, leaves)
        out = kernel.trace_chunk(params, key_words, starts[0], n_valid[0], effects=effects, lanes=lanes,
                                 chunk=width)
        return jax.tree_util.tree_map(lambda a: a[None], out)

    spec = jax.sharding.PartitionSpec
    program = jax.jit(jax.shard_map(per_device, mesh=mesh, in_specs=(spec(), spec(), spec("chunks"), spec("chunks")),
                                    out_specs=spec("chunks"), check_vma=False))
    abstract = tuple(jax.ShapeDtypeStruct(s, d, sharding=replicated) for s, d in shapes)
    args = (abstract, jax.ShapeDtypeStruct((2,), "uint32", sharding=replicated),
            jax.ShapeDtypeStruct((n_devices,), "uint32", sharding=split),
            jax.ShapeDtypeStruct((n_devices,), "int32", sharding=split))
    program = cached_program(program, args, ("trace_chunk", effects, lanes, width, signature, n_devices))
    return program.lower(*args).compile(kernel.COMPILER_OPTIONS)


def _result(scene: Scene, run: _Run, eff: Effects, sums: list, counts: list, arrays: dict) -> TraceResult:
    n = rays = run.rays
    scale = scene.leds.power_W / n  # W per unit ray weight
    ncol = len(kernel.COLUMNS)
    col = {name: sums[i].fraction for i, name in enumerate(kernel.COLUMNS)}
    sq = {name: sums[ncol + i].fraction for i, name in enumerate(kernel.SQUARES)}
    balance = sum(col[c] for c in kernel.POWER_COLUMNS)
    ledger_error = float(abs(n - balance) / n)
    ext_b, ext_y = col["extracted_blue"], col["extracted_yellow"]
    ler, se_ler = mean_and_se(ext_b + ext_y + col["extracted_other"], sq["total"], n)
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

    hist = budget = None
    maps: dict[str, Any] = {}
    R = scene.cavity.radius_mm
    if arrays["map"] is not None:
        bins = eff.map_bins
        area = (2.0 * R / bins) ** 2
        parts = fixed_to_w(arrays["map"]).reshape(kernel.MAP_PARTS, bins, bins) / area
        maps = map_fields(parts, symmetric=map_symmetry(scene) == 8)
    if arrays["histogram"] is not None:
        hist = fixed_to_w(arrays["histogram"]).reshape(2, eff.histogram_bins)
    if arrays["budget"] is not None:
        budget = fixed_to_w(arrays["budget"]).reshape(eff.budget_bins, len(kernel.BUDGET_COLUMNS))
    return TraceResult(
        rays=rays, seed=run.seed, chunk=run.chunk, lanes=run.lanes,
        emitted=power,
        extracted={"blue": float(ext_b) * scale, "yellow": float(ext_y) * scale,
                   "total": float(ext_b + ext_y + col["extracted_other"]) * scale},
        absorbed={short: float(col[c]) * scale for c, short in absorbed_names.items()},
        roulette=float(col["roulette"]) * scale, discarded=float(col["discarded"]) * scale,
        truncated=float(col["truncated"]) * scale,
        ledger_error=ledger_error, LER=ler, YBR=ybr, std_err=std_err,
        interactions=int(counts[kernel.CNT_EVENTS]), plate_interactions=int(counts[kernel.CNT_PLATE]),
        clamped_interactions=int(counts[kernel.CNT_CLAMP]),
        **maps, incidence_histogram=hist, budget=budget, radius_mm=R,
        elapsed_s=run.elapsed, compile_s=run.compile_s, effects=eff,
        spectral=spectral_result(scene, n, col, arrays) if eff.spectral else None,
    )


def spectral_result(scene: Scene, n: int, col: dict, arrays: dict) -> SpectralResult:
    """The spectral tallies of a trace: spectrum (W/nm) with standard errors, bands, ledger in power and photons.

    Parameters
    ----------
    scene : Scene
        The traced spectral scene.
    n : int
        Number of rays traced.
    col : dict of str to Fraction
        Column of :data:`kernel.COLUMNS` → summed per-ray weight (in unit-weight rays).
    arrays : dict
        The kernel's array tallies; ``spectrum`` and ``emitted`` are read.

    Returns
    -------
    SpectralResult
        Extracted and emitted spectra [W/nm] on the bins [nm], standard errors, and the power and photon ledger.
    """
    tab = scene_spectral_tables(scene)
    lam = tab.lam
    K = lam.size
    step = float(lam[1] - lam[0])
    power = scene.leds.power_W
    fp = kernel.FIXED_POINT
    spec = np.array([Fraction(int(v), int(fp)) for v in arrays["spectrum"]], dtype=object)
    s1, s2 = spec[:K], spec[K:]
    mean_se = [mean_and_se(a, b, n) for a, b in zip(s1, s2)]
    spectrum = np.array([m for m, _ in mean_se]) * power / step
    spectrum_se = np.array([e for _, e in mean_se]) * power / step
    emitted_bins = np.array([int(v) for v in arrays["emitted"]], dtype=object)
    return SpectralResult(wavelength_nm=lam, spectrum_W_per_nm=spectrum, spectrum_std_err=spectrum_se,
                          emitted_W_per_nm=np.array([float(Fraction(int(c), n)) for c in emitted_bins]) * power / step,
                          ledger=spectral_ledger(col, emitted_bins, tab.photon_scale, lam, n, power),
                          extrapolated_nm=tab.extrapolated_nm, capped=tab.capped,
                          yiys_nm=tab.yiys_nm)


def threshold_bias(scene: Scene, rays: int, seed: int, thresholds, **kwargs) -> list[dict]:
    """LER with the per-ray flux threshold Th vs the unbiased (roulette) LER at the same seed.

    Returns one row per Th: ``{"Th", "LER", "LER_roulette", "bias", "se_roulette", "discarded"}``.

    Parameters
    ----------
    scene : Scene
        The parsed scene.
    rays : int
        Rays per trace.
    seed : int
        Seed of every trace.
    thresholds : iterable of float
        Per-ray flux thresholds Th [-] (fraction of a ray's starting weight).
    **kwargs
        Passed to :func:`trace`.

    Returns
    -------
    list of dict
        One row per threshold.
    """
    ref = trace(scene, rays, seed, **kwargs)
    rows = []
    for th in thresholds:
        sc = replace(scene, trace=replace(scene.trace, termination="threshold", threshold=float(th)))
        r = trace(sc, rays, seed, **kwargs)
        rows.append({"Th": float(th), "LER": r.LER, "LER_roulette": ref.LER, "bias": r.LER - ref.LER,
                     "se_roulette": ref.std_err["LER"], "discarded": r.discarded / r.emitted})
    return rows
