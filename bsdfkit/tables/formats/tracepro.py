"""TracePro surface-property text files: Asymmetric Table (Scatter 5) and ABg (Scatter 1).

Layout ([TracePro-IO] in docs/references.md: TracePro Help "Surface Property Import/Export Format", and a
genuine TracePro 19.6 export, [TracePro-examples]; docs/exports.md §2.1): a 16-line header (magic line,
File Name, TracePro Release, Database Version, timestamp, blank, Name, Catalog, Description, Coating,
Scatter, Interaction, Polarization, User_Data, Solve, blank), a column-header line starting ``Temperature``,
one 22-column surface-data row per incidence angle, then for Scatter 5 a ``Table_BSDF_Data`` line, its
8-column header and one row per IncAngle × ScatterBeta × ScatterAzimuth (IncAngle outer, ScatterAzimuth
inner, as [TracePro-examples]), and ``SAVE-DATA``. bsdfkit writes tabs and CRLF line ends like TracePro itself.

Conventions ([TracePro-UM]; docs/exports.md §2.1):

* ScatterBeta = |β − β0| and ScatterAzimuth = azimuth of β − β0 on one grid shared by all incidences
  (TracePro cannot use per-incidence ScatterBeta lists). BRDF and BTDF are columns of the same row.
  For a plate in air β0 = (sin θi, 0) on both sides (:mod:`bsdfkit.core.frames`).
* TracePro's floating zero-azimuth axis is "always orthogonal to the plane of incidence" ([TracePro-UM]); which
  of the two perpendicular directions it is was not recoverable (docs/exports.md §5, question 1). bsdfkit
  writes ScatterAzimuth = ψ_sample − ``zero_azimuth_deg`` with a default of 270°: TracePro's x axis is
  the sample −y axis, i.e. unit(k × n) for the incident propagation vector k (the s-polarisation
  direction), so forward scatter (away from the source) lies at ScatterAzimuth 90° and the source side
  at 270°. The choice is recorded in the Description as ``[bsdfkit zero_azimuth_deg=270]`` and read
  back from there. It is immaterial for lobes symmetric about β0 (Lambertian, Gaussian, ABg).
* Energy: TracePro requires a + Rs + Ts + TS_R + TS_T = 1 (eq. 7.30 of [TracePro-UM]). The writer sets
  Abso_S = Abso_P = 1 − TS_R − TS_T − Refl − Tran with TS computed from the written (rounded) table by
  :func:`bsdfkit.tables.grids.tis_harvey_shack_table` — the same function the reader uses — so the file's
  implied total scatter and its recomputed TIS agree to rounding. A sum above 1 is refused, except by the
  ``scatter_excess_allowed`` of a fit that passed the plausibility gate (TIS above 1 within k standard
  uncertainties, :mod:`bsdfkit.fit.plausibility`): that fit is written as fitted, as by the Zemax and ASAP
  writers, with Abso = 0, and the file's energy balance then exceeds 1 by that insignificant excess.
* ABg (Scatter 1): BSDF = A/(B + |β − β0|^g) (eq. 7.25 of [TracePro-UM]); TIS by :func:`tis_abg` (polar
  quadrature over the unit disk about β0).

Not supported (FormatError when read): Scatter codes other than 0, 1, 5; direction-sensitive
properties (Side1_Data/Side2_Data); GratingData; several Temperature/Wavelength pairs or several
properties in one file.
"""
from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.core.frames import SIDES
from bsdfkit.core.lazy import LazyModule
from bsdfkit.io import atomic
from bsdfkit.io.text import read_text
from bsdfkit.models.registry import bsdf_model
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

__all__ = [
    "DEFAULT_ZERO_AZIMUTH_DEG",
    "SURFACE_COLUMNS",
    "TABLE_COLUMNS",
    "TraceProOptions",
    "TraceProProperty",
    "abg_property",
    "read_tracepro",
    "table_property",
    "tis_abg",
    "tracepro_text",
    "write_tracepro",
]

MAGIC = "TracePro Surface Property Data"
DEFAULT_ZERO_AZIMUTH_DEG = 270.0
SURFACE_COLUMNS: tuple[str, ...] = (
    "Temperature", "Wavelength", "IncAngle", "AziAngle", "Abso_S", "Abso_P", "Refl_S", "Refl_P",
    "Tran_S", "Tran_P", "PhaseRefl", "PhaseTran", "BRDF_A", "BRDF_B", "BRDF_By", "BRDF_g", "BRDF_gy",
    "BTDF_A", "BTDF_B", "BTDF_By", "BTDF_g", "BTDF_gy",
)
TABLE_COLUMNS: tuple[str, ...] = (
    "Temperature", "Wavelength", "IncAngle", "AziAngle", "ScatterBeta", "ScatterAzimuth", "BRDF", "BTDF",
)
_HEADER_KEYS = ("Name", "Catalog", "Description", "Coating", "Scatter", "Interaction", "Polarization",
                "User_Data", "Solve")
_MONTHS = ("January", "February", "March", "April", "May", "June", "July", "August", "September",
           "October", "November", "December")
_ZERO_TAG = re.compile(r"\[bsdfkit zero_azimuth_deg=([-+0-9.eE]+)\]")
_VALUE_FMT = ".7g"
_ENERGY_SLACK = 1e-6


@dataclass(frozen=True)
class TraceProOptions:
    """Header and bookkeeping choices of a TracePro export (defaults as a genuine export; docs/exports.md §2.1)."""

    name: str = "bsdfkit_export"
    catalog: str = "bsdfkit"
    description: str = "exported by bsdfkit"
    temperature_K: float = 300.0
    wavelength_um: float = 0.55
    zero_azimuth_deg: float = DEFAULT_ZERO_AZIMUTH_DEG
    release: str = "19 6 0"
    database_version: str = "4 1 0"
    db_file_name: str = r"C:\bsdfkit\TracePro.db"

    def __post_init__(self) -> None:
        for key in ("name", "catalog", "description"):
            text = getattr(self, key)
            if "\n" in text or "\r" in text or "\t" in text or (key != "description" and not text.strip()):
                raise ValidationError("TracePro header text must be one non-empty line without tabs",
                                      field=key, expected="one line of text without tabs", got=text)
        # ranges of a physical sample: a temperature up to a flame's, a wavelength from the deep UV to the far IR
        if not (np.isfinite(self.temperature_K) and 0 < self.temperature_K <= 1e4):
            raise ValidationError("temperature out of range", field="temperature_K", expected="0 < T <= 10000 K",
                                  got=self.temperature_K)
        if not (np.isfinite(self.wavelength_um) and 0.1 <= self.wavelength_um <= 100.0):
            raise ValidationError("wavelength out of range", field="wavelength_um",
                                  expected="0.1-100 micrometres", got=self.wavelength_um)
        if not (np.isfinite(self.zero_azimuth_deg) and -360.0 <= self.zero_azimuth_deg <= 360.0):
            raise ValidationError("azimuth of TracePro's ScatterAzimuth 0 out of range", field="zero_azimuth_deg",
                                  expected="a finite angle in [-360, 360] deg", got=self.zero_azimuth_deg)


@dataclass(frozen=True, eq=False)
class TraceProProperty:
    """One TracePro surface property, as written or as read.

    ``table`` (Scatter 5) has dims ``(side, theta_i, rho, psi)`` with both sides, ψ in TracePro's
    ScatterAzimuth frame; ``abg`` (Scatter 1) has dims ``(side, theta_i, param)`` with param A, B, g.
    Per-incidence arrays align with ``theta_i_deg`` (the surface-data IncAngles).
    """

    options: TraceProOptions
    scatter: int
    theta_i_deg: NDArray[np.float64]
    absorptance: NDArray[np.float64]
    specular_reflectance: NDArray[np.float64]
    specular_transmittance: NDArray[np.float64]
    table: xr.DataArray | None = None
    abg: xr.DataArray | None = None
    coating: int = 1
    solve: str = "<None>"
    path: str | None = field(default=None)

    def tis_computed(self) -> dict[str, NDArray[np.float64]]:
        """Total integrated scatter per side and incidence, recomputed from the scatter data."""
        if self.scatter == 5 and self.table is not None:
            tis = grids.tis_harvey_shack_table(
                self.table.values, self.table["rho"].values, self.table["psi"].values,
                self.table["theta_i"].values, self.options.zero_azimuth_deg,
            )
            return {side: tis[k] for k, side in enumerate(self.table["side"].values.tolist())}
        if self.scatter == 1 and self.abg is not None:
            return {
                side: np.array([tis_abg(*self.abg.sel(side=side, theta_i=t).values, theta_i_deg=t)
                                for t in self.theta_i_deg])
                for side in SIDES
            }
        return {side: np.zeros(self.theta_i_deg.size) for side in SIDES}

    def tis_stated(self) -> NDArray[np.float64]:
        """Total scatter (BRDF + BTDF) implied by the energy balance: 1 − Abso − Refl − Tran."""
        return 1.0 - self.absorptance - self.specular_reflectance - self.specular_transmittance


# --------------------------------------------------------------------------------------------------
# building properties
# --------------------------------------------------------------------------------------------------
def tis_abg(a: float, b: float, g: float, theta_i_deg: float) -> float:
    """TIS of A/(B + |β − β0|^g) over the unit disk at incidence θi [deg], 0 when A = 0 (the registry's ABg).

    Parameters
    ----------
    a : float
        A [1/sr].
    b : float
        B [-].
    g : float
        g [-].
    theta_i_deg : float
        Incidence [deg].

    Returns
    -------
    float
        TIS [-].
    """
    if a == 0.0:
        return 0.0
    return float(bsdf_model("abg").total_integrated_scatter({"A": a, "B": b, "g": g}, theta_i_deg))


def _per_incidence(name: str, value: ArrayLike, n: int) -> NDArray[np.float64]:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 1):
        raise ValidationError("specular term must be a fraction in [0, 1]", field=name, got=arr.tolist())
    return arr


def _absorptance(theta: NDArray, scatter_total: NDArray, refl: NDArray, tran: NDArray,
                 allowed: ArrayLike = 0.0) -> NDArray:
    """Abso = 1 − TIS_R − TIS_T − Refl − Tran, refused where the sum exceeds 1 by more than ``allowed`` (+ rounding
    slack); where a source's uncertainty allows an excess (a fit consistent with TIS ≤ 1), Abso is written as 0."""
    allowed = np.broadcast_to(np.asarray(allowed, dtype=np.float64), np.shape(theta))
    abso = 1.0 - scatter_total - refl - tran
    bad = abso < -(_ENERGY_SLACK + allowed)
    if np.any(bad):
        k = int(np.argmax(bad))
        within = f" + {allowed[k]:.3g} (the source's uncertainty)" if allowed[k] > 0 else ""
        raise ValidationError(
            f"energy balance exceeds 1 at IncAngle {theta[k]:g} deg (TIS_R + TIS_T + Refl + Tran)",
            field="absorptance", expected=f"<= 1{within}", got=float(scatter_total[k] + refl[k] + tran[k]),
        )
    return grids.quantize(np.clip(abso, 0.0, 1.0), _VALUE_FMT)


def _allowance(value: ArrayLike, n: int) -> NDArray[np.float64]:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValidationError("allowed scatter excess must be finite and >= 0", field="scatter_excess_allowed",
                              got=arr.tolist())
    return arr


def table_property(
    grid: xr.DataArray,
    *,
    options: TraceProOptions = TraceProOptions(),
    specular_reflectance: ArrayLike = 0.0,
    specular_transmittance: ArrayLike = 0.0,
    scatter_excess_allowed: ArrayLike = 0.0,
) -> TraceProProperty:
    """Asymmetric-table (Scatter 5) property from a Harvey–Shack grid.

    ``grid`` comes from :func:`bsdfkit.tables.grids.harvey_shack_grid` with
    ``zero_azimuth_deg = options.zero_azimuth_deg``; a missing side is written as zeros. Values are
    rounded to what the file will hold before the TIS and the absorptance are computed.
    ``scatter_excess_allowed`` [1] (per incidence): by how much TIS_R + TIS_T + Refl + Tran may exceed 1 —
    k·u(TIS) of a fit that passed :mod:`bsdfkit.fit.plausibility`, so that this writer refuses what the gate
    refuses and nothing more (Abso is then 0); 0 by default (the sum may exceed 1 only by rounding).

    Parameters
    ----------
    grid : xarray.DataArray
        BSDF [1/sr] on dims (side, theta_i [deg], rho [-], psi [deg]).
    options : TraceProOptions
        Header settings and the table's azimuth frame.
    specular_reflectance : float or array_like
        Specular reflectance Refl per incidence [-].
    specular_transmittance : float or array_like
        Specular transmittance Tran per incidence [-].
    scatter_excess_allowed : float or array_like
        Allowed excess of the energy sum over 1 per incidence [-].

    Returns
    -------
    TraceProProperty
        Scatter 5 property: table [1/sr] and absorptance [-] per incidence.
    """
    if tuple(grid.dims) != ("side", "theta_i", "rho", "psi"):
        raise ValidationError("grid must have dims (side, theta_i, rho, psi)", field="grid", got=str(grid.dims))
    zero = float(grid.attrs.get("zero_azimuth_deg", 0.0))
    if abs(zero - options.zero_azimuth_deg) > 1e-9:
        raise ValidationError("grid azimuth frame differs from the TracePro option", field="zero_azimuth_deg",
                              expected=f"{options.zero_azimuth_deg:g}", got=zero)
    theta = np.asarray(grid["theta_i"].values, dtype=np.float64)
    full = np.zeros((2,) + grid.shape[1:])
    for k, side in enumerate(SIDES):
        if side in grid["side"].values:
            full[k] = grids.quantize(grid.sel(side=side).values, _VALUE_FMT)
    table = xr.DataArray(
        full, dims=grid.dims,
        coords={"side": list(SIDES), "theta_i": theta, "rho": grids.quantize(grid["rho"].values, grids.ANGLE_FORMAT),
                "psi": grids.quantize(grid["psi"].values, grids.ANGLE_FORMAT)},
        name="bsdf", attrs={"units": "1/sr", "frame": "harvey_shack", "zero_azimuth_deg": zero},
    )
    refl = _per_incidence("specular_reflectance", specular_reflectance, theta.size)
    tran = _per_incidence("specular_transmittance", specular_transmittance, theta.size)
    tis = grids.tis_harvey_shack_table(full, table["rho"].values, table["psi"].values, theta, zero)
    allowed = _allowance(scatter_excess_allowed, theta.size)
    return TraceProProperty(
        options=options, scatter=5, theta_i_deg=theta,
        absorptance=_absorptance(theta, tis.sum(axis=0), refl, tran, allowed),
        specular_reflectance=refl, specular_transmittance=tran, table=table,
    )


def abg_property(
    theta_i_deg: Sequence[float],
    brdf_abg: ArrayLike | None,
    btdf_abg: ArrayLike | None = None,
    *,
    options: TraceProOptions = TraceProOptions(),
    specular_reflectance: ArrayLike = 0.0,
    specular_transmittance: ArrayLike = 0.0,
    scatter_excess_allowed: ArrayLike = 0.0,
) -> TraceProProperty:
    """ABg (Scatter 1) property: ``brdf_abg``/``btdf_abg`` are (A, B, g) per incidence, shape (n, 3) or (3,).

    ``scatter_excess_allowed`` as in :func:`table_property`.

    Parameters
    ----------
    theta_i_deg : sequence of float
        Incidences [deg].
    brdf_abg : array_like or None
        Reflection (A [1/sr], B [-], g [-]); None: no reflected scatter.
    btdf_abg : array_like or None
        Transmission (A [1/sr], B [-], g [-]); None: no transmitted scatter.
    options : TraceProOptions
        Header settings and the table's azimuth frame.
    specular_reflectance : float or array_like
        Specular reflectance Refl per incidence [-].
    specular_transmittance : float or array_like
        Specular transmittance Tran per incidence [-].
    scatter_excess_allowed : float or array_like
        Allowed excess of the energy sum over 1 per incidence [-].

    Returns
    -------
    TraceProProperty
        Scatter 1 property: ABg parameters and absorptance [-] per incidence.
    """
    theta = np.asarray(theta_i_deg, dtype=np.float64)
    params = np.zeros((2, theta.size, 3))
    for k, (side, value) in enumerate(zip(SIDES, (brdf_abg, btdf_abg))):
        if value is None:
            continue
        arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (theta.size, 3))
        a, b, g = arr[:, 0], arr[:, 1], arr[:, 2]
        if not np.all(np.isfinite(arr)) or np.any(a < 0) or np.any((b <= 0) & (g != 0)) or np.any(b < 0):
            raise ValidationError("ABg parameters need A >= 0 and B > 0 (B >= 0 when g = 0)",
                                  field=f"{side} ABg", got=arr.tolist())
        params[k] = grids.quantize(arr, _VALUE_FMT)
    abg = xr.DataArray(params, dims=("side", "theta_i", "param"),
                       coords={"side": list(SIDES), "theta_i": theta, "param": ["A", "B", "g"]})
    refl = _per_incidence("specular_reflectance", specular_reflectance, theta.size)
    tran = _per_incidence("specular_transmittance", specular_transmittance, theta.size)
    total = np.array([sum(tis_abg(*params[s, t], theta_i_deg=theta[t]) for s in range(2)) for t in range(theta.size)])
    allowed = _allowance(scatter_excess_allowed, theta.size)
    return TraceProProperty(
        options=options, scatter=1, theta_i_deg=theta, absorptance=_absorptance(theta, total, refl, tran, allowed),
        specular_reflectance=refl, specular_transmittance=tran, abg=abg,
    )


# --------------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------------
def _timestamp(when: datetime) -> str:
    return f"Data generated at {when:%H:%M:%S} {_MONTHS[when.month - 1]} {when.day}, {when.year}"


def _fmt(value: float, fmt: str = _VALUE_FMT) -> str:
    return format(float(value), fmt)


def tracepro_text(prop: TraceProProperty, generated_at: datetime | None = None) -> str:
    """The file text (LF line ends; :func:`write_tracepro` converts to CRLF).

    Parameters
    ----------
    prop : TraceProProperty
        The property.
    generated_at : datetime, optional
        Time stated in the header (default: now).

    Returns
    -------
    str
        The file text.
    """
    o = prop.options
    when = generated_at or datetime.now()
    description = f"{o.description} [bsdfkit zero_azimuth_deg={o.zero_azimuth_deg:g}]".strip()
    lines = [
        MAGIC,
        f"File Name\t{o.db_file_name}",
        f"TracePro Release: {o.release}",
        f"Database Version: {o.database_version}",
        _timestamp(when),
        "",
        f"Name\t{o.name}",
        f"Catalog\t{o.catalog}",
        f"Description\t{description}",
        f"Coating    {prop.coating}",
        f"Scatter    {prop.scatter}",
        "Interaction 0",
        "Polarization\t0",
        "User_Data  1",
        f"Solve\t{prop.solve}",
        "",
        "\t".join(SURFACE_COLUMNS),
    ]
    prefix = f"{_fmt(o.temperature_K, grids.ANGLE_FORMAT)}\t{_fmt(o.wavelength_um, grids.ANGLE_FORMAT)}"
    for t, theta in enumerate(prop.theta_i_deg):
        abg = np.zeros((2, 3)) if prop.abg is None else prop.abg.values[:, t, :]
        a_r, b_r, g_r = abg[0]
        a_t, b_t, g_t = abg[1]
        cells = [
            _fmt(theta, grids.ANGLE_FORMAT), "0",
            _fmt(prop.absorptance[t]), _fmt(prop.absorptance[t]),
            _fmt(prop.specular_reflectance[t]), _fmt(prop.specular_reflectance[t]),
            _fmt(prop.specular_transmittance[t]), _fmt(prop.specular_transmittance[t]),
            "0", "0",
            _fmt(a_r), _fmt(b_r), _fmt(b_r), _fmt(g_r), _fmt(g_r),
            _fmt(a_t), _fmt(b_t), _fmt(b_t), _fmt(g_t), _fmt(g_t),
        ]
        lines.append(prefix + "\t" + "\t".join(cells))
    if prop.scatter == 5 and prop.table is not None:
        lines.append("Table_BSDF_Data")
        lines.append("\t".join(TABLE_COLUMNS))
        rho = [_fmt(r, grids.ANGLE_FORMAT) for r in prop.table["rho"].values]
        psi = [_fmt(p, grids.ANGLE_FORMAT) for p in prop.table["psi"].values]
        values = prop.table.values
        for t, theta in enumerate(prop.table["theta_i"].values):
            head = f"{prefix}\t{_fmt(theta, grids.ANGLE_FORMAT)}\t0\t"
            brdf, btdf = values[0, t], values[1, t]
            for j, r in enumerate(rho):
                lines.extend(
                    f"{head}{r}\t{p}\t{_fmt(brdf[j, k])}\t{_fmt(btdf[j, k])}" for k, p in enumerate(psi)
                )
    lines.append("SAVE-DATA")
    return "\n".join(lines) + "\n"


def write_tracepro(
    path: str | Path, prop: TraceProProperty, *, force: bool = False, generated_at: datetime | None = None
) -> Path:
    """Write ``prop`` atomically (CRLF, tabs); refuses to overwrite unless ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    prop : TraceProProperty
        The property.
    force : bool
        Replace an existing file.
    generated_at : datetime, optional
        Time stated in the header (default: now).

    Returns
    -------
    Path
        The file written.
    """
    atomic.check_writable(path, force)
    return atomic.write_text(path, tracepro_text(prop, generated_at), force=force, newline="\r\n")


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------
def _numbers(tokens: list[str], columns: Sequence[str], path: str, line: int) -> list[float]:
    """One row of numbers, or a FormatError naming the line and the column."""
    if len(tokens) != len(columns):
        raise FormatError("wrong number of columns", file=path, line=line,
                          field=f"{columns[0]}..{columns[-1]}", expected=f"{len(columns)} values", got=len(tokens))
    out = []
    for token, name in zip(tokens, columns):
        try:
            value = float(token)
        except ValueError:
            raise FormatError("not a number", file=path, line=line, field=name, expected="a number",
                              got=token) from None
        if not np.isfinite(value):
            raise FormatError("not a finite number", file=path, line=line, field=name, expected="a finite number",
                              got=token)
        out.append(value)
    return out


def _rows(texts: list[str], line_numbers: list[int], columns: Sequence[str], path: str) -> NDArray[np.float64]:
    """Parse many rows at once; on any problem fall back to :func:`_numbers` to name line and column."""
    try:  # numpy's C text reader: a third of the time of float() on each token (a 3 MB table: 0.9 → 0.3 s)
        arr = np.loadtxt(texts, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        arr = None
    if arr is not None and arr.shape == (len(texts), len(columns)) and np.all(np.isfinite(arr)):
        return arr
    tokens = [t.split() for t in texts]
    if all(len(t) == len(columns) for t in tokens):
        try:
            arr = np.array(tokens, dtype=np.float64)
        except ValueError:
            arr = None
        if arr is not None and np.all(np.isfinite(arr)):
            return arr.reshape(len(texts), len(columns))
    for tok, line in zip(tokens, line_numbers):
        _numbers(tok, columns, path, line)
    raise AssertionError("unreachable: _numbers raises for the row that failed")  # pragma: no cover


def _numeric_block(lines: list[str], index: int) -> tuple[list[str], list[int], int]:
    """Collect the data lines from ``index`` up to the next line starting with a letter."""
    texts: list[str] = []
    numbers: list[int] = []
    while index < len(lines):
        stripped = lines[index].strip()
        if stripped:
            if stripped[0].isalpha():
                break
            texts.append(stripped)
            numbers.append(index + 1)
        index += 1
    return texts, numbers, index


def _keyword_value(lines: list[str], index: int, key: str, path: str) -> str:
    if index >= len(lines):
        raise FormatError("file ends inside the header", file=path, line=len(lines), field=key,
                          expected=f"a '{key}' line")
    text = lines[index]
    parts = text.strip().split(None, 1)
    if not parts or parts[0] != key:
        raise FormatError("missing header keyword", file=path, line=index + 1, field=key,
                          expected=f"a line starting with '{key}'", got=text.strip())
    return parts[1].strip() if len(parts) > 1 else ""


def _int_value(text: str, key: str, path: str, line: int, allowed: range) -> int:
    try:
        value = int(text)
    except ValueError:
        raise FormatError("not an integer", file=path, line=line, field=key,
                          expected=f"an integer in {allowed.start}..{allowed.stop - 1}", got=text) from None
    if value not in allowed:
        raise FormatError("value out of range", file=path, line=line, field=key,
                          expected=f"an integer in {allowed.start}..{allowed.stop - 1}", got=value)
    return value


def read_tracepro(path: str | Path, *, zero_azimuth_deg: float | None = None) -> TraceProProperty:
    """Read a TracePro surface-property file (Scatter 0, 1 or 5).

    The table's azimuth frame is taken from a ``[bsdfkit zero_azimuth_deg=…]`` tag in the Description,
    else from ``zero_azimuth_deg``, else :data:`DEFAULT_ZERO_AZIMUTH_DEG`. Errors name file, line and
    field.

    Parameters
    ----------
    path : str or Path
        The surface-property file.
    zero_azimuth_deg : float, optional
        Sample azimuth of table azimuth 0 when the file has no tag [deg].

    Returns
    -------
    TraceProProperty
        Incidences [deg], absorptance and specular terms [-], and the table [1/sr] or ABg parameters.
    """
    path = str(path)
    text = read_text(path, expected="a TracePro surface property file", legacy="latin-1")
    lines = text.splitlines()
    header, index = _read_header(lines, path)
    coating = _int_value(header["Coating"], "Coating", path, int(header["Coating@line"]), range(0, 8))
    scatter = _int_value(header["Scatter"], "Scatter", path, int(header["Scatter@line"]), range(0, 9))
    if scatter not in (0, 1, 5):
        raise FormatError("scatter model not supported by bsdfkit", file=path, line=int(header["Scatter@line"]),
                          field="Scatter", expected="0 (none), 1 (ABg) or 5 (asymmetric table)", got=scatter)
    polarization = _int_value(header["Polarization"], "Polarization", path, int(header["Polarization@line"]),
                              range(0, 2))
    _int_value(header["Interaction"], "Interaction", path, int(header["Interaction@line"]), range(0, 2))
    _int_value(header["User_Data"], "User_Data", path, int(header["User_Data@line"]), range(0, 2))
    rows, surface_lines, index = _surface_rows(lines, index, path)
    temperature, wavelength, theta = rows[0, 0], rows[0, 1], rows[:, 2]
    if polarization == 0:
        absorptance, refl, tran = rows[:, 4], rows[:, 6], rows[:, 8]
    else:
        absorptance, refl, tran = rows[:, 4:6].mean(axis=1), rows[:, 6:8].mean(axis=1), rows[:, 8:10].mean(axis=1)
    tag = _ZERO_TAG.search(header["Description"])
    zero = float(tag.group(1)) if tag else (DEFAULT_ZERO_AZIMUTH_DEG if zero_azimuth_deg is None else zero_azimuth_deg)
    options = _options(header, lines, (temperature, wavelength, zero), surface_lines[0], path)
    abg = _abg(rows, surface_lines, path) if scatter == 1 else None
    table = None
    rest_start = index
    if index < len(lines) and lines[index].strip().startswith("GratingData"):
        raise FormatError("grating data are not supported", file=path, line=index + 1, field="GratingData",
                          expected="Table_BSDF_Data or SAVE-DATA", got=lines[index].strip())
    if index < len(lines) and lines[index].strip() == "Table_BSDF_Data":
        table, index = _read_table(lines, index + 1, path, temperature, wavelength, theta, surface_lines, zero)
    elif scatter == 5:
        raise FormatError("Scatter 5 needs a Table_BSDF_Data section", file=path, line=min(rest_start + 1, len(lines)),
                          field="Table_BSDF_Data", expected="'Table_BSDF_Data'",
                          got=lines[index].strip() if index < len(lines) else "end of file")
    _check_save_data(lines, index, path)
    return TraceProProperty(
        options=options, scatter=scatter, theta_i_deg=theta, absorptance=absorptance,
        specular_reflectance=refl, specular_transmittance=tran, table=table, abg=abg, coating=coating,
        solve=header["Solve"], path=path,
    )


def _read_header(lines: list[str], path: str) -> tuple[dict[str, str], int]:
    """The magic line, the four header lines and the keyword lines: keyword values (and ``key@line``, their
    1-based line) and the index of the line after them."""
    if not lines or lines[0].strip() != MAGIC:
        raise FormatError("not a TracePro surface property file", file=path, line=1, field="magic",
                          expected=repr(MAGIC), got=lines[0].strip() if lines else "")
    # lines 2-5: File Name, Release, Database Version, timestamp (only Database Version is read by TracePro)
    for index, prefix in ((1, "File Name"), (2, "TracePro Release:"), (3, "Database Version:"), (4, "Data generated")):
        if index >= len(lines) or not lines[index].strip().startswith(prefix):
            raise FormatError("missing header line", file=path, line=index + 1, field=prefix.rstrip(":"),
                              expected=f"a line starting with '{prefix}'",
                              got=lines[index].strip() if index < len(lines) else "end of file")
    index = 5
    while index < len(lines) and not lines[index].strip():
        index += 1
    header: dict[str, str] = {}
    for key in _HEADER_KEYS:
        header[key] = _keyword_value(lines, index, key, path)
        header[key + "@line"] = str(index + 1)
        index += 1
    return header, index


def _section_rows(lines: list[str], index: int, path: str, columns: Sequence[str], no_header: tuple[str, str],
                  no_rows: tuple[str, str]) -> tuple[NDArray[np.float64], list[int], int]:
    """The numeric rows under the 'Temperature ...' column header at line ``index``, their 1-based lines and the
    index after them; ``no_header``/``no_rows``: (message, field) of the one-line error when either is missing."""
    if index >= len(lines) or not lines[index].strip().startswith("Temperature"):
        raise FormatError(no_header[0], file=path, line=min(index + 1, len(lines)), field=no_header[1],
                          expected="a line starting with 'Temperature'",
                          got=lines[index].strip() if index < len(lines) else "end of file")
    texts, row_lines, index = _numeric_block(lines, index + 1)
    if not texts:
        raise FormatError(no_rows[0], file=path, line=min(index + 1, len(lines)), field=no_rows[1],
                          expected=f"rows of {len(columns)} numbers",
                          got=lines[index].strip() if index < len(lines) else "end of file")
    return _rows(texts, row_lines, columns, path), row_lines, index


def _surface_rows(lines: list[str], index: int, path: str) -> tuple[NDArray[np.float64], list[int], int]:
    """The surface-data rows from line ``index`` on (one Temperature/Wavelength, IncAngle strictly increasing in
    [0, 90)), their 1-based lines and the index of the line after them."""
    while index < len(lines) and not lines[index].strip():
        index += 1
    if index < len(lines) and lines[index].strip().startswith(("Side1_Data", "Side2_Data")):
        raise FormatError("direction-sensitive properties are not supported", file=path, line=index + 1,
                          field="Side1_Data", expected="a single-sided property", got=lines[index].strip())
    rows, surface_lines, index = _section_rows(lines, index, path, SURFACE_COLUMNS,
                                               ("missing surface-data column header", "Temperature"),
                                               ("no surface-data rows", "surface data"))
    temperature, wavelength = rows[0, 0], rows[0, 1]
    for k in range(1, rows.shape[0]):
        if rows[k, 0] != temperature or rows[k, 1] != wavelength:
            raise FormatError("several Temperature/Wavelength pairs are not supported", file=path,
                              line=surface_lines[k], field="Temperature/Wavelength",
                              expected=f"{temperature:g}/{wavelength:g}", got=f"{rows[k, 0]:g}/{rows[k, 1]:g}")
    theta = rows[:, 2]
    if np.any(np.diff(theta) <= 0):
        k = int(np.argmax(np.diff(theta) <= 0)) + 1
        raise FormatError("IncAngle rows must be strictly increasing", file=path, line=surface_lines[k],
                          field="IncAngle", expected=f"> {theta[k - 1]:g}", got=theta[k])
    if np.any(theta < 0) or np.any(theta >= 90):
        k = int(np.argmax((theta < 0) | (theta >= 90)))
        raise FormatError("incidence angle out of range", file=path, line=surface_lines[k], field="IncAngle",
                          expected="0 <= IncAngle < 90", got=theta[k])
    return rows, surface_lines, index


def _options(header: dict[str, str], lines: list[str], conditions: tuple[float, float, float], first_row_line: int,
             path: str) -> TraceProOptions:
    """The property's options from its header and ``conditions`` = (temperature [K], wavelength [µm], zero
    azimuth [deg]); an invalid value is reported on its keyword's line (else the first surface-data row's)."""
    temperature, wavelength, zero = conditions
    try:
        return TraceProOptions(
            name=header["Name"], catalog=header["Catalog"],
            description=_ZERO_TAG.sub("", header["Description"]).strip(),
            temperature_K=temperature, wavelength_um=wavelength, zero_azimuth_deg=zero,
            release=lines[2].split(":", 1)[1].strip(), database_version=lines[3].split(":", 1)[1].strip(),
            db_file_name=lines[1].strip()[len("File Name"):].strip(),
        )
    except ValidationError as exc:
        key = {"name": "Name", "catalog": "Catalog", "description": "Description"}.get(exc.field or "")
        line = int(header[key + "@line"]) if key else first_row_line
        raise FormatError("invalid header value", file=path, line=line, field=key or exc.field,
                          expected=exc.expected, got=exc.got) from None


def _abg(rows: NDArray[np.float64], surface_lines: list[int], path: str) -> xr.DataArray:
    """The ABg parameters (side, theta_i, param) of Scatter 1 surface-data rows, checked (A ≥ 0, B > 0 or B = g
    = 0)."""
    for col_a, col_b, col_g in ((12, 13, 15), (17, 18, 20)):
        bad = (rows[:, col_a] < 0) | (rows[:, col_b] < 0) | ((rows[:, col_b] == 0) & (rows[:, col_g] != 0)
                                                               & (rows[:, col_a] > 0))
        if np.any(bad):
            k = int(np.argmax(bad))
            raise FormatError("invalid ABg parameters", file=path, line=surface_lines[k],
                              field=f"{SURFACE_COLUMNS[col_a]}/{SURFACE_COLUMNS[col_b]}",
                              expected="A >= 0 and B > 0 (B = 0 only with g = 0)",
                              got=f"A={rows[k, col_a]:g}, B={rows[k, col_b]:g}, g={rows[k, col_g]:g}")
    params = np.stack([rows[:, [12, 13, 15]], rows[:, [17, 18, 20]]])
    return xr.DataArray(params, dims=("side", "theta_i", "param"),
                        coords={"side": list(SIDES), "theta_i": rows[:, 2], "param": ["A", "B", "g"]})


def _check_save_data(lines: list[str], index: int, path: str) -> None:
    """The property ends with SAVE-DATA at line ``index`` (after blank lines) and nothing follows."""
    while index < len(lines) and not lines[index].strip():
        index += 1
    # TracePro ends every property with SAVE-DATA: a file that stops before it is cut (its last rows may be lost)
    if index >= len(lines):
        raise FormatError("the file ends before 'SAVE-DATA' (truncated?)", file=path, line=len(lines),
                          field="SAVE-DATA", expected="a complete TracePro file ending with 'SAVE-DATA'")
    if lines[index].strip() != "SAVE-DATA":
        raise FormatError("unexpected line", file=path, line=index + 1, field="SAVE-DATA",
                          expected="'SAVE-DATA'", got=lines[index].strip())
    for extra in range(index + 1, len(lines)):
        if lines[extra].strip():
            raise FormatError("several properties in one file are not supported", file=path, line=extra + 1,
                              field="SAVE-DATA", expected="end of file after SAVE-DATA", got=lines[extra].strip())


def _read_table(
    lines: list[str], index: int, path: str, temperature: float, wavelength: float,
    theta: NDArray[np.float64], surface_lines: list[int], zero: float,
) -> tuple[xr.DataArray, int]:
    while index < len(lines) and not lines[index].strip():
        index += 1
    rows, row_lines, index = _section_rows(lines, index, path, TABLE_COLUMNS,
                                           ("missing Table_BSDF_Data column header", "Table_BSDF_Data"),
                                           ("empty Table_BSDF_Data section", "Table_BSDF_Data"))
    bad = (rows[:, 0] != temperature) | (rows[:, 1] != wavelength)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise FormatError("table Temperature/Wavelength differ from the surface data", file=path,
                          line=row_lines[k], field="Temperature/Wavelength",
                          expected=f"{temperature:g}/{wavelength:g}", got=f"{rows[k, 0]:g}/{rows[k, 1]:g}")
    bad = (rows[:, 4] < 0) | (rows[:, 4] > 2)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise FormatError("ScatterBeta out of range", file=path, line=row_lines[k], field="ScatterBeta",
                          expected="0 <= |beta-beta0| <= 2", got=rows[k, 4])
    for col, name in ((6, "BRDF"), (7, "BTDF")):
        if np.any(rows[:, col] < 0):
            k = int(np.argmax(rows[:, col] < 0))
            raise FormatError("negative BSDF", file=path, line=row_lines[k], field=name, expected=">= 0",
                              got=rows[k, col])
    inc = np.unique(rows[:, 2])
    beta = np.unique(rows[:, 4])
    azimuth = np.unique(np.mod(rows[:, 5], 360.0))
    missing_inc = [t for t in inc if not np.any(theta == t)]
    if missing_inc:
        k = int(np.argmax(rows[:, 2] == missing_inc[0]))
        raise FormatError("table IncAngle has no surface-data row", file=path, line=row_lines[k], field="IncAngle",
                          expected=f"one of {theta.tolist()}", got=missing_inc[0])
    if inc.size != theta.size:
        absent = [t for t in theta if not np.any(inc == t)][0]
        raise FormatError("surface-data IncAngle has no table rows", file=path,
                          line=surface_lines[int(np.argmax(theta == absent))], field="IncAngle",
                          expected="table rows for every IncAngle", got=absent)
    expected = inc.size * beta.size * azimuth.size
    t_idx = np.searchsorted(inc, rows[:, 2])
    b_idx = np.searchsorted(beta, rows[:, 4])
    a_idx = np.searchsorted(azimuth, np.mod(rows[:, 5], 360.0))
    flat = (t_idx * beta.size + b_idx) * azimuth.size + a_idx
    order = np.argsort(flat, kind="stable")
    repeat = np.flatnonzero(np.diff(flat[order]) == 0)
    if repeat.size:
        first, second = sorted((int(order[repeat[0]]), int(order[repeat[0] + 1])))
        raise FormatError("duplicate table row", file=path, line=row_lines[second],
                          field="IncAngle/ScatterBeta/ScatterAzimuth",
                          expected="each combination once", got=f"same cell as line {row_lines[first]}")
    seen = np.full(expected, -1)
    seen[flat] = np.arange(flat.size)
    if rows.shape[0] != expected:
        hole = int(np.argmax(seen < 0))
        t, rest = divmod(hole, beta.size * azimuth.size)
        b, a = divmod(rest, azimuth.size)
        raise FormatError(
            f"table is not rectangular: {rows.shape[0]} rows for {inc.size} IncAngle x {beta.size} ScatterBeta x "
            f"{azimuth.size} ScatterAzimuth", file=path, line=row_lines[-1], field="Table_BSDF_Data",
            expected=f"{expected} rows", got=f"no row for IncAngle {inc[t]:g}, ScatterBeta {beta[b]:g}, "
                                             f"ScatterAzimuth {azimuth[a]:g}",
        )
    data = np.zeros((2, inc.size, beta.size, azimuth.size))
    data[0].reshape(-1)[flat] = rows[:, 6]
    data[1].reshape(-1)[flat] = rows[:, 7]
    table = xr.DataArray(
        data, dims=("side", "theta_i", "rho", "psi"),
        coords={"side": list(SIDES), "theta_i": inc, "rho": beta, "psi": azimuth},
        name="bsdf", attrs={"units": "1/sr", "frame": "harvey_shack", "zero_azimuth_deg": zero},
    )
    return table, index



# ------------------------------------------------------------------------------------------- registry hooks
def _as_floats(values: ArrayLike) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]


def _abg_rows(params: Sequence[Any], side: str, theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """(A, B, g) per exported incidence for ``side`` from the fit's ABg parameter list."""
    rows = []
    for t in theta:
        match = [p for p in params if p.side == side and abs(p.theta_i_deg - t) <= 1e-9]
        if not match:
            raise ValidationError("no fitted ABg parameters at this incidence", field="theta_i",
                                  expected=f"one of {sorted({p.theta_i_deg for p in params})}", got=float(t))
        rows.append([match[0].a, match[0].b, match[0].g])
    return np.array(rows)


def _write_job(job: WriteJob) -> WriteOutcome:
    """Both sides in one file (BRDF and BTDF columns; a side not exported is zero): Scatter 5 table or Scatter 1
    ABg (ABg fit results only)."""
    settings, opts = job.settings, job.settings.tracepro
    axes, info = None, {"mode": "none (TracePro ABg property)"}
    if settings.tracepro_scatter == "abg":
        if not job.abg:
            raise ValidationError("TracePro ABg export needs an ABg fit result", field="tracepro_scatter",
                                  expected="table for this source", got="abg")
        by_side = {s: _abg_rows(job.abg, s, job.theta) for s in job.sides}
        prop = abg_property(job.theta, by_side.get("reflection"), by_side.get("transmission"), options=opts,
                            specular_reflectance=settings.specular_reflectance,
                            specular_transmittance=settings.specular_transmittance,
                            scatter_excess_allowed=job.tis_excess_allowed)
    else:
        axes, info = axes_choice.harvey_shack_axes(job.fn, job.theta, job.sides, settings, opts.zero_azimuth_deg)
        grid = axes_choice.harvey_shack_table(job.fn, job.theta, job.sides, axes, info, settings)
        prop = table_property(grid, options=opts, specular_reflectance=settings.specular_reflectance,
                              specular_transmittance=settings.specular_transmittance,
                              scatter_excess_allowed=job.tis_excess_allowed)
    write_tracepro(job.path, prop, force=job.force, generated_at=job.generated_at)
    return WriteOutcome(axes, info)


def _summarise(path: str) -> FileSummary:
    return _summary(read_tracepro(path), path)


def _vendor_table(path: str) -> VendorTable:
    return _table(read_tracepro(path), path)


def _summary_and_table(path: str) -> tuple[FileSummary, VendorTable | None]:
    prop = read_tracepro(path)
    return _summary(prop, path), (_table(prop, path) if prop.scatter == 5 else None)


def _summary(prop: TraceProProperty, path: str) -> FileSummary:
    computed = prop.tis_computed()
    theta = prop.theta_i_deg
    if prop.table is not None:
        theta = prop.table["theta_i"].values
    return FileSummary(
        format="tracepro", path=path, incidences_deg=_as_floats(theta),
        tis_computed={**{s: _as_floats(v) for s, v in computed.items()}, "total": _as_floats(sum(computed.values()))},
        tis_stated={"total": _as_floats(prop.tis_stated())},
        details={"scatter": prop.scatter, "name": prop.options.name,
                 "zero_azimuth_deg": prop.options.zero_azimuth_deg,
                 "absorptance": _as_floats(prop.absorptance),
                 "table_shape": None if prop.table is None else dict(prop.table.sizes),
                 **({} if prop.scatter == 5 else
                    {"tis_rule": "the model's own integral (a TracePro ABg property holds no table)"})},
    )


def _table(prop: TraceProProperty, path: str) -> VendorTable:
    if prop.scatter != 5 or prop.table is None:
        raise FormatError("only TracePro tables (Scatter 5) can be read as data", file=path, field="Scatter",
                          expected="5 (asymmetric table)", got=prop.scatter)
    table = prop.table
    out = []
    for side in [str(s) for s in table["side"].values]:
        v = np.asarray(table.sel(side=side).values, dtype=np.float64)  # (theta, rho, psi)
        if not np.any(v):
            continue  # TracePro writes both columns; a side that is all zero was not given
        out.append(VendorGrid("harvey_shack", side, np.asarray(table["theta_i"].values, dtype=np.float64),
                              np.asarray(table["rho"].values, dtype=np.float64),
                              np.asarray(table["psi"].values, dtype=np.float64), np.moveaxis(v, -1, -2),
                              zero_azimuth_deg=float(prop.options.zero_azimuth_deg)))
    if not out:
        raise FormatError("the TracePro table is zero everywhere", file=path, field="Table_BSDF_Data",
                          expected="some non-zero BRDF or BTDF")
    return VendorTable("tracepro", tuple(out), 1000.0 * float(prop.options.wavelength_um),
                       {"name": prop.options.name, "zero_azimuth_deg": prop.options.zero_azimuth_deg})


FORMAT = TableFormat(name="tracepro", title="TracePro", extensions=(".txt",), guess_can_open=first_line_is(MAGIC),
                     summarise=_summarise, vendor_table=_vendor_table, summary_and_table=_summary_and_table,
                     write=_write_job, sides_per_file=2,
                     grid_kind="harvey_shack")
