"""Angular reductions: hemisphere reconstruction from two measured arcs, and TIS with error bars.

A goniometer scan of the power-budget paper (§2 of [Power-budget], docs/references.md) measures two arcs
per incidence and side: the plane of incidence, and the plane perpendicular to it through the specular
direction. The TIS needs the whole hemisphere. We work in Harvey–Shack direction cosines, where the
projected solid angle is exactly cos θs dΩ = dβx dβy (docs/exports.md §3), so

    TIS = ∫∫_{|β| ≤ 1} f(β) dβx dβy,

and reconstruct f around the specular point β0 (for the source at φi = 180°, β0 = (sin θi, 0); the same β0 for
light transmitted through a plate). With Δ = β − β0 = r(cos ψ, sin ψ):

* the in-plane arc gives two half-profiles along ±Δα (Δβ = 0): f_+α(r), f_−α(r);
* the perpendicular arc gives two half-profiles along ±Δβ; it is **not** a line of constant α — its points
  are Δα = −sin θi (1 − cos ε), Δβ = sin ε (docs/reductions.md, step 2) — so each point is placed at its true radius
  r = |Δ|, not at sin ε;
* the hemisphere is the elliptical blend of the two arcs (docs/reductions.md, step 3; done in f rather than
  ln f so that the TIS is linear in the data and negative values after dark subtraction are kept):

      f(r, ψ) = cos²ψ · f_{sgn cos ψ · α}(r) + sin²ψ · f_{sgn sin ψ · β}(r).

  It is exact for any f that depends on |Δ| only (a Lambertian body, Gaussian or ABg lobes about β0) and for
  an in-plane profile that differs on the two sides of the specular point.

Half-profiles are interpolated in r (in ln f between positive samples for the TIS value, in f for the linear
weights) and held constant beyond the last measured radius. Missing arcs
are filled from the others (documented in :meth:`Hemisphere.from_profile`). The integral uses polar
coordinates centred on β0, clipped to the unit disk at t_max(ψ) = −b cos ψ + √(b² cos² ψ + 1 − b²): a midpoint
rule in ψ (periodic, exponentially convergent) and Gauss–Legendre in r.

Outside the radii a half-axis actually sampled (the perpendicular arc stops at ε = ±60°; about the normal it
starts at |β| = sin θi), its weight is handed to the half-axes sampled at that radius; only where none is,
the half-axis sampled farthest out holds its last value.

Error bars: the measurement part propagates the per-record standard uncertainties through the (linear)
quadrature weights and adds the scale uncertainty common to all records (the reference beam,
``attrs['common_relative_std']`` of the profile); the TIS value itself interpolates half-profiles in ln f where
neighbouring samples are
positive (linear in f elsewhere), which follows the convex tails of lobes between sparse samples
(docs/reductions.md, step 5). The reconstruction part adds in quadrature (i) the change when the quadrature grid is
halved, (ii) the change when half-profiles are interpolated in f instead of ln f, (iii) the largest change
when the blend exponent goes from 2 (cos²ψ) to 1 or 4, and (iv) the change when data ends are held instead of
borrowed. The single-arc (radially symmetric) reconstructions are reported for comparison.

The paper's own rectangle sum, eq. (7) of [Power-budget], is :func:`tis_rectangle_sum`.
"""
from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import CONVERSION_BAND_NM, SIDES, InteractionBands
from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.core.hemisphere import linear_weights, unit_disk_reach
from bsdfkit.core.quadrature import gauss_legendre
from bsdfkit.core.records import incidences, select
from bsdfkit.reduction.spectral import bispectral_band_integral, interaction_profile

HALVES = ("+alpha", "-alpha", "+beta", "-beta")


@dataclass(frozen=True)
class HalfProfile:
    """Samples of f along one half-axis: radii (sorted, unique), values, and the record index of each sample."""

    radius: NDArray[np.float64]
    value: NDArray[np.float64]
    record: NDArray[np.int64]


@dataclass(frozen=True)
class QuadratureGrid:
    """Polar nodes about β0 clipped to the unit disk: radius, angle and area weight (r dr dψ) per node."""

    r: NDArray[np.float64]
    psi: NDArray[np.float64]
    w: NDArray[np.float64]


def polar_grid(beta0: tuple[float, float], n_psi: int = 256, n_r: int = 400) -> QuadratureGrid:
    """Nodes covering the unit disk in polar coordinates centred on β0 (|β0| < 1).

    Parameters
    ----------
    beta0 : tuple of float
        Centre β0 = (βx, βy) in direction cosines [-], |β0| < 1.
    n_psi : int, optional
        Quadrature nodes in ψ (midpoint rule).
    n_r : int, optional
        Gauss–Legendre nodes in r.

    Returns
    -------
    QuadratureGrid
        Radii r [-] and angles ψ [rad] about β0, and area weights w [-] (Σ w ≈ π, the disk's area), n_psi·n_r nodes.

    Raises
    ------
    NumericalError
        If β0 is on or outside the unit disk.
    """
    bx, by = beta0
    b2 = bx * bx + by * by
    if not b2 < 1.0:
        raise NumericalError("specular point on or outside the unit disk", field="theta_i", expected="θi < 90°")
    psi = (np.arange(n_psi) + 0.5) * (2 * np.pi / n_psi)
    t_max = unit_disk_reach(bx * np.cos(psi) + by * np.sin(psi), b2)
    # Gauss–Legendre in r: spectral convergence for smooth f (the trapezoid rule was only O(h²) here).
    x, tw = gauss_legendre(n_r)
    x, tw = 0.5 * (x + 1.0), 0.5 * tw
    r = t_max[:, None] * x[None, :]
    w = (t_max[:, None] ** 2) * x[None, :] * tw[None, :] * (2 * np.pi / n_psi)
    return QuadratureGrid(r=r.ravel(), psi=np.repeat(psi, n_r), w=w.ravel())


@dataclass(frozen=True)
class Hemisphere:
    """A reconstruction of f over the scattering hemisphere from half-profiles about β0."""

    beta0: tuple[float, float]
    halves: dict[str, tuple[tuple[HalfProfile, float], ...]]  # half-axis -> Σ coef·interpolant
    n_records: int
    measured_range: dict[str, tuple[float, float]]  # radii [first, last] actually sampled per half-axis
    axis: tuple[float, float] = (1.0, 0.0)  # unit vector of +α: from the source toward the specular side

    # -- construction --------------------------------------------------------------------------------------
    @classmethod
    def from_profile(cls, profile: xr.Dataset, use: str = "both", center: str = "specular") -> "Hemisphere":
        """Build from a profile of one incidence and one side (dim ``record``, var ``bsdf``, angle coords).

        ``center`` = "specular" (β0: Harvey–Shack shift invariance, right for elastic scatter) or "normal"
        (β = 0: rotational symmetry about the normal, right for light re-emitted by a phosphor, which forgets
        the incident direction; §4.2 of the power-budget paper finds biys "lambertian").

        ``use`` = "both" (default), "in_plane" or "perpendicular" (the single-arc, radially symmetric variants).
        Fill rules: a missing perpendicular branch copies the other; no perpendicular arc → f_±β = mean of the
        in-plane halves; a missing in-plane half copies the other; no in-plane arc → f_±α = mean of f_±β.
        Records with a non-finite value (grazing, masked) are skipped.

        Parameters
        ----------
        profile : xarray.Dataset
            Profile of one incidence and side: ``bsdf`` [1/sr] on ``record`` with coordinates ``theta_i``, ``phi_i``,
            ``theta_s``, ``phi_s`` [deg], ``side`` and optionally ``arc``.
        use : {"both", "in_plane", "perpendicular"}, optional
            Which arcs to use.
        center : {"specular", "normal"}, optional
            Reconstruction centre.

        Returns
        -------
        Hemisphere
            The reconstruction.

        Raises
        ------
        InputError
            If the profile is empty, mixes incidences or sides, has no usable record, or ``use``/``center`` is unknown.
        """
        th = np.radians(profile["theta_i"].values)
        if th.size == 0:
            raise InputError("empty profile", field="record", expected="records of one incidence and side")
        if np.ptp(th) > 1e-9 or len(set(profile["side"].values)) != 1:
            raise InputError("profile mixes incidences or sides", field="theta_i/side",
                             expected="one incidence and one side")
        phi_i = np.radians(profile["phi_i"].values[0])
        theta_i = th[0]
        if center == "specular":
            b0 = (np.sin(theta_i) * np.cos(phi_i - np.pi), np.sin(theta_i) * np.sin(phi_i - np.pi))
        elif center == "normal":
            b0 = (0.0, 0.0)
        else:
            raise InputError("unknown reconstruction centre", field="center", expected="specular or normal", got=center)
        ts = np.radians(profile["theta_s"].values)
        ps = np.radians(profile["phi_s"].values)
        # components in the frame aligned with the plane of incidence (u along β0 direction)
        u_dir = np.array([np.cos(phi_i - np.pi), np.sin(phi_i - np.pi)])
        a = np.sin(ts) * np.cos(ps)
        b = np.sin(ts) * np.sin(ps)
        du = (a - b0[0]) * u_dir[0] + (b - b0[1]) * u_dir[1]
        dv = -(a - b0[0]) * u_dir[1] + (b - b0[1]) * u_dir[0]
        value = profile["bsdf"].values
        ok = np.isfinite(value)
        arc = profile["arc"].values if "arc" in profile.coords else np.full(value.size, "other")
        inplane = ok & (arc == "in_plane")
        perp = ok & (arc == "perpendicular")
        idx = np.arange(value.size)
        r_all = np.hypot(du, dv)

        def half(mask: NDArray[np.bool_]) -> HalfProfile | None:
            if not mask.any():
                return None
            order = np.argsort(r_all[mask], kind="stable")
            r, v, k = r_all[mask][order], value[mask][order], idx[mask][order]
            keep = np.concatenate([[True], np.diff(r) > 1e-12])  # duplicate radius: keep the first sample
            return HalfProfile(r[keep], v[keep], k[keep])

        # The sample at the centre anchors the perpendicular half-axes (for the normal centre the perpendicular
        # arc starts at |β| = sin θi and borrowing fills the inside).
        anchor = inplane & (np.abs(du) < 1e-9)
        halves: dict[str, HalfProfile | None] = {
            "+alpha": half(inplane & (du >= -1e-9)),
            "-alpha": half(inplane & (du <= 1e-9)),
            "+beta": half(perp & (dv > 0) | anchor),
            "-beta": half(perp & (dv < 0) | anchor),
        }
        if use == "in_plane":
            halves["+beta"] = halves["-beta"] = None
        elif use == "perpendicular":
            halves["+alpha"] = halves["-alpha"] = None
        elif use != "both":
            raise InputError("unknown reconstruction", field="use", expected="both, in_plane or perpendicular", got=use)
        own = {"+alpha": inplane & (du >= -1e-9), "-alpha": inplane & (du <= 1e-9),
               "+beta": perp & (dv > 0), "-beta": perp & (dv < 0)}
        measured = {}
        for k, h in halves.items():
            radii = r_all[own[k]]
            measured[k] = ((float(radii.min()), float(radii.max())) if h is not None and radii.size
                           else (np.inf, -np.inf))
        filled = _fill(halves)
        return cls(beta0=(float(b0[0]), float(b0[1])), halves=filled, n_records=value.size, measured_range=measured,
                   axis=(float(u_dir[0]), float(u_dir[1])))

    # -- evaluation ------------------------------------------------------------------------------------------
    def coefficients(self, r: NDArray, psi: NDArray, p: float = 2.0, borrow: bool = True,
                     repeats: int = 1) -> NDArray[np.float64]:
        """Blend coefficients (n, 4) of the half-axes at polar nodes (r, ψ); rows sum to 1.

        Base weights |cos ψ|^p, |sin ψ|^p (normalised; p = 2 is the cos²/sin² blend) on the half-axes the
        node's quadrant faces. With ``borrow``, a half-axis asked for outside the radii it actually sampled
        hands its weight to the half-axes sampled at that radius (an isotropy assumption used only where data
        are missing); where none is, the half-axis sampled farthest out takes all the weight and its last value
        is held. ``repeats`` > 1 says that ψ comes in blocks of that many equal values (the nodes of
        :func:`polar_grid`, ψ repeated over the radii): the blend is then computed once per block (same numbers).

        Parameters
        ----------
        r : ndarray
            Radii about β0 in direction cosines [-].
        psi : ndarray
            Polar angles about β0 in the plane-of-incidence frame [rad], as many as ``r``.
        p : float, optional
            Blend exponent [-].
        borrow : bool, optional
            Hand the weight of unsampled radii to the half-axes sampled there.
        repeats : int, optional
            Block length of equal ψ values (1: no blocks).

        Returns
        -------
        ndarray, shape (n, 4)
            Coefficients [-] of the half-axes in :data:`HALVES` order.
        """
        r = np.asarray(r, dtype=np.float64).ravel()
        psi = np.asarray(psi, dtype=np.float64).ravel()[::repeats]
        ca, sb = np.abs(np.cos(psi)) ** p, np.abs(np.sin(psi)) ** p
        norm = ca + sb
        ca, sb = ca / norm, sb / norm
        c = np.cos(psi)
        sn = np.sin(psi)
        # one contiguous array per half-axis (the columns of the result): the same element-wise operations as
        # on the (n, 4) array, without its strided columns (3.5x faster on the 102 400 nodes of polar_grid)
        cols = [np.where(c > 0, ca, 0.0), np.where(c <= 0, ca, 0.0), np.where(sn > 0, sb, 0.0),
                np.where(sn <= 0, sb, 0.0)]
        if repeats > 1:
            cols = [np.repeat(col, repeats) for col in cols]
        if borrow:
            lo = [self.measured_range[h][0] for h in HALVES]
            hi = [self.measured_range[h][1] for h in HALVES]
            m = [(r >= lo_k - 1e-12) & (r <= hi_k + 1e-12) for lo_k, hi_k in zip(lo, hi)]
            # the four half-axes summed in numpy's order for a row sum
            n_measured = ((m[0].astype(np.int64) + m[1]) + m[2]) + m[3]
            kept = [np.where(m_k, 0.0, col) for m_k, col in zip(m, cols)]
            lost = ((kept[0] + kept[1]) + kept[2]) + kept[3]
            share = np.where(n_measured > 0, lost / np.maximum(n_measured, 1), 0.0)
            # Beyond every sampled radius: the half-axis sampled farthest out holds its last value.
            farthest = int(np.argmax(np.where(np.isfinite(lo), hi, -np.inf)))
            some = n_measured > 0
            cols = [np.where(some, np.where(m_k, col + share, 0.0), float(k == farthest))
                    for k, (m_k, col) in enumerate(zip(m, cols))]
        # column-major: coef[:, k], the half-axis every caller reads, is contiguous
        coef = np.empty((cols[0].size, len(HALVES)), order="F")
        for k, col in enumerate(cols):
            coef[:, k] = col
        return coef

    def evaluate_polar(self, r: NDArray, psi: NDArray, mode: str = "linear", p: float = 2.0,
                       borrow: bool = True) -> NDArray[np.float64]:
        """f at polar coordinates (r, ψ) about β0 (ψ in the plane-of-incidence frame).

        Parameters
        ----------
        r : ndarray
            Radii about β0 in direction cosines [-].
        psi : ndarray
            Polar angles about β0 [rad], broadcast with ``r``.
        mode : {"linear", "log"}, optional
            Interpolate the half-profiles in f or in ln f (between positive samples).
        p : float, optional
            Blend exponent [-].
        borrow : bool, optional
            Hand the weight of unsampled radii to the half-axes sampled there.

        Returns
        -------
        ndarray
            f [1/sr] with the broadcast shape of ``r`` and ``psi``.
        """
        shape = np.broadcast(r, psi).shape
        r_flat = np.broadcast_to(r, shape).ravel()
        coef = self.coefficients(r_flat, np.broadcast_to(psi, shape).ravel(), p, borrow)
        return self._evaluate(r_flat, coef, mode).reshape(shape)

    def _evaluate(self, r: NDArray, coef: NDArray, mode: str, rows: tuple[NDArray, ...] | None = None,
                  at_nodes: dict[int, NDArray] | None = None) -> NDArray[np.float64]:
        """Σ_halves coef·interpolant at radii ``r``; ``rows[k]``: the nodes where coef[:, k] ≠ 0 (the others are
        skipped: a node blends only the half-axes its quadrant faces). ``at_nodes`` maps ``id(half profile)`` to
        its interpolant at every radius of ``r``, computed beforehand (:meth:`tis_variants`)."""
        if mode not in ("linear", "log"):
            raise InputError("unknown interpolation mode", field="mode", expected="linear or log", got=mode)
        out = np.zeros(r.size)
        for k, name in enumerate(HALVES):
            if at_nodes is not None:  # finite everywhere: a node with coef 0 adds exactly 0, no gather needed
                for h, share in self.halves[name]:
                    out += coef[:, k] * share * at_nodes[id(h)]
                continue
            idx = np.flatnonzero(coef[:, k]) if rows is None else rows[k]
            for h, share in self.halves[name]:
                out[idx] += coef[idx, k] * share * _interp(h, r[idx], mode)
        return out

    def _grid_coefficients(self, n_psi: int, n_r: int, p: float = 2.0,
                           borrow: bool = True) -> tuple[QuadratureGrid, NDArray, tuple[NDArray, ...]]:
        """The quadrature grid, its blend coefficients and their non-zero rows, shared by every reconstruction
        with the same geometry (a band series repeats one scan plan for dozens of bands)."""
        ranges = tuple(self.measured_range[h] for h in HALVES)
        return _grid_coefficients(self.beta0, ranges, n_psi, n_r, float(p), bool(borrow))

    def bsdf(self, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        """f (1/sr) for unit vectors (..., 3) in the scattering hemisphere's sample frame (source at φi = 180°
        unless the profile said otherwise).

        Parameters
        ----------
        directions : ndarray, shape (..., 3)
            Unit scatter directions in the sample frame [-].

        Returns
        -------
        ndarray, shape (...)
            f [1/sr].
        """
        d = np.asarray(directions, dtype=np.float64)
        x = d[..., 0] - self.beta0[0]
        y = d[..., 1] - self.beta0[1]
        ux, uy = self.axis
        du, dv = x * ux + y * uy, -x * uy + y * ux
        return self.evaluate_polar(np.hypot(du, dv), np.arctan2(dv, du))

    def weights(self, n_psi: int = 256, n_r: int = 400) -> NDArray[np.float64]:
        """w such that TIS = Σ_records w_k f_k (the reconstruction and quadrature are linear in the data).

        Parameters
        ----------
        n_psi : int, optional
            Quadrature nodes in ψ (midpoint rule).
        n_r : int, optional
            Gauss–Legendre nodes in r.

        Returns
        -------
        ndarray, shape (n_records,)
            Weight per profile record [sr] (linear interpolation in f).
        """
        # the weights depend on the sampled radii and records only, not on the values: a reduction that asks
        # again for the same geometry (the lobe of every tail rule, a band series) gets them from the cache
        halves = tuple(tuple((h.radius.tobytes(), h.record.tobytes(), h.record.dtype.str, float(share))
                             for h, share in self.halves[name]) for name in HALVES)
        ranges = tuple(self.measured_range[h] for h in HALVES)
        return _record_weights(self.beta0, ranges, halves, self.n_records, n_psi, n_r).copy()

    def tis(self, mode: str = "linear", n_psi: int = 256, n_r: int = 400, p: float = 2.0, borrow: bool = True) -> float:
        """TIS of the reconstruction: ∫∫_{|β|≤1} f dβx dβy on the :func:`polar_grid` about β0.

        Parameters
        ----------
        mode : {"linear", "log"}, optional
            Interpolate the half-profiles in f or in ln f (between positive samples).
        n_psi, n_r : int, optional
            Quadrature nodes in ψ and in r.
        p : float, optional
            Blend exponent [-] (see :meth:`coefficients`).
        borrow : bool, optional
            Hand the weight of unsampled radii to the half-axes sampled there.

        Returns
        -------
        float
            Total integrated scatter [-] (for f in [1/sr]).
        """
        grid, coef, rows = self._grid_coefficients(n_psi, n_r, p, borrow)
        return float(np.sum(self._evaluate(grid.r, coef, mode, rows) * grid.w))

    def tis_variants(self, mode: str, n_psi: int, n_r: int,
                     variants: Sequence[tuple[float, bool]]) -> list[float]:
        """:meth:`tis` for several (p, borrow) blends on one quadrature grid, the same numbers bit for bit.

        The grid's radii do not depend on the blend, so every half-profile is interpolated at all of them
        once and each blend only gathers (the error budget of :func:`tis_from_profile` needs four blends).

        Parameters
        ----------
        mode : {"linear", "log"}
            Interpolate the half-profiles in f or in ln f (between positive samples).
        n_psi, n_r : int
            Quadrature nodes in ψ and in r.
        variants : sequence of (float, bool)
            (blend exponent p [-], borrow) per TIS.

        Returns
        -------
        list of float
            TIS [-] per variant, in order.
        """
        grid = self._grid_coefficients(n_psi, n_r)[0]
        at_nodes: dict[int, NDArray] | None = {id(h): _interp(h, grid.r, mode)
                                               for entries in self.halves.values() for h, _ in entries}
        if not all(np.isfinite(v).all() for v in at_nodes.values()):
            at_nodes = None  # a non-finite interpolant would turn 0·v into NaN: interpolate per blend instead
        out = []
        for p, borrow in variants:
            grid, coef, rows = self._grid_coefficients(n_psi, n_r, p, borrow)
            out.append(float(np.sum(self._evaluate(grid.r, coef, mode, rows, at_nodes) * grid.w)))
        return out


@functools.lru_cache(maxsize=16)
def _grid_coefficients(beta0: tuple[float, float], ranges: tuple[tuple[float, float], ...], n_psi: int, n_r: int,
                       p: float, borrow: bool) -> tuple[QuadratureGrid, NDArray, tuple[NDArray, ...]]:
    # Depends only on the geometry (β0, the sampled radii per half-axis), not on the data: cached (read-only).
    hemi = Hemisphere(beta0=beta0, halves={}, n_records=0, measured_range=dict(zip(HALVES, ranges)))
    grid = _polar_grid(float(np.hypot(*beta0)), n_psi, n_r)
    coef = hemi.coefficients(grid.r, grid.psi, p, borrow, repeats=n_r)
    rows = tuple(np.flatnonzero(coef[:, k]) for k in range(len(HALVES)))
    for a in (grid.r, grid.psi, grid.w, coef, *rows):
        a.setflags(write=False)
    return grid, coef, rows


@functools.lru_cache(maxsize=8)
def _polar_grid(b: float, n_psi: int, n_r: int) -> QuadratureGrid:
    # the grid about (b, 0), shared by the blends and sampled ranges of one incidence (read-only)
    grid = polar_grid((b, 0.0), n_psi, n_r)
    for a in (grid.r, grid.psi, grid.w):
        a.setflags(write=False)
    return grid


@functools.lru_cache(maxsize=64)
def _record_weights(beta0: tuple[float, float], ranges: tuple[tuple[float, float], ...],
                    halves: tuple[tuple[tuple[bytes, bytes, str, float], ...], ...], n_records: int, n_psi: int,
                    n_r: int) -> NDArray[np.float64]:
    # :meth:`Hemisphere.weights` from the half-profiles' radii and records (bytes, record dtype) and shares.
    # Each node's share of coef·w goes to its two neighbouring samples, summed node by node per sample
    # (np.bincount) and then added to the sample's record (records are unique within a half-profile).
    grid, coef, rows = _grid_coefficients(beta0, ranges, n_psi, n_r, 2.0, True)
    nodes = _half_axis_nodes(beta0, ranges, n_psi, n_r)
    w = np.zeros(n_records)
    for k, entries in enumerate(halves):
        r, cw = nodes[k]
        for radius, record, dtype, share in entries:
            samples, rec = np.frombuffer(radius), np.frombuffer(record, dtype=dtype)
            a = cw if share == 1.0 else coef[rows[k], k] * share * grid.w[rows[k]]
            lo, _, wl, wh = linear_weights(samples, r)
            w[rec] += np.bincount(lo, weights=a * wl, minlength=samples.size)
            if samples.size > 1:  # the upper neighbour is lo + 1 (one sample: its weight is 0)
                w[rec[1:]] += np.bincount(lo, weights=a * wh, minlength=samples.size - 1)
    w.setflags(write=False)
    return w


@functools.lru_cache(maxsize=8)
def _half_axis_nodes(beta0: tuple[float, float], ranges: tuple[tuple[float, float], ...], n_psi: int,
                     n_r: int) -> tuple[tuple[NDArray, NDArray], ...]:
    # per half-axis: the radii of the grid nodes it has a share in, and coef·w there (the blend of p = 2 with
    # borrowing), gathered once per geometry for every half-profile weighted on it (read-only)
    grid, coef, rows = _grid_coefficients(beta0, ranges, n_psi, n_r, 2.0, True)
    out = []
    for k, idx in enumerate(rows):
        r, cw = grid.r[idx], coef[idx, k] * grid.w[idx]
        for a in (r, cw):
            a.setflags(write=False)
        out.append((r, cw))
    return tuple(out)


def _interp(h: HalfProfile, r: NDArray, mode: str) -> NDArray[np.float64]:
    """Linear interpolation in f (or in ln f between positive neighbours), constant beyond the ends."""
    if mode == "linear":
        return np.interp(r, h.radius, h.value)
    positive = h.value > 0
    logv = np.interp(r, h.radius, np.log(np.where(positive, h.value, 1.0)))
    if positive.all():  # the usual case: every node lies between positive neighbours
        return np.exp(logv)
    lin = np.interp(r, h.radius, h.value)
    good = np.interp(r, h.radius, positive.astype(float)) > 1 - 1e-12
    return np.where(good, np.exp(logv), lin)


def _fill(halves: dict[str, HalfProfile | None]) -> dict[str, tuple[tuple[HalfProfile, float], ...]]:
    """Missing half-axes from the measured ones (rules in :meth:`Hemisphere.from_profile`)."""
    h = dict(halves)
    for a, b in (("+beta", "-beta"), ("-beta", "+beta"), ("+alpha", "-alpha"), ("-alpha", "+alpha")):
        if h[a] is None and h[b] is not None:
            h[a] = h[b]
    if h["+alpha"] is None and h["+beta"] is None:
        raise InputError("no usable records to reconstruct the hemisphere", field="bsdf",
                         expected="finite values on an arc")
    out: dict[str, tuple[tuple[HalfProfile, float], ...]] = {}
    for name, other in (("+alpha", ("+beta", "-beta")), ("-alpha", ("+beta", "-beta")),
                        ("+beta", ("+alpha", "-alpha")), ("-beta", ("+alpha", "-alpha"))):
        if h[name] is not None:
            out[name] = ((h[name], 1.0),)
        else:  # radial symmetry from the other arc: the mean of its two halves
            out[name] = ((h[other[0]], 0.5), (h[other[1]], 0.5))
    return out


# ----------------------------------------------------------------------------------------------- TIS
@dataclass(frozen=True)
class TIS:
    """TIS (fraction of incident power) with its measurement and reconstruction standard uncertainties."""

    value: float
    std_measurement: float
    std_reconstruction: float
    components: dict[str, float]
    #: linear weights per profile record (Σ w·f is the linear-interpolation TIS) [sr]
    weights: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    @property
    def std(self) -> float:
        return float(np.hypot(self.std_measurement, self.std_reconstruction))


#: Reconstruction centre per interaction of the two-wavelength approach.
CENTER = {"bibs": "specular", "yiys": "specular", "biys": "normal"}


def tis_from_profile(profile: xr.Dataset, n_psi: int = 256, n_r: int = 400, center: str | None = None,
                     singles: bool = True) -> TIS:
    """TIS of one incidence and side of a profile (1/sr per record), with error bars (module docstring).

    ``center`` defaults to the profile's interaction (``attrs['interaction']``) via :data:`CENTER`, else specular.
    ``singles=False`` leaves out the components ``in_plane_only`` and ``perpendicular_only`` (two more
    reconstructions; value and error bars do not use them).

    Parameters
    ----------
    profile : xarray.Dataset
        Profile of one incidence and side (:func:`bsdfkit.reduction.spectral.interaction_profile`): ``bsdf`` and
        optionally ``bsdf_std`` [1/sr] per record.
    n_psi : int, optional
        Quadrature nodes in ψ (midpoint rule).
    n_r : int, optional
        Gauss–Legendre nodes in r.
    center : {"specular", "normal"}, optional
        Reconstruction centre; None picks it from the profile's interaction.
    singles : bool, optional
        Compute the single-arc components (default True).

    Returns
    -------
    TIS
        Value and standard uncertainties [-], error-budget components and single-arc TIS [-], record weights [sr].
    """
    center = center or CENTER.get(profile.attrs.get("interaction", ""), "specular")
    hemi = Hemisphere.from_profile(profile, center=center)
    w = hemi.weights(n_psi, n_r)
    f = np.nan_to_num(profile["bsdf"].values, nan=0.0)
    s = np.nan_to_num(profile["bsdf_std"].values, nan=0.0) if "bsdf_std" in profile else np.zeros_like(f)
    linear = float(w @ f)
    # ln-f interpolation follows convex lobe tails between sparse samples (docs/reductions.md); the linear
    # form (exactly w·f) gives the first-order propagation of the measurement uncertainty.
    # the value, two other blends and no borrowing (hold), on one grid
    value, *blends, hold = hemi.tis_variants("log", n_psi, n_r, [(2.0, True), (1.0, True), (4.0, True), (2.0, False)])
    # per-record noise through the linear weights, plus the scale common to all records (reference beam)
    std_meas = float(np.hypot(np.sqrt(np.sum((w * s) ** 2)), profile.attrs.get("common_relative_std", 0.0) * value))
    coarse = hemi.tis("log", n_psi // 2, n_r // 2)
    parts = {"quadrature": abs(value - coarse), "interpolation": abs(value - linear),
             "blend": max(abs(b - value) for b in blends), "extrapolation": abs(hold - value)}
    std_rec = float(np.sqrt(sum(v * v for v in parts.values())))
    arcs = {}
    for use in ("in_plane", "perpendicular") if singles else ():
        try:
            arcs[f"{use}_only"] = Hemisphere.from_profile(profile, use=use, center=center).tis("log", n_psi, n_r)
        except InputError:
            arcs[f"{use}_only"] = float("nan")  # that arc was not measured
    return TIS(value=value, std_measurement=std_meas, std_reconstruction=std_rec, components={**parts, **arcs},
               weights=w)


def tis_table(ds: xr.Dataset, interactions: tuple[str, ...] = ("bibs", "biys", "yiys"),
              theta_i_deg: list[float] | None = None, bands: InteractionBands | None = None) -> xr.Dataset:
    """TIS per interaction, side and incidence from a calibrated scan: a Dataset with ``tis``, ``tis_std``,
    ``tis_std_measurement``, ``tis_std_reconstruction`` (fractions) over (interaction, side, theta_i).

    ``bands``: the bands of the profiles (:func:`bsdfkit.reduction.spectral.interaction_profile`), recorded in
    the attributes ``blue_band_nm`` and ``yellow_band_nm`` so that a later photon budget can check it uses the
    same ones.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan.
    interactions : tuple of str, optional
        Interactions to reduce (``"bibs"``, ``"biys"``, ``"yiys"``, ``"elastic"``).
    theta_i_deg : list of float, optional
        Angles of incidence [deg]; None for every measured incidence.
    bands : InteractionBands, optional
        The bands [nm]; None for the power-budget filters.

    Returns
    -------
    xarray.Dataset
        ``tis``, ``tis_std``, ``tis_std_measurement``, ``tis_std_reconstruction`` [-] over (interaction, side,
        theta_i [deg]).

    Raises
    ------
    InputError
        If an incidence has no records on a side.
    """

    bands = bands or InteractionBands()
    angles = theta_i_deg if theta_i_deg is not None else incidences(ds)
    sides = list(SIDES)
    shape = (len(interactions), len(sides), len(angles))
    arrays = {k: np.full(shape, np.nan) for k in ("tis", "tis_std", "tis_std_measurement", "tis_std_reconstruction")}
    for a, inter in enumerate(interactions):
        prof = interaction_profile(ds, inter, bands=bands)
        for b, side in enumerate(sides):
            for c, th in enumerate(angles):
                sel = (prof["side"].values == side) & np.isclose(prof["theta_i"].values, th, atol=1e-6)
                if not sel.any():
                    raise InputError("no records for this incidence and side", file=ds.attrs.get("source"),
                                     field="theta_i", expected=f"records at {th:g} deg, {side}")
                t = tis_from_profile(prof.isel(record=np.flatnonzero(sel)))
                arrays["tis"][a, b, c] = t.value
                arrays["tis_std"][a, b, c] = t.std
                arrays["tis_std_measurement"][a, b, c] = t.std_measurement
                arrays["tis_std_reconstruction"][a, b, c] = t.std_reconstruction
    out = xr.Dataset({k: (("interaction", "side", "theta_i"), v) for k, v in arrays.items()},
                     coords={"interaction": list(interactions), "side": sides, "theta_i": angles})
    for k in arrays:
        out[k].attrs["units"] = "1"
    out["theta_i"].attrs["units"] = "deg"
    out.attrs.update(quantity="tis", source=ds.attrs.get("source", ""), blue_band_nm=list(bands.blue_nm),
                     yellow_band_nm=list(bands.yellow_nm))
    return out


def hemispherical_spectrum(ds: xr.Dataset, config: str, theta_i_deg: float, side: str, interaction: str = "biys",
                           band_nm: tuple[float, float] = CONVERSION_BAND_NM) -> xr.DataArray:
    """Spectral TIS density (1/nm): the bi-spectral BSDF integrated over the hemisphere at each λs.

    The hemisphere weights of the band-integrated profile are linear in the data, so one reconstruction
    integrates every wavelength: Φ_λ,s/Φ_i = Σ_k w_k ⟨q_λ⟩_k(λs). Its integral over ``band`` is the TIS.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated phosphor scan with ``bsdf_bispectral``.
    config : str
        Excitation configuration (e.g. ``"blue"``).
    theta_i_deg : float
        Angle of incidence [deg], a measured one.
    side : str
        ``"reflection"`` or ``"transmission"``.
    interaction : str, optional
        Interaction whose reconstruction centre is used (:data:`CENTER`).
    band_nm : tuple of float, optional
        (low, high) emission band [nm] of the profile that sets the hemisphere weights.

    Returns
    -------
    xarray.DataArray
        Spectral TIS density [1/nm] over ``wavelength`` [nm].
    """

    sub = select(ds, config=config, theta_i_deg=theta_i_deg, side=side)
    prof = bispectral_band_integral(sub, config, band_nm)
    hemi = Hemisphere.from_profile(prof, center=CENTER.get(interaction, "specular"))
    w = hemi.weights()
    density = np.nan_to_num(sub["bsdf_bispectral"].values, nan=0.0).T @ w
    out = xr.DataArray(density, dims=["wavelength"], coords={"wavelength": ds["wavelength"].values})
    out.attrs.update(units="1/nm", long_name=f"hemispherical spectral TIS density, {side}, θi = {theta_i_deg:g}°")
    return out


def hemisphere_bsdf_fn(ds: xr.Dataset, interaction: str, side: str) -> Callable[[float, str, NDArray], NDArray]:
    """A callable ``f(theta_i_deg, side, directions) -> bsdf`` over measured incidences (for grids/exports).

    Only measured incidences are available (no interpolation across incidence); others raise InputError.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan.
    interaction : str
        ``"bibs"``, ``"biys"`` or ``"yiys"``.
    side : str
        ``"reflection"`` or ``"transmission"``.

    Returns
    -------
    callable
        ``f(theta_i_deg, side, directions)``: incidence [deg], side, unit directions (..., 3) [-] → BSDF [1/sr];
        its attribute ``incidences_deg`` lists the measured incidences [deg].
    """

    prof = interaction_profile(ds, interaction, side)
    cache: dict[float, Hemisphere] = {}

    def fn(theta_i_deg: float, side_: str, directions: NDArray) -> NDArray:
        if side_ != side:
            raise InputError("this reconstruction is for another side", field="side", expected=side, got=side_)
        key = round(float(theta_i_deg), 6)
        if key not in cache:
            sel = np.isclose(prof["theta_i"].values, theta_i_deg, atol=1e-6)
            if not sel.any():
                raise InputError("incidence not measured", field="theta_i", expected="one of "
                                 + ", ".join(f"{t:g}" for t in incidences(prof)), got=theta_i_deg)
            cache[key] = Hemisphere.from_profile(prof.isel(record=np.flatnonzero(sel)), center=CENTER[interaction])
        return cache[key].bsdf(directions)

    fn.incidences_deg = incidences(prof)  # type: ignore[attr-defined]
    return fn


def tis_rectangle_sum(bsdf: Callable[[NDArray, NDArray], NDArray], dtheta_deg: float, dphi_deg: float) -> float:
    """Eq. (7) of the power-budget paper: Σ_φ Σ_θ f(θ, φ) cos θ sin θ Δθ Δφ on the nodes θ = 0, Δθ, …, 90°
    and φ = 0, Δφ, …, 360° − Δφ. ``bsdf(theta_rad, phi_rad)`` evaluates f on broadcast arrays.

    Parameters
    ----------
    bsdf : callable
        ``bsdf(theta_rad, phi_rad)``: scatter polar angle and azimuth [rad] → BSDF [1/sr].
    dtheta_deg : float
        Polar step Δθ [deg], dividing 90°.
    dphi_deg : float
        Azimuth step Δφ [deg], dividing 360°.

    Returns
    -------
    float
        Total integrated scatter [-].

    Raises
    ------
    InputError
        If a step does not divide its range.
    """
    n_t = int(round(90.0 / dtheta_deg))
    n_p = int(round(360.0 / dphi_deg))
    if n_t < 1 or n_p < 1 or abs(n_t * dtheta_deg - 90) > 1e-9 or abs(n_p * dphi_deg - 360) > 1e-9:
        raise InputError("steps must divide the hemisphere", field="dtheta/dphi", expected="90/Δθ and 360/Δφ integers",
                         got=(dtheta_deg, dphi_deg))
    th = np.radians(np.arange(n_t + 1) * dtheta_deg)[:, None]
    ph = np.radians(np.arange(n_p) * dphi_deg)[None, :]
    f = bsdf(th, ph)
    return float(np.sum(f * np.cos(th) * np.sin(th)) * np.radians(dtheta_deg) * np.radians(dphi_deg))
