"""Raw counts → calibrated BSDF (1/sr) and bi-spectral BSDF (1/(sr·nm)) with standard uncertainties.

Measurement equation ([ASTM-E2387] form of eq. (1) of [Power-budget]; keys in docs/references.md, assumptions
in docs/raw-format.md "Measurement equation"):

    f(λ) = P_s(λ) / (P_i(λ) · Ω · cos θs),      P_s = (C_s − D)/t_s,   P_i = (C_ref − D)/(t_ref · T_ND)

with C raw counts, D the mean dark at the same exposure, T_ND the transmittance of the attenuator used for the
reference (direct-beam) spectrum, taken by the same detector so the spectral responsivity cancels pixel by
pixel, and Ω the exact solid angle of the circular aperture (:func:`aperture_solid_angle`).

Wavelength conversion (eqs. (2), (9)-(10) of [Power-budget]): light scattered at λs comes from the whole
incident band, so the quantity measured per configuration is the band-averaged bi-spectral BSDF

    ⟨q_λ⟩(λs) = [P_s(λs)/R(λs)] / (Φ_i · Ω · cos θs),   Φ_i = Σ_λi P_i(λi)/R(λi) Δλi

in 1/(sr·nm); here the detector's relative spectral responsivity R does not cancel and is taken from the
manifest. Inside the incident band ⟨q_λ⟩ = f(λ)·p_i(λ) with p_i the normalised incident spectrum.

Negative values after dark subtraction are kept (ISO 11146-3 clause 3.1, [ISO-11146-3]): clipping would bias
every mean upward. Pixels more than ``BELOW_DARK_SIGMA`` standard uncertainties *below* the dark level are not
noise but a sign of dark frames above the signal (wrong dark file, warmer detector, light leak in the darks):
they are flagged ``below_dark`` and counted (attributes ``below_dark_pixels``, ``negative_raw_counts``), and
``bsdfkit info``/``run`` report the counts. Positions whose aperture reaches within one aperture diameter of the horizon
(θs > 90° − 2·atan(a/d)) are flagged ``grazing`` and their BSDF is masked, never infinite.

Uncertainty ([GUM], uncorrelated): Var(C − D) = max(C − D, 0)/G + σ_D² + σ_D²/n_D with G the conversion gain
(e⁻/count), σ_D² the variance of the dark frames (read + dark-current noise) and n_D their number; the same for
the averaged reference frames. Only counting and dark noise are propagated; systematic terms (Ω, alignment,
linearity, stray light, T_ND; listed in docs/raw-format.md) are not.
"""
from __future__ import annotations

import json

import numpy as np
import xarray as xr

from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.measurement.instrument import Instrument, aperture_solid_angle, aperture_solid_angle_small

__all__ = ["calibrate", "aperture_solid_angle", "aperture_solid_angle_small", "dark_statistics"]

#: Incident spectral power below this fraction of its peak (or below 10 standard uncertainties) is "no light".
INCIDENT_THRESHOLD = 1e-3
#: Dark-subtracted counts below −BELOW_DARK_SIGMA standard uncertainties are flagged ``below_dark``.
BELOW_DARK_SIGMA = 6.0


def dark_statistics(raw: xr.Dataset) -> dict[float, tuple[np.ndarray, np.ndarray, int]]:
    """Mean, variance (ddof=1) and frame count of the dark frames per exposure time."""
    out = {}
    t = raw["dark_exposure"].values
    counts = raw["dark_counts"].values
    for value in np.unique(t):
        frames = counts[np.isclose(t, value, rtol=1e-12, atol=0)]
        out[round(float(value), 12)] = (frames.mean(axis=0), frames.var(axis=0, ddof=1), frames.shape[0])
    return out


def _net(counts: np.ndarray, exposure: np.ndarray, darks: dict, gain: float, source: str) -> tuple[np.ndarray, ...]:
    """Dark-subtracted counts, their variance and the per-pixel dark noise variance (with mean-dark term)."""
    mean = np.empty_like(counts)
    var_d = np.empty_like(counts)
    n_d = np.empty(counts.shape[0])
    for k, t in enumerate(exposure):
        key = round(float(t), 12)
        if key not in darks:
            raise InputError("no dark frames for an exposure time", file=source, field="exposure_s",
                             expected="a dark at the same exposure", got=float(t))
        mean[k], var_d[k], n_d[k] = darks[key]
    net = counts - mean
    dark_var = var_d * (1.0 + 1.0 / n_d[:, None])
    var = np.clip(net, 0.0, None) / gain + dark_var
    return net, var, dark_var


def calibrate(raw: xr.Dataset) -> xr.Dataset:
    """Calibrate a raw scan (from :func:`bsdfkit.measurement.raw_scan.read_scan`) into a BSDF dataset.

    Returns a Dataset over ``record`` × ``wavelength`` with ``bsdf`` and ``bsdf_std`` (1/sr; NaN where there is
    no incident light at λ or the position is grazing, see ``incident_valid`` and ``grazing``),
    ``bsdf_bispectral`` and its std (1/(sr·nm)), the noise floors (noise-equivalent BSDFs), ``saturated``,
    and per configuration the normalised incident spectrum ``incident_spectrum`` (1/nm, unit integral).
    """
    source = raw.attrs.get("source", "<dataset>")
    instrument = Instrument(raw.attrs["detector_distance_mm"], raw.attrs["aperture_diameter_mm"],
                            raw.attrs["beam_diameter_mm"])
    gain = float(raw.attrs["gain_e_per_count"])
    full_scale = float(raw.attrs["full_scale_counts"])
    lam = raw["wavelength"].values
    darks = dark_statistics(raw)
    resp = raw["responsivity"].values
    omega = instrument.solid_angle_sr
    half = instrument.half_angle_rad

    configs = list(raw["configuration"].values)
    n_cfg, n_wl = len(configs), lam.size
    p_i = np.zeros((n_cfg, n_wl))
    var_p_i = np.zeros((n_cfg, n_wl))
    valid = np.zeros((n_cfg, n_wl), dtype=bool)
    phi = np.zeros(n_cfg)
    var_phi = np.zeros(n_cfg)
    spectrum = np.zeros((n_cfg, n_wl))
    weights = np.gradient(lam)  # trapezoid-like Δλ per pixel (exact Δλ on a uniform grid)
    for c, name in enumerate(configs):
        sel = raw["reference_config"].values == name
        if not np.any(sel):
            raise InputError("no reference-beam frames for a configuration", file=source, field="reference_file",
                             expected=f"frames for configuration '{name}'")
        t_ref = raw["reference_exposure"].values[sel]
        net, var, _ = _net(raw["reference_counts"].values[sel], t_ref, darks, gain, source)
        rate = (net / t_ref[:, None]).mean(axis=0)
        var_rate = (var / t_ref[:, None] ** 2).sum(axis=0) / sel.sum() ** 2
        att = float(raw["reference_attenuation"].sel(configuration=name))
        p_i[c] = rate / att
        var_p_i[c] = var_rate / att**2
        peak = p_i[c].max()
        valid[c] = (p_i[c] > INCIDENT_THRESHOLD * peak) & (p_i[c] > 10.0 * np.sqrt(var_p_i[c]))
        if not valid[c].any():
            raise NumericalError("zero incident power in the reference beam", file=source,
                                 field=f"configuration '{name}'",
                                 expected="a reference spectrum above 10 standard uncertainties somewhere",
                                 got=f"peak {peak:.3g} counts/s")
        power = np.where(valid[c], p_i[c] / resp, 0.0)
        phi[c] = np.sum(power * weights)
        var_phi[c] = np.sum(np.where(valid[c], var_p_i[c] / resp**2, 0.0) * weights**2)
        spectrum[c] = power / phi[c]

    cfg_index = np.array([configs.index(c) for c in raw["config"].values])
    t = raw["exposure"].values
    counts = raw["counts"].values
    net, var, dark_var = _net(counts, t, darks, gain, source)
    saturated = counts >= full_scale
    # the dark noise pooled over the pixels (a per-pixel variance from a few frames can be tiny by chance)
    pooled = np.median(dark_var, axis=1, keepdims=True)
    below_dark = net < -BELOW_DARK_SIGMA * np.sqrt(np.maximum(dark_var, pooled))
    theta_s = np.radians(raw["theta_s"].values)
    grazing = theta_s > np.pi / 2 - 2 * half
    cos = np.where(grazing, np.nan, np.cos(theta_s))
    geom = omega * cos[:, None]
    rate = net / t[:, None]
    var_rate = var / t[:, None] ** 2
    pi_rec = p_i[cfg_index]
    ok = valid[cfg_index] & ~grazing[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = np.where(ok, pi_rec * geom, np.nan)
        bsdf = rate / denom
        rel_ref = var_p_i[cfg_index] / pi_rec**2
        bsdf_var = var_rate / denom**2 + bsdf**2 * rel_ref
        floor = np.sqrt(dark_var) / t[:, None] / denom
        denom_b = phi[cfg_index][:, None] * geom * resp[None, :]
        bisp = rate / denom_b
        bisp_var = var_rate / denom_b**2 + bisp**2 * (var_phi[cfg_index] / phi[cfg_index] ** 2)[:, None]
        floor_b = np.sqrt(dark_var) / t[:, None] / denom_b

    coords = {k: raw[k] for k in ("config", "theta_i", "phi_i", "theta_s", "phi_s", "side", "arc", "exposure",
                                  "source_line")}
    ds = xr.Dataset(
        {
            "bsdf": (("record", "wavelength"), bsdf),
            "bsdf_std": (("record", "wavelength"), np.sqrt(bsdf_var)),
            "noise_floor": (("record", "wavelength"), floor),
            "bsdf_bispectral": (("record", "wavelength"), bisp),
            "bsdf_bispectral_std": (("record", "wavelength"), np.sqrt(bisp_var)),
            "noise_floor_bispectral": (("record", "wavelength"), floor_b),
            "saturated": (("record", "wavelength"), saturated),
            "below_dark": (("record", "wavelength"), below_dark),
            "grazing": ("record", grazing),
            "incident_spectrum": (("configuration", "wavelength"), spectrum),
            "incident_relative_std": (("configuration", "wavelength"),
                                      np.where(valid, np.sqrt(var_p_i) / np.where(valid, p_i, 1.0), np.nan)),
            "incident_valid": (("configuration", "wavelength"), valid),
            "incident_power_relative_std": ("configuration", np.sqrt(var_phi) / phi),
            "incident_band": raw["incident_band"],
            "configuration_description": raw["configuration_description"],
        },
        coords={**coords, "wavelength": raw["wavelength"], "configuration": raw["configuration"],
                "band_edge": raw["band_edge"]},
    )
    for name in ("band_series", "excitation_wavelength"):  # present for a monochromator scan only
        if name in raw:
            ds[name] = raw[name]
    ds["bsdf"].attrs.update(units="1/sr", long_name="BSDF", note="NaN where incident_valid is false or grazing is true")
    ds["bsdf_std"].attrs.update(units="1/sr", long_name="standard uncertainty of bsdf (counting and dark noise)")
    ds["noise_floor"].attrs.update(units="1/sr", long_name="noise-equivalent BSDF (dark noise)")
    ds["bsdf_bispectral"].attrs.update(units="1/(sr nm)",
                                       long_name="band-averaged bi-spectral BSDF <q_lambda>(lambda_s)",
                                       note="eq. (10) of the power-budget paper; NaN only where grazing")
    ds["bsdf_bispectral_std"].attrs.update(units="1/(sr nm)")
    ds["noise_floor_bispectral"].attrs.update(units="1/(sr nm)")
    ds["incident_spectrum"].attrs.update(units="1/nm", long_name="incident spectral power, normalised to unit integral")
    ds["incident_relative_std"].attrs.update(
        units="1", long_name="relative standard uncertainty of the reference-beam power per pixel",
        note="common to every record of the configuration: a fully correlated scale uncertainty")
    ds["incident_power_relative_std"].attrs.update(
        units="1", long_name="relative standard uncertainty of the band-integrated incident power Φ_i",
        note="common to every bi-spectral value of the configuration")
    ds["saturated"].attrs["long_name"] = "raw counts at full scale"
    ds["below_dark"].attrs.update(long_name=f"signal more than {BELOW_DARK_SIGMA:g} standard uncertainties below "
                                            "the dark level (dark frames above the signal?)")
    ds["grazing"].attrs["long_name"] = "aperture within one diameter of the horizon; BSDF masked"
    geometry = {k: raw.attrs[k] for k in ("detector_distance_mm", "aperture_diameter_mm", "beam_diameter_mm")}
    ds.attrs.update(
        quantity="bsdf",
        frame="sample",
        side="reflection transmission",
        units="1/sr",
        angle_convention="sample frame; source at phi_i (deg), specular at phi_s = phi_i - 180; "
                         "transmission angles from the back normal",
        sample_name=raw.attrs.get("sample_name", ""),
        synthetic=raw.attrs.get("synthetic", 0),
        source=source,
        solid_angle_sr=omega,
        aperture_half_angle_deg=float(np.degrees(half)),
        gain_e_per_count=gain,
        manifest_json=raw.attrs.get("manifest_json", "{}"),
        below_dark_pixels=int(below_dark.sum()),
        negative_raw_counts=int((counts < 0).sum()),
        **geometry,
    )
    return ds


def truth_tis(ds: xr.Dataset) -> dict[str, dict[str, float]] | None:
    """The exact TIS table recorded in a synthetic data set's manifest (percent), keyed by incidence, or None."""
    manifest = json.loads(ds.attrs.get("manifest_json", "{}"))
    truth = manifest.get("truth")
    return None if truth is None else truth.get("tis_percent")


def dark_above_signal(ds: xr.Dataset, limit: int = 6) -> str | None:
    """One line saying which records of a calibrated scan have pixels far below the dark level, or None.

    A dark frame brighter than the signal (a light leak while the darks were taken, a dark of another
    exposure) makes the net signal negative and biases every reduction of those records low; the flag
    ``below_dark`` (pixels more than :data:`BELOW_DARK_SIGMA` standard uncertainties below the dark level)
    records it, and this line says it where a person reads it.

    Parameters
    ----------
    ds
        A calibrated dataset; one without a ``below_dark`` flag (a measured table) gives None.
    limit
        At most this many source lines are listed.

    Returns
    -------
    str or None
        ``"dark frames above the signal: N of M pixels on K records (source lines …; exposures … s) lie more
        than 6 standard uncertainties below the dark level: their BSDF is biased low (flag below_dark)"``.
    """
    if "below_dark" not in ds:
        return None
    flag = np.asarray(ds["below_dark"].values, dtype=bool)
    per_record = flag.any(axis=tuple(range(1, flag.ndim)))
    if not per_record.any():
        return None
    rec = np.flatnonzero(per_record)
    lines = ds["source_line"].values[rec] if "source_line" in ds.coords else rec
    configs = ds["config"].values[rec] if "config" in ds.coords else np.array([""] * rec.size)
    groups = []
    for c in dict.fromkeys(configs.tolist()):  # per configuration (its scan file), in order of appearance
        n = [int(x) for x, cc in zip(lines, configs) if cc == c]
        text = ", ".join(map(str, n[:limit])) + (f", … ({len(n) - limit} more)" if len(n) > limit else "")
        groups.append(f"configuration {c} lines {text}" if c else f"lines {text}")
    listed = "; ".join(groups)
    exposures = ""
    if "exposure" in ds.coords:
        t = np.unique(ds["exposure"].values[rec][np.isfinite(ds["exposure"].values[rec])])
        if t.size:
            exposures = "; exposures " + ", ".join(f"{x:g}" for x in t) + " s"
    return (f"{ds.attrs.get('source', '')}: dark frames above the signal: {int(flag.sum())} of {flag.size} pixels "
            f"on {rec.size} records ({listed}{exposures}) lie more than {BELOW_DARK_SIGMA:g} standard "
            "uncertainties below the dark level: their BSDF and every reduction of them is biased low "
            "(flag below_dark)")
