"""The hemispherical value of a BSDF given in an angle basis (Klems patches, tensor-tree leaves).

A file in a basis holds one BSDF value per cell of the outgoing hemisphere (a Klems patch, a tensor-tree leaf):
the BSDF is constant over each cell. Its directional-hemispherical value is then exactly the sum
ρ = Σ_k f_k Λ_k over the cells, Λ_k the projected solid angle of cell k [sr] (Σ_k Λ_k = π over the hemisphere),
which is what Radiance computes for such a file. The BSDF XML reader (``bsdfkit read``) and the hemispherical
engine (``bsdfkit tis`` on an ingested file, whose records carry the coordinate :data:`COORD`) both call
:func:`basis_sum`, so the two report one number.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["COORD", "COVERAGE_RTOL", "basis_sum", "covers_hemisphere"]

#: name of the per-record coordinate [sr]: the projected solid angle of the basis cell (or of the part of it)
#: the record stands for
COORD = "basis_psa"
#: Σ Λ over the records must equal π within this relative tolerance for the basis sum to be the hemispherical value
COVERAGE_RTOL = 1e-6


def basis_sum(values: NDArray[np.float64], psa: NDArray[np.float64]) -> NDArray[np.float64]:
    """Σ_k f_k Λ_k [1] over the first axis of ``values`` (cells × ...) [1/sr], ``psa`` (cells,) [sr].

    Parameters
    ----------
    values : ndarray, shape (cells, ...)
        BSDF of each cell [1/sr].
    psa : ndarray, shape (cells,)
        Projected solid angle of each cell [sr].

    Returns
    -------
    ndarray, shape (...)
        Directional-hemispherical value [-].
    """
    return np.asarray(psa, dtype=np.float64) @ np.asarray(values, dtype=np.float64)


def covers_hemisphere(psa: NDArray[np.float64]) -> bool:
    """True when the cells' projected solid angles [sr] are finite, positive and sum to π (the whole hemisphere).

    Parameters
    ----------
    psa : ndarray, shape (cells,)
        Projected solid angle of each cell [sr].

    Returns
    -------
    bool
    """
    p = np.asarray(psa, dtype=np.float64)
    return bool(p.size and np.all(np.isfinite(p)) and np.all(p > 0)
                and abs(float(p.sum()) - np.pi) <= COVERAGE_RTOL * np.pi)
