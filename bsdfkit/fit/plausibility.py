"""One plausibility gate for BSDF fits: the single rule every writer, the command line, the main job and the report use.

A fit result (:func:`bsdfkit.fit.least_squares.fit_bsdf`, or any dataset of a registered BSDF model such as the
Lambertian model of a reflectance spectrum, :func:`bsdfkit.fit.lambertian.lambertian_from_reflectance`) *fails the
gate* at an incidence when any of these holds (thresholds in :class:`Thresholds`, defaults :data:`THRESHOLDS`):

* **physically impossible**: the model's total integrated scatter exceeds 1 by more than ``tis_sigma`` standard
  uncertainties, TIS − 1 > k·u(TIS) (a TIS above 1 *within* its uncertainty is consistent with an energy-conserving
  surface and passes);
* **undetermined**: a fitted parameter ends on a bound of its range (the covariance, hence every uncertainty, is then
  not valid), or its standard error is not finite or exceeds ``undetermined_ratio`` times its magnitude;
* **does not describe the data**: the coefficient of determination R² is below ``min_r2`` (or undefined) and, for a
  model without shape (``lambert``, see Notes), its residuals exceed the stated uncertainties: reduced χ² (weighted
  by the data's standard uncertainties) above ``max_reduced_chi2``.

:func:`evaluate` returns the flags and one-line reasons, :func:`annotate` stores them in the dataset (variables
``physically_possible``, ``determined``, ``plausible`` and the JSON list ``attrs['warnings']``) and
:func:`refuse_implausible` raises the one :class:`~bsdfkit.core.errors.ValidationError` with which every exporter
refuses a failing fit. The gate is evaluated afresh from the parameters, so a fit saved before the gate existed
(or built by hand) is judged by the same rule.

R², the bound test and the standard-error ratio apply to least-squares results (datasets with ``r2``); a model that
is not a fit (the reflectance model, whose ρ is a measured value clipped to [0, 1]) is judged on its TIS and on
having finite uncertainties only.

Notes
-----
R² compares the model with the best *constant*. For the ``lambert`` model, which *is* a constant at each
incidence (up to the aperture average), R² of noisy Lambertian data is ≈ 0 however good the fit, so R² alone (the
rule as stated in issue #23) flagged every Lambertian fit of noise-dominated data, including the fallback of a lobe
model on a diffuse sample (:func:`bsdfkit.fit.least_squares.fit_bsdf`). For such a model the gate also asks the
goodness-of-fit question R² cannot answer: a Lambertian fit with R² below ``min_r2`` still describes its data when
the reduced χ² = Σr̃²/(n − p) of the residuals weighted by the stated uncertainties is at most
``max_reduced_chi2``; a glossy sample fitted as Lambertian has χ²/dof in the hundreds and stays flagged.
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from bsdfkit.core.errors import ValidationError
from bsdfkit.models.registry import BSDF_MODELS, Parameter, bsdf_model

__all__ = [
    "SHAPELESS_MODELS",
    "Thresholds",
    "THRESHOLDS",
    "Verdict",
    "annotate",
    "at_bound",
    "evaluate",
    "refuse_implausible",
    "tis_excess_allowed",
    "tis_std",
]


@dataclass(frozen=True)
class Thresholds:
    """Thresholds of the plausibility gate (all stated here, nowhere else).

    Attributes
    ----------
    tis_sigma
        Coverage factor k [1]: a fit is physically impossible where TIS − 1 > k·u(TIS). Default 3: a verdict of
        impossibility only when the excess is three standard uncertainties (a surface with TIS exactly 1 is
        refused in 0.13 % of fits), the coverage the fits used before this gate.
    min_r2
        Smallest accepted coefficient of determination [1], in the fit's residual space (ln BSDF for the default
        log residuals). Default 0.9, the value stated in issue #23: below it the model leaves more than a tenth
        of the data's variance unexplained.
    bound_rtol
        A parameter with a finite range [lo, hi] is at a bound when within ``bound_rtol``·(hi − lo) of it [1].
        Default 1e-6, the rule of the ``at_bound`` variable of :func:`bsdfkit.fit.least_squares.least_squares`.
    bound_rtol_open
        A parameter with a one-sided range is at its bound when within ``bound_rtol_open``·max(1, |value|) of
        it [1] (values in the parameter's unit). Default 1e-9, as ``at_bound``: legitimate values such as an ABg
        B of 1e-8 stay clear of it.
    undetermined_ratio
        A parameter is undetermined when its standard error exceeds this multiple of its magnitude [1]. Default
        1: the data then do not fix even the sign of the parameter (its 1σ interval contains 0).
    max_reduced_chi2
        Largest reduced χ² [1] (weighted by the data's stated standard uncertainties) with which a model without
        shape (:data:`SHAPELESS_MODELS`) describes its data although R² < ``min_r2``. Default 4: residuals with an
        RMS up to twice the stated uncertainty, since stated uncertainties are often estimates (ingest assumes
        5 % where a file states none) and a factor 2 misstatement should not refuse a good Lambertian fit.
    """

    tis_sigma: float = 3.0
    min_r2: float = 0.9
    bound_rtol: float = 1e-6
    bound_rtol_open: float = 1e-9
    undetermined_ratio: float = 1.0
    max_reduced_chi2: float = 4.0

    def __post_init__(self) -> None:
        for name in ("tis_sigma", "bound_rtol", "bound_rtol_open", "undetermined_ratio", "max_reduced_chi2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValidationError("plausibility threshold must be a finite number >= 0", field=name, got=value)
        if not (math.isfinite(self.min_r2) and self.min_r2 <= 1):
            raise ValidationError("R² threshold must be a finite number <= 1", field="min_r2", got=self.min_r2)


#: The thresholds of the gate (:class:`Thresholds` defaults).
THRESHOLDS = Thresholds()

#: 1 − R² below which a fit reproduces its data (residual within 1 % of their spread; for constant data, within
#: 1e-8 of their norm, :data:`bsdfkit.fit.least_squares._CONSTANT_DATA`): a parameter on its bound is then where
#: the data put it (a solver stops a part in 10⁹ short of a bound) and is not flagged.
EXACT_R2 = 1e-4

#: Models that are a constant at each incidence (up to the aperture average): R² of their fits compares the model
#: with itself, so the gate judges their description of the data by the reduced χ² (:class:`Thresholds`).
SHAPELESS_MODELS = ("lambert",)


@dataclass(frozen=True)
class Verdict:
    """The gate's judgement of one fit dataset.

    Attributes
    ----------
    physically_possible, determined, describes_data, plausible
        Boolean arrays [1] with the dimensions of the model parameters (e.g. ``theta_i``); ``plausible`` is the
        conjunction of the other three.
    reasons
        One line per failure, prefixed by where it occurs (``incidence 30 deg: ...``).
    notes
        One line per finding that does not fail the gate (a TIS above 1 within its uncertainty).
    """

    physically_possible: xr.DataArray
    determined: xr.DataArray
    describes_data: xr.DataArray
    plausible: xr.DataArray
    reasons: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        """True when the fit passes the gate everywhere."""
        return bool(np.all(self.plausible.values))


def at_bound(value: np.ndarray | float, parameter: Parameter, thresholds: Thresholds = THRESHOLDS) -> np.ndarray:
    """Whether ``value`` [parameter unit] lies on a bound of ``parameter`` (rule in :class:`Thresholds`).

    Parameters
    ----------
    value : float or ndarray
        Parameter values, in the parameter's unit.
    parameter : Parameter
        The parameter, with its bounds.
    thresholds : Thresholds
        The gate's limits; default :data:`THRESHOLDS`.

    Returns
    -------
    ndarray
        Boolean, same shape as ``value``.
    """
    v = np.asarray(value, dtype=np.float64)
    lo, hi = parameter.lower, parameter.upper
    if math.isfinite(lo) and math.isfinite(hi):
        tol = thresholds.bound_rtol * (hi - lo)
    else:
        tol = thresholds.bound_rtol_open * np.maximum(1.0, np.abs(v))
    out = np.zeros(v.shape, bool)
    if math.isfinite(lo):
        out |= v - lo <= tol
    if math.isfinite(hi):
        out |= hi - v <= tol
    return out


def tis_std(model: str, theta_i_deg: np.ndarray, values: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """Standard uncertainty [1] of the model TIS from the parameter covariance (central differences).

    Parameters
    ----------
    model
        Registered BSDF model name.
    theta_i_deg
        Incidences [deg], shape (n,).
    values
        Parameters [their units], shape (n, p), ordered as the model's parameters.
    covariance
        Parameter covariance [unit_i·unit_j], shape (n, p, p).

    Returns
    -------
    numpy.ndarray
        u(TIS) [1], shape (n,); 0 where the variance is exactly 0 (an exact fit: zero residual, zero
        covariance); NaN only where the covariance gives no finite variance ≥ 0.
    """
    spec = bsdf_model(model)
    names = spec.parameter_names
    values = np.asarray(values, dtype=np.float64).reshape(-1, len(names))
    theta = np.broadcast_to(np.asarray(theta_i_deg, dtype=np.float64), values.shape[:1])
    grad = np.zeros_like(values)
    for k in range(len(names)):
        h = 1e-6 * np.maximum(np.abs(values[:, k]), 1e-12)
        up, down = values.copy(), values.copy()
        up[:, k] += h
        down[:, k] = np.maximum(down[:, k] - h, 0.0) if spec.parameters[k].lower == 0 else down[:, k] - h
        t_up = spec.total_integrated_scatter(dict(zip(names, up.T)), theta)
        t_down = spec.total_integrated_scatter(dict(zip(names, down.T)), theta)
        grad[:, k] = (t_up - t_down) / (up[:, k] - down[:, k])
    cov = np.asarray(covariance, dtype=np.float64).reshape(values.shape[0], len(names), len(names))
    var = np.einsum("bi,bij,bj->b", grad, cov, grad)
    return np.sqrt(np.where(np.isfinite(var) & (var >= 0), var, np.nan))


def _model_of(fit: xr.Dataset) -> str:
    model = str(fit.attrs.get("model", ""))
    if model not in BSDF_MODELS:
        raise ValidationError("not a fit of a registered BSDF model", field="model",
                              expected=" | ".join(BSDF_MODELS), got=model)
    return model


def _template(fit: xr.Dataset, names: Sequence[str]) -> xr.DataArray:
    """A parameter array broadcast over the dims of all parameters: the shape on which the gate judges."""
    return xr.broadcast(*[fit[n] for n in names])[0]


def _where(coords: Mapping[str, object]) -> str:
    parts = []
    for dim, value in coords.items():
        if dim == "theta_i":
            parts.append(f"incidence {float(value):g} deg")  # type: ignore[arg-type]
        elif dim == "wavelength":
            parts.append(f"{float(value):g} nm")  # type: ignore[arg-type]
        else:
            parts.append(str(value))
    return ", ".join(parts) or "fit"


def _values(fit: xr.Dataset, name: str, template: xr.DataArray) -> np.ndarray:
    """``fit[name]`` broadcast over the dims of ``template`` (in its order) as a float array."""
    return np.asarray(fit[name].broadcast_like(template).transpose(*template.dims).values, dtype=np.float64)


def _tis_and_std(fit: xr.Dataset, model: str, template: xr.DataArray) -> tuple[np.ndarray, np.ndarray]:
    """Model TIS and u(TIS) over the parameter dims: stored where the fit has them, else computed."""
    names = bsdf_model(model).parameter_names
    shape = template.shape
    values = np.stack([_values(fit, n, template) for n in names], axis=-1)
    theta = (_values(fit, "theta_i", template) if "theta_i" in fit.coords else np.zeros(shape))
    flat_v, flat_t = values.reshape(-1, len(names)), theta.reshape(-1)
    if "tis" in fit:
        tis = _values(fit, "tis", template)
    else:
        tis = np.asarray(bsdf_model(model).total_integrated_scatter(dict(zip(names, flat_v.T)), flat_t),
                         dtype=np.float64).reshape(shape)
    if "tis_std" in fit:
        return tis, _values(fit, "tis_std", template)
    if "covariance" in fit and set(fit["covariance"].dims) >= {"parameter", "parameter_2"}:
        cov_da = fit["covariance"].broadcast_like(template)
        cov = cov_da.transpose(*template.dims, "parameter", "parameter_2").values
    else:  # no covariance: the parameters' standard errors, uncorrelated (0 where not stated)
        stds = np.stack([_values(fit, f"{n}_std", template) if f"{n}_std" in fit else np.zeros(shape)
                         for n in names], axis=-1)
        cov = np.einsum("...i,ij->...ij", stds**2, np.eye(len(names)))
    return tis, tis_std(model, flat_t, flat_v, np.reshape(cov, (-1, len(names), len(names)))).reshape(shape)


def _reduced_chi2(fit: xr.Dataset, template: xr.DataArray) -> np.ndarray | None:
    """Σr̃²/(n − p) [1] of a least-squares result (``cost`` = ½Σr̃², ``dof``) over the parameter dims; None when the
    fit does not state them (a dataset built by hand): then R² alone judges it."""
    if "cost" not in fit or "dof" not in fit:
        return None
    dof = _values(fit, "dof", template)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dof > 0, 2.0 * _values(fit, "cost", template) / dof, np.nan)


def evaluate(fit: xr.Dataset, thresholds: Thresholds = THRESHOLDS) -> Verdict:
    """Judge a fit dataset by the gate (module docstring), everywhere along its parameter dimensions.

    Parameters
    ----------
    fit
        Dataset with ``attrs['model']`` a registered BSDF model and one variable per model parameter (any
        dimensions, e.g. ``theta_i`` [deg], ``side``, ``wavelength`` [nm]); optional ``<name>_std``,
        ``covariance``, ``tis`` and ``tis_std`` [1], ``r2`` [1].
    thresholds
        :class:`Thresholds`; default :data:`THRESHOLDS`.

    Returns
    -------
    Verdict
        Flags and one-line reasons.
    """
    model = _model_of(fit)
    spec = bsdf_model(model)
    names = spec.parameter_names
    missing = [n for n in names if n not in fit.data_vars]
    if missing:
        raise ValidationError(f"fit result lacks parameter '{missing[0]}' of model {model}", field=missing[0],
                              expected=", ".join(names), got=sorted(fit.data_vars))
    template = _template(fit, names)
    dims, shape = tuple(template.dims), template.shape
    tis, u_tis = _tis_and_std(fit, model, template)
    is_fit = "r2" in fit
    r2 = _values(fit, "r2", template) if is_fit else None
    chi2 = _reduced_chi2(fit, template) if is_fit and model in SHAPELESS_MODELS else None
    params = {p.name: _values(fit, p.name, template) for p in spec.parameters}
    stds = {p.name: _values(fit, f"{p.name}_std", template) if f"{p.name}_std" in fit else np.zeros(shape)
            for p in spec.parameters}
    labels = {d: template[d].values for d in dims if d in template.coords}
    possible = np.ones(shape, bool)
    determined = np.ones(shape, bool)
    describes = np.ones(shape, bool)
    reasons: list[str] = []
    notes: list[str] = []
    k = thresholds.tis_sigma
    for index in np.ndindex(*shape):
        where = _where({d: labels[d][i] for d, i in zip(dims, index) if d in labels})
        excess = tis[index] - 1.0
        u = u_tis[index] if np.isfinite(u_tis[index]) else 0.0
        if not np.isfinite(tis[index]) or excess > k * u:
            possible[index] = False
            reasons.append(f"{where}: model TIS {tis[index]:.4f} ± {u:.2g} exceeds 1 by more than {k:g} standard "
                           "uncertainties: physically impossible")
        elif excess > 0:
            notes.append(f"{where}: model TIS {tis[index]:.4f} ± {u:.2g} exceeds 1 within {k:g} standard "
                         "uncertainties (consistent with energy conservation)")
        within_noise = chi2 is not None and bool(chi2[index] <= thresholds.max_reduced_chi2)
        if r2 is not None and not r2[index] >= thresholds.min_r2 and not within_noise:
            describes[index] = False
            worse = ", worse than a constant" if r2[index] < 0 else ""
            noise = "" if chi2 is None else f" and χ²/dof = {chi2[index]:.3g} > {thresholds.max_reduced_chi2:g}"
            reasons.append(f"{where}: R² = {r2[index]:.3g} < {thresholds.min_r2:g}{noise}: the model does not "
                           f"describe the data{worse}")
        # a fit that reproduces the data (R² within EXACT_R2 of 1) has its parameters where the data put them,
        # also on a bound (a noiseless white Lambertian: rho = 1): nothing pushes the model beyond its range
        exact = r2 is not None and bool(r2[index] >= 1.0 - EXACT_R2)
        for p in spec.parameters:
            value, std = float(params[p.name][index]), float(stds[p.name][index])
            if is_fit and not exact and bool(at_bound(value, p, thresholds)):
                determined[index] = False
                bound = p.lower if abs(value - p.lower) <= abs(value - p.upper) else p.upper
                reasons.append(f"{where}: {p.name} = {value:.4g} is at its bound {bound:g}")
            elif not math.isfinite(std) or (is_fit and std > thresholds.undetermined_ratio * abs(value)):
                determined[index] = False
                reasons.append(f"{where}: {p.name} = {value:.4g} ± {std:.3g} is undetermined (standard error "
                               f"above {thresholds.undetermined_ratio:g}× its magnitude)")

    def flag(values: np.ndarray) -> xr.DataArray:
        return xr.DataArray(values, dims=dims, coords={d: template[d] for d in dims if d in template.coords})

    plausible = possible & determined & describes
    return Verdict(flag(possible), flag(determined), flag(describes), flag(plausible), tuple(reasons), tuple(notes))


def annotate(fit: xr.Dataset, thresholds: Thresholds = THRESHOLDS) -> xr.Dataset:
    """``fit`` with the gate's verdict stored: ``physically_possible``, ``determined``, ``plausible`` [bool] and
    ``attrs['warnings']``, a JSON list of the reasons (then the notes). Returns the same dataset, modified.

    Parameters
    ----------
    fit : xarray.Dataset
        Fit dataset (see :func:`evaluate`).
    thresholds : Thresholds
        The gate's limits; default :data:`THRESHOLDS`.

    Returns
    -------
    xarray.Dataset
        ``fit``, with the verdict added.
    """
    verdict = evaluate(fit, thresholds)
    fit["physically_possible"] = verdict.physically_possible.assign_attrs(
        long_name=f"model TIS not above 1 by more than {thresholds.tis_sigma:g} standard uncertainties")
    fit["determined"] = verdict.determined.assign_attrs(
        long_name="no parameter at a bound; every standard error finite and at most "
                  f"{thresholds.undetermined_ratio:g}x its parameter")
    fit["plausible"] = verdict.plausible.assign_attrs(
        long_name=f"passes the plausibility gate (physically possible, determined, R² >= {thresholds.min_r2:g})")
    fit.attrs["warnings"] = json.dumps(list(verdict.reasons + verdict.notes))
    return fit


def refuse_implausible(fit: xr.Dataset, label: str = "", *, thresholds: Thresholds = THRESHOLDS) -> None:
    """Raise the exporters' one refusal when ``fit`` fails the gate anywhere.

    Parameters
    ----------
    fit
        Fit dataset (see :func:`evaluate`); select the interaction, side and incidences to be written first.
    label
        The fit's file name, which the message names (as the ``file`` of the error); "" for none.
    thresholds
        :class:`Thresholds`; default :data:`THRESHOLDS`.

    Raises
    ------
    ValidationError
        One line: the fit's file, its model, the first reason and how many more there are.
    """
    verdict = evaluate(fit, thresholds)
    if verdict.passed:
        return
    more = f" (and {len(verdict.reasons) - 1} more)" if len(verdict.reasons) > 1 else ""
    raise ValidationError(f"the {fit.attrs.get('model')} fit fails the plausibility gate: {verdict.reasons[0]}{more}",
                          file=label or None, field="plausible")


def tis_excess_allowed(fit: xr.Dataset, theta_i_deg: Sequence[float], thresholds: Thresholds = THRESHOLDS
                       ) -> np.ndarray:
    """How far [1] the total scatter of a table written from ``fit`` may exceed 1 at each incidence [deg]:
    k·u(TIS), the gate's own allowance (0 where u(TIS) is not finite or the fit has no such incidence).

    A writer that checks energy itself (TracePro, whose absorptance cannot be negative) uses this so that it
    refuses exactly what the gate refuses. ``fit`` is one side of one interaction over ``theta_i``.

    Parameters
    ----------
    fit : xarray.Dataset
        Fit of one side of one interaction over ``theta_i``.
    theta_i_deg : sequence of float
        Incidences of the table [deg].
    thresholds : Thresholds
        The gate's limits; default :data:`THRESHOLDS`.

    Returns
    -------
    ndarray
        Allowed excess of the total scatter over 1 per incidence [-].
    """
    model = _model_of(fit)
    names = bsdf_model(model).parameter_names
    template = _template(fit, names)
    _, u = _tis_and_std(fit, model, template)
    u_da = xr.DataArray(np.where(np.isfinite(u), u, 0.0), dims=template.dims,
                        coords={d: template[d] for d in template.dims if d in template.coords})
    out = []
    for t in theta_i_deg:
        if "theta_i" in u_da.dims:
            near = np.abs(np.asarray(u_da["theta_i"].values, dtype=np.float64) - float(t)) <= 1e-9
            sel = u_da.isel(theta_i=np.flatnonzero(near))
        else:
            sel = u_da
        out.append(float(np.max(sel.values, initial=0.0)) * thresholds.tis_sigma)  # no fit there: nothing allowed
    return np.asarray(out)
