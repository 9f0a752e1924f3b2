"""Machine-readable summaries of scan datasets (``bsdfkit info``)."""
from __future__ import annotations

import json

import numpy as np
import xarray as xr

from bsdfkit.core.records import incidences


def describe(ds: xr.Dataset) -> dict:
    """Incidences, sides, positions per arc, wavelength range and configurations of a raw or calibrated scan.

    Parameters
    ----------
    ds : xarray.Dataset
        Raw scan (:func:`bsdfkit.measurement.raw_scan.read_scan`) or calibrated one (it then also has ``bsdf``).

    Returns
    -------
    dict
        JSON-ready summary: ``quantity``, ``sample``, ``synthetic``, ``records``, ``incidences_deg`` [deg],
        ``sides``, ``positions`` (detector positions per incidence, side and arc, counted in one configuration),
        ``wavelength_nm`` (min, max, median step [nm] and count), ``configurations`` (name, description,
        ``incident_band_nm`` [nm], records), ``instrument`` (distance and diameters [mm], ``solid_angle_sr``
        [sr] when known); for a calibrated scan ``calibration`` (counts of grazing records, saturated pixels,
        finite BSDF values, values above 10 × noise floor, negative values after dark subtraction and, when
        recorded, pixels below dark and negative raw counts); ``truth_tis_percent`` [%] when the manifest holds
        a truth.
    """
    lam = ds["wavelength"].values
    positions: dict[str, dict[str, dict[str, int]]] = {}
    for th in incidences(ds):
        at = np.isclose(ds["theta_i"].values, th, atol=1e-6)
        per_side: dict[str, dict[str, int]] = {}
        for side in sorted(set(ds["side"].values[at])):
            sel = at & (ds["side"].values == side)
            # count distinct detector positions (configurations repeat the same positions)
            first_cfg = ds["config"].values[sel][0]
            sel_cfg = sel & (ds["config"].values == first_cfg)
            arcs = ds["arc"].values[sel_cfg]
            per_side[side] = {a: int((arcs == a).sum()) for a in sorted(set(arcs))}
        positions[f"{th:g}"] = per_side
    configs = []
    for k, name in enumerate(ds["configuration"].values):
        entry = {"name": str(name), "description": str(ds["configuration_description"].values[k]),
                 "incident_band_nm": [float(x) for x in ds["incident_band"].values[k]],
                 "records": int((ds["config"].values == name).sum())}
        configs.append(entry)
    manifest = json.loads(ds.attrs.get("manifest_json", "{}"))
    out = {
        "quantity": ds.attrs.get("quantity"),
        "sample": ds.attrs.get("sample_name"),
        "synthetic": bool(ds.attrs.get("synthetic", 0)),
        "records": int(ds.sizes["record"]),
        "incidences_deg": incidences(ds),
        "sides": sorted(set(ds["side"].values.tolist())),
        "positions": positions,
        "wavelength_nm": {"min": float(lam.min()), "max": float(lam.max()),
                          "step": float(np.median(np.diff(lam))) if lam.size > 1 else None, "count": int(lam.size)},
        "configurations": configs,
        "instrument": {k: float(ds.attrs[k])
                       for k in ("detector_distance_mm", "aperture_diameter_mm", "beam_diameter_mm")},
    }
    if "solid_angle_sr" in ds.attrs:
        out["instrument"]["solid_angle_sr"] = float(ds.attrs["solid_angle_sr"])
    if "bsdf" in ds:
        finite = np.isfinite(ds["bsdf"].values)
        above = finite & (ds["bsdf"].values > 10 * ds["noise_floor"].values)
        out["calibration"] = {
            "grazing_records": int(ds["grazing"].values.sum()),
            "saturated_pixels": int(ds["saturated"].values.sum()),
            "bsdf_values": int(finite.sum()),
            "bsdf_above_10x_noise_floor": int(above.sum()),
            "negative_after_dark": int((ds["bsdf_bispectral"].values < 0).sum()),
        }
        if "below_dark" in ds:  # plausibility: dark frames above the signal, negative raw counts
            out["calibration"]["below_dark_pixels"] = int(ds["below_dark"].values.sum())
        if "negative_raw_counts" in ds.attrs:
            out["calibration"]["negative_raw_counts"] = int(ds.attrs["negative_raw_counts"])
    if "truth" in manifest:
        out["truth_tis_percent"] = manifest["truth"].get("tis_percent")
    return out
