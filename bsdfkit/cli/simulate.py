"""``bsdfkit simulate --preset cl830-synthetic -o DIR``: raw export from the virtual goniometer."""
from __future__ import annotations

import argparse

from bsdfkit.core.errors import InputError
from bsdfkit.io import atomic

PRESETS = ("cl830-synthetic",)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("simulate", help="simulate a raw goniometer export with the virtual goniometer")
    p.add_argument("--preset", choices=PRESETS, default="cl830-synthetic")
    p.add_argument("--seed", type=int, default=830)
    p.add_argument("-o", "--output", required=True, help="folder to write (manifest.toml + spectra)")
    p.add_argument("--force", action="store_true", help="replace an existing, non-empty output folder as a whole")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    # here, not at the top: `bsdfkit --help` registers every verb and must not import JAX
    from bsdfkit.simulation import virtual_goniometer as virtual

    if not 0 <= args.seed < 2**63:
        raise InputError("option out of range", field="--seed", expected="an integer in [0, 2**63)", got=args.seed)
    atomic.check_output_folder(args.output, args.force)  # before simulating
    export = virtual.cl830_synthetic(seed=args.seed)
    virtual.write_raw_export(export, args.output, args.force)
    n = sum(len(s["columns"]["side"]) for s in export.scans.values())
    print(f"wrote {args.output}: {n} records (synthetic, seed {args.seed})")
    return 0
