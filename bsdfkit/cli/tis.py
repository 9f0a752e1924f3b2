"""``bsdfkit tis SCAN --incidence 45 [--json]``: the plate's interaction table (Table 2 of the power-budget paper)."""
from __future__ import annotations

import argparse

from bsdfkit.cli._common import emit_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tis", help="TIS per interaction and side, power and photons, EQE (Table 2 style)")
    p.add_argument("scan", help="calibrated scan (netCDF from `bsdfkit ingest`) or a raw measurement folder")
    p.add_argument("--incidence", type=float, required=True, help="incidence angle, deg (a measured one)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)


def load_scan(path: str):
    from pathlib import Path

    from bsdfkit.io import netcdf
    from bsdfkit.measurement.calibrate import calibrate
    from bsdfkit.measurement.raw_scan import read_scan

    return calibrate(read_scan(path)) if Path(path).is_dir() else netcdf.load(path, quantity="bsdf")


def _run(args: argparse.Namespace) -> int:
    from bsdfkit.reduction.budget import KEYS, interaction_table

    table = interaction_table(load_scan(args.scan), args.incidence)
    if args.json:
        emit_json(table.as_dict())
        return 0
    print(f"θi = {table.theta_i:g}°   [%] initial power        [%] initial photons")
    for k in KEYS:
        print(f"  {k:14s} {table.power[k]:7.2f} ± {table.power_std[k]:.2f}      "
              f"{table.photons[k]:7.2f} ± {table.photons_std[k]:.2f}")
    print(f"  EQE = {table.eqe:.3f} ± {table.eqe_std:.3f}")
    return 0
