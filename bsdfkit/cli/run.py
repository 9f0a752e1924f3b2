"""``bsdfkit run RECIPE.toml -o OUT/``: the main job.

While it runs, the stages and the traces of the trace stage show a progress bar (``rich``) and a line per stage
on stderr when stderr is a terminal; ``--quiet`` turns them off. A log file or a pipe gets no progress (the
stage lines with ``--verbose``), so the stderr of a failed run is its one error line. Nothing of it goes to
stdout, so ``--json`` output stays one JSON document.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator

from bsdfkit import api
from bsdfkit.cli._common import emit_json
from bsdfkit.pipeline.helper import helper_process

#: What the progress bars say for the run's progress tasks.
TASKS = {"stages": "stages of the run", "trace": "module traces (device + studies)"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``run`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("run", help="run a fit/run recipe (fitting/*.toml) and write its outputs")
    p.add_argument("recipe")
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument("--force", action="store_true",
                   help="replace an existing, non-empty output folder as a whole (never one holding an input)")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.add_argument("--quiet", action="store_true", help="no stage lines and no progress bars on stderr")
    p.add_argument("--verbose", action="store_true",
                   help="the stage lines on stderr also when it is not a terminal (a log file, a pipe)")
    p.set_defaults(func=_run)


@contextlib.contextmanager
def run_feedback(quiet: bool, verbose: bool = False) -> Iterator[tuple[Callable[[str], None],
                                                                     Callable[[str, int, int], None] | None]]:
    """``(log, progress)`` callbacks for :func:`bsdfkit.api.run`: stage lines and rich progress bars on stderr.

    Both only when stderr is a terminal; a log file or a pipe gets the stage lines with ``verbose`` and nothing
    otherwise (a failed run's stderr is then its one error line); nothing at all with ``quiet``.

    Parameters
    ----------
    quiet : bool
        No stage lines and no progress bars.
    verbose : bool, optional
        Stage lines also when stderr is not a terminal.

    Yields
    ------
    log : callable
        ``log(message)`` for a stage line.
    progress : callable or None
        ``progress(task, done, total)`` for the progress bars; None without a terminal.
    """
    if quiet or (not sys.stderr.isatty() and not verbose):
        yield (lambda message: None), None
        return
    if not sys.stderr.isatty():
        yield (lambda message: print(message, file=sys.stderr)), None
        return
    # rich only for a terminal, imported here: `bsdfkit --help` registers this verb too
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=Console(stderr=True)) as bars:
        tasks: dict[str, int] = {}

        def progress(task: str, done: int, total: int) -> None:
            if task not in tasks:
                tasks[task] = bars.add_task(TASKS.get(task, task), total=total)
            bars.update(tasks[task], completed=done, total=total)

        # plain text: a stage line may hold brackets ("[Power-budget]") that rich would take for markup
        yield (lambda message: bars.console.print(message, markup=False, highlight=False)), progress


def _run(args: argparse.Namespace) -> int:
    # the command line is the main script, guarded: a spawned helper can compute and draw beside it; started
    # before the pipeline is imported here, it imports the pipeline at the same time on the other core
    with helper_process(True) as helper, run_feedback(args.quiet, args.verbose) as (log, progress):
        summary = api.run(args.recipe, args.output, args.force, log=log, progress=progress, helper_processes=helper)
    if args.json:
        emit_json(summary)
    else:
        print(f"wrote {len(summary['outputs'])} files to {args.output}: {', '.join(summary['outputs'])}")
        for line in summary.get("report_lines", []):
            print(line)
    return 0
