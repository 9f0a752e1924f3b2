"""The tracer's phosphor plate from a measurement: the toolkit's own TIS and BSDF fits per interaction and side.

This is where a scene's ``[top] from = "fitting/<recipe>.toml"`` is resolved (:func:`plate_from_recipe`, the
:data:`bsdfkit.raytrace.scene.PlateResolver` that ``bsdfkit trace`` and ``bsdfkit sweep`` pass to the scene
parser: reading, calibrating, reducing and fitting a measurement is pipeline work, which the tracer never
imports), and where the main job builds the plate it traces. The plate is made of the two-arc TIS of each
interaction (bibs, biys, yiys), side and measured incidence, with angular shapes from lambert+gaussian fits for
the elastic interactions and a Lambertian distribution for the converted light (§4.2 of [Power-budget],
``docs/references.md``).

Beyond the measured incidences (a goniometer measures a few, e.g. 5°, 45° and 56° in [Power-budget] §2, while
the cavity lights the plate from 0° to grazing) the plate's grid is extended from the fitted models
(:func:`extrapolated_tis`): each channel keeps the fitted parameters of the nearest measured incidence, and its
TIS follows the model's own dependence on incidence (the lobe centred on β0 = sin θi, clipped by the unit disk),
scaled to meet the measured TIS at that incidence. The tracer then interpolates instead of clamping; how much
of the light reaches the plate on model-extrapolated incidences is a tally of every trace (the incidence
histogram) and is reported by the main job.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import SIDES
from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.io.recipe_head import read_recipe_head
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.models.registry import BSDF_MODELS
from bsdfkit.raytrace.plate import LambertGaussian, Lambertian, PhosphorPlate, PlateChannel
from bsdfkit.reduction.spectral import interaction_profile
from bsdfkit.reduction.tis import tis_table

#: Incidences [deg] the plate gets from the fitted models where the measurement has none (only those outside
#: the measured range are used): normal incidence, and 5° steps from 60° to grazing.
EXTRAPOLATION_GRID_DEG = (0.0, 60.0, 65.0, 70.0, 75.0, 80.0, 85.0, 90.0)

#: Notes marker of a plate whose grid was extended beyond the measured incidences.
EXTRAPOLATED_NOTE = "model-extrapolated outside the measured incidences"


def extrapolated_tis(measured_tis: float, model: str, params: dict[str, float], edge_deg: float,
                     theta_deg: np.ndarray) -> np.ndarray:
    """TIS [1] of a channel at incidences ``theta_deg`` [deg] outside the measured range, from its fitted model.

    The fitted ``params`` of the nearest measured incidence ``edge_deg`` are kept; the TIS follows the model's
    dependence on incidence, TIS(θ) = TIS_measured(θe) · TIS_model(θ)/TIS_model(θe), which equals the measured
    TIS at θe (no step at the edge of the measured range). For a Lambertian model the ratio is 1; for a
    Lambert + Gaussian lobe the lobe moves with β0 = sin θ and loses the part beyond the unit disk (half of a
    narrow lobe at grazing incidence).

    Parameters
    ----------
    measured_tis : float
        Measured TIS of the channel at ``edge_deg`` [-].
    model : str
        Name of the fitted model in :data:`bsdfkit.models.registry.BSDF_MODELS`.
    params : dict of str to float
        The model's fitted parameters at ``edge_deg``.
    edge_deg : float
        Nearest measured incidence [deg].
    theta_deg : ndarray
        Incidences to extrapolate to [deg].

    Returns
    -------
    ndarray
        TIS at ``theta_deg`` [-].
    """
    spec = BSDF_MODELS[model]
    theta = np.asarray(theta_deg, dtype=float)
    at_edge = float(spec.total_integrated_scatter(params, edge_deg))
    if at_edge <= 0.0:
        return np.full(theta.shape, float(measured_tis))
    return float(measured_tis) * spec.total_integrated_scatter(params, theta) / at_edge


def plate_from_scan(scan: xr.Dataset, tis: xr.Dataset | None = None, name: str = "",
                    fits: dict | None = None, extrapolate: bool = True) -> PhosphorPlate:
    """A :class:`bsdfkit.raytrace.PhosphorPlate` from a calibrated scan.

    Parameters
    ----------
    scan
        Calibrated phosphor-plate dataset (configurations blue and yellow).
    tis
        Its TIS table (:func:`bsdfkit.reduction.tis.tis_table`); computed when not given.
    name
        Plate name (default: the sample name of the scan).
    fits
        lambert+gaussian fits already made, keyed by (interaction, side); missing ones are fitted here.
    extrapolate
        Extend the grid to :data:`EXTRAPOLATION_GRID_DEG` outside the measured incidences with
        :func:`extrapolated_tis` (default). If a colour's extrapolated TIS would add up to more than 1 at some
        incidence, that colour's channels are scaled down to sum to 1 there (energy conservation). Without
        it the plate holds the measured incidences only, and the tracer clamps outside them.
    """
    tis = tis if tis is not None else tis_table(scan)
    measured = tuple(float(t) for t in tis["theta_i"].values)
    lo, hi = measured[0], measured[-1]
    extra = [t for t in EXTRAPOLATION_GRID_DEG if extrapolate and (t < lo or t > hi)]
    grid = tuple(sorted(measured + tuple(extra)))
    values: dict[str, np.ndarray] = {}
    dists: dict[str, list] = {}
    for inter in ("bibs", "biys", "yiys"):
        for side in SIDES:
            key = f"{inter}_{side}"
            meas = {t: float(np.clip(tis["tis"].sel(interaction=inter, side=side, theta_i=t), 0.0, 1.0))
                    for t in measured}
            if inter == "biys":
                model, params = "lambert", {t: {"rho": meas[t]} for t in measured}
                shape = {t: Lambertian() for t in measured}
            else:
                fit = (fits or {}).get((inter, side))
                if fit is None or fit.attrs.get("model") not in (None, "lambert+gaussian") or "sigma" not in fit:
                    prof = interaction_profile(scan, inter, side)
                    prof = prof.isel(record=np.flatnonzero(np.isfinite(prof["bsdf"].values)))
                    fit = fit_bsdf(prof, "lambert+gaussian")
                model = "lambert+gaussian"
                params = {t: {p: float(fit[p].sel(theta_i=t)) for p in ("rho", "A", "sigma")} for t in measured}
                shape = {t: LambertGaussian(rho_per_sr=params[t]["rho"] / np.pi, a_per_sr=params[t]["A"],
                                            sigma=params[t]["sigma"]) for t in measured}
            row = []
            for t in grid:
                edge = lo if t < lo else hi if t > hi else t
                row.append(meas[t] if t == edge else
                           float(extrapolated_tis(meas[edge], model, params[edge], edge, np.array(t))))
            values[key] = np.clip(np.asarray(row), 0.0, 1.0)
            dists[key] = [shape[lo if t < lo else hi if t > hi else t] for t in grid]
    for colour in (("bibs", "biys"), ("yiys",)):
        keys = [f"{i}_{s}" for i in colour for s in SIDES]
        total = sum(values[k] for k in keys)
        scale = np.where(total > 1.0, 1.0 / np.maximum(total, 1.0), 1.0)  # extrapolated points only can exceed 1
        for k in keys:
            values[k] = values[k] * scale
    channels = {k: PlateChannel(tuple(float(v) for v in values[k]), tuple(dists[k])) for k in values}
    notes = (f"from {scan.attrs.get('source', '')}: bsdfkit TIS (two-arc reconstruction) and lambert+gaussian fits "
             f"at the measured incidences {', '.join(f'{t:g}' for t in measured)} deg")
    if extra:
        notes += (f"; {EXTRAPOLATED_NOTE} at {', '.join(f'{t:g}' for t in extra)} deg (fitted parameters of the "
                  "nearest measured incidence, TIS following the model's incidence dependence)")
    plate = PhosphorPlate(theta_i_deg=grid, name=name or scan.attrs.get("sample_name", ""), notes=notes, **channels)
    plate.validate()
    return plate


def plate_from_recipe(recipe: str | Path) -> PhosphorPlate:
    """The phosphor plate of a recipe's measurement (for scenes with ``[top] from = "fitting/<recipe>.toml"``;
    a :data:`bsdfkit.raytrace.scene.PlateResolver`).

    Parameters
    ----------
    recipe : str or Path
        The fitting recipe's TOML file.

    Returns
    -------
    PhosphorPlate
        The plate from the calibrated scan of the recipe's measurement.
    """
    name, measurement = read_recipe_head(recipe)
    return plate_from_scan(calibrate(read_scan(measurement)), name=name)
