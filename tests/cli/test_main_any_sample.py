"""Any sample from the command line: a measured table fitted, saved and exported; a reflectance standard exported."""
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import cli

DATA = Path(__file__).parent.parent / "data"
ANSYS = DATA / "ansys-radiant-zemax-bsdf" / "inplane_spectral_goniometric_2D_data.csv"
SPECTRALON = DATA / "grit-spectralon" / "Spectralon_Num4.txt"


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    path = tmp_path_factory.mktemp("any") / "a.nc"
    done = cli("ingest", ANSYS, "--quantity", "reflectance-factor", "-o", path)
    assert done.returncode == 0, done.stderr
    return path


@pytest.mark.slow
def test_measured_table_fit_saved_and_exported(tmp_path, scan):
    fit = tmp_path / "fit.nc"
    done = cli("fit", "bsdf", scan, "--interaction", "elastic", "--side", "reflection", "-o", fit, "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert len(out["fits"]) == 5
    # a white diffuser with a gloss lobe: 0.9 < TIS < 1 at the near-normal incidences
    assert all(0.9 < f["tis"] < 1.0 for f in out["fits"] if f["theta_i_deg"] <= 40)
    # the data's TIS beside the fit's is the engine's value (what `bsdfkit tis` reports), one function
    import xarray as xr

    from bsdfkit.reduction.any_sample import tis
    table = tis(xr.load_dataset(scan))
    for f in out["fits"]:
        row = table.sel(side="reflection", theta_i=f["theta_i_deg"]).isel(config=0)
        assert f["data_tis"] == pytest.approx(float(row["tis_band"]), rel=1e-12)
        assert f["data_tis_std"] == pytest.approx(float(row["tis_band_std"]), rel=1e-12)
        if f["plausible"]:  # a plausible fit integrates to the data within their combined uncertainties
            assert abs(f["tis"] - f["data_tis"]) < 3 * np.hypot(f["tis_std"], f["data_tis_std"]), f
    # at 80° the Lambert + Gaussian model explains too little of the data (R² 0.85): that fit fails the gate
    assert [f["theta_i_deg"] for f in out["fits"] if not f["plausible"]] == [80.0]
    assert len(out["warnings"]) == 1 and "incidence 80 deg: R² = 0.85" in out["warnings"][0]
    table = tmp_path / "t.bsdf"
    refused = cli("export", fit, "--to", "zemax", "--interaction", "elastic", "--side", "reflection", "-o", table)
    assert refused.returncode == 2 and "fails the plausibility gate: incidence 80 deg: R²" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1 and not table.exists()
    done = cli("export", fit, "--to", "zemax", "--interaction", "elastic", "--side", "reflection", "-o", table,
               "--incidences", "10,25,40,60", "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    np.testing.assert_allclose(result["tis_table"]["reflection"], result["tis_source"]["reflection"], rtol=0.01)
    # the fit is not overwritten without --force
    again = cli("fit", "bsdf", scan, "--interaction", "elastic", "--side", "reflection", "-o", fit)
    assert again.returncode == 2 and "Traceback" not in again.stderr and len(again.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_reflectance_standard_to_zemax_at_a_wavelength(tmp_path):
    model = tmp_path / "spectralon.nc"
    done = cli("fit", "reflectance", SPECTRALON, "-o", model)
    assert done.returncode == 0, done.stderr
    wl, rho, _ = np.loadtxt(SPECTRALON, unpack=True)
    for nm in (450.0, 600.0):
        out = tmp_path / f"s{nm:g}.bsdf"
        done = cli("export", model, "--to", "zemax", "--interaction", "elastic", "--side", "reflection",
                   "--wavelength-nm", nm, "-o", out, "--json")
        assert done.returncode == 0, done.stderr
        back = cli("read", out, "--json")
        tis = json.loads(back.stdout)["tis_computed"]["reflection"]
        np.testing.assert_allclose(tis, np.interp(nm, wl, rho), rtol=1e-3)
    bad = cli("fit", "reflectance", SPECTRALON, "--percent", "-o", tmp_path / "x.nc")
    assert bad.returncode == 0  # percent flag scales 0.99 to 0.0099: plausible, the user said so
    wrong = tmp_path / "percent.txt"
    wrong.write_text("\n".join(f"{w:g} {98.5:g}" for w in range(400, 420)))
    refused = cli("fit", "reflectance", wrong, "-o", tmp_path / "y.nc")
    assert refused.returncode == 2 and "percent" in refused.stderr and "Traceback" not in refused.stderr


@pytest.mark.slow
@pytest.mark.parametrize("verb", [["tis"], ["info"]])
def test_other_verbs_read_measured_tables(scan, verb):
    done = cli(*verb, scan)
    assert done.returncode == 0, done.stderr
