"""``bsdfkit trace SCENE.toml``: Monte Carlo trace of a remote-phosphor module scene."""
from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from bsdfkit import api
from bsdfkit.cli._common import Progress, emit_json
from bsdfkit.io.atomic import OutputSet, write_with

#: a trace whose truncated power exceeds this fraction of the emitted power says so on stderr (one line)
TRUNCATION_WARNING = 1e-3


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``trace`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("trace", help="trace a scene (LER, YBR, absorption, non-uniformity, energy ledger)",
                       description="Trace SCENE.toml with the JAX Monte Carlo tracer (docs/tracer.md).")
    p.add_argument("scene", help="scene TOML file")
    p.add_argument("--rays", type=int, default=1_000_000, help="number of rays (default 1e6)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--chunk", type=int, default=None, help="rays per compiled call (default: the scene's)")
    p.add_argument("--lanes", type=int, default=None, help="rays in flight at once (default: the scene's)")
    p.add_argument("--full-kernel", action="store_true", help="compile every optional branch (benchmarking)")
    p.add_argument("-o", "--output", default=None, help="also write the result as netCDF (map, histogram, budget)")
    p.add_argument("--force", action="store_true", help="overwrite --output if it exists")
    p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # here, not at the top: `bsdfkit --help` registers every verb and must not import JAX
    """Run ``bsdfkit trace`` with the parsed options.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of the verb.

    Returns
    -------
    int
        Exit status: 0 on success.
    """
    from bsdfkit.raytrace import trace

    scene = api.load_scene(args.scene)  # a phosphor top from a recipe resolved as the API does
    out = Path(args.output) if args.output else None
    # every file this verb writes is one output set, checked (existing, an input, writable) before tracing
    with (OutputSet(out.parent, [out.name], args.force, inputs=[args.scene]) if out
          else contextlib.nullcontext()) as outputs:
        bar = Progress(args.rays, label="trace")
        try:
            result = trace(scene, args.rays, args.seed, chunk=args.chunk, lanes=args.lanes,
                           full_kernel=args.full_kernel, progress=bar.update)
        finally:
            bar.close()
        if out:
            ds = result.to_dataset()
            write_with(outputs.path(out.name), lambda tmp: ds.to_netcdf(tmp, format="NETCDF4"), True)
    if result.truncated > TRUNCATION_WARNING * result.emitted:
        # rays still bouncing at max_events: the ledger holds their power, but LER and YBR are lower bounds
        print(f"bsdfkit trace: warning: {100 * result.truncated / result.emitted:.3g} % of the emitted power was "
              f"truncated at trace.max_events = {scene.trace.max_events} (rays still in flight); LER and YBR are "
              "lower bounds: raise max_events or add a loss", file=sys.stderr)
    report = result.to_dict()
    if args.json:
        emit_json(report)
        return 0
    e, a, se = result.extracted, result.absorbed, result.std_err
    lines = [
        f"scene        {args.scene}  ({result.rays} rays, seed {result.seed})",
        f"LER          {result.LER:.5f} ± {se['LER']:.5f}",
        (f"YBR          {result.YBR:.4f} ± {se['YBR']:.4f}  (yellow / blue extracted ray power)" if e["blue"] > 0
         else "YBR          n/a (no blue extracted)"),
        f"extracted W  blue {e['blue']:.6g}  yellow {e['yellow']:.6g}  total {e['total']:.6g}",
        "absorbed W   " + "  ".join(f"{k} {v:.6g}" for k, v in a.items()),
        f"ledger       roulette {result.roulette:.3g} W, threshold {result.discarded:.3g} W, truncated "
        f"{result.truncated:.3g} W; relative error {result.ledger_error:.2e}",
    ]
    if result.spectral is not None:
        sp = report["spectral"]
        b, y, led = sp["bands"]["blue"], sp["bands"]["yellow"], sp["ledger"]
        lines[2] = (f"YBR          {result.YBR:.4f} ± {se['YBR']:.4f}  (extracted {y['label']} / {b['label']})"
                    if e["blue"] > 0 else "YBR          n/a (nothing extracted in the blue band)")
        efficacy = sp["luminous_efficacy_lm_per_W"]
        lines += [
            f"spectrum     {len(sp['wavelength_nm'])} bins {sp['wavelength_nm'][0]:g}-{sp['wavelength_nm'][-1]:g} nm; "
            + (f"luminous efficacy {efficacy:.1f} lm/W" if efficacy is not None else "nothing extracted"),
            f"Stokes loss  {led['power_W']['stokes']:.6g} W",
            f"photons      emitted {led['photons_per_s']['emitted']:.6g} /s, extracted "
            f"{led['photons_per_s']['extracted']:.6g} /s; photon ledger error {led['photons_per_s']['error']:.2e}",
        ]
    conv = result.non_uniformity_converged
    if result.non_uniformity is not None and conv is not None:
        lines.append(f"non-uniform. {result.non_uniformity:.4f} ± {conv['std']:.4f} (split-half on {conv['bins']} "
                     f"cells per side, {'converged' if conv['converged'] else 'NOT converged'} in the map grid; "
                     f"whole map {result.non_uniformity_map:.4f})")
    if result.clamped_interactions:
        lines.append(f"clamped      {result.clamped_interactions} plate incidences outside the measured grid")
    lines.append(f"speed        {result.rays_per_s:.3g} rays/s, {result.interactions_per_s:.3g} interactions/s "
                 f"(compile {result.compile_s:.2f} s, total {result.elapsed_s:.2f} s)")
    print("\n".join(lines))
    return 0
