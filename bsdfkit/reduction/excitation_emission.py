"""Excitation-emission reductions: the bi-spectral matrix of a monochromator scan and the plate model per
excitation wavelength (docs/spectral.md).

A measurement with a ``[[band_series]]`` (docs/raw-format.md) illuminates the plate with narrow bands centred
at λi. Calibration gives, per band and detector position, the band-averaged bi-spectral BSDF
⟨q_λ⟩(λs) = P_s(λs)/(Φ_i Ω cos θs) of eq. (10) of [Power-budget] (1/(sr·nm), per unit incident power of the
band). Stacked over the bands it is a bandpass-weighted Donaldson matrix (rows = excitation, columns =
emission): :func:`bispectral_matrix`.

Each row holds two parts (the papers' Fig. 3 of [Power-budget]):

* elastic light, only inside the incident band: there ⟨q_λ⟩ = f(λ)·p_i(λ), so the sum over the band is the
  incident-weighted mean BSDF of eq. (5) (1/sr);
* converted light, everywhere the emission reaches. Under the incident band it cannot be told from elastic
  light spectrally, so it is interpolated linearly across the elastic window (the valid incident pixels
  widened by :data:`ELASTIC_MARGIN_NM`) between the means of the :data:`ANCHOR_PIXELS` pixels on either side
  (the CIE bandpass convention: the pump is not counted twice).

Both parts are linear maps of the row (coefficient vectors over wavelength), so standard uncertainties
propagate exactly (first order; the common reference-beam scale is added by the TIS). Per side, incidence and
excitation the hemisphere integral of :func:`bsdfkit.reduction.tis.tis_from_profile` (elastic: centred on the
specular direction; converted: on the normal, §4.2 of [Power-budget]) gives the elastic and converted TIS;
the converted spectra integrated with the same reconstruction's linear weights give the emission spectrum,
turned into a photon-number pdf (eqs. (14)-(16): photons ∝ power·λ). :func:`plate_spectral_model` returns
the result in the file format of docs/spectral.md.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import FormatError, InputError, NumericalError, ValidationError
from bsdfkit.core.records import incidences
from bsdfkit.core.spectra import photon_pdf_from_power
from bsdfkit.core.version import __version__
from bsdfkit.io import netcdf
from bsdfkit.reduction.spectral import SpectrumLike, band_sum, mean_wavelength, spectrum_on
from bsdfkit.reduction.tis import TIS, tis_from_profile

#: ``attrs['quantity']`` of the plate model dataset, and its format version (docs/spectral.md).
QUANTITY = "plate_spectral_model"
FORMAT_VERSION = 1
#: Width added on each side of the valid incident pixels to make the elastic window [nm].
ELASTIC_MARGIN_NM = 2.0
#: Pixels on each side of the elastic window whose mean anchors the interpolated converted spectrum.
ANCHOR_PIXELS = 3
#: Coverage factor of the physical checks: a value is "above 1" or "below 0" only beyond this many σ.
CHECK_SIGMA = 3.0
#: What identifies a detector position (the record coordinates shared by every band).
POSITION = ("theta_i", "phi_i", "theta_s", "phi_s", "side", "arc")
MODEL_VARIABLES = ("elastic_tis", "elastic_tis_std", "converted_tis", "converted_tis_std", "emission_pdf",
                   "photon_yield")


# ------------------------------------------------------------------------------------- the matrix
def series_configurations(ds: xr.Dataset, series: str | None = None) -> list[str]:
    """Configurations of one band series, sorted by band centre (the only series unless ``series`` names one).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan with ``band_series`` and ``excitation_wavelength`` [nm] per configuration.
    series : str, optional
        Name of the band series; None takes the only one (an InputError when there are several).

    Returns
    -------
    list of str
        Configuration names, sorted by excitation band centre [nm].
    """
    source = ds.attrs.get("source")
    if "excitation_wavelength" not in ds or "band_series" not in ds:
        raise InputError("no band series in the dataset", file=source, field="band_series",
                         expected="a measurement with a [[band_series]] (docs/raw-format.md)")
    names = [str(s) for s in ds["band_series"].values if str(s)]
    available = sorted(set(names))
    if series is None:
        if len(available) != 1:
            raise InputError("several band series: name one", file=source, field="band_series",
                             expected=" or ".join(available), got=None)
        series = available[0]
    if series not in available:
        raise InputError("unknown band series", file=source, field="band_series", expected=" or ".join(available),
                         got=series)
    sel = ds["band_series"].values == series
    configs = ds["configuration"].values[sel]
    centres = ds["excitation_wavelength"].values[sel]
    return [str(c) for _, c in sorted(zip(centres, configs))]


def _position_keys(sub: xr.Dataset) -> list[tuple]:
    """One hashable key per record: its rounded detector position and side."""
    return [(round(float(a), 6), round(float(b) % 360.0, 6), round(float(c), 6),
             0.0 if c < 1e-9 else round(float(d) % 360.0, 6), str(e))
            for a, b, c, d, e in zip(sub["theta_i"].values, sub["phi_i"].values, sub["theta_s"].values,
                                     sub["phi_s"].values, sub["side"].values)]


def bispectral_matrix(ds: xr.Dataset, series: str | None = None) -> xr.Dataset:
    """The bi-spectral BSDF of a band series over (position, excitation band, emission wavelength).

    Returns a Dataset with dims ``record`` (one detector position: coords θi, φi, θs, φs [deg], ``side``,
    ``arc``), ``wavelength_i`` (band centre, nm) and ``wavelength`` (emission, nm): ``bsdf_donaldson`` and
    ``bsdf_donaldson_std`` [1/(sr nm)] — per unit incident power of the band, ⟨q_λ⟩ of eq. (10) of
    [Power-budget]; its converted part is the Donaldson-matrix row, its elastic part f(λ)p_i(λ) sits under the
    band — and per band ``incident_spectrum`` [1/nm], ``incident_valid`` and ``incident_power_relative_std``.
    :func:`bsdfkit.reduction.spectral.bispectral_weighted_mean` reduces it to ⟨q_λ⟩ for any excitation spectrum.
    Every band must hold the same detector positions.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated excitation-emission scan (``bsdfkit.ingest``) with a ``[[band_series]]``.
    series : str, optional
        Name of the band series; None takes the only one.

    Returns
    -------
    xarray.Dataset
        The matrix described above: ``bsdf_donaldson`` [1/(sr nm)] over (record, wavelength_i [nm],
        wavelength [nm]) with its per-band incident spectra.
    """
    names = series_configurations(ds, series)
    source = ds.attrs.get("source")
    config = ds["config"].values
    first = ds.isel(record=np.flatnonzero(config == names[0]))
    keys = _position_keys(first)
    lam = ds["wavelength"].values
    q = np.empty((len(keys), len(names), lam.size))
    s = np.empty_like(q)
    for k, name in enumerate(names):
        sub = ds.isel(record=np.flatnonzero(config == name))
        index = {key: r for r, key in enumerate(_position_keys(sub))}
        missing = [key for key in keys if key not in index]
        if missing or len(index) != len(keys):
            gap = (f", missing θi={missing[0][0]:g} θs={missing[0][2]:g} φs={missing[0][3]:g} {missing[0][4]}"
                   if missing else "")
            raise InputError("bands of a series measured at different detector positions", file=source,
                             field=f"config '{name}'", expected=f"the {len(keys)} positions of '{names[0]}'",
                             got=f"{len(index)} positions{gap}")
        order = [index[key] for key in keys]
        q[:, k] = sub["bsdf_bispectral"].values[order]
        s[:, k] = sub["bsdf_bispectral_std"].values[order]
    centres = ds["excitation_wavelength"].sel(configuration=names).values.astype(np.float64)
    out = xr.Dataset(
        {"bsdf_donaldson": (("record", "wavelength_i", "wavelength"), q),
         "bsdf_donaldson_std": (("record", "wavelength_i", "wavelength"), s),
         "incident_spectrum": (("wavelength_i", "wavelength"), ds["incident_spectrum"].sel(configuration=names).values),
         "incident_valid": (("wavelength_i", "wavelength"), ds["incident_valid"].sel(configuration=names).values),
         "incident_power_relative_std": ("wavelength_i",
                                         ds["incident_power_relative_std"].sel(configuration=names).values)},
        coords={**{k: ("record", first[k].values) for k in POSITION},
                "wavelength_i": centres, "wavelength": lam.astype(np.float64),
                "configuration": ("wavelength_i", np.array(names, dtype=object))},
    )
    out["bsdf_donaldson"].attrs.update(
        units="1/(sr nm)", long_name="band-averaged bi-spectral BSDF per band of the series (eq. 10 of [Power-budget])",
        note="per unit incident power of the band; elastic part f(lambda)*p_i(lambda) under the band")
    out["bsdf_donaldson_std"].attrs["units"] = "1/(sr nm)"
    out["incident_spectrum"].attrs.update(units="1/nm", long_name="incident spectral power of the band, unit integral")
    out["wavelength_i"].attrs.update(units="nm", long_name="excitation: nominal band centre")
    out["wavelength"].attrs.update(units="nm", long_name="emission (detected) wavelength")
    for k in ("theta_i", "phi_i", "theta_s", "phi_s"):
        out[k].attrs["units"] = "deg"
    out.attrs.update(quantity="bsdf_donaldson", source=ds.attrs.get("source", ""),
                     sample_name=ds.attrs.get("sample_name", ""), band_series=str(ds["band_series"].sel(
                         configuration=names[0]).values))
    return out


# ------------------------------------------------------------------------ elastic / converted split
def _split_maps(lam: NDArray[np.float64], valid: NDArray[np.bool_],
                source: str | None, name: str) -> tuple[NDArray, NDArray, NDArray]:
    """Linear maps of one band's row: converted spectrum C (n_λ × n_λ, conv = row @ C.T), and the coefficient
    vectors of the elastic and the converted band integrals (row @ c → 1/sr)."""
    step = np.gradient(lam)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        raise NumericalError("no incident light in a band", file=source, field=f"configuration '{name}'",
                             expected="valid incident pixels")
    window = (lam >= lam[idx[0]] - ELASTIC_MARGIN_NM - 1e-9) & (lam <= lam[idx[-1]] + ELASTIC_MARGIN_NM + 1e-9)
    inside = np.flatnonzero(window)
    left = np.arange(max(inside[0] - ANCHOR_PIXELS, 0), inside[0])
    right = np.arange(inside[-1] + 1, min(inside[-1] + 1 + ANCHOR_PIXELS, lam.size))
    if left.size == 0 and right.size == 0:
        raise InputError("the incident band covers the whole wavelength grid", file=source,
                         field=f"configuration '{name}'", expected="converted light measured outside the band")
    conv = np.eye(lam.size)
    conv[inside] = 0.0
    if left.size and right.size:
        xl, xr_ = lam[left].mean(), lam[right].mean()
        t = (lam[inside] - xl) / (xr_ - xl)
        conv[np.ix_(inside, left)] = (1.0 - t)[:, None] / left.size
        conv[np.ix_(inside, right)] = t[:, None] / right.size
    else:  # at a grid end: hold the one anchor
        anchor = left if left.size else right
        conv[np.ix_(inside, anchor)] = 1.0 / anchor.size
    c_conv = conv.T @ step
    return conv, step - c_conv, c_conv


def _profile(matrix: xr.Dataset, value: NDArray, std: NDArray, rel: float) -> xr.Dataset:
    prof = xr.Dataset({"bsdf": ("record", value), "bsdf_std": ("record", std)},
                      coords={k: matrix[k] for k in POSITION})
    prof["bsdf"].attrs["units"] = "1/sr"
    prof.attrs["common_relative_std"] = rel
    return prof


def _tis(prof: xr.Dataset, sel: NDArray[np.bool_], center: str) -> TIS:
    # the single-arc components are not used here: two reconstructions fewer per band (a third of the time)
    return tis_from_profile(prof.isel(record=np.flatnonzero(sel)), center=center, singles=False)


# ------------------------------------------------------------------------------------- the model
def plate_spectral_model(ds: xr.Dataset, series: str | None = None) -> xr.Dataset:
    """The plate per excitation wavelength from a calibrated excitation-emission measurement.

    ``ds`` is a calibrated scan (``bsdfkit.ingest``) with a ``[[band_series]]``. Returns the dataset of
    docs/spectral.md: dims ``side`` (reflection = back into the cavity, transmission = out of the module),
    ``incidence`` [deg], ``excitation`` [nm, band centres], ``emission`` [nm, the uniform spectrometer grid];
    ``elastic_tis``/``converted_tis`` (side, incidence, excitation) [1] (power scattered elastically / converted
    power leaving into that hemisphere per incident power: eqs. (7), (13) of [Power-budget]) with ``_std``;
    ``emission_pdf`` (excitation, emission) [1/nm], the photon-number pdf of the converted light,
    Σ pdf·Δλ = 1 with Δλ = numpy.gradient(emission); ``photon_yield`` (incidence, excitation) [1], converted
    photons per incident photon.

    Raises :class:`ValidationError` (one line) when elastic + converted TIS or the photon yield exceeds 1 by
    more than :data:`CHECK_SIGMA` standard uncertainties, or when the negative part of an emission spectrum
    is more than its noise explains (noise is removed and its share kept in ``emission_pdf_clipped_mass``).
    A band whose converted TIS is not above CHECK_SIGMA·σ at every incidence converts nothing measurable: its
    pdf row, converted TIS and photon yield are 0.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated excitation-emission scan with a ``[[band_series]]``.
    series : str, optional
        Name of the band series; None takes the only one.

    Returns
    -------
    xarray.Dataset
        The plate model described above (TIS [-], ``emission_pdf`` [1/nm], ``photon_yield`` [-]).
    """
    source = ds.attrs.get("source", "")
    matrix = bispectral_matrix(ds, series)
    lam = matrix["wavelength"].values
    step = np.gradient(lam)
    if not np.allclose(step, step[0], rtol=1e-9, atol=1e-9):
        raise InputError("emission grid not uniform", file=source, field="wavelength",
                         expected="a uniform spectrometer grid", got=f"steps {step.min():g}..{step.max():g} nm")
    centres = matrix["wavelength_i"].values
    angles = incidences(matrix)
    grid = (float(lam[0]), float(lam[-1]))
    sides = matrix["side"].values
    shape = (len(SIDES), len(angles), centres.size)
    el, el_s, cv, cv_s = (np.full(shape, np.nan) for _ in range(4))
    pdf = np.zeros((centres.size, lam.size))
    yield_ = np.full((len(angles), centres.size), np.nan)
    clipped = np.zeros(centres.size)
    names = matrix["configuration"].values
    parts = []  # per band: elastic and converted profiles, converted spectrum per record
    for k, name in enumerate(names):
        row = matrix["bsdf_donaldson"].values[:, k]
        row_s = matrix["bsdf_donaldson_std"].values[:, k]
        conv_map, c_el, c_cv = _split_maps(lam, matrix["incident_valid"].values[k], source, str(name))
        rel = float(matrix["incident_power_relative_std"].values[k])
        finite = np.isfinite(row).all(axis=1)
        values = np.where(finite[:, None], row, 0.0)
        var = np.where(finite[:, None], row_s, 0.0) ** 2
        elastic = _profile(matrix, np.where(finite, values @ c_el, np.nan), np.sqrt(var @ c_el**2), rel)
        converted = _profile(matrix, np.where(finite, values @ c_cv, np.nan), np.sqrt(var @ c_cv**2), rel)
        parts.append((elastic, converted, values @ conv_map.T))
    densities = np.zeros((centres.size, lam.size))
    # geometry-major: every band of a side and incidence shares one scan plan, so the reconstruction's grid
    # coefficients (cached in reduction.tis) are computed once per geometry instead of once per band
    for b, side in enumerate(SIDES):
        for a, th in enumerate(angles):
            sel = (sides == side) & np.isclose(matrix["theta_i"].values, th, atol=1e-6)
            for k, (elastic, converted, spectrum) in enumerate(parts):
                t_el, t_cv = _tis(elastic, sel, "specular"), _tis(converted, sel, "normal")
                el[b, a, k], el_s[b, a, k] = t_el.value, t_el.std
                cv[b, a, k], cv_s[b, a, k] = t_cv.value, t_cv.std
                densities[k] += spectrum[sel].T @ t_cv.weights  # the converted profile's linear weights
    for k, name in enumerate(names):
        density = densities[k]
        total = cv[:, :, k].sum(axis=0)
        total_std = np.hypot(*cv_s[:, :, k])
        if not np.all(total > CHECK_SIGMA * total_std):  # nothing (measurable) converts: an all-zero row
            cv[:, :, k] = 0.0
            yield_[:, k] = 0.0
            _check_budget(el[:, :, k], el_s[:, :, k], 0.0 * total, total_std, yield_[:, k], angles, centres[k], source)
            continue
        photons = density * lam
        norm = band_sum(lam, photons, grid)
        # Where nothing is emitted the spectrum is noise about 0; a pdf cannot be negative, so the negative part
        # is removed and its share recorded, unless it is more than white noise of the spectrum's own scatter
        # explains (dark frames above the signal). The dark-mean error common to all records of an exposure
        # makes the propagated per-pixel σ too small for this, hence the empirical σ from second differences
        # (robust: 1.4826·MAD; Var(Δ²x) = 6σ² for white noise). Pure noise on n pixels has a negative part of
        # mean n·σ/√(2π) and standard deviation ≈ 0.58·σ·√n (times Δλ).
        negative = band_sum(lam, np.clip(-photons, 0.0, None), grid)
        clipped[k] = negative / norm
        noise = 1.4826 * np.median(np.abs(np.diff(photons, 2))) / np.sqrt(6.0)
        allowed = noise * step[0] * (lam.size / np.sqrt(2 * np.pi) + CHECK_SIGMA * 0.58 * np.sqrt(lam.size))
        if negative > allowed:
            j = int(np.argmin(photons))
            raise ValidationError("emission spectrum negative beyond the noise", file=source,
                                  field=f"configuration '{name}'",
                                  expected=f"a negative part within what the spectrum's noise explains "
                                           f"({allowed / norm:.2%} of the photons)",
                                  got=f"{clipped[k]:.2%} (lowest at {lam[j]:g} nm)")
        pdf[k] = photon_pdf_from_power(lam, np.clip(density, 0.0, None), grid)  # clip(S)·λ = clip(S·λ): λ > 0
        incident = matrix["incident_spectrum"].isel(wavelength_i=k)
        per_photon = mean_wavelength(incident, grid) * band_sum(lam, pdf[k] / lam, grid)
        yield_[:, k] = total / per_photon
        _check_budget(el[:, :, k], el_s[:, :, k], total, total_std, yield_[:, k], angles, centres[k], source)
    if not (np.isfinite(el).all() and np.isfinite(cv).all()):
        raise NumericalError("a TIS could not be reconstructed", file=source, field="elastic_tis/converted_tis",
                             expected="finite values at every side, incidence and excitation")
    return _model_dataset(ds, matrix, angles, _ModelArrays(el, el_s, cv, cv_s, pdf, yield_, clipped))


def _check_budget(el: NDArray, el_s: NDArray, conv: NDArray, conv_s: NDArray, yield_: NDArray,
                  angles: list[float], centre: float, source: str) -> None:
    """Elastic + converted ≤ 1 and photon yield ≤ 1, both within CHECK_SIGMA standard uncertainties."""
    total = el.sum(axis=0) + conv
    std = np.sqrt((el_s**2).sum(axis=0) + conv_s**2)
    for a, th in enumerate(angles):
        if total[a] > 1.0 + CHECK_SIGMA * std[a]:
            raise ValidationError("plate scatters more power than it receives", file=source,
                                  field=f"incidence {th:g} deg, excitation {centre:g} nm",
                                  expected=f"elastic + converted TIS ≤ 1 (+{CHECK_SIGMA:g}σ = "
                                           f"{CHECK_SIGMA * std[a]:.2g})",
                                  got=round(float(total[a]), 4))
        y_std = yield_[a] * conv_s[a] / conv[a] if conv[a] > 0 else 0.0
        if yield_[a] > 1.0 + CHECK_SIGMA * y_std:
            raise ValidationError("more converted photons than incident photons", file=source,
                                  field=f"incidence {th:g} deg, excitation {centre:g} nm",
                                  expected=f"photon yield ≤ 1 (+{CHECK_SIGMA:g}σ = {CHECK_SIGMA * y_std:.2g})",
                                  got=round(float(yield_[a]), 4))


class _ModelArrays(NamedTuple):
    """The reduced arrays of :func:`plate_spectral_model`, in the layout of its dataset."""

    el: NDArray       # elastic TIS (side, incidence, excitation) [-]
    el_s: NDArray     # its standard uncertainty [-]
    cv: NDArray       # converted TIS (side, incidence, excitation) [-]
    cv_s: NDArray     # its standard uncertainty [-]
    pdf: NDArray      # emission photon pdf (excitation, emission) [1/nm]
    yield_: NDArray   # photon yield (incidence, excitation) [-]
    clipped: NDArray  # negative share removed from each pdf row (excitation) [-]


def _model_dataset(ds: xr.Dataset, matrix: xr.Dataset, angles: list[float], arrays: _ModelArrays) -> xr.Dataset:
    """The plate model dataset of docs/spectral.md from the reduced arrays, with units and provenance."""
    el, el_s, cv, cv_s, pdf, yield_, clipped = arrays
    dims = ("side", "incidence", "excitation")
    manifest = json.loads(ds.attrs.get("manifest_json", "{}"))
    provenance = {
        "function": "bsdfkit.reduction.excitation_emission.plate_spectral_model", "bsdfkit_version": __version__,
        "measurement": ds.attrs.get("source", ""), "sample_name": ds.attrs.get("sample_name", ""),
        "synthetic": bool(ds.attrs.get("synthetic", 0)), "band_series": matrix.attrs["band_series"],
        "configurations": [str(c) for c in matrix["configuration"].values],
        "measurement_command": manifest.get("provenance_command", ""),
        "elastic_margin_nm": ELASTIC_MARGIN_NM, "anchor_pixels": ANCHOR_PIXELS, "check_sigma": CHECK_SIGMA,
    }
    out = xr.Dataset(
        {"elastic_tis": (dims, el), "elastic_tis_std": (dims, el_s), "converted_tis": (dims, cv),
         "converted_tis_std": (dims, cv_s), "emission_pdf": (("excitation", "emission"), pdf),
         "photon_yield": (("incidence", "excitation"), yield_),
         "emission_pdf_clipped_mass": ("excitation", clipped)},
        coords={"side": list(SIDES), "incidence": np.asarray(angles, dtype=np.float64),
                "excitation": matrix["wavelength_i"].values.astype(np.float64),
                "emission": matrix["wavelength"].values.astype(np.float64)},
    )
    notes = {
        "elastic_tis": ("1", "power scattered elastically into the hemisphere per incident power at the excitation"),
        "elastic_tis_std": ("1", "standard uncertainty of elastic_tis (measurement and reconstruction)"),
        "converted_tis": ("1", "converted power leaving into the hemisphere per incident power (eqs. 7, 13 of "
                               "[Power-budget])"),
        "converted_tis_std": ("1", "standard uncertainty of converted_tis (measurement and reconstruction)"),
        "emission_pdf": ("1/nm", "photon-number pdf of the converted light; sum(pdf * gradient(emission)) = 1; "
                                 "all zero where nothing converts"),
        "photon_yield": ("1", "converted photons (both sides) per incident photon"),
        "emission_pdf_clipped_mass": ("1", "negative noise removed from the pdf before normalising (its share)"),
    }
    for name, (units, long_name) in notes.items():
        out[name].attrs.update(units=units, long_name=long_name)
    out["side"].attrs.update(units="1", long_name="reflection: back into the cavity; transmission: out of the module")
    out["incidence"].attrs.update(units="deg", long_name="incidence polar angle from the plate normal")
    out["excitation"].attrs.update(units="nm", long_name="excitation wavelength (band centre)")
    out["emission"].attrs.update(units="nm", long_name="emission wavelength (uniform grid)")
    out.attrs.update(quantity=QUANTITY, format_version=FORMAT_VERSION, source=ds.attrs.get("source", ""),
                     sample_name=ds.attrs.get("sample_name", ""), provenance=json.dumps(provenance, sort_keys=True),
                     units="see each variable")
    return out


# ----------------------------------------------------------------------------------- band averages
def band_averaged_tis(model: xr.Dataset, spectrum: SpectrumLike, emission_band_nm: tuple[float, float] | None = None
                      ) -> xr.Dataset:
    """The model's TIS for a broadband incident spectrum E (any SpectrumLike of :mod:`.spectral`).

    ⟨T⟩ = Σ E(λ) T(λ) Δλ / Σ E Δλ on a 0.5 nm grid, T linear in excitation between band centres; with
    ``emission_band`` only the converted power emitted inside it (the biys of eq. (13) of [Power-budget] uses
    470-740 nm). Returns ``elastic_tis`` and ``converted_tis`` (side, incidence) [1]. E must lie inside the
    excitation range of the model.

    Parameters
    ----------
    model : xarray.Dataset
        Plate model of :func:`plate_spectral_model`.
    spectrum : SpectrumLike
        Incident spectral power E over wavelength [nm] (any scale: it is normalised).
    emission_band_nm : tuple of float, optional
        (low, high) emission wavelengths [nm] that the converted power is counted in; None counts all of it.

    Returns
    -------
    xarray.Dataset
        ``elastic_tis`` and ``converted_tis`` over (side, incidence [deg]) [-].
    """
    centres = model["excitation"].values
    lam = np.arange(centres[0], centres[-1] + 1e-9, 0.5)
    weight = spectrum_on(spectrum, lam)
    fine = np.linspace(centres[0] - 200.0, centres[-1] + 200.0, 4001)
    outside = spectrum_on(spectrum, fine) * ((fine < centres[0]) | (fine > centres[-1]))
    if not weight.sum() > 0 or outside.max() > 1e-3 * weight.max():
        raise InputError("incident spectrum outside the excitation range of the model", field="spectrum",
                         expected=f"power only within {centres[0]:g}-{centres[-1]:g} nm")
    step = np.gradient(lam)
    w = xr.DataArray(weight * step / np.sum(weight * step), dims=["excitation"], coords={"excitation": lam})
    converted = model["converted_tis"]
    if emission_band_nm is not None:
        em = model["emission"].values
        power = model["emission_pdf"].values / em  # converted power spectrum ∝ photons/λ
        grid = (float(em[0]), float(em[-1]))
        share = np.array([band_sum(em, p, emission_band_nm) / band_sum(em, p, grid) if p.any() else 0.0 for p in power])
        converted = converted * xr.DataArray(share, dims=["excitation"], coords={"excitation": centres})
    out = xr.Dataset({"elastic_tis": (model["elastic_tis"].interp(excitation=lam) * w).sum("excitation"),
                      "converted_tis": (converted.interp(excitation=lam) * w).sum("excitation")})
    for name in out:
        out[name].attrs["units"] = "1"
    return out


# ----------------------------------------------------------------------------------------- file I/O
def save_plate_spectral_model(model: xr.Dataset, path: str | Path, force: bool = False) -> Path:
    """Write the model as netCDF (atomic; refuses to overwrite without ``force``): docs/spectral.md.

    Parameters
    ----------
    model : xarray.Dataset
        Plate model of :func:`plate_spectral_model`; its schema is checked first.
    path : str or pathlib.Path
        Destination file.
    force : bool
        Overwrite an existing file.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    _check_schema(model, str(path))
    return netcdf.save(model, path, force)


def load_plate_spectral_model(path: str | Path) -> xr.Dataset:
    """Read a model written by :func:`save_plate_spectral_model`; a file of another schema is a FormatError.

    Parameters
    ----------
    path : str or pathlib.Path
        netCDF file of a plate spectral model.

    Returns
    -------
    xarray.Dataset
        The plate model, as :func:`plate_spectral_model` returns it.
    """
    model = netcdf.load(path, quantity=QUANTITY)
    _check_schema(model, str(path))
    return model


def _check_schema(model: xr.Dataset, source: str) -> None:
    """A FormatError unless ``model`` has this format version, every model variable and both sides."""
    if model.attrs.get("format_version") != FORMAT_VERSION:
        raise FormatError("unsupported plate spectral model version", file=source, field="format_version",
                          expected=str(FORMAT_VERSION), got=model.attrs.get("format_version"))
    for name in MODEL_VARIABLES:
        if name not in model:
            raise FormatError("plate spectral model variable missing", file=source, field=name,
                              expected=", ".join(MODEL_VARIABLES))
    if tuple(str(s) for s in model["side"].values) != SIDES:
        raise FormatError("sides of a plate spectral model", file=source, field="side", expected=" and ".join(SIDES),
                          got=[str(s) for s in model["side"].values])
