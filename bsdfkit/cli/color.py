"""``bsdfkit color FILE [--json]``: chromaticity, CCT/Duv, luminous efficacy and YBR of a spectrum file."""
from __future__ import annotations

import argparse
import sys

from bsdfkit.cli._common import emit_json
from bsdfkit.core.errors import BsdfkitError


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``color`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("color", help="CIE 1931 x, y, CCT and Duv (Ohno 2013), luminous efficacy and YBR of a spectrum")
    p.add_argument("file", help="two-column text spectrum: wavelength (nm), value")
    p.add_argument("--json", action="store_true",
                   help="print x, y, cct_K, duv, luminous_efficacy_lm_per_W, ybr as JSON")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    # here, not at the top: `bsdfkit --help` registers every verb and must not import colour-science
    from bsdfkit.io.spectrum_file import read_spectrum
    from bsdfkit.reduction.colorimetry import DUV_LIMIT, colorimetric_summary

    sd = read_spectrum(args.file)
    try:
        c = colorimetric_summary(sd)
    except BsdfkitError as exc:  # name the file: colorimetry only knows the spectrum's name
        if exc.file is not None:
            raise
        raise type(exc)(str(exc), file=args.file) from None
    if not c.cct_meaningful:
        print(f"bsdfkit color: warning: |Duv| = {abs(c.duv):.3f} > {DUV_LIMIT} — the CCT of {args.file} "
              "is not meaningful (CIE 015)", file=sys.stderr)
    if args.json:
        emit_json({"file": str(args.file), "x": c.x, "y": c.y, "cct_K": c.cct_K, "duv": c.duv,
                   "luminous_efficacy_lm_per_W": c.luminous_efficacy_lm_per_W, "ybr": c.ybr,
                   "ybr_bands_nm": {"yellow": list(c.ybr_yellow_band_nm), "blue": list(c.ybr_blue_band_nm)},
                   "cct_meaningful": c.cct_meaningful})
        return 0
    print(f"{args.file}:")
    print(f"  CIE 1931 2°: x = {c.x:.4f}, y = {c.y:.4f}")
    print(f"  CCT = {c.cct_K:.0f} K, Duv = {c.duv:+.4f} (Ohno 2013){'' if c.cct_meaningful else ' — not meaningful'}")
    print(f"  luminous efficacy of radiation = {c.luminous_efficacy_lm_per_W:.1f} lm/W")
    print(f"  {c.ybr_label} = " + ("undefined (no blue flux)" if c.ybr is None else f"{c.ybr:.3f}"))
    return 0
