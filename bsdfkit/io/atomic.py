"""Atomic, non-clobbering output: single files and whole output sets.

**Single files.** Every file bsdfkit writes goes to a temporary file ``.bsdfkit-<pid>.<8 hex>.part`` in the
destination directory (at most 33 bytes, so that any valid output name, up to the 255 bytes of NAME_MAX, has a
temporary name that fits), is flushed and fsynced, and is then moved to the target. Without ``force`` the move is
an exclusive create (``os.link`` of the finished temporary file, which fails if the target exists), so of two
concurrent writers exactly one succeeds and the other gets :class:`OutputExistsError`; with ``force`` it is
``os.replace``. A reader therefore sees either the old file or the complete new one, never a partial file,
even if the process is killed mid-write. Temporary files of processes that no longer run are removed by the
next write to the same target.

**Checked files** (:class:`StagedFile`: ``bsdfkit convert``, ``export``). A file that must pass a check on
what was written (the TIS of a re-read table) is written under a hidden name in its folder
(``.bsdfkit-staged-<pid>.<8 hex><suffix>``), re-read and checked there, and placed as above only when it passed
(or kept under a name that says it failed, :func:`failed_check_path`, when asked); otherwise it is removed, and an
earlier output at the path, replaced only by a checked file, stays as it was.

**Output sets** (:class:`OutputSet`: ``bsdfkit run``, ``simulate``, ``bench``, ``trace``, ``sweep``). The files
are written into a staging folder ``.<folder>.<pid>.staging`` beside the target folder and moved into place at
the end: a missing or empty target folder is replaced by one rename, a target holding only a previous set of
the same outputs is swapped (with ``force``), and only a target that also holds other files gets the staged
files one by one. A kill or a full disk therefore leaves the previous complete set or nothing, and a rerun
works without ``force``; stale staging folders of dead processes are removed by the next run.

An existing output folder keeps its owner and mode: the folder moved into its place takes them, and a folder
whose mode grants no write permission (mode 555, also for root, who could write anyway) is refused before any
work. A folder that is a mount point (a bind mount, on the same file system or not; ``/proc/self/mountinfo``)
cannot be renamed (EBUSY) nor receive renamed files from outside it (EXDEV): the set is staged inside it and
its files are moved into place one by one, each atomically; a rename that still fails with EBUSY or EXDEV
falls back to the same per-file placement (a file is then copied into a temporary file inside the target
first).

A folder that *is* the output (``whole_folder``: ``run``, ``simulate``; :func:`check_output_folder`) is never
mixed with other files: when it exists and is not empty it is refused without ``force`` and replaced as a
whole with it (swapped in by two renames), never when it is or holds an input of the command.

**Checks before computing.** :func:`check_writable` refuses, before any work is done, an existing output
without ``force``, an output path that is a directory (or whose parent is a file), an output that is one of
the command's own inputs or exists and is not a regular file (a symbolic link, FIFO, device; both even with
``force``) and a destination that cannot be written (a probe file is
created and removed, which also catches read-only file systems when running as root).

Operating-system faults (permission, read-only file system, no space, ...) become :class:`OutputError`: one
line naming the path and the fault. A full device says so (``no space left on device while writing <file>``),
also when the netCDF/HDF5 library reports it only as "NetCDF: HDF error" (the free space is checked after
the failure, :data:`FULL_DEVICE_BYTES`).
"""
from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from bsdfkit.core.errors import BsdfkitError, OutputError, OutputExistsError

__all__ = ["OutputError", "OutputExistsError", "OutputSet", "StagedFile", "atomic_path", "check_output_folder",
           "check_writable", "defer_until_committed", "describe_os_error", "failed_check_path", "refuse_inputs",
           "remove_partial_outputs", "write_bytes", "write_text", "write_with"]

#: Temporary files and staging folders of this process that are not finished yet (removed on SIGTERM).
_PARTIAL: set[Path] = set()
#: Held while partial outputs are removed and while an output set is moved into place, so that a signal watcher
#: thread (bsdfkit.cli.main) never empties a staging folder that the main thread is committing; reentrant for the
#: exit a signal handler deferred to the end of a commit (defer_until_committed), which runs while it is held.
_COMMIT_LOCK = threading.RLock()
#: Threads moving an output set into place, and what a signal handler that interrupted one of them asked to run
#: once the set is in place (defer_until_committed).
_COMMITTING: set[int] = set()
_AFTER_COMMIT: list[Callable[[], None]] = []


def defer_until_committed(action: Callable[[], None]) -> bool:
    """Run ``action`` when this thread's output-set commit ends, if one is in progress (a signal handler that
    interrupted it): the set is then moved into place whole, or not at all, before the process ends. Without
    this, a handler ending the process halfway left the staging folder behind, or a finished set beside the
    message "unfinished outputs removed" (seen when SIGTERM met the end of ``bsdfkit simulate``).

    Parameters
    ----------
    action : callable
        What to run after the commit (typically: end the process).

    Returns
    -------
    bool
        True when ``action`` was deferred; False when no commit is in progress in this thread (run it now).
    """
    if threading.get_ident() not in _COMMITTING:
        return False
    _AFTER_COMMIT.append(action)
    return True


@contextlib.contextmanager
def _commit_zone() -> Iterator[None]:
    """Where this thread moves finished outputs into place: partial outputs are not removed meanwhile (the lock)
    and a signal handler's exit waits until the end (:func:`defer_until_committed`), then runs."""
    with _COMMIT_LOCK:
        _COMMITTING.add(threading.get_ident())
        try:
            yield
        finally:
            _COMMITTING.discard(threading.get_ident())
            while _AFTER_COMMIT:
                _AFTER_COMMIT.pop(0)()


def remove_partial_outputs() -> int:
    """Remove this process's unfinished temporary files and staging folders (for a signal handler).

    The lock is not released: the caller is about to end the process, and no commit may start meanwhile.

    Returns
    -------
    int
        How many unfinished outputs were removed (0: every output of the command is complete, or none was
        begun; a handler then need not say that any were removed).
    """
    _COMMIT_LOCK.acquire()
    count = 0
    for path in list(_PARTIAL):
        with contextlib.suppress(OSError):
            count += os.path.lexists(path)  # registered before its first byte: nothing begun there yet
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink()
        _PARTIAL.discard(path)
    return count

PathLike = str | Path

_REASONS = {
    errno.ENOSPC: "no space left on the device",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EISDIR: "the path is a directory",
    errno.ENOTDIR: "a parent of the path is a file, not a folder",
    errno.EEXIST: "the path exists",
    errno.ENAMETOOLONG: "file name too long",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large for the file system",
    errno.EIO: "input/output error",
    errno.ENOENT: "no such file or folder",
    errno.ELOOP: "too many levels of symbolic links",
    errno.EXDEV: "cross-device move (the folder is a mount point)",
    errno.EBUSY: "the folder is a mount point or in use (device or resource busy)",
}

#: prefix of temporary files, probes and (for names too long to prefix) staging folders:
#: ``.bsdfkit-<pid>.<8 hex>.part``
TEMP_PREFIX = ".bsdfkit-"
#: the longest file name most file systems take (bytes of the encoded name)
NAME_MAX = 255
#: prefix of the files :class:`StagedFile` checks before committing: ``.bsdfkit-staged-<pid>.<8 hex><suffix>``
STAGED_PREFIX = ".bsdfkit-staged-"
#: what :func:`failed_check_path` puts before the suffix of a table kept after failing its check
FAILED_CHECK_TAG = ".failed-check"


def _token() -> str:
    """8 random hex digits: ``secrets.token_hex(4)`` (os.urandom), without importing secrets (hmac, random, base64)
    into every command."""
    return os.urandom(4).hex()


def _temp_name(suffix: str = ".part") -> str:
    """A short temporary name of this process: fits beside any valid output name."""
    return f"{TEMP_PREFIX}{os.getpid()}.{_token()}{suffix}"


def _beside_name(name: str, suffix: str) -> str:
    """``.<name>.<pid>.<8 hex><suffix>`` when it fits in :data:`NAME_MAX` bytes, else a :func:`_temp_name`."""
    long = f".{name}.{os.getpid()}.{_token()}{suffix}"
    return long if len(os.fsencode(long)) <= NAME_MAX else _temp_name(suffix)


def describe_os_error(exc: BaseException) -> str:
    """A short, stable description of an OS error: 'no space left on the device [ENOSPC]'.

    Parameters
    ----------
    exc : BaseException
        The error, usually an :class:`OSError` with an ``errno``.

    Returns
    -------
    str
        Reason and errno name, or the error's text when it has no errno.
    """
    code = getattr(exc, "errno", None)
    if code is None:
        return str(exc) or type(exc).__name__
    name = errno.errorcode.get(code, str(code))
    reason = _REASONS.get(code) or (getattr(exc, "strerror", None) or type(exc).__name__).lower()
    return f"{reason} [{name}]"


def _fault(exc: OSError, path: PathLike, writable: bool = False) -> OutputError:
    code = getattr(exc, "errno", None)
    if code in (errno.ENOSPC, errno.EDQUOT):
        return _no_space(path, code)
    # HDF5 reports a full device as EACCES (or with no errno) when it fails to write into a file this process has
    # just created: a folder that took the temporary file is writable, so a full device is the cause
    if (code is None or (writable and code in (errno.EACCES, errno.EPERM, errno.EIO))) \
            and _device_full(Path(path).parent):
        return _no_space(path)
    return OutputError(f"cannot write output: {describe_os_error(exc)}", file=path)


def _no_space(path: PathLike, code: int = errno.ENOSPC) -> OutputError:
    """The one line of a full device (or quota): which file, and how much is free where."""
    path = Path(path)
    what = "no space left on device" if code == errno.ENOSPC else "disk quota exceeded"
    try:
        free = f"{shutil.disk_usage(_nearest_existing(path.parent)).free / 1e6:.3g} MB free when the write failed"
    except OSError:
        free = None
    return OutputError(f"{what} while writing {path.name} [{errno.errorcode[code]}]", file=path,
                       expected=f"free space on the device of {path.parent} (free some, or write elsewhere)",
                       got=free)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _stale(folder: Path, prefix: str, suffix: str, any_tail: bool = False) -> Iterator[Path]:
    """Entries ``<prefix><pid>.<...><suffix>`` of ``folder`` whose process is gone (``any_tail``: whatever follows
    ``<pid>.<8 hex>``, the output's own suffix of a staged file)."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        name = entry.name
        if not (name.startswith(prefix) and name.endswith(suffix)):
            continue
        # exactly <pid>.<8 hex digits>[.probe]: not the temporary file of another target sharing the prefix
        parts = name[len(prefix):len(name) - len(suffix)].split(".")
        if not (len(parts) >= 2 and parts[0].isdigit() and len(parts[1]) == 8
                and all(c in "0123456789abcdef" for c in parts[1])
                and (any_tail or parts[2:] in ([], ["probe"]))):
            continue
        if not _pid_alive(int(parts[0])):
            yield entry


def _remove_stale_temps(path: Path) -> None:
    """Remove temporary files in the folder of ``path`` left by processes that were killed (both the short
    names of today and the ``.<name>.<pid>.<hex>.part`` names of earlier versions)."""
    for prefix in (TEMP_PREFIX, f".{path.name}."):
        for entry in _stale(path.parent, prefix, ".part"):
            with contextlib.suppress(OSError):
                entry.unlink()
    for entry in _stale(path.parent, STAGED_PREFIX, "", any_tail=True):  # StagedFile of a killed process
        with contextlib.suppress(OSError):
            entry.unlink()


def refuse_inputs(output: PathLike, inputs: Iterable[PathLike | None]) -> None:
    """Raise if writing ``output`` would replace one of ``inputs`` (a file, or a file inside an input folder).

    Refused even with ``force``: compares resolved paths and, for existing files, ``os.path.samefile``.

    Parameters
    ----------
    output : str or Path
        Output file or folder.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).
    """
    out = Path(output)
    out_resolved = out.resolve()
    for inp in inputs:
        if inp is None:
            continue
        src = Path(inp)
        try:
            src_resolved = src.resolve()
            same = out_resolved == src_resolved or (out.exists() and src.exists() and os.path.samefile(out, src))
            inside = (src.is_dir() and out.exists() and not out.is_dir()
                      and out_resolved.is_relative_to(src_resolved))
        except OSError:
            continue
        if same or inside:
            raise OutputError("output would overwrite an input of this command (refused even with --force)",
                              file=out, expected="an output path different from every input", got=str(src))


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _probe(folder: Path, name: str, target: Path) -> None:
    """Create and remove a small file in ``folder`` (the nearest existing ancestor of the output)."""
    _check_mode(folder, target)
    probe = folder / _temp_name(".probe.part")
    try:
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"cannot write output: {describe_os_error(exc)}", file=target,
                          expected=f"a writable folder ({folder})") from None


def _check_mode(folder: Path, target: Path) -> None:
    """Refuse a folder whose mode grants no write permission (555): for root too, who could write anyway but
    would then ignore what the owner of the folder said."""
    try:
        mode = folder.stat().st_mode
    except OSError:
        return
    if not mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
        raise OutputError(f"cannot write output: the folder {folder} is not writable (permission denied, mode "
                          f"{stat.S_IMODE(mode):o})", file=target,
                          expected="a folder you may write into (chmod u+w, or another output folder)",
                          got=f"mode {stat.S_IMODE(mode):o}")


def _is_mount_point(folder: Path) -> bool:
    """True for a mount point, bind mounts of the same file system included (``os.path.ismount`` misses those)."""
    with contextlib.suppress(OSError):
        if os.path.ismount(folder):
            return True
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="surrogateescape") as fh:
            points = {line.split()[4] for line in fh if len(line.split()) > 4}
    except OSError:
        return False
    # mountinfo escapes space, tab, newline and backslash as octal (\040 ...)
    decode = {"\\040": " ", "\\011": "\t", "\\012": "\n", "\\134": "\\"}
    for point in points:
        for code, char in decode.items():
            point = point.replace(code, char)
        if point == str(folder):
            return True
    return False


def _adopt_owner_and_mode(new: Path, old: Path) -> None:
    """Give folder ``new`` (moved into the place of ``old``) the owner, group and mode of ``old``."""
    try:
        st = old.stat()
        os.chmod(new, stat.S_IMODE(st.st_mode))
        if (st.st_uid, st.st_gid) != (os.getuid(), os.getgid()):
            with contextlib.suppress(PermissionError):
                os.chown(new, st.st_uid, st.st_gid)
    except OSError:
        pass


def _move_file(src: Path, dst: Path, force: bool) -> None:
    """:func:`_place` ``src`` at ``dst``; across a mount point (EXDEV) it is first copied into a temporary file
    beside ``dst`` (fsynced), so ``dst`` still appears complete or not at all."""
    try:
        _place(src, dst, force)
        return
    except OSError as exc:
        if exc.errno not in (errno.EXDEV, errno.EBUSY):
            raise
    tmp = dst.parent / _temp_name()
    _PARTIAL.add(tmp)
    try:
        shutil.copyfile(src, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        _place(tmp, dst, force)
        with contextlib.suppress(OSError):
            src.unlink()
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()
        _PARTIAL.discard(tmp)


def check_writable(path: PathLike, force: bool, inputs: Iterable[PathLike | None] = ()) -> Path:
    """Check an output before computing it; return it as a Path.

    Raises :class:`OutputExistsError` if it exists and not ``force``, and :class:`OutputError` if it is a
    folder, a parent is a file, it is one of ``inputs`` (even with ``force``), it exists and is not a regular
    file (a symbolic link, FIFO, device or socket; even with ``force``) or its folder cannot be written.

    Parameters
    ----------
    path : str or Path
        Output file.
    force : bool, optional
        Replace an existing output.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError("output path is a folder", file=path, expected="a file name")
    refuse_inputs(path, inputs)
    _refuse_special(path)
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputExistsError("output exists; pass --force (force=True) to overwrite", file=path)
    anchor = _nearest_existing(path.parent)
    if not anchor.is_dir():
        raise OutputError("a parent of the output path is a file, not a folder", file=path, got=str(anchor))
    _probe(anchor, path.name, path)
    return path


def _refuse_special(path: Path) -> None:
    """Refuse an existing output that is not a regular file, even with ``force``: the rename that replaces it
    would replace a symbolic link (not the file it points to), a FIFO another program reads, or a device node
    (``-o /dev/null --force`` as root would replace /dev/null with a table: its temporary file is made in /dev)."""
    try:
        mode = path.lstat().st_mode
    except OSError:
        return  # missing (or unreadable: the probe and the write say why)
    if stat.S_ISREG(mode):
        return
    kind = ("a symbolic link" if stat.S_ISLNK(mode) else "a FIFO" if stat.S_ISFIFO(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a special file")
    raise OutputError(f"output is {kind}, not a regular file (refused even with --force)", file=path,
                      expected="a new file name or an existing regular file")


def _folder_anchor(folder: Path) -> Path:
    """The nearest existing folder of an output folder; an output folder (or a parent) that is a file is an
    :class:`OutputError`."""
    if folder.exists() and not folder.is_dir():
        raise OutputError("output folder is a file", file=folder, expected="a folder (or a new name)")
    anchor = _nearest_existing(folder)
    if not anchor.is_dir():
        raise OutputError("a parent of the output folder is a file, not a folder", file=folder, got=str(anchor))
    return anchor


def _staging_inside(entry: Path) -> bool:
    """A staging folder of an output set staged inside its target (a mount point, an unwritable parent)."""
    return entry.name.startswith(".bsdfkit.") and entry.name.endswith(".staging")


def _other_entries(folder: Path) -> list[Path]:
    """What ``folder`` holds besides staging folders of output sets (empty for a missing folder)."""
    try:
        return sorted(e for e in folder.iterdir() if not _staging_inside(e))
    except (FileNotFoundError, NotADirectoryError):
        return []


def check_output_folder(folder: PathLike, force: bool, inputs: Iterable[PathLike | None] = ()) -> Path:
    """Check a folder that is one command's output as a whole, before computing; return it as a Path.

    Raises :class:`OutputError` if it is a file, a parent is a file, it cannot be created or written, or (with
    ``force``) it is or holds one of ``inputs`` or the current folder; :class:`OutputExistsError` if it exists,
    is not empty and ``force`` is not given.

    Parameters
    ----------
    folder : str or Path
        Output folder.
    force : bool
        Replace an existing, non-empty folder as a whole.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Returns
    -------
    Path
        ``folder``.
    """
    folder = Path(folder)
    if folder.is_symlink():  # --force would replace the folder it points to, not the link (issue #44)
        raise OutputError("output folder is a symbolic link, not a folder (refused even with --force)", file=folder,
                          expected="a real folder or a new name", got=f"a link to {os.readlink(folder)}")
    anchor = _folder_anchor(folder)
    others = _other_entries(folder)
    if others and not force:
        raise OutputExistsError("output folder exists and is not empty; pass --force (force=True) to replace it "
                                "as a whole", file=folder, got=f"{len(others)} entries, e.g. {others[0].name}")
    if others:
        resolved = folder.resolve()
        with contextlib.suppress(OSError):
            if Path.cwd().resolve().is_relative_to(resolved):
                raise OutputError("the output folder holds the current folder (refused even with --force)",
                                  file=folder, expected="an output folder apart from the current folder")
        for inp in inputs:
            if inp is not None and Path(inp).resolve().is_relative_to(resolved):
                raise OutputError("the output folder is or holds an input of this command (refused even with "
                                  "--force)", file=folder, expected="an output folder apart from every input",
                                  got=str(inp))
    _probe(anchor, folder.name, folder)
    return folder


#: a file system with less free space than this [bytes] is taken to be full when a writer fails without errno
FULL_DEVICE_BYTES = 1 << 20


def _device_full(folder: Path) -> bool:
    try:
        return shutil.disk_usage(folder).free < FULL_DEVICE_BYTES
    except OSError:
        return False


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _place(tmp: Path, path: Path, force: bool) -> None:
    """Move the finished ``tmp`` to ``path``: exclusive without ``force`` (no clobbering, even concurrently)."""
    if force:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)
    except FileExistsError:
        raise OutputExistsError("output appeared while writing (another process?); pass --force to overwrite",
                                file=path) from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.EXDEV):
            raise
        # no hard links on this file system: reserve the name exclusively, then replace the placeholder
        try:
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        except FileExistsError:
            raise OutputExistsError("output appeared while writing (another process?); pass --force to "
                                    "overwrite", file=path) from None
        os.replace(tmp, path)
        return
    os.unlink(tmp)


@contextlib.contextmanager
def atomic_path(path: PathLike, force: bool = False, inputs: Iterable[PathLike | None] = ()) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is moved to ``path``.

    Use for writers that insist on a file name (netCDF engines, matplotlib)::

        with atomic_path("out.nc", force) as tmp:
            ds.to_netcdf(tmp)

    Parameters
    ----------
    path : str or Path
        Output file.
    force : bool, optional
        Replace an existing output.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Yields
    ------
    Path
        Temporary file beside ``path`` to write to.
    """
    path = check_writable(path, force, inputs)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_temps(path)
        tmp = path.parent / _temp_name()
        # 0o666 & ~umask: the permissions an ordinary open() would give the final file
        _PARTIAL.add(tmp)
        os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        _place(tmp, path, force)
        _fsync_dir(path.parent)
    except OSError as exc:
        raise _fault(exc, path, writable=tmp is not None and tmp.exists()) from None
    except RuntimeError as exc:
        # netCDF4/HDF5 report a write that failed for want of space as "NetCDF: HDF error", without an errno
        if tmp is not None and _device_full(tmp.parent):
            raise _no_space(path) from None
        if "netcdf" in str(exc).lower() or "hdf" in str(exc).lower():
            raise OutputError(f"cannot write output: the netCDF library failed ({exc})", file=path) from None
        raise
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
            _PARTIAL.discard(tmp)


def write_bytes(path: PathLike, data: bytes, force: bool = False, inputs: Iterable[PathLike | None] = ()) -> Path:
    """Atomically write ``data`` to ``path``.

    Parameters
    ----------
    path : str or Path
        Output file.
    data : bytes
        File content.
    force : bool, optional
        Replace an existing output.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Returns
    -------
    Path
        ``path``.
    """
    with atomic_path(path, force, inputs) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
    return Path(path)


def write_text(path: PathLike, text: str, force: bool = False, newline: str | None = "\n",
               inputs: Iterable[PathLike | None] = ()) -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``. ``newline="\\r\\n"`` gives CRLF line ends.

    Parameters
    ----------
    path : str or Path
        Output file.
    text : str
        File content, lines ended by ``"\\n"``.
    force : bool, optional
        Replace an existing output.
    newline : str or None, optional
        Line end written for each ``"\\n"``; None keeps ``"\\n"``.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Returns
    -------
    Path
        ``path``.
    """
    data = text if newline in (None, "\n") else text.replace("\n", newline)
    return write_bytes(path, data.encode("utf-8"), force, inputs)


def write_with(path: PathLike, writer: Callable[[Path], object], force: bool = False,
               inputs: Iterable[PathLike | None] = ()) -> Path:
    """Atomically create ``path`` by calling ``writer(tmp_path)``.

    Parameters
    ----------
    path : str or Path
        Output file.
    writer : callable
        ``writer(tmp_path)`` writes the whole file at the temporary path it is given.
    force : bool, optional
        Replace an existing output.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).

    Returns
    -------
    Path
        ``path``.
    """
    with atomic_path(path, force, inputs) as tmp:
        writer(tmp)
    return Path(path)


# --------------------------------------------------------------------------------------------------
# one file checked before it is committed
# --------------------------------------------------------------------------------------------------
def failed_check_path(path: PathLike) -> Path:
    """Where a table that failed its check is kept when asked: ``<stem>.failed-check<suffix>`` beside ``path``
    (``out.txt`` -> ``out.failed-check.txt``): the name says it failed, and the suffix still says the format.

    Parameters
    ----------
    path : str or Path
        The output the table was meant for.

    Returns
    -------
    Path
        The name of the failed table.

    Raises
    ------
    OutputError
        If that name is longer than :data:`NAME_MAX` bytes (said before computing, not when the table failed).
    """
    path = Path(path)
    failed = path.with_name(f"{path.stem}{FAILED_CHECK_TAG}{path.suffix}")
    if len(os.fsencode(failed.name)) > NAME_MAX:
        raise OutputError("output name too long to keep a failed table beside it", file=path,
                          expected=f"a name of at most {NAME_MAX - len(FAILED_CHECK_TAG)} bytes with --keep-failed",
                          got=f"{len(os.fsencode(path.name))} bytes")
    return failed


class StagedFile:
    """One output file written and checked under a hidden name in its folder, then committed or discarded.

    For a writer that must re-read and check what it wrote before the file may take its name (``bsdfkit
    convert``, ``bsdfkit export``): a table that fails its check never stands at the requested path, and an
    earlier output there (``force``) stays until a checked one replaces it::

        with StagedFile("out.txt", force, inputs=[source]) as staged:
            write(staged.path)           # any number of times (with force=True): the name is this process's
            if check(staged.path):
                staged.commit()          # exclusive without force (no clobbering), os.replace with it
        # not committed: the staged file is removed, the target is untouched

    The target is checked on construction, before any computing (:func:`check_writable`). The staged file,
    ``.bsdfkit-staged-<pid>.<8 hex><suffix>`` (the output's suffix: a reader that sniffs by extension reads it
    as it will read the output), is an unfinished output until it is placed: removed when the block is left
    without a commit (an exception), by a signal handler (:func:`remove_partial_outputs`), and, after a kill,
    by the next write into the same folder. A signal arriving while it is placed ends the process once it is
    in place (:func:`defer_until_committed`).

    Parameters
    ----------
    path : str or Path
        Output file.
    force : bool, optional
        Replace an existing output (a regular file that is not an input) when committing.
    inputs : iterable of (str or Path or None), optional
        Input files or folders the output must not replace (None entries are skipped).
    """

    def __init__(self, path: PathLike, force: bool = False, inputs: Iterable[PathLike | None] = ()) -> None:
        self.target = check_writable(path, force, inputs)
        self.force = force
        # no folder is made here: a command refused after this check (a missing input) must leave no trace; the
        # writer makes it (atomic_path), as for any output
        _remove_stale_temps(self.target)
        name = f"{STAGED_PREFIX}{os.getpid()}.{_token()}"
        if len(os.fsencode(name + self.target.suffix)) <= NAME_MAX:
            name += self.target.suffix
        self._staged: Path | None = self.target.parent / name
        self.placed: Path | None = None  # where the file went: the target, or the name it was kept under
        _PARTIAL.add(self._staged)

    @property
    def path(self) -> Path:
        """Where to write the file (hidden, in the output's folder; write it with ``force=True``)."""
        if self._staged is None:
            raise RuntimeError("staged output already committed or discarded")
        return self._staged

    def commit(self) -> Path:
        """Move the checked file to the target.

        Returns
        -------
        Path
            The target.
        """
        return self.keep_as(self.target)

    def keep_as(self, path: PathLike) -> Path:
        """Move the file to ``path`` instead (a table kept under a name that says it failed its check).

        Parameters
        ----------
        path : str or Path
            Where to keep it; check it with :func:`check_writable` before computing. Replaced only with
            ``force``.

        Returns
        -------
        Path
            ``path``.
        """
        staged, dst = self.path, Path(path)
        with _commit_zone():
            try:
                with open(staged, "rb+") as fh:
                    os.fsync(fh.fileno())
                _place(staged, dst, self.force)
            except OSError as exc:
                raise _fault(exc, dst) from None
            # placed: no longer an unfinished output that a signal handler would remove
            _PARTIAL.discard(staged)
            self._staged, self.placed = None, dst
            _fsync_dir(dst.parent)
        return dst

    def discard(self) -> None:
        """Remove the staged file; the target is left untouched."""
        if self._staged is not None:
            with contextlib.suppress(OSError):
                self._staged.unlink()
            _PARTIAL.discard(self._staged)
            self._staged = None

    def __enter__(self) -> StagedFile:
        return self

    def __exit__(self, kind, exc, tb) -> None:
        staged = self._staged
        self.discard()
        if isinstance(exc, BsdfkitError) and staged is not None and str(staged) in str(exc):
            # an error naming the hidden staged file names the requested output instead
            raise type(exc)(str(exc).replace(str(staged), str(self.target))) from None


# --------------------------------------------------------------------------------------------------
# output sets
# --------------------------------------------------------------------------------------------------
def _rmtree(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)


class OutputSet:
    """Several outputs under one folder, written into a staging folder and moved into place together.

    ``names`` are paths relative to ``folder`` (``"exports/bibs.zemax.bsdf"``), in the order in which they are
    moved when the target also holds other files (put a summary last). Everything that can be checked is
    checked on construction, before any computing: the folder is not a file, no output exists (without
    ``force``), no output is an input, and the staging folder beside the target can be created::

        with OutputSet("out", ["a.nc", "summary.json"], force) as out:
            ...compute...
            netcdf.save(ds, out.path("a.nc"), force=True)
            write_text(out.path("summary.json"), text, force=True)
        # committed here; on an exception the staging folder is removed and the target is untouched
    """

    def __init__(self, folder: PathLike, names: Iterable[str], force: bool = False,
                 inputs: Iterable[PathLike | None] = (), min_free_bytes: int = 0, whole_folder: bool = False) -> None:
        self.folder = Path(folder)
        self.names = list(dict.fromkeys(names))
        self.force = force
        self.inputs = [i for i in inputs if i is not None]
        self.whole_folder = whole_folder
        self.staging: Path | None = None
        self._preflight()
        self._open_staging()
        if min_free_bytes:
            self._check_space(min_free_bytes)

    def _check_space(self, needed: int) -> None:
        """Refuse before computing when the file system clearly cannot hold the outputs (an estimate)."""
        try:
            free = shutil.disk_usage(self.staging).free
        except OSError:
            return
        if free < needed:
            self.abort()
            raise OutputError("not enough free space for the outputs", file=self.folder,
                              expected=f"about {needed / 1e6:.3g} MB free", got=f"{free / 1e6:.3g} MB free")

    # -- checks ------------------------------------------------------------------------------------
    def _preflight(self) -> None:
        folder = self.folder
        if self.whole_folder:
            check_output_folder(folder, self.force, self.inputs)
        else:
            _folder_anchor(folder)  # the folder and its parents are folders (or do not exist yet)
        if folder.is_dir():
            _check_mode(folder, folder)  # an existing output folder that says "not writable" is refused
        for name in self.names:
            target = folder / name
            if target.is_dir():
                raise OutputError("output path is a folder", file=target, expected="a file name")
            refuse_inputs(target, self.inputs)
            if (target.exists() or target.is_symlink()) and not self.force:
                raise OutputExistsError("output exists; pass --force (force=True) to overwrite", file=target)

    def _open_staging(self) -> None:
        resolved = self.folder.resolve()
        parent, name = resolved.parent, resolved.name
        try:
            if resolved.is_dir() and (resolved.stat().st_dev != parent.stat().st_dev or _is_mount_point(resolved)
                                      or Path.cwd().resolve().is_relative_to(resolved)):
                # the target is a mount point (staged files beside it could not be renamed into it, EXDEV) or
                # holds the current folder (a rename would leave this process in a deleted folder)
                self._open_staging_inside(resolved, None)
                return
        except OSError:
            pass
        try:
            parent.mkdir(parents=True, exist_ok=True)
            for prefix in (f".{name}.", TEMP_PREFIX):
                for entry in _stale(parent, prefix, ".staging"):
                    _rmtree(entry)
            for entry in _stale(parent, f".{name}.", ".old"):
                # a swap interrupted between its two renames: restore the previous set if the target is gone
                if not resolved.exists():
                    os.rename(entry, resolved)
                else:
                    _rmtree(entry)
            self.staging = parent / _beside_name(name, ".staging")
            _PARTIAL.add(self.staging)
            self.staging.mkdir()
        except OSError as exc:
            self._open_staging_inside(resolved, exc)

    def _open_staging_inside(self, resolved: Path, first: OSError | None) -> None:
        """The target folder exists but its parent cannot be written, or it is on another file system than its
        parent: stage inside the target instead."""
        if self.staging is not None:
            _PARTIAL.discard(self.staging)
            self.staging = None
        if not resolved.is_dir():
            raise OutputError(f"cannot write output: {describe_os_error(first)}", file=self.folder,
                              expected=f"a writable folder ({resolved.parent})") from None
        try:
            for entry in _stale(resolved, ".bsdfkit.", ".staging"):
                _rmtree(entry)
            self.staging = resolved / f".bsdfkit.{os.getpid()}.{_token()}.staging"
            _PARTIAL.add(self.staging)
            self.staging.mkdir()
        except OSError as exc:
            raise OutputError(f"cannot write output: {describe_os_error(exc)}", file=self.folder,
                              expected=f"a writable folder ({resolved})") from None

    # -- use ---------------------------------------------------------------------------------------
    def path(self, name: str) -> Path:
        """Where to write output ``name`` (inside the staging folder; write it with ``force=True``).

        Parameters
        ----------
        name : str
            Output path relative to the set's folder, e.g. ``"exports/bibs.zemax.bsdf"``.

        Returns
        -------
        Path
            Where to write it in the staging folder.
        """
        if self.staging is None:
            raise RuntimeError("output set already committed or aborted")
        if name not in self.names:
            self.names.append(name)
        target = self.staging / name
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _fault(exc, self.folder / name) from None
        return target

    def abort(self) -> None:
        """Remove the staging folder and what it holds; the target folder is left untouched."""
        if self.staging is not None:
            _rmtree(self.staging)
            _PARTIAL.discard(self.staging)
            self.staging = None

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, kind, exc, tb) -> None:
        stage = self.staging
        if kind is not None:
            self.abort()
            self._rename_in_message(exc, stage)
            return
        try:
            self.commit()
        except BaseException as fault:
            self.abort()
            self._rename_in_message(fault, stage)
            raise

    def _rename_in_message(self, exc: BaseException | None, stage: Path | None) -> None:
        """An error naming a file in the staging folder names the final output instead."""
        if isinstance(exc, BsdfkitError) and stage is not None and str(stage) in str(exc):
            raise type(exc)(str(exc).replace(str(stage), str(self.folder))) from None

    # -- commit ------------------------------------------------------------------------------------
    def _only_ours(self, target: Path) -> bool:
        files = set(self.names)
        dirs = {str(Path(n).parent) for n in self.names} - {"."}
        for root, subdirs, filenames in os.walk(target):
            rel_root = Path(root).relative_to(target)
            for d in subdirs:
                if str(rel_root / d) not in dirs:
                    return False
            for f in filenames:
                if str(rel_root / f) not in files:
                    return False
        return True

    def commit(self) -> None:
        """Move the staged outputs into place (see the module docstring)."""
        if self.staging is None:
            raise RuntimeError("output set already committed or aborted")
        stage, target = self.staging, self.folder.resolve()
        with _commit_zone():
            _PARTIAL.discard(stage)
            try:
                self._commit(stage, target)
            except BaseException:
                if self.staging is not None:
                    _PARTIAL.add(stage)
                raise

    def _swap_in(self, stage: Path, target: Path, old: Path) -> None:
        """Second rename of a swap: the staged set into the place of the previous one (moved to ``old``)."""
        try:
            os.rename(stage, target)
        except OSError:
            os.rename(old, target)
            raise
        self.staging = None
        _rmtree(old)
        _fsync_dir(target.parent)

    def _commit(self, stage: Path, target: Path) -> None:
        missing = [n for n in self.names if not (stage / n).is_file()]
        if missing:
            raise RuntimeError(f"output {missing[0]} was announced but not written")
        try:
            inside = stage.parent == target
            if not inside and (not target.exists() or (target.is_dir() and not any(target.iterdir()))):
                try:
                    if target.is_dir():  # an empty folder that is replaced keeps its owner and mode
                        _adopt_owner_and_mode(stage, target)
                    os.rename(stage, target)  # replaces a missing or empty folder in one step
                    self.staging = None
                    _fsync_dir(target.parent)
                    return
                except OSError as exc:
                    if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.EBUSY, errno.EXDEV):
                        raise
                    # someone wrote into the target meanwhile (check and merge below), or the target is a
                    # mount point that cannot be replaced (EBUSY, EXDEV): its files are placed one by one below
                    inside = inside or exc.errno in (errno.EBUSY, errno.EXDEV)
            clash = ([e.name for e in _other_entries(target) if e != stage] if self.whole_folder
                     else [n for n in self.names if (target / n).exists()])
            if clash and not self.force:
                raise OutputExistsError("output appeared while computing (another process?); pass --force to "
                                        "overwrite", file=self.folder / clash[0])
            if self.force and not inside and (self.whole_folder or self._only_ours(target)):
                old = target.parent / _beside_name(target.name, ".old")
                _adopt_owner_and_mode(stage, target)
                try:
                    os.rename(target, old)
                except OSError as exc:
                    if exc.errno not in (errno.EBUSY, errno.EXDEV):
                        raise
                    inside = True  # a mount point: placed file by file below
                else:
                    self._swap_in(stage, target, old)
                    return
            if self.whole_folder:  # staged inside the target: the previous content goes first
                for entry in _other_entries(target):
                    if entry.is_dir() and not entry.is_symlink():
                        _rmtree(entry)
                    else:
                        entry.unlink()
            for name in self.names:  # the target holds other files: move ours in one by one
                dst = target / name
                dst.parent.mkdir(parents=True, exist_ok=True)
                _move_file(stage / name, dst, self.force)
            _rmtree(stage)
            self.staging = None
        except OSError as exc:
            raise _fault(exc, self.folder) from None
