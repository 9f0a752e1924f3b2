"""bsdfkit.fit.lm: the batched Levenberg–Marquardt solver, directly and as bsdfkit.fit.least_squares's default
solver."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from bsdfkit.core.errors import FitError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import least_squares as fit
from bsdfkit.fit import lm
from bsdfkit.fit.spectrum import models as spectrum_models
from bsdfkit.fit.spectrum import starts as spectrum_starts


# ------------------------------------------------------------------------------------ the driver, NumPy-only
def rosenbrock(u: np.ndarray, rows: np.ndarray) -> lm.Linearization:
    """Rosenbrock's function as least squares, r = (10(u₁ − u₀²), 1 − u₀), minimum 0 at (1, 1)."""
    r = np.stack([10.0 * (u[:, 1] - u[:, 0] ** 2), 1.0 - u[:, 0]], axis=1)
    jac = np.zeros((u.shape[0], 2, 2))
    jac[:, 0, 0], jac[:, 0, 1], jac[:, 1, 0] = -20.0 * u[:, 0], 10.0, -1.0
    return lm.Linearization(0.5 * np.sum(r * r, axis=1), np.einsum("kij,ki->kj", jac, r),
                            np.einsum("kij,kil->kjl", jac, jac), r)


def test_rosenbrock_converges_from_the_classic_start_and_others():
    u0 = np.array([[-1.2, 1.0], [2.0, -2.0], [0.0, 0.0], [1.0, 1.0]])
    res = lm.levenberg_marquardt(rosenbrock, u0, xtol=1e-12, gtol=1e-14, maxiter=200)
    assert res.converged.all()
    np.testing.assert_allclose(res.u, 1.0, atol=1e-9)
    assert np.all(res.cost < 1e-20)
    assert res.iterations[3] == 0  # started on the minimum: the gradient test stops it before any step
    assert np.all(res.iterations[:3] > 3) and np.all(res.iterations < 50)  # stops once converged
    np.testing.assert_allclose(res.initial_cost[0], 0.5 * ((10 * (1.0 - 1.44)) ** 2 + 2.2**2))
    np.testing.assert_allclose(res.extra, 0.0, atol=1e-9)  # extra (here: r) is kept for the accepted point


def test_chunked_evaluation_gives_the_same_result_as_one_call():
    rng = np.random.default_rng(3)
    u0 = rng.uniform(-2.0, 2.0, (37, 2))
    calls = []

    def counting(u, rows):
        calls.append(rows.size)
        return rosenbrock(u, rows)

    whole = lm.levenberg_marquardt(rosenbrock, u0, maxiter=100)
    chunked = lm.levenberg_marquardt(counting, u0, maxiter=100, chunk=8)
    assert set(calls) == {8}  # every call sees exactly `chunk` rows (the last one padded)
    np.testing.assert_array_equal(whole.u, chunked.u)
    np.testing.assert_array_equal(whole.iterations, chunked.iterations)


def test_only_running_fits_are_evaluated():
    seen = []

    def recording(u, rows):
        seen.append(rows.copy())
        return rosenbrock(u, rows)

    u0 = np.array([[1.0, 1.0], [-1.2, 1.0]])  # the first fit is converged at the start
    res = lm.levenberg_marquardt(recording, u0, maxiter=100)
    assert res.iterations[0] == 0 and res.converged.all()
    assert all(list(rows) == [1] for rows in seen[1:])
    assert len(seen) == 1 + res.iterations[1] and res.iterations[1] < 50


def test_non_convergence_is_reported():
    # y = e^θ fitted to −1: the optimum is at θ → −∞, the gradient never vanishes exactly.
    def lin(u, rows):
        e = np.exp(u[:, 0])
        r = e + 1.0
        return lm.Linearization(0.5 * r * r, (e * r)[:, None], (e * e)[:, None, None], None)

    res = lm.levenberg_marquardt(lin, np.array([[0.0]]), xtol=0.0, gtol=0.0, maxiter=7)
    assert not res.converged[0] and res.iterations[0] == 7
    assert np.isfinite(res.u).all() and res.u[0, 0] < 0.0


def test_singular_normal_equations_are_rejected_steps_not_nans():
    # The second parameter has no influence: JᵀJ is singular; the diagonal floor keeps the step finite.
    def lin(u, rows):
        r = (u[:, 0] - 3.0)[:, None] * np.ones((1, 5))
        jac = np.zeros((u.shape[0], 5, 2))
        jac[:, :, 0] = 1.0
        return lm.Linearization(0.5 * np.sum(r * r, axis=1), np.einsum("kij,ki->kj", jac, r),
                                np.einsum("kij,kil->kjl", jac, jac), None)

    res = lm.levenberg_marquardt(lin, np.array([[0.0, 5.0]]), maxiter=50)
    assert res.converged[0]
    np.testing.assert_allclose(res.u[0], [3.0, 5.0], atol=1e-8)


def test_bad_arguments_raise_one_line_validation_errors():
    u0 = np.zeros((1, 2))
    cases = [
        dict(u0=np.zeros(2)),
        dict(u0=np.array([[np.nan, 0.0]])),
        dict(xtol=-1.0),
        dict(gtol=math.inf),
        dict(maxiter=0),
        dict(chunk=0),
    ]
    for case in cases:
        kwargs = {"u0": u0, **case}
        with pytest.raises(ValidationError) as exc:
            lm.levenberg_marquardt(rosenbrock, **kwargs)
        assert "\n" not in str(exc.value)
    with pytest.raises(ValidationError, match="linearize"):
        lm.levenberg_marquardt(lambda u, rows: lm.Linearization(np.zeros(3), np.zeros((3, 2)),
                                                                np.zeros((3, 2, 2)), None), u0)


def test_jacobian_products_match_the_analytic_jacobian():
    x = np.linspace(0.0, 2.0, 7)
    y = np.cos(x)
    with x64():
        cost, g, jtj, aux = lm.jacobian_products(lambda t: (t[0] * jnp.exp(-t[1] * x) - y, t[0]),
                                                 jnp.array([1.5, 0.3]))
    e = np.exp(-0.3 * x)
    r = 1.5 * e - y
    jac = np.stack([e, -1.5 * x * e], axis=1)
    np.testing.assert_allclose(cost, 0.5 * r @ r, rtol=1e-14)
    np.testing.assert_allclose(g, jac.T @ r, rtol=1e-13)
    np.testing.assert_allclose(jtj, jac.T @ jac, rtol=1e-13)
    assert float(aux) == 1.5


# ------------------------------------------------------------------------------ through bsdfkit.fit.least_squares (JAX)
C = 4.0 * math.log(2.0)


def split_gaussian_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    wl = np.arange(380.0, 781.0, 2.0)
    peak, fwhm, alpha = rng.uniform(450, 600, n), rng.uniform(30, 150, n), rng.uniform(-0.3, 0.3, n)
    off = wl[None, :] - peak[:, None]
    width = fwhm[:, None] * (1.0 + np.sign(off) * alpha[:, None])
    return wl, np.exp(-C * (off / width) ** 2) + 0.01 * rng.standard_normal((n, wl.size))


def start(wl: np.ndarray, y: np.ndarray) -> np.ndarray:
    rows = [spectrum_starts._peak_and_fwhm(wl, row / row.max(), np.ones(wl.size, bool)) for row in y]
    return np.array([[p, w, 0.0, a * row.max()] for (p, w, a), row in zip(rows, y)])


def split_fit(wl, y, p0, **options):
    params = spectrum_models._parameters("split-gaussian", float(wl[0]), float(wl[-1]))
    options.setdefault("solver", "lm")
    return fit.least_squares(spectrum_models._split_gaussian, wl, y, p0, params, options=fit.FitOptions(**options))


def values(ds) -> np.ndarray:
    return np.stack([np.atleast_1d(ds[k].values) for k in ("peak_nm", "fwhm_nm", "alpha", "amplitude")], axis=-1)


def test_split_gaussian_fits_agree_with_scipy_and_with_jaxopt():
    wl, y = split_gaussian_data(6, seed=11)
    p0 = start(wl, y)
    ds = split_fit(wl, y, p0)
    assert ds.attrs["solver"].startswith("bsdfkit.fit.lm") and bool(ds.converged.all())
    params = spectrum_models._parameters("split-gaussian", float(wl[0]), float(wl[-1]))
    lo, hi = params[0].lower, params[0].upper

    def natural(u):
        return np.array([lo + (hi - lo) / (1 + math.exp(-u[0])), math.exp(u[1]), -1 + 2 / (1 + math.exp(-u[2])),
                         math.exp(u[3])])

    def numpy_model(t):
        off = wl - t[0]
        return t[3] * np.exp(-C * (off / (t[1] * (1.0 + np.sign(off) * t[2]))) ** 2)

    u0 = fit._to_unconstrained(p0, params)
    ref = np.array([natural(scipy.optimize.least_squares(lambda u, row=row: numpy_model(natural(u)) - row, u,
                                                         method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12).x)
                    for u, row in zip(u0, y)])
    np.testing.assert_allclose(values(ds), ref, rtol=1e-7, atol=1e-9)
    jo = split_fit(wl, y, p0, solver="jaxopt")
    assert jo.attrs["solver"].startswith("jaxopt") and bool(jo.converged.all())
    np.testing.assert_allclose(values(ds), values(jo), rtol=1e-7, atol=1e-9)
    for name in ("peak_nm_std", "alpha_std", "r2", "rms", "cost"):
        np.testing.assert_allclose(ds[name].values, jo[name].values, rtol=1e-6)


def test_a_fits_result_does_not_depend_on_the_rest_of_its_batch():
    wl, y = split_gaussian_data(12, seed=5)
    p0 = start(wl, y)
    a = split_fit(wl, y[:8], p0[:8])
    other = split_fit(wl, np.concatenate([y[:1], y[8:], y[1:4]]), np.concatenate([p0[:1], p0[8:], p0[1:4]]))
    # Same batch size → same compiled kernel: fit 0 is bit-for-bit the same with different companions.
    np.testing.assert_array_equal(values(a)[0], values(other)[0])
    assert int(a.iterations[0]) == int(other.iterations[0])
    np.testing.assert_array_equal(a.covariance.values[0], other.covariance.values[0])
    alone = split_fit(wl, y[0], p0[0])  # another batch size: another kernel, same arithmetic up to rounding
    np.testing.assert_allclose(values(alone)[0], values(a)[0], rtol=1e-8)


def test_masked_points_are_ignored_whatever_they_hold():
    wl, y = split_gaussian_data(2, seed=8)
    p0 = start(wl, y)
    keep = (wl < 520.0) | (wl > 560.0)
    spoiled = np.where(keep, y, np.nan)
    masked = fit.least_squares(spectrum_models._split_gaussian, wl, spoiled, p0,
                               spectrum_models._parameters("split-gaussian", float(wl[0]), float(wl[-1])),
                               mask=np.broadcast_to(keep, y.shape), options=fit.FitOptions(solver="lm"))
    cut = fit.least_squares(spectrum_models._split_gaussian, wl[keep], y[:, keep], p0,
                            spectrum_models._parameters("split-gaussian", float(wl[0]), float(wl[-1])),
                            options=fit.FitOptions(solver="lm"))
    assert bool(masked.converged.all()) and list(masked.n_points.values) == [int(keep.sum())] * 2
    np.testing.assert_allclose(values(masked), values(cut), rtol=1e-9)
    np.testing.assert_allclose(masked.r2.values, cut.r2.values, rtol=1e-9)


def test_iteration_limit_gives_converged_false_with_finite_values():
    wl, y = split_gaussian_data(3, seed=2)
    p0 = start(wl, y)
    ds = split_fit(wl, y, p0, maxiter=1)
    assert not bool(ds.converged.any()) and list(ds.iterations.values) == [1, 1, 1]
    assert np.isfinite(values(ds)).all()


def test_model_not_finite_at_the_start_is_a_fit_error_with_both_solvers():
    def log_model(theta, x):
        return theta[0] * jnp.log(x - theta[1])

    x = np.linspace(0.0, 1.0, 12)
    params = [fit.Parameter("a"), fit.Parameter("b")]
    for solver in ("lm", "jaxopt"):
        with pytest.raises(FitError, match="not finite at the initial parameters"):
            fit.least_squares(log_model, x, np.ones_like(x), [1.0, 0.5], params,
                              options=fit.FitOptions(solver=solver))


def test_kernel_is_shared_across_batch_sizes_and_solver_settings():
    wl, y = split_gaussian_data(300, seed=1)
    p0 = start(wl, y)
    split_fit(wl, y[:150], p0[:150])
    before = fit._lm_kernel._cache_size()
    ds = split_fit(wl, y, p0, maxiter=50, xtol=1e-8, gtol=1e-9)  # 300 fits: still chunks of _LM_CHUNK
    assert fit._lm_kernel._cache_size() == before
    assert bool(ds.converged.all())


def test_natural_transform_and_slope_match_the_jax_transform():
    params = [fit.Parameter("a", -1.0, 3.0), fit.Parameter("b", 2.0), fit.Parameter("c", upper=-1.0),
              fit.Parameter("d")]
    u = np.array([[0.3, -1.2, 2.5, 7.0], [45.0, 61.0, -70.0, -3.0], [-39.0, 59.0, -59.0, 0.0]])
    theta, slope = fit._natural_and_slope(u, params)
    spec = fit._Spec(tuple(p.transform for p in params), fit.FitOptions())
    bounds = jnp.asarray([[p.lower, p.upper] for p in params])
    with x64():
        for row in range(u.shape[0]):
            t, d = jax.jvp(lambda v: fit._to_natural(v, spec, bounds), (jnp.asarray(u[row]),),
                           (jnp.ones(4),))
            np.testing.assert_allclose(theta[row], np.asarray(t), rtol=1e-15)
            np.testing.assert_allclose(slope[row], np.asarray(d), rtol=1e-12, atol=0.0)
    assert slope[1, 0] == 0.0 and slope[1, 1] == 0.0 and slope[1, 2] == 0.0  # clipped: no influence


def test_empty_batch_gives_an_empty_result_with_both_solvers():
    x = np.linspace(0.0, 1.0, 10)
    params = [fit.Parameter("a"), fit.Parameter("b")]
    for solver in ("lm", "jaxopt"):
        ds = fit.least_squares(lambda t, x: t[0] + t[1] * x, x, np.zeros((0, 10)), np.zeros((0, 2)), params,
                               options=fit.FitOptions(solver=solver))
        assert ds.sizes["fit"] == 0 and ds.a.shape == (0,) and ds.converged.dtype == bool


def test_fit_options_validate_solver_and_tolerances():
    assert fit.FitOptions().solver == "lm"
    for bad in (dict(solver="scipy"), dict(xtol=-1e-3), dict(gtol=float("nan"))):
        with pytest.raises(ValidationError) as exc:
            fit.FitOptions(**bad)
        assert "\n" not in str(exc.value)
