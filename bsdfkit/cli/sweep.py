"""``bsdfkit sweep SCENE.toml --param KEYS=VALUES … -o OUT.nc``: parameter studies of a scene."""
from __future__ import annotations

import argparse
from pathlib import Path

from bsdfkit import api
from bsdfkit.cli._common import Progress, emit_json
from bsdfkit.core.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("sweep", help="trace a scene over a grid of parameters (netCDF + PNG)",
                       description="Sweep scene keys, e.g. --param wall.reflectance,base.reflectance=0.80:0.98:5 "
                                   "or --param cavity.height_mm=10,43,80; without --param the scene's [sweep] "
                                   "table is used (fitting/scenes/study_*.toml).")
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--param", action="append", default=None, metavar="KEYS=VALUES",
                   help="swept keys and values: start:stop:count or a comma list (repeatable)")
    p.add_argument("-o", "--output", required=True, help="output netCDF file (PNG plots are written beside it)")
    p.add_argument("--rays", type=int, default=None, help="rays per point (default: [sweep] rays or 200000)")
    p.add_argument("--seed", type=int, default=None, help="seed (default: [sweep] seed or 0)")
    p.add_argument("--chunk", type=int, default=None, help="rays per compiled call")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="run the points as tasks on a local dask.distributed cluster of N worker processes")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the points on an existing dask.distributed scheduler (e.g. tcp://host:8786)")
    p.add_argument("--verbose", action="store_true",
                   help="show dask's own log on stderr (worker failures with tracebacks); by default a failed "
                        "point is reported once, in the one error line")
    p.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run, extra_outputs=_extra_outputs)


def _extra_outputs(args: argparse.Namespace) -> list:
    """The figures a sweep writes beside its output (checked against the inputs before it runs)."""
    if args.no_plots:
        return []
    from bsdfkit.raytrace.sweep import plot_paths  # dask: only once the verb runs

    return plot_paths(Path(args.output))


def run(args: argparse.Namespace) -> int:
    # here, not at the top: `bsdfkit --help` registers every verb and must not import JAX, matplotlib or dask
    """Run ``bsdfkit sweep`` with the parsed options.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of the verb.

    Returns
    -------
    int
        Exit status: 0 on success.
    """
    from bsdfkit.plotting.figures import sweep_figure
    from bsdfkit.raytrace.sweep import Cluster, run_sweep, sweep_spec

    scene = api.load_scene(args.scene)
    defaults = scene.sweep
    params = args.param or (list(defaults.params) if defaults else [])
    if not params:
        raise InputError("nothing to sweep", file=args.scene, field="sweep.params",
                         expected="--param KEYS=VALUES or a [sweep] params list in the scene")
    rays = args.rays if args.rays is not None else (defaults.rays if defaults and defaults.rays else 200_000)
    if rays < 1:
        raise InputError("rays per point out of range", field="--rays", expected=">= 1", got=rays)
    seed = args.seed if args.seed is not None else (defaults.seed if defaults and defaults.seed is not None else 0)
    if args.workers is not None and args.scheduler:
        raise InputError("--workers and --scheduler exclude each other", field="--workers",
                         expected="a local cluster (--workers N) or an existing one (--scheduler ADDRESS)")
    distributed = args.workers is not None or args.scheduler
    cluster = Cluster(args.workers, args.scheduler, args.verbose) if distributed else None
    bar = Progress(1, label="sweep")

    def progress(done: int, total: int) -> None:
        bar.total = float(total)
        bar.update(done)

    try:
        ds = run_sweep(scene, sweep_spec(params, rays, seed, args.chunk), args.output, force=args.force,
                       figure=None if args.no_plots else sweep_figure, progress=progress, cluster=cluster)
    finally:
        bar.close()
    summary = {"output": args.output, "dims": {d: int(n) for d, n in ds["LER"].sizes.items()},
               "LER": ds["LER"].values, "YBR": ds["YBR"].values, "non_uniformity": ds["non_uniformity"].values,
               "YBR_definition": ds["YBR"].attrs.get("definition", ""),
               "max_ledger_error": float(ds["ledger_error"].max()), "rays_per_point": rays, "seed": seed}
    if args.json:
        emit_json(summary)
    else:
        print(ds[["LER", "std_err_LER", "YBR", "non_uniformity", "ledger_error"]].to_dataframe().to_string())
        print(f"YBR = {summary['YBR_definition']}")
        print(f"wrote {args.output}")
    return 0
