"""Issue #44.7: a recipe key that selects from the data must lie inside what was measured, refused before the run.

A recipe with ``figure_wavelength_nm = 2000`` on the 380-780 nm bundled scan drew the 780 nm curve titled "2000 nm"
and exited 0. Every key that picks a wavelength, a configuration or an incidence of a measurement is now checked
against the measurement when the recipe is loaded (:func:`bsdfkit.pipeline.recipe.load_recipe`): one line naming the
recipe file, the key, the measured range and the value, exit status 2, before the pipeline starts.
"""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT

from bsdfkit.core.errors import ValidationError
from bsdfkit.pipeline.recipe import load_recipe, measured_axes

RECIPE = ROOT / "fitting" / "cl830.toml"


def _copy(tmp_path: Path, **changes: str) -> Path:
    """The bundled recipe in ``tmp_path``, its paths made absolute and each ``key = value`` line of ``changes``
    replaced (the key's first line)."""
    text = RECIPE.read_text()
    for rel in ("../measurements/cl830-synthetic", "../measurements/eem-synthetic"):
        text = text.replace(f'"{rel}"', f'"{(RECIPE.parent / rel).resolve().as_posix()}"')
    text = text.replace('scene = "scenes/', f'scene = "{(RECIPE.parent / "scenes").as_posix()}/')
    for key, value in changes.items():
        text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, count=1, flags=re.M)
        assert n == 1, key
    path = tmp_path / "recipe.toml"
    path.write_text(text)
    return path


def test_bundled_measurements_axes():
    axes = measured_axes(ROOT / "measurements" / "cl830-synthetic")
    assert axes.wavelength_nm == (380.0, 780.0)
    assert axes.configurations == ("blue", "yellow")
    assert axes.incidences_deg == (5.0, 45.0, 56.0)
    assert measured_axes(ROOT / "measurements") is None  # no export there: the run's reader names the fault


@pytest.mark.parametrize("wavelength", ["380", "780", "460.5"])
def test_copy_inside_the_data_loads(tmp_path, wavelength):
    recipe = load_recipe(_copy(tmp_path, figure_wavelength_nm=wavelength))
    assert recipe.report.figure_wavelength_nm == float(wavelength)


@pytest.mark.parametrize(("key", "value", "field", "expected"), [
    ("figure_wavelength_nm", "2000", "report.figure_wavelength_nm", "expected a wavelength in [380, 780] nm"),
    ("figure_wavelength_nm", "379.5", "report.figure_wavelength_nm", "expected a wavelength in [380, 780] nm"),
    ("figure_config", '"red"', "report.figure_config", "expected one of blue, yellow"),
    ("budget_incidence_deg", "30.0", "reductions.budget_incidence_deg", "expected one of 5, 45, 56 deg"),
    ("emission_incidence_deg", "0.785", "fits.emission_incidence_deg", "expected one of 5, 45, 56 deg"),
    ("incidence_deg", "[45.0, 60.0]", "spectral.incidence_deg[1]", "expected one of 5, 45, 56 deg"),
])
def test_key_outside_the_data_is_refused(tmp_path, key, value, field, expected):
    path = _copy(tmp_path, **{key: value})
    with pytest.raises(ValidationError) as caught:
        load_recipe(path)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: field '{field}': ")
    assert expected in message
    assert f"got {value.strip('[]').split(', ')[-1].strip(chr(34))}" in message.replace("'", "")


def test_run_refuses_before_running(tmp_path):
    path = _copy(tmp_path, figure_wavelength_nm="2000")
    out = tmp_path / "out"
    start = time.perf_counter()
    done = subprocess.run([str(Path(sys.executable).with_name("bsdfkit")), "run", str(path), "-o", str(out)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    took = time.perf_counter() - start
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""
    assert done.stderr.splitlines() == [
        f"bsdfkit run: error: {path}: field 'report.figure_wavelength_nm': wavelength outside the measured range; "
        "expected a wavelength in [380, 780] nm (the range of cl830-synthetic), got 2000.0"]
    assert took < 10.0, f"the refusal took {took:.1f} s: the pipeline ran first?"
    assert not out.exists()
