"""``bsdfkit info SCAN [--json]``: what a scan (netCDF or raw folder) contains."""
from __future__ import annotations

import argparse
from pathlib import Path

from bsdfkit import api
from bsdfkit.cli._common import emit_json
from bsdfkit.io.text import existing_source


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("info",
                       help="summarise a scan: incidences, sides, positions per arc, wavelengths, configurations")
    p.add_argument("scan", help="netCDF written by bsdfkit, or a raw measurement folder")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    # a mistyped path is answered before the engine is imported
    existing_source(args.scan, "a raw export folder or a netCDF dataset written by bsdfkit")
    # the engine here, not at the top: `bsdfkit --help` registers every verb and must stay light
    from bsdfkit.measurement.raw_scan import read_scan
    from bsdfkit.tables.export import open_bsdf_dataset

    path = Path(args.scan)
    ds = read_scan(path) if path.is_dir() else open_bsdf_dataset(path, raw_counts=True)  # checked: docs/errors.md
    info = api.describe(ds)
    info["file"] = str(path)
    if args.json:
        emit_json(info)
        return 0
    print(f"{path}: {info['quantity']} of '{info['sample']}'{' (SYNTHETIC)' if info['synthetic'] else ''}")
    print(f"  records: {info['records']}; incidences (deg): {', '.join(f'{t:g}' for t in info['incidences_deg'])}")
    w = info["wavelength_nm"]
    if w["step"] is None:
        print(f"  wavelength: {w['min']:g} nm (a single wavelength)")
    else:
        print(f"  wavelength: {w['min']:g}-{w['max']:g} nm, step {w['step']:g} nm ({w['count']} values)")
    for c in info["configurations"]:
        print(f"  configuration {c['name']}: {c['description']} "
              f"(band {c['incident_band_nm'][0]:g}-{c['incident_band_nm'][1]:g} nm)")
    for th, sides in info["positions"].items():
        parts = [f"{side}: " + ", ".join(f"{n} {arc}" for arc, n in arcs.items()) for side, arcs in sides.items()]
        print(f"  θi = {th}°: " + "; ".join(parts))
    cal = info.get("calibration", {})
    if cal.get("below_dark_pixels") or cal.get("negative_raw_counts"):
        print(f"  WARNING: {cal.get('below_dark_pixels', 0)} pixels far below the dark level (dark frames above "
              f"the signal?), {cal.get('negative_raw_counts', 0)} negative raw counts (flag below_dark)")
    return 0
