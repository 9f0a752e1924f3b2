"""Reader for text spectra: wavelength (nm) and one value column (:func:`read_spectrum_arrays`) or several
(:func:`read_spectrum_table`, e.g. the LEDs of a batch measurement side by side).

Accepted: an optional header line (the first non-blank, non-comment line, if it is not numeric), fields
separated by tab, comma, semicolon or blanks (detected from the first data line), UTF-8 with or without
a byte-order mark, LF or CRLF line ends, ``#`` comment lines and blank lines anywhere. With a tab,
semicolon or blank separator a decimal comma (``450,5``) is accepted, as spreadsheet exports in many
locales write it. Instrument Systems ``.ISD`` exports (header ``wl<TAB>pwr``) are read as is.

Rejected with a one-line :class:`bsdfkit.core.errors.InputError` / :class:`~bsdfkit.core.errors.FormatError`
naming the file, line and field: missing or unreadable file, not UTF-8, empty file, a line with other
than two fields (a table: other than the first data row's number, at least two), a non-numeric cell, NaN
or infinity, wavelengths not strictly increasing or not positive, fewer than three data rows.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.io.text import read_text, refuse_cut_last_line

if TYPE_CHECKING:
    from colour import SpectralDistribution

__all__ = ["read_spectrum", "read_spectrum_arrays", "read_spectrum_table", "select_columns", "MIN_ROWS"]

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


def _parse(path: str | Path, columns: int | None) -> tuple[np.ndarray, np.ndarray, str | None, list[str]]:
    """Parse a spectrum table → (wavelength nm, values (k, n), header or None, header fields). ``columns``:
    the exact number of columns required (2 for a plain spectrum), or None for any number ≥ 2, the same on
    every row."""
    path = Path(path)
    text = read_text(path, expected="a spectrum table")

    header: str | None = None
    header_line = ""
    sep: str | None = None
    sep_known = False
    width = columns
    rows: list[list[float]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if not sep_known:
            sep = _delimiter(stripped)
        fields = _split(stripped, sep)
        numbers = [_number(f, sep) for f in fields]
        if not sep_known and header is None and not rows and any(n is None for n in numbers):
            # First content line and not numeric: the header. The separator is taken from the data.
            header = header_line = stripped
            continue
        sep_known = True
        if width is None:
            if len(fields) < 2:
                raise FormatError("wrong number of columns", file=path, line=lineno,
                                  expected="at least 2 (wavelength, value, ...)", got=len(fields))
            width = len(fields)
        if len(fields) != width:
            expected = "2 (wavelength, value)" if width == 2 else f"{width} (as on the first data row)"
            raise FormatError("wrong number of columns", file=path, line=lineno, expected=expected, got=len(fields))
        for k, (cell, number) in enumerate(zip(fields, numbers)):
            name = _FIELDS[min(k, 1)] if width == 2 else ("wavelength" if k == 0 else f"column {k + 1}")
            if number is None:
                raise FormatError("non-numeric cell", file=path, line=lineno, field=name,
                                  expected="a number", got=cell)
            if not math.isfinite(number):
                raise FormatError("value is not finite", file=path, line=lineno, field=name,
                                  expected="a finite number", got=cell)
        w = numbers[0]
        if w <= 0:
            raise ValidationError("wavelength must be positive", file=path, line=lineno,
                                  field="wavelength", expected="> 0 nm", got=w)
        if rows and not w > rows[-1][0]:
            raise ValidationError("wavelengths must increase strictly", file=path, line=lineno,
                                  field="wavelength", expected=f"> {rows[-1][0]:g}", got=w)
        rows.append(numbers)

    refuse_cut_last_line(text, path, sep, expected="a row of numbers")
    if not rows:
        raise FormatError("no data rows", file=path,
                          expected="two numeric columns (wavelength nm, value)",
                          got="an empty file" if header is None else f"only the header {header!r}")
    if len(rows) < MIN_ROWS:
        raise FormatError("too few data rows", file=path, expected=f"at least {MIN_ROWS}", got=len(rows))
    table = np.asarray(rows, dtype=float)
    header_fields = [f.strip().strip('"').strip("'") for f in _split(header_line, sep)] if header else []
    return table[:, 0], table[:, 1:].T, header, header_fields


def read_spectrum_arrays(path: str | Path) -> tuple[np.ndarray, np.ndarray, str | None]:
    """Read a two-column spectrum file → (wavelength nm, values, header line or None).

    Parameters
    ----------
    path : str or Path
        Text file: a wavelength column [nm] and value columns.

    Returns
    -------
    wavelength : ndarray
        Wavelengths as in the file [nm].
    values : ndarray
        Values of the second column, in the file's unit.
    header : str or None
        The header line, if any.
    """
    wl, values, header, _ = _parse(path, 2)
    return wl, values[0], header


def read_spectrum_table(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray], str | None]:
    """Read a spectrum table with one wavelength column [nm] and one or more value columns.

    Same format rules as :func:`read_spectrum_arrays` (separators, header, BOM, decimal comma, comments), with
    any number ≥ 2 of columns, the same on every row. Returns (wavelength, {column name: values}, header):
    names are the header's fields when the header has one per column, else "column 2", "column 3", ...
    (the 1-based column number in the file). A two-column file gives one column.

    Parameters
    ----------
    path : str or Path
        Text file: a wavelength column [nm] and value columns.

    Returns
    -------
    wavelength : ndarray
        Wavelengths as in the file [nm].
    columns : dict of str to ndarray
        Values of each value column, in the file's unit.
    header : str or None
        The header line, if any.
    """
    wl, values, header, fields = _parse(path, None)
    k = values.shape[0]
    if len(fields) == k + 1 and len(set(fields[1:])) == k and all(fields[1:]):
        names = fields[1:]
    else:
        names = [f"column {j + 2}" for j in range(k)]
    return wl, dict(zip(names, values)), header


def select_columns(path: str | Path, table: dict[str, np.ndarray], wanted: list[str] | None) -> list[str]:
    """Names of ``table`` picked by ``wanted`` (header names, or 1-based file column numbers ≥ 2); all if None.

    Raises :class:`ValidationError` naming the file and the available columns for an unknown name.

    Parameters
    ----------
    path : str or Path
        The file the table was read from (named in the error).
    table : dict of str to ndarray
        Columns of :func:`read_spectrum_table`.
    wanted : list of str or None
        Column names or 1-based column numbers ≥ 2 as text; None or empty selects all.

    Returns
    -------
    list of str
        The selected column names, in the order asked.
    """
    names = list(table)
    if not wanted:
        return names
    out = []
    for w in wanted:
        if w in table:
            out.append(w)
        elif w.strip().isdigit() and 2 <= int(w) <= len(names) + 1:
            out.append(names[int(w) - 2])
        else:
            raise ValidationError("no such column", file=path, field="--column",
                                  expected=" | ".join(names) + f" or a column number 2..{len(names) + 1}", got=w)
    return out


def read_spectrum(path: str | Path) -> SpectralDistribution:
    """Read a two-column spectrum file as a :class:`colour.SpectralDistribution` (wavelength in nm).

    The distribution is named after the file stem; values keep the file's unit. Irregular grids are kept
    as they are (colorimetry resamples when it must, see :mod:`bsdfkit.reduction.colorimetry`).

    Parameters
    ----------
    path : str or Path
        Text file: a wavelength column [nm] and value columns.

    Returns
    -------
    colour.SpectralDistribution
        Values on the file's wavelengths [nm], named after the file stem.
    """
    import colour

    wl, values, _ = read_spectrum_arrays(path)
    return colour.SpectralDistribution(values, wl, name=Path(path).stem)
