"""Benchmarks and accuracy runs of the tracer (not a test; numbers go into docs/tracer.md).

    /tmp/venv/bin/python benchmarks/bench_trace.py                # speed: minimal vs full kernel vs NumPy
    /tmp/venv/bin/python benchmarks/bench_trace.py --oracle       # 9-case LER grid vs radiosity at 1e6 rays
    /tmp/venv/bin/python benchmarks/bench_trace.py --threshold    # bias of the flux threshold Th
    /tmp/venv/bin/python benchmarks/bench_trace.py --trends       # non-uniformity / LER trends of §5
    /tmp/venv/bin/python benchmarks/bench_trace.py --all

Speed is measured after compilation, on the example scene (fitting/scenes/example.toml), in the same
process for all three implementations; ratios are against the NumPy baseline of the same run.
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bsdfkit.raytrace import PhosphorPlate, load_scene, trace, with_values
from bsdfkit.raytrace.oracles.numpy_reference import trace_numpy
from bsdfkit.raytrace.oracles.radiosity import module_radiosity

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "fitting" / "scenes" / "example.toml"
TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def best_of(fn, repeats: int):
    """Run ``fn`` ``repeats`` times; return the result with the shortest wall time and that time."""
    best = None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t
        if best is None or dt < best[1]:
            best = (out, dt)
    return best


def speed(rays: int, repeats: int) -> None:
    scene = load_scene(EXAMPLE)
    print(f"# speed: {EXAMPLE.name}, {rays} rays, best of {repeats}; {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs (shared)")
    rows = []
    for label, kw in (("JAX minimal kernel", {}), ("JAX full kernel (forced)", {"full_kernel": True})):
        trace(scene, 20_000, seed=1, **kw)  # compile
        r, dt = best_of(lambda kw=kw: trace(scene, rays, seed=1, **kw), repeats)
        rows.append((label, r.interactions, dt, r.LER, r.std_err["LER"], r.ledger_error))
    ref, dt = best_of(lambda: trace_numpy(scene, rays, seed=1), repeats)
    rows.append(("NumPy reference (baseline)", ref.interactions, dt, ref.LER, ref.se_LER, ref.ledger_error))
    base = rows[-1][1] / rows[-1][2]
    print(f"{'implementation':30s} {'interactions/s':>15s} {'vs NumPy':>9s} {'LER':>9s} {'± se':>8s} {'ledger':>9s}")
    for label, n, dt, ler, se, led in rows:
        print(f"{label:30s} {n / dt:15.3e} {n / dt / base:9.2f} {ler:9.5f} {se:8.5f} {led:9.1e}")


def oracle(rays: int) -> None:
    base = load_scene(EXAMPLE)
    print(f"# oracle: exit top, LER vs radiosity (exact view factors), {rays} rays per case")
    print(f"{'h_mm':>5s} {'rho':>6s} {'LER_MC':>9s} {'sigma':>8s} {'LER_rad':>9s} {'z':>6s} {'ledger':>9s} {'s':>6s}")
    worst = 0.0
    for h in (10.0, 43.0, 80.0):
        for rho in (0.80, 0.90, 0.985):
            s = with_values(base, {"cavity.height_mm": h, "wall.reflectance": rho, "base.reflectance": rho})
            ref = module_radiosity(s).LER
            r = trace(s, rays, seed=int(h * 1000 + rho * 1000))
            z = (r.LER - ref) / r.std_err["LER"]
            worst = max(worst, abs(z))
            print(f"{h:5.0f} {rho:6.3f} {r.LER:9.5f} {r.std_err['LER']:8.5f} {ref:9.5f} {z:6.2f} "
                  f"{r.ledger_error:9.1e} {r.elapsed_s:6.1f}")
    print(f"max |z| = {worst:.2f}")


def plate_scene(tmp: Path, h=43.0, rho=0.985):
    path = tmp / "table2_plate.json"
    PhosphorPlate.constant(TABLE2, name="Table 2 (45 deg), angle-independent, Lambertian").save(path, force=True)
    s = load_scene(EXAMPLE)
    s = replace(s, top=replace(s.top, kind="phosphor", plate=PhosphorPlate.constant(TABLE2), plate_file=str(path)))
    return with_values(s, {"cavity.height_mm": h, "wall.reflectance": rho, "base.reflectance": rho})


def threshold(rays: int, tmp: Path) -> None:
    s = plate_scene(tmp)
    ref = trace(s, rays, seed=5)
    rad = module_radiosity(s)
    print(f"# threshold Th: Table-2 plate, h = 43 mm, rho = 0.985, {rays} rays; radiosity LER {rad.LER:.5f}")
    print(f"roulette (unbiased): LER {ref.LER:.5f} ± {ref.std_err['LER']:.5f}, YBR {ref.YBR:.3f} ± "
          f"{ref.std_err['YBR']:.3f}")
    print("(a) per-ray threshold: a ray is dropped when its weight < Th")
    print(f"{'Th':>7s} {'LER':>9s} {'bias':>9s} {'bias/se':>8s} {'YBR':>7s} {'dropped':>8s} {'interactions':>12s}")
    for th in (0.001, 0.01, 0.05, 0.1, 0.2):
        sc = replace(s, trace=replace(s.trace, termination="threshold", threshold=th))
        r = trace(sc, rays, seed=5)
        print(f"{th:7.3f} {r.LER:9.5f} {r.LER - ref.LER:9.5f} {(r.LER - ref.LER) / ref.std_err['LER']:8.1f} "
              f"{r.YBR:7.3f} {r.discarded / r.emitted:8.5f} {r.interactions / r.rays:12.2f}")
    print("(b) Fig. 6 rule: stop after the first plate interaction k whose remaining (in-flight) power < Th")
    cb = ref.cumulative_budget()
    print(f"{'Th':>7s} {'k':>3s} {'LER':>9s} {'bias':>9s}")
    for th in (0.001, 0.01, 0.05, 0.1):
        k = int(np.argmax(cb["in_flight"] < th * ref.emitted))
        ler = cb["extracted"][k] / ref.emitted
        print(f"{th:7.3f} {k + 1:3d} {ler:9.5f} {ler - ref.LER:9.5f}")
    print("cumulative extracted / losses after interaction k (Fig. 10 of the power-budget paper), % of emitted:")
    pct = {name: 100 * values / ref.emitted for name, values in cb.items()}
    for k in range(8):
        print(f"  k={k + 1}: extracted {pct['extracted'][k]:5.1f} (blue {pct['extracted_blue'][k]:4.1f}, "
              f"yellow {pct['extracted_yellow'][k]:5.1f})  losses {pct['losses'][k]:5.1f}  "
              f"in flight {pct['in_flight'][k]:5.1f}")


def trends(rays: int, tmp: Path) -> None:
    s = replace(plate_scene(tmp), tallies=replace(load_scene(EXAMPLE).tallies, irradiance_map=True))
    print(f"# trends (Table-2 plate, {rays} rays per point)")
    print(f"{'case':38s} {'LER':>8s} {'se':>7s} {'YBR':>6s} {'NU':>6s}")
    cases = [
        ("diffuser walls, h=43, rho=0.985", {"wall.specular_fraction": 0.0, "base.specular_fraction": 0.0}),
        ("mirror walls,   h=43, rho=0.985", {"wall.specular_fraction": 1.0, "base.specular_fraction": 1.0}),
        ("h=10", {"cavity.height_mm": 10.0}),
        ("h=43", {"cavity.height_mm": 43.0}),
        ("h=80", {"cavity.height_mm": 80.0}),
        ("rho=0.80, h=43", {"wall.reflectance": 0.80, "base.reflectance": 0.80}),
        ("rho=0.98, h=43", {"wall.reflectance": 0.98, "base.reflectance": 0.98}),
        ("LED FWHM 30 deg", {"leds.fwhm_deg": 30.0}),
        ("LED FWHM 120 deg (Lambertian)", {"leds.fwhm_deg": 120.0}),
    ]
    for label, values in cases:
        r = trace(with_values(s, values), rays, seed=7)
        print(f"{label:38s} {r.LER:8.4f} {r.std_err['LER']:7.4f} {r.YBR:6.2f} {r.non_uniformity:6.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rays", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--oracle", action="store_true")
    p.add_argument("--threshold", action="store_true")
    p.add_argument("--trends", action="store_true")
    p.add_argument("--all", action="store_true")
    p.add_argument("--tmp", default="/tmp/bsdfkit_bench")
    a = p.parse_args()
    tmp = Path(a.tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    if a.all or not (a.oracle or a.threshold or a.trends):
        speed(a.rays, a.repeats)
    if a.all or a.oracle:
        oracle(a.rays)
    if a.all or a.threshold:
        threshold(a.rays, tmp)
    if a.all or a.trends:
        trends(min(a.rays, 400_000), tmp)


if __name__ == "__main__":
    main()
