"""``bsdfkit <verb>``: a thin command line over the library.

Each verb lives in its own module under :mod:`bsdfkit.cli` and exposes ``register(subparsers)``;
verbs are discovered here, so adding one touches no shared file. Every verb is a call into the library
that a notebook user can make too.

User errors (:class:`bsdfkit.core.errors.BsdfkitError`) are printed as one line on stderr with exit status 2;
no traceback is shown for them. Ctrl-C (SIGINT) and SIGTERM end the process within a second, even inside a
long compiled call, with this process's unfinished outputs removed and status 128 + signal (130, 143);
:func:`main` called from Python exits the same way.

Compiled kernels persist between runs: the entry point switches on JAX's persistent compilation cache in a
per-user folder (:func:`compile_cache_dir`, ``$XDG_CACHE_HOME/bsdfkit/jax`` or ``~/.cache/bsdfkit/jax``)
unless ``--no-compile-cache`` is given or ``BSDFKIT_NO_COMPILE_CACHE=1`` is set. Nothing is configured on
``import bsdfkit``; JAX is not imported here (its settings go through its environment variables when it has
not been imported yet; dask workers started by a verb inherit them), and the environment is restored after
each call of :func:`main`. Likewise the CPU cores become JAX CPU devices (:func:`cpu_devices`), on which the
tracer runs chunks of rays in parallel.
"""
from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import os
import signal
import sys
import threading
import warnings
import zlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NoReturn

from bsdfkit.core.collector import fewer_collections
from bsdfkit.core.errors import BsdfkitError
from bsdfkit.core.jaxconfig import DEVICES_FLAG
from bsdfkit.core.version import __version__
from bsdfkit.io.atomic import defer_until_committed, describe_os_error, remove_partial_outputs
from bsdfkit.io.xarray_dask import deferred_dask

VERBS = ("bench", "budget", "color", "convert", "export", "fit", "info", "ingest", "read", "run", "simulate", "sweep",
         "tis", "trace")


NO_CACHE_ENV = "BSDFKIT_NO_COMPILE_CACHE"
NO_CACHE_FLAG = "--no-compile-cache"
#: JAX settings of the persistent compilation cache (besides its folder). A maximum size switches on JAX's file
#: lock around every read and write of the cache (package ``filelock``), so concurrent processes (parallel
#: runs, dask workers) never read an entry another process is still writing.
CACHE_SETTINGS = {
    "jax_persistent_cache_min_compile_time_secs": 0.1,
    "jax_persistent_cache_min_entry_size_bytes": 0,
    "jax_compilation_cache_max_size": 4 * 1024 ** 3,
}


def compile_cache_dir() -> Path:
    """The per-user folder of compiled kernels: ``$XDG_CACHE_HOME/bsdfkit/jax`` or ``~/.cache/bsdfkit/jax``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "bsdfkit" / "jax"


def compile_cache_wanted(flag_off: bool = False) -> bool:
    """False with ``--no-compile-cache`` or ``BSDFKIT_NO_COMPILE_CACHE`` set to anything but "" or "0".

    Parameters
    ----------
    flag_off : bool, optional
        Whether ``--no-compile-cache`` was given.

    Returns
    -------
    bool
    """
    return not flag_off and os.environ.get(NO_CACHE_ENV, "").strip() in ("", "0")


@contextlib.contextmanager
def _environment(values: dict[str, str]) -> Iterator[None]:
    """The environment variables ``values`` set for the duration of the block; each is restored on exit (or
    removed, where it was not set)."""
    saved = {key: os.environ.get(key) for key in values}
    try:
        os.environ.update(values)
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextlib.contextmanager
def compile_cache(enabled: bool) -> Iterator[Path | None]:
    """JAX's persistent compilation cache in :func:`compile_cache_dir` for the duration of the block.

    The settings go into JAX's environment variables, which JAX reads when it is imported (the verbs import it
    after this point; dask workers started by a verb inherit them). If JAX was already imported by the calling
    process (``main`` called from Python), its configuration is left alone and None is returned. The
    environment is restored on exit; an explicit ``JAX_COMPILATION_CACHE_DIR`` of the user is respected.

    Parameters
    ----------
    enabled : bool
        Use the cache (:func:`compile_cache_wanted`); False leaves JAX's settings alone.

    Yields
    ------
    Path or None
        The cache folder, or None when nothing was set.
    """
    if not enabled or "jax" in sys.modules:
        yield None
        return
    settings = {"jax_compilation_cache_dir": os.environ.get("JAX_COMPILATION_CACHE_DIR") or str(compile_cache_dir()),
                **CACHE_SETTINGS}
    with _environment({k.upper(): str(v) for k, v in settings.items()}):
        yield Path(settings["jax_compilation_cache_dir"])


#: at most this many CPU devices (one chunk of rays runs on each at the same time)
MAX_CPU_DEVICES = 8


@contextlib.contextmanager
def cpu_devices() -> Iterator[int | None]:
    """One JAX CPU device per usable core (at most :data:`MAX_CPU_DEVICES`) for the duration of the block.

    XLA runs one program on one CPU device essentially on one core; the tracer runs its chunks on all local
    devices at once (:func:`bsdfkit.raytrace.tracer.compiled_kernel`), so on a CPU the command line exposes the
    cores as devices through ``XLA_FLAGS`` (read when JAX is imported; code that does not ask for a device
    uses the first one, as before). Nothing happens when JAX is already imported or ``XLA_FLAGS`` already sets
    the device count; ``XLA_FLAGS`` is restored on exit.
    """
    flags = os.environ.get("XLA_FLAGS")
    if "jax" in sys.modules or DEVICES_FLAG in (flags or ""):
        yield None
        return
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    count = max(1, min(cores, MAX_CPU_DEVICES))
    with _environment({"XLA_FLAGS": f"{flags or ''} {DEVICES_FLAG}={count}".strip()}):
        yield count


#: the thread-pool sizes of the BLAS libraries numpy and scipy may load (OpenBLAS, MKL); OpenBLAS also reads
#: OMP_NUM_THREADS, so a user's setting of any of the three is kept
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
USER_THREAD_VARS = (*BLAS_THREAD_VARS, "OMP_NUM_THREADS")


@contextlib.contextmanager
def single_thread_blas() -> Iterator[bool]:
    """One BLAS thread for the duration of the block, unless the user set a pool size or numpy is imported.

    The command's linear algebra is many small calls (Gauss–Legendre nodes by ``eigvalsh``, 2 x 2 solves): a
    BLAS thread pool hands each of them to another thread, which on a shared 2-core machine made
    ``numpy.polynomial.legendre.leggauss(400)`` take 0.5-1.2 s instead of 0.04 s and ``bsdfkit tis`` of the
    ansys scan 1.4x slower (paired runs). The command's own parallelism is its JAX devices
    (:func:`cpu_devices`) and dask workers, which inherit the setting. The pool is sized when numpy is first
    imported, so nothing happens when it already is; the environment is restored on exit.
    """
    if "numpy" in sys.modules or any(v in os.environ for v in USER_THREAD_VARS):
        yield False
        return
    try:
        os.environ.update(dict.fromkeys(BLAS_THREAD_VARS, "1"))
        yield True
    finally:
        for v in BLAS_THREAD_VARS:
            os.environ.pop(v, None)


@contextlib.contextmanager
def child_warnings_off() -> Iterator[None]:
    """``PYTHONWARNINGS=ignore`` for the processes started in the block (Python reads it when it starts); the
    environment is restored on exit.

    Yields
    ------
    None
    """
    with _environment({"PYTHONWARNINGS": "ignore"}):
        yield


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors on one line (exit status 2), like every other bsdfkit error."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def build_parser(verbs: Sequence[str] = VERBS) -> argparse.ArgumentParser:
    """The parser with the given verbs registered (all by default; `main` registers only the one it runs).

    Parameters
    ----------
    verbs : sequence of str, optional
        Verbs to register (modules of :mod:`bsdfkit.cli`).

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = _Parser(
        prog="bsdfkit",
        description="Goniometer scans to calibrated BSDFs, fits, ray-tracer tables and module budgets.",
    )
    parser.add_argument("--version", action="version", version=f"bsdfkit {__version__}")
    parser.add_argument(NO_CACHE_FLAG, action="store_true",
                        help=f"do not use the persistent cache of compiled kernels ({compile_cache_dir()}; "
                             f"also {NO_CACHE_ENV}=1)")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for verb in verbs:
        # a verb's module (and the libraries it needs) is imported only when that verb is registered
        module = importlib.import_module(f"bsdfkit.cli.{verb}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``bsdfkit`` command: one line on stderr for any error, never a traceback.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments after the program name; ``sys.argv[1:]`` by default.

    Returns
    -------
    int
        Exit status: 0 on success, 2 for an error, 130 when interrupted.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    no_cache = NO_CACHE_FLAG in argv  # accepted before or after the verb
    argv = [a for a in argv if a != NO_CACHE_FLAG]
    # before the verb's modules (and so JAX) are imported: JAX reads its cache settings when imported
    # Ctrl-C and SIGTERM end the process at once, unfinished outputs removed (exit_now), from the first moment:
    # a KeyboardInterrupt can be swallowed by a library callback (JAX's gc hook) and the run would go on
    previous = {signum: _on_signal(signum, _terminated) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        # xarray wraps arrays without importing dask (0.5-0.7 s; bsdfkit.io.xarray_dask), in this command only
        with compile_cache(compile_cache_wanted(no_cache)), cpu_devices(), single_thread_blas(), deferred_dask(), \
                fewer_collections():
            return _run(argv)
    except KeyboardInterrupt:  # a Ctrl-C that came before the handler above
        print("bsdfkit: interrupted", file=sys.stderr)
        return 130
    finally:
        for signum, handler in previous.items():
            _on_signal(signum, handler)


def _run(argv: list[str]) -> int:
    parser = build_parser((argv[0],) if argv and argv[0] in VERBS else VERBS)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.error(f"no verb given; expected one of {', '.join(VERBS)}")
    try:
        # library warnings (numpy's RuntimeWarning with its source line, xarray, dask) never reach stderr: what
        # a user must know is said by bsdfkit in its own one-line warnings, which do not use the warnings module;
        # nor from the processes the command starts (dask workers, the run's helper; JAX's compilation cache
        # warned there of a concurrent write with an empty cache)
        with prompt_signals(), warnings.catch_warnings(), child_warnings_off():
            warnings.simplefilter("ignore")
            from bsdfkit.cli._common import refuse_replacing_inputs  # a verb's module imported it already
            refuse_replacing_inputs(args)  # --force never replaces an input, for every verb
            return int(args.func(args) or 0)
    except BsdfkitError as exc:
        print(f"bsdfkit {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except (OSError, EOFError, zlib.error, UnicodeDecodeError, MemoryError) as exc:
        # safety net: a fault the verb did not turn into a BsdfkitError is still one line, never a traceback
        print(f"bsdfkit {args.verb}: error: {_fault_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"bsdfkit {args.verb}: interrupted", file=sys.stderr)
        return 130


def exit_process(code: int) -> NoReturn:
    """End the command-line process with status ``code`` once :func:`main` has returned, without the
    interpreter's shutdown.

    Everything the command writes is complete by then (outputs are renamed into place, the dask cluster of a
    sweep is closed). What shutdown would still do is tear down the modules and JAX's runtime, which took
    0.3-0.6 s of a 1.7-2.3 s ``bsdfkit trace`` (measured: 0.34-0.64 s from main's return to the process's
    end, 0.04 s with this). The ``atexit`` handlers still run (logging, multiprocessing), and stdout and
    stderr are flushed; a stdout that cannot be flushed (a closed pipe) turns status 0 into 1, as Python's
    own shutdown does. Only for the console command and ``python -m bsdfkit``, never on import.

    Parameters
    ----------
    code : int
        Exit status.
    """
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            code = code or 1
    os._exit(code)


def _terminated(signum, frame) -> None:
    # exit at once, whatever is running (an exception raised here could be swallowed by a library callback),
    # except in the middle of moving an output set into place: then as soon as it is in place
    if not defer_until_committed(lambda: exit_now(signum)):
        exit_now(signum)


def exit_now(signum: int) -> None:
    """Remove this process's unfinished outputs and end it with status 128 + ``signum``, skipping shutdown.

    Interpreter shutdown would wait for (or crash on) a compiled call still running in XLA's threads.

    Parameters
    ----------
    signum : int
        Number of the signal that ends the process.
    """
    removed = remove_partial_outputs()
    # worker processes this process started (a sweep's dask LocalCluster) must not outlive it; os._exit below
    # skips the cluster's own shutdown. Their nannies stop their workers on SIGTERM.
    mp = sys.modules.get("multiprocessing")
    if mp is not None:
        for child in mp.active_children():
            with contextlib.suppress(OSError, ValueError, AttributeError):
                child.terminate()
        # release this process's semaphores and queues (the cluster's) as a normal exit does first
        # (multiprocessing.util._exit_function), else the resource tracker warns of "leaked semaphore objects"
        # on stderr; priority >= 0 leaves out the joins of feeder threads, which could wait
        with contextlib.suppress(Exception):
            sys.modules["multiprocessing.util"]._run_finalizers(0)
    with contextlib.suppress(OSError, ValueError):
        sys.stdout.flush()
    name = "interrupted" if signum == signal.SIGINT else "terminated"
    with contextlib.suppress(OSError):
        # an interrupt that came after the commit finds nothing unfinished, and says so
        what = "unfinished outputs removed" if removed else "no unfinished output (what was written is complete)"
        os.write(2, f"bsdfkit: {name}; {what}\n".encode())
    os._exit(128 + signum)


#: after Ctrl-C or SIGTERM, the main thread gets this long [s] to stop by itself before the process is ended
SIGNAL_GRACE_S = 1.0


@contextlib.contextmanager
def prompt_signals(grace_s: float = SIGNAL_GRACE_S) -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM end the process within ``grace_s`` even while a compiled kernel runs.

    Python runs its signal handlers in the main thread between bytecodes, so a long call into XLA (one chunk
    of the tracer, a compilation) would delay them until it returns. The C-level handler still writes the
    signal number to :func:`signal.set_wakeup_fd` at once; a watcher thread reads it and, if the main thread
    has not finished ``grace_s`` later (its own KeyboardInterrupt cleanup runs first), removes this process's
    unfinished outputs and exits with status 128 + signal (:func:`exit_now`). A KeyboardInterrupt leaving the
    block ends the process too, so ``main`` called from Python exits on Ctrl-C like the command does. Outside
    the main thread nothing is installed.

    Parameters
    ----------
    grace_s : float, optional
        Time the main thread gets to stop by itself after a signal [s].
    """
    try:
        read_fd, write_fd = os.pipe()
    except OSError:
        yield
        return
    os.set_blocking(write_fd, False)
    try:
        old_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    except ValueError:  # not the main thread
        os.close(read_fd)
        os.close(write_fd)
        yield
        return
    finished = threading.Event()

    def watch() -> None:
        while True:
            try:
                data = os.read(read_fd, 1)
            except OSError:
                return
            if not data or finished.is_set():
                return
            if data[0] not in (signal.SIGINT, signal.SIGTERM) or finished.wait(grace_s):
                continue
            exit_now(data[0])

    watcher = threading.Thread(target=watch, name="bsdfkit-signals", daemon=True)
    watcher.start()
    try:
        yield
    except KeyboardInterrupt:
        # the verb's own cleanup (its context managers) has run; end the process here (see exit_now)
        exit_now(signal.SIGINT)
    finally:
        finished.set()
        signal.set_wakeup_fd(old_fd)
        os.close(write_fd)  # the watcher reads end-of-file and returns
        watcher.join(timeout=grace_s + 1.0)
        os.close(read_fd)


def _on_signal(signum: int, handler):
    if handler is None or (signum == signal.SIGINT and signal.getsignal(signum) == signal.SIG_IGN):
        return None  # nothing to restore; an ignored Ctrl-C (nohup, background job) stays ignored
    try:
        return signal.signal(signum, handler)
    except (ValueError, TypeError):  # not the main thread, or no previous Python handler to restore
        return None


def _fault_line(exc: BaseException) -> str:
    """One line for an exception that escaped a verb: the path (when known) and the fault."""
    if isinstance(exc, UnicodeDecodeError):
        return (f"an input is not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); "
                "expected a UTF-8 text file")
    if isinstance(exc, zlib.error | EOFError):
        return f"an input is not a readable compressed file ({exc}); expected an intact gzip file"
    if isinstance(exc, MemoryError):
        return "not enough memory for this input or these options; expected smaller sizes"
    where = getattr(exc, "filename", None)
    text = describe_os_error(exc)
    return f"{where}: {text}" if where else text


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
