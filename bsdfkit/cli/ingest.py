"""``bsdfkit ingest FOLDER -o scan.nc``: read a raw export, calibrate, write netCDF."""
from __future__ import annotations

import argparse

from bsdfkit.cli._common import emit_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ingest", help="read + calibrate a raw goniometer export into a netCDF BSDF dataset")
    p.add_argument("folder", help="measurement folder holding manifest.toml")
    p.add_argument("-o", "--output", required=True, help="netCDF file to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--json", action="store_true", help="print the dataset summary as JSON")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from bsdfkit.io import atomic, netcdf
    from bsdfkit.measurement.calibrate import calibrate
    from bsdfkit.measurement.describe import describe
    from bsdfkit.measurement.raw_scan import read_scan

    atomic.check_writable(args.output, args.force)
    ds = calibrate(read_scan(args.folder))
    netcdf.save(ds, args.output, args.force)
    info = describe(ds)
    if args.json:
        emit_json(info)
    else:
        print(f"wrote {args.output}: {info['records']} records, incidences {info['incidences_deg']} deg, "
              f"{info['wavelength_nm']['count']} wavelengths")
    return 0
