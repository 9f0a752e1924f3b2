"""The public API of the README: a scan to an exported table and a trace, from the top-level names."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import BUNDLED, ROOT

import bsdfkit
from bsdfkit.core.errors import InputError, OutputExistsError


def test_every_api_name_is_at_the_top_level():
    for name in ("ingest", "tis", "budget", "profile", "describe", "save", "fit_bsdf", "fit_spectrum", "export",
                 "read", "load_scene", "trace", "run"):
        assert callable(getattr(bsdfkit, name)), name
    with pytest.raises(AttributeError):
        bsdfkit.no_such_name  # noqa: B018


@pytest.mark.slow
def test_the_readme_one_liner_works_as_written():
    code = ("import bsdfkit, xarray as xr; ds = bsdfkit.ingest('measurements/cl830-synthetic'); "
            "print(ds.bsdf.tis())")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "tis" in done.stdout and "interaction" in done.stdout


@pytest.mark.slow
def test_scan_to_table_through_the_api(tmp_path, bundled_scan):
    ds = bsdfkit.ingest(BUNDLED)
    assert float(np.nanmax(np.abs(ds["bsdf"].values - bundled_scan["bsdf"].values))) == 0.0
    tis = ds.bsdf.tis(45)
    # the manifest's exact truth at 45°: bibs reflection 10.9 % (Table 2 of the power-budget paper)
    assert float(tis["tis"].sel(interaction="bibs", side="reflection")) == pytest.approx(0.109, abs=0.002)
    assert bsdfkit.budget(ds, 45).eqe == pytest.approx(0.80, abs=0.01)
    assert ds.bsdf.describe()["incidences_deg"] == [5.0, 45.0, 56.0]
    fit = ds.bsdf.fit("bibs", "reflection")
    out = tmp_path / "bibs.bsdf"
    result = bsdfkit.export(fit, "zemax", "bibs", "reflection", out)
    back = bsdfkit.read(out)
    np.testing.assert_allclose(back.tis_computed["reflection"], result.tis_source["reflection"], rtol=2e-3)
    saved = ds.bsdf.save(tmp_path / "scan.nc")
    with pytest.raises(OutputExistsError):
        ds.bsdf.save(saved)
    with pytest.raises(InputError, match="missing"):
        bsdfkit.ingest(tmp_path / "missing")
    with pytest.raises(InputError, match="incidence"):
        bsdfkit.tis(ds, 33.0)


def test_trace_from_a_scene_path():
    result = bsdfkit.trace(ROOT / "fitting" / "scenes" / "example.toml", rays=20_000, seed=1)
    assert 0.0 < result.LER < 1.0
    assert abs(result.ledger_error) < 1e-9


@pytest.mark.slow  # builds the plate of the cl830 measurement twice (6 s); the fast lane's route through the same
# resolver (api.load_scene, as the trace verb loads scenes): test_scene.py::test_the_trace_verb_resolves_a_recipe_plate
def test_load_scene_builds_a_recipe_plate_as_the_trace_verb_does():
    """A scene whose phosphor top names a fitting recipe (`from = ...`) loads through the API with the plate of
    that recipe's measurement: the plate the pipeline module builds from the same recipe, channel for channel."""
    from bsdfkit.pipeline.plate_from_scan import plate_from_recipe

    scene = bsdfkit.load_scene(ROOT / "fitting" / "scenes" / "cl830_device.toml")
    direct = plate_from_recipe(ROOT / "fitting" / "cl830.toml")
    assert scene.top.kind == "phosphor"
    assert scene.top.plate == direct
