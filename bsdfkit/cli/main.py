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
import sys
from collections.abc import Sequence

from bsdfkit.core.errors import BsdfkitError
from bsdfkit.core.version import __version__

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
    try:
        return int(args.func(args) or 0)
    except BsdfkitError as exc:
        print(f"bsdfkit {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"bsdfkit {args.verb}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
