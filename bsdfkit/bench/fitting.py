"""Fitting studies: parameter error vs solver tolerance and time; batched vs one-by-one."""
from __future__ import annotations

import time

import numpy as np

from bsdfkit.bench.core import Row, Study
from bsdfkit.fit.least_squares import FitOptions
from bsdfkit.fit.spectrum import fit_spectra, fit_spectrum, spectrum_model_values

TRUTH = {"peak_nm": 596.7, "fwhm_nm": 154.3, "alpha": -0.12, "amplitude": 1.0}  # Table 2, cylindrical-module paper


def _spectra(n: int, seed: int, noise: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lam = np.arange(380.0, 781.0, 1.0)
    clean = spectrum_model_values("split-gaussian", TRUTH, lam)
    return lam, clean[None, :] + noise * rng.standard_normal((n, lam.size))


def _parameter_error(ds) -> float:
    """Largest relative deviation of peak, FWHM and (1 + α) from the truth, averaged over the batch."""
    errs = [np.abs(np.asarray(ds[k]) - TRUTH[k]) / abs(TRUTH[k]) for k in ("peak_nm", "fwhm_nm")]
    errs.append(np.abs(np.asarray(ds["alpha"]) - TRUTH["alpha"]) / (1 + TRUTH["alpha"]))
    return float(np.max(np.mean(errs, axis=1)))


def fit_tolerance(quick: bool) -> Study:
    """Split-Gaussian fits (Table 2 yellow, 0.1 % noise): error vs the solver's step tolerance (xtol = gtol).

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    lam, y = _spectra(32 if quick else 128, seed=1, noise=0.001)
    rows = []
    for tol in ((1e-2, 1e-4, 1e-8) if quick else (1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10)):
        opts = FitOptions(xtol=tol, gtol=tol)
        fit_spectra(lam, y, "split-gaussian", options=opts)  # compile (same shapes) outside the timing
        start = time.perf_counter()
        ds = fit_spectra(lam, y, "split-gaussian", options=opts)
        wall = time.perf_counter() - start
        rows.append(Row(f"xtol = gtol = {tol:g}", _parameter_error(ds), wall, float(np.mean(ds["iterations"])),
                        {"converged": float(np.mean(ds["converged"]))}))
    return Study("fit_tolerance", "Spectrum fits: parameter error vs solver tolerance (split Gaussian, 0.1 % noise)",
                 "mean over the batch of the largest relative error of peak, FWHM and 1 + α against the truth",
                 "mean iterations", tuple(rows),
                 notes="Below the statistical floor of the noise, a tighter tolerance buys nothing but iterations.")


def batched_vs_loop(quick: bool) -> Study:
    """The same fits one call per spectrum vs one batched (vmapped) call, compile included in both.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    n = 32 if quick else 200
    lam, y = _spectra(n, seed=2)
    rows = []
    start = time.perf_counter()
    loop = [fit_spectrum(lam, row, "split-gaussian") for row in y]
    wall_loop = time.perf_counter() - start
    err_loop = _parameter_error({k: np.array([float(d[k]) for d in loop]) for k in ("peak_nm", "fwhm_nm", "alpha")})
    rows.append(Row(f"loop of {n} fits", err_loop, wall_loop, n, {"group": "loop", "fits_per_s": n / wall_loop}))
    start = time.perf_counter()
    ds = fit_spectra(lam, y, "split-gaussian")
    wall = time.perf_counter() - start
    rows.append(Row(f"one batched call, {n} fits", _parameter_error(ds), wall, n,
                    {"group": "batched", "fits_per_s": n / wall}))
    return Study("fit_batch", "Spectrum fits: batched (vmap) vs a loop of single fits",
                 "mean over the fits of the largest relative error of peak, FWHM and 1 + α (1 % noise)", "fits",
                 tuple(rows), groups=("loop", "batched"),
                 notes="See docs/fitting.md for the 1000-fit benchmark against scipy.optimize.least_squares.")
