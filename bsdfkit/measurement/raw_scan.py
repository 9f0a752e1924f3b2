"""Read a raw goniometer export (manifest + spectra files) into an xarray Dataset, with validation.

No physics happens here: counts stay counts. Calibration is :mod:`bsdfkit.measurement.calibrate`. Every malformed input
raises a :class:`bsdfkit.core.errors.InputError` subclass whose one-line message names the file, the line or
field, what was expected and what was found. The format is documented in docs/raw-format.md.
"""
from __future__ import annotations

import csv
import gzip
import io
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io.text import decode_text, refuse_cut_last_line
from bsdfkit.measurement.manifest import ConfigurationEntry, Manifest, read_manifest

SCAN_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_s_deg", "phi_s_deg", "side", "exposure_s")
SCAN_OPTIONAL = ("arc",)
FRAME_COLUMNS = ("frame", "exposure_s")
ARCS = ("in_plane", "perpendicular", "other")
#: Largest plausible |count| of one spectrometer pixel: 1e15, far above any frame however co-added (a 16-bit
#: detector summing a million frames reaches 7e10). A larger number is an overflow or a corrupt cell, and the
#: calibration would turn it into an infinite power (1e308 / exposure) that reads as no light at all.
MAX_ABS_COUNTS = 1e15


@dataclass(frozen=True)
class SpectraTable:
    """A parsed spectra file: named text/number columns and a counts matrix over its wavelength header."""

    path: Path
    columns: dict[str, list[str]]
    wavelength: NDArray[np.float64]
    counts: NDArray[np.float64]
    first_data_line: int
    #: physical (1-based) line of each data row: comments and blank lines between rows count
    lines: tuple[int, ...] = ()


def _open_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=path) from None
    if path.suffix == ".gz" or raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise FormatError(f"not a readable gzip file ({exc})", file=path, expected="an intact gzip file") from None
    return decode_text(raw, path, expected="a CSV scan table")


def _numbered_rows(text: str, path: Path) -> list[tuple[int, list[str]]]:
    """The CSV rows of ``text`` with their 1-based physical line, blank and ``#`` comment lines left out."""
    if '"' not in text and "\r" not in text:  # no quoting, one row per line: what csv.reader gives, 3× faster
        rows = [(k, line.split(",")) for k, line in enumerate(text.split("\n"), start=1) if line]
    else:
        try:
            reader = csv.reader(io.StringIO(text))
            # the reader's physical line (a quoted cell may span lines: a row's index is not its line)
            rows = [(reader.line_num, r) for r in reader]
        except csv.Error as exc:
            raise FormatError(f"not valid CSV ({exc})", file=path) from None
    # Skip blank and '#' comment lines but keep 1-based physical line numbers for messages.
    return [(k, r) for k, r in rows if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]


def _header_columns(header: list[str], header_line: int, path: Path, required: tuple[str, ...],
                    optional: tuple[str, ...]) -> tuple[list[str], NDArray[np.float64]]:
    """The named columns and the strictly increasing wavelengths [nm] of a spectra file's header."""
    names: list[str] = []
    wl: list[float] = []
    for h in header:
        try:
            value = float(h)
        except ValueError:
            if wl:
                raise FormatError("text column after the wavelength columns", file=path, line=header_line, field=h,
                                  expected="wavelength (nm) headers only after the named columns") from None
            if h not in required and h not in optional:
                raise FormatError("unknown column", file=path, line=header_line, field=h,
                                  expected="one of " + ", ".join(required + optional)
                                           + " or a wavelength in nm") from None
            if h in names:
                raise FormatError("column appears twice", file=path, line=header_line, field=h) from None
            names.append(h)
        else:
            if not np.isfinite(value):
                raise FormatError("wavelength header not finite", file=path, line=header_line, field=h)
            wl.append(value)
    missing = [c for c in required if c not in names]
    if missing:
        raise FormatError("required column missing", file=path, line=header_line, field=missing[0],
                          expected="columns " + ", ".join(required))
    if not wl:
        raise FormatError("no wavelength columns", file=path, line=header_line,
                          expected="count columns headed by wavelength in nm")
    wavelength = np.asarray(wl)
    steps = np.diff(wavelength)
    if np.any(steps <= 0):
        bad = int(np.argmax(steps <= 0)) + 1
        raise ValidationError("wavelength grid not strictly increasing", file=path, line=header_line,
                              field=header[len(names) + bad], expected=f"> {wavelength[bad - 1]:g} nm",
                              got=wavelength[bad])
    return names, wavelength


def _counts(data: list[tuple[int, list[str]]], header: list[str], n_named: int, n_wl: int, path: Path
            ) -> NDArray[np.float64]:
    """The counts matrix (rows × wavelengths) of the data rows, checked in file order, as a row-by-row reader
    would check them: the first faulty row is the one reported."""
    width = n_named + n_wl
    n_ok = next((r for r, (_, row) in enumerate(data) if len(row) != width), len(data))
    try:  # one conversion of every count cell (a per-row conversion was most of the time of a 62-file scan)
        counts = np.array([row[n_named:] for _, row in data[:n_ok]], dtype=np.float64).reshape(n_ok, n_wl)
    except ValueError:  # find the first bad cell for the message
        for line, row in data[:n_ok]:
            for k, cell in enumerate(row[n_named:]):
                try:
                    float(cell)
                except ValueError:
                    raise FormatError("count is not a number", file=path, line=line, field=header[n_named + k],
                                      expected="a number", got=cell) from None
        raise FormatError("counts are not numbers", file=path, expected="a number in every count cell") from None
    bad = ~np.isfinite(counts)
    if bad.any():
        r, k = np.argwhere(bad)[0]
        line, row = data[r]
        raise ValidationError("count is not finite", file=path, line=line, field=header[n_named + k],
                              expected="a finite number", got=row[n_named + k])
    huge = np.abs(counts) > MAX_ABS_COUNTS
    if huge.any():
        r, k = np.argwhere(huge)[0]
        line, row = data[r]
        raise ValidationError("count implausibly large (an overflow or a corrupt cell)", file=path, line=line,
                              field=header[n_named + k], expected=f"|count| <= {MAX_ABS_COUNTS:g}",
                              got=row[n_named + k].strip())
    if n_ok < len(data):
        line, row = data[n_ok]
        raise FormatError("wrong number of fields", file=path, line=line, expected=f"{width} fields", got=len(row))
    return counts


def read_spectra_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> SpectraTable:
    """Parse a CSV spectra file: named columns first, then one column per wavelength (header = nm).

    Blank lines and ``#`` comment lines are skipped; a gzip file (``.gz`` or gzip magic bytes) is decompressed.

    Parameters
    ----------
    path : Path
        Spectra file (CSV, optionally gzip-compressed).
    required : tuple of str
        Named columns the header must hold, e.g. :data:`SCAN_COLUMNS` or :data:`FRAME_COLUMNS`.
    optional : tuple of str, optional
        Further named columns allowed in the header.

    Returns
    -------
    SpectraTable
        The named columns as text, the wavelengths of the header [nm] (strictly increasing), the counts
        (rows × wavelengths) [counts] and the physical line of each data row.

    Raises
    ------
    InputError
        The file is missing, unreadable, empty or has no data row; its subclasses ``FormatError`` and
        ``ValidationError`` for a malformed header, a count that is not a finite number or a wrong field count.
    """
    text = _open_text(path)
    refuse_cut_last_line(text, path, ",", expected="a row of counts")
    numbered = _numbered_rows(text, path)
    if not numbered:
        raise InputError("empty file", file=path, expected="a header line and at least one data row")
    header_line, header = numbered[0]
    header = [h.strip() for h in header]
    data = numbered[1:]
    if not data:
        raise InputError("no data rows", file=path, line=header_line, expected="at least one data row after the header")
    names, wavelength = _header_columns(header, header_line, path, required, optional)
    counts = _counts(data, header, len(names), wavelength.size, path)
    columns = {n: [row[j].strip() for _, row in data] for j, n in enumerate(names)}
    return SpectraTable(path=path, columns=columns, wavelength=wavelength, counts=counts, first_data_line=data[0][0],
                        lines=tuple(line for line, _ in data))


def _floats(table: SpectraTable, name: str, lo: float, hi: float, lo_open: bool = False,
            hi_open: bool = False) -> NDArray[np.float64]:
    out = np.empty(len(table.columns[name]))
    for k, cell in enumerate(table.columns[name]):
        try:
            value = float(cell)
        except ValueError:
            value = np.nan
        ok = (np.isfinite(value) and (value > lo if lo_open else value >= lo)
              and (value < hi if hi_open else value <= hi))
        if not ok:
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
            raise ValidationError("value out of range", file=table.path, line=_line_of(table, k), field=name,
                                  expected=f"a number in {rng}", got=cell)
        out[k] = value
    return out


def _line_of(table: SpectraTable, row: int) -> int:
    # the physical line: comment or blank lines between data rows shift it (not first line + row)
    return table.lines[row] if table.lines else table.first_data_line + row


def _check_grid(table: SpectraTable, grid: NDArray[np.float64], manifest: Manifest) -> None:
    if table.wavelength.size != grid.size:
        raise ValidationError("wavelength grid does not match the manifest", file=table.path, field="wavelength header",
                              expected=f"{grid.size} values {grid[0]:g}..{grid[-1]:g} nm step "
                                       f"{manifest.wavelength_step_nm:g} (from {manifest.path.name})",
                              got=f"{table.wavelength.size} values "
                                  f"{table.wavelength[0]:g}..{table.wavelength[-1]:g} nm")
    off = np.flatnonzero(~np.isclose(table.wavelength, grid, atol=1e-6, rtol=0))
    if off.size:
        k = int(off[0])
        raise ValidationError("wavelength grid does not match the manifest", file=table.path, field="wavelength header",
                              expected=f"{grid[k]:g} nm in wavelength column {k + 1} "
                                       f"(grid {grid[0]:g}..{grid[-1]:g} nm "
                                       f"step {manifest.wavelength_step_nm:g} from {manifest.path.name})",
                              got=f"{table.wavelength[k]:g} nm")


def _read_responsivity(path: Path, grid: NDArray[np.float64]) -> NDArray[np.float64]:
    text = _open_text(path)
    try:
        rows = [r for r in csv.reader(io.StringIO(text)) if r and r[0].strip() and not r[0].lstrip().startswith("#")]
    except csv.Error as exc:
        raise FormatError(f"not valid CSV ({exc})", file=path) from None
    if len(rows) < 2:
        raise InputError("empty responsivity file", file=path, expected="header + one row per wavelength")
    values = []
    for k, r in enumerate(rows[1:], start=2):
        try:
            lam, val = float(r[0]), float(r[1])
        except (ValueError, IndexError):
            raise FormatError("bad responsivity row", file=path, line=k, expected="wavelength_nm,relative_responsivity",
                              got=",".join(r)) from None
        if not (np.isfinite(val) and val > 0):
            raise ValidationError("responsivity must be positive", file=path, line=k, field="relative_responsivity",
                                  got=r[1])
        values.append((lam, val))
    arr = np.asarray(values)
    if arr.shape[0] != grid.size or not np.allclose(arr[:, 0], grid, atol=1e-6):
        raise ValidationError("responsivity wavelengths do not match the manifest grid", file=path,
                              field="wavelength_nm",
                              expected=f"{grid.size} values {grid[0]:g}..{grid[-1]:g} nm", got=f"{arr.shape[0]} rows")
    return arr[:, 1]


def _grid(manifest: Manifest) -> NDArray[np.float64]:
    """The manifest's wavelength grid [nm]; its range must be a whole number of steps."""
    n = int(round((manifest.wavelength_max_nm - manifest.wavelength_min_nm) / manifest.wavelength_step_nm)) + 1
    grid = manifest.wavelength_min_nm + manifest.wavelength_step_nm * np.arange(n)
    if abs(grid[-1] - manifest.wavelength_max_nm) > 1e-6:
        raise ValidationError("wavelength range is not a whole number of steps", file=manifest.path,
                              field="spectrometer.wavelength_step_nm",
                              expected="(max − min)/step integral", got=manifest.wavelength_step_nm)
    return grid


def _sides_and_arcs(table: SpectraTable) -> tuple[list[str], list[str]]:
    """The checked ``side`` (lower case) and ``arc`` (default ``other``) of every row of a scan file."""
    side = []
    for k, s in enumerate(table.columns["side"]):
        if s.lower() not in SIDES:
            raise ValidationError("unknown side", file=table.path, line=_line_of(table, k), field="side",
                                  expected="reflection or transmission", got=s)
        side.append(s.lower())
    arcs = table.columns.get("arc") or ["other"] * len(side)
    for k, a in enumerate(arcs):
        if a not in ARCS:
            raise ValidationError("unknown arc", file=table.path, line=_line_of(table, k), field="arc",
                                  expected=" or ".join(ARCS), got=a)
    return side, arcs


def _refuse_duplicates(table: SpectraTable, angles: tuple[NDArray[np.float64], ...], side: list[str]) -> None:
    """Refuse a position measured twice: identical directions (θi, φi, θs, φs [deg]) to 1e-6°, φ modulo 360,
    and φ irrelevant at θ = 0."""
    theta_i, phi_i, theta_s, phi_s = angles
    seen: dict[tuple, int] = {}
    # on Python floats: rounding NumPy scalars one by one was a tenth of a 62-file scan's reading time
    for k, (ti, pi, ts, phs, sd) in enumerate(zip(theta_i.tolist(), phi_i.tolist(), theta_s.tolist(),
                                                  phi_s.tolist(), side)):
        ps = 0.0 if ts < 1e-9 else round(phs % 360.0, 6) % 360.0
        key = (round(ti, 6), round(pi % 360.0, 6) % 360.0, round(ts, 6), ps, sd)
        if key in seen:
            raise ValidationError("duplicate detector position", file=table.path, line=_line_of(table, k),
                                  field="theta_s_deg/phi_s_deg",
                                  expected=f"each position once (same as line {_line_of(table, seen[key])})",
                                  got=f"θi={theta_i[k]:g} θs={theta_s[k]:g} φs={phi_s[k]:g} {side[k]}")
        seen[key] = k


def _scan_part(cfg: ConfigurationEntry, grid: NDArray[np.float64], manifest: Manifest) -> xr.Dataset:
    """The records of one configuration's scan file: counts and the per-record coordinates."""
    table = read_spectra_table(cfg.scan_file, SCAN_COLUMNS, SCAN_OPTIONAL)
    _check_grid(table, grid, manifest)
    theta_i = _floats(table, "theta_i_deg", 0.0, 90.0, hi_open=True)
    phi_i = _floats(table, "phi_i_deg", -360.0, 360.0)
    theta_s = _floats(table, "theta_s_deg", 0.0, 90.0)
    phi_s = _floats(table, "phi_s_deg", -360.0, 360.0)
    exposure = _floats(table, "exposure_s", 0.0, np.inf, lo_open=True, hi_open=True)
    side, arcs = _sides_and_arcs(table)
    _refuse_duplicates(table, (theta_i, phi_i, theta_s, phi_s), side)
    return xr.Dataset(
        {"counts": (("record", "wavelength"), table.counts)},
        coords={
            "config": ("record", np.array([cfg.name] * len(side), dtype=object)),
            "theta_i": ("record", theta_i), "phi_i": ("record", phi_i),
            "theta_s": ("record", theta_s), "phi_s": ("record", phi_s),
            "side": ("record", np.array(side, dtype=object)),
            "arc": ("record", np.array(arcs, dtype=object)),
            "exposure": ("record", exposure),
            "source_line": ("record", np.array([_line_of(table, k) for k in range(len(side))], dtype=np.int64)),
        },
    )


def _reference_part(cfg: ConfigurationEntry, grid: NDArray[np.float64], manifest: Manifest) -> xr.Dataset:
    """The reference-beam frames of one configuration."""
    ref = read_spectra_table(cfg.reference_file, FRAME_COLUMNS)
    _check_grid(ref, grid, manifest)
    return xr.Dataset(
        {"reference_counts": (("reference_record", "wavelength"), ref.counts)},
        coords={"reference_config": ("reference_record", np.array([cfg.name] * ref.counts.shape[0], dtype=object)),
                "reference_exposure": ("reference_record", _floats(ref, "exposure_s", 0.0, np.inf,
                                                                   lo_open=True, hi_open=True))},
    )


def _dark(manifest: Manifest, grid: NDArray[np.float64], needed: set[float]) -> tuple[SpectraTable, NDArray]:
    """The dark frames and their exposures [s]: at least two at every exposure time in ``needed``."""
    dark = read_spectra_table(manifest.dark_file, FRAME_COLUMNS)
    _check_grid(dark, grid, manifest)
    dark_exposure = _floats(dark, "exposure_s", 0.0, np.inf, lo_open=True, hi_open=True)
    have: dict[float, int] = {}
    for t in dark_exposure:
        have[round(t, 12)] = have.get(round(t, 12), 0) + 1
    for t in sorted(needed):
        if have.get(round(t, 12), 0) < 2:
            raise ValidationError("not enough dark frames for an exposure time", file=manifest.dark_file,
                                  field="exposure_s",
                                  expected=f"≥ 2 dark frames at {t:g} s (used by a scan or reference)",
                                  got=have.get(round(t, 12), 0))
    return dark, dark_exposure


def read_scan(folder: str | Path) -> xr.Dataset:
    """Read a raw export folder into a raw xarray Dataset (counts, darks, references; no physics).

    Dims: ``record`` (one detector position and configuration), ``wavelength`` (nm), ``reference_record``,
    ``dark_record``, ``configuration``. Record coordinates: ``config``, ``theta_i``, ``phi_i``, ``theta_s``,
    ``phi_s`` (degrees), ``side``, ``arc``, ``exposure`` (s), ``source_line``. A manifest with a
    ``[[band_series]]`` adds ``band_series`` and ``excitation_wavelength`` (nm) per configuration.

    Parameters
    ----------
    folder : str or Path
        Export folder holding ``manifest.toml`` and the spectra files it names (or the manifest file itself).

    Returns
    -------
    xarray.Dataset
        Raw scan: ``counts``, ``reference_counts``, ``dark_counts`` [counts], ``responsivity`` [-] (ones when
        the manifest names no responsivity file), per configuration ``reference_attenuation`` [-],
        ``incident_band`` [nm] and ``configuration_description``; the manifest's instrument geometry [mm], gain
        [e⁻/count], full scale [counts] and text in the attributes.

    Raises
    ------
    InputError
        Any malformed manifest or spectra file (one line naming the file, the line or field, what was expected
        and what was found).
    """
    manifest = read_manifest(folder)
    grid = _grid(manifest)
    parts, refs = [], []
    for cfg in manifest.configurations:
        parts.append(_scan_part(cfg, grid, manifest))
        refs.append(_reference_part(cfg, grid, manifest))
    needed = set(np.concatenate([p["exposure"].values for p in parts]
                                + [r["reference_exposure"].values for r in refs]).tolist())
    dark, dark_exposure = _dark(manifest, grid, needed)
    responsivity = (_read_responsivity(manifest.responsivity_file, grid) if manifest.responsivity_file
                    else np.ones_like(grid))
    ds = xr.concat(parts, dim="record")
    ds = xr.merge([ds, xr.concat(refs, dim="reference_record")])
    ds["dark_counts"] = (("dark_record", "wavelength"), dark.counts)
    ds = ds.assign_coords(dark_exposure=("dark_record", dark_exposure), wavelength=grid,
                          configuration=[c.name for c in manifest.configurations])
    ds["responsivity"] = ("wavelength", responsivity)
    ds = _per_configuration(ds, manifest)
    _describe_raw(ds, manifest)
    return ds


def _per_configuration(ds: xr.Dataset, manifest: Manifest) -> xr.Dataset:
    """The manifest's per-configuration values: attenuation, incident band, description, band series."""
    ds["reference_attenuation"] = ("configuration", [c.reference_attenuation for c in manifest.configurations])
    ds["incident_band"] = (("configuration", "band_edge"), [list(c.incident_band_nm) for c in manifest.configurations])
    ds = ds.assign_coords(band_edge=["low", "high"])
    ds["configuration_description"] = ("configuration",
                                       np.array([c.description for c in manifest.configurations], dtype=object))
    if any(c.series for c in manifest.configurations):  # a monochromator scan: which band is which
        ds["band_series"] = ("configuration", np.array([c.series for c in manifest.configurations], dtype=object))
        ds["excitation_wavelength"] = ("configuration", [c.excitation_nm for c in manifest.configurations])
        ds["band_series"].attrs["long_name"] = "[[band_series]] of the configuration ('' for a [[configuration]])"
        ds["excitation_wavelength"].attrs.update(units="nm", long_name="nominal centre of a band-series band",
                                                 note="NaN for configurations outside a band series")
    return ds


def _describe_raw(ds: xr.Dataset, manifest: Manifest) -> None:
    """Units and long names of the raw dataset's variables, and its attributes from the manifest."""
    for name in ("theta_i", "phi_i", "theta_s", "phi_s"):
        ds[name].attrs["units"] = "deg"
    ds["wavelength"].attrs.update(units="nm", long_name="scattered (detected) wavelength")
    ds["exposure"].attrs["units"] = "s"
    ds["counts"].attrs.update(units="counts", long_name="raw spectrometer counts (dark not subtracted)")
    ds["responsivity"].attrs.update(units="1", long_name="relative spectral responsivity of the detector")
    ds.attrs.update(
        quantity="raw_counts",
        sample_name=manifest.sample_name,
        synthetic=int(manifest.synthetic),
        source=str(manifest.folder),
        detector_distance_mm=manifest.instrument.detector_distance_mm,
        aperture_diameter_mm=manifest.instrument.aperture_diameter_mm,
        beam_diameter_mm=manifest.instrument.beam_diameter_mm,
        gain_e_per_count=manifest.gain_e_per_count,
        full_scale_counts=manifest.full_scale_counts,
        manifest_json=json.dumps(manifest.raw, sort_keys=True),
    )
