"""Text inputs read one way: encodings by byte-order mark, binary and undecodable files refused in one line.

Every text reader of bsdfkit (measured tables, TracePro/Zemax/ASAP-style tables, spectra, ray files, plate
JSON, scene/recipe/manifest TOML, budget tables) decodes its bytes with :func:`decode_text`:

* a byte-order mark selects the encoding: UTF-8, UTF-16 LE/BE (Excel's "Unicode text" export is UTF-16LE,
  tab-separated) or UTF-32 LE/BE; UTF-16 without a mark is recognised when every second byte of ASCII text
  is NUL;
* otherwise the text must be UTF-8, or, for vendor formats that are written by Windows tools, the caller's
  ``legacy`` single-byte encoding (cp1252, latin-1);
* a NUL byte left after decoding means a binary file (or a file damaged by a crash) and is refused with its
  line number, as is an empty file.
"""
from __future__ import annotations

import codecs
import csv
import re
from collections.abc import Sequence
from pathlib import Path

from bsdfkit.core.errors import FormatError, InputError

__all__ = ["decode_text", "existing_source", "is_float", "loads_toml", "read_text", "read_toml", "refuse_cut_last_line",
           "text_and_encoding"]

#: byte-order marks, longest first (the UTF-32 LE mark starts with the UTF-16 LE one)
_BOMS = ((codecs.BOM_UTF32_LE, "utf-32-le"), (codecs.BOM_UTF32_BE, "utf-32-be"), (codecs.BOM_UTF8, "utf-8"),
         (codecs.BOM_UTF16_LE, "utf-16-le"), (codecs.BOM_UTF16_BE, "utf-16-be"))


#: what a verb that reads measurements accepts
SOURCES = "a raw export folder, a text table, a vendor BSDF file or a netCDF dataset"


def existing_source(path: str | Path, expected: str = SOURCES) -> Path:
    """``path`` if it is a file or a raw export folder (one holding ``manifest.toml``); else one clear error.

    Light on purpose: the verbs call it before they import their engine, so a mistyped path is answered at once.

    Parameters
    ----------
    path : str or Path
        File or raw export folder.
    expected : str, optional
        What the file should be, for the error message.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    if p.is_dir():
        if not (p / "manifest.toml").is_file():
            raise InputError("folder without manifest.toml", file=p, expected=f"{expected} (a raw export folder holds "
                             "manifest.toml: docs/raw-format.md)")
        return p
    if not p.is_file():
        raise InputError("no such file or folder", file=p, expected=expected)
    return p


def is_float(token: str) -> bool:
    """Whether ``float(token)`` accepts the token (names the first bad token of a refused row).

    Parameters
    ----------
    token : str
        One cell of a row.

    Returns
    -------
    bool
        True when ``float(token)`` succeeds.
    """
    try:
        float(token)
    except ValueError:
        return False
    return True


def _unmarked_utf16(raw: bytes) -> str | None:
    """'utf-16-le'/'utf-16-be' when the bytes look like mostly-ASCII text in UTF-16 without a byte-order mark:
    (nearly) every second byte NUL, the others not."""
    head = raw[:4096]
    if len(head) < 4 or len(head) % 2:
        return None
    n = len(head) // 2
    even, odd = head[0::2].count(0), head[1::2].count(0)
    if odd >= 0.75 * n and even <= 0.05 * n:
        return "utf-16-le"
    if even >= 0.75 * n and odd <= 0.05 * n:
        return "utf-16-be"
    return None


def text_and_encoding(raw: bytes, path: str | Path, *, expected: str = "a text file", legacy: str | None = None,
                      allow_empty: bool = False) -> tuple[str, str]:
    """The text of a file's bytes and the encoding it was read with (see the module docstring).

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : str or Path
        The file, for the error message.
    expected : str
        What the file should be ("a TracePro surface property file"), for the error message.
    legacy : str, optional
        A single-byte encoding used when the bytes are not UTF-8 (undefined bytes become U+FFFD); None refuses
        such files.
    allow_empty : bool
        Accept a file without any content but white space (else an error).

    Returns
    -------
    text : str
        Without the byte-order mark.
    encoding : str
        "utf-8", "utf-8-sig", "utf-16-le", "utf-16-be", "utf-32-le", "utf-32-be" or ``legacy``.

    Raises
    ------
    FormatError
        Empty, binary (a NUL byte, with its line) or undecodable bytes, naming ``path``.
    """
    if not raw.strip() and not allow_empty:
        raise FormatError("the file is empty", file=path, expected=expected)
    bom, encoding = next(((b, enc) for b, enc in _BOMS if raw.startswith(b)), (b"", None))
    body = raw[len(bom):]
    encoding = encoding or _unmarked_utf16(raw) or "utf-8"
    name = "utf-8-sig" if bom == codecs.BOM_UTF8 else encoding
    try:
        text = body.decode(encoding)
    except UnicodeDecodeError as exc:
        if legacy is None or encoding != "utf-8" or b"\x00" in body:
            line = body[:exc.start].count(b"\n") + 1
            offset = exc.start + len(bom)
            found = (f"a cut or invalid character at byte offset {offset}" if encoding != "utf-8"
                     else "binary data" if b"\x00" in body else f"byte 0x{raw[offset]:02x} at offset {offset}")
            raise FormatError(f"not {encoding.upper()} text ({found})", file=path, line=line,
                              expected=f"{expected} in UTF-8 (or UTF-16/32 with a byte-order mark)") from None
        text, name = body.decode(legacy, errors="replace"), legacy
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise FormatError("binary data (NUL byte) in a text file", file=path, line=line, expected=expected)
    return text, name


def decode_text(raw: bytes, path: str | Path, *, expected: str = "a text file", legacy: str | None = None,
                allow_empty: bool = False) -> str:
    """The text of a file's bytes (:func:`text_and_encoding` without the encoding).

    Parameters
    ----------
    raw : bytes
        The file's bytes.
    path : str or Path
        The file (named in errors).
    expected : str, optional
        What the file should be, for the error message.
    legacy : str, optional
        Codec tried when the bytes are not UTF-8 (e.g. ``"cp1252"``); None refuses them.
    allow_empty : bool, optional
        Accept an empty file.

    Returns
    -------
    str
        The decoded text.
    """
    return text_and_encoding(raw, path, expected=expected, legacy=legacy, allow_empty=allow_empty)[0]


def read_text(path: str | Path, *, expected: str = "a text file", legacy: str | None = None,
              allow_empty: bool = False) -> str:
    """Read and decode a text file (:func:`decode_text`); a missing file, a folder or an unreadable file is an
    :class:`InputError` naming ``path``.

    Parameters
    ----------
    path : str or Path
        Text file.
    expected : str, optional
        What the file should be, for the error message.
    legacy : str, optional
        Codec tried when the bytes are not UTF-8 (e.g. ``"cp1252"``); None refuses them.
    allow_empty : bool, optional
        Accept an empty file.

    Returns
    -------
    str
        The decoded text.
    """
    p = Path(path)
    if p.is_dir():
        raise InputError("a folder, not a file", file=path, expected=expected)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", file=path, expected=expected) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or type(exc).__name__})", file=path) from None
    return decode_text(raw, path, expected=expected, legacy=legacy, allow_empty=allow_empty)


def loads_toml(text: str, path: str | Path | None) -> dict:
    """Parse TOML text; invalid TOML is a :class:`FormatError` naming ``path`` and the parser's line.

    Parameters
    ----------
    text : str
        TOML text.
    path : str or Path or None
        The file it came from (named in errors), None for text of no file.

    Returns
    -------
    dict
        The parsed document.
    """
    import tomllib  # here: only the verbs that read a recipe or a manifest parse TOML

    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"not valid TOML ({exc})", file=path) from None


def read_toml(path: str | Path, *, expected: str = "a TOML file") -> dict:
    """Read, decode (:func:`read_text`) and parse a TOML file (:func:`loads_toml`).

    Parameters
    ----------
    path : str or Path
        TOML file.
    expected : str, optional
        What the file should be, for the error message.

    Returns
    -------
    dict
        The parsed document.
    """
    return loads_toml(read_text(path, expected=expected), path)


# ------------------------------------------------------------------------------------------ cut files
#: a number's layout: digits, fraction digits (after '.' or a decimal ','), exponent digits
_NUMBER = re.compile(r"^[+-]?(\d*)(?:[.,](\d*))?(?:[eE][+-]?(\d*))?$")


def _layout(cell: str) -> tuple[int | None, int | None] | None:
    """(fraction digits or None, exponent digits or None) of a number cell; None when it is not a number."""
    m = _NUMBER.match(cell.strip())
    if not m or not (m.group(1) or m.group(2)):
        return None
    return (None if m.group(2) is None else len(m.group(2)), None if m.group(3) is None else len(m.group(3)))


def _looks_cut(last: str, column: Sequence[str]) -> bool:
    """True when ``last`` looks like the start of a number whose end was lost, judged against ``column`` (the
    same column's cells on the rows before, written the same way)."""
    cell = last.strip()
    if not cell:
        return bool(column) and all(c.strip() for c in column)  # a cut right after a separator
    if cell[-1] in "eE+-":
        return True
    layouts = [_layout(c) for c in column]
    mine = _layout(cell)
    if len(layouts) < 2 or None in layouts or mine is None:
        return False
    exponents = {e for _, e in layouts}
    if len(exponents) == 1 and None not in exponents:
        return mine[1] not in exponents  # every row before has an exponent of this many digits
    if mine[1] is not None and len(exponents - {None}) == 1:
        return mine[1] not in exponents  # a shorter exponent than every exponent before
    fractions = {f for f, _ in layouts}
    if exponents == {None} and len(fractions) == 1 and None not in fractions:
        return mine[1] is None and (mine[0] or 0) < min(fractions)  # fewer decimals than every row before
    return False


def refuse_cut_last_line(text: str, path: str | Path, delimiter: str | None, *, expected: str,
                         comments: tuple[str, ...] = ("#",), previous_rows: int = 20) -> None:
    """Raise :class:`FormatError` when ``text`` ends, without a line break, inside a number: a file cut while it
    was written or copied.

    Only the last line of a file that does not end with a line break can hold a cut number; its last cell is
    compared with the same column on the ``previous_rows`` rows before it that have as many cells. It is cut
    when it ends in an exponent sign, when it is empty where every row before has a value, or when those rows
    share one layout (decimals, exponent digits) that it lacks (``0.318`` below rows of ``0.3183``). Rows of
    a different width are left to the reader's own checks.

    Parameters
    ----------
    text : str
        The decoded file.
    path : str or Path
        The file, for the message.
    delimiter : str or None
        The cell separator (None: white space).
    expected : str
        What the last line should hold, for the message.
    comments : tuple of str
        Prefixes of comment lines (not compared).
    previous_rows : int
        How many rows before the last one are compared.
    """
    if not text or text.endswith(("\n", "\r")):
        return
    lines = text.splitlines()
    last = lines[-1]
    if not last.strip() or last.strip().startswith(comments):
        return

    def split(line: str) -> list[str]:
        if delimiter is None:
            return line.split()
        return next(csv.reader([line], delimiter=delimiter, quotechar='"'))

    cells = split(last)
    column = []
    for line in reversed(lines[:-1]):
        if len(column) >= previous_rows:
            break
        if line.strip() and not line.strip().startswith(comments):
            row = split(line)
            if len(row) == len(cells):
                if row[-1].strip() and _layout(row[-1]) is None:
                    break  # a header or a unit row: the data above it is another block
                column.append(row[-1])
    if _looks_cut(cells[-1], column):
        raise FormatError("the file ends inside a number (truncated?)", file=path, line=len(lines),
                          expected=f"{expected}, ending with a complete row",
                          got=last.strip()[-40:] if last.strip() else "an empty last cell")
