"""Fault injection (issue #13): bounds before allocation, endless scenes, and trace/sweep outputs as one set.

Every size a user can give (sweep points, tally bins, chunk, events per ray) is bounded before anything is
allocated or traced, with the limit named in the one-line error; a closed lossless cavity, in which every
ray would run to ``max_events``, is refused at scene validation; ``trace`` and ``sweep`` write all their
files as one atomic output set (a failure half-way leaves the previous files or none, a rerun needs no
``--force``).
"""
from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
import xarray as xr

from bsdfkit.cli.main import main
from bsdfkit.core.errors import BsdfkitError, InputError, ValidationError
from bsdfkit.raytrace import loads_scene, trace
from bsdfkit.raytrace import sweep as sweep_module
from bsdfkit.raytrace.scene import LOSSLESS_MAX_EVENTS

SCENE = """
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = {rho}
[base]
reflectance = {rho}
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
distribution = "lambertian"
power_W = 1.0
[top]
{top}
[trace]
lanes = 512
{trace}
"""


def _scene_text(rho: float = 0.9, top: str = 'kind = "exit"', trace_opts: str = "", tallies: str = "") -> str:
    return SCENE.format(rho=rho, top=top, trace=trace_opts) + tallies


def _one_line(code: int, err: str, *needles: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


def _leftovers(folder: Path) -> list[str]:
    return [p.name for p in folder.rglob("*") if p.name.endswith((".part", ".staging", ".old", ".probe"))]


# ------------------------------------------------------------------------------------------------ bounds
@pytest.mark.parametrize("tallies,needle", [
    ("[tallies]\nmap_bins = 100000\n", "MAX_MAP_BINS"),
    ("[tallies]\nhistogram_bins = 1000000000\n", "MAX_HISTOGRAM_BINS"),
    ("[tallies]\nbudget_bins = 1000000000\n", "MAX_BUDGET_BINS"),
])
def test_tally_sizes_are_bounded_with_the_limit_named(tallies, needle):
    with pytest.raises(InputError, match=needle):
        loads_scene(_scene_text(tallies=tallies), "s.toml")


@pytest.mark.parametrize("termination", ["threshold", "roulette"])
def test_closed_lossless_cavity_with_many_events_is_refused(termination):
    closed = 'kind = "lambertian"\nreflectance = 1.0\ntransmittance = 0.0'
    text = _scene_text(1.0, closed, f'termination = "{termination}"\nmax_events = 100000000')
    with pytest.raises(ValidationError, match="LOSSLESS_MAX_EVENTS") as info:
        loads_scene(text, "s.toml")
    assert "s.toml" in str(info.value) and "trace.max_events" in str(info.value)
    # the same cavity with a short cap (a test of the truncation ledger), an exit, or any loss is accepted
    ok = loads_scene(_scene_text(1.0, closed, f"max_events = {LOSSLESS_MAX_EVENTS}"))
    loads_scene(_scene_text(1.0, 'kind = "exit"', "max_events = 100000000"))
    loads_scene(_scene_text(0.999, closed, "max_events = 100000000"))
    # a scene built in Python bypasses the file reader; the tracer checks again before compiling
    endless = replace(ok, trace=replace(ok.trace, max_events=10**6))
    with pytest.raises(ValidationError, match="LOSSLESS_MAX_EVENTS"):
        trace(endless, 10)


@pytest.mark.parametrize("termination", ["threshold", "roulette"])
def test_slowly_absorbing_closed_cavity_is_bounded_by_its_work(termination):
    """A closed cavity that absorbs 1e-6 per bounce: ln(Th)/ln(ρ) ≈ 4.6e6 events per ray (threshold), or ≈ 1e6 more
    on average (roulette); 1e6 rays would cost ~1e12 events, over MAX_TRACE_EVENTS: refused before compiling."""
    from bsdfkit.raytrace.scene import MAX_TRACE_EVENTS, events_per_ray

    closed = 'kind = "lambertian"\nreflectance = 0.999999\ntransmittance = 0.0'
    scene = loads_scene(_scene_text(0.999999, closed, f'termination = "{termination}"\nmax_events = 100000000'))
    n = events_per_ray(scene.wall, scene.base, scene.leds, scene.top, scene.trace)
    level = scene.trace.threshold if termination == "threshold" else scene.trace.roulette_threshold
    assert n >= math.log(level) / math.log(0.999999)
    start = time.perf_counter()
    with pytest.raises(ValidationError, match="MAX_TRACE_EVENTS"):
        trace(scene, 10**6)
    assert time.perf_counter() - start < 1.0  # refused before anything is compiled
    assert 10**6 * n > MAX_TRACE_EVENTS
    # the same cavity with a loss of 10 % per bounce costs a few dozen events per ray: accepted
    lossy = loads_scene(_scene_text(0.9, 'kind = "lambertian"\nreflectance = 0.9\ntransmittance = 0.0'))
    assert events_per_ray(lossy.wall, lossy.base, lossy.leds, lossy.top, lossy.trace) < 100


def test_chunk_above_the_kernel_limit_is_an_error_not_a_silent_cap():
    with pytest.raises(ValidationError, match="MAX_CHUNK"):
        trace(loads_scene(_scene_text()), 10, chunk=2**40)


@pytest.mark.parametrize("spec,needle", [
    ("wall.reflectance=0.5:0.9:1000000000000", "MAX_SWEEP_POINTS"),
    ("wall.reflectance=nan:0.9:3", "finite"),
    ("wall.reflectance=0.5:inf:3", "finite"),
])
def test_sweep_values_are_bounded_before_allocation(spec, needle):
    with pytest.raises(InputError, match=needle):
        sweep_module.parse_parameter(spec)


def test_sweep_grid_size_is_bounded_before_tracing(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text())
    started = time.perf_counter()
    code = main(["sweep", str(path), "--param", "wall.reflectance=0.5:0.9:1000", "--param",
                 "base.reflectance=0.5:0.9:1000", "-o", str(tmp_path / "x.nc")])
    _one_line(code, capsys.readouterr().err, "MAX_SWEEP_POINTS", "1000000")
    assert time.perf_counter() - started < 5.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


# ----------------------------------------------------------------------------------- trace/sweep output sets
def test_sweep_failing_after_the_netcdf_leaves_no_file(tmp_path, capsys, monkeypatch):
    """The plot fails after the netCDF file is written: neither file appears; the rerun needs no --force."""
    path = tmp_path / "s.toml"
    path.write_text(_scene_text())
    out = tmp_path / "sweep.nc"
    args = ["sweep", str(path), "--param", "wall.reflectance=0.8,0.9", "--rays", "2000", "-o", str(out)]

    def broken_figure(ds):
        raise OSError(28, "No space left on device")

    import bsdfkit.plotting.figures as figures  # the verb imports it when it runs

    monkeypatch.setattr(figures, "sweep_figure", broken_figure)
    _one_line(main(args), capsys.readouterr().err, "no space left")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]
    monkeypatch.undo()
    assert main(args) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml", "sweep.nc", "sweep_LER_YBR.png"]
    assert xr.load_dataset(out)["LER"].shape == (2,)
    assert _leftovers(tmp_path) == []


def test_sweep_and_trace_refuse_their_scene_as_output_even_with_force(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text())
    before = path.read_text()
    _one_line(main(["trace", str(path), "--rays", "10", "-o", str(path), "--force"]), capsys.readouterr().err,
              "input")
    _one_line(main(["sweep", str(path), "--param", "wall.reflectance=0.8,0.9", "--rays", "10", "-o", str(path),
                    "--force"]), capsys.readouterr().err, "input")
    assert path.read_text() == before and _leftovers(tmp_path) == []


KILLED_SWEEP = """import sys
import jax
import bsdfkit.cli.sweep
from bsdfkit.cli.main import main
print("ready", flush=True)
sys.exit(main(["sweep", sys.argv[1], "--param", "wall.reflectance=0.5:0.9:50", "--rays", "1000000",
               "-o", sys.argv[2]]))
"""


@pytest.mark.slow  # a fresh interpreter killed mid-sweep (5 s); the fast lane's kill of an output set:
# tests/io/test_atomic.py::test_killed_output_set_leaves_previous_set
def test_killed_sweep_leaves_nothing_and_rerun_needs_no_force(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text())
    out = tmp_path / "sweep.nc"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_SWEEP, str(path), str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(2.0)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    assert not out.exists()
    assert main(["sweep", str(path), "--param", "wall.reflectance=0.8", "--rays", "1000", "--no-plots",
                 "-o", str(out)]) == 0  # no --force; the dead process's staging folder is removed
    assert out.exists() and _leftovers(tmp_path) == []


def test_bad_options_are_checked_before_the_output_set_is_opened(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text())
    for argv, needle in ((["trace", str(path), "--rays", "0"], "rays"),
                         (["trace", str(path), "--chunk", "0"], "chunk"),
                         (["trace", str(path), "--lanes", "-3"], "lanes"),
                         (["sweep", str(path), "--param", "wall.reflectance=0.8", "--rays", "-1"], "--rays")):
        code = main(argv + ["-o", str(tmp_path / "o.nc")])
        err = capsys.readouterr().err
        _one_line(code, err, needle)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]
    with pytest.raises(BsdfkitError):
        trace(loads_scene(_scene_text()), 10, chunk=-1)


@pytest.mark.parametrize("field, value", [("wavelength_um", 1e12), ("wavelength_um", 0.0), ("temperature_K", 1e12),
                                          ("temperature_K", -1.0), ("wavelength_um", float("nan"))])
def test_tracepro_header_numbers_are_range_checked(field, value):
    from bsdfkit.tables.formats.tracepro import TraceProOptions

    with pytest.raises(ValidationError, match=field):
        TraceProOptions(**{field: value})
    TraceProOptions(wavelength_um=0.55, temperature_K=300.0)


@pytest.mark.parametrize("argv, needle", [
    (["--split-nm", "0", "--model", "two-band"], "out of range"),
    (["--split-nm", "nan", "--model", "two-band-wide"], "out of range"),
    (["--split-nm", "1e12", "--model", "two-band-led"], "out of range"),
    (["--split-nm", "500"], "two-band model"),
])
def test_fit_spectrum_split_is_checked_not_ignored(tmp_path, capsys, argv, needle):
    path = tmp_path / "s.txt"
    path.write_text("".join(f"{w}\t{math.exp(-((w - 450) / 10) ** 2)}\n" for w in range(380, 781)))
    assert main(["fit", "spectrum", str(path), *argv]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "--split-nm" in err and needle in err
