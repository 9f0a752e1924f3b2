"""Compact batched Levenberg–Marquardt for many small least-squares problems (few parameters each).

The solver is written for the case bsdfkit meets everywhere: hundreds to tens of thousands of independent
fits, each with a handful of parameters (p ≤ ~8) and a few hundred data points, where the problems share a
model and differ only in their data. Each iteration it needs, for every fit still running, the cost, the
gradient and the Gauss–Newton matrix at one trial point; those come from a caller-supplied *linearisation*
function. In bsdfkit that function is a single compiled JAX kernel (``jax.jit(jax.vmap(...))`` of the
residuals and their forward-mode Jacobian, :func:`jacobian_products`); everything else — the damped normal
equations, accepting or rejecting the step, the damping update and the convergence tests — runs in NumPy on
arrays of shape (fits, p) and (fits, p, p).

Why the iteration is not a ``lax.while_loop``
---------------------------------------------
A batch of ~1000 fits runs for ~15 iterations, so the compiled program's *build* time (tracing, lowering,
XLA compilation) matters as much as its run time. XLA's CPU compile time is dominated by LLVM code
generation and grows with the number of kernels in the program. With the whole iteration inside one
compiled ``while_loop`` (small matrix algebra, selects on every state array, convergence flags), the LM
bookkeeping adds ~40 kernels around the one that matters, the model and its Jacobian: for 1000
split-Gaussian fits, a prototype of that design took 0.24 s to trace and lower and 0.55–0.75 s to compile,
against 0.10 s and 0.09 s for the kernel alone, and ran no faster (0.13–0.15 s). Driving the iteration
from the host costs a few milliseconds of NumPy per iteration instead, and lets each iteration evaluate
only the fits still running, in fixed-size chunks so that one compilation serves every call.
docs/fitting.md §8 has the measurements.

Algorithm (per fit; all fits advance together, each with its own state)
------------------------------------------------------------------------
Minimise F(u) = ½‖r(u)‖² over unconstrained parameters u ∈ ℝᵖ (Levenberg 1944; Marquardt 1963,
J. Soc. Indust. Appl. Math. 11, 431; in the form of Moré 1978, "The Levenberg–Marquardt algorithm:
implementation and theory", Lecture Notes in Mathematics 630, 105).

* The residuals are divided by their norm at the start point, so the cost starts at ½ and the gradient
  tolerance is relative to the initial misfit (the convention of :mod:`bsdfkit.fit.least_squares`).
* With g = Jᵀr and A = JᵀJ at the current point, the step δ solves the damped normal equations
  (A + λ·D)δ = −g with D = diag(A) (Marquardt's scaling, which makes the step invariant to the scale of
  each parameter; entries below 10⁻¹² of the largest are raised to that floor so that a parameter without
  influence cannot make the system singular). The p × p system is solved by Cholesky factorisation of the
  Jacobi-equilibrated matrix. (Moré's alternative, the running maximum of diag(A) over the iterations,
  was tried: when the start is far off it keeps the damping large relative to the final curvature and
  turns the last, quadratically convergent Gauss–Newton steps into linear ones.)
* Gain ratio ρ = (F(u) − F(u + δ)) / (L(0) − L(δ)) with the predicted decrease
  L(0) − L(δ) = −gᵀδ − ½δᵀAδ. The step is accepted if ρ > 10⁻⁴ (Moré 1978) and the new cost, gradient and
  JᵀJ are finite.
* Damping (Nielsen 1999, IMM-REP-1999-05; Madsen, Nielsen & Tingleff 2004, "Methods for non-linear least
  squares problems", §3.2): λ₀ = 10⁻³; accepted: λ ← λ·max(⅓, 1 − (2ρ − 1)³), ν ← 2; rejected:
  λ ← λ·ν, ν ← 2ν (capped so they stay finite).
* Stop when ‖g‖∞ ≤ gtol at the current point, or when the step just computed (accepted or not) satisfies
  ‖δ‖₂ ≤ xtol·(‖u‖₂ + xtol) — the Madsen–Nielsen rule; a fit that does neither within ``maxiter`` steps is
  returned with ``converged = False``. A step whose linear solve fails (not finite) counts as a rejected
  step. ``iterations`` counts the steps tried, accepted or not.

Each fit's arithmetic is row-wise (NumPy batched over fits, the kernel vmapped over fits), so a fit's result
does not depend on the other members of its batch; only the set of rows evaluated together changes.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from bsdfkit.core.errors import ValidationError

__all__ = [
    "COMPILER_OPTIONS",
    "SMALL_KERNEL_OPTIONS",
    "SMALL_KERNEL_POINTS",
    "Linearization",
    "LMResult",
    "jacobian_products",
    "levenberg_marquardt",
]

#: Per-function XLA options for compiled linearisation kernels (``jax.jit(..., compiler_options=...)``;
#: never global flags). XLA's newer CPU fusion emitters cost compile time without making these small
#: elementwise-plus-reduction kernels faster: measured on the split-Gaussian kernel (256 fits × 448 points)
#: 0.12 s → 0.085 s to compile, 1.8 ms per call either way.
COMPILER_OPTIONS: dict[str, Any] = {"xla_cpu_use_fusion_emitters": False}

#: Options for kernels of at most :data:`SMALL_KERNEL_POINTS` points per call (fits × padded length): no LLVM
#: optimisation. That build compiles in a third of the time (0.035 s instead of 0.10 s) and runs ~5× slower
#: (~80 ns more per point and evaluation), which pays while a whole solve needs fewer than ~800 000 point
#: evaluations; 16 384 points per call × ~20 calls stays well below.
SMALL_KERNEL_OPTIONS: dict[str, Any] = {**COMPILER_OPTIONS, "xla_backend_optimization_level": 0}
SMALL_KERNEL_POINTS = 16384

_LAMBDA_0 = 1e-3
_LAMBDA_MIN = 1e-20
_LAMBDA_MAX = 1e16
_NU_MAX = 2.0**40
_ACCEPT_RHO = 1e-4
_TINY = 1e-300
_DIAG_FLOOR = 1e-12


class Linearization(NamedTuple):
    """What the caller's linearisation returns for k rows (trial points): NumPy arrays, leading axis k.

    cost: ½Σr² (k,); grad: Jᵀr (k, p); jtj: JᵀJ (k, p, p), all with respect to the solver's variables u and
    *not* normalised; extra: any pytree of per-row arrays (e.g. natural parameters, fitted values) that the
    solver keeps for the accepted point of each fit and returns with the result.
    """

    cost: np.ndarray
    grad: np.ndarray
    jtj: np.ndarray
    extra: Any


class LMResult(NamedTuple):
    """Per fit (leading axis = fits): solution ``u``, ``cost`` ½Σr² there (not normalised),
    ``initial_cost`` at the start point, ``iterations`` (steps tried), ``converged`` (a stopping rule was
    met), ``jtj`` JᵀJ at the solution (with respect to u, not normalised) and ``extra`` as returned by the
    linearisation at the solution."""

    u: np.ndarray
    cost: np.ndarray
    initial_cost: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    jtj: np.ndarray
    extra: Any


def jacobian_products(residuals: Callable[[jax.Array], tuple[jax.Array, Any]], theta: jax.Array
                      ) -> tuple[jax.Array, jax.Array, jax.Array, Any]:
    """For *one* fit: (½Σr², Jᵀr, JᵀJ, aux) at θ, with J = ∂r/∂θ by forward mode (``jax.jacfwd``).

    ``residuals(θ) -> (r, aux)``; the residuals and ``aux`` come from the same primal evaluation as the p
    Jacobian columns (one pass, vectorised over the tangents). Use it inside ``jax.vmap`` to build the
    linearisation kernel of a batch.

    Parameters
    ----------
    residuals : callable
        θ → (r, aux): the residual vector (in the units it is weighted to) and any auxiliary output.
    theta : jax.Array
        Parameter vector θ of the fit (not an angle) [each parameter's own unit].

    Returns
    -------
    cost : jax.Array
        ½Σr².
    jtr : jax.Array
        Jᵀr.
    jtj : jax.Array
        JᵀJ.
    aux : object
        The auxiliary output of ``residuals``.
    """
    jac, (r, aux) = jax.jacfwd(lambda t: _with_copy(residuals(t)), has_aux=True)(theta)
    return 0.5 * jnp.sum(r * r), jac.T @ r, jac.T @ jac, aux


def _with_copy(out: tuple[jax.Array, Any]) -> tuple[jax.Array, tuple[jax.Array, Any]]:
    return out[0], out


def _check(name: str, ok: bool, expected: str, got: object) -> None:
    if not ok:
        raise ValidationError("invalid Levenberg–Marquardt argument", field=name, expected=expected, got=got)


def _solve_damped(a: np.ndarray, g: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """δ with (A + λ·D)δ = −g, D = diag(A) floored, for each row; rows whose system is not positive
    definite give NaN.

    The matrix is Jacobi-equilibrated (unit diagonal) before the Cholesky factorisation, which makes the
    factorisation insensitive to the parameters' scales.
    """
    k, p = g.shape
    m = a.copy()
    idx = np.arange(p)
    d = np.diagonal(a, axis1=1, axis2=2)
    d = np.maximum(d, _DIAG_FLOOR * np.max(d, axis=1, keepdims=True))
    m[:, idx, idx] += lam[:, None] * d
    diag = m[:, idx, idx]
    good = np.all(diag > 0, axis=1) & np.all(np.isfinite(m), axis=(1, 2))
    s = 1.0 / np.sqrt(np.where(good[:, None], diag, 1.0))
    mh = np.where(good[:, None, None], m * s[:, :, None] * s[:, None, :], np.eye(p))
    rhs = -g * s
    step = np.full((k, p), np.nan)
    try:
        chol = np.linalg.cholesky(mh)
        ok = good
    except np.linalg.LinAlgError:  # some row is not numerically positive definite: factor row by row
        chol = np.zeros_like(mh)
        ok = good.copy()
        for i in range(k):
            try:
                chol[i] = np.linalg.cholesky(mh[i])
            except np.linalg.LinAlgError:
                ok[i] = False
                chol[i] = np.eye(p)
    z = np.linalg.solve(chol, rhs[:, :, None])
    x = np.linalg.solve(np.swapaxes(chol, 1, 2), z)[:, :, 0]
    step[ok] = (x * s)[ok]
    return step


def levenberg_marquardt(
    linearize: Callable[[np.ndarray, np.ndarray], Linearization],
    u0: np.ndarray,
    *,
    xtol: float = 1e-10,
    gtol: float = 1e-10,
    maxiter: int = 200,
    chunk: int | None = None,
) -> LMResult:
    """Solve many independent small nonlinear least-squares problems (algorithm in the module docstring).

    Parameters
    ----------
    linearize
        ``linearize(u, rows) -> Linearization`` for trial points ``u`` (k, p) of the fits numbered ``rows``
        (k,) (indices into the batch). With ``chunk`` set it is always called with exactly ``chunk`` rows
        (the last chunk of an iteration is padded by repeating a row, whose result is discarded), so a
        compiled kernel behind it sees one shape only.
    u0
        Start points, shape (fits, p) with at least one fit, finite.
    xtol, gtol
        Step and gradient tolerances (module docstring); ≥ 0.
    maxiter
        Maximum number of steps per fit (≥ 1).
    chunk
        Rows per call of ``linearize``; None = all fits still running, in one call.

    Returns
    -------
    :class:`LMResult`.
    """
    u0 = np.asarray(u0, dtype=float)
    _check("u0", u0.ndim == 2 and u0.shape[0] >= 1 and u0.shape[1] >= 1, "shape (fits, parameters)", u0.shape)
    _check("u0", bool(np.all(np.isfinite(u0))), "finite start points", "non-finite values")
    _check("xtol", math.isfinite(xtol) and xtol >= 0, "a finite number ≥ 0", xtol)
    _check("gtol", math.isfinite(gtol) and gtol >= 0, "a finite number ≥ 0", gtol)
    _check("maxiter", isinstance(maxiter, int) and maxiter >= 1, "a positive integer", maxiter)
    _check("chunk", chunk is None or (isinstance(chunk, int) and chunk >= 1), "None or a positive integer", chunk)
    n_fit = u0.shape[0]

    def evaluate(u: np.ndarray, rows: np.ndarray) -> Linearization:
        return _evaluate(linearize, u, rows, chunk)

    first = evaluate(u0, np.arange(n_fit))
    ok0 = _finite(first)
    two_c = 2.0 * first.cost
    big = ok0 & (two_c > _TINY)
    scale2 = np.where(big, 1.0 / np.where(big, two_c, 1.0), 1.0)  # residuals / ‖r(u0)‖, squared
    it = _Iterate(u=u0.copy(), c=scale2 * first.cost, g=scale2[:, None] * first.grad,
                  a=scale2[:, None, None] * first.jtj, cost_raw=first.cost.copy(), jtj_raw=first.jtj.copy(),
                  extra=jax.tree_util.tree_map(np.array, first.extra))  # writable copies (kernel outputs: read-only)
    lam = np.full(n_fit, _LAMBDA_0)
    nu = np.full(n_fit, 2.0)
    iterations = np.zeros(n_fit, dtype=int)
    with np.errstate(invalid="ignore"):
        converged = ok0 & (np.max(np.abs(it.g), axis=1) <= gtol)
    active = ok0 & ~converged

    while active.any():
        rows = np.flatnonzero(active)
        with np.errstate(all="ignore"):
            step = _solve_damped(it.a[rows], it.g[rows], lam[rows])
        solved = np.all(np.isfinite(step), axis=1)
        accept, rho = _try_steps(evaluate, it, rows, step, solved, scale2)
        # Damping (Nielsen): shrink after a good step, grow geometrically after rejections.
        lr, nr = lam[rows], nu[rows]
        with np.errstate(all="ignore"):  # ρ of rejected steps may be huge or NaN; only accepted ones are used
            shrink = np.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            lam[rows] = np.where(accept, np.maximum(lr * shrink, _LAMBDA_MIN), np.minimum(lr * nr, _LAMBDA_MAX))
        nu[rows] = np.where(accept, 2.0, np.minimum(2.0 * nr, _NU_MAX))
        iterations[rows] += 1
        with np.errstate(invalid="ignore"):
            g_small = np.max(np.abs(it.g[rows]), axis=1) <= gtol
            step_norm = np.sqrt(np.sum(np.where(solved[:, None], step, 0.0) ** 2, axis=1))
            x_small = solved & (step_norm <= xtol * (np.sqrt(np.sum(it.u[rows] ** 2, axis=1)) + xtol))
        converged[rows] = g_small | x_small
        active[rows] = ~converged[rows] & (iterations[rows] < maxiter)

    return LMResult(u=it.u, cost=it.cost_raw, initial_cost=first.cost.copy(), iterations=iterations,
                    converged=converged, jtj=it.jtj_raw, extra=it.extra)


@dataclass
class _Iterate:
    """The current point of every fit, updated in place where a step is accepted: ``u``, its scaled cost ``c``,
    gradient ``g`` and Gauss–Newton matrix ``a`` (residuals / ‖r(u0)‖), and the unscaled cost, JᵀJ and the
    linearisation's ``extra`` there."""

    u: np.ndarray
    c: np.ndarray
    g: np.ndarray
    a: np.ndarray
    cost_raw: np.ndarray
    jtj_raw: np.ndarray
    extra: Any


def _try_steps(evaluate: Callable[[np.ndarray, np.ndarray], Linearization], it: _Iterate, rows: np.ndarray,
               step: np.ndarray, solved: np.ndarray, scale2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate the ``solved`` steps of fits ``rows`` and move ``it`` to the trial points that lower the cost by
    more than :data:`_ACCEPT_RHO` of the predicted decrease. Returns (accepted, gain ratio ρ) per row."""
    tried = rows[solved]
    accept = np.zeros(rows.size, bool)
    rho = np.zeros(rows.size)
    if not tried.size:
        return accept, rho
    st = step[solved]
    ut = it.u[tried] + st
    lin = evaluate(ut, tried)
    s2 = scale2[tried]
    ct = s2 * lin.cost
    with np.errstate(all="ignore"):
        pred = -np.sum(it.g[tried] * st, axis=1) - 0.5 * np.einsum("ki,kij,kj->k", st, it.a[tried], st)
        r = (it.c[tried] - ct) / np.where(pred > 0, pred, 1.0)
    ok = _finite(lin) & (pred > 0) & (r > _ACCEPT_RHO)
    accept[solved] = ok
    rho[solved] = r
    acc = tried[ok]
    it.u[acc] = ut[ok]
    it.c[acc] = ct[ok]
    it.cost_raw[acc] = lin.cost[ok]
    it.g[acc] = s2[ok, None] * lin.grad[ok]
    it.a[acc] = s2[ok, None, None] * lin.jtj[ok]
    it.jtj_raw[acc] = lin.jtj[ok]

    def keep(store: np.ndarray, new: np.ndarray) -> np.ndarray:
        store[acc] = new[ok]
        return store

    it.extra = jax.tree_util.tree_map(keep, it.extra, lin.extra)
    return accept, rho


def _evaluate(linearize: Callable[[np.ndarray, np.ndarray], Linearization], u: np.ndarray, rows: np.ndarray,
              chunk: int | None) -> Linearization:
    """``linearize`` at points ``u`` of fits ``rows``, in calls of ``chunk`` rows (the last padded by repeating
    its first row, whose results are dropped), results checked in shape and concatenated."""
    k, p = rows.size, u.shape[1]
    bounds = [(0, k)] if chunk is None else [(lo, min(lo + chunk, k)) for lo in range(0, k, chunk)]
    # Call linearize for every chunk before reading any result back: a JAX kernel dispatches
    # asynchronously, so preparing the next chunk overlaps with computing the previous one.
    pending = []
    for lo, hi in bounds:
        uu, rr = u[lo:hi], rows[lo:hi]
        if chunk is not None and hi - lo < chunk:
            fill = chunk - (hi - lo)
            uu = np.concatenate([uu, np.repeat(uu[:1], fill, axis=0)])
            rr = np.concatenate([rr, np.repeat(rr[:1], fill)])
        pending.append((hi - lo, rr.size, linearize(uu, rr)))
    outs = []
    for m, q, lin in pending:
        cost, grad, jtj = (np.asarray(a, dtype=float) for a in (lin.cost, lin.grad, lin.jtj))
        _check("linearize", cost.shape == (q,) and grad.shape == (q, p) and jtj.shape == (q, p, p),
               f"cost ({q},), grad ({q}, {p}), jtj ({q}, {p}, {p})", (cost.shape, grad.shape, jtj.shape))
        cost, grad, jtj = cost[:m], grad[:m], jtj[:m]
        outs.append(Linearization(cost, grad, jtj,
                                  jax.tree_util.tree_map(lambda a, m=m: np.asarray(a)[:m], lin.extra)))
    if len(outs) == 1:
        return outs[0]
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=0), *outs)


def _finite(lin: Linearization) -> np.ndarray:
    """Fits whose cost, gradient and JᵀJ are all finite."""
    return (np.isfinite(lin.cost) & np.all(np.isfinite(lin.grad), axis=1)
            & np.all(np.isfinite(lin.jtj), axis=(1, 2)))
