"""One plausibility gate for fits (issue #23, point 5): flagged with reasons, and refused by every writer alike."""
import json

import numpy as np
import pytest
import xarray as xr
from conftest import fast_lane
from test_least_squares import make_profile

from bsdfkit.core.errors import ValidationError
from bsdfkit.fit import plausibility
from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.models.registry import bsdf_model
from bsdfkit.tables.export import export, read_any

WRITERS = [("tracepro", {}), ("tracepro-abg", {}), ("zemax", {}), ("asap", {})]


def test_a_good_fit_has_no_warnings_and_a_tis_uncertainty():
    fit = fit_bsdf(make_profile({45.0: dict(rho=0.12, A=2.0, sigma=0.06)}, seed=3))
    assert json.loads(fit.attrs["warnings"]) == []
    assert bool(fit["physically_possible"].all()) and bool(fit["determined"].all())
    assert bool(fit["plausible"].all())
    # TIS = ρ + clipped lobe; its uncertainty follows from the covariance and is small but positive
    assert 0 < float(fit["tis_std"].sel(theta_i=45.0)) < 0.01


def test_tis_above_one_is_flagged_and_not_exported(tmp_path):
    # a "reflector" whose data integrate to 1.2: Lambertian 0.9 plus a lobe of 2πσ²A ≈ 0.3
    profile = make_profile({30.0: dict(rho=0.9, A=12.0, sigma=0.063)}, noise=0.01, seed=1)
    fit = fit_bsdf(profile)
    assert float(fit["tis"].sel(theta_i=30.0)) > 1.1
    assert not bool(fit["physically_possible"].sel(theta_i=30.0))
    assert not bool(fit["plausible"].sel(theta_i=30.0))
    reasons = json.loads(fit.attrs["warnings"])
    assert any("exceeds 1" in r and "physically impossible" in r for r in reasons)
    fit = fit.expand_dims(interaction=["bibs"], side=["reflection"])
    fit.attrs["model"] = "lambert+gaussian"
    for to in ("zemax", "tracepro", "asap"):
        with pytest.raises(ValidationError, match="fails the plausibility gate: .*physically impossible"):
            export(fit, to, "bibs", "reflection", tmp_path / f"x.{to}")
        assert not (tmp_path / f"x.{to}").exists()


def test_a_degenerate_abg_fit_is_flagged():
    # a pure Lambertian surface fitted with ABg: the lobe has nothing to describe (a constant is as good)
    profile = make_profile({5.0: dict(rho=0.5)}, model="lambert", noise=0.02, seed=2)
    fit = fit_bsdf(profile, "abg")
    reasons = json.loads(fit.attrs["warnings"])
    assert not bool(fit["plausible"].all()) and reasons, reasons
    assert np.all(np.isfinite(fit["tis"].values))


# ------------------------------------------------------------------------------------- the same for every writer
def synthetic_fit(model: str, tis: float, tis_std: float, r2: float, theta_i: float = 30.0) -> xr.Dataset:
    """A fit result at one incidence whose model TIS is ``tis`` ± ``tis_std`` (the uncertainty in the amplitude-like
    parameter, which scales the TIS linearly) and whose R² is ``r2``, with the gate's verdict stored."""
    spec = bsdf_model(model)
    if model == "lambert+gaussian":
        lobe = dict(rho=0.0, A=9.0, sigma=0.06)
        params = dict(lobe, rho=tis - float(spec.total_integrated_scatter(lobe, theta_i)))
        linear = "rho"  # dTIS/dρ = 1
        scale = 1.0
    else:  # abg: TIS ∝ A
        unit = dict(A=1.0, B=0.01, g=2.0)
        per_a = float(spec.total_integrated_scatter(unit, theta_i))
        params = dict(unit, A=tis / per_a)
        linear = "A"
        scale = 1.0 / per_a
    names = spec.parameter_names
    std = {n: (tis_std * scale if n == linear else 1e-4 * abs(params[n])) for n in names}
    cov = np.diag([std[n] ** 2 for n in names])[None]
    ds = xr.Dataset(
        {**{n: ("theta_i", [params[n]]) for n in names}, **{f"{n}_std": ("theta_i", [std[n]]) for n in names},
         "covariance": (("theta_i", "parameter", "parameter_2"), cov),
         "r2": ("theta_i", [r2]), "converged": ("theta_i", [True]),
         "tis": ("theta_i", spec.total_integrated_scatter(params, [theta_i]))},
        coords={"theta_i": [theta_i], "parameter": list(names), "parameter_2": list(names)},
        attrs={"model": model, "side": "reflection", "interaction": "bibs"},
    )
    values = np.array([[params[n] for n in names]])
    ds["tis_std"] = ("theta_i", plausibility.tis_std(model, np.array([theta_i]), values, cov))
    return plausibility.annotate(ds)


def write(fit: xr.Dataset, writer: str, path):
    to = writer.split("-")[0]
    from bsdfkit.tables.export import ExportSettings
    settings = ExportSettings(tracepro_scatter="abg" if writer == "tracepro-abg" else "table")
    return export(fit, to, "bibs", "reflection", path, settings=settings)


def writers_for(model: str) -> list[str]:
    return ["tracepro", "zemax", "asap"] + (["tracepro-abg"] if model == "abg" else [])


# each writer's table of the other model in the full suite (fast lane: ABg, which also has TracePro's ABg scatter)
@pytest.mark.parametrize("model", fast_lane(["abg", "lambert+gaussian"], fast=["abg"]))
def test_tis_above_one_within_its_uncertainty_is_written_by_every_writer(tmp_path, model):
    # the user's case: TIS 1.070 ± 0.088, once refused by TracePro only (its own energy check) and written by the
    # Zemax and ASAP writers; within 3σ of 1 it passes the gate, so every writer writes it, as fitted
    fit = synthetic_fit(model, 1.070, 0.088, r2=0.97)
    assert float(fit["tis"][0]) == pytest.approx(1.070, rel=1e-9)
    assert float(fit["tis_std"][0]) == pytest.approx(0.088, rel=1e-3)
    assert bool(fit["plausible"].all()) and bool(fit["physically_possible"].all())
    notes = json.loads(fit.attrs["warnings"])
    assert len(notes) == 1 and "within 3 standard uncertainties" in notes[0]
    for writer in writers_for(model):
        path = tmp_path / f"t.{writer}"
        result = write(fit, writer, path)
        assert path.exists(), writer
        assert result.tis_table["reflection"][0] == pytest.approx(1.070, rel=0.01), writer
        summary = read_any(path)
        assert summary.tis_computed["reflection"][0] == pytest.approx(1.070, rel=0.01), writer
        if writer.startswith("tracepro"):
            assert summary.details["absorptance"] == [0.0]  # TracePro's balance: Abso cannot go below 0


@pytest.mark.parametrize("model", ["abg", "lambert+gaussian"])
def test_tis_above_one_beyond_its_uncertainty_is_refused_by_every_writer(tmp_path, model):
    fit = synthetic_fit(model, 1.070, 0.02, r2=0.97)  # 3.5σ above 1
    assert not bool(fit["plausible"].all()) and not bool(fit["physically_possible"].all())
    for writer in writers_for(model):
        with pytest.raises(ValidationError, match=r"fails the plausibility gate: incidence 30 deg: model TIS 1\.07"):
            write(fit, writer, tmp_path / f"t.{writer}")
        assert not (tmp_path / f"t.{writer}").exists()


@pytest.mark.parametrize("model", fast_lane(["abg", "lambert+gaussian"], fast=["lambert+gaussian"]))
def test_a_poor_r2_is_flagged_and_refused_by_every_writer(tmp_path, model):
    fit = synthetic_fit(model, 0.5, 0.01, r2=0.5)
    assert bool(fit["physically_possible"].all()) and bool(fit["determined"].all())
    assert not bool(fit["plausible"].all())
    assert any("R² = 0.5 < 0.9" in r for r in json.loads(fit.attrs["warnings"]))
    for writer in writers_for(model):
        with pytest.raises(ValidationError, match=r"R² = 0\.5 < 0\.9: the model does not describe the data"):
            write(fit, writer, tmp_path / f"t.{writer}")
        assert not (tmp_path / f"t.{writer}").exists()
    # the same fit with a good R² is written by all of them
    good = synthetic_fit(model, 0.5, 0.01, r2=0.95)
    for writer in writers_for(model):
        write(good, writer, tmp_path / f"good.{writer}")
        assert (tmp_path / f"good.{writer}").exists()


def test_the_gate_judges_a_stored_fit_afresh(tmp_path):
    # a fit saved before the gate (no flags, or flags that say otherwise) is judged by the parameters it holds
    fit = synthetic_fit("lambert+gaussian", 0.5, 0.01, r2=0.5).drop_vars(["plausible", "physically_possible",
                                                                          "determined"])
    fit.attrs["warnings"] = "[]"
    with pytest.raises(ValidationError, match="R²"):
        export(fit, "zemax", "bibs", "reflection", tmp_path / "t.bsdf")


# fast lane: the Lambertian (constant data, once "R² = nan"); the lobe model's exact fit in the full suite
@pytest.mark.parametrize("model", fast_lane(["lambert", "lambert+gaussian"], fast=["lambert"]))
def test_a_perfect_noiseless_fit_is_not_flagged(tmp_path, model):
    # data that the model reproduces exactly: R² = 1 (for the Lambertian, the data are constant: once "R² = nan")
    truth = dict(rho=0.5) if model == "lambert" else dict(rho=0.12, A=2.0, sigma=0.06)
    profile = make_profile({5.0: truth, 45.0: truth}, model=model, noise=0.0, std_fraction=0.01)
    fit = fit_bsdf(profile, model)
    assert np.all(fit["r2"].values == pytest.approx(1.0, abs=1e-9))
    assert json.loads(fit.attrs["warnings"]) == [] and bool(fit["plausible"].all())
    fit = fit.expand_dims(interaction=["bibs"], side=["reflection"])
    for to in ("tracepro", "zemax", "asap"):
        export(fit, to, "bibs", "reflection", tmp_path / f"p.{to}")
        assert (tmp_path / f"p.{to}").exists()


def test_a_lambertian_fit_that_misses_the_data_is_flagged(tmp_path):
    # a glossy surface fitted as Lambertian: R² far below 0.9, flagged (the main job's biys fits) and refused
    profile = make_profile({45.0: dict(rho=0.3, A=2.0, sigma=0.06)}, noise=0.02, seed=4)
    fit = fit_bsdf(profile, "lambert")
    r2 = float(fit["r2"].sel(theta_i=45.0))
    assert r2 < 0.9
    assert not bool(fit["plausible"].sel(theta_i=45.0))
    assert bool(fit["physically_possible"].all()) and bool(fit["determined"].all())
    reasons = json.loads(fit.attrs["warnings"])
    assert any(r.startswith("incidence 45 deg: R² = ") and "< 0.9" in r for r in reasons), reasons
    with pytest.raises(ValidationError, match="fails the plausibility gate"):
        export(fit, "asap", "bibs", "reflection", tmp_path / "l.txt")


def test_thresholds_are_stated_and_used():
    t = plausibility.THRESHOLDS
    assert (t.tis_sigma, t.min_r2, t.undetermined_ratio) == (3.0, 0.9, 1.0)
    fit = synthetic_fit("lambert+gaussian", 0.5, 0.01, r2=0.85)
    assert not plausibility.evaluate(fit).passed
    assert plausibility.evaluate(fit, plausibility.Thresholds(min_r2=0.8)).passed
    with pytest.raises(ValidationError):
        plausibility.Thresholds(min_r2=1.5)


def test_fit_bsdf_cli_reports_the_gate(capsys):
    # the main job's converted light fitted as Lambertian: converged, but R² far below 0.9 at 56°
    from pathlib import Path

    from bsdfkit.cli.main import main

    scan = Path(__file__).resolve().parents[2] / "measurements" / "cl830-synthetic"
    argv = ["fit", "bsdf", str(scan), "--interaction", "biys", "--side", "reflection", "--model", "lambert",
            "--incidence", "56"]
    assert main(argv + ["--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (row,) = out["fits"]
    assert row["converged"] and row["r2"] < 0.9
    assert row["plausible"] is False and out["plausible"] is False
    assert any(r.startswith("R² = ") and "< 0.9" in r for r in row["reasons"]), row["reasons"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if "θi = 56°" in x)
    assert "converged, FAILS the plausibility gate: R² = " in line
