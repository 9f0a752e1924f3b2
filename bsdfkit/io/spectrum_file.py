"""Reader for two-column text spectra: wavelength (nm), value.

Accepted: an optional header line (the first non-blank, non-comment line, if it is not numeric), fields
separated by tab, comma, semicolon or blanks (detected from the first data line), UTF-8 with or without
a byte-order mark, LF or CRLF line ends, ``#`` comment lines and blank lines anywhere. With a tab,
semicolon or blank separator a decimal comma (``450,5``) is accepted, as spreadsheet exports in many
locales write it. Instrument Systems ``.ISD`` exports (header ``wl<TAB>pwr``) are read as is.

Rejected with a one-line :class:`bsdfkit.core.errors.InputError` / :class:`~bsdfkit.core.errors.FormatError`
naming the file, line and field: missing or unreadable file, not UTF-8, empty file, a line with other
than two fields, a non-numeric cell, NaN or infinity, wavelengths not strictly increasing or not
positive, fewer than three data rows.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bsdfkit.core.errors import FormatError, InputError, ValidationError

if TYPE_CHECKING:
    from colour import SpectralDistribution

__all__ = ["read_spectrum", "read_spectrum_arrays", "MIN_ROWS"]

#: Fewest data rows accepted (a peak and its two flanks).
MIN_ROWS = 3

_FIELDS = ("wavelength", "value")
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d*(?:[eE][+-]?\d+)?$")


def _delimiter(line: str) -> str | None:
    """Separator of a data line: tab, semicolon, comma, else blanks (None = split on whitespace)."""
    for sep in ("\t", ";", ","):
        if sep in line:
            return sep
    return None


def _split(line: str, sep: str | None) -> list[str]:
    return [f.strip() for f in line.split(sep)] if sep is not None else line.split()


def _number(text: str, sep: str | None) -> float | None:
    """Parse a numeric cell; None if it is not a number."""
    cell = text.strip().strip('"').strip("'")
    if sep != "," and _DECIMAL_COMMA.match(cell):
        cell = cell.replace(",", ".")
    try:
        return float(cell)
    except ValueError:
        return None


def read_spectrum_arrays(path: str | Path) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Read a two-column spectrum file → (wavelength nm, values, header line or None)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError("spectrum file not found", file=path) from None
    except IsADirectoryError:
        raise InputError("expected a file, got a directory", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read spectrum file ({exc.strerror or exc})", file=path) from None
    try:
        text = raw.decode("utf-8-sig")  # strips a BOM if present
    except UnicodeDecodeError as exc:
        raise FormatError("file is not UTF-8 text", file=path, expected="UTF-8",
                          got=f"byte 0x{raw[exc.start]:02x} at offset {exc.start}") from None

    header: str | None = None
    sep: str | None = None
    sep_known = False
    wl: list[float] = []
    val: list[float] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if not sep_known:
            sep = _delimiter(stripped)
        fields = _split(stripped, sep)
        numbers = [_number(f, sep) for f in fields]
        if not sep_known and header is None and not wl and any(n is None for n in numbers):
            # First content line and not numeric: the header. The separator is taken from the data.
            header = stripped
            continue
        sep_known = True
        if len(fields) != 2:
            raise FormatError("wrong number of columns", file=path, line=lineno,
                              expected="2 (wavelength, value)", got=len(fields))
        for name, cell, number in zip(_FIELDS, fields, numbers):
            if number is None:
                raise FormatError("non-numeric cell", file=path, line=lineno, field=name,
                                  expected="a number", got=cell)
            if not math.isfinite(number):
                raise FormatError("value is not finite", file=path, line=lineno, field=name,
                                  expected="a finite number", got=cell)
        w, v = numbers
        if w <= 0:
            raise ValidationError("wavelength must be positive", file=path, line=lineno,
                                  field="wavelength", expected="> 0 nm", got=w)
        if wl and not w > wl[-1]:
            raise ValidationError("wavelengths must increase strictly", file=path, line=lineno,
                                  field="wavelength", expected=f"> {wl[-1]:g}", got=w)
        wl.append(w)
        val.append(v)

    if not wl:
        raise FormatError("no data rows", file=path,
                          expected="two numeric columns (wavelength nm, value)",
                          got="an empty file" if header is None else f"only the header {header!r}")
    if len(wl) < MIN_ROWS:
        raise FormatError("too few data rows", file=path, expected=f"at least {MIN_ROWS}", got=len(wl))
    return np.asarray(wl, dtype=float), np.asarray(val, dtype=float), header


def read_spectrum(path: str | Path) -> SpectralDistribution:
    """Read a two-column spectrum file as a :class:`colour.SpectralDistribution` (wavelength in nm).

    The distribution is named after the file stem; values keep the file's unit. Irregular grids are kept
    as they are (colorimetry resamples when it must, see :mod:`bsdfkit.reduction.colorimetry`).
    """
    import colour

    wl, values, _ = read_spectrum_arrays(path)
    return colour.SpectralDistribution(values, wl, name=Path(path).stem)
