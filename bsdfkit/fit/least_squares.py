"""Batched nonlinear least squares in JAX, and the BSDF-model fitting entry point.

:func:`least_squares` fits one model to a batch of data sets at once. The default solver (``FitOptions.solver
= "lm"``, :mod:`bsdfkit.fit.lm`) evaluates residuals and Jacobians of the whole batch in one compiled
``jax.vmap``/``jax.jacfwd`` kernel and runs the Levenberg–Marquardt iteration on the host; ``solver =
"jaxopt"`` runs :class:`jaxopt.LevenbergMarquardt` under ``jax.jit(jax.vmap(...))``. Both give the same
solutions (tests/fit/test_lm.py); the measured costs are in docs/fitting.md §8. :func:`fit_bsdf` builds on it
for goniometer profiles.

How a fit is set up (docs/fitting.md has the derivations):

* **Bounds** by parameter transforms θ = T(u) on an unconstrained u: lower and upper bound →
  θ = lo + (hi − lo)·sigmoid(u) (logit); lower only → θ = lo + eᵘ (log); upper only → θ = hi − eᵘ;
  none → θ = u. The solver works in u; the results are reported in θ.
* **Residual kinds** (docs/fitting.md §6): ``absolute`` r = f − y; ``relative`` r = (f − y)/|y|;
  ``log`` r = ln(f + ε) − ln(y + ε), for BSDFs spanning decades. With standard uncertainties u(y) each
  residual is divided by its propagated uncertainty: u(y), u(y)/|y| and u(y)/(y + ε) respectively.
* **Robust losses** as in :func:`scipy.optimize.least_squares` (cost ½Σ c²ρ(r²/c²), c = ``f_scale``):
  soft_l1 ρ(z) = 2(√(1+z) − 1), huber ρ(z) = z (z ≤ 1) else 2√z − 1, cauchy ρ(z) = ln(1+z). They are
  realised by rescaling each residual, r̃ = r·√(ρ(z)/z), so that ½Σr̃² is exactly that cost and the
  Levenberg–Marquardt machinery applies unchanged.
* **Uncertainties**: covariance C = s²(JᵀJ)⁻¹ with J the Jacobian of the (weighted, robust-rescaled)
  residuals with respect to the *natural* parameters θ at the solution, and s² = Σr̃²/(n − p) (set
  s² = 1 with ``absolute_sigma=True`` when the supplied uncertainties are trusted in absolute terms).
  By the chain rule J_u = J_θ·diag(dθ/du), so this equals diag(dθ/du)·s²(J_uᵀJ_u)⁻¹·diag(dθ/du), the
  covariance of u mapped through the transform's Jacobian; J_θ is used directly because it stays
  regular when a parameter approaches a bound (dθ/du → 0).
* **R² and RMS** are computed unweighted in the residual space: on y for ``absolute``, on
  (f − y)/|y| for ``relative`` (R² there uses the absolute form) and on ln(y + ε) for ``log``.

Degenerate problems (fewer unmasked points than parameters + 1, all-zero data, a singular JᵀJ at the
solution) raise :class:`bsdfkit.core.errors.FitError`; a fit that stops at ``maxiter`` is returned with
``converged = False``. With ``FitOptions.on_singular = "report"`` a fit whose JᵀJ is singular (or whose parameters
went non-finite) is returned instead, with a NaN covariance and the message in the variable ``problem``: the caller
decides (:func:`fit_bsdf` uses it to tell an absent lobe from a failed fit, docs/fitting.md "Fallback"). All work
runs in float64 inside :func:`bsdfkit.core.jaxconfig.x64`.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import FitError, InputError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import lm, plausibility
from bsdfkit.measurement.instrument import Instrument, aperture_quadrature
from bsdfkit.models.registry import BSDF_MODELS, Parameter, bsdf_model

__all__ = [
    "Parameter",
    "FitOptions",
    "least_squares",
    "BSDF_MODELS",
    "BsdfFitOptions",
    "fit_bsdf",
    "bsdf_model_values",
]

ResidualKind = Literal["absolute", "relative", "log"]
LossKind = Literal["linear", "soft_l1", "huber", "cauchy"]

# Clip of the unconstrained variables: keeps eᵘ and sigmoid(u) away from overflow/underflow so that a
# wild trial step yields a rejected step instead of inf/NaN (which would poison the solver state).
_U_CLIP_EXP = 60.0
_U_CLIP_SIGMOID = 40.0
# Stand-in for a non-finite residual at a trial point: large, so the step is rejected, and finite.
_BAD_RESIDUAL = 1e100
# Residual norm, relative to the norm of the data (in residual space), below which a fit reproduces the data exactly.
_EXACT_RESIDUAL = 1e-10
# Spread of the data, relative to their norm, below which they count as constant: no measurement resolves a part
# in 10⁶, and below it ss_tot is rounding noise (a noiseless Lambertian profile, a fit stopped at a bound a part in
# 10⁹ from the data), so that 1 − ss_res/ss_tot would be 0/0 or −10¹⁴.
_CONSTANT_DATA = 1e-6


@dataclass(frozen=True)
class FitOptions:
    """Configuration of :func:`least_squares`.

    Attributes
    ----------
    residual
        'absolute', 'relative' or 'log' (see the module docstring).
    loss
        'linear' (plain least squares), 'soft_l1', 'huber' or 'cauchy' (scipy definitions).
    f_scale
        Soft margin c of the robust losses, in residual units (after weighting by uncertainties).
    log_epsilon
        ε of the log residual, in data units (e.g. the noise-equivalent BSDF).
    absolute_sigma
        If true the covariance is (JᵀJ)⁻¹ (uncertainties trusted as absolute); otherwise s²(JᵀJ)⁻¹.
    maxiter
        Maximum Levenberg–Marquardt iterations (steps tried); reaching it without meeting a stopping rule
        marks the fit ``converged = False``.
    xtol, gtol
        Madsen–Nielsen stopping rule: stop when ‖Δu‖ ≤ xtol·(‖u‖ + xtol) or ‖∇‖∞ ≤ gtol, where the
        residuals are divided by their norm at the start point, so gtol is relative to the initial cost.
    max_condition
        JᵀJ (column-equilibrated) with a larger condition number is treated as singular → FitError.
    solver
        'lm' (default): :func:`bsdfkit.fit.lm.levenberg_marquardt`, one compiled Jacobian kernel and a
        host-driven iteration over the fits still running — fast to compile (docs/fitting.md §8).
        'jaxopt': :class:`jaxopt.LevenbergMarquardt` under ``jax.jit(jax.vmap(...))``, the whole iteration
        compiled. Both use the same residuals, transforms, tolerances and result semantics.
    on_singular
        'raise' (default): a fit whose JᵀJ is singular or worse conditioned than ``max_condition``, or whose
        parameters went non-finite, raises :class:`~bsdfkit.core.errors.FitError`. 'report': such fits are returned
        with NaN covariance and standard errors, and the one-line message in the string variable ``problem`` ("" for
        a sound fit); a model that is not finite at the start point still raises.
    """

    residual: ResidualKind = "absolute"
    loss: LossKind = "linear"
    f_scale: float = 1.0
    log_epsilon: float = 0.0
    absolute_sigma: bool = False
    maxiter: int = 200
    xtol: float = 1e-10
    gtol: float = 1e-10
    max_condition: float = 1e12
    solver: Literal["lm", "jaxopt"] = "lm"
    on_singular: Literal["raise", "report"] = "raise"

    def __post_init__(self) -> None:
        if self.residual not in ("absolute", "relative", "log"):
            raise ValidationError("unknown residual kind", field="residual",
                                  expected="absolute, relative or log", got=self.residual)
        if self.loss not in ("linear", "soft_l1", "huber", "cauchy"):
            raise ValidationError("unknown loss", field="loss",
                                  expected="linear, soft_l1, huber or cauchy", got=self.loss)
        if not (self.f_scale > 0 and math.isfinite(self.f_scale)):
            raise ValidationError("f_scale must be positive", field="f_scale", got=self.f_scale)
        if not (self.log_epsilon >= 0 and math.isfinite(self.log_epsilon)):
            raise ValidationError("log_epsilon must be ≥ 0", field="log_epsilon", got=self.log_epsilon)
        if not (isinstance(self.maxiter, int) and self.maxiter >= 1):
            raise ValidationError("maxiter must be a positive integer", field="maxiter", got=self.maxiter)
        for name in ("xtol", "gtol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value >= 0):
                raise ValidationError(f"{name} must be a finite number ≥ 0", field=name, got=value)
        if self.solver not in ("lm", "jaxopt"):
            raise ValidationError("unknown solver", field="solver", expected="lm or jaxopt", got=self.solver)
        if self.on_singular not in ("raise", "report"):
            raise ValidationError("unknown on_singular", field="on_singular", expected="raise or report",
                                  got=self.on_singular)


# ------------------------------------------------------------------------------------------------
# Parameter transforms
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Spec:
    """Hashable, static description of a problem for the jitted solver (the bound *values* are traced
    arguments, so fits that differ only in bounds share one compilation)."""

    transforms: tuple[str, ...]
    options: FitOptions


def _to_natural(u: jnp.ndarray, spec: _Spec, bounds: jnp.ndarray) -> jnp.ndarray:
    """θ = T(u); ``bounds`` is the (p, 2) array of (lower, upper)."""
    out = []
    for k, kind in enumerate(spec.transforms):
        lo, hi, uk = bounds[k, 0], bounds[k, 1], u[k]
        if kind == "logit":
            out.append(lo + (hi - lo) * jax.nn.sigmoid(jnp.clip(uk, -_U_CLIP_SIGMOID, _U_CLIP_SIGMOID)))
        elif kind == "log":
            out.append(lo + jnp.exp(jnp.clip(uk, -_U_CLIP_EXP, _U_CLIP_EXP)))
        elif kind == "neglog":
            out.append(hi - jnp.exp(jnp.clip(uk, -_U_CLIP_EXP, _U_CLIP_EXP)))
        else:
            out.append(uk)
    return jnp.stack(out)


def _to_unconstrained(theta: np.ndarray, parameters: Sequence[Parameter]) -> np.ndarray:
    """Inverse transform (NumPy) of initial values, which must lie strictly inside their bounds."""
    u = np.empty_like(theta, dtype=float)
    for k, p in enumerate(parameters):
        t = theta[..., k]
        if not np.all(np.isfinite(t)):
            raise ValidationError("initial value is not finite", field=p.name, got=float(t[~np.isfinite(t)][0]))
        inside = (t > p.lower) & (t < p.upper)
        if not np.all(inside):
            bad = float(t[~inside].ravel()[0])
            raise ValidationError("initial value must lie strictly inside the bounds", field=p.name,
                                  expected=f"{p.lower} < value < {p.upper}", got=bad)
        kind = p.transform
        if kind == "logit":
            q = (t - p.lower) / (p.upper - p.lower)
            u[..., k] = np.log(q) - np.log1p(-q)
        elif kind == "log":
            u[..., k] = np.log(t - p.lower)
        elif kind == "neglog":
            u[..., k] = np.log(p.upper - t)
        else:
            u[..., k] = t
    return u


# ------------------------------------------------------------------------------------------------
# Residuals and robust loss
# ------------------------------------------------------------------------------------------------
def _model_space(f: jnp.ndarray, options: FitOptions) -> jnp.ndarray:
    """Map model values to the residual space (ln(f + ε) for log residuals)."""
    if options.residual == "log":
        # The floor keeps ln finite (and its gradient zero) if a trial model value goes non-positive.
        return jnp.log(jnp.maximum(f + options.log_epsilon, 1e-300))
    return f


def _robust_scale(r: jnp.ndarray, options: FitOptions) -> jnp.ndarray:
    """r̃ = r·√(ρ(z)/z), z = (r/c)², so ½Σr̃² = ½Σc²ρ(z) (scipy's robust cost)."""
    if options.loss == "linear":
        return r
    z = (r / options.f_scale) ** 2
    if options.loss == "soft_l1":
        phi = 2.0 / (1.0 + jnp.sqrt(1.0 + z))
    elif options.loss == "huber":
        big = z > 1.0
        z_safe = jnp.where(big, z, 1.0)
        phi = jnp.where(big, (2.0 * jnp.sqrt(z_safe) - 1.0) / z_safe, 1.0)
    else:  # cauchy
        small = z < 1e-8
        z_safe = jnp.where(small, 1.0, z)
        phi = jnp.where(small, 1.0 - 0.5 * z, jnp.log1p(z_safe) / z_safe)
    return r * jnp.sqrt(phi)


def _residuals_natural(theta, x, y_t, w, m, model, options):
    """Weighted, robust-rescaled residuals at natural parameters θ; masked points give exactly 0."""
    f = model(theta, x)
    r = (_model_space(f, options) - y_t) * w
    r = jnp.where(m, r, 0.0)
    r = _robust_scale(r, options)
    return jnp.where(jnp.isfinite(r), r, _BAD_RESIDUAL)


def _jaxopt():
    # jaxopt announces on import that it is no longer maintained (DeprecationWarning); bsdfkit pins and
    # tests the version it uses, so that notice is noise for users of bsdfkit.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import jaxopt
    return jaxopt


def _solve_one(u0, x, y_t, w, m, bounds, *, model, spec: _Spec):
    jaxopt = _jaxopt()

    options = spec.options

    def natural(theta):
        return _residuals_natural(theta, x, y_t, w, m, model, options)

    r0 = natural(_to_natural(u0, spec, bounds))
    # Scale residuals to unit norm at the start so gtol is relative. A start that is already exact
    # (‖r0‖ = 0, or below 1e-100) keeps scale 1: a huge scale would overflow JᵀJ.
    norm0 = jnp.sqrt(jnp.sum(r0**2))
    scale = jnp.where(norm0 > 1e-100, 1.0 / jnp.where(norm0 > 1e-100, norm0, 1.0), 1.0)

    def scaled(u):
        return natural(_to_natural(u, spec, bounds)) * scale

    solver = jaxopt.LevenbergMarquardt(
        residual_fun=scaled,
        maxiter=options.maxiter,
        stop_criterion="madsen-nielsen",
        xtol=options.xtol,
        gtol=options.gtol,
        # Cholesky of JᵀJ + μI: twice as fast as jaxopt's QR of [J; √μ I] on large batches. On an
        # exactly singular problem it can return NaN; that fit is then reported as a FitError below.
        solver="cholesky",
        materialize_jac=True,
        implicit_diff=False,
        jit=True,
    )
    u, state = solver.run(u0)
    theta = _to_natural(u, spec, bounds)
    r = natural(theta)
    jac = jax.jacfwd(natural)(theta)
    f = model(theta, x)
    plain = jnp.where(m, _model_space(f, options) - y_t, 0.0)
    return {
        "theta": theta,
        "r0_finite": jnp.all(jnp.isfinite(r0)) & jnp.all(jnp.abs(r0) < _BAD_RESIDUAL),
        "sum_sq": jnp.sum(r**2),
        "jtj": jac.T @ jac,
        "plain": plain,
        "iterations": state.iter_num,
    }


def _solve_batch_impl(u0, x, y_t, w, m, bounds, *, model, spec):
    one = partial(_solve_one, model=model, spec=spec)
    return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, None))(u0, x, y_t, w, m, bounds)


# One compiled solver per (model, spec, shape). Small problems are compiled with XLA's backend
# optimisation off: that halves the compile time, which dominates their cost, while large batches
# (where run time dominates) get the fully optimised build. Per-function compiler options: no global flag.
_SMALL_PROBLEM = 1 << 16  # padded batch × points
_solve_batch = jax.jit(_solve_batch_impl, static_argnames=("model", "spec"))
_solve_batch_small = jax.jit(_solve_batch_impl, static_argnames=("model", "spec"),
                             compiler_options={"xla_backend_optimization_level": 0})


# ------------------------------------------------------------------------------------------------
# Public entry point
# ------------------------------------------------------------------------------------------------
def _bucket(k: int) -> int:
    """Padded size: the next power of two up to 64, then the next multiple of 64."""
    k = max(int(k), 1)
    return 1 << (k - 1).bit_length() if k <= 64 else -(-k // 64) * 64


def _as_batch(name: str, a: Any, shape: tuple[int, int]) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim > 2 and arr.shape[:2] == shape:
        return arr  # per-point sub-arrays (e.g. detector-aperture nodes) ride along unchanged
    try:
        return np.broadcast_to(arr, shape)
    except ValueError:
        raise InputError("array does not match the data shape", field=name,
                         expected=f"broadcastable to {shape}", got=np.shape(a)) from None


def _natural_and_slope(u: np.ndarray, parameters: Sequence[Parameter]) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :func:`_to_natural` for the ``solver='lm'`` path: θ = T(u) and dθ/du (elementwise;
    zero where the clip of u is active, as for the JAX transform), for u of shape (..., p)."""
    theta = np.empty_like(u)
    slope = np.empty_like(u)
    for k, p in enumerate(parameters):
        uk = u[..., k]
        kind = p.transform
        if kind == "logit":
            inside = np.abs(uk) < _U_CLIP_SIGMOID
            sig = 1.0 / (1.0 + np.exp(-np.clip(uk, -_U_CLIP_SIGMOID, _U_CLIP_SIGMOID)))
            theta[..., k] = p.lower + (p.upper - p.lower) * sig
            slope[..., k] = np.where(inside, (p.upper - p.lower) * sig * (1.0 - sig), 0.0)
        elif kind in ("log", "neglog"):
            inside = np.abs(uk) < _U_CLIP_EXP
            e = np.exp(np.clip(uk, -_U_CLIP_EXP, _U_CLIP_EXP))
            theta[..., k] = p.lower + e if kind == "log" else p.upper - e
            slope[..., k] = np.where(inside, e if kind == "log" else -e, 0.0)
        else:
            theta[..., k] = uk
            slope[..., k] = 1.0
    return theta, slope


def _lm_kernel_impl(theta, slope, x, y_t, w, m, *, model, options: FitOptions):
    """Linearisation kernel of the ``solver='lm'`` path, for a chunk of fits at natural parameters θ with
    transform slopes dθ/du: ½Σr̃², J_uᵀr̃, J_uᵀJ_u, J_θᵀJ_θ and the plain residuals, where J_θ = ∂r̃/∂θ by
    forward mode and J_u = J_θ·diag(dθ/du) (chain rule). The residuals are those of
    :func:`_residuals_natural`. The transform and the row gather stay on the host, so the kernel depends
    only on the model, the residual settings, the chunk size and the padded length."""

    def one(theta, slope, x, y_t, w, m):
        def residuals(t):
            plain = jnp.where(m, _model_space(model(t, x), options) - y_t, 0.0)
            r = _robust_scale(plain * w, options)
            return jnp.where(jnp.isfinite(r), r, _BAD_RESIDUAL), plain

        cost, g_theta, jtj_theta, plain = lm.jacobian_products(residuals, theta)
        return cost, slope * g_theta, slope[:, None] * jtj_theta * slope[None, :], jtj_theta, plain

    return jax.vmap(one)(theta, slope, x, y_t, w, m)


# One compilation per (model, residual settings, chunk, padded length); tolerances, maxiter, bounds and the
# batch size are not part of the kernel. XLA options: bsdfkit.fit.lm.COMPILER_OPTIONS; kernels of at most
# lm.SMALL_KERNEL_POINTS points per call are built without LLVM optimisation (lm.SMALL_KERNEL_OPTIONS).
_lm_kernel = jax.jit(_lm_kernel_impl, static_argnames=("model", "options"), compiler_options=lm.COMPILER_OPTIONS)
_lm_kernel_small = jax.jit(_lm_kernel_impl, static_argnames=("model", "options"),
                           compiler_options=lm.SMALL_KERNEL_OPTIONS)
_LM_CHUNK = 128  # fits per kernel call (bsdfkit.fit.lm evaluates only the fits still running, in such chunks)


def _solve_lm(u0: np.ndarray, x: Any, y_t: np.ndarray, w: np.ndarray, m: np.ndarray,
              parameters: Sequence[Parameter], *, model, options: FitOptions) -> dict[str, np.ndarray]:
    """The ``solver='lm'`` path of :func:`least_squares`: inputs have the fits on axis 0 and the points
    padded to a bucket; the result dict has the layout of the jaxopt path, plus ``converged``."""
    n_fit, n_par = u0.shape
    if n_fit == 0:  # an empty batch gives an empty result, as on the jaxopt path
        return {"theta": np.zeros((0, n_par)), "r0_finite": np.zeros(0, bool), "sum_sq": np.zeros(0),
                "jtj": np.zeros((0, n_par, n_par)), "plain": np.zeros((0, y_t.shape[1])),
                "iterations": np.zeros(0, int), "converged": np.zeros(0, bool)}
    kernel_options = dataclasses.replace(FitOptions(), residual=options.residual, loss=options.loss,
                                         f_scale=options.f_scale, log_epsilon=options.log_epsilon)
    chunk = min(_bucket(u0.shape[0]), _LM_CHUNK)
    kernel = _lm_kernel_small if chunk * y_t.shape[1] <= lm.SMALL_KERNEL_POINTS else _lm_kernel

    def linearize(u: np.ndarray, rows: np.ndarray) -> lm.Linearization:
        theta, slope = _natural_and_slope(u, parameters)
        contiguous = np.array_equal(rows, np.arange(rows[0], rows[0] + rows.size))
        pick = slice(rows[0], rows[0] + rows.size) if contiguous else rows
        data = jax.tree_util.tree_map(lambda a: a[pick], (x, y_t, w, m))
        # Device arrays are returned unread: the kernel runs asynchronously while lm prepares the next chunk.
        cost, grad, jtj, jtj_theta, plain = kernel(theta, slope, *data, model=model, options=kernel_options)
        return lm.Linearization(cost, grad, jtj, (theta, jtj_theta, plain))

    res = lm.levenberg_marquardt(linearize, u0, xtol=options.xtol, gtol=options.gtol, maxiter=options.maxiter,
                                 chunk=chunk)
    theta, jtj_theta, plain = res.extra
    return {
        "theta": theta,
        # A residual replaced by the stand-in for a non-finite value makes Σr̃² ≥ (1e100)².
        "r0_finite": np.isfinite(res.initial_cost) & (2.0 * res.initial_cost < _BAD_RESIDUAL**2),
        "sum_sq": 2.0 * res.cost,
        "jtj": jtj_theta,
        "plain": plain,
        "iterations": res.iterations,
        "converged": res.converged,
    }


def least_squares(
    model: Callable[[jnp.ndarray, Any], jnp.ndarray],
    x: Any,
    y: np.ndarray,
    p0: np.ndarray,
    parameters: Sequence[Parameter],
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    batch_dim: str = "fit",
    batch_labels: Sequence[str] | None = None,
    model_name: str | None = None,
) -> xr.Dataset:
    """Fit ``model`` to one data set or a batch of them (Levenberg–Marquardt, float64).

    The solver is chosen by ``options.solver``: 'lm' (:mod:`bsdfkit.fit.lm`, the default) or 'jaxopt'; both
    solve the same problem with the same stopping rule and return the same result layout.

    Parameters
    ----------
    model
        Pure JAX function ``model(theta, x) -> f`` for *one* data set: θ is the 1-D array of natural
        parameters (ordered as ``parameters``), ``x`` a pytree of arrays of shape (n,). It must be
        hashable (a module-level function or a ``functools.partial`` kept alive by the caller) because it
        is a static argument of the compiled solver.
    x
        Independent variable(s): a pytree whose leaves broadcast to the shape of ``y``.
    y
        Data, shape (n,) for one fit or (batch, n). Pad unequal lengths and mask the padding.
    p0
        Initial natural parameters, shape (p,) or (batch, p), strictly inside the bounds.
    parameters
        One :class:`Parameter` per model parameter (names, bounds, units).
    sigma
        Standard uncertainties of ``y`` (same units), broadcast to ``y``; None = unweighted.
    mask
        Boolean, True = use the point; broadcast to ``y``. None = use all points.
    options
        :class:`FitOptions`.
    batch_dim
        Name of the batch dimension of the result.
    batch_labels
        How error messages name each member of a batch (default "fit 0", "fit 1", ...; "" = no prefix).
    model_name
        Recorded in the result's attributes.

    Returns
    -------
    xarray.Dataset over ``batch_dim`` (and ``parameter``/``parameter_2`` for the covariance) with, for
    each parameter ``name``: ``name`` and ``name_std``; plus ``covariance``, ``at_bound`` (per parameter),
    ``r2``, ``rms``, ``cost`` (½Σr̃²), ``n_points``, ``dof``, ``iterations`` and ``converged`` (and ``problem``
    with ``options.on_singular = "report"``). A 1-D ``y`` gives a result without the batch dimension.

    Raises
    ------
    FitError
        Too few unmasked points, all-zero data, model not finite at ``p0``, singular JᵀJ (unless
        ``options.on_singular = "report"``).
    InputError
        Non-finite data or uncertainty on an unmasked point, non-positive uncertainty, shape mismatch.
    """
    options = options or FitOptions()
    parameters = tuple(parameters)
    names = [p.name for p in parameters]
    if len(set(names)) != len(parameters):
        raise ValidationError("parameter names must be unique", field="parameters", got=names)
    single = np.ndim(y) == 1
    x2, y2, p0, m = _as_batches(x, y, p0, len(parameters), mask)
    where = _labeller(single, batch_labels)
    y_t, w = _residual_space(y2, sigma, m, single, options)
    n_used = _check_enough_data(y2, m, len(parameters), where)
    out = _solve(model, x2, y_t, w, m, _to_unconstrained(p0, parameters), parameters, options)
    diverged = _check_solution(out, names, p0, where)
    cov, unconstrained, ill = _covariance(out, names, n_used - len(parameters), where, options)
    if options.on_singular == "raise":
        # in the order the checks are made: the first diverged fit, else the first with a zero column, else the
        # first ill-conditioned one (as a loop over the batch would find them)
        for messages in (diverged, unconstrained, ill):
            if any(messages):
                raise FitError(next(msg for msg in messages if msg))
    # one message per fit, the most basic first (a diverged fit's JᵀJ is not finite either)
    problems = [a or b or c for a, b, c in zip(diverged, unconstrained, ill)]
    r2, rms = _goodness_of_fit(out["plain"], y2, y_t, m, n_used, options)
    ds = _fit_dataset(out, parameters, cov, r2, rms, n_used, options, batch_dim)
    if options.on_singular == "report":
        ds["problem"] = ((batch_dim,), np.asarray(problems, dtype=object),
                         {"long_name": "why the covariance is not defined ('' for a sound fit)"})
    ds.attrs = {"model": model_name or getattr(model, "__name__", repr(model)), **ds.attrs}
    return ds.isel({batch_dim: 0}) if single else ds


def _as_batches(x, y, p0, n_par: int, mask) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """``x``, ``y``, ``p0`` and the mask with the fits on axis 0 (one fit: a batch of one), checked in shape."""
    y = np.asarray(y, dtype=float)
    if y.ndim not in (1, 2):
        raise InputError("data must be 1-D (one fit) or 2-D (batch, n)", field="y", got=y.shape)
    y2 = y[None, :] if y.ndim == 1 else y
    p0 = np.asarray(p0, dtype=float)
    if p0.shape[-1:] != (n_par,):
        raise InputError("initial values do not match the parameters", field="p0",
                         expected=f"last dimension {n_par}", got=p0.shape)
    p0 = np.broadcast_to(p0, (y2.shape[0], n_par))
    m = np.ones(y2.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y2.shape)
    x2 = jax.tree_util.tree_map(lambda leaf: _as_batch("x", leaf, y2.shape), x)
    return x2, y2, p0, m


def _labeller(single: bool, batch_labels: Sequence[str] | None) -> Callable[[int], str]:
    """How messages name fit ``b`` of a batch: "" for a single fit, else its label or "fit b", then ": "."""
    def where(b: int) -> str:
        if single:
            return ""
        if batch_labels is not None:
            return f"{batch_labels[b]}: " if batch_labels[b] else ""
        return f"fit {b}: "
    return where


def _residual_space(y2: np.ndarray, sigma, m: np.ndarray, single: bool,
                    options: FitOptions) -> tuple[np.ndarray, np.ndarray]:
    """The data in residual space and the weights of their residuals (module docstring), after checking that the
    unmasked data and uncertainties are finite (and the uncertainties positive)."""
    shape = y2.shape
    used_y = np.where(m, y2, 1.0)
    if not np.all(np.isfinite(used_y)):
        i, j = np.argwhere(~np.isfinite(used_y))[0]
        raise InputError("data value is not finite", field=f"y[{i}, {j}]" if not single else f"y[{j}]",
                         got=float(y2[i, j]))
    if sigma is None:
        s = np.ones(shape)
    else:
        s = _as_batch("sigma", sigma, shape)
        used_s = np.where(m, s, 1.0)
        bad = ~(np.isfinite(used_s) & (used_s > 0))
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise InputError("standard uncertainty must be finite and > 0", field=f"sigma[{i}, {j}]",
                             got=float(s[i, j]))
    eps = options.log_epsilon
    if options.residual == "absolute":
        y_t, w = y2, 1.0 / np.where(m, s, 1.0)
        if sigma is None:
            w = np.ones(shape)
    elif options.residual == "relative":
        if np.any(m & (y2 == 0)):
            raise FitError("relative residuals need non-zero data on every unmasked point; mask the zeros")
        # r = (f − y)/|y| with uncertainty u/|y|  ⇒  weight |y|/u (or 1/|y| unweighted).
        y_t = y2
        w = 1.0 / np.where(m, np.abs(y2), 1.0) if sigma is None else 1.0 / np.where(m, s, 1.0)
    else:
        shifted = y2 + eps
        if np.any(m & ~(shifted > 0)):
            raise FitError("log residuals need data + log_epsilon > 0 on every unmasked point; "
                           "mask non-positive points or raise log_epsilon")
        y_t = np.log(np.where(m, shifted, 1.0))
        w = np.ones(shape) if sigma is None else np.where(m, shifted, 1.0) / np.where(m, s, 1.0)
    return y_t, w


def _check_enough_data(y2: np.ndarray, m: np.ndarray, n_par: int, where: Callable[[int], str]) -> np.ndarray:
    """The unmasked points per fit, after checking that every fit has more than ``n_par`` and some non-zero."""
    n_used = m.sum(axis=1)
    too_few = n_used <= n_par
    bad = too_few | ~np.any(m & (y2 != 0), axis=1)
    if bad.any():  # the first offending fit, as a loop over the batch would find it
        b = int(np.argmax(bad))
        if too_few[b]:
            raise FitError(f"{where(b)}{int(n_used[b])} unmasked points for {n_par} parameters; "
                           f"need at least {n_par + 1}")
        raise FitError(f"{where(b)}all unmasked data are zero; nothing to fit")
    return n_used


def _solve(model, x2, y_t: np.ndarray, w: np.ndarray, m: np.ndarray, u0: np.ndarray,
           parameters: Sequence[Parameter], options: FitOptions) -> dict[str, np.ndarray]:
    """Run the solver of ``options.solver`` on the batch (fits on axis 0) from unconstrained start ``u0``; the
    result dict of :func:`_solve_lm` with ``plain`` cut back to the data's points."""
    n_batch, n = y_t.shape
    # Pad the point and batch axes to buckets (masked points; copies of fit 0) so that problems of
    # similar size share one compiled solver instead of compiling once per exact shape.
    n_pad, b_pad = _bucket(n), _bucket(n_batch)

    def pad(a: np.ndarray, value: float | None, batch: bool = True) -> np.ndarray:
        if batch:
            a = np.concatenate([a, np.repeat(a[:1], b_pad - n_batch, axis=0)], axis=0)
        width = ((0, 0), (0, n_pad - n)) + ((0, 0),) * (a.ndim - 2)  # trailing per-point axes unpadded
        return np.pad(a, width, mode="edge") if value is None else np.pad(a, width, constant_values=value)

    if options.solver == "lm":
        # Only the points are padded: bsdfkit.fit.lm gathers the fits it evaluates into fixed-size chunks.
        with x64():
            out = _solve_lm(u0, jax.tree_util.tree_map(lambda leaf: pad(leaf, None, False), x2),
                            pad(np.asarray(y_t, float), 0.0, False), pad(np.asarray(w, float), 0.0, False),
                            pad(m, False, False), parameters, model=model, options=options)
    else:
        spec = _Spec(
            transforms=tuple(p.transform for p in parameters),
            # Only what the solver loop uses: post-processing options must not force a recompilation.
            options=dataclasses.replace(options, absolute_sigma=False, max_condition=1e12, on_singular="raise"),
        )
        u0_pad = np.concatenate([u0, np.repeat(u0[:1], b_pad - n_batch, axis=0)], axis=0)
        with x64():
            solve = _solve_batch_small if b_pad * n_pad <= _SMALL_PROBLEM else _solve_batch
            out = solve(
                jnp.asarray(u0_pad),
                jax.tree_util.tree_map(lambda leaf: jnp.asarray(pad(leaf, None)), x2),
                jnp.asarray(pad(np.asarray(y_t, float), 0.0)),
                jnp.asarray(pad(np.asarray(w, float), 0.0)),
                jnp.asarray(pad(m, False)),
                jnp.asarray([[p.lower, p.upper] for p in parameters], dtype=jnp.float64),
                model=model,
                spec=spec,
            )
            out = {k: np.asarray(v)[:n_batch] for k, v in out.items()}
        # jaxopt reports no stopping reason: a fit that used all maxiter steps counts as not converged.
        out["converged"] = out["iterations"] < options.maxiter
    out["plain"] = out["plain"][:, :n]
    return out


def _check_solution(out: dict[str, np.ndarray], names: Sequence[str], p0: np.ndarray,
                    where: Callable[[int], str]) -> list[str]:
    """FitError for the first fit whose model was not finite at the start; the message of each fit whose parameters
    went non-finite ("" for the others)."""
    bad_start = ~out["r0_finite"]
    if bad_start.any():
        b = int(np.argmax(bad_start))
        raise FitError(f"{where(b)}model is not finite at the initial parameters "
                       f"{dict(zip(names, p0[b].tolist()))}")
    diverged = ~np.isfinite(out["theta"]).all(axis=1)
    return [f"{where(b)}the solver produced non-finite parameters (singular normal equations during the "
            f"iterations); the data do not determine {', '.join(names)}" if diverged[b] else ""
            for b in range(diverged.size)]


def _covariance(out: dict[str, np.ndarray], names: Sequence[str], dof: np.ndarray, where: Callable[[int], str],
                options: FitOptions) -> tuple[np.ndarray, list[str], list[str]]:
    """Covariance C = s²(JᵀJ)⁻¹ of every fit, computed on the column-equilibrated matrix (all fits at once), and
    the messages of the fits whose JᵀJ has a zero or non-finite column, or a condition number above
    ``options.max_condition`` ("" for the others); those fits get a NaN covariance."""
    jtj = out["jtj"]
    n_par = len(names)
    d = np.sqrt(np.abs(np.diagonal(jtj, axis1=1, axis2=2)))
    unconstrained = ~np.isfinite(jtj).all(axis=(1, 2)) | ~(d > 0).all(axis=1)
    zero_msgs = []
    for b in range(jtj.shape[0]):
        zero = [names[k] for k in range(n_par) if not (np.isfinite(d[b, k]) and d[b, k] > 0)]
        zero_msgs.append(f"{where(b)}singular JᵀJ: the data do not constrain "
                         f"{', '.join(zero) or 'the parameters (non-finite Jacobian)'}" if unconstrained[b] else "")
    # a unit matrix stands in for the unusable ones, so that the batched eigen-decomposition and inverse run
    d = np.where(unconstrained[:, None], 1.0, d)
    outer = d[:, :, None] * d[:, None, :]
    corr = np.where(unconstrained[:, None, None], np.eye(n_par), jtj / outer)
    ev, evec = np.linalg.eigh(corr)
    with np.errstate(divide="ignore"):
        cond = np.where(ev[:, 0] > 0, ev[:, -1] / np.where(ev[:, 0] > 0, ev[:, 0], 1.0), np.inf)
    singular = ~(cond <= options.max_condition)
    ill_msgs = []
    for b in range(jtj.shape[0]):
        # The eigenvector of the smallest eigenvalue names the parameter combination left undetermined.
        weak = [names[k] for k in np.argsort(-np.abs(evec[b, :, 0])) if abs(evec[b, k, 0]) > 0.3]
        ill_msgs.append(f"{where(b)}singular JᵀJ (condition number {cond[b]:.3g} > {options.max_condition:.3g}): "
                        f"{', '.join(weak)} not separately determined by these data; fix the model (fewer "
                        "parameters) or the data (masks, range)" if singular[b] else "")
    bad = unconstrained | singular
    s2 = np.ones(jtj.shape[0]) if options.absolute_sigma else out["sum_sq"] / dof
    cov = s2[:, None, None] * np.linalg.inv(np.where(bad[:, None, None], np.eye(n_par), corr)) / outer
    return np.where(bad[:, None, None], np.nan, cov), zero_msgs, ill_msgs


def _goodness_of_fit(plain: np.ndarray, y2: np.ndarray, y_t: np.ndarray, m: np.ndarray, n_used: np.ndarray,
                     options: FitOptions) -> tuple[np.ndarray, np.ndarray]:
    """R² and RMS of every fit from its plain residuals ``plain`` (module docstring, "R² and RMS")."""
    ss_res = np.sum(plain**2, axis=1)
    if options.residual == "relative":
        # R² on the data themselves; the RMS is the relative one.
        fitted = y2 + plain
        ss_res_abs = np.sum(np.where(m, (fitted - y2) ** 2, 0.0), axis=1)
        mean = np.sum(np.where(m, y2, 0.0), axis=1) / n_used
        ss_tot = np.sum(np.where(m, (y2 - mean[:, None]) ** 2, 0.0), axis=1)
        rms = np.sqrt(np.sum(np.where(m, (plain / np.where(m, np.abs(y2), 1.0)) ** 2, 0.0), axis=1) / n_used)
        ss_for_r2 = ss_res_abs
    else:
        mean = np.sum(np.where(m, y_t, 0.0), axis=1) / n_used
        ss_tot = np.sum(np.where(m, (y_t - mean[:, None]) ** 2, 0.0), axis=1)
        rms = np.sqrt(ss_res / n_used)
        ss_for_r2 = ss_res
    # Residuals at rounding level (a model that reproduces the data exactly) give R² = 1 even when the data are
    # constant (ss_tot = 0, e.g. a noiseless Lambertian profile), where 1 − ss_res/ss_tot is 0/0 or rounding noise.
    scale = np.sqrt(np.sum(np.where(m, y_t if options.residual != "relative" else y2, 0.0) ** 2, axis=1))
    exact = ss_for_r2 <= (_EXACT_RESIDUAL * scale) ** 2
    # the spread of constant data is floored at _CONSTANT_DATA of their norm: a model within that of the data
    # scores R² ≈ 1, one further off scores R² ≪ 0 (worse than the constant that fits exactly), never NaN
    ss_ref = np.maximum(ss_tot, (_CONSTANT_DATA * scale) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(exact, 1.0, np.where(ss_ref > 0, 1.0 - ss_for_r2 / ss_ref, np.nan)), rms


def _fit_dataset(out: dict[str, np.ndarray], parameters: Sequence[Parameter], cov: np.ndarray, r2: np.ndarray,
                 rms: np.ndarray, n_used: np.ndarray, options: FitOptions, batch_dim: str) -> xr.Dataset:
    """The result of :func:`least_squares` over ``batch_dim`` (its ``model`` attribute set by the caller)."""
    theta = out["theta"]
    names = [p.name for p in parameters]
    converged = out["converged"] & np.all(np.isfinite(theta), axis=1) & np.isfinite(out["sum_sq"])
    std = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    at_bound = np.stack([plausibility.at_bound(theta[:, k], p) for k, p in enumerate(parameters)], axis=-1)
    data_vars: dict[str, Any] = {}
    for k, p in enumerate(parameters):
        data_vars[p.name] = ((batch_dim,), theta[:, k], {"units": p.unit, "lower": p.lower, "upper": p.upper})
        data_vars[f"{p.name}_std"] = ((batch_dim,), std[:, k], {"units": p.unit,
                                                                "long_name": f"standard error of {p.name}"})
    data_vars["covariance"] = ((batch_dim, "parameter", "parameter_2"), cov)
    data_vars["at_bound"] = ((batch_dim, "parameter"), at_bound,
                             {"long_name": "parameter ended on (within 1e-6 of) a bound"})
    data_vars["r2"] = ((batch_dim,), r2, {"long_name": "coefficient of determination",
                                          "note": "1 when the residuals vanish (to 1e-10 of the data); NaN only "
                                                  "if the unmasked data are constant and the model misses them"})
    data_vars["rms"] = ((batch_dim,), rms, {"long_name": f"RMS of the unweighted {options.residual} residuals"})
    data_vars["cost"] = ((batch_dim,), 0.5 * out["sum_sq"], {"long_name": "final cost ½Σr̃²"})
    data_vars["n_points"] = ((batch_dim,), n_used.astype(int))
    data_vars["dof"] = ((batch_dim,), (n_used - len(parameters)).astype(int))
    data_vars["iterations"] = ((batch_dim,), out["iterations"].astype(int))
    data_vars["converged"] = ((batch_dim,), converged)
    return xr.Dataset(
        data_vars,
        coords={"parameter": names, "parameter_2": names},
        attrs={
            "solver": ("bsdfkit.fit.lm Levenberg–Marquardt (Marquardt scaling, Nielsen damping, madsen-nielsen "
                       "stop), float64" if options.solver == "lm" else
                       "jaxopt.LevenbergMarquardt (madsen-nielsen stop), float64"),
            "residual": options.residual,
            "loss": options.loss,
            "f_scale": options.f_scale,
            "log_epsilon": options.log_epsilon,
            "absolute_sigma": int(options.absolute_sigma),
            "maxiter": options.maxiter,
        },
    )


# ------------------------------------------------------------------------------------------------
# BSDF model fitting
# ------------------------------------------------------------------------------------------------
def _aperture_average(function: Callable, theta, x):
    """The model as the goniometer reports it: averaged over the detector aperture.

    A detector of solid angle Ω centred at θs reports Σ_n w_n f(ω_n) cos θ_n / (Ω cos θs) over aperture nodes
    ω_n (:func:`bsdfkit.measurement.instrument.aperture_quadrature`); ``x["weight"]`` holds w_n cos θ_n / (Ω cos θs).
    Fitting the point model to such data would bias sharp lobes; convolving the model is safer than
    deconvolving the data (docs/fitting.md §7, "Finite aperture").
    """
    nodes = {"theta_i": x["theta_i"][..., None], "theta_s": x["theta_s_nodes"], "phi_s": x["phi_s_nodes"]}
    return jnp.sum(function(theta, nodes) * x["weight"], axis=-1)


#: Aperture-averaged versions of the registry's model functions (module-level objects: hashable, compiled once).
_APERTURE_FUNCTIONS: dict[str, Callable] = {
    name: functools.partial(_aperture_average, m.function) for name, m in BSDF_MODELS.items()}


@dataclass(frozen=True)
class BsdfFitOptions:
    """Masks and residual settings of :func:`fit_bsdf`.

    Attributes
    ----------
    max_theta_s_deg
        Points with θs above this (grazing) are masked; default 85°.
    noise_floor_k
        Points with bsdf < k·bsdf_std are masked (below the noise floor); default 3.
    specular_core_deg
        Points within this angle of the specular direction are masked (detector half-angle); default 0
        (no mask).
    aperture
        Average the model over the detector aperture when the profile states the instrument geometry
        (attributes ``detector_distance_mm`` and ``aperture_diameter_mm``); default True.
    fit
        :class:`FitOptions`; default log residuals (BSDFs span decades), linear loss.
    fallback
        Fit the lobe model's diffuse part alone (``lambert`` for ``lambert+gaussian`` and ``lambert+abg``) when the
        data do not determine its lobe at any incidence, and say so in the result (:data:`FALLBACK_MODELS`,
        docs/fitting.md "Fallback"); default True. False: the requested model or an error.
    """

    max_theta_s_deg: float = 85.0
    noise_floor_k: float = 3.0
    specular_core_deg: float = 0.0
    aperture: bool = True
    fit: FitOptions = field(default_factory=lambda: FitOptions(residual="log"))
    fallback: bool = True


#: The model that a lobe model falls back to when the data do not determine its lobe (:func:`fit_bsdf`): its
#: diffuse part, which the lobe model contains (lobe amplitude A = 0).
FALLBACK_MODELS: dict[str, str] = {"lambert+gaussian": "lambert", "lambert+abg": "lambert"}
#: A lobe amplitude is consistent with zero when A < k·u(A) with this k [1]: 2, a two-sided 95 % interval that
#: contains 0 (the gate's own "undetermined" is the looser 1·u(A)).
LOBE_AMPLITUDE_K = 2.0
#: Significance level [1] of the F-test of the lobe (the extra parameters of the lobe model against its diffuse
#: part): a lobe whose fit improvement has a p-value below it is real, and the fit never falls back then. 1e-3: one
#: fit in a thousand of a truly diffuse sample keeps its (undetermined) lobe and fails as before, rather than a real
#: weak lobe being dropped.
LOBE_SIGNIFICANCE = 1e-3


def bsdf_model_values(model: str, params: dict[str, float], theta_i_deg, theta_s_deg, phi_s_deg) -> np.ndarray:
    """Evaluate a named BSDF model [1/sr] at angles in **degrees** (source at φi = 180°).

    Parameters
    ----------
    model : str
        Model name, e.g. 'lambert+gaussian' (:mod:`bsdfkit.models.registry`).
    params : dict of str to float
        The model's parameters.
    theta_i_deg : float or array_like
        Angle of incidence [deg].
    theta_s_deg : float or array_like
        Scatter polar angle [deg].
    phi_s_deg : float or array_like
        Scatter azimuth [deg].

    Returns
    -------
    ndarray
        BSDF [1/sr].
    """
    return bsdf_model(model).values(params, theta_i_deg, theta_s_deg, phi_s_deg)


def _initial_bsdf_parameters(model: str, d: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Start values from the data of one incidence: d = |β − β0| and f = BSDF on the usable points."""
    far = d > max(0.3, np.quantile(d, 0.5))
    base = float(np.median(f[far])) if far.any() else float(np.min(f))
    rho = float(np.clip(np.pi * base, 1e-4, 0.999))
    peak_idx = int(np.argmin(d))
    peak = float(np.max(f[d <= d[peak_idx] + 1e-9]))
    excess = f - rho / np.pi
    amp = max(peak - rho / np.pi, 1e-3 * max(peak, 1e-12))
    # Half-width of the peak above the diffuse base → σ of a Gaussian (HWHM = 1.1774σ).
    above = excess >= 0.5 * amp
    hw = float(np.max(d[above])) if above.any() else 0.05
    sigma = float(np.clip(hw / 1.1774 if hw > 0 else 0.05, 5e-3, 0.5))
    if model == "lambert":
        return np.array([rho])
    if model == "lambert+gaussian":
        return np.array([rho, amp, sigma])
    g = 1.5
    B = max((1.1774 * sigma) ** g, 1e-8)
    if model == "abg":
        pk = max(peak, 1e-12)
        return np.array([pk * B, B, g])
    return np.array([rho, amp * B, B, g])


def _profile_field(profile: xr.Dataset, name: str) -> np.ndarray:
    if name not in profile.variables:
        raise InputError("BSDF profile lacks a required variable", field=name,
                         expected="bsdf, bsdf_std, theta_i, phi_i, theta_s, phi_s, side on dim 'record'")
    var = profile[name]
    if var.dims != ("record",):
        raise InputError("variable must be 1-D on dimension 'record'", field=name, got=var.dims)
    return np.asarray(var.values)


def fit_bsdf(
    profile: xr.Dataset,
    model: str = "lambert+gaussian",
    *,
    options: BsdfFitOptions | None = None,
    incidence_deg: float | None = None,
) -> xr.Dataset:
    """Fit a BSDF model to a goniometer profile, one fit per incidence angle (batched with vmap).

    Parameters
    ----------
    profile
        xarray.Dataset on dimension ``record`` with data variables ``bsdf`` and ``bsdf_std`` (sr⁻¹) and
        coordinates ``theta_i``, ``phi_i``, ``theta_s``, ``phi_s`` (degrees; source at φi = 180°, so the
        specular direction is at φs = 0) and ``side`` ('reflection' or 'transmission', one value only).
        For transmission the angles are measured from the back normal and the lobe sits on the direct
        (straight-through) direction, which has the same β0 = (sin θi, 0). A source at another φi is
        handled by rotating φs by φi − 180°.
    model
        'lambert+gaussian' (ρ, A, σ), 'abg' (A, B, g), 'lambert+abg' (ρ, A, B, g) or 'lambert' (ρ),
        see :mod:`bsdfkit.models.functions`.
    options
        :class:`BsdfFitOptions`: default masks θs > 85° and bsdf < 3·bsdf_std; log residuals weighted by
        bsdf_std/bsdf.
    incidence_deg
        Fit only the records at this incidence angle [deg].

    Returns
    -------
    xarray.Dataset over ``theta_i`` (degrees) with each parameter and its ``_std``, ``r2``, ``rms``,
    ``converged``, ``iterations``, ``n_points`` and ``tis``: the model's total integrated scatter over
    the hemisphere (exact numerical integral of the lobe clipped by the unit disk), ``tis_std``, and the verdict
    of the plausibility gate (:mod:`bsdfkit.fit.plausibility`): ``physically_possible``, ``determined``,
    ``plausible`` and the JSON list of reasons ``attrs['warnings']``. ``attrs['model']`` is the model fitted,
    ``attrs['model_requested']`` the one asked for and ``attrs['fallback_reason']`` why they differ ("" when they do
    not): a lobe model falls back to its diffuse part (:data:`FALLBACK_MODELS`) when at every incidence the data do
    not determine the lobe (JᵀJ singular or ill-conditioned, amplitude at 0 or below :data:`LOBE_AMPLITUDE_K`
    standard errors, or no convergence) *and* the lobe does not fit them significantly better (F-test at
    :data:`LOBE_SIGNIFICANCE`); ``options.fallback = False`` turns this off.

    Raises
    ------
    InputError
        The profile lacks a variable, holds non-finite values or more than one side, or an angle is out of range.
    FitError
        Too few usable points, a model not finite at its start, or a lobe the data show but do not determine (the
        message names the incidence and the cause).
    """
    options = options or BsdfFitOptions()
    bsdf_model(model)  # an unknown model is refused before the data are read
    fields, side = _profile_fields(profile)
    ti_all = np.round(fields["theta_i"], 6)
    incidences = np.unique(ti_all)
    if incidence_deg is not None:
        sel = np.isclose(incidences, incidence_deg, atol=1e-6)
        if not sel.any():
            raise InputError("no records at the requested incidence", field="incidence",
                             expected=f"one of {incidences.tolist()}", got=incidence_deg)
        incidences = incidences[sel]
    groups = [np.flatnonzero(ti_all == t) for t in incidences]
    geometry = ("detector_distance_mm", "aperture_diameter_mm")
    # tables from other instruments may not state the geometry (NaN): then the point model is fitted
    with_aperture = options.aperture and all(
        k in profile.attrs and math.isfinite(float(profile.attrs[k])) for k in geometry)

    def run(name: str, fit_options: FitOptions) -> xr.Dataset:
        x, f, s, m, p0 = _incidence_batch(fields, groups, incidences, name, options)
        function = bsdf_model(name).function
        if with_aperture:
            x.update(_aperture_nodes(profile, x["theta_s"], x["phi_s"]))
            function = _APERTURE_FUNCTIONS[name]
        out = least_squares(function, x, f, p0, bsdf_model(name).parameters, sigma=s, mask=m, options=fit_options,
                            batch_dim="theta_i", batch_labels=[f"incidence {t:g}°" for t in incidences],
                            model_name=name)
        return out.assign_coords(theta_i=("theta_i", incidences.astype(float), {"units": "degree"}))

    target = FALLBACK_MODELS.get(model) if options.fallback else None
    if target is None:
        ds, used, reason = run(model, options.fit), model, ""
    else:  # singular fits reported, not raised: an absent lobe is told from a failed fit by _lobe_or_fallback
        ds = run(model, dataclasses.replace(options.fit, on_singular="report"))
        ds, used, reason = _lobe_or_fallback(ds, model, target, lambda: run(target, options.fit))
    spec = bsdf_model(used)
    tis = spec.total_integrated_scatter({p.name: np.atleast_1d(ds[p.name].values) for p in spec.parameters},
                                        incidences.astype(float))
    ds["tis"] = ("theta_i", tis, {"long_name": "total integrated scatter of the fitted model "
                                                            "(hemisphere, lobe clipped by the unit disk)"})
    ds.attrs["model_requested"] = model
    ds.attrs["model_used"] = used
    ds.attrs["fallback_reason"] = reason
    ds.attrs["side"] = side
    ds.attrs["max_theta_s_deg"] = options.max_theta_s_deg
    ds.attrs["noise_floor_k"] = options.noise_floor_k
    ds.attrs["specular_core_deg"] = options.specular_core_deg
    ds.attrs["aperture_averaged"] = int(with_aperture)
    common = float(profile.attrs.get("common_relative_std", 0.0))
    if common > 0:
        # A common scale error of the data (the reference beam) moves every amplitude-like parameter by the
        # same fraction; shape parameters (σ, B, g) are scale-free. Add it to their standard errors.
        for name in ("rho", "A"):
            if name in ds and f"{name}_std" in ds:
                ds[f"{name}_std"] = np.hypot(ds[f"{name}_std"], common * np.abs(ds[name]))
        ds.attrs["common_relative_std"] = common
    return _with_plausibility(ds, used, incidences.astype(float))


def _lobe_undetermined(fit: xr.Dataset, problem: np.ndarray) -> list[str]:
    """Why the data do not determine the lobe at each incidence of a lobe model's ``fit`` ("" where they do): a
    singular or ill-conditioned JᵀJ (``problem``), an amplitude A at its bound 0 or within
    :data:`LOBE_AMPLITUDE_K` standard errors of it, or a fit that did not converge."""
    amp, amp_std = np.atleast_1d(fit["A"].values), np.atleast_1d(fit["A_std"].values)
    param_a = next(p for p in bsdf_model(str(fit.attrs["model"])).parameters if p.name == "A")
    out = []
    for b in range(amp.size):
        if problem[b]:
            out.append("singular JᵀJ" if "singular" in problem[b] else "non-finite parameters")
        elif bool(plausibility.at_bound(amp[b], param_a)):
            out.append("A at its bound 0")
        elif not (np.isfinite(amp_std[b]) and amp[b] >= LOBE_AMPLITUDE_K * amp_std[b]):
            out.append(f"A = {amp[b]:.3g} ± {amp_std[b]:.2g} consistent with 0")
        elif not bool(np.atleast_1d(fit["converged"].values)[b]):
            out.append("not converged")
        else:
            out.append("")
    return out


def _lobe_p_value(full: xr.Dataset, diffuse: xr.Dataset) -> np.ndarray:
    """p-value [1] of the F-test of the lobe at each incidence: the probability that a lobe-free sample lowers the
    weighted residual sum of squares by as much as the lobe model's extra parameters did, F = ((S₀ − S₁)/Δp) /
    (S₁/(n − p₁)) with S₀, S₁ the sums of the diffuse and lobe fits. 1 where the diffuse fit reproduces the data
    (nothing left to explain), 0 where the lobe fit is exact and the diffuse one is not, NaN where the lobe fit has
    no finite cost (the test cannot be made)."""
    from scipy.special import fdtrc  # F distribution's survival function; scipy is imported only on this path

    s1 = 2.0 * np.atleast_1d(full["cost"].values)
    s0 = 2.0 * np.atleast_1d(diffuse["cost"].values)
    dfn = full.sizes["parameter"] - diffuse.sizes["parameter"]
    dfd = np.atleast_1d(full["dof"].values).astype(float)
    exact0 = np.atleast_1d(diffuse["r2"].values) >= 1.0 - plausibility.EXACT_R2
    with np.errstate(divide="ignore", invalid="ignore"):
        stat = np.maximum(s0 - s1, 0.0) / dfn / (s1 / dfd)
        p = np.where(s1 > 0, fdtrc(dfn, dfd, np.where(np.isfinite(stat), stat, 0.0)), np.where(s0 > 0, 0.0, 1.0))
    return np.where(exact0, 1.0, np.where(np.isfinite(s1), p, np.nan))


def _lobe_or_fallback(full: xr.Dataset, model: str, target: str,
                      fit_target: Callable[[], xr.Dataset]) -> tuple[xr.Dataset, str, str]:
    """The lobe model's ``full`` fit (singular fits reported in ``problem``), or the fit of its diffuse part
    ``target`` when the data determine the lobe at no incidence and the lobe is not significant at any; with the
    model used and the reason. FitError (one line, naming incidence and cause) for a fit that is singular while
    the lobe is real, or where only some incidences lack a lobe."""
    problem = np.atleast_1d(full["problem"].values).astype(str)
    full = full.drop_vars("problem")
    why = _lobe_undetermined(full, problem)
    if not any(why):
        return full, model, ""
    diffuse = fit_target()
    p = _lobe_p_value(full, diffuse)
    absent = np.array([bool(w) for w in why]) & (p >= LOBE_SIGNIFICANCE)
    where = [f"{t:g}°" for t in np.atleast_1d(full["theta_i"].values)]
    if absent.all():
        causes: dict[str, list[str]] = {}
        for w, t in zip(why, where):
            causes.setdefault(w if "consistent" not in w else "A consistent with 0", []).append(t)
        listed = "; ".join(f"{c} at {', '.join(ts) if len(ts) <= 6 else f'{len(ts)} incidences'}"
                           for c, ts in causes.items())
        reason = (f"{model} fell back to {target}: the data do not determine the lobe at any incidence ({listed}) "
                  f"and it does not fit them significantly better (F-test p ≥ {LOBE_SIGNIFICANCE:g} everywhere, "
                  f"lowest p = {np.nanmin(p):.2g})")
        return diffuse, target, reason
    bad = [b for b in range(problem.size) if problem[b]]
    if not bad:
        return full, model, ""  # a lobe everywhere or undetermined only in its standard errors: the gate judges it
    b = bad[0]
    at, cause = problem[b].split(": ", 1) if problem[b].startswith("incidence ") else ("", problem[b])
    at = f"{at}: " if at else ""
    if absent[b]:
        raise FitError(f"{at}no lobe at {', '.join(t for t, a in zip(where, absent) if a)} ({cause}) but a real one "
                       f"at {', '.join(t for t, a in zip(where, absent) if not a)}, so {target} cannot replace "
                       f"{model} for the whole scan: fit the incidences separately (--incidence) or choose the "
                       "model (--model)")
    if not np.isfinite(p[b]):
        raise FitError(f"{at}the {model} fit failed ({cause}) and has no finite residuals, so whether the data hold "
                       f"a lobe cannot be tested: no fallback to {target}")
    raise FitError(f"{at}the data hold a lobe ({model} fits them better than {target}: F-test p = {p[b]:.2g} < "
                   f"{LOBE_SIGNIFICANCE:g}) but do not determine its parameters ({cause})")


def _profile_fields(profile: xr.Dataset) -> tuple[dict[str, np.ndarray], str]:
    """The record variables of a profile (angles in degrees, as float) and its side, checked: finite, one side,
    positive uncertainties, not all zero, angles in range."""
    names = ("bsdf", "bsdf_std", "theta_i", "phi_i", "theta_s", "phi_s", "side")
    fields = {n: _profile_field(profile, n) for n in names}
    sides = np.unique(fields["side"].astype(str))
    if sides.size != 1 or sides[0] not in SIDES:
        raise InputError("fit one side at a time", field="side", expected="a single 'reflection' or "
                         "'transmission'", got=sides.tolist())
    # messages name the scan and, where the records came from a text file, its line
    source = str(profile.attrs.get("source", "")) or None
    lines = np.asarray(profile["source_line"].values) if "source_line" in profile.coords else None

    def at(k: int) -> str:
        return f"record {k}" + (f" (line {int(lines[k])})" if lines is not None and lines.size > k and lines[k] > 0
                                else "")

    for n in names[:6]:
        arr = fields[n].astype(float)
        bad = ~np.isfinite(arr)
        if bad.any():
            raise InputError("value is not finite", file=source, field=f"{n} of {at(int(np.argmax(bad)))}",
                             got=float(arr[bad][0]))
        fields[n] = arr
    if fields["bsdf"].size and np.all(fields["bsdf"] == 0):
        raise InputError("every BSDF value is 0 (an all-zero table: no scatter to fit)", file=source,
                         field="bsdf", expected="values > 0 where the sample scatters",
                         got=f"0 on all {fields['bsdf'].size} records")
    if np.any(fields["bsdf_std"] <= 0):
        k = int(np.argmax(fields["bsdf_std"] <= 0))
        raise InputError("standard uncertainty must be > 0", file=source, field=f"bsdf_std of {at(k)}",
                         expected="> 0 1/sr", got=float(fields["bsdf_std"][k]))
    if np.any((fields["theta_s"] < 0) | (fields["theta_s"] > 90)):
        k = int(np.argmax((fields["theta_s"] < 0) | (fields["theta_s"] > 90)))
        raise InputError("scatter polar angle out of range", field=f"theta_s[record={k}]",
                         expected="0..90 degrees", got=float(fields["theta_s"][k]))
    if np.any((fields["theta_i"] < 0) | (fields["theta_i"] >= 90)):
        k = int(np.argmax((fields["theta_i"] < 0) | (fields["theta_i"] >= 90)))
        raise InputError("incidence angle out of range", field=f"theta_i[record={k}]",
                         expected="0..<90 degrees", got=float(fields["theta_i"][k]))
    return fields, str(sides[0])


def _incidence_batch(fields: dict[str, np.ndarray], groups: list[np.ndarray], incidences: np.ndarray, model: str,
                     options: BsdfFitOptions):
    """One fit per incidence (the records of ``groups``): angles in radians (source at φi = 180°), BSDF,
    uncertainty, the mask of usable points and start values, padded to the longest group."""
    n_par = len(bsdf_model(model).parameters)
    shape = (len(groups), max(g.size for g in groups))
    f = np.ones(shape)
    s = np.ones(shape)
    ti = np.zeros(shape)
    ts = np.zeros(shape)
    ps = np.zeros(shape)
    m = np.zeros(shape, bool)
    p0 = np.zeros((len(groups), n_par))
    for b, idx in enumerate(groups):
        k = idx.size
        f[b, :k] = fields["bsdf"][idx]
        s[b, :k] = fields["bsdf_std"][idx]
        ti[b, :k] = np.radians(fields["theta_i"][idx])
        ts[b, :k] = np.radians(fields["theta_s"][idx])
        # Rotate so that the source is at φi = 180° (specular at φs = 0).
        ps[b, :k] = np.radians(fields["phi_s"][idx] - (fields["phi_i"][idx] - 180.0))
        use = (fields["theta_s"][idx] <= options.max_theta_s_deg)
        use &= f[b, :k] >= options.noise_floor_k * s[b, :k]
        # |β − β0| for the start values (NumPy: same formula as models.delta_beta, no JAX dispatch).
        dbeta = np.hypot(np.sin(ts[b, :k]) * np.cos(ps[b, :k]) - np.sin(ti[b, :k]),
                         np.sin(ts[b, :k]) * np.sin(ps[b, :k]))
        if options.specular_core_deg > 0:
            # Angle between the scatter and the specular direction, from the 3-D unit vectors.
            sx, sz = np.sin(ts[b, :k]) * np.cos(ps[b, :k]), np.cos(ts[b, :k])
            cos_dev = sx * np.sin(ti[b, :k]) + sz * np.cos(ti[b, :k])
            use &= np.degrees(np.arccos(np.clip(cos_dev, -1, 1))) > options.specular_core_deg
        m[b, :k] = use
        if use.sum() <= n_par:
            # name the data's own fault where there is one: a BSDF mostly at or below 0 is no scatter to fit (a
            # physical impossibility or a failed dark subtraction), not a numerical problem of the fit
            negative = int(np.sum(f[b, :k] <= 0))
            if 2 * negative > k:
                raise ValidationError(f"incidence {incidences[b]:g}°: {negative} of {k} BSDF values are ≤ 0: no "
                                      "scatter above the noise to fit", field="bsdf",
                                      expected="a BSDF > 0 (check the dark subtraction and the calibration)",
                                      got=f"{int(use.sum())} usable points for {n_par} parameters")
            raise FitError(f"incidence {incidences[b]:g}°: {int(use.sum())} usable points after masking "
                           f"(θs ≤ {options.max_theta_s_deg:g}°, bsdf ≥ {options.noise_floor_k:g}·bsdf_std) "
                           f"for {n_par} parameters")
        p0[b] = _initial_bsdf_parameters(model, dbeta[use], f[b, :k][use])
    return {"theta_i": ti, "theta_s": ts, "phi_s": ps}, f, s, m, p0


def _aperture_nodes(profile: xr.Dataset, ts: np.ndarray, ps: np.ndarray) -> dict[str, np.ndarray]:
    """The detector-aperture quadrature of every point (θs, φs in radians) for :func:`_aperture_average`, from the
    instrument geometry the profile states."""
    inst = Instrument(float(profile.attrs["detector_distance_mm"]), float(profile.attrs["aperture_diameter_mm"]),
                      float(profile.attrs.get("beam_diameter_mm", 1.0)))
    quad = aperture_quadrature(ts, ps, inst)
    d = quad.directions
    cos_nodes = np.clip(d[..., 2], 0.0, None)
    return {"theta_s_nodes": np.arccos(np.clip(d[..., 2], -1.0, 1.0)), "phi_s_nodes": np.arctan2(d[..., 1], d[..., 0]),
            "weight": quad.weights * cos_nodes / (inst.solid_angle_sr * np.cos(ts)[..., None])}


def _with_plausibility(ds: xr.Dataset, model: str, theta_i_deg: np.ndarray) -> xr.Dataset:
    """The model TIS's standard uncertainty ``tis_std`` and the verdict of the plausibility gate
    (:mod:`bsdfkit.fit.plausibility`: ``physically_possible``, ``determined``, ``plausible`` and the reasons in
    ``attrs['warnings']``); exports refuse a fit that fails the gate."""
    values = np.stack([np.atleast_1d(ds[n].values).astype(float) for n in bsdf_model(model).parameter_names], axis=-1)
    ds["tis_std"] = ("theta_i", plausibility.tis_std(model, theta_i_deg, values, ds["covariance"].values),
                     {"long_name": "standard uncertainty of the model TIS (from the parameter covariance)"})
    return plausibility.annotate(ds)
