"""Directional-hemispherical reflectance and transmittance of elastic scatter, any sample, with error bars.

The quantity is the TIS of :mod:`bsdfkit.reduction.tis` per wavelength: ρ(θi, λ) = ∬_{|β| ≤ 1} f dβx dβy in
Harvey–Shack direction cosines, for each configuration, incidence and side a calibrated dataset holds
(reflection-only, transmission-only, monochrome and many-wavelength scans alike).

Decomposition (why one centre is not enough)
    The commonest real sample is a diffuse body plus a specular lobe. The body is symmetric about the NORMAL
    (it depends on |β| and, weakly, on the azimuth), the lobe about the SPECULAR point β0 = (sin θi, 0)
    (Harvey–Shack shift invariance). Reconstructing everything about β0 reads a body that darkens toward
    grazing at |β − β0| instead of |β| (a few % high at 10°, 10-20 % at 80°); about the normal, the lobe is
    smeared over a whole ring. So f = D + L:

    1. *Lobe region*: on the in-plane arc (and the perpendicular arc, if measured) the region around the
       specular point where the profile stands above a smooth floor, found on the band-mean profile by
       walking outward from the highest sample within ±:data:`PEAK_WINDOW` of β0 until the profile is locally
       straight at two successive samples (:func:`_straightness`: within :data:`TAIL_EXCESS` (2 %) + 2u of the line
       through the next three samples, and within three times that of the line through the samples up to
       :data:`WIDE_WINDOW` outward; a convex lobe tail lies above such lines, a concave core below) and has
       stopped falling (by at most :data:`EDGE_DROP` of its fall from the peak over the next
       :data:`WIDE_WINDOW`). An edge still on a finely sampled flat top is searched again farther out; the
       shorter side is then extended to the radius of the longer (a Harvey–Shack lobe has one radius in every
       direction), and the perpendicular arc's region to that radius too. No lobe when both walks stop at the
       peak. The lobe's centre is the vertex of the parabola through ln f at the three highest in-plane
       samples (β0 itself when the lobe sits where expected; a tilted sample moves it).
       The region then grows one sample per edge until the body outside it is symmetric about the normal
       (RMS relative asymmetry ≤ :data:`BODY_ASYMMETRY`, :func:`_grown_until_symmetric`): a broad lobe sampled
       finely near specular and coarsely beyond stops the walk on the fine samples and would leave its wings in
       the body.
    2. *Body D*: the records outside the lobe region, reconstructed about the normal with
       :class:`~bsdfkit.reduction.tis.Hemisphere` (``center="normal"``); under the lobe it interpolates
       linearly between the edges.
    3. *Lobe L*: the residuals f − D at the records in the region (0 elsewhere), reconstructed about the lobe's
       centre with the same machinery (``center="specular"``), so that D + L equals the data at every measured
       record. The lobe is integrated with ln-f interpolation between samples (the ratio of its ln-f to its
       linear integral on the band-mean profile scales the linear weights); a lobe sampled more than
       :data:`UNDER_SAMPLED_STEP` σ apart is integrated as the Gaussian through ln L at its three highest
       in-plane samples instead (:func:`_gaussian_lobe_tis`), the ln-f integral then entering the error bar.

    Both parts, and so ρ(λ) = Σ_k c_k f_k(λ), are linear in the data for a given region: the region and the tail
    rule are chosen once per incidence and side on the band-mean profile, then every wavelength is one dot
    product. A half-axis of the body that ends before 90° is extrapolated to |β| = 1 (and, where a lobe region
    reaches the data end, bridged under it) by the *trend*: its last value plus the least-squares slope (in θs)
    of its last three samples times the angle gone on, kept between 0 and the last value.

Error bars
    ``std_measurement``: per-record standard uncertainties through the weights c_k (independent), plus the
    scale common to all records (``incident_relative_std`` of the configuration, or
    ``attrs['common_relative_std']``). ``std_reconstruction``: in quadrature, for each group of alternative
    reconstructions the largest |alternative − central|:

    * ``tail``: beyond the last measured angle the body held at its last value, or going linearly to 0 at 90°
      (only when something is extrapolated; the angle is reported as ``extrapolated_beyond_deg``);
    * ``azimuth``: with in-plane data only, the body's and the lobe's perpendicular half-profiles are the
      mean of the two in-plane halves (central), or either half alone; with both arcs the blend exponent
      2 → 1 or 4;
    * ``separation``: the lobe region one and two samples wider at each edge;
    * ``interpolation``: the lobe integrated with f instead of ln f interpolation (without a lobe: the whole
      profile with ln f instead of f);
    * ``quadrature``: the polar grid halved.

    The single-centre reconstructions (everything about β0, everything about the normal) are reported in the
    components for comparison; they are not folded in when a lobe is found, because each one contradicts the
    symmetry of one part (they are exact only for the part whose centre they use).

Assumptions are returned in words with every result (``assumptions``); with in-plane data only the key one is
that the body is rotationally symmetric about the normal and the lobe about the specular point.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import InputError
from bsdfkit.core.hemisphere import linear_weights
from bsdfkit.core.records import incidences
from bsdfkit.core.spectra import band_mask
from bsdfkit.reduction import basis, disk
from bsdfkit.reduction.tis import HALVES, Hemisphere, polar_grid

#: Half-width (in direction cosines) of the window around β0 in which the lobe's peak is looked for.
PEAK_WINDOW = 0.1
#: Width (direction cosines) of the wider window of the straightness test.
WIDE_WINDOW = 0.1
#: A floor edge falls over the next three samples by at most this fraction of the drop from the peak.
EDGE_DROP = 0.2
#: Relative excess over the outward secant that marks a lobe tail.
TAIL_EXCESS = 0.02
#: Angles (deg) at or beyond which a half-profile counts as reaching the horizon (no extrapolation).
HORIZON_DEG = 89.9

@dataclass(frozen=True)
class Geometry:
    """Per-record directions of one profile (one configuration, incidence and side)."""

    theta_i: float  # deg
    phi_i: float  # deg
    theta_s: NDArray[np.float64]  # deg
    phi_s: NDArray[np.float64]  # deg
    arc: NDArray[np.str_]
    side: str
    #: projected solid angle [sr] of the basis cell each record stands for (records of a file in an angle basis,
    #: :mod:`bsdfkit.reduction.basis`), else None
    basis_psa: NDArray[np.float64] | None = None
    #: index of the basis cell each record lies in, and the basis (:func:`bsdfkit.reduction.basis.cell_index`):
    #: the file's BSDF is then evaluated by exact cell lookup; else None (nearest record)
    basis_cell: NDArray[np.int64] | None = None
    basis_spec: str | None = None

    @property
    def n(self) -> int:
        return self.theta_s.size

    def frame(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(x, y): direction cosines along +α (toward the specular side) and perpendicular to it (read-only)."""
        return self._frame

    @functools.cached_property
    def _frame(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # once per geometry: a reduction asked for it 9 times per profile (0.4 s of a 12 800-record table's read)
        ts, ps = np.radians(self.theta_s), np.radians(self.phi_s)
        u = np.radians(self.phi_i) - np.pi
        a, b = np.sin(ts) * np.cos(ps), np.sin(ts) * np.sin(ps)
        x, y = a * np.cos(u) + b * np.sin(u), -a * np.sin(u) + b * np.cos(u)
        x.setflags(write=False)
        y.setflags(write=False)
        return x, y

    def dataset(self, keep: NDArray[np.int64], values: NDArray[np.float64] | None = None,
                extra_deg: list[tuple[float, float]] = (), theta_i_deg: float | None = None) -> xr.Dataset:
        """A profile dataset of the records ``keep`` plus virtual in-plane records (θs, φs) in ``extra_deg``;
        ``theta_i_deg`` [deg] overrides the incidence, which places the specular centre of a reconstruction.

        Parameters
        ----------
        keep : ndarray of int
            Indices of the records to keep.
        values : ndarray, optional
            ``bsdf`` per output record [1/sr] (default: zeros).
        extra_deg : list of tuple of float
            Virtual in-plane records (θs, φs) [deg].
        theta_i_deg : float, optional
            Incidence [deg] (default: the profile's).

        Returns
        -------
        xarray.Dataset
            ``bsdf`` over ``record`` with coordinates ``theta_i``, ``phi_i``, ``theta_s``, ``phi_s`` [deg], ``side``,
            ``arc``.
        """
        ts = np.concatenate([self.theta_s[keep], [e[0] for e in extra_deg]])
        ps = np.concatenate([self.phi_s[keep], [e[1] for e in extra_deg]])
        arc = np.concatenate([self.arc[keep], ["in_plane"] * len(extra_deg)])
        n = ts.size
        v = np.zeros(n) if values is None else np.asarray(values, dtype=np.float64)
        th = self.theta_i if theta_i_deg is None else theta_i_deg
        return xr.Dataset({"bsdf": ("record", v)},
                          coords={"theta_i": ("record", np.full(n, th)),
                                  "phi_i": ("record", np.full(n, self.phi_i)),
                                  "theta_s": ("record", ts), "phi_s": ("record", ps),
                                  "side": ("record", np.array([self.side] * n)), "arc": ("record", arc)})


@dataclass(frozen=True)
class Region:
    """The lobe region: record indices (into the profile) and its in-plane extent (signed θs, deg)."""

    records: NDArray[np.int64]
    in_plane_deg: tuple[float, float] | None
    perpendicular_deg: tuple[float, float] | None = None
    center_deg: float | None = None  # lobe centre: signed in-plane θs of the peak (deg)
    arcs: tuple = ()  # (record order along the arc, index of the lower edge, of the upper edge) per arc

    def grown(self, geom: Geometry, k: int) -> "Region":
        """The region with every edge moved outward by k samples (inward for k < 0).

        Parameters
        ----------
        geom : Geometry
            Per-record directions of the profile.
        k : int
            Number of samples each edge moves outward (inward for k < 0).

        Returns
        -------
        Region
        """
        return _region(geom, list(self.arcs), self.center_deg, k)


@dataclass
class Reconstruction:
    """Weights c (per profile record) of the central reconstruction and of every alternative."""

    central: NDArray[np.float64]
    alternatives: dict[str, dict[str, NDArray[np.float64]]]  # group -> name -> weights
    comparisons: dict[str, NDArray[np.float64]]  # single-centre reconstructions (not folded in)
    lobe: NDArray[np.float64]  # weights of the lobe part alone (central)
    region: Region
    extrapolated_beyond_deg: float | None
    assumptions: list[str]
    method: str
    #: f at directions from record values: ``evaluate(values (n,), directions (m, 3)) -> (m,)`` [1/sr]; the
    #: pointwise reconstruction whose integral is ``central @ values`` (what an exported table samples)
    evaluate: Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]] | None = None


# ------------------------------------------------------------------------------------------- lobe region
@dataclass(frozen=True)
class _Straightness:
    """:func:`_straightness` of every sample of a sorted profile for one walking direction, as lists (the walk reads
    them one sample at a time): ``ok[j]``, ``tol[j]`` and ``far[j]``, the index of the last sample within
    :data:`WIDE_WINDOW` outward when there are three or more of them, else −1."""

    ok: list[bool]
    tol: list[float]
    far: list[int]


def _line_at(x: NDArray, g: NDArray, idx: NDArray[np.int64], use: NDArray[np.bool_],
             at: NDArray) -> NDArray[np.float64]:
    """Least-squares lines through the samples ``idx[j, use[j]]`` evaluated at ``at[j]``, one per row (rows with
    fewer than two samples give NaN). Centred closed form (x̄, ḡ, Σ dx dg / Σ dx²) instead of one
    :func:`numpy.polyfit` per row: the walks of a table's profiles made 17 600 such fits (13 s); it agrees with
    polyfit to rounding. A row whose samples share one x (no slope) is fitted by polyfit as before."""
    w = use.astype(np.float64)
    cnt = w.sum(axis=1)
    xs, gs = x[idx] * w, g[idx] * w
    with np.errstate(invalid="ignore", divide="ignore"):
        xm, gm = xs.sum(axis=1) / cnt, gs.sum(axis=1) / cnt
        dx = (x[idx] - xm[:, None]) * w
        sxx = np.sum(dx * dx, axis=1)
        slope = np.sum(dx * (g[idx] - gm[:, None]) * w, axis=1) / sxx
        pred = gm + slope * (at - xm)
    pred[cnt < 2] = np.nan
    # samples at one x (their mean may round off it, leaving a spurious Σ dx² > 0): polyfit's answer, as before
    one_x = np.where(use, x[idx], np.inf).min(axis=1) == np.where(use, x[idx], -np.inf).max(axis=1)
    for j in np.flatnonzero((cnt >= 2) & (one_x | ~(sxx > 0))):
        k = idx[j, use[j]]
        pred[j] = np.polyval(np.polyfit(x[k], g[k], 1), at[j])
    return pred


def _straightness(x: NDArray, g: NDArray, s: NDArray, step: int, tail_excess: float) -> _Straightness:
    """Whether g is locally straight at each sample j walking in direction ``step`` (±1), and the tolerance used.

    Two scales: the least-squares line through the next three samples outward must pass within
    τ·|line| + 2u_j of g_j, and the line through the samples up to :data:`WIDE_WINDOW` outward within three
    times that (a lobe wide compared with the sampling step is straight on the first scale only). With one
    sample outward, g_j is compared with it at the wide tolerance; (False, 0) without samples outward. Every
    sample at once (``x`` ascending): the walk asks at most twice per sample, formerly one fit each.
    """
    n = x.size
    j = np.arange(n)
    # the next three samples outward
    outer = j[:, None] + step * np.arange(1, 4)[None, :]
    o_use = (outer >= 0) & (outer < n)
    outer = np.clip(outer, 0, n - 1)
    m_o = o_use.sum(axis=1)
    pred_o = np.where(m_o == 1, g[outer[:, 0]], _line_at(x, g, outer, o_use, x))
    t_o = np.where(m_o > 1, 1.0, 3.0) * tail_excess * np.abs(pred_o) + 2.0 * s
    ok = np.abs(g - pred_o) <= t_o
    tol = np.where(m_o > 0, t_o, 0.0)
    # the samples up to WIDE_WINDOW outward (x sorted: a run from j + step; its length bounded by a search)
    lo = np.searchsorted(x, x - WIDE_WINDOW - 1e-9, side="left")
    hi = np.searchsorted(x, x + WIDE_WINDOW + 1e-9, side="right")
    reach = int(np.max(hi - 1 - j if step > 0 else j - lo, initial=0)) + 1
    far = np.full(n, -1, dtype=np.int64)
    rows = max(1, _WALK_BLOCK // reach)  # bounded memory on densely sampled profiles
    for b in range(0, n, rows):
        jb = j[b:b + rows]
        wide = jb[:, None] + step * np.arange(1, reach + 1)[None, :]
        w_use = (wide >= 0) & (wide < n)
        wide = np.clip(wide, 0, n - 1)
        w_use &= np.abs(x[wide] - x[jb, None]) <= WIDE_WINDOW
        m_w = w_use.sum(axis=1)
        pred_w = _line_at(x, g, wide, w_use, x[jb])
        t_w = 3.0 * tail_excess * np.abs(pred_w) + 2.0 * s[jb]
        fit = m_w >= 2
        k = jb[fit]
        ok[k] &= np.abs(g[k] - pred_w[fit]) <= t_w[fit]
        tol[k] = np.maximum(tol[k], t_w[fit])
        # the last sample of the run (x sorted: the run is a prefix of the offsets)
        far[jb[m_w >= 3]] = wide[m_w >= 3, m_w[m_w >= 3] - 1]
    ok &= m_o > 0
    return _Straightness(ok.tolist(), tol.tolist(), far.tolist())


#: Rows × offsets of one block of :func:`_straightness`'s wide-window fits.
_WALK_BLOCK = 1 << 20


def _walk(x: NDArray, g: NDArray, s: NDArray, start: int, step: int, tail_excess: float,
          min_fall: float = 0.0, straight: _Straightness | None = None) -> int:
    """Index of the floor's edge walking from the peak ``start`` in direction ``step`` (±1); −1 or len(x) when
    the profile never reaches the floor before the data end.

    Sample j is the edge when the profile is locally straight at j and at the next sample outward (a lobe's
    convex tail lies above the line through the samples outward, its concave core below), and over the next
    samples (up to :data:`WIDE_WINDOW`) falls by at most :data:`EDGE_DROP` of what it has already fallen from
    the peak (this rejects the inflection point of a broad lobe, where the profile is straight but steep), and
    it lies at least ``min_fall`` below the peak. ``straight``: :func:`_straightness` of the profile for ``step``
    (computed when not given).
    """
    st = straight if straight is not None else _straightness(x, g, s, step, tail_excess)
    gl = g.tolist()
    n = x.size
    top = gl[start]
    j = start
    while 0 <= j < n:
        if not 0 <= j + step < n:
            return j + step  # lobe runs to the data end
        if top - gl[j] < min_fall:
            j += step
            continue
        far = gl[st.far[j]] if st.far[j] >= 0 else gl[min(max(j + 3 * step, 0), n - 1)]
        settled = abs(gl[j] - far) <= EDGE_DROP * abs(top - gl[j]) + st.tol[j]
        if st.ok[j] and settled:
            if st.ok[j + step] or not 0 <= j + 2 * step < n:
                return j
        j += step
    return j


def _edges(x: NDArray, g: NDArray, s: NDArray, p: int, tail_excess: float) -> tuple[int, int]:
    """Both floor edges around the peak p. An edge that has not fallen half-way from the peak to the other
    edge (a lobe's flat top, sampled finely) is searched again farther out with that fall required."""
    down, up = (_straightness(x, g, s, step, tail_excess) for step in (-1, +1))
    lo = _walk(x, g, s, p, -1, tail_excess, straight=down)
    hi = _walk(x, g, s, p, +1, tail_excess, straight=up)
    n = x.size
    g_lo = g[lo] if 0 <= lo < n else np.nan
    g_hi = g[hi] if 0 <= hi < n else np.nan
    if np.isfinite(g_lo) and np.isfinite(g_hi):
        half_lo, half_hi = 0.5 * (g[p] - g_hi), 0.5 * (g[p] - g_lo)
        if g[p] - g_lo < half_lo:
            lo = _walk(x, g, s, p, -1, tail_excess, half_lo, down)
        if g[p] - g_hi < half_hi:
            hi = _walk(x, g, s, p, +1, tail_excess, half_hi, up)
    elif np.isfinite(g_lo) and lo == p:  # the other side runs to the data end: so must this one's flat top
        lo = _walk(x, g, s, p, -1, tail_excess, 0.5 * (g[p] - np.min(g)), down)
    elif np.isfinite(g_hi) and hi == p:
        hi = _walk(x, g, s, p, +1, tail_excess, 0.5 * (g[p] - np.min(g)), up)
    return lo, hi


def find_region(geom: Geometry, g: NDArray[np.float64], s: NDArray[np.float64],
                tail_excess: float = TAIL_EXCESS) -> Region:
    """The lobe region of a profile from its band-mean values ``g`` and their uncertainties ``s`` (module doc).

    Parameters
    ----------
    geom : Geometry
        Per-record directions of the profile.
    g : ndarray
        Band-mean BSDF per record [1/sr] (NaN = no data).
    s : ndarray
        Standard uncertainty of ``g`` [1/sr].
    tail_excess : float
        Relative excess over the outward secant that marks a lobe tail [-].

    Returns
    -------
    Region
        Record indices of the lobe and its extent [deg].
    """
    x, y = geom.frame()
    x0 = np.sin(np.radians(geom.theta_i))
    ok = np.isfinite(g)
    arcs: list[tuple[NDArray[np.int64], int, int]] = []
    center = None
    ip = np.flatnonzero(ok & (geom.arc == "in_plane"))
    if ip.size:
        order = ip[np.argsort(x[ip], kind="stable")]
        xs, gs, ss = x[order], g[order], s[order]
        near = np.flatnonzero(np.abs(xs - x0) <= PEAK_WINDOW)
        if near.size:
            p = int(near[np.argmax(gs[near])])
            lo, hi = _edges(xs, gs, ss, p, tail_excess)
            if hi - lo > 1:
                center = _peak_vertex(xs, gs, p)
                radius = max(abs(xs[k] - center) for k in (lo, hi) if 0 <= k < xs.size) if (
                    0 <= lo or hi < xs.size) else np.inf
                lo, hi = _symmetric(np.abs(xs - center), lo, hi, p, radius)
                arcs.append((order, lo, hi))
    pp = np.flatnonzero(ok & (geom.arc == "perpendicular"))
    if arcs and pp.size:
        order = pp[np.argsort(y[pp], kind="stable")]
        ys, gs, ss = y[order], g[order], s[order]
        d = np.hypot(x[order] - center, ys)
        if d.min() <= PEAK_WINDOW:
            p = int(np.argmin(d))
            lo, hi = _edges(ys, gs, ss, p, tail_excess)
            lo, hi = _symmetric(d, lo, hi, p, radius)
            if hi - lo > 1:
                arcs.append((order, lo, hi))
    center_deg = None if center is None else float(np.degrees(np.arcsin(np.clip(center, -1.0, 1.0))))
    return _region(geom, arcs, center_deg)


def _symmetric(dist: NDArray, lo: int, hi: int, p: int, radius: float) -> tuple[int, int]:
    """Edges moved outward (never inward) so that the region reaches ``radius`` from the lobe centre on both
    sides of the peak p: a Harvey–Shack lobe has one radius in every direction, and noise or a sloping floor
    can stop one walk early."""
    n = dist.size
    while lo >= 0 and lo < p and dist[lo] < radius - 1e-12:
        lo -= 1
    while hi < n and hi > p and dist[hi] < radius - 1e-12:
        hi += 1
    return lo, hi


def _region(geom: Geometry, arcs: list[tuple[NDArray[np.int64], int, int]], center_deg: float | None,
            grow: int = 0) -> Region:
    """The Region of the samples strictly between the edges of each arc, edges moved out by ``grow`` samples."""
    x, y = geom.frame()
    members: list[int] = []
    extents: list[tuple[float, float] | None] = [None, None]
    for k, (order, lo, hi) in enumerate(arcs):
        inside = np.arange(max(lo + 1 - grow, 0), min(hi + grow, order.size))
        if inside.size == 0:
            continue
        members += order[inside].tolist()
        coord = (x if k == 0 else y)[order[inside]]
        ang = np.degrees(np.arcsin(np.clip(coord, -1.0, 1.0)))
        extents[k] = (float(ang.min()), float(ang.max()))
    return Region(np.array(sorted(set(members)), dtype=np.int64), extents[0], extents[1], center_deg,
                  tuple(arcs))


#: A lobe whose in-plane sample step exceeds this many of its Gaussian σ is integrated as a Gaussian.
UNDER_SAMPLED_STEP = 1.2


def _gaussian_lobe_tis(geom: Geometry, region: NDArray[np.int64], resid: NDArray[np.float64]) -> float | None:
    """∬ L dβ of an under-sampled lobe from the Gaussian through ln L at its three highest in-plane samples.

    Between samples more than :data:`UNDER_SAMPLED_STEP` σ apart, ln-f interpolation cuts the parabola of
    ln L under its chords (4-9 % low at 1.7 σ); the Gaussian through the three samples (a Harvey–Shack lobe
    isotropic in β, as the decomposition assumes) is exact for a Gaussian lobe. Its part outside the unit disk
    is removed along β_x. None when the lobe is resolved, or not peaked at an inner, positive triple."""
    x, _ = geom.frame()
    ip = np.flatnonzero(geom.arc[region] == "in_plane")
    if ip.size < 3:
        return None
    o = ip[np.argsort(x[region[ip]], kind="stable")]
    xs, ls = x[region[o]], resid[o]
    p = int(np.argmax(ls))
    fit = _log_parabola(xs, ls, p)
    if fit is None:
        return None
    a, b, c = fit
    sigma = float(np.sqrt(-1.0 / (2.0 * a)))
    step = float(np.max(np.diff(xs[p - 1:p + 2])))
    if step <= UNDER_SAMPLED_STEP * sigma:
        return None
    x0 = -b / (2.0 * a)
    peak = float(np.exp(c - b * b / (4.0 * a)))
    inside = 0.5 * (math.erf((1.0 - x0) / (np.sqrt(2.0) * sigma)) - math.erf((-1.0 - x0) / (np.sqrt(2.0) * sigma)))
    return 2.0 * np.pi * sigma**2 * peak * inside


def _unresolved_lobe_bound(geom: Geometry, region: Region, ref: NDArray[np.float64],
                           std: NDArray[np.float64]) -> float | None:
    """Upper bound U of ∬ L dβ for a lobe narrower than the sampling (one or two in-plane samples), else None.

    Such a lobe's width is not measured, only bounded: a Gaussian of peak L0 (the peak sample above the mean of
    its nearest in-plane neighbours outside the region) would have shown at the nearest neighbour, a distance
    d away, unless σ ≤ d/√(2 ln(L0/t)), t = twice the neighbours' standard uncertainty (at least 1 % of their
    level). So 0 < ∬ L dβ ≤ U = 2π σ_max² L0; the reconstruction reports U/2 ± U/2."""
    x, _ = geom.frame()
    members = region.records[geom.arc[region.records] == "in_plane"]
    if not 0 < members.size < 3:
        return None
    ip = np.flatnonzero(np.isfinite(ref) & (geom.arc == "in_plane"))
    outside = np.setdiff1d(ip, members)
    peak = int(members[np.argmax(ref[members])])
    lower, upper = outside[x[outside] < x[peak]], outside[x[outside] > x[peak]]
    neighbours = [int(a[np.argmax(x[a])]) for a in (lower,) if a.size] + \
                 [int(a[np.argmin(x[a])]) for a in (upper,) if a.size]
    if not neighbours:
        return None
    level = float(np.mean(ref[neighbours]))
    l0 = float(ref[peak]) - level
    d = float(min(abs(x[k] - x[peak]) for k in neighbours))
    t = max(2.0 * float(np.max(std[neighbours])), 0.01 * abs(level), 1e-300)
    if not l0 > 0 or not d > 0:
        return None
    sigma_max = d / np.sqrt(2.0 * np.log(l0 / t)) if l0 > t * np.e else d
    return float(2.0 * np.pi * sigma_max**2 * l0)


def _log_parabola(x: NDArray, g: NDArray, p: int) -> tuple[float, float, float] | None:
    """(a, b, c) of ln g = a x² + b x + c through sample p and its two neighbours (a Gaussian exactly), or None
    when p is an end sample, a value is not positive or the parabola does not open downward."""
    if p == 0 or p == x.size - 1 or not np.all(g[p - 1:p + 2] > 0):
        return None
    a, b, c = np.polyfit(x[p - 1:p + 2], np.log(g[p - 1:p + 2]), 2)
    return (float(a), float(b), float(c)) if a < 0 else None


def _peak_vertex(x: NDArray, g: NDArray, p: int) -> float:
    """In-plane position of a lobe's peak: vertex of the parabola through ln g at the highest sample and its
    neighbours (exact for a Gaussian lobe), kept within one sample step of the highest sample."""
    fit = _log_parabola(x, g, p)
    if fit is None:
        return float(x[p])
    a, b, _ = fit
    return float(np.clip(-b / (2 * a), x[p - 1], x[p + 1]))


# ------------------------------------------------------------------------------------------- linear maps
def _evaluation_matrix(hemi: Hemisphere, r: NDArray, psi: NDArray, p: float = 2.0) -> NDArray[np.float64]:
    """M such that hemi's linear reconstruction at polar points (r, ψ) is M @ values (records of hemi)."""
    coef = hemi.coefficients(r, psi, p)
    m = np.zeros((r.size, hemi.n_records))
    rows = np.arange(r.size)
    for k, name in enumerate(HALVES):
        for h, share in hemi.halves[name]:
            lo, hi, wl, wh = linear_weights(h.radius, r)
            a = coef[:, k] * share
            np.add.at(m, (rows, h.record[lo]), a * wl)
            np.add.at(m, (rows, h.record[hi]), a * wh)
    return m


def _weights(hemi: Hemisphere, n_psi: int, n_r: int, p: float = 2.0) -> NDArray[np.float64]:
    """Integration weights of ``hemi`` (linear reconstruction) with blend exponent ``p`` (as
    :meth:`Hemisphere.weights`, which has p = 2)."""
    if p == 2.0:
        return hemi.weights(n_psi, n_r)
    grid = polar_grid((float(np.hypot(*hemi.beta0)), 0.0), n_psi, n_r)
    coef = hemi.coefficients(grid.r, grid.psi, p)
    w = np.zeros(hemi.n_records)
    for k, name in enumerate(HALVES):
        for h, share in hemi.halves[name]:
            a = coef[:, k] * share * grid.w
            if h.radius.size == 1:
                w += np.bincount(h.record[:1], weights=[a.sum()], minlength=hemi.n_records)
                continue
            lo, hi, w_lo, w_hi = linear_weights(h.radius, grid.r)
            w += np.bincount(h.record[lo], weights=a * w_lo, minlength=hemi.n_records)
            w += np.bincount(h.record[hi], weights=a * w_hi, minlength=hemi.n_records)
    return w


def _polar(hemi: Hemisphere, geom: Geometry, idx: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    x, y = geom.frame()
    dx, dy = x[idx] - hemi.beta0[0], y[idx] - hemi.beta0[1]
    return np.hypot(dx, dy), np.arctan2(dy, dx)


def _with_perpendicular(hemi: Hemisphere, source: str) -> Hemisphere:
    """``hemi`` with both perpendicular half-axes replaced by the in-plane half ``source`` (azimuth bounds)."""
    halves = dict(hemi.halves)
    measured = dict(hemi.measured_range)
    halves["+beta"] = halves["-beta"] = halves[source]
    measured["+beta"] = measured["-beta"] = hemi.measured_range[source]
    return dataclasses.replace(hemi, halves=halves, measured_range=measured)


def _tail_rows(geom: Geometry, keep: NDArray[np.int64], finite: NDArray[np.bool_], x: NDArray, rule: str,
               ref: NDArray[np.float64]) -> tuple[list[tuple[float, float]], NDArray[np.float64], list[float]]:
    """Virtual in-plane records that end the body's half-profiles short of the horizon.

    On each in-plane half (about the normal) whose body samples ``keep`` stop before 90°: if the data go on
    (a lobe region reaching the data end), a record at the last measured angle by the *trend*; then a record at
    90° by ``rule``: "trend", "hold" (the last value) or "zero". The trend is the last value plus the
    least-squares slope in θs of the last three body samples times the angle gone on, kept between 0 and the
    last value on the band-mean profile (a body rising toward a lobe is its tail: not extrapolated upward).
    Returns the virtual records' (θs, φs), the matrix T (virtual × profile records) giving their values, and
    the last measured angle of every extrapolated half.
    """
    extra, rows, ends = [], [], []
    ip = keep[geom.arc[keep] == "in_plane"]
    every = np.flatnonzero(finite & (geom.arc == "in_plane"))
    phi_spec = (geom.phi_i - 180.0) % 360.0
    for sign, phi in ((1.0, phi_spec), (-1.0, (phi_spec + 180.0) % 360.0)):
        half = ip[sign * x[ip] >= -1e-12]
        if half.size == 0:
            continue
        ang = geom.theta_s[half]
        order = np.argsort(ang)
        half, ang = half[order], ang[order]
        data_end = float(geom.theta_s[every[sign * x[every] >= -1e-12]].max())
        if data_end >= HORIZON_DEG:
            continue
        last_row = np.zeros(geom.n)
        last_row[half[-1]] = 1.0
        slope = np.zeros(geom.n)
        if half.size >= 2:
            a = geom.theta_s[half[-3:]]
            slope[half[-3:]] = np.linalg.pinv(np.stack([np.ones_like(a), a], axis=1))[1]

        def trend(at: float, base: NDArray, since: float, slope: NDArray = slope) -> NDArray[np.float64]:
            row = base + (at - since) * slope
            value = row @ np.nan_to_num(ref)
            return np.zeros(geom.n) if value < 0 else base if value > base @ np.nan_to_num(ref) else row

        end_row = last_row
        if data_end > ang[-1] + 1e-9:  # bridge under the lobe to the data end
            end_row = trend(data_end, last_row, float(ang[-1]))
            extra.append((data_end, phi))
            rows.append(end_row)
        if rule == "trend":
            row = trend(90.0, end_row, max(data_end, float(ang[-1])))
        else:
            row = end_row if rule == "hold" else np.zeros(geom.n)
        rows.append(row)
        extra.append((90.0, phi))
        ends.append(data_end)
    t = np.array(rows) if rows else np.zeros((0, geom.n))
    return extra, t, ends


@dataclass(frozen=True)
class _ArcOptions:
    """One reconstruction of the arcs (:func:`_body_and_lobe`): the tail rule, the polar grid's azimuth and radius
    nodes, the perpendicular half-profiles ("mean" or an in-plane half), the blend exponent and the body's centre."""

    rule: str = "trend"
    n_psi: int = 256
    n_r: int = 400
    azimuth: str = "mean"
    p: float = 2.0
    body_center: str = "normal"


def _body_and_lobe(geom: Geometry, reg: Region, finite: NDArray[np.bool_], ref: NDArray[np.float64],
                   opts: _ArcOptions, with_kappa: bool = False) -> tuple:
    """Weights over profile records of the body (about the normal) and of the lobe (about its centre).

    Returns (body weights, lobe weights with linear interpolation, last measured angles of extrapolated halves,
    κ = lobe with ln-f interpolation / lobe with f interpolation on the band-mean profile if ``with_kappa``,
    else 1).
    """
    x, _ = geom.frame()
    n = geom.n
    region = reg.records
    outside = np.setdiff1d(np.flatnonzero(finite), region)
    extra, t, ends = _tail_rows(geom, outside, finite, x, opts.rule, ref)
    body = Hemisphere.from_profile(geom.dataset(outside, extra_deg=extra), center=opts.body_center)
    if opts.azimuth != "mean":
        body = _with_perpendicular(body, opts.azimuth)
    wb = _weights(body, opts.n_psi, opts.n_r, opts.p)
    # body weights back onto profile records: own records + virtual ones through T
    c_body = np.zeros(n)
    np.add.at(c_body, outside, wb[:outside.size])
    c_body += wb[outside.size:] @ t
    c_lobe = np.zeros(n)
    kappa = kappa_alt = 1.0
    lobe_parts: tuple | None = None
    if region.size:
        # body at the region's records, as a linear map of the profile records
        r, psi = _polar(body, geom, region)
        m = _evaluation_matrix(body, r, psi, opts.p)
        e = np.zeros((region.size, n))
        e[:, outside] += m[:, :outside.size]
        e += m[:, outside.size:] @ t
        resid = -e
        resid[np.arange(region.size), region] += 1.0  # residual_j = f_j − D(β_j) for region records
        lobe_keep = np.flatnonzero(finite)
        lobe_values = np.zeros(lobe_keep.size)
        pos = np.searchsorted(lobe_keep, region)
        lobe_values[pos] = resid @ np.nan_to_num(ref)
        center = min(max(reg.center_deg if reg.center_deg is not None else geom.theta_i, 0.0), 89.0)
        lobe = Hemisphere.from_profile(geom.dataset(lobe_keep, lobe_values, theta_i_deg=center), center="specular")
        if opts.azimuth != "mean":
            lobe = _with_perpendicular(lobe, opts.azimuth)
        wl = _weights(lobe, opts.n_psi, opts.n_r, opts.p)
        c_lobe = wl[pos] @ resid
        lobe_parts = (lobe_keep, pos, resid, center)
        linear = float(wl @ lobe_values)
        if with_kappa and linear > 0:
            kappa = float(np.clip(lobe.tis("log", opts.n_psi, opts.n_r) / linear, 0.5, 1.5))
            gauss = _gaussian_lobe_tis(geom, region, lobe_values[pos])
            if gauss is not None:  # an under-sampled lobe: its Gaussian integral, the ln-f one in the error bar
                kappa_alt, kappa = kappa, float(np.clip(gauss / linear, 0.5, 2.0))

    def evaluate(values: NDArray[np.float64], directions: NDArray[np.float64], k: float = 1.0) -> NDArray:
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        d = geom.dataset(outside, np.concatenate([v[outside], t @ v]), extra_deg=extra)
        out = Hemisphere.from_profile(d, center=opts.body_center).bsdf(directions)
        if lobe_parts is not None and k != 0.0:
            keep, at, res, centre = lobe_parts
            lv = np.zeros(keep.size)
            lv[at] = res @ v
            out = out + k * Hemisphere.from_profile(geom.dataset(keep, lv, theta_i_deg=centre),
                                                    center="specular").bsdf(directions)
        return out

    return c_body, c_lobe, ends, (kappa, kappa_alt), evaluate


def _mismatch(geom: Geometry, g: NDArray[np.float64], center: str) -> float:
    """RMS relative difference of the in-plane profile at equal distances on the two sides of the normal
    (``center="normal"``) or of the specular point; NaN with fewer than three matched distances."""
    x, _ = geom.frame()
    ip = np.flatnonzero(np.isfinite(g) & (geom.arc == "in_plane"))
    c = 0.0 if center == "normal" else float(np.sin(np.radians(geom.theta_i)))
    d = x[ip] - c
    plus, minus = ip[d > 1e-9], ip[d < -1e-9]
    if plus.size < 2 or minus.size < 2:
        return float("nan")
    dp, dm = x[plus] - c, c - x[minus]
    op, om = np.argsort(dp), np.argsort(dm)
    lo, hi = max(dp.min(), dm.min()), min(dp.max(), dm.max())
    at = np.union1d(dp, dm)
    at = at[(at >= lo) & (at <= hi)]
    if at.size < 3:
        return float("nan")
    fp = np.interp(at, dp[op], g[plus][op])
    fm = np.interp(at, dm[om], g[minus][om])
    scale = 0.5 * (np.abs(fp) + np.abs(fm))
    return float(np.sqrt(np.mean(((fp - fm) / np.where(scale > 0, scale, 1.0)) ** 2)))


#: RMS relative asymmetry about the normal above which the body outside a lobe region still holds lobe wings.
BODY_ASYMMETRY = 0.10
#: A hemispherical value above 1 by more than this many standard uncertainties is flagged as impossible.
IMPOSSIBLE_SIGMA = 2.0
#: At most this many samples are added to each edge of a lobe region to make the body symmetric.
MAX_GROWTH = 40


def _grown_until_symmetric(geom: Geometry, ref: NDArray[np.float64], region: Region) -> Region:
    """The lobe region grown sample by sample until the body outside it is symmetric about the normal.

    A broad lobe sampled finely near the specular direction and coarsely farther out can stop the edge walk on
    the fine samples; its wings then stay in the body, which the normal-centred reconstruction smears over a
    ring (100 % high at 80° in the extreme). Criterion: the in-plane body (records outside the region) has an
    RMS relative asymmetry about the normal (:func:`_mismatch`) of at most :data:`BODY_ASYMMETRY`, or too few
    matched distances remain to tell; otherwise the region grows by one sample per edge, at most
    :data:`MAX_GROWTH` times (the last region is kept)."""
    if not region.records.size:
        return region
    previous = None
    for k in range(MAX_GROWTH + 1):
        grown = region.grown(geom, k) if k else region
        if previous is not None and np.array_equal(grown.records, previous.records):
            return previous  # nothing left to grow into
        body = ref.copy()
        body[grown.records] = np.nan
        m = _mismatch(geom, body, "normal")
        if not np.isfinite(m) or m <= BODY_ASYMMETRY:
            return grown
        previous = grown
    return previous


def sampling_method(geom: Geometry, finite: NDArray[np.bool_]) -> str:
    """``basis`` when the records are the cells of an angle basis covering the hemisphere (a BSDF XML file: every
    record carries its cell's projected solid angle, :mod:`bsdfkit.reduction.basis`, and the finite ones cover
    the hemisphere): the BSDF is piecewise constant and its integral is the basis sum. Else ``arcs`` when every
    finite record lies on the in-plane arc or the perpendicular arc through the specular
    direction (half-profiles about the normal and the specular point, with the in-plane lobe rules: under-sampled
    and unresolved lobes), else ``disk`` (polar interpolation of every record over the projected disk,
    :mod:`bsdfkit.reduction.disk`): grids, C-planes, other planes, a φs = 90/270° arc, scattered records.

    Parameters
    ----------
    geom : Geometry
        Per-record directions of the profile.
    finite : ndarray of bool
        Which records hold finite data.

    Returns
    -------
    str
        ``basis``, ``arcs`` or ``disk``.
    """
    if geom.basis_psa is not None and basis.covers_hemisphere(geom.basis_psa[finite]):
        return "basis"
    on_arcs = np.isin(geom.arc[finite], ("in_plane", "perpendicular"))
    return "arcs" if bool(on_arcs.all()) else "disk"


def reconstruct(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64],
                n_psi: int = 256, n_r: int = 400, errors: bool = True) -> Reconstruction:
    """Central weights and alternatives for one profile (module docstring); ``ref`` is the band-mean profile
    (NaN = record without data), ``ref_std`` its standard uncertainty. The method follows
    :func:`sampling_method`. ``errors=False`` skips the alternative reconstructions (the value only).

    Parameters
    ----------
    geom : Geometry
        Per-record directions of the profile.
    ref : ndarray
        Band-mean BSDF per record [1/sr] (NaN = no data).
    ref_std : ndarray
        Standard uncertainty of ``ref`` [1/sr].
    n_psi, n_r : int
        Quadrature nodes in azimuth and radius of the polar grids.
    errors : bool
        Compute the alternative reconstructions (the reconstruction error).

    Returns
    -------
    Reconstruction
        Weights per record [sr] of the central value and of every alternative.
    """
    finite = np.isfinite(ref)
    if not finite.any():
        raise InputError("no usable records to reconstruct the hemisphere", field="bsdf",
                         expected="finite values on an arc")
    method = sampling_method(geom, finite)
    if method == "basis":
        return _reconstruct_basis(geom, finite)
    if method == "disk":
        return _reconstruct_disk(geom, ref, ref_std, n_psi, n_r, errors)
    return _reconstruct_arcs(geom, ref, ref_std, n_psi, n_r, errors)


def _reconstruct_basis(geom: Geometry, finite: NDArray[np.bool_]) -> Reconstruction:
    """Records that are the cells of an angle basis: the central weights are the cells' projected solid angles
    (the basis sum, :func:`bsdfkit.reduction.basis.basis_sum`), exact for the piecewise-constant BSDF the file
    defines, so no alternative reconstruction. The pointwise BSDF is the value of the cell the direction lies in:
    found exactly when the records carry their cells (:func:`bsdfkit.reduction.basis.cell_index`), else the value
    of the nearest record in the projected disk (the cell containing the direction, up to the cells' shapes)."""
    psa = np.where(finite, geom.basis_psa, 0.0)
    if geom.basis_spec == basis.NORMAL_GRID:  # a full table about the normal: its own interpolant, not cells
        return _reconstruct_normal_grid(geom, finite, psa)
    evaluate = _cell_lookup(geom, finite)
    if evaluate is None:
        evaluate = _nearest_record(geom, finite)
    return Reconstruction(central=psa, alternatives={}, comparisons={}, lobe=np.zeros(geom.n),
                          region=Region(records=np.zeros(0, dtype=np.int64), in_plane_deg=None),
                          extrapolated_beyond_deg=None,
                          assumptions=["the records are the cells of the file's angle basis (Klems patches or "
                                       "tensor-tree leaves): the BSDF is constant over each cell, its hemispherical "
                                       "value the sum of value x projected solid angle over the cells (exact for "
                                       "the file; Radiance's value)"],
                          method="basis: sum of f x projected solid angle over the cells of the file's angle basis",
                          evaluate=evaluate)


def _reconstruct_normal_grid(geom: Geometry, finite: NDArray[np.bool_], weights: NDArray[np.float64]
                             ) -> Reconstruction:
    """A full θs × φs table about the normal (Speos, LightTools): the table's own interpolant, linear in ρ = sin θs
    between its rows and in φs between its columns (periodic), integrated exactly by the records' hat weights
    (:func:`bsdfkit.reduction.basis.normal_grid_weights`) and evaluated by the same interpolation."""
    x, y = geom.frame()
    rho = np.hypot(x, y)
    pole = finite & (rho < 1e-9)
    ring = finite & ~pole
    phi = np.round(np.mod(np.degrees(np.arctan2(y, x)), 360.0), 9)
    rows, cols = np.unique(np.round(rho[ring], 12)), np.unique(phi[ring])
    r_idx = np.searchsorted(rows, np.round(rho[ring], 12))
    c_idx = np.searchsorted(cols, phi[ring])
    records = np.flatnonzero(ring)
    pole_records = np.flatnonzero(pole)

    def evaluate(values: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        table = np.zeros((rows.size + 1, cols.size))
        table[0] = v[pole_records].mean() if pole_records.size else 0.0
        table[1 + r_idx, c_idx] = v[records]
        dx, dy = direction_frame(geom, directions)
        q_rho = np.clip(np.hypot(dx, dy), 0.0, 1.0)
        q_phi = np.mod(np.degrees(np.arctan2(dy, dx)), 360.0)
        knots = np.concatenate([[0.0], rows])
        i = np.clip(np.searchsorted(knots, q_rho, side="right") - 1, 0, knots.size - 2)
        t = np.clip((q_rho - knots[i]) / (knots[i + 1] - knots[i]), 0.0, 1.0)
        ext = np.concatenate([cols, [cols[0] + 360.0]])
        j = np.clip(np.searchsorted(ext, np.where(q_phi < cols[0], q_phi + 360.0, q_phi), side="right") - 1, 0,
                    cols.size - 1)
        u = np.clip((np.where(q_phi < cols[0], q_phi + 360.0, q_phi) - ext[j]) / (ext[j + 1] - ext[j]), 0.0, 1.0)
        j1 = (j + 1) % cols.size
        lo = table[i, j] * (1.0 - u) + table[i, j1] * u
        hi = table[i + 1, j] * (1.0 - u) + table[i + 1, j1] * u
        return (lo * (1.0 - t) + hi * t).reshape(np.shape(dx))

    return Reconstruction(central=weights, alternatives={}, comparisons={}, lobe=np.zeros(geom.n),
                          region=Region(records=np.zeros(0, dtype=np.int64), in_plane_deg=None),
                          extrapolated_beyond_deg=None,
                          assumptions=["the records are a full table about the normal (every θs row × φs column): "
                                       "its BSDF is the table interpolated linearly in sin θs and φs, integrated "
                                       "exactly (the file's own representation, not reconstructed)"],
                          method="grid: the table's own interpolant (linear in sin θs and φs), integrated exactly",
                          evaluate=evaluate)


def _cell_lookup(geom: Geometry, finite: NDArray[np.bool_]) -> Callable | None:
    """Exact evaluation of a basis file's BSDF: each direction takes the mean value of the records of its cell
    (a Klems patch's records share its value), 0 in a cell without finite records; None when the records do not
    carry their cells."""
    if geom.basis_cell is None or geom.basis_spec is None:
        return None
    cells = geom.basis_cell
    try:
        basis.cell_index(geom.basis_spec, np.zeros(1), np.zeros(1))
    except ValueError:
        return None
    n_cells = int(cells.max()) + 1 if cells.size else 0
    members = finite & (cells >= 0)
    count = np.bincount(cells[members], minlength=n_cells).astype(np.float64)
    records = np.flatnonzero(members)

    def evaluate(values: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        total = np.bincount(cells[records], weights=v[records], minlength=n_cells)
        mean = np.divide(total, count, out=np.zeros(n_cells), where=count > 0)
        dx, dy = direction_frame(geom, directions)
        k = basis.cell_index(geom.basis_spec, dx, dy)
        return np.where(k < n_cells, mean[np.minimum(k, n_cells - 1)], 0.0).reshape(np.shape(dx))

    return evaluate


def _nearest_record(geom: Geometry, finite: NDArray[np.bool_]) -> Callable:
    """The value of the nearest finite record in the projected disk (records without their cells)."""
    x, y = geom.frame()
    nodes = np.stack([x[finite], y[finite]], axis=1)
    index = np.flatnonzero(finite)
    trees: list = []  # the nodes' k-d tree, built on the first evaluation (writers evaluate in many chunks)

    def evaluate(values: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:
        if not trees:
            from scipy.spatial import cKDTree

            trees.append(cKDTree(nodes))
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        dx, dy = direction_frame(geom, directions)
        _, k = trees[0].query(np.stack([np.ravel(dx), np.ravel(dy)], axis=1))
        return v[index[k]].reshape(np.shape(dx))

    return evaluate


def _perpendicular_anisotropy(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64],
                              lobe_records: NDArray[np.int64]) -> float:
    """The body's relative departure from symmetry about the normal that the perpendicular arc shows: its records
    (outside the lobe region) against the in-plane body at the same |β| (the mean of the in-plane halves there,
    linear in |β|), rms over the records with the measurement noise removed in quadrature; 0 when the excess over
    the noise is within twice its standard error."""
    x, y = geom.frame()
    finite = np.isfinite(ref)
    off = np.ones(geom.n, dtype=bool)
    off[lobe_records] = False
    ip = np.flatnonzero(finite & off & (geom.arc == "in_plane"))
    pp = np.flatnonzero(finite & off & (geom.arc == "perpendicular"))
    r_pp = np.hypot(x[pp], y[pp])
    pred, pred_u, n = np.zeros(pp.size), np.zeros(pp.size), np.zeros(pp.size)
    for half in (x[ip] >= 0, x[ip] < 0):
        k = ip[half]
        if k.size < 2:
            continue
        order = np.argsort(np.abs(x[k]))
        rk = np.abs(x[k])[order]
        inside = (r_pp >= rk[0]) & (r_pp <= rk[-1])
        pred[inside] += np.interp(r_pp[inside], rk, ref[k][order])
        pred_u[inside] += np.interp(r_pp[inside], rk, np.nan_to_num(ref_std[k][order])) ** 2
        n[inside] += 1
    ok = (n > 0) & (pred > 0)
    if np.sum(ok) < 3:
        return 0.0
    pred, pred_u = pred[ok] / n[ok], np.sqrt(pred_u[ok]) / n[ok]
    d = ref[pp[ok]] / pred - 1.0
    noise = (np.nan_to_num(ref_std[pp[ok]]) ** 2 + pred_u ** 2) / pred ** 2
    excess = d * d - noise
    # a departure within twice its own standard error is noise, not anisotropy
    if float(np.mean(excess)) <= 2.0 * float(np.std(excess)) / np.sqrt(excess.size):
        return 0.0
    return float(np.sqrt(float(np.mean(excess))))


#: A perpendicular-arc departure from the in-plane body [relative rms] above this is stated in the assumptions.
ANISOTROPY_STATED = 0.01


@dataclass(frozen=True)
class _ArcFit:
    """The central reconstruction of the arcs and what its alternatives and assumptions are made from."""

    region: Region
    options: _ArcOptions  # the central reconstruction's
    other_center: str | None  # without a lobe: the other centre, when about as symmetric (the ``centre`` error)
    mismatch: dict[str, float]  # without a lobe: the in-plane asymmetry about the normal and the specular point
    two_arcs: bool
    errors: bool
    body: NDArray[np.float64]
    lobe: NDArray[np.float64]
    kappa: float
    kappa_alt: float
    ends: list[float]
    bound: float | None
    linear_lobe: float
    anisotropy: float
    evaluate: Callable


def _arc_centre(geom: Geometry, ref: NDArray[np.float64]) -> tuple[str, str | None, dict[str, float]]:
    """Without a separable lobe: the body's centre, the other centre when about as symmetric, the asymmetries."""
    # the centre the in-plane profile is more symmetric about (a lobe as broad as the arc, e.g. forward scatter
    # in transmission, or a body that depends on |β| only)
    body_center, other_center = "normal", None
    mismatch = {c: _mismatch(geom, ref, c) for c in ("normal", "specular")}
    m_n, m_s = mismatch["normal"], mismatch["specular"]
    if np.isfinite(m_s) and np.isfinite(m_n) and m_s < m_n:
        body_center = "specular"
    other = "specular" if body_center == "normal" else "normal"
    if np.isfinite(m_s) and np.isfinite(m_n) and mismatch[other] <= 2.0 * mismatch[body_center] + 0.01:
        other_center = other
    return body_center, other_center, mismatch


def _arc_fit(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64], n_psi: int, n_r: int,
             errors: bool) -> _ArcFit:
    """The lobe region, the body's centre and the central body and lobe weights of the arcs."""
    finite = np.isfinite(ref)
    two_arcs = bool(np.any(finite & (geom.arc == "perpendicular")))
    s = np.nan_to_num(ref_std)
    region = _grown_until_symmetric(geom, ref, find_region(geom, ref, s))
    body_center, other_center, mismatch = "normal", None, {}
    if not region.records.size:
        body_center, other_center, mismatch = _arc_centre(geom, ref)
    opts = _ArcOptions(n_psi=n_psi, n_r=n_r, body_center=body_center)
    body, lobe, ends, (kappa, kappa_alt), evaluate = _body_and_lobe(geom, region, finite, ref, opts, with_kappa=True)
    bound = _unresolved_lobe_bound(geom, region, ref, s) if region.records.size else None
    linear_lobe = float(lobe @ np.nan_to_num(ref))
    if bound is not None and linear_lobe > 0:  # a lobe narrower than the sampling: U/2 ± U/2
        kappa = 0.5 * bound / linear_lobe
    aniso = _perpendicular_anisotropy(geom, ref, s, region.records) if two_arcs and errors else 0.0
    return _ArcFit(region=region, options=opts, other_center=other_center, mismatch=mismatch, two_arcs=two_arcs,
                   errors=errors, body=body, lobe=lobe, kappa=kappa, kappa_alt=kappa_alt, ends=ends, bound=bound,
                   linear_lobe=linear_lobe, anisotropy=aniso, evaluate=evaluate)


def _arc_variant(geom: Geometry, ref: NDArray[np.float64], fit: _ArcFit, reg: Region | None = None,
                 **changes: object) -> NDArray[np.float64]:
    """The weights of one alternative reconstruction: the central options with ``changes``, the lobe region ``reg``."""
    if not fit.errors:
        return fit.body + fit.kappa * fit.lobe
    opts = dataclasses.replace(fit.options, **changes)
    b, lo, _, _, _ = _body_and_lobe(geom, fit.region if reg is None else reg, np.isfinite(ref), ref, opts)
    return b + fit.kappa * lo


def _arc_alternatives(geom: Geometry, ref: NDArray[np.float64], fit: _ArcFit) -> dict[str, dict[str, NDArray]]:
    """The alternative reconstructions of the arcs by error group (module docstring, Error bars)."""
    variant = functools.partial(_arc_variant, geom, ref, fit)
    body, lobe, kappa, region, opts = fit.body, fit.lobe, fit.kappa, fit.region, fit.options
    alt: dict[str, dict[str, NDArray]] = {}
    if fit.other_center is not None:
        alt["centre"] = {f"{fit.other_center}_centred": variant(body_center=fit.other_center)}
    if fit.ends:
        alt["tail"] = {rule: variant(rule=rule) for rule in ("hold", "zero")}
    if fit.two_arcs:
        alt["azimuth"] = {f"blend_p{p:g}": variant(p=p) for p in (1.0, 4.0)}
        if fit.anisotropy > 0:  # the arcs show a body not symmetric about the normal: unmeasured azimuths vary too
            alt["anisotropy"] = {"body_scaled": body + kappa * lobe + fit.anisotropy * body}
    else:
        alt["azimuth"] = {"forward": variant(azimuth="+alpha"), "backward": variant(azimuth="-alpha")}
    sep = {}
    if region.records.size:
        for name, k in (("wider_1", 1), ("wider_2", 2)):
            other = region.grown(geom, k)
            if other.records.size and not np.array_equal(other.records, region.records):
                sep[name] = variant(reg=other)
    if sep:
        alt["separation"] = sep
    if fit.bound is not None and fit.linear_lobe > 0:
        alt["unresolved_lobe"] = {"none": body, "upper_bound": body + 2.0 * kappa * lobe}
    elif region.records.size:
        alt["interpolation"] = {"linear_lobe": body + lobe}
        if fit.kappa_alt != kappa:  # the Gaussian integral was used: the ln-f one is the alternative
            alt["interpolation"]["log_lobe"] = body + fit.kappa_alt * lobe
    else:  # the whole profile with ln-f instead of f interpolation (band-mean ratio)
        finite = np.isfinite(ref)
        keep = np.flatnonzero(finite)
        extra, t, _ = _tail_rows(geom, keep, finite, geom.frame()[0], "trend", ref)
        values = np.concatenate([ref[keep], t @ np.nan_to_num(ref)])
        hemi = Hemisphere.from_profile(geom.dataset(keep, values, extra), center=opts.body_center)
        linear = hemi.tis("linear", opts.n_psi, opts.n_r)
        if linear > 0:
            ratio = float(np.clip(hemi.tis("log", opts.n_psi, opts.n_r) / linear, 0.5, 1.5))
            alt["interpolation"] = {"log_f": body * ratio}
    alt["quadrature"] = {"half_grid": variant(n_psi=opts.n_psi // 2, n_r=opts.n_r // 2)}
    return alt


def _centred_comparisons(geom: Geometry, finite: NDArray[np.bool_], n_psi: int, n_r: int
                         ) -> dict[str, NDArray[np.float64]]:
    """The single-centre reconstructions of the arcs (about the specular point, about the normal)."""
    comparisons = {}
    keep = np.flatnonzero(finite)
    for center in ("specular", "normal"):
        hemi = Hemisphere.from_profile(geom.dataset(keep), center=center)
        w = np.zeros(geom.n)
        w[keep] = hemi.weights(n_psi, n_r)
        comparisons[f"{center}_centred"] = w
    return comparisons


def _arc_assumptions(geom: Geometry, fit: _ArcFit) -> tuple[str, list[str]]:
    """The method of the arcs' reconstruction and its assumptions in words."""
    region, body_center, other_center, mismatch = fit.region, fit.options.body_center, fit.other_center, fit.mismatch
    assumptions = []
    if region.records.size:
        method = "body about the normal + lobe about its peak"
        assumptions.append(
            "diffuse body rotationally symmetric about the normal; specular lobe rotationally symmetric "
            f"(Harvey-Shack) about its in-plane peak at {region.center_deg:.2f} deg "
            f"(nominal specular {geom.theta_i:g} deg); lobe region found on the band-mean profile")
    else:
        what = {"normal": "the normal", "specular": "the specular direction (Harvey-Shack)"}
        method = f"everything about {what[body_center].split(' (')[0]} (no separable specular lobe)"
        sym = (f"; in-plane asymmetry {100 * mismatch['normal']:.1f} % about the normal, "
               f"{100 * mismatch['specular']:.1f} % about the specular direction"
               if np.isfinite(mismatch.get("normal", np.nan)) and np.isfinite(mismatch.get("specular", np.nan))
               else "")
        assumptions.append(f"no lobe separable from a floor near the specular direction: scatter taken as "
                           f"rotationally symmetric about {what[body_center]}{sym}"
                           + (f" (error bar: about {what[other_center]})" if other_center else ""))
    if fit.bound is not None and fit.linear_lobe > 0:
        n_in = int(np.sum(geom.arc[region.records] == "in_plane"))
        assumptions.append(f"specular lobe narrower than the sampling ({n_in} in-plane sample(s)): its integral "
                           f"is bounded, 0 to {fit.bound:.3g} on the band mean, and "
                           "reported as half the bound with half the bound as its error")
    if fit.anisotropy > ANISOTROPY_STATED:
        assumptions.append(f"the perpendicular arc departs from the in-plane body at the same distance from the "
                           f"normal by {100 * fit.anisotropy:.2g} % rms beyond noise: the body is not symmetric about "
                           "the normal, the azimuths between the arcs are not measured (error bar: the whole body "
                           "scaled by that departure)")
    if not fit.two_arcs:
        assumptions.append("in-plane data only: the perpendicular half-profiles are the mean of the two in-plane "
                           "halves (error bar: either half alone)")
    if fit.ends:
        assumptions.append(f"in-plane profile extrapolated beyond {min(fit.ends):g} deg to the horizon along the trend "
                           "of its last three samples (error bar: held at the last value, or linear to 0 at 90 deg)")
    return method, assumptions


def _reconstruct_arcs(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64],
                      n_psi: int = 256, n_r: int = 400, errors: bool = True) -> Reconstruction:
    """Body about the normal + lobe about its peak for records on the in-plane and perpendicular arcs."""
    finite = np.isfinite(ref)
    if not finite.any():
        raise InputError("no usable records to reconstruct the hemisphere", field="bsdf",
                         expected="finite values on an arc")
    fit = _arc_fit(geom, ref, ref_std, n_psi, n_r, errors)
    alt = _arc_alternatives(geom, ref, fit)
    comparisons = _centred_comparisons(geom, finite, n_psi, n_r) if errors else {}
    method, assumptions = _arc_assumptions(geom, fit)
    kappa, evaluate = fit.kappa, fit.evaluate
    return Reconstruction(central=fit.body + kappa * fit.lobe, alternatives=alt, comparisons=comparisons,
                          lobe=kappa * fit.lobe, region=fit.region,
                          extrapolated_beyond_deg=min(fit.ends) if fit.ends else None,
                          assumptions=assumptions, method=method,
                          evaluate=lambda values, directions: evaluate(values, directions, kappa))


# ------------------------------------------------------------------------------------------- disk sampling
def direction_frame(geom: Geometry, directions: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """(x, y) of unit vectors (..., 3) in the sample frame, in the frame of :meth:`Geometry.frame`.

    Parameters
    ----------
    geom : Geometry
        Per-record directions of the profile.
    directions : ndarray
        Unit vectors (..., 3) in the sample frame [-].

    Returns
    -------
    tuple of ndarray
        x and y direction cosines [-], flattened.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    u = np.radians(geom.phi_i) - np.pi
    a, b = d[:, 0], d[:, 1]
    return a * np.cos(u) + b * np.sin(u), -a * np.sin(u) + b * np.cos(u)


#: Lobe regions one and two steps wider (factors on the region radius) for the ``separation`` error.
DISK_WIDER = (1.25, 1.5)
#: A lobe region must leave at least this share of the records to the body (else no separable lobe).
MIN_BODY_SHARE = 0.2


class _RegionTooWide(Exception):
    """A lobe region that leaves too few records to reconstruct the body."""


def _disk_region(geom: Geometry, ref: NDArray[np.float64], s: NDArray[np.float64]
                 ) -> tuple[float | None, float, NDArray[np.int64]]:
    """Lobe centre (in-plane direction cosine), region radius and the in-plane region found on the records of
    the in-plane and perpendicular arcs (:func:`find_region`, grown like the arcs'); (None, 0, []) without a
    separable lobe or without an in-plane arc."""
    on = np.flatnonzero(np.isfinite(ref) & np.isin(geom.arc, ("in_plane", "perpendicular")))
    if np.sum(geom.arc[on] == "in_plane") < 5:
        return None, 0.0, np.zeros(0, dtype=np.int64)
    sub = Geometry(theta_i=geom.theta_i, phi_i=geom.phi_i, theta_s=geom.theta_s[on], phi_s=geom.phi_s[on],
                   arc=geom.arc[on], side=geom.side)
    region = _grown_until_symmetric(sub, ref[on], find_region(sub, ref[on], s[on]))
    if not region.records.size or region.center_deg is None:
        return None, 0.0, np.zeros(0, dtype=np.int64)
    x, y = sub.frame()
    c = float(np.sin(np.radians(region.center_deg)))
    dist = np.hypot(x - c, y)
    inside = dist[region.records].max()
    members = np.zeros(on.size, dtype=bool)
    members[region.records] = True
    beyond = dist[~members & (dist > inside + 1e-12)]
    radius = 0.5 * (inside + beyond.min()) if beyond.size else inside * 1.1 + 1e-6
    return c, float(radius), on[region.records]


#: A lobe region wider than this (direction cosines) is no specular lobe (scatter rising toward grazing).
LOBE_MAX_RADIUS = 0.5


#: Azimuth weight of the body's triangulation where the records cover the azimuths densely (near the metric of
#: the disk at mid radius: records joined to their nearest neighbours), and the share of ring sectors that counts
#: as dense. Sparse azimuths (C-planes, a few planes) keep :data:`bsdfkit.reduction.disk.AZIMUTH_WEIGHT`, which
#: joins records at one distance from the centre across the gaps between planes.
DENSE_AZIMUTH_WEIGHT = 0.5
DENSE_COVERAGE = 0.5


def _body_interpolant(x: NDArray[np.float64], y: NDArray[np.float64], center: tuple[float, float], rim: str,
                      reference: NDArray[np.float64], about_direction: float | None = None,
                      spokes: bool = False):
    """The body's polar interpolant: about the normal with the azimuth weight of :func:`_body_azimuth_weight`,
    or, about the specular point, a polar grid on its own spokes (straight in β, or great circles through the
    specular direction when ``about_direction`` gives the incidence [deg])."""
    if spokes:
        return disk.build(x, y, center, rim=disk.Rim(rim, normal_centered=False, reference=reference), spokes=True,
                          about_direction_deg=about_direction)
    return disk.build(x, y, center, rim=disk.Rim(rim, normal_centered=True, reference=reference),
                      azimuth_weight=_body_azimuth_weight(x, y))


#: Share of the records on spokes (three or more records at one azimuth) about the specular point from which the
#: records are a polar grid about it (:func:`_native_grid`).
SPOKE_SHARE = 0.9


#: A native polar grid has at least this many spokes (planes through the specular point are not one).
MIN_SPOKES = 24


def _native_grid(geom: Geometry, finite: NDArray[np.bool_]) -> str | None:
    """``beta`` when at least :data:`SPOKE_SHARE` of the records lie on :data:`MIN_SPOKES` or more straight spokes
    about the specular point in β (Harvey–Shack tables: TracePro, ASAP-style), ``direction`` when they lie on as
    many great circles through the specular direction (Zemax tables), else None."""
    x, y = geom.frame()
    k = np.flatnonzero(finite)
    c = float(np.sin(np.radians(geom.theta_i)))
    dx, dy = x[k] - c, y[k]
    r = np.hypot(dx, dy)
    off = r > 1e-9
    if off.sum() < 4 * MIN_SPOKES:
        return None
    psi = np.arctan2(dy[off], dx[off])
    spoke_dir, _ = disk.direction_polar((c, 0.0), psi, r[off], geom.theta_i)
    for name, az in (("beta", psi), ("direction", spoke_dir)):
        key = np.round(az / 1e-6).astype(np.int64)
        uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        on = counts[np.asarray(inverse).ravel()] >= 3
        if np.mean(on) >= SPOKE_SHARE and np.sum(counts >= 3) >= MIN_SPOKES:
            return name
    return None


def _body_azimuth_weight(x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """:data:`DENSE_AZIMUTH_WEIGHT` when the records occupy at least :data:`DENSE_COVERAGE` of the 10° sectors of
    the rings (0.05 wide in |β|) they reach, area-weighted; else :data:`bsdfkit.reduction.disk.AZIMUTH_WEIGHT`."""
    r = np.hypot(x, y)
    ring = np.minimum((r / 0.05).astype(int), 19)
    sector = (np.mod(np.degrees(np.arctan2(y, x)), 360.0) // 10).astype(int)
    occupied = np.zeros((20, 36), dtype=bool)
    occupied[ring, sector] = True
    reached = occupied.any(axis=1)
    area = (np.arange(20) + 0.5)[reached]
    share = float(np.sum(area * occupied[reached].mean(axis=1)) / np.sum(area)) if reached.any() else 0.0
    return DENSE_AZIMUTH_WEIGHT if share >= DENSE_COVERAGE else disk.AZIMUTH_WEIGHT


#: An azimuth gap wider than this [deg] in a ring of the body's records is stated with the assumptions.
AZIMUTH_GAP_DEG = 90.0


def _azimuth_gap(geom: Geometry, finite: NDArray[np.bool_]) -> tuple[float, float, float] | None:
    """The widest azimuth gap [deg] of the records in rings 0.1 wide in |β| (up to 0.9) and that ring's edges,
    when wider than :data:`AZIMUTH_GAP_DEG`; None otherwise (the lobe region's records count: they are measured)."""
    gaps = [g for g in _ring_gaps(geom, finite) if g[0] > AZIMUTH_GAP_DEG and g[1] > 0.05]
    return max(gaps, key=lambda g: g[0])[:3] if gaps else None


#: Ring width [direction cosines] of the azimuth-gap analysis (:func:`_ring_gaps`).
RING_WIDTH = 0.1


def _ring_gaps(geom: Geometry, finite: NDArray[np.bool_]) -> list[tuple[float, float, float, NDArray[np.int64]]]:
    """Per ring :data:`RING_WIDTH` wide in |β| about the normal: (widest azimuth gap [deg], inner edge, outer edge,
    the ring's finite records); rings with fewer than two records are left out."""
    x, y = geom.frame()
    keep = np.flatnonzero(finite)
    r = np.hypot(x[keep], y[keep])
    ang = np.mod(np.degrees(np.arctan2(y[keep], x[keep])), 360.0)
    out = []
    for lo in np.arange(0.0, 1.0 - 1e-9, RING_WIDTH):
        on = (r >= lo) & (r < lo + RING_WIDTH) & (r > 1e-9)
        a = np.sort(ang[on])
        if a.size < 2:
            continue
        out.append((float(np.max(np.diff(np.r_[a, a[0] + 360.0]))), float(lo), float(lo + RING_WIDTH), keep[on]))
    return out


#: A ring counts as covered in azimuth (its spread measures the body's anisotropy) with records in this many 30°
#: sectors (:func:`_gap_anisotropy`).
COVERED_SECTORS = 4


def _gap_anisotropy(geom: Geometry, finite: NDArray[np.bool_], ref: NDArray[np.float64],
                    body_records: NDArray[np.int64]) -> tuple[NDArray[np.float64], float] | None:
    """Weights whose dot product with the records is the body's integral [fraction] over the azimuth gaps wider
    than :data:`AZIMUTH_GAP_DEG`, times the body's relative azimuthal variation δ measured in the rings that are
    covered in azimuth (rms about a linear radial trend, relative to the ring's mean; the largest ring); and δ.
    None when no ring has such a gap or no ring is covered (then the anisotropy is not measured at all)."""
    x, y = geom.frame()
    body = np.zeros(geom.n, dtype=bool)
    body[body_records] = True
    rings = _ring_gaps(geom, finite & body)
    gapped = [g for g in rings if g[0] > AZIMUTH_GAP_DEG]
    if not gapped:
        return None
    deltas = []
    for _, _, _, k in rings:
        sectors = np.unique((np.mod(np.degrees(np.arctan2(y[k], x[k])), 360.0) // 30).astype(int))
        v = np.nan_to_num(ref[k])
        if sectors.size < COVERED_SECTORS or k.size < 6 or np.mean(v) <= 0:
            continue
        a = np.stack([np.ones(k.size), np.hypot(x[k], y[k])], 1)
        resid = v - a @ np.linalg.lstsq(a, v, rcond=None)[0]
        deltas.append(float(np.sqrt(np.mean(resid ** 2)) / np.mean(v)))
    if not deltas:
        return None
    delta = max(deltas)
    w = np.zeros(geom.n)
    for gap, lo, hi, k in gapped:
        w[k] += delta * (gap / 360.0) * np.pi * (hi * hi - lo * lo) / k.size  # the gap's share of the ring's area
    return w, delta


#: Records within this azimuth [deg] about the normal lie on one half-plane of a planes layout (:func:`_gap_planes`).
PLANE_TOL_DEG = 0.05
#: A half-plane holds at least this many records off the normal.
PLANE_MIN_RECORDS = 4
#: A plane's excess over the body counts as a lobe flank where it exceeds this share of the body (and 3 u).
FLANK_FLOOR = 0.05
#: The Gaussian across a gap raises ln f above the chord between its flanks by at most this (the peak between
#: two planes at most e³ ≈ 20 times its flanks' geometric mean): two planes cannot measure a lobe's width across
#: them, and a lobe narrower across than along the planes would otherwise be raised without bound.
BULGE_CAP = 3.0
#: The ``between_planes`` alternative: a lobe this many times narrower across the planes than along them, in σ².
GAP_NARROWER = 1.5
#: Factors on a lobe's width across the planes for the ``across_width`` error of a planes layout whose lobe lies on
#: a measured plane (:func:`_reconstruct_disk`): a Gaussian lobe's integral scales with its width across.
ACROSS_WIDTH_FACTORS = (0.5, 2.0)
#: A plane passing the specular direction within this distance [direction cosines] samples a specular lobe there
#: (:func:`_specular_unsampled`; a narrow glossy lobe is a few hundredths wide).
SPECULAR_SAMPLED = 0.02
#: A neighbouring plane passing the lobe's centre within this share of its region radius (about one σ) samples
#: its width across (:func:`_across_width_factors`).
ACROSS_SAMPLED = 1.0 / 3.0
#: Half-planes closer than this in azimuth [deg] (median gap) are a grid, interpolated across; from C-planes 15°
#: apart on, a lobe can lie between planes unmeasured (:func:`_gap_planes`).
GAP_MIN_DEG = 12.5
#: Gauss–Legendre nodes across a gap, radial nodes per half-plane gap (:func:`_gap_integral`).
GAP_U_NODES, GAP_R_NODES = 16, 240


@dataclass(frozen=True)
class _GapPlanes:
    """A planes layout: every finite record off the normal on a half-plane through the normal (C-planes, a θs × φs
    grid, an in-plane arc with a φs = 90/270° arc), and the lobe flanks each half-plane shows (:func:`_gap_planes`).

    Per half-plane k (sorted by azimuth ``phi`` [rad] about the normal, in the frame of :meth:`Geometry.frame`):
    its records sorted by radius (``members``, radii ``r`` [direction cosines]), the excess ``excess`` of the
    band-mean values over the body (the median over the half-planes at that radius) [1/sr], the smallest excess
    that counts as a lobe flank ``floor`` [1/sr], and ``sigma``: the lobe's Gaussian width along the plane
    [direction cosines] (log-parabola through the highest flank sample and its neighbours; NaN: no lobe)."""

    phi: NDArray[np.float64]
    members: tuple
    r: tuple
    excess: tuple
    floor: tuple
    sigma: NDArray[np.float64]


def _gap_planes(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64]) -> _GapPlanes | None:
    """The half-planes of a planes layout with their lobe flanks; None when a finite record off the normal lies
    on no half-plane of :data:`PLANE_MIN_RECORDS` or more records, or with fewer than three half-planes."""
    finite = np.isfinite(ref)
    x, y = geom.frame()
    keep = np.flatnonzero(finite)
    r_all = np.hypot(x[keep], y[keep])
    off = keep[r_all > disk.CENTER_TOL]
    if off.size < 3 * PLANE_MIN_RECORDS:
        return None
    az = np.mod(np.degrees(np.arctan2(y[off], x[off])), 360.0)
    key = np.round(az / PLANE_TOL_DEG).astype(np.int64) % int(round(360.0 / PLANE_TOL_DEG))
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    if uniq.size < 3 or counts.min() < PLANE_MIN_RECORDS:
        return None
    inverse = np.asarray(inverse).ravel()
    members, radii = [], []
    for j in range(uniq.size):
        m = off[inverse == j]
        rr = np.hypot(x[m], y[m])
        o = np.argsort(rr, kind="stable")
        members.append(m[o])
        radii.append(rr[o])
    phi = np.radians(uniq * PLANE_TOL_DEG)
    gaps = np.diff(np.concatenate([np.sort(phi), [np.sort(phi)[0] + 2.0 * np.pi]]))
    if np.degrees(np.median(gaps)) < GAP_MIN_DEG:
        # planes this close (a θs × φs grid of a vendor table, 1-10° in azimuth) are interpolated across, as any
        # grid: a lobe cannot hide between them, and a flat-topped patch between two of them is no Gaussian
        return None
    v = np.nan_to_num(ref)
    u = np.nan_to_num(ref_std)
    # the body: the median over the half-planes at each radius (a lobe on a few planes leaves it), each plane
    # interpolated along its radius (held beyond its ends)
    excess, floor, sigma = [], [], np.full(uniq.size, np.nan)
    for j in range(uniq.size):
        at = np.stack([np.interp(radii[j], radii[i], v[members[i]]) for i in range(uniq.size)])
        body = np.median(at, axis=0)
        e = v[members[j]] - body
        t = np.maximum(3.0 * u[members[j]], FLANK_FLOOR * np.abs(body))
        excess.append(e)
        floor.append(t)
        flank = np.flatnonzero(e > t)
        if flank.size:
            p = int(flank[np.argmax(e[flank])])
            fit = _log_parabola(radii[j], e, p)
            if fit is not None and np.sqrt(-0.5 / fit[0]) < LOBE_MAX_RADIUS:
                sigma[j] = float(np.sqrt(-0.5 / fit[0]))
    return _GapPlanes(phi=phi, members=tuple(members), r=tuple(radii), excess=tuple(excess), floor=tuple(floor),
                      sigma=sigma)


def _gap_flank(planes: _GapPlanes, k: int, r: NDArray[np.float64]) -> tuple[NDArray, NDArray[np.bool_]]:
    """Half-plane k's excess over the body at radii r [1/sr] (0 beyond its end) and where it is a lobe flank."""
    k = k % planes.phi.size
    e = np.interp(r, planes.r[k], planes.excess[k], right=0.0)
    return e, e > np.interp(r, planes.r[k], planes.floor[k])


def _gap_width(planes: _GapPlanes, a: int) -> float:
    """Azimuth [rad] from half-plane a to the next."""
    n = planes.phi.size
    return float(np.mod(planes.phi[(a + 1) % n] - planes.phi[a % n], 2.0 * np.pi)) or 2.0 * np.pi


def _gap_curvature(planes: _GapPlanes, a: int, r: NDArray[np.float64], la: NDArray, lb: NDArray,
                   narrow: float = 1.0) -> NDArray:
    """d²(ln L)/dt² across the gap from half-plane a to the next [1/direction cosines²] at radii r, t the distance
    across: measured by the parabola through ln L on three neighbouring planes where the plane before a or after
    the next shows the flank too (the mean of the two), else that of a Gaussian as wide across as along the planes
    (−1/(σ_a σ_b), times ``narrow``: σ² across = σ_a σ_b / narrow); never above 0 (ln L is then interpolated
    linearly across)."""
    g = r * _gap_width(planes, a)
    total, count = np.zeros(r.size), np.zeros(r.size)
    for side in (-1, 1):
        e3, f3 = _gap_flank(planes, a - 1 if side < 0 else a + 2, r)
        g3 = r * _gap_width(planes, a - 1 if side < 0 else a + 1)
        ok = f3 & (g > 0) & (g3 > 0)
        if not ok.any():
            continue
        l3 = np.log(np.where(ok, e3, 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            if side < 0:  # planes at −g3, 0, g
                c = 2.0 * ((lb - la) / g - (la - l3) / g3) / (g + g3)
            else:  # planes at 0, g, g + g3
                c = 2.0 * ((l3 - lb) / g3 - (lb - la) / g) / (g + g3)
        total += np.where(ok, c, 0.0)
        count += ok
    sa, sb = planes.sigma[a % planes.phi.size], planes.sigma[(a + 1) % planes.phi.size]
    round_lobe = -narrow / (sa * sb) if np.isfinite(sa) and np.isfinite(sb) else 0.0
    measured = np.divide(total, count, out=np.full(r.size, round_lobe), where=count > 0)
    return np.minimum(measured, 0.0)


def _gap_cell(planes: _GapPlanes, k: int, r: NDArray[np.float64], u: NDArray[np.float64], narrow: float = 1.0,
              cap: float = BULGE_CAP) -> NDArray[np.float64]:
    """The lobe across the gap from half-plane k to the next, less its linear interpolation across azimuth [1/sr],
    at radii ``r`` and fractions ``u`` of the gap (arrays of one shape).

    Where both planes show a flank at that radius, ln L is the chord between them raised by the parabola of a
    Gaussian across the planes (:func:`_gap_curvature`: measured on three planes, else as wide across as along
    them): exact for a Gaussian lobe wherever its peak lies, between the planes or on one. Where one plane shows a
    flank, the lobe falls off from it as the Gaussian of its width along the plane (peaked on the plane: the least
    it can hold). Elsewhere 0. ``narrow`` and ``cap``: the alternative of a lobe narrower across than along the
    planes (:func:`_gap_curvature`) and the largest rise of ln L above the chord."""
    ea, fa = _gap_flank(planes, k, r)
    eb, fb = _gap_flank(planes, k + 1, r)
    sa, sb = planes.sigma[k % planes.phi.size], planes.sigma[(k + 1) % planes.phi.size]
    g = r * _gap_width(planes, k)  # the gap's width across at r [direction cosines]
    out = np.zeros_like(r)
    both = fa & fb & (np.isfinite(sa) | np.isfinite(sb))
    if both.any():
        la, lb = np.log(ea[both]), np.log(eb[both])
        curv = _gap_curvature(planes, k, r[both], la, lb, narrow)
        ub = u[both]
        bulge = np.minimum(-curv * g[both] ** 2 / 8.0, cap) * 4.0 * ub * (1.0 - ub)
        out[both] = np.exp((1.0 - ub) * la + ub * lb + bulge) - ((1.0 - ub) * ea[both] + ub * eb[both])
    for flank, s, e, t in ((fa & ~fb, sa, ea, u), (fb & ~fa, sb, eb, 1.0 - u)):
        if np.isfinite(s) and flank.any():  # one flank: the lobe falls off from its plane
            # the other plane's (insignificant) excess stays interpolated linearly
            out[flank] = e[flank] * (np.exp(-0.5 * (t[flank] * g[flank] / s) ** 2) - (1.0 - t[flank]))
    return out


def _gap_integral(planes: _GapPlanes, narrow: float = 1.0, cap: float = BULGE_CAP) -> tuple[float, float]:
    """∬ over the gaps between the half-planes of :func:`_gap_cell` [fraction] (polar quadrature about the normal:
    Gauss–Legendre across each gap, trapezoids in r out to the nearer plane end), and the largest ratio of the
    lobe's peak across a gap to its higher flank (> 1: a peak between planes that no plane measures); ``narrow``
    and ``cap`` as for :func:`_gap_cell`."""
    xg, wg = np.polynomial.legendre.leggauss(GAP_U_NODES)
    uu, wu = 0.5 * (xg + 1.0), 0.5 * wg
    total, peak = 0.0, 1.0
    n = planes.phi.size
    for k in range(n):
        b = (k + 1) % n
        if not (np.isfinite(planes.sigma[k]) or np.isfinite(planes.sigma[b])):
            continue
        gap = float(np.mod(planes.phi[b] - planes.phi[k], 2.0 * np.pi)) or 2.0 * np.pi
        rmax = min(planes.r[k][-1], planes.r[b][-1])
        rr = np.linspace(0.0, rmax, GAP_R_NODES)
        wr = np.full(rr.size, rr[1] - rr[0])
        wr[[0, -1]] *= 0.5
        r2, u2 = np.meshgrid(rr, uu, indexing="ij")
        d = _gap_cell(planes, k, r2.ravel(), u2.ravel(), narrow, cap).reshape(r2.shape)
        total += float(np.sum(d * (wr * rr)[:, None] * wu[None, :]) * gap)
        ea = np.interp(rr, planes.r[k], planes.excess[k], right=0.0)
        eb = np.interp(rr, planes.r[b], planes.excess[b], right=0.0)
        hi = np.maximum(ea, eb)
        lin = (1.0 - u2) * ea[:, None] + u2 * eb[:, None]
        model = d + lin
        ok = hi > 0
        if ok.any():
            peak = max(peak, float(np.max(model[ok].max(axis=1) / hi[ok])))
    return total, peak


@dataclass(frozen=True)
class _DiskOptions:
    """One reconstruction over the disk (:func:`_disk_parts`): the body's centre ("normal" or "specular"), the
    lobe's centre (in-plane direction cosine; None: no lobe) and region radius [direction cosines], the body's rim
    rule, an in-plane half of the lobe mirrored onto the other ("forward", "backward") and a native polar grid."""

    body_center: str = "normal"
    lobe_c: float | None = None
    radius: float = 0.0
    rim: str = "trend"
    mirror: str | None = None
    native: str | None = None


def _disk_parts(geom: Geometry, finite: NDArray[np.bool_], ref: NDArray[np.float64], opts: _DiskOptions) -> tuple:
    """Body (about ``body_center``) and lobe (about (lobe_c, 0) within ``radius``) weights over the profile's
    records, the linear lobe integral's log/linear ratio on ``ref``, extrapolated radius, and an evaluator."""
    body_center, lobe_c, radius, rim, mirror, native = (opts.body_center, opts.lobe_c, opts.radius, opts.rim,
                                                        opts.mirror, opts.native)
    x, y = geom.frame()
    n = geom.n
    keep = np.flatnonzero(finite)
    x0 = float(np.sin(np.radians(geom.theta_i)))
    bc = (0.0, 0.0) if body_center == "normal" else (x0, 0.0)
    if lobe_c is not None:
        dist = np.hypot(x[keep] - lobe_c, y[keep])
        region, outside = keep[dist < radius], keep[dist >= radius]
        if outside.size < max(3, MIN_BODY_SHARE * keep.size):
            raise _RegionTooWide(f"{outside.size} of {keep.size} records outside the lobe region")
    else:
        region, outside = np.zeros(0, dtype=np.int64), keep
    body = _body_interpolant(x[outside], y[outside], bc, rim, ref[outside],
                             None if native != "direction" else geom.theta_i, spokes=native is not None)
    c_body = np.zeros(n)
    c_body[outside] = body.weights()
    c_lobe = np.zeros(n)
    ratio = 1.0
    lobe = None
    resid = None
    if region.size:
        e = body.matrix(x[region], y[region]).toarray()  # body at the region's records
        resid = np.zeros((region.size, n))
        resid[:, outside] = -e
        resid[np.arange(region.size), region] += 1.0
        lx, ly, rows = x[region], y[region], resid
        if mirror is not None:  # one in-plane half mirrored onto the other (lobe isotropy alternative)
            half = (lx - lobe_c) >= -1e-12 if mirror == "forward" else (lx - lobe_c) <= 1e-12
            lx = np.concatenate([lx[half], 2 * lobe_c - lx[half]])
            ly = np.concatenate([ly[half], -ly[half]])
            rows = np.concatenate([resid[half], resid[half]])
            lx, uniq = np.unique(np.round(np.stack([lx, ly], 1), 12), axis=0, return_index=True)
            lx, ly, rows = lx[:, 0], lx[:, 1], rows[uniq]
        lobe = disk.build(lx, ly, (lobe_c, 0.0), rim=disk.Rim("ring", radius=radius, normal_centered=False))
        w = lobe.weights()
        c_lobe = w @ rows
        lv = rows @ np.nan_to_num(ref)
        linear = float(w @ lv)
        if linear > 0:
            # a lobe between samples: ln-f chords lie under a Gaussian's concave ln f, f chords over its convex
            # tails; their mean is within 0.1 % of a Gaussian sampled at 0.7-0.9 σ, the difference the error
            ratio = float(np.clip(0.5 * (1.0 + lobe.integral(lv, "log") / linear), 0.5, 1.5))
        resid = rows

    def evaluate(values: NDArray[np.float64], directions: NDArray[np.float64], k: float = 1.0) -> NDArray:
        v = np.nan_to_num(np.asarray(values, dtype=np.float64))
        dx, dy = direction_frame(geom, directions)
        out = body.evaluate(v[outside], dx, dy)
        if lobe is not None and k != 0.0:
            out = out + k * lobe.evaluate(resid @ v, dx, dy)
        return out

    return c_body, c_lobe, ratio, body.extrapolated_beyond, evaluate, region


@dataclass(frozen=True)
class _DiskFit:
    """The central reconstruction over the disk and what its alternatives and assumptions are made from."""

    options: _DiskOptions  # the central reconstruction's
    in_plane_region: NDArray[np.int64]  # the lobe region found on the in-plane arc
    resolved: bool  # a peak wider than LOBE_MAX_RADIUS: no specular lobe, everything about the normal
    errors: bool
    body: NDArray[np.float64]
    lobe: NDArray[np.float64]
    kappa: float
    beyond: float | None
    evaluate: Callable
    region: NDArray[np.int64]  # the records of the lobe region


def _disk_fit(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64], errors: bool,
              lobe: bool = True) -> _DiskFit:
    """The lobe region, the body's centre and the central body and lobe weights over the disk; ``lobe=False``:
    everything about the normal (the lobe is then the planes' own, :func:`_gap_planes`)."""
    finite = np.isfinite(ref)
    no_lobe = (None, 0.0, np.zeros(0, dtype=np.int64))
    native = _native_grid(geom, finite)
    # a polar grid about the specular point or direction: integrated on its own spokes (no lobe region)
    lobe_c, radius, in_plane_region = (no_lobe if native or not lobe
                                       else _disk_region(geom, ref, np.nan_to_num(ref_std)))
    resolved = lobe_c is not None and radius > LOBE_MAX_RADIUS
    if resolved:  # scatter rising over most of the disk is no specular lobe: integrated directly with the body
        lobe_c, radius, in_plane_region = no_lobe
    # the body is always interpolated about the normal: there the domain is r ≤ 1 for every azimuth, so records
    # at one distance from the centre never straddle the horizon (about an off-normal centre they do, and
    # interpolating across azimuth at constant distance bridges the concave edge of the domain)
    opts = _DiskOptions(body_center="specular" if native else "normal", lobe_c=lobe_c, radius=radius, native=native)
    try:
        parts = _disk_parts(geom, finite, ref, opts)
    except _RegionTooWide:  # a "lobe" covering most of the disk is the body itself (never with a native grid)
        lobe_c, radius, in_plane_region = no_lobe
        opts = dataclasses.replace(opts, lobe_c=None, radius=0.0)
        parts = _disk_parts(geom, finite, ref, opts)
    body, lobe, kappa, beyond, evaluate, region = parts
    return _DiskFit(options=opts, in_plane_region=in_plane_region, resolved=resolved, errors=errors, body=body,
                    lobe=lobe, kappa=kappa, beyond=beyond, evaluate=evaluate, region=region)


def _disk_variant(geom: Geometry, ref: NDArray[np.float64], fit: _DiskFit, **changes: object) -> NDArray[np.float64]:
    """The weights of one alternative reconstruction over the disk: the central options with ``changes``."""
    if not fit.errors:
        return fit.body + fit.kappa * fit.lobe
    b, lo, _, _, _, _ = _disk_parts(geom, np.isfinite(ref), ref, dataclasses.replace(fit.options, **changes))
    return b + fit.kappa * lo


def _sparse_lobe(geom: Geometry, fit: _DiskFit) -> bool:
    """Whether the lobe is measured at fewer than three azimuths about its peak where it is strong (within half
    the region radius): then the in-plane arc alone."""
    region, lobe_c, radius = fit.region, fit.options.lobe_c, fit.options.radius
    gx, gy = geom.frame()
    core = region[np.hypot(gx[region] - (lobe_c or 0.0), gy[region]) < 0.5 * radius] if region.size else region
    lobe_psi = np.unique(np.round(np.degrees(np.arctan2(gy[core], gx[core] - (lobe_c or 0.0))) % 180.0, 1))
    return region.size > 0 and len(lobe_psi) < 3


def _disk_alternatives(geom: Geometry, ref: NDArray[np.float64], fit: _DiskFit, sparse_lobe: bool
                       ) -> dict[str, dict[str, NDArray]]:
    """The alternative reconstructions over the disk by error group, but the azimuth gap (:func:`_gap_statement`)."""
    variant = functools.partial(_disk_variant, geom, ref, fit)
    body, lobe = fit.body, fit.lobe
    alt: dict[str, dict[str, NDArray]] = {}
    if fit.beyond is not None:
        alt["tail"] = {rule: variant(rim=rule) for rule in ("hold", "zero")}
    if sparse_lobe:
        mirrored = {}
        for m in ("forward", "backward"):
            try:
                mirrored[m] = variant(mirror=m)
            except InputError:  # a half with too few records off the lobe's centre: that alternative is void
                continue
        if mirrored:
            alt["azimuth"] = mirrored
    if fit.region.size:
        sep = {}
        for k, factor in enumerate(DISK_WIDER):
            try:
                sep[f"wider_{k + 1}"] = variant(radius=factor * fit.options.radius)
            except _RegionTooWide:
                break
        if sep:
            alt["separation"] = sep
        alt["interpolation"] = {"linear_lobe": body + lobe}
    elif fit.errors:
        keep = np.flatnonzero(np.isfinite(ref))
        x, y = geom.frame()
        whole = _body_interpolant(x[keep], y[keep], (0.0, 0.0), "trend", ref[keep])
        v = np.nan_to_num(ref[keep])
        linear = whole.integral(v, "linear")
        if linear > 0:
            alt["interpolation"] = {"log_f": body * float(np.clip(whole.integral(v, "log") / linear, 0.5, 1.5))}
    return alt


def _gap_statement(geom: Geometry, ref: NDArray[np.float64], fit: _DiskFit
                   ) -> tuple[dict[str, NDArray] | None, str | None]:
    """The ``azimuth_gap`` alternatives and the assumption stated for azimuths the records leave unmeasured."""
    finite = np.isfinite(ref)
    # a polar grid about the specular point is interpolated along its spokes, not across azimuth about the normal
    gap = None if fit.options.native else _azimuth_gap(geom, finite)
    if gap is None:
        return None, None
    text = (f"the records leave azimuths of up to {gap[0]:.0f} deg unmeasured at {gap[1]:.2g}-{gap[2]:.2g} "
            "from the normal (direction cosines): the body there is interpolated across the gap at the same "
            "distance from the normal, exact for a body symmetric about the normal; ")
    aniso = (_gap_anisotropy(geom, finite, ref, np.setdiff1d(np.flatnonzero(finite), fit.region)) if fit.errors
             else None)
    if aniso is None:
        return None, text + "an anisotropy there is not measured and not in the error bar"
    text += (f"error bar: the body over the gaps varying as much as it does across azimuth where the "
             f"records cover it ({100 * aniso[1]:.2g} % rms)")
    return {"anisotropic_body": fit.body + fit.kappa * fit.lobe + aniso[0]}, text


def _lobe_center_deg(fit: _DiskFit) -> float | None:
    """The lobe's in-plane centre [deg] (None without a lobe)."""
    return None if fit.options.lobe_c is None else float(np.degrees(np.arcsin(fit.options.lobe_c)))


def _disk_method(geom: Geometry, fit: _DiskFit, sparse_lobe: bool) -> tuple[str, list[str]]:
    """The method of the reconstruction over the disk and its assumptions after the records' and the gap's."""
    opts, region = fit.options, fit.region
    assumptions = []
    if region.size:
        method = "disk: body about the normal + lobe about its peak"
        assumptions.append(f"specular lobe about its in-plane peak at {_lobe_center_deg(fit):.2f} deg within "
                           f"{opts.radius:.3g} (direction cosines), {region.size} record(s); the body under it "
                           "interpolated from the records around it")
        if sparse_lobe:
            assumptions.append("lobe measured on the in-plane arc only: rotationally symmetric about its peak "
                               "(error bar: either in-plane half alone)")
    elif opts.native:
        what = ("straight spokes about the specular point in direction cosines (a Harvey-Shack table)"
                if opts.native == "beta" else "great circles through the specular direction (a radial x azimuth "
                "table about it)")
        method = "disk: a polar grid about the specular point, on its own spokes"
        assumptions.append(f"the records lie on {what}: interpolated along and between its spokes, each spoke "
                           "held at its outermost value up to the horizon (as the format's readers do)")
    elif fit.resolved:
        method = "disk: everything about the normal (no specular lobe narrower than the disk)"
        assumptions.append(f"the peak near the specular direction extends over more than {LOBE_MAX_RADIUS:g} in "
                           "direction cosines: no separable specular lobe, every record interpolated about the normal")
    else:
        what = {"normal": "the normal", "specular": "the specular direction"}
        method = f"disk: everything about {what[opts.body_center]} (no separable specular lobe)"
    if fit.beyond is not None:
        edge = float(np.degrees(np.arcsin(min(fit.beyond, 1.0)))) if opts.body_center == "normal" else None
        assumptions.append("data end short of the horizon" + (f" (from {edge:.3g} deg)" if edge is not None else "")
                           + ": extrapolated along the trend of the last 10 deg (error bar: held at the last value, "
                           "or linear to 0 at the horizon)")
    return method, assumptions


def _gap_weights(planes: _GapPlanes, ref: NDArray[np.float64], delta: float) -> NDArray[np.float64] | None:
    """Weights over the records whose dot product with ``ref`` is ``delta`` [fraction], spread over the lobe
    flanks the half-planes show (a lobe between planes scales with them at every wavelength); None without
    flanks."""
    m = np.zeros(ref.size)
    for k in range(planes.phi.size):
        if np.isfinite(planes.sigma[k]):
            m[planes.members[k][planes.excess[k] > planes.floor[k]]] = 1.0
    level = float(m @ np.nan_to_num(ref))
    return m * (delta / level) if level > 0 else None


def _gap_evaluate(planes: _GapPlanes, geom: Geometry, directions: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`_gap_cell` at unit vectors (..., 3) in the sample frame [1/sr] (on the band-mean profile)."""
    dx, dy = direction_frame(geom, directions)
    r = np.hypot(dx, dy)
    phi = np.mod(np.arctan2(dy, dx), 2.0 * np.pi)
    n = planes.phi.size
    k = np.searchsorted(planes.phi, phi, side="right") - 1
    k = np.where(k < 0, n - 1, k)
    gaps = np.mod(np.roll(planes.phi, -1) - planes.phi, 2.0 * np.pi)
    gaps = np.where(gaps > 0, gaps, 2.0 * np.pi)
    u = np.mod(phi - planes.phi[k], 2.0 * np.pi) / gaps[k]
    out = np.zeros(r.size)
    for j in np.unique(k):
        on = k == j
        out[on] = _gap_cell(planes, int(j), r[on], u[on])
    return out


#: The lobe between planes is modelled when its Gaussian across a gap peaks this much above the higher flank
#: (:func:`_gap_integral`): then no plane measures the lobe's peak.
BETWEEN_PEAK = 1.05


def _specular_unsampled(planes: _GapPlanes, theta_i_deg: float) -> str | None:
    """The statement that no measured half-plane passes near the specular direction β0 = (sin θi, 0), where a
    lobe no plane sees could lie (neither in the value nor in its error bar); None when one passes within
    :data:`SPECULAR_SAMPLED` of it."""
    b0 = float(np.sin(np.radians(theta_i_deg)))
    # distance from β0 to each half-plane (a ray from the normal at azimuth φ): |b0 sin φ| ahead of the normal
    d = np.where(np.cos(planes.phi) > 0, np.abs(b0 * np.sin(planes.phi)), b0)
    nearest = float(d.min()) if d.size else b0
    if nearest <= SPECULAR_SAMPLED:
        return None
    return (f"no measured plane passes within {nearest:.3g} (direction cosines) of the specular direction: a "
            f"specular lobe narrower than about {nearest / 3:.2g} there would not be seen, and is neither in the "
            "value nor in its error bar")


def _across_width_factors(planes: _GapPlanes, opts: _DiskOptions) -> tuple[float, ...]:
    """Factors on the width across the planes of a lobe seen on one plane (:data:`ACROSS_WIDTH_FACTORS`, the wider
    one capped where the neighbouring planes, at distance d = |β_c| sin(gap) from its centre, would have seen it:
    d / radius, none beyond when they pass within the radius); none when they pass through its core, d below
    :data:`ACROSS_SAMPLED` × radius (the data sample its width: every C-plane passes the normal-incidence lobe)."""
    if opts.lobe_c is None or opts.radius <= 0:
        return ()
    phi = np.sort(planes.phi)
    gap = float(np.median(np.diff(np.concatenate([phi, [phi[0] + 2.0 * np.pi]]))))
    reach = abs(opts.lobe_c) * np.sin(min(gap, np.pi / 2)) / opts.radius
    if reach <= ACROSS_SAMPLED:
        return ()
    lo, hi = ACROSS_WIDTH_FACTORS
    return (lo,) if reach <= 1.0 else (lo, min(hi, reach))


def _reconstruct_disk(geom: Geometry, ref: NDArray[np.float64], ref_std: NDArray[np.float64],
                      n_psi: int = 256, n_r: int = 400, errors: bool = True) -> Reconstruction:
    """Body + lobe over the projected disk for records off the two arcs (:func:`sampling_method`).

    On a planes layout (:func:`_gap_planes`) whose lobe peaks between two half-planes, the lobe is not the
    in-plane arc's: everything is interpolated about the normal and the lobe across every gap follows the Gaussian
    the planes' flanks imply (:func:`_gap_cell`); the linear interpolation across azimuth is the alternative
    (``between_planes`` in the error bar)."""
    finite = np.isfinite(ref)
    planes = _gap_planes(geom, ref, ref_std)
    delta, peak = _gap_integral(planes) if planes is not None else (0.0, 1.0)
    # only a peak between planes leaves the in-plane lobe model: a lobe on a measured plane keeps it
    use_gap = planes is not None and peak > BETWEEN_PEAK
    fit = _disk_fit(geom, ref, ref_std, errors, lobe=not use_gap)
    w_gap = _gap_weights(planes, ref, delta) if use_gap else None
    sparse_lobe = _sparse_lobe(geom, fit)
    alt = _disk_alternatives(geom, ref, fit, sparse_lobe)
    comparisons = {"normal_centred": _disk_variant(geom, ref, fit, lobe_c=None, body_center="normal")}
    n_other = int(np.sum(finite & (geom.arc == "other")))
    assumptions = [f"records off the in-plane and perpendicular arcs ({n_other} of {int(finite.sum())}): "
                   "interpolated over the projected disk in polar coordinates (linear in the distance from the "
                   "centre, across azimuth between records at about the same distance)"]
    gap_alternatives, gap_text = _gap_statement(geom, ref, fit)
    if gap_alternatives is not None:
        alt["azimuth_gap"] = gap_alternatives
    if gap_text is not None:
        assumptions.append(gap_text)
    method, stated = _disk_method(geom, fit, sparse_lobe)
    center_deg = _lobe_center_deg(fit)
    reg = Region(fit.in_plane_region, None if center_deg is None else (center_deg, center_deg), None, center_deg, ())
    kappa, evaluate, beyond = fit.kappa, fit.evaluate, fit.beyond
    central = fit.body + kappa * fit.lobe
    lobe = kappa * fit.lobe

    def evaluated(values: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:
        return evaluate(values, directions, kappa)

    if w_gap is not None:
        alt = {g: {k: w + w_gap for k, w in a.items()} for g, a in alt.items()}
        # two planes do not measure the lobe's width across them: as wide as along them (central), not raised
        # at all (linear across), or narrower (σ² across ÷ GAP_NARROWER) with a rise of e more allowed
        alt["between_planes"] = {"linear_across": central.copy()}
        narrower = _gap_weights(planes, ref, _gap_integral(planes, GAP_NARROWER, BULGE_CAP + 1.0)[0])
        if narrower is not None:
            alt["between_planes"]["narrower_across"] = central + narrower
        central = central + w_gap
        lobe = lobe + w_gap
        method = "disk: everything about the normal, the lobe between planes as the Gaussian its flanks imply"
        stated.append(f"a lobe peaks between the measured planes ({peak:.3g} x the higher flank): across every gap "
                      "the lobe is the Gaussian through the two planes' flanks as wide across the planes as along "
                      "them (round in direction cosines; raised at most e^3 above its flanks), or falls off from "
                      "the one plane that shows it (error bar: interpolated linearly across azimuth)")
        level = float(w_gap @ np.nan_to_num(ref)) / delta if delta else 0.0
        m = w_gap / delta * level if delta else w_gap

        def evaluated(values: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:  # noqa: F811
            v = np.nan_to_num(np.asarray(values, dtype=np.float64))
            scale = float(m @ v) / level if level > 0 else 0.0
            return evaluate(values, directions, kappa) + scale * _gap_evaluate(planes, geom, directions)

    if planes is not None:
        unseen = _specular_unsampled(planes, geom.theta_i)
        if unseen is not None:
            stated.append(unseen)
    if w_gap is None and planes is not None and np.any(lobe):
        factors = _across_width_factors(planes, fit.options)
        if factors:
            # planes 15° or more apart that pass the lobe farther than its radius see it on one plane only: its
            # extent across the planes is the in-plane one by assumption (round in direction cosines), which the
            # data do not pin down; the error bar takes it narrower and as much wider as the neighbouring planes,
            # which show no lobe, allow (the lobe's integral scales with its width across)
            alt["across_width"] = {f"x{f:.3g}": fit.body + f * lobe for f in factors}
            stated.append("planes layout: the lobe is taken as wide across the planes as along them (round); the "
                          "error bar includes it " + " and ".join(f"{f:.3g}x" for f in factors) + " as wide across")

    return Reconstruction(central=central, alternatives=alt, comparisons=comparisons,
                          lobe=lobe, region=reg,
                          extrapolated_beyond_deg=(None if beyond is None else
                                                   float(np.degrees(np.arcsin(min(beyond, 1.0))))),
                          assumptions=assumptions + stated, method=method, evaluate=evaluated)


# ------------------------------------------------------------------------------------------- datasets
def band_selection(wavelength_nm: NDArray[np.float64], band_nm: tuple[float, float] | None
                   ) -> tuple[NDArray[np.bool_], float, float]:
    """The wavelengths [nm] of a closed band (low, high) [nm] (default: all of ``wavelength_nm``) and its edges;
    one line naming the band when it is empty or holds no measured wavelength.

    Parameters
    ----------
    wavelength_nm : ndarray
        Wavelengths [nm].
    band_nm : tuple of float, optional
        (low, high) [nm], closed (default: all of ``wavelength_nm``).

    Returns
    -------
    tuple
        Mask of ``wavelength_nm`` in the band, and its low and high edges [nm].
    """
    lo, hi = band_nm if band_nm is not None else (float(wavelength_nm.min()), float(wavelength_nm.max()))
    if not hi >= lo:
        raise InputError("empty wavelength band", field="band", expected="LO <= HI (nm)", got=(lo, hi))
    sel = band_mask(wavelength_nm, (lo, hi))
    if not sel.any():
        raise InputError("no measured wavelength in the band", field="band",
                         expected=f"a band overlapping {wavelength_nm.min():g}-{wavelength_nm.max():g} nm",
                         got=(lo, hi))
    return sel, float(lo), float(hi)


@dataclass(frozen=True)
class HemisphericalResult:
    """Directional-hemispherical reflectance or transmittance (fractions) of one configuration, incidence and side,
    per wavelength (nm), with standard uncertainties and the components of the reconstruction error."""

    config: str
    theta_i: float
    side: str
    wavelength: NDArray[np.float64]
    value: NDArray[np.float64]
    std_measurement: NDArray[np.float64]
    std_reconstruction: NDArray[np.float64]
    components: dict[str, NDArray[np.float64]]
    method: str
    assumptions: list[str]
    extrapolated_beyond_deg: float | None
    lobe_region_deg: tuple[float, float] | None
    lobe: NDArray[np.float64]
    notes: tuple[str, ...] = ()  # conflicting duplicates and other facts a user must see (with ``warnings``)

    @property
    def std(self) -> NDArray[np.float64]:
        return np.hypot(self.std_measurement, self.std_reconstruction)

    def band_average(self, band_nm: tuple[float, float] | None = None) -> dict:
        """Δλ-weighted mean of ρ over a wavelength band (an equal-energy spectrum).

        Parameters
        ----------
        band_nm
            (low, high) [nm], closed; default: every wavelength with data.

        Returns
        -------
        dict
            ``value``, ``std``, ``std_measurement`` (independent between wavelengths), ``std_reconstruction``
            (fully correlated between wavelengths), ``lobe`` [fractions]; ``band_nm``, the number of
            ``wavelengths``, and the labels, method, assumptions and band-averaged components.
        """
        wl = self.wavelength
        if not np.all(np.isfinite(wl)):  # a monochrome dataset without a wavelength coordinate
            return self._summary(np.ones(wl.size, dtype=bool), None)
        sel, lo, hi = band_selection(wl, band_nm)
        return self._summary(sel, [lo, hi])

    def _summary(self, sel: NDArray[np.bool_], band: list[float] | None) -> dict:
        wl = self.wavelength
        w = np.gradient(wl[sel]) if sel.sum() > 1 else np.ones(1)
        a = w / w.sum()
        value = float(a @ self.value[sel])
        meas = float(np.sqrt(np.sum((a * self.std_measurement[sel]) ** 2)))
        rec = float(a @ self.std_reconstruction[sel])
        comps = {k: float(a @ v[sel]) for k, v in self.components.items()}
        return {"incidence_deg": self.theta_i, "side": self.side, "config": self.config,
                "band_nm": band, "wavelengths": int(sel.sum()), "value": value,
                "std": float(np.hypot(meas, rec)), "std_measurement": meas, "std_reconstruction": rec,
                "lobe": float(a @ self.lobe[sel]), "method": self.method,
                "extrapolated_beyond_deg": self.extrapolated_beyond_deg, "assumptions": self.assumptions,
                "components": comps}

    @property
    def warnings(self) -> list[str]:
        """Physically impossible values: a reflectance or transmittance above 1 by more than
        :data:`IMPOSSIBLE_SIGMA` standard uncertainties (a calibration, quantity or reconstruction problem)."""
        over = np.flatnonzero(self.value - IMPOSSIBLE_SIGMA * self.std > 1.0)
        if not over.size:
            return list(self.notes)
        k = int(over[np.argmax(self.value[over])])
        where = f"{self.wavelength[k]:g} nm" if np.isfinite(self.wavelength[k]) else "the one wavelength"
        return [f"{self.side} at {self.theta_i:g} deg exceeds 1 by more than {IMPOSSIBLE_SIGMA:g} standard "
                f"uncertainties at {over.size} of {self.value.size} wavelengths (largest {self.value[k]:.4g} "
                f"± {self.std[k]:.2g} at {where}): not a physical result; check the reference-beam calibration, "
                "the table's quantity (--quantity) or the sampling of the specular lobe", *self.notes]

    def as_dict(self) -> dict:
        """The result as a JSON-ready dict.

        Returns
        -------
        dict
            ``incidence_deg`` [deg], ``side``, ``config``, ``wavelength_nm`` [nm]; ``value``, ``std``,
            ``std_measurement``, ``std_reconstruction`` and ``lobe`` [fractions] per wavelength; ``method``,
            ``lobe_region_deg`` and ``extrapolated_beyond_deg`` [deg], ``assumptions`` and ``warnings``.
        """
        return {"incidence_deg": self.theta_i, "side": self.side, "config": self.config,
                "wavelength_nm": self.wavelength, "value": self.value, "std": self.std,
                "std_measurement": self.std_measurement, "std_reconstruction": self.std_reconstruction,
                "lobe": self.lobe, "method": self.method, "lobe_region_deg": self.lobe_region_deg,
                "extrapolated_beyond_deg": self.extrapolated_beyond_deg, "assumptions": self.assumptions,
                "warnings": self.warnings}


def _scale_std(ds: xr.Dataset, config: str, n_wl: int) -> NDArray[np.float64]:
    rel = np.full(n_wl, float(ds.attrs.get("common_relative_std", 0.0)))
    if "incident_relative_std" in ds and "configuration" in ds["incident_relative_std"].dims:
        names = [str(c) for c in ds["configuration"].values]
        if config in names:
            extra = np.nan_to_num(ds["incident_relative_std"].values[names.index(config)])
            rel = np.hypot(rel, extra)
    return rel


#: Duplicates (one direction measured more than once) disagree when their χ² per degree of freedom exceeds this.
DUPLICATE_CHI2 = 4.0


@dataclass(frozen=True)
class ProfileModel:
    """One configuration, incidence and side of a dataset, ready to integrate and to evaluate.

    Records measured at the same direction are merged (``geom``, ``f``, ``u`` are per merged record): their mean,
    with the larger of the propagated and the observed standard error of the mean. ``parts`` holds one
    :class:`Reconstruction` per set of wavelengths with the same finite records (columns ``cols`` of ``f``)."""

    config: str
    theta_i: float
    side: str
    geom: Geometry
    f: NDArray[np.float64]  # merged records × wavelengths [1/sr]
    u: NDArray[np.float64]
    wavelength: NDArray[np.float64]  # [nm] (NaN: unknown)
    cols: NDArray[np.int64]  # wavelengths with finite data
    parts: tuple[tuple[NDArray[np.int64], Reconstruction], ...]  # (indices into cols, reconstruction)
    scale: NDArray[np.float64]  # relative standard uncertainty common to all records, per wavelength
    warnings: tuple[str, ...] = ()
    assumptions: tuple[str, ...] = ()  # made on the records before the reconstruction (a mirrored half)

    def band_weights(self, band_nm: tuple[float, float] | None = None) -> NDArray[np.float64]:
        """Δλ weights (summing to 1) over ``cols`` of the band mean (every finite wavelength by default).

        Parameters
        ----------
        band_nm : tuple of float, optional
            (low, high) [nm], closed (default: every finite wavelength).

        Returns
        -------
        ndarray
            Weights [-] over ``cols``, summing to 1 (equal weights without wavelengths).
        """
        wl = self.wavelength[self.cols]
        if not np.all(np.isfinite(wl)):
            return np.full(wl.size, 1.0 / wl.size)
        sel, _, _ = band_selection(wl, band_nm)
        w = np.zeros(wl.size)
        w[sel] = np.gradient(wl[sel]) if sel.sum() > 1 else 1.0
        return w / w.sum()

    def bsdf_at(self, weights: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """The reconstructed BSDF [1/sr] of the weighted wavelength mean (``weights`` over ``cols``) at unit
        vectors (..., 3) in the sample frame: the function whose integral :func:`hemispherical_profile` reports.

        Parameters
        ----------
        weights : ndarray
            Wavelength weights [-] over ``cols`` (e.g. :meth:`band_weights`).
        directions : ndarray
            Unit vectors (..., 3) in the sample frame [-].

        Returns
        -------
        ndarray
            BSDF [1/sr], shape ``directions.shape[:-1]``, clipped at 0.
        """
        d = np.asarray(directions, dtype=np.float64)
        out = np.zeros(d.shape[:-1]).ravel()
        fz = np.nan_to_num(self.f[:, self.cols])
        for js, rec in self.parts:
            a = weights[js]
            if np.any(a):
                out = out + rec.evaluate(fz[:, js] @ a, d.reshape(-1, 3))
        # a lobe residual below a bridged body can take the sum under 0 in a few directions: a BSDF is not
        # negative there (the table integrates to the value within the clipped part, which the TIS check shows)
        return np.maximum(out, 0.0).reshape(d.shape[:-1])


def unique_rows(key: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """``np.unique(key, axis=0, return_index=True, return_inverse=True, return_counts=True)`` of an (n, 2) float
    array without its row-view sort (0.8 s of 52 calls on a 130 000-record table; a lexsort is a few ms): the
    first index of each distinct row (rows ordered by column 0, then 1), each row's group, the group sizes. −0.0
    and 0.0 are one value.

    Parameters
    ----------
    key : ndarray
        (n, 2) float array.

    Returns
    -------
    tuple of ndarray
        First index of each distinct row, each row's group index, group sizes.
    """
    k = np.asarray(key, dtype=np.float64) + 0.0
    if k.shape[0] == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    order = np.lexsort((k[:, 1], k[:, 0]))  # stable: the first occurrence leads its group
    ks = k[order]
    new = np.empty(ks.shape[0], dtype=bool)
    new[0] = True
    new[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    inverse = np.empty(k.shape[0], dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    starts = np.flatnonzero(new)
    return order[starts].astype(np.int64), inverse, np.diff(np.append(starts, ks.shape[0])).astype(np.int64)


def _merge_duplicates(geom: Geometry, f: NDArray, u: NDArray, label: str
                      ) -> tuple[Geometry, NDArray, NDArray, list[str]]:
    """Records at the same direction merged: mean value; standard uncertainty the larger of the propagated
    (rms u/√k) and the observed (sample std/√k) standard error of the mean; a warning when they disagree beyond
    their uncertainties (χ²/dof > :data:`DUPLICATE_CHI2`)."""
    x, y = geom.frame()
    key = np.round(np.stack([x, y], axis=1), 9)
    first, inverse, counts = unique_rows(key)
    if counts.max() == 1:
        return geom, f, u, []
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    group = rank[inverse]
    m = first.size
    fm = np.full((m, f.shape[1]), np.nan)
    um = np.full((m, f.shape[1]), np.nan)
    warnings: list[str] = []
    worst = (0.0, -1)
    for g in range(m):
        members = np.flatnonzero(group == g)
        if members.size == 1:
            fm[g], um[g] = f[members[0]], u[members[0]]
            continue
        v, s = f[members], u[members]
        k = np.sum(np.isfinite(v), axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.nanmean(np.where(np.isfinite(v), v, np.nan), axis=0) if np.isfinite(v).any() else v[0]
            prop = np.sqrt(np.nanmean(s ** 2, axis=0) / np.maximum(k, 1))
            spread = np.nanstd(v, axis=0, ddof=1) / np.sqrt(np.maximum(k, 1)) if members.size > 1 else 0.0
            chi2 = np.nansum((v - mean) ** 2 / np.where(s > 0, s, np.inf) ** 2, axis=0) / np.maximum(k - 1, 1)
        fm[g] = mean
        um[g] = np.fmax(prop, np.nan_to_num(spread))
        c = float(np.nanmax(chi2)) if np.isfinite(chi2).any() else 0.0
        if c > worst[0]:
            worst = (c, g)
    keep = first[order]
    arc = geom.arc[keep].copy()
    for g in range(m):  # a merged direction lies on an arc if any of its records does
        labels = set(geom.arc[group == g])
        arc[g] = "in_plane" if "in_plane" in labels else "perpendicular" if "perpendicular" in labels else arc[g]
    psa = None
    if geom.basis_psa is not None:  # a cell's records at one direction: their parts of the cell add up
        psa = np.zeros(m)
        np.add.at(psa, group, geom.basis_psa)
    merged = Geometry(theta_i=geom.theta_i, phi_i=geom.phi_i, theta_s=geom.theta_s[keep], phi_s=geom.phi_s[keep],
                      arc=arc, side=geom.side, basis_psa=psa,
                      basis_cell=None if geom.basis_cell is None else geom.basis_cell[keep],
                      basis_spec=geom.basis_spec)
    n_dup = int(np.sum(counts > 1))
    if worst[0] > DUPLICATE_CHI2:
        g = worst[1]
        vals = f[group == g]
        warnings.append(f"{label}: {geom.side} at {geom.theta_i:g} deg: the direction θs = {merged.theta_s[g]:g}, "
                        f"φs = {merged.phi_s[g]:g} deg is measured {int(np.sum(group == g))} times with values "
                        f"{np.nanmin(vals):.4g}-{np.nanmax(vals):.4g} 1/sr, beyond their uncertainties "
                        f"(χ²/dof = {worst[0]:.3g}); merged as their mean, the spread in its uncertainty "
                        f"({n_dup} direction(s) measured more than once)")
    return merged, fm, um, warnings


def _mirrored_half(geom: Geometry, f: NDArray, u: NDArray) -> tuple[Geometry, NDArray, NDArray, list[str]]:
    """Records on one side of the plane of incidence only (a half-hemisphere scan) mirrored across it: plane
    symmetry assumed and stated. The mirrored records repeat the measured values (their uncertainties are not
    independent of the originals: the measurement part is then understated by up to √2 off the plane)."""
    _, y = geom.frame()
    ok = np.isfinite(f).any(axis=1)
    yy = y[ok]
    if not (np.any(np.abs(yy) > 1e-9) and (np.all(yy >= -1e-9) or np.all(yy <= 1e-9))):
        return geom, f, u, []
    off = np.flatnonzero(np.abs(y) > 1e-9)
    phi_spec = geom.phi_i - 180.0
    mirrored = Geometry(theta_i=geom.theta_i, phi_i=geom.phi_i,
                        theta_s=np.concatenate([geom.theta_s, geom.theta_s[off]]),
                        phi_s=np.concatenate([geom.phi_s, np.mod(2.0 * phi_spec - geom.phi_s[off], 360.0)]),
                        arc=np.concatenate([geom.arc, geom.arc[off]]), side=geom.side)
    note = (f"records on one side of the plane of incidence only: mirrored across it ({off.size} records), the "
            "sample assumed plane-symmetric")
    return mirrored, np.concatenate([f, f[off]]), np.concatenate([u, u[off]]), [note]


def label_mask(values: object, label: str) -> NDArray[np.bool_]:
    """``values == label`` for a coordinate of string labels (``config``, ``side``): an object or unicode array is
    compared as it is; ``astype(str)`` of the 130 000 labels of a large vendor table cost 30-60 ms per call, and
    a reduction asks per configuration, incidence and side.

    Parameters
    ----------
    values : array_like
        Labels of a coordinate.
    label : str
        Label to match.

    Returns
    -------
    ndarray of bool
    """
    arr = np.asarray(values)
    if arr.dtype.kind in "OU":
        return np.asarray(arr == label, dtype=bool)
    return arr.astype(str) == label


def label_set(values: object) -> list[str]:
    """The distinct string labels of a coordinate, sorted (``sorted(set(values.astype(str)))``, without the copy).

    Parameters
    ----------
    values : array_like
        Labels of a coordinate.

    Returns
    -------
    list of str
    """
    return sorted({str(v) for v in set(np.asarray(values).ravel().tolist())})


def profile_model(ds: xr.Dataset, config: str, theta_i_deg: float, side: str, n_psi: int = 256,
                  n_r: int = 400, errors: bool = True) -> ProfileModel:
    """The records of one configuration, incidence [deg] and side, merged and reconstructed (:class:`ProfileModel`);
    ``errors=False`` gives the value without the reconstruction error (no alternative reconstructions).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset (see :func:`hemispherical_profile`).
    config : str
        Configuration name.
    theta_i_deg : float
        Incidence angle [deg], a measured one.
    side : str
        ``"reflection"`` or ``"transmission"``.
    n_psi, n_r : int
        Quadrature nodes in azimuth and radius of the polar grids.
    errors : bool
        Compute the reconstruction error (alternative reconstructions).

    Returns
    -------
    ProfileModel
    """
    sel = label_mask(ds["config"].values, config) & (ds["side"].values == side) & np.isclose(
        ds["theta_i"].values, theta_i_deg, atol=1e-6, rtol=0)
    if not sel.any():
        raise InputError("no records for this configuration, incidence and side", file=ds.attrs.get("source"),
                         field="theta_i", expected=f"records of '{config}' at {theta_i_deg:g} deg, {side}")
    idx = np.flatnonzero(sel)
    f = np.atleast_2d(ds["bsdf"].values[idx].reshape(idx.size, -1)).astype(np.float64)
    u = (ds["bsdf_std"].values[idx].reshape(idx.size, -1).astype(np.float64) if "bsdf_std" in ds
         else np.zeros_like(f))
    wl = np.atleast_1d(ds["wavelength"].values if "wavelength" in ds.dims else np.array([np.nan])).astype(float)
    phi_i = ds["phi_i"].values[idx]
    if np.ptp(phi_i) > 1e-9:
        raise InputError("records of one incidence have different source azimuths", field="phi_i",
                         expected="one phi_i per incidence")
    arc = (np.asarray(ds["arc"].values[idx]).astype(str) if "arc" in ds.coords
           else np.full(idx.size, "in_plane"))
    psa = (ds[basis.COORD].values[idx].astype(np.float64) if basis.COORD in ds.coords else None)
    cell = spec = None
    if psa is not None and basis.CELL_COORD in ds.coords:
        cell = np.asarray(ds[basis.CELL_COORD].values[idx], dtype=np.int64)
        spec = str(ds[basis.CELL_COORD].attrs.get("basis", "")) or None
    geom = Geometry(theta_i=float(theta_i_deg), phi_i=float(phi_i[0]), theta_s=ds["theta_s"].values[idx].astype(float),
                    phi_s=ds["phi_s"].values[idx].astype(float), arc=arc, side=side, basis_psa=psa,
                    basis_cell=cell, basis_spec=spec)
    label = str(ds.attrs.get("source", "dataset"))
    geom, f, u, warnings = _merge_duplicates(geom, f, u, label)
    geom, f, u, stated = _mirrored_half(geom, f, u)
    finite = np.isfinite(f)
    cols = np.flatnonzero(finite.any(axis=0))
    if cols.size == 0:
        raise InputError("no finite BSDF values", file=ds.attrs.get("source"), field="bsdf",
                         expected=f"values for '{config}' at {theta_i_deg:g} deg, {side}")
    # wavelengths with the same set of finite records share one reconstruction
    patterns: dict[bytes, list[int]] = {}
    for j, c in enumerate(cols):
        patterns.setdefault(finite[:, c].tobytes(), []).append(j)
    parts = []
    for key, js in patterns.items():
        mask = np.frombuffer(key, dtype=bool)
        sub = f[:, cols[js]]
        ref = np.where(mask, np.nan_to_num(sub).mean(axis=1), np.nan)
        ref_std = np.sqrt(np.mean(np.nan_to_num(u[:, cols[js]]) ** 2, axis=1) / len(js))
        parts.append((np.asarray(js, dtype=np.int64), reconstruct(geom, ref, ref_std, n_psi, n_r, errors)))
    return ProfileModel(config=config, theta_i=float(theta_i_deg), side=side, geom=geom, f=f, u=u, wavelength=wl,
                        cols=cols, parts=tuple(parts), scale=_scale_std(ds, config, wl.size),
                        warnings=tuple(warnings), assumptions=tuple(stated))


def hemispherical_profile(ds: xr.Dataset, config: str, theta_i_deg: float, side: str, n_psi: int = 256,
                          n_r: int = 400) -> HemisphericalResult:
    """Directional-hemispherical reflectance or transmittance ρ(λ) of one configuration, incidence and side.

    Parameters
    ----------
    ds
        Calibrated dataset (record × wavelength; ``bsdf`` and optionally ``bsdf_std`` [1/sr]; per-record
        ``theta_i``, ``phi_i``, ``theta_s``, ``phi_s`` [deg], ``side``, ``arc``, ``config``).
    config
        Configuration name (the ``config`` label of the records).
    theta_i_deg
        Incidence angle [deg], a measured one.
    side
        ``"reflection"`` or ``"transmission"``.
    n_psi, n_r
        Quadrature nodes in azimuth and radius of the polar grids (the ``quadrature`` error halves both).

    Returns
    -------
    HemisphericalResult
        ρ [fraction of the incident power] per wavelength [nm] with finite data, its measurement and
        reconstruction standard uncertainties [fraction], the lobe part, the components of the error, the
        method and the assumptions (module docstring).
    """
    return result_of(profile_model(ds, config, theta_i_deg, side, n_psi, n_r))


def result_of(model: ProfileModel) -> HemisphericalResult:
    """The :class:`HemisphericalResult` of a :class:`ProfileModel`: every wavelength one dot product.

    Parameters
    ----------
    model : ProfileModel
        Merged and reconstructed records of one configuration, incidence and side.

    Returns
    -------
    HemisphericalResult
    """
    cols, f, u, scale = model.cols, model.f, model.u, model.scale
    out = {k: np.full(cols.size, np.nan) for k in ("value", "meas", "rec", "lobe")}
    comps: dict[str, NDArray] = {}
    info = None
    for js, rec in model.parts:
        info = rec if info is None or len(js) > 1 else info
        fz = np.nan_to_num(f[:, cols[js]])
        uz = np.nan_to_num(u[:, cols[js]])
        value = rec.central @ fz
        out["value"][js] = value
        out["lobe"][js] = rec.lobe @ fz
        out["meas"][js] = np.hypot(np.sqrt((rec.central ** 2) @ uz ** 2), scale[cols[js]] * value)
        parts = []
        for group, alts in rec.alternatives.items():
            dev = np.max([np.abs(w @ fz - value) for w in alts.values()], axis=0)
            comps.setdefault(group, np.zeros(cols.size))[js] = dev
            parts.append(dev)
        out["rec"][js] = np.sqrt(np.sum(np.square(parts), axis=0))
        for name, w in rec.comparisons.items():
            comps.setdefault(name, np.full(cols.size, np.nan))[js] = w @ fz
    assert info is not None
    return HemisphericalResult(config=model.config, theta_i=model.theta_i, side=model.side,
                               wavelength=model.wavelength[cols], value=out["value"], std_measurement=out["meas"],
                               std_reconstruction=out["rec"], components=comps, method=info.method,
                               assumptions=[*model.assumptions, *info.assumptions],
                               extrapolated_beyond_deg=info.extrapolated_beyond_deg,
                               lobe_region_deg=info.region.in_plane_deg, lobe=out["lobe"],
                               notes=model.warnings)


def hemispherical(ds: xr.Dataset, theta_i_deg: list[float] | None = None, sides: tuple[str, ...] | None = None,
                  configs: list[str] | None = None, n_psi: int = 256, n_r: int = 400,
                  errors: bool = True) -> list[HemisphericalResult]:
    """Directional-hemispherical reflectance/transmittance for every configuration, incidence and side.

    Parameters
    ----------
    ds
        Calibrated dataset (see :func:`hemispherical_profile`).
    theta_i_deg
        Incidence angles [deg] to reduce; default: every measured one (per configuration and side).
    sides
        Sides to reduce; default: those the dataset holds.
    configs
        Configurations to reduce; default: all.
    n_psi, n_r
        Quadrature nodes (see :func:`hemispherical_profile`).
    errors
        False: the values only, without the reconstruction error (``std_reconstruction`` 0).

    Returns
    -------
    list of HemisphericalResult
        Ordered by configuration, side (reflection first) and incidence.
    """
    cfg_all = label_set(ds["config"].values)
    side_of = ds["side"].values
    theta_of = np.round(ds["theta_i"].values, 9)
    out = []
    for config in configs or cfg_all:
        in_cfg = label_mask(ds["config"].values, config)  # masks, not ds.isel: a copy of every variable per call
        if not in_cfg.any():
            raise InputError("no records with this configuration", file=ds.attrs.get("source"), field="config",
                             expected="one of " + ", ".join(cfg_all), got=config)
        for side in sides or SIDES:
            on_side = in_cfg & (side_of == side)
            if not on_side.any():
                continue
            for th in theta_i_deg if theta_i_deg is not None else sorted(set(theta_of[on_side].tolist())):
                out.append(result_of(profile_model(ds, config, th, side, n_psi, n_r, errors)))
    if not out:
        raise InputError("no records to reduce", file=ds.attrs.get("source"), field="side",
                         expected="reflection or transmission records")
    return out


# ------------------------------------------------------------------------------------------- which reduction
def reduction_kind(ds: xr.Dataset) -> str:
    """"interactions" for a phosphor scan of the two-wavelength approach, else "hemispherical".

    Rule: the interaction table (bibs/biys/yiys, Table 2 of the power-budget paper) is made when the dataset
    holds a bi-spectral BSDF (variable ``bsdf_bispectral`` with finite values), configurations named ``blue``
    and ``yellow``, records on both sides, and is not marked elastic (``attrs['elastic']``, set by the table
    reader). Any other dataset is reduced as elastic scatter: hemispherical reflectance/transmittance.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset.

    Returns
    -------
    str
        ``"interactions"`` or ``"hemispherical"``.
    """
    if int(ds.attrs.get("elastic", 0) or 0):
        return "hemispherical"
    configs = set(label_set(ds["config"].values)) if "config" in ds.coords else set()
    sides = set(label_set(ds["side"].values)) if "side" in ds.coords else set()
    bispectral = "bsdf_bispectral" in ds and bool(np.isfinite(ds["bsdf_bispectral"].values).any())
    if bispectral and {"blue", "yellow"} <= configs and set(SIDES) <= sides:
        return "interactions"
    return "hemispherical"


# ---------------------------------------------------------------------------------- one reconstruction, every path
@dataclass(frozen=True)
class ElasticSource:
    """The reconstructed BSDF of elastic data at one wavelength (or a band mean) per side, with the engine's
    hemispherical value per incidence: what ``convert`` and ``export`` write and check against."""

    fn: Callable[[float, str, NDArray[np.float64]], NDArray[np.float64]]  # bsdf_fn(theta_i_deg, side, dirs)
    incidences_deg: dict[str, list[float]]
    tis: dict[str, list[float]]  # per side, one value per incidence [fraction]
    wavelength_nm: float | None
    what: str  # "550 nm", "mean over 12 wavelengths 500-600 nm", "single wavelength"
    methods: dict[str, list[str]]
    #: the file's angle basis when every profile is one (:mod:`bsdfkit.reduction.basis`), else None
    basis: str | None = None

    @property
    def piecewise_constant(self) -> bool:
        """True when every profile is a file's angle basis (integrated by its basis sum): ``fn`` is then constant
        over each cell of the basis."""
        return all(m.startswith("basis") for ms in self.methods.values() for m in ms)

    def exact_tis(self, theta_i_deg: float, side: str) -> float:
        """The engine's hemispherical value [-] at a reconstructed incidence [deg] and side.

        Parameters
        ----------
        theta_i_deg : float
            Incidence [deg], one of :attr:`incidences_deg`.
        side : str
            ``reflection`` or ``transmission``.

        Returns
        -------
        float
            TIS [-].
        """
        t = round(float(theta_i_deg), 6)
        for u, v in zip(self.incidences_deg.get(side, ()), self.tis.get(side, ())):
            if round(float(u), 6) == t:
                return float(v)
        raise InputError("incidence not in the source", field="theta_i",
                         expected=", ".join(f"{u:g}" for u in self.incidences_deg.get(side, [])), got=theta_i_deg)


def _spectral_weights(model: ProfileModel, wavelength: float | None, band: tuple[float, float] | None,
                      label: str) -> tuple[NDArray[np.float64], float | None, str]:
    wl = model.wavelength[model.cols]
    if band is not None:
        w = model.band_weights(band)
        lo, hi = band
        return w, float(w @ wl), f"mean over {int(np.sum(w > 0))} wavelengths {lo:g}-{hi:g} nm (Δλ-weighted)"
    if wl.size == 1:
        if wavelength is not None and np.isfinite(wl[0]) and abs(wl[0] - wavelength) > 1e-6:
            raise InputError("wavelength not in the source", file=label, field="--wavelength",
                             expected=f"{wl[0]:g} nm", got=wavelength)
        chosen = float(wl[0]) if np.isfinite(wl[0]) else wavelength
        return np.ones(1), chosen, "single wavelength" if chosen is None else f"{chosen:g} nm"
    if wavelength is None:
        raise InputError(f"the source holds {wl.size} wavelengths; a ray-tracer table holds one", file=label,
                         field="--wavelength", expected=f"--wavelength NM ({wl.min():g}-{wl.max():g} nm) or "
                         "--band LO,HI for their mean")
    k = int(np.argmin(np.abs(wl - wavelength)))
    if abs(wl[k] - wavelength) > 1e-6:
        raise InputError("wavelength not measured", file=label, field="--wavelength",
                         expected=f"one of the measured wavelengths ({wl.min():g}-{wl.max():g} nm, "
                                  f"{wl.size} values) or --band LO,HI", got=wavelength)
    w = np.zeros(wl.size)
    w[k] = 1.0
    return w, float(wl[k]), f"{wl[k]:g} nm"


def elastic_source(ds: xr.Dataset, sides: tuple[str, ...] | list[str], wavelength_nm: float | None = None,
                   band_nm: tuple[float, float] | None = None, config: str | None = None,
                   theta_i_deg: list[float] | None = None) -> ElasticSource:
    """The engine's reconstruction of elastic data as a BSDF callable, and its hemispherical values.

    Parameters
    ----------
    ds
        Calibrated dataset of one configuration (elastic scatter).
    sides
        Sides to reconstruct.
    wavelength_nm
        Wavelength [nm] to write from a spectral dataset (a monochrome one takes it as its label).
    band_nm
        (low, high) [nm]: the Δλ-weighted mean over the band (as :meth:`HemisphericalResult.band_average`).
    config
        Configuration (default: the only one).
    theta_i_deg
        Incidences [deg] (default: every measured one, per side).

    Returns
    -------
    ElasticSource
        ``fn(theta_i_deg, side, directions)`` [1/sr] integrates to ``tis`` at every incidence: the table a
        writer samples from it integrates to what ``bsdfkit tis`` reports.
    """
    label = str(ds.attrs.get("source", "dataset"))
    configs = label_set(ds["config"].values)
    if config is None:
        if len(configs) != 1:
            raise InputError("the dataset holds several configurations; choose one", file=label,
                             field="config", expected=" or ".join(configs))
        config = configs[0]
    models: dict[tuple[str, float], ProfileModel] = {}
    weights: dict[tuple[str, float], NDArray] = {}
    out_t: dict[str, list[float]] = {}
    out_tis: dict[str, list[float]] = {}
    methods: dict[str, list[str]] = {}
    chosen, what = None, ""
    for side in sides:
        on = ds.isel(record=np.flatnonzero((ds["side"].values == side)
                                           & label_mask(ds["config"].values, config)))
        if on.sizes["record"] == 0:
            raise InputError("the source holds no data for this side", file=label, field="--side", got=side)
        angles = theta_i_deg if theta_i_deg is not None else incidences(on)
        out_t[side], out_tis[side], methods[side] = [], [], []
        for th in angles:
            model = profile_model(ds, config, float(th), side, errors=False)  # the value is what is checked
            w, chosen, what = _spectral_weights(model, wavelength_nm, band_nm, label)
            res = result_of(model)
            key = (side, round(float(th), 6))
            models[key], weights[key] = model, w
            out_t[side].append(float(th))
            out_tis[side].append(float(w @ res.value))
            methods[side].append(res.method)

    def fn(theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        key = (side, round(float(theta_i_deg), 6))
        if key not in models:
            raise InputError("incidence not measured", file=label, field="theta_i",
                             expected="one of " + ", ".join(f"{t:g}" for t in out_t.get(side, [])),
                             got=theta_i_deg)
        return models[key].bsdf_at(weights[key], directions)

    specs = {m.geom.basis_spec for m in models.values()}
    return ElasticSource(fn=fn, incidences_deg=out_t, tis=out_tis, wavelength_nm=chosen,
                         what=what, methods=methods, basis=specs.pop() if len(specs) == 1 else None)
