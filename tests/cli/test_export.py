"""``bsdfkit export`` / ``bsdfkit read``: fit-result and scan sources, JSON summaries, errors, --force."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import fast_lane

from bsdfkit.cli.main import main
from bsdfkit.tables import grids
from bsdfkit.tables.export import fit_bsdf_fn

REAL = Path(__file__).parent.parent / "data" / "ansys-radiant-zemax-bsdf" / (
    "radiant_imaging_sphere_planesymmetric_BRDF.bsdf")
THETA = [0.0, 30.0, 60.0]


def fit_result(path: Path) -> Path:
    """lambert+gaussian fit over (interaction, side, theta_i), as a netCDF file."""
    shape = (2, 2, 3)
    rho = np.empty(shape)
    rho[:, 0], rho[:, 1] = 0.2, 0.1  # reflection, transmission
    ds = xr.Dataset(
        {"rho": (("interaction", "side", "theta_i"), rho),
         "A": (("interaction", "side", "theta_i"), np.full(shape, 3.0)),
         "sigma": (("interaction", "side", "theta_i"), np.full(shape, 0.04))},
        coords={"interaction": ["bibs", "biys"], "side": ["reflection", "transmission"], "theta_i": THETA},
        attrs={"model": "lambert+gaussian"},
    )
    ds.to_netcdf(path)
    return path


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# the verb's path in the fast lane with Zemax; TracePro (both sides, 4 s) and ASAP in the full suite (their writers'
# fast checks: tests/tables/formats/test_tracepro.py and test_asap.py)
@pytest.mark.parametrize(("to", "side"), fast_lane([("tracepro", "both"), ("zemax", "transmission"),
                                                    ("asap", "reflection")], {("zemax", "transmission")}))
def test_export_then_read_json(tmp_path, capsys, to, side):
    src = fit_result(tmp_path / "fit.nc")
    out = tmp_path / f"table.{to}"
    code, text, err = run(capsys, "export", str(src), "--to", to, "--interaction", "bibs", "--side", side,
                          "-o", str(out))
    assert code == 0, err
    assert f"wrote {to} table" in text
    code, text, err = run(capsys, "read", str(out), "--json")
    assert code == 0, err
    summary = json.loads(text)
    assert {"format", "incidences_deg", "tis_computed", "tis_stated"} <= set(summary)
    assert summary["format"] == to and summary["incidences_deg"] == THETA
    ds = xr.open_dataset(src)
    sides = ["reflection", "transmission"] if side == "both" else [side]
    for s in sides:
        fn = fit_bsdf_fn(ds, "bibs", s)
        source = [grids.tis_reference(fn, t, s) for t in THETA]
        lobe_inside = (0.2 if s == "reflection" else 0.1) + 2 * np.pi * 0.04**2 * 3.0
        assert source[0] == pytest.approx(lobe_inside, rel=1e-9)  # Lambert + 2 pi sigma^2 A at normal incidence
        np.testing.assert_allclose(summary["tis_computed"][s], source, rtol=5e-3)
    ds.close()
    # the file's own TIS line is the format's quadrature of its table (the writer's self-check)
    quadrature = summary["details"]["tis_format_quadrature"]
    if to == "tracepro":
        np.testing.assert_allclose(summary["tis_stated"]["total"], quadrature["total"], atol=2e-7)
    else:
        for s in sides:
            np.testing.assert_allclose(summary["tis_stated"][s], quadrature[s], rtol=1e-6)


def test_force_is_needed_to_overwrite(tmp_path, capsys):
    src = fit_result(tmp_path / "fit.nc")
    out = tmp_path / "t.bsdf"
    out.write_text("precious")
    argv = ["export", str(src), "--to", "zemax", "--interaction", "biys", "-o", str(out)]
    code, _, err = run(capsys, *argv)
    assert code == 2 and out.read_text() == "precious"
    assert err.count("\n") == 1 and "output exists" in err and str(out) in err
    code, _, err = run(capsys, *argv, "--force")
    assert code == 0, err
    assert "DataBegin" in out.read_text()


def test_json_export_summary_and_incidence_subset(tmp_path, capsys):
    src = fit_result(tmp_path / "fit.nc")
    out = tmp_path / "t.txt"
    code, text, err = run(capsys, "export", str(src), "--to", "tracepro", "--interaction", "bibs",
                          "--incidences", "30", "--json", "-o", str(out), "--name", "rpc_bibs")
    assert code == 0, err
    result = json.loads(text)
    assert result["incidences_deg"] == [30.0] and result["sides"] == ["reflection"]
    assert result["tis_table"]["reflection"][0] == pytest.approx(result["tis_source"]["reflection"][0], rel=5e-3)
    assert "Name\trpc_bibs" in out.read_text()


@pytest.mark.parametrize(
    ("mutate", "message"),
    [(lambda ds: ds.assign_attrs(model="phong"), "unknown fit model"),
     (lambda ds: ds.drop_vars("sigma"), "lacks parameter 'sigma'"),
     (lambda ds: ds.assign(A=ds["A"].where(ds["theta_i"] != 30.0)), "field 'A[theta_i=30]'"),
     (lambda ds: ds.sel(interaction=["biys"]), "interaction not in the source")],
)
def test_bad_fit_results_are_one_line_errors(tmp_path, capsys, mutate, message):
    src = fit_result(tmp_path / "fit.nc")
    with xr.open_dataset(src) as ds:
        bad = mutate(ds.load())
    bad.to_netcdf(tmp_path / "bad.nc")
    code, _, err = run(capsys, "export", str(tmp_path / "bad.nc"), "--to", "asap", "--interaction", "bibs",
                       "-o", str(tmp_path / "x.txt"))
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x.txt").exists()


def test_incidence_not_in_fit(tmp_path, capsys):
    src = fit_result(tmp_path / "fit.nc")
    code, _, err = run(capsys, "export", str(src), "--to", "zemax", "--interaction", "bibs", "--incidences", "45",
                       "-o", str(tmp_path / "x.bsdf"))
    assert code == 2 and "no fitted parameters at this incidence" in err and "45" in err


def scan_dataset() -> xr.Dataset:
    return xr.Dataset({"bsdf": (("theta_i", "direction"), np.ones((2, 3)))},
                      coords={"theta_i": [0.0, 45.0]}, attrs={"quantity": "bsdf"})


def test_scan_source_uses_the_hemisphere_reconstruction(tmp_path, monkeypatch):
    import bsdfkit.tables.export as export_module

    calls = []

    def hemisphere_bsdf_fn(ds, interaction, side):
        calls.append((interaction, side, float(ds["bsdf"].sum())))
        return lambda theta_i_deg, side_, d: np.full(d.shape[:-1], 0.25 / np.pi)

    monkeypatch.setattr(export_module, "hemisphere_bsdf_fn", hemisphere_bsdf_fn)
    monkeypatch.setattr(export_module, "reduction_kind", lambda ds: "interactions")  # a phosphor scan
    result = export_module.export(scan_dataset(), "tracepro", "yiys", "both", tmp_path / "scan.txt")
    assert calls == [("yiys", "reflection", 6.0), ("yiys", "transmission", 6.0)]
    assert result.incidences_deg == (0.0, 45.0)
    summary = export_module.read_any(tmp_path / "scan.txt")
    np.testing.assert_allclose(summary.tis_computed["reflection"], [0.25, 0.25], rtol=1e-6)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "1e12"])
def test_wavelength_out_of_range_is_refused(tmp_path, capsys, value):
    out = tmp_path / "w.txt"
    code, _, err = run(capsys, "export", str(fit_result(tmp_path / "fit.nc")), "--to", "tracepro",
                       "--interaction", "bibs", "-o", str(out), "--wavelength-nm", value)
    assert code == 2
    assert err.strip().startswith("bsdfkit export: error: field '--wavelength-nm': wavelength out of range"), err
    assert "100-20000 nm" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_wavelength_is_refused_for_a_phosphor_interaction_not_ignored(tmp_path, monkeypatch):
    import bsdfkit.tables.export as export_module
    from bsdfkit.core.errors import InputError

    monkeypatch.setattr(export_module, "reduction_kind", lambda ds: "interactions")  # a phosphor scan
    settings = export_module.ExportSettings(wavelength_nm=550.0)
    with pytest.raises(InputError, match="--wavelength-nm does not apply to a phosphor interaction"):
        export_module.export(scan_dataset(), "tracepro", "yiys", "both", tmp_path / "scan.txt", settings=settings)
    assert not (tmp_path / "scan.txt").exists()


def test_read_real_zemax_file_text_and_json(capsys):
    code, text, err = run(capsys, "read", str(REAL))
    assert code == 0, err
    assert "zemax" in text and "0.134506" in text
    code, text, _ = run(capsys, "read", str(REAL), "--json")
    summary = json.loads(text)
    assert summary["tis_stated"]["reflection"][0] == 0.134506
    assert len(summary["tis_computed"]["reflection"]) == 13
    # the format's quadrature (zero beyond its last radial node) is kept beside the engine's value
    assert summary["details"]["tis_format_quadrature"]["reflection"][0] == pytest.approx(0.1300, abs=5e-5)
    # one BSDF, one answer: read reports what tis reports for the same file
    code, text, _ = run(capsys, "tis", str(REAL), "--json")
    tis = [b["value"] for b in json.loads(text)["band_averaged"]]
    np.testing.assert_allclose(summary["tis_computed"]["reflection"], tis, rtol=1e-12)


def test_read_errors_are_one_line(tmp_path, capsys):
    junk = tmp_path / "junk.txt"
    junk.write_text("hello\n")
    code, _, err = run(capsys, "read", str(junk))
    assert code == 2 and err.count("\n") == 1 and "unrecognised table format" in err
    code, _, err = run(capsys, "read", str(tmp_path / "missing.txt"))
    assert code == 2 and "cannot read file" in err


@pytest.mark.slow
def test_cli_subprocess_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.bsdf"
    bad.write_text(REAL.read_text().replace("TIS 0.1321704", "TIS zero"))
    proc = subprocess.run([sys.executable, "-m", "bsdfkit", "read", str(bad)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
    assert f"{bad}:38: field 'TIS'" in proc.stderr
