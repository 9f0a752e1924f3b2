"""Ansys Speos "complete scattering" surface file (``*.brdf``, spectral, isotropic, text mode): writer and reader.

Layout (one item per line; tabs between numbers)::

    OPTIS - brdf surface file v8.0
    0                                   text mode
    <comment>                           bsdfkit writes "bsdfkit <version>"
    <number of characters of the description>
    <description>
    bReflection  bTransmission
    1                                   1: values proportional to the BSDF (0: to BSDF·cos θ)
    nIncidence  nWavelength
    <incidences, deg>
    <wavelengths, nm>
    [per side present (reflection first), incidence, wavelength (inner):]
    <percent>                           the table's reflectance (transmittance) in percent
    nTheta  nPhi
    TAB + phi list
    one row per theta: theta then nPhi values (transmission: theta 90..180)
    End of file

Angles [deg] as in :mod:`bsdfkit.tables.formats.speos`: about the normal, X the projection of the incoming
direction, specular at (θi, 0), straight-through at (180° − θi, 0) — bsdfkit's own frame.

**Normalisation (the format's rule).** Each table has its own percentage: Speos scales every table so that its
integral equals it. The reader applies this with the hemispherical engine for every table
(``VendorTable.normalise_each``): BSDF = v · R / TIS_engine(v) per side and incidence.

**Spectral rule.** The file holds a table per wavelength. bsdfkit writes one wavelength (the exported one; a
one-wavelength file). Reading a file with several wavelengths, ``read`` reports the stated percentages of every
wavelength (``details['stated_percent']``) and bsdfkit's dataset (``ingest``, ``read``'s computed TIS) takes the
wavelength nearest 555 nm (the photopic peak), stated in ``details['wavelength_nm']``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.conventions import PHOTOPIC_NM, SIDES, WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.core.version import __version__
from bsdfkit.io import atomic
from bsdfkit.io.text import read_text
from bsdfkit.tables import grids, normal_axes
from bsdfkit.tables.format_spec import (
    FileSummary,
    TableFormat,
    VendorGrid,
    VendorTable,
    WriteJob,
    WriteOutcome,
    first_line_is,
)
from bsdfkit.tables.formats.speos import Lines, speos_nodes

__all__ = ["MAGIC", "SpeosBrdf", "read_speos_brdf", "write_speos_brdf"]

MAGIC = "OPTIS - brdf surface file v8.0"
_VALUE_FMT = ".7g"


@dataclass(frozen=True, eq=False)
class SpeosBrdf:
    """Incidences [deg], wavelengths [nm], theta [deg, 0..90 for both sides] and phi [deg] axes; per side the
    tables (incidence, wavelength, theta, phi) as written and the stated percentages (incidence, wavelength)."""

    incidences: NDArray[np.float64]
    wavelengths: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    tables: dict[str, NDArray[np.float64]]
    percent: dict[str, NDArray[np.float64]]
    intensity: bool = False
    comment: str = ""


def speos_brdf(fn: grids.BsdfFn, theta_i_deg: NDArray[np.float64], sides: tuple[str, ...],
               wavelength_nm: float | None,
               axes: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None) -> SpeosBrdf:
    """One-wavelength tables of a BSDF callable on ``axes`` (θs, φs [deg] in [0, 360); default: the fixed grid; the
    φ = 360° column repeating 0° is added); the percentages are the source's direct integrals.

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_i_deg : ndarray
        Incidences [deg].
    sides : tuple of str
        ``reflection`` and/or ``transmission``.
    wavelength_nm : float or None
        The table's wavelength [nm] (None: 550 nm).
    axes : tuple of ndarray, optional
        (θs [deg], φs [deg]) axes.

    Returns
    -------
    SpeosBrdf
        Tables [1/sr] and percentages (100 × TIS).
    """
    theta_i = np.asarray(theta_i_deg, dtype=np.float64)
    theta, phi, _ = speos_nodes(axes)
    tables, percent = {}, {}
    for side in sides:
        tables[side] = np.stack([normal_axes.node_values(fn, float(t), side, theta, phi).T for t in theta_i])[:, None]
        percent[side] = np.array([[100.0 * grids.tis_reference(fn, float(t), side)] for t in theta_i])
        over = np.flatnonzero(percent[side][:, 0] > 100.0)
        if over.size:  # the format states 0..100 % per table (its reader refuses more): refused before writing
            k = int(over[0])
            raise ValidationError("a Speos .brdf file cannot hold this non-physical source (each table states its "
                                  "percentage, at most 100 %)", field=f"{side} at theta_i={theta_i[k]:g} deg",
                                  expected="<= 100 %", got=f"{percent[side][k, 0]:.4g} %")
    lam = np.array([550.0 if wavelength_nm is None else float(wavelength_nm)])
    return SpeosBrdf(theta_i, lam, theta, phi, tables, percent, comment=f"bsdfkit {__version__}")


def speos_brdf_text(b: SpeosBrdf) -> str:
    """The file text of ``b`` (values to 7 significant digits).

    Parameters
    ----------
    b : SpeosBrdf
        The tables.

    Returns
    -------
    str
        The ``.brdf`` text.
    """
    sides = [s for s in SIDES if s in b.tables]
    description = "bsdfkit export"
    out = [MAGIC, "0", b.comment, str(len(description)), description,
           f"{int('reflection' in sides)}\t{int('transmission' in sides)}", "0" if b.intensity else "1",
           f"{b.incidences.size}\t{b.wavelengths.size}", " ".join(f"{t:g}" for t in b.incidences),
           " ".join(f"{w:g}" for w in b.wavelengths)]
    for s in sides:
        rows = b.theta if s == "reflection" else 180.0 - b.theta[::-1]
        for k in range(b.incidences.size):
            for j in range(b.wavelengths.size):
                table = b.tables[s][k, j] if s == "reflection" else b.tables[s][k, j][::-1]
                out += [f"{b.percent[s][k, j]:{_VALUE_FMT}}", f"{b.theta.size}\t{b.phi.size}",
                        "\t" + "\t".join(f"{p:g}" for p in b.phi)]
                out += [f"{r:g}\t" + "\t".join(format(float(v), _VALUE_FMT) for v in row)
                        for r, row in zip(rows, table)]
    out += ["End of file", ""]
    return "\n".join(out)


def write_speos_brdf(path: str | Path, b: SpeosBrdf, *, force: bool = False) -> Path:
    """Write atomically; an existing file is replaced only with ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    b : SpeosBrdf
        The tables.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        The file written.
    """
    return atomic.write_text(path, speos_brdf_text(b), force=force)


def _wavelengths_nm(r: Lines, n_wl: int) -> NDArray[np.float64]:
    """The wavelength line [nm]: FormatError naming the file, line and column of a value outside
    :data:`bsdfkit.core.conventions.WAVELENGTH_RANGE_NM` (a grid in metres or micrometres: the file's own field, not
    an option of the command)."""
    lam = r.numbers("wavelengths", n_wl)
    lo, hi = WAVELENGTH_RANGE_NM
    out = np.flatnonzero((lam < lo) | (lam > hi))
    if out.size:
        v = float(lam[out[0]])
        if v <= 0:
            looks = "it is not positive"
        elif v < 1e-4:
            looks = "it looks like metres (5.5e-07 = 550 nm)"
        elif v < 30.0:
            looks = "it looks like micrometres (0.55 = 550 nm)"
        else:
            looks = "it is not in nanometres"
        raise FormatError(f"wavelength in column {out[0] + 1} out of range: the format states nm, {looks}",
                          file=r.path, line=r.k, field="wavelengths", expected=f"a wavelength in nm, {lo:g}..{hi:g}",
                          got=v)
    return lam


def read_speos_brdf(path: str | Path) -> SpeosBrdf:
    """Read a text ``*.brdf``. FormatError names the file, line and field.

    Parameters
    ----------
    path : str or Path
        The ``.brdf`` file.

    Returns
    -------
    SpeosBrdf
        Incidences and axes [deg], wavelengths [nm], tables as written, stated percentages.
    """
    path = str(path)
    r = Lines(read_text(path, expected="a Speos .brdf file", legacy="latin-1"), path)
    first = r.next("header").strip()
    if first != MAGIC:
        raise FormatError("not a Speos brdf v8.0 file", file=path, line=1, field="header", expected=MAGIC,
                          got=first[:60])
    if r.integer("text/binary flag", 0, 1) != 0:
        raise FormatError("binary Speos files are not read", file=path, line=2, field="mode", expected="0 (text)",
                          got=1)
    comment = r.next("comment").strip()
    r.integer("description length", 0, 10**6)
    r.next("description")
    flags = r.numbers("bReflection bTransmission", 2)
    sides = [s for s, f in zip(SIDES, flags) if f == 1]
    if not sides or not np.all(np.isin(flags, (0, 1))):
        raise FormatError("no side flagged", file=path, line=r.k, field="bReflection bTransmission",
                          expected="1 for at least one side", got=" ".join(f"{f:g}" for f in flags))
    intensity = r.integer("BSDF/intensity flag", 0, 1) == 0
    n_inc, n_wl = (int(v) for v in r.numbers("nIncidence nWavelength", 2))
    inc = r.numbers("incidences", n_inc)
    if np.any((inc < 0) | (inc >= 90)) or np.any(np.diff(inc) <= 0):
        raise FormatError("incidences must increase within [0, 90) deg", file=path, line=r.k, field="incidences",
                          expected="increasing angles in [0, 90)", got=" ".join(f"{v:g}" for v in inc)[:60])
    lam = _wavelengths_nm(r, n_wl)
    theta = phi = None
    tables, percent = {}, {}
    for s in sides:
        t_s = np.zeros((n_inc, n_wl), dtype=object)
        pct = np.zeros((n_inc, n_wl))
        for k, t in enumerate(inc):
            for j, w in enumerate(lam):
                where = f"{s} table at theta_i={t:g}, {w:g} nm"
                pct[k, j] = r.numbers(f"{where}: percent", 1)[0]
                if not 0 <= pct[k, j] <= 100:
                    raise FormatError("percentage out of range", file=path, line=r.k, field=f"{where}: percent",
                                      expected="0..100 %", got=float(pct[k, j]))
                n_theta, n_phi = (int(v) for v in r.numbers(f"{where}: nTheta nPhi", 2))
                ph = r.numbers(f"{where}: phi list", n_phi)
                rows = np.array([r.numbers(f"{where}: row", n_phi + 1) for _ in range(n_theta)])
                th, values = rows[:, 0], rows[:, 1:]
                if s == "transmission":
                    if np.any(th < 90 - 1e-9):
                        raise FormatError("transmission rows must be at theta 90..180", file=path, line=r.k,
                                          field=where, expected="theta in [90, 180] deg", got=float(th.min()))
                    th, values = 180.0 - th[::-1], values[::-1]
                if np.any(np.diff(th) <= 0) or th.min() < 0 or th.max() > 90 + 1e-9 or np.any(values < 0):
                    raise FormatError("table rows not increasing within the hemisphere or negative", file=path,
                                      line=r.k, field=where, expected="increasing theta in [0, 90] deg, values >= 0")
                if intensity:
                    c = np.cos(np.radians(th))
                    values = values / np.where(c > 1e-9, c, 1.0)[:, None]
                    for m in np.flatnonzero(c <= 1e-9):
                        values[m] = values[m - 1] if m > 0 else 0.0
                if theta is not None and (theta.shape != th.shape or not np.allclose(theta, th)
                                          or phi.shape != ph.shape or not np.allclose(phi, ph)):
                    raise FormatError("tables on different grids are not supported", file=path, line=r.k,
                                      field=where, expected="the grid of the first table")
                theta, phi = th, ph
                t_s[k, j] = values
        tables[s] = np.array([[t_s[k, j] for j in range(n_wl)] for k in range(n_inc)], dtype=np.float64)
        percent[s] = pct
    return SpeosBrdf(inc, lam, theta, phi, tables, percent, intensity, comment)


# ------------------------------------------------------------------------------------------- registry hooks
def _write_job(job: WriteJob) -> WriteOutcome:
    theta_i = np.asarray(job.theta, dtype=np.float64)
    theta, phi, info = normal_axes.normal_axes(job.fn, theta_i, job.sides, job.settings)
    b = speos_brdf(job.fn, theta_i, tuple(job.sides), job.settings.wavelength_nm, axes=(theta, phi))
    write_speos_brdf(job.path, b, force=job.force)
    return WriteOutcome(None, normal_axes.describe(info, b.theta.size, b.phi.size))


def _chosen(b: SpeosBrdf) -> int:
    return int(np.argmin(np.abs(b.wavelengths - PHOTOPIC_NM)))


def _summarise(path: str) -> FileSummary:
    b = read_speos_brdf(path)
    j = _chosen(b)
    theta = [float(t) for t in b.incidences]
    return FileSummary(format="speosbrdf", path=path, incidences_deg=theta,
                       tis_computed={s: [float("nan")] * len(theta) for s in b.tables},
                       tis_stated={s: [float(v) / 100.0 for v in b.percent[s][:, j]] for s in b.tables},
                       details={"own_quadrature": False, "wavelength_nm": float(b.wavelengths[j]),
                                "wavelengths_nm": [float(w) for w in b.wavelengths], "comment": b.comment,
                                "stated_percent": {s: b.percent[s].tolist() for s in b.tables},
                                "normalisation": "every table is scaled so that its hemispherical integral equals "
                                                 "its stated percentage"})


def _vendor_table(path: str) -> VendorTable:
    b = read_speos_brdf(path)
    j = _chosen(b)
    th, ph = np.meshgrid(b.theta, b.phi, indexing="ij")
    keep = (ph < 360.0 - 1e-9) | (th < 1e-9)
    out = [VendorGrid("directions", s, b.incidences, th[keep], ph[keep], b.tables[s][:, j][:, keep])
           for s in b.tables]
    each = {s: [(float(t), float(b.percent[s][k, j]) / 100.0) for k, t in enumerate(b.incidences)] for s in b.tables}
    return VendorTable("speosbrdf", tuple(out), float(b.wavelengths[j]), {"comment": b.comment},
                       normalise_each=each)


FORMAT = TableFormat(name="speosbrdf", title="Speos spectral .brdf (text)", extensions=(".brdf",),
                     guess_can_open=first_line_is(MAGIC), summarise=_summarise, vendor_table=_vendor_table,
                     write=_write_job, sides_per_file=2, grid_kind="normal")
