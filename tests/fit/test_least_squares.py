"""bsdfkit.fit.least_squares: the least-squares core (uncertainties, losses, degeneracies) and BSDF model fits."""
import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
import xarray as xr

from bsdfkit.core.errors import FitError, InputError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import least_squares as fit
from bsdfkit.models import functions as models

TRUTH = {  # θi (deg) → lambert+gaussian parameters (ρ, A sr⁻¹, σ)
    5.0: dict(rho=0.10, A=5.0, sigma=0.03),
    45.0: dict(rho=0.12, A=2.0, sigma=0.06),
    56.0: dict(rho=0.08, A=0.5, sigma=0.10),
}


def goniometer_angles(theta_i_deg):
    """In-plane θs 0–88° every 2° on both sides of the normal + the perpendicular arc ε = −60…60° through
    the specular direction: θs = acos(cos ε cos θi), φs = atan2(sin ε, cos ε sin θi). Degrees."""
    ts = np.arange(0.0, 89.0, 2.0)
    theta = np.concatenate([ts, ts[1:]])
    phi = np.concatenate([np.zeros(ts.size), np.full(ts.size - 1, 180.0)])
    eps = np.radians(np.arange(-60.0, 61.0, 2.0))
    ti = math.radians(theta_i_deg)
    theta_arc = np.degrees(np.arccos(np.cos(eps) * math.cos(ti)))
    phi_arc = np.degrees(np.arctan2(np.sin(eps), np.cos(eps) * math.sin(ti)))
    return np.concatenate([theta, theta_arc]), np.concatenate([phi, phi_arc])


def make_profile(truths, model="lambert+gaussian", noise=0.03, seed=0, side="reflection", std_fraction=None):
    """A goniometer profile Dataset (the fit_bsdf input contract) generated from a model."""
    rng = np.random.default_rng(seed)
    cols = {k: [] for k in ("bsdf", "bsdf_std", "theta_i", "phi_i", "theta_s", "phi_s", "side")}
    for ti, params in truths.items():
        th, ph = goniometer_angles(ti)
        f = fit.bsdf_model_values(model, params, ti, th, ph)
        cols["bsdf"].append(f * (1.0 + noise * rng.standard_normal(f.size)))
        cols["bsdf_std"].append((std_fraction if std_fraction is not None else noise) * f)
        cols["theta_i"].append(np.full(f.size, float(ti)))
        cols["phi_i"].append(np.full(f.size, 180.0))
        cols["theta_s"].append(th)
        cols["phi_s"].append(ph)
        cols["side"].append(np.full(f.size, side, dtype=object))
    c = {k: np.concatenate(v) for k, v in cols.items()}
    return xr.Dataset(
        {"bsdf": ("record", c["bsdf"]), "bsdf_std": ("record", c["bsdf_std"])},
        coords={k: ("record", c[k]) for k in ("theta_i", "phi_i", "theta_s", "phi_s", "side")},
    )


# ---------------------------------------------------------------------------------------------- BSDF fits
@pytest.fixture(scope="module")
def noisy_fit():
    return fit_bsdf_checked(make_profile(TRUTH, seed=7))


def fit_bsdf_checked(profile, model="lambert+gaussian", **kw):
    ds = fit.fit_bsdf(profile, model, **kw)
    assert list(ds.theta_i.values) == sorted(np.unique(profile.theta_i.values))
    return ds


def test_lambert_gaussian_truth_recovered_within_three_standard_errors(noisy_fit):
    ds = noisy_fit
    assert ds.attrs["model"] == "lambert+gaussian" and ds.attrs["side"] == "reflection"
    assert ds.attrs["residual"] == "log"
    for b, ti in enumerate(ds.theta_i.values):
        assert bool(ds.converged[b])
        for name, true in TRUTH[float(ti)].items():
            value, std = float(ds[name][b]), float(ds[f"{name}_std"][b])
            assert 0 < std < 0.2 * abs(true), (ti, name, std)
            assert abs(value - true) < 3 * std, (ti, name, value, true, std)
        assert float(ds.r2[b]) > 0.99
        # log residuals of 3 % noise: RMS ≈ 0.03
        assert 0.02 < float(ds.rms[b]) < 0.04


def test_default_masks_drop_grazing_and_noise_floor_points(noisy_fit):
    th, _ = goniometer_angles(45.0)
    assert int(noisy_fit.n_points.sel(theta_i=45.0)) == int(np.sum(th <= 85.0))
    profile = make_profile(TRUTH, seed=1)
    # Points whose value is below 3·bsdf_std are below the noise floor and must be ignored.
    low = profile.theta_s.values > 60
    profile["bsdf_std"] = profile.bsdf_std.where(~low, profile["bsdf"] / 2.0)
    ds = fit.fit_bsdf(profile)
    assert int(ds.n_points.sel(theta_i=45.0)) == int(np.sum((th <= 85.0) & ~(th > 60)))
    with_core = fit.fit_bsdf(make_profile(TRUTH, seed=1), options=fit.BsdfFitOptions(specular_core_deg=2.5))
    # within 2.5° of specular at θi = 45°: in-plane 44, 46° and the arc points ε = 0, ±2°
    assert int(with_core.n_points.sel(theta_i=45.0)) == int(np.sum(th <= 85.0)) - 5


def test_tis_is_clipped_disk_integral_of_fitted_model(noisy_fit):
    for b, ti in enumerate(noisy_fit.theta_i.values):
        p = {k: float(noisy_fit[k][b]) for k in ("rho", "A", "sigma")}
        with x64():
            expect = float(models.tis_lambert_gaussian(math.radians(ti), p["rho"], p["A"], p["sigma"]))
        assert float(noisy_fit.tis[b]) == pytest.approx(expect, rel=1e-12)


def test_fit_reproduces_closed_form_tis_lambert_gaussian():
    """Lobes far from the disk edge: TIS = ρ + 2πσ²A exactly; the fitted model reproduces it to 1e-4."""
    truths = {5.0: dict(rho=0.1, A=5.0, sigma=0.03), 20.0: dict(rho=0.2, A=1.0, sigma=0.05),
              30.0: dict(rho=0.05, A=3.0, sigma=0.04)}
    ds = fit.fit_bsdf(make_profile(truths, noise=0.0, std_fraction=0.01))
    for b, ti in enumerate(ds.theta_i.values):
        t = truths[float(ti)]
        closed = t["rho"] + 2 * math.pi * t["sigma"] ** 2 * t["A"]
        assert float(ds.tis[b]) == pytest.approx(closed, rel=1e-4)


def test_fit_reproduces_closed_form_tis_abg_normal_incidence():
    truth = dict(A=0.01, B=0.01, g=2.0)
    ds = fit.fit_bsdf(make_profile({0.0: truth}, model="abg", noise=0.0, std_fraction=0.01), "abg")
    assert bool(ds.converged[0])
    closed = models.tis_abg_normal_incidence(**truth)  # = πA ln(1 + 1/B)
    assert closed == pytest.approx(math.pi * 0.01 * math.log(101.0), rel=1e-14)
    assert float(ds.tis[0]) == pytest.approx(closed, rel=1e-4)
    for k, v in truth.items():
        assert float(ds[k][0]) == pytest.approx(v, rel=1e-6)


def test_transmission_side_and_rotated_source_azimuth():
    profile = make_profile(TRUTH, noise=0.0, std_fraction=0.01, side="transmission")
    # Same measurement described with the source at φi = 90°: every azimuth shifts by −90°.
    rotated = profile.assign_coords(phi_i=profile.phi_i - 90.0, phi_s=profile.phi_s - 90.0)
    a = fit.fit_bsdf(profile)
    b = fit.fit_bsdf(rotated)
    assert a.attrs["side"] == "transmission"
    for k in ("rho", "A", "sigma"):
        assert float(a[k].sel(theta_i=45.0)) == pytest.approx(TRUTH[45.0][k], rel=1e-6)
        np.testing.assert_allclose(b[k].values, a[k].values, rtol=1e-9)
    one = fit.fit_bsdf(profile, incidence_deg=56.0)
    assert list(one.theta_i.values) == [56.0]


def test_bsdf_input_errors_are_one_line():
    profile = make_profile({45.0: TRUTH[45.0]}, seed=2)
    two_sides = profile.assign_coords(side=("record", np.where(np.arange(profile.sizes["record"]) % 2, "reflection",
                                                               "transmission").astype(object)))
    bad = profile.copy()
    bad["bsdf"] = bad["bsdf"].where(np.arange(bad.sizes["record"]) != 3)
    cases = [
        (two_sides, InputError, "one side"),
        (profile.drop_vars("bsdf_std"), InputError, "bsdf_std"),
        (bad, InputError, "bsdf of record 3"),
    ]
    for ds, err, text in cases:
        with pytest.raises(err) as exc:
            fit.fit_bsdf(ds)
        assert text in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(InputError, match="incidence"):
        fit.fit_bsdf(profile, incidence_deg=30.0)
    with pytest.raises(ValidationError, match="unknown BSDF model"):
        fit.fit_bsdf(profile, "phong")


# ---------------------------------------------------------------------------------------------- core
def _line(theta, x):
    return theta[0] + theta[1] * x


def _exponential(theta, x):
    return theta[0] * jnp.exp(-theta[1] * x)


def test_covariance_equals_linear_least_squares_formula():
    """For a model linear in θ, C = s²(XᵀX)⁻¹ exactly — also through a log-transformed (bounded) slope."""
    rng = np.random.default_rng(0)
    x = np.linspace(0.0, 10.0, 16)
    sigma = np.full(x.size, 0.2)
    y = 1.0 + 0.5 * x + sigma * rng.standard_normal(x.size)
    params = [fit.Parameter("a"), fit.Parameter("b", 0.0, math.inf)]
    ds = fit.least_squares(_line, x, y, [0.0, 1.0], params, sigma=sigma)
    X = np.stack([np.ones_like(x), x], axis=1) / sigma[:, None]
    coef, *_ = np.linalg.lstsq(X, y / sigma, rcond=None)
    s2 = np.sum((X @ coef - y / sigma) ** 2) / (x.size - 2)
    cov = s2 * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose([float(ds.a), float(ds.b)], coef, rtol=1e-9)
    np.testing.assert_allclose(ds.covariance.values, cov, rtol=1e-6)
    np.testing.assert_allclose([float(ds.a_std), float(ds.b_std)], np.sqrt(np.diag(cov)), rtol=1e-6)
    assert int(ds.dof) == 14 and bool(ds.converged)
    # absolute_sigma: C = (XᵀX)⁻¹ without the s² factor
    ds_abs = fit.least_squares(_line, x, y, [0.0, 1.0], params, sigma=sigma,
                               options=fit.FitOptions(absolute_sigma=True))
    np.testing.assert_allclose(ds_abs.covariance.values, np.linalg.inv(X.T @ X), rtol=1e-6)


def test_robust_rescaling_reproduces_scipy_losses():
    """½Σr̃² equals scipy's cost ½Σc²ρ(r²/c²) for every loss (scipy.optimize.least_squares definitions)."""
    r = np.array([-30.0, -2.0, -0.3, 0.0, 1e-5, 0.7, 1.0, 5.0])
    c = 0.8
    rhos = {
        "linear": lambda z: z,
        "soft_l1": lambda z: 2 * (np.sqrt(1 + z) - 1),
        "huber": lambda z: np.where(z <= 1, z, 2 * np.sqrt(z) - 1),
        "cauchy": lambda z: np.log1p(z),
    }
    for loss, rho in rhos.items():
        opts = fit.FitOptions(loss=loss, f_scale=c)
        with x64():
            rt = np.asarray(fit._robust_scale(jnp.asarray(r), opts))
        # atol: the textbook soft_l1 form 2(√(1+z) − 1) cancels for tiny z; the rescaling does not.
        np.testing.assert_allclose(0.5 * rt**2, 0.5 * c**2 * rho((r / c) ** 2), rtol=1e-12, atol=1e-15)
        # and the same cost as scipy evaluates at the solution of a trivial problem
        res = scipy.optimize.least_squares(lambda p: r + 0 * p, [0.0], loss=loss, f_scale=c)
        assert 0.5 * np.sum(rt**2) == pytest.approx(res.cost, rel=1e-12)


def test_soft_l1_resists_outliers():
    rng = np.random.default_rng(5)
    x = np.linspace(0.0, 4.0, 16)
    y = 2.0 * np.exp(-0.7 * x) + 0.01 * rng.standard_normal(x.size)
    y[[3, 9]] += 0.8  # gross outliers
    params = [fit.Parameter("a", 0.0), fit.Parameter("k", 0.0)]
    plain = fit.least_squares(_exponential, x, y, [1.0, 1.0], params, sigma=0.01)
    robust = fit.least_squares(_exponential, x, y, [1.0, 1.0], params, sigma=0.01,
                               options=fit.FitOptions(loss="soft_l1", f_scale=3.0))
    err_plain = abs(float(plain.k) - 0.7)
    err_robust = abs(float(robust.k) - 0.7)
    assert err_robust < 0.01 < err_plain


def test_degenerate_fits_raise_fit_error():
    x = np.linspace(0.0, 1.0, 10)
    params = [fit.Parameter("a"), fit.Parameter("b")]
    with pytest.raises(FitError, match="2 unmasked points for 2 parameters"):
        fit.least_squares(_line, x, x, [0.0, 1.0], params, mask=x < 0.15)
    with pytest.raises(FitError, match="all unmasked data are zero"):
        fit.least_squares(_line, x, np.zeros_like(x), [0.0, 1.0], params)
    with pytest.raises(FitError) as exc:  # all x equal: intercept and slope cannot be told apart
        fit.least_squares(_line, np.full(10, 2.0), np.full(10, 3.0) + 0.01 * np.sin(np.arange(10)), [0.5, 0.5],
                          params)
    msg = str(exc.value)
    assert "singular" in msg and "a" in msg and "b" in msg and "\n" not in msg
    with pytest.raises(InputError, match=r"y\[3\]"):
        fit.least_squares(_line, x, np.where(np.arange(10) == 3, np.nan, x), [0.0, 1.0], params)
    with pytest.raises(InputError, match="sigma"):
        fit.least_squares(_line, x, x, [0.0, 1.0], params, sigma=np.zeros_like(x))
    with pytest.raises(ValidationError, match="strictly inside"):
        fit.least_squares(_line, x, x, [0.0, -1.0], [fit.Parameter("a"), fit.Parameter("b", 0.0)])
    with pytest.raises(FitError, match="log residuals"):
        fit.least_squares(_line, x, x - 0.5, [0.0, 1.0], params, options=fit.FitOptions(residual="log"))


def test_non_convergence_is_reported_not_hidden():
    x = np.linspace(0.0, 4.0, 16)
    y = 2.0 * np.exp(-0.7 * x)
    params = [fit.Parameter("a", 0.0), fit.Parameter("k", 0.0)]
    ds = fit.least_squares(_exponential, x, y, [50.0, 5.0], params, options=fit.FitOptions(maxiter=2))
    assert not bool(ds.converged) and int(ds.iterations) == 2
    assert np.isfinite(float(ds.a)) and np.isfinite(float(ds.k))
    ok = fit.least_squares(_exponential, x, y, [50.0, 5.0], params)
    assert bool(ok.converged) and float(ok.k) == pytest.approx(0.7, rel=1e-8)


def test_batched_fit_equals_individual_fits():
    x = np.linspace(0.0, 4.0, 16)
    ks = np.array([0.3, 0.7, 1.1])
    y = 2.0 * np.exp(-ks[:, None] * x) + 0.001 * np.cos(5 * x)
    params = [fit.Parameter("a", 0.0), fit.Parameter("k", 0.0)]
    batch = fit.least_squares(_exponential, x, y, [1.0, 1.0], params)
    assert batch.sizes["fit"] == 3
    for b in range(3):
        one = fit.least_squares(_exponential, x, y[b], [1.0, 1.0], params)
        assert float(batch.k[b]) == pytest.approx(float(one.k), rel=1e-10)
        assert float(batch.k_std[b]) == pytest.approx(float(one.k_std), rel=1e-6)


def test_fit_bsdf_cli_on_bundled_measurement(capsys, bundled_scan):
    """``bsdfkit fit bsdf`` end to end on the bundled synthetic measurement (lead's reductions module)."""
    import json
    from pathlib import Path

    from bsdfkit.cli.main import main

    scan = Path(__file__).resolve().parents[2] / "measurements" / "cl830-synthetic"
    assert main(["fit", "bsdf", str(scan), "--interaction", "bibs", "--side", "reflection",
                 "--model", "lambert+gaussian", "--incidence", "45", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["interaction"] == "bibs" and out["side"] == "reflection" and out["residual"] == "log"
    (row,) = out["fits"]
    assert row["theta_i_deg"] == 45.0 and row["converged"]
    p = row["params"]
    assert 0 < p["rho"] < 1 and p["A"] > 0 and 0 < p["sigma"] < 0.5
    # TIS = ρ + (clipped) lobe ≥ ρ, and below 1 for a passive sample
    assert p["rho"] <= row["tis"] < 1.0
    # the data's TIS beside it: the interaction table `bsdfkit tis` reports (of the session's ingest of the same
    # folder: ingest is read_scan + calibrate)
    from bsdfkit.reduction.any_sample import tis
    measured = tis(bundled_scan, 45.0).sel(interaction="bibs", side="reflection")
    assert row["data_tis"] == pytest.approx(float(measured["tis"]), rel=1e-12)
