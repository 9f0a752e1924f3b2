"""Fits that are physically impossible or undetermined are flagged with reasons and never exported."""
import json

import numpy as np
import pytest
from test_fit import make_profile

from bsdfkit.core.errors import ValidationError
from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.tables.export import export


def test_a_good_fit_has_no_warnings_and_a_tis_uncertainty():
    fit = fit_bsdf(make_profile({45.0: dict(rho=0.12, A=2.0, sigma=0.06)}, seed=3))
    assert json.loads(fit.attrs["warnings"]) == []
    assert bool(fit["physically_possible"].all()) and bool(fit["determined"].all())
    # TIS = ρ + clipped lobe; its uncertainty follows from the covariance and is small but positive
    assert 0 < float(fit["tis_std"].sel(theta_i=45.0)) < 0.01


def test_tis_above_one_is_flagged_and_not_exported(tmp_path):
    # a "reflector" whose data integrate to 1.2: Lambertian 0.9 plus a lobe of 2πσ²A ≈ 0.3
    profile = make_profile({30.0: dict(rho=0.9, A=12.0, sigma=0.063)}, noise=0.01, seed=1)
    fit = fit_bsdf(profile)
    assert float(fit["tis"].sel(theta_i=30.0)) > 1.1
    assert not bool(fit["physically_possible"].sel(theta_i=30.0))
    reasons = json.loads(fit.attrs["warnings"])
    assert any("exceeds 1" in r and "physically impossible" in r for r in reasons)
    fit = fit.expand_dims(interaction=["bibs"], side=["reflection"])
    fit.attrs["model"] = "lambert+gaussian"
    with pytest.raises(ValidationError, match="physically impossible"):
        export(fit, "zemax", "bibs", "reflection", tmp_path / "x.bsdf")
    assert not (tmp_path / "x.bsdf").exists()


def test_a_degenerate_abg_fit_is_flagged():
    # a pure Lambertian surface fitted with ABg: the lobe has nothing to describe (a constant is as good)
    profile = make_profile({5.0: dict(rho=0.5)}, model="lambert", noise=0.02, seed=2)
    fit = fit_bsdf(profile, "abg")
    reasons = json.loads(fit.attrs["warnings"])
    flagged = not bool(fit["determined"].all()) or not bool(fit["physically_possible"].all())
    assert flagged and reasons, reasons
    assert np.all(np.isfinite(fit["tis"].values))
