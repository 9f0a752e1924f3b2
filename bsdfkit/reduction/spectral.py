"""Spectral reductions: weighted mean BSDFs, bi-spectral band averages, band integrals, photons.

Equation numbers refer to the power-budget paper ("Power and photon budget of a remote phosphor LED module",
[Power-budget] in docs/references.md).

* Weighted mean BSDF over an incident spectrum E (eqs. (3)-(5), (8)); only the relative shape of E matters:
  ⟨q⟩ = Σ_band q(λ) E(λ) Δλ / Σ_band E(λ) Δλ.
* Band-averaged bi-spectral BSDF (eqs. (9)-(10)): ⟨q_λ⟩(λs) = Σ_λi q_λ(λi, λs) E(λi) Δλi / Σ E Δλi. A calibrated
  scan holds it directly (``bsdf_bispectral``, for the measurement's incident spectrum); a dataset with an
  excitation axis ``wavelength_i`` (a Donaldson-style matrix ``bsdf_donaldson``) is reduced to it by
  :func:`bispectral_weighted_mean` for any excitation spectrum.
* Its average over the emission band (eqs. (11)-(12)): ⟨⟨q_λ⟩⟩ = Σ_band ⟨q_λ⟩ Δλs / ΔΛs, so that the TIS of
  eq. (13) integrates ⟨⟨q_λ⟩⟩·ΔΛs = Σ_band ⟨q_λ⟩ Δλs (:func:`bispectral_band_integral`).
* Power ↔ photons (eqs. (14)-(16)): Φ_e = Φ_photons · hc·ΣΦ_λΔλ / ΣΦ_λ λ Δλ = Φ_photons · hc/λ̄, with λ̄ the
  power-weighted mean wavelength of the spectrum (:func:`mean_photon_energy`).

Spectra cross the public API as ``colour.SpectralDistribution`` (or xarray DataArrays over ``wavelength``);
sums use the data's own wavelength grid with Δλ from :func:`numpy.gradient` (exact on uniform grids).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import CONVERSION_BAND_NM, ELASTIC_INTERACTION, INTERACTIONS, SIDES, InteractionBands
from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.core.spectra import LIGHT_C, PLANCK_H, Band, band_mask, band_sum, mean_wavelength_nm

if TYPE_CHECKING:
    import colour

__all__ = ["LIGHT_C", "PLANCK_H", "Band", "SpectrumLike", "band_sum", "band_integral", "spectrum_on",
           "to_spectral_distribution", "incident_spectrum", "weighted_mean_bsdf", "bispectral_band_integral",
           "bispectral_band_mean", "bispectral_weighted_mean", "mean_wavelength", "mean_photon_energy", "photon_ratio",
           "interaction_profile"]

SpectrumLike = "colour.SpectralDistribution | xr.DataArray"


def _is_spectral_distribution(spectrum: object) -> bool:
    # Duck-typed so that this module does not import colour-science (about 1 s, and it pulls in matplotlib):
    # the tracer reaches these reductions through the plate builder and needs no colorimetry.
    return hasattr(spectrum, "wavelengths") and hasattr(spectrum, "values") and not isinstance(spectrum, xr.DataArray)


def spectrum_on(spectrum: SpectrumLike, wavelength_nm: NDArray[np.float64]) -> NDArray[np.float64]:
    """Values of ``spectrum`` on ``wavelength`` (nm): linear interpolation, zero outside its domain.

    Parameters
    ----------
    spectrum : colour.SpectralDistribution or xarray.DataArray
        Spectrum over wavelength [nm] (a DataArray over ``wavelength``), any value unit.
    wavelength_nm : ndarray
        Wavelengths to sample at [nm].

    Returns
    -------
    ndarray
        Values at ``wavelength``, in the unit of ``spectrum``.

    Raises
    ------
    InputError
        If ``spectrum`` is of another type or has non-finite values.
    """
    if _is_spectral_distribution(spectrum):
        wl, values = spectrum.wavelengths, spectrum.values
    elif isinstance(spectrum, xr.DataArray):
        wl, values = spectrum["wavelength"].values, spectrum.values
    else:
        raise InputError("unsupported spectrum type", field="spectrum",
                         expected="colour.SpectralDistribution or xarray.DataArray over 'wavelength'",
                         got=type(spectrum).__name__)
    values = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(values)):
        raise InputError("spectrum has non-finite values", field="spectrum", expected="finite values")
    return np.interp(wavelength_nm, wl, values, left=0.0, right=0.0)


def to_spectral_distribution(da: xr.DataArray, name: str = "") -> colour.SpectralDistribution:
    """A 1-D DataArray over ``wavelength`` as a colour SpectralDistribution.

    Parameters
    ----------
    da : xarray.DataArray
        1-D spectrum over ``wavelength`` [nm].
    name : str, optional
        Name of the distribution.

    Returns
    -------
    colour.SpectralDistribution
        The same samples.
    """
    import colour  # only here: see _is_spectral_distribution

    return colour.SpectralDistribution(dict(zip(da["wavelength"].values.tolist(), da.values.tolist())), name=name)


def incident_spectrum(ds: xr.Dataset, config: str) -> colour.SpectralDistribution:
    """The measured, normalised incident spectrum of configuration ``config`` (1/nm).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan with ``incident_spectrum`` over (configuration, wavelength).
    config : str
        Configuration name (e.g. ``"blue"``).

    Returns
    -------
    colour.SpectralDistribution
        Normalised incident spectrum over wavelength [nm], values [1/nm].
    """
    return to_spectral_distribution(ds["incident_spectrum"].sel(configuration=config), name=f"incident {config}")


def _arrays(spectrum: SpectrumLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if _is_spectral_distribution(spectrum):
        return spectrum.wavelengths, spectrum.values
    return spectrum["wavelength"].values, spectrum.values


def band_integral(spectrum: SpectrumLike, band_nm: Band) -> float:
    """Σ_band S(λ) Δλ on the spectrum's own grid (:func:`band_sum`).

    Parameters
    ----------
    spectrum : colour.SpectralDistribution or xarray.DataArray
        Spectrum over wavelength [nm].
    band_nm : tuple of float
        (low, high) band [nm], inclusive.

    Returns
    -------
    float
        The integral, in the spectrum's unit times nm.
    """
    return band_sum(*_arrays(spectrum), band_nm)


def weighted_mean_bsdf(ds: xr.Dataset, config: str, band_nm: Band | None,
                       spectrum: SpectrumLike | None = None) -> xr.Dataset:
    """Spectrally weighted mean BSDF per record (eq. (5); eq. (8) for yellow), with propagated std.

    ``spectrum`` is the weighting spectrum E(λ) (its relative shape only); by default the measured incident
    spectrum of ``config``. Only pixels inside ``band`` [nm] (None: every measured wavelength, also an unknown
    NaN one) where the BSDF is defined (incident light present) are used; a band without such pixels raises
    :class:`InputError` (a band with no signal). A scan of one wavelength is its own mean (weight 1).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan (``bsdf``, ``bsdf_std`` per record and wavelength, ``incident_spectrum``).
    config : str
        Configuration whose records are averaged.
    band_nm : tuple of float or None
        (low, high) band [nm], inclusive; None for every measured wavelength.
    spectrum : colour.SpectralDistribution or xarray.DataArray, optional
        Weighting spectrum E over wavelength [nm] (relative shape only); None for the measured incident spectrum.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` on ``record`` [1/sr], with the records' angle coordinates;
        ``attrs['common_relative_std']`` [-] when the scan records the incident light's relative uncertainty.

    Raises
    ------
    InputError
        If ``config`` has no records or the band carries no incident light.
    """
    sub = ds.isel(record=np.flatnonzero(ds["config"].values == config))
    if sub.sizes["record"] == 0:
        raise InputError("no records for configuration", file=ds.attrs.get("source"), field="config", got=config)
    lam = sub["wavelength"].values
    weight = (sub["incident_spectrum"].sel(configuration=config).values if spectrum is None
              else spectrum_on(spectrum, lam))
    in_band = np.ones(lam.size, dtype=bool) if band_nm is None else band_mask(lam, band_nm)
    usable = in_band & sub["incident_valid"].sel(configuration=config).values & (weight > 0)
    if not usable.any():
        raise InputError("band with no signal: no wavelength in the band carries incident light",
                         file=ds.attrs.get("source"),
                         field="band", expected=f"overlap with the incident light of '{config}'", got=band_nm)
    # one wavelength has no spacing (np.gradient needs two): its weight is 1, the mean is its value
    w = weight * (np.gradient(lam) if lam.size > 1 else np.ones(1)) * usable
    q = sub["bsdf"].values
    s = sub["bsdf_std"].values
    defined = np.isfinite(q[:, usable]).all(axis=1)
    norm = w.sum()
    with np.errstate(invalid="ignore"):
        mean = np.where(defined, np.nansum(q * w, axis=1) / norm, np.nan)
        std = np.where(defined, np.sqrt(np.nansum((s * w) ** 2, axis=1)) / norm, np.nan)
    span = "the measured wavelengths" if band_nm is None else f"{band_nm[0]:g}-{band_nm[1]:g} nm"
    out = _profile(sub, mean, std, "1/sr", f"weighted mean BSDF over {span} (eq. 5)")
    if "incident_relative_std" in sub:
        # The reference beam divides every record alike: its noise is a common scale factor, which per-record
        # standard uncertainties (and fits that treat records as independent) cannot carry.
        rel = np.nan_to_num(sub["incident_relative_std"].sel(configuration=config).values)
        out.attrs["common_relative_std"] = float(np.sqrt(np.sum((w * rel) ** 2)) / norm)
    return out


def bispectral_band_integral(ds: xr.Dataset, config: str, band_nm: Band = CONVERSION_BAND_NM) -> xr.Dataset:
    """Σ_band ⟨q_λ⟩(λs) Δλs per record, in 1/sr: ⟨⟨q_λ⟩⟩·ΔΛs of eqs. (11)-(13).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated phosphor scan with ``bsdf_bispectral`` [1/(sr nm)] and its std.
    config : str
        Configuration whose records are integrated (the excitation, e.g. ``"blue"``).
    band_nm : tuple of float, optional
        (low, high) emission band [nm], inclusive.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` on ``record`` [1/sr], with the records' angle coordinates;
        ``attrs['common_relative_std']`` [-] when the scan records the incident power's relative uncertainty.

    Raises
    ------
    InputError
        If the band holds no wavelength of the grid.
    """
    sub = ds.isel(record=np.flatnonzero(ds["config"].values == config))
    lam = sub["wavelength"].values
    inside = band_mask(lam, band_nm)
    if not inside.any():
        raise InputError("band outside the wavelength grid", field="band", got=band_nm)
    w = np.gradient(lam) * inside
    q = sub["bsdf_bispectral"].values
    s = sub["bsdf_bispectral_std"].values
    total = np.sum(np.where(inside, q, 0.0) * w, axis=1)
    total = np.where(np.isfinite(q[:, inside]).all(axis=1), total, np.nan)
    std = np.sqrt(np.sum(np.where(inside, s, 0.0) ** 2 * w**2, axis=1))
    out = _profile(sub, total, std, "1/sr",
                   f"bi-spectral BSDF integrated over {band_nm[0]:g}-{band_nm[1]:g} nm (eq. 13)")
    if "incident_power_relative_std" in sub:
        out.attrs["common_relative_std"] = float(sub["incident_power_relative_std"].sel(configuration=config))
    return out


def bispectral_band_mean(ds: xr.Dataset, config: str, band_nm: Band = CONVERSION_BAND_NM) -> xr.Dataset:
    """⟨⟨q_λ⟩⟩ per record (eq. (12)), in 1/(sr·nm): the band integral divided by ΔΛs = high − low.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated phosphor scan with ``bsdf_bispectral`` [1/(sr nm)] and its std.
    config : str
        Configuration whose records are averaged (the excitation, e.g. ``"blue"``).
    band_nm : tuple of float, optional
        (low, high) emission band [nm], inclusive.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` on ``record`` [1/(sr nm)], as :func:`bispectral_band_integral` otherwise.
    """
    out = bispectral_band_integral(ds, config, band_nm)
    width = band_nm[1] - band_nm[0]
    out["bsdf"] = out["bsdf"] / width
    out["bsdf_std"] = out["bsdf_std"] / width
    out["bsdf"].attrs.update(units="1/(sr nm)", long_name="<<q_lambda>> (eq. 12)")
    out["bsdf_std"].attrs["units"] = "1/(sr nm)"
    return out


def bispectral_weighted_mean(donaldson: xr.DataArray, excitation: SpectrumLike) -> xr.DataArray:
    """Reduce a Donaldson-style bi-spectral BSDF q_λ(λi, λs) (dims include ``wavelength_i``) to ⟨q_λ⟩(λs), eq. (10).

    Parameters
    ----------
    donaldson : xarray.DataArray
        Bi-spectral BSDF q_λ [1/(sr nm)] with a dimension ``wavelength_i`` (excitation [nm]).
    excitation : colour.SpectralDistribution or xarray.DataArray
        Excitation spectrum E over wavelength [nm] (relative shape only).

    Returns
    -------
    xarray.DataArray
        ⟨q_λ⟩ [1/(sr nm)], the dimensions of ``donaldson`` without ``wavelength_i``.

    Raises
    ------
    InputError
        If ``donaldson`` has no ``wavelength_i`` dimension.
    NumericalError
        If the excitation spectrum has no power on the excitation grid.
    """
    if "wavelength_i" not in donaldson.dims:
        raise InputError("no excitation axis", field="wavelength_i", expected="a dimension 'wavelength_i'")
    lam_i = donaldson["wavelength_i"].values
    e = spectrum_on(excitation, lam_i) * np.gradient(lam_i)
    if not e.sum() > 0:
        raise NumericalError("excitation spectrum has no power on the excitation grid", field="excitation")
    weights = xr.DataArray(e / e.sum(), dims=["wavelength_i"], coords={"wavelength_i": lam_i})
    out = (donaldson * weights).sum("wavelength_i")
    out.attrs.update(units="1/(sr nm)", long_name="<q_lambda>(lambda_s), eq. (10)")
    return out


def mean_wavelength(spectrum: SpectrumLike, band_nm: Band) -> float:
    """Power-weighted mean wavelength λ̄ = Σ Φ_λ λ Δλ / Σ Φ_λ Δλ over ``band`` (nm)
    (:func:`bsdfkit.core.spectra.mean_wavelength_nm`).

    Parameters
    ----------
    spectrum : colour.SpectralDistribution or xarray.DataArray
        Power spectrum over wavelength [nm].
    band_nm : tuple of float
        (low, high) band [nm], inclusive.

    Returns
    -------
    float
        Mean wavelength λ̄ [nm].
    """
    return mean_wavelength_nm(*_arrays(spectrum), band_nm)


def mean_photon_energy(spectrum: SpectrumLike, band_nm: Band) -> float:
    """hc·ΣΦ_λΔλ / ΣΦ_λλΔλ in joules: the factor converting photon flux to power in eqs. (14)-(15).

    Parameters
    ----------
    spectrum : colour.SpectralDistribution or xarray.DataArray
        Power spectrum over wavelength [nm].
    band_nm : tuple of float
        (low, high) band [nm], inclusive.

    Returns
    -------
    float
        Mean photon energy hc/λ̄ [J].
    """
    return PLANCK_H * LIGHT_C / (mean_wavelength(spectrum, band_nm) * 1e-9)


def photon_ratio(incident: SpectrumLike, incident_band_nm: Band, scattered: SpectrumLike,
                 scattered_band_nm: Band) -> float:
    """TIS_photons / TIS_power for a converting interaction, eq. (16): E_ph,incident / E_ph,scattered = λ̄s/λ̄i.

    Parameters
    ----------
    incident : colour.SpectralDistribution or xarray.DataArray
        Incident power spectrum over wavelength [nm].
    incident_band_nm : tuple of float
        (low, high) band of ``incident`` [nm], inclusive.
    scattered : colour.SpectralDistribution or xarray.DataArray
        Scattered (converted) power spectrum over wavelength [nm].
    scattered_band_nm : tuple of float
        (low, high) band of ``scattered`` [nm], inclusive.

    Returns
    -------
    float
        λ̄s/λ̄i [-].
    """
    return mean_photon_energy(incident, incident_band_nm) / mean_photon_energy(scattered, scattered_band_nm)


def _profile(sub: xr.Dataset, value: NDArray, std: NDArray, units: str, name: str) -> xr.Dataset:
    keep = ["config", "theta_i", "phi_i", "theta_s", "phi_s", "side", "arc"]
    out = xr.Dataset({"bsdf": ("record", value), "bsdf_std": ("record", std)},
                     coords={k: sub[k] for k in keep if k in sub.coords})
    out["bsdf"].attrs.update(units=units, long_name=name)
    out["bsdf_std"].attrs["units"] = units
    out.attrs.update({k: v for k, v in sub.attrs.items() if k in (
        "source", "sample_name", "aperture_half_angle_deg", "solid_angle_sr", "detector_distance_mm",
        "aperture_diameter_mm", "beam_diameter_mm")})
    out["bsdf_std"].attrs["note"] = ("per-record (independent) part; see attrs['common_relative_std'] "
                                     "for the shared scale")
    out.attrs["quantity"] = "bsdf_profile"
    return out



def _only_configuration(ds: xr.Dataset) -> str:
    names = [str(n) for n in ds["configuration"].values] if "configuration" in ds else sorted(
        {str(c) for c in ds["config"].values})
    if len(names) != 1:
        raise InputError("the elastic interaction needs one configuration or a named one", file=ds.attrs.get("source"),
                         field="configuration", expected="one configuration (or configs={'elastic': NAME})",
                         got=", ".join(names))
    return names[0]


def interaction_profile(ds: xr.Dataset, interaction: str, side: str | None = None,
                        bands: InteractionBands | None = None, configs: dict[str, str] | None = None) -> xr.Dataset:
    """The per-record BSDF profile (1/sr) of one interaction of the two-wavelength approach, or of any sample.

    bibs: eq. (5) weighted mean over the blue band with the blue configuration; yiys: eq. (8) over the yellow
    band with the yellow configuration; biys: eq. (13) integrand ⟨⟨q_λ⟩⟩·ΔΛs from the blue configuration.
    ``elastic``: any sample (a measured table, a vendor file, a monochrome scan): the weighted mean over the
    whole measured range (or ``bands.elastic_nm``) of the dataset's only configuration (or
    ``configs["elastic"]``). Optionally restricted to one ``side``. ``bands``: the bands [nm]
    (:class:`bsdfkit.core.conventions.InteractionBands`, default the power-budget filters); configuration names
    can be overridden.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan.
    interaction : str
        ``"bibs"``, ``"biys"``, ``"yiys"`` or ``"elastic"``.
    side : str, optional
        One of :data:`~bsdfkit.core.conventions.SIDES`; None keeps both.
    bands : InteractionBands, optional
        The bands [nm]; None for the power-budget filters.
    configs : dict of str to str, optional
        Configuration names by role (``blue``, ``yellow``, ``elastic``) overriding the defaults.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` on ``record`` [1/sr] (see :func:`weighted_mean_bsdf`), ``attrs['interaction']``
        set.

    Raises
    ------
    InputError
        If ``interaction`` or ``side`` is unknown, or the elastic configuration is ambiguous.
    """
    bands = bands or InteractionBands()
    configs = {"blue": "blue", "yellow": "yellow", **(configs or {})}
    if interaction == "bibs":
        out = weighted_mean_bsdf(ds, configs["blue"], bands.blue_nm)
    elif interaction == "yiys":
        out = weighted_mean_bsdf(ds, configs["yellow"], bands.yellow_nm)
    elif interaction == "biys":
        out = bispectral_band_integral(ds, configs["blue"], bands.yellow_nm)
    elif interaction == ELASTIC_INTERACTION:
        config = configs.get(ELASTIC_INTERACTION) or _only_configuration(ds)
        lam = ds["wavelength"].values
        # default: the measured range; None (every wavelength) where it is unknown (a NaN monochrome wavelength)
        band = bands.elastic_nm or (
            (float(lam.min()), float(lam.max())) if np.all(np.isfinite(lam)) else None)
        out = weighted_mean_bsdf(ds, config, band)
    else:
        raise InputError("unknown interaction", file=ds.attrs.get("source"), field="interaction",
                         expected=" or ".join((*INTERACTIONS, ELASTIC_INTERACTION)), got=interaction)
    out.attrs["interaction"] = interaction
    if side is not None:
        if side not in SIDES:
            raise InputError("unknown side", field="side", expected=" or ".join(SIDES), got=side)
        held = sorted(set(map(str, out["side"].values)))
        if side not in held:  # name what the data hold, not an empty selection
            raise InputError("the data hold no records for this side", file=ds.attrs.get("source"), field="--side",
                             expected=" or ".join(held) or "records on some side", got=side)
        out = out.isel(record=np.flatnonzero(out["side"].values == side))
    return out

