"""``bsdfkit bench [--quick] [-o DIR]``: what accuracy costs in time (writes accuracy.md and figures)."""
from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("bench", help="accuracy-vs-time studies; writes DIR/accuracy.md and PNG figures")
    p.add_argument("--quick", action="store_true", help="fewer settings (under 2 minutes)")
    p.add_argument("-o", "--output", default="docs", help="folder for accuracy.md and figures (default: docs)")
    p.add_argument("--only", action="append", help="run only this study (repeatable)")
    p.add_argument("--force", action="store_true", help="replace an existing accuracy.md and figures")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    # here, not at the top: `bsdfkit --help` registers every verb and must not import colour, JAX or matplotlib
    from bsdfkit.bench.run import run_bench

    command = "bsdfkit bench" + (" --quick" if args.quick else "")
    studies = run_bench(args.output, args.quick, args.force, command, args.only,
                        log=lambda m: print(m, file=sys.stderr))
    for study in studies:
        for target in (0.01, 0.001):
            for group in (study.groups or (None,)):
                best = study.cheapest(target, group)
                label = f"{study.name}{'/' + group if group else ''}"
                print(f"{label}: {100 * target:g} % reached by {best.setting if best else 'no setting tried'}")
    print(f"wrote {args.output}/accuracy.md")
    return 0
