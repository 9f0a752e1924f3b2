"""``bsdfkit <verb>``: a thin command line over the library.

Each verb lives in its own module under :mod:`bsdfkit.cli` and exposes ``register(subparsers)``;
verbs are discovered here, so adding one touches no shared file. Every verb is a call into the library
that a notebook user can make too.

User errors (:class:`bsdfkit.core.errors.BsdfkitError`) are printed as one line on stderr with exit status 2;
no traceback is shown for them.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import zlib
from collections.abc import Sequence

from bsdfkit.core.errors import BsdfkitError
from bsdfkit.core.version import __version__
from bsdfkit.io.atomic import describe_os_error, remove_partial_outputs

VERBS = ("bench", "budget", "color", "convert", "export", "fit", "info", "ingest", "read", "run", "simulate", "sweep",
         "tis", "trace")


def build_parser(verbs: Sequence[str] = VERBS) -> argparse.ArgumentParser:
    """The parser with the given verbs registered (all by default; `main` registers only the one it runs)."""
    parser = argparse.ArgumentParser(
        prog="bsdfkit",
        description="Goniometer scans to calibrated BSDFs, fits, ray-tracer tables and module budgets.",
    )
    parser.add_argument("--version", action="version", version=f"bsdfkit {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for verb in verbs:
        # a verb's module (and the libraries it needs) is imported only when that verb is registered
        module = importlib.import_module(f"bsdfkit.cli.{verb}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser((argv[0],) if argv and argv[0] in VERBS else VERBS)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    previous = _on_sigterm(_terminated)  # a kill (SIGTERM) removes unfinished outputs
    try:
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
    finally:
        _on_sigterm(previous)


def _terminated(signum, frame) -> None:
    # exit at once, whatever is running (an exception raised here could be swallowed by a library callback)
    remove_partial_outputs()
    sys.stderr.write("bsdfkit: terminated; unfinished outputs removed\n")
    sys.stderr.flush()
    os._exit(128 + signum)


def _on_sigterm(handler):
    try:
        return signal.signal(signal.SIGTERM, handler)
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
