"""``bsdfkit trace`` and ``bsdfkit sweep`` from the command line."""
from __future__ import annotations

import json

import pytest
import xarray as xr

from bsdfkit.cli.main import main

SCENE = """
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = 0.90
specular_fraction = 0.0
[base]
reflectance = 0.90
specular_fraction = 0.0
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
distribution = "lambertian"
power_W = 1.0
[top]
kind = "exit"
[trace]
lanes = 512
"""

KEYS = {"extracted", "LER", "YBR", "absorbed", "ledger_error", "std_err", "non_uniformity", "rays", "elapsed_s",
        "rays_per_s", "interactions_per_s"}


def test_trace_json_report(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    assert main(["trace", str(path), "--rays", "20000", "--seed", "3", "--chunk", "20000", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert KEYS <= set(report)
    assert set(report["extracted"]) == {"blue", "yellow", "total"}
    assert set(report["absorbed"]) == {"wall", "base", "leds", "plate"}
    assert report["rays"] == 20000 and report["ledger_error"] <= 1e-9
    assert report["LER"] == pytest.approx(report["extracted"]["total"], rel=1e-12)  # 1 W emitted
    assert 0 < report["std_err"]["LER"] < 0.01
    assert report["non_uniformity"] is None  # no map for an exit top unless asked
    assert report["interactions_per_s"] > 0


def test_trace_netcdf_output_is_not_clobbered(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE + "[tallies]\nirradiance_map = true\n")
    out = tmp_path / "r.nc"
    args = ["trace", str(path), "--rays", "20000", "--chunk", "20000", "-o", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "LER" in text and "non-uniform" in text
    ds = xr.load_dataset(out)
    assert ds["irradiance"].shape == (32, 32) and float(ds["LER"]) > 0.5
    assert main(args) == 2
    assert "exists" in capsys.readouterr().err


def test_bad_scene_is_one_line_error(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("reflectance = 0.90\nspecular_fraction = 0.0\n[base]",
                                  "reflectance = 0.90\nspecular_fraction = 2.0\n[base]"))
    assert main(["trace", str(path), "--rays", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "wall.specular_fraction" in err and "expected" in err and "got 2.0" in err


def test_sweep_writes_dataset_and_plot(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    out = tmp_path / "sweep.nc"
    args = ["sweep", str(path), "--param", "wall.reflectance,base.reflectance=0.80:0.98:2",
            "--param", "cavity.height_mm=10,43", "--rays", "20000", "--chunk", "20000", "-o", str(out), "--json"]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["dims"] == {"wall.reflectance": 2, "cavity.height_mm": 2}
    ds = xr.load_dataset(out)
    assert ds.attrs["rays"] == 20000 and "scene_toml" in ds.attrs
    ler = ds["LER"]
    # LER rises with reflectance and falls with height (cylindrical-module paper, Figs. 8 and 11)
    assert float(ler.sel({"wall.reflectance": 0.98, "cavity.height_mm": 43})) > \
        float(ler.sel({"wall.reflectance": 0.80, "cavity.height_mm": 43}))
    assert float(ler.sel({"wall.reflectance": 0.80, "cavity.height_mm": 10})) > \
        float(ler.sel({"wall.reflectance": 0.80, "cavity.height_mm": 43}))
    assert float(ds["ledger_error"].max()) <= 1e-9
    assert (tmp_path / "sweep_LER_YBR.png").stat().st_size > 1000
    assert main(args) == 2  # outputs exist, no --force
    assert "exists" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0


def test_sweep_needs_parameters(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    assert main(["sweep", str(path), "-o", str(tmp_path / "x.nc")]) == 2
    assert "sweep.params" in capsys.readouterr().err
    assert main(["sweep", str(path), "--param", "wall.reflectance", "-o", str(tmp_path / "x.nc")]) == 2
    assert "KEYS=VALUES" in capsys.readouterr().err
