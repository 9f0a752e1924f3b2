"""``bsdfkit tis SCAN [--incidence DEG] [--band LO HI] [--json]``: TIS of a scan.

Which reduction runs is decided by what the dataset holds (:func:`bsdfkit.reduction.hemispherical.reduction_kind`):

* a phosphor scan of the two-wavelength approach (bi-spectral BSDF with converted light, configurations ``blue``
  and ``yellow``, both sides, not marked elastic) gives the plate's interaction table (Table 2 of the
  power-budget paper: bibs/biys/yiys, power and photons, EQE) at ``--incidence``;
* anything else (any sample, any configuration names, one side or both, one wavelength or many) gives the
  directional-hemispherical reflectance/transmittance per wavelength and its band average over ``--band``
  (default: the measured range), with measurement and reconstruction error bars and the assumptions made.

``--mode`` overrides the choice. ``--band`` is refused (one line, exit 2) for the interaction table, whose
interactions each have their own band. The numbers are those of the API's :func:`bsdfkit.tis` (the same function,
:func:`bsdfkit.reduction.any_sample.tis`), and of :func:`bsdfkit.budget` for the interaction table.
"""
from __future__ import annotations

import argparse
import sys

from bsdfkit.cli._common import emit_json, warn_dark
from bsdfkit.core.conventions import QUANTITIES
from bsdfkit.core.errors import InputError
from bsdfkit.io.text import existing_source


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``tis`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("tis", help="TIS: a phosphor plate's interaction table (Table 2 style), or the "
                                   "hemispherical reflectance/transmittance of any elastic scan")
    p.add_argument("scan", help="calibrated scan (netCDF from `bsdfkit ingest`), a raw measurement folder, a "
                                "measured BSDF text table or a vendor file (as for `bsdfkit ingest`)")
    p.add_argument("--incidence", type=float, help="incidence angle, deg (a measured one); required for the "
                                                   "interaction table, else a filter (default: all incidences)")
    p.add_argument("--band", type=float, nargs=2, metavar=("LO", "HI"),
                   help="wavelength band of the band average, nm (default: the measured range)")
    p.add_argument("--mode", choices=("auto", "interactions", "hemispherical"), default="auto",
                   help="reduction (default auto: decided by what the dataset holds)")
    p.add_argument("--quantity", choices=QUANTITIES, help="for a text table that does not say what it holds")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)


def load_scan(path: str, quantity: str | None = None, verb: str = "tis"):
    """A calibrated dataset from a raw folder, a bsdfkit netCDF, a measured text table or a vendor file.

    Records whose dark frames are brighter than their signal are said on stderr (one line, ``bsdfkit VERB:
    warning: …``): every reduction of them is biased low.

    Parameters
    ----------
    path : str
        Raw measurement folder, bsdfkit netCDF, measured BSDF text table or vendor table file.
    quantity : str, optional
        What a text table holds (one of :data:`bsdfkit.core.conventions.QUANTITIES`) when it does not say;
        None to take it from the table.
    verb : str, optional
        The verb named in the warning line.

    Returns
    -------
    xarray.Dataset
        The calibrated BSDF dataset (:func:`bsdfkit.tables.to_dataset.ingest`).
    """
    existing_source(path)  # a mistyped path is answered before the engine is imported
    # the engine here, not at the top: `bsdfkit --help` registers every verb and must stay light
    from bsdfkit.tables.to_dataset import ingest

    ds = ingest(path, quantity=quantity)
    warn_dark(ds, verb)
    return ds


def _run(args: argparse.Namespace) -> int:
    ds = load_scan(args.scan, getattr(args, "quantity", None))
    from bsdfkit.reduction.any_sample import check_band, check_incidence
    from bsdfkit.reduction.hemispherical import reduction_kind

    band = check_band(args.band, "--band")
    check_incidence(ds, args.incidence, "--incidence")
    kind = reduction_kind(ds) if args.mode == "auto" else args.mode
    if kind == "interactions":
        return _interactions(ds, args, band)
    return _hemispherical(ds, args, band)


def _interactions(ds, args: argparse.Namespace, band: tuple[float, float] | None) -> int:
    from bsdfkit.reduction.any_sample import budget
    from bsdfkit.reduction.any_sample import refuse_band_for_interactions as refuse_band
    from bsdfkit.reduction.budget import KEYS

    if args.incidence is None:
        raise InputError("the interaction table needs an incidence", file=args.scan, field="--incidence",
                         expected="a measured incidence angle in degrees")
    refuse_band(band, "--band")
    table = budget(ds, args.incidence)
    if args.json:
        emit_json(table.as_dict())
        return 0
    print(f"θi = {table.theta_i:g}°   [%] initial power        [%] initial photons")
    for k in KEYS:
        print(f"  {k:14s} {table.power[k]:7.2f} ± {table.power_std[k]:.2f}      "
              f"{table.photons[k]:7.2f} ± {table.photons_std[k]:.2f}")
    print(f"  EQE = {table.eqe:.3f} ± {table.eqe_std:.3f}")
    return 0


def _hemispherical(ds, args: argparse.Namespace, band: tuple[float, float] | None) -> int:
    from bsdfkit.reduction.any_sample import hemispherical_json, tis
    from bsdfkit.reduction.hemispherical import reduction_kind

    # the API's function (bsdfkit.tis), so that the command line and the API give the same numbers
    out = hemispherical_json(tis(ds, args.incidence, band, mode="hemispherical"))
    if args.json:
        emit_json({"reduction": "hemispherical", "source": str(args.scan), "units": "1 (fraction of incident power)",
                   "rule": reduction_kind.__doc__.split("\n\n")[1].strip().replace("\n    ", " "), **out})
        return 0
    for w in out["warnings"]:
        print(f"bsdfkit tis: warning: {w}", file=sys.stderr)
    for r, b in zip(out["hemispherical"], out["band_averaged"]):
        span = "monochrome" if b["band_nm"] is None else f"{b['band_nm'][0]:g}-{b['band_nm'][1]:g} nm"
        note = f"; specular lobe {b['lobe']:.4f}" if r["lobe_region_deg"] is not None else ""
        if r["extrapolated_beyond_deg"] is not None:
            note += f"; extrapolated beyond {r['extrapolated_beyond_deg']:g}°"
        print(f"{r['side']:12s} θi = {r['incidence_deg']:5g}°  {r['config']}: {b['value']:.4f} ± {b['std']:.4f} "
              f"({span}, {b['wavelengths']} wavelengths{note})")
    return 0
