"""Radiance tensor-tree BSDF data (``IncidentDataStructure`` ``TensorTree3`` / ``TensorTree4``, angle basis
``LBNL/Shirley-Chiu``), as written by Radiance's ``bsdf2ttree``, ``genBSDF`` and ``pabopto2bsdf``: parser, slices
and hemispherical values. Used by :mod:`bsdfkit.tables.formats.bsdfxml`, which reads the XML around it.

Layout (the BSDF XML ``ScatteringData`` of one block)
    A tree over the unit hypercube [0, 1)^D, D = 4 (anisotropic: incident square coordinates (x0, x1), outgoing
    (x2, x3)) or D = 3 (isotropic: incident coordinate x0, outgoing (x1, x2)). A node is ``{ … }`` holding either
    2^D child nodes (child n covers the upper half of dimension i where bit i of n is set) or a grid of 2^(D·k)
    values (k ≥ 0, row-major: the last dimension varies fastest), each the BSDF [1/sr] over its cell (no
    interpolation). Values are separated by white space or commas.

Coordinates
    A direction's (x, y) components map to the unit square by the Shirley–Chiu concentric map, which preserves
    area: a cell of edge s covers the projected solid angle π s² [sr] (the whole square: π). Outgoing (x1, x2)
    or (x2, x3) are the outgoing direction's components. Incident: with the incident vector ``i`` pointing from
    the sample to the source, TT4 holds the square coordinates of (−i_x, −i_y); TT3 holds x0 = ½ − ½ sin θi
    (only x0 < ½ is used) with the outgoing directions rotated so that −i lies at azimuth 0. bsdfkit's frame
    (source at azimuth 180°, specular direction at β0 = (sin θi, 0)) is this frame: −i = (sin θi, 0).

Hemispherical value (what Radiance's direct-hemispherical query returns for the file)
    ρ(θi) = π Σ f s² over the leaves of the slice at the incidence: the basis sum of
    :mod:`bsdfkit.reduction.basis`, exact for the piecewise-constant BSDF of the file.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bsdfkit.reduction.basis import basis_sum, disk_to_square, grid_directions, square_to_disk

__all__ = ["TensorTree", "TreeSyntaxError", "disk_to_square", "grid_directions", "incidences_deg", "parse_tree",
           "square_to_disk"]

_TOKEN = re.compile(r"[{}]|[^\s,{}]+")
#: Radiance's FTINY: normal incidence sits just inside the lower half of TT3's incident axis
_TINY = 1e-6
#: ingest: the outgoing square is listed on a uniform grid of at least MIN_CELLS × MIN_CELLS cells (each leaf a
#: union of cells, so the basis sum is kept exactly)
MIN_CELLS = 16


@dataclass(frozen=True, eq=False)
class TensorTree:
    """The leaves of one tree: ``corner`` (leaf, D) and ``size`` (leaf,) in the unit hypercube, ``value`` [1/sr]."""

    ndim: int
    corner: NDArray[np.float64]
    size: NDArray[np.float64]
    value: NDArray[np.float64]

    def incident_point(self, theta_deg: float) -> NDArray[np.float64]:
        """Incident hypercube coordinates of the source at ``theta_deg`` [deg], azimuth 180° (bsdfkit's frame).

        Parameters
        ----------
        theta_deg : float
            Incidence [deg].

        Returns
        -------
        ndarray
            (1,) for TT3 or (2,) for TT4 coordinates in [0, 1] [-].
        """
        r = float(np.sin(np.radians(theta_deg)))
        if self.ndim == 3:
            return np.array([min(0.5 - 0.5 * r, 0.5 - _TINY)])
        return np.asarray(disk_to_square(np.array([r]), np.array([0.0]))).reshape(2)

    def slice_at(self, theta_deg: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """(corner (leaf, 2), size (leaf,), value (leaf,)) of the outgoing leaves at the incidence [deg].

        Parameters
        ----------
        theta_deg : float
            Incidence [deg].

        Returns
        -------
        corner : ndarray
            (leaf, 2) outgoing corners in the unit square [-].
        size : ndarray
            (leaf,) edge lengths [-].
        value : ndarray
            (leaf,) BSDF [1/sr].
        """
        p = self.incident_point(theta_deg)
        ni = self.ndim - 2
        lo = self.corner[:, :ni]
        inside = np.all((lo <= p) & (p < lo + self.size[:, None]), axis=1)
        return self.corner[inside, ni:], self.size[inside], self.value[inside]

    def hemispherical(self, theta_deg: float) -> float:
        """ρ = π Σ f s² [1] over the slice at the incidence [deg] (the module docstring).

        Parameters
        ----------
        theta_deg : float
            Incidence [deg].

        Returns
        -------
        float
            ρ [-].
        """
        _, size, value = self.slice_at(theta_deg)
        return float(basis_sum(value, np.pi * size**2))

    def incident_edges(self) -> NDArray[np.float64]:
        """Leaf boundaries along the incident axis in the plane of incidence (TT3: x0 in [0, ½]; TT4: x0 in [½, 1]
        at x1 = ½): between two consecutive ones the slice, and so every value, is the same."""
        if self.ndim == 3:
            edges = np.concatenate([self.corner[:, 0], self.corner[:, 0] + self.size, [0.0, 0.5]])
            return np.unique(edges[edges <= 0.5])
        on = (self.corner[:, 1] <= 0.5) & (0.5 < self.corner[:, 1] + self.size)
        edges = np.concatenate([self.corner[on, 0], self.corner[on, 0] + self.size[on], [0.5, 1.0]])
        return np.unique(edges[edges >= 0.5])


    def cells_per_side(self, minimum: int = MIN_CELLS) -> int:
        """Cells per side of the finest uniform grid every outgoing leaf is a union of (at least ``minimum``).

        Parameters
        ----------
        minimum : int
            Fewest cells per side.

        Returns
        -------
        int
            Cells per side.
        """
        return max(minimum, int(round(1.0 / float(self.size.min()))))

    def out_grid(self, theta_deg: float, m: int) -> NDArray[np.float64]:
        """The BSDF [1/sr] on the m × m uniform grid of the outgoing square at the incidence [deg] (cell (a, b)
        covers [a, a + 1) / m × [b, b + 1) / m): each cell takes the value of the leaf it lies in.

        Parameters
        ----------
        theta_deg : float
            Incidence [deg].
        m : int
            Cells per side.

        Returns
        -------
        ndarray
            (m, m) BSDF [1/sr] (NaN where no leaf covers a cell).
        """
        corner, size, value = self.slice_at(theta_deg)
        out = np.full((m, m), np.nan)
        lo = np.rint(corner * m).astype(int)
        n = np.maximum(np.rint(size * m).astype(int), 1)
        for (a, b), k, v in zip(lo, n, value):
            out[a:a + k, b:b + k] = v
        return out


def incidences_deg(edges: NDArray[np.float64], ndim: int) -> list[float]:
    """Normal incidence and the centres of the incident cells between consecutive ``edges`` (of
    :meth:`TensorTree.incident_edges`) [deg], ascending.

    Parameters
    ----------
    edges : ndarray
        Leaf boundaries along the incident axis [-].
    ndim : int
        3 (TT3) or 4 (TT4).

    Returns
    -------
    list of float
        Incidences [deg].
    """
    e = np.unique(edges)
    c = 0.5 * (e[:-1] + e[1:])
    r = 1.0 - 2.0 * c if ndim == 3 else 2.0 * c - 1.0  # TT3: x0 = (1 - sin) / 2; TT4: x0 = (1 + sin) / 2
    return sorted({0.0, *(round(float(np.degrees(np.arcsin(np.clip(v, 0.0, 1.0)))), 9) for v in r)})


class TreeSyntaxError(ValueError):
    """A malformed tree: ``offset`` (characters into the ScatteringData text), what was expected and found."""

    def __init__(self, message: str, offset: int, expected: str, got: str | int) -> None:
        super().__init__(message)
        self.offset, self.expected, self.got = offset, expected, got


def parse_tree(text: str, ndim: int) -> TensorTree:
    """The leaves of the tree in ``text`` (a ScatteringData body) of dimension ``ndim`` (3 or 4).

    Raises :class:`TreeSyntaxError` on a missing brace, a grid whose value count is not 2^(D·k), a value that is
    not a finite number ≥ 0 [1/sr] or text after the tree.

    Parameters
    ----------
    text : str
        The ScatteringData body.
    ndim : int
        3 (TT3) or 4 (TT4).

    Returns
    -------
    TensorTree
        The leaves (values [1/sr]).
    """
    tokens = [(m.group(), m.start()) for m in _TOKEN.finditer(text)]
    leaves: list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]] = []
    pos = _node(tokens, 0, np.zeros(ndim), 1.0, 0, ndim, leaves, text)
    if pos < len(tokens):
        raise TreeSyntaxError("extra characters after the tensor tree", tokens[pos][1], "end of ScatteringData",
                              tokens[pos][0][:40])
    return TensorTree(ndim, np.concatenate([c for c, _, _ in leaves]), np.concatenate([s for _, s, _ in leaves]),
                      np.concatenate([v for _, _, v in leaves]))


def _node(tokens: list[tuple[str, int]], pos: int, corner: NDArray[np.float64], edge: float, depth: int, ndim: int,
          leaves: list, text: str) -> int:
    """Read the node at token ``pos`` (covering the cube ``corner`` + [0, edge)^D) into ``leaves``; the position
    after it."""
    pos = _expect(tokens, pos, "{", text)
    if pos < len(tokens) and tokens[pos][0] == "{":  # 2^D children; child n is upper in dimension i if bit i
        if depth >= 30:
            raise TreeSyntaxError("tensor tree nested too deeply", tokens[pos][1], "at most 30 levels", "more")
        bits = (np.arange(2**ndim)[:, None] >> np.arange(ndim)[None, :]) & 1
        for n in range(2**ndim):
            pos = _node(tokens, pos, corner + 0.5 * edge * bits[n], 0.5 * edge, depth + 1, ndim, leaves, text)
        return _expect(tokens, pos, "}", text)
    start = pos
    while pos < len(tokens) and tokens[pos][0] not in ("{", "}"):
        pos += 1
    grid = _grid_values(tokens, start, pos, text)
    n_side = _grid_side(grid.size, ndim, tokens[start][1] if start < len(tokens) else len(text))
    idx = np.indices((n_side,) * ndim).reshape(ndim, -1).T  # row-major: the last dimension fastest
    leaves.append((corner + idx * (edge / n_side), np.full(grid.size, edge / n_side), grid))
    return _expect(tokens, pos, "}", text)


def _expect(tokens: list[tuple[str, int]], pos: int, brace: str, text: str) -> int:
    if pos >= len(tokens) or tokens[pos][0] != brace:
        got = tokens[pos][0][:40] if pos < len(tokens) else "end of data"
        where = tokens[pos][1] if pos < len(tokens) else len(text)
        raise TreeSyntaxError(f"missing '{brace}' in tensor tree", where, f"'{brace}'", got)
    return pos + 1


def _grid_values(tokens: list[tuple[str, int]], start: int, stop: int, text: str) -> NDArray[np.float64]:
    out = np.empty(stop - start)
    for k in range(start, stop):
        word, where = tokens[k]
        try:
            v = float(word)
        except ValueError:
            raise TreeSyntaxError("not a number in tensor tree", where, "a number (1/sr)", word[:40]) from None
        if not (np.isfinite(v) and v >= 0.0):
            raise TreeSyntaxError("BSDF value not a finite number >= 0", where, "finite >= 0 (1/sr)", word[:40])
        out[k - start] = v
    return out


def _grid_side(count: int, ndim: int, where: int) -> int:
    """n with n^D = ``count`` and n a power of 2 (a leaf grid of 2^(D·k) values)."""
    n = 1
    while n**ndim < count:
        n *= 2
    if count == 0 or n**ndim != count:
        raise TreeSyntaxError("wrong number of values in a tensor-tree leaf grid", where,
                              f"2^({ndim}k) values (1, {2**ndim}, {4**ndim}, ...)", count)
    return n


# ------------------------------------------------------------------------------------------- writer (TensorTree3)
#: TT3 written: 2^LOG2_CELLS cells per dimension (64: outgoing cells of about 1.8 deg at the normal)
LOG2_CELLS = 6
#: sub-samples per side of an outgoing cell for its average (uniform in the square = in projected solid angle)
SUB_SAMPLES_TREE = 6
#: 2^D cells are merged into one leaf (their mean: the basis sum is kept) when (max - min) <= MERGE_RTOL * max
#: (about 90 % of the cells of a smooth body, as Radiance's own bsdf2ttree culls by default)
MERGE_RTOL = 0.05


def cell_averages(values_at: Callable[[NDArray[np.float64]], NDArray[np.float64]], n: int,
                  sub: int = SUB_SAMPLES_TREE) -> NDArray[np.float64]:
    """(n, n) projected-solid-angle averages [1/sr] over the cells of the outgoing square of ``values_at(d)`` (unit
    vectors (..., 3)): ``sub`` × ``sub`` points per cell, uniform in the square (the map preserves area).

    Parameters
    ----------
    values_at : callable
        Unit directions (..., 3) → BSDF [1/sr].
    n : int
        Cells per side.
    sub : int
        Sub-samples per side of a cell.

    Returns
    -------
    ndarray
        (n, n) averages [1/sr].
    """
    k = (np.arange(n * sub) + 0.5) / (n * sub)
    a, b = np.meshgrid(k, k, indexing="ij")
    x, y = square_to_disk(a, b)
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, None))
    v = values_at(np.stack([x, y, z], axis=-1))
    return v.reshape(n, sub, n, sub).mean(axis=(1, 3))


def tree_text(grid: NDArray[np.float64], rtol: float = MERGE_RTOL) -> str:
    """The ``{ … }`` text of a full (n, n, n) TT3 grid [1/sr] (n a power of 2), cells merged where uniform within
    ``rtol`` (each merged leaf holds the mean of its cells, so π Σ f s² is unchanged).

    Parameters
    ----------
    grid : ndarray
        (n, n, n) BSDF [1/sr].
    rtol : float
        Relative spread below which cells merge [-].

    Returns
    -------
    str
        The tree text.
    """
    out: list[str] = []
    _emit(np.asarray(grid, dtype=np.float64), rtol, out)
    return "\n".join(out)


def _emit(block: NDArray[np.float64], rtol: float, out: list[str]) -> None:
    hi, lo = float(block.max()), float(block.min())
    if block.shape[0] == 1 or hi - lo <= rtol * hi:
        out.append(f"{{ {float(block.mean()):.7g} }}")
        return
    if block.shape[0] == 2:  # a 2 x 2 x 2 grid, row-major
        out.append("{ " + " ".join(f"{float(v):.7g}" for v in block.ravel()) + " }")
        return
    h = block.shape[0] // 2
    out.append("{")
    for n in range(8):  # child n: upper half of dimension i where bit i of n is set
        s = [slice(h, None) if (n >> i) & 1 else slice(0, h) for i in range(3)]
        _emit(block[tuple(s)], rtol, out)
    out.append("}")
