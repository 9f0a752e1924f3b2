"""ASAP-style export: a plain, documented BSDF table in Harvey–Shack coordinates plus model parameters.

**No ASAP manual was available** while this was written ([ASAP] in docs/references.md: the syntax of
ASAP's ``HARVEY``, ``BSDDATA``, ``MODELS`` and ``SCATTER MODEL`` commands could not be retrieved). This module
therefore does *not* write an ASAP command deck and claims no compatibility with any ASAP command. It
writes the subset that is safe without the manual (docs/exports.md §2.3): the BSDF tabulated in the Harvey–Shack
direction-cosine coordinates that ASAP, FRED and TracePro share, and — when given — fitted ABg and
Harvey parameters, for a user to transfer into ASAP by hand.

File layout (bsdfkit's own, version 1; every line is one record, fields separated by spaces)::

    # comment lines (the header documents the conventions below)
    tis <R|T> <theta_i_deg> <tis>               one per side and incidence
    abg <R|T> <theta_i_deg> <A> <B> <g>         optional: BSDF = A / (B + rho^g)
    harvey <R|T> <theta_i_deg> <b0> <S> <L>     optional: BSDF = b0 (1 + (rho/L)^2)^(S/2)
    side theta_i_deg rho psi_deg bsdf           column header
    <R|T> <theta_i_deg> <rho> <psi_deg> <bsdf>  one row per side x incidence x rho x psi (psi inner)
    end

rho = |β − β0|, psi = azimuth of β − β0 from the sample +x axis (the plane of incidence, pointing away
from the source), counter-clockwise; β0 = (sin θi, 0) for reflection and for transmission through a
plate in air; BSDF in 1/sr, not cosine-weighted; nodes with |β| > 1 hold 0. ``tis`` is
:func:`bsdfkit.tables.grids.tis_harvey_shack_table` of the written table, the same integral the reader uses.
The Harvey form is the "modified three-term Harvey model" as FRED parameterises it ([FRED]; the written
formula is inferred); ABg ↔ Harvey: g = −S, B = L^g, A = b0·L^g (docs/fitting.md §5, exact for g = 2).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.core.frames import SIDES
from bsdfkit.core.lazy import LazyModule
from bsdfkit.core.version import __version__
from bsdfkit.io import atomic
from bsdfkit.io.text import read_text
from bsdfkit.tables import axes_choice, grids
from bsdfkit.tables.format_spec import (
    FileSummary,
    TableFormat,
    VendorGrid,
    VendorTable,
    WriteJob,
    WriteOutcome,
    first_line_is,
)

#: xarray on first use: the verbs read this module's registration (format names) and must stay light
xr = LazyModule("xarray")

__all__ = ["MAGIC", "AbgParameters", "AsapTable", "HarveyParameters", "asap_table", "asap_text", "read_asap",
           "write_asap"]

MAGIC = "# bsdfkit ASAP-style Harvey-Shack BSDF table, version 1"
_CODE = {"reflection": "R", "transmission": "T"}
_SIDE = {v: k for k, v in _CODE.items()}
_VALUE_FMT = ".7g"
_DOC = """\
# NO ASAP MANUAL WAS AVAILABLE to bsdfkit. This is NOT an ASAP command deck: the syntax of ASAP's
# HARVEY, BSDDATA, MODELS and SCATTER MODEL commands could not be obtained. It is a plain table in the
# Harvey-Shack coordinates shared by ASAP, FRED and TracePro, for manual transfer; it claims no more.
# Frame: z = surface normal on the scattering side; x = plane of incidence, pointing away from the source.
# beta = (sin(ts) cos(ps), sin(ts) sin(ps)); beta0 = (sin(theta_i), 0) for R and for T (plate in air).
# rho = |beta - beta0|; psi_deg = azimuth of beta - beta0 from +x, counter-clockwise (degrees).
# bsdf = BSDF in 1/sr (not cosine weighted); rows with |beta| > 1 are not directions and hold 0.
# tis <side> <theta_i_deg> <value>: integral of the table over |beta| <= 1 (projected solid angle),
#   per-row piecewise-linear in rho up to the unit circle, trapezoid in psi (bsdfkit.tables.grids).
# abg <side> <theta_i_deg> <A> <B> <g>: BSDF = A / (B + rho^g).
# harvey <side> <theta_i_deg> <b0> <S> <L>: BSDF = b0 * (1 + (rho/L)^2)^(S/2) (FRED's form; inferred).
# side: R = reflection (BRDF), T = transmission (BTDF)."""


@dataclass(frozen=True)
class AbgParameters:
    """ABg parameters of one side and incidence: BSDF = A/(B + |β − β0|^g) ([TracePro-UM]; docs/fitting.md §5)."""

    side: str
    theta_i_deg: float
    a: float
    b: float
    g: float

    def __post_init__(self) -> None:
        _check_param_side(self.side)
        if not all(np.isfinite([self.theta_i_deg, self.a, self.b, self.g])) or self.a < 0 or self.b < 0 or (
            self.b == 0 and self.g != 0
        ):
            raise ValidationError("ABg parameters need finite A >= 0 and B > 0 (B >= 0 when g = 0)",
                                  field="abg", got=(self.a, self.b, self.g))


@dataclass(frozen=True)
class HarveyParameters:
    """Harvey parameters of one side and incidence: BSDF = b0 (1 + (ρ/L)²)^(S/2) ([FRED])."""

    side: str
    theta_i_deg: float
    b0: float
    s: float
    l: float  # noqa: E741 (the knee is called L in the literature)

    def __post_init__(self) -> None:
        _check_param_side(self.side)
        if not all(np.isfinite([self.theta_i_deg, self.b0, self.s, self.l])) or self.b0 < 0 or self.l <= 0:
            raise ValidationError("Harvey parameters need finite b0 >= 0 and L > 0", field="harvey",
                                  got=(self.b0, self.s, self.l))


def _check_param_side(side: str) -> None:
    if side not in SIDES:
        raise ValidationError("unknown scattering side", field="side", expected=" or ".join(SIDES), got=side)


@dataclass(frozen=True, eq=False)
class AsapTable:
    """An ASAP-style table: ``table`` dims ``(side, theta_i, rho, psi)``, ``tis_stated`` dims ``(side, theta_i)``."""

    table: xr.DataArray
    tis_stated: xr.DataArray
    abg: tuple[AbgParameters, ...] = ()
    harvey: tuple[HarveyParameters, ...] = ()
    comments: tuple[str, ...] = ()
    path: str | None = field(default=None)

    def tis_computed(self) -> xr.DataArray:
        """TIS per side and incidence recomputed from the table (:func:`grids.tis_harvey_shack_table`)."""
        t = self.table
        tis = grids.tis_harvey_shack_table(t.values, t["rho"].values, t["psi"].values, t["theta_i"].values, 0.0)
        return xr.DataArray(tis, dims=("side", "theta_i"),
                            coords={"side": t["side"].values, "theta_i": t["theta_i"].values})


def asap_table(
    grid: xr.DataArray,
    *,
    abg: Sequence[AbgParameters] = (),
    harvey: Sequence[HarveyParameters] = (),
    comments: Sequence[str] = (),
) -> AsapTable:
    """An ASAP-style table from :func:`bsdfkit.tables.grids.harvey_shack_grid` (azimuths from the sample x axis).

    Parameters
    ----------
    grid : xarray.DataArray
        BSDF [1/sr] on dims (side, theta_i [deg], rho [-], psi [deg]).
    abg : sequence of AbgParameters
        ABg parameters to state.
    harvey : sequence of HarveyParameters
        Harvey parameters to state.
    comments : sequence of str
        Single-line comments.

    Returns
    -------
    AsapTable
        The table, values and angles rounded as written, with its stated TIS [-].
    """
    if tuple(grid.dims) != ("side", "theta_i", "rho", "psi"):
        raise ValidationError("grid must have dims (side, theta_i, rho, psi)", field="grid", got=str(grid.dims))
    if float(grid.attrs.get("zero_azimuth_deg", 0.0)) != 0.0:
        raise ValidationError("ASAP-style tables measure psi from the sample x axis", field="zero_azimuth_deg",
                              expected="0", got=grid.attrs.get("zero_azimuth_deg"))
    for text in comments:
        if "\n" in text or "\r" in text:
            raise ValidationError("comments must be single lines", field="comments", got=text)
    values = grids.quantize(grid.values, _VALUE_FMT)
    rho = grids.quantize(grid["rho"].values, grids.ANGLE_FORMAT)
    psi = grids.quantize(grid["psi"].values, grids.ANGLE_FORMAT)
    theta = np.asarray(grid["theta_i"].values, dtype=np.float64)
    table = grid.copy(data=values).assign_coords(rho=rho, psi=psi)
    tis = grids.tis_harvey_shack_table(values, rho, psi, theta, 0.0)
    tis_da = xr.DataArray(grids.quantize(tis, _VALUE_FMT), dims=("side", "theta_i"),
                          coords={"side": grid["side"].values, "theta_i": theta})
    return AsapTable(table=table, tis_stated=tis_da, abg=tuple(abg), harvey=tuple(harvey), comments=tuple(comments))


def asap_text(asap: AsapTable, generated_at: datetime | None = None) -> str:
    """The file text. Line 2 (bsdfkit version and time) is the only line that changes between runs.

    Parameters
    ----------
    asap : AsapTable
        The table.
    generated_at : datetime, optional
        Time stated on line 2 (default: now).

    Returns
    -------
    str
        The file text.
    """
    when = generated_at or datetime.now()
    f = lambda v, fmt=_VALUE_FMT: format(float(v), fmt)  # noqa: E731
    lines = [MAGIC, f"# bsdfkit {__version__} {when:%Y-%m-%dT%H:%M:%S}", _DOC]
    lines += [f"# {c}" for c in asap.comments]
    t = asap.table
    sides = [str(s) for s in t["side"].values]
    theta = t["theta_i"].values
    for s, side in enumerate(sides):
        for i, th in enumerate(theta):
            lines.append(f"tis {_CODE[side]} {f(th, grids.ANGLE_FORMAT)} {f(asap.tis_stated.values[s, i])}")
    for p in asap.abg:
        lines.append(f"abg {_CODE[p.side]} {f(p.theta_i_deg, grids.ANGLE_FORMAT)} {f(p.a)} {f(p.b)} {f(p.g)}")
    for p in asap.harvey:
        lines.append(f"harvey {_CODE[p.side]} {f(p.theta_i_deg, grids.ANGLE_FORMAT)} {f(p.b0)} {f(p.s)} {f(p.l)}")
    lines.append("side theta_i_deg rho psi_deg bsdf")
    rho = [f(r, grids.ANGLE_FORMAT) for r in t["rho"].values]
    psi = [f(p, grids.ANGLE_FORMAT) for p in t["psi"].values]
    values = t.values
    for s, side in enumerate(sides):
        for i, th in enumerate(theta):
            head = f"{_CODE[side]} {f(th, grids.ANGLE_FORMAT)} "
            for j, r in enumerate(rho):
                lines.extend(f"{head}{r} {p} {f(values[s, i, j, k])}" for k, p in enumerate(psi))
    lines.append("end")
    return "\n".join(lines) + "\n"


def write_asap(path: str | Path, asap: AsapTable, *, force: bool = False,
               generated_at: datetime | None = None) -> Path:
    """Write ``asap`` atomically; refuses to overwrite unless ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    asap : AsapTable
        The table.
    force : bool
        Replace an existing file.
    generated_at : datetime, optional
        Time stated in the file (default: now).

    Returns
    -------
    Path
        The file written.
    """
    atomic.check_writable(path, force)
    return atomic.write_text(path, asap_text(asap, generated_at), force=force)


def _number(token: str, path: str, line: int, name: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise FormatError("not a number", file=path, line=line, field=name, expected="a number", got=token) from None
    if not np.isfinite(value):
        raise FormatError("not a finite number", file=path, line=line, field=name, expected="a finite number",
                          got=token)
    return value


def _side(token: str, path: str, line: int) -> str:
    if token not in _SIDE:
        raise FormatError("unknown side code", file=path, line=line, field="side", expected="R or T", got=token)
    return _SIDE[token]


def read_asap(path: str | Path) -> AsapTable:
    """Read a table written by :func:`write_asap`; errors name file, line and field.

    Parameters
    ----------
    path : str or Path
        The table file.

    Returns
    -------
    AsapTable
        The table (BSDF [1/sr], angles [deg]), stated TIS [-], parameters and comments.
    """
    path = str(path)
    text = read_text(path, expected="a bsdfkit ASAP-style table")
    lines = text.splitlines()
    if not lines or lines[0].strip() != MAGIC:
        raise FormatError("not a bsdfkit ASAP-style table", file=path, line=1, field="magic", expected=repr(MAGIC),
                          got=lines[0].strip() if lines else "")
    comments, tis, abg, harvey, rows = _read_lines(lines, path)
    table, tis_da = _tables(rows, _data(rows, path), tis, path)
    doc_lines = len(_DOC.splitlines())
    return AsapTable(table=table, tis_stated=tis_da, abg=tuple(abg), harvey=tuple(harvey),
                     comments=tuple(comments[doc_lines:]), path=path)


def _read_lines(lines: list[str], path: str):
    """The comments, stated TIS by (side, θi), ABg and Harvey parameters and the data rows (line, side code,
    tokens) of a table's lines, checked in order: parameter lines, the column header, R/T rows, 'end'."""
    comments: list[str] = []
    tis: dict[tuple[str, float], float] = {}
    abg: list[AbgParameters] = []
    harvey: list[HarveyParameters] = []
    rows: list[tuple[int, str, list[str]]] = []
    header_seen = ended = False
    for number, line in enumerate(lines, start=1):
        body = line.strip()
        if not body:
            continue
        if body.startswith("#"):
            if number > 2:
                comments.append(body[1:].strip())
            continue
        if ended:
            raise FormatError("content after 'end'", file=path, line=number, field="end", expected="end of file",
                              got=body[:60])
        tokens = body.split()
        key = tokens[0]
        if key == "end":
            ended = True
        elif key in ("tis", "abg", "harvey") and not header_seen:
            _parameter_line(tokens, path, number, tis, abg, harvey)
        elif key == "side" and not header_seen:
            if tokens != ["side", "theta_i_deg", "rho", "psi_deg", "bsdf"]:
                raise FormatError("wrong column header", file=path, line=number, field="header",
                                  expected="'side theta_i_deg rho psi_deg bsdf'", got=body)
            header_seen = True
        elif header_seen and key in _SIDE:
            rows.append((number, key, tokens))
        else:
            raise FormatError("unexpected line", file=path, line=number, field="record",
                              expected="tis/abg/harvey lines, the column header, then R/T rows" if not header_seen
                              else "an R or T data row or 'end'", got=body[:60])
    last = len(lines)
    if not header_seen:
        raise FormatError("missing column header", file=path, line=last, field="header",
                          expected="'side theta_i_deg rho psi_deg bsdf'", got="end of file")
    if not ended:
        raise FormatError("file is truncated", file=path, line=last, field="end", expected="a final 'end' line",
                          got=lines[-1].strip()[:60] if lines else "")
    if not rows:
        raise FormatError("no data rows", file=path, line=last, field="data", expected="R/T rows", got="none")
    return comments, tis, abg, harvey, rows


def _parameter_line(tokens: list[str], path: str, number: int, tis: dict, abg: list, harvey: list) -> None:
    """Add a 'tis', 'abg' or 'harvey' line (``tokens``, on line ``number``) to ``tis``, ``abg`` or ``harvey``."""
    key = tokens[0]
    n = {"tis": 4, "abg": 6, "harvey": 6}[key]
    if len(tokens) != n:
        raise FormatError(f"'{key}' line needs {n - 1} fields", file=path, line=number, field=key,
                          expected=f"{n - 1} fields", got=len(tokens) - 1)
    side = _side(tokens[1], path, number)
    nums = [_number(t, path, number, f"{key} field {k + 3}") for k, t in enumerate(tokens[2:])]
    if key == "tis":
        tis[(side, nums[0])] = nums[1]
        return
    try:
        if key == "abg":
            abg.append(AbgParameters(side, *nums))
        else:
            harvey.append(HarveyParameters(side, *nums))
    except ValidationError as exc:
        raise FormatError(f"invalid {key} parameters", file=path, line=number, field=key,
                          expected="A >= 0, B > 0" if key == "abg" else "b0 >= 0, L > 0",
                          got=" ".join(tokens[2:])) from exc


def _data(rows: list[tuple[int, str, list[str]]], path: str) -> NDArray[np.float64]:
    """The numbers of the data rows, (rows, 4): θi, ρ, ψ, BSDF; a bad cell or a negative BSDF named by its line."""
    names = ("side", "theta_i_deg", "rho", "psi_deg", "bsdf")
    data = None
    if all(len(tokens) == 5 for _, _, tokens in rows):
        try:
            data = np.array([tokens[1:] for _, _, tokens in rows], dtype=np.float64).reshape(len(rows), 4)
        except ValueError:
            data = None
    if data is None or not np.all(np.isfinite(data)):
        for number, _, tokens in rows:  # slow path: find and name the bad cell
            if len(tokens) != 5:
                raise FormatError("wrong number of columns", file=path, line=number, field="data row",
                                  expected="5 values", got=len(tokens))
            for t, n in zip(tokens[1:], names[1:]):
                _number(t, path, number, n)
    assert data is not None
    if np.any(data[:, 3] < 0):
        k = int(np.argmax(data[:, 3] < 0))
        raise FormatError("negative BSDF", file=path, line=rows[k][0], field="bsdf", expected=">= 0", got=data[k, 3])
    return data


def _tables(rows: list[tuple[int, str, list[str]]], data: NDArray[np.float64], tis: dict,
            path: str) -> tuple[xr.DataArray, xr.DataArray]:
    """The rectangular BSDF table (side, theta_i, rho, psi) of the data rows and the stated TIS (side, theta_i)."""
    codes = [code for _, code, _ in rows]
    sides = [s for s in SIDES if _CODE[s] in codes]
    theta, rho, psi = np.unique(data[:, 0]), np.unique(data[:, 1]), np.unique(data[:, 2])
    shape = (len(sides), theta.size, rho.size, psi.size)
    flat = ((np.array([sides.index(_SIDE[c]) for c in codes]) * theta.size + np.searchsorted(theta, data[:, 0]))
            * rho.size + np.searchsorted(rho, data[:, 1])) * psi.size + np.searchsorted(psi, data[:, 2])
    order = np.argsort(flat, kind="stable")
    repeat = np.flatnonzero(np.diff(flat[order]) == 0)
    if repeat.size:
        first, second = sorted((int(order[repeat[0]]), int(order[repeat[0] + 1])))
        raise FormatError("duplicate data row", file=path, line=rows[second][0], field="side/theta_i/rho/psi",
                          expected="each combination once", got=f"same cell as line {rows[first][0]}")
    if len(rows) != int(np.prod(shape)):
        raise FormatError(f"table is not rectangular: {len(rows)} rows", file=path, line=rows[-1][0],
                          field="data", expected=f"{int(np.prod(shape))} rows (side x theta_i x rho x psi = {shape})",
                          got=len(rows))
    values = np.zeros(int(np.prod(shape)))
    values[flat] = data[:, 3]
    tis_arr = np.zeros((len(sides), theta.size))
    for s, side in enumerate(sides):
        for i, th in enumerate(theta):
            if (side, th) not in tis:
                raise FormatError("missing tis line", file=path, line=rows[0][0], field="tis",
                                  expected=f"'tis {_CODE[side]} {th:g} <value>' before the table", got="none")
            tis_arr[s, i] = tis[(side, th)]
    table = xr.DataArray(values.reshape(shape), dims=("side", "theta_i", "rho", "psi"),
                         coords={"side": sides, "theta_i": theta, "rho": rho, "psi": psi}, name="bsdf",
                         attrs={"units": "1/sr", "frame": "harvey_shack", "zero_azimuth_deg": 0.0})
    return table, xr.DataArray(tis_arr, dims=("side", "theta_i"), coords={"side": sides, "theta_i": theta})


# ------------------------------------------------------------------------------------------- registry hooks
def _as_floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]


def _write_job(job: WriteJob) -> WriteOutcome:
    """The sides as rows, plus the fitted ABg parameters at the written incidences."""
    axes, info = axes_choice.harvey_shack_axes(job.fn, job.theta, job.sides, job.settings, 0.0)
    grid = axes_choice.harvey_shack_table(job.fn, job.theta, job.sides, axes, info, job.settings)
    chosen = [p for p in job.abg if np.any(np.abs(np.asarray(job.theta) - p.theta_i_deg) <= 1e-9)]
    table = asap_table(grid, abg=chosen, comments=job.comments)
    write_asap(job.path, table, force=job.force, generated_at=job.generated_at)
    return WriteOutcome(axes, info)


def _summarise(path: str) -> FileSummary:
    return _summary(read_asap(path), path)


def _vendor_table(path: str) -> VendorTable:
    return _nodes(read_asap(path))


def _summary_and_table(path: str) -> tuple[FileSummary, VendorTable | None]:
    table = read_asap(path)
    return _summary(table, path), _nodes(table)


def _summary(table: AsapTable, path: str) -> FileSummary:
    computed = table.tis_computed()
    sides = [str(s) for s in table.table["side"].values]
    return FileSummary(
        format="asap", path=path, incidences_deg=_as_floats(table.table["theta_i"].values),
        tis_computed={s: _as_floats(computed.sel(side=s).values) for s in sides},
        tis_stated={s: _as_floats(table.tis_stated.sel(side=s).values) for s in sides},
        details={"abg": [vars(p) for p in table.abg], "harvey": [vars(p) for p in table.harvey],
                 "table_shape": dict(table.table.sizes)},
    )


def _nodes(asap_table: AsapTable) -> VendorTable:
    table = asap_table.table
    out = [VendorGrid("harvey_shack", str(side), np.asarray(table["theta_i"].values, dtype=np.float64),
                      np.asarray(table["rho"].values, dtype=np.float64),
                      np.asarray(table["psi"].values, dtype=np.float64),
                      np.moveaxis(np.asarray(table.sel(side=side).values, dtype=np.float64), -1, -2))
           for side in table["side"].values]
    return VendorTable("asap", tuple(out), None, {})


FORMAT = TableFormat(name="asap", title="bsdfkit ASAP-style", extensions=(".txt", ".asap"),
                     guess_can_open=first_line_is(MAGIC), summarise=_summarise, vendor_table=_vendor_table,
                     write=_write_job, sides_per_file=2, grid_kind="harvey_shack",
                     summary_and_table=_summary_and_table)
