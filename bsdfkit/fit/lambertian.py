"""A Lambertian surface model per wavelength from a measured reflectance spectrum (e.g. a Spectralon standard).

A reflectance standard is calibrated as a directional-hemispherical reflectance ρ(λ) (8°/h); assuming the
surface is Lambertian, its BSDF is ρ(λ)/π at every incidence and direction [1]_. The model is a fit-result
dataset of the registry's ``lambert`` model (:mod:`bsdfkit.models.registry`) with a wavelength dimension:
:func:`at_wavelength` gives the dataset at one wavelength, which :func:`bsdfkit.tables.export.export` writes
like any fit, and :func:`band_weighted_reflectance` gives the reflectance a ray tracer's "blue" or "yellow"
ray sees, weighted by the spectrum of that light over a band (eq. (5) of [2]_ applied to a reflectance).

References
----------
.. [1] ``docs/references.md``, [Nicodemus] (Lambertian BRDF ρ/π).
.. [2] ``docs/references.md``, [Power-budget].
"""
from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from bsdfkit.core.conventions import ELASTIC_INTERACTION, SIDES, WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.fit import plausibility
from bsdfkit.reduction.spectral import band_sum

#: Incidences of the model [deg]: a Lambertian surface is the same at every incidence; exports need a grid.
DEFAULT_INCIDENCES_DEG: tuple[float, ...] = tuple(float(t) for t in range(0, 90, 5))


def lambertian_from_reflectance(
    wavelength_nm: ArrayLike,
    reflectance: ArrayLike,
    reflectance_std: ArrayLike | None = None,
    *,
    side: str = "reflection",
    interaction: str = ELASTIC_INTERACTION,
    theta_i_deg: Sequence[float] = DEFAULT_INCIDENCES_DEG,
    source: str = "",
) -> xr.Dataset:
    """The ``lambert`` model ρ(λ)/π of a measured reflectance (or transmittance) spectrum.

    Parameters
    ----------
    wavelength_nm
        Strictly increasing wavelengths [nm].
    reflectance
        Directional-hemispherical reflectance (or transmittance with ``side="transmission"``) [1], a fraction
        (not percent): each value must lie in [0, 1] within 3 standard uncertainties.
    reflectance_std
        Standard uncertainty per wavelength [1]; 0 when not given.
    side, interaction
        Labels of the model (``reflection``/``transmission``; ``elastic`` by default).
    theta_i_deg
        Incidence grid [deg] of the model (the values do not depend on it).
    source
        Where the spectrum came from (file name), kept in the attributes and used in messages.

    Returns
    -------
    xarray.Dataset
        ``rho`` and ``rho_std`` on (interaction, side, wavelength, theta_i), attrs ``model = "lambert"``, and the
        verdict of the plausibility gate (:func:`bsdfkit.fit.plausibility.annotate`: ``physically_possible``,
        ``determined``, ``plausible``, ``attrs['warnings']``).
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)
    std = np.zeros_like(rho) if reflectance_std is None else np.asarray(reflectance_std, dtype=np.float64)
    where = source or None
    if wl.ndim != 1 or wl.size < 2 or rho.shape != wl.shape or std.shape != wl.shape:
        raise InputError("reflectance spectrum needs matching 1-D columns", file=where, field="wavelength",
                         expected="at least 2 wavelengths with one reflectance (and uncertainty) each",
                         got=f"{wl.shape}, {rho.shape}, {std.shape}")
    if not (np.all(np.isfinite(wl)) and np.all(np.diff(wl) > 0)):
        raise InputError("wavelengths must be finite and strictly increasing", file=where, field="wavelength")
    if wl[0] < WAVELENGTH_RANGE_NM[0] or wl[-1] > WAVELENGTH_RANGE_NM[1]:
        raise InputError("wavelengths are not in nm", file=where, field="wavelength",
                         expected=f"{WAVELENGTH_RANGE_NM[0]:g}-{WAVELENGTH_RANGE_NM[1]:g} nm",
                         got=f"{wl[0]:g}-{wl[-1]:g}")
    bad = ~(np.isfinite(rho) & np.isfinite(std) & (std >= 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError("reflectance or its uncertainty is not a finite number", file=where,
                         field=f"reflectance[{wl[k]:g} nm]", got=float(rho[k]))
    outside = (rho < -3 * std) | (rho > 1 + 3 * std)
    if outside.any():
        k = int(np.argmax(outside))
        hint = " (percent? give fractions)" if np.nanmax(rho) > 1.5 else ""
        raise InputError(f"reflectance outside [0, 1] beyond its uncertainty{hint}", file=where,
                         field=f"reflectance[{wl[k]:g} nm]", expected="0..1", got=float(rho[k]))
    if side not in SIDES:
        raise ValidationError("unknown side", field="side", expected=" or ".join(SIDES), got=side)
    theta = np.asarray(theta_i_deg, dtype=np.float64)
    if theta.ndim != 1 or theta.size == 0 or np.any((theta < 0) | (theta >= 90)):
        raise ValidationError("incidence grid out of range", field="theta_i_deg", expected="angles in [0, 90) deg",
                              got=theta.tolist())
    dims = ("interaction", "side", "wavelength", "theta_i")
    grid = np.ones((1, 1, 1, theta.size))
    ds = xr.Dataset(
        {"rho": (dims, np.clip(rho, 0.0, 1.0)[None, None, :, None] * grid,
                 {"units": "1", "long_name": "Lambertian reflectance (BSDF = rho/pi)"}),
         "rho_std": (dims, std[None, None, :, None] * grid, {"units": "1"})},
        coords={"interaction": [interaction], "side": [side], "wavelength": ("wavelength", wl, {"units": "nm"}),
                "theta_i": ("theta_i", theta, {"units": "degree"})},
        attrs={"model": "lambert", "quantity": "bsdf_fit", "source": source, "warnings": json.dumps([]),
               "note": "Lambertian model of a measured reflectance spectrum (values clipped to [0, 1])"},
    )
    return plausibility.annotate(ds)


def at_wavelength(model: xr.Dataset, wavelength_nm: float) -> xr.Dataset:
    """The model at one wavelength [nm] (linear interpolation; no extrapolation): an ordinary fit result, with
    the plausibility gate's verdict at that wavelength.

    Parameters
    ----------
    model : xarray.Dataset
        A Lambertian model over ``wavelength`` (:func:`lambertian_from_reflectance`).
    wavelength_nm : float
        The wavelength [nm], within the model's range.

    Returns
    -------
    xarray.Dataset
        The fit result at that wavelength (``rho`` [-]).
    """
    wl = model["wavelength"].values
    if not (np.isfinite(wavelength_nm) and wl[0] <= wavelength_nm <= wl[-1]):
        raise InputError("wavelength outside the measured spectrum", file=model.attrs.get("source") or None,
                         field="wavelength", expected=f"{wl[0]:g}-{wl[-1]:g} nm", got=wavelength_nm)
    flags = [v for v in ("physically_possible", "determined", "plausible") if v in model]
    out = model.drop_vars(flags).interp(wavelength=float(wavelength_nm))
    out.attrs = dict(model.attrs, wavelength_nm=float(wavelength_nm))
    return plausibility.annotate(out)


def band_weighted_reflectance(model: xr.Dataset, spectrum_wavelength_nm: ArrayLike, spectrum: ArrayLike,
                              band_nm: tuple[float, float]) -> float:
    """Σ_band ρ(λ) S(λ) Δλ / Σ_band S(λ) Δλ on the spectrum's grid: the reflectance seen by light of spectrum S.

    This is the single reflectance a two-wavelength tracer gives its "blue" or "yellow" rays. The model is
    interpolated onto the spectrum's wavelengths, which must lie within the measured range.

    Parameters
    ----------
    model : xarray.Dataset
        A Lambertian model over ``wavelength``.
    spectrum_wavelength_nm : array_like
        Wavelengths of the weighting spectrum [nm].
    spectrum : array_like
        Weighting power spectrum S, any scale, ≥ 0 in the band.
    band_nm : tuple of float
        (low, high) band edges [nm].

    Returns
    -------
    float
        The weighted reflectance [-].
    """
    lam = np.asarray(spectrum_wavelength_nm, dtype=np.float64)
    s = np.asarray(spectrum, dtype=np.float64)
    wl = model["wavelength"].values
    inside = (lam >= band_nm[0]) & (lam <= band_nm[1])
    if not inside.any():
        raise InputError("no spectrum sample in the band", field="band", expected="wavelengths inside the band",
                         got=band_nm)
    if lam[inside].min() < wl[0] or lam[inside].max() > wl[-1]:
        raise InputError("the band reaches outside the measured reflectance", field="band",
                         expected=f"within {wl[0]:g}-{wl[-1]:g} nm", got=band_nm)
    if np.any(s[inside] < 0):
        raise InputError("the weighting spectrum has negative power in the band", field="spectrum",
                         expected="a power spectrum >= 0", got=float(s[inside].min()))
    rho = np.interp(lam, wl, model["rho"].isel(interaction=0, side=0, theta_i=0).values)
    total = band_sum(lam, s, band_nm)
    if not total > 0:
        raise InputError("the weighting spectrum has no power in the band", field="spectrum", got=total)
    return band_sum(lam, rho * s, band_nm) / total
