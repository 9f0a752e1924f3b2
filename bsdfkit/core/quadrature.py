"""Quadrature rules shared by the reductions, the instrument model and the oracles.

Gauss–Legendre nodes are cached per order: a TIS table asks for the same order hundreds of times, and
``numpy.polynomial.legendre.leggauss(400)`` costs milliseconds each time.
"""
from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray


@functools.lru_cache(maxsize=64)
def _gauss_legendre(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    nodes, weights = np.polynomial.legendre.leggauss(n)
    nodes.setflags(write=False)
    weights.setflags(write=False)
    return nodes, weights


def gauss_legendre(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nodes x ∈ (−1, 1) and weights of the n-point Gauss–Legendre rule (exact for degree ≤ 2n − 1).

    The arrays are cached and read-only; copy them before changing them in place.

    Parameters
    ----------
    n : int
        Number of nodes, ≥ 1.

    Returns
    -------
    nodes : ndarray, shape (n,)
        Abscissae in (−1, 1) [-].
    weights : ndarray, shape (n,)
        Weights, summing to 2 [-].
    """
    if int(n) != n or n < 1:
        raise ValueError(f"Gauss-Legendre order must be a positive integer, got {n!r}")
    return _gauss_legendre(int(n))
