"""``bsdfkit ingest PATH -o scan.nc``: a raw export, a measured text table or a vendor BSDF file → netCDF dataset.

PATH is a raw goniometer export folder (read + calibrated, ``docs/raw-format.md``), a measured text table
(:func:`bsdfkit.measurement.table.read_table`) or a Zemax/Radiant ``.bsdf``, TracePro or ASAP-style file
(:func:`bsdfkit.tables.to_dataset.vendor_dataset`); see :func:`bsdfkit.api.ingest`. The table
options say what the file does not: ``--quantity``, ``--side``, ``--relative-std``, ``--wavelength`` ….
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings

from bsdfkit import api
from bsdfkit.cli._common import check_options, emit_json, warn_dark
from bsdfkit.core.conventions import DEFAULT_RELATIVE_STD, QUANTITIES, SIDES, ZERO_POLICIES
from bsdfkit.core.errors import StatedTisWarning
from bsdfkit.io import atomic
from bsdfkit.io.text import existing_source
from bsdfkit.tables import registry

#: numeric options: finite and in these ranges
OPTION_RANGES = {
    "incidence": (0.0, 90.0, "an incidence angle in [0, 90] deg"),
    "phi_i": (-360.0, 360.0, "an azimuth in [-360, 360] deg"),
    "wavelength": (1e-3, 1e6, "a wavelength in nm, > 0"),
    "relative_std": (0.0, 10.0, "a relative standard deviation in [0, 10]"),
    "tis_tolerance": (0.0, 1.0, "a relative tolerance in [0, 1]"),
    "symmetry_tolerance": (0.0, 1.0, "a relative tolerance in [0, 1]"),
}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``ingest`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser(
        "ingest", help="read a raw export, a measured text table or a vendor BSDF file into a netCDF dataset",
        description="Read a raw goniometer export (calibrated), a measured text table (wide or long; comma, "
                    "semicolon or tab separated) or a BSDF table of a registered format "
                    f"({', '.join(registry.names())}; sniffed by content) into the calibrated BSDF dataset "
                    "(docs/raw-format.md).")
    p.add_argument("path", metavar="PATH", help="raw export folder (manifest.toml), text table or vendor file")
    p.add_argument("-o", "--output", required=True, help="netCDF file to write")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--quantity", choices=QUANTITIES, default=None, type=str.lower,
                   help="what a table holds where the file does not say (never guessed); brdf/btdf also fix the "
                        "side, cosine-corrected values are divided by cos(theta_s), factors by pi")
    p.add_argument("--side", choices=SIDES, default=None,
                   help="scattering side where neither a side column nor the quantity says")
    p.add_argument("--relative-std", type=float, default=None, metavar="R",
                   help=f"standard uncertainty as a fraction of the value when the table has none "
                        f"(default: the file's '# relative_std:', else {DEFAULT_RELATIVE_STD:g})")
    p.add_argument("--wavelength", type=float, default=None, metavar="NM",
                   help="wavelength of a monochrome table or Zemax/ASAP file (default: NaN, recorded as unknown)")
    p.add_argument("--incidence", type=float, default=None, metavar="DEG",
                   help="incidence of a table without an incidence column")
    p.add_argument("--phi-i", type=float, default=None, metavar="DEG",
                   help="source azimuth of a table without a phi_i column (default 180: specular at phi_s = 0)")
    p.add_argument("--zeros", choices=ZERO_POLICIES, default=None,
                   help="exact zeros: auto (tables: a record zero at every wavelength is a gap), keep, missing")
    p.add_argument("--sample", default=None, help="sample name (default: from the file or its name)")
    p.add_argument("--face", choices=("front", "back"), default=None,
                   help="BSDF XML: the face of the sample to read (default: the front; a file with back blocks "
                        "only: those)")
    p.add_argument("--block", default=None, metavar="LABEL",
                   help="BSDF XML: the spectral block to read by its label (default: Visible, else the first)")
    p.add_argument("--json", action="store_true", help="print the dataset summary as JSON")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    check_options(args, OPTION_RANGES)
    existing_source(args.path)  # before the engine is imported: a mistyped path is answered at once
    atomic.check_writable(args.output, args.force, inputs=[args.path])
    # the CLI silences library warnings; a vendor file whose stated TIS disagrees with its data is said in one line
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StatedTisWarning)
        ds = api.ingest(args.path, quantity=args.quantity, side=args.side, relative_std=args.relative_std,
                        wavelength_nm=args.wavelength, incidence_deg=args.incidence, phi_i_deg=args.phi_i,
                        zeros=args.zeros, sample=args.sample, face=args.face, block=args.block)
    api.save(ds, args.output, args.force)
    warn_dark(ds, "ingest")
    for w in caught:
        if issubclass(w.category, StatedTisWarning):
            print(f"bsdfkit ingest: warning: {w.message}", file=sys.stderr)
    info = api.describe(ds)
    extra = {k: ds.attrs[k] for k in ("source_format", "source_layout", "source_quantity", "bsdf_std_origin",
                                      "gap_records_dropped", "zero_records_as_gaps", "wavelength_note",
                                      "azimuth_note", "face", "faces_note", "block", "blocks_note")
             if k in ds.attrs and ds.attrs[k] != ""}
    if "tis_stated_json" in ds.attrs:  # stated vs integrated TIS of a vendor file (check_stated_tis)
        extra["tis_stated"] = json.loads(ds.attrs["tis_stated_json"])
    if args.json:
        emit_json({**info, "output": str(args.output), **extra})
        return 0
    w = info["wavelength_nm"]
    lam = f"{w['count']} wavelengths" if w["count"] > 1 else (
        f"1 wavelength ({w['min']:g} nm)" if w["min"] == w["min"] else "1 wavelength (unknown)")
    print(f"wrote {args.output}: {info['records']} records, incidences {info['incidences_deg']} deg, {lam}, "
          f"sides {', '.join(info['sides'])}")
    if "source_format" in extra:
        print(f"  from {extra['source_format']} ({extra.get('source_layout', '')}), quantity "
              f"{extra.get('source_quantity', '')}; gaps dropped: {extra.get('gap_records_dropped', 0)} records"
              + (f" ({extra['zero_records_as_gaps']} all-zero)" if extra.get("zero_records_as_gaps") else ""))
        print(f"  bsdf_std: {extra.get('bsdf_std_origin', '')}")
        if "wavelength_note" in extra:
            print(f"  wavelength: {extra['wavelength_note']}")
        if "faces_note" in extra:  # what else the file holds, never dropped in silence
            print(f"  face: {extra.get('face', '')}; {extra['faces_note']}")
        if "blocks_note" in extra:
            print(f"  spectral block: {extra.get('block', '')}; {extra['blocks_note']}")
        if "azimuth_note" in extra:
            print(f"  azimuth: {extra['azimuth_note']}")
    return 0
