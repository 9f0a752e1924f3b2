"""Polar interpolation of BSDF records sampled anywhere on the projected disk, and its exact quadrature weights.

The hemispherical integral of elastic scatter is ρ = ∬_{|β| ≤ 1} f dβx dβy in Harvey–Shack direction cosines
(:mod:`bsdfkit.reduction.tis`). Where records lie on one or two arcs, :mod:`bsdfkit.reduction.hemispherical`
reconstructs half-profiles about the normal and the specular point. Everything else an instrument writes — a
θs × φs grid of an imaging sphere or scatterometer, photometric C-planes through the normal, several planes
through the specular point, a φs = 90/270° arc, scattered records — is interpolated here:

* about a centre c (the normal for a diffuse body, the lobe's peak for a specular lobe) every record has polar
  coordinates (ψ, r), r = |β − c|;
* the records, a line of nodes at r = 0 (the value at the centre: the record there, or the mean of the innermost
  records) and a rim of nodes at the outer edge of the domain are triangulated (Delaunay) in (s·ψ, r) with the
  azimuth weighted by :data:`AZIMUTH_WEIGHT` (≪ 1) and copied at ψ ± 2π, so that f is interpolated linearly in r
  along spokes and between records at about the same distance from the centre across azimuth: exact for any f
  that depends on r only, on any sampling, and the trapezoid rule in ψ between planes of a C-plane set;
* rim nodes: on the horizon, by an extrapolation rule from the outermost data along each azimuth (``trend``:
  along the slope of the last 10° in θ, kept between 0 and the last value; ``hold``; ``zero``); for a lobe, a
  ring of zeros at the lobe region's radius.

Every node value is a fixed linear combination of the record values, so the integral on a polar quadrature
grid about c (midpoint in ψ, Gauss–Legendre in r, clipped to the unit disk) is a dot product w · f, and the
same interpolant evaluated at any direction is what an exported table samples: one reconstruction for the
number and for the table.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.errors import InputError
from bsdfkit.core.hemisphere import unit_disk_reach
from bsdfkit.core.lazy import LazyModule
from bsdfkit.core.quadrature import gauss_legendre

if TYPE_CHECKING:
    from scipy.spatial import Delaunay

# scipy's sparse and spatial modules (0.3-0.7 s to import) are needed only when records are triangulated; a
# table on its own spokes (Zemax, TracePro, ASAP) is integrated without them (`bsdfkit tis`/`read` stay light)
sp = LazyModule("scipy.sparse")

#: scipy's Qhull wrapper: Delaunay and QhullError (scipy.spatial re-exports them)
QHULL = "scipy.spatial._qhull"
#: the LAPACK routines the Qhull wrapper calls
LAPACK = "scipy.linalg.cython_lapack"


def qhull() -> ModuleType:
    """:data:`QHULL`, without the rest of scipy.spatial when that is not imported yet.

    The package's import also loads scipy.spatial.distance (and with it scipy.special), transform, the k-d trees
    and the Voronoi code, none of which a reduction uses: 0.1-0.3 s of every ``bsdfkit read`` and ``tis``
    (docs/performance.md). The extension module is then loaded from its file under its own name, as the package's
    import would load it (a later ``import scipy.spatial`` finds and re-exports it); any other layout or failure
    falls back to the package import.
    """
    module = sys.modules.get(QHULL)
    if module is not None:
        return module
    if "scipy.spatial" not in sys.modules:
        try:
            import scipy

            folder = Path(scipy.__file__).parent
            # Qhull's wrapper takes its LAPACK routines from scipy.linalg.cython_lapack: loaded the same way when
            # scipy.linalg is not imported yet (the package's import, 0.07 s, is not needed for them)
            if "scipy.linalg" not in sys.modules:
                _extension(LAPACK, folder / "linalg" / "cython_lapack")
            module = _extension(QHULL, folder / "spatial" / "_qhull")
            if module is not None:
                return module
        except Exception:  # any surprise of another scipy: the ordinary import below
            sys.modules.pop(QHULL, None)
    from scipy.spatial import _qhull

    return _qhull


def _extension(name: str, stem: Path) -> ModuleType | None:
    """The extension module ``name`` loaded from its file ``stem`` + the interpreter's suffix (None: no such file),
    registered under its own name as its package's import would register it."""
    module = sys.modules.get(name)
    if module is not None:
        return module
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = stem.with_name(stem.name + suffix)
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None or not path.is_file():
            continue
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(name, None)
            raise
        return module
    return None

#: Weight of the azimuth (radians) against the radius (direction cosines) in the triangulation metric: records
#: at about the same distance from the centre are joined across azimuth before records along a spoke.
AZIMUTH_WEIGHT = 0.02
#: Nodes on the centre line and on the rim (one every 2° of azimuth).
N_RIM = 180
#: The trend extrapolation takes its slope over this polar angle [deg] inside the last data.
TREND_SPAN_DEG = 10.0
#: Polar quadrature grid (azimuths × Gauss–Legendre radii) for domains not bounded by r = 1 about the normal.
QUAD_PSI, QUAD_R = 256, 160
#: Records within this distance (direction cosines) of the centre define the centre value.
CENTER_TOL = 1e-7


def horizon_distance(center: tuple[float, float], psi: NDArray[np.float64],
                     cos_sin: tuple[NDArray, NDArray] | None = None) -> NDArray[np.float64]:
    """Distance t_max(ψ) from ``center`` (inside the unit disk) to the unit circle along azimuth ψ.

    Parameters
    ----------
    center : tuple of float
        Centre (βx, βy) in direction cosines [-], inside the unit disk.
    psi : ndarray
        Azimuths about the centre [rad].
    cos_sin : tuple of ndarray, optional
        (cos ψ, sin ψ) [-] when already known.

    Returns
    -------
    ndarray
        t_max per azimuth, in direction cosines [-].
    """
    cos_psi, sin_psi = (np.cos(psi), np.sin(psi)) if cos_sin is None else cos_sin
    bu = center[0] * cos_psi + center[1] * sin_psi
    return unit_disk_reach(bu, center[0] ** 2 + center[1] ** 2)


@dataclass(frozen=True)
class PolarInterpolant:
    """A linear interpolant of n records over a polar domain about ``center`` (β, direction cosines).

    ``nodes`` (N × n, sparse) gives the value of every interpolation node from the record values; the
    triangulation ``tri`` of the points (s·ψ, r) maps each point to a node through ``point_node``.
    ``radius`` (None = the unit disk) bounds the domain at min(radius, t_max(ψ)).
    """

    center: tuple[float, float]
    tri: Delaunay
    point_node: NDArray[np.int64]
    nodes: sp.csr_matrix
    n_records: int
    radius: float | None
    extrapolated_beyond: float | None  # smallest polar distance [direction cosines] where the rim extrapolates
    azimuth_weight: float = AZIMUTH_WEIGHT  # s of the triangulation metric (s·ψ, r)
    #: polar coordinates of the interpolation other than (ψ, r) about the centre in β: the incidence [deg]
    #: of a grid about the specular *direction* (azimuth about it, angle from it), or None
    direction_polar: float | None = None

    def matrix(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> sp.csr_matrix:
        """M (m × n, sparse) such that the interpolant at β = (x, y) is M @ values.

        Parameters
        ----------
        x, y : ndarray
            Points βx, βy in direction cosines [-] (flattened; m of them).

        Returns
        -------
        scipy.sparse.csr_matrix
            m × n, rows zero beyond a bounded domain.
        """
        psi, r = self._polar(x, y)
        return self._matrix_polar(psi, r)

    def _polar(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        dx, dy = np.ravel(x) - self.center[0], np.ravel(y) - self.center[1]
        return np.arctan2(dy, dx), np.hypot(dx, dy)

    def _located(self, psi: NDArray[np.float64], r: NDArray[np.float64], repeats: int = 1
                 ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
        """Barycentric coordinates (m, 3) and node indices (m, 3) of polar points (clipped to the domain), and
        whether each point lies inside the domain (a lobe is zero beyond it).
        ``repeats`` > 1 says that ψ comes in blocks of that many equal values (the polar quadrature grid, ψ repeated
        over the radii): what depends on ψ alone is computed once per block (the same numbers)."""
        psi_u = np.mod(psi[::repeats] + np.pi, 2.0 * np.pi) - np.pi
        sin_u, cos_u = np.sin(psi_u), np.cos(psi_u)
        top_u = self._top(psi_u, (cos_u, sin_u))  # once for the clip and the domain test
        if repeats > 1:
            psi, top, sin_psi = (np.repeat(a, repeats) for a in (psi_u, top_u, sin_u))
            cos_psi = np.repeat(cos_u, repeats) if self.direction_polar is not None else None
        else:
            psi, top, sin_psi, cos_psi = psi_u, top_u, sin_u, cos_u
        inside = ~(r > top * (1.0 + 1e-9) + 1e-12)
        r = np.clip(r, 0.0, top * (1.0 - 1e-12))
        if self.direction_polar is not None:
            psi, r = direction_polar(self.center, psi, r, self.direction_polar, (cos_psi, sin_psi))
            sin_psi = psi  # ψ from arctan2 lies in [−π, π], where sin ψ has the sign of ψ (all _coords takes of it)
        q = _coords(psi, r, self.azimuth_weight, sin_psi)
        q, simplex = _locate(self.tri, q)
        # T⁻¹ (q − p2) written out: the same products and sums as einsum's, without its (m, 3, 2) gather
        t = self.tri.transform.reshape(-1, 6)
        d0, d1 = q[:, 0] - t[simplex, 4], q[:, 1] - t[simplex, 5]
        bary = np.empty((simplex.size, 3))
        bary[:, 0] = t[simplex, 0] * d0 + t[simplex, 1] * d1
        bary[:, 1] = t[simplex, 2] * d0 + t[simplex, 3] * d1
        bary[:, 2] = 1.0 - (bary[:, 0] + bary[:, 1])
        return bary, self.point_node[self.tri.simplices[simplex]], inside

    def _matrix_polar(self, psi: NDArray[np.float64], r: NDArray[np.float64]) -> sp.csr_matrix:
        bary, cols, inside = self._located(psi, r)
        m = r.size
        rows = np.repeat(np.arange(m), 3)
        bmat = sp.csr_matrix((bary.ravel(), (rows, cols.ravel())), shape=(m, self.nodes.shape[0]))
        out = bmat @ self.nodes
        if not inside.all():  # beyond the domain of a lobe: zero
            out = sp.diags(inside.astype(float)) @ out
        return out.tocsr()

    def _top(self, psi: NDArray[np.float64], cos_sin: tuple[NDArray, NDArray] | None = None) -> NDArray[np.float64]:
        t = horizon_distance(self.center, psi, cos_sin)
        return t if self.radius is None else np.minimum(t, self.radius)

    def evaluate(self, values: NDArray[np.float64], x: NDArray[np.float64],
                 y: NDArray[np.float64]) -> NDArray[np.float64]:
        """The (linear) interpolant of ``values`` (per record) at β = (x, y).

        The node values first, then each point's three (N·v at the triangle's nodes): the same number as
        ``matrix(x, y) @ values`` up to rounding, without building the m × n matrix (an exported table evaluates
        hundreds of chunks of directions).

        Parameters
        ----------
        values : ndarray
            One value per record (a BSDF [1/sr]).
        x, y : ndarray
            Points βx, βy in direction cosines [-] (flattened).

        Returns
        -------
        ndarray
            The interpolant at each point, in the unit of ``values``; 0 beyond a bounded domain.
        """
        psi, r = self._polar(x, y)
        bary, cols, inside = self._located(psi, r)
        at_nodes = self.nodes @ np.asarray(values, dtype=np.float64)
        return np.where(inside, np.sum(bary * at_nodes[cols], axis=1), 0.0)

    def _cells(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The triangles clipped to one period ψ ∈ [−π, π) and to the domain, as sub-triangles: parent nodes
        (K, 3), the parents' barycentric coordinates at the sub-triangle's vertices (K, 3, 3), areas in (ψ, r)
        [rad × direction cosines] and vertex radii (K, 3). Clipping (not a centroid rule) keeps the integral
        exactly that of the evaluated interpolant: ring interpolation makes triangles that span wide azimuths.
        Computed once per interpolant (its weights and its ln-f integral both need it)."""
        return self._clipped

    @functools.cached_property
    def _clipped(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        simp = self.tri.simplices
        pts = self.tri.points[simp].copy()  # (T, 3, 2) in (s·ψ, r)
        pts[:, :, 0] /= self.azimuth_weight
        nodes = self.point_node[simp]
        psi_c, r_c = pts[:, :, 0].mean(axis=1), pts[:, :, 1].mean(axis=1)
        # the hull bridges concave stretches of the rim polygon with triangles of rim nodes outside the domain
        on_rim = (nodes > self.n_records).all(axis=1)  # the centre line is node n, the rim n + 1 ...
        outside = on_rim & (r_c > self._top(psi_c) * (1.0 + 1e-12))
        lo, hi = pts[:, :, 0].min(axis=1), pts[:, :, 0].max(axis=1)
        inner = ~outside & (lo >= -np.pi) & (hi <= np.pi)
        eye = np.broadcast_to(np.eye(3), (int(inner.sum()), 3, 3))
        # the triangles across the seam, all at once: clipped to ψ ≥ −π, then (if three vertices are left) ψ ≤ π
        cut = np.flatnonzero(~outside & ~inner & (hi > -np.pi) & (lo < np.pi))
        poly = pts[cut]
        bary = np.broadcast_to(np.eye(3), (cut.size, 3, 3))
        count = np.full(cut.size, 3)
        for bound, sign in ((-np.pi, 1.0), (np.pi, -1.0)):
            poly, bary, count = _clip_batch(poly, bary, count, bound, sign)
            count = np.where(count < 3, 0, count)
        # fans (0, k, k + 1), polygon by polygon in order
        n_fan = np.maximum(count - 2, 0)
        owner = np.repeat(np.arange(cut.size), n_fan)
        k = np.arange(owner.size) - np.repeat(np.cumsum(n_fan) - n_fan, n_fan) + 1
        corner = np.stack([np.zeros_like(k), k, k + 1], axis=1)
        fan_pts = poly[owner[:, None], corner]
        fan_bary = bary[owner[:, None], corner]
        n_ = np.concatenate([nodes[inner], nodes[cut[owner]]])
        bary = np.concatenate([eye, fan_bary])
        p = np.concatenate([pts[inner], fan_pts])
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        return n_, bary, area, p[:, :, 1]

    @property
    def _flat_top(self) -> bool:
        """The domain is r ≤ 1 about the normal: a rectangle in (ψ, r), integrated exactly per triangle. Elsewhere
        (a centre off the normal, a lobe's ring) the horizon bounds it by a curve the triangulation's hull does not
        follow, and a polar quadrature grid clipped to the domain integrates what :meth:`matrix` evaluates."""
        return (self.radius is None and self.center == (0.0, 0.0)
                and float(self.tri.points[:, 1].max()) <= 1.0 + 1e-9)  # held spokes reach beyond the horizon

    def _grid(self, n_psi: int = QUAD_PSI, n_r: int = QUAD_R
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Nodes (ψ, r) and area weights of the polar quadrature grid clipped to the domain."""
        psi = (np.arange(n_psi) + 0.5) * (2 * np.pi / n_psi) - np.pi
        top = self._top(psi)
        x, tw = gauss_legendre(n_r)
        x, tw = 0.5 * (x + 1.0), 0.5 * tw
        r = top[:, None] * x[None, :]
        w = (top[:, None] ** 2) * x[None, :] * tw[None, :] * (2 * np.pi / n_psi)
        return np.repeat(psi, n_r), r.ravel(), w.ravel()

    def weights(self) -> NDArray[np.float64]:
        """w such that the integral of the (linear) interpolant over its domain is w @ values [sr]: exact on
        each (sub-)triangle, ∫ g r dA = A [Σ_k g_k r_k + (Σ_k g_k)(Σ_k r_k)] / 12 for g linear (about the
        normal), else on a polar grid of :data:`QUAD_PSI` × :data:`QUAD_R` nodes clipped to the domain."""
        if not self._flat_top:
            psi, r, w = self._grid()
            # wᵀM = ((w on the domain)ᵀ B) N, B the points' barycentrics: no m × n matrix (equal up to rounding)
            bary, cols, inside = self._located(psi, r, QUAD_R)
            w_nodes = np.bincount(cols.ravel(), weights=(bary * np.where(inside, w, 0.0)[:, None]).ravel(),
                                  minlength=self.nodes.shape[0])
            return np.asarray(self.nodes.T @ w_nodes).ravel()
        nodes, bary, area, r = self._cells()
        # per parent node i: g = λ_i, its values at the sub-triangle's vertices bary[:, k, i]
        per = area[:, None] / 12.0 * (np.einsum("kvi,kv->ki", bary, r) + bary.sum(axis=1) * r.sum(axis=1)[:, None])
        w_nodes = np.bincount(nodes.ravel(), weights=per.ravel(), minlength=self.nodes.shape[0])
        return np.asarray(self.nodes.T @ w_nodes).ravel()

    def integral(self, values: NDArray[np.float64], mode: str = "linear") -> float:
        """∬ f dβ of the interpolant of ``values`` over its domain.

        Parameters
        ----------
        values : ndarray
            One value per record (a BSDF [1/sr]).
        mode : str
            ``"linear"`` (``weights() @ values``) or ``"log"``: ln f interpolated on triangles whose three nodes
            are positive (a 7-point degree-5 rule per triangle), f elsewhere.

        Returns
        -------
        float
            The integral: the unit of ``values`` times [sr] (a BSDF gives a fraction of the incident power [-]).
        """
        if mode == "linear":
            return float(self.weights() @ values)
        if not self._flat_top:
            psi, r, w = self._grid()
            bary, nodes, _ = self._located(psi, r, QUAD_R)
            v = (self.nodes @ np.asarray(values, dtype=np.float64))[nodes]
            pos = (v > 0).all(axis=1)
            out = np.sum(bary * v, axis=1)
            out[pos] = np.exp(np.sum(bary[pos] * np.log(v[pos]), axis=1))
            return float(w @ out)
        nodes, bary, area, r = self._cells()
        v = (self.nodes @ np.asarray(values, dtype=np.float64))[nodes]  # (K, 3) parent node values
        pos = (v > 0).all(axis=1)
        lam = np.einsum("qv,kvi->kqi", _DUNAVANT_POINTS, bary)  # parent barycentrics at the points (K, 7, 3)
        rq = r @ _DUNAVANT_POINTS.T  # (K, 7)
        lin = np.einsum("kqi,ki->kq", lam, v)
        logv = np.einsum("kqi,ki->kq", lam, np.log(np.where(v > 0, v, 1.0)))
        g = np.where(pos[:, None], np.exp(logv), lin)
        return float(np.sum(area[:, None] * _DUNAVANT_WEIGHTS[None, :] * g * rq))



def _clip_batch(poly: NDArray[np.float64], bary: NDArray[np.float64], count: NDArray[np.int64], bound: float,
                sign: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Sutherland–Hodgman on many polygons at once: the part of each polygon (vertices (ψ, r) ``poly`` (P, V, 2)
    with barycentrics ``bary`` (P, V, 3), the first ``count`` of V in use) with sign·(ψ − bound) ≥ 0 (ψ ≥ −π,
    or ψ ≤ π). Vertex by vertex as the one-polygon rule: a vertex kept where it is inside, then the crossing of
    its edge to the next vertex where the edge crosses the bound (one polygon at a time made 9 000 calls on the
    Radiant file). Returns the clipped polygons (P, 2V, ·) and their vertex counts."""
    n_p, n_v = poly.shape[:2]
    out_p = np.zeros((n_p, 2 * n_v, 2))
    out_b = np.zeros((n_p, 2 * n_v, 3))
    if n_p == 0:
        return out_p, out_b, np.zeros(0, dtype=np.int64)
    rows = np.arange(n_p)
    emit = np.zeros((n_p, 2 * n_v), dtype=bool)
    cand_p = np.zeros((n_p, 2 * n_v, 2))
    cand_b = np.zeros((n_p, 2 * n_v, 3))
    for k in range(n_v):
        used = k < count
        nxt = np.where(used, (k + 1) % np.maximum(count, 1), 0)
        p, q = poly[:, k], poly[rows, nxt]
        b, c = bary[:, k], bary[rows, nxt]
        dp, dq = sign * (p[:, 0] - bound), sign * (q[:, 0] - bound)
        cross = used & ((dp >= 0) != (dq >= 0))
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(cross, dp / np.where(cross, dp - dq, 1.0), 0.0)[:, None]
        emit[:, 2 * k] = used & (dp >= 0)
        emit[:, 2 * k + 1] = cross
        cand_p[:, 2 * k], cand_b[:, 2 * k] = p, b
        cand_p[:, 2 * k + 1], cand_b[:, 2 * k + 1] = p + t * (q - p), b + t * (c - b)
    slot = np.cumsum(emit, axis=1) - 1
    r, col = np.nonzero(emit)
    out_p[r, slot[r, col]] = cand_p[r, col]
    out_b[r, slot[r, col]] = cand_b[r, col]
    return out_p, out_b, emit.sum(axis=1)


#: Dunavant's 7-point rule on a triangle (degree 5): barycentric points and weights summing to 1.
_A1, _B1, _A2, _B2 = 0.059715871789770, 0.470142064105115, 0.797426985353087, 0.101286507323456
_DUNAVANT_POINTS = np.array([[1 / 3, 1 / 3, 1 / 3], [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
                             [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2]])
_DUNAVANT_WEIGHTS = np.array([0.225] + [0.132394152788506] * 3 + [0.125939180544827] * 3)


def _locate(tri: Delaunay, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Simplices of the points q (s·ψ, r); a point just beyond the hull (the rim is a polygon through nodes on
    a curve) is moved inward along its radius to the hull's edge."""
    simplex = tri.find_simplex(q)
    bad = np.flatnonzero(simplex < 0)
    if bad.size:
        lo, hi = np.zeros(bad.size), q[bad, 1].copy()
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            ok = tri.find_simplex(np.stack([q[bad, 0], mid], axis=1)) >= 0
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        q = q.copy()
        q[bad, 1] = lo
        simplex[bad] = tri.find_simplex(q[bad])
        if (simplex[bad] < 0).any():
            raise InputError("direction outside the reconstructed disk", field="directions",
                             expected="directions above the horizon")
    return q, simplex


#: Shear that breaks the ties of a regular polar grid mirror-symmetrically (a cell's diagonal follows the sign of
#: the azimuth), so that data symmetric about the plane of incidence are interpolated symmetrically.
TIE_SHEAR = 1e-7


def _coords(psi: NDArray, r: NDArray, s: float, sin_psi: NDArray | None = None) -> NDArray[np.float64]:
    """Triangulation coordinates (s·ψ + shear, r) of polar points (``sin_psi``: sin ψ, or an array of its signs,
    when already known: the shear takes only its sign)."""
    sin_psi = np.sin(psi) if sin_psi is None else sin_psi
    return np.stack([s * psi + TIE_SHEAR * np.sign(sin_psi) * r, r], axis=1)


def _triangulate(psi: NDArray, r: NDArray, s: float) -> Delaunay:
    pts = np.ascontiguousarray(_coords(psi, r, s))
    # the error variants of one reconstruction (tail rules, lobe alternatives) triangulate the same points again
    key = (pts.shape, hashlib.blake2b(pts.tobytes(), digest_size=16).digest())
    tri = _TRIANGULATIONS.get(key)
    if tri is None:
        tri = qhull().Delaunay(pts, qhull_options="Qbb Qc Qz Q12")
        if getattr(tri, "_transform", 0) is None:  # scipy computes it lazily, one LAPACK call per simplex
            tri._transform = barycentric_transforms(tri.points, tri.simplices)
        _TRIANGULATIONS[key] = tri
        while len(_TRIANGULATIONS) > _TRIANGULATIONS_KEPT:
            _TRIANGULATIONS.pop(next(iter(_TRIANGULATIONS)))
    return tri


#: The last few triangulations by their points (a reconstruction and its error variants share most of them).
_TRIANGULATIONS: dict[tuple, Delaunay] = {}
_TRIANGULATIONS_KEPT = 8


def barycentric_transforms(points: NDArray[np.float64], simplices: NDArray[np.int64]) -> NDArray[np.float64]:
    """The affine maps to barycentric coordinates of 2-D triangles, as :attr:`scipy.spatial.Delaunay.transform`
    holds them: (K, 3, 2), ``[:, :2]`` = T⁻¹ with T[:, j] = p_j − p_2 and ``[:, 2]`` = p_2; NaN for a triangle whose
    1-norm reciprocal condition number is below 1000 ε (scipy's rule for a degenerate simplex).

    scipy computes them lazily with one LU factorisation and condition estimate per triangle; with a threaded BLAS
    on a loaded 2-core machine that took 0.5-4 s for 28 000 triangles (0.2 s single-threaded), this closed form
    a few milliseconds. Every :func:`~scipy.spatial.Delaunay.find_simplex` needs it.

    Parameters
    ----------
    points : ndarray
        Vertex coordinates (N, 2), in the units of the triangulated plane.
    simplices : ndarray
        Vertex indices of the triangles (K, 3).

    Returns
    -------
    ndarray
        (K, 3, 2) transforms, NaN for degenerate triangles.
    """
    p = points[simplices]  # (K, 3, 2)
    t = np.stack([p[:, 0] - p[:, 2], p[:, 1] - p[:, 2]], axis=2)  # (K, 2, 2): columns p0 − p2, p1 − p2
    a, b, c, d = t[:, 0, 0], t[:, 0, 1], t[:, 1, 0], t[:, 1, 1]
    det = a * d - b * c
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.stack([np.stack([d, -b], axis=1), np.stack([-c, a], axis=1)], axis=1) / det[:, None, None]
        norm_t = np.maximum(np.abs(a) + np.abs(c), np.abs(b) + np.abs(d))
        norm_inv = np.maximum(np.abs(inv[:, 0, 0]) + np.abs(inv[:, 1, 0]), np.abs(inv[:, 0, 1]) + np.abs(inv[:, 1, 1]))
        rcond = 1.0 / (norm_t * norm_inv)
    out = np.concatenate([inv, p[:, 2][:, None, :]], axis=1)
    out[~(rcond >= 1000.0 * np.finfo(np.float64).eps)] = np.nan
    return out


def _periodic(psi: NDArray, r: NDArray, node: NDArray, n_records: int | None = None
              ) -> tuple[NDArray, NDArray, NDArray]:
    """Points within a margin of the seam ψ = ±π copied across it (at ψ ± 2π): the margin is twice the widest
    azimuth gap between the records (nodes below ``n_records``; at least 30°), so that triangles across the seam
    join the same neighbours as anywhere else."""
    own = psi if n_records is None else psi[node < n_records]
    u = np.unique(np.round(own, 9))
    gap = float(np.max(np.diff(np.r_[u, u[0] + 2 * np.pi]))) if u.size > 1 else 2 * np.pi
    margin = min(np.pi, max(np.pi / 6, 2.0 * gap))
    near_lo, near_hi = psi < -np.pi + margin, psi >= np.pi - margin
    p = np.concatenate([psi, psi[near_lo] + 2 * np.pi, psi[near_hi] - 2 * np.pi])
    rr = np.concatenate([r, r[near_lo], r[near_hi]])
    nn = np.concatenate([node, node[near_lo], node[near_hi]])
    return p, rr, nn


def _rim_psi() -> NDArray[np.float64]:
    return (np.arange(N_RIM) + 0.5) * (2 * np.pi / N_RIM) - np.pi


@dataclass(frozen=True)
class Rim:
    """How a polar interpolant ends toward the horizon beyond its outermost records (:func:`build`).

    Attributes
    ----------
    rule
        ``trend`` | ``hold`` | ``zero``: the value on the horizon beyond the outermost data (module doc);
        ``ring``: zeros on the circle of ``radius`` (a lobe), the edge value held where the horizon cuts it.
    radius
        With ``rule="ring"``: the domain's radius about the centre [direction cosines].
    normal_centered
        The centre is the normal (θs = arcsin r: the trend's slope is taken in θs).
    reference
        Band-mean record values that decide the trend's clipping (between 0 and the last value).
    """

    rule: str = "trend"
    radius: float | None = None
    normal_centered: bool = True
    reference: NDArray[np.float64] | None = None


def _polar_records(x: NDArray[np.float64], y: NDArray[np.float64], center: tuple[float, float],
                   about_direction: float | None) -> tuple[NDArray, NDArray, NDArray[np.bool_], NDArray[np.int64]]:
    """The records' polar (ψ, r) about ``center`` (about the specular direction with ``about_direction``), which
    are at the centre, and the indices of the others (two or more)."""
    if x.size == 0:
        raise InputError("no usable records to reconstruct the hemisphere", field="bsdf",
                         expected="finite values")
    dx, dy = x - center[0], y - center[1]
    r = np.hypot(dx, dy)
    psi = np.arctan2(dy, dx)
    if about_direction is not None:
        psi, r = direction_polar(center, psi, r, about_direction)
    at_center = r < CENTER_TOL
    off = np.flatnonzero(~at_center)
    if off.size < 2:
        raise InputError("too few records off the centre to interpolate the hemisphere", field="bsdf",
                         expected="records at two or more directions")
    return psi, r, at_center, off


def _center_row(r: NDArray[np.float64], at_center: NDArray[np.bool_], off: NDArray[np.int64]) -> NDArray:
    """The centre value as a row over the records: the records there, else the mean of the innermost ring."""
    c_row = np.zeros(r.size)
    if at_center.any():
        c_row[at_center] = 1.0 / at_center.sum()
    else:
        inner = off[r[off] <= 1.5 * r[off].min() + 1e-12]
        c_row[inner] = 1.0 / inner.size
    return c_row


def _rim_rows(stage0: PolarInterpolant, tri0: Delaunay, rim: Rim, rim_psi: NDArray[np.float64]
              ) -> tuple[sp.csr_matrix, NDArray[np.float64], float | None]:
    """The rim nodes' rows over the records, their radii and the smallest extrapolated edge (None: none)."""
    n, s = stage0.n_records, stage0.azimuth_weight
    t_max = horizon_distance(stage0.center, rim_psi)
    if rim.rule == "ring":
        if rim.radius is None:
            raise InputError("a ring rim needs a radius", field="radius")
        top = np.minimum(t_max, rim.radius)
        # zeros on the ring; where the horizon cuts the ring, the lobe goes on: its edge value held there
        cut = t_max < rim.radius
        rim_rows = sp.csr_matrix((N_RIM, n))
        if cut.any():
            edge = np.minimum(_edge(tri0, rim_psi, t_max, s), top)
            rim_rows = (sp.diags(cut.astype(float)) @ stage0._matrix_polar(rim_psi, edge * (1.0 - 1e-9))).tocsr()
        return rim_rows, top, None
    edge = _edge(tri0, rim_psi, t_max, s)
    m_edge = stage0._matrix_polar(rim_psi, edge * (1.0 - 1e-9))
    gap = t_max - edge > 1e-6
    extrapolated = float(edge[gap].min()) if gap.any() else None
    if rim.rule == "hold" or not gap.any():
        rim_rows = m_edge
    elif rim.rule == "zero":
        rim_rows = sp.diags((~gap).astype(float)) @ m_edge
    elif rim.rule == "trend":
        rim_rows = _trend_rows(stage0, rim_psi, edge, t_max, m_edge, rim.normal_centered, rim.reference)
    else:
        raise InputError("unknown rim rule", field="rim", expected="trend, hold, zero or ring", got=rim.rule)
    return rim_rows, t_max, extrapolated


def build(x: NDArray[np.float64], y: NDArray[np.float64], center: tuple[float, float], *,
          rim: Rim | None = None, azimuth_weight: float = AZIMUTH_WEIGHT, spokes: bool = False,
          about_direction_deg: float | None = None) -> PolarInterpolant:
    """The polar interpolant of records at β = (x, y) about ``center``.

    Parameters
    ----------
    x, y
        Record positions [direction cosines] in the frame of the incidence (x toward the specular side).
    center
        Centre of the polar coordinates [direction cosines].
    rim
        How the interpolant ends beyond the outermost records (:class:`Rim`; default: the trend, about the normal).
    azimuth_weight
        s of the triangulation metric (s·ψ, r) [direction cosines per radian].
    spokes
        The records are a polar grid about ``center`` (straight spokes in β, as a Harvey–Shack table): each spoke
        is held at its outermost value beyond it (as the table's own readers do), instead of a rim; the horizon
        then cuts a domain that the spokes fill.
    about_direction_deg
        With ``spokes``: the incidence [deg] of a grid whose spokes are great circles through the specular
        *direction* (a Zemax table: radial angle and azimuth about it); interpolated in those coordinates.

    Returns
    -------
    PolarInterpolant
    """
    rim = Rim() if rim is None else rim
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    n = x.size
    psi, r, at_center, off = _polar_records(x, y, center, about_direction_deg)
    rim_psi = _rim_psi()
    i_center = n
    # stage 1: records + centre line
    p0 = np.concatenate([psi[off], rim_psi])
    r0 = np.concatenate([r[off], np.zeros(N_RIM)])
    n0 = np.concatenate([off, np.full(N_RIM, i_center)])
    rows_c = sp.csr_matrix(_center_row(r, at_center, off)[None, :])
    base = sp.vstack([sp.identity(n, format="csr"), rows_c]).tocsr()
    if spokes:
        return _with_spokes(center, psi, r, off, base, azimuth_weight, about_direction_deg)
    pp, rr, nn = _periodic(p0, r0, n0, n)
    try:
        tri0 = _triangulate(pp, rr, azimuth_weight)
    except qhull().QhullError as exc:
        raise InputError("records are degenerate on the disk (all on one line through the centre)",
                         field="bsdf", expected="records spanning an area of the disk") from exc
    stage0 = PolarInterpolant(center, tri0, nn.astype(np.int64), base, n, None, None, azimuth_weight)
    rim_rows, top, extrapolated = _rim_rows(stage0, tri0, rim, rim_psi)
    nodes = sp.vstack([base, rim_rows]).tocsr()
    i_rim = n + 1 + np.arange(N_RIM)
    p1 = np.concatenate([p0, rim_psi])
    r1 = np.concatenate([r0, top])
    n1 = np.concatenate([n0, i_rim])
    radius = rim.radius
    if radius is not None:  # a lobe: only the records inside its ring
        keep = r1 <= np.concatenate([np.minimum(radius, horizon_distance(center, p0)), top]) + 1e-12
        p1, r1, n1 = p1[keep], r1[keep], n1[keep]
    pp, rr, nn = _periodic(p1, r1, n1, n)
    tri = _triangulate(pp, rr, azimuth_weight)
    return PolarInterpolant(center, tri, nn.astype(np.int64), nodes, n, radius, extrapolated, azimuth_weight)


def _edge(tri: Delaunay, psi: NDArray, t_max: NDArray, s: float) -> NDArray[np.float64]:
    """Outermost radius of the triangulation's hull along each azimuth, at most t_max."""
    hull = tri.convex_hull  # (E, 2) point indices
    p = tri.points[hull]  # (E, 2, 2)
    x = s * psi
    a, b = np.minimum(p[:, 0, 0], p[:, 1, 0]), np.maximum(p[:, 0, 0], p[:, 1, 0])
    span = p[:, 1, 0] - p[:, 0, 0]
    t = (x[:, None] - p[None, :, 0, 0]) / np.where(np.abs(span) > 0, span, np.inf)[None, :]
    r = p[None, :, 0, 1] + t * (p[None, :, 1, 1] - p[None, :, 0, 1])
    spans = (x[:, None] >= a[None, :] - 1e-15) & (x[:, None] <= b[None, :] + 1e-15)
    edge = np.max(np.where(spans, r, -np.inf), axis=1)
    return np.clip(edge, 0.0, t_max)


def _trend_rows(stage0: PolarInterpolant, psi: NDArray, edge: NDArray, t_max: NDArray, m_edge: sp.csr_matrix,
                normal_centered: bool, reference: NDArray | None) -> sp.csr_matrix:
    """Horizon values along the slope of the last :data:`TREND_SPAN_DEG` inside the data edge, kept between 0
    and the edge value on the reference profile (a body rising toward the horizon is held, not raised)."""
    if normal_centered:
        th_edge = np.arcsin(np.clip(edge, 0.0, 1.0))
        th_in = np.maximum(th_edge - np.radians(TREND_SPAN_DEG), 0.0)
        r_in = np.sin(th_in)
        gone = np.arcsin(np.clip(t_max, 0.0, 1.0)) - th_edge
        span = th_edge - th_in
    else:
        r_in = np.maximum(edge - np.sin(np.radians(TREND_SPAN_DEG)), 0.0)
        gone, span = t_max - edge, edge - r_in
    m_in = stage0._matrix_polar(psi, r_in)
    slope = sp.diags(np.where(span > 1e-9, gone / np.where(span > 1e-9, span, 1.0), 0.0)) @ (m_edge - m_in)
    rows = (m_edge + slope).tocsr()
    if reference is not None:
        ref = np.nan_to_num(reference)
        v_edge, v = m_edge @ ref, rows @ ref
        hold = v > v_edge  # rising: hold the edge value
        zero = v < 0
        keep = ~(hold | zero)
        rows = (sp.diags(keep.astype(float)) @ rows + sp.diags(hold.astype(float)) @ m_edge).tocsr()
    return rows


#: Spokes of a polar grid are held out to this distance from the centre (beyond any horizon: |β − β0| < 2).
SPOKE_END = 2.0


def _with_spokes(center: tuple[float, float], psi: NDArray, r: NDArray, off: NDArray[np.int64],
                 base: sp.csr_matrix, s: float, about_direction: float | None = None) -> PolarInterpolant:
    """A polar grid about ``center``: every spoke (records at one azimuth) held at its outermost value out to
    :data:`SPOKE_END`, so that the triangulation fills the whole disk between spokes (no rim)."""
    n, rim_psi = base.shape[1], _rim_psi()
    key = np.round(psi[off] / 1e-6).astype(np.int64)
    ends_p, ends_n = [], []
    for k in np.unique(key):
        members = off[key == k]
        last = members[np.argmax(r[members])]
        ends_p.append(psi[last])
        ends_n.append(last)
    ends_p, ends_n = np.asarray(ends_p), np.asarray(ends_n, dtype=np.int64)
    p1 = np.concatenate([psi[off], rim_psi, ends_p])
    end = SPOKE_END if about_direction is None else np.pi  # beyond the horizon in either coordinates
    r1 = np.concatenate([r[off], np.zeros(N_RIM), np.full(ends_p.size, end)])
    n1 = np.concatenate([off, np.full(N_RIM, n), ends_n])
    pp, rr, nn = _periodic(p1, r1, n1, n)
    tri = _triangulate(pp, rr, s)
    return PolarInterpolant(center, tri, nn.astype(np.int64), base, n, None, None, s, about_direction)


def direction_polar(center: tuple[float, float], psi: NDArray, r: NDArray, theta_i_deg: float,
                    cos_sin: tuple[NDArray, NDArray] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(azimuth about the specular direction, angle from it) [rad] of the points at polar (ψ, r) about
    ``center`` in β (the frame of the incidence: +x toward the specular side).

    Parameters
    ----------
    center : tuple of float
        Polar centre (βx, βy) in direction cosines [-].
    psi : ndarray
        Azimuths about the centre [rad].
    r : ndarray
        Distances from the centre in direction cosines [-].
    theta_i_deg : float
        Incidence angle [deg], which fixes the specular direction.
    cos_sin : tuple of ndarray, optional
        (cos ψ, sin ψ) [-] when already known.

    Returns
    -------
    tuple of ndarray
        Azimuth about the specular direction [rad] and polar angle from it [rad].
    """
    cos_psi, sin_psi = (np.cos(psi), np.sin(psi)) if cos_sin is None else cos_sin
    x = center[0] + r * cos_psi
    y = center[1] + r * sin_psi
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, 1.0))
    ti = np.radians(theta_i_deg)
    along = x * np.cos(ti) - z * np.sin(ti)  # on e1 = (cos θi, 0, −sin θi)
    cos_a = np.clip(x * np.sin(ti) + z * np.cos(ti), -1.0, 1.0)
    return np.arctan2(y, along), np.arccos(cos_a)

