"""Benchmark (not a test): N split-Gaussian spectrum fits, batched bsdfkit solvers vs a scipy loop.

    .venv/bin/python benchmarks/bench_fit.py [--n 1000] [--repeats 3] [--no-jaxopt]

Every solver solves the same problems: eq. (3) of the cylindrical-module paper (split Gaussian with
amplitude) on a 380-780 nm, 1 nm grid, 1 % noise, in the same unconstrained variables (logit peak and α,
log FWHM and amplitude), from the same data-derived start (argmax, half-maximum crossings), with relative
step tolerance 1e-10 and gradient tolerance 1e-10. Timed, all in this one process:

* ``lm``: :func:`bsdfkit.fit.least_squares.least_squares` with ``solver='lm'`` (:mod:`bsdfkit.fit.lm`: one compiled
  ``jit(vmap(jacfwd))`` kernel, host-driven Levenberg–Marquardt), float64, *including compilation*: the JAX
  caches are cleared before every repeat. Then the same call again with the kernel compiled (steady state),
  and, separately, the kernel's tracing + lowering and XLA compile alone (caches cleared first).
* ``jaxopt``: the same entry point with ``solver='jaxopt'`` (jaxopt LevenbergMarquardt under
  ``jit(vmap(...))``), including compilation (caches cleared). Skipped with ``--no-jaxopt``.
* scipy: a Python loop of :func:`scipy.optimize.least_squares` (method 'lm', MINPACK; 2-point Jacobian,
  xtol = gtol = ftol = 1e-10) on a NumPy version of the model.

Prints the times, the medians over the repeats, the ratios of the medians, and the agreement of the
solutions (bsdfkit solvers vs scipy, and vs the truth).
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import jax
import numpy as np
import scipy.optimize

from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import least_squares as fit
from bsdfkit.fit import spectrum as spectra

C = 4.0 * math.log(2.0)
NAMES = ["peak_nm", "fwhm_nm", "alpha", "amplitude"]


def make_spectra(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    wl = np.arange(380.0, 781.0)
    peak = rng.uniform(440.0, 620.0, n)
    fwhm = rng.uniform(20.0, 160.0, n)
    alpha = rng.uniform(-0.4, 0.4, n)
    off = wl[None, :] - peak[:, None]
    width = fwhm[:, None] * (1.0 + np.sign(off) * alpha[:, None])
    y = np.exp(-C * (off / width) ** 2) + 0.01 * rng.standard_normal((n, wl.size))
    truth = np.stack([peak, fwhm, alpha, np.ones(n)], axis=1)
    return wl, y, truth


def start_values(wl: np.ndarray, y: np.ndarray) -> np.ndarray:
    rows = [spectra._peak_and_fwhm(wl, row / row.max(), np.ones(wl.size, bool)) for row in y]
    return np.array([[p, w, 0.0, a * row.max()] for (p, w, a), row in zip(rows, y)])


def run_bsdfkit(wl, y, p0, params, solver: str):
    return fit.least_squares(spectra._split_gaussian, wl, y, p0, params, batch_dim="spectrum",
                             options=fit.FitOptions(xtol=1e-10, gtol=1e-10, solver=solver))


def numpy_model(theta, wl):
    peak, fwhm, alpha, amp = theta
    off = wl - peak
    width = fwhm * (1.0 + np.sign(off) * alpha)
    return amp * np.exp(-C * (off / width) ** 2)


def run_scipy(wl, y, p0, params):
    lo_p, hi_p = params[0].lower, params[0].upper

    def natural(u):
        return np.array([lo_p + (hi_p - lo_p) / (1.0 + math.exp(-u[0])), math.exp(u[1]),
                         -1.0 + 2.0 / (1.0 + math.exp(-u[2])), math.exp(u[3])])

    u0 = fit._to_unconstrained(p0, params)
    out = np.empty_like(p0)
    for i in range(y.shape[0]):
        res = scipy.optimize.least_squares(lambda u, row=y[i]: numpy_model(natural(u), wl) - row, u0[i],
                                           method="lm", xtol=1e-10, gtol=1e-10, ftol=1e-10)
        out[i] = natural(res.x)
    return out


def kernel_compile_time(wl, y, p0, params) -> tuple[float, float]:
    """Tracing + lowering, and XLA compilation, of the lm kernel least_squares builds for this problem."""
    n_batch, n = y.shape
    chunk, n_pad = min(fit._bucket(n_batch), fit._LM_CHUNK), fit._bucket(n)
    with x64():
        args = (np.full((chunk, len(params)), 1.0), np.ones((chunk, len(params))), np.zeros((chunk, n_pad)),
                np.zeros((chunk, n_pad)),
                np.zeros((chunk, n_pad)), np.zeros((chunk, n_pad), bool))
        jax.clear_caches()
        t0 = time.perf_counter()
        lowered = fit._lm_kernel.lower(*args, model=spectra._split_gaussian, options=fit.FitOptions())
        t1 = time.perf_counter()
        lowered.compile()
        t2 = time.perf_counter()
    return t1 - t0, t2 - t1


def solution(ds) -> np.ndarray:
    return np.stack([ds[name].values for name in NAMES], axis=1)


def fmt(times: list[float]) -> str:
    return ", ".join(f"{t:.3f}" for t in times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-jaxopt", action="store_true", help="skip the jaxopt solver")
    args = parser.parse_args()

    wl, y, truth = make_spectra(args.n)
    params = spectra._parameters("split-gaussian", float(wl[0]), float(wl[-1]))
    p0 = start_values(wl, y)

    times: dict[str, list[float]] = {"lm": [], "lm_steady": [], "jaxopt": [], "scipy": [], "trace": [],
                                     "compile": []}
    for _ in range(args.repeats):
        jax.clear_caches()  # include tracing + XLA compilation in every repeat
        t0 = time.perf_counter()
        ds_lm = run_bsdfkit(wl, y, p0, params, "lm")
        times["lm"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        run_bsdfkit(wl, y, p0, params, "lm")  # kernel compiled: steady state
        times["lm_steady"].append(time.perf_counter() - t0)
        if not args.no_jaxopt:
            jax.clear_caches()
            t0 = time.perf_counter()
            ds_jo = run_bsdfkit(wl, y, p0, params, "jaxopt")
            times["jaxopt"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ref = run_scipy(wl, y, p0, params)
        times["scipy"].append(time.perf_counter() - t0)
        trace, comp = kernel_compile_time(wl, y, p0, params)
        times["trace"].append(trace)
        times["compile"].append(comp)

    med = {k: statistics.median(v) for k, v in times.items() if v}
    it = ds_lm.iterations.values
    print(f"{args.n} split-Gaussian fits, 401 points each, {args.repeats} repeats (median; all repeats in brackets)")
    print(f"  bsdfkit lm, compile included:           {med['lm']:.3f} s  ({fmt(times['lm'])})")
    print(f"  bsdfkit lm, steady state (compiled):    {med['lm_steady']:.3f} s  ({fmt(times['lm_steady'])})")
    print(f"    lm kernel trace + lower alone:        {med['trace']:.3f} s  ({fmt(times['trace'])})")
    print(f"    lm kernel XLA compile alone:          {med['compile']:.3f} s  ({fmt(times['compile'])})")
    if not args.no_jaxopt:
        print(f"  bsdfkit jaxopt, compile included:       {med['jaxopt']:.3f} s  ({fmt(times['jaxopt'])})")
    print(f"  scipy.optimize.least_squares loop (lm): {med['scipy']:.3f} s  ({fmt(times['scipy'])})")
    print(f"  ratio scipy / lm incl. compile:  {med['scipy'] / med['lm']:.2f}x")
    print(f"  ratio scipy / lm steady state:   {med['scipy'] / med['lm_steady']:.2f}x")
    print(f"  bound incl. compile, scipy / (trace + compile of the kernel alone): "
          f"{med['scipy'] / (med['trace'] + med['compile']):.2f}x")
    if not args.no_jaxopt:
        print(f"  ratio scipy / jaxopt incl. compile: {med['scipy'] / med['jaxopt']:.2f}x")
    print(f"  lm: converged {int(ds_lm.converged.sum())}/{args.n}; iterations median {np.median(it):.0f}, "
          f"max {it.max()}, mean {it.mean():.1f}")
    got = solution(ds_lm)
    diff = np.abs(got - ref)
    print("  max |lm − scipy|:     " + ", ".join(f"{n} {d:.2e}" for n, d in zip(NAMES, diff.max(axis=0))))
    if not args.no_jaxopt:
        print(f"  jaxopt: converged {int(ds_jo.converged.sum())}/{args.n}")
        diff = np.abs(solution(ds_jo) - ref)
        print("  max |jaxopt − scipy|: " + ", ".join(f"{n} {d:.2e}" for n, d in zip(NAMES, diff.max(axis=0))))
    err = np.abs(got - truth)
    print("  median |lm − truth|:  " + ", ".join(f"{n} {d:.2e}" for n, d in zip(NAMES, np.median(err, axis=0))))


if __name__ == "__main__":
    main()
