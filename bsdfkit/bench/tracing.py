"""Tracer studies: LER error vs rays, roulette vs the flux threshold Th, float32 vs float64.

The truth is the two-wavelength radiosity oracle with exact view factors (:mod:`bsdfkit.raytrace.oracles.radiosity`) of
the same scene: a fully diffuse cavity with Lambertian LEDs, exit top or the Table-2 plate taken as
angle-independent and Lambertian. Errors are relative; for a Monte Carlo run the reported error is
max(|LER − oracle|, 2σ)/oracle, so a lucky run cannot claim an accuracy its statistics do not support.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from bsdfkit.bench.core import Row, Study
from bsdfkit.raytrace import PhosphorPlate, Top, load_scene, trace, with_values
from bsdfkit.raytrace.oracles.radiosity import module_radiosity
from bsdfkit.raytrace.tracer import _sizes

SCENES = Path(__file__).resolve().parents[2] / "fitting" / "scenes"
TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def _example(plate: bool):
    scene = load_scene(SCENES / "example.toml")
    if plate:

        scene = replace(scene, top=Top(kind="phosphor", plate=PhosphorPlate.constant(TABLE2, name="Table 2, 45°")))
    return scene


def _compile(scene, rays: int) -> None:
    """Compile the kernel that ``trace(scene, rays)`` runs (its lanes and emission width; the compiled kernels
    are cached per process) by tracing a few rays through it, so that the timed trace excludes compilation."""
    width = _sizes(scene, rays, 0, None, None, None)[2]
    trace(scene, 2000, 0, width=width)


def _error(result, oracle: float) -> float:
    return max(abs(result.LER - oracle), 2 * result.std_err["LER"]) / oracle


def rays(quick: bool) -> Study:
    """LER error of the example cavity against the radiosity oracle as the ray count grows.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    scene = _example(plate=True)
    oracle = module_radiosity(scene).LER
    rows = []
    for n in ((10_000, 100_000, 400_000) if quick else (10_000, 100_000, 1_000_000, 4_000_000)):
        _compile(scene, n)  # outside the timing
        start = time.perf_counter()
        r = trace(scene, n, 7)
        wall = time.perf_counter() - start
        rows.append(Row(f"{n:.0e} rays", _error(r, oracle), wall, n,
                        {"LER": r.LER, "sigma_rel": r.std_err["LER"] / oracle, "oracle": oracle}))
    return Study("trace_rays", "Tracer: LER error vs rays (example cavity h = 43 mm, ρ = 0.9, Table-2 plate)",
                 "max(|LER − radiosity oracle|, 2σ) / oracle", "rays", tuple(rows),
                 notes="Wall time excludes compilation (done once per scene configuration, 2-6 s here).")


def termination(quick: bool) -> Study:
    """Russian roulette against the per-ray flux threshold Th: LER error and bias at ρ = 0.985.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    scene = with_values(_example(plate=True), {"wall.reflectance": 0.985, "base.reflectance": 0.985})
    oracle = module_radiosity(scene).LER
    n = 100_000 if quick else 1_000_000
    rows = []
    _compile(scene, n)
    start = time.perf_counter()
    ref = trace(scene, n, 3)
    rows.append(Row("Russian roulette (unbiased)", _error(ref, oracle), time.perf_counter() - start, n,
                    {"group": "roulette", "bias": ref.LER - oracle}))
    for th in ((0.01, 0.1) if quick else (0.001, 0.01, 0.05, 0.1, 0.2)):
        sc = replace(scene, trace=replace(scene.trace, termination="threshold", threshold=th))
        _compile(sc, n)
        start = time.perf_counter()
        r = trace(sc, n, 3)
        rows.append(Row(f"flux threshold Th = {th:g}", _error(r, oracle), time.perf_counter() - start, n,
                        {"group": "threshold", "bias": r.LER - oracle, "discarded": r.discarded / r.emitted}))
    return Study("trace_termination", "Tracer: Russian roulette vs the per-ray flux threshold Th (ρ = 0.985, plate)",
                 "max(|LER − radiosity oracle|, 2σ) / oracle", "rays", tuple(rows), groups=("roulette", "threshold"),
                 notes="The threshold drops light (biased low); roulette keeps the expectation exact. Per-iteration "
                       "thresholds as in Fig. 6 of the cylindrical-module paper are discussed in docs/tracer.md.")


def precision(quick: bool) -> Study:
    """float32 against float64 ray geometry: LER error against the radiosity oracle, same seed.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    scene = _example(plate=True)
    oracle = module_radiosity(scene).LER
    n = 100_000 if quick else 1_000_000
    rows = []
    for prec in ("float32", "float64"):
        sc = replace(scene, trace=replace(scene.trace, precision=prec))
        _compile(sc, n)
        start = time.perf_counter()
        r = trace(sc, n, 5)
        rows.append(Row(prec, _error(r, oracle), time.perf_counter() - start, n,
                        {"group": prec, "LER": r.LER, "ledger_error": r.ledger_error}))
    return Study("trace_precision", "Tracer: float32 vs float64 ray geometry (same seed; tallies always float64)",
                 "max(|LER − radiosity oracle|, 2σ) / oracle", "rays", tuple(rows), groups=("float32", "float64"))
