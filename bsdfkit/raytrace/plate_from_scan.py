"""The tracer's phosphor plate from a measurement: the toolkit's own TIS and BSDF fits per interaction and side.

This is where a scene's ``[top] from = "fitting/<recipe>.toml"`` is resolved, and where the main job builds the
plate it traces. The plate is made of the two-arc TIS of each interaction (bibs, biys, yiys), side and measured
incidence, with angular shapes from lambert+gaussian fits for the elastic interactions and a Lambertian
distribution for the converted light (§4.2 of [Power-budget], ``docs/references.md``).
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import xarray as xr

from bsdfkit.core.errors import FormatError, InputError
from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.raytrace.plate import LambertGaussian, Lambertian, PhosphorPlate, PlateChannel
from bsdfkit.reduction.spectral import interaction_profile
from bsdfkit.reduction.tis import tis_table


def plate_from_scan(scan: xr.Dataset, tis: xr.Dataset | None = None, name: str = "",
                    fits: dict | None = None) -> PhosphorPlate:
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
    """
    tis = tis if tis is not None else tis_table(scan)
    grid = tuple(float(t) for t in tis["theta_i"].values)
    channels = {}
    for inter in ("bibs", "biys", "yiys"):
        for side in ("reflection", "transmission"):
            values = tuple(float(np.clip(tis["tis"].sel(interaction=inter, side=side, theta_i=t), 0.0, 1.0))
                           for t in grid)
            if inter == "biys":
                dists = (Lambertian(),) * len(grid)
            else:
                fit = (fits or {}).get((inter, side))
                if fit is None or fit.attrs.get("model") not in (None, "lambert+gaussian") or "sigma" not in fit:
                    prof = interaction_profile(scan, inter, side)
                    prof = prof.isel(record=np.flatnonzero(np.isfinite(prof["bsdf"].values)))
                    fit = fit_bsdf(prof, "lambert+gaussian")
                dists = tuple(LambertGaussian(rho_per_sr=float(fit["rho"].sel(theta_i=t)) / np.pi,
                                              a_per_sr=float(fit["A"].sel(theta_i=t)),
                                              sigma=float(fit["sigma"].sel(theta_i=t))) for t in grid)
            channels[f"{inter}_{side}"] = PlateChannel(values, dists)
    plate = PhosphorPlate(theta_i_deg=grid, name=name or scan.attrs.get("sample_name", ""),
                          notes=f"from {scan.attrs.get('source', '')}: bsdfkit TIS (two-arc reconstruction) and "
                                "lambert+gaussian fits", **channels)
    plate.validate()
    return plate


def recipe_measurement(recipe: str | Path) -> tuple[Path, str]:
    """The measurement folder and name that a fitting recipe names (its ``[recipe]`` table)."""
    recipe = Path(recipe)
    if not recipe.is_file():
        raise InputError("recipe not found", file=recipe, expected="a TOML recipe file")
    try:
        head = tomllib.loads(recipe.read_text(encoding="utf-8-sig")).get("recipe")
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"not valid TOML ({exc})", file=recipe) from None
    if not isinstance(head, dict) or not isinstance(head.get("measurement"), str):
        raise InputError("recipe names no measurement", file=recipe, field="recipe.measurement",
                         expected="a path to a measurement folder", got=None if not isinstance(head, dict)
                         else head.get("measurement"))
    name = head.get("name") if isinstance(head.get("name"), str) else ""
    return (recipe.parent / head["measurement"]).resolve(), name


def plate_from_recipe(recipe: str | Path) -> PhosphorPlate:
    """The phosphor plate of a recipe's measurement (for scenes with ``[top] from = "fitting/<recipe>.toml"``)."""
    measurement, name = recipe_measurement(recipe)
    return plate_from_scan(calibrate(read_scan(measurement)), name=name)
