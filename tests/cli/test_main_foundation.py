"""The foundation verbs through the command line: ingest, info --json, run."""
import json

import pytest
from conftest import BUNDLED, ROOT, cli


@pytest.mark.slow
def test_ingest_then_info_json(tmp_path):
    out = tmp_path / "scan.nc"
    proc = cli("ingest", BUNDLED, "-o", out)
    assert proc.returncode == 0, proc.stderr
    info = json.loads(cli("info", out, "--json").stdout)
    assert info["incidences_deg"] == [5.0, 45.0, 56.0]
    assert info["sides"] == ["reflection", "transmission"]
    assert info["positions"]["45"]["reflection"]["in_plane"] > 30
    assert info["positions"]["45"]["transmission"]["perpendicular"] > 20
    assert info["wavelength_nm"] == {"min": 380.0, "max": 780.0, "step": 0.5, "count": 801}
    names = [c["name"] for c in info["configurations"]]
    assert names == ["blue", "yellow"]
    assert "450-470" in info["configurations"][0]["description"]
    # ingest refuses to overwrite without --force, and keeps the file
    before = out.stat().st_mtime_ns
    proc = cli("ingest", BUNDLED, "-o", out)
    assert proc.returncode != 0 and "--force" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert out.stat().st_mtime_ns == before


def test_info_on_raw_folder():
    proc = cli("info", BUNDLED)
    assert proc.returncode == 0 and "SYNTHETIC" in proc.stdout


def _small_recipe(tmp_path):
    """The bundled recipe with fewer rays and one value per study: every stage runs, in a fraction of the time.

    The device scene traces with 64 lanes: its kernels (compiling them is most of the run) then have one loop
    level instead of two, about half the compilation; lanes never change a result (tests/raytrace)."""
    import tomllib

    from bsdfkit.io.toml_write import dumps

    recipe = ROOT / "fitting" / "cl830.toml"
    scene = tmp_path / "cl830_device.toml"
    text = (ROOT / "fitting" / "scenes" / "cl830_device.toml").read_text()
    scene.write_text(text.replace('"../cl830.toml"', json.dumps(str(recipe)))
                     + "\n[trace]\nlanes = 64\n")
    data = tomllib.loads(recipe.read_text())
    data["recipe"]["measurement"] = str(ROOT / "measurements" / "cl830-synthetic")
    data["exports"].update(interactions=["bibs"], sides=["reflection"])
    data["trace"].update(scene=str(scene), rays=20000,
                         reflectance=[0.8, 0.98], height_mm=[10.0, 80.0], led_fwhm_deg=[30.0], specular_fraction=[1.0])
    data["spectral"].update(measurement=str(ROOT / "measurements" / "eem-synthetic"), rays=20000)
    path = tmp_path / "small.toml"
    path.write_text(dumps(data))
    return path


@pytest.mark.slow
def test_run_writes_every_format_and_outputs_and_refuses_to_clobber(tmp_path):
    """One small main job (in this process: the run, not the process, is under test) with every registered
    writable table format requested (exports.formats): the default outputs, each format re-read and TIS-checked,
    the spectral comparison of its helper process equal to this process's, and no overwrite without --force."""
    import tomllib

    from bsdfkit.io.toml_write import dumps
    from bsdfkit.tables import registry

    out = tmp_path / "out"
    recipe = _small_recipe(tmp_path)
    data = tomllib.loads(recipe.read_text())
    data["exports"]["formats"] = list(registry.writable())
    recipe.write_text(dumps(data))
    proc = cli("run", recipe, "-o", out, "--verbose")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "stage trace ..." in proc.stderr and "helper process failed" not in proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    expected = {"scan.nc", "inplane_bsdf.png", "tis.nc", "interaction_tables.json", "module_budget.png",
                "exports/bibs_reflection.tracepro.txt", "exports/bibs_reflection.zemax.bsdf", "bsdf_fits.json",
                "bsdf_fits.png", "trace.json", "trace_device.nc", "trace_studies.png", "module_spectrum.csv",
                "module_spectrum.png", "module_spectrum.json", "summary.json"}
    assert expected <= set(summary["outputs"])
    for name in expected:
        assert (out / name).stat().st_size > 0, name
    assert (out / "inplane_bsdf.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    checks = summary["export_checks"]
    assert {c["format"] for c in checks} == set(registry.writable())
    assert all(c["ok"] for c in checks), [c for c in checks if not c["ok"]]
    assert (out / "exports" / "bibs_reflection.bsdfxml.xml").stat().st_size > 0
    assert summary["trace"]["device"]["ledger_error"] < 1e-9
    assert 0.3 < summary["trace"]["device"]["LER"] < 0.8
    assert set(summary["module_spectrum"]["colour"]) >= {"x", "y", "cct_K", "duv", "luminous_efficacy_lm_per_W"}
    assert summary["spectral_comparison"]["spectral"]["ledger"]["power_W"]["error"] < 1e-9
    # the command line computed the comparison in its helper process: the numbers of this process, bit for bit
    from bsdfkit.io.jsonout import dumps as json_dumps
    from bsdfkit.pipeline.recipe import _spectral_comparison, load_recipe

    here = json.loads(json_dumps(_spectral_comparison(load_recipe(recipe).spectral).summary))

    def untimed(s: dict) -> str:
        return json.dumps({k: v for k, v in s.items() if k != "stage_seconds"}, sort_keys=True)

    assert untimed(here) == untimed(summary["spectral_comparison"])
    assert (out / "spectral_comparison.png").stat().st_size > 0
    assert 'id="spectral-modes"' in (out / "report.html").read_text()
    proc = cli("run", recipe, "-o", out)
    assert proc.returncode == 2 and "--force" in proc.stderr
