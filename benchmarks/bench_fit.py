"""Benchmark (not a test): 1000 split-Gaussian spectrum fits, batched JAX/jaxopt vs a scipy loop.

    /tmp/venv/bin/python benchmarks/bench_fit.py [--n 1000] [--repeats 3]

Both sides solve the same problem: eq. (3) of the cylindrical-module paper (split Gaussian with
amplitude) on a 380-780 nm, 1 nm grid, 1 % noise, in the same unconstrained variables (logit peak and α,
log FWHM and amplitude), from the same data-derived start (argmax, half-maximum crossings), with
relative step tolerance 1e-10 and gradient tolerance 1e-10:

* JAX: :func:`bsdfkit.fit.least_squares` — jaxopt Levenberg–Marquardt, ``jit(vmap(...))`` over the
  whole batch, float64. Timed *including compilation*: the JAX caches are cleared before every repeat.
  The steady-state time (compiled function reused) is printed too.
* scipy: a Python loop of :func:`scipy.optimize.least_squares` (method 'lm', MINPACK; 2-point
  Jacobian, xtol = gtol = ftol = 1e-10) on a NumPy version of the model.

Prints the absolute times, the median ratio over the repeats and the agreement of the solutions.
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import jax
import numpy as np
import scipy.optimize

from bsdfkit import fit, spectra

C = 4.0 * math.log(2.0)


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
    p0 = np.array([[p, w, 0.0, a * row.max()] for (p, w, a), row in zip(rows, y)])
    return p0


def run_jax(wl, y, p0, params):
    return fit.least_squares(spectra._split_gaussian, wl, y, p0, params, batch_dim="spectrum",
                             options=fit.FitOptions(xtol=1e-10, gtol=1e-10))


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    wl, y, truth = make_spectra(args.n)
    params = spectra._parameters("split-gaussian", float(wl[0]), float(wl[-1]))
    p0 = start_values(wl, y)

    jax_times, scipy_times = [], []
    for _ in range(args.repeats):
        jax.clear_caches()  # include tracing + XLA compilation in every repeat
        t0 = time.perf_counter()
        ds = run_jax(wl, y, p0, params)
        jax_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ref = run_scipy(wl, y, p0, params)
        scipy_times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    run_jax(wl, y, p0, params)  # compiled function reused
    steady = time.perf_counter() - t0

    names = ["peak_nm", "fwhm_nm", "alpha", "amplitude"]
    got = np.stack([ds[n].values for n in names], axis=1)
    jax_t, scipy_t = statistics.median(jax_times), statistics.median(scipy_times)
    print(f"{args.n} split-Gaussian fits, 401 points each, {args.repeats} repeats (median)")
    print(f"  JAX/jaxopt batched (jit+vmap, compile included): {jax_t:.2f} s   (all: "
          + ", ".join(f"{t:.2f}" for t in jax_times) + ")")
    print(f"  JAX/jaxopt batched, steady state (compiled):    {steady:.2f} s")
    print(f"  scipy.optimize.least_squares loop ('lm'):       {scipy_t:.2f} s   (all: "
          + ", ".join(f"{t:.2f}" for t in scipy_times) + ")")
    print(f"  ratio scipy/JAX incl. compile: {scipy_t / jax_t:.2f}x; steady state: {scipy_t / steady:.2f}x")
    print(f"  converged: {int(ds.converged.sum())}/{args.n}; max iterations {int(ds.iterations.max())}")
    diff = np.abs(got - ref)
    print("  max |JAX − scipy|: " + ", ".join(f"{n} {d:.2e}" for n, d in zip(names, diff.max(axis=0))))
    err = np.abs(got - truth)
    print("  median |fit − truth|: " + ", ".join(f"{n} {d:.2e}" for n, d in zip(names, np.median(err, axis=0))))


if __name__ == "__main__":
    main()
