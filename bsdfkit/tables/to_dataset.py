"""Vendor BSDF files into the calibrated dataset schema, and the ``ingest`` / ``convert`` front ends.

* :func:`vendor_dataset` reads a Zemax/Radiant tabular BSDF (``.bsdf``), a TracePro surface-property table
  (Scatter 5) or a bsdfkit ASAP-style table into the dataset of
  :func:`bsdfkit.measurement.calibrate.calibrate` (one record per table node above the horizon, in the sample
  frame of ``docs/raw-format.md``; the table's BSDF values [1/sr]; ``bsdf_std`` = ``relative_std`` × value).
* :func:`source_kind` tells a raw-scan folder, a netCDF dataset, a vendor file and a text table apart;
  :func:`ingest` reads any of them into that dataset (``bsdfkit ingest``, :func:`bsdfkit.api.ingest`).
* :func:`convert` writes any readable source as a TracePro, Zemax or ASAP-style table (``bsdfkit convert``)
  and checks the TIS of the re-read file against the TIS of the source: for a vendor file, the TIS bsdfkit
  recomputes from the original file with that format's quadrature (:func:`bsdfkit.tables.export.read_any`);
  for a dataset, the direct integral of the two-arc hemisphere reconstruction
  (:class:`bsdfkit.reduction.tis.Hemisphere`) that is exported.

Vendor files are converted through their own grids, not through a dataset: the BSDF callable interpolates the
original table bilinearly in its native coordinates (radial × azimuth about the specular direction for Zemax,
|β − β0| × azimuth for TracePro/ASAP), zero beyond the last radial node like the readers' quadratures.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core import frames
from bsdfkit.core.errors import FormatError, InputError, NumericalError, ValidationError
from bsdfkit.io import atomic, netcdf
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.measurement.table import (
    read_table,
)
from bsdfkit.reduction.hemispherical import elastic_source, reduction_kind
from bsdfkit.reduction.tis import hemisphere_bsdf_fn
from bsdfkit.tables import grids
from bsdfkit.tables.export import FORMATS, ExportResult, ExportSettings, export, read_any
from bsdfkit.tables.vendor import _Grid, _read_vendor, sniff_format, vendor_dataset

__all__ = ["VENDOR_FORMATS", "ConvertResult", "source_kind", "vendor_dataset", "vendor_bsdf_fn", "ingest",
           "convert", "TABLE_OPTIONS"]

VENDOR_FORMATS: tuple[str, ...] = ("zemax", "tracepro", "asap")
#: Options :func:`ingest` passes to the text-table and vendor readers.
TABLE_OPTIONS = ("quantity", "side", "relative_std", "wavelength", "incidence", "phi_i", "zeros", "sample")
_NETCDF_MAGIC = (b"\x89HDF", b"CDF\x01", b"CDF\x02")
_MATCH_DEG = 1e-6

BsdfFn = Callable[[float, str, NDArray[np.float64]], NDArray[np.float64]]


# ------------------------------------------------------------------------------------------- sniffing
def source_kind(path: str | Path) -> str:
    """``raw-scan`` | ``netcdf`` | ``zemax`` | ``tracepro`` | ``asap`` | ``table`` (any other text file)."""
    p = Path(path)
    if p.is_dir():
        if not (p / "manifest.toml").is_file():
            raise InputError("folder without manifest.toml", file=p,
                             expected="a raw goniometer export (docs/raw-format.md), a text table or a vendor file")
        return "raw-scan"
    if not p.is_file():
        raise InputError("no such file or folder", file=p,
                         expected="a raw export folder, a text table, a vendor BSDF file or a netCDF dataset")
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=p) from None
    if head.startswith(_NETCDF_MAGIC):
        return "netcdf"
    try:
        return sniff_format(p)
    except FormatError:
        return "table"


# ------------------------------------------------------------------------------------------- native callables
def _rows_interp(first: NDArray, block: NDArray, rows: NDArray[np.int64], q: NDArray) -> NDArray:
    """Piecewise-linear interpolation in the first coordinate of ``block[rows[k]]`` at ``q[k]`` (vectorised),
    clamped below the first node and 0 beyond the last node (the readers' quadratures stop there)."""
    if first.size == 1:
        return np.where(q > first[0] + 1e-12, 0.0, block[rows, 0])
    hi = np.clip(np.searchsorted(first, q, side="right"), 1, first.size - 1)
    lo = hi - 1
    t = np.clip((q - first[lo]) / (first[hi] - first[lo]), 0.0, 1.0)
    out = (1.0 - t) * block[rows, lo] + t * block[rows, hi]
    return np.where(q > first[-1] + 1e-12, 0.0, out)


def _hold_outside(grid: _Grid) -> NDArray[np.float64]:
    """Harvey–Shack rows with the nodes outside the unit disk replaced by the last inside value (the readers'
    quadrature holds that value up to the edge)."""
    vals = grid.values.copy()
    if grid.kind != "harvey_shack":
        return vals
    for k, theta in enumerate(grid.theta_i):
        rmax = grids.rho_max(theta, grid.azimuth + grid.zero_azimuth_deg)
        for a in range(grid.azimuth.size):
            inside = grid.first <= rmax[a] + 1e-12
            if inside.any() and not inside.all():
                last = int(np.flatnonzero(inside)[-1])
                vals[k, a, last + 1:] = vals[k, a, last]
    return vals


def _grid_fn(grid: _Grid) -> BsdfFn:
    vals_all = _hold_outside(grid)
    az = grid.azimuth
    if grid.plane_symmetric:
        az_ext, ext_idx = az, np.arange(az.size)
    else:  # periodic: close the circle
        az_ext = np.concatenate([az - 360.0, az, az + 360.0])
        ext_idx = np.concatenate([np.arange(az.size)] * 3)

    def fn(theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        if side != grid.side:
            raise ValidationError("the file holds no data for this side", field="side", expected=grid.side, got=side)
        k = int(np.argmin(np.abs(grid.theta_i - theta_i_deg)))
        if abs(grid.theta_i[k] - theta_i_deg) > _MATCH_DEG:
            raise InputError("incidence not in the file", field="theta_i",
                             expected="one of " + ", ".join(f"{t:g}" for t in grid.theta_i), got=theta_i_deg)
        d = np.asarray(directions, dtype=np.float64)
        shape = d.shape[:-1]
        d = d.reshape(-1, 3)
        if grid.kind == "specular":
            r, a = frames.specular_from_direction(d, np.radians(theta_i_deg))
            first, azq = np.degrees(r), np.degrees(a)
            if grid.plane_symmetric:
                azq = np.where(azq > 180.0, 360.0 - azq, azq)
                azq = np.clip(azq, az[0], az[-1])
        else:
            rho, psi = frames.harvey_shack_from_direction(d, np.radians(theta_i_deg))
            first = rho
            azq = np.mod(np.degrees(psi) - grid.zero_azimuth_deg, 360.0)
        hi = np.clip(np.searchsorted(az_ext, azq, side="right"), 1, az_ext.size - 1)
        lo = hi - 1
        span = az_ext[hi] - az_ext[lo]
        t = np.where(span > 0, (azq - az_ext[lo]) / np.where(span > 0, span, 1.0), 0.0)
        block = vals_all[k]  # (azimuth, first)
        v_lo = _rows_interp(grid.first, block, ext_idx[lo], first)
        v_hi = _rows_interp(grid.first, block, ext_idx[hi], first)
        return ((1.0 - t) * v_lo + t * v_hi).reshape(shape)

    return fn


def vendor_bsdf_fn(path: str | Path) -> tuple[dict[str, BsdfFn], NDArray[np.float64], float | None, str]:
    """BSDF callables per side that interpolate a vendor table on its own grid, the file's incidences [deg],
    its wavelength [nm] (or None) and its format."""
    vendor = _read_vendor(path)
    fns = {g.side: _grid_fn(g) for g in vendor.grids}
    theta = vendor.grids[0].theta_i
    for g in vendor.grids[1:]:
        if g.theta_i.shape != theta.shape or np.any(np.abs(g.theta_i - theta) > _MATCH_DEG):
            raise FormatError("the sides of the file have different incidences", file=path, field="theta_i")
    return fns, theta, vendor.wavelength_nm, vendor.format


# ------------------------------------------------------------------------------------------- ingest
def ingest(path: str | Path, **options: Any) -> xr.Dataset:
    """Any measurement into the calibrated BSDF dataset: a raw export folder (read + calibrate), a text table
    (:func:`bsdfkit.measurement.table.read_table`), a vendor file (:func:`vendor_dataset`) or a bsdfkit
    netCDF dataset. ``options`` (:data:`TABLE_OPTIONS`) apply to tables and vendor files only."""
    kind = source_kind(path)
    given = {k: v for k, v in options.items() if v is not None}
    unknown = [k for k in given if k not in TABLE_OPTIONS]
    if unknown:
        raise InputError("unknown ingest option", field=", ".join(unknown), expected=", ".join(TABLE_OPTIONS))
    if kind in ("raw-scan", "netcdf") and given:
        raise InputError(f"options apply to text tables and vendor files, not to a {kind}", file=path,
                         field=", ".join(f"--{k.replace('_', '-')}" for k in given), expected="no options")
    if kind == "raw-scan":
        return calibrate(read_scan(path))
    if kind == "netcdf":
        return netcdf.load(path, quantity="bsdf")
    if kind in VENDOR_FORMATS:
        bad = [k for k in given if k in ("incidence", "phi_i")]
        if bad:
            raise InputError("vendor files state their incidences", file=path, field=", ".join(bad),
                             expected="no --incidence/--phi-i")
        return vendor_dataset(path, **given)
    return read_table(path, **given)


# ------------------------------------------------------------------------------------------- convert
@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert` wrote and how the TIS of the written table compares with the source's.

    ``tis_original`` maps side → TIS per incidence of the source (vendor file: recomputed from the original
    with its format's quadrature; dataset: direct integral of the exported reconstruction); ``tis_written``
    the same for the re-read output. ``worst_relative_difference`` is the largest |written/original − 1|
    over sides and incidences with a TIS above 1e-12.
    """

    source: str
    source_kind: str
    export: ExportResult
    incidences_deg: tuple[float, ...]
    tis_original: dict[str, list[float]]
    tis_written: dict[str, list[float]]
    worst_relative_difference: float
    tolerance: float
    wavelength_nm: float | None
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.worst_relative_difference <= self.tolerance

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "source_kind": self.source_kind, "format": self.export.format,
                "path": self.export.path, "sides": list(self.export.sides),
                "incidences_deg": list(self.incidences_deg), "tis_original": self.tis_original,
                "tis_written": self.tis_written, "tis_reference_of_callable": self.export.tis_source,
                "worst_relative_difference": self.worst_relative_difference, "tolerance": self.tolerance,
                "ok": self.ok, "wavelength_nm": self.wavelength_nm, "notes": list(self.notes)}


def _dispatch(fns: dict[str, BsdfFn]) -> BsdfFn:
    def fn(theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        if side not in fns:
            raise ValidationError("the source holds no data for this side", field="side",
                                  expected=" or ".join(fns), got=side)
        return np.asarray(fns[side](theta_i_deg, side, directions), dtype=np.float64)

    return fn


def _written_tis(path: str | Path, fmt: str, sides: Sequence[str]) -> tuple[list[float], dict[str, list[float]]]:
    summary = read_any(path)
    out = {}
    for side in sides:
        if side not in summary.tis_computed:
            raise NumericalError("the re-read table has no TIS for this side", file=path, field=side,
                                 expected=", ".join(summary.tis_computed))
        out[side] = [float(v) for v in summary.tis_computed[side]]
    return [float(t) for t in summary.incidences_deg], out


def convert(source: str | Path | xr.Dataset, to: str, path: str | Path, force: bool = False, *,
            side: str | None = None, wavelength: float | None = None, band: tuple[float, float] | None = None,
            interaction: str | None = None, theta_i_deg: Sequence[float] | None = None,
            settings: ExportSettings | None = None, tolerance: float = 0.01,
            **table_options: Any) -> ConvertResult:
    """Write any readable source as a ``to`` (tracepro | zemax | asap) table and check its TIS.

    Parameters
    ----------
    source
        A vendor file (converted on its own grid), a text table or raw export (ingested first; table options
        such as ``quantity``, ``side``, ``relative_std`` go to :func:`ingest`), a netCDF dataset or a Dataset.
    to, path, force
        Target format and file; an existing file is replaced only with ``force``.
    side
        ``reflection`` | ``transmission`` | ``both`` (default: every side of the source; Zemax holds one).
    wavelength, band
        For spectral datasets: the wavelength [nm] to write, or a (low, high) band whose wavelengths are
        averaged; a monochrome table without wavelength takes ``wavelength`` as its label.
    interaction
        For calibrated raw scans (configurations blue/yellow): bibs, biys or yiys, reconstructed by
        :func:`bsdfkit.reduction.tis.hemisphere_bsdf_fn`.
    theta_i_deg
        Incidences to write [deg] (default: all of the source).
    settings
        Further :class:`bsdfkit.tables.export.ExportSettings` (axes, Zemax symmetry, TracePro options).
    tolerance
        Largest accepted |TIS written / TIS original − 1| (reported in the result; default 0.01).

    Returns
    -------
    ConvertResult
    """
    if to not in FORMATS:
        raise ValidationError("unknown target format", field="--to", expected=" | ".join(FORMATS), got=to)
    if side is not None and side not in ("reflection", "transmission", "both"):
        raise ValidationError("unknown side", field="--side", expected="reflection | transmission | both", got=side)
    atomic.check_writable(path, force, inputs=[source] if isinstance(source, (str, Path)) else ())
    settings = settings or ExportSettings()
    notes: list[str] = []
    tis_original: dict[str, list[float]] = {}
    engine_tis: dict[str, list[float]] | None = None
    src_t: dict[str, list[float]] = {}
    label = "dataset" if isinstance(source, xr.Dataset) else str(source)
    kind = "dataset" if isinstance(source, xr.Dataset) else source_kind(source)
    chosen_lambda: float | None = None
    if kind in VENDOR_FORMATS:
        extra = {k: v for k, v in table_options.items() if v is not None}
        if extra or band is not None or interaction is not None:
            raise InputError("options apply to datasets and text tables, not to a vendor file", file=label,
                             field=", ".join([*extra, *(["band"] if band else []),
                                              *(["interaction"] if interaction else [])]))
        fns, thetas_all, chosen_lambda, _ = vendor_bsdf_fn(source)
        if wavelength is not None:
            if chosen_lambda is not None and abs(chosen_lambda - wavelength) > 1e-6:
                raise InputError("the file states another wavelength", file=label, field="--wavelength",
                                 expected=f"{chosen_lambda:g} nm", got=wavelength)
            chosen_lambda = float(wavelength)
        summary = read_any(source)
        for s in fns:
            key = s if s in summary.tis_computed else next(k for k in summary.tis_computed if k.startswith(s))
            tis_original[s] = [float(v) for v in summary.tis_computed[key]]
        thetas = [float(t) for t in thetas_all]
    else:
        if isinstance(source, xr.Dataset):
            ds = source
        else:
            opts = {k: v for k, v in table_options.items() if v is not None}
            if kind == "table" and "side" not in opts and side in ("reflection", "transmission"):
                opts["side"] = side
            ds = ingest(source, **opts)
        sides_ds = [s for s in ("reflection", "transmission") if s in set(map(str, ds["side"].values))]
        use_sides = sides_ds if side in (None, "both") else [side]
        for s in use_sides:
            if s not in sides_ds:
                raise InputError("the source holds no data for this side", file=label, field="--side",
                                 expected=" or ".join(sides_ds), got=s)
        fns = {}
        theta_sets = []
        if reduction_kind(ds) == "hemispherical":
            if interaction is not None:
                raise InputError("--interaction applies to calibrated phosphor scans with blue/yellow "
                                 "configurations", file=label, field="--interaction", got=interaction)
            if ds.sizes.get("wavelength", 0) == 1 and not np.isfinite(ds["wavelength"].values[0]) \
                    and wavelength is not None:
                ds = ds.assign_coords(wavelength=[float(wavelength)])
            src = elastic_source(ds, use_sides, wavelength, band)
            chosen_lambda = src.wavelength_nm
            for s in use_sides:
                fns[s] = src.fn
                theta_sets.append(set(np.round(src.incidences_deg[s], 9)))
            engine_tis, src_t = src.tis, src.incidences_deg
            notes.insert(0, f"values at {src.what}; reconstructed by the hemispherical engine "
                            "(bsdfkit.reduction.hemispherical: " + ", ".join(sorted(set(
                                m for ms in src.methods.values() for m in ms))) + ")")
        else:
            if interaction is None:
                raise InputError("a calibrated scan holds several interactions; choose one", file=label,
                                 field="--interaction", expected="bibs, biys or yiys")
            for s in use_sides:
                fns[s] = hemisphere_bsdf_fn(ds, interaction, s)
                theta_sets.append(set(np.round(fns[s].incidences_deg, 9)))  # type: ignore[attr-defined]
            notes.append(f"interaction {interaction}, reconstructed by bsdfkit.reduction.tis.hemisphere_bsdf_fn")
        common = sorted(set.intersection(*theta_sets))
        if not common:
            raise InputError("the sides share no incidence", file=label, field="theta_i",
                             expected="a common incidence, or --side")
        thetas = [float(t) for t in common]
    sides = list(fns) if side in (None, "both") else [side]
    for s in sides:
        if s not in fns:
            raise InputError("the source holds no data for this side", file=label, field="--side",
                             expected=" or ".join(fns), got=s)
    if to == "zemax" and len(sides) > 1:
        raise InputError("a Zemax file holds one side; the source has both", file=label, field="--side",
                         expected="--side reflection or --side transmission", got="both")
    if theta_i_deg is not None:
        wanted = [float(t) for t in theta_i_deg]
        missing = [t for t in wanted if not any(abs(t - u) <= _MATCH_DEG for u in thetas)]
        if missing:
            raise InputError("incidence not in the source", file=label, field="--incidences",
                             expected="some of " + ", ".join(f"{t:g}" for t in thetas), got=missing[0])
        thetas = sorted(wanted)
    tp = settings.tracepro
    if chosen_lambda is not None and np.isfinite(chosen_lambda) and to == "tracepro":
        tp = replace(tp, wavelength_um=float(chosen_lambda) / 1000.0)
    elif to == "tracepro":
        notes.append(f"wavelength unknown: TracePro Wavelength column set to {tp.wavelength_um:g} um")
    settings = replace(settings, theta_i_deg=tuple(thetas), tracepro=tp,
                       comments=tuple(settings.comments) + (f"converted by bsdfkit from {Path(label).name}",))
    result = export(_dispatch({s: fns[s] for s in sides}), to, "", "both" if len(sides) > 1 else sides[0], path,
                    force, settings=settings)
    if engine_tis is not None:  # a dataset: what bsdfkit tis reports for it, at the written wavelength
        tis_original = {s: [engine_tis[s][[round(u, 6) for u in src_t[s]].index(round(t, 6))] for t in thetas]
                        for s in sides}
    elif not tis_original:
        tis_original = {s: list(result.tis_source[s]) for s in sides}
    else:
        keep = [k for k, t in enumerate(thetas_all) if any(abs(t - u) <= _MATCH_DEG for u in thetas)]
        tis_original = {s: [tis_original[s][k] for k in keep] for s in sides}
    read_thetas, tis_written = _written_tis(path, to, sides)
    worst = 0.0
    for s in sides:
        for k, t in enumerate(thetas):
            j = int(np.argmin(np.abs(np.asarray(read_thetas) - t)))
            a, b = tis_original[s][k], tis_written[s][j]
            if abs(a) > 1e-12:
                worst = max(worst, abs(b / a - 1.0))
            elif abs(b) > 1e-9:
                worst = max(worst, float("inf"))
    return ConvertResult(source=label, source_kind=kind, export=result, incidences_deg=tuple(thetas),
                         tis_original=tis_original, tis_written=tis_written, worst_relative_difference=worst,
                         tolerance=float(tolerance), wavelength_nm=chosen_lambda, notes=tuple(notes))
