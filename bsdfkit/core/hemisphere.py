"""Geometry of the projected hemisphere shared by the reductions, the models and the table grids.

In direction-cosine space the hemisphere is the unit disk |β| ≤ 1 (docs/exports.md §1). One home for the
distance from a point inside the disk to its edge (the radial limit of every polar quadrature about the specular
point, of the table grids and of the models' exact TIS) and for the linear interpolation weights of the
half-profile reconstructions (issue #28). NumPy; :func:`unit_disk_reach` takes an array module ``xp`` so that
the JAX models pass ``jax.numpy`` without this module importing JAX.
"""
from __future__ import annotations

from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["unit_disk_reach", "linear_weights"]


def unit_disk_reach(bu: ArrayLike, b2: ArrayLike, xp: ModuleType = np):
    """Distance t ≥ 0 from a point β0 of the unit disk to the disk's edge along a unit direction u [1].

    t = −bu + √(bu² + 1 − b2), the positive root of |β0 + t·u| = 1, from bu = β0·u and b2 = |β0|² (broadcast;
    the root's argument is floored at 0 for points on the edge). The form of the models' exact TIS, which the
    synthetic measurements' recorded truth depends on to the last bit.

    Parameters
    ----------
    bu : array_like
        β0·u, the start point's component along the unit direction [-].
    b2 : array_like
        |β0|², the start point's squared distance from the disk centre [-], ≤ 1.
    xp : module, optional
        Array module (``numpy`` or ``jax.numpy``).

    Returns
    -------
    array
        Distance t ≥ 0 to the edge in direction-cosine space [-], broadcast from ``bu`` and ``b2``.
    """
    return -bu + xp.sqrt(xp.maximum(bu * bu + 1.0 - b2, 0.0))


def linear_weights(samples: NDArray[np.float64], query: NDArray[np.float64]
                   ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """(lo, hi, w_lo, w_hi): indices and weights of linear interpolation in increasing ``samples`` with constant
    extrapolation beyond the ends (the rule of :func:`numpy.interp`): f(q) = w_lo·f[lo] + w_hi·f[hi].

    Parameters
    ----------
    samples : ndarray, shape (m,)
        Strictly increasing sample abscissae (any unit), m ≥ 1.
    query : ndarray, shape (n,)
        Abscissae to interpolate at, in the unit of ``samples``.

    Returns
    -------
    lo, hi : ndarray of int, shape (n,)
        Indices into ``samples`` of the two neighbours (equal, 0, when m = 1).
    w_lo, w_hi : ndarray, shape (n,)
        Their weights [-], summing to 1.
    """
    m = samples.size
    if m == 1:
        z = np.zeros(query.size, dtype=np.int64)
        return z, z, np.ones(query.size), np.zeros(query.size)
    q = np.clip(query, samples[0], samples[-1])
    # the upper neighbour among samples[1:m-1] (+1): searchsorted(samples, q, "right") clipped to [1, m − 1], as q
    # lies in [samples[0], samples[-1]]; the interval widths from one np.diff (the same differences)
    hi = np.searchsorted(samples[1:-1], q, side="right") + 1
    lo = hi - 1
    t = (q - samples[lo]) / np.diff(samples)[lo]
    return lo, hi, 1.0 - t, t
