"""``bsdfkit convert IN --to FORMAT -o OUT [--force]``: any readable table or dataset to a
ray-tracer table, with the TIS of the written file checked against the source.

IN is a Zemax/Radiant ``.bsdf``, TracePro or ASAP-style file (converted on its own grid), a measured text
table or raw export (ingested first, table options as for ``bsdfkit ingest``) or a bsdfkit netCDF dataset; see
:func:`bsdfkit.tables.to_dataset.convert`. The table is written and re-read under a hidden name in the folder of
OUT and takes the name OUT only when it passed its check. Exit status 0 when every re-read TIS is within
``--tis-tolerance`` of the source's; 1 when the check failed: nothing is written to OUT (an earlier OUT, with
``--force``, is untouched) and the table is removed, or kept as ``<stem>.failed-check<suffix>`` with
``--keep-failed``; 2 for bad input.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bsdfkit.cli._common import add_grid_arguments, add_table_arguments, check_options, emit_json
from bsdfkit.cli.export import add_nonphysical_argument
from bsdfkit.cli.ingest import OPTION_RANGES
from bsdfkit.core.conventions import QUANTITIES, ZERO_POLICIES
from bsdfkit.core.errors import ValidationError
from bsdfkit.io.atomic import failed_check_path
from bsdfkit.tables import registry


def _floats(text: str, name: str, count: int | None = None) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(",") if v)
    except ValueError:
        raise ValidationError("expected comma-separated numbers", field=name, got=text) from None
    if not values or (count is not None and len(values) != count):
        raise ValidationError("wrong number of values", field=name,
                              expected=f"{count} numbers" if count else "numbers", got=text)
    return values


def _grid_tis_default(args: argparse.Namespace) -> float | None:
    """The auto grid's TIS tolerance when not given: half the TIS check the written file must pass (a valid
    ``--tis-tolerance`` only; a bad one is refused by the check itself)."""
    t = args.tis_tolerance
    return 0.5 * t if isinstance(t, float) and 0.0 < t < 2.0 else None


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``convert`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    formats = registry.names()
    p = sub.add_parser("convert", help="convert a BSDF table or dataset to another table format "
                                       f"({', '.join(formats)})",
                       description="Convert any readable BSDF source (a table of a registered format: "
                                   f"{', '.join(formats)}; a measured text table, raw export, netCDF dataset) to a "
                                   "table of a registered format and compare the TIS of the re-read file with "
                                   "the source's.")
    p.add_argument("source", metavar="IN", help="vendor file, text table, raw export folder or netCDF dataset")
    p.add_argument("--to", required=True, choices=formats, help="target format")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output file")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--keep-failed", action="store_true",
                   help="keep a table that fails its TIS check as OUT's <stem>.failed-check<suffix> (default: "
                        "removed; OUT itself is never written by a failed check)")
    p.add_argument("--side", choices=("reflection", "transmission", "both"), default=None,
                   help="side(s) to write (default: all of the source; Zemax holds one)")
    p.add_argument("--wavelength", type=float, default=None, metavar="NM",
                   help="wavelength to write from a spectral source (or the label of a monochrome table)")
    p.add_argument("--band", default=None, metavar="LO,HI", help="write the mean over the wavelengths in this band")
    p.add_argument("--interaction", default=None, help="bibs, biys or yiys for calibrated raw scans")
    p.add_argument("--incidences", default=None, metavar="DEG,DEG,...", help="incidences to write (default: all)")
    p.add_argument("--quantity", choices=QUANTITIES, default=None, type=str.lower,
                   help="for text tables (see bsdfkit ingest)")
    p.add_argument("--relative-std", type=float, default=None, metavar="R", help="for text tables")
    p.add_argument("--zeros", choices=ZERO_POLICIES, default=None, help="for text tables (see bsdfkit ingest)")
    p.add_argument("--face", choices=("front", "back"), default=None,
                   help="BSDF XML source: the face to convert (default: the front; to BSDF XML both faces are kept)")
    p.add_argument("--block", default=None, metavar="LABEL",
                   help="BSDF XML source: the spectral block to convert (default: Visible, else the first)")
    add_table_arguments(p)
    p.add_argument("--tis-tolerance", type=float, default=0.01, metavar="FRACTION",
                   help="largest accepted |TIS written / TIS source - 1| (default 0.01)")
    add_grid_arguments(p, "auto grid: largest estimated relative TIS error of the table (default: half of "
                            "--tis-tolerance, 0.005)")
    add_nonphysical_argument(p)
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    # the failed table's name is an output too: --force never replaces an input with it (bsdfkit.cli.main); a
    # converted table keeps the source's own symmetry (Zemax): plane-symmetric only when the source is
    p.set_defaults(func=run, extra_outputs=_failed_output, symmetry="auto")


def _failed_output(args: argparse.Namespace) -> list[str]:
    """The name a failed table is kept under, when ``--keep-failed`` asks for it."""
    return [str(failed_check_path(args.output))] if args.keep_failed else []


def _convert(args: argparse.Namespace, settings):
    """:func:`bsdfkit.tables.to_dataset.convert` of the parsed command line with ``settings``."""
    from bsdfkit.tables.to_dataset import convert

    return convert(
        args.source, args.to, args.output, args.force, side=args.side, wavelength_nm=args.wavelength,
        band_nm=_floats(args.band, "--band", 2) if args.band else None, interaction=args.interaction,
        theta_i_deg=_floats(args.incidences, "--incidences") if args.incidences else None, settings=settings,
        tolerance=args.tis_tolerance, quantity=args.quantity, relative_std=args.relative_std, zeros=args.zeros,
        face=args.face, block=args.block, keep_failed=args.keep_failed,
    )


def run(args: argparse.Namespace) -> int:
    """Run ``bsdfkit convert``: write the table and compare the TIS of the re-read file with the source's.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of the verb.

    Returns
    -------
    int
        Exit status: 0 when every re-read TIS is within ``--tis-tolerance`` and the table is at OUT, 1 when the
        check failed (nothing written to OUT).
    """
    # the engine here, not at the top: `bsdfkit --help` registers every verb and must stay light
    from bsdfkit.cli.export import describe_grid, grid_tolerance, nonphysical_warnings
    from bsdfkit.tables.export import ExportSettings

    check_options(args, OPTION_RANGES)
    settings = ExportSettings(zemax_symmetry=args.symmetry, symmetry_tolerance=args.symmetry_tolerance,
                              xml_back=args.xml_back, xml_basis=args.xml_basis,
                              grid=args.grid, grid_tolerance=grid_tolerance(args, _grid_tis_default(args)),
                              node_values=args.node_values, allow_nonphysical=args.allow_nonphysical)
    with nonphysical_warnings("convert"):
        result = _convert(args, settings)
    if args.json:
        emit_json(result.to_dict())
    else:
        done = "wrote" if result.committed else "checked (not written)"
        print(f"{done} {result.export.format} table {result.export.path} from {result.source_kind} {result.source}")
        print(f"  {describe_grid(result.export)}")
        if result.export.peak_error:
            print(f"  peak of the lobe: largest error of the re-read table "
                  f"{100 * result.export.worst_peak_error:.3g} % of the source's peak")
        for note in result.notes:
            print(f"  note: {note}")
        print(f"{'side':<13}{'theta_i':>8}{'TIS source':>13}{'TIS written':>13}{'diff %':>9}")
        for side in result.tis_original:
            for t, a, b in zip(result.incidences_deg, result.tis_original[side], result.tis_written[side]):
                diff = 100.0 * (b / a - 1.0) if a else 0.0
                print(f"{side:<13}{t:>8g}{a:>13.6g}{b:>13.6g}{diff:>+9.3f}")
    if not result.committed:
        kept = (f"the table is kept as {result.failed_path}" if result.failed_path
                else "the table is removed (--keep-failed keeps it)")
        out = result.export.path  # an earlier file there (--force) was not replaced
        where = f"{out} left as it was" if Path(out).exists() else f"nothing written to {out}"
        print(f"bsdfkit convert: TIS check failed: largest difference {100 * result.worst_relative_difference:.3g} % "
              f"> {100 * result.tolerance:.3g} %; {where}; {kept}", file=sys.stderr)
        return 1
    return 0
