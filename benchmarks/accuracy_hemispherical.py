"""Accuracy sweep (not a test): hemispherical reflectance/transmittance of synthetic scans with exact truth.

    .venv/bin/python benchmarks/accuracy_hemispherical.py            # noise-free grid, 2016 cases (~4 min)
    .venv/bin/python benchmarks/accuracy_hemispherical.py --noise    # 2 % and 5 % noise, 4032 values (~8 min)

Truth: a Lambertian body ρ plus a Harvey–Shack Gaussian lobe (TIS t, width σ in direction cosines), whose
hemispherical integral is exact (the truths and the goniometer plans are those of
``tests/reduction/test_hemispherical.py``).
The noise-free grid: ρ 0.3/0.8, t 0.02/0.2, σ 0.01/0.05/0.2, in-plane or two arcs, reflection or transmission,
uniform 2°, 5° or 10° steps with or without 1° steps within ±10° of specular, incidences 0-80°. The noisy grid:
reflection, 2° and 5° steps, σ 0.02/0.05/0.2, 2 % and 5 % relative noise per record, three wavelengths, two
seeds. Prints how many values are off by more than 1 % and 5 %, outside one (noise-free) or three (noisy)
standard uncertainties, and above 1 + 2σ (impossible), then the worst cases. docs/reductions.md records the
results.
"""
from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_hemispherical import exact_lambert_gaussian, lambert_gaussian, lobe, make_dataset  # noqa: E402

from bsdfkit.reduction.hemispherical import hemispherical  # noqa: E402

GRID = {"n_psi": 128, "n_r": 200}


def noise_free() -> list[tuple]:
    rows = []
    for side, two, step, fine, rho, tis, sigma in itertools.product(
            ("reflection", "transmission"), (False, True), (2.0, 5.0, 10.0), (True, False), (0.3, 0.8),
            (0.02, 0.2), (0.01, 0.05, 0.2)):
        plan = {"step": step} if fine else {"step": step, "fine": step, "fine_half": 0.0}
        amp = lobe(tis, sigma)
        ds = make_dataset(lambert_gaussian(rho, amp, sigma), side=side, two_arcs=two, **plan)
        for r in hemispherical(ds, **GRID):
            exact = exact_lambert_gaussian(rho, amp, sigma, r.theta_i)
            rows.append(((side, two, step, fine, rho, tis, sigma, r.theta_i), float(r.value[0]), float(r.std[0]),
                         float(exact)))
    return rows


def noisy() -> list[tuple]:
    rows = []
    for noise, two, step, rho, tis, sigma, seed in itertools.product(
            (0.02, 0.05), (False, True), (2.0, 5.0), (0.3, 0.8), (0.02, 0.2), (0.02, 0.05, 0.2), (0, 1)):
        amp = lobe(tis, sigma)
        ds = make_dataset(lambert_gaussian(rho, amp, sigma), two_arcs=two, step=step, rel_noise=noise, seed=seed,
                          wavelengths=(450.0, 550.0, 650.0))
        for r in hemispherical(ds, **GRID):
            exact = exact_lambert_gaussian(rho, amp, sigma, r.theta_i)
            for j in range(r.value.size):
                rows.append(((noise, two, step, rho, tis, sigma, seed, r.theta_i, j), float(r.value[j]),
                             float(r.std[j]), float(exact)))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise", action="store_true", help="the noisy grid instead of the noise-free one")
    args = parser.parse_args()
    rows = noisy() if args.noise else noise_free()
    value = np.array([r[1] for r in rows])
    std = np.array([r[2] for r in rows])
    exact = np.array([r[3] for r in rows])
    rel = (value - exact) / exact
    z = np.abs(value - exact) / np.maximum(std, 1e-300)
    k = 3.0 if args.noise else 1.0
    print(f"{len(rows)} values: |error| > 1 %: {np.sum(np.abs(rel) > 0.01)}, > 5 %: {np.sum(np.abs(rel) > 0.05)}, "
          f"outside {k:g} sigma: {np.sum(z > k)}, above 1 + 2 sigma: {np.sum(value - 2 * std > 1)}")
    for i in np.argsort(-np.abs(rel))[:10]:
        print(f"  {rows[i][0]}: {value[i]:.4f} ± {std[i]:.4f} for {exact[i]:.4f} ({100 * rel[i]:+.2f} %)")


if __name__ == "__main__":
    main()
