"""``bsdfkit fit spectrum FILE [FILE ...]`` and ``bsdfkit fit bsdf SCAN``: model fits from the command line.

``fit spectrum`` fits emission-spectrum models (:mod:`bsdfkit.fit.spectrum`: eqs. (2)-(3) of the
cylindrical-module paper, the LED line shapes of :mod:`bsdfkit.models.led`, the two-band pump + phosphor sums,
or ``best`` by AICc/BIC) to one or many spectrum files, or to the value columns of a multi-column table, in one
batch per model (one compiled kernel), and reports the measured metrics beside the fitted ones. ``fit bsdf``
reduces a scan (netCDF written by bsdfkit, or a raw measurement folder) to the profile of one interaction and
side (:func:`bsdfkit.reduction.spectral.interaction_profile`) and fits a BSDF model per incidence
(:func:`bsdfkit.fit.least_squares.fit_bsdf`). Suspicious fits (iteration limit, R² < 0, parameters on a bound,
fitted peak or FWHM far from the measured) are reported with warning lines on stderr and, with ``--json``, in
each record's ``warnings``; degenerate fits are one-line errors (exit status 2). A BSDF fit is judged by the
plausibility gate (:mod:`bsdfkit.fit.plausibility`): each incidence says whether it passes and, if not, why
(``plausible`` and ``reasons`` with ``--json``); exports refuse a fit that fails it. A lobe model whose lobe the data
do not determine at any incidence falls back to ``lambert`` (:func:`bsdfkit.fit.least_squares.fit_bsdf`): the header
names the model used and the one requested, a one-line ``note:`` says why (``model``, ``model_requested`` and
``fallback_reason`` with ``--json``); ``--no-fallback`` fits the requested model or fails.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from bsdfkit import api
from bsdfkit.cli._common import emit_json, warn_dark
from bsdfkit.core.conventions import ELASTIC_INTERACTION, SIDES, SPECTRUM_CRITERIA, WAVELENGTH_RANGE_NM
from bsdfkit.core.conventions import INTERACTIONS as PHOSPHOR_INTERACTIONS
from bsdfkit.core.errors import FitError, InputError, ValidationError
from bsdfkit.io import atomic

if TYPE_CHECKING:
    import xarray as xr

# the model registry's names, written out: its module imports numpy (0.15 s of `bsdfkit --help`); a test checks
# them against bsdfkit.models.registry. The fits (JAX, colour-science) are imported by the verb that runs.
BSDF_MODELS = ("lambert", "lambert+gaussian", "abg", "lambert+abg")
SPECTRUM_MODELS = ("gaussian", "split-gaussian", "ohno2005", "split-pseudo-voigt", "split-pearson7",
                   "pseudo-voigt-shoulder", "pearson7-shoulder", "two-band", "two-band-led", "two-band-wide")
INTERACTIONS = (*PHOSPHOR_INTERACTIONS, ELASTIC_INTERACTION)
#: ``fit bsdf --wavelength NM`` takes the nearest measured wavelength within this distance [nm].
WAVELENGTH_TOLERANCE_NM = 0.5


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``fit`` verb and its options to the ``bsdfkit`` parser.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of the ``bsdfkit`` parser.
    """
    p = sub.add_parser("fit", help="fit spectrum or BSDF models (Levenberg-Marquardt, float64)")
    p.set_defaults(func=lambda args: _help(p))
    fit_sub = p.add_subparsers(dest="fit_verb", metavar="{spectrum,bsdf,reflectance}")

    s = fit_sub.add_parser("spectrum", help="fit emission-spectrum models to spectrum files (batched)")
    s.add_argument("files", nargs="+", metavar="FILE",
                   help="text spectra: wavelength (nm) and one or more value columns (.ISD, CSV, TSV ...)")
    s.add_argument("--column", action="append", metavar="NAME",
                   help="fit this value column (header name or 1-based column number); repeatable; "
                        "default: every value column")
    s.add_argument("--model", choices=("best",) + SPECTRUM_MODELS, default="best",
                   help="line shape; 'best' (default) fits every single-band model and keeps the lowest "
                        "--criterion; a fitted peak more than 0.5 nm or FWHM more than 5 %% from the measured "
                        "one is warned about")
    s.add_argument("--criterion", choices=SPECTRUM_CRITERIA, default="aicc",
                   help="information criterion for --model best")
    s.add_argument("--range", nargs=2, type=float, metavar=("LO", "HI"),
                   help="fit only wavelengths LO..HI nm (inclusive), e.g. 380 780 or the phosphor band")
    s.add_argument("--split-nm", type=float, default=None,
                   help="two-band: fixed pump/phosphor split (nm); default: each spectrum's valley")
    s.add_argument("--maxiter", type=int, default=200, help="iteration limit per pass (default 200)")
    s.add_argument("--json", action="store_true", help="print one JSON record per spectrum (one per line)")
    s.set_defaults(func=_run_spectrum)

    b = fit_sub.add_parser("bsdf", help="fit a BSDF model per incidence to one interaction and side of a scan")
    b.add_argument("scan", help="a dataset (netCDF), raw measurement folder, measured table or vendor file")
    b.add_argument("--interaction", choices=INTERACTIONS, required=True,
                   help="bibs, biys, yiys (phosphor plates) or elastic (any sample)")
    b.add_argument("--side", choices=SIDES, required=True)
    b.add_argument("--model", choices=BSDF_MODELS, default="lambert+gaussian",
                   help="default lambert+gaussian; a lobe model whose lobe the data do not determine at any incidence "
                        "falls back to lambert, with a note saying why")
    b.add_argument("--no-fallback", action="store_true",
                   help="fit --model as asked: no fallback to lambert (an undetermined lobe is then an error)")
    b.add_argument("--incidence", type=float, metavar="DEG", help="fit only this incidence angle (degrees)")
    b.add_argument("--wavelength", type=float, metavar="NM",
                   help="elastic: fit only this measured wavelength [nm] (the nearest within "
                        f"{WAVELENGTH_TOLERANCE_NM:g} nm); default: the whole measured range (a single-wavelength "
                        "scan: its one wavelength)")
    b.add_argument("-o", "--output", metavar="FIT.nc", help="save the fit (netCDF) for `bsdfkit export`")
    b.add_argument("--force", action="store_true", help="overwrite an existing output")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=_run_bsdf)

    r = fit_sub.add_parser("reflectance", help="Lambertian surface model of a measured reflectance spectrum "
                                            "(e.g. a Spectralon 8°/h calibration)")
    r.add_argument("file", help="spectrum table: wavelength [nm], reflectance[, standard uncertainty]")
    r.add_argument("--percent", action="store_true", help="the reflectance column is in percent")
    r.add_argument("--side", choices=SIDES, default="reflection")
    r.add_argument("-o", "--output", required=True, metavar="MODEL.nc", help="the model (netCDF)")
    r.add_argument("--force", action="store_true", help="overwrite an existing output")
    r.set_defaults(func=_run_reflectance)


def _help(parser: argparse.ArgumentParser) -> int:
    """``bsdfkit fit`` without a sub-verb: a usage error, one line on stderr with exit status 2 (argparse's)."""
    parser.error("no sub-verb given; expected one of spectrum, bsdf, reflectance")


def _warn_unconverged(label: str, iterations: int) -> None:
    print(f"bsdfkit fit: warning: {label} did not converge ({iterations} iterations, the limit); "
          "the parameters are the last iterate", file=sys.stderr)


def _fmt(value, spec: str = ".2f") -> str:
    return "n/a" if value is None else format(value, spec)


def _run_spectrum(args: argparse.Namespace) -> int:
    from bsdfkit.fit.least_squares import FitOptions
    from bsdfkit.fit.spectrum import TWO_BAND_MODELS, analyse_spectra
    from bsdfkit.io.spectrum_file import read_spectrum_table, select_columns

    if args.maxiter < 1:
        raise ValidationError("iteration limit must be ≥ 1", field="--maxiter", got=args.maxiter)
    if args.split_nm is not None:
        if args.model not in TWO_BAND_MODELS:
            raise ValidationError("--split-nm is the pump/phosphor split of a two-band model", field="--split-nm",
                                  expected=f"--model {' | '.join(TWO_BAND_MODELS)}", got=args.model)
        lo, hi = WAVELENGTH_RANGE_NM
        if not (math.isfinite(args.split_nm) and lo <= args.split_nm <= hi):
            raise ValidationError("option out of range", field="--split-nm",
                                  expected=f"a wavelength in nm ({lo:g}-{hi:g})", got=args.split_nm)
    if args.range is not None and not args.range[0] < args.range[1]:
        raise ValidationError("empty fit range", field="--range", expected="LO < HI", got=tuple(args.range))
    spectra, sources = [], []
    for file in args.files:
        wl, table, _ = read_spectrum_table(file)
        names = select_columns(file, table, args.column)
        for name in names:
            spectra.append((wl, table[name]))
            sources.append((str(file), name if len(table) > 1 else None))
    labels = [Path(f).name + (f" [{c}]" if c else "") for f, c in sources]
    ranges = [None if args.range is None else tuple(args.range)] * len(spectra)
    records = analyse_spectra(spectra, args.model, ranges_nm=ranges, labels=labels, criterion=args.criterion,
                              options=FitOptions(maxiter=args.maxiter), split_nm=args.split_nm)
    failed = 0
    for (file, column), label, rec in zip(sources, labels, records):
        rec = {"file": file, "column": column, **rec}
        if "error" in rec:
            failed += 1
            if len(records) == 1:
                raise FitError(rec["error"])
            print(f"bsdfkit fit: error: {rec['error']}", file=sys.stderr)
        else:
            for w in rec["warnings"]:
                print(f"bsdfkit fit: warning: {label}: {w}", file=sys.stderr)
        if args.json:  # JSON lines: one record per spectrum, one line each
            from bsdfkit.io.jsonout import to_jsonable

            print(json.dumps(to_jsonable(rec)), flush=True)
        elif "error" not in rec:
            _print_spectrum(label, rec)
    return 2 if failed else 0


def _print_spectrum(label: str, rec: dict) -> None:
    rng = rec["range_nm"]
    where = "" if rng is None else f" in {rng[0]:g}-{rng[1]:g} nm"
    print(f"{label}: {rec['model']} fit, {rec['n_points']} points{where}")
    for n, v in rec["params"].items():
        print(f"  {n:<22} {v:.6g} ± {rec['std'][n]:.2g}")
    print(f"  R² = {rec['r2']:.5f}; {'converged' if rec['converged'] else 'NOT converged'} "
          f"after {rec['iterations']} iterations; AICc {rec['criteria']['aicc']:.1f}, BIC {rec['criteria']['bic']:.1f}")
    me, fi, di = rec["measured"], rec["fitted"], rec["difference"]
    print(f"  {'':<22}{'measured':>10}{'fitted':>10}{'fit-meas':>10}")
    for key in ("peak_nm", "fwhm_nm", "centroid_nm", "dominant_wavelength_nm", "purity"):
        if key in fi:
            print(f"  {key:<22}{_fmt(me.get(key)):>10}{_fmt(fi.get(key)):>10}{_fmt(di.get(key), '+.2f'):>10}")
    if "measured_split" in rec:
        sp = rec["measured_split"]
        print(f"  measured: pump maximum {sp['pump_peak_nm']:.2f} nm, valley {sp['valley_nm']:.2f} nm, "
              f"phosphor maximum {sp['phosphor_peak_nm']:.2f} nm")
    for part, c in rec.get("components", {}).items():
        print(f"  {part}: peak {_fmt(c['peak_nm'])} nm, FWHM {_fmt(c['fwhm_nm'])} nm, power {c['power']:.4g} "
              f"(input units·nm, {_fmt(c['power_fraction'], '.1%')} of the total)")
    if "candidates" in rec:
        crit = rec["criterion"]
        ranked = sorted(rec["candidates"].items(), key=lambda kv: kv[1].get(crit, float("inf")))
        print(f"  candidates by {crit}: " + ", ".join(
            f"{n} {v[crit]:.1f}" if "error" not in v else f"{n} (failed)" for n, v in ranked))


def _run_reflectance(args: argparse.Namespace) -> int:
    from bsdfkit.fit.lambertian import lambertian_from_reflectance
    from bsdfkit.io import netcdf
    from bsdfkit.io.spectrum_file import read_spectrum_table

    atomic.check_writable(args.output, args.force, inputs=[args.file])
    wl, columns, _ = read_spectrum_table(args.file)
    values = list(columns.values())
    if len(values) > 2:
        raise InputError("a reflectance table has 2 or 3 columns", file=args.file,
                         expected="wavelength, reflectance[, uncertainty]", got=f"{len(values) + 1} columns")
    scale = 0.01 if args.percent else 1.0
    rho = values[0] * scale
    std = values[1] * scale if len(values) == 2 else None
    model = lambertian_from_reflectance(wl, rho, std, side=args.side, source=Path(args.file).name)
    netcdf.save(model, args.output, args.force, inputs=[args.file])
    print(f"wrote {args.output}: Lambertian {args.side} model, {wl.size} wavelengths {wl[0]:g}-{wl[-1]:g} nm, "
          f"mean reflectance {float(rho.mean()):.4f}; export one wavelength with "
          f"`bsdfkit export {args.output} --interaction elastic --wavelength-nm NM ...`")
    return 0


def _std(value: float | None) -> str:
    """An uncertainty for the text output: ``0`` for an exact fit, ``n/a`` where none could be formed (never
    ``nan``)."""
    return "n/a" if value is None or not math.isfinite(value) else format(value, ".2g")


def select_wavelength(ds: xr.Dataset, wavelength_nm: float, scan: str) -> xr.Dataset:
    """The dataset at the measured wavelength nearest ``nm`` [nm], within :data:`WAVELENGTH_TOLERANCE_NM`.

    Parameters
    ----------
    ds : xarray.Dataset
        A calibrated BSDF dataset (dimension ``wavelength`` [nm]).
    wavelength_nm : float
        The wavelength asked for [nm].
    scan : str
        The scan's path, for the message.

    Returns
    -------
    xarray.Dataset
        ``ds`` with the one wavelength (dimension kept, size 1).

    Raises
    ------
    InputError
        The scan states no wavelength (NaN), or none lies within the tolerance (the message names the measured
        ones).
    """
    import numpy as np

    lam = np.asarray(ds["wavelength"].values, dtype=np.float64)
    finite = np.flatnonzero(np.isfinite(lam))
    if finite.size == 0:
        raise InputError("the scan does not state its wavelength", file=scan, field="--wavelength",
                         expected="a scan with a stated wavelength (ingest a monochrome table with --wavelength NM)",
                         got=wavelength_nm)
    k = int(finite[np.argmin(np.abs(lam[finite] - wavelength_nm))])
    if not abs(lam[k] - wavelength_nm) <= WAVELENGTH_TOLERANCE_NM:
        measured = np.unique(lam[finite])
        available = (", ".join(f"{w:g}" for w in measured.tolist()) + " nm" if measured.size <= 8 else
                     f"one of the {measured.size} measured wavelengths {measured[0]:g}..{measured[-1]:g} nm")
        raise InputError(f"no measured wavelength within {WAVELENGTH_TOLERANCE_NM:g} nm of --wavelength",
                         file=scan, field="--wavelength",
                         expected=available + (f" (nearest {lam[k]:g} nm)" if measured.size > 1 else ""),
                         got=wavelength_nm)
    return ds.isel(wavelength=[k])


def _run_bsdf(args: argparse.Namespace) -> int:
    from bsdfkit.fit import plausibility
    from bsdfkit.fit.least_squares import BsdfFitOptions, fit_bsdf
    from bsdfkit.io import netcdf
    from bsdfkit.reduction.any_sample import measured_tis
    from bsdfkit.reduction.spectral import interaction_profile

    if args.wavelength is not None:
        if not (math.isfinite(args.wavelength) and args.wavelength > 0):
            raise ValidationError("option out of range", field="--wavelength", expected="a wavelength > 0 nm",
                                  got=args.wavelength)
        if args.interaction != ELASTIC_INTERACTION:
            raise InputError("--wavelength selects the wavelength of an elastic fit", field="--wavelength",
                             expected=f"--interaction {ELASTIC_INTERACTION} (the phosphor interactions have "
                                      "their own bands)", got=args.interaction)
    if args.output:
        atomic.check_writable(args.output, args.force, inputs=[args.scan])
    ds = api.ingest(args.scan)
    if args.wavelength is not None:
        ds = select_wavelength(ds, args.wavelength, args.scan)
    warn_dark(ds, "fit bsdf")
    profile = interaction_profile(ds, args.interaction, args.side)
    result = fit_bsdf(profile, args.model, incidence_deg=args.incidence,
                      options=BsdfFitOptions(fallback=not args.no_fallback))
    result.attrs["interaction"] = args.interaction
    used, fallback = str(result.attrs["model"]), str(result.attrs.get("fallback_reason", "")) or None
    if args.wavelength is not None:
        result.attrs["wavelength_nm"] = float(ds["wavelength"].values[0])
    warnings = json.loads(result.attrs.get("warnings", "[]"))
    if args.output:
        netcdf.save(result, args.output, args.force, inputs=[args.scan])
    names = [str(n) for n in result.parameter.values]
    verdict = plausibility.evaluate(result)
    fits = []
    for k, theta in enumerate(result.theta_i.values):
        row = result.isel(theta_i=k)
        if not bool(row.converged):
            _warn_unconverged(f"{used} fit at θi = {theta:g}°", int(row.iterations))
        where = f"incidence {theta:g} deg: "
        data_tis, data_tis_std = measured_tis(ds, args.interaction, args.side, float(theta))
        fits.append({
            "theta_i_deg": float(theta),
            "params": {n: float(row[n]) for n in names},
            "std": {n: float(row[f"{n}_std"]) for n in names},
            "r2": float(row.r2), "rms": float(row.rms), "tis": float(row.tis), "tis_std": float(row.tis_std),
            "data_tis": data_tis, "data_tis_std": data_tis_std,
            "converged": bool(row.converged), "n_points": int(row.n_points),
            "physically_possible": bool(row.physically_possible), "determined": bool(row.determined),
            "plausible": bool(verdict.plausible.values[k]),
            "reasons": [r[len(where):] for r in verdict.reasons if r.startswith(where)],
        })
    if args.json:
        emit_json({"scan": str(args.scan), "interaction": args.interaction, "side": args.side,
                   "model": used, "model_requested": args.model, "model_used": used, "fallback_reason": fallback,
                   "residual": result.attrs["residual"], "fits": fits,
                   "plausible": verdict.passed, "warnings": warnings, "output": args.output})
        return 0
    for w in warnings:
        print(f"bsdfkit fit: warning: {w}", file=sys.stderr)
    requested = "" if used == args.model else f", requested {args.model}"
    print(f"{args.scan}: {args.interaction} {args.side}, model {used}{requested} ({result.attrs['residual']} "
          "residuals)")
    if fallback:
        print(f"  note: {fallback}")
    for f in fits:
        parts = ", ".join(f"{n} = {f['params'][n]:.4g} ± {_std(f['std'][n])}" for n in names)
        gate = ("passes the plausibility gate" if f["plausible"] else
                "FAILS the plausibility gate: " + "; ".join(f["reasons"]))
        print(f"  θi = {f['theta_i_deg']:g}°: {parts}; TIS = {f['tis']:.4f} ± {_std(f['tis_std'])} "
              f"(data {f['data_tis']:.4f} ± {_std(f['data_tis_std'])}); R² = {f['r2']:.4f}; "
              f"{'converged' if f['converged'] else 'NOT converged'}, {gate}")
    if args.output:
        print(f"wrote {args.output}" + ("" if verdict.passed else
                                        " (fails the plausibility gate: exports refuse it; see the warnings)"))
    return 0
