"""Zemax OpticStudio tabular BSDF files (``*.bsdf``, "BSDF Data Interchange"), Monochrome.

Layout ([Zemax-BSDF] in docs/references.md; docs/exports.md §2.2): keyword lines ``Source``, ``Symmetry``,
``SpectralContent``, ``ScatterType``, then ``SampleRotation n`` / ``AngleOfIncidence n`` / ``ScatterAzimuth n`` /
``ScatterRadial n`` each followed by a line of n angles (degrees), a blank line, the spectral indicator
``Monochrome``, ``DataBegin``, then for each SampleRotation and each AngleOfIncidence one block — a line
``TIS t`` and one row per ScatterAzimuth holding the ScatterRadial values — and ``DataEnd``.

Conventions ([Zemax-BSDF]; docs/exports.md §2.2, §4):

* AngleOfIncidence is the specular (BRDF) or direct-transmission (BTDF) angle; for a plate in air it
  equals θi. ScatterRadial/ScatterAzimuth are spherical coordinates about that direction; azimuth 0
  points from it toward the surface normal, counter-clockwise (:func:`bsdfkit.core.frames.specular_from_direction`).
* PlaneSymmetrical tables give azimuths 0…180° and stand for their mirror images 360° − φ;
  Asymmetrical tables give the full circle (the handedness of asymmetric data is open question 2 of
  docs/exports.md §5; bsdfkit uses the right-handed specular frame of Ansys' converter, [Ansys-OA]).
* Values are BSDF in 1/sr, not cosine-weighted. ``TIS`` = ∫ BSDF cos θs dΩ of the block. The writer
  computes it from the written (rounded) table with :func:`bsdfkit.tables.grids.tis_specular_table`, the
  integral the reader uses, so stated and recomputed TIS agree to the printed digits.

The reader is lenient where vendor files vary: keywords are case-insensitive (``ASymmetrical`` is
accepted), ``#`` starts a comment anywhere on a line, fields are separated by any mix of tabs and spaces,
trailing tabs are ignored. It is strict about counts: every list and every data row must hold exactly
the announced number of values; errors name file, line and field. XYZ files and several spectral
channels are not supported (FormatError).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.core.lazy import LazyModule
from bsdfkit.core.version import __version__
from bsdfkit.io import atomic
from bsdfkit.io.text import is_float, read_text
from bsdfkit.tables import axes_choice, grids
from bsdfkit.tables.format_spec import FileSummary, TableFormat, VendorGrid, VendorTable, WriteJob, WriteOutcome
from bsdfkit.tables.formats.lighttools import is_lighttools_header

#: xarray on first use: the verbs read this module's registration (format names) and must stay light
xr = LazyModule("xarray")

__all__ = ["SYMMETRIES", "ZemaxBsdf", "read_zemax", "write_zemax", "zemax_bsdf", "zemax_text"]

SYMMETRIES: tuple[str, ...] = ("PlaneSymmetrical", "Asymmetrical", "Asymmetrical4D")
_SYMMETRY_BY_LOWER = {s.lower(): s for s in SYMMETRIES}
_SCATTER_TYPES = {"brdf": "BRDF", "btdf": "BTDF"}
_SIDE_OF = {"BRDF": "reflection", "BTDF": "transmission"}
_TYPE_OF = {v: k for k, v in _SIDE_OF.items()}
_LISTS = ("samplerotation", "angleofincidence", "scatterazimuth", "scatterradial")
_LIST_NAMES = {"samplerotation": "SampleRotation", "angleofincidence": "AngleOfIncidence",
               "scatterazimuth": "ScatterAzimuth", "scatterradial": "ScatterRadial"}
_VALUE_FMT = ".6E"
_TIS_FMT = ".7g"


@dataclass(frozen=True, eq=False)
class ZemaxBsdf:
    """One Zemax tabular BSDF, as written or as read.

    ``table`` has dims ``(sample_rotation, theta_i, azimuth, radial)`` (degrees; file order),
    ``tis_stated`` dims ``(sample_rotation, theta_i)``.
    """

    scatter_type: str
    symmetry: str
    table: xr.DataArray
    tis_stated: xr.DataArray
    source: str = "Measured"
    comments: tuple[str, ...] = ()
    path: str | None = field(default=None)

    @property
    def side(self) -> str:
        """``reflection`` for BRDF, ``transmission`` for BTDF."""
        return _SIDE_OF[self.scatter_type]

    @property
    def plane_symmetric(self) -> bool:
        return self.symmetry == "PlaneSymmetrical"

    def tis_computed(self) -> xr.DataArray:
        """TIS per sample rotation and incidence recomputed from the table (:func:`grids.tis_specular_table`)."""
        t = self.table
        tis = grids.tis_specular_table(t.values, t["radial"].values, t["azimuth"].values, t["theta_i"].values,
                                       self.plane_symmetric)
        return xr.DataArray(tis, dims=("sample_rotation", "theta_i"),
                            coords={"sample_rotation": t["sample_rotation"].values, "theta_i": t["theta_i"].values})


# --------------------------------------------------------------------------------------------------
# building and writing
# --------------------------------------------------------------------------------------------------
def zemax_bsdf(
    grid: xr.DataArray, *, symmetry: str = "PlaneSymmetrical", comments: Sequence[str] = ()
) -> ZemaxBsdf:
    """A Monochrome Zemax BSDF from one side of :func:`bsdfkit.tables.grids.specular_grid`.

    ``grid`` has dims ``(side, theta_i, azimuth, radial)`` with a single side. Values are rounded to
    the written precision and the TIS of each block is computed from the rounded table. For
    ``PlaneSymmetrical`` the azimuths must lie in [0, 180]; checking that the source really is plane
    symmetric is the caller's job (:func:`bsdfkit.tables.export.export` does it).

    Parameters
    ----------
    grid : xarray.DataArray
        BSDF [1/sr] on dims (side, theta_i [deg], azimuth [deg], radial [deg]).
    symmetry : str
        ``PlaneSymmetrical`` or ``Asymmetrical``.
    comments : sequence of str
        Single-line comments.

    Returns
    -------
    ZemaxBsdf
        The table as written, with its stated TIS [-].
    """
    if tuple(grid.dims) != ("side", "theta_i", "azimuth", "radial") or grid.sizes["side"] != 1:
        raise ValidationError("grid must have dims (side, theta_i, azimuth, radial) with one side",
                              field="grid", got=f"{grid.dims} {dict(grid.sizes)}")
    if symmetry not in ("PlaneSymmetrical", "Asymmetrical"):
        raise ValidationError("unsupported symmetry for writing", field="symmetry",
                              expected="PlaneSymmetrical or Asymmetrical", got=symmetry)
    azimuth = np.asarray(grid["azimuth"].values, dtype=np.float64)
    if symmetry == "PlaneSymmetrical" and (azimuth.min() < 0 or azimuth.max() > 180):
        raise ValidationError("PlaneSymmetrical tables hold azimuths 0..180 deg", field="azimuth",
                              got=[float(azimuth.min()), float(azimuth.max())])
    for text in comments:
        if "\n" in text or "\r" in text:
            raise ValidationError("comments must be single lines", field="comments", got=text)
    side = str(grid["side"].values[0])
    values = grids.quantize(grid.values[0], _VALUE_FMT)[None]
    theta = np.asarray(grid["theta_i"].values, dtype=np.float64)
    radial = grids.quantize(grid["radial"].values, grids.ANGLE_FORMAT)
    azimuth = grids.quantize(azimuth, grids.ANGLE_FORMAT)
    table = xr.DataArray(values, dims=("sample_rotation", "theta_i", "azimuth", "radial"),
                         coords={"sample_rotation": [0.0], "theta_i": theta, "azimuth": azimuth, "radial": radial},
                         name="bsdf", attrs={"units": "1/sr", "frame": "specular"})
    tis = grids.tis_specular_table(values, radial, azimuth, theta, symmetry == "PlaneSymmetrical")
    tis_da = xr.DataArray(grids.quantize(tis, _TIS_FMT), dims=("sample_rotation", "theta_i"),
                          coords={"sample_rotation": [0.0], "theta_i": theta})
    return ZemaxBsdf(scatter_type=_TYPE_OF[side], symmetry=symmetry, table=table, tis_stated=tis_da,
                     comments=tuple(comments))


def _join(values: Sequence[float], fmt: str) -> str:
    return "\t".join(format(float(v), fmt) for v in values)


def zemax_text(bsdf: ZemaxBsdf, generated_at: datetime | None = None) -> str:
    """The file text. Line 2 is the only line that changes between runs (bsdfkit version and time).

    Parameters
    ----------
    bsdf : ZemaxBsdf
        The table.
    generated_at : datetime, optional
        Time stated on line 2 (default: now).

    Returns
    -------
    str
        The file text.
    """
    when = generated_at or datetime.now()
    t = bsdf.table
    lines = ["# Data generated by bsdfkit (Zemax tabular BSDF, docs/exports.md section 2.2)",
             f"# bsdfkit {__version__} {when:%Y-%m-%dT%H:%M:%S}"]
    lines += [f"# {c}" for c in bsdf.comments]
    lines += [
        f"Source  {bsdf.source}",
        f"Symmetry  {bsdf.symmetry}",
        "SpectralContent  Monochrome",
        f"ScatterType  {bsdf.scatter_type}",
        f"SampleRotation  {t.sizes['sample_rotation']}",
        _join(t["sample_rotation"].values, grids.ANGLE_FORMAT),
        f"AngleOfIncidence  {t.sizes['theta_i']}",
        _join(t["theta_i"].values, grids.ANGLE_FORMAT),
        f"ScatterAzimuth  {t.sizes['azimuth']}",
        _join(t["azimuth"].values, grids.ANGLE_FORMAT),
        f"ScatterRadial  {t.sizes['radial']}",
        _join(t["radial"].values, grids.ANGLE_FORMAT),
        "",
        "Monochrome",
        "DataBegin",
    ]
    values = t.values
    for r in range(t.sizes["sample_rotation"]):
        for i in range(t.sizes["theta_i"]):
            lines.append(f"TIS {format(float(bsdf.tis_stated.values[r, i]), _TIS_FMT)}")
            lines.extend(_join(row, _VALUE_FMT) for row in values[r, i])
    lines.append("DataEnd")
    return "\n".join(lines) + "\n"


def write_zemax(
    path: str | Path, bsdf: ZemaxBsdf, *, force: bool = False, generated_at: datetime | None = None
) -> Path:
    """Write ``bsdf`` atomically (LF line ends, tab-separated values); refuses to overwrite unless ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    bsdf : ZemaxBsdf
        The table.
    force : bool
        Replace an existing file.
    generated_at : datetime, optional
        Time stated on line 2 (default: now).

    Returns
    -------
    Path
        The file written.
    """
    atomic.check_writable(path, force)
    return atomic.write_text(path, zemax_text(bsdf, generated_at), force=force)


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------
def _entries(text: str) -> list[tuple[int, list[str]]]:
    """(line number, tokens) of every non-empty line, ``#`` comments removed."""
    out = []
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if body:
            out.append((number, body.split()))
    return out


def _floats(tokens: list[str], path: str, line: int, name: str) -> NDArray[np.float64]:
    try:
        arr = np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not is_float(t))
        raise FormatError("not a number", file=path, line=line, field=name, expected="numbers", got=bad) from None
    if not np.all(np.isfinite(arr)):
        raise FormatError("not a finite number", file=path, line=line, field=name, expected="finite numbers",
                          got=tokens[int(np.argmax(~np.isfinite(arr)))])
    return arr


def _check_axis(values: NDArray, name: str, lo: float, hi: float, hi_open: bool, path: str, line: int) -> None:
    if np.any(np.diff(values) <= 0):
        raise FormatError("angles must be strictly increasing", file=path, line=line, field=name,
                          expected="increasing angles", got=values.tolist()[:12])
    top_bad = values.max() >= hi if hi_open else values.max() > hi
    if values.min() < lo or top_bad:
        raise FormatError("angle out of range", file=path, line=line, field=name,
                          expected=f"{lo:g} <= angle {'<' if hi_open else '<='} {hi:g} deg",
                          got=[float(values.min()), float(values.max())])


def read_zemax(path: str | Path) -> ZemaxBsdf:
    """Read a Monochrome Zemax tabular BSDF file (any of the three symmetries).

    Parameters
    ----------
    path : str or Path
        The Zemax ``.bsdf`` file.

    Returns
    -------
    ZemaxBsdf
        The table (BSDF [1/sr], angles [deg]) and stated TIS [-].
    """
    path = str(path)
    text = read_text(path, expected="a Zemax tabular BSDF file", legacy="latin-1")
    comments = tuple(line.strip()[1:].strip() for line in text.splitlines() if line.strip().startswith("#"))
    entries = _entries(text)
    last_line = text.count("\n") + (0 if text.endswith("\n") else 1)
    header, header_lines, k = _read_header(entries, path, last_line)
    symmetry = str(header["symmetry"])
    rotation = np.asarray(header["samplerotation"])
    theta = np.asarray(header["angleofincidence"])
    azimuth = np.asarray(header["scatterazimuth"])
    radial = np.asarray(header["scatterradial"])
    if rotation.size != 1 and symmetry != "Asymmetrical4D":
        raise FormatError("several sample rotations need Symmetry Asymmetrical4D", file=path,
                          line=header_lines["samplerotation"], field="SampleRotation", expected="1",
                          got=rotation.size)
    _check_axis(theta, "AngleOfIncidence", 0.0, 90.0, True, path, header_lines["angleofincidence@list"])
    az_hi = 180.0 if symmetry == "PlaneSymmetrical" else 360.0
    _check_axis(azimuth, "ScatterAzimuth", 0.0, az_hi, False, path, header_lines["scatterazimuth@list"])
    _check_axis(radial, "ScatterRadial", 0.0, 180.0, False, path, header_lines["scatterradial@list"])
    data, tis, k = _read_blocks(entries, k + 1, (rotation, theta, azimuth, radial), path, last_line)
    if k >= len(entries):
        raise FormatError("missing DataEnd", file=path, line=last_line, field="DataEnd", expected="'DataEnd'",
                          got="end of file")
    number, tokens = entries[k]
    if tokens[0].lower() != "dataend":
        raise FormatError("more data than announced, or missing DataEnd", file=path, line=number, field="DataEnd",
                          expected="'DataEnd'", got=" ".join(tokens)[:60])
    if k + 1 < len(entries):
        number, tokens = entries[k + 1]
        raise FormatError("unexpected content after DataEnd", file=path, line=number, field="DataEnd",
                          expected="end of file", got=" ".join(tokens)[:60])
    coords = {"sample_rotation": rotation, "theta_i": theta}
    table = xr.DataArray(data, dims=("sample_rotation", "theta_i", "azimuth", "radial"),
                         coords={**coords, "azimuth": azimuth, "radial": radial}, name="bsdf",
                         attrs={"units": "1/sr", "frame": "specular"})
    return ZemaxBsdf(
        scatter_type=str(header["scattertype"]), symmetry=symmetry, table=table,
        tis_stated=xr.DataArray(tis, dims=("sample_rotation", "theta_i"), coords=coords),
        source=str(header["source"]), comments=comments, path=path,
    )


def _read_header(entries: list[tuple[int, list[str]]], path: str,
                 last_line: int) -> tuple[dict[str, object], dict[str, int], int]:
    """The keywords before DataBegin: values by lower-case keyword, the line of each (lists: ``key@list`` too)
    and the index of the DataBegin entry; every required keyword checked present."""
    header: dict[str, object] = {}
    header_lines: dict[str, int] = {}
    k = 0
    while True:
        if k >= len(entries):
            raise FormatError("file ends before DataBegin", file=path, line=last_line, field="DataBegin",
                              expected="'DataBegin'", got="end of file")
        number, tokens = entries[k]
        key = tokens[0].lower()
        if key == "databegin":
            break
        if key in header_lines:
            raise FormatError("keyword given twice", file=path, line=number, field=tokens[0],
                              expected="each keyword once", got=f"also on line {header_lines[key]}")
        header_lines[key] = number
        if key in ("source", "symmetry", "spectralcontent", "scattertype"):
            header[key] = _header_value(key, tokens, path, number)
            k += 1
        elif key in _LISTS:
            name = _LIST_NAMES[key]
            if len(tokens) != 2 or not tokens[1].isdigit() or int(tokens[1]) < 1:
                raise FormatError("list keyword needs a positive count", file=path, line=number, field=name,
                                  expected=f"'{name} <n>' with n >= 1", got=" ".join(tokens))
            count = int(tokens[1])
            if k + 1 >= len(entries):
                raise FormatError("file ends before the list of angles", file=path, line=last_line, field=name,
                                  expected=f"{count} angles", got="end of file")
            list_line, list_tokens = entries[k + 1]
            if len(list_tokens) != count:
                raise FormatError("wrong number of angles", file=path, line=list_line, field=name,
                                  expected=f"{count} values", got=len(list_tokens))
            header[key] = _floats(list_tokens, path, list_line, name)
            header_lines[key + "@list"] = list_line
            k += 2
        elif key == "monochrome":
            header["indicator"] = "Monochrome"
            k += 1
        elif key.startswith("tristimulus"):
            raise FormatError("XYZ data are not supported", file=path, line=number, field="spectral indicator",
                              expected="Monochrome", got=tokens[0])
        else:
            raise FormatError("unknown keyword", file=path, line=number, field="keyword",
                              expected="Source, Symmetry, SpectralContent, ScatterType, SampleRotation, "
                                       "AngleOfIncidence, ScatterAzimuth, ScatterRadial, Monochrome or DataBegin",
                              got=tokens[0])
    required = {"source": "Source", "symmetry": "Symmetry", "spectralcontent": "SpectralContent",
                "scattertype": "ScatterType",
                **_LIST_NAMES, "indicator": "Monochrome"}
    for key, name in required.items():
        if key not in header:
            raise FormatError("missing keyword", file=path, line=entries[k][0], field=name,
                              expected=f"'{name}' before DataBegin", got="DataBegin")
    return header, header_lines, k


def _header_value(key: str, tokens: list[str], path: str, number: int) -> str:
    """The value of a one-value keyword (Source, Symmetry, SpectralContent, ScatterType), in its canonical
    spelling."""
    if len(tokens) != 2:
        raise FormatError("keyword needs one value", file=path, line=number, field=tokens[0],
                          expected=f"'{tokens[0]} <value>'", got=" ".join(tokens))
    value = tokens[1]
    if key == "symmetry":
        if value.lower() not in _SYMMETRY_BY_LOWER:
            raise FormatError("unknown symmetry", file=path, line=number, field="Symmetry",
                              expected=" or ".join(SYMMETRIES), got=value)
        return _SYMMETRY_BY_LOWER[value.lower()]
    if key == "spectralcontent":
        if value.lower() != "monochrome":
            raise FormatError("spectral content not supported", file=path, line=number,
                              field="SpectralContent", expected="Monochrome", got=value)
        return "Monochrome"
    if key == "scattertype":
        if value.lower() not in _SCATTER_TYPES:
            raise FormatError("unknown scatter type", file=path, line=number, field="ScatterType",
                              expected="BRDF or BTDF", got=value)
        return _SCATTER_TYPES[value.lower()]
    return value


def _read_blocks(entries: list[tuple[int, list[str]]], k: int, axes: tuple[NDArray, ...], path: str,
                 last_line: int) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The data blocks from entry ``k`` on (one per sample rotation and incidence of ``axes`` = (rotation,
    incidence, azimuth, radial)): the BSDF table, the stated TIS and the index of the entry after the last block."""
    rotation, theta, azimuth, radial = axes
    data = np.zeros((rotation.size, theta.size, azimuth.size, radial.size))
    tis = np.zeros((rotation.size, theta.size))
    for r in range(rotation.size):
        for i in range(theta.size):
            where = f"block SampleRotation {rotation[r]:g}, AngleOfIncidence {theta[i]:g}"
            if k >= len(entries):
                raise FormatError(f"file ends before {where}", file=path, line=last_line, field="TIS",
                                  expected="'TIS <value>'", got="end of file")
            number, tokens = entries[k]
            if tokens[0].lower() != "tis" or len(tokens) != 2:
                raise FormatError(f"missing TIS line of {where}", file=path, line=number, field="TIS",
                                  expected="'TIS <value>'", got=" ".join(tokens)[:60])
            tis[r, i] = _floats(tokens[1:], path, number, "TIS")[0]
            for a in range(azimuth.size):
                k += 1
                name = f"ScatterAzimuth {azimuth[a]:g} row of {where}"
                if k >= len(entries):
                    raise FormatError("file ends inside a data block", file=path, line=last_line, field=name,
                                      expected=f"{radial.size} values", got="end of file")
                number, tokens = entries[k]
                if len(tokens) != radial.size:
                    raise FormatError("wrong number of values in a data row", file=path, line=number, field=name,
                                      expected=f"{radial.size} values (ScatterRadial count)", got=len(tokens))
                row = _floats(tokens, path, number, name)
                if np.any(row < 0):
                    raise FormatError("negative BSDF", file=path, line=number, field=name, expected=">= 0",
                                      got=float(row.min()))
                data[r, i, a] = row
            k += 1
    return data, tis, k


# ------------------------------------------------------------------------------------------- registry hooks
def _as_floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]


def _write_job(job: WriteJob) -> WriteOutcome:
    """One ScatterType per file; PlaneSymmetrical writes the mirror average of the source (refused when the
    source deviates from plane symmetry by more than ``settings.symmetry_tolerance``)."""
    settings = job.settings
    if settings.zemax_symmetry == "auto":  # the source's own symmetry: PlaneSymmetrical when it has it
        try:
            return _write_job(replace(job, settings=replace(settings, zemax_symmetry="PlaneSymmetrical")))
        except ValidationError as exc:
            if exc.field != "zemax_symmetry":
                raise
        outcome = _write_job(replace(job, settings=replace(settings, zemax_symmetry="Asymmetrical")))
        outcome.grid["symmetry"] = (f"Asymmetrical (the source deviates from plane symmetry by more than "
                                    f"{settings.symmetry_tolerance:g} of the block maximum)")
        return outcome
    axes, info = axes_choice.specular_axes(job.fn, job.theta, job.sides, settings)
    deviation = None
    if settings.zemax_symmetry == "PlaneSymmetrical":
        grid, deviation = axes_choice.plane_symmetric_grid(job.fn, job.theta, job.side, axes,
                                                           settings.symmetry_tolerance)
    else:
        grid = grids.specular_grid(job.fn, job.theta, job.side, axes)
    bsdf = zemax_bsdf(grid, symmetry=settings.zemax_symmetry, comments=job.comments)
    write_zemax(job.path, bsdf, force=job.force, generated_at=job.generated_at)
    return WriteOutcome(axes, info, deviation)


def _summarise(path: str) -> FileSummary:
    return _summary(read_zemax(path), path)


def _summary(bsdf: ZemaxBsdf, path: str) -> FileSummary:
    computed, stated = bsdf.tis_computed(), bsdf.tis_stated
    rotations = _as_floats(bsdf.table["sample_rotation"].values)
    keys = [bsdf.side] if len(rotations) == 1 else [f"{bsdf.side}@rotation={r:g}" for r in rotations]
    return FileSummary(
        format="zemax", path=path, incidences_deg=_as_floats(bsdf.table["theta_i"].values),
        tis_computed={k: _as_floats(computed.values[r]) for r, k in enumerate(keys)},
        tis_stated={k: _as_floats(stated.values[r]) for r, k in enumerate(keys)},
        details={"symmetry": bsdf.symmetry, "scatter_type": bsdf.scatter_type, "source": bsdf.source,
                 "table_shape": dict(bsdf.table.sizes)},
    )


def _vendor_table(path: str) -> VendorTable:
    return _nodes(read_zemax(path), path)


def _summary_and_table(path: str) -> tuple[FileSummary, VendorTable | None]:
    """Summary (with the stated TIS) and nodes from one parse: ``bsdfkit read`` and the stated-TIS check of
    ``ingest`` (:func:`bsdfkit.tables.vendor.check_stated_tis`) need both, and a large file takes a while to parse.
    No nodes (None) for several sample rotations, which :func:`_vendor_table` refuses."""
    z = read_zemax(path)
    return _summary(z, path), (_nodes(z, path) if z.table.sizes["sample_rotation"] == 1 else None)


def _nodes(z: ZemaxBsdf, path: str) -> VendorTable:
    if z.table.sizes["sample_rotation"] != 1:
        raise FormatError("several sample rotations are not supported", file=path, field="SampleRotation",
                          expected="1 sample rotation", got=int(z.table.sizes["sample_rotation"]))
    t = z.table.isel(sample_rotation=0)
    grid = VendorGrid("specular", z.side, np.asarray(t["theta_i"].values, dtype=np.float64),
                      np.asarray(t["radial"].values, dtype=np.float64),
                      np.asarray(t["azimuth"].values, dtype=np.float64), np.asarray(t.values, dtype=np.float64),
                      plane_symmetric=z.plane_symmetric)
    return VendorTable("zemax", (grid,), None, {"symmetry": z.symmetry, "source": z.source,
                                                "scatter_type": z.scatter_type})


def _guess_can_open(head: str, path: Path) -> bool:
    if is_lighttools_header(head):  # the same keywords, but ScatterAzimuth before any Zemax-only one
        return False
    for line in head.splitlines():
        body = line.split("#", 1)[0].strip()
        if body:
            return body.split()[0].lower() in ("source", "symmetry", "spectralcontent", "scattertype")
    return False


FORMAT = TableFormat(name="zemax", title="Zemax BSDF", extensions=(".bsdf",), guess_can_open=_guess_can_open,
                     summarise=_summarise, vendor_table=_vendor_table, write=_write_job, sides_per_file=1,
                     grid_kind="specular", summary_and_table=_summary_and_table)
