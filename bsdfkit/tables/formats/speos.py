"""Ansys Speos anisotropic BSDF surface file (``*.anisotropicbsdf``, text mode): writer and reader.

Layout (one item per line; tabs between numbers)::

    OPTIS - Anisotropic BSDF surface file v8.0
    0                                   text mode (1 = binary, not read)
    <comment>                           bsdfkit writes "bsdfkit <version> wavelength_nm=<λ>"
    <number of characters of the description>
    <description>
    0  1  0                             anisotropy vector
    bReflection  bTransmission          1/0 each
    1                                   1: values proportional to the BSDF (0: to BSDF·cos θ, the intensity)
    [per side present, R first] number of anisotropy angles (1) / their list / number of incidences / incidences
    [per side present] theta phi of the spectrum measurement / description line / number of wavelengths /
                       one "wavelength_nm <TAB> percent" line per wavelength
    [per side, anisotropy angle, incidence] "nTheta nPhi" / TAB + phi list / one row per theta: theta then values
    End of file

Angles [deg] about the surface normal, in the frame whose X axis is the projection of the incoming direction on
the surface: the specular direction of incidence θi is (θ, φ) = (θi, 0), the straight-through direction
(180° − θi, 0); transmission rows run over θ = 90°…180°. bsdfkit's frame (source at azimuth 180°, specular at
φs = 0) is the same frame; a transmission row θ is bsdfkit's θs = 180° − θ.

**Normalisation (the format's rule).** Speos rescales the table so that its integral at the incidence of the
spectrum measurement equals the spectrum's reflectance (transmittance): only the shape of the table and the
percentages are data. The reader applies that rule with bsdfkit's hemispherical engine
(:class:`bsdfkit.tables.format_spec.VendorTable` ``normalise``): BSDF = v · R / TIS_engine(v) at that incidence,
every incidence of the side alike. The writer writes the BSDF itself (row 8 = 1) and the TIS of the source at
its first incidence as the spectrum, so a bsdfkit file reads back at its own scale (a source above 1 there, written
past the plausibility gate of :mod:`bsdfkit.tables.plausible`, states the first incidence at most 1; above 1 at
every incidence it is refused: the percentage cannot exceed 100 %).

**Spectral rule.** The file holds one table per incidence for all wavelengths; the spectrum scales it. bsdfkit
writes the BSDF at one wavelength (the exported one, in the comment) and a flat spectrum (350 and 850 nm at the
same percentage): Speos then treats the sample as grey. A spectral sample needs one file per wavelength (or the
``.brdf`` of :mod:`bsdfkit.tables.formats.speosbrdf`, also one wavelength per file as bsdfkit writes it).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.conventions import SIDES, WAVELENGTH_RANGE_NM
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

__all__ = ["MAGIC", "SpeosBsdf", "read_speos", "speos_text", "write_speos"]

MAGIC = "OPTIS - Anisotropic BSDF surface file v8.0"
_WAVELENGTH_TAG = re.compile(r"wavelength_nm=([-+0-9.eE]+)")
_VALUE_FMT = ".7g"


@dataclass(frozen=True, eq=False)
class SpeosBsdf:
    """One anisotropic BSDF file: per side, the incidences [deg], the theta [deg, about the normal, 0..90 for
    both sides] and phi [deg] axes and the tables (incidence, theta, phi) as written (proportional to the BSDF);
    the spectrum incidence [deg] and its mean percentage per side."""

    incidences: dict[str, NDArray[np.float64]]
    theta: dict[str, NDArray[np.float64]]
    phi: dict[str, NDArray[np.float64]]
    tables: dict[str, NDArray[np.float64]]
    spectrum: dict[str, tuple[float, float]]  # side -> (theta_i of the spectrum [deg], mean percent)
    intensity: bool = False  # row 8 = 0: the values are BSDF * cos(theta)
    comment: str = ""
    description: str = ""
    wavelength_nm: float | None = None


def speos_nodes(axes: tuple[NDArray[np.float64], NDArray[np.float64]] | None
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """θs, φs [deg] written (``axes``, default the fixed grid :func:`bsdfkit.tables.normal_axes.fixed_normal_axes`,
    with the φ = 360° column repeating 0° that both Speos formats write) and their directions (θ, φ, 3).

    Parameters
    ----------
    axes : tuple of ndarray or None
        (θs [deg], φs [deg]) axes; None: the fixed grid.

    Returns
    -------
    theta, phi : ndarray
        The axes written [deg].
    directions : ndarray
        (θ, φ, 3) unit directions [-].
    """
    theta, phi = axes if axes is not None else normal_axes.fixed_normal_axes()
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.append(np.asarray(phi, dtype=np.float64), 360.0)
    return theta, phi, normal_axes.normal_directions(theta, phi).swapaxes(0, 1)


def speos_bsdf(fn: grids.BsdfFn, theta_i_deg: NDArray[np.float64], sides: tuple[str, ...], *,
               wavelength_nm: float | None = None, description: str = "bsdfkit export",
               axes: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None) -> SpeosBsdf:
    """Tables of a BSDF callable on ``axes`` (θs, φs [deg] in [0, 360); default: the fixed grid; the φ = 360° column
    repeating 0° is added); the spectrum is the source's TIS at its first incidence
    (:func:`bsdfkit.tables.grids.tis_reference`, the direct integral), or at the first incidence where it is at
    most 1 (the percentage the format can state).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_i_deg : ndarray
        Incidences [deg].
    sides : tuple of str
        ``reflection`` and/or ``transmission``.
    wavelength_nm : float, optional
        Wavelength noted in the comment line [nm].
    description : str
        The file's description.
    axes : tuple of ndarray, optional
        (θs [deg], φs [deg]) axes.

    Returns
    -------
    SpeosBsdf
        Tables [1/sr] and the spectrum (incidence [deg], TIS in per cent).
    """
    theta_i = np.asarray(theta_i_deg, dtype=np.float64)
    theta, phi, _ = speos_nodes(axes)
    tables, spectrum = {}, {}
    for side in sides:
        tables[side] = np.stack([normal_axes.node_values(fn, float(t), side, theta, phi).T for t in theta_i])
        spectrum[side] = _spectrum(fn, theta_i, side)
    return SpeosBsdf({s: theta_i for s in sides}, {s: theta for s in sides}, {s: phi for s in sides}, tables,
                     spectrum, comment=f"bsdfkit {__version__}" + (f" wavelength_nm={wavelength_nm:g}"
                                                                    if wavelength_nm is not None else ""),
                     description=description, wavelength_nm=wavelength_nm)


def _spectrum(fn: grids.BsdfFn, theta_i: NDArray[np.float64], side: str) -> tuple[float, float]:
    """The spectrum of ``side``: (incidence [deg], TIS [%]) at the first incidence whose TIS the format can state.

    The percentage is 0..100 % (Speos's rule; the reader refuses more), and the whole side is scaled to it: a
    source above 1 there (written only past the plausibility gate, ``allow_nonphysical``) takes the spectrum at the
    first incidence at most 1, so that every table still reads back at its own scale. A side above 1 at every
    incidence cannot be written: refused before anything is written.
    """
    values = []
    for t in theta_i:
        pct = 100.0 * grids.tis_reference(fn, float(t), side)
        if float(format(pct, _VALUE_FMT)) <= 100.0:
            return float(t), pct
        values.append(pct)
    raise ValidationError("the Speos anisotropic BSDF format cannot hold this source: it states each side's "
                          "hemispherical value as a percentage of 0..100 % at one incidence, and the source is "
                          "above 1 at every incidence", field=f"{side}: spectrum",
                          expected="a hemispherical value <= 1 at one incidence at least",
                          got=round(min(values) / 100.0, 6))


def speos_text(bsdf: SpeosBsdf) -> str:
    """The file text of ``bsdf`` (values to 7 significant digits; a flat spectrum at the stated percentage).

    Parameters
    ----------
    bsdf : SpeosBsdf
        The tables.

    Returns
    -------
    str
        The ``.anisotropicbsdf`` text.
    """
    sides = [s for s in SIDES if s in bsdf.tables]
    out = [MAGIC, "0", bsdf.comment, str(len(bsdf.description)), bsdf.description, "0\t1\t0",
           f"{int('reflection' in sides)}\t{int('transmission' in sides)}", "0" if bsdf.intensity else "1"]
    for s in sides:
        out += ["1", "0.0\t", str(bsdf.incidences[s].size), "\t".join(f"{t:g}" for t in bsdf.incidences[s]) + "\t"]
    for s in sides:
        t0, pct = bsdf.spectrum[s]
        out += [f"{t0:g}\t0", "", "2", f"350\t{pct:{_VALUE_FMT}}", f"850\t{pct:{_VALUE_FMT}}"]
    for s in sides:
        theta, phi = bsdf.theta[s], bsdf.phi[s]
        rows = theta if s == "reflection" else 180.0 - theta[::-1]
        for k in range(bsdf.incidences[s].size):
            table = bsdf.tables[s][k] if s == "reflection" else bsdf.tables[s][k][::-1]
            out += [f"{theta.size} {phi.size}", "\t" + "\t".join(f"{p:g}" for p in phi) + "\t"]
            out += [f"{r:g}\t" + "\t".join(format(float(v), _VALUE_FMT) for v in row) for r, row in zip(rows, table)]
    out += ["End of file", ""]
    return "\n".join(out)


def write_speos(path: str | Path, bsdf: SpeosBsdf, *, force: bool = False) -> Path:
    """Write atomically; an existing file is replaced only with ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    bsdf : SpeosBsdf
        The tables.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        The file written.
    """
    return atomic.write_text(path, speos_text(bsdf), force=force)


# ------------------------------------------------------------------------------------------- reader
class Lines:
    """Line reader of the Speos text files: FormatError names the file, line and field."""

    def __init__(self, text: str, path: str) -> None:
        self.lines = text.splitlines()
        self.k = 0
        self.path = path

    def next(self, what: str) -> str:
        """The next line (FormatError at the end of the file).

        Parameters
        ----------
        what : str
            The field expected, named in errors.

        Returns
        -------
        str
            The line.
        """
        if self.k >= len(self.lines):
            raise FormatError("file ends early", file=self.path, line=self.k + 1, field=what, expected=what,
                              got="end of file")
        self.k += 1
        return self.lines[self.k - 1]

    def numbers(self, what: str, count: int | None = None) -> NDArray[np.float64]:
        """The numbers of the next line, all finite (FormatError otherwise).

        Parameters
        ----------
        what : str
            The field expected, named in errors.
        count : int, optional
            Required number of values.

        Returns
        -------
        ndarray
            The values.
        """
        tokens = self.next(what).split()
        values = np.full(len(tokens), np.nan)
        for j, token in enumerate(tokens):
            try:
                values[j] = float(token)
            except ValueError:
                raise FormatError(f"not a number in column {j + 1}", file=self.path, line=self.k, field=what,
                                  expected="numbers", got=token[:40]) from None
            if not np.isfinite(values[j]):
                raise FormatError(f"value not finite in column {j + 1}", file=self.path, line=self.k, field=what,
                                  expected="finite numbers", got=token[:40])
        if count is not None and values.size != count:
            raise FormatError("wrong number of values", file=self.path, line=self.k, field=what,
                              expected=f"{count} numbers", got=values.size)
        return values

    def integer(self, what: str, lo: int, hi: int) -> int:
        """The next line as one integer in [lo, hi] (FormatError otherwise).

        Parameters
        ----------
        what : str
            The field expected, named in errors.
        lo, hi : int
            Inclusive bounds.

        Returns
        -------
        int
            The value.
        """
        v = self.numbers(what, 1)[0]
        if v != int(v) or not lo <= v <= hi:
            raise FormatError("integer out of range", file=self.path, line=self.k, field=what,
                              expected=f"an integer in [{lo}, {hi}]", got=float(v))
        return int(v)


def read_speos(path: str | Path) -> SpeosBsdf:
    """Read a text ``*.anisotropicbsdf`` (one anisotropy angle). FormatError names the file, line and field.

    Parameters
    ----------
    path : str or Path
        The ``.anisotropicbsdf`` file.

    Returns
    -------
    SpeosBsdf
        Axes and incidences [deg], tables as written, spectrum (incidence [deg], per cent).
    """
    path = str(path)
    r = Lines(read_text(path, expected="a Speos anisotropic BSDF file", legacy="latin-1"), path)
    first = r.next("header").strip()
    if first != MAGIC:
        raise FormatError("not a Speos anisotropic BSDF v8.0 file", file=path, line=1, field="header",
                          expected=MAGIC, got=first[:60])
    if r.integer("text/binary flag", 0, 1) != 0:
        raise FormatError("binary Speos files are not read", file=path, line=2, field="mode", expected="0 (text)",
                          got=1)
    comment = r.next("comment").strip()
    r.integer("description length", 0, 10**6)
    description = r.next("description").strip()
    r.numbers("anisotropy vector", 3)
    flags = r.numbers("bReflection bTransmission", 2)
    sides = [s for s, f in zip(SIDES, flags) if f == 1]
    if not sides or not np.all(np.isin(flags, (0, 1))):
        raise FormatError("no side flagged", file=path, line=r.k, field="bReflection bTransmission",
                          expected="1 for at least one side", got=" ".join(f"{f:g}" for f in flags))
    intensity = r.integer("BSDF/intensity flag", 0, 1) == 0
    incidences = {}
    for s in sides:
        n_aniso = r.integer(f"{s}: number of anisotropy angles", 1, 10**4)
        if n_aniso != 1:
            raise FormatError("several anisotropy angles are not supported", file=path, line=r.k,
                              field=f"{s}: anisotropy angles", expected="1", got=n_aniso)
        r.numbers(f"{s}: anisotropy angles", 1)
        n_inc = r.integer(f"{s}: number of incidences", 1, 10**4)
        inc = r.numbers(f"{s}: incidences", n_inc)
        if np.any((inc < 0) | (inc >= 90)):
            raise FormatError("incidence out of range", file=path, line=r.k, field=f"{s}: incidences",
                              expected="[0, 90) deg", got=float(inc[(inc < 0) | (inc >= 90)][0]))
        incidences[s] = inc
    spectrum = {}
    for s in sides:
        t0 = r.numbers(f"{s}: spectrum incidence", 2)[0]
        r.next(f"{s}: spectrum description")
        n_wl = r.integer(f"{s}: number of wavelengths", 1, 10**6)
        pct = np.array([r.numbers(f"{s}: spectrum line", 2)[1] for _ in range(n_wl)])
        if np.any(pct < 0) or np.any(pct > 100):
            raise FormatError("percentage out of range", file=path, line=r.k, field=f"{s}: spectrum",
                              expected="0..100 %", got=float(pct[(pct < 0) | (pct > 100)][0]))
        spectrum[s] = (float(t0), float(np.mean(pct)))
    theta, phi, tables = {}, {}, {}
    for s in sides:
        blocks = []
        for t in incidences[s]:
            where = f"{s} table at theta_i={t:g}"
            n_theta, n_phi = (int(v) for v in r.numbers(f"{where}: nTheta nPhi", 2))
            ph = r.numbers(f"{where}: phi list", n_phi)
            rows = np.array([r.numbers(f"{where}: row", n_phi + 1) for _ in range(n_theta)])
            th, values = rows[:, 0], rows[:, 1:]
            if s == "transmission":
                if np.any(th < 90 - 1e-9):
                    raise FormatError("transmission rows must be at theta 90..180", file=path, line=r.k, field=where,
                                      expected="theta in [90, 180] deg", got=float(th.min()))
                th, values = 180.0 - th[::-1], values[::-1]
            if np.any(np.diff(th) <= 0) or th.min() < 0 or th.max() > 90 + 1e-9:
                raise FormatError("theta rows not increasing within the hemisphere", file=path, line=r.k, field=where,
                                  expected="increasing theta in [0, 90] deg", got=f"{th.min():g}..{th.max():g}")
            if np.any(values < 0):
                raise FormatError("negative value", file=path, line=r.k, field=where, expected=">= 0",
                                  got=float(values.min()))
            if intensity:  # BSDF * cos(theta): back to the BSDF; a grazing row (cos 0) takes the row before it
                c = np.cos(np.radians(th))
                values = values / np.where(c > 1e-9, c, 1.0)[:, None]
                for j in np.flatnonzero(c <= 1e-9):
                    values[j] = values[j - 1] if j > 0 else 0.0
            if s in theta and (theta[s].shape != th.shape or not np.allclose(theta[s], th)
                               or not np.allclose(phi[s], ph)):
                raise FormatError("tables of one side on different grids are not supported", file=path, line=r.k,
                                  field=where, expected="the grid of the first table")
            theta[s], phi[s] = th, ph
            blocks.append(values)
        tables[s] = np.stack(blocks)
    return SpeosBsdf(incidences, theta, phi, tables, spectrum, intensity, comment, description,
                     _comment_wavelength(comment, path))


def _comment_wavelength(comment: str, path: str) -> float | None:
    """The ``wavelength_nm=`` of the comment line (line 3) [nm], None without one; FormatError naming the file, line
    and field for a value that is no wavelength in nm (a number in metres: the file's field, not an option)."""
    tag = _WAVELENGTH_TAG.search(comment)
    if tag is None:
        return None
    lo, hi = WAVELENGTH_RANGE_NM
    try:
        value = float(tag.group(1))
    except ValueError:
        value = float("nan")
    if not lo <= value <= hi:
        raise FormatError("wavelength of the comment out of range: it is stated in nm", file=path, line=3,
                          field="comment: wavelength_nm", expected=f"a wavelength in nm, {lo:g}..{hi:g}",
                          got=tag.group(1))
    return value


# ------------------------------------------------------------------------------------------- registry hooks
def _write_job(job: WriteJob) -> WriteOutcome:
    theta_i = np.asarray(job.theta, dtype=np.float64)
    theta, phi, info = normal_axes.normal_axes(job.fn, theta_i, job.sides, job.settings)
    bsdf = speos_bsdf(job.fn, theta_i, tuple(job.sides), wavelength_nm=job.settings.wavelength_nm,
                      description=(job.comments[0] if job.comments else "bsdfkit export")[:200], axes=(theta, phi))
    write_speos(job.path, bsdf, force=job.force)
    return WriteOutcome(None, normal_axes.describe(info, bsdf.theta[job.sides[0]].size,
                                                   bsdf.phi[job.sides[0]].size))


def _incidences(bsdf: SpeosBsdf) -> list[float]:
    return sorted({float(t) for v in bsdf.incidences.values() for t in v})


def _summarise(path: str) -> FileSummary:
    bsdf = read_speos(path)
    theta = _incidences(bsdf)
    stated = {s: [bsdf.spectrum[s][1] / 100.0 if abs(t - bsdf.spectrum[s][0]) < 1e-9 else float("nan")
                  for t in theta] for s in bsdf.tables}
    return FileSummary(format="speos", path=path, incidences_deg=theta,
                       tis_computed={s: [float("nan")] * len(theta) for s in bsdf.tables}, tis_stated=stated,
                       details={"own_quadrature": False, "intensity": bsdf.intensity, "comment": bsdf.comment,
                                "spectrum": {s: list(v) for s, v in bsdf.spectrum.items()},
                                "wavelength_nm": bsdf.wavelength_nm,
                                "normalisation": "the table is scaled so that its hemispherical integral at the "
                                                 "spectrum's incidence equals the spectrum's percentage"})


def _vendor_table(path: str) -> VendorTable:
    bsdf = read_speos(path)
    out = []
    for s in bsdf.tables:
        th, ph = np.meshgrid(bsdf.theta[s], bsdf.phi[s], indexing="ij")
        keep = (ph < 360.0 - 1e-9) | (th < 1e-9)  # phi 360 repeats phi 0
        values = bsdf.tables[s][:, keep]
        out.append(VendorGrid("directions", s, bsdf.incidences[s], th[keep], ph[keep], values))
    return VendorTable("speos", tuple(out), bsdf.wavelength_nm, {"comment": bsdf.comment},
                       normalise={s: (bsdf.spectrum[s][0], bsdf.spectrum[s][1] / 100.0) for s in bsdf.tables})


FORMAT = TableFormat(name="speos", title="Speos anisotropic BSDF (text)", extensions=(".anisotropicbsdf",),
                     guess_can_open=first_line_is(MAGIC), summarise=_summarise, vendor_table=_vendor_table,
                     write=_write_job, sides_per_file=2, grid_kind="normal")
