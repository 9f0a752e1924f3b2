"""Batch solution of the spectrum fits: grid checks, one compiled kernel per model and pass, degenerate
members isolated, multi-start rounds, and the front-ends :func:`fit_spectra` / :func:`fit_spectrum`.
Wavelengths in nm.
"""
from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import xarray as xr

from bsdfkit.core.errors import FitError, InputError, ValidationError
from bsdfkit.fit.least_squares import FitOptions, least_squares
from bsdfkit.fit.spectrum.models import (
    _FUNCTIONS,
    _RELATIVE,
    PUMP_MAX_FWHM_NM,
    SHOULDER_MODELS,
    SINGLE_BAND_MODELS,
    SPECTRUM_MODELS,
    _gaussian,
    _parameters,
    _relative_parameters,
    _split_gaussian,
)
from bsdfkit.fit.spectrum.starts import (
    TwoBandSplit,
    _inside,
    _peak_and_fwhm,
    _phosphor_pair_starts,
    _shoulder_starts,
    find_two_band_split,
)
from bsdfkit.reduction.colorimetry import check_wavelengths_nm

#: Retries of a batch after a degenerate member made :func:`least_squares` raise (:func:`_solve`), and the
#: condition-number limit of those batch solves: near 1/ε, where inverting JᵀJ itself can fail; the usual
#: limit (``FitOptions.max_condition``) is applied per spectrum afterwards.
MAX_BATCH_RETRIES: int = 6
LENIENT_MAX_CONDITION: float = 1e15
#: Iterations of each start point in the first round of a multi-start fit (:func:`_solve_multistart`).
MULTISTART_ROUND1_MAXITER: int = 40


def _validated_grid(wavelength: np.ndarray) -> np.ndarray:
    wl = np.asarray(wavelength, dtype=float)
    if wl.ndim != 1 or wl.size < 3:
        raise InputError("wavelength grid must be 1-D with at least 3 samples", field="wavelength",
                         got=wl.shape)
    if not np.all(np.isfinite(wl)):
        raise InputError("wavelength is not finite", field="wavelength", got=float(wl[~np.isfinite(wl)][0]))
    if not np.all(np.diff(wl) > 0):
        k = int(np.argmax(~(np.diff(wl) > 0))) + 1
        raise InputError("wavelengths must increase strictly", field=f"wavelength[{k}]",
                         expected=f"> {wl[k - 1]:g}", got=float(wl[k]))
    return wl


def _nm_grid(wavelength: np.ndarray) -> np.ndarray:
    """:func:`_validated_grid` of a grid that must be in nm (µm or m values are refused)."""
    wl = _validated_grid(wavelength)
    check_wavelengths_nm(wl, "wavelength")
    return wl


def _validated_grids(wavelength: np.ndarray, n_batch: int) -> np.ndarray:
    """(batch, n) grids in nm: one grid broadcast, or one strictly increasing grid per spectrum."""
    wl = np.asarray(wavelength, dtype=float)
    if wl.ndim == 1:
        return np.broadcast_to(_nm_grid(wl), (n_batch, wl.size))
    if wl.ndim != 2 or wl.shape[0] != n_batch:
        raise InputError("wavelength must be (n,) or (batch, n)", field="wavelength",
                         expected=f"(n,) or ({n_batch}, n)", got=wl.shape)
    for row in wl:
        _nm_grid(row)
    return wl


@dataclass(frozen=True)
class _Batch:
    """What every solve of one batch shares: the standard uncertainties (batch, n) or None, the solver options, one
    label per spectrum (for messages) and whether a failing spectrum is recorded (``collect``) or raises."""

    sigma: np.ndarray | None
    options: FitOptions
    labels: Sequence[str]
    collect: bool

    def rows(self, idx) -> _Batch:
        """The settings of the spectra ``idx`` of the batch (in that order)."""
        return replace(self, sigma=None if self.sigma is None else self.sigma[idx],
                       labels=[self.labels[i] for i in idx])

    def tiled(self, k: int) -> _Batch:
        """The settings of ``k`` copies of the batch stacked (multi-start rounds)."""
        return replace(self, sigma=None if self.sigma is None else np.concatenate([self.sigma] * k, axis=0),
                       labels=list(self.labels) * k)


def _solve(function, wl, y, m, p0, parameters, batch: _Batch, model_name: str):
    """:func:`least_squares` over a batch. Returns (result or None, errors: index → one-line message).

    Without ``collect`` any degenerate member raises :class:`FitError` as :func:`least_squares` does. With
    ``collect`` one degenerate spectrum must not take the others with it (:func:`least_squares` raises for the
    whole batch): the batch is solved with the condition-number refusal relaxed to "numerically singular"
    (:data:`LENIENT_MAX_CONDITION`) and the usual check is redone per spectrum on the returned covariance (Jacobi
    equilibrated, as :func:`least_squares` does on JᵀJ, so the condition numbers agree within a factor of
    about p² by van der Sluis). A spectrum that still makes the batch raise is named by the error (internal
    labels), recorded, and its row replaced by a copy of a healthy one, so the retry keeps the batch shape and
    the compiled kernel (at most :data:`MAX_BATCH_RETRIES` retries; after that, or on an error naming no
    spectrum, the spectra are fitted one at a time)."""
    sigma, options, labels, collect = batch.sigma, batch.options, batch.labels, batch.collect
    kwargs = dict(batch_dim="spectrum", model_name=model_name)
    n = y.shape[0]

    def run(idx, opts, names):
        x = wl[idx] if not isinstance(wl, dict) else {k: v[idx] for k, v in wl.items()}
        s = None if sigma is None else sigma[idx]
        return least_squares(function, x, y[idx], _inside(p0[idx], parameters), parameters, sigma=s,
                             mask=m[idx], batch_labels=names, options=opts, **kwargs)

    every = np.arange(n)
    if not collect:
        return run(every, options, [labels[i] for i in every]), {}
    lenient = replace(options, max_condition=LENIENT_MAX_CONDITION)
    internal = [f"#{i}" for i in every]
    source = every.copy()
    errors: dict[int, str] = {}
    result = None
    for _ in range(MAX_BATCH_RETRIES + 1):
        try:
            with np.errstate(invalid="ignore", divide="ignore"):  # variances of degenerate members: flagged below
                result = run(source, lenient, internal)
            break
        except FitError as exc:
            named = re.match(r"#(\d+): (.*)", str(exc))
            healthy = [j for j in every if j not in errors and (not named or j != int(named.group(1)))]
            if not named or not healthy:
                break
            k = int(named.group(1))
            errors[k] = f"{labels[k]}: {named.group(2)}" if labels[k] else named.group(2)
            source[k] = healthy[0]
        except np.linalg.LinAlgError:
            break
    if result is not None:
        flagged = _degenerate(result, labels, options.max_condition)
        errors.update({k: v for k, v in flagged.items() if k not in errors})
        return result, errors
    rows, errors = {}, {}
    for b in every:
        try:
            rows[int(b)] = run(np.array([b]), options, [labels[b]])
        except FitError as exc:
            errors[int(b)] = str(exc)
    if not rows:
        return None, errors
    alive = np.array(sorted(rows))
    return _expand(xr.concat([rows[int(b)] for b in alive], dim="spectrum"), alive, n), errors


def _degenerate(result: xr.Dataset, labels: Sequence[str], max_condition: float) -> dict[int, str]:
    """Spectra whose covariance (Jacobi-equilibrated) has a condition number above ``max_condition``."""
    names = [str(n) for n in result.parameter.values]
    errors = {}
    for b, cov in enumerate(result.covariance.values):
        d = np.sqrt(np.abs(np.diagonal(cov)))
        if not (np.all(np.isfinite(cov)) and np.all(np.diagonal(cov) > 0)):
            errors[b] = f"{labels[b]}: singular JᵀJ: the data do not constrain the parameters"
            continue
        ev, evec = np.linalg.eigh(cov / np.outer(d, d))
        cond = ev[-1] / ev[0] if ev[0] > 0 else math.inf
        if not cond <= max_condition:
            weak = [names[k] for k in np.argsort(-np.abs(evec[:, -1])) if abs(evec[k, -1]) > 0.3]
            errors[b] = (f"{labels[b]}: singular JᵀJ (condition number {cond:.3g} > {max_condition:.3g}): "
                         f"{', '.join(weak)} not separately determined by these data")
    return errors


class _PaddedSpectra(NamedTuple):
    """Spectra on (batch, n) grids: wavelengths [nm], values, the mask of the samples used, and one label each."""

    wavelength_nm: np.ndarray
    values: np.ndarray
    mask: np.ndarray
    labels: list[str]

    def rows(self, index: np.ndarray) -> _PaddedSpectra:
        """The spectra at ``index`` (an integer array)."""
        return _PaddedSpectra(self.wavelength_nm[index], self.values[index], self.mask[index],
                             [self.labels[b] for b in index])


def _fit_batch(spectra: _PaddedSpectra, model, *, sigma, options, split_nm, collect):
    """Core of :func:`fit_spectra` on (batch, n) grids. Returns (Dataset on normalised data or None, errors,
    splits) where errors maps a spectrum index to a one-line message."""
    wl2, y, m, labels = spectra
    n_batch = y.shape[0]
    peak_values = np.max(np.where(m, y, -np.inf), axis=1)
    if not np.all(peak_values > 0):
        b = int(np.argmax(~(peak_values > 0)))
        raise FitError(f"{labels[b] or 'spectrum'}: no positive value to normalise by")
    scale = peak_values[:, None]
    y_n = y / scale
    s_n = None if sigma is None else np.broadcast_to(np.asarray(sigma, dtype=float), y.shape) / scale
    used = np.where(m, wl2, np.nan)
    lo, hi = float(np.nanmin(used)), float(np.nanmax(used))
    batch = _Batch(s_n, options, labels, collect)
    errors: dict[int, str] = {}
    splits: dict[int, TwoBandSplit] = {}

    if model in ("gaussian", "split-gaussian"):
        p0 = np.array([_peak_and_fwhm(wl2[b], y_n[b], m[b]) for b in range(n_batch)])
        wl_in = wl2[0] if np.all(wl2 == wl2[0]) else wl2  # 1-D grid as before: identical numbers
        wl_use = np.broadcast_to(wl_in, y.shape)
        first, errors = _solve(_gaussian, wl_use, y_n, m, p0, _parameters("gaussian", lo, hi), batch, "gaussian")
        result = first
        if model == "split-gaussian" and first is not None:
            p1 = np.stack([first.peak_nm.values, first.fwhm_nm.values, np.zeros(n_batch),
                           first.amplitude.values], axis=1)
            alive = np.array([b for b in range(n_batch) if b not in errors])
            result, more = _solve(_split_gaussian, wl_use[alive], y_n[alive], m[alive], p1[alive],
                                  _parameters(model, lo, hi), batch.rows(alive), model)
            errors.update({int(alive[k]): v for k, v in more.items()})
            result = _expand(result, alive, n_batch)
    elif model in SHOULDER_MODELS:
        result, errors = _fit_multistart(wl2, y_n, m, model, _parameters(model, lo, hi), batch)
    elif model in SINGLE_BAND_MODELS:
        rows = []
        for b in range(n_batch):
            peak, fwhm, amp, alpha = _peak_and_fwhm(wl2[b], y_n[b], m[b], with_alpha=True)
            if model == "ohno2005":
                rows.append([peak, fwhm, amp])
            else:
                rows.append([peak, fwhm, alpha, 0.5 if model == "split-pseudo-voigt" else 2.0, amp])
        result, errors = _solve(_FUNCTIONS[model], wl2, y_n, m, np.array(rows), _parameters(model, lo, hi), batch,
                                model)
    else:
        result, errors, splits = _fit_two_band(wl2, y_n, m, model, split_nm=split_nm, batch=batch)

    if result is None:
        return None, errors, splits
    # Undo the normalisation of the amplitudes (value, std and covariance).
    names = list(result.parameter.values)
    factors = np.ones((n_batch, len(names)))
    for k, name in enumerate(names):
        if name.endswith("amplitude"):
            factors[:, k] = scale[:, 0]
            result[name] = result[name] * scale[:, 0]
            result[f"{name}_std"] = result[f"{name}_std"] * scale[:, 0]
            result[name].attrs["units"] = result[f"{name}_std"].attrs["units"] = "input units"
    result["covariance"] = result["covariance"] * (factors[:, :, None] * factors[:, None, :])
    result["normalisation"] = (("spectrum",), scale[:, 0], {"long_name": "maximum the data were divided by"})
    result.attrs["model"] = model
    result.attrs["normalisation"] = "fitted on values / max(values); amplitudes rescaled to input units"
    if model == "split-gaussian":
        result.attrs["passes"] = "alpha fixed at 0, then alpha free (docs/fitting.md §2)"
    return result, errors, splits


def _fit_multistart(wl2, y_n, m, model, parameters, batch: _Batch):
    """Shoulder models: every spectrum from each of :func:`_shoulder_starts`; see :func:`_solve_multistart`."""
    shape = 0.5 if model.startswith("pseudo-voigt") else 2.0
    starts = np.array([_shoulder_starts(*_peak_and_fwhm(wl2[b], y_n[b], m[b], with_alpha=True)[:4], shape)
                       for b in range(y_n.shape[0])]).transpose(1, 0, 2)
    return _solve_multistart(_FUNCTIONS[model], wl2, y_n, m, starts, parameters, batch, model)


def _solve_multistart(function, x, y_n, m, starts: np.ndarray, parameters, batch: _Batch, model_name: str):
    """Solve every spectrum from each of ``starts`` (shape (k, batch, p)) and keep the lowest cost.

    Two rounds on the same compiled kernel (the batch keeps its k × batch shape): every start runs for at most
    :data:`MULTISTART_ROUND1_MAXITER` iterations; the best start of each spectrum then continues from where it
    stopped with the full iteration limit (the batch padded with copies of one healthy spectrum, whose results
    are discarded). The first round is short because the host loop lasts as long as its slowest fit. Returns
    (result, errors)."""
    k_starts, n_batch = starts.shape[:2]

    def tile(a):
        return np.concatenate([a] * k_starts, axis=0)

    x_t = {k: tile(v) for k, v in x.items()} if isinstance(x, dict) else tile(x)
    short = replace(batch.options, maxiter=min(batch.options.maxiter, MULTISTART_ROUND1_MAXITER))
    first, errors = _solve(function, x_t, tile(y_n), tile(m), starts.reshape(k_starts * n_batch, -1), parameters,
                           replace(batch.tiled(k_starts), options=short), model_name)
    if first is None:
        return None, {b: errors.get(b, "fit failed") for b in range(n_batch)}
    cost = first.cost.values.reshape(k_starts, n_batch)
    failed = np.array([[k * n_batch + b in errors for b in range(n_batch)] for k in range(k_starts)])
    cost = np.where(failed | ~np.isfinite(cost), np.inf, cost)
    pick = np.argmin(cost, axis=0)
    names = [str(n) for n in first.parameter.values]
    best = np.stack([first[n].values for n in names], axis=1)[pick * n_batch + np.arange(n_batch)]
    dead = np.all(failed, axis=0)
    best[dead] = starts[0][dead]  # all starts failed: rerun the first (its error is reported anyway)
    # The padding rows (kept so that the kernel is reused) repeat the healthiest spectrum, not each spectrum:
    # a degenerate spectrum then fails once in this round, not k times.
    healthy = np.flatnonzero(~dead)
    donor = int(healthy[np.argmin(np.min(cost, axis=0)[healthy])]) if healthy.size else 0

    def continue_from(src: np.ndarray, start: np.ndarray):
        """The rows ``src`` of the batch from ``start[src]`` with the full iteration limit."""
        x_s = {k: v[src] for k, v in x.items()} if isinstance(x, dict) else x[src]
        return _solve(function, x_s, y_n[src], m[src], start[src], parameters, batch.rows(src), model_name)

    result, errors2 = continue_from(np.concatenate([np.arange(n_batch), np.full((k_starts - 1) * n_batch, donor)]),
                                    best)
    if result is None:
        return None, {b: errors2.get(b, errors.get(b, "fit failed")) for b in range(n_batch)}
    chosen = result.isel(spectrum=np.arange(n_batch))
    # A spectrum whose best start ends degenerate (a side band gone to zero height: its position and width no
    # longer matter) continues from its next-best start instead, in a batch of the same shape (same kernel).
    order = np.argsort(cost, axis=0)
    rank = np.zeros(n_batch, dtype=int)
    round1 = np.stack([first[n].values for n in names], axis=1)
    for _ in range(k_starts - 1):
        retry = [b for b in range(n_batch) if b in errors2 and not dead[b] and rank[b] + 1 < k_starts
                 and math.isfinite(cost[order[rank[b] + 1, b], b])]
        if not retry:
            break
        for b in retry:
            rank[b] += 1
            pick[b] = order[rank[b], b]
        src = np.array([b if b in retry else donor for b in range(n_batch)] + [donor] * ((k_starts - 1) * n_batch))
        again, errors3 = continue_from(src, round1[pick * n_batch + np.arange(n_batch)])
        if again is None:
            break
        fixed = [b for b in retry if b not in errors3]
        chosen = xr.concat([again.isel(spectrum=b) if b in fixed else chosen.isel(spectrum=b) for b in range(n_batch)],
                           dim="spectrum", data_vars="all", coords="minimal", compat="override")
        for b in retry:
            if b in fixed:
                errors2.pop(b)
            else:
                errors2[b] = errors3[b]
    chosen["iterations"] = chosen["iterations"] + first.iterations.values[pick * n_batch + np.arange(n_batch)]
    chosen.attrs["starts"] = (f"{k_starts} start points per spectrum, {short.maxiter} iterations each; the lowest "
                              "cost continued to convergence (the next lowest if that ended degenerate)")
    out_errors = {b: errors[b] for b in range(n_batch) if dead[b]}
    out_errors.update({b: errors2[b] for b in range(n_batch) if b in errors2 and b not in out_errors})
    return chosen, out_errors


def _expand(result, alive: np.ndarray, n_batch: int):
    """Put the rows of a fit of ``alive`` spectra back on the full batch (NaN rows for the others)."""
    if result is None or alive.size == n_batch:
        return result
    template = result.isel(spectrum=0)
    rows = []
    k = 0
    for b in range(n_batch):
        if k < alive.size and alive[k] == b:
            rows.append(result.isel(spectrum=k))
            k += 1
        else:
            rows.append(xr.full_like(template, np.nan, dtype=float).assign(
                converged=template.converged & False, at_bound=template.at_bound & False))
    return xr.concat(rows, dim="spectrum", data_vars="all", coords="minimal", compat="override")


def _fit_two_band(wl2, y_n, m, model, *, split_nm, batch: _Batch):
    """Two-band fit with a per-spectrum split: pump maximum and valley from :func:`find_two_band_split` (or the
    valley fixed at ``split_nm``), components held on their side of their own spectrum's valley."""
    n_batch = y_n.shape[0]
    labels = batch.labels
    errors: dict[int, str] = {}
    splits: dict[int, TwoBandSplit] = {}
    for b in range(n_batch):
        try:
            if split_nm is None:
                splits[b] = find_two_band_split(wl2[b], y_n[b], m[b], label=labels[b])
            else:
                region = m[b] & (wl2[b] < split_nm)
                if np.count_nonzero(region) < 3 or np.count_nonzero(m[b] & (wl2[b] >= split_nm)) < 3:
                    raise FitError(f"{labels[b] + ': ' if labels[b] else ''}fewer than 3 samples on one side "
                                   f"of the split at {split_nm:g} nm")
                pk, _, pv = _peak_and_fwhm(wl2[b], y_n[b], region)
                yk, _, yv = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] >= split_nm))
                i_split = int(np.argmin(np.abs(wl2[b] - split_nm)))
                splits[b] = TwoBandSplit(pk, pv, float(split_nm), float(y_n[b, i_split]), yk, yv)
        except FitError as exc:
            if not batch.collect:
                raise
            errors[b] = str(exc)
    alive = np.array(sorted(splits), dtype=int)
    if alive.size == 0:
        return None, errors, splits
    rows = []
    for b in alive:
        s = splits[int(b)]
        bp, bw, ba = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] < s.valley_nm))
        yp, yw, ya = _peak_and_fwhm(wl2[b], y_n[b], m[b] & (wl2[b] >= s.valley_nm))
        bw = min(bw, 0.75 * PUMP_MAX_FWHM_NM)
        # Phosphor asymmetry free from α = 0 in one pass: an α = 0 pass first lets the symmetric phosphor tail
        # swallow a small pump (warm whites), after which the pump has no influence left.
        rows.append(([bp - s.pump_peak_nm, bw, ba], [max(yp - s.valley_nm, 1.0), yw, 0.0, ya]))
    x = {"wl": wl2[alive],
         "pump": np.broadcast_to(np.array([splits[int(b)].pump_peak_nm for b in alive])[:, None],
                                 (alive.size, wl2.shape[1])),
         "valley": np.broadcast_to(np.array([splits[int(b)].valley_nm for b in alive])[:, None],
                                   (alive.size, wl2.shape[1]))}
    sub = batch.rows(alive)
    function = _RELATIVE[model][0]
    if model == "two-band":
        p0 = np.array([pump + phosphor for pump, phosphor in rows])
        result, more = _solve(function, x, y_n[alive], m[alive], p0, _relative_parameters(model), sub, model)
    else:
        # Pump line + side band (offset, FWHM, height fraction) from three starts; the lowest cost is kept.
        pump_starts = ((5.0, 15.0, 0.3), (10.0, 25.0, 0.3), (15.0, 30.0, 0.2))
        if model == "two-band-wide":
            extra = [_phosphor_pair_starts(wl2[b], y_n[b], m[b], splits[int(b)]) for b in alive]
            starts = np.array([[pump[:2] + [(1.0 - f) * pump[2], off, wid, f * pump[2]] + ph
                                for (pump, _), ex in zip(rows, extra) for ph in [ex[k]]]
                               for k, (off, wid, f) in enumerate(pump_starts)])
        else:
            starts = np.array([[pump[:2] + [(1.0 - f) * pump[2], off, wid, f * pump[2]] + phosphor
                                for pump, phosphor in rows]
                               for off, wid, f in pump_starts])
        result, more = _solve_multistart(function, x, y_n[alive], m[alive], starts, _relative_parameters(model),
                                         sub, model)
    errors.update({int(alive[k]): v for k, v in more.items()})
    if result is None:
        return None, errors, splits
    # Back to absolute peaks: blue_peak_nm = pump maximum + offset, yellow_peak_nm = valley + offset.
    pump_ref = np.array([splits[int(b)].pump_peak_nm for b in alive])
    valley = np.array([splits[int(b)].valley_nm for b in alive])
    for name, ref in (("blue_peak_nm", pump_ref), ("yellow_peak_nm", valley)):
        attrs = dict(result[name].attrs)
        result[name] = result[name] + ref
        attrs.update(lower=float(attrs["lower"]), upper=float(attrs["upper"]),
                     note="bounds relative to the spectrum's " + ("pump maximum" if name.startswith("blue")
                                                                  else "valley"))
        result[name].attrs = attrs
    result["split_nm"] = (("spectrum",), valley, {"units": "nm", "long_name": "valley between pump and phosphor"})
    return _expand(result, alive, n_batch), errors, splits


def fit_spectra(
    wavelength_nm: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float | None = None,
) -> xr.Dataset:
    """Fit a spectrum model to a batch of spectra (one compiled kernel per model and pass).

    Parameters
    ----------
    wavelength_nm
        Grid [nm], shape (n,) shared by the batch or (batch, n) one per spectrum (pad shorter spectra with
        increasing wavelengths and mask the padding), strictly increasing (any spacing).
    values
        Spectra, shape (batch, n), any unit (relative or W/nm).
    model
        'gaussian' (eq. 2 of the cylindrical-module paper: peak_nm, fwhm_nm, amplitude),
        'split-gaussian' (eq. 3: peak_nm, fwhm_nm, alpha, amplitude), 'ohno2005' (peak_nm, fwhm_nm, amplitude),
        'split-pseudo-voigt' (peak_nm, fwhm_nm, alpha, eta, amplitude), 'split-pearson7' (peak_nm, fwhm_nm,
        alpha, shape_m, amplitude) — see :mod:`bsdfkit.models.led`; 'pseudo-voigt-shoulder' /
        'pearson7-shoulder' (that line plus a split-Gaussian side band: side_offset_nm from the peak,
        side_fwhm_nm, side_amplitude, side_alpha; fitted from three starts); 'two-band' (pump eq. 2 + phosphor
        eq. 3 jointly: blue_peak_nm, blue_fwhm_nm, blue_amplitude, yellow_peak_nm, yellow_fwhm_nm, yellow_alpha,
        yellow_amplitude) or 'two-band-led' (pump = Gaussian line + Gaussian side band: adds
        blue_side_offset_nm, blue_side_fwhm_nm, blue_side_amplitude after blue_amplitude) or 'two-band-wide'
        (that pump; phosphor split Gaussian + Gaussian: adds phosphor2_offset_nm from yellow_peak_nm,
        phosphor2_fwhm_nm, phosphor2_amplitude after yellow_amplitude). Every ``fwhm_nm`` is
        the true FWHM of that shape [nm] (of the main line for the models with a side band).
    sigma
        Standard uncertainties of ``values`` (same units), broadcast to ``values``; None = unweighted.
    mask
        Boolean, True = use the sample (e.g. restrict to a band); broadcast to ``values``.
    options
        :class:`bsdfkit.fit.least_squares.FitOptions` (default: absolute residuals, linear loss).
    split_nm
        Two-band only. None (default): each spectrum's split is its valley between pump and phosphor
        (:func:`find_two_band_split`, which refuses spectra without a pump or a phosphor band). A number [nm]:
        that split for every spectrum (the pump maximum is then the largest value below it).

    Returns
    -------
    xarray.Dataset over ``spectrum`` (see :func:`bsdfkit.fit.least_squares.least_squares`); amplitudes are in the
    units of ``values``. Two-band results also hold ``split_nm`` (the valley used).

    Raises
    ------
    FitError
        A degenerate fit of any member, or (two-band) a spectrum without pump or phosphor band.
    ValidationError
        Wavelengths not in nm (:func:`bsdfkit.reduction.colorimetry.check_wavelengths_nm`).
    """
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    options = options or FitOptions()
    y = np.asarray(values, dtype=float)
    if y.ndim != 2:
        raise InputError("spectra must have shape (batch, n)", field="values", expected="(batch, n)", got=y.shape)
    wl2 = _validated_grids(wavelength_nm, y.shape[0])
    if y.shape[1] != wl2.shape[1]:
        raise InputError("spectra must have shape (batch, n) matching the wavelength grid", field="values",
                         expected=f"(batch, {wl2.shape[1]})", got=y.shape)
    m = np.ones(y.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), y.shape)
    finite_used = np.where(m, y, 0.0)
    if not np.all(np.isfinite(finite_used)):
        i, j = np.argwhere(~np.isfinite(finite_used))[0]
        raise InputError("spectral value is not finite", field=f"values[{i}, {j}] at {wl2[i, j]:g} nm",
                         got=float(y[i, j]))
    labels = [f"spectrum {b}" for b in range(y.shape[0])] if y.shape[0] > 1 else [""]
    result, _, _ = _fit_batch(_PaddedSpectra(wl2, y, m, labels), model, sigma=sigma, options=options,
                              split_nm=split_nm, collect=False)
    return result


def fit_spectrum(
    wavelength_nm: np.ndarray,
    values: np.ndarray,
    model: str = "gaussian",
    *,
    sigma: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    options: FitOptions | None = None,
    split_nm: float | None = None,
) -> xr.Dataset:
    """Fit one spectrum; see :func:`fit_spectra` for the models and arguments (λ in nm).

    Parameters
    ----------
    wavelength_nm : ndarray, shape (n,)
        Grid [nm], strictly increasing.
    values : ndarray, shape (n,)
        The spectrum, any unit (relative or W/nm).
    model : str, optional
        Spectrum model (see :func:`fit_spectra`).
    sigma : ndarray, optional
        Standard uncertainties of ``values`` (same unit); None = unweighted.
    mask : ndarray of bool, optional
        True = use the sample.
    options : FitOptions, optional
        Solver options (default: absolute residuals, linear loss).
    split_nm : float, optional
        Two-band only: the pump/phosphor split [nm]; None finds each spectrum's valley.

    Returns
    -------
    xarray.Dataset
        Scalars: each parameter (peaks and widths [nm], amplitudes in the unit of ``values``) and its ``_std``,
        ``covariance``, ``r2``, ``rms``, ``iterations`` and ``converged``.

    Raises
    ------
    InputError
        If ``values`` is not 1-D.
    """
    y = np.asarray(values, dtype=float)
    if y.ndim != 1:
        raise InputError("a single spectrum must be 1-D", field="values", got=y.shape)
    # 1-D sigma/mask broadcast against the (1, n) batch.
    ds = fit_spectra(wavelength_nm, y[None, :], model, sigma=sigma, mask=mask, options=options, split_nm=split_nm)
    return ds.isel(spectrum=0)
