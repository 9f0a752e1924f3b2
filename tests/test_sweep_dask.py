"""Sweeps on dask.distributed: a 2-worker LocalCluster (processes, loopback) gives the serial sweep bit for bit,
and a failed point is reported, not dropped."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from conftest import ROOT

from bsdfkit.cli.main import main
from bsdfkit.raytrace import load_scene
from bsdfkit.raytrace.sweep import Cluster, SweepPointsFailed, run_sweep

EXAMPLE = ROOT / "fitting" / "scenes" / "example.toml"
ARGS = ["--param", "cavity.height_mm=10,43,80", "--param", "wall.reflectance=0.8,0.9", "--rays", "4000",
        "--seed", "5", "--no-plots"]


@pytest.fixture
def shared_jax_cache(tmp_path, monkeypatch):
    # the workers inherit the environment: one compilation serves both of them
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "jax-cache"))
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


@pytest.mark.slow
def test_a_failed_point_is_reported_not_dropped(tmp_path, shared_jax_cache):
    scene = load_scene(EXAMPLE)
    out = tmp_path / "partial.nc"
    with pytest.raises(SweepPointsFailed, match=r"1 sweep point\(s\) failed.*cavity.height_mm=-5"):
        run_sweep(scene, ["cavity.height_mm=10,-5"], out, rays=2000, seed=1, cluster=Cluster(workers=1))
    with xr.open_dataset(out) as ds:  # the good point is kept, the failed one is NaN and named
        assert np.isfinite(ds["LER"].values[0]) and np.isnan(ds["LER"].values[1])
        assert "cavity.height_mm=-5" in ds.attrs["failed_points"]


def test_workers_and_scheduler_exclude_each_other(tmp_path, capsys):
    assert main(["sweep", str(EXAMPLE), *ARGS, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1",
                 "-o", str(tmp_path / "x.nc")]) == 2
    assert "exclude each other" in capsys.readouterr().err
