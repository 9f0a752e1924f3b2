"""How the table grids evaluate a BSDF callable: padded chunks for any callable (JAX compiles once per shape), the
directions as they are for a Pointwise one, and the auto grid's memos (node values, edge strips) give what a fresh
evaluation gives."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.core.errors import ValidationError
from bsdfkit.tables import export, grids, to_dataset


def _lobe(theta_i, side, d):
    bx = d[..., 0] - np.sin(np.radians(theta_i))
    return 0.05 + 40.0 * np.exp(-(bx ** 2 + d[..., 1] ** 2) / (2 * 0.05 ** 2))


class _Recorder:
    """The lobe, recording the number of directions of every call."""

    def __init__(self):
        self.sizes = []

    def __call__(self, theta_i, side, d):
        self.sizes.append(d.shape[0])
        return _lobe(theta_i, side, d)


def _directions(n):
    beta = np.random.default_rng(3).uniform(-0.6, 0.6, (n, 2))
    return np.concatenate([beta, np.sqrt(1.0 - np.sum(beta ** 2, axis=-1))[:, None]], axis=-1)


def test_a_pointwise_callable_gets_the_directions_unpadded():
    d = _directions(5000)
    plain, pointwise = _Recorder(), _Recorder()
    a = grids.evaluate_bsdf(plain, 30.0, "reflection", d)
    b = grids.evaluate_bsdf(grids.Pointwise(pointwise), 30.0, "reflection", d)
    assert plain.sizes == [grids.CHUNK, grids.CHUNK]  # the last chunk padded
    assert pointwise.sizes == [grids.CHUNK, 5000 - grids.CHUNK]
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(b, _lobe(30.0, "reflection", d))
    # its answers are checked as any callable's
    with pytest.raises(ValidationError, match="wrong shape"):
        grids.evaluate_bsdf(grids.Pointwise(lambda t, s, x: np.zeros(3)), 30.0, "reflection", d[:10])
    with pytest.raises(ValidationError, match="negative"):
        grids.evaluate_bsdf(grids.Pointwise(lambda t, s, x: -np.ones(x.shape[0])), 30.0, "reflection", d[:10])
    scalar = grids.evaluate_bsdf(grids.Pointwise(lambda t, s, x: np.float64(0.2)), 30.0, "reflection", d[:7])
    np.testing.assert_array_equal(scalar, np.full(7, 0.2))


def test_reconstructions_are_marked_pointwise_and_models_are_not():
    numpy_fn = grids.Pointwise(_lobe)
    assert isinstance(to_dataset._dispatch({"reflection": _lobe}), grids.Pointwise)
    assert isinstance(export._dispatch({"reflection": numpy_fn, "transmission": numpy_fn}), grids.Pointwise)
    assert not isinstance(export._dispatch({"reflection": numpy_fn, "transmission": _lobe}), grids.Pointwise)


def test_edge_strip_memo_gives_the_fresh_edge_values():
    """Edge values of candidate axes that share rows and strips, the strips' integrals taken from one memo: the same
    numbers as each table computed on its own, and each strip evaluated once."""
    theta = (0.0, 40.0, 70.0)
    psi = tuple(np.arange(24) * 15.0)
    first = grids.HarveyShackAxes((0.0, 0.05, 0.2, 0.6, 1.0, 2.0), psi, 270.0)
    second = grids.HarveyShackAxes((0.0, 0.05, 0.1, 0.2, 0.6, 1.2, 2.0), psi, 270.0)
    memo = grids._PolarMemo((1, len(theta)), (len(theta),))
    counted = _Recorder()
    for axes in (first, second, first):
        samples = grids.harvey_shack_grid(_lobe, theta, "reflection", axes).values
        fresh = grids.harvey_shack_edge_values(samples, _lobe, theta, "reflection", axes)
        shared = grids.harvey_shack_edge_values(samples, grids.Pointwise(counted), theta, "reflection", axes,
                                                strips=memo)
        np.testing.assert_array_equal(shared, fresh)
        assert np.any(shared != samples)  # some rows end in an edge value
    assert sum(counted.sizes) == int(np.sum(memo.known)) * grids.EDGE_ORDER  # the third pass evaluated nothing
    with pytest.raises(ValidationError, match="memo"):
        grids.harvey_shack_edge_values(samples, _lobe, theta[:2], "reflection", first, strips=memo)


def test_node_memo_evaluates_each_node_once_as_the_grid_samples_it():
    theta = np.array([10.0, 60.0])
    counted = _Recorder()
    nodes = grids._NodeValues(grids.Pointwise(counted), theta, ("reflection",), 270.0)
    rho = np.array([0.0, 0.05, 0.2, 0.6, 1.0, 2.0])
    psi = np.arange(24) * 15.0
    nodes(rho[::2], psi[::3])  # a part first, as a coarse round asks
    values = nodes(rho, psi)
    grid = grids.harvey_shack_grid(_lobe, theta, "reflection", grids.HarveyShackAxes(tuple(rho), tuple(psi), 270.0))
    np.testing.assert_array_equal(values, np.swapaxes(grid.values, -1, -2))  # (side, theta, psi, rho)
    inside = rho[None, None, :] <= grids.rho_max(theta[:, None, None], psi[None, :, None] + 270.0)
    assert sum(counted.sizes) == int(np.sum(inside))  # every node inside the disk once
    np.testing.assert_array_equal(nodes(rho[1:3], psi[5:7]), values[..., 5:7, 1:3])
    assert sum(counted.sizes) == int(np.sum(inside))
