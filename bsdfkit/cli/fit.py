"""``bsdfkit fit spectrum FILE`` and ``bsdfkit fit bsdf SCAN``: model fits from the command line.

``fit spectrum`` fits eq. (2) (gaussian), eq. (3) (split-gaussian) or both jointly (two-band) of the
cylindrical-module paper to a two-column spectrum file (:mod:`bsdfkit.fit.spectrum`). ``fit bsdf`` reduces a
scan (netCDF written by bsdfkit, or a raw measurement folder) to the profile of one interaction and side
(:func:`bsdfkit.reduction.spectral.interaction_profile`) and fits a BSDF model per incidence
(:func:`bsdfkit.fit.least_squares.fit_bsdf`). A fit that stops at the iteration limit is reported with a warning line on
stderr; degenerate fits are one-line errors (exit status 2).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bsdfkit.cli._common import emit_json

SPECTRUM_MODELS = ("gaussian", "split-gaussian", "two-band")
BSDF_MODELS = ("lambert+gaussian", "abg", "lambert+abg", "lambert")
INTERACTIONS = ("bibs", "biys", "yiys")
SIDES = ("reflection", "transmission")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="fit spectrum or BSDF models (jaxopt Levenberg-Marquardt, float64)")
    p.set_defaults(func=lambda args: _help(p))
    fit_sub = p.add_subparsers(dest="fit_verb", metavar="{spectrum,bsdf}")

    s = fit_sub.add_parser("spectrum", help="fit a Gaussian / split-Gaussian / two-band model to a spectrum file")
    s.add_argument("file", help="two-column text spectrum: wavelength (nm), value")
    s.add_argument("--model", choices=SPECTRUM_MODELS, default="gaussian")
    s.add_argument("--range", nargs=2, type=float, metavar=("LO", "HI"),
                   help="fit only wavelengths LO..HI nm (inclusive), e.g. the phosphor band")
    s.add_argument("--split-nm", type=float, default=500.0,
                   help="two-band: pump/phosphor split used to initialise the components (default 500 nm)")
    s.add_argument("--maxiter", type=int, default=200, help="iteration limit per pass (default 200)")
    s.add_argument("--json", action="store_true", help="print model, params, std, r2, converged as JSON")
    s.set_defaults(func=_run_spectrum)

    b = fit_sub.add_parser("bsdf", help="fit a BSDF model per incidence to one interaction and side of a scan")
    b.add_argument("scan", help="netCDF written by bsdfkit, or a raw measurement folder")
    b.add_argument("--interaction", choices=INTERACTIONS, required=True)
    b.add_argument("--side", choices=SIDES, required=True)
    b.add_argument("--model", choices=BSDF_MODELS, default="lambert+gaussian")
    b.add_argument("--incidence", type=float, metavar="DEG", help="fit only this incidence angle (degrees)")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=_run_bsdf)


def _help(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _warn_unconverged(label: str, iterations: int) -> None:
    print(f"bsdfkit fit: warning: {label} did not converge ({iterations} iterations, the limit); "
          "the parameters are the last iterate", file=sys.stderr)


def _run_spectrum(args: argparse.Namespace) -> int:
    from bsdfkit.core.errors import ValidationError
    from bsdfkit.fit.least_squares import FitOptions
    from bsdfkit.fit.spectrum import fit_spectrum
    from bsdfkit.io.spectrum_file import read_spectrum_arrays

    wl, values, _ = read_spectrum_arrays(args.file)
    mask = None
    if args.range is not None:
        lo, hi = args.range
        mask = (wl >= lo) & (wl <= hi)
    if args.maxiter < 1:
        raise ValidationError("iteration limit must be ≥ 1", field="--maxiter", got=args.maxiter)
    ds = fit_spectrum(wl, values, args.model, mask=mask, split_nm=args.split_nm,
                      options=FitOptions(maxiter=args.maxiter))
    names = [str(n) for n in ds.parameter.values]
    for n, hit in zip(names, ds.at_bound.values):
        if hit:
            print(f"bsdfkit fit: warning: {n} ended on its bound ({float(ds[n]):.6g}); the model may not "
                  "describe this spectrum", file=sys.stderr)
    params = {n: float(ds[n]) for n in names}
    std = {n: float(ds[f"{n}_std"]) for n in names}
    converged = bool(ds.converged)
    if not converged:
        _warn_unconverged(f"{args.model} fit of {args.file}", int(ds.iterations))
    if args.json:
        emit_json({"file": str(args.file), "model": args.model, "params": params, "std": std,
                   "r2": float(ds.r2), "converged": converged,
                   "range_nm": None if args.range is None else list(args.range),
                   "n_points": int(ds.n_points)})
        return 0
    print(f"{Path(args.file).name}: {args.model} fit, {int(ds.n_points)} points"
          + ("" if args.range is None else f" in {args.range[0]:g}-{args.range[1]:g} nm"))
    for n in names:
        unit = ds[n].attrs.get("units", "")
        unit = "" if unit in ("1", "input units") else f" {unit}"
        print(f"  {n:<18} {params[n]:.6g} ± {std[n]:.2g}{unit}")
    print(f"  R² = {float(ds.r2):.5f}; {'converged' if converged else 'NOT converged'} "
          f"after {int(ds.iterations)} iterations")
    return 0


def _load_scan(path: Path):
    from bsdfkit.io import netcdf

    if path.is_dir():
        from bsdfkit.measurement.calibrate import calibrate
        from bsdfkit.measurement.raw_scan import read_scan

        return calibrate(read_scan(path))
    return netcdf.load(path, quantity="bsdf")


def _run_bsdf(args: argparse.Namespace) -> int:
    from bsdfkit.fit.least_squares import fit_bsdf
    from bsdfkit.reduction.spectral import interaction_profile

    ds = _load_scan(Path(args.scan))
    profile = interaction_profile(ds, args.interaction, args.side)
    result = fit_bsdf(profile, args.model, incidence_deg=args.incidence)
    result.attrs["interaction"] = args.interaction
    names = [str(n) for n in result.parameter.values]
    fits = []
    for k, theta in enumerate(result.theta_i.values):
        row = result.isel(theta_i=k)
        if not bool(row.converged):
            _warn_unconverged(f"{args.model} fit at θi = {theta:g}°", int(row.iterations))
        fits.append({
            "theta_i_deg": float(theta),
            "params": {n: float(row[n]) for n in names},
            "std": {n: float(row[f"{n}_std"]) for n in names},
            "r2": float(row.r2), "rms": float(row.rms), "tis": float(row.tis),
            "converged": bool(row.converged), "n_points": int(row.n_points),
        })
    if args.json:
        emit_json({"scan": str(args.scan), "interaction": args.interaction, "side": args.side,
                   "model": args.model, "residual": result.attrs["residual"], "fits": fits})
        return 0
    print(f"{args.scan}: {args.interaction} {args.side}, model {args.model} ({result.attrs['residual']} residuals)")
    for f in fits:
        parts = ", ".join(f"{n} = {f['params'][n]:.4g} ± {f['std'][n]:.2g}" for n in names)
        print(f"  θi = {f['theta_i_deg']:g}°: {parts}; TIS = {f['tis']:.4f}; R² = {f['r2']:.4f}"
              f"{'' if f['converged'] else ' (NOT converged)'}")
    return 0
