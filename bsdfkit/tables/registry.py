"""The one registry of BSDF table formats: what each can read and write, found by ``export``, ``convert``, ``read``
and ``ingest`` (none of them dispatches on a format name by hand).

A format is **one module** in :mod:`bsdfkit.tables.formats` that defines ``FORMAT``, a
:class:`bsdfkit.tables.format_spec.TableFormat`, and is listed once, by its name (the module's), in :data:`NAMES`
below (:data:`FORMATS`, the declarations themselves, imports every format module):

* ``name`` (the ``--to`` value and the ``format`` of ``bsdfkit read``), ``title``, file ``extensions``;
* ``guess_can_open(head, path) -> bool``: a content sniffer (``head`` is the file's first 4 KiB decoded as
  text; as xarray's backends' ``guess_can_open``, it looks at content; the extension only breaks a tie);
* ``summarise(path) -> FileSummary``: incidences and TIS by the format's own quadrature and as stated;
* ``vendor_table(path) -> VendorTable``: the file's nodes in its native coordinates (for the calibrated dataset
  of ``ingest`` and the TIS the hemispherical engine computes for ``read``);
* ``write(job) -> WriteOutcome``: write a table from a BSDF callable (``None`` for a read-only format);
  ``sides_per_file``: 1 when a file holds one side (``both`` is refused before any work).
"""
from __future__ import annotations

from importlib import import_module
from pathlib import Path
from typing import Any

from bsdfkit.core.errors import FormatError, InputError
from bsdfkit.io.text import decode_text
from bsdfkit.tables.format_spec import (
    FileSummary,
    TableFormat,
    VendorGrid,
    VendorTable,
    WriteJob,
    WriteOutcome,
)

__all__ = ["NAMES", "WRITABLE", "FileSummary", "TableFormat", "VendorGrid", "VendorTable", "WriteJob",
           "WriteOutcome", "get", "names", "sniff_format", "writable"]

#: every format by name, in sniffing order (a format whose sniffer would also accept another's files goes later);
#: each is the module ``bsdfkit.tables.formats.<name>`` (its ``FORMAT.name`` is the same word, a test checks it),
#: imported when the format is first used: the verbs' help texts name the formats without importing numpy and
#: seven readers and writers (0.3 s of the 0.5 s of ``bsdfkit --help``)
NAMES: tuple[str, ...] = ("tracepro", "zemax", "asap", "bsdfxml", "speos", "speosbrdf", "lighttools")
#: the formats with a writer (``FORMAT.can_write``; checked by the same test)
WRITABLE: tuple[str, ...] = NAMES
#: bytes handed to the sniffers
SNIFF_BYTES = 4096


def __getattr__(name: str) -> Any:
    # PEP 562: FORMATS (every declaration, which imports every format module) only when asked for
    if name == "FORMATS":
        return tuple(get(n) for n in NAMES)
    raise AttributeError(f"module 'bsdfkit.tables.registry' has no attribute {name!r}")


def names() -> tuple[str, ...]:
    """Names of the registered formats."""
    return NAMES


def get(name: str) -> TableFormat:
    """The format called ``name`` (FormatError naming the known ones otherwise); imports its module.

    Parameters
    ----------
    name : str
        A name of :data:`NAMES`.

    Returns
    -------
    TableFormat
        The format's declaration.
    """
    if name not in NAMES:
        raise FormatError("unknown table format", field="format", expected=" | ".join(NAMES), got=name)
    return import_module(f"bsdfkit.tables.formats.{name}").FORMAT


def writable() -> tuple[str, ...]:
    """Names of the formats with a writer."""
    return WRITABLE


def _head(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            raw = fh.read(SNIFF_BYTES)
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=path) from None
    return decode_text(raw, path, expected="a table", legacy="latin-1")


def sniff_format(path: str | Path) -> str:
    """The name of the registered format whose sniffer accepts the file's content (FormatError otherwise).

    Parameters
    ----------
    path : str or Path
        The table file.

    Returns
    -------
    str
        The format's name.
    """
    path = Path(path)
    head = _head(path)
    formats = [get(n) for n in NAMES]
    matches = [f for f in formats if f.guess_can_open(head, path)]
    if matches:
        ext = [f for f in matches if path.suffix.lower() in f.extensions]
        return (ext or matches)[0].name
    lines = head.splitlines()
    first = lines[0].strip() if lines else ""
    raise FormatError("unrecognised table format", file=path, line=1, field="format",
                      expected="a " + ", ".join(f.title for f in formats) + " file", got=first[:60])
