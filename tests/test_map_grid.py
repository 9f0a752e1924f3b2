"""Non-uniformity of a Monte Carlo irradiance map vs its grid (issue #27): rebinning, the split-half estimate, the
grid study. The noisy maps are Poisson counts of a known smooth field, so each estimate has a known answer."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.raytrace.tallies import (
    converged_non_uniformity,
    grid_study,
    interior_bins,
    non_uniformity,
    rebin_map,
    split_half_non_uniformity,
)

N = 64


def _field(bins: int) -> np.ndarray:
    """A smooth irradiance field [arbitrary units] sampled at the cell centres of a bins × bins map of [−1, 1]²."""
    c = (np.arange(bins) + 0.5) / bins * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    return 1.0 + 0.2 * np.exp(-(x ** 2 + y ** 2) / 0.3) - 0.1 * (x ** 2 + y ** 2)


def _noisy(rng: np.random.Generator, hits_per_cell: float, seeds: int) -> np.ndarray:
    mean = _field(N) * hits_per_cell
    return rng.poisson(mean, size=(seeds, N, N)).astype(np.float64) / hits_per_cell


def test_rebinning_keeps_the_power_and_refuses_a_grid_that_does_not_divide():
    m = np.random.default_rng(1).random((2, N, N))
    for bins in (32, 16, 8):
        coarse = rebin_map(m, bins)
        assert coarse.shape == (2, bins, bins)
        assert coarse.sum() * (N // bins) ** 2 == pytest.approx(m.sum(), rel=1e-14)
    assert rebin_map(m[0], 1)[0, 0] == pytest.approx(m[0].mean(), rel=1e-14)
    with pytest.raises(ValueError, match="do not divide"):
        rebin_map(m, 24)


def test_noise_raises_the_plain_estimate_and_the_split_half_estimate_removes_it():
    truth = non_uniformity(_field(N))
    maps = _noisy(np.random.default_rng(7), 100.0, 8)  # 10 % noise per cell
    plain = np.mean([non_uniformity(m) for m in maps])
    split = split_half_non_uniformity(maps[0::2].mean(axis=0), maps[1::2].mean(axis=0))
    assert plain > truth + 0.15  # the noise maximum: far above the field's own non-uniformity
    # not raised by the noise (a noisy choice of the extreme cells can only lower it), and far closer to the truth
    assert split < truth + 0.01 and abs(split - truth) < 0.25 * (plain - truth)
    # without noise the split-half estimate is the definition itself
    assert split_half_non_uniformity(_field(N), _field(N)) == pytest.approx(truth, rel=1e-14)


def test_grid_study_gives_sigma_per_grid_and_the_plain_estimate_grows_with_finer_cells():
    maps = _noisy(np.random.default_rng(3), 400.0, 8)
    study = grid_study(maps, (64, 32, 16))
    assert set(study) == {"64", "32", "16"}
    plain = [study[g]["mean"] for g in ("16", "32", "64")]
    assert plain[0] < plain[1] < plain[2]  # finer cells, fewer hits each: a larger noise maximum
    for g in ("16", "32", "64"):
        row = study[g]
        assert row["std"] > 0 and row["split_half_std"] > 0
        truth = non_uniformity(rebin_map(_field(N), int(g)))
        assert abs(row["split_half"] - truth) < 4 * row["split_half_std"] + 0.01
    assert interior_bins(16).sum() < interior_bins(64).sum()
    with pytest.raises(ValueError, match="seeds >= 2"):
        grid_study(maps[:1], (16,))


def test_sigma_of_one_maps_non_uniformity_from_the_map_alone_matches_the_spread_over_seeds():
    """σ from one map (neighbour residuals, redrawn) against the σ over 12 independent noisy maps of the field."""
    from bsdfkit.raytrace.tallies import non_uniformity_std

    coarse = rebin_map(_noisy(np.random.default_rng(11), 100.0, 12), 32)  # 5 % noise per 32-grid cell
    spread = np.std([non_uniformity(m) for m in coarse], ddof=1)
    from_map = np.array([non_uniformity_std(m) for m in coarse[:4]])
    assert np.all(from_map > 0.5 * spread) and np.all(from_map < 2.0 * spread), (from_map, spread)
    assert non_uniformity_std(coarse[0]) == non_uniformity_std(coarse[0])  # reproducible: its own generator
    # a noise-free smooth field: the neighbour residual is the field's curvature only, far below the noise above
    assert non_uniformity_std(_field(32)) < 0.2 * spread


@pytest.mark.parametrize("hits, converges", [(400.0, True), (1600.0, True), (25.0, False)])
def test_converged_non_uniformity_of_one_traces_sub_maps(hits, converges):
    """Eight sub-maps of interleaved rays (the tracer's MAP_PARTS): the chosen grid is the coarsest whose value
    changes by less than its σ on the next finer grid, and the value there is the field's own non-uniformity on that
    grid within 4 σ (+ 0.01 for the residual selection bias). Too few hits per cell (25 per sub-map cell, 20 %
    noise) converge on no grid: the finest is reported and flagged, never called converged."""
    parts = _noisy(np.random.default_rng(int(hits)), hits, 8)
    conv = converged_non_uniformity(parts)
    assert sorted(conv["grids"]) == [8, 16, 32, 64]
    g = conv["bins"]
    assert conv["converged"] is converges
    coarser = [k for k in conv["grids"] if k < g]
    assert all(abs(conv["grids"][2 * k]["value"] - conv["grids"][k]["value"]) >= conv["grids"][k]["std"]
               for k in coarser)
    if not converges:
        assert g == N and np.isnan(conv["finer"])
        return
    assert abs(conv["finer"] - conv["value"]) < conv["std"] and conv["finer"] == conv["grids"][2 * g]["value"]
    truth = non_uniformity(rebin_map(_field(N), g))
    assert abs(conv["value"] - truth) < 4 * conv["std"] + 0.01, (conv, truth)
