"""netCDF datasets are checked like text tables before any verb computes with them (issue #44, point 4).

Every file is a valid dataset (a Zemax BRDF file ingested) written by plain xarray after one damage; the verbs read
it through ``bsdfkit.tables.export.open_bsdf_dataset`` (``bsdfkit.measurement.schema.validate_bsdf_dataset`` and
the measured tables' value checks) and refuse it in one line naming the variable and what was found.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import ROOT, cli

import bsdfkit

SOURCE = ROOT / "tests" / "data" / "ansys-radiant-zemax-bsdf" / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"


@pytest.fixture(scope="module")
def dataset():
    return bsdfkit.ingest(str(SOURCE))


def _plain(ds, path: Path, bare: bool = False) -> Path:
    """``ds`` written by plain xarray, without bsdfkit's attributes (``bare``: without any attribute)."""
    out = ds.copy(deep=True)
    out.attrs = {}
    if bare:
        for var in out.variables.values():
            var.attrs = {}
    out.to_netcdf(path)
    return path


def _damaged(ds, path: Path, damage) -> Path:
    out = ds.copy(deep=True)
    damage(out)
    out.to_netcdf(path)
    return path


def _refused(*args) -> str:
    done = cli(*args)
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    return lines[0]


def _values(report: dict) -> list[tuple]:
    return [(r["incidence_deg"], r["side"], r["value"], r["std"]) for r in report["hemispherical"]]


def test_a_plain_xarray_copy_of_a_valid_dataset_gives_the_same_tis(dataset, tmp_path):
    original = cli("tis", SOURCE, "--json")
    assert original.returncode == 0, original.stderr
    for bare in (False, True):
        path = _plain(dataset, tmp_path / f"plain-{bare}.nc", bare)
        copy = cli("tis", path, "--json")
        assert copy.returncode == 0 and copy.stderr == "", copy.stderr
        assert _values(json.loads(copy.stdout)) == _values(json.loads(original.stdout))


def test_no_quantity_attribute_is_read_as_bsdf(dataset, tmp_path):
    def damage(ds):
        del ds.attrs["quantity"]

    done = cli("tis", _damaged(dataset, tmp_path / "noq.nc", damage), "--json")
    assert done.returncode == 0 and "another quantity" not in done.stderr, done.stderr


def test_another_quantity_is_named_with_the_expected_one(dataset, tmp_path):
    def damage(ds):
        ds.attrs["quantity"] = "brdf"

    line = _refused("tis", _damaged(dataset, tmp_path / "brdf.nc", damage))
    assert "brdf.nc" in line and "field 'quantity'" in line and "another quantity" in line
    assert "expected 'bsdf'" in line and "got 'brdf'" in line


def test_a_missing_bsdf_variable_is_named_with_what_the_file_holds(dataset, tmp_path):
    path = tmp_path / "nobsdf.nc"
    dataset.drop_vars("bsdf").to_netcdf(path)
    for verb in (("tis",), ("info",), ("ingest", "-o", tmp_path / "o.nc")):
        line = _refused(verb[0], path, *verb[1:])
        assert "nobsdf.nc" in line and "field 'bsdf'" in line and "variable missing" in line, line
        assert "bsdf_std" in line and "got 'nothing'" in line, line
    assert not (tmp_path / "o.nc").exists()


def test_bsdf_in_another_unit_is_refused_naming_both_units(dataset, tmp_path):
    def damage(ds):
        ds["bsdf"].attrs["units"] = "1/deg"

    line = _refused("tis", _damaged(dataset, tmp_path / "deg.nc", damage))
    assert "field 'bsdf'" in line and "other units" in line and "'1/sr'" in line and "got '1/deg'" in line


def test_a_missing_unit_contradicted_by_another_attribute_is_refused(dataset, tmp_path):
    path = _plain(dataset, tmp_path / "percent.nc", bare=True)
    ds = xr.load_dataset(path)
    ds["bsdf_std"].attrs["unit"] = "%"
    ds.to_netcdf(tmp_path / "percent2.nc")
    line = _refused("tis", tmp_path / "percent2.nc")
    assert "field 'bsdf_std'" in line and "'unit'" in line and "got '%'" in line, line


def test_negative_values_well_below_the_noise_are_refused(dataset, tmp_path):
    def damage(ds):
        ds["bsdf"][:] = -0.5

    path = _damaged(dataset, tmp_path / "neg.nc", damage)
    for verb in (("tis",), ("export", "--to", "zemax", "--side", "reflection", "-o", tmp_path / "x.bsdf")):
        line = _refused(verb[0], path, *verb[1:])
        assert "neg.nc" in line and "field 'bsdf of record 0'" in line and "negative beyond noise" in line, line
        assert "-0.5" in line, line
    assert not (tmp_path / "x.bsdf").exists()


def test_dark_noise_around_zero_is_read(dataset, tmp_path):
    def damage(ds):
        rng = np.random.default_rng(1)
        ds["bsdf"][:] = rng.normal(0.0, 1e-4, ds["bsdf"].shape)
        ds["bsdf_std"][:] = 1e-4

    done = cli("tis", _damaged(dataset, tmp_path / "dark.nc", damage), "--json")
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize(("name", "value", "field", "found"), [
    ("bsdf", 1e300, "bsdf of record 5", "1e+300"),
    ("bsdf_std", -1.0, "bsdf_std", "-1.0"),
    ("theta_s", 120.0, "theta_s", "120.0"),
    ("phi_i", 400.0, "phi_i", "400.0"),
    ("wavelength", -550.0, "wavelength", "-550.0"),
])
def test_an_impossible_number_is_refused_naming_the_field_and_the_value(dataset, tmp_path, name, value, field,
                                                                      found):
    def damage(ds):
        v = ds[name].values.copy()
        v[5 if v.size > 5 else 0] = value
        ds[name] = ds[name].copy(data=v)

    line = _refused("tis", _damaged(dataset, tmp_path / f"{name}.nc", damage))
    assert f"{name}.nc" in line and f"field '{field}'" in line and found in line, line


def test_a_dataset_of_nan_only_is_refused(dataset, tmp_path):
    def damage(ds):
        ds["bsdf"][:] = np.nan

    line = _refused("tis", _damaged(dataset, tmp_path / "nan.nc", damage))
    assert "nan.nc" in line and "field 'bsdf'" in line and "no finite BSDF value" in line and "NaN" in line


def test_the_command_itself_says_one_line(dataset, tmp_path):
    """The installed entry point (not only the in-process CLI): exit 2, one line, no traceback."""
    path = tmp_path / "nobsdf.nc"
    dataset.drop_vars("bsdf").to_netcdf(path)
    done = subprocess.run([sys.executable, "-m", "bsdfkit", "tis", str(path)], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert len(done.stderr.splitlines()) == 1 and "Traceback" not in done.stderr
    assert "field 'bsdf'" in done.stderr and "variable missing" in done.stderr
