"""The TIS of any sample as one labelled Dataset: the function behind both ``bsdfkit.tis`` and ``bsdfkit tis``.

Which reduction runs is decided by what the dataset holds (:func:`bsdfkit.reduction.hemispherical.reduction_kind`):

* elastic scatter (any sample, any configuration names, one side or both, one wavelength or many): the
  directional-hemispherical reflectance/transmittance per wavelength and its band average
  (:func:`hemispherical_table`, over :func:`bsdfkit.reduction.hemispherical.hemispherical`);
* a phosphor plate of the two-wavelength approach: the TIS per interaction (bibs, biys, yiys) and side
  (:func:`bsdfkit.reduction.tis.tis_table`); its power and photon budget is :func:`budget`.

Only the requested incidence is reduced. A wavelength band is honoured by the hemispherical reduction (the
Δλ-weighted band average) and refused, with one line, by the interaction table, whose three interactions each
have their own band ([Power-budget] §2: bibs over :data:`~bsdfkit.core.conventions.EXCITATION_BAND_NM`, biys
and yiys over :data:`~bsdfkit.core.conventions.CONVERSION_BAND_NM`); it is never ignored.

The command line's JSON and text are built from the Dataset returned here (:func:`hemispherical_json`), so the
API and the CLI give the same numbers.
"""
from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import CONVERSION_BAND_NM, EXCITATION_BAND_NM, band_label
from bsdfkit.core.errors import InputError
from bsdfkit.core.records import incidences
from bsdfkit.io.jsonout import to_jsonable
from bsdfkit.reduction.budget import InteractionTable, interaction_table, require_phosphor_scan
from bsdfkit.reduction.hemispherical import HemisphericalResult, hemispherical, reduction_kind
from bsdfkit.reduction.tis import tis_table

#: What the hemispherical value of each side is.
QUANTITY = {"reflection": "directional-hemispherical reflectance",
            "transmission": "directional-hemispherical transmittance"}
#: Per-wavelength variables of the hemispherical table [fraction of the incident power] and their long names.
PER_WAVELENGTH = {"tis": "directional-hemispherical reflectance or transmittance (TIS per wavelength)",
                  "tis_std": "standard uncertainty (measurement and reconstruction)",
                  "tis_std_measurement": "standard uncertainty, measurement part",
                  "tis_std_reconstruction": "standard uncertainty, hemisphere-reconstruction part",
                  "lobe": "specular-lobe part of tis"}
#: Band-averaged variables: the name in the table → the key of :meth:`HemisphericalResult.band_average`.
BAND_AVERAGED = {"tis_band": "value", "tis_band_std": "std", "tis_band_std_measurement": "std_measurement",
                 "tis_band_std_reconstruction": "std_reconstruction", "lobe_band": "lobe"}
MODES = ("auto", "interactions", "hemispherical")


def check_band(band_nm: Sequence[float] | None, field: str = "band") -> tuple[float, float] | None:
    """A wavelength band (low, high) [nm] with finite limits, 0 < low < high ≤ 1e6, or ``None``.

    Parameters
    ----------
    band_nm : sequence of float or None
        (low, high) wavelengths [nm].
    field : str, optional
        Option named in the error.

    Returns
    -------
    tuple of float or None
        (low, high) [nm], or None.
    """
    if band_nm is None:
        return None
    try:
        lo, hi = (float(b) for b in band_nm)
    except (TypeError, ValueError):
        raise InputError("not a wavelength band", field=field, expected="(LO, HI) in nm", got=band_nm) from None
    if not (all(math.isfinite(b) and 0 < b <= 1e6 for b in (lo, hi)) and lo < hi):
        raise InputError("option out of range", field=field, expected="LO < HI, finite wavelengths in nm > 0",
                         got=tuple(band_nm))
    return lo, hi


def check_incidence(ds: xr.Dataset, incidence_deg: float | None, field: str = "incidence") -> float | None:
    """The measured incidence [deg] matching ``incidence_deg`` (within 1e-6 deg), ``None`` for ``None``.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset (:func:`bsdfkit.ingest`).
    incidence_deg : float or None
        Requested angle of incidence [deg].
    field : str, optional
        Option named in the error.

    Returns
    -------
    float or None
        The measured angle of incidence [deg], or None.
    """
    if incidence_deg is None:
        return None
    measured = incidences(ds)
    try:
        value = float(incidence_deg)
    except (TypeError, ValueError):
        value = math.nan
    match = [t for t in measured if abs(t - value) < 1e-6]
    if not match:
        raise InputError("no records at this incidence", file=ds.attrs.get("source"), field=field,
                         expected="one of " + ", ".join(f"{t:g}" for t in measured) + " deg", got=incidence_deg)
    return match[0]


def refuse_band_for_interactions(band_nm: tuple[float, float] | None, field: str = "band") -> None:
    """Refuse a user band for the interaction table (one line): each interaction has its own band.

    Parameters
    ----------
    band_nm : tuple of float or None
        (low, high) wavelengths [nm] the user asked for; None passes.
    field : str, optional
        Option named in the error.
    """
    if band_nm is not None:
        raise InputError("a band does not apply to a phosphor plate's interaction table, whose interactions each "
                         f"have their own band (bibs {band_label(EXCITATION_BAND_NM)}, biys and yiys "
                         f"{band_label(CONVERSION_BAND_NM)})", field=field,
                         expected="no band, or the hemispherical reduction per wavelength (bsdfkit tis --mode "
                                  "hemispherical)", got=band_nm)


def tis(ds: xr.Dataset, incidence_deg: float | None = None, band_nm: Sequence[float] | None = None,
        mode: str = "auto") -> xr.Dataset:
    """TIS [fraction] of any sample: hemispherical values of elastic data, the interaction TIS of a phosphor plate.

    Parameters
    ----------
    ds
        Calibrated dataset (:func:`bsdfkit.ingest`).
    incidence_deg
        Incidence angle [deg], one of the measured ones: only that incidence is reduced and ``theta_i`` becomes
        a scalar coordinate. ``None`` reduces every measured incidence.
    band_nm
        (low, high) [nm], closed: the band of the band average of the hemispherical reduction (default: the
        measured range of each configuration, side and incidence). Refused for the interaction table.
    mode
        ``"auto"`` (:func:`~bsdfkit.reduction.hemispherical.reduction_kind`), ``"interactions"`` or
        ``"hemispherical"``.

    Returns
    -------
    xarray.Dataset
        Elastic data: :func:`hemispherical_table`. Phosphor plate: ``tis``, ``tis_std``,
        ``tis_std_measurement``, ``tis_std_reconstruction`` [1] on (interaction, side, theta_i)
        (:func:`bsdfkit.reduction.tis.tis_table`).
    """
    if mode not in MODES:
        raise InputError("unknown reduction", field="mode", expected=" or ".join(MODES), got=mode)
    band = check_band(band_nm)
    theta = check_incidence(ds, incidence_deg)
    kind = reduction_kind(ds) if mode == "auto" else mode
    if kind == "interactions":
        refuse_band_for_interactions(band)
        require_phosphor_scan(ds)  # a forced mode on elastic data: say why, not "no records for 'blue'"
        table = tis_table(ds, theta_i_deg=None if theta is None else [theta])
        table.attrs["reduction"] = "interactions"
    else:
        table = hemispherical_table(ds, theta, band)
    return table if theta is None else table.isel(theta_i=0)


def measured_tis(ds: xr.Dataset, interaction: str, side: str, incidence_deg: float) -> tuple[float, float]:
    """The data's TIS [fraction] and its standard uncertainty beside a fit of one interaction profile: what
    :func:`tis` reports for that interaction (phosphor plate) or the band average over the measured range of
    the dataset's only configuration (``elastic``), at one measured incidence [deg] and side.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset (:func:`bsdfkit.ingest`).
    interaction : {"bibs", "biys", "yiys"}
        Interaction of a phosphor plate (ignored for elastic data).
    side : {"reflection", "transmission"}
        Scattering side.
    incidence_deg : float
        A measured angle of incidence [deg].

    Returns
    -------
    tis : float
        TIS [-] (fraction of the incident power).
    std : float
        Its standard uncertainty [-].
    """
    table = tis(ds, incidence_deg)
    if table.attrs.get("reduction") == "interactions":
        row = table.sel(interaction=interaction, side=side)
        return float(row["tis"]), float(row["tis_std"])
    row = table.sel(side=side).isel(config=0)
    return float(row["tis_band"]), float(row["tis_band_std"])


def budget(ds: xr.Dataset, incidence_deg: float) -> InteractionTable:
    """Table 2 of the power-budget paper at one measured incidence [deg] (a phosphor scan only).

    Elastic data is refused with one line saying why (:func:`bsdfkit.reduction.budget.require_phosphor_scan`).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated phosphor scan (configurations ``blue`` and ``yellow``).
    incidence_deg : float
        A measured angle of incidence [deg].

    Returns
    -------
    InteractionTable
        Power and photon TIS of every interaction and side [%].
    """
    require_phosphor_scan(ds)
    return interaction_table(ds, check_incidence(ds, incidence_deg))


def hemispherical_table(ds: xr.Dataset, incidence_deg: float | None = None,
                        band_nm: tuple[float, float] | None = None) -> xr.Dataset:
    """Directional-hemispherical reflectance/transmittance of elastic data as one labelled Dataset.

    Parameters
    ----------
    ds
        Calibrated dataset (record × wavelength; :func:`bsdfkit.reduction.hemispherical.hemispherical_profile`).
    incidence_deg
        A measured incidence [deg] (see :func:`check_incidence`): only it is reduced, for every configuration
        and side measured at it. ``None``: every incidence.
    band_nm
        (low, high) [nm] of the band average; ``None``: the measured range of each entry.

    Returns
    -------
    xarray.Dataset
        On (config, side, theta_i [deg], wavelength [nm]): ``tis`` (the reflectance on the reflection side,
        the transmittance on the transmission side), ``tis_std``, ``tis_std_measurement``,
        ``tis_std_reconstruction`` and ``lobe`` [1]; NaN where not measured. On (config, side, theta_i): the
        Δλ-weighted band averages ``tis_band``, ``tis_band_std``, ``tis_band_std_measurement`` (independent
        between wavelengths), ``tis_band_std_reconstruction`` (fully correlated) and ``lobe_band`` [1]. Attrs:
        ``reduction`` ("hemispherical"), ``band_nm`` (JSON: the requested band or null), ``entries`` (JSON,
        one object per reduced configuration, side and incidence: quantity, method, assumptions,
        lobe_region_deg, extrapolated_beyond_deg, band_nm, wavelengths in the band, band-averaged
        components of the error, warnings) and ``warnings`` (JSON list).
    """
    if incidence_deg is None:
        results = hemispherical(ds)
    else:
        results = []
        names = np.asarray(ds["config"].values).astype(str)
        sides = np.asarray(ds["side"].values).astype(str)
        for config in sorted(set(names)):
            for side in QUANTITY:
                on = ds.isel(record=np.flatnonzero((names == config) & (sides == side)))
                if on.sizes["record"] and any(abs(t - incidence_deg) < 1e-6 for t in incidences(on)):
                    results += hemispherical(ds, theta_i_deg=[incidence_deg], sides=(side,), configs=[config])
    return _table(ds, results, band_nm)


def _table(ds: xr.Dataset, results: list[HemisphericalResult], band: tuple[float, float] | None) -> xr.Dataset:
    configs = list(dict.fromkeys(r.config for r in results))
    sides = [s for s in QUANTITY if any(r.side == s for r in results)]
    thetas = sorted({r.theta_i for r in results})
    finite = [r.wavelength[np.isfinite(r.wavelength)] for r in results]
    wavelength = np.unique(np.concatenate(finite)) if any(w.size for w in finite) else np.array([np.nan])
    shape = (len(configs), len(sides), len(thetas))
    per_wl = {k: np.full((*shape, wavelength.size), np.nan) for k in PER_WAVELENGTH}
    averaged = {k: np.full(shape, np.nan) for k in BAND_AVERAGED}
    entries = []
    for r in results:
        at = (configs.index(r.config), sides.index(r.side), thetas.index(r.theta_i))
        cols = np.searchsorted(wavelength, r.wavelength) if np.isfinite(wavelength).all() else np.array([0])
        for name, values in zip(PER_WAVELENGTH, (r.value, r.std, r.std_measurement, r.std_reconstruction,
                                                 r.lobe)):
            per_wl[name][(*at, cols)] = values
        summary = r.band_average(band)
        for name, key in BAND_AVERAGED.items():
            averaged[name][at] = summary[key]
        entries.append({"config": r.config, "side": r.side, "theta_i_deg": r.theta_i, "quantity": QUANTITY[r.side],
                        "method": r.method, "assumptions": r.assumptions, "lobe_region_deg": r.lobe_region_deg,
                        "extrapolated_beyond_deg": r.extrapolated_beyond_deg, "band_nm": summary["band_nm"],
                        "wavelengths": summary["wavelengths"], "components": summary["components"],
                        "warnings": r.warnings})
    dims = ("config", "side", "theta_i")
    out = xr.Dataset({**{k: ((*dims, "wavelength"), v) for k, v in per_wl.items()},
                      **{k: (dims, v) for k, v in averaged.items()}},
                     coords={"config": configs, "side": sides, "theta_i": thetas, "wavelength": wavelength})
    for name, text in PER_WAVELENGTH.items():
        out[name].attrs.update(units="1", long_name=text)
    for name, key in BAND_AVERAGED.items():
        out[name].attrs.update(units="1", long_name="band average of " + ("lobe" if key == "lobe" else "tis")
                               + ("" if key in ("value", "lobe") else ", " + PER_WAVELENGTH["tis_" + key]))
    out["theta_i"].attrs["units"] = "deg"
    out["wavelength"].attrs["units"] = "nm"
    out.attrs.update(reduction="hemispherical", quantity="directional-hemispherical reflectance/transmittance",
                     units="1 (fraction of incident power)", source=str(ds.attrs.get("source", "")),
                     band_nm=_json(None if band is None else list(band)), entries=_json(entries),
                     warnings=_json([w for r in results for w in r.warnings]))
    return out


def _json(obj: Any) -> str:
    return json.dumps(to_jsonable(obj))


def hemispherical_json(table: xr.Dataset) -> dict:
    """The records of ``bsdfkit tis --json`` from a :func:`hemispherical_table` (with or without ``theta_i``).

    Parameters
    ----------
    table : xarray.Dataset
        Result of :func:`hemispherical_table`.

    Returns
    -------
    dict
        ``hemispherical``: per entry the per-wavelength ``value``, ``std``, ``std_measurement``,
        ``std_reconstruction``, ``lobe`` [1] at ``wavelength_nm`` [nm] (where measured), with labels, method and
        assumptions; ``band_averaged``: per entry the band averages; ``warnings``.
    """
    records, bands = [], []
    for e in json.loads(table.attrs["entries"]):
        at = {"config": e["config"], "side": e["side"]}
        if "theta_i" in table.dims:
            at["theta_i"] = e["theta_i_deg"]
        sub = table.sel(at)
        keep = np.isfinite(sub["tis"].values)
        labels = {"incidence_deg": e["theta_i_deg"], "side": e["side"], "config": e["config"]}
        records.append({**labels, "wavelength_nm": table["wavelength"].values[keep],
                        **{key: sub[name].values[keep] for key, name in
                           (("value", "tis"), ("std", "tis_std"), ("std_measurement", "tis_std_measurement"),
                            ("std_reconstruction", "tis_std_reconstruction"), ("lobe", "lobe"))},
                        "method": e["method"], "lobe_region_deg": e["lobe_region_deg"],
                        "extrapolated_beyond_deg": e["extrapolated_beyond_deg"], "assumptions": e["assumptions"],
                        "warnings": e["warnings"], "quantity": e["quantity"]})
        bands.append({**labels, "band_nm": e["band_nm"], "wavelengths": e["wavelengths"],
                      **{key: float(sub[name]) for name, key in BAND_AVERAGED.items()},
                      "method": e["method"], "extrapolated_beyond_deg": e["extrapolated_beyond_deg"],
                      "assumptions": e["assumptions"], "components": e["components"], "quantity": e["quantity"]})
    return {"hemispherical": records, "band_averaged": bands, "warnings": json.loads(table.attrs["warnings"])}
