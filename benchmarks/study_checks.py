"""Two checks of the main job's module trace that are too costly for the job itself (numbers in docs/tracer.md).

    .venv/bin/python benchmarks/study_checks.py --grid  [--seeds 8 --rays 400000]   # non-uniformity vs map grid
    .venv/bin/python benchmarks/study_checks.py --clamp [--recipe fitting/cl830.toml]  # studies, clamped plate

``--grid``: the device of ``fitting/cl830.toml`` (its own plate) and the five study points for which the
cylindrical-module paper prints a non-uniformity, traced with a 128 × 128 irradiance map for ``--seeds``
independent seeds; each map is summed into 64, 32 and 16 cells per side (exact: the coarse cells are blocks of
the fine ones), and the non-uniformity (E_max − E_min)/(E_max + E_min) over the cells entirely inside the plate
is given per grid as the mean over seeds with the seeds' standard deviation (σ of one run), with the pooled map of
all seeds (``--seeds`` × ``--rays`` rays), and with the split-half estimate (cells of the extremes chosen on one
half of the seeds, their irradiance read on the other half: no noise maximum).

``--clamp``: every study point of the recipe traced twice, with the plate model-extrapolated beyond the measured
incidences (the main job) and with the plate on its measured incidences only (the tracer clamps outside them);
per point LER, YBR, non-uniformity with σ, and the share of plate power on extrapolated incidences. The trend
verdicts of both are printed with the main job's rule (:func:`bsdfkit.pipeline.recipe._trends`).

Writes JSON to ``--out`` (default: print only).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from bsdfkit.cli.main import DEVICES_FLAG, MAX_CPU_DEVICES

if DEVICES_FLAG not in os.environ.get("XLA_FLAGS", ""):
    _cores = min(len(os.sched_getaffinity(0)), MAX_CPU_DEVICES)
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {DEVICES_FLAG}={_cores}".strip()

import numpy as np  # noqa: E402

from bsdfkit.measurement.calibrate import calibrate  # noqa: E402
from bsdfkit.measurement.raw_scan import read_scan  # noqa: E402
from bsdfkit.pipeline.plate_from_scan import plate_from_scan  # noqa: E402
from bsdfkit.pipeline.recipe import STUDIES, _scene_with_plate, _trends, incidence_shares, load_recipe  # noqa: E402
from bsdfkit.raytrace import trace, with_values  # noqa: E402
from bsdfkit.raytrace.tallies import grid_study, non_uniformity_std  # noqa: E402
from bsdfkit.reduction.tis import tis_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ROOT / "fitting" / "cl830.toml"
#: The panels with a non-uniformity printed by the cylindrical-module paper (the device is h = 43 mm, FWHM 120°).
PANELS = {"device": {}, "mirror walls": {"wall.specular_fraction": 1.0, "base.specular_fraction": 1.0},
          "diffuse walls": {"wall.specular_fraction": 0.0, "base.specular_fraction": 0.0},
          "h = 10 mm": {"cavity.height_mm": 10.0}, "FWHM 30°": {"leds.fwhm_deg": 30.0}}


def _scene(extrapolate: bool, bins: int, recipe_path: Path = RECIPE):
    recipe = load_recipe(recipe_path)
    scan = calibrate(read_scan(recipe.measurement))
    tis = tis_table(scan)
    plate = plate_from_scan(scan, tis, name=recipe.name, extrapolate=extrapolate)
    scene = with_values(_scene_with_plate(recipe.trace.scene, plate),
                        {"tallies.irradiance_map": True, "tallies.map_bins": bins,
                         "tallies.incidence_histogram": True})
    measured = (float(tis["theta_i"].values[0]), float(tis["theta_i"].values[-1]))
    return recipe, scene, measured


def grid(seeds: int, rays: int, panels: list[str]) -> dict:
    _, scene, _ = _scene(True, 128)
    out = {}
    for name in panels:
        maps = [trace(with_values(scene, PANELS[name]) if PANELS[name] else scene, rays, seed).irradiance
                for seed in range(1, seeds + 1)]
        out[name] = grid_study(np.stack(maps), (128, 64, 32, 16))
        print(name, json.dumps(out[name]), flush=True)
    return out


def _row(r, values: dict, measured) -> dict:
    return {"values": values, "LER": r.LER, "LER_std": r.std_err["LER"], "YBR": r.YBR, "YBR_std": r.std_err["YBR"],
            "non_uniformity": r.non_uniformity, "non_uniformity_std": non_uniformity_std(r.irradiance),
            "plate_incidence": incidence_shares(r, measured)}


def clamp(rays: int | None, recipe_path: Path = RECIPE) -> dict:
    out = {}
    for label, extrapolate in (("extrapolated", True), ("clamped", False)):
        recipe, scene, measured = _scene(extrapolate, 32, recipe_path)
        opts = recipe.trace
        device = trace(scene, opts.rays if rays is None else rays, opts.seed)
        studies: dict[str, list[dict]] = {}
        for study, (keys, _) in STUDIES.items():
            for value in getattr(opts, study):
                values = dict.fromkeys(keys, value)
                r = trace(with_values(scene, values), opts.rays if rays is None else rays, opts.seed)
                studies.setdefault(study, []).append(_row(r, values, measured))
        out[label] = {"device": _row(device, {}, measured), "studies": studies,
                      "trends": _trends(device, studies)}
        for name, t in out[label]["trends"].items():
            print(f"{label:12s} {name}: {'holds' if t['holds'] else 'does not hold'} ({t['detail']})", flush=True)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--grid", action="store_true")
    p.add_argument("--clamp", action="store_true")
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--rays", type=int, default=None, help="rays per trace (default: the recipe's; --grid: 400000)")
    p.add_argument("--recipe", type=Path, default=RECIPE, help="--clamp: the recipe whose studies are traced")
    p.add_argument("--panels", default=",".join(PANELS))
    p.add_argument("--out", type=Path)
    a = p.parse_args()
    result = {}
    if a.grid:
        result["grid"] = grid(a.seeds, a.rays or 400_000, a.panels.split(","))
    if a.clamp:
        result["clamp"] = clamp(a.rays, a.recipe)
    if not result:
        sys.exit("choose --grid and/or --clamp")
    if a.out:
        a.out.write_text(json.dumps(result, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()
