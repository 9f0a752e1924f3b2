"""``bsdfkit export SOURCE --to FORMAT [--interaction I] --side S -o PATH [--force]``.

SOURCE is a fit result netCDF (attribute ``model``), a calibrated phosphor scan netCDF (an interaction, reconstructed
by ``bsdfkit.reduction.tis.hemisphere_bsdf_fn``) or any other measured dataset (elastic scatter, reconstructed by the
hemispherical engine of ``bsdfkit.reduction.hemispherical``: the table integrates to what ``bsdfkit tis`` reports);
see :func:`bsdfkit.tables.export.export`. The table is written, re-checked and re-read under a hidden name in the
folder of PATH (the auto grid's re-check may write it several times) and takes the name PATH only at the end
(:class:`bsdfkit.io.atomic.StagedFile`): an interrupted or failed export leaves nothing there, and an earlier
PATH (``--force``) stays until the finished table replaces it.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

from bsdfkit import api
from bsdfkit.cli._common import add_grid_arguments, add_table_arguments, emit_json
from bsdfkit.core.errors import ValidationError
from bsdfkit.io.atomic import StagedFile
from bsdfkit.tables import registry


def _incidences(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(",") if v)
    except ValueError:
        raise ValidationError("incidences must be comma-separated numbers (deg)", field="--incidences",
                              got=text) from None
    if not values:
        raise ValidationError("no incidence given", field="--incidences", got=text)
    return values


def grid_tolerance(args: argparse.Namespace, tis_default: float | None = None):
    """The :class:`bsdfkit.tables.grids.GridTolerance` of ``--grid-tis-tolerance`` / ``--grid-peak-tolerance``
    (``tis_default`` [1] replaces the class default of the TIS tolerance when the option is not given).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``grid``, ``grid_tis_tolerance``, ``grid_peak_tolerance``).
    tis_default : float, optional
        Relative TIS tolerance [-] used when ``--grid-tis-tolerance`` is not given; None keeps the class default.

    Returns
    -------
    GridTolerance
        The tolerances of the automatic grid.

    Raises
    ------
    ValidationError
        If a grid tolerance is given without ``--grid auto``.
    """
    from bsdfkit.tables.grids import GridTolerance

    given = {k: v for k, v in (("tis_rtol", args.grid_tis_tolerance), ("peak_rtol", args.grid_peak_tolerance))
             if v is not None}
    if given and args.grid != "auto":
        raise ValidationError("grid tolerances apply to --grid auto", field="--grid", expected="auto", got=args.grid)
    if tis_default is not None and "tis_rtol" not in given:
        given["tis_rtol"] = tis_default
    return GridTolerance(**given)


def describe_grid(result) -> str:
    """One line: written size [bytes] and how the axes were chosen.

    Parameters
    ----------
    result : bsdfkit.tables.export.ExportResult
        A written table (its ``grid`` description and ``size_bytes``).

    Returns
    -------
    str
        The description.
    """
    g = result.grid
    text = f"{result.size_bytes:,} bytes; grid {g.get('mode', '?')}"
    if "radial" in g:
        text += f": {g['radial']} radial x {g['azimuth']} azimuth nodes"
    elif "theta" in g and "phi" in g:
        text += f": {g['theta']} theta x {g['phi']} phi nodes (normal frame)"
    elif "radial_nodes" in g and "azimuth" in g:
        text += f": {g['radial_nodes']} radial x {g['azimuth']} azimuth nodes (normal frame)"
    if g.get("mode") == "auto":
        text += f" (TIS tolerance {g['tis_rtol']:g}, peak tolerance {g['peak_rtol']:g})"
    if "values" in g:
        text += f"; {g['values']}"
    return text


def add_nonphysical_argument(p: argparse.ArgumentParser) -> None:
    """The ``--allow-nonphysical`` option of ``export`` and ``convert`` (:mod:`bsdfkit.tables.plausible`).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The verb's parser.
    """
    p.add_argument("--allow-nonphysical", action="store_true",
                   help="write a source whose hemispherical value (or reflection + transmission) exceeds 1 by more "
                        "than 0.01 at some incidence, with a warning (default: refused, nothing written)")


@contextmanager
def nonphysical_warnings(verb: str) -> Iterator[None]:
    """Say each :class:`bsdfkit.tables.plausible.NonphysicalWarning` of the block as one line on stderr (the CLI
    silences library warnings; a table written past the plausibility gate must be said).

    Parameters
    ----------
    verb : str
        The verb named in the line (``export``, ``convert``).

    Yields
    ------
    None
        While the export runs.
    """
    from bsdfkit.tables.plausible import NonphysicalWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", NonphysicalWarning)
        try:
            yield
        finally:  # said also when the write then fails: the user asked for it
            for w in caught:
                if issubclass(w.category, NonphysicalWarning):
                    print(f"bsdfkit {verb}: warning: {w.message}", file=sys.stderr)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    formats = registry.names()
    p = sub.add_parser("export", help=f"write a BSDF table ({', '.join(formats)})",
                       description=f"Write a BSDF table ({', '.join(formats)}) from a fit result or a "
                                   "calibrated scan, and report the TIS of source and table (docs/exports.md).")
    p.add_argument("source", metavar="SOURCE", help="fit result or calibrated scan (netCDF)")
    p.add_argument("--to", required=True, choices=formats, help="target format")
    p.add_argument("--interaction", default="", help="interaction of a phosphor scan or fit (bibs, biys, yiys); "
                                                     "'elastic' or nothing for any other sample")
    p.add_argument("--side", default="reflection", choices=("reflection", "transmission", "both"),
                   help="scattering side (TracePro and ASAP accept both; default reflection)")
    p.add_argument("-o", "--output", required=True, metavar="PATH", help="output file")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--incidences", metavar="DEG,DEG,...", help="incidence angles to export (default: the source's)")
    add_table_arguments(p)
    p.add_argument("--tracepro-scatter", default="table", choices=("table", "abg"),
                   help="TracePro Scatter 5 asymmetric table, or Scatter 1 ABg (ABg fits only)")
    p.add_argument("--zero-azimuth", type=float, default=None, metavar="DEG",
                   help="sample-frame azimuth of TracePro's ScatterAzimuth 0 (default 270; see docs/exports.md)")
    p.add_argument("--name", default=None, help="TracePro property name")
    p.add_argument("--wavelength-um", type=float, default=None, help="TracePro wavelength column (um)")
    p.add_argument("--wavelength-nm", type=float, default=None, metavar="NM",
                   help="the wavelength to export from a per-wavelength model (bsdfkit fit reflectance)")
    p.add_argument("--temperature-k", type=float, default=None, help="TracePro temperature column (K)")
    add_grid_arguments(p, "auto grid: largest estimated relative TIS error of the table (default 0.001)")
    add_nonphysical_argument(p)
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``bsdfkit export``: write the table and print the TIS of source and table per side and incidence.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of the verb.

    Returns
    -------
    int
        Exit status: 0 on success.
    """
    # the engine here, not at the top: `bsdfkit --help` registers every verb and must stay light
    from bsdfkit.tables.export import ExportSettings
    from bsdfkit.tables.formats.tracepro import TraceProOptions

    tp = TraceProOptions()
    changes = {k: v for k, v in (("name", args.name), ("wavelength_um", args.wavelength_um),
                                 ("temperature_K", args.temperature_k), ("zero_azimuth_deg", args.zero_azimuth))
               if v is not None}
    settings = ExportSettings(
        theta_i_deg=_incidences(args.incidences) if args.incidences else None,
        zemax_symmetry=args.symmetry,
        symmetry_tolerance=args.symmetry_tolerance,
        xml_back=args.xml_back, xml_basis=args.xml_basis,
        tracepro=replace(tp, **changes),
        tracepro_scatter=args.tracepro_scatter,
        grid=args.grid,
        grid_tolerance=grid_tolerance(args),
        node_values=args.node_values,
        allow_nonphysical=args.allow_nonphysical,
    )
    # PATH checked here, before computing; the table is written and re-read at the staging file (force: it is this
    # process's own) and moved to PATH once complete
    with StagedFile(args.output, args.force, inputs=[args.source]) as staged, nonphysical_warnings("export"):
        result = api.export(args.source, args.to, args.interaction, args.side, staged.path, True, settings=settings,
                            wavelength_nm=args.wavelength_nm)
        staged.commit()
    result = replace(result, path=str(args.output))  # named by the output, not its staging file
    if args.json:
        emit_json(result.to_dict())
        return 0
    print(f"wrote {result.format} table {result.path} ({describe_grid(result)})")
    if result.peak_error:
        print(f"peak of the lobe: largest error of the re-read table {100 * result.worst_peak_error:.3g} % "
              "of the source's peak")
    if result.plane_symmetry_deviation is not None:
        print(f"plane-symmetry deviation of the source: {result.plane_symmetry_deviation:.3g} of the block maximum "
              "(mirror average written)")
    print(f"{'side':<13}{'theta_i':>8}{'TIS source':>13}{'TIS table':>12}{'diff %':>9}")
    for side in result.sides:
        for t, src, tab in zip(result.incidences_deg, result.tis_source[side], result.tis_table[side]):
            diff = 100.0 * (tab / src - 1.0) if src else 0.0
            print(f"{side:<13}{t:>8g}{src:>13.6g}{tab:>12.6g}{diff:>+9.3f}")
    return 0
