"""Axes of the tables written about the surface normal (Speos, Speos ``.brdf``, LightTools): polar angle θs from the
normal and azimuth φs, one list of each for every incidence of a file.

The fixed grid (θs every 1°, φs every 2°) cannot hold a lobe narrower than its azimuth step: a specular lobe at
grazing incidence (the ansys in-plane scan at 80°: full width about 2° in θs, peak 57/sr) falls between two
azimuth columns, and the hemispherical engine behind ``bsdfkit read``, which interpolates records across azimuth,
then integrated the table 6.3 % above the source. :func:`auto_normal_axes` keeps the 1° θs rows and chooses the
azimuths as the polar tables' auto grids do (:func:`bsdfkit.tables.grids._refine_polar`): from 24 (15°), an
azimuth interval is bisected where that changes the table's TIS or uncovers a higher peak, until the estimated TIS
error is within the tolerance: fine where the lobe is, coarse over the smooth body (docs/exports.md, "Grid
resolution"). Coarser θs rows were tried and left alone: the engine's reconstruction of records about the normal
(a lobe about its peak, with its log/linear correction) then missed the source by 0.5-1.3 % at 10-40° on the
ansys scan even where the table's own TIS had converged.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bsdfkit.reduction import basis
from bsdfkit.tables import grids
from bsdfkit.tables.axes_choice import FALLBACK

__all__ = ["FIXED_PHI_STEP_DEG", "FIXED_THETA_STEP_DEG", "auto_normal_axes", "describe", "fixed_normal_axes",
           "normal_axes", "normal_directions", "tis_normal_table"]

#: the fixed grid: θs 0…90° every 1°, φs 0…360° every 2° (5° azimuths miss 1-2 % of a grazing lobe)
FIXED_THETA_STEP_DEG = 1.0
FIXED_PHI_STEP_DEG = 2.0


def normal_directions(theta_deg: NDArray[np.float64], phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit vectors (φ, θ, 3) of the nodes θs = ``theta_deg``, φs = ``phi_deg`` [deg] (bsdfkit's sample frame:
    specular at φs = 0); the horizon row exactly at z = 0.

    Parameters
    ----------
    theta_deg : ndarray
        Polar angles θs from the normal [deg].
    phi_deg : ndarray
        Azimuths φs [deg].

    Returns
    -------
    ndarray
        Unit direction vectors [-], shape ``(phi_deg.size, theta_deg.size, 3)``.
    """
    a, t = np.meshgrid(np.radians(phi_deg), np.radians(theta_deg), indexing="ij")
    d = np.stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)], axis=-1)
    d[..., 2] = np.maximum(d[..., 2], 0.0)
    return d


def node_values(bsdf_fn: grids.BsdfFn, theta_i_deg: float, side: str, theta_deg: NDArray[np.float64],
                phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """The BSDF [1/sr] a table about the normal holds at its nodes (φ, θ): point values, or for a piecewise-constant
    source (:class:`bsdfkit.tables.grids.PiecewiseConstant`) each node's mean over its hat function in sin θs and
    φs — exact for Klems cells (:func:`bsdfkit.reduction.basis.klems_on_normal_grid`), by quadrature for others
    (:func:`bsdfkit.tables.grids.node_means`) — so that the table, read as its own piecewise-linear interpolant
    (:func:`bsdfkit.reduction.basis.normal_grid_weights`), integrates to the source's value.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions)`` → BSDF [1/sr].
    theta_i_deg : float
        Incidence [deg].
    side : str
        ``reflection`` or ``transmission``.
    theta_deg, phi_deg : ndarray
        The table's axes [deg] (φs over the full circle).

    Returns
    -------
    ndarray
        BSDF [1/sr], shape ``(phi_deg.size, theta_deg.size)``.
    """
    theta = np.asarray(theta_deg, dtype=np.float64)
    phi = np.asarray(phi_deg, dtype=np.float64)
    if not isinstance(bsdf_fn, grids.PiecewiseConstant):
        return grids.evaluate_bsdf(bsdf_fn, float(theta_i_deg), side, normal_directions(theta, phi))
    spec = bsdf_fn.basis or ""
    if (spec.startswith("klems") or spec.startswith("shirley-chiu")) and theta[0] == 0.0 and theta[-1] == 90.0:
        cells = grids.evaluate_bsdf(bsdf_fn, float(theta_i_deg), side, basis.cell_directions(spec))
        if spec.startswith("klems"):  # cells that are rectangles in (sin θs, φs): exact means
            return basis.klems_on_normal_grid(spec, cells, theta, phi)
        return basis.cells_on_normal_grid(spec, cells, theta, phi)  # each cell's power shared among the hats

    def directions(t_deg: NDArray, a_deg: NDArray) -> NDArray:
        t, a = np.radians(t_deg), np.radians(a_deg)
        return np.stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.maximum(np.cos(t), 0.0)], axis=-1)

    def density(t_deg: NDArray, a_deg: NDArray, d: NDArray) -> NDArray:  # dΛ = ρ dρ dφ, ρ = sin θs
        return np.sin(np.radians(t_deg))

    return grids.node_means(bsdf_fn, float(theta_i_deg), side, theta, phi, directions, "sin", density)


def tis_normal_table(values: NDArray[np.float64], theta_deg: NDArray[np.float64],
                     phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """TIS [-] of tables ``values[..., phi, theta]`` [1/sr] about the normal: per azimuth row the piecewise-linear
    interpolant in the distance from the normal in direction cosines, ρ = sin θs, against ρ dρ (exact per segment;
    the hemispherical engine behind ``bsdfkit read`` interpolates records about the normal linearly in that
    distance), then periodic trapezoid weights in φs (a row at 360° repeating 0° counts once).

    This is the refinement's yardstick only (the formats state no quadrature of their own; ``bsdfkit read``
    integrates them with the hemispherical engine, which the export re-checks on the written file).

    Parameters
    ----------
    values : ndarray
        BSDF tables [1/sr], shape ``(..., phi, theta)``.
    theta_deg : ndarray
        The θs axis, increasing from the normal [deg].
    phi_deg : ndarray
        The φs axis [deg].

    Returns
    -------
    ndarray
        TIS of each table [-], shape ``values.shape[:-2]``.
    """
    f = np.asarray(values, dtype=np.float64)
    rho = np.sin(np.radians(np.asarray(theta_deg, dtype=np.float64)))
    seg = grids._segment_rho_moment(rho[:-1], rho[1:], f[..., :-1], f[..., 1:]).sum(axis=-1)  # (..., phi)
    row_w = grids._azimuth_row_weights(np.asarray(phi_deg, dtype=np.float64), plane_symmetric=False)
    return np.sum(seg * row_w, axis=-1)


def fixed_normal_axes() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The fixed grid: θs [deg] 0…90 every 1°, φs [deg] 0…358 every 2°."""
    theta = np.linspace(0.0, 90.0, int(round(90.0 / FIXED_THETA_STEP_DEG)) + 1)
    return theta, np.arange(0.0, 360.0, FIXED_PHI_STEP_DEG)


def auto_normal_axes(
    bsdf_fn: grids.BsdfFn,
    theta_i_deg: Sequence[float],
    sides: Sequence[str] | str,
    tolerance: grids.GridTolerance | None = None,
    max_nodes: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """θs and φs axes [deg] (φs in [0, 360), bsdfkit's frame): the θs rows of the fixed grid and the azimuths
    ``bsdf_fn`` needs to meet ``tolerance``.

    Parameters
    ----------
    bsdf_fn
        The source, ``bsdf_fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_i_deg
        Incidences [deg] the axes serve (one pair of axes for all, as a LightTools file requires).
    sides
        Sides the axes serve.
    tolerance
        TIS and peak tolerances (:class:`bsdfkit.tables.grids.GridTolerance`); the TIS compared is
        :func:`tis_normal_table`.
    max_nodes
        None when meeting the tolerance takes more θs × φs nodes than this.

    Returns
    -------
    tuple of numpy.ndarray or None
        The θs axis (0 … 90) and the φs axis [deg], or None.

    Notes
    -----
    θs every :data:`FIXED_THETA_STEP_DEG` (not refined); azimuths from
    :data:`bsdfkit.tables.grids.MIN_AZIMUTHS` refined with :func:`bsdfkit.tables.grids._refine_polar` (θs in the
    role of the radial axis, area weight sin θ cos θ; the peak criterion over the rows' core, from the normal
    outward while the BSDF stays at least half its value there).
    """
    tolerance = tolerance or grids.GridTolerance()
    thetas = grids._check_incidences(theta_i_deg)
    sides = grids._check_sides(sides)

    def evaluate(r: NDArray, a: NDArray) -> tuple[NDArray, NDArray]:
        out = np.stack([np.stack([node_values(bsdf_fn, float(t), s, r, a) for t in thetas]) for s in sides])
        return out, np.ones((thetas.size, a.size, r.size), dtype=bool)

    theta = fixed_normal_axes()[0]
    start_phi = np.arange(grids.MIN_AZIMUTHS) * (360.0 / grids.MIN_AZIMUTHS)
    # min_step = the θs step: no θs segment is long enough to bisect, the rows stay
    problem = grids._PolarProblem(evaluate, tis_normal_table,
                                  lambda r: np.sin(np.radians(r)) * np.cos(np.radians(r)) * (np.pi / 180.0),
                                  grids.azimuth_midpoints_deg)
    chosen = grids._refine_polar(problem, theta, start_phi, tolerance,
                                 grids._RefineLimits(FIXED_THETA_STEP_DEG, int(tolerance.max_azimuths), max_nodes))
    if chosen is None:
        return None
    return np.asarray(grids._tidy(chosen[0])), np.asarray(grids._tidy(chosen[1]))


def normal_axes(fn: grids.BsdfFn, theta_deg: NDArray[np.float64], sides: Sequence[str],
                settings: Any) -> tuple[NDArray[np.float64], NDArray[np.float64], dict]:
    """The θs and φs axes [deg] of an export about the normal (``settings`` an ``ExportSettings``): ``grid`` fixed,
    or auto (:func:`auto_normal_axes`; the fixed grid when the tolerance needs more nodes than it), and the
    ``grid`` entry of the export's result (``mode``, ``theta``, ``phi`` node counts, tolerances).

    Parameters
    ----------
    fn : callable
        The source, ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (:data:`bsdfkit.tables.grids.BsdfFn`).
    theta_deg : ndarray
        Incidences of the file [deg].
    sides : sequence of str
        Sides the axes serve (``reflection``, ``transmission``).
    settings : bsdfkit.tables.export.ExportSettings
        The export's settings (``grid``, ``grid_tolerance``).

    Returns
    -------
    theta : ndarray
        The θs axis [deg].
    phi : ndarray
        The φs axis [deg].
    info : dict
        The ``grid`` entry: ``mode``, ``theta`` and ``phi`` node counts, and ``tis_rtol``, ``peak_rtol`` [-]
        unless the mode is ``fixed``.
    """
    fixed = fixed_normal_axes()
    axes, mode = fixed, "fixed"
    tol = settings.grid_tolerance
    if settings.grid == "auto":
        auto = auto_normal_axes(fn, theta_deg, sides, tol, max_nodes=fixed[0].size * fixed[1].size)
        axes, mode = (auto, "auto") if auto is not None else (fixed, FALLBACK)
    info: dict = {"mode": mode, "theta": int(axes[0].size), "phi": int(axes[1].size)}
    if mode != "fixed":
        info.update(tis_rtol=tol.tis_rtol, peak_rtol=tol.peak_rtol)
    return axes[0], axes[1], info


def describe(info: dict, n_theta: int, n_phi: int) -> dict:
    """The ``grid`` entry of a written table about the normal: ``info`` of :func:`normal_axes` with the written node
    counts (``theta``; ``phi`` with a repeated 360° column where the format writes one) and, for the fixed grid,
    the steps in ``mode``.

    Parameters
    ----------
    info : dict
        The ``grid`` entry of :func:`normal_axes`.
    n_theta : int
        Number of θs nodes written.
    n_phi : int
        Number of φs nodes written.

    Returns
    -------
    dict
        ``info`` with the written node counts (and the fixed grid's steps in ``mode``).
    """
    out = dict(info, theta=int(n_theta), phi=int(n_phi))
    if out["mode"] == "fixed":
        out["mode"] = f"fixed: theta {FIXED_THETA_STEP_DEG:g} deg x phi {FIXED_PHI_STEP_DEG:g} deg (normal frame)"
    return out
