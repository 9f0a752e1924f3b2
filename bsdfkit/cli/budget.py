"""``bsdfkit budget (SCAN --incidence 45 | --table T.json) --eta-mc 0.94 --iterations 7 [--json]``."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bsdfkit.cli._common import emit_json
from bsdfkit.cli.tis import load_scan
from bsdfkit.core.errors import FormatError, InputError
from bsdfkit.io.text import existing_source, read_text


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``budget`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("budget", help="iterative module power budget (Figs. 9-10, Table 3 of the power-budget paper)")
    p.add_argument("scan", nargs="?", help="calibrated scan or raw measurement folder (with --incidence)")
    p.add_argument("--incidence", type=float, help="incidence angle of the scan's interaction table, deg")
    p.add_argument("--table", help='JSON {"power": {"B_bibs": 10.9, ...}} in percent (instead of a scan)')
    p.add_argument("--eta-mc", type=float, required=True, help="mixing-chamber efficiency η_MC")
    p.add_argument("--iterations", type=int, default=7, help="plate interactions (the first is the LEDs' direct pass)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    if args.scan is not None:
        existing_source(args.scan)  # a mistyped path is answered before the engine is imported
    # the engine here, not at the top: `bsdfkit --help` registers every verb and must stay light
    from bsdfkit.reduction.any_sample import budget
    from bsdfkit.reduction.budget import MAX_ITERATIONS, module_budget, table_from_json

    if not (math.isfinite(args.eta_mc) and 0.0 <= args.eta_mc <= 1.0):
        raise InputError("option out of range", field="--eta-mc", expected="a mixing-chamber efficiency in [0, 1]",
                         got=args.eta_mc)
    if not 1 <= args.iterations <= MAX_ITERATIONS:
        raise InputError("option out of range", field="--iterations", expected=f"an integer in [1, {MAX_ITERATIONS}]",
                         got=args.iterations)
    if args.incidence is not None and not (math.isfinite(args.incidence) and 0.0 <= args.incidence < 90.0):
        raise InputError("option out of range", field="--incidence", expected="an angle in [0, 90) deg",
                         got=args.incidence)
    if (args.scan is None) == (args.table is None):
        raise InputError("give either a scan (with --incidence) or --table", field="scan/--table")
    if args.table is not None:
        path = Path(args.table)
        if not path.is_file():
            raise InputError("a folder, not a table file" if path.is_dir() else "file not found", file=path,
                             expected="a JSON interaction table")
        text = read_text(path, expected="a JSON interaction table")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise FormatError(f"not valid JSON ({exc.msg})", file=path, line=exc.lineno) from None
        except RecursionError:
            raise InputError("cannot read the table (RecursionError)", file=path) from None
        tables = table_from_json(data, str(path))
    else:
        if args.incidence is None:
            raise InputError("a scan needs --incidence", field="--incidence")
        # bsdfkit.budget: elastic data refused with one line
        t = budget(load_scan(args.scan, verb="budget"), args.incidence)
        tables = {"power": t.power, "photons": t.photons}
    result = module_budget(tables["power"], args.eta_mc, args.iterations).as_dict()
    if "photons" in tables:
        result["photons"] = module_budget(tables["photons"], args.eta_mc, args.iterations).as_dict()
    if args.json:
        emit_json(result)
        return 0
    print(f"η_MC = {args.eta_mc:g}; cumulative extracted (% of LED power) per plate interaction")
    print("  k   blue  yellow   total  losses  in flight")
    for k, row in enumerate(result["iterations"], start=1):
        print(f"  {k:<2d} {row['blue']:6.2f} {row['yellow']:7.2f} {row['total']:7.2f} {row['losses']:7.2f} "
              f"{row['backscattered']:9.2f}")
    c = result["converged"]
    print(f"  ∞  {c['blue']:6.2f} {c['yellow']:7.2f} {c['total']:7.2f} {c['losses']:7.2f}")
    f = result["first_iteration"]
    print(f"  first interaction: forward {f['forward']:.1f}, lost {f['lost']:.1f}, "
          f"backscattered {f['backscattered']:.1f}")
    return 0
