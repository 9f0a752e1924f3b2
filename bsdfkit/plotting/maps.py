"""Irradiance maps of the phosphor plate (Figs. 10, 12, 14 of [Cylindrical-module]).

A map is the ``irradiance`` variable of a trace result (``TraceResult.to_dataset()``, ``trace_device.nc``):
dims ``(y_mm, x_mm)``, bin centres in mm spanning the plate's square [−R, R]², units ``W/mm^2`` for the
LED power of the scene (1 W in the bundled scenes). Sweep datasets (``sweep_dataset``) carry the same
variable with one extra dimension per swept parameter, e.g. ``(wall.specular_fraction, y_mm, x_mm)``.

Only bins lying entirely inside the plate are drawn: they are the bins over which the tracer computes the
irradiance non-uniformity (E_max − E_min)/(E_max + E_min) (§5.1 of [Cylindrical-module],
:func:`bsdfkit.raytrace.tallies.non_uniformity`), so the colour bar's ends are exactly E_min and E_max of
that figure. Uses matplotlib's object API (no pyplot, no global backend state).
"""
from __future__ import annotations

import itertools
from collections.abc import Mapping

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from bsdfkit.plotting.layout import Margins, fixed_margins
from bsdfkit.raytrace.tallies import interior_bins

__all__ = ["MAP_DIMS", "find_map_variable", "irradiance_map_figure", "irradiance_maps_figure", "map_display",
           "map_non_uniformity", "map_panels"]

#: The two spatial dimensions of a map, (row, column).
MAP_DIMS = ("y_mm", "x_mm")

#: File units → (display units, factor): irradiance is shown in W/m² (SI).
_UNITS = {"W/mm^2": ("W/m²", 1e6), "W/mm2": ("W/m²", 1e6), "W/cm^2": ("W/m²", 1e4), "W/m^2": ("W/m²", 1.0),
          "W/m2": ("W/m²", 1.0)}


#: Margins of :func:`irradiance_maps_figure` [in]: tick labels and axis label left and below, a line of a panel
#: title at fontsize 9, the figure title, the colour bar's column (gap, bar, its tick labels and label)
_LEFT_IN, _BOTTOM_IN, _RIGHT_IN, _WSPACE_IN = 0.75, 0.55, 0.15, 0.85
_LINE_IN, _TITLE_PAD_IN, _SUPTITLE_IN = 0.155, 0.1, 0.3
_COLOURBAR_IN, _COLOURBAR_GAP_IN, _COLOURBAR_WIDTH_IN = 1.3, 0.25, 0.15


def find_map_variable(ds: xr.Dataset) -> str | None:
    """The name of the irradiance-map variable of ``ds`` (``irradiance`` first), or None.

    A map-like variable is a float variable having both dims ``y_mm`` and ``x_mm``.

    Parameters
    ----------
    ds : xarray.Dataset
        Trace or sweep dataset.

    Returns
    -------
    str or None
    """
    candidates = [name for name, var in ds.data_vars.items()
                  if all(d in var.dims for d in MAP_DIMS) and var.dtype.kind == "f"]
    for preferred in ("irradiance", "map"):
        if preferred in candidates:
            return preferred
    return candidates[0] if candidates else None


def _interior(da: xr.DataArray) -> np.ndarray:
    """Mask of the bins entirely inside the plate (square maps centred on the plate); all bins otherwise."""
    ny, nx = da.sizes[MAP_DIMS[0]], da.sizes[MAP_DIMS[1]]
    x = np.asarray(da[MAP_DIMS[1]].values, dtype=float)
    y = np.asarray(da[MAP_DIMS[0]].values, dtype=float)
    centred = ny == nx and nx > 1 and np.allclose(x, -x[::-1]) and np.allclose(y, -y[::-1]) and np.allclose(x, y)
    return interior_bins(nx) if centred else np.ones((ny, nx), dtype=bool)


def _plate_radius_mm(da: xr.DataArray) -> float:
    x = np.asarray(da[MAP_DIMS[1]].values, dtype=float)
    half_bin = 0.5 * (x[1] - x[0]) if x.size > 1 else 0.0
    return float(np.max(np.abs(x)) + abs(half_bin))


def map_non_uniformity(da: xr.DataArray) -> float:
    """(E_max − E_min)/(E_max + E_min) of one 2-D map over the bins entirely inside the plate.

    Parameters
    ----------
    da : xarray.DataArray
        Irradiance map on dims ``(y_mm, x_mm)``, bin centres [mm], values in its ``units`` attribute (e.g. [W/mm^2]).

    Returns
    -------
    float
        Non-uniformity [-]; NaN without finite positive values.
    """
    values = np.asarray(da.transpose(*MAP_DIMS).values, dtype=float)[_interior(da)]
    values = values[np.isfinite(values)]
    if values.size == 0:
        return float("nan")
    hi, lo = float(values.max()), float(values.min())
    return (hi - lo) / (hi + lo) if hi + lo > 0 else float("nan")


def map_display(da: xr.DataArray) -> tuple[np.ndarray, str]:
    """The 2-D map in display units (bins outside the plate masked as NaN) and the unit text.

    Parameters
    ----------
    da : xarray.DataArray
        Irradiance map on dims ``(y_mm, x_mm)``, bin centres [mm], values in its ``units`` attribute (e.g. [W/mm^2]).

    Returns
    -------
    values : ndarray, shape (ny, nx)
        The map in display units (W/m² for irradiance), NaN outside the plate.
    units : str
        The display unit.
    """
    units = str(da.attrs.get("units", ""))
    label, factor = _UNITS.get(units.replace(" ", ""), (units or "arbitrary units", 1.0))
    values = np.asarray(da.transpose(*MAP_DIMS).values, dtype=float) * factor
    return np.where(_interior(da), values, np.nan), label


def _colour_label(da: xr.DataArray, units: str, emitted_W: float | None) -> str:
    text = f"irradiance E ({units})"
    if emitted_W is not None and np.isfinite(emitted_W):
        text += f"\nfor {emitted_W:g} W emitted by the LEDs"
    return text


def _draw(ax, da: xr.DataArray, vmin: float, vmax: float, title: str):
    """One map on ``ax``; returns the mappable for a colour bar."""
    values, _ = map_display(da)
    x = np.asarray(da[MAP_DIMS[1]].values, dtype=float)
    y = np.asarray(da[MAP_DIMS[0]].values, dtype=float)
    mesh = ax.pcolormesh(x, y, np.ma.masked_invalid(values), shading="nearest", cmap="viridis", vmin=vmin,
                         vmax=vmax)
    radius = _plate_radius_mm(da)
    ax.add_patch(Circle((0.0, 0.0), radius, fill=False, lw=0.8, ls="--", color="0.3"))
    ax.set_xlim(-radius * 1.03, radius * 1.03)
    ax.set_ylim(-radius * 1.03, radius * 1.03)
    ax.set_aspect("equal")
    ax.set_xlabel("x on the plate (mm)")
    ax.set_ylabel("y on the plate (mm)")
    ax.set_title(title, fontsize=9)
    return mesh


def _nu_text(nu: float) -> str:
    return "non-uniformity n/a" if not np.isfinite(nu) else f"non-uniformity {100 * nu:.1f} %"


def irradiance_map_figure(da: xr.DataArray, title: str = "irradiance on the cavity side of the plate",
                          non_uniformity: float | None = None, emitted_W: float | None = None) -> Figure:
    """One irradiance map: axes in mm, equal aspect, colour bar with units, the non-uniformity in the title.

    ``da`` has dims ``(y_mm, x_mm)``; ``non_uniformity`` (fraction) defaults to the value computed from the map
    (the same definition as the tracer's). The dashed circle is the plate's edge.

    Parameters
    ----------
    da : xarray.DataArray
        Irradiance map on dims ``(y_mm, x_mm)``, bin centres [mm], values in its ``units`` attribute (e.g. [W/mm^2]).
    title : str, optional
        First title line.
    non_uniformity : float, optional
        Non-uniformity to show [-]; computed from the map when None.
    emitted_W : float, optional
        LED power of the scene, named in the colour-bar label [W].

    Returns
    -------
    matplotlib.figure.Figure
    """
    if set(da.dims) != set(MAP_DIMS):
        raise ValueError(f"an irradiance map has dims {MAP_DIMS}, got {da.dims}")
    nu = map_non_uniformity(da) if non_uniformity is None else float(non_uniformity)
    values, units = map_display(da)
    finite = values[np.isfinite(values)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    fig = Figure(figsize=(5.6, 4.6))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    mesh = _draw(ax, da, vmin, vmax, f"{title}\n{_nu_text(nu)} ((E_max − E_min)/(E_max + E_min))")
    bar = fig.colorbar(mesh, ax=ax)
    bar.set_label(_colour_label(da, units, emitted_W))
    fig.tight_layout()
    return fig


def map_panels(da: xr.DataArray) -> list[tuple[str, xr.DataArray]]:
    """Split a map with extra dims (a sweep) into titled 2-D panels, in the order of the extra dims.

    Parameters
    ----------
    da : xarray.DataArray
        Map with dims ``(y_mm, x_mm)`` and any extra dims.

    Returns
    -------
    list of (str, xarray.DataArray)
        Panel title and 2-D map, one per combination of the extra dims' indices.
    """
    extra = [d for d in da.dims if d not in MAP_DIMS]
    if not extra:
        return [("", da)]
    panels = []
    for index in itertools.product(*[range(da.sizes[d]) for d in extra]):
        sub = da.isel(dict(zip(extra, index)))
        labels = []
        for d in extra:
            value = sub[d].values.item() if d in sub.coords else index[extra.index(d)]
            labels.append(f"{d} = {value:g}" if isinstance(value, int | float) else f"{d} = {value}")
        panels.append((", ".join(labels), sub))
    return panels


def irradiance_maps_figure(maps: Mapping[str, xr.DataArray] | xr.DataArray, ncols: int | None = None,
                           shared_scale: bool = True, emitted_W: float | None = None,
                           title: str | None = None) -> Figure:
    """A grid of irradiance maps, e.g. three wall finishes (Fig. 10) or three heights (Fig. 12).

    ``maps`` is either {panel title: 2-D map} or one DataArray with extra dims (a sweep dataset's map), whose
    first extra dimension gives the rows and the second the columns. With ``shared_scale`` all panels share
    one colour bar (so panels compare directly); each panel's title carries its own non-uniformity.

    Parameters
    ----------
    maps : Mapping of str to xarray.DataArray, or xarray.DataArray
        Panel title → 2-D map, or one map with extra dims; values as in :func:`map_display`.
    ncols : int, optional
        Number of columns of the grid.
    shared_scale : bool, optional
        One colour bar for all panels.
    emitted_W : float, optional
        LED power of the scene, named in the colour-bar label [W].
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if isinstance(maps, xr.DataArray):
        extra = [d for d in maps.dims if d not in MAP_DIMS]
        panels = map_panels(maps)
        if ncols is None:
            ncols = maps.sizes[extra[-1]] if len(extra) >= 2 else len(panels)
    else:
        panels = list(maps.items())
    if not panels:
        raise ValueError("no maps to draw")
    ncols = max(1, min(len(panels), 3) if ncols is None else int(ncols))
    nrows = -(-len(panels) // ncols)
    displays = [map_display(da) for _, da in panels]
    units = displays[0][1]
    width, height = 3.6 * ncols + (1.0 if shared_scale else 0.0), 3.5 * nrows + (0.4 if title else 0.0)
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    # fixed margins in inches instead of a layout engine (constrained layout measured every text twice: 40 % of
    # the report's map drawing time); the panel titles' lines set the room above each row
    head = _LINE_IN * max((name.count("\n") + 2 if name else 1) for name, _ in panels) + _TITLE_PAD_IN
    top = head + (_SUPTITLE_IN if title else 0.0)
    right = _COLOURBAR_IN if shared_scale else _RIGHT_IN
    fixed_margins(fig, nrows, ncols, Margins(left=_LEFT_IN, right=right, bottom=_BOTTOM_IN, top=top,
                                             wspace=_WSPACE_IN, hspace=head + _BOTTOM_IN))
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    finite = np.concatenate([v[np.isfinite(v)] for v, _ in displays])
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    meshes = []
    for ax, (name, da), (values, _) in zip(axes, panels, displays):
        if shared_scale:
            vmin, vmax = lo, hi
        else:
            own = values[np.isfinite(values)]
            vmin, vmax = (float(own.min()), float(own.max())) if own.size else (0.0, 1.0)
        mesh = _draw(ax, da, vmin, vmax, f"{name}\n{_nu_text(map_non_uniformity(da))}" if name else
                     _nu_text(map_non_uniformity(da)))
        meshes.append((ax, mesh))
        if not shared_scale:
            fig.colorbar(mesh, ax=ax).set_label(_colour_label(da, units, emitted_W))
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if shared_scale:
        # the colour bar spans the rows, in the right margin
        lo_y, hi_y = _BOTTOM_IN / height, 1.0 - top / height
        cax = fig.add_axes((1.0 - (_COLOURBAR_IN - _COLOURBAR_GAP_IN) / width, lo_y, _COLOURBAR_WIDTH_IN / width,
                            hi_y - lo_y))
        bar = fig.colorbar(meshes[0][1], cax=cax)
        bar.set_label(_colour_label(panels[0][1], units, emitted_W))
    if title:
        fig.suptitle(title, fontsize=10, y=1.0 - 0.08 / height, va="top")
    return fig
