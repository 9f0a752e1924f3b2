"""The one registry of BSDF table formats: what each can read and write, found by ``export``, ``convert``, ``read``
and ``ingest`` (none of them dispatches on a format name by hand).

A format is **one module** in :mod:`bsdfkit.tables.formats` that defines ``FORMAT``, a
:class:`bsdfkit.tables.format_spec.TableFormat`, and is listed once in :data:`FORMATS` below:

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

from pathlib import Path

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
from bsdfkit.tables.formats import asap, bsdfxml, lighttools, speos, speosbrdf, tracepro, zemax

__all__ = ["FORMATS", "FileSummary", "TableFormat", "VendorGrid", "VendorTable", "WriteJob", "WriteOutcome",
           "get", "names", "sniff_format", "writable"]

#: every format, in sniffing order (a format whose sniffer would also accept another's files goes later)
FORMATS: tuple[TableFormat, ...] = (tracepro.FORMAT, zemax.FORMAT, asap.FORMAT, bsdfxml.FORMAT,
                                     speos.FORMAT, speosbrdf.FORMAT, lighttools.FORMAT)
#: bytes handed to the sniffers
SNIFF_BYTES = 4096


def names() -> tuple[str, ...]:
    """Names of the registered formats."""
    return tuple(f.name for f in FORMATS)


def get(name: str) -> TableFormat:
    """The format called ``name`` (FormatError naming the known ones otherwise)."""
    for f in FORMATS:
        if f.name == name:
            return f
    raise FormatError("unknown table format", field="format", expected=" | ".join(names()), got=name)


def writable() -> tuple[str, ...]:
    """Names of the formats with a writer."""
    return tuple(f.name for f in FORMATS if f.can_write)


def _head(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            raw = fh.read(SNIFF_BYTES)
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=path) from None
    return decode_text(raw, path, expected="a table", legacy="latin-1")


def sniff_format(path: str | Path) -> str:
    """The name of the registered format whose sniffer accepts the file's content (FormatError otherwise)."""
    path = Path(path)
    head = _head(path)
    matches = [f for f in FORMATS if f.guess_can_open(head, path)]
    if matches:
        ext = [f for f in matches if path.suffix.lower() in f.extensions]
        return (ext or matches)[0].name
    lines = head.splitlines()
    first = lines[0].strip() if lines else ""
    raise FormatError("unrecognised table format", file=path, line=1, field="format",
                      expected="a " + ", ".join(f.title for f in FORMATS) + " file", got=first[:60])
