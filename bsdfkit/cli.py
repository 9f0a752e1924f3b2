"""``bsdfkit <verb>``: a thin command line over the library.

Each verb lives in its own module under :mod:`bsdfkit.commands` and exposes ``register(subparsers)``;
verbs are discovered here, so adding one touches no shared file. Every verb is a call into the library
that a notebook user can make too.

User errors (:class:`bsdfkit.errors.BsdfkitError`) are printed as one line on stderr with exit status 2;
no traceback is shown for them.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from bsdfkit import __version__
from bsdfkit.errors import BsdfkitError


def build_parser() -> argparse.ArgumentParser:
    import bsdfkit.commands as commands

    parser = argparse.ArgumentParser(
        prog="bsdfkit",
        description="Goniometer scans to calibrated BSDFs, fits, ray-tracer tables and module budgets.",
    )
    parser.add_argument("--version", action="version", version=f"bsdfkit {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"bsdfkit.commands.{info.name}")
        module.register(sub)
    return parser



def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
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
