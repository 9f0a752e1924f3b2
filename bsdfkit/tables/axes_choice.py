"""How an export chooses its table axes (given, fixed or tolerance-driven auto), shared by the writers of
:mod:`bsdfkit.tables.formats` (``settings`` is a :class:`bsdfkit.tables.export.ExportSettings`)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.lazy import LazyModule
from bsdfkit.tables import grids

#: xarray on first use: the verbs' registration reads the format registry, which imports this module
xr = LazyModule("xarray")

BsdfFn = grids.BsdfFn


def plane_symmetric_grid(
    fn: BsdfFn, theta_deg: NDArray, side: str, axes: grids.SpecularAxes, tolerance: float
) -> tuple[xr.DataArray, float]:
    """Specular grid for a PlaneSymmetrical file: the mirror average (f(a) + f(360° − a))/2 of the source.

    Plane symmetry is a property the *source* must have; measured reconstructions hold it only to their
    noise. The deviation max|f(a) − f(360° − a)| / max f (per incidence block) is returned; above
    ``tolerance`` the export is refused (use Asymmetrical). The average leaves the TIS unchanged (the
    projected solid angle is symmetric under the mirror y → −y).

    Parameters
    ----------
    fn : callable
        The source, ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (:data:`bsdfkit.tables.grids.BsdfFn`).
    theta_deg : ndarray
        Incidences of the table (the specular angle) [deg].
    side : str
        The side tabulated, ``reflection`` or ``transmission``.
    axes : bsdfkit.tables.grids.SpecularAxes
        The table's radial and azimuth axes [deg].
    tolerance : float
        Largest deviation from plane symmetry accepted, relative to the block maximum [-].

    Returns
    -------
    grid : xarray.DataArray
        The mirror-averaged BSDF [1/sr], dims ``(side, theta_i, azimuth, radial)``.
    deviation : float
        The largest deviation found, relative to the block maximum [-].
    """
    mirrored = tuple(sorted({float(np.mod(360.0 - a, 360.0)) for a in axes.azimuth_deg}))
    half = grids.specular_grid(fn, theta_deg, side, axes)
    full = grids.specular_grid(fn, theta_deg, side, grids.SpecularAxes(axes.radial_deg, mirrored))
    mirror = np.stack([full.sel(azimuth=float(np.mod(360.0 - a, 360.0))).values for a in axes.azimuth_deg], axis=-2)
    scale = np.max(half.values, axis=(-1, -2), keepdims=True)
    deviation = np.abs(half.values - mirror) / np.where(scale > 0, scale, 1.0)
    worst = float(np.max(deviation))
    if worst > tolerance:
        _, t, k, _ = np.unravel_index(int(np.argmax(deviation)), deviation.shape)
        a = axes.azimuth_deg[k]
        raise ValidationError(
            f"source is not plane-symmetric at theta_i={theta_deg[t]:g} deg "
            f"(azimuth {a:g} vs {np.mod(360 - a, 360):g})",
            field="zemax_symmetry", expected=f"deviation <= {tolerance:g} of the block maximum, or Asymmetrical",
            got=f"{worst:.3g}",
        )
    return half.copy(data=0.5 * (half.values + mirror)), worst


#: Grid mode reported when the auto grid would need more nodes than the fixed grid: the fixed grid is written.
FALLBACK = "fixed (the tolerance needs more nodes than the fixed grid)"
#: Grid mode reported when the written auto table failed its re-check after RECHECK_ROUNDS re-choices.
FALLBACK_RECHECK = "fixed (the auto table failed its re-read TIS check)"
#: The written auto table's TIS (as bsdfkit read integrates it) must be within RECHECK_FACTOR × tis_rtol of the
#: direct integral of the source callable; else its axes are chosen again with tis_rtol × RECHECK_TIGHTEN^k
#: (k = 1, 2, …), at most RECHECK_ROUNDS times, and the written table closest to the source kept (cell averages: the
#: azimuths doubled, then the fixed grid).
RECHECK_FACTOR = 1.0
RECHECK_ROUNDS = 2
RECHECK_TIGHTEN = 0.7


def grid_info(mode: str, n_radial: int, n_azimuth: int, settings: Any) -> dict[str, Any]:
    """The ``grid`` entry of an export's result: mode, node counts and, for a mode other than fixed or given, the
    tolerances.

    Parameters
    ----------
    mode : str
        How the axes were chosen: ``given``, ``fixed``, ``auto`` or a fallback (:data:`FALLBACK`).
    n_radial : int
        Number of radial nodes.
    n_azimuth : int
        Number of azimuth nodes.
    settings : bsdfkit.tables.export.ExportSettings
        The export's settings (its ``grid_tolerance``).

    Returns
    -------
    dict
        ``mode``, ``radial``, ``azimuth``, and ``tis_rtol``, ``peak_rtol`` [-] unless ``mode`` is ``fixed`` or
        ``given``.
    """
    info: dict[str, Any] = {"mode": mode, "radial": n_radial, "azimuth": n_azimuth}
    if mode != "fixed" and mode != "given":
        info.update(tis_rtol=settings.grid_tolerance.tis_rtol, peak_rtol=settings.grid_tolerance.peak_rtol)
    return info


def harvey_shack_axes(fn: BsdfFn, theta_deg: NDArray[np.float64], sides: Sequence[str], settings: Any,
                       zero_azimuth_deg: float) -> tuple[grids.HarveyShackAxes, dict[str, Any]]:
    """The Harvey–Shack axes of an export: given, fixed (the fine defaults) or auto (tolerance-driven; for a table
    of cell averages, ``settings.node_values == "cell"``, refined by the lobe's peak only:
    :func:`harvey_shack_table`).

    Parameters
    ----------
    fn : callable
        The source, ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (:data:`bsdfkit.tables.grids.BsdfFn`).
    theta_deg : ndarray
        Incidences of the table [deg].
    sides : sequence of str
        Sides the axes serve (``reflection``, ``transmission``).
    settings : bsdfkit.tables.export.ExportSettings
        The export's settings (``harvey_shack_axes``, ``grid``, ``grid_tolerance``, ``node_values``).
    zero_azimuth_deg : float
        Sample-frame azimuth of the table's 0 azimuth axis [deg].

    Returns
    -------
    axes : bsdfkit.tables.grids.HarveyShackAxes
        The chosen axes.
    info : dict
        The ``grid`` entry of the export's result (:func:`grid_info`).
    """
    if settings.harvey_shack_axes is not None:
        axes, mode = settings.harvey_shack_axes, "given"
    elif settings.grid == "fixed":
        axes, mode = grids.HarveyShackAxes.default(zero_azimuth_deg=zero_azimuth_deg), "fixed"
    else:
        fixed = grids.HarveyShackAxes.default(zero_azimuth_deg=zero_azimuth_deg)
        values = settings.node_values
        # cell averages: TIS is the source's on any axes, so only the lobe's peak refines them; edge values: the
        # TIS compared is that of each candidate table with its own edge values
        auto = grids.auto_harvey_shack_axes(fn, theta_deg, sides, settings.grid_tolerance, zero_azimuth_deg,
                                            max_nodes=len(fixed.rho) * len(fixed.azimuth_deg),
                                            cell_average=values == "cell", edge_values=values == "edge")
        axes, mode = (auto, "auto") if auto is not None else (fixed, FALLBACK)
    return axes, grid_info(mode, len(axes.rho), len(axes.azimuth_deg), settings)


def harvey_shack_table(fn: BsdfFn, theta_deg: NDArray[np.float64], sides: Sequence[str], axes: grids.HarveyShackAxes,
                       info: dict[str, Any], settings: Any) -> xr.DataArray:
    """The values a Harvey–Shack writer (TracePro, ASAP-style) puts on its axes, recorded in ``info['values']``
    (:data:`VALUES_LABEL`): ``settings.node_values`` ``edge`` (default: point samples, each row's last node inside
    the disk its edge value, :func:`bsdfkit.tables.grids.harvey_shack_edge_values`), ``point`` (point samples) or
    ``cell`` (cell averages: the table's TIS by its format's rule is the source's on any axes,
    :func:`bsdfkit.tables.grids.harvey_shack_cell_grid`). On auto axes the values are printed with the digits the TIS
    tolerance needs (:func:`bsdfkit.tables.grids.value_digits`, recorded in ``info['value_digits']``).

    Parameters
    ----------
    fn : callable
        The source, ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (:data:`bsdfkit.tables.grids.BsdfFn`).
    theta_deg : ndarray
        Incidences of the table [deg].
    sides : sequence of str
        Sides tabulated (``reflection``, ``transmission``).
    axes : bsdfkit.tables.grids.HarveyShackAxes
        The table's axes (:func:`harvey_shack_axes`).
    info : dict
        The ``grid`` entry of the export's result; its ``values`` is set here.
    settings : bsdfkit.tables.export.ExportSettings
        The export's settings (its ``node_values``).

    Returns
    -------
    xarray.DataArray
        The BSDF values on the nodes [1/sr], dims ``(side, theta_i, rho, psi)``.
    """
    values = settings.node_values
    info["values"] = VALUES_LABEL[values]
    if values == "cell":
        grid = grids.harvey_shack_cell_grid(fn, theta_deg, sides, axes)
    elif values == "edge":
        grid = grids.harvey_shack_edge_grid(fn, theta_deg, sides, axes)
    else:
        grid = grids.harvey_shack_grid(fn, theta_deg, sides, axes)
    if info.get("mode") == "auto":  # as many digits as the TIS tolerance needs (a round-off budget far below it)
        digits = grids.value_digits(settings.grid_tolerance.tis_rtol)
        info["value_digits"] = digits
        grid = grid.copy(data=grids.quantize(grid.values, f".{digits}g"))
    return grid


#: ``grid['values']`` of an export by ``node_values`` (and back: the re-check rewrites with the same values)
VALUES_LABEL = {"point": "point samples", "edge": "point samples, edge values at the disk's edge",
                "cell": "cell averages"}


def specular_axes(fn: BsdfFn, theta_deg: NDArray[np.float64], sides: Sequence[str],
                   settings: Any) -> tuple[grids.SpecularAxes, dict[str, Any]]:
    """The Zemax axes of an export: given, fixed (the fine defaults) or auto (tolerance-driven).

    Parameters
    ----------
    fn : callable
        The source, ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (:data:`bsdfkit.tables.grids.BsdfFn`).
    theta_deg : ndarray
        Incidences of the table (the specular angle) [deg].
    sides : sequence of str
        Sides the axes serve (``reflection``, ``transmission``).
    settings : bsdfkit.tables.export.ExportSettings
        The export's settings (``specular_axes``, ``grid``, ``grid_tolerance``, ``zemax_symmetry``).

    Returns
    -------
    axes : bsdfkit.tables.grids.SpecularAxes
        The chosen radial and azimuth axes [deg].
    info : dict
        The ``grid`` entry of the export's result (:func:`grid_info`).
    """
    symmetric = settings.zemax_symmetry == "PlaneSymmetrical"
    if settings.specular_axes is not None:
        axes, mode = settings.specular_axes, "given"
    elif settings.grid == "fixed":
        axes, mode = grids.SpecularAxes.default(plane_symmetric=symmetric), "fixed"
    else:
        fixed = grids.SpecularAxes.default(plane_symmetric=symmetric)
        auto = grids.auto_specular_axes(fn, theta_deg, sides, settings.grid_tolerance, symmetric,
                                        max_nodes=len(fixed.radial_deg) * len(fixed.azimuth_deg))
        axes, mode = (auto, "auto") if auto is not None else (fixed, FALLBACK)
    return axes, grid_info(mode, len(axes.radial_deg), len(axes.azimuth_deg), settings)
