"""``bsdfkit fit bsdf``: ``--wavelength NM`` picks one measured wavelength (issue #26.2), and an exact fit reports
zero uncertainties, never NaN (issue #26.3). Truth: Lambertian tables f = ρ(λ)/π [1/sr] written with repr floats,
so the fit reproduces them exactly (zero residual)."""
from __future__ import annotations

import json
import math

import pytest

from bsdfkit.cli.main import main

RHO = {450.0: 0.2, 550.0: 0.3, 650.0: 0.4}


def lambert_table(path, wavelengths):
    """A long table at θi = 10°, θs 0..75° by 5°, φs 0/90/180°, one row per wavelength: f = ρ(λ)/π."""
    rows = ["theta_i,theta_s,phi_s,wavelength,brdf"]
    for ts in range(0, 80, 5):
        for ps in (0, 90, 180):
            rows += [f"10,{ts},{ps},{lam!r},{RHO[lam] / math.pi!r}" for lam in wavelengths]
    path.write_text("\n".join(rows) + "\n")
    return path


def fit(capsys, path, *extra):
    code = main(["fit", "bsdf", str(path), "--interaction", "elastic", "--side", "reflection", "--model", "lambert",
                 *extra])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("asked,expected", [(450.0, 450.0), (550.3, 550.0), (649.6, 650.0)])
def test_wavelength_option_fits_the_nearest_measured_wavelength(tmp_path, capsys, asked, expected):
    path = lambert_table(tmp_path / "three.csv", (450.0, 550.0, 650.0))
    code, out, _ = fit(capsys, path, "--wavelength", str(asked), "--json")
    assert code == 0
    rho = json.loads(out)["fits"][0]["params"]["rho"]
    assert rho == pytest.approx(RHO[expected], rel=1e-9)


def test_without_wavelength_a_single_wavelength_table_uses_its_one_wavelength(tmp_path, capsys):
    path = lambert_table(tmp_path / "one.csv", (650.0,))
    code, out, _ = fit(capsys, path, "--json")
    assert code == 0 and json.loads(out)["fits"][0]["params"]["rho"] == pytest.approx(0.4, rel=1e-9)


@pytest.mark.parametrize("wavelengths,asked,named", [
    ((450.0, 550.0, 650.0), 600.0, "450, 550, 650 nm"),
    ((550.0,), 551.0, "550 nm"),
])
def test_a_wavelength_not_measured_is_refused_in_one_line(tmp_path, capsys, wavelengths, asked, named):
    path = lambert_table(tmp_path / "t.csv", wavelengths)
    code, out, err = fit(capsys, path, "--wavelength", str(asked))
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(path) in err and "--wavelength" in err and named in err and str(asked) in err


def test_wavelength_is_refused_for_a_phosphor_interaction(tmp_path, capsys):
    path = lambert_table(tmp_path / "t.csv", (550.0,))
    code = main(["fit", "bsdf", str(path), "--interaction", "bibs", "--side", "reflection", "--wavelength", "550"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--interaction elastic" in err


def test_an_exact_fit_reports_zero_uncertainty_not_nan(tmp_path, capsys):
    path = lambert_table(tmp_path / "exact.csv", (550.0,))
    code, out, err = fit(capsys, path)
    assert code == 0
    assert "nan" not in (out + err).replace(str(path), "FILE").lower()  # the folder is named after this test
    assert "rho = 0.3 ± 0;" in out and "TIS = 0.3000 ± 0 " in out
    code, out, _ = fit(capsys, path, "--json")
    record = json.loads(out)["fits"][0]
    assert code == 0 and "NaN" not in out
    numbers = [*record["params"].values(), *record["std"].values(), record["tis"], record["tis_std"], record["r2"]]
    assert all(isinstance(x, float) and math.isfinite(x) for x in numbers)
    assert record["std"]["rho"] == 0.0 and record["tis_std"] == 0.0
