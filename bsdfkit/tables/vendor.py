"""Vendor BSDF files (any format of :mod:`bsdfkit.tables.registry`) as calibrated datasets.

:func:`sniff_format` (the registry's) tells the formats apart by content; :func:`vendor_dataset` turns every
table node above the horizon into one record of the calibrated-dataset schema
(:func:`bsdfkit.measurement.table.records_dataset`), in the sample frame, so that the hemispherical engine of
:mod:`bsdfkit.reduction.hemispherical` integrates a vendor file exactly as it integrates a measurement
(``bsdfkit read``, ``ingest``, ``tis`` and the TIS checks of ``convert`` and ``export`` all do).
"""
from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core import frames
from bsdfkit.core.errors import FormatError, InputError, StatedTisWarning
from bsdfkit.measurement.table import (
    DEFAULT_RELATIVE_STD,
    ZERO_POLICIES,
    RecordDirections,
    RecordsOrigin,
    normalise_quantity,
    records_dataset,
    side_of_quantity,
)
from bsdfkit.reduction import basis
from bsdfkit.reduction.hemispherical import hemispherical, unique_rows
from bsdfkit.tables import grids, registry
from bsdfkit.tables.format_spec import FileSummary
from bsdfkit.tables.registry import VendorGrid, VendorTable, sniff_format

__all__ = ["STATED_TIS_ATOL", "STATED_TIS_RTOL", "check_stated_tis", "sniff_format", "vendor_dataset"]

#: Tolerance of :func:`check_stated_tis`: a file's stated TIS S and the integral I of its data disagree when
#: |I - S| > STATED_TIS_RTOL * |S| AND |I - S| > STATED_TIS_ATOL (TIS is a fraction of the incident power, [-]).
#: 10 % because the hemispherical engine and a vendor's own quadrature differ on coarse grids: the well-behaved
#: Radiant Imaging Sphere Zemax file (tests/data/ansys-radiant-zemax-bsdf; 10 deg azimuth steps, radial nodes to
#: 80 deg in 5-10 deg steps) integrates 0.9 % (15 deg) to 7.4 % (75 deg) above its stated TIS. 0.005 absolute so
#: that a faint scatterer (stated TIS ~0.01, a few printed digits) is not flagged for quadrature noise.
STATED_TIS_RTOL = 0.10
STATED_TIS_ATOL = 0.005

#: what bsdfkit does with a file whose stated TIS disagrees (part of the warning and of ``tis_stated_json``): the
#: table is the BSDF; whether OpticStudio rescales a Zemax table to its TIS line is open (docs/exports.md §5)
_STATED_TIS_ACTION = "bsdfkit uses the data as they are (not rescaled to the stated TIS)"


#: kept under their old names for readers of this module
_Grid = VendorGrid
_Vendor = VendorTable


def _read_vendor(path: str | Path, fmt: str | None = None) -> VendorTable:
    """The file's nodes in its native coordinates, by its format's registry hook (sniffed by content)."""
    return registry.get(fmt or sniff_format(path)).vendor_table(str(path))


def _read_summary_and_vendor(path: str, table: VendorTable | None) -> tuple[FileSummary, VendorTable]:
    """The file's summary (its stated TIS) and its nodes (``table`` when given), by one parse where the format
    offers ``summary_and_table``."""
    fmt = registry.get(sniff_format(path))
    summary = None
    if table is None and fmt.summary_and_table is not None:
        summary, table = fmt.summary_and_table(path)
    if table is None:
        table = fmt.vendor_table(path)
    return (summary if summary is not None else fmt.summarise(path)), table


def check_stated_tis(summary: FileSummary, integrated: Mapping[str, Sequence[float]] | None = None, *,
                     integral: str | None = None, skip: Sequence[str] = ()) -> dict[str, Any]:
    """Compare a file's stated TIS with the integral of its data; warn when they disagree.

    The one rule of every format that states a TIS (``FileSummary.tis_stated``: Zemax and ASAP-style per side
    and incidence, LightTools per block, TracePro the total 1 - Abso - Refl - Tran): at each key and incidence
    with both values finite, stated S and integrated I disagree when ``|I - S| > STATED_TIS_RTOL * |S|`` and
    ``|I - S| > STATED_TIS_ATOL``. One :class:`bsdfkit.core.errors.StatedTisWarning` names the file, every
    disagreeing key and incidence with both values, and what bsdfkit does: it keeps the data as they are. (A
    format whose rule makes the table a shape scaled to the stated TIS, Speos, is scaled on reading,
    ``VendorTable.normalise``; its keys are passed in ``skip``.)

    Parameters
    ----------
    summary : FileSummary
        The file's summary: path, format, incidences [deg] and ``tis_stated`` [-].
    integrated : mapping of str to sequence of float, optional
        Key -> integral of the data [-] per entry of ``summary.incidences_deg`` (default ``summary.tis_computed``,
        the engine's values of :func:`bsdfkit.tables.export.read_any`). Keys missing here are not compared.
    integral : str, optional
        How ``integrated`` was computed (recorded; default ``summary.details['tis_rule']``).
    skip : sequence of str
        Keys not compared (the format scales their data to the stated TIS; all keys when ``summary.details`` has
        a ``normalisation`` rule).

    Returns
    -------
    dict
        JSON-ready record: ``rule``, ``rtol`` and ``atol`` [-], ``integral``, ``action``, ``disagrees`` (bool) and
        ``tis`` = key -> {``theta_i_deg`` [deg], ``stated`` [-], ``integrated`` [-], ``disagrees`` [bool]} (lists
        over the incidences where both values are finite).
    """
    integrated = summary.tis_computed if integrated is None else integrated
    if "normalisation" in summary.details:  # Speos: the table is a shape scaled to the stated TIS on reading
        skip = tuple(summary.tis_stated)
    rows: dict[str, dict[str, list]] = {}
    bad: list[str] = []
    for key, stated in summary.tis_stated.items():
        got = integrated.get(key)
        if got is None or key in skip:
            continue
        row: dict[str, list] = {"theta_i_deg": [], "stated": [], "integrated": [], "disagrees": []}
        for theta, s, i in zip(summary.incidences_deg, stated, got):
            s, i = float(s), float(i)
            if not (np.isfinite(s) and np.isfinite(i)):  # a format may state the TIS at some incidences only
                continue
            diff = abs(i - s)
            off = bool(diff > STATED_TIS_RTOL * abs(s) and diff > STATED_TIS_ATOL)
            for name, value in (("theta_i_deg", float(theta)), ("stated", s), ("integrated", i), ("disagrees", off)):
                row[name].append(value)
            if off:
                rel = f" ({100.0 * (i / s - 1.0):+.1f} %)" if s else ""
                bad.append(f"{key} at theta_i {float(theta):g} deg: stated {s:.6g}, integrated {i:.4g}{rel}")
        if row["theta_i_deg"]:
            rows[key] = row
    record = {"rule": "disagree when |integrated - stated| > rtol * |stated| and > atol",
              "rtol": STATED_TIS_RTOL, "atol": STATED_TIS_ATOL,
              "integral": integral or summary.details.get("tis_rule", "the format's own quadrature"),
              "action": _STATED_TIS_ACTION, "disagrees": bool(bad), "tis": rows}
    if bad:
        warnings.warn(StatedTisWarning(
            f"{summary.path}: the {summary.format} file's stated TIS disagrees with the integral of its data "
            f"(by more than {100 * STATED_TIS_RTOL:g} % and {STATED_TIS_ATOL:g}): " + "; ".join(bad)
            + f"; {_STATED_TIS_ACTION}", file=summary.path, details=record), stacklevel=2)
    return record


def _stated_tis_record(ds: xr.Dataset, vendor: VendorTable, summary: FileSummary, sides: list[str]) -> dict:
    """:func:`check_stated_tis` of the ingested dataset ``ds`` (the ``sides`` chosen from ``vendor``): the
    hemispherical engine on its records, as ``bsdfkit read`` and ``bsdfkit tis`` integrate them."""
    scaled = set(vendor.normalise) | set(vendor.normalise_each)  # the format's rule: scaled to the stated TIS
    back = "@back" if ds.attrs.get("face") == "back" else ""  # summary keys of a back face (FileSummary)
    parts: dict[str, list[str]] = {}
    for key in summary.tis_stated:
        if key == "total":  # TracePro's energy balance: both sides, compared only when both were ingested
            if not {g.side for g in vendor.grids} - set(sides):
                parts[key] = list(sides)
        elif key.removesuffix(back) in sides and (not back or key.endswith(back)) and key not in scaled:
            parts[key] = [key.removesuffix(back)]
    if not parts:  # other faces, sample rotations, one side of a TracePro total: nothing in ds to compare with
        return check_stated_tis(summary, {}, skip=tuple(scaled))
    need = sorted({s for p in parts.values() for s in p})
    found = {(r.side, round(float(r.theta_i), 6)): float(r.band_average()["value"])
             for r in hemispherical(ds, sides=tuple(need), errors=False)}
    integrated = {key: [float(sum(found.get((s, round(float(t), 6)), 0.0) for s in p))
                        for t in summary.incidences_deg] for key, p in parts.items()}
    return check_stated_tis(summary, integrated, skip=tuple(scaled),
                            integral="bsdfkit.reduction.hemispherical on the ingested records (as bsdfkit read/tis)")


def _grid_nodes(grid: _Grid, k: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Directions (n, 3) of the nodes of incidence k above the horizon, their values, table azimuths and the
    perpendicular-arc flag (for the two-arc reconstruction)."""
    theta = grid.theta_i[k]
    if grid.kind == "directions":  # scattered directions as given (theta_s, phi_s in the sample frame)
        th, ph = np.radians(np.asarray(grid.first, dtype=np.float64)), np.radians(np.asarray(grid.azimuth))
        d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
        phi_deg = np.asarray(grid.azimuth, dtype=np.float64)
        return d, np.asarray(grid.values[k], dtype=np.float64), phi_deg, np.isclose(np.mod(phi_deg, 180.0), 90.0)
    az = grid.azimuth
    vals = grid.values[k]
    if grid.plane_symmetric:
        mirror = (az > 1e-9) & (az < 180.0 - 1e-9)
        az = np.concatenate([az, 360.0 - az[mirror]])
        vals = np.concatenate([vals, vals[mirror]], axis=0)
    a2, f2 = np.meshgrid(np.radians(az), grid.first, indexing="ij")
    if grid.kind == "specular":
        inside = np.radians(f2) <= grids.horizon_radial(theta, np.degrees(a2)) + 1e-12
        d = frames.direction_from_specular(np.radians(f2[inside]), a2[inside], np.radians(theta))
        d[:, 2] = np.maximum(d[:, 2], 0.0)
        perp_az = np.degrees(a2[inside])
    else:
        psi_sample = np.degrees(a2) + grid.zero_azimuth_deg
        inside = f2 <= grids.rho_max(theta, psi_sample) + 1e-12
        d = frames.direction_from_harvey_shack(f2[inside], np.radians(psi_sample[inside]), np.radians(theta))
        perp_az = psi_sample[inside]
    perp = np.isclose(np.mod(perp_az, 180.0), 90.0, atol=1e-9)
    return d / np.linalg.norm(d, axis=-1, keepdims=True), vals[inside], np.degrees(a2[inside]), perp


FACES = ("front", "back")


def chosen_face(vendor: VendorTable, path: str, face: str | None) -> tuple[str, str]:
    """The face of the sample to read (``face``, else the front, else the only one) and a note for the dataset:
    what else the file holds, never dropped in silence.

    Parameters
    ----------
    vendor : VendorTable
        The file's grids.
    path : str
        The file (named in errors).
    face : str or None
        ``front``, ``back`` or None (the default rule).

    Returns
    -------
    tuple of str
        The face and the note ('' when the file holds one face).
    """
    faces = [f for f in FACES if any(g.face == f for g in vendor.grids)]
    if face is not None and face not in faces:
        raise InputError("the file holds no data for this face", file=path, field="--face",
                         expected=" or ".join(faces), got=face)
    chosen = face or faces[0]
    if faces == ["back"]:
        return chosen, ("the file holds back-side blocks only (Radiance's own writers): they are read as the "
                        "sample's face")
    others = [f for f in faces if f != chosen]
    return chosen, (f"the file also holds the {others[0]} face: ingest it with --face {others[0]}" if others else "")


def chosen_block(vendor: VendorTable, path: str, block: str | None) -> tuple[str, str]:
    """The spectral block to read (``block``, else the file's default: BSDF XML's ``Visible``, else its first) and a
    note naming the others, never dropped in silence; ('', '') for a format of one block.

    Parameters
    ----------
    vendor : VendorTable
        The file's grids.
    path : str
        The file (named in errors).
    block : str or None
        A block's label, or None.

    Returns
    -------
    tuple of str
        The block and the note.
    """
    blocks = list(dict.fromkeys(g.block for g in vendor.grids))
    if block is not None and block not in blocks:
        raise InputError("the file holds no spectral block of this label", file=path, field="--block",
                         expected=" or ".join(b for b in blocks if b) or "no --block (one block)", got=block)
    chosen = block if block is not None else str(vendor.details.get("wavelength_label", blocks[0]))
    chosen = chosen if chosen in blocks else blocks[0]
    others = [b for b in blocks if b != chosen]
    return chosen, (f"the file also holds the {', '.join(others)} block(s): ingest with --block LABEL" if others
                    else "")


def _chosen_grids(vendor: VendorTable, path: str, quantity: str | None, side: str | None,
                  face: str | None = None, block: str | None = None) -> list:
    """The file's grids of the face, spectral block and side asked for (all sides without one), after checking
    ``quantity``, ``side``, ``face`` and ``block``."""
    block, _ = chosen_block(vendor, path, block)
    vendor = replace(vendor, grids=tuple(g for g in vendor.grids if g.block == block))
    face, _ = chosen_face(vendor, path, face)
    vendor = replace(vendor, grids=tuple(g for g in vendor.grids if g.face == face))
    sides_in = [g.side for g in vendor.grids]
    if quantity is not None:
        q = normalise_quantity(quantity, field="--quantity")
        q_side = side_of_quantity(q)
        if q not in ("brdf", "btdf", "bsdf") or (q_side is not None and q_side not in sides_in):
            raise InputError("the file states another quantity than --quantity", file=path, field="--quantity",
                             expected=" or ".join("brdf" if s == "reflection" else "btdf" for s in sides_in), got=q)
        side = side or q_side
    if side is not None:
        if side not in sides_in:
            raise InputError("the file holds no data for this side", file=path, field="--side",
                             expected=" or ".join(sides_in), got=side)
    return [g for g in vendor.grids if side is None or g.side == side]


def _checked_wavelength(stated: float | None, wavelength: float | None, path: str) -> float | None:
    """The table's wavelength [nm]: the file's, else ``wavelength`` (which must agree with the file's)."""
    if wavelength is None:
        return stated
    if not (np.isfinite(wavelength) and wavelength > 0):
        raise InputError("wavelength must be positive", field="--wavelength", expected="> 0 nm", got=wavelength)
    if stated is not None and abs(stated - wavelength) > 1e-6:
        raise InputError("the file states another wavelength", file=path, field="--wavelength",
                         expected=f"{stated:g} nm (or no --wavelength)", got=wavelength)
    return float(wavelength)


def _node_columns(chosen: list) -> dict[str, list]:
    """Per unique node above the horizon of the chosen grids: incidence, direction [deg], side, value, arc and
    basis solid angle (columns of lists)."""
    cols: dict[str, list] = {k: [] for k in ("theta_i", "theta_s", "phi_s", "side", "value", "arc", "psa", "cell")}
    for grid in chosen:
        for k, theta in enumerate(grid.theta_i):
            d, v, _, perp = _grid_nodes(grid, k)
            th, ph = frames.angles_from_direction(d)
            th_deg = np.degrees(th)
            ph_deg = np.where(th_deg < 1e-9, 0.0, np.mod(np.round(np.degrees(ph), 9), 360.0))
            key = np.round(np.stack([th_deg, ph_deg], axis=-1), 7)
            first, inverse, _ = unique_rows(key)
            cols["psa"] += _merged_solid_angle(grid, k, first, np.asarray(inverse).ravel())
            order = np.argsort(first)
            first = first[order]
            cols["cell"] += (np.asarray(grid.cell[k])[first].tolist() if grid.cell is not None else [-1] * first.size)
            arcs = _arc_of(theta, th_deg[first], ph_deg[first], perp[first])
            cols["theta_i"] += [float(theta)] * first.size
            cols["theta_s"] += th_deg[first].tolist()
            cols["phi_s"] += ph_deg[first].tolist()
            cols["side"] += [grid.side] * first.size
            cols["value"] += v[first].tolist()
            cols["arc"] += arcs.tolist()
    return cols


def vendor_dataset(path: str | Path, quantity: str | None = None, side: str | None = None,
                   relative_std: float | None = None, *, wavelength_nm: float | None = None, zeros: str = "keep",
                   sample: str | None = None, table: VendorTable | None = None, face: str | None = None,
                   block: str | None = None) -> xr.Dataset:
    """A Zemax, TracePro (Scatter 5) or ASAP-style table as a calibrated BSDF dataset.

    Parameters
    ----------
    path
        The vendor file (format sniffed like ``bsdfkit read``).
    quantity, side
        Checked against the file (its ScatterType / BRDF-BTDF columns say what it holds); ``side`` also selects
        one side of a two-sided TracePro or ASAP table.
    relative_std
        Standard uncertainty as a fraction of the value (vendor tables state none; default
        :data:`bsdfkit.measurement.table.DEFAULT_RELATIVE_STD`).
    wavelength_nm
        Wavelength [nm] of a Monochrome Zemax or an ASAP-style file (TracePro files state theirs).
    zeros
        ``keep`` (default: a table value 0 is a value) | ``missing`` | ``auto`` (as for text tables).
    sample
        Sample name stored in ``attrs['sample_name']`` (default: the file name without its suffix).
    table
        The file's nodes when already read by its format's registry hook (not read again).
    face
        ``front`` or ``back``: the face of a file that holds both (BSDF XML); default the front (a file with back
        blocks only: those). The dataset's ``face`` attribute names it, ``faces_note`` what else the file holds.
    block
        The spectral block of a file that holds several, by its label (BSDF XML: ``Visible``, ``Solar``, …; default
        ``Visible``, else the first); ``attrs['block']`` names it, ``blocks_note`` the others.

    Returns
    -------
    xarray.Dataset
        One record per table node above the horizon (sample frame, degrees; PlaneSymmetrical Zemax tables
        are mirrored to the full circle; the specular node once), ``bsdf``/``bsdf_std`` [1/sr].
    """
    path = str(path)
    if zeros not in ZERO_POLICIES:
        raise InputError("unknown zero policy", field="zeros", expected=" | ".join(ZERO_POLICIES), got=zeros)
    vendor = table if table is not None else _read_vendor(path)
    chosen = _chosen_grids(vendor, path, quantity, side, face, block)
    block, blocks_note = chosen_block(vendor, path, block)
    face, faces_note = chosen_face(replace(vendor, grids=tuple(g for g in vendor.grids if g.block == block)), path,
                                   face)
    lam = _checked_wavelength(vendor.wavelength_nm, wavelength_nm, path)
    rel = DEFAULT_RELATIVE_STD if relative_std is None else float(relative_std)
    if not (np.isfinite(rel) and rel > 0):
        raise InputError("relative standard uncertainty must be a positive fraction", field="--relative-std",
                         expected="> 0", got=relative_std)
    if registry.get(vendor.format).grid_kind == "normal":  # a full table about the normal: its own interpolant
        chosen = [_normal_grid(g) for g in chosen]
    cols = _node_columns(chosen)
    f = np.asarray(cols["value"], dtype=np.float64)
    if zeros == "missing" or zeros == "auto":
        f = np.where(f == 0.0, np.nan, f)
    keep = np.isfinite(f)
    if not keep.any():
        raise InputError("the file holds no usable values", file=path, field="data", expected="non-zero values")
    idx = np.flatnonzero(keep)
    n = idx.size
    pick = (lambda name: [cols[name][i] for i in idx])  # noqa: E731
    ds = records_dataset(RecordDirections(pick("theta_i"), np.full(n, 180.0), pick("theta_s"), pick("phi_s"),
                                          pick("side"), arc=pick("arc")),
                         [np.nan if lam is None else lam], f[idx][:, None], rel * np.abs(f[idx])[:, None],
                         RecordsOrigin(path, std_origin=f"{rel:g} x |bsdf|" + (
                             " (assumed default: the file states no uncertainty)" if relative_std is None
                             else " (relative_std given)"),
                             description=f"{vendor.format} file {Path(path).name}",
                             wavelength_note="" if lam is not None else
                             "not stated by the file; pass --wavelength NM (NaN = unknown)"))
    if all(g.solid_angle is not None for g in chosen):
        ds = ds.assign_coords({basis.COORD: ("record", np.asarray(pick("psa"), dtype=np.float64))})
        ds[basis.COORD].attrs.update(units="sr", long_name="projected solid angle of the basis cell of the record")
    specs = {g.basis for g in chosen}
    if all(g.cell is not None for g in chosen) and len(specs) == 1 and None not in specs:
        ds = ds.assign_coords({basis.CELL_COORD: ("record", np.asarray(pick("cell"), dtype=np.int64))})
        ds[basis.CELL_COORD].attrs.update(long_name="index of the basis cell the record lies in",
                                          basis=specs.pop())
    ds.attrs.update(source_format=vendor.format, source_layout=vendor.grids[0].kind,
                    source_quantity=" ".join("brdf" if g.side == "reflection" else "btdf" for g in chosen),
                    sample_name=sample or Path(path).stem, zeros_policy=zeros, relative_std=rel, face=face,
                    faces_note=faces_note, block=block, blocks_note=blocks_note,
                    gap_records_dropped=int((~keep).sum()),
                    manifest_json=_json({"format": vendor.format, "details": dict(vendor.details, face=face,
                                                                                  note=faces_note),
                                         "reader": "bsdfkit.tables.to_dataset"}))
    if lam is None:
        ds.attrs["wavelength_note"] = "not stated by the file; pass --wavelength NM (NaN = unknown)"
    return _normalised(ds, vendor, path)


def checked_vendor_dataset(path: str | Path, **options: Any) -> xr.Dataset:
    """:func:`vendor_dataset`, with the TIS the file states compared with the hemispherical integral of the
    ingested records (:func:`check_stated_tis`: a :class:`bsdfkit.core.errors.StatedTisWarning` when they disagree;
    the data are kept as they are) and both recorded in ``attrs['tis_stated_json']``: what ``ingest`` does. The
    TIS checks of ``read``, ``convert`` and ``export`` integrate the dataset themselves.

    Parameters
    ----------
    path
        The vendor file.
    **options
        The keyword options of :func:`vendor_dataset` (``table`` excepted: the file is read here, once where its
        format can give its summary and nodes in one parse).

    Returns
    -------
    xarray.Dataset
        The dataset of :func:`vendor_dataset`, with ``attrs['tis_stated_json']``.
    """
    summary, vendor = _read_summary_and_vendor(str(path), None)
    ds = vendor_dataset(path, table=vendor, **options)
    chosen = _chosen_grids(vendor, str(path), options.get("quantity"), options.get("side"), options.get("face"),
                           options.get("block"))
    ds.attrs["tis_stated_json"] = _json(_stated_tis_record(ds, vendor, summary, [g.side for g in chosen]))
    return ds


def _normal_grid(grid: VendorGrid) -> VendorGrid:
    """A table about the normal (nodes θs × φs, ``directions``) with each node's hat weight [sr] as its solid angle
    and the basis :data:`bsdfkit.reduction.basis.NORMAL_GRID` when the nodes are the full product of its rows and
    columns (the engine then integrates and evaluates the table's own piecewise-linear interpolant); else as it
    is (reconstructed as scattered records)."""
    theta = np.asarray(grid.first, dtype=np.float64)
    phi = np.mod(np.asarray(grid.azimuth, dtype=np.float64), 360.0)
    pole = theta < 1e-9
    rows, cols = np.unique(theta[~pole]), np.unique(np.round(phi[~pole], 9))
    if not pole.any() or rows.size < 2 or cols.size < 3 or (~pole).sum() != rows.size * cols.size:
        return grid
    r = np.searchsorted(rows, theta[~pole])
    c = np.searchsorted(cols, np.round(phi[~pole], 9))
    if np.unique(r * cols.size + c).size != rows.size * cols.size:
        return grid
    w = basis.normal_grid_weights(np.concatenate([[0.0], rows]), cols)
    node_w = np.empty(theta.size)
    node_w[~pole] = w[1 + r, c]
    node_w[pole] = w[0].sum() / pole.sum()  # the pole row is one direction: its nodes share its weight
    cell = np.arange(theta.size)
    n = len(grid.theta_i)
    return replace(grid, solid_angle=np.tile(node_w, (n, 1)), cell=np.tile(cell, (n, 1)), basis=basis.NORMAL_GRID)


def _merged_solid_angle(grid: _Grid, k: int, first: NDArray[np.int64], inverse: NDArray[np.int64]) -> list[float]:
    """Basis solid angles [sr] of the unique nodes of incidence k, in the order of ``first`` once sorted: nodes at
    one direction add their parts of the cell (NaN per node for a grid without basis)."""
    if grid.solid_angle is None:
        return [float("nan")] * first.size
    merged = np.zeros(first.size)
    np.add.at(merged, inverse, np.asarray(grid.solid_angle[k], dtype=np.float64))
    return merged[np.argsort(first)].tolist()


def _normalised(ds: xr.Dataset, vendor: VendorTable, path: str) -> xr.Dataset:
    """The format's own scale rule (``VendorTable.normalise``): each side scaled so that the hemispherical
    engine's TIS at the stated incidence equals the stated TIS (Speos: the table is a shape, the spectrum its
    scale)."""
    if not vendor.normalise and not vendor.normalise_each:
        return ds
    sides = np.asarray(ds["side"].values).astype(str)
    thetas = np.asarray(ds["theta_i"].values, dtype=np.float64)
    scale = np.ones(sides.size)
    notes: dict[str, Any] = {}
    for side, pairs in vendor.normalise_each.items():
        for theta, stated in pairs:
            rows = (sides == side) & (np.abs(thetas - theta) <= 1e-6)
            if not rows.any():
                continue
            res = hemispherical(ds, theta_i_deg=[float(theta)], sides=(side,), errors=False)
            raw = float(res[0].band_average()["value"]) if res else 0.0
            if not raw > 0:
                if stated > 0:
                    raise FormatError("the table integrates to zero but states a positive TIS", file=path,
                                      field=f"{side}: table at theta_i={theta:g}", expected="a positive integral")
                continue
            scale[rows] = stated / raw
            notes[f"{side}@{theta:g}"] = {"tis_stated": float(stated), "tis_table": raw, "scale": float(stated / raw)}
    for side, (theta, stated) in vendor.normalise.items():
        if side not in set(sides):
            continue
        have = np.unique(np.asarray(ds["theta_i"].values)[sides == side])
        if not np.any(np.abs(have - theta) <= 1e-6):
            raise FormatError("the spectrum's incidence is not one of the table's", file=path,
                              field=f"{side}: spectrum incidence", expected=f"one of {have.tolist()}", got=theta)
        res = hemispherical(ds, theta_i_deg=[float(theta)], sides=(side,), errors=False)
        raw = float(res[0].band_average()["value"]) if res else 0.0
        if not raw > 0:
            raise FormatError("the table integrates to zero where the spectrum is stated", file=path,
                              field=f"{side}: table at theta_i={theta:g}", expected="a positive integral")
        scale[sides == side] = stated / raw
        notes[side] = {"theta_i_deg": float(theta), "tis_stated": float(stated), "tis_table": raw,
                       "scale": float(stated / raw)}
    out = ds.copy()
    for name in ("bsdf", "bsdf_std"):
        if name in out:
            out[name] = out[name] * xr.DataArray(scale, dims=out[name].dims[:1])
    out.attrs["normalisation_json"] = _json(notes)
    return out


def _arc_of(theta_i: float, theta_s: NDArray, phi_s: NDArray, perp_line: NDArray) -> NDArray[np.object_]:
    rel = np.radians(phi_s)
    in_plane = (np.abs(np.sin(rel)) * np.sin(np.radians(theta_s)) < 1e-9) | (theta_s < 1e-9)
    return np.where(in_plane, "in_plane", np.where(perp_line, "perpendicular", "other")).astype(object)


def _json(obj: Any) -> str:
    return json.dumps(obj, default=str)


