"""Measured BSDF text tables → the calibrated BSDF dataset of :func:`bsdfkit.measurement.calibrate.calibrate`.

Instruments and vendors export scattering data as plain text tables. :func:`read_table` turns any such table
into the dataset every later step uses (dims ``record`` × ``wavelength``; per-record coords ``theta_i``,
``phi_i``, ``theta_s``, ``phi_s`` [deg], ``side``, ``arc``, ``config``; ``bsdf``, ``bsdf_std`` [1/sr]; see
``docs/raw-format.md``, section "Measured tables and vendor files", for the rules in full).

Accepted text
    comma, semicolon, tab (or, when none of these separates the header, whitespace) separated; ``#`` comment
    lines anywhere (``# key: value`` comments before the header are read as metadata: quantity, side,
    wavelength, incidence, phi_i, relative_std, sample); a preamble of ``key: value`` / ``key,value`` lines
    before the header is read the same way; UTF-8 with or without BOM, UTF-16 with BOM, else Windows-1252;
    quoted cells; a decimal comma when the separator is not a comma.

Layouts
    LONG: one row per direction (and wavelength): columns for θi, φi, θs, φs, wavelength, side, the value
    and its standard uncertainty, recognised by the usual spellings (``theta_i``, ``AOI``,
    ``Incidence angle (deg)``, ``scatter angle``, ``phi_s``, ``azimuth``, ``lambda``, ``BRDF``, ``value``,
    ``std``, ``uncertainty`` …) and units in the header (``deg``, ``rad``, ``nm``, ``um``, ``%``).
    WIDE: the angle columns, then one value column per wavelength whose header carries the wavelength
    (``550``, ``550nm``, `` 550 nm ``, ``BRDF 550 nm``, ``0.55 um``); or one value column per incidence
    (``AOI 10``, ``10 deg``, ``theta_i=10``).
    Without a φs column, θs is a *signed in-plane* angle: positive on the specular side (φs = 0), negative on
    the source side (φs = 180°). Angles follow docs/raw-format.md: sample frame, source at φi (180° unless a
    φi column or ``# phi_i:`` says otherwise), φs = 0 on the specular side; in transmission θs from the back
    normal and φs = 0 at the undeviated direction.

Quantities
    ``brdf``, ``btdf`` (1/sr, and they fix the side), ``ccbrdf``, ``ccbtdf`` (cosine-corrected, f·cos θs:
    divided by cos θs), ``reflectance-factor``, ``transmittance-factor`` (R = π·BSDF: divided by π), and
    ``bsdf`` (side from a side column or ``side``). The quantity is taken from the headers or the metadata, or
    from the ``quantity`` argument; it is never guessed: if neither says, :class:`InputError`.

Gaps
    Empty cells, ``NaN``, ``-``, ``N/A`` are gaps (NaN in the dataset; records without any value are
    dropped), never zeros. ``zeros="auto"`` (default) also treats a record whose every value is exactly 0 as a
    gap (instruments write 0 where the source blocks the detector near retro-reflection); ``"keep"`` keeps
    zeros as data, ``"missing"`` makes every exact 0 a gap.

Uncertainty
    A std/uncertainty column (absolute, or relative when its header says ``rel`` or ``%`` on a non-%
    value) is converted like the value; without one, ``bsdf_std = relative_std · |bsdf|`` with
    ``relative_std`` from the argument, the metadata, or :data:`DEFAULT_RELATIVE_STD` (5 %), recorded in the
    attributes (``bsdf_std_origin``).

Every problem raises a one-line :class:`~bsdfkit.core.errors.InputError` / :class:`FormatError` /
:class:`ValidationError` naming the file, the line and the column.
"""
from __future__ import annotations

import codecs
import csv
import hashlib
import io
import json
import math
import re
from array import array
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import DEFAULT_RELATIVE_STD, QUANTITIES, SIDES, ZERO_POLICIES
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.core.version import __version__
from bsdfkit.io.text import _BOMS, _unmarked_utf16, refuse_cut_last_line, text_and_encoding
from bsdfkit.measurement.schema import new_bsdf_dataset

__all__ = ["QUANTITIES", "DEFAULT_RELATIVE_STD", "CONFIG_NAME", "read_table", "guess_can_open", "records_dataset",
           "RecordDirections", "RecordsOrigin",
           "to_bsdf", "side_of_quantity", "normalise_quantity", "arc_labels"]

#: prefixes of comment lines
_COMMENTS = ("#", "//", "%", "!")
_QUANTITY_SIDE = {"brdf": "reflection", "ccbrdf": "reflection", "reflectance-factor": "reflection",
                  "btdf": "transmission", "ccbtdf": "transmission", "transmittance-factor": "transmission",
                  "bsdf": None}
#: The configuration name of datasets read from tables and vendor files (one elastic configuration).
CONFIG_NAME = "measured"
_MISSING = {"", "nan", "-nan", "+nan", "na", "n/a", "n.a.", "-", "--", "---", "—", "–", "null", "none", "missing",
            "?", "#n/a", "#value!", "nv", "n.v."}
#: Direction-cosine tolerance of the in-plane and perpendicular arcs (:func:`arc_labels`).
ARC_TOL = 1e-5


# ------------------------------------------------------------------------------------------- quantities
def normalise_quantity(text: str, *, file: str | None = None, field: str = "quantity",
                       line: int | None = None) -> str:
    """One of :data:`QUANTITIES` from a user or file spelling (``BRDF``, ``cc-BRDF``, ``reflectance factor`` …).

    Parameters
    ----------
    text : str
        The spelling to recognise (case, ``_``, ``-`` and spaces do not matter).
    file : str, optional
        File named in the error message.
    field : str, optional
        Field (column, metadata key or option) named in the error message.
    line : int, optional
        Line named in the error message.

    Returns
    -------
    str
        ``brdf``, ``btdf``, ``ccbrdf``, ``ccbtdf``, ``reflectance-factor``, ``transmittance-factor`` or
        ``bsdf``.

    Raises
    ------
    InputError
        ``text`` names no known quantity.
    """
    q = _quantity_from_words(str(text))
    if q is None:
        raise InputError("unknown quantity", file=file, line=line, field=field,
                         expected=" | ".join(QUANTITIES[:-1]), got=str(text))
    return q


def _quantity_from_words(text: str) -> str | None:
    t = text.lower().replace("_", " ").replace("-", " ").strip()
    t = re.sub(r"\s+", " ", t)
    compact = t.replace(" ", "").replace(".", "")
    if re.search(r"(cc|cos(ine)?(corr(ected)?)?)brdf|brdf(\*|x)?cos|cosinecorrectedbrdf|brdfcos", compact):
        return "ccbrdf"
    if re.search(r"(cc|cos(ine)?(corr(ected)?)?)btdf|btdf(\*|x)?cos|cosinecorrectedbtdf|btdfcos", compact):
        return "ccbtdf"
    if re.search(r"(reflectance|refl|reflection|radiance)factor|^b?rf$|bidirectionalreflectancefactor", compact):
        return "reflectance-factor"
    if re.search(r"(transmittance|trans|transmission)factor|^tf$", compact):
        return "transmittance-factor"
    if "brdf" in compact:
        return "brdf"
    if "btdf" in compact:
        return "btdf"
    if "bsdf" in compact:
        return "bsdf"
    return None


def side_of_quantity(quantity: str) -> str | None:
    """The side a quantity fixes (``brdf`` → reflection …), or None for ``bsdf``.

    Parameters
    ----------
    quantity : str
        One of :data:`QUANTITIES` (as :func:`normalise_quantity` gives).

    Returns
    -------
    str or None
        ``"reflection"``, ``"transmission"``, or None when the quantity fixes no side.
    """
    return _QUANTITY_SIDE[quantity]


def _side_word(text: str) -> str | None:
    t = text.strip().lower()
    if t in ("reflection", "reflected", "reflectance", "refl", "r", "brdf", "front", "reflect"):
        return "reflection"
    if t in ("transmission", "transmitted", "transmittance", "trans", "t", "btdf", "back", "transmit"):
        return "transmission"
    return None


def to_bsdf(values: NDArray[np.float64], quantity: str, theta_s_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """BSDF [1/sr] from a table quantity: cosine-corrected values / cos θs, factors / π (broadcast over the
    last axis = wavelength when ``values`` is 2-D). cos θs = 0 gives NaN (no finite BSDF at grazing).

    Parameters
    ----------
    values : ndarray
        Table values in the unit of ``quantity`` (BRDF/BTDF [1/sr], cosine-corrected [1/sr], factors [-]),
        per record, or records × wavelengths.
    quantity : str
        One of :data:`QUANTITIES`.
    theta_s_deg : ndarray
        Scatter polar angle of each record [deg].

    Returns
    -------
    ndarray
        BSDF [1/sr], the shape of ``values``.
    """
    v = np.asarray(values, dtype=np.float64)
    theta = np.asarray(theta_s_deg, dtype=np.float64)
    if quantity in ("ccbrdf", "ccbtdf"):
        cos = np.cos(np.radians(theta))
        cos = np.where(cos > 1e-12, cos, np.nan)
        return v / (cos[:, None] if v.ndim == 2 else cos)
    if quantity in ("reflectance-factor", "transmittance-factor"):
        return v / np.pi
    return v


# ------------------------------------------------------------------------------------------- columns
@dataclass
class _Column:
    index: int
    header: str
    role: str = "ignore"  # theta_i, phi_i, theta_s, phi_s, wavelength, side, value, std, ignore
    scale: float = 1.0  # multiply numbers by this (rad -> deg, um -> nm, % -> fraction)
    percent: bool = False
    quantity: str | None = None
    wavelength: float | None = None  # wide layout: this column's wavelength [nm]
    incidence: float | None = None  # wide layout: this column's incidence [deg]
    relative: bool = False  # std columns: relative to the value
    pair: int | None = None  # std columns: index of the value column they belong to


_UNIT_RE = re.compile(r"[\(\[\{]([^\)\]\}]*)[\)\]\}]")


_PER_SR = re.compile(r"(?:[_\s]|^)(?:1/sr|/sr|per sr|per steradian|sr\^?-1|sr⁻¹|sr\*\*-1)(?=[_\s]|$)", re.IGNORECASE)


def _clean_header(text: str) -> str:
    t = text.replace("\ufeff", "").strip().strip('"').strip("'").strip()
    # camelCase instrument headers ("ScatterAngle", "ThetaI") split into words; "BRDF", "AOI" stay whole
    t = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", t)
    # a per-steradian unit written without brackets ("brdf_sr-1", "BRDF 1/sr") is the value's unit, not a number
    t = _PER_SR.sub(" (1/sr) ", t)
    for a, b in (("θ", "theta"), ("ϑ", "theta"), ("φ", "phi"), ("ϕ", "phi"), ("λ", "lambda"), ("°", " deg "),
                 ("µ", "u"), ("μ", "u"), ("σ", "sigma"), ("±", " std ")):
        t = t.replace(a, b)
    return t


def _units_of(text: str) -> tuple[str, str]:
    """(header without bracketed units, units text) — units also recognised as a trailing _deg/_nm/_rad."""
    units = " ".join(m.group(1) for m in _UNIT_RE.finditer(text)).strip().lower()
    name = _UNIT_RE.sub(" ", text).lower()
    m = re.search(r"(?:[_\s])(deg|degrees?|rad|radians?|mrad|nm|um|microns?|pct|percent)$", name.strip())
    if m and not units:
        units = m.group(1)
        name = name.strip()[: m.start()]
    name = re.sub(r"(?<!\d)\.|\.(?!\d)|[_\-:/]+", " ", name)
    return re.sub(r"\s+", " ", name).strip(), units


def _angle_scale(units: str, header: str, file: str, line: int) -> float:
    u = units.replace(" ", "")
    if u in ("", "deg", "degree", "degrees", "°", "d"):
        return 1.0
    if u in ("rad", "radian", "radians"):
        return 180.0 / math.pi
    if u in ("mrad",):
        return 0.180 / math.pi
    raise FormatError("unknown angle unit in a column header", file=file, line=line, field=header,
                      expected="deg or rad", got=units)


def _wavelength_scale(units: str, header: str, file: str, line: int) -> float:
    u = units.replace(" ", "")
    if u in ("", "nm", "nanometer", "nanometers", "nanometre", "nanometres"):
        return 1.0
    if u in ("um", "micron", "microns", "micrometer", "micrometers", "micrometre", "micrometres"):
        return 1000.0
    if u in ("a", "å", "angstrom", "angstroms"):
        return 0.1
    if u in ("m", "meter", "meters", "metre", "metres"):
        return 1e9  # declared in the header: converted (undeclared metres are refused by _check_units)
    raise FormatError("unknown wavelength unit in a column header", file=file, line=line, field=header,
                      expected="nm, um or m", got=units)


_STD_WORDS = re.compile(r"\b(std|stdev|stddev|std dev|sd|sigma|uncertainty|unc|u|error|err|stderr|"
                        r"standard deviation|standard uncertainty|deviation)\b")
_NUMBER_IN = re.compile(r"(?<![a-z])([0-9]+(?:[.,][0-9]+)?)\s*(nm|um|deg|d)?(?![0-9])")

_ROLE_PATTERNS: tuple[tuple[str, re.Pattern[str]], ...] = (
    ("phi_i", re.compile(r"^(phi ?i|phii|phi inc(ident|idence)?|phi in|incident azimuth|incidence azimuth|"
                         r"azimuth of incidence|source azimuth|illumination azimuth|azimuth i|azi i|"
                         r"phi source|incident phi|phi_i)$")),
    ("theta_i", re.compile(r"^(theta ?i|thetai|theta inc(ident|idence)?|theta in|aoi|angle of incidence|"
                           r"incidence( angle)?|incident( angle)?|inc( angle)?|illumination( angle)?|"
                           r"illumination zenith|source angle|incidence zenith|zenith i|polar i|"
                           r"incident zenith|incident theta|theta source|incident polar angle|ai)$")),
    ("phi_s", re.compile(r"^(phi ?s|phis|phi ?r|phir|phi ?o|phio|phi out|phi scat(ter(ed|ing)?)?|phi det(ector)?|"
                         r"phi v(iew)?|phi|azimuth( angle)?|scatter(ed|ing)? azimuth|detector azimuth|"
                         r"view(ing)? azimuth|observation azimuth|azimuth s|azi|azi s|outgoing azimuth|"
                         r"receiver azimuth|azimuthal angle)$")),
    ("theta_s", re.compile(r"^(theta ?s|thetas|theta ?r|thetar|theta ?o|thetao|theta out|theta scat(ter(ed|ing)?)?|"
                           r"theta det(ector)?|theta v(iew)?|theta|scatter(ed|ing)?( angle)?|measure(ment|d)?( angle)?|"
                           r"detector( angle)?|observation( angle)?|view(ing)?( angle)?|reflection angle|aov|aos|det|"
                           r"angle of (view|observation|scatter(ing)?|reflection|detection|emergence)|"
                           r"emergence( angle)?|exit( angle)?|outgoing( angle)?|polar( angle)?|zenith( angle)?|"
                           r"zenith s|polar s|receiver( angle)?|angle|in plane angle|signed angle|"
                           r"signed scatter(ing)? angle|scatter angle signed|as)$")),
    ("wavelength", re.compile(r"^(wavelength|wave length|lambda|wl|wvl|nm|um|wavelength nm)$")),
    ("side", re.compile(r"^(side|hemisphere|mode|type|r ?t|scatter type|geometry)$")),
    ("value", re.compile(r"^(value|values|data)$")),
)


def _classify(header: str, index: int, file: str, line: int) -> _Column:
    raw = _clean_header(header)
    name, units = _units_of(raw)
    col = _Column(index=index, header=header.strip())
    if not name and not units:
        raise FormatError("empty column header", file=file, line=line, field=f"column {index + 1}",
                          expected="a column name", got=header)
    low = raw.lower()
    percent = "%" in low or units in ("pct", "percent")
    # uncertainty columns first ("BRDF std", "u(BRDF)", "uncertainty (%)")
    if _STD_WORDS.search(name) or re.match(r"^u ?\(", raw.strip().lower()):
        col.role = "std"
        col.relative = bool(re.search(r"\brel(ative)?\b|rsd|cv", name))
        col.percent = percent
        col.quantity = _quantity_from_words(name)
        return col
    # "theta_s signed", "signed scatter angle": signedness follows from the layout (no φs column)
    unsigned = re.sub(r"\s*\bsigned\b\s*", " ", name).strip() or name
    for role, pattern in _ROLE_PATTERNS:
        if pattern.match(name) or (role == "theta_s" and pattern.match(unsigned)):
            col.role = role
            if role in ("theta_i", "phi_i", "theta_s", "phi_s"):
                col.scale = _angle_scale(units, col.header, file, line)
            elif role == "wavelength":
                col.scale = _wavelength_scale("um" if name == "um" else units, col.header, file, line)
            elif role == "value":
                col.percent = percent
            return col
    quantity = _quantity_from_words(name)
    # a number in the header: wide layout (wavelength or incidence per column)
    number = _NUMBER_IN.search(name)
    if number is not None:
        value = float(number.group(1).replace(",", "."))
        unit = (number.group(2) or "").lower()
        if not unit and units.replace(" ", "") in ("nm", "um", "deg", "micron", "microns"):
            unit = units.replace(" ", "")[:2]
        rest = (name[: number.start()] + " " + name[number.end():]).strip()
        incidence_words = re.search(r"\b(aoi|inc|incidence|incident|theta ?i|thetai|ai)\b", rest)
        if unit in ("deg", "d") or incidence_words:
            if not 0.0 <= value < 90.0:
                raise FormatError("incidence in a column header out of range", file=file, line=line,
                                  field=col.header, expected="0 <= incidence < 90 deg", got=value)
            col.role, col.incidence, col.quantity, col.percent = "value", value, quantity, percent
            return col
        scale = 1.0
        if unit == "um" or units in ("um", "micron", "microns"):
            scale = 1000.0
        lam = value * scale
        if unit or units in ("nm",) or 100.0 <= lam <= 100000.0 or quantity or re.search(r"lambda|wl|wavelength",
                                                                                            rest):
            if not lam > 0:
                raise FormatError("wavelength in a column header must be positive", file=file, line=line,
                                  field=col.header, expected="> 0 nm", got=value)
            col.role, col.wavelength, col.quantity, col.percent = "value", lam, quantity, percent
            return col
        raise FormatError("column header holds a number that is neither a wavelength nor an incidence",
                          file=file, line=line, field=col.header,
                          expected="'550 nm' (wavelength) or 'AOI 10' / '10 deg' (incidence)", got=header.strip())
    if quantity is not None or re.match(r"^(reflectance|transmittance|r|t)$", name):
        col.role, col.quantity, col.percent = "value", quantity, percent
        if quantity is None:
            col.quantity = None  # "Reflectance", "R": a value whose quantity the file does not say
        return col
    col.role = "ignore"
    return col


# ------------------------------------------------------------------------------------------- text
@dataclass
class _Text:
    path: str
    lines: list[tuple[int, str]]  # (line number, text) of non-empty, non-comment lines
    comments: list[tuple[int, str]]
    encoding: str
    last_line: int
    text: str = ""


def _decode(raw: bytes, path: str) -> tuple[str, str]:
    # Windows instrument software writes cp1252 when it does not write UTF-8 or UTF-16
    return text_and_encoding(raw, path, expected="a text table", legacy="cp1252")


#: Bytes read at a time when a table is checked and streamed (the text of a table is never held whole).
_READ_BYTES = 1 << 20
#: Bytes at the end of a file read to check its last line (:func:`refuse_cut_last_line`).
_TAIL_BYTES = 1 << 18
#: Non-comment lines kept from the head of a table to find its header, metadata and decimal separator.
_HEAD_LINES = 280


class _Source:
    """The physical lines of a table file, streamed from disk for each pass.

    The bytes are first checked as a whole, in blocks of :data:`_READ_BYTES`: UTF-8 (or UTF-16/32 with a
    byte-order mark, or unmarked UTF-16) without a NUL byte is then streamed line by line, numbered as
    ``str.splitlines`` numbers them. Any other file (Windows-1252, binary, empty) is decoded whole by
    :func:`_decode`, which gives the one-line error or the legacy text.
    """

    def __init__(self, path: str) -> None:
        p = Path(path)
        if p.is_dir():
            raise InputError("is a folder, not a table", file=path, expected="a text table file")
        if not p.is_file():
            raise InputError("file not found", file=path, expected="a text table")
        self.path = path
        self.text: str | None = None
        try:
            with open(p, "rb") as fh:
                head = fh.read(4096)
                bom, codec = next(((b, enc) for b, enc in _BOMS if head.startswith(b)), (b"", None))
                codec = codec or _unmarked_utf16(head) or "utf-8"
                fh.seek(len(bom))
                decoder = codecs.getincrementaldecoder(codec)()
                plain, blank = True, True
                try:
                    while chunk := fh.read(_READ_BYTES):
                        part = decoder.decode(chunk)
                        if "\x00" in part:
                            plain = False
                            break
                        blank = blank and not part.strip()
                    decoder.decode(b"", final=True)
                except UnicodeDecodeError:
                    plain = False
            if not plain or blank:
                self.text, self.encoding = _decode(p.read_bytes(), path)
        except OSError as exc:
            raise InputError(f"cannot read file ({exc.strerror})", file=path) from None
        if self.text is None:
            self.codec, self.skip = codec, len(bom)
            self.encoding = "utf-8-sig" if bom == codecs.BOM_UTF8 else codec

    def lines(self) -> Iterator[tuple[int, str]]:
        """(line number from 1, text without its line break) of every physical line."""
        if self.text is not None:
            yield from enumerate(self.text.splitlines(), start=1)
            return
        number = 0
        with open(self.path, "rb") as raw:
            raw.seek(self.skip)
            with io.TextIOWrapper(raw, encoding=self.codec, newline=None) as fh:
                for physical in fh:
                    for piece in physical.splitlines():
                        number += 1
                        yield number, piece

    def tail(self) -> str:
        """The end of the text (whole lines, the last one as in the file, with or without its line break)."""
        if self.text is not None:
            return self.text
        size = Path(self.path).stat().st_size
        if self.codec == "utf-8" and size > 2 * _TAIL_BYTES:
            with open(self.path, "rb") as fh:
                fh.seek(size - _TAIL_BYTES)
                block = fh.read()
            cut = block.find(b"\n")
            if cut >= 0:
                return block[cut + 1:].decode("utf-8")
        return "\n".join(line for _, line in self.lines()) + ("" if self._ends_open() else "\n")

    def _ends_open(self) -> bool:
        with open(self.path, "rb") as fh:
            fh.seek(max(self.skip, Path(self.path).stat().st_size - 8))
            end = fh.read()
        return not end.replace(b"\x00", b"").endswith((b"\n", b"\r"))

    def count_lines(self) -> int:
        """How many physical lines the file has."""
        return sum(1 for _ in self.lines())


def _load_text(path: str, source: _Source | None = None) -> _Text:
    """The head of a table: its first :data:`_HEAD_LINES` non-empty, non-comment lines and the comments among
    them (the rest is streamed by :func:`read_table`)."""
    source = source or _Source(path)
    lines, comments = [], []
    number = 0
    for number, line in source.lines():
        body = line.strip().lstrip("\ufeff").strip()
        if not body or not body.strip(",;\t "):
            continue
        if body.startswith(_COMMENTS):
            comments.append((number, body.lstrip("#/%! ").strip()))
            continue
        lines.append((number, line.lstrip("\ufeff")))
        if len(lines) >= _HEAD_LINES:
            break
    return _Text(path, lines, comments, source.encoding, number)


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [c.strip() for c in next(csv.reader([line], delimiter=delimiter, quotechar='"', skipinitialspace=True))]


def _fields(line: str, delimiter: str | None) -> list[str]:
    """Cells of a line without trailing empty cells (trailing separators are common in exports)."""
    cells = _split(line, delimiter)
    while len(cells) > 1 and not cells[-1].strip():
        cells.pop()
    return cells


def _sniff_delimiter(lines: list[str]) -> str | None:
    """Tab, semicolon or comma: the first that splits the first line into ≥ 2 fields with a consistent count
    over the following lines; whitespace when none does."""
    head = lines[0]
    following = lines[1:20]
    best: str | None = None
    for delim in ("\t", ";", ","):
        n = len(_fields(head, delim))
        if n < 2:
            continue
        if not following or all(len(_fields(x, delim)) == n for x in following):
            return delim
        if best is None and sum(len(_fields(x, delim)) == n for x in following) >= 0.5 * len(following):
            best = delim
    if best is not None:
        return best
    return None


_META_KEYS = {
    "quantity": re.compile(r"^(quantity|type|data type|measured quantity|measurand|units? of data|data)$"),
    "side": re.compile(r"^(side|hemisphere|scatter type|scattertype)$"),
    "wavelength": re.compile(r"^(wavelength|lambda|wl|wavelength nm)$"),
    "incidence": re.compile(r"^(incidence|aoi|theta i|thetai|angle of incidence|incidence angle|incident angle)$"),
    "phi_i": re.compile(r"^(phi i|phii|incident azimuth|source azimuth)$"),
    "relative_std": re.compile(r"^(relative std|relative uncertainty|rel std|relative standard uncertainty)$"),
    "sample": re.compile(r"^(sample|sample name|material|specimen|name)$"),
}


def _metadata(entries: list[tuple[int, str]]) -> dict[str, tuple[str, int]]:
    """``key: value`` / ``key = value`` / ``key,value`` pairs → known metadata keys (value, line)."""
    out: dict[str, tuple[str, int]] = {}
    for number, text in entries:
        m = re.match(r"^\s*([^:=,;\t]+?)\s*[:=,;\t]\s*(.+?)\s*$", text)
        if not m:
            continue
        key_raw = _clean_header(m.group(1))
        key, units = _units_of(key_raw)
        value = m.group(2).strip().strip('"').strip(",;").strip()
        for name, pattern in _META_KEYS.items():
            if pattern.match(key) and name not in out:
                out[name] = (value + (f" {units}" if units else ""), number)
    return out


def _meta_number(meta: dict[str, tuple[str, int]], key: str, path: str, unit_scale: dict[str, float],
                 default_unit: str) -> float | None:
    if key not in meta:
        return None
    text, number = meta[key]
    m = re.match(r"^\s*([+-]?[0-9]*[.,]?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([a-zA-Zµ%°]*)\s*$", text)
    if not m:
        raise FormatError("metadata value is not a number", file=path, line=number, field=key,
                          expected=f"a number in {default_unit}", got=text)
    unit = (m.group(2) or default_unit).lower().replace("µ", "u").replace("°", "deg")
    if unit not in unit_scale:
        raise FormatError("unknown unit in metadata", file=path, line=number, field=key,
                          expected=" or ".join(unit_scale), got=m.group(2))
    return float(m.group(1).replace(",", ".")) * unit_scale[unit]


# ------------------------------------------------------------------------------------------- numbers
def _number(cell: str, decimal_comma: bool) -> float:
    """float of a cell; NaN for a gap; raises ValueError for text."""
    t = cell.strip().strip('"').strip()
    if t.lower() in _MISSING:
        return math.nan
    if decimal_comma:
        t = t.replace(",", ".")
    t = t.replace("\u2212", "-")
    value = float(t)
    return value


# ------------------------------------------------------------------------------------------- the reader
@dataclass
class _Rows:
    """What the parser found: one entry per (row, value column) with a finite or NaN value.

    Numbers in float64 arrays (8 bytes an entry); a quantity constant over the table is a read-only broadcast
    array. ``spec`` is the index of the entry's value column in ``quantities`` / ``headers``; ``side`` is 0 for
    reflection, 1 for transmission; ``line`` the physical line of the row.
    """

    theta_i: NDArray[np.float64]
    phi_i: NDArray[np.float64]
    theta_s: NDArray[np.float64]  # signed for in-plane tables
    phi_s: NDArray[np.float64]
    wavelength: NDArray[np.float64]
    value: NDArray[np.float64]
    std: NDArray[np.float64]
    std_relative: NDArray[np.bool_]
    side: NDArray[np.int8]
    spec: NDArray[np.int16]
    line: NDArray[np.integer]
    quantities: list[str]
    headers: list[str]

    def column(self, k: int) -> str:
        """Header of the value column of entry ``k``."""
        return self.headers[int(self.spec[k])]

    def quantity(self, k: int) -> str:
        """Quantity of entry ``k``."""
        return self.quantities[int(self.spec[k])]


def _find_header(text: _Text) -> tuple[int, str | None, list[_Column], list[tuple[int, str]]]:
    """Index (in text.lines) of the header row, its delimiter and columns, and the preamble lines before it."""
    if not text.lines:
        raise FormatError("empty table (no header, no data)", file=text.path, line=max(text.last_line, 1),
                          expected="a header line and data rows")
    preamble: list[tuple[int, str]] = []
    first_error: FormatError | None = None
    for k, (number, line) in enumerate(text.lines[:200]):
        following = [x for _, x in text.lines[k + 1: k + 21]]
        delim = _sniff_delimiter([line, *following])
        cells = _fields(line, delim)
        if (delim is None or len(cells) <= 2) and re.match(r"^\s*[^\d\s,;\t][^,;\t]*?\s*[:=]\s*\S", line) \
                and not re.search(r"[:=]\s*[\d.]+\s*(nm|um|deg)?\s*[,;\t]", line):
            preamble.append((number, line))  # 'key: value' metadata, not a header
            continue
        if cells and all(_is_numberlike(c) for c in cells if c.strip()):
            if first_error is not None:
                raise first_error
            raise FormatError("data before a header line", file=text.path, line=number, field="header",
                              expected="a header naming the columns (e.g. theta_i, theta_s, BRDF)",
                              got=line.strip()[:60])
        try:
            columns = [_classify(c, i, text.path, number) for i, c in enumerate(cells)]
        except FormatError as exc:
            first_error = first_error or exc
            preamble.append((number, line))
            continue
        roles = {c.role for c in columns}
        angle = roles & {"theta_s", "theta_i"} or any(c.incidence is not None for c in columns)
        if angle and ("value" in roles) and len(cells) >= 2:
            return k, delim, columns, preamble
        if ("theta_s" in roles or "theta_i" in roles) and "value" not in roles:
            first_error = first_error or FormatError(
                "header has no value column", file=text.path, line=number, field="header",
                expected="a value column (BRDF, BTDF, value, reflectance factor, or one per wavelength '550 nm')",
                got=[c.header for c in columns][:8])
        preamble.append((number, line))
    if first_error is not None:
        raise first_error
    number, line = text.lines[0]
    raise FormatError("no header line with angle and value columns", file=text.path, line=number, field="header",
                      expected="columns such as theta_i, theta_s (or a signed scatter angle), BRDF",
                      got=line.strip()[:60])


def _is_numberlike(cell: str) -> bool:
    t = cell.strip().strip('"').replace(",", ".").replace("\u2212", "-")
    if t.lower() in _MISSING:
        return True
    try:
        float(t)
    except ValueError:
        return False
    return True


def _resolve_quantity(columns: list[_Column], meta: dict[str, tuple[str, int]], quantity: str | None,
                      path: str, header_line: int) -> None:
    """Give every value/std column its quantity; errors when none is stated or statements disagree."""
    given = normalise_quantity(quantity, field="--quantity") if quantity is not None else None
    # a 'type:'/'data:' line that names no quantity is not a statement
    meta_q = _quantity_from_words(meta["quantity"][0]) if "quantity" in meta else None
    for col in columns:
        if col.role not in ("value", "std"):
            continue
        stated = col.quantity or meta_q
        where_line = header_line if col.quantity else (meta["quantity"][1] if meta_q else header_line)
        if given is not None and stated is not None and stated != given:
            if not (stated == "bsdf" and given in ("brdf", "btdf")):
                raise InputError("the table states another quantity than --quantity", file=path, line=where_line,
                                 field=col.header, expected=given, got=stated)
        q = given or stated
        if q is None:
            if col.role == "std":
                continue
            raise InputError("the table does not say which quantity it holds; pass --quantity", file=path,
                             line=header_line, field=col.header,
                             expected="--quantity " + "|".join(QUANTITIES[:-1]), got=col.header)
        col.quantity = q
    for col in columns:
        if col.role == "std" and col.quantity is None:
            col.quantity = next((c.quantity for c in columns if c.role == "value"), None)


def _pair_std(columns: list[_Column], path: str, line: int) -> None:
    values = [c for c in columns if c.role == "value"]
    stds = [c for c in columns if c.role == "std"]
    if not stds:
        return
    if len(values) == 1:
        if len(stds) > 1:
            raise FormatError("several uncertainty columns for one value column", file=path, line=line,
                              field=stds[1].header, expected="one std column", got=[s.header for s in stds])
        stds[0].pair = values[0].index
        return
    # wide/several values: pair by wavelength/incidence in the header, else by quantity, else by position
    for s_col in stds:
        number = _NUMBER_IN.search(_units_of(_clean_header(s_col.header))[0])
        match = None
        if number is not None:
            v = float(number.group(1).replace(",", "."))
            for c in values:
                if (c.wavelength is not None and abs(c.wavelength - v) < 1e-6) or (
                        c.incidence is not None and abs(c.incidence - v) < 1e-9):
                    match = c
                    break
        if match is None and s_col.quantity is not None:
            same = [c for c in values if c.quantity == s_col.quantity]
            if len(same) == 1:
                match = same[0]
        if match is None:
            before = [c for c in values if c.index < s_col.index]
            match = before[-1] if before else None
        if match is None:
            raise FormatError("cannot tell which value column an uncertainty column belongs to", file=path,
                              line=line, field=s_col.header, expected="a std column right after its value column")
        s_col.pair = match.index


def _events(source: _Source, after: int, skip: int | None, comments: list[tuple[int, str]]
            ) -> Iterator[tuple[str, int, str]]:
    """``("data", line, text)`` and ``("comment", line, text)`` of the lines after line ``after`` (the
    header) but ``skip`` (a units row); blank lines left out; the comments are also appended to ``comments``."""
    for number, line in source.lines():
        if number <= after or number == skip:
            continue
        body = line.strip().lstrip("\ufeff").strip()
        if not body or not body.strip(",;\t "):
            continue
        if body.startswith(_COMMENTS):
            entry = (number, body.lstrip("#/%! ").strip())
            comments.append(entry)
            yield "comment", entry[0], entry[1]
            continue
        yield "data", number, line.lstrip("\ufeff")


def _rows_estimate(path: str, head: list[tuple[int, str]]) -> int:
    """Data rows a table probably holds: its size over the mean length of the first data rows, plus a quarter."""
    length = sum(len(t) + 1 for _, t in head[:200]) / max(len(head[:200]), 1)
    return int(1.25 * Path(path).stat().st_size / max(length, 1.0)) + 1024


def _states_incidence(events: Iterator[tuple[str, int, str]], delim: str | None) -> bool:
    """Whether a comment or a ``key: value`` line after the header states an incidence (a pass over the file)."""
    for kind, line, text in events:
        if kind == "comment" or not _is_numberlike(_fields(text, delim)[0]):
            if "incidence" in _metadata([(line, text)]):
                return True
    return False


def _refuse_cut_end(source: _Source, path: str, delim: str | None) -> None:
    """:func:`refuse_cut_last_line` on the end of the file (read from its tail), with the file's line count."""
    try:
        refuse_cut_last_line(source.tail(), path, delim, expected="a row of numbers", comments=_COMMENTS)
    except FormatError as exc:
        raise FormatError("the file ends inside a number (truncated?)", file=path, line=source.count_lines(),
                          expected=exc.expected, got=exc.got) from None


def _check_options(zeros: str, side: str | None, relative_std: float | None, wavelength: float | None) -> None:
    """Refuse options of :func:`read_table` outside their domain (before the file is opened)."""
    if zeros not in ZERO_POLICIES:
        raise InputError("unknown zero policy", field="zeros", expected=" | ".join(ZERO_POLICIES), got=zeros)
    if side is not None and side not in SIDES:
        raise InputError("unknown side", field="--side", expected="reflection | transmission", got=side)
    if relative_std is not None and not (np.isfinite(relative_std) and relative_std > 0):
        raise InputError("relative standard uncertainty must be a positive fraction", field="--relative-std",
                         expected="> 0 (e.g. 0.05 for 5 %)", got=relative_std)
    if wavelength is not None and not (np.isfinite(wavelength) and wavelength > 0):
        raise InputError("wavelength must be positive", field="--wavelength", expected="> 0 nm", got=wavelength)


def _roles_of(columns: list[_Column], path: str, header_line: int) -> dict[str, list[_Column]]:
    """The columns by role; at most one column per angle, wavelength and side."""
    roles: dict[str, list[_Column]] = {}
    for c in columns:
        roles.setdefault(c.role, []).append(c)
    for role in ("theta_i", "phi_i", "theta_s", "phi_s", "wavelength", "side"):
        if len(roles.get(role, [])) > 1:
            raise FormatError(f"two columns for {role}", file=path, line=header_line, field=roles[role][1].header,
                              expected=f"one {role} column", got=[c.header for c in roles[role]])
    return roles


def _check_header_layout(columns: list[_Column], roles: dict[str, list[_Column]], path: str, header_line: int,
                         wavelength: float | None, incidence: float | None) -> None:
    """Refuse a header whose layout contradicts itself or the options: wavelengths or incidences both in a
    column and in value headers (or also given as an option), no scatter angle, wavelength columns repeated
    or not increasing."""
    values = roles.get("value", [])
    wide_wl = [c for c in values if c.wavelength is not None]
    wide_inc = [c for c in values if c.incidence is not None]
    if wide_wl and "wavelength" in roles:
        raise FormatError("wavelength both in a column and in value headers", file=path, line=header_line,
                          field=roles["wavelength"][0].header, expected="one of the two layouts")
    if wide_inc and "theta_i" in roles:
        raise FormatError("incidence both in a column and in value headers", file=path, line=header_line,
                          field=roles["theta_i"][0].header, expected="one of the two layouts")
    if "theta_s" not in roles:
        raise FormatError("no scatter-angle column", file=path, line=header_line, field="header",
                          expected="theta_s (with phi_s) or a signed in-plane scatter angle",
                          got=[c.header for c in columns][:8])
    if wavelength is not None and (wide_wl or "wavelength" in roles):
        raise InputError("the table states its wavelengths; --wavelength is for monochrome tables", file=path,
                         line=header_line, field="--wavelength", got=wavelength)
    wl_list = [c.wavelength for c in wide_wl]
    if len(set(np.round(wl_list, 9))) != len(wl_list):
        first, dup = [c for c in wide_wl if wl_list.count(c.wavelength) > 1][:2]
        raise FormatError(f"wavelength given twice in the header: {_column_name(first)} and {_column_name(dup)} "
                          "would be read as two measurements", file=path, line=header_line, field=dup.header,
                          expected="distinct wavelengths", got=dup.wavelength)
    if len(wl_list) > 1 and np.any(np.diff(wl_list) <= 0):
        bad = next(wide_wl[i + 1] for i in range(len(wl_list) - 1) if wl_list[i + 1] <= wl_list[i])
        raise FormatError("wavelength columns not increasing", file=path, line=header_line, field=bad.header,
                          expected="increasing wavelengths", got=bad.wavelength)
    if incidence is not None and ("theta_i" in roles or wide_inc):
        raise InputError("the table states its incidences; --incidence is for tables without them", file=path,
                         line=header_line, field="--incidence", got=incidence)


def _refuse_side_not_held(side: str | None, held: list[str], how: str, path: str, line: int | None) -> None:
    """Refuse ``side`` (``--side``) when the table holds none of it: the side asked and the sides it holds (``held``,
    as ``how`` says they are known) in one line, at ``line`` (the first data row, which holds another side)."""
    if side is None or side in held or not held:
        return
    raise InputError(f"the table holds no {side} data, only {' and '.join(held)} ({how})", file=path, line=line,
                     field="--side", expected=f"--side {' or '.join(held)} (or no --side)", got=side)


def _column_name(col: _Column) -> str:
    """``column N 'header'`` (N from 1), as the messages name a column."""
    return f"column {col.index + 1} '{col.header}'"


def _refuse_repeated_values(columns: list[_Column], path: str, header_line: int) -> None:
    """Refuse two value columns that hold the same thing: the same quantity at the same wavelength and incidence
    (``BRDF`` twice, ``brdf`` and ``BRDF [1/sr]``, ``AOI 10`` twice). Each would be read as a measurement of its
    own, a repetition of every direction, and count twice in every sum (TIS). Called once the quantities are
    resolved (:func:`_resolve_quantity`)."""
    seen: dict[tuple[Any, ...], _Column] = {}
    for c in columns:
        if c.role != "value":
            continue
        key = (c.quantity, None if c.wavelength is None else round(c.wavelength, 9),
               None if c.incidence is None else round(c.incidence, 9))
        if key in seen:
            first = seen[key]
            same = "the same header" if first.header.lower() == c.header.lower() else "the same quantity"
            raise FormatError(f"value column given twice: {_column_name(first)} and {_column_name(c)} name "
                              f"{same}, and would be read as two measurements of every direction", file=path,
                              line=header_line, field=c.header,
                              expected="one value column per quantity, wavelength and incidence (rename or "
                                       "remove the copy)", got=[first.header, c.header])
        seen[key] = c


def _default_side(meta: dict[str, tuple[str, int]], side: str | None, path: str) -> str | None:
    """The side of rows without a side column: ``--side`` or the metadata's (which must agree)."""
    side_meta = None
    if "side" in meta:
        side_meta = _side_word(meta["side"][0]) or _side_of_words(meta["side"][0])
        if side_meta is None:
            raise InputError("unknown side in the metadata", file=path, line=meta["side"][1], field="side",
                             expected="reflection or transmission", got=meta["side"][0])
    if side is not None and side_meta is not None and side != side_meta:
        raise InputError("--side contradicts the table", file=path, line=meta["side"][1], field="side",
                         expected=side_meta, got=side)
    return side or side_meta


def _provenance(layout: _Layout, text: _Text, header_line: int, meta: dict[str, tuple[str, int]],
                comments: list[tuple[int, str]], stated: list[str]) -> dict[str, Any]:
    """How the table was read (``manifest_json`` of its dataset): layout, delimiter, encoding, the role of each
    column, the metadata and the first comments."""
    columns = layout.columns
    wide = any(c.wavelength is not None or c.incidence is not None for c in columns if c.role == "value")
    return {
        "format": "measured-table",
        "reader": f"bsdfkit.measurement.table {__version__}",
        "layout": "wide" if wide else "long",
        "delimiter": {"\t": "tab", ";": "semicolon", ",": "comma", None: "whitespace"}[layout.delim],
        "decimal_comma": bool(layout.decimal_comma),
        "encoding": text.encoding,
        "header_line": header_line,
        "columns": {c.header: (c.role if c.role not in ("value", "std") else
                               f"{c.role} ({c.quantity}"
                               + (f", {c.wavelength:g} nm" if c.wavelength is not None else "")
                               + (f", theta_i {c.incidence:g} deg" if c.incidence is not None else "") + ")")
                    for c in columns},
        "metadata": {k: v for k, (v, _) in meta.items()},
        "comments": [c for _, c in comments][:50],
        "quantity": stated,
        "signed_in_plane_angle": layout.signed,
    }


def _row_defaults(meta: dict[str, tuple[str, int]], path: str, wavelength: float | None,
                  incidence: float | None, phi_i: float | None) -> _RowDefaults:
    """θi, φi [deg] and wavelength [nm] of rows without such columns: the options, else the metadata (φi
    180°); the side is set later (:func:`_default_side`)."""
    meta_lambda = _meta_number(meta, "wavelength", path, {"nm": 1.0, "um": 1000.0}, "nm")
    meta_inc = _meta_number(meta, "incidence", path, {"deg": 1.0, "rad": 180.0 / math.pi}, "deg")
    meta_phi = _meta_number(meta, "phi_i", path, {"deg": 1.0, "rad": 180.0 / math.pi}, "deg")
    return _RowDefaults(theta_i=incidence if incidence is not None else meta_inc,
                        phi_i=phi_i if phi_i is not None else (meta_phi if meta_phi is not None else 180.0),
                        wavelength=wavelength if wavelength is not None else meta_lambda, side=None)


def _data_head(text: _Text, k_header: int, delim: str | None, columns: list[_Column]
               ) -> tuple[list[tuple[int, str]], int | None]:
    """The data lines of the table's head and the line of a units row right after the header (applied to the
    columns), or None; refuses a header without data rows."""
    header_line = text.lines[k_header][0]
    data = text.lines[k_header + 1:]
    units_line = None
    if data and _units_row(data[0][1], delim, columns, text.path, data[0][0]):
        units_line = data[0][0]
        data = data[1:]
    if not data:
        raise FormatError("header only, no data rows", file=text.path, line=header_line, field="data",
                          expected="data rows after the header")
    return data, units_line


def read_table(path: str | Path, quantity: str | None = None, side: str | None = None,
               relative_std: float | None = None, *, wavelength_nm: float | None = None,
               incidence_deg: float | None = None, phi_i_deg: float | None = None, zeros: str = "auto",
               sample: str | None = None) -> xr.Dataset:
    """Read a measured BSDF text table into the calibrated BSDF dataset schema.

    Parameters
    ----------
    path
        The table (layouts, headers and rules in the module docstring and ``docs/raw-format.md``).
    quantity
        What the values are where the file does not say: ``brdf``, ``btdf``, ``ccbrdf``, ``ccbtdf``,
        ``reflectance-factor``, ``transmittance-factor`` (also ``bsdf``, with ``side``). Never guessed.
    side
        ``reflection`` or ``transmission`` where neither a side column nor the quantity fixes it.
    relative_std
        Standard uncertainty as a fraction of the value when the table has no uncertainty column
        (default: the file's ``# relative_std:``, else :data:`DEFAULT_RELATIVE_STD` = 0.05).
    wavelength_nm
        Wavelength [nm] of a monochrome table (one without wavelength columns); without it such a table gets
        a single NaN wavelength and the attribute ``wavelength_note``.
    incidence_deg, phi_i_deg
        θi and φi [deg] when the table has no such column (default φi = 180°, the specular side at φs = 0).
    zeros
        ``auto`` | ``keep`` | ``missing``: what an exact 0 means (module docstring).
    sample
        Sample name (default: the file's ``# sample:``, else the file name).

    Returns
    -------
    xarray.Dataset
        ``bsdf``, ``bsdf_std`` [1/sr] on (record, wavelength [nm]) with the coords and attributes of
        :func:`bsdfkit.measurement.calibrate.calibrate` (``quantity = "bsdf"``); the table's own quantity is
        ``attrs['source_quantity']``.
    """
    path = str(path)
    _check_options(zeros, side, relative_std, wavelength_nm)
    source = _Source(path)
    text = _load_text(path, source)  # the head of the file; the data rows are streamed by _parse_rows
    k_header, delim, columns, preamble = _find_header(text)
    _refuse_cut_end(source, path, delim)
    header_line = text.lines[k_header][0]
    comments = [c for c in text.comments if c[0] < header_line]
    meta = _metadata(comments + preamble)
    data, units_line = _data_head(text, k_header, delim, columns)
    roles = _roles_of(columns, path, header_line)
    _check_header_layout(columns, roles, path, header_line, wavelength_nm, incidence_deg)
    _resolve_quantity(columns, meta, quantity, path, header_line)
    _refuse_repeated_values(columns, path, header_line)
    _pair_std(columns, path, header_line)
    defaults = _row_defaults(meta, path, wavelength_nm, incidence_deg, phi_i_deg)
    meta_rel = _meta_number(meta, "relative_std", path, {"": 1.0, "%": 0.01}, "")
    wide_inc = any(c.incidence is not None for c in roles.get("value", []))
    if "theta_i" not in roles and not wide_inc and defaults.theta_i is None \
            and not _states_incidence(_events(source, header_line, units_line, []), delim):
        raise FormatError("no incidence column", file=path, line=header_line, field="header",
                          expected="a theta_i / AOI / incidence column, '# incidence: 10 deg', or --incidence",
                          got=[c.header for c in columns][:8])
    fixed = [c for c in roles["value"] if side_of_quantity(c.quantity) is not None]
    if len(fixed) == len(roles["value"]):  # every value column's quantity fixes its side
        more = f" and {len(fixed) - 1} more" if len(fixed) > 1 else ""
        _refuse_side_not_held(side, [x for x in SIDES if any(side_of_quantity(c.quantity) == x for c in fixed)],
                              f"its values are {'/'.join(sorted({str(c.quantity) for c in fixed}))}: "
                              f"{_column_name(fixed[0])}{more}", path, data[0][0])  # the first row of them
    defaults = replace(defaults, side=_default_side(meta, side, path))
    rel = relative_std if relative_std is not None else meta_rel
    decimal_comma = delim in ("\t", ";", None) and _uses_decimal_comma(data, delim)
    layout = _layout(path, delim, columns, roles, decimal_comma, _fields(text.lines[k_header][1], delim))
    rows = _parse_rows(_events(source, header_line, units_line, comments), layout, defaults,
                       _rows_estimate(path, data))
    _refuse_cut_last_block(path, rows)
    if "side" in roles:  # the side column decides the side of its rows, whatever --side says
        codes = set(np.unique(rows.side).tolist()) if rows.side.strides != (0,) else {int(rows.side[0])}
        _refuse_side_not_held(side, [x for k, x in enumerate(SIDES) if k in codes],
                              f"the rows of its side column, {_column_name(roles['side'][0])}", path,
                              int(rows.line[0]))
    _check_units(path, rows, roles)
    _check_values(path, rows, rel)
    stated = sorted({rows.quantities[k] for k in np.unique(rows.spec).tolist()})
    ds = _assemble(path, rows, layout.signed, rel, zeros)
    provenance = _provenance(layout, text, header_line, meta, comments, stated)
    ds.attrs.update(
        source_format="text table",
        source_layout=provenance["layout"],
        source_quantity=" ".join(stated),
        sample_name=sample or (meta["sample"][0] if "sample" in meta else Path(path).stem),
        manifest_json=json.dumps(provenance),
    )
    return ds


_UNIT_CELL = re.compile(r"^[\(\[]?\s*(deg|degrees?|°|rad|radians?|mrad|nm|um|µm|μm|micron|a|å|1/sr|sr-1|sr\^-1|/sr|"
                        r"sr⁻¹|%|-|a\.u\.|au|arb\.?|none|1|counts)?\s*[\)\]]?$", re.IGNORECASE)


def _units_row(line: str, delim: str | None, columns: list[_Column], path: str, number: int) -> bool:
    """A row of units right after the header (``deg, deg, nm, 1/sr``): apply it to the columns and return True."""
    cells = _fields(line, delim)
    if len(cells) > len(columns) or any(_is_numberlike(c) and c.strip() not in ("-", "") for c in cells):
        return False
    units = [c.strip().strip('"').lower().strip("()[] ").replace("µ", "u").replace("μ", "u").replace("°", "deg")
             for c in cells]
    if not any(units) or not all(_UNIT_CELL.match(c.strip().strip('"')) for c in cells):
        return False
    for col, unit in zip(columns, units):
        if not unit:
            continue
        if col.role in ("theta_i", "phi_i", "theta_s", "phi_s"):
            col.scale = _angle_scale(unit, col.header, path, number)
        elif col.role == "wavelength":
            col.scale = _wavelength_scale(unit, col.header, path, number)
        elif col.role in ("value", "std") and unit == "%":
            col.percent = True
    return True


def _side_of_words(text: str) -> str | None:
    q = _quantity_from_words(text)
    return None if q is None else side_of_quantity(q)


def _uses_decimal_comma(data: list[tuple[int, str]], delim: str | None) -> bool:
    pattern = re.compile(r"^[+-]?\d*,\d+([eE][+-]?\d+)?$")
    for _, line in data[:50]:
        for cell in _split(line, delim):
            c = cell.strip()
            if pattern.match(c):
                return True
            if re.match(r"^[+-]?\d*\.\d+", c):
                return False
    return False


#: Entries handled at a time by the whole-table checks (their temporaries stay a few MB).
_SLICE = 1 << 16


def _codes(x: Any, key: Any = None, n: int | None = None) -> tuple[NDArray, int]:
    """Integer codes 0..m-1 of the classes of equal ``key(x)`` and m, computed in slices of :data:`_SLICE`.

    ``x`` is an array or a function of a slice giving the values there (then ``n`` is the length); ``key`` an
    elementwise function applied to the distinct values only. NaN is one class. Codes follow the order of the
    distinct values; a constant (broadcast) column gets one class without memory.
    """
    get = x if callable(x) else (lambda sl: x[sl])
    n = len(x) if n is None else n
    if not callable(x) and isinstance(x, np.ndarray) and x.ndim == 1 and x.strides == (0,):
        return np.broadcast_to(np.int32(0), (n,)), 1 if n else 0
    parts = [np.unique(get(slice(i, i + _SLICE))) for i in range(0, n, _SLICE)]
    u = np.unique(np.concatenate(parts)) if parts else np.zeros(0)
    del parts
    group, m = None, u.size
    if key is not None:
        ku, group = np.unique(np.asarray(key(u)), return_inverse=True)
        group, m = np.asarray(group).ravel(), ku.size
    out = np.empty(n, dtype=np.int32 if u.size < 2**31 else np.int64)
    for i in range(0, n, _SLICE):
        idx = np.searchsorted(u, get(slice(i, i + _SLICE)))
        out[i: i + _SLICE] = idx if group is None else group[idx]
    return out, m


def _combine(a: NDArray, na: int, b: NDArray, nb: int) -> tuple[NDArray, int]:
    """Codes of the pairs (a, b), numbered in the order of (a, b), and their number (in slices)."""
    if nb <= 1:
        return a, na
    if na <= 1:
        return b, nb
    n = a.size
    dense = na * nb <= max(2 * n, 1 << 16)  # a remap table of at most 2n int32: less than sorting the pairs
    present = np.zeros(na * nb, dtype=bool) if dense else None
    parts = []
    for i in range(0, n, _SLICE):
        k = a[i: i + _SLICE].astype(np.int64) * nb + b[i: i + _SLICE]
        if dense:
            present[k] = True
        else:
            parts.append(np.unique(k))
    if dense:
        remap = np.cumsum(present, dtype=np.int32 if na * nb < 2**31 else np.int64)
        remap -= 1
        m = int(present.sum())
        del present
    else:
        u = np.unique(np.concatenate(parts))
        m = u.size
        del parts
    out = np.empty(n, dtype=np.int32 if m < 2**31 else np.int64)
    for i in range(0, n, _SLICE):
        k = a[i: i + _SLICE].astype(np.int64) * nb + b[i: i + _SLICE]
        out[i: i + _SLICE] = remap[k] if dense else np.searchsorted(u, k)
    return out, m


def _codes_of_tuples(columns: list[tuple[Any, Any]], n: int) -> tuple[NDArray, int]:
    """Codes 0..m-1 of the classes of equal tuples (key(x) of each column; see :func:`_codes`), numbered in the
    order of the tuples, and m: one code array written, the per-column codes only formed slice by slice."""
    tables = []
    for x, key in columns:
        get = x if callable(x) else (lambda sl, x=x: x[sl])
        parts = [np.unique(get(slice(i, i + _SLICE))) for i in range(0, n, _SLICE)]
        u = np.unique(np.concatenate(parts)) if parts else np.zeros(0)
        if key is None:
            group, m = np.arange(u.size), u.size
        else:
            ku, group = np.unique(np.asarray(key(u)), return_inverse=True)
            group, m = np.asarray(group).ravel(), ku.size
        tables.append((get, u, group, max(m, 1)))
    size = math.prod(t[3] for t in tables)
    if size > max(2 * n, 1 << 16):  # too many combinations for a table of them: pair by pair
        code, m = _codes(columns[0][0], columns[0][1], n)
        for x, key in columns[1:]:
            more, n_more = _codes(x, key, n)
            code, m = _combine(code, m, more, n_more)
        return code, m

    def key_of(sl: slice) -> NDArray[np.int64]:
        k = np.zeros(len(range(*sl.indices(n))), dtype=np.int64)
        for get, u, group, m in tables:
            k *= m
            k += group[np.searchsorted(u, get(sl))]
        return k

    present = np.zeros(size, dtype=bool)
    for i in range(0, n, _SLICE):
        present[key_of(slice(i, i + _SLICE))] = True
    remap = np.cumsum(present, dtype=np.int32 if size < 2**31 else np.int64)
    remap -= 1
    m = int(present.sum())
    del present
    out = np.empty(n, dtype=np.int32 if m < 2**31 else np.int64)
    for i in range(0, n, _SLICE):
        out[i: i + _SLICE] = remap[key_of(slice(i, i + _SLICE))]
    return out, m


def _exact(x: NDArray) -> NDArray:
    """Angles and wavelengths as compared by the checks and the record keys: rounded to 1e-9."""
    return np.round(x, 9)


def _rank_in_group(ids: NDArray, seen: NDArray[np.integer]) -> NDArray[np.int64]:
    """Rank of each entry among the entries of its group so far (``seen``: counts before this slice, updated)."""
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    starts = np.r_[0, np.flatnonzero(np.diff(sorted_ids)) + 1]
    run = np.arange(ids.size) - np.repeat(starts, np.diff(np.r_[starts, ids.size]))
    rank = np.empty(ids.size, dtype=np.int64)
    rank[order] = run
    rank += seen[ids]
    uid, cnt = np.unique(ids, return_counts=True)
    seen[uid] += cnt
    return rank


def _first_index(code: NDArray, m: int) -> NDArray[np.int64]:
    """Index of the first entry of each class 0..m-1."""
    first = np.full(m, -1, dtype=np.int64)
    for i in range(0, code.size, _SLICE):
        uid, at = np.unique(code[i: i + _SLICE], return_index=True)
        new = first[uid] < 0
        first[uid[new]] = at[new] + i
    return first


def _refuse_cut_last_block(path: str, rows: _Rows) -> None:
    """Refuse a table whose last block (one incidence, wavelength, side and value column) stops early: its
    scatter angles are a strict beginning of those of every other block, and those all agree (a file cut
    after a whole row). Checked in slices of :data:`_SLICE` entries."""
    n = rows.line.size
    if n == 0:
        return
    block, nb = _codes_of_tuples([(rows.theta_i, _exact), (rows.phi_i, _exact), (rows.wavelength, _exact),
                                  (rows.side, None), (rows.spec, None)], n)
    last_line = int(rows.line.max())
    at_end = np.zeros(nb, dtype=bool)
    at_end[block[np.asarray(rows.line) == last_line]] = True
    counts = np.zeros(nb, dtype=np.int64)
    for i in range(0, n, _SLICE):  # in slices: bincount would copy the codes to int64 at once
        counts += np.bincount(block[i: i + _SLICE], minlength=nb)
    whole = np.flatnonzero(~at_end)
    if whole.size < 2 or np.any(counts[whole] != counts[whole[0]]):
        return  # blocks of their own sizes: nothing tells a shorter last block from a cut one
    ref = block == whole[0]
    ref_ts, ref_ps = _exact(rows.theta_s[ref]), _exact(rows.phi_s[ref])
    del ref
    seen = np.zeros(nb, dtype=np.int64)
    differs = np.zeros(nb, dtype=bool)
    for start in range(0, n, _SLICE):
        sl = slice(start, start + _SLICE)
        ids = block[sl]
        rank = _rank_in_group(ids, seen)
        inside = rank < ref_ts.size
        r = np.where(inside, rank, 0)
        bad = ~inside | (_exact(rows.theta_s[sl]) != ref_ts[r]) | (_exact(rows.phi_s[sl]) != ref_ps[r])
        differs[ids[bad]] = True
    if differs[whole].any():
        return
    for b in np.flatnonzero(at_end).tolist():
        if counts[b] < ref_ts.size and not differs[b]:
            k = int(np.argmax(block == b))
            th_i = float(_exact(rows.theta_i[k]))
            raise FormatError("the last block stops early (truncated?)", file=path, line=last_line,
                              field=f"theta_i={th_i:g}" if not math.isnan(th_i) else "last block",
                              expected=f"{ref_ts.size} scatter angles like every other block", got=int(counts[b]))


#: Data lines parsed at a time (the block's numbers in float64 arrays: 8 bytes a number).
_BLOCK_LINES = 1 << 13
_SIDE_CODE = {None: -1, "reflection": 0, "transmission": 1}


class _Store:
    """Per-entry numbers written block by block into one array per quantity, allocated once for the estimated
    number of entries (pages never written cost no memory) and grown by half when the estimate falls short:
    no list of blocks to join, no heap of small blocks between temporaries. A quantity constant over the whole
    table (no φi column, no uncertainty column, one side) is kept as one value and read as a broadcast array."""

    def __init__(self, capacity: int, dtypes: dict[str, Any]) -> None:
        self.capacity, self.dtypes = max(int(capacity), 1024), dtypes
        self.size: dict[str, int] = {}
        self.arrays: dict[str, NDArray] = {}
        self.const: dict[str, Any] = {}

    def add(self, name: str, values: NDArray) -> None:
        values = np.asarray(values)
        k = values.size
        if k == 0:
            return
        n0 = self.size.get(name, 0)
        arr = self.arrays.get(name)
        if arr is None:
            v0 = values.flat[0]
            constant = bool(np.all(values == v0)) or (values.dtype.kind == "f" and bool(np.all(np.isnan(values))))
            c = self.const.get(name, v0)
            if constant and (c == v0 or (c != c and v0 != v0)):
                self.const[name], self.size[name] = c, n0 + k
                return
            arr = np.empty(max(self.capacity, n0 + k), dtype=self.dtypes[name])
            if n0:
                arr[:n0] = self.const.pop(name)
            self.arrays[name] = arr
        if n0 + k > arr.size:
            grown = np.empty(int((n0 + k) * 1.5), dtype=arr.dtype)
            grown[:n0] = arr[:n0]
            self.arrays[name] = arr = grown
        arr[n0: n0 + k] = values
        self.size[name] = n0 + k

    def take(self, name: str) -> NDArray:
        """The entries of ``name`` (read-only and of no size when constant)."""
        n = self.size.get(name, 0)
        if name in self.arrays:
            return self.arrays.pop(name)[:n]
        value = self.const.pop(name, 0)
        return np.broadcast_to(np.asarray(value, dtype=self.dtypes[name]), (n,))


@dataclass(frozen=True)
class _Layout:
    """What every data row of a table shares: the file, its delimiter and columns, and what they hold.

    ``specs`` has one entry per value column: (the column, its uncertainty column or None, whether that
    uncertainty is relative to the value, the side the column's quantity fixes or None).
    """

    path: str
    delim: str | None
    columns: list[_Column]
    roles: dict[str, list[_Column]]
    decimal_comma: bool
    header_norm: list[str]
    specs: list[tuple[_Column, _Column | None, bool, str | None]]

    @property
    def signed(self) -> bool:
        """No φs column: θs is a signed in-plane angle."""
        return "phi_s" not in self.roles

    @property
    def wide_inc(self) -> bool:
        """One value column per incidence."""
        return any(c.incidence is not None for c, *_ in self.specs)

    @property
    def plain(self) -> bool:
        """Every column numeric and no decimal comma: blocks may be parsed as arrays."""
        numeric = {"theta_i", "phi_i", "theta_s", "phi_s", "wavelength", "value", "std"}
        return not self.decimal_comma and all(c.role in numeric for c in self.columns)


def _layout(path: str, delim: str | None, columns: list[_Column], roles: dict[str, list[_Column]],
            decimal_comma: bool, header_cells: list[str]) -> _Layout:
    """The :class:`_Layout` of a table: its value columns paired with their uncertainty columns."""
    std_of = {c.pair: c for c in roles.get("std", [])}
    specs = []
    for c in roles["value"]:
        s_col = std_of.get(c.index)
        relative = bool(s_col is not None and (s_col.relative or (s_col.percent and not c.percent)))
        specs.append((c, s_col, relative, side_of_quantity(c.quantity)))
    return _Layout(path, delim, columns, roles, decimal_comma,
                   [c.strip().strip('"').lower() for c in header_cells], specs)


@dataclass(frozen=True)
class _RowDefaults:
    """Values of the rows that follow where the table has no column: set before the header, changed by
    ``# incidence: 20`` comments or ``Incidence: 20`` lines between blocks (θi, φi [deg], wavelength [nm])."""

    theta_i: float | None
    phi_i: float
    wavelength: float | None
    side: str | None


def _with_metadata(defaults: _RowDefaults, meta: dict[str, tuple[str, int]], path: str) -> _RowDefaults:
    """``defaults`` changed by the metadata of a comment or ``key: value`` line."""
    angle = {"deg": 1.0, "rad": 180.0 / math.pi}
    changes: dict[str, Any] = {}
    if "incidence" in meta:
        changes["theta_i"] = _meta_number(meta, "incidence", path, angle, "deg")
    if "phi_i" in meta:
        changes["phi_i"] = _meta_number(meta, "phi_i", path, angle, "deg")
    if "wavelength" in meta:
        changes["wavelength"] = _meta_number(meta, "wavelength", path, {"nm": 1.0, "um": 1000.0}, "nm")
    if "side" in meta:
        word = _side_word(meta["side"][0]) or _side_of_words(meta["side"][0])
        if word is None:
            raise InputError("unknown side", file=path, line=meta["side"][1], field="side",
                             expected="reflection or transmission", got=meta["side"][0])
        changes["side"] = word
    return replace(defaults, **changes) if changes else defaults


@dataclass
class _Firsts:
    """The first line of what decides the frame and side of a whole table, noted while its blocks are parsed:
    a polar angle beyond 90° (``front``), a transmitted angle within 0..90° (``back``), a value without a side
    (``sideless``: line and column)."""

    front: int | None = None
    back: int | None = None
    sideless: tuple[int, str] | None = None

    def note(self, key: str, value: Any) -> None:
        """Keep ``value`` as the first ``key`` unless one is already kept."""
        if getattr(self, key) is None:
            setattr(self, key, value)


def _cell_number(cells: list[str], col: _Column, line: int, what: str, layout: _Layout) -> float:
    """The number of a cell in the column's unit (scaled); NaN for a gap; one-line errors for text and ±inf."""
    try:
        v = _number(cells[col.index], layout.decimal_comma)
    except ValueError:
        raise FormatError(f"not a number in the {what} column", file=layout.path, line=line,
                          field=f"column {col.index + 1} '{col.header}'", expected="a number or an empty cell",
                          got=cells[col.index]) from None
    if math.isinf(v):
        raise FormatError(f"infinite number in the {what} column", file=layout.path, line=line,
                          field=f"column {col.index + 1} '{col.header}'", expected="a finite number",
                          got=cells[col.index])
    return v * col.scale


def _required(cells: list[str], role: str, line: int, default: float | None, layout: _Layout) -> float:
    """The number of the row's ``role`` column (never a gap), or ``default`` (NaN for None) without one."""
    if role not in layout.roles:
        return math.nan if default is None else default
    col = layout.roles[role][0]
    v = _cell_number(cells, col, line, role, layout)
    if math.isnan(v):
        raise FormatError(f"missing {role}", file=layout.path, line=line,
                          field=f"column {col.index + 1} '{col.header}'",
                          expected="a number (angles and wavelengths cannot be gaps)", got=cells[col.index])
    return v


#: The float64 entry arrays of a parsed block.
_FLOAT_ENTRIES = ("theta_i", "phi_i", "theta_s", "phi_s", "wavelength", "value", "std")
#: Entry arrays of a parsed block, in the order of :class:`_Rows`.
_ENTRY_NAMES = ("theta_i", "phi_i", "theta_s", "phi_s", "wavelength", "value", "std", "std_relative", "side", "line")


def _store_entries(store: _Store, entries: dict[str, NDArray], n_v: int) -> None:
    """Append a block's entries (``n_v`` per row, one per value column) to the store, with their column index."""
    n = entries["line"].size
    for name in _ENTRY_NAMES[:-1]:
        store.add(name, entries[name])
    store.add("spec", np.tile(np.arange(n_v, dtype=np.int16), n // n_v if n_v else 0))
    store.add("line", entries["line"])


def _fast_columns(a: NDArray, layout: _Layout, state: _RowDefaults) -> dict[str, NDArray] | None:
    """The direction columns (θi, φi, θs, φs [deg], wavelength [nm]) of a block of numbers; None when a row
    is out of range (the row path then says which)."""
    n = a.shape[0]

    def col(role: str, default: float | None) -> NDArray:
        if role in layout.roles:
            c = layout.roles[role][0]
            return a[:, c.index] * c.scale
        return np.full(n, math.nan if default is None else default)

    out = {"theta_i": col("theta_i", state.theta_i), "phi_i": col("phi_i", state.phi_i),
           "theta_s": col("theta_s", None), "phi_s": col("phi_s", 0.0),
           "wavelength": col("wavelength", state.wavelength)}
    th_i, th_s = out["theta_i"], out["theta_s"]
    th_i0 = np.where(np.isnan(th_i), 0.0, th_i)
    if (np.isnan(th_i).any() and not layout.wide_inc) or not np.all((th_i0 >= 0.0) & (th_i0 < 90.0)) \
            or not np.all((th_s >= (-90.0 if layout.signed else 0.0)) & (th_s <= 90.0)) \
            or not np.all((np.abs(out["phi_i"]) <= 360.0) & (np.abs(out["phi_s"]) <= 360.0)) \
            or ("wavelength" in layout.roles and not np.all(out["wavelength"] > 0)):
        return None
    return out


def _parse_fast(block: list[tuple[int, str]], layout: _Layout, state: _RowDefaults, firsts: _Firsts
                ) -> dict[str, NDArray] | None:
    """The entries of a block of plain numbers, parsed as arrays; None (nothing noted) when a row needs the
    row path."""
    if not layout.plain:
        return None
    try:
        a = np.loadtxt([t for _, t in block], delimiter=layout.delim, comments=None, quotechar='"',
                       dtype=np.float64, ndmin=2)
    except (ValueError, TypeError, OverflowError):  # anything not plain numbers: the row path says what
        return None
    n, n_v = len(block), len(layout.specs)
    if a.shape != (n, len(layout.columns)) or not np.all(np.isfinite(a)):
        return None
    cols = _fast_columns(a, layout, state)
    if cols is None:
        return None
    shape = (n, n_v)
    v, s = np.empty(shape), np.full(shape, math.nan)
    rel, side = np.zeros(shape, dtype=bool), np.empty(shape, dtype=np.int8)
    t_i, wl = np.empty(shape), np.empty(shape)
    for j, (c, scol, s_rel, q_side) in enumerate(layout.specs):
        v[:, j] = a[:, c.index] * 0.01 if c.percent else a[:, c.index]
        if scol is not None:
            sj = a[:, scol.index] * scol.scale
            if np.any(sj < 0):
                return None
            s[:, j] = sj * 0.01 if scol.percent else sj
            rel[:, j] = s_rel
        this_side = state.side
        if q_side is not None:
            if this_side is not None and this_side != q_side:
                return None
            this_side = q_side
        side[:, j] = _SIDE_CODE[this_side]
        t_i[:, j] = cols["theta_i"] if c.incidence is None else c.incidence
        wl[:, j] = cols["wavelength"] if c.wavelength is None else c.wavelength
    lines = np.fromiter((ln for ln, _ in block), dtype=np.int64, count=n)
    _note_fast_sides(side, cols["theta_s"], lines, layout, firsts)
    return {"theta_i": t_i.ravel(), "phi_i": np.repeat(cols["phi_i"], n_v),
            "theta_s": np.repeat(cols["theta_s"], n_v), "phi_s": np.repeat(cols["phi_s"], n_v),
            "wavelength": wl.ravel(), "value": v.ravel(), "std": s.ravel(), "std_relative": rel.ravel(),
            "side": side.ravel(), "line": np.repeat(lines, n_v)}


def _note_fast_sides(side: NDArray[np.int8], th_s: NDArray, lines: NDArray, layout: _Layout,
                     firsts: _Firsts) -> None:
    """Note the first transmitted angle from the back normal and the first value without a side of a block."""
    n_v = len(layout.specs)
    if np.any(side == 1):
        back = (side == 1) & ((0.0 < np.abs(th_s)) & (np.abs(th_s) < 90.0))[:, None]
        if back.any():
            firsts.note("back", int(lines[np.argmax(back.any(axis=1))]))
    if np.any(side == -1):
        k = int(np.argmax(side.ravel() == -1))
        c = layout.specs[k % n_v][0]
        firsts.note("sideless", (int(lines[k // n_v]), f"column {c.index + 1} '{c.header}'"))


class _RowDirection(NamedTuple):
    """One data row's direction: θi, φi, θs, φs [deg], wavelength [nm], whether θs was given from the front
    normal beyond 90° (``through``: a transmitted direction) and the side its side column or defaults give.
    (A named tuple: one is made per row of the row path.)"""

    theta_i: float
    phi_i: float
    theta_s: float
    phi_s: float
    wavelength: float
    through: bool
    side: str | None


def _row_direction(cells: list[str], line: int, layout: _Layout, state: _RowDefaults, firsts: _Firsts
                   ) -> _RowDirection:
    """The direction of one data row, checked (one-line errors naming the line and column)."""
    path, roles = layout.path, layout.roles
    th_i = _required(cells, "theta_i", line, state.theta_i, layout)
    if math.isnan(th_i) and not layout.wide_inc:
        raise FormatError("no incidence for this row", file=path, line=line, field="theta_i",
                          expected="a theta_i column, or '# incidence: <deg>' before the block")
    ph_i = _required(cells, "phi_i", line, state.phi_i, layout)
    th_s = _required(cells, "theta_s", line, None, layout)
    ph_s = _required(cells, "phi_s", line, 0.0, layout)
    lam = _required(cells, "wavelength", line, state.wavelength, layout)
    # a polar angle beyond 90° is measured from the FRONT normal (full-sphere goniometers): a transmitted
    # direction, 180° − θs from the back normal with the same azimuth (the undeviated side stays φs = 0)
    through = 90.0 < abs(th_s) <= 180.0
    if through:
        th_s = math.copysign(180.0 - abs(th_s), th_s) if layout.signed else 180.0 - th_s
        firsts.note("front", line)
    row_side = state.side
    if "side" in roles:
        col = roles["side"][0]
        word = _side_word(cells[col.index]) or _side_of_words(cells[col.index])
        if word is None:
            raise FormatError("unknown side", file=path, line=line, field=f"column {col.index + 1} '{col.header}'",
                              expected="reflection/transmission (R/T, BRDF/BTDF)", got=cells[col.index])
        row_side = word
    _check_angles(path, line, 0.0 if math.isnan(th_i) else th_i, ph_i, th_s, ph_s, layout.signed, roles)
    if "wavelength" in roles and not lam > 0:
        col = roles["wavelength"][0]
        raise FormatError("wavelength must be positive", file=path, line=line,
                          field=f"column {col.index + 1} '{col.header}'", expected="> 0 nm", got=cells[col.index])
    return _RowDirection(th_i, ph_i, th_s, ph_s, lam, through, row_side)


def _row_values(cells: list[str], line: int, d: _RowDirection, layout: _Layout, firsts: _Firsts,
                out: dict[str, array]) -> None:
    """Append the entries of one data row to ``out``: per value cell its value, uncertainty, whether that is
    relative, its side (the row's, the one its quantity fixes, transmission beyond 90° from the front normal),
    θi and wavelength; the row's φi, θs, φs and line once per value cell. One call per row: the row path's
    time is per call."""
    for col, scol, s_rel_spec, q_side in layout.specs:
        try:
            v = float(cells[col.index])  # fast path; gaps, decimal commas and errors go through _cell_number()
        except ValueError:
            v = _cell_number(cells, col, line, "value", layout)
        else:
            if math.isinf(v) or layout.decimal_comma:
                v = _cell_number(cells, col, line, "value", layout)
        if col.percent:
            v *= 0.01
        s, s_rel = math.nan, False
        if scol is not None:
            s = _cell_number(cells, scol, line, "uncertainty", layout)
            if not math.isnan(s) and s < 0:
                raise FormatError("negative uncertainty", file=layout.path, line=line,
                                  field=f"column {scol.index + 1} '{scol.header}'", expected=">= 0",
                                  got=cells[scol.index])
            s_rel = s_rel_spec
            if scol.percent:
                s *= 0.01
        this_side = d.side
        if q_side is not None:
            if this_side is not None and this_side != q_side:
                raise InputError(f"side contradicts the quantity {col.quantity}", file=layout.path, line=line,
                                 field=f"column {col.index + 1} '{col.header}'", expected=q_side, got=this_side)
            this_side = q_side
        if d.through:
            if this_side == "reflection":
                c = layout.roles["theta_s"][0]
                raise ValidationError(f"scatter angle out of range for the reflection side ({col.header})",
                                      file=layout.path, line=line, field=f"column {c.index + 1} '{c.header}'",
                                      expected="theta_s <= 90 deg (beyond 90 deg from the front normal is "
                                               "transmission)", got=cells[c.index].strip())
            this_side = "transmission"
        elif this_side == "transmission" and 0.0 < abs(d.theta_s) < 90.0:
            firsts.note("back", line)
        if this_side is None:
            firsts.note("sideless", (line, f"column {col.index + 1} '{col.header}'"))
        out["side"].append(_SIDE_CODE[this_side])
        out["value"].append(v)
        out["std"].append(s)
        out["std_relative"].append(s_rel)
        out["theta_i"].append(d.theta_i if col.incidence is None else col.incidence)
        out["wavelength"].append(d.wavelength if col.wavelength is None else col.wavelength)
    n_v = len(layout.specs)
    out["phi_i"].extend([d.phi_i] * n_v)
    out["theta_s"].extend([d.theta_s] * n_v)
    out["phi_s"].extend([d.phi_s] * n_v)
    out["line"].extend([line] * n_v)


def _row_cells(text: str, line: int, layout: _Layout) -> list[str] | None:
    """The cells of a data line, or None for the header repeated at the start of a block."""
    cells = _split(text, layout.delim)
    if [c.strip().strip('"').lower() for c in _fields(text, layout.delim)] == layout.header_norm:
        return None
    return cells


def _parse_by_rows(block: list[tuple[int, str]], layout: _Layout, state: _RowDefaults,
                   pending: deque[tuple[int, str]], firsts: _Firsts) -> tuple[dict[str, NDArray], _RowDefaults]:
    """The entries of a block parsed row by row, and the row defaults after it (comments in ``pending`` and
    ``key: value`` lines between its rows change them)."""
    out = {k: array("d") for k in _FLOAT_ENTRIES}
    out.update(std_relative=array("b"), side=array("b"), line=array("q"))
    n_cols = len(layout.columns)
    for line, text in block:
        while pending and pending[0][0] < line:
            state = _with_metadata(state, _metadata([pending.popleft()]), layout.path)
        cells = _row_cells(text, line, layout)
        if cells is None:
            continue  # the header repeated at the start of the next block
        if cells and not _is_numberlike(cells[0]):
            meta = _metadata([(line, text.strip())])
            if meta and re.match(r"^\s*[^:=]+[:=]", text):
                state = _with_metadata(state, meta, layout.path)
                continue
        while len(cells) > n_cols and not cells[-1].strip():
            cells.pop()  # trailing separators
        if len(cells) != n_cols:
            raise FormatError("wrong number of fields", file=layout.path, line=line, field="row",
                              expected=f"{n_cols} fields like the header", got=len(cells))
        _row_values(cells, line, _row_direction(cells, line, layout, state, firsts), layout, firsts, out)
    entries = {k: np.frombuffer(out[k], dtype=np.float64) for k in _FLOAT_ENTRIES}
    entries.update(std_relative=np.frombuffer(out["std_relative"], dtype=np.int8).astype(bool),
                   side=np.frombuffer(out["side"], dtype=np.int8), line=np.frombuffer(out["line"], dtype=np.int64))
    return entries, state


def _parse_rows(events: Iterator[tuple[str, int, str]], layout: _Layout, state: _RowDefaults,
                rows_estimate: int = 0) -> _Rows:
    """Rows → one entry per value cell, streamed in blocks of :data:`_BLOCK_LINES` lines.

    ``events`` yields ``("data", line, text)`` for the data lines and ``("comment", line, text)`` for the
    comment lines after the header, in file order. Between blocks, a repeated header is skipped, and
    ``# incidence: 20`` comments or ``Incidence: 20`` lines set the incidence (wavelength, phi_i, side) of the
    rows that follow (``state``: the defaults before the first row). A block of plain numbers is parsed by
    :func:`numpy.loadtxt` and checked as arrays; any other block (gaps, text, a decimal comma, a side column,
    angles beyond 90°, a bad value) row by row, which gives the one-line error of the first bad row with its
    physical line. ``rows_estimate`` (rows expected) sizes the arrays.
    """
    pending: deque[tuple[int, str]] = deque()
    firsts = _Firsts()
    store = _Store(rows_estimate * max(len(layout.specs), 1), {
        "theta_i": np.float64, "phi_i": np.float64, "theta_s": np.float64, "phi_s": np.float64,
        "wavelength": np.float64, "value": np.float64, "std": np.float64, "std_relative": bool, "side": np.int8,
        "spec": np.int16, "line": np.int32 if Path(layout.path).stat().st_size < 2**31 - 1 else np.int64})
    for block in _blocks(events, pending):
        while pending and pending[0][0] < block[0][0]:
            state = _with_metadata(state, _metadata([pending.popleft()]), layout.path)
        entries = _parse_fast(block, layout, state, firsts)
        if entries is None:
            entries, state = _parse_by_rows(block, layout, state, pending, firsts)
        if entries["line"].size:
            _store_entries(store, entries, len(layout.specs))
    return _rows_of(store, layout, firsts)


def _blocks(events: Iterator[tuple[str, int, str]], pending: deque[tuple[int, str]]
            ) -> Iterator[list[tuple[int, str]]]:
    """Blocks of at most :data:`_BLOCK_LINES` data lines, cut at every comment; the comments are appended to
    ``pending`` as they come (before the block that follows them is given)."""
    block: list[tuple[int, str]] = []
    for kind, line, text in events:
        if kind == "comment":
            if block:
                yield block
                block = []
            pending.append((line, text))
            continue
        block.append((line, text))
        if len(block) >= _BLOCK_LINES:
            yield block
            block = []
    if block:
        yield block


def _rows_of(store: _Store, layout: _Layout, firsts: _Firsts) -> _Rows:
    """The parsed entries as :class:`_Rows`, once the frame and the sides of the whole table are known."""
    path = layout.path
    if firsts.front is not None and firsts.back is not None:
        raise ValidationError("transmission scatter angles in two frames", file=path, line=firsts.back,
                              field="theta_s", expected="all from the back normal (<= 90 deg) or all from the front "
                              "normal (> 90 deg)", got=f"line {firsts.front} beyond 90 deg")
    side = store.take("side")
    if firsts.sideless is not None:
        if firsts.front is None:
            line, where = firsts.sideless
            raise InputError("the table does not say which side it holds; pass --side", file=path, line=line,
                             field=where, expected="--side reflection|transmission, a side column, "
                             "--quantity brdf|btdf, or polar angles up to 180 deg from the front normal")
        side = np.where(side < 0, np.int8(0), side)  # full sphere: up to 90° reflects
    return _Rows(
        theta_i=store.take("theta_i"), phi_i=store.take("phi_i"), theta_s=store.take("theta_s"),
        phi_s=store.take("phi_s"), wavelength=store.take("wavelength"), value=store.take("value"),
        std=store.take("std"), std_relative=store.take("std_relative"), side=side, spec=store.take("spec"),
        line=store.take("line"),
        quantities=[c.quantity for c, *_ in layout.specs], headers=[c.header for c, *_ in layout.specs])


#: Plausible wavelengths [nm]: 1 nm (soft X-ray) to 100 µm (far infrared); a column outside is in another unit.
WAVELENGTH_RANGE_NM = (1.0, 1e5)
#: Largest plausible |BSDF| [1/sr]: a perfect mirror seen by a 1e-10 sr detector; beyond, a value is not a BSDF
#: (and its square, in every uncertainty, overflows float64 near 1e154).
MAX_ABS_BSDF = 1e10
#: A polar-angle column in degrees whose |values| never exceed this [deg] over at least RADIAN_MIN_DISTINCT
#: distinct values is in radians (π/2 = 1.571 rounded up): no BSDF scan covers only 1.6° of polar angle.
RADIAN_POLAR_MAX, RADIAN_AZIMUTH_MAX, RADIAN_MIN_DISTINCT = 1.6, 6.3, 5
#: Negative beyond noise: at one wavelength the mean BSDF is below zero by more than this many standard errors
#: of the mean and by more than the median stated uncertainty (dark-subtraction noise around 0 stays).
NEGATIVE_SIGMA = 5.0


def _unit_guess(values: NDArray[np.float64]) -> str:
    """What unit wavelength numbers that are not nm look like."""
    hi = float(np.nanmax(np.abs(values)))
    if hi < 1e-4:
        return "metres (e.g. 5.5e-07 = 550 nm)"
    if hi < 1e-1:
        return "millimetres or metres"
    if hi < 1.0 or hi < 30.0:
        return "micrometres (e.g. 0.55 = 550 nm)"
    return "not nanometres (angstroms, picometres or wavenumbers?)"


def _span(values: NDArray[np.float64]) -> str:
    return f"{np.nanmin(values):g}..{np.nanmax(values):g}"


def _lines_of(lines: NDArray[np.int64], limit: int = 5) -> str:
    u = np.unique(lines)
    return ", ".join(map(str, u[:limit].tolist())) + (f", … ({u.size - limit} more)" if u.size > limit else "")


def _check_units(path: str, rows: _Rows, roles: dict[str, list[_Column]]) -> None:
    """Refuse wavelength and angle columns whose magnitudes contradict their declared (or assumed) unit."""
    lines = np.asarray(rows.line, dtype=np.int64)
    if "wavelength" in roles:
        col = roles["wavelength"][0]
        where = f"column {col.index + 1} '{col.header}'"
        unit = {1.0: "nm", 1000.0: "um", 1e9: "m", 0.1: "angstrom"}.get(col.scale, f"x{col.scale:g} nm")
        lam = np.asarray(rows.wavelength, dtype=np.float64)
        lo, hi = WAVELENGTH_RANGE_NM
        out = (lam < lo) | (lam > hi)
        if out.all():
            raise ValidationError(f"wavelengths implausible in {unit}: they look like {_unit_guess(lam / col.scale)}",
                                  file=path, line=int(lines[0]), field=where,
                                  expected=f"{lo:g}..{hi:g} nm, or the unit in the header (e.g. "
                                           "'wavelength [um]', 'wavelength [m]')",
                                  got=f"{np.nanmin(lam) / col.scale:g}..{np.nanmax(lam) / col.scale:g}")
        ratio = np.nanmax(lam) / np.nanmin(lam) if np.all(lam > 0) else np.inf
        if out.any() or ratio > 1000.0:
            # two units in one column (µm rows among nm rows): the rows of the smaller group are named
            small = lam < np.sqrt(np.nanmax(lam) * np.nanmin(lam))
            minority = small if small.sum() <= (~small).sum() else ~small
            raise ValidationError("wavelengths in two units in one column (um and nm mixed?)", file=path,
                                  line=int(lines[minority][0]), field=where,
                                  expected=f"one unit: {lo:g}..{hi:g} nm after the header's unit ({unit})",
                                  got=f"{_span(lam[minority] / col.scale)} on lines {_lines_of(lines[minority])} "
                                      f"among {_span(lam[~minority] / col.scale)}")
    for role, bound in (("theta_s", RADIAN_POLAR_MAX), ("theta_i", RADIAN_POLAR_MAX), ("phi_s", RADIAN_AZIMUTH_MAX)):
        if role not in roles or roles[role][0].scale != 1.0:
            continue
        col = roles[role][0]
        v = np.asarray(getattr(rows, role), dtype=np.float64)
        if max(float(np.nanmax(v)), -float(np.nanmin(v))) > bound:
            continue  # degrees (the distinct values below are only counted when every angle is small)
        distinct = np.unique(np.round(v[np.isfinite(v)], 9))
        if distinct.size >= RADIAN_MIN_DISTINCT:
            raise ValidationError(f"{role} angles look like radians under a degree unit", file=path,
                                  line=int(lines[0]), field=f"column {col.index + 1} '{col.header}'",
                                  expected=f"degrees (some |{role}| > {bound:g} over {distinct.size} distinct "
                                           f"angles), or '{col.header.split('[')[0].strip()} [rad]' in the header",
                                  got=f"|{role}| <= {np.nanmax(np.abs(v)):.4g} over {distinct.size} distinct values")


def _check_values(path: str, rows: _Rows, rel: float | None) -> None:
    """Refuse values that are no BSDF before computing with them: huge (overflow), all zero, negative beyond noise.
    Checked in slices of :data:`_SLICE` entries."""
    v, s, lines = rows.value, rows.std, rows.line
    n = v.size
    lam_code, n_lam = _codes(rows.wavelength)
    count = np.zeros(n_lam, dtype=np.int64)
    total = np.zeros(n_lam)
    first_stated, nonzero = -1, False
    for i in range(0, n, _SLICE):
        vs = v[i: i + _SLICE]
        stated = np.isfinite(vs)
        if first_stated < 0 and stated.any():
            first_stated = i + int(np.argmax(stated))
        huge = stated & (np.abs(vs) > MAX_ABS_BSDF)
        if huge.any():
            k = i + int(np.argmax(huge))
            raise ValidationError("value implausibly large for a BSDF", file=path, line=int(lines[k]),
                                  field=rows.column(k),
                                  expected=f"|value| <= {MAX_ABS_BSDF:g} (1/sr)", got=f"{v[k]:g}")
        nonzero = nonzero or bool(np.any(vs[stated] != 0.0))
        codes = lam_code[i: i + _SLICE][stated]
        count += np.bincount(codes, minlength=n_lam)
        total += np.bincount(codes, weights=vs[stated], minlength=n_lam)
    if first_stated < 0:
        return  # every cell a gap: refused by the assembly with its own message
    no_std = s.strides == (0,) and bool(np.isnan(s[:1]).all())  # no uncertainty column: nothing to check
    for i in range(n if no_std else 0, n, _SLICE):
        vs, ss = v[i: i + _SLICE], s[i: i + _SLICE]
        too_big = np.isfinite(ss) & (ss > MAX_ABS_BSDF * (1.0 + np.abs(vs)))
        if too_big.any():
            k = i + int(np.argmax(too_big))
            raise ValidationError("uncertainty implausibly large", file=path, line=int(lines[k]),
                                  field=f"uncertainty of '{rows.column(k)}'", expected=f"<= {MAX_ABS_BSDF:g}",
                                  got=f"{s[k]:g}")
    if not nonzero:
        k = first_stated
        raise ValidationError("the table is all zero: every value is 0", file=path, line=int(lines[k]),
                              field=rows.column(k), expected="values > 0 where the sample scatters",
                              got=f"0 in all {int(count.sum())} cells")
    _refuse_negative(path, rows, lam_code, (count, total), rel)


def _refuse_negative(path: str, rows: _Rows, lam_code: NDArray, sums: tuple[NDArray, NDArray], rel: float | None
                     ) -> None:
    """Refuse a table whose mean value at a wavelength (NaN wavelength: one group) lies below zero beyond the noise
    (:data:`NEGATIVE_SIGMA`), naming the negative value that comes first in the file among the wavelengths refused:
    the wavelengths are tried in sorted order, which is not the file's (a table listing 650 nm before 550 nm)."""
    v, s, lines = rows.value, rows.std, rows.line
    count, total = sums
    first = None  # (line, entry, count, negatives, mean, standard error) of the earliest negative refused
    for w in np.flatnonzero((count > 0) & (total < 0)).tolist():
        sel = np.isfinite(v) & (lam_code == w)
        n_w = int(sel.sum())
        x = v[sel]
        u = np.where(rows.std_relative[sel], s[sel] * np.abs(x), s[sel])
        u = np.where(np.isfinite(u), u, (DEFAULT_RELATIVE_STD if rel is None else rel) * np.abs(x))
        mean = float(np.mean(x))
        if mean >= 0:
            continue
        sem = max(float(np.std(x)) / math.sqrt(n_w), float(np.sqrt(np.sum(u**2))) / n_w)
        if -mean > NEGATIVE_SIGMA * sem and -mean > float(np.median(u)):
            negative = np.flatnonzero(sel & (v < 0))
            k = int(negative[np.argmin(lines[negative])])  # the entries are in file order; the line decides
            if first is None or (int(lines[k]), k) < first[:2]:
                first = (int(lines[k]), k, n_w, int((x < 0).sum()), mean, sem)
    if first is None:
        return
    line, k, n_w, n_neg, mean, sem = first
    lam_k = float(rows.wavelength[k])
    at = "" if math.isnan(lam_k) else f" at {lam_k:g} nm"
    raise ValidationError(f"BSDF negative beyond noise{at}: {n_neg} of {n_w} values < 0", file=path, line=line,
                          field=rows.column(k),
                          expected=f">= 0 within the noise (mean > -{NEGATIVE_SIGMA:g} standard errors "
                                   f"= {-NEGATIVE_SIGMA * sem:.3g})",
                          got=f"mean {mean:.4g} (first negative {v[k]:g})")


def _check_angles(path: str, line: int, th_i: float, ph_i: float, th_s: float, ph_s: float, signed: bool,
                  roles: dict[str, list[_Column]]) -> None:
    def where(role: str) -> str:
        c = roles.get(role)
        return f"column {c[0].index + 1} '{c[0].header}'" if c else role

    if not 0.0 <= th_i < 90.0:
        raise ValidationError("incidence angle out of range", file=path, line=line, field=where("theta_i"),
                              expected="0 <= theta_i < 90 deg", got=th_i)
    if signed:
        if not -90.0 <= th_s <= 90.0:
            raise ValidationError("signed in-plane scatter angle out of range", file=path, line=line,
                                  field=where("theta_s"),
                                  expected="-90..90 deg (transmission: from the back normal, with --side)", got=th_s)
    elif not 0.0 <= th_s <= 90.0:
        raise ValidationError("scatter angle out of range", file=path, line=line, field=where("theta_s"),
                              expected="0 <= theta_s <= 90 deg (with a phi_s column)", got=th_s)
    for role, v in (("phi_i", ph_i), ("phi_s", ph_s)):
        if not -360.0 <= v <= 360.0:
            raise ValidationError("azimuth out of range", file=path, line=line, field=where(role),
                                  expected="-360..360 deg", got=v)


# ------------------------------------------------------------------------------------------- dataset
def arc_labels(theta_i_deg: NDArray, phi_i_deg: NDArray, theta_s_deg: NDArray,
               phi_s_deg: NDArray) -> NDArray[np.object_]:
    """``in_plane`` (φs on the specular or source side, or θs = 0), ``perpendicular`` (the great circle
    through the specular direction normal to the plane of incidence) or ``other``, per record (degrees).

    Parameters
    ----------
    theta_i_deg : ndarray
        Angle of incidence of each record [deg].
    phi_i_deg : ndarray
        Source azimuth of each record [deg].
    theta_s_deg : ndarray
        Scatter polar angle of each record [deg].
    phi_s_deg : ndarray
        Scatter azimuth of each record [deg].

    Returns
    -------
    ndarray of object
        ``"in_plane"``, ``"perpendicular"`` or ``"other"`` per record (tolerance :data:`ARC_TOL` on direction
        cosines).
    """
    ti, pi_, ts, ps = (np.radians(np.asarray(a, dtype=np.float64))
                       for a in (theta_i_deg, phi_i_deg, theta_s_deg, phi_s_deg))
    rel = np.mod(ps - (pi_ - np.pi) + np.pi, 2 * np.pi) - np.pi  # φs relative to the specular azimuth
    # tolerance ARC_TOL (1e-5 rad ≈ 0.0006°): angles written in radians or with few decimals are not exact
    in_plane = (np.abs(np.sin(rel)) * np.sin(ts) < ARC_TOL) | (ts < 1e-12)
    # d = (sin θs cos rel, sin θs sin rel, cos θs) in a frame with the specular azimuth on +x;
    # the perpendicular great circle through r0 = (sin θi, 0, cos θi) has normal (−cos θi, 0, sin θi)
    dot = -np.cos(ti) * np.sin(ts) * np.cos(rel) + np.sin(ti) * np.cos(ts)
    perp = (np.abs(dot) < ARC_TOL) & ~in_plane
    return np.where(in_plane, "in_plane", np.where(perp, "perpendicular", "other")).astype(object)


@dataclass(frozen=True)
class RecordDirections:
    """Where each record of a table or vendor file was measured.

    Attributes
    ----------
    theta_i, phi_i, theta_s, phi_s
        Per-record incidence and scatter angles [deg], sample frame.
    side
        ``reflection`` or ``transmission`` per record.
    arc
        ``in_plane`` / ``perpendicular`` / ``other`` per record (default: from the angles, :func:`arc_labels`).
    source_line
        Line of each record in its file (default 0).
    """

    theta_i: Sequence[float]
    phi_i: Sequence[float]
    theta_s: Sequence[float]
    phi_s: Sequence[float]
    side: Sequence[str]
    arc: Sequence[str] | None = None
    source_line: Sequence[int] | None = None


@dataclass(frozen=True)
class RecordsOrigin:
    """What a dataset of records says about its source.

    Attributes
    ----------
    source
        The file read.
    std_origin
        Where ``bsdf_std`` comes from (the ``origin`` of ``bsdf_std`` and ``attrs['bsdf_std_origin']``).
    description
        The configuration's description (default ``"measured table"``).
    wavelength_note
        Why the wavelength is NaN, when it is (the ``note`` of ``wavelength``).
    """

    source: str
    std_origin: str = ""
    description: str = ""
    wavelength_note: str = ""


def _flat_incident(lam: NDArray[np.float64]) -> tuple[NDArray[np.float64], list[float]]:
    """The incident spectrum of elastic data [1/nm] (flat, unit integral when there are several wavelengths)
    and its band (low, high) [nm]."""
    if lam.size > 1 and np.all(np.isfinite(lam)):
        return np.full(lam.size, 1.0 / float(np.sum(np.gradient(lam)))), [float(lam.min()), float(lam.max())]
    return np.ones(lam.size), [float(lam[0]), float(lam[0])]


def records_dataset(records: RecordDirections, wavelength_nm: Sequence[float], bsdf: NDArray[np.float64],
                    bsdf_std: NDArray[np.float64], origin: RecordsOrigin) -> xr.Dataset:
    """The BSDF dataset (:mod:`bsdfkit.measurement.schema`) of per-record directions and BSDF values [1/sr]
    (records × wavelengths [nm], NaN = gap).

    One configuration (:data:`CONFIG_NAME`) with a flat incident spectrum over the wavelengths (elastic data:
    each wavelength is scattered at itself); no bi-spectral values (NaN), no noise floor (NaN), no instrument
    geometry (NaN attributes). Used by the table reader and by :mod:`bsdfkit.tables.vendor`.

    Parameters
    ----------
    records : RecordDirections
        Per-record angles [deg], side, and optionally arc and source line.
    wavelength_nm : sequence of float
        Wavelengths [nm] (one NaN when the source states none).
    bsdf : ndarray
        BSDF [1/sr], records × wavelengths (reshaped to it), NaN for a gap.
    bsdf_std : ndarray
        Standard uncertainty of ``bsdf`` [1/sr], same shape.
    origin : RecordsOrigin
        Source file, origin of ``bsdf_std``, description and wavelength note.

    Returns
    -------
    xarray.Dataset
        Validated BSDF dataset of one configuration, with ``source_sha256`` when the source file can be read.
    """
    n = len(records.theta_i)
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    th_i, ph_i, th_s, ph_s = (np.asarray(a, dtype=np.float64) for a in (records.theta_i, records.phi_i,
                                                                        records.theta_s, records.phi_s))
    arcs = np.asarray(records.arc, dtype=object) if records.arc is not None else arc_labels(th_i, ph_i, th_s, ph_s)
    spectrum, band = _flat_incident(lam)
    # the quantities an elastic table does not state: one read-only NaN matrix of no size, shared
    nan2 = np.broadcast_to(np.float64(np.nan), (n, lam.size))
    data = {
        "bsdf": np.asarray(bsdf, dtype=np.float64).reshape(n, lam.size),
        "bsdf_std": np.asarray(bsdf_std, dtype=np.float64).reshape(n, lam.size),
        "noise_floor": nan2, "bsdf_bispectral": nan2, "bsdf_bispectral_std": nan2, "noise_floor_bispectral": nan2,
        "saturated": np.zeros((n, lam.size), dtype=bool),
        "grazing": th_s >= 90.0 - 1e-9,
        "incident_spectrum": spectrum[None, :],
        "incident_relative_std": np.zeros((1, lam.size)),
        "incident_valid": np.ones((1, lam.size), dtype=bool),
        "incident_power_relative_std": np.zeros(1),
        "incident_band": np.array([band]),
        "configuration_description": np.array([origin.description or "measured table"], dtype=object),
    }
    lines = records.source_line
    coords = {
        "config": np.full(n, CONFIG_NAME, dtype=object), "theta_i": th_i, "phi_i": ph_i, "theta_s": th_s,
        "phi_s": ph_s, "side": np.asarray(records.side, dtype=object), "arc": arcs, "exposure": np.full(n, np.nan),
        "source_line": np.asarray(lines if lines is not None else np.zeros(n), dtype=np.int64),
        "wavelength": lam, "configuration": np.array([CONFIG_NAME], dtype=object),
        "band_edge": np.array(["low", "high"], dtype=object),
    }
    sides = set(pd.unique(coords["side"]).tolist())
    ds = new_bsdf_dataset(data, coords, _records_attributes(origin, [s for s in SIDES if s in sides]))
    _describe_records(ds, origin)
    digest = _sha256(origin.source)
    if digest is not None:
        ds.attrs["source_sha256"] = digest
    return ds


def _records_attributes(origin: RecordsOrigin, sides: list[str]) -> dict[str, Any]:
    """The dataset attributes of elastic records the schema does not fix, with NaN instrument geometry."""
    return dict(
        side=" ".join(sides), sample_name="", synthetic=0, source=str(origin.source), elastic=1,
        bsdf_std_origin=origin.std_origin,
        solid_angle_sr=np.nan, aperture_half_angle_deg=np.nan, gain_e_per_count=np.nan,
        detector_distance_mm=np.nan, aperture_diameter_mm=np.nan, beam_diameter_mm=np.nan,
        manifest_json="{}",
    )


def _describe_records(ds: xr.Dataset, origin: RecordsOrigin) -> None:
    """Long names and notes of the variables of elastic records (units come from the schema)."""
    if origin.wavelength_note:
        ds["wavelength"].attrs["note"] = origin.wavelength_note
    ds["bsdf"].attrs.update(long_name="BSDF", note="NaN where the table has no value (gap)")
    ds["bsdf_std"].attrs.update(long_name="standard uncertainty of bsdf", origin=origin.std_origin)
    ds["noise_floor"].attrs.update(long_name="noise-equivalent BSDF (not stated by the source: NaN)")
    ds["bsdf_bispectral"].attrs.update(note="elastic data: no wavelength conversion measured (NaN)")
    ds["incident_spectrum"].attrs.update(long_name="flat (equal-energy) weighting over the measured "
                                         "wavelengths: the source states no incident spectrum")
    ds["grazing"].attrs["long_name"] = "theta_s = 90 deg (no finite BSDF from a cosine-corrected value)"


def _sha256(path: str) -> str | None:
    """SHA-256 of a file read in blocks (the file is not held whole), or None when it cannot be read."""
    try:
        digest = hashlib.sha256()
        with open(path, "rb") as fh:
            while block := fh.read(1 << 20):
                digest.update(block)
    except OSError:
        return None
    return digest.hexdigest()


#: A peak counts when it stands this many times above the profile's median and above the mirrored position.
_PEAK_CONTRAST = 3.0
#: Window (deg) in θs around θi, and tolerance (deg) in azimuth, of the specular and retro positions.
_PEAK_WINDOW_DEG, _AZIMUTH_TOL_DEG = 2.0, 1.0


def _azimuth_frame(th_i: NDArray, ph_i: NDArray, th_s: NDArray, ph_s: NDArray, values: NDArray) -> str:
    """Which azimuth origin a table with a φs column uses, decided by its data.

    Tables write φs either in the sample frame (the documented convention: source at φi, specular at φi − 180°)
    or from the specular direction (φs = 0 on the specular side whatever φi says). Where every record has
    φi = 180° the two agree. Otherwise each incidence θi > 2° votes by where its peak near θs = θi sits: at
    φs = φi − 180° (the specular position of the sample frame) or at φs = 0 (that of the other origin; with
    φi = 0 it is the sample frame's retro position, where a goniometer's own source blocks the detector). A vote
    needs a peak :data:`_PEAK_CONTRAST` times above the profile's median and above the other position (a gap
    counts as 0).

    Returns
    -------
    str
        ``"sample"`` (keep), or ``"specular"`` when at least one incidence puts its peak at φs = 0 and none at
        φi − 180°.
    """
    if np.allclose(np.mod(ph_i - 180.0, 360.0), 0.0, atol=1e-9):
        return "sample"
    band = np.nanmean(np.where(np.isfinite(values), values, np.nan), axis=1) if values.size else values
    votes = {"sample": 0, "specular": 0}
    groups = np.unique(np.stack([np.round(th_i, 9), np.round(np.mod(ph_i, 360.0), 9)], axis=1), axis=0)
    for ti, pi_ in groups:
        if ti <= _PEAK_WINDOW_DEG:
            continue
        g = (np.abs(th_i - ti) < 1e-9) & (np.abs(np.mod(ph_i, 360.0) - pi_) < 1e-9) & np.isfinite(band)
        if g.sum() < 5:
            continue
        floor = float(np.median(np.abs(band[g])))
        near = g & (np.abs(th_s - ti) <= _PEAK_WINDOW_DEG)

        def peak(azimuth: float, near: NDArray = near) -> float:
            d = np.abs((ph_s - azimuth + 180.0) % 360.0 - 180.0)
            sel = near & (d <= _AZIMUTH_TOL_DEG)
            return float(np.max(band[sel])) if sel.any() else 0.0

        if abs(pi_ % 360.0 - 180.0) < _AZIMUTH_TOL_DEG:
            continue  # φi ≈ 180°: both origins put the specular position at φs = 0
        sample, specular = peak(pi_ - 180.0), peak(0.0)
        if sample > _PEAK_CONTRAST * max(floor, specular):
            votes["sample"] += 1
        elif specular > _PEAK_CONTRAST * max(floor, sample):
            votes["specular"] += 1
    return "specular" if votes["specular"] and not votes["sample"] else "sample"


def _theta_s_of(rows: _Rows, signed: bool, sl: Any) -> NDArray:
    """θs [deg] of the entries ``sl``: |θs| of a signed in-plane angle."""
    t = rows.theta_s[sl]
    return np.abs(t) if signed else t


def _phi_s_of(rows: _Rows, signed: bool, sl: Any) -> NDArray:
    """φs [deg] in [0, 360) of the entries ``sl`` (0 at θs = 0); of a signed in-plane angle: the specular side
    (φi − 180°) for θs ≥ 0, the source side (φi) below."""
    ts = rows.theta_s[sl]
    if signed:
        pi_ = rows.phi_i[sl]
        ps = np.where(ts >= 0, np.mod(pi_ - 180.0, 360.0), np.mod(pi_, 360.0))
        ts = np.abs(ts)
    else:
        ps = rows.phi_s[sl]
    p = np.mod(ps, 360.0)
    return np.where((ts < 1e-12) | (p >= 360.0), 0.0, p)


def _record_of_entries(rows: _Rows, signed: bool) -> tuple[NDArray, NDArray[np.int64]]:
    """The record of every entry and the first entry of every record: records keyed by (side, θi, φi, θs, φs)
    rounded to 1e-9, in order of first appearance, one per repetition of a direction."""
    n = rows.line.size
    direction = [(rows.side, None), (rows.theta_i, _exact), (rows.phi_i, lambda u: _exact(np.mod(u, 360.0))),
                 (partial(_theta_s_of, rows, signed), _exact),
                 (partial(_phi_s_of, rows, signed), lambda u: np.mod(_exact(u), 360.0))]
    # a direction measured more than once (the nadir of every C-plane, a repeated point) is kept as several
    # records, one per repetition: the hemispherical engine merges them with their spread in the uncertainty
    cell, n_cell = _codes_of_tuples([*direction, (rows.wavelength, None)], n)
    if n_cell == n:  # every (direction, wavelength) once: no repetitions
        del cell
    code, nc = _codes_of_tuples(direction, n)
    if n_cell < n:
        occurrence = np.empty(n, dtype=np.int32 if n < 2**31 else np.int64)
        seen = np.zeros(n_cell, dtype=occurrence.dtype)
        for i in range(0, n, _SLICE):
            occurrence[i: i + _SLICE] = _rank_in_group(cell[i: i + _SLICE], seen)
        del seen
        del cell
        code, nc = _combine(code, nc, occurrence, int(occurrence.max()) + 1)
        del occurrence
    first = _first_index(code, nc)
    order = np.argsort(first, kind="stable")  # records in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    rec_of = np.array(code, dtype=np.int32 if nc < 2**31 else np.int64)
    del code
    for i in range(0, n, _SLICE):
        rec_of[i: i + _SLICE] = rank[rec_of[i: i + _SLICE]]
    return rec_of, first[order]


@dataclass
class _Records:
    """The directions of the records [deg], their sides and first lines (φs rewritten once the azimuth origin
    is known)."""

    theta_i: NDArray[np.float64]
    phi_i: NDArray[np.float64]
    theta_s: NDArray[np.float64]
    phi_s: NDArray[np.float64]
    side: list[str]
    line: list[int]


def _records_of(rows: _Rows, first: NDArray[np.int64], signed: bool) -> _Records:
    """The directions of the records from their first entries; the entries' directions are then released."""
    rec = _Records(np.array(rows.theta_i[first]), np.array(rows.phi_i[first]), _theta_s_of(rows, signed, first),
                   _phi_s_of(rows, signed, first), [SIDES[int(c)] for c in rows.side[first]],
                   np.asarray(rows.line[first], dtype=np.int64).tolist())
    for name in ("theta_i", "phi_i", "theta_s", "phi_s"):
        # the directions are in the records now: released
        setattr(rows, name, np.zeros(0, dtype=getattr(rows, name).dtype))
    return rec


def _wavelengths(rows: _Rows, path: str) -> tuple[NDArray[np.float64], bool]:
    """The sorted distinct wavelengths [nm] of the entries (one NaN when none is stated) and whether any is;
    refuses a table where stated and unstated wavelengths mix (a (record, wavelength) pair would repeat)."""
    n = rows.line.size
    finite = [np.unique(w[np.isfinite(w)]) for w in (rows.wavelength[i: i + _SLICE] for i in range(0, n, _SLICE))]
    lam = np.unique(np.concatenate(finite)) if finite else np.zeros(0)
    if lam.size == 0:
        return np.array([np.nan]), False
    for i in range(0, n, _SLICE):
        unstated = np.isnan(rows.wavelength[i: i + _SLICE])
        if unstated.any():
            k = i + int(np.argmax(unstated))
            raise FormatError("no wavelength for this row, where other rows state theirs", file=path,
                              line=int(rows.line[k]), field="wavelength",
                              expected="a wavelength column, '# wavelength: NM' before the first block, or "
                                       "--wavelength NM", got="no wavelength")
    return lam, True


def _record_quantities(rows: _Rows, first: NDArray[np.int64], rec_of: NDArray, path: str) -> NDArray[np.object_]:
    """The quantity of every record (that of its first entry); refuses a direction holding two quantities."""
    n = rows.line.size
    q_names = sorted(set(rows.quantities))
    q_of_spec = np.array([q_names.index(q) for q in rows.quantities])
    q_first = q_of_spec[rows.spec[first]]
    if len(q_names) > 1:
        for i in range(0, n, _SLICE):
            other = q_of_spec[rows.spec[i: i + _SLICE]] != q_first[rec_of[i: i + _SLICE]]
            if other.any():
                k = i + int(np.argmax(other))
                raise ValidationError("one direction holds two quantities", file=path, line=int(rows.line[k]),
                                      field=rows.column(k), expected=q_names[q_first[rec_of[k]]],
                                      got=rows.quantity(k))
    return np.array([q_names[c] for c in q_first], dtype=object)


def _value_matrices(rows: _Rows, rec_of: NDArray, lam: NDArray[np.float64], stated_lam: bool, n_rec: int
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool]:
    """Values and absolute uncertainties on (record, wavelength) (NaN = gap), and whether the table has no
    uncertainty column (then the uncertainties are a read-only NaN matrix of no size); the entries are then
    released."""
    n = rows.line.size
    no_std = rows.std.strides == (0,) and bool(np.isnan(rows.std[:1]).all())
    values = np.full((n_rec, lam.size), np.nan)
    stds = np.broadcast_to(np.float64(np.nan), values.shape) if no_std else np.full((n_rec, lam.size), np.nan)
    v_flat, s_flat = values.reshape(-1), stds.reshape(-1)
    for i in range(0, n, _SLICE):
        sl = slice(i, i + _SLICE)
        lam_at = np.searchsorted(lam, rows.wavelength[sl]) if stated_lam else np.zeros(len(range(*sl.indices(n))),
                                                                                       dtype=np.int64)
        at = rec_of[sl].astype(np.int64) * lam.size + lam_at
        v = rows.value[sl]
        v_flat[at] = v
        if not no_std:
            s_flat[at] = np.where(rows.std_relative[sl], rows.std[sl] * np.abs(v), rows.std[sl])
    for name in ("wavelength", "value", "std", "std_relative", "side", "spec", "line"):
        # the entries are in the matrices now: released
        setattr(rows, name, np.zeros(0, dtype=getattr(rows, name).dtype))
    return values, stds, no_std


def _zeros_as_gaps(values: NDArray[np.float64], zeros: str) -> tuple[NDArray[np.float64], int]:
    """The values with exact zeros made gaps per the policy, and how many all-zero records became gaps."""
    if zeros == "missing":
        return np.where(values == 0.0, np.nan, values), 0
    if zeros == "auto":
        stated = np.isfinite(values)
        all_zero = stated.any(axis=1) & np.all(np.where(stated, values == 0.0, True), axis=1)
        values[all_zero] = np.nan
        return values, int(all_zero.sum())
    return values, 0


def _bsdf_matrices(values: NDArray[np.float64], stds: NDArray[np.float64], no_std: bool, quantity: NDArray,
                   theta_s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """BSDF and its absolute uncertainty [1/sr] from the table's quantities (None: no uncertainty column)."""
    if len(set(quantity.tolist())) == 1:  # one quantity: converted whole (no copy for brdf/btdf/bsdf)
        return (to_bsdf(values, quantity[0], theta_s),
                None if no_std else np.abs(to_bsdf(stds, quantity[0], theta_s)))
    f = np.full_like(values, np.nan)
    s = np.full_like(values, np.nan)
    for q in set(quantity.tolist()):
        sel = quantity == q
        f[sel] = to_bsdf(values[sel], q, theta_s[sel])
        if not no_std:
            s[sel] = np.abs(to_bsdf(stds[sel], q, theta_s[sel]))
    return f, s


def _fill_std(f: NDArray[np.float64], s: NDArray[np.float64] | None, has_std: NDArray[np.bool_], rel: float | None
              ) -> tuple[NDArray[np.float64], str]:
    """The uncertainty [1/sr] with ``relative_std · |f|`` where the table states none, and where it comes from."""
    rel_used = DEFAULT_RELATIVE_STD if rel is None else float(rel)
    if s is None or not has_std.any():  # rel · |f| everywhere, formed in place
        s = np.abs(f)
        s *= rel_used
    else:
        np.copyto(s, rel_used * np.abs(f), where=~has_std)
        s[~np.isfinite(f)] = np.nan
    if has_std.all():
        return s, "the table's uncertainty column"
    if has_std.any():
        return s, (f"the table's uncertainty column where given, else {rel_used:g} x |bsdf|"
                   + (" (assumed default)" if rel is None else ""))
    return s, f"{rel_used:g} x |bsdf|" + (" (assumed default: the table states no uncertainty)" if rel is None
                                          else " (relative_std given)")


def _assemble(path: str, rows: _Rows, signed: bool, rel: float | None, zeros: str) -> xr.Dataset:
    """The dataset of the parsed entries: records keyed by (side, θi, φi, θs, φs) rounded to 1e-9, in order of
    first appearance, one per repetition of a direction. Computed in slices of :data:`_SLICE` entries on integer
    codes; the entries of ``rows`` are released once the value matrices are filled."""
    wavelength_known = bool(np.isfinite(rows.wavelength).any())
    rec_of, first = _record_of_entries(rows, signed)
    rec = _records_of(rows, first, signed)
    lam, stated_lam = _wavelengths(rows, path)
    quantity = _record_quantities(rows, first, rec_of, path)
    values, stds, no_std = _value_matrices(rows, rec_of, lam, stated_lam, first.size)
    del rec_of
    frame = "sample" if signed else _azimuth_frame(rec.theta_i, rec.phi_i, rec.theta_s, rec.phi_s, values)
    if frame == "specular":  # φs measured from the specular direction: into the sample frame
        rec.phi_s = np.where(rec.theta_s < 1e-12, 0.0, np.mod(rec.phi_s + rec.phi_i - 180.0, 360.0))
    values, zero_records = _zeros_as_gaps(values, zeros)
    has_std = np.zeros(values.shape, dtype=bool) if no_std else np.isfinite(stds) & np.isfinite(values)
    f, s = _bsdf_matrices(values, stds, no_std, quantity, rec.theta_s)
    del values, stds
    s, origin = _fill_std(f, s, has_std, rel)
    keep = np.isfinite(f).any(axis=1)
    if not keep.any():
        raise InputError("the table holds no values (every cell is a gap)", file=path, field="value",
                         expected="at least one finite value")
    idx = np.flatnonzero(keep)
    note = "" if wavelength_known else "not stated by the table; pass --wavelength NM (NaN = unknown)"
    if idx.size < keep.size:  # records without any value dropped (a copy of the matrices only then)
        f, s = f[idx], s[idx]
    ds = records_dataset(RecordDirections(rec.theta_i[idx], rec.phi_i[idx], rec.theta_s[idx], rec.phi_s[idx],
                                          [rec.side[i] for i in idx], source_line=[rec.line[i] for i in idx]),
                         lam, f, s, RecordsOrigin(path, std_origin=origin, wavelength_note=note,
                                                  description=f"measured table {Path(path).name}: "
                                                              f"{', '.join(sorted(set(quantity.tolist())))}, "
                                                              "elastic"))
    if frame == "specular":
        ds.attrs["azimuth_note"] = ("phi_s read from the specular direction (phi_s = 0 on the specular side): the "
                                    "table's peaks sit at phi_s = 0 although phi_i is not 180 deg")
    ds.attrs.update(gap_records_dropped=int((~keep).sum()), zero_records_as_gaps=zero_records, zeros_policy=zeros,
                    negative_values=int(np.sum(f < 0)),
                    relative_std=DEFAULT_RELATIVE_STD if rel is None else float(rel))
    if note:
        ds.attrs["wavelength_note"] = note
    return ds


def guess_can_open(path: str | Path) -> bool:
    """True when ``path`` looks like a measured text table :func:`read_table` can read (a header with angle and
    value columns within the first lines); never raises.

    Parameters
    ----------
    path : str or Path
        File to probe (its first 64 KiB are read).

    Returns
    -------
    bool
        True when a header with angle and value columns is found; False for anything else (missing file,
        netCDF/HDF5 or zip, no header).
    """
    p = Path(path)
    try:
        if not p.is_file():
            return False
        with open(p, "rb") as fh:
            head = fh.read(65536)
        if head.startswith((b"\x89HDF", b"CDF\x01", b"CDF\x02", b"PK\x03\x04")):
            return False
        text, _ = _decode(head, str(p))
        lines = [(n, ln) for n, ln in enumerate(text.splitlines()[:-1] or text.splitlines(), 1)
                 if ln.strip() and not ln.strip().startswith(_COMMENTS)]
        if not lines:
            return False
        _find_header(_Text(str(p), lines[:220], [], "", len(lines)))
        return True
    except (InputError, OSError, ValueError, csv.Error):
        return False


def describe_columns(path: str | Path) -> dict[str, Any]:
    """Which role bsdfkit gives each column of a table (for error messages and ``--json`` summaries).

    Parameters
    ----------
    path : str or Path
        Measured text table.

    Returns
    -------
    dict
        ``delimiter`` (tab, ``;`` or ``,``; None for whitespace) and ``columns``: (header, role) per column,
        roles ``theta_i``, ``phi_i``, ``theta_s``, ``phi_s``, ``wavelength``, ``side``, ``value``, ``std`` or
        ``ignore``.

    Raises
    ------
    InputError
        The file cannot be read or has no recognisable header.
    """
    text = _load_text(str(path))
    _, delim, columns, _ = _find_header(text)
    return {"delimiter": delim, "columns": [(c.header, c.role) for c in columns]}
