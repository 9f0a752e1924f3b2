"""``bsdfkit run RECIPE.toml -o OUT/``: the main job."""
from __future__ import annotations

import argparse
import sys

from bsdfkit import api
from bsdfkit.cli._common import emit_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a fit/run recipe (fitting/*.toml) and write its outputs")
    p.add_argument("recipe")
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:

    summary = api.run(args.recipe, args.output, args.force, log=lambda m: print(m, file=sys.stderr))
    if args.json:
        emit_json(summary)
    else:
        print(f"wrote {len(summary['outputs'])} files to {args.output}: {', '.join(summary['outputs'])}")
        for line in summary.get("report_lines", []):
            print(line)
    return 0
