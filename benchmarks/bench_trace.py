"""Benchmarks and accuracy runs of the tracer (not a test; numbers go into docs/tracer.md).

    .venv/bin/python benchmarks/bench_trace.py                  # speed: kernel vs NumPy vs Mitsuba 3 (if installed)
    .venv/bin/python benchmarks/bench_trace.py --baseline HEAD  # + the kernel of a git revision, same run
    .venv/bin/python benchmarks/bench_trace.py --phosphor       # full phosphor kernel of the main job
    .venv/bin/python benchmarks/bench_trace.py --backend        # paths/s and segments/s on the JAX backend present
    .venv/bin/python benchmarks/bench_trace.py --oracle         # 9-case LER grid vs radiosity at 1e6 rays
    .venv/bin/python benchmarks/bench_trace.py --threshold      # bias of the flux threshold Th
    .venv/bin/python benchmarks/bench_trace.py --trends         # non-uniformity / LER trends of §5
    .venv/bin/python benchmarks/bench_trace.py --spectral       # spectral vs two-wavelength mode, same scene
    .venv/bin/python benchmarks/bench_trace.py --ab REV         # kernel vs the kernel at REV, interleaved runs
    .venv/bin/python benchmarks/bench_trace.py --all

Speed is measured after compilation, in one process for every implementation, as the median of
``--repeats`` runs; ratios are between implementations of the same run (the machine may be shared). The
speed scene is fitting/scenes/example.toml: diffuse cylinder r 35 mm, h 43 mm, ρ 0.90, four Lambertian LEDs,
exit top; LER is checked against the radiosity answer (z = (LER − LER_rad)/σ).

Mitsuba 3 (``pip install -c requirements.lock '.[bench]'``; its LLVM variant needs a system libLLVM, e.g.
Debian's libllvm19, found through DRJIT_LIBLLVM_PATH — the script tries the usual library folders) traces the
same cavity with its forward light tracer (``ptracer``, LLVM backend, all cores): four diffuse area-light
disks in the base, a two-sided diffuse tube and base, and the exit top as an irradiance meter; paths/s is light
paths (samples) per second after a warm-up render. The meter's reading is not compared as an LER (its scale
was not calibrated: reading/LER differs by 7 % between rho 0 and 0.9), only the speed.
"""
from __future__ import annotations

import argparse
import glob
import importlib.util
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from bsdfkit.cli.main import DEVICES_FLAG, MAX_CPU_DEVICES

# like the command line: one JAX CPU device per core (the tracer runs a chunk on each), unless XLA_FLAGS says
if DEVICES_FLAG not in os.environ.get("XLA_FLAGS", ""):
    _cores = min(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1,
                 MAX_CPU_DEVICES)
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {DEVICES_FLAG}={_cores}".strip()

import jax  # noqa: E402  (after XLA_FLAGS)
import numpy as np  # noqa: E402

from bsdfkit.pipeline.plate_from_scan import plate_from_recipe  # noqa: E402
from bsdfkit.raytrace import PhosphorPlate, load_scene, trace, with_values  # noqa: E402
from bsdfkit.raytrace.oracles.numpy_reference import trace_numpy  # noqa: E402
from bsdfkit.raytrace.oracles.radiosity import module_radiosity  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "fitting" / "scenes" / "example.toml"
DEVICE = ROOT / "fitting" / "scenes" / "cl830_device.toml"
SPECTRAL = ROOT / "fitting" / "scenes" / "spectral_example.toml"
TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def median_of(fn, repeats: int):
    """Run ``fn`` ``repeats`` times; return the last result and the median wall time."""
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, statistics.median(times)


# --- the kernel of another git revision, for "today vs now" ratios in one run ---------------------------------------

def baseline_trace(rev: str):
    """``trace`` of the tracer at git revision ``rev`` (kernel, sampling, effects, tracer taken from git; the other
    modules are today's), imported from a temporary package."""
    tmp = Path(tempfile.mkdtemp(prefix="bsdfkit_baseline_"))
    pkg = tmp / "baseline_raytrace"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for name in ("kernel", "sampling", "effects", "tracer"):
        text = subprocess.run(["git", "show", f"{rev}:bsdfkit/raytrace/{name}.py"], cwd=ROOT, check=True,
                              capture_output=True, text=True).stdout
        for mod in ("kernel", "sampling", "effects", "tracer"):
            text = text.replace(f"from bsdfkit.raytrace.{mod} import", f"from baseline_raytrace.{mod} import")
        text = text.replace("from bsdfkit.raytrace import geometry, sampling",
                            "from bsdfkit.raytrace import geometry\nfrom baseline_raytrace import sampling")
        text = text.replace("from bsdfkit.raytrace import kernel", "from baseline_raytrace import kernel")
        (pkg / f"{name}.py").write_text(text)
    sys.path.insert(0, str(tmp))
    spec = importlib.util.find_spec("baseline_raytrace.tracer")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.trace


# --- Mitsuba 3 -------------------------------------------------------------------------------------------------------

def _find_libllvm() -> str | None:
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    found = glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*")

    def version(path: str) -> tuple:  # the newest LLVM (Dr.Jit needs a recent one)
        return tuple(int(x) for x in re.findall(r"\d+", Path(path).name))

    return max(found, key=version) if found else None


def mitsuba_tracer(scene):
    """A function paths → (seconds, LER) tracing ``scene`` (exit top) with Mitsuba 3's ``ptracer``, or None."""
    if importlib.util.find_spec("mitsuba") is None:
        return None, "mitsuba not installed (pip install -c requirements.lock '.[bench]')"
    lib = _find_libllvm()
    if lib:
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", lib)
    import mitsuba as mi  # optional benchmark dependency, imported only when present

    try:
        mi.set_variant("llvm_ad_mono")
    except Exception as exc:  # no usable libLLVM
        return None, f"mitsuba LLVM variant unavailable ({exc})"
    R, H = scene.cavity.radius_mm, scene.cavity.height_mm
    rho = scene.wall.reflectance
    k, pitch, a = scene.leds.grid, scene.leds.pitch_mm, scene.leds.emitter_radius_mm
    T = mi.ScalarTransform4f
    diffuse = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": rho}}}
    base_rho = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum",
                                                                                 "value": scene.base.reflectance}}}
    led_area = math.pi * a * a
    radiance = scene.leds.power_W / (k * k) / (led_area * math.pi)  # Lambertian disk of power P/k²
    d = {"type": "scene",
         "integrator": {"type": "ptracer", "max_depth": -1, "rr_depth": 5, "hide_emitters": False},
         "wall": {"type": "cylinder", "p0": [0, 0, 0], "p1": [0, 0, H], "radius": R, "bsdf": diffuse},
         "base": {"type": "disk", "to_world": T().scale([R, R, 1]), "bsdf": base_rho},
         "top": {"type": "disk", "to_world": T().translate([0, 0, H]).scale([R, R, 1]).rotate([1, 0, 0], 180),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}},
                 "sensor": {"type": "irradiancemeter",
                            "film": {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"},
                                     "pixel_format": "luminance"}}}}
    for i in range(k):
        for j in range(k):
            cx, cy = (i - (k - 1) / 2) * pitch, (j - (k - 1) / 2) * pitch
            d[f"led{i}{j}"] = {"type": "disk", "to_world": T().translate([cx, cy, 1e-4]).scale([a, a, 1]),
                               "bsdf": base_rho,
                               "emitter": {"type": "area", "radiance": {"type": "spectrum", "value": radiance}}}
    mscene = mi.load_dict(d)
    top_area = math.pi * R * R

    def run(paths: int, seed: int = 1):
        t = time.perf_counter()
        img = mi.render(mscene, spp=paths, seed=seed)
        value = float(np.asarray(img).ravel()[0])
        return time.perf_counter() - t, value * top_area / scene.leds.power_W  # irradiance × area = flux

    return run, "ok"


# --- speed -----------------------------------------------------------------------------------------------------------

def speed(rays: int, repeats: int, baseline: str | None, with_mitsuba: bool = True) -> None:
    scene = load_scene(EXAMPLE)
    rad = module_radiosity(scene).LER
    print(f"# speed: {EXAMPLE.name} (r 35, h 43, rho 0.90, 4 Lambertian LEDs, exit top), {rays} paths, median of "
          f"{repeats}; {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs (shared), JAX backend "
          f"{jax.default_backend()} x {len(jax.local_devices())} devices; radiosity LER {rad:.5f}")
    rows = []  # (label, paths, segments, seconds, LER, se)
    trace(scene, 1000, seed=1)  # compile (the rays below reuse it: same emission width)
    trace(scene, rays, seed=1)
    r, dt = median_of(lambda: trace(scene, rays, seed=1), repeats)
    rows.append(("bsdfkit JAX kernel", rays, r.interactions, dt, r.LER, r.std_err["LER"]))
    trace(scene, rays, seed=1, full_kernel=True)
    r, dt = median_of(lambda: trace(scene, rays, seed=1, full_kernel=True), repeats)
    rows.append(("bsdfkit JAX kernel, every effect", rays, r.interactions, dt, r.LER, r.std_err["LER"]))
    if baseline:
        old = baseline_trace(baseline)
        old(scene, 20_000, seed=1)
        r, dt = median_of(lambda: old(scene, rays, seed=1), repeats)
        rows.append((f"bsdfkit kernel at {baseline}", rays, r.interactions, dt, r.LER, r.std_err["LER"]))
    ref, dt = median_of(lambda: trace_numpy(scene, rays, seed=1), repeats)
    rows.append(("NumPy reference", rays, ref.interactions, dt, ref.LER, ref.se_LER))
    mitsuba_row = None
    if with_mitsuba:
        run, why = mitsuba_tracer(scene)
        if run is None:
            print(f"(Mitsuba 3 skipped: {why})")
        else:
            run(rays)  # JIT warm-up
            times = [run(rays, seed=s + 1) for s in range(repeats)]
            dt = statistics.median(t for t, _ in times)
            # the meter's reading is not a calibrated LER (its scale depends on the angular distribution at the
            # top: reading/LER_rad = 8.9e3 at rho 0, 9.5e3 at rho 0.9), so only the time is compared
            mitsuba_row = ("Mitsuba 3 llvm ptracer", rays, float("nan"), dt, float("nan"), float("nan"))
            rows.append(mitsuba_row)
    base = mitsuba_row or rows[-1]
    print(f"{'implementation':34s} {'paths/s':>10s} {'segments/s':>11s} {'vs ' + base[0].split()[0]:>12s} "
          f"{'LER':>9s} {'± se':>8s} {'z vs rad':>8s}")
    for label, n, seg, dt, ler, se in rows:
        z = (ler - rad) / se if se == se and se > 0 else float("nan")
        print(f"{label:34s} {n / dt:10.3e} {seg / dt:11.3e} {(n / dt) / (base[1] / base[3]):12.2f} {ler:9.5f} "
              f"{se:8.5f} {z:8.2f}")


def phosphor(rays: int, repeats: int, baseline: str | None) -> None:
    """The full phosphor kernel of the main job: the test device with the recipe's own plate."""
    scene = load_scene(DEVICE, plate_resolver=plate_from_recipe)
    print(f"# phosphor kernel: {DEVICE.name} (plate from fitting/cl830.toml), {rays} rays, median of {repeats}")
    rows = []
    trace(scene, rays, seed=1)
    r, dt = median_of(lambda: trace(scene, rays, seed=1), repeats)
    rows.append(("bsdfkit JAX kernel", r, dt))
    if baseline:
        old = baseline_trace(baseline)
        old(scene, 20_000, seed=1)
        r0, dt0 = median_of(lambda: old(scene, rays, seed=1), repeats)
        rows.append((f"bsdfkit kernel at {baseline}", r0, dt0))
    base = rows[-1]
    print(f"{'implementation':30s} {'interactions/s':>14s} {'ratio':>6s} {'LER':>9s} {'YBR':>7s} {'NU':>6s}")
    for label, r, dt in rows:
        print(f"{label:30s} {r.interactions / dt:14.3e} {(r.interactions / dt) / (base[1].interactions / base[2]):6.2f}"
              f" {r.LER:9.5f} {r.YBR:7.3f} {r.non_uniformity:6.3f}")


def backend(rays: int, repeats: int) -> None:
    """Paths/s and segments/s on whatever JAX backend is present (CPU, GPU)."""
    scene = load_scene(EXAMPLE)
    print(f"# backend {jax.default_backend()} ({', '.join(str(d) for d in jax.devices())}), {rays} paths")
    trace(scene, rays, seed=1)
    r, dt = median_of(lambda: trace(scene, rays, seed=1), repeats)
    print(f"paths/s {rays / dt:.3e}  segments/s {r.interactions / dt:.3e}  (LER {r.LER:.5f} ± {r.std_err['LER']:.5f})")


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


def spectral(rays: int, repeats: int) -> None:
    """Time per ray of the spectral mode vs the two-wavelength mode on the same scene (spectral_example.toml: the
    Table-2 plate, 81 bins of 5 nm), both timed in this process after compilation; and the two modes' powers."""
    s = load_scene(SPECTRAL)
    two = replace(s, trace=replace(s.trace, mode="two-wavelength"))
    print(f"# spectral mode: {SPECTRAL.name}, {rays} rays, median of {repeats}; {os.cpu_count()} CPUs (shared), "
          f"{len(jax.local_devices())} JAX devices")
    rows = []
    for label, sc in (("two-wavelength", two), ("spectral", s)):
        trace(sc, rays, seed=1)  # compile
        r, dt = median_of(lambda sc=sc: trace(sc, rays, seed=1), repeats)
        rows.append((label, r, dt))
    print(f"{'mode':16s} {'s/ray':>10s} {'interactions/ray':>16s} {'LER':>9s} {'± se':>8s} {'blue W':>9s} "
          f"{'yellow W':>9s} {'ledger':>8s}")
    for label, r, dt in rows:
        print(f"{label:16s} {dt / rays:10.3e} {r.interactions / rays:16.2f} {r.LER:9.5f} {r.std_err['LER']:8.5f} "
              f"{r.extracted['blue']:9.5f} {r.extracted['yellow']:9.5f} {r.ledger_error:8.1e}")
    sp = rows[1][1].spectral
    print(f"time per ray spectral / two-wavelength: {rows[1][2] / rows[0][2]:.2f}; photon ledger error "
          f"{sp.ledger['photons_per_s']['error']:.1e}; Stokes loss {sp.ledger['power_W']['stokes']:.4f} W; "
          f"luminous efficacy {sp.luminous_efficacy_lm_per_W():.1f} lm/W")


def ab(rev: str, repeats: int) -> None:
    """Today's kernel vs the kernel at git revision ``rev`` on the phosphor device and the exit-top example,
    runs alternating (new, old, new, old, …) so that a change of the machine's load hits both alike."""
    old = baseline_trace(rev)
    print(f"# interleaved A/B against {rev}, {repeats} pairs; {os.cpu_count()} CPUs (shared)")
    for path, rays in ((DEVICE, 200_000), (EXAMPLE, 1_000_000)):
        s = load_scene(path, plate_resolver=plate_from_recipe)
        trace(s, rays, seed=1)
        old(s, rays, seed=1)
        t_new, t_old = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            a = trace(s, rays, seed=1)
            t_new.append(time.perf_counter() - t)
            t = time.perf_counter()
            b = old(s, rays, seed=1)
            t_old.append(time.perf_counter() - t)
        same = a.LER == b.LER and a.interactions == b.interactions
        print(f"{path.name}: {rays} rays, new/old time {statistics.median(t_new) / statistics.median(t_old):.3f} "
              f"(pairs " + " ".join(f"{x / y:.2f}" for x, y in zip(t_new, t_old)) + f"); same result: {same}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rays", type=int, default=2 ** 21)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--baseline", default=None, metavar="REV", help="also time the kernel of this git revision")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--phosphor", action="store_true")
    p.add_argument("--backend", action="store_true")
    p.add_argument("--oracle", action="store_true")
    p.add_argument("--threshold", action="store_true")
    p.add_argument("--trends", action="store_true")
    p.add_argument("--spectral", action="store_true")
    p.add_argument("--ab", default=None, metavar="REV", help="interleaved timing against the kernel of REV")
    p.add_argument("--all", action="store_true")
    p.add_argument("--tmp", default=str(Path(tempfile.gettempdir()) / "bsdfkit_bench"))
    a = p.parse_args()
    tmp = Path(a.tmp)
    tmp.mkdir(parents=True, exist_ok=True)
    only = a.phosphor or a.backend or a.oracle or a.threshold or a.trends or a.spectral or a.ab
    if a.all or not only:
        speed(a.rays, a.repeats, a.baseline, not a.no_mitsuba)
    if a.all or a.phosphor:
        phosphor(min(a.rays, 400_000), a.repeats, a.baseline)
    if a.backend:
        backend(a.rays, a.repeats)
    if a.all or a.oracle:
        oracle(min(a.rays, 1_000_000))
    if a.all or a.threshold:
        threshold(min(a.rays, 1_000_000), tmp)
    if a.all or a.trends:
        trends(min(a.rays, 400_000), tmp)
    if a.all or a.spectral:
        spectral(min(a.rays, 1_000_000), a.repeats)
    if a.ab:
        ab(a.ab, a.repeats)


if __name__ == "__main__":
    main()
