"""Sweeps on dask.distributed: a 2-worker LocalCluster (processes, loopback) gives the serial sweep bit for bit,
and a failed point is reported, not dropped."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from conftest import ROOT

from bsdfkit.cli.main import CACHE_SETTINGS, main

EXAMPLE = ROOT / "fitting" / "scenes" / "example.toml"
ARGS = ["--param", "cavity.height_mm=10,43,80", "--param", "wall.reflectance=0.8,0.9", "--rays", "4000",
        "--seed", "5", "--no-plots"]


@pytest.fixture
def shared_jax_cache(tmp_path, monkeypatch, shared_compile_cache):
    # the workers inherit the environment: one compilation serves both of them, and later runs of the suite (the
    # suite's persistent cache, conftest.py; a folder of this test's own when the suite runs without it), with
    # the command line's settings (its size limit switches on the file lock the concurrent writers need)
    folder = shared_compile_cache or tmp_path / "jax-cache"
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(folder))
    for key, value in CACHE_SETTINGS.items():
        monkeypatch.setenv(key.upper(), str(value))
    monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")


@pytest.mark.slow
def test_two_worker_sweep_equals_the_serial_sweep_bit_for_bit(tmp_path, shared_jax_cache):
    assert main(["sweep", str(EXAMPLE), *ARGS, "-o", str(tmp_path / "serial.nc")]) == 0
    assert main(["sweep", str(EXAMPLE), *ARGS, "--workers", "2", "-o", str(tmp_path / "dask.nc")]) == 0
    with xr.open_dataset(tmp_path / "serial.nc") as a, xr.open_dataset(tmp_path / "dask.nc") as b:
        assert set(a.data_vars) == set(b.data_vars) and a["LER"].shape == (3, 2)
        for name in a.data_vars:
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
        assert a.attrs == b.attrs


#: a cavity closed by a half-reflecting top: at base.reflectance = 0.999999 a point costs ~3e5 events per ray,
#: 1e6 rays exceed MAX_TRACE_EVENTS, and the tracer (in the worker) refuses that point only
CLOSED = """[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = 0.9
[base]
reflectance = 0.9
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
distribution = "lambertian"
power_W = 1.0
[top]
kind = "lambertian"
reflectance = 0.5
transmittance = 0.5
[trace]
lanes = 512
max_events = 300000
"""


@pytest.mark.slow
def test_a_failed_point_is_reported_not_dropped(tmp_path, shared_jax_cache, capfd):
    """One point fails in its worker: the good point is kept, the failed one is NaN and named, and stderr holds
    only the one error line (no "distributed.worker - ERROR - Compute Failed" record, no traceback)."""
    path = tmp_path / "closed.toml"
    path.write_text(CLOSED)
    out = tmp_path / "partial.nc"
    code = main(["sweep", str(path), "--param", "base.reflectance=0.9,0.999999", "--rays", "1000000",
                 "--workers", "2", "--no-plots", "-o", str(out)])
    err = capfd.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "distributed" not in err and len(err.strip().splitlines()) == 1, err
    assert "1 sweep point(s) failed, written as NaN: base.reflectance=0.999999" in err and "MAX_TRACE_EVENTS" in err
    with xr.open_dataset(out) as ds:
        assert np.isfinite(ds["LER"].values[0]) and np.isnan(ds["LER"].values[1])
        assert "base.reflectance=0.999999" in ds.attrs["failed_points"]


def test_a_point_out_of_range_is_refused_before_any_worker_starts(tmp_path, capfd):
    out = tmp_path / "x.nc"
    code = main(["sweep", str(EXAMPLE), "--param", "cavity.height_mm=10,-5", "--rays", "2000", "--workers", "2",
                 "--no-plots", "-o", str(out)])
    err = capfd.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "cavity.height_mm" in err and "-5" in err
    assert not out.exists()


def test_workers_and_scheduler_exclude_each_other(tmp_path, capsys):
    assert main(["sweep", str(EXAMPLE), *ARGS, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1",
                 "-o", str(tmp_path / "x.nc")]) == 2
    assert "exclude each other" in capsys.readouterr().err
