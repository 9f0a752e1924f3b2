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
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.measurement.instrument import Instrument, aperture_solid_angle, aperture_solid_angle_small
from bsdfkit.measurement.raw_scan import MAX_ABS_COUNTS
from bsdfkit.measurement.schema import new_bsdf_dataset

__all__ = ["calibrate", "aperture_solid_angle", "aperture_solid_angle_small", "dark_statistics"]

#: Incident spectral power below this fraction of its peak (or below 10 standard uncertainties) is "no light".
INCIDENT_THRESHOLD = 1e-3
#: Dark-subtracted counts below −BELOW_DARK_SIGMA standard uncertainties are flagged ``below_dark``.
BELOW_DARK_SIGMA = 6.0


def dark_statistics(raw: xr.Dataset) -> dict[float, tuple[np.ndarray, np.ndarray, int]]:
    """Mean, variance (ddof=1) and frame count of the dark frames per exposure time.

    Parameters
    ----------
    raw : xarray.Dataset
        Raw scan with ``dark_counts`` (frame × wavelength) [counts] and ``dark_exposure`` per frame [s].

    Returns
    -------
    dict of float to tuple
        Exposure time [s] (rounded to 12 decimals) → (mean dark per pixel [counts], its frame-to-frame variance
        [counts²], number of frames).
    """
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


@dataclass(frozen=True)
class _Incident:
    """The reference beam per configuration (rows of ``configuration`` × ``wavelength``)."""

    power: np.ndarray  # P_i per pixel [counts/s]
    var_power: np.ndarray  # its variance
    valid: np.ndarray  # incident light present
    flux: np.ndarray  # Φ_i, band-integrated, responsivity-corrected (one per configuration)
    var_flux: np.ndarray  # its variance
    spectrum: np.ndarray  # normalised incident spectrum [1/nm]


def _incident_of(raw: xr.Dataset, name: str, darks: dict, gain: float, source: str
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P_i, its variance and the valid pixels of one configuration's reference beam."""
    sel = raw["reference_config"].values == name
    if not np.any(sel):
        raise InputError("no reference-beam frames for a configuration", file=source, field="reference_file",
                         expected=f"frames for configuration '{name}'")
    t_ref = raw["reference_exposure"].values[sel]
    counts = raw["reference_counts"].values[sel]
    _refuse_overflow(raw, name, counts, source)
    net, var, _ = _net(counts, t_ref, darks, gain, source)
    rate = (net / t_ref[:, None]).mean(axis=0)
    var_rate = (var / t_ref[:, None] ** 2).sum(axis=0) / sel.sum() ** 2
    att = float(raw["reference_attenuation"].sel(configuration=name))
    power, var_power = rate / att, var_rate / att**2
    _refuse_overflow(raw, name, counts, source, (power, var_power))
    peak = power.max()
    valid = (power > INCIDENT_THRESHOLD * peak) & (power > 10.0 * np.sqrt(var_power))
    if not valid.any():
        raise NumericalError("zero incident power in the reference beam", file=source,
                             field=f"configuration '{name}'",
                             expected="a reference spectrum above 10 standard uncertainties somewhere",
                             got=f"peak {peak:.3g} counts/s")
    return power, var_power, valid


def _reference_file(raw: xr.Dataset, name: str, source: str) -> str:
    """The reference file of configuration ``name`` as its manifest names it (``[[configuration]]``), else the scan's
    folder ``source``."""
    try:
        entries = json.loads(raw.attrs.get("manifest_json", "{}")).get("configuration", [])
        file = next(c["reference_file"] for c in entries if c.get("name") == name)
    except (ValueError, TypeError, AttributeError, KeyError, StopIteration):
        return source
    return f"{source.rstrip('/')}/{file}" if source else str(file)


def _refuse_overflow(raw: xr.Dataset, name: str, counts: np.ndarray, source: str,
                     power: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Refuse a reference beam whose counts are implausibly large (:data:`MAX_ABS_COUNTS`), or whose incident
    power (``power``: P_i and its variance per pixel, once computed) overflows: said as such, never as "zero
    incident power" (an infinite peak leaves no pixel above its 1e-3 and none above an infinite uncertainty)."""
    huge = ~np.isfinite(counts) | (np.abs(counts) > MAX_ABS_COUNTS)
    over = np.zeros(counts.shape[1], dtype=bool)
    if power is not None:
        over = ~(np.isfinite(power[0]) & np.isfinite(power[1]))
    if not (huge.any() or over.any()):
        return
    lam = raw["wavelength"].values
    k = int(np.argmax(huge.any(axis=0))) if huge.any() else int(np.argmax(over))
    biggest = float(np.nanmax(np.abs(np.where(np.isfinite(counts[:, k]), counts[:, k], np.inf))))
    what = ("reference counts implausibly large" if huge.any() else
            "reference power overflows (counts divided by a tiny exposure_s or reference_attenuation)")
    raise NumericalError(f"{what}: the incident power is not finite (an overflow, not zero light)",
                         file=_reference_file(raw, name, source),
                         field=f"configuration '{name}': reference counts at {lam[k]:g} nm",
                         expected=f"|count| <= {MAX_ABS_COUNTS:g} and a finite incident power",
                         got=f"{biggest:g} counts")


def _incident(raw: xr.Dataset, darks: dict, gain: float, source: str) -> _Incident:
    """The reference beam of every configuration, its band-integrated power Φ_i and normalised spectrum."""
    lam = raw["wavelength"].values
    resp = raw["responsivity"].values
    weights = np.gradient(lam)  # trapezoid-like Δλ per pixel (exact Δλ on a uniform grid)
    parts = [_incident_of(raw, name, darks, gain, source) for name in raw["configuration"].values]
    power, var_power, valid = (np.array([p[k] for p in parts]) for k in range(3))
    spectral = np.where(valid, power / resp, 0.0)
    flux = np.sum(spectral * weights, axis=1)
    var_flux = np.sum(np.where(valid, var_power / resp**2, 0.0) * weights**2, axis=1)
    return _Incident(power, var_power, valid, flux, var_flux, spectral / flux[:, None])


def _records(raw: xr.Dataset, inc: _Incident, instrument: Instrument, darks: dict, source: str
             ) -> dict[str, np.ndarray]:
    """The per-record values of the measurement equation: BSDF, bi-spectral BSDF, their uncertainties and noise
    floors, and the flags (``saturated``, ``below_dark``, ``grazing``)."""
    gain = float(raw.attrs["gain_e_per_count"])
    configs = list(raw["configuration"].values)
    cfg_index = np.array([configs.index(c) for c in raw["config"].values])
    t = raw["exposure"].values
    counts = raw["counts"].values
    net, var, dark_var = _net(counts, t, darks, gain, source)
    # the dark noise pooled over the pixels (a per-pixel variance from a few frames can be tiny by chance)
    pooled = np.median(dark_var, axis=1, keepdims=True)
    theta_s = np.radians(raw["theta_s"].values)
    grazing = theta_s > np.pi / 2 - 2 * instrument.half_angle_rad
    geom = instrument.solid_angle_sr * np.where(grazing, np.nan, np.cos(theta_s))[:, None]
    rate = net / t[:, None]
    var_rate = var / t[:, None] ** 2
    pi_rec = inc.power[cfg_index]
    ok = inc.valid[cfg_index] & ~grazing[:, None]
    flux = inc.flux[cfg_index]
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = np.where(ok, pi_rec * geom, np.nan)
        bsdf = rate / denom
        bsdf_var = var_rate / denom**2 + bsdf**2 * (inc.var_power[cfg_index] / pi_rec**2)
        denom_b = flux[:, None] * geom * raw["responsivity"].values[None, :]
        bisp = rate / denom_b
        bisp_var = var_rate / denom_b**2 + bisp**2 * (inc.var_flux[cfg_index] / flux**2)[:, None]
        return {"bsdf": bsdf, "bsdf_std": np.sqrt(bsdf_var), "noise_floor": np.sqrt(dark_var) / t[:, None] / denom,
                "bsdf_bispectral": bisp, "bsdf_bispectral_std": np.sqrt(bisp_var),
                "noise_floor_bispectral": np.sqrt(dark_var) / t[:, None] / denom_b,
                "saturated": counts >= float(raw.attrs["full_scale_counts"]),
                "below_dark": net < -BELOW_DARK_SIGMA * np.sqrt(np.maximum(dark_var, pooled)), "grazing": grazing}


def calibrate(raw: xr.Dataset) -> xr.Dataset:
    """Calibrate a raw scan (from :func:`bsdfkit.measurement.raw_scan.read_scan`) into a BSDF dataset.

    Returns a Dataset over ``record`` × ``wavelength`` with ``bsdf`` and ``bsdf_std`` (1/sr; NaN where there is
    no incident light at λ or the position is grazing, see ``incident_valid`` and ``grazing``),
    ``bsdf_bispectral`` and its std (1/(sr·nm)), the noise floors (noise-equivalent BSDFs), ``saturated``,
    and per configuration the normalised incident spectrum ``incident_spectrum`` (1/nm, unit integral); the
    schema of :mod:`bsdfkit.measurement.schema`.

    Parameters
    ----------
    raw : xarray.Dataset
        Raw scan: sample, dark and reference-beam counts, exposures [s], angles [deg], responsivity [-],
        instrument geometry [mm] and detector gain in its attributes.

    Returns
    -------
    xarray.Dataset
        Calibrated BSDF dataset: ``bsdf``, ``bsdf_std``, ``noise_floor`` [1/sr], ``bsdf_bispectral``, its std
        and noise floor [1/(sr·nm)], the flags ``saturated``, ``below_dark``, ``grazing``, and the incident
        spectrum [1/nm] and its relative uncertainties [-] per configuration.

    Raises
    ------
    InputError
        No dark frames at a record's exposure time, or no reference-beam frames for a configuration.
    NumericalError
        A configuration's reference beam has no pixel above 10 standard uncertainties.
    """
    source = raw.attrs.get("source", "<dataset>")
    instrument = Instrument(raw.attrs["detector_distance_mm"], raw.attrs["aperture_diameter_mm"],
                            raw.attrs["beam_diameter_mm"])
    darks = dark_statistics(raw)
    inc = _incident(raw, darks, float(raw.attrs["gain_e_per_count"]), source)
    data: dict[str, Any] = _records(raw, inc, instrument, darks, source)
    data.update(incident_spectrum=inc.spectrum,
                incident_relative_std=np.where(inc.valid, np.sqrt(inc.var_power) / np.where(inc.valid, inc.power, 1.0),
                                               np.nan),
                incident_valid=inc.valid, incident_power_relative_std=np.sqrt(inc.var_flux) / inc.flux,
                incident_band=raw["incident_band"], configuration_description=raw["configuration_description"])
    for name in ("band_series", "excitation_wavelength"):  # present for a monochromator scan only
        if name in raw:
            data[name] = raw[name]
    coords = {k: raw[k] for k in ("config", "theta_i", "phi_i", "theta_s", "phi_s", "side", "arc", "exposure",
                                  "source_line", "wavelength", "configuration", "band_edge")}
    ds = new_bsdf_dataset(data, coords, _attributes(raw, instrument, data["below_dark"], source))
    _describe(ds)
    return ds


def _attributes(raw: xr.Dataset, instrument: Instrument, below_dark: np.ndarray, source: str) -> dict[str, Any]:
    """The dataset attributes of a calibrated scan the schema does not fix: the gain, the below-dark counts."""
    geometry = {k: raw.attrs[k] for k in ("detector_distance_mm", "aperture_diameter_mm", "beam_diameter_mm")}
    return dict(
        side="reflection transmission",
        sample_name=raw.attrs.get("sample_name", ""),
        synthetic=raw.attrs.get("synthetic", 0),
        source=source,
        solid_angle_sr=instrument.solid_angle_sr,
        aperture_half_angle_deg=float(np.degrees(instrument.half_angle_rad)),
        gain_e_per_count=float(raw.attrs["gain_e_per_count"]),
        manifest_json=raw.attrs.get("manifest_json", "{}"),
        below_dark_pixels=int(below_dark.sum()),
        negative_raw_counts=int((raw["counts"].values < 0).sum()),
        **geometry,
    )


def _describe(ds: xr.Dataset) -> None:
    """The long names and notes of a calibrated scan's variables (units come from the schema)."""
    ds["bsdf"].attrs.update(long_name="BSDF", note="NaN where incident_valid is false or grazing is true")
    ds["bsdf_std"].attrs.update(long_name="standard uncertainty of bsdf (counting and dark noise)")
    ds["noise_floor"].attrs.update(long_name="noise-equivalent BSDF (dark noise)")
    ds["bsdf_bispectral"].attrs.update(long_name="band-averaged bi-spectral BSDF <q_lambda>(lambda_s)",
                                       note="eq. (10) of the power-budget paper; NaN only where grazing")
    ds["incident_spectrum"].attrs.update(long_name="incident spectral power, normalised to unit integral")
    ds["incident_relative_std"].attrs.update(
        long_name="relative standard uncertainty of the reference-beam power per pixel",
        note="common to every record of the configuration: a fully correlated scale uncertainty")
    ds["incident_power_relative_std"].attrs.update(
        long_name="relative standard uncertainty of the band-integrated incident power Φ_i",
        note="common to every bi-spectral value of the configuration")
    ds["saturated"].attrs["long_name"] = "raw counts at full scale"
    ds["below_dark"].attrs.update(long_name=f"signal more than {BELOW_DARK_SIGMA:g} standard uncertainties below "
                                            "the dark level (dark frames above the signal?)")
    ds["grazing"].attrs["long_name"] = "aperture within one diameter of the horizon; BSDF masked"


def truth_tis(ds: xr.Dataset) -> dict[str, dict[str, float]] | None:
    """The exact TIS table recorded in a synthetic data set's manifest (percent), keyed by incidence, or None.

    Parameters
    ----------
    ds : xarray.Dataset
        Raw or calibrated scan; its ``manifest_json`` attribute is read.

    Returns
    -------
    dict or None
        Angle of incidence as text (``"45"``) [deg] → TIS entry (Table 2 keys) → TIS [%]; None when the
        manifest has no ``[truth]`` table (a real measurement).
    """
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
