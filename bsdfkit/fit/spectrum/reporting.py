"""Batch analysis of ``bsdfkit fit spectrum``: measured metrics beside the fitted curve's, model selection by
AICc or BIC, and warnings (:func:`analyse_spectra`). Wavelengths in nm.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from bsdfkit.core.errors import BsdfkitError, InputError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import lm
from bsdfkit.fit.least_squares import FitOptions
from bsdfkit.fit.spectrum.models import (
    _FUNCTIONS,
    CRITERIA,
    SINGLE_BAND_MODELS,
    SPECTRUM_MODELS,
    TWO_BAND_MODELS,
    _parameters,
)
from bsdfkit.fit.spectrum.solver import _fit_batch, _PaddedSpectra, _validated_grid
from bsdfkit.models.registry import pump_two_band, pump_two_band_led
from bsdfkit.reduction.colorimetry import check_power_spectrum, check_wavelengths_nm
from bsdfkit.reduction.spectrum_metrics import spectrum_metrics

#: Warning of :func:`analyse_spectra` below this R² (R² < 0 always gets its own warning).
WARN_R2: float = 0.9
#: Warnings of :func:`analyse_spectra` when the fitted curve's peak or FWHM is this far from the measured one:
#: 0.5 nm is half the 1 nm sampling of the Benkner spectra, 5 % the FWHM precision a line-shape comparison needs
#: (the AICc-best model meets both on every single-band LED of docs/fitting.md §10.6; the Gaussian misses the FWHM
#: by 16-37 %).
WARN_PEAK_NM: float = 0.5
WARN_FWHM_RELATIVE: float = 0.05


def information_criteria(cost: float, n_points: int, n_parameters: int) -> dict[str, float]:
    """AICc and BIC of a least-squares fit with Gaussian errors of unknown variance.

    With RSS = 2·cost and k = n_parameters + 1 (the variance): AIC = n·ln(RSS/n) + 2k,
    AICc = AIC + 2k(k + 1)/(n − k − 1), BIC = n·ln(RSS/n) + k·ln n. Only differences between models fitted to
    the same data matter.

    Parameters
    ----------
    cost : float
        Least-squares cost ½·RSS, in the squared unit of the residuals.
    n_points : int
        Number of fitted samples n.
    n_parameters : int
        Number of fitted model parameters.

    Returns
    -------
    dict of str to float
        ``aicc`` and ``bic`` [-]; NaN when RSS = 0 or n ≤ k + 1.
    """
    n, k = int(n_points), int(n_parameters) + 1
    rss = 2.0 * float(cost)
    if not (rss > 0 and n > k + 1):
        return {"aicc": math.nan, "bic": math.nan}
    base = n * math.log(rss / n)
    return {"aicc": base + 2 * k + 2 * k * (k + 1) / (n - k - 1), "bic": base + k * math.log(n)}


def _pad_spectra(spectra: Sequence[tuple[np.ndarray, np.ndarray]], ranges) -> tuple[np.ndarray, ...]:
    """(batch, n) grids, values and masks from spectra of different lengths: padded past their last
    wavelength (+1 nm steps) with masked zeros."""
    n = max(np.asarray(w).size for w, _ in spectra)
    wl2 = np.empty((len(spectra), n))
    y2 = np.zeros((len(spectra), n))
    m2 = np.zeros((len(spectra), n), bool)
    for b, (w, v) in enumerate(spectra):
        w = _validated_grid(w)
        v = np.asarray(v, dtype=float)
        if v.shape != w.shape:
            raise InputError("values do not match the wavelength grid", field=f"values[{b}]",
                             expected=str(w.shape), got=v.shape)
        k = w.size
        wl2[b, :k], y2[b, :k] = w, v
        wl2[b, k:] = w[-1] + np.arange(1, n - k + 1)
        lo, hi = ranges[b] if ranges[b] is not None else (-math.inf, math.inf)
        m2[b, :k] = (w >= lo) & (w <= hi)
        if np.count_nonzero(m2[b]) < 3:
            raise InputError("fewer than 3 samples in the fit range", field=f"range of spectrum {b}",
                             expected="≥ 3 samples", got=(lo, hi))
    return wl2, y2, m2


#: Points of the fine grid on which fitted curves are measured (peak, FWHM): ~0.05 nm over 400 nm.
FINE_POINTS = 8192


@partial(jax.jit, static_argnames=("function",), compiler_options=lm.SMALL_KERNEL_OPTIONS)
def _evaluate(theta, x, function):
    """function(θ_b, x_b) for every spectrum b of a batch (one compilation per model and shape)."""
    return jax.vmap(function)(theta, x)


_PUMPS = {"two-band": pump_two_band, "two-band-led": pump_two_band_led, "two-band-wide": pump_two_band_led}


def _curves(model: str, ds: xr.Dataset, wl2: np.ndarray, m2: np.ndarray) -> dict[str, np.ndarray]:
    """Fitted curves of every spectrum of a batch on its fine grid (``fine``, :data:`FINE_POINTS` over its fit
    range) and on its samples (``data``); for two-band models also the pump and phosphor components."""
    names = [str(n) for n in ds.parameter.values]
    theta = np.stack([ds[n].values for n in names], axis=1)
    theta = np.where(np.isfinite(theta), theta, 1.0)  # failed fits: any finite row (their curves are unused)
    lo = np.array([row[mask].min() for row, mask in zip(wl2, m2)])
    hi = np.array([row[mask].max() for row, mask in zip(wl2, m2)])
    fine = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, FINE_POINTS)[None, :]
    x = np.concatenate([fine, wl2], axis=1)
    with x64():
        values = np.asarray(_evaluate(jnp.asarray(theta), jnp.asarray(x), function=_FUNCTIONS[model]))
        out = {"fine_wl": fine, "fine": values[:, :FINE_POINTS], "data": values[:, FINE_POINTS:]}
        if model in _PUMPS:
            pump = np.asarray(_evaluate(jnp.asarray(theta), jnp.asarray(x), function=_PUMPS[model]))
            out["pump_fine"], out["pump_data"] = pump[:, :FINE_POINTS], pump[:, FINE_POINTS:]
    return out


_METRIC_KEYS = ("peak_nm", "fwhm_nm", "centroid_nm", "dominant_wavelength_nm", "purity")


def _finite_or_none(v) -> float | None:
    return float(v) if v is not None and math.isfinite(float(v)) else None


def _row_record(ds: xr.Dataset, b: int, model: str, curves: dict[str, np.ndarray], wl: np.ndarray,
                mask: np.ndarray, measured: dict[str, Any], colorimetry: bool) -> dict[str, Any]:
    """Record of spectrum ``b`` of a batch result (see :func:`analyse_spectra`). The fitted curve is measured
    like the data: peak and FWHM on the fine grid, centroid and colour on the data's own samples."""
    row = ds.isel(spectrum=b)
    names = [str(n) for n in ds.parameter.values]
    params = {n: float(row[n]) for n in names}
    fine_wl, fine = curves["fine_wl"][b], curves["fine"][b]
    dense = spectrum_metrics(fine_wl, fine, colorimetry=False)
    fitted: dict[str, Any] = {"peak_nm": dense.peak_nm, "fwhm_nm": dense.fwhm_nm}
    if colorimetry:
        on_grid = spectrum_metrics(wl[mask], curves["data"][b][mask])
        fitted.update(centroid_nm=on_grid.centroid_nm, dominant_wavelength_nm=on_grid.dominant_wavelength_nm,
                      purity=on_grid.purity)
    fitted = {k: _finite_or_none(v) for k, v in fitted.items()}
    diff = {k: (None if measured.get(k) is None or fitted.get(k) is None else fitted[k] - measured[k])
            for k in _METRIC_KEYS if k in fitted}
    at_bound = [n for n, hit in zip(names, row.at_bound.values) if bool(hit)]
    record = {
        "model": model, "params": params, "std": {n: float(row[f"{n}_std"]) for n in names},
        "r2": float(row.r2), "rms": float(row.rms), "converged": bool(row.converged),
        "iterations": int(row.iterations), "n_points": int(row.n_points), "at_bound": at_bound,
        "criteria": information_criteria(float(row.cost), int(row.n_points), len(names)),
        "fitted": fitted, "difference": diff,
    }
    if model in TWO_BAND_MODELS:
        components = {}
        for part in ("pump", "phosphor"):
            if part == "pump":
                on_fine, on_data = curves["pump_fine"][b], curves["pump_data"][b]
            else:
                on_fine, on_data = fine - curves["pump_fine"][b], curves["data"][b] - curves["pump_data"][b]
            m = spectrum_metrics(fine_wl, on_fine, colorimetry=False) if np.max(on_fine) > 0 else None
            components[part] = {"peak_nm": None if m is None else m.peak_nm,
                                "fwhm_nm": None if m is None else _finite_or_none(m.fwhm_nm),
                                "power": float(np.trapezoid(on_data[mask], wl[mask]))}
        total = sum(c["power"] for c in components.values())
        for c in components.values():
            c["power_fraction"] = c["power"] / total if total > 0 else None
        record["components"] = components
        record["split_nm"] = float(row.split_nm)
    return record


def _warnings(record: dict[str, Any], measured: dict[str, Any]) -> list[str]:
    out = []
    if not record["converged"]:
        out.append(f"did not converge ({record['iterations']} iterations, the limit); parameters are the last "
                   "iterate")
    if record["r2"] < 0:
        out.append(f"R² = {record['r2']:.3f} < 0: the model describes this spectrum worse than its mean")
    elif record["r2"] < WARN_R2:
        out.append(f"R² = {record['r2']:.3f} < {WARN_R2:g}: the model describes this spectrum poorly")
    for name in record["at_bound"]:
        out.append(f"{name} ended on its bound ({record['params'][name]:.6g}); the model may not describe "
                   "this spectrum")
    split = record.get("measured_split")
    if split and record.get("components", {}).get("pump", {}).get("peak_nm") is not None:
        d_pump = record["components"]["pump"]["peak_nm"] - split["pump_peak_nm"]
        if abs(d_pump) > WARN_PEAK_NM:
            out.append(f"fitted pump peak {record['components']['pump']['peak_nm']:.2f} nm is {d_pump:+.2f} nm from "
                       f"the measured pump maximum {split['pump_peak_nm']:.2f} nm (the pump shape does not match"
                       + ("; try two-band-led or two-band-wide)" if record["model"] == "two-band" else ")"))
    if record["model"] in SINGLE_BAND_MODELS:
        d_peak, d_fwhm = record["difference"]["peak_nm"], record["difference"]["fwhm_nm"]
        if d_peak is not None and abs(d_peak) > WARN_PEAK_NM:
            out.append(f"fitted peak {record['fitted']['peak_nm']:.2f} nm is {d_peak:+.2f} nm from the measured "
                       f"{measured['peak_nm']:.2f} nm")
        if d_fwhm is not None and measured.get("fwhm_nm") and abs(d_fwhm) > WARN_FWHM_RELATIVE * measured["fwhm_nm"]:
            out.append(f"fitted FWHM {record['fitted']['fwhm_nm']:.2f} nm differs from the measured "
                       f"{measured['fwhm_nm']:.2f} nm by {d_fwhm / measured['fwhm_nm']:+.0%}")
    return out


def analyse_spectra(
    spectra: Sequence[tuple[np.ndarray, np.ndarray]],
    model: str = "best",
    *,
    ranges_nm: Sequence[tuple[float, float] | None] | None = None,
    labels: Sequence[str] | None = None,
    criterion: str = "aicc",
    candidates: Sequence[str] = SINGLE_BAND_MODELS,
    options: FitOptions | None = None,
    split_nm: float | None = None,
) -> list[dict[str, Any]]:
    """Fit many spectra in one batch per model and report measured and fitted metrics side by side.

    Parameters
    ----------
    spectra
        (wavelength [nm], values [any unit]) pairs; grids may differ (they are padded and masked into one batch, so each
        model is compiled once for all of them).
    model
        One of :data:`SPECTRUM_MODELS`, or 'best': every model of ``candidates`` is fitted and the one with the
        lowest ``criterion`` is reported (all candidates' criteria, R², peak and FWHM are in ``candidates``).
    ranges_nm
        Per spectrum (lo, hi) [nm] inclusive fit range, or None for all samples.
    labels
        Names used in messages (default "spectrum 0", ...).
    criterion
        'aicc' or 'bic' (:func:`information_criteria`).
    candidates
        Models tried by 'best' (single-band models by default).
    options
        :class:`~bsdfkit.fit.least_squares.FitOptions`.
    split_nm
        Two-band: None = split at each spectrum's valley (:func:`find_two_band_split`), or a fixed split [nm].

    Returns
    -------
    One dict per spectrum, in order: ``measured`` (:func:`bsdfkit.reduction.spectrum_metrics.spectrum_metrics`
    of the data in the fit range: peak_nm, fwhm_nm, centroid_nm, dominant_wavelength_nm, purity), ``model``,
    ``params``, ``std``, ``r2``, ``rms``, ``converged``, ``iterations``, ``n_points``, ``at_bound``, ``criteria``
    (aicc, bic), ``fitted`` (the same metrics of the fitted curve), ``difference`` (fitted − measured),
    ``warnings`` (list of one-line strings, empty when nothing is suspicious) and, for two-band models,
    ``components`` (pump and phosphor peak_nm, fwhm_nm, power [input units·nm], power_fraction) and
    ``split_nm``. A spectrum whose fit failed or was refused has ``error`` (one line) instead of the fit keys,
    among them implausible spectra (:func:`bsdfkit.reduction.colorimetry.check_power_spectrum` without the
    colorimetric sample count: wavelengths not in nm, negative power beyond the noise) and fewer samples in the
    fit range than a model's parameters + 2.
    """
    _check_request(spectra, model, criterion, candidates)
    options = options or FitOptions()
    n_batch = len(spectra)
    ranges_nm = list(ranges_nm) if ranges_nm is not None else [None] * n_batch
    labels = list(labels) if labels is not None else [f"spectrum {b}" for b in range(n_batch)]
    wl2, y2, m2 = _pad_spectra(spectra, ranges_nm)
    models_to_fit = list(candidates) if model == "best" else [model]
    n_parameters = {name: len(_parameters(name, 380.0, 780.0)) for name in models_to_fit}
    records = _measured_records(spectra, ranges_nm, labels, wl2, y2, m2, n_parameters)
    alive_all = np.array([b for b in range(n_batch) if "error" not in records[b]], dtype=int)
    per_model = {name: _fit_model(name, alive_all, _PaddedSpectra(wl2, y2, m2, labels), records, n_parameters[name],
                                  options, split_nm, colorimetry=len(models_to_fit) == 1)
                 for name in models_to_fit}
    for b in alive_all:
        _complete_record(records[int(b)], {name: per_model[name][int(b)] for name in models_to_fit}, model, criterion,
                         per_model, wl2[b], m2[b], labels[b])
    return records


def _check_request(spectra, model: str, criterion: str, candidates: Sequence[str]) -> None:
    """One-line refusals of :func:`analyse_spectra`'s arguments."""
    if model != "best" and model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model",
                              expected="best | " + " | ".join(SPECTRUM_MODELS), got=model)
    if criterion not in CRITERIA:
        raise ValidationError("unknown information criterion", field="criterion", expected=" | ".join(CRITERIA),
                              got=criterion)
    for c in candidates:
        if c not in SPECTRUM_MODELS:
            raise ValidationError("unknown candidate model", field="candidates",
                                  expected=" | ".join(SPECTRUM_MODELS), got=c)
    if not spectra:
        raise InputError("no spectra to fit", field="spectra")


def _measured_records(spectra, ranges, labels, wl2, y2, m2, n_parameters: dict[str, int]) -> list[dict[str, Any]]:
    """One record per spectrum with its fit range and ``measured`` metrics, or ``error`` for a spectrum no model
    can use (implausible power, too few samples for the smallest model)."""
    records: list[dict[str, Any]] = []
    fewest = min(n_parameters.values()) + 2  # AICc needs n > p + 2 (p counting the variance)
    for b in range(len(spectra)):
        w, v = wl2[b][m2[b]], y2[b][m2[b]]
        rec: dict[str, Any] = {"range_nm": None if ranges[b] is None else [float(r) for r in ranges[b]]}
        try:
            # a spectral power in nm (one line per implausible spectrum: sign errors, noise, µm or m values)
            check_wavelengths_nm(spectra[b][0], "wavelength")
            check_power_spectrum(spectra[b][0], spectra[b][1], "values", colorimetry=False)
            if w.size < fewest:
                raise ValidationError("too few samples in the fit range", field="values",
                                      expected=f"at least {fewest} for a {min(n_parameters, key=n_parameters.get)} "
                                               "fit (its parameters + 2)", got=w.size)
            measured = spectrum_metrics(w, v).as_dict()
            rec["measured"] = {k: _finite_or_none(measured[k]) for k in _METRIC_KEYS}
        except BsdfkitError as exc:
            rec["error"] = f"{labels[b]}: {exc}"
        records.append(rec)
    return records


def _fit_model(name: str, alive_all: np.ndarray, spectra: _PaddedSpectra, records, n_parameters: int,
               options: FitOptions, split_nm: float | None, colorimetry: bool) -> dict[Any, Any]:
    """Model ``name`` fitted to the usable spectra in one batch: {spectrum index: record or {"error"}}, plus the
    batch result ``_ds`` and its curves ``_curves`` (the chosen model's colorimetry is computed from them)."""
    wl2, _, m2, labels = spectra
    out: dict[Any, Any] = {}
    too_few = [b for b in alive_all if np.count_nonzero(m2[b]) < n_parameters + 2]
    for b in too_few:
        out[int(b)] = {"error": f"{labels[b]}: too few samples in the fit range for a {name} fit "
                                f"(at least {n_parameters + 2}, got {np.count_nonzero(m2[b])})"}
    alive = np.array([b for b in alive_all if b not in too_few], dtype=int)
    if alive.size == 0:
        return out
    ds, errors, splits = _fit_batch(spectra.rows(alive), name, sigma=None, options=options, split_nm=split_nm,
                                    collect=True)
    if ds is None:
        for k, b in enumerate(alive):
            out[int(b)] = {"error": errors.get(k, f"{labels[b]}: fit failed")}
        return out
    curves = _curves(name, ds, wl2[alive], m2[alive])
    for k, b in enumerate(alive):
        b = int(b)
        if k in errors:
            out[b] = {"error": errors[k]}
            continue
        out[b] = _row_record(ds, k, name, curves, wl2[b], m2[b], records[b]["measured"], colorimetry=colorimetry)
        out[b]["_k"] = k
        if k in splits:
            out[b]["measured_split"] = {"pump_peak_nm": splits[k].pump_peak_nm, "valley_nm": splits[k].valley_nm,
                                        "phosphor_peak_nm": splits[k].phosphor_peak_nm}
    out["_ds"], out["_curves"] = ds, curves
    return out


def _complete_record(rec: dict[str, Any], results: dict[str, dict[str, Any]], model: str, criterion: str,
                     per_model: dict[str, dict[Any, Any]], wl: np.ndarray, mask: np.ndarray, label: str) -> None:
    """Fill a usable spectrum's record from its fits: the requested model's, or with ``model="best"`` every
    candidate's criteria and the lowest-criterion candidate's full record (its colorimetry computed here)."""
    if model == "best":
        ok = {n: r for n, r in results.items() if "error" not in r and math.isfinite(r["criteria"][criterion])}
        rec["criterion"] = criterion
        rec["candidates"] = {
            n: ({"error": r["error"]} if "error" in r else
                {criterion: r["criteria"][criterion], **{c: r["criteria"][c] for c in CRITERIA},
                 "r2": r["r2"], "peak_nm": r["fitted"]["peak_nm"], "fwhm_nm": r["fitted"]["fwhm_nm"],
                 "warnings": len(_warnings(r, rec["measured"]))})
            for n, r in results.items()}
        if not ok:
            rec["error"] = "; ".join(r["error"] for r in results.values() if "error" in r) or \
                f"{label}: no candidate model could be fitted"
            return
        best = min(ok, key=lambda n: ok[n]["criteria"][criterion])
        # Colorimetry of the chosen curve only (the candidates report peak, FWHM and criteria).
        chosen = _row_record(per_model[best]["_ds"], ok[best]["_k"], best, per_model[best]["_curves"], wl, mask,
                             rec["measured"], colorimetry=True)
    else:
        chosen = results[model]
        if "error" in chosen:
            rec["error"] = chosen["error"]
            return
    rec.update({k: v for k, v in chosen.items() if not k.startswith("_")})
    rec["warnings"] = _warnings(chosen, rec["measured"])
