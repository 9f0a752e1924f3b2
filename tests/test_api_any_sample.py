"""The public API for any sample (issue #23, point 4): ``bsdfkit.tis`` / ``ds.bsdf.tis`` / ``bsdfkit.budget``.

Elastic data gives the directional-hemispherical values as a labelled Dataset, number for number those of
``bsdfkit tis --json`` (one quantity, one function); only the requested incidence is reduced; a band is honoured
by the hemispherical reduction and refused by the interaction table of a phosphor plate; the budget refuses
elastic data with one line saying why.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import bsdfkit
from bsdfkit.cli.main import main
from bsdfkit.core.errors import InputError
from bsdfkit.io import netcdf
from bsdfkit.reduction import any_sample
from bsdfkit.reduction.hemispherical import hemispherical

ANSYS = Path(__file__).parent / "data" / "ansys-radiant-zemax-bsdf" / "inplane_spectral_goniometric_2D_data.csv"
PER_WL = {"value": "tis", "std": "tis_std", "std_measurement": "tis_std_measurement",
          "std_reconstruction": "tis_std_reconstruction", "lobe": "lobe"}
BAND = {"value": "tis_band", "std": "tis_band_std", "std_measurement": "tis_band_std_measurement",
        "std_reconstruction": "tis_band_std_reconstruction", "lobe": "lobe_band"}


@pytest.fixture(scope="module")
def ansys() -> xr.Dataset:
    return bsdfkit.ingest(ANSYS, quantity="reflectance-factor")


def cli_json(capsys, *args) -> dict:
    assert main(["tis", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def lambertian_scan(sides_incidences: dict[str, tuple[float, ...]], wavelengths=(500.0, 510.0, 530.0, 560.0, 600.0),
                    config: str = "lamp") -> xr.Dataset:
    """An in-plane scan of a Lambertian sample, ρ(λ) = 0.3 + λ/2000 (reflection) or 0.6 ρ (transmission)."""
    rows = []
    for side, thetas in sides_incidences.items():
        for th in thetas:
            signed = np.arange(-85.0, 86.0, 5.0)
            if side == "reflection" and th > 0:
                signed = signed[np.abs(signed + th) > 3.0]  # the source blocks the detector
            rows += [(side, th, abs(s), 0.0 if s >= 0 else 180.0) for s in signed]
    side, th, ts, ps = (np.array([r[k] for r in rows]) for k in range(4))
    wl = np.asarray(wavelengths, dtype=float)
    rho = (0.3 + wl / 2000.0)[None, :] * np.where(side == "reflection", 1.0, 0.6)[:, None]
    f = rho / np.pi * np.ones((side.size, 1))
    n = side.size
    ds = xr.Dataset({"bsdf": (("record", "wavelength"), f), "bsdf_std": (("record", "wavelength"), 0.01 * f)},
                    coords={"theta_i": ("record", th.astype(float)), "phi_i": ("record", np.full(n, 180.0)),
                            "theta_s": ("record", ts.astype(float)), "phi_s": ("record", ps.astype(float)),
                            "side": ("record", side.astype(object)),
                            "arc": ("record", np.array(["in_plane"] * n, dtype=object)),
                            "config": ("record", np.array([config] * n, dtype=object)), "wavelength": wl})
    ds.attrs.update(quantity="bsdf", units="1/sr", source="synthetic")
    return ds


# ------------------------------------------------------------------------------------------ elastic data
def test_the_ansys_scan_through_the_api_equals_the_cli_number_for_number(ansys, capsys):
    table = bsdfkit.tis(ansys)
    assert table.attrs["reduction"] == "hemispherical"
    assert dict(table.sizes) == {"config": 1, "side": 1, "theta_i": 5, "wavelength": 35}
    assert list(table["theta_i"].values) == [10.0, 25.0, 40.0, 60.0, 80.0]
    assert all(table[v].attrs["units"] == "1" for v in (*PER_WL.values(), *BAND.values()))
    out = cli_json(capsys, ANSYS, "--quantity", "reflectance-factor")
    assert len(out["hemispherical"]) == len(out["band_averaged"]) == 5
    for rec, band in zip(out["hemispherical"], out["band_averaged"]):
        at = table.sel(config=rec["config"], side=rec["side"], theta_i=rec["incidence_deg"])
        assert list(at["wavelength"].values) == rec["wavelength_nm"]
        for key, name in PER_WL.items():
            assert at[name].values.tolist() == rec[key], (rec["incidence_deg"], key)  # exactly, not approx
        for key, name in BAND.items():
            assert float(at[name]) == band[key], (rec["incidence_deg"], key)
    entries = json.loads(table.attrs["entries"])
    assert [e["theta_i_deg"] for e in entries] == [r["incidence_deg"] for r in out["hemispherical"]]
    assert all(e["method"] and e["assumptions"] for e in entries)
    assert json.loads(table.attrs["warnings"]) == out["warnings"] == []
    # the accessor forwards; the layout is that of the library's results
    via_accessor = ansys.bsdf.tis()
    for r in hemispherical(ansys, theta_i_deg=[10.0, 80.0]):
        at = via_accessor.sel(config=r.config, side=r.side, theta_i=r.theta_i, wavelength=r.wavelength)
        np.testing.assert_array_equal(at["tis"].values, r.value)
        np.testing.assert_array_equal(at["tis_std"].values, r.std)


def test_an_incidence_reduces_only_that_incidence(ansys, monkeypatch, capsys):
    full = bsdfkit.tis(ansys)
    calls = []
    real = any_sample.hemispherical

    def spy(ds, theta_i_deg=None, sides=None, configs=None):
        results = real(ds, theta_i_deg=theta_i_deg, sides=sides, configs=configs)
        calls.append((theta_i_deg, [r.theta_i for r in results]))
        return results

    monkeypatch.setattr(any_sample, "hemispherical", spy)
    at25 = bsdfkit.tis(ansys, 25)
    assert calls == [([25.0], [25.0])]
    assert float(at25["theta_i"]) == 25.0 and "theta_i" not in at25.dims
    xr.testing.assert_equal(at25[["tis", "tis_band"]], full[["tis", "tis_band"]].sel(theta_i=25.0))
    calls.clear()
    out = cli_json(capsys, ANSYS, "--quantity", "reflectance-factor", "--incidence", "25")
    assert calls == [([25.0], [25.0])]  # the CLI runs the same function
    assert [r["incidence_deg"] for r in out["hemispherical"]] == [25.0]
    assert out["hemispherical"][0]["value"] == at25["tis"].sel(config="measured", side="reflection").values.tolist()
    with pytest.raises(InputError, match="field 'incidence': no records at this incidence; expected one of 10, 25"):
        bsdfkit.tis(ansys, 33.0)


def test_a_side_not_measured_at_the_incidence_is_left_out_and_nan_filled():
    ds = lambertian_scan({"reflection": (0.0, 30.0), "transmission": (30.0,)})
    table = bsdfkit.tis(ds)
    assert list(table["side"].values) == ["reflection", "transmission"]
    assert np.isnan(table["tis"].sel(side="transmission", theta_i=0.0)).all()
    assert np.isnan(table["tis_band"].sel(side="transmission", theta_i=0.0)).all()
    rho = 0.3 + table["wavelength"].values / 2000.0
    np.testing.assert_allclose(table["tis"].sel(config="lamp", side="reflection"), [rho, rho], rtol=0.01)
    np.testing.assert_allclose(table["tis"].sel(config="lamp", side="transmission", theta_i=30.0), 0.6 * rho,
                               rtol=0.01)
    normal = bsdfkit.tis(ds, 0.0)  # only the reflection side was measured at 0°
    assert list(normal["side"].values) == ["reflection"] and len(json.loads(normal.attrs["entries"])) == 1


def test_a_band_gives_the_delta_lambda_weighted_mean_of_the_per_wavelength_values():
    ds = lambertian_scan({"reflection": (30.0,)})  # 500, 510, 530, 560, 600 nm: unequal Δλ
    table = bsdfkit.tis(ds, 30.0, band_nm=(505.0, 600.0))
    assert json.loads(table.attrs["band_nm"]) == [505.0, 600.0]
    at = table.sel(config="lamp", side="reflection")
    wl = at["wavelength"].values
    inside = (wl >= 505.0) & (wl <= 600.0)
    dl = np.gradient(wl[inside])  # central-difference sample spacing: 20, 25, 35, 40 nm
    np.testing.assert_allclose(dl, [20.0, 25.0, 35.0, 40.0])
    a = dl / dl.sum()
    assert float(at["tis_band"]) == pytest.approx(a @ at["tis"].values[inside], rel=1e-12)
    assert float(at["tis_band_std_measurement"]) == pytest.approx(
        np.sqrt(np.sum((a * at["tis_std_measurement"].values[inside]) ** 2)), rel=1e-12)
    assert float(at["tis_band_std_reconstruction"]) == pytest.approx(
        a @ at["tis_std_reconstruction"].values[inside], rel=1e-12)
    # a plain mean would differ: the band is honoured with its Δλ weights, not ignored
    assert abs(float(at["tis_band"]) - at["tis"].values[inside].mean()) > 1e-4
    default = bsdfkit.tis(ds, 30.0)
    assert json.loads(default.attrs["band_nm"]) is None
    assert json.loads(default.attrs["entries"])[0]["band_nm"] == [500.0, 600.0]
    assert float(default["tis_band"].sel(config="lamp", side="reflection")) != float(at["tis_band"])
    with pytest.raises(InputError, match="field 'band': no measured wavelength in the band"):
        bsdfkit.tis(ds, band_nm=(700.0, 800.0))
    with pytest.raises(InputError, match="field 'band': option out of range"):
        ds.bsdf.tis(band_nm=(600.0, 500.0))


def test_a_monochrome_scan_without_a_wavelength_coordinate():
    ds = lambertian_scan({"transmission": (0.0, 40.0)}, wavelengths=(633.0,)).isel(wavelength=0, drop=True)
    table = bsdfkit.tis(ds)
    assert table.sizes["wavelength"] == 1 and np.isnan(table["wavelength"].values).all()
    np.testing.assert_allclose(table["tis_band"].sel(config="lamp", side="transmission"), 0.6 * (0.3 + 633 / 2000),
                               rtol=0.01)
    assert all(e["band_nm"] is None for e in json.loads(table.attrs["entries"]))
    assert table["tis"].values.ravel().tolist() == table["tis_band"].values.ravel().tolist()


def test_the_budget_says_in_one_line_why_it_does_not_apply_to_elastic_data(ansys, tmp_path, capsys):
    with pytest.raises(InputError) as err:
        bsdfkit.budget(ansys, 25)
    message = str(err.value)
    assert "\n" not in message and "does not apply to elastic data" in message
    assert "'blue' and 'yellow'" in message and "bi-spectral" in message and "use tis" in message
    assert "configuration(s) 'measured', reflection only, no bi-spectral BSDF" in message
    path = netcdf.save(ansys, tmp_path / "ansys.nc")
    for argv in (["budget", path, "--incidence", "25", "--eta-mc", "0.9"],
                 ["tis", path, "--mode", "interactions", "--incidence", "25"]):
        assert main([str(a) for a in argv]) == 2
        err_text = capsys.readouterr().err.strip()
        assert len(err_text.splitlines()) == 1 and "does not apply to elastic data" in err_text, err_text


# ------------------------------------------------------------------------------------------ phosphor plate
def test_a_phosphor_plate_reduces_one_incidence_and_refuses_a_band(bundled_scan, monkeypatch, tmp_path, capsys):
    calls = []
    real = any_sample.tis_table

    def spy(ds, theta_i_deg=None):
        calls.append(theta_i_deg)
        return real(ds, theta_i_deg=theta_i_deg)

    monkeypatch.setattr(any_sample, "tis_table", spy)
    table = bsdfkit.tis(bundled_scan, 45)
    assert calls == [[45.0]]
    assert table.attrs["reduction"] == "interactions" and float(table["theta_i"]) == 45.0
    assert list(table["interaction"].values) == ["bibs", "biys", "yiys"]
    # the manifest's exact truth at 45°: bibs reflection 10.9 % (Table 2 of the power-budget paper)
    assert float(table["tis"].sel(interaction="bibs", side="reflection")) == pytest.approx(0.109, abs=0.002)
    with pytest.raises(InputError, match="field 'band': a band does not apply to a phosphor plate's interaction"):
        bsdfkit.tis(bundled_scan, 45, band_nm=(450.0, 470.0))
    with pytest.raises(InputError, match="no records at this incidence"):
        bundled_scan.bsdf.tis(33.0)
    path = netcdf.save(bundled_scan, tmp_path / "plate.nc")
    assert main(["tis", str(path), "--incidence", "45", "--band", "450", "470"]) == 2
    err_text = capsys.readouterr().err.strip()
    assert len(err_text.splitlines()) == 1 and "'--band'" in err_text and "own band" in err_text
    assert main(["tis", str(path), "--incidence", "45", "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    api = bsdfkit.budget(bundled_scan, 45).as_dict()
    assert cli["power"] == api["power"] and cli["eqe"] == api["eqe"]
    assert cli["power"]["B_bibs"] == 100 * float(table["tis"].sel(interaction="bibs", side="reflection"))
