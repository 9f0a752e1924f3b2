"""Atomic, non-clobbering output.

Every file bsdfkit writes goes to a temporary file in the destination directory, is flushed and fsynced,
and is then renamed over the target (``os.replace`` is atomic on POSIX and Windows). A reader therefore
sees either the old file or the complete new one, never a partial file, even if the process is killed
mid-write. An existing target is only replaced when ``force`` is true.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from bsdfkit.core.errors import OutputExistsError


def check_writable(path: str | Path, force: bool) -> Path:
    """Return ``path`` as a Path, raising :class:`OutputExistsError` if it exists and not ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError("output exists; pass --force (force=True) to overwrite", file=path)
    return path


@contextlib.contextmanager
def atomic_path(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed to ``path``.

    Use for writers that insist on a file name (netCDF engines, matplotlib)::

        with atomic_path("out.nc", force) as tmp:
            ds.to_netcdf(tmp)
    """
    path = check_writable(path, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    # mkstemp creates 0600; give the final file the permissions an ordinary open() would.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_bytes(path: str | Path, data: bytes, force: bool = False) -> Path:
    """Atomically write ``data`` to ``path``."""
    with atomic_path(path, force) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
    return Path(path)


def write_text(path: str | Path, text: str, force: bool = False, newline: str | None = "\n") -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``. ``newline="\\r\\n"`` gives CRLF line ends."""
    data = text if newline in (None, "\n") else text.replace("\n", newline)
    return write_bytes(path, data.encode("utf-8"), force)


def write_with(path: str | Path, writer: Callable[[Path], object], force: bool = False) -> Path:
    """Atomically create ``path`` by calling ``writer(tmp_path)``."""
    with atomic_path(path, force) as tmp:
        writer(tmp)
    return Path(path)
