"""``bsdfkit read FILE [--json]``: sniff a table of any registered format (:mod:`bsdfkit.tables.registry`) by its
content and report its TIS.

JSON keys: ``format``, ``incidences_deg``, ``tis_computed`` and ``tis_stated`` (each a mapping from side
— or ``total`` for TracePro's energy balance — to one value per incidence), plus ``path`` and ``details``.
A stated TIS that disagrees with the computed one beyond the tolerance of
:func:`bsdfkit.tables.vendor.check_stated_tis` gets one warning line on stderr.
"""
from __future__ import annotations

import argparse
import sys
import warnings

from bsdfkit import api
from bsdfkit.cli._common import emit_json
from bsdfkit.core.errors import StatedTisWarning
from bsdfkit.tables import registry


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``read`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    formats = ", ".join(registry.names())
    p = sub.add_parser("read", help=f"summarise a BSDF table ({formats})",
                       description=f"Sniff a BSDF table ({formats}) by its content and report its incidences and "
                                   "TIS, recomputed and as stated (docs/exports.md).")
    p.add_argument("file", metavar="FILE", help="table file")
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``bsdfkit read``: the table's format, and its TIS per incidence, recomputed and as stated.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of the verb.

    Returns
    -------
    int
        Exit status: 0 on success, also when the file's stated TIS disagrees with its data (one warning line on
        stderr, :func:`bsdfkit.tables.vendor.check_stated_tis`).
    """
    from bsdfkit.tables.vendor import check_stated_tis  # the engine: imported by api.read anyway

    # the CLI silences library warnings; a file whose stated TIS disagrees with its data is said in one line
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StatedTisWarning)
        summary = api.read(args.file)
        check_stated_tis(summary)
    for w in caught:
        if issubclass(w.category, StatedTisWarning):
            print(f"bsdfkit read: warning: {w.message}", file=sys.stderr)
    if args.json:
        emit_json(summary.to_dict())
        return 0
    print(f"{summary.path}: {summary.format}")
    keys = list(summary.tis_computed) + [k for k in summary.tis_stated if k not in summary.tis_computed]
    header = f"{'theta_i':>8}"
    for k in keys:
        header += f"  {'TIS ' + k + ' computed':>26}"
        if k in summary.tis_stated:
            header += f"  {'stated':>10}  {'diff %':>8}"
    print(header)
    for n, t in enumerate(summary.incidences_deg):
        row = f"{t:>8g}"
        for k in keys:
            c = summary.tis_computed.get(k)
            s = summary.tis_stated.get(k)
            row += f"  {(f'{c[n]:.6g}' if c else '-'):>26}"
            if s and s[n] == s[n]:  # a format may state the TIS at some incidences only (NaN elsewhere)
                diff = f"{100.0 * (c[n] / s[n] - 1.0):+.2f}" if c and s[n] else "-"
                row += f"  {s[n]:>10.6g}  {diff:>8}"
            elif s:
                row += f"  {'-':>10}  {'-':>8}"
        print(row)
    for note in summary.details.get("notes", ()):  # what the numbers mean (an anisotropic file's azimuth)
        print(f"note: {note}")
    return 0
