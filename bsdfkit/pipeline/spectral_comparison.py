"""The main job's spectral comparison (issue 17, Build 4): one plate, both tracer modes, two module spectra.

From ONE excitation-emission measurement (a raw export with a ``[[band_series]]``, docs/spectral.md) the stage
builds both descriptions of the same plate — the two-wavelength plate of the papers from its blue and yellow
configurations (:func:`bsdfkit.pipeline.plate_from_scan.plate_from_scan`) and the plate spectral model from its
monochromator scan (:func:`bsdfkit.reduction.excitation_emission.plate_spectral_model`) — traces the module
device scene in both modes with the same LED spectrum, and compares the module spectra:

* spectral mode: the extracted spectrum (W/nm) with per-bin standard errors, as traced;
* two-wavelength mode, as §4.2 of [Cylindrical-module] builds it (its eq. (2) and Fig. 7): extracted blue power
  × the LED spectrum shape + extracted yellow power × the phosphor emission shape, on the same bins. The
  emission shape is this measurement's converted light at the blue configuration (both hemispheres, at the
  recipe's ``fits.emission_incidence_deg``) above the blue filter's upper edge
  (:data:`~bsdfkit.core.conventions.EXCITATION_BAND_NM`), each shape normalised to unit integral;
* their difference, the power in :data:`NEAR_PUMP_BAND_NM` and in the module yellow band
  (:data:`~bsdfkit.core.conventions.MODULE_YELLOW_BAND_NM`) of both with the relative difference and its σ, the
  direction check of §4.2 (the two-wavelength model overestimates the power near 470 nm and underestimates the
  yellow emission), LER, YBR (with band edges) and luminous efficacy of radiation of both, and the power and
  photon ledgers of the spectral trace (Stokes loss on its own line);
* the same relative difference in the sub-bands :data:`SUB_BANDS_NM` (380-459 nm, the band §4.2 names
  465-475 nm, the emission onset 480-500 nm), each with σ and the paper's direction where it states one, and
  its causes by ablation (:func:`ablations`): conversion off, re-absorption off (spectral plate, above
  :data:`ABLATION_ABOVE_NM`), and the two-wavelength plate's pump TIS averaged over the LED spectrum instead of
  the blue filter. The ablations trace ``ablation_rays`` rays each (one compiled kernel per mode).

Uncertainties: the spectral band powers carry the trace's per-ray standard errors (bins in quadrature); the
two-wavelength band powers those of the extracted blue and yellow powers, each times its shape's share of the
band (the blue-yellow covariance, −x̄_b·x̄_y/N per ray, is neglected, which overstates σ). The shapes are taken
as exact. The two traces use different seeds, so their errors are independent.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import (
    CONVERSION_BAND_NM,
    EXCITATION_BAND_NM,
    MODULE_BLUE_BAND_NM,
    MODULE_YELLOW_BAND_NM,
    RAY_YBR_DEFINITION,
    SIDES,
    band_label,
)
from bsdfkit.core.errors import InputError
from bsdfkit.io.atomic import write_text
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.pipeline.plate_from_scan import plate_from_scan
from bsdfkit.plotting.render import FigureFile
from bsdfkit.plotting.spectra import mode_spectra_figure
from bsdfkit.raytrace import trace
from bsdfkit.raytrace.plate import PhosphorPlate
from bsdfkit.raytrace.scene import Scene
from bsdfkit.raytrace.spectral import (
    PLATE_TEMPERATURE_K,
    SpectralPlateModel,
    anti_stokes_share,
    conditional_emission_pdf,
    gaussian_led_spectrum,
    led_bin_power,
    model_on_bins,
    spectral_model_from_dataset,
)
from bsdfkit.raytrace.tallies import SPECTRAL_YBR_DEFINITION
from bsdfkit.raytrace.tracer import emission_width
from bsdfkit.reduction import tis as angular
from bsdfkit.reduction.colorimetry import luminous_efficacy_of_radiation, spectral_distribution
from bsdfkit.reduction.excitation_emission import band_averaged_tis, plate_spectral_model

#: Where §4.2 of [Cylindrical-module] sees the two-wavelength spectrum too high ("near 470 nm") [nm]: the pump's
#: long-wave tail and the emission's short-wave onset, where excitation and emission overlap.
NEAR_PUMP_BAND_NM: tuple[float, float] = (460.0, 500.0)

#: Sub-bands of the comparison [nm] (issue 27): the short-wave blue, where the two plates' blue TIS differ by their
#: averaging (blue filter vs LED spectrum); the band §4.2 names ("near 470 nm"); the emission's short-wave onset.
SUB_BANDS_NM: dict[str, tuple[float, float]] = {"short_blue": (380.0, 459.0), "near_470": (465.0, 475.0),
                                                "onset": (480.0, 500.0)}
#: Every band compared, in table order.
BANDS: dict[str, tuple[float, float]] = {"short_blue": SUB_BANDS_NM["short_blue"], "near_pump": NEAR_PUMP_BAND_NM,
                                         "near_470": SUB_BANDS_NM["near_470"], "onset": SUB_BANDS_NM["onset"],
                                         "yellow": MODULE_YELLOW_BAND_NM}
#: The direction §4.2 of [Cylindrical-module] states per band: +1 two-wavelength above spectral ("overestimate …
#: near 470 nm"), −1 below ("underestimates the yellow emission"); bands it does not name are absent (0).
PAPER_DIRECTION: dict[str, int] = {"near_pump": 1, "near_470": 1, "yellow": -1}
#: The ablations' wavelength [nm]: above it the spectral plate's conversion (or its absorption) is switched off.
ABLATION_ABOVE_NM = 475.0
#: Excitation wavelengths [nm] at which the summary gives the anti-Stokes share of the emission table.
ANTI_STOKES_REPORTED_NM = (450.0, 480.0, 500.0, 520.0, 560.0)

#: The paper's observation the direction check tests.
PAPER_OBSERVATION = ("§4.2 of [Cylindrical-module]: the two-wavelength model overestimates the power near 470 nm and "
                     "underestimates the yellow emission (excitation and emission overlap; re-absorption)")


@dataclass(frozen=True)
class SpectralComparisonOptions:
    """The recipe's ``[spectral]`` table (paths resolved against the recipe).

    ``measurement``: the excitation-emission raw export; ``scene``: the device scene (its top's plate is replaced
    by this measurement's); ``rays`` per mode; ``seed`` of the two-wavelength trace (the spectral trace uses
    seed + 1). The LED spectrum is the scene's, else the Gaussian ``led_peak_nm``/``led_fwhm_nm`` [nm] (the
    recipe's ``[fits]``); ``emission_incidence_deg`` [deg] is where the emission shape is measured.
    ``incidence_deg`` [deg]: the measured incidences both plates are built from (all when empty); fewer make the
    reduction cheaper (its cost is proportional to the incidences), and one makes both plates angle-independent.
    ``ablation_rays`` per ablation trace (:func:`ablations`); ``temperature_K`` [K] the plate temperature of the
    spectral mode's thermal tail (:mod:`bsdfkit.raytrace.spectral`).
    """

    measurement: Path
    scene: Path
    rays: int = 200_000
    seed: int = 1
    led_peak_nm: float = 450.1
    led_fwhm_nm: float = 22.9
    emission_incidence_deg: float = 45.0
    incidence_deg: tuple[float, ...] = ()
    ablation_rays: int = 50_000
    temperature_K: float = PLATE_TEMPERATURE_K


@dataclass(frozen=True)
class SpectralComparison:
    """Spectra on the spectral trace's bins [nm] in W/nm (σ = standard errors), and the summary (JSON-ready)."""

    wavelength_nm: np.ndarray
    spectral: np.ndarray
    spectral_std: np.ndarray
    two_wavelength: np.ndarray
    two_wavelength_std: np.ndarray
    summary: dict

    @property
    def difference(self) -> np.ndarray:
        """Two-wavelength − spectral [W/nm]."""
        return self.two_wavelength - self.spectral

    @property
    def difference_std(self) -> np.ndarray:
        """Standard error of :attr:`difference` [W/nm] (the traces are independent)."""
        return np.hypot(self.two_wavelength_std, self.spectral_std)

    def to_csv(self) -> str:
        """The spectra, their σ and their difference as CSV text, one row per bin (wavelength [nm], W/nm)."""
        rows = zip(self.wavelength_nm, self.spectral, self.spectral_std, self.two_wavelength, self.two_wavelength_std,
                   self.difference, self.difference_std)
        return ("wavelength_nm,spectral_W_per_nm,spectral_std_W_per_nm,two_wavelength_W_per_nm,"
                "two_wavelength_std_W_per_nm,difference_W_per_nm,difference_std_W_per_nm\n"
                + "".join(f"{w:.2f}," + ",".join(f"{v:.8e}" for v in rest) + "\n" for w, *rest in rows))


def emission_shape(scan: xr.Dataset, wavelength_nm: np.ndarray, incidence_deg: float) -> np.ndarray:
    """The phosphor emission shape [1/nm] of the two-wavelength reconstruction on the bins ``wavelength_nm``.

    The measured converted light of the blue configuration at ``incidence_deg``, both hemispheres
    (:func:`bsdfkit.reduction.tis.hemispherical_spectrum`), above the blue filter's upper edge (below it the
    elastic pump dominates), negative noise set to 0, normalised to Σ shape·Δλ = 1.

    Parameters
    ----------
    scan : xarray.Dataset
        Calibrated excitation-emission scan with a ``blue`` configuration.
    wavelength_nm : numpy.ndarray
        Uniform bin centres [nm].
    incidence_deg : float
        Measured incidence the shape is taken at [deg].

    Returns
    -------
    numpy.ndarray
        The shape on the bins [1/nm].
    """
    density = sum(angular.hemispherical_spectrum(scan, "blue", incidence_deg, side) for side in SIDES)
    values = np.where(density["wavelength"].values > EXCITATION_BAND_NM[1], np.clip(density.values, 0.0, None), 0.0)
    shape = np.interp(wavelength_nm, density["wavelength"].values, values, left=0.0, right=0.0)
    return shape / (shape.sum() * (wavelength_nm[1] - wavelength_nm[0]))


def _at_incidences(scan: xr.Dataset, incidence_deg: tuple[float, ...], source: Path) -> xr.Dataset:
    """The records of ``scan`` at the given incidences [deg]; each must have been measured."""
    theta = scan["theta_i"].values
    measured = sorted({float(t) for t in np.round(theta, 6)})
    for t in incidence_deg:
        if not np.any(np.isclose(theta, t, atol=1e-6)):
            raise InputError("incidence not measured", file=source, field="spectral.incidence_deg",
                             expected="one of " + ", ".join(f"{m:g}" for m in measured), got=t)
    keep = np.any(np.isclose(theta[:, None], np.asarray(incidence_deg)[None, :], atol=1e-6), axis=1)
    return scan.isel(record=np.flatnonzero(keep))


def _in_band(wavelength_nm: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Which bins [nm] lie inside ``band`` (edges included)."""
    return (wavelength_nm >= band[0]) & (wavelength_nm <= band[1])


def _relative(a: float, sa: float, b: float, sb: float) -> tuple[float, float]:
    """a/b − 1 and its σ (a, b independent)."""
    return a / b - 1.0, math.hypot(sa / b, a * sb / b**2)


class _Clock:
    """Seconds per step of the stage (``lap(name)`` books the time since the previous lap)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = round(self.seconds.get(name, 0.0) + now - self._last, 3)
        self._last = now


def _plates(options: SpectralComparisonOptions, clock: _Clock):
    """(all calibrated records, the records at the plates' incidences, two-wavelength plate, model dataset,
    validated spectral model) of ``options.measurement``."""
    raw = read_scan(options.measurement)
    if options.incidence_deg:  # calibrate only the records used (the plates' and the emission shape's incidences)
        raw = _at_incidences(raw, tuple(sorted({*options.incidence_deg, options.emission_incidence_deg})),
                             options.measurement)
    measured = calibrate(raw)
    scan = _at_incidences(measured, options.incidence_deg, options.measurement) if options.incidence_deg else measured
    clock.lap("ingest")
    plate = plate_from_scan(scan, name=f"{scan.attrs.get('sample_name', '')} (two-wavelength)")
    clock.lap("two_wavelength_plate")
    model_ds = plate_spectral_model(scan)
    model = spectral_model_from_dataset(model_ds, source=options.measurement)
    clock.lap("plate_spectral_model")
    return measured, plate, model_ds, model


class _Reconstruction:
    """The two-wavelength module spectrum of §4.2 of [Cylindrical-module] from a two-wavelength trace: extracted
    blue power × the LED shape + extracted yellow power × the emission shape (shapes [1/nm] on the bins)."""

    def __init__(self, two, led_shape: np.ndarray, yellow_shape: np.ndarray, lam: np.ndarray) -> None:
        self.lam, self.step = lam, float(lam[1] - lam[0])
        self.blue, self.yellow = two.extracted["blue"], two.extracted["yellow"]
        self.blue_se, self.yellow_se = two.std_err["blue"], two.std_err["yellow"]
        self.led_shape, self.yellow_shape = led_shape, yellow_shape

    def spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.blue * self.led_shape + self.yellow * self.yellow_shape,
                np.hypot(self.blue_se * self.led_shape, self.yellow_se * self.yellow_shape))

    def band(self, band: tuple[float, float]) -> tuple[float, float]:
        """Band power [W] and its σ."""
        inside = _in_band(self.lam, band)
        fb, fy = self.led_shape[inside].sum() * self.step, self.yellow_shape[inside].sum() * self.step
        return float(self.blue * fb + self.yellow * fy), float(math.hypot(self.blue_se * fb, self.yellow_se * fy))


def _band_rows(recon: _Reconstruction, sr) -> dict[str, dict]:
    """Every band of :data:`BANDS`: both powers with σ, two-wavelength / spectral − 1 with σ, z, and the paper's
    direction (+1 two-wavelength above, −1 below, 0 not stated) with ``contradicts`` (opposite beyond 1 σ)."""
    rows = {}
    for name, band in BANDS.items():
        p2, s2 = recon.band(band)
        ps, ss = sr.band_power(band)
        rel, rel_std = _relative(p2, s2, ps, ss)
        direction = PAPER_DIRECTION.get(name, 0)
        rows[name] = {"band_nm": list(band), "label": band_label(band), "two_wavelength_W": p2,
                      "two_wavelength_std_W": s2, "spectral_W": ps, "spectral_std_W": ss,
                      "relative_difference": rel, "relative_difference_std": rel_std,
                      "z": rel / rel_std if rel_std > 0 else float("nan"), "paper_direction": direction,
                      "contradicts_paper": bool(direction != 0 and direction * rel < -rel_std)}
    return rows


def compare_tracer_modes(options: SpectralComparisonOptions,
                         scene_with_plate: Callable[[Path, PhosphorPlate], Scene]) -> SpectralComparison:
    """Build both plates from ``options.measurement``, trace the device in both modes, compare the spectra and
    trace the ablations (:func:`ablations`).

    ``scene_with_plate(path, plate)`` returns the scene at ``path`` with its phosphor top's plate replaced (the
    recipe's :func:`bsdfkit.pipeline.recipe._scene_with_plate`). See the module docstring for what is computed.

    Parameters
    ----------
    options : SpectralComparisonOptions
        The recipe's ``[spectral]`` table.
    scene_with_plate : callable
        ``(path, plate) -> Scene``, the device scene with its phosphor top's plate replaced.

    Returns
    -------
    SpectralComparison
        Both module spectra on the spectral trace's bins [nm] in W/nm and the JSON-ready summary.
    """
    clock = _Clock()
    measured, plate, model_ds, model = _plates(options, clock)
    scene = scene_with_plate(options.scene, plate)
    leds = scene.leds
    if leds.spectrum is None:  # the same LED spectrum in both modes and in the reconstruction
        leds = replace(leds, spectrum_peak_nm=options.led_peak_nm, spectrum_fwhm_nm=options.led_fwhm_nm,
                       spectrum=gaussian_led_spectrum(options.led_peak_nm, options.led_fwhm_nm))
    two_scene = replace(scene, leds=leds, trace=replace(scene.trace, mode="two-wavelength"))
    spec_scene = replace(two_scene, top=replace(two_scene.top, spectral_model=model,
                                                temperature_K=options.temperature_K),
                         trace=replace(scene.trace, mode="spectral"))
    two = trace(two_scene, options.rays, options.seed)
    clock.lap("trace_two_wavelength")
    spec = trace(spec_scene, options.rays, options.seed + 1)
    clock.lap("trace_spectral")

    sr = spec.spectral
    lam = sr.wavelength_nm
    recon = _Reconstruction(two, led_bin_power(leds.spectrum, lam, leds.spectrum_file) / sr.step_nm,
                            emission_shape(measured, lam, options.emission_incidence_deg), lam)
    bands = _band_rows(recon, sr)
    # the ablations run on the main traces' compiled kernels (each kernel loaded once: about 1-2 s apiece)
    ablated = ablations(options, two_scene, spec_scene, model_ds, model, recon, clock,
                        widths={"two_wavelength": emission_width(two.chunk), "spectral": emission_width(spec.chunk)})
    shares = anti_stokes_shares(model, plate, options.temperature_K)
    results = {"bands": bands, "direction_check": _direction_check(bands), "ablations": ablated,
               "two_wavelength": _two_wavelength_summary(two, recon, sr),
               "spectral": _spectral_summary(spec, options.temperature_K, shares)}
    summary = _summary(options, leds, plate, sr, results, clock.seconds)
    return SpectralComparison(lam, sr.spectrum_W_per_nm, sr.spectrum_std_err, *recon.spectrum(), summary)


def _summary(options: SpectralComparisonOptions, leds, plate: PhosphorPlate, sr, results: dict,
             seconds: dict[str, float]) -> dict:
    """The stage's JSON-ready summary (see the module docstring); ``results`` holds its bands, direction check,
    ablations and both modes' entries, in that order."""
    lam, step = sr.wavelength_nm, sr.step_nm
    return {
        "measurement": str(options.measurement),
        "scene": str(options.scene),
        "rays": options.rays,
        "seeds": {"two_wavelength": options.seed, "spectral": options.seed + 1},
        "led_spectrum": ({"peak_nm": leds.spectrum_peak_nm, "fwhm_nm": leds.spectrum_fwhm_nm}
                         if leds.spectrum_file is None else {"file": leds.spectrum_file}),
        "emission_shape": (f"measured converted light of the blue configuration at {options.emission_incidence_deg:g}"
                           f" deg, both hemispheres, above {EXCITATION_BAND_NM[1]:g} nm, unit integral"),
        "bins_nm": [float(lam[0]), float(lam[-1]), step],
        "plate_incidences_deg": list(plate.theta_i_deg),
        **results,
        "LER_definition": "extracted / emitted LED power",
        "stage_seconds": seconds,
    }


def _direction_check(bands: dict[str, dict]) -> dict:
    """The §4.2 direction check of the band rows: near-pump over, yellow under, no sub-band against it."""
    over = bands["near_pump"]["relative_difference"] > 0
    under = bands["yellow"]["relative_difference"] < 0
    # the direction holds only where no sub-band with a paper direction goes against it beyond its σ (issue #27:
    # the 460-500 nm headline must not hide the 465-475 nm band the paper names)
    against = [k for k, b in bands.items() if b["contradicts_paper"]]
    return {"observation": PAPER_OBSERVATION, "near_pump_overestimated": bool(over),
            "yellow_underestimated": bool(under), "holds": bool(over and under and not against),
            "contradicting_bands": against}


def _efficacy(lam: np.ndarray, values: np.ndarray, name: str) -> float:
    """Luminous efficacy of radiation [lm/W] of a spectrum on the bins ``lam`` [nm]."""
    return luminous_efficacy_of_radiation(spectral_distribution(lam, values, name))


def _two_wavelength_summary(two, recon: _Reconstruction, sr) -> dict:
    """The summary's ``two_wavelength`` entry: the trace's powers and ratios and its reconstructed spectrum's."""
    blue2, blue2_std = recon.band(MODULE_BLUE_BAND_NM)
    yellow2, yellow2_std = recon.band(MODULE_YELLOW_BAND_NM)
    spectrum2 = recon.spectrum()[0]
    return {
        "extracted_W": dict(two.extracted), "std_err_W": {"blue": recon.blue_se, "yellow": recon.yellow_se},
        "LER": two.LER, "LER_std": two.std_err["LER"],
        "YBR_rays": two.YBR, "YBR_rays_std": two.std_err["YBR"], "YBR_rays_definition": RAY_YBR_DEFINITION,
        "YBR_spectrum": yellow2 / blue2,
        "YBR_spectrum_std": yellow2 / blue2 * math.hypot(yellow2_std / yellow2, blue2_std / blue2),
        "YBR_spectrum_definition": SPECTRAL_YBR_DEFINITION.replace("spectral mode", "reconstructed spectrum"),
        "luminous_efficacy_lm_per_W": _efficacy(sr.wavelength_nm, spectrum2, "two-wavelength module spectrum"),
        "spectrum_integral_W": float(spectrum2.sum() * sr.step_nm), "ledger_error": two.ledger_error}


def _spectral_summary(spec, temperature_K: float, shares: dict) -> dict:
    """The summary's ``spectral`` entry: the spectral trace's powers, ratios, ledgers and anti-Stokes shares."""
    sr = spec.spectral
    return {
        "extracted_W": dict(spec.extracted), "LER": spec.LER, "LER_std": spec.std_err["LER"],
        "YBR": spec.YBR, "YBR_std": spec.std_err["YBR"], "YBR_definition": SPECTRAL_YBR_DEFINITION,
        "luminous_efficacy_lm_per_W": _efficacy(sr.wavelength_nm, sr.spectrum_W_per_nm,
                                                "spectral-mode module spectrum"),
        "spectrum_integral_W": float(sr.spectrum_W_per_nm.sum() * sr.step_nm), "ledger": sr.ledger,
        "photon_capped_cells": len(sr.capped), "extrapolated_bins_nm": sr.to_dict()["extrapolated_bins_nm"],
        "plate_temperature_K": temperature_K, "anti_stokes_share": shares}


def anti_stokes_shares(model: SpectralPlateModel, plate: PhosphorPlate | None, temperature_K: float) -> dict:
    """Share of converted photons that leave at a shorter wavelength than they were absorbed at, per excitation
    wavelength of :data:`ANTI_STOKES_REPORTED_NM` (nearest bin): the data's emission rows (``data``) and the
    conditional rows the tracer samples at ``temperature_K`` [K] (``conditional``).

    Parameters
    ----------
    model : SpectralPlateModel
        The tracer's spectral plate model.
    plate : PhosphorPlate or None
        Plate whose bins the model is put on (None: the model's own).
    temperature_K : float
        Plate temperature of the thermal tail [K].

    Returns
    -------
    dict
        ``excitation_nm`` [nm], ``data`` and ``conditional`` shares [-] and ``temperature_K`` [K].
    """
    _, _, pdf = model_on_bins(model, plate)
    lam = model.emission_nm
    data, cond = anti_stokes_share(pdf), anti_stokes_share(conditional_emission_pdf(pdf, lam, temperature_K))
    rows = [int(np.argmin(np.abs(lam - x))) for x in ANTI_STOKES_REPORTED_NM]
    return {"excitation_nm": [float(lam[k]) for k in rows], "data": [float(data[k]) for k in rows],
            "conditional": [float(cond[k]) for k in rows], "temperature_K": float(temperature_K)}


def _with_excitations(model: SpectralPlateModel, points: tuple[float, ...]) -> SpectralPlateModel:
    """The model with excitation grid points added at ``points`` [nm] (values interpolated linearly, as the
    tracer interpolates between excitations), so a change from one point on is sharp on the bins."""
    x = model.excitation_nm
    new = np.union1d(x, [p for p in points if x[0] < p < x[-1]])
    idx = np.clip(np.searchsorted(x, new, side="right") - 1, 0, x.size - 2)
    t = np.clip((new - x[idx]) / (x[idx + 1] - x[idx]), 0.0, 1.0)

    def interp(a: np.ndarray) -> np.ndarray:  # along the excitation axis (the last for TIS, the first for pdf)
        return (1.0 - t) * a[..., idx] + t * a[..., idx + 1]

    pdf = (1.0 - t)[:, None] * model.emission_pdf[idx] + t[:, None] * model.emission_pdf[idx + 1]
    return replace(model, excitation_nm=new, elastic_tis=interp(model.elastic_tis),
                   converted_tis=interp(model.converted_tis), emission_pdf=pdf)


def ablated_model(model: SpectralPlateModel, kind: str, above_nm: float = ABLATION_ABOVE_NM) -> SpectralPlateModel:
    """The spectral model with one cause switched off at excitations above ``above_nm`` [nm] (a grid point is
    added at the bin just above it, so bins ≤ ``above_nm`` keep their values).

    ``"conversion"``: nothing converts (the photons it converted are absorbed); ``"reabsorption"``: the plate
    does not absorb its own light — the photons it converted are scattered elastically instead, on the same side
    (its other losses are kept).

    Parameters
    ----------
    model : SpectralPlateModel
        The tracer's spectral plate model.
    kind : str
        ``"conversion"`` or ``"reabsorption"``.
    above_nm : float
        Excitation wavelength above which the cause is off [nm].

    Returns
    -------
    SpectralPlateModel
        The ablated model (no capped cells).
    """
    m = _with_excitations(model, (above_nm, above_nm + 1.0))
    off = (m.excitation_nm > above_nm)[None, None, :]
    converted = np.where(off, 0.0, m.converted_tis)
    elastic = m.elastic_tis
    if kind == "reabsorption":
        step = m.step_nm
        inv = (m.emission_pdf * step / m.emission_nm[None, :]).sum(axis=1)
        photons = np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), 0.0) / m.excitation_nm  # λ̃/λ per excitation
        elastic = np.where(off, elastic + m.converted_tis * photons[None, None, :], elastic)
    elif kind != "conversion":
        raise ValueError(f"unknown ablation {kind!r}")
    return replace(m, elastic_tis=elastic, converted_tis=converted, capped=())


def led_averaged_plate(plate: PhosphorPlate, model_ds: xr.Dataset, led_spectrum) -> PhosphorPlate:
    """The two-wavelength plate with its pump channels (bibs, biys) scaled at every incidence so that at the
    model's incidence they equal the spectral model's TIS averaged over the LED spectrum instead of the blue
    filter's (biys: converted light in :data:`~bsdfkit.core.conventions.CONVERSION_BAND_NM`, as measured).

    Parameters
    ----------
    plate : PhosphorPlate
        The two-wavelength plate.
    model_ds : xarray.Dataset
        Plate spectral model dataset (:func:`~bsdfkit.reduction.excitation_emission.plate_spectral_model`); its
        first incidence [deg] is where the TIS are matched.
    led_spectrum : tuple of array_like
        (wavelength [nm], relative spectral power [-]) of the LEDs.

    Returns
    -------
    PhosphorPlate
        The plate with its bibs and biys TIS [-] rescaled.
    """
    wl, values = led_spectrum
    spectrum = xr.DataArray(np.asarray(values, dtype=np.float64), dims=["wavelength"],
                            coords={"wavelength": np.asarray(wl, dtype=np.float64)})
    elastic = band_averaged_tis(model_ds, spectrum)["elastic_tis"]
    converted = band_averaged_tis(model_ds, spectrum, CONVERSION_BAND_NM)["converted_tis"]
    theta = float(model_ds["incidence"].values[0])
    grid = np.asarray(plate.theta_i_deg, dtype=float)
    channels = {}
    for inter, values in (("bibs", elastic), ("biys", converted)):
        for side in SIDES:
            ch = plate.channel(f"{inter}_{side}")
            tis = np.asarray(ch.tis, dtype=float)
            target = float(values.sel(side=side).isel(incidence=0))
            scale = target / float(np.interp(theta, grid, tis))
            channels[f"{inter}_{side}"] = replace(ch, tis=tuple(float(v) for v in tis * scale))
    return replace(plate, **channels)


def ablations(options, two_scene: Scene, spec_scene: Scene, model_ds: xr.Dataset, model: SpectralPlateModel,
              recon: _Reconstruction, clock: _Clock, widths: dict[str, int] | None = None) -> dict:
    """The causes of the mode difference by ablation, all at ``options.ablation_rays`` rays with the main
    traces' seeds, so every row traces the main traces' first rays (common random numbers): the differences
    between a row and ``reference`` are the cause's, not noise. The rows of a mode share one compiled kernel
    (same effects, emission width and parameter shapes); ``widths`` (mode → emission width, ``"two_wavelength"``
    and ``"spectral"``) runs them on the main traces' kernels instead of kernels of their own width: loading a
    kernel costs more than the unused emissions of the wider one (about 1-2 s against a few hundredths).

    ``reference``: both modes as in the main job; ``conversion`` / ``reabsorption``: the spectral plate without
    conversion / without re-absorption above :data:`ABLATION_ABOVE_NM` (:func:`ablated_model`); ``led_spectrum``:
    the two-wavelength plate with its pump TIS averaged over the LED spectrum instead of the blue filter
    (:func:`led_averaged_plate`). The σ of a row are those of its own two traces.

    Parameters
    ----------
    options : SpectralComparisonOptions
        The recipe's ``[spectral]`` table (``ablation_rays``, ``seed``).
    two_scene, spec_scene : Scene
        The main traces' scenes, two-wavelength and spectral mode.
    model_ds : xarray.Dataset
        Plate spectral model dataset.
    model : SpectralPlateModel
        The same model as the tracer uses it.
    recon : _Reconstruction
        The main two-wavelength reconstruction (its shapes [1/nm] and bins [nm] are reused).
    clock : _Clock
        Books the seconds [s] of each ablation.
    widths : dict, optional
        Mode → emission width of the main trace's kernel [-]; None compiles kernels of their own width.

    Returns
    -------
    dict
        Row name → description, rays, seeds and the band rows of :data:`BANDS`.
    """
    n = options.ablation_rays
    seeds = {"two_wavelength": options.seed, "spectral": options.seed + 1}
    widths = widths or {}

    def on_kernel(sc, mode: str):
        # the main trace's kernel emits `width` rays per call: the ablation's chunks must not be larger (a run of
        # fewer main rays than ablation rays has a narrower kernel); results do not depend on the chunk
        width = widths.get(mode)
        chunk = None if width is None else min(int(sc.trace.chunk), width)
        return trace(sc, n, seeds[mode], chunk=chunk, width=width)

    def spectral(model_: SpectralPlateModel):
        return on_kernel(replace(spec_scene, top=replace(spec_scene.top, spectral_model=model_)), "spectral").spectral

    def two_wavelength(plate: PhosphorPlate) -> _Reconstruction:
        r = on_kernel(replace(two_scene, top=replace(two_scene.top, plate=plate)), "two_wavelength")
        return _Reconstruction(r, recon.led_shape, recon.yellow_shape, recon.lam)

    two, spec = two_wavelength(two_scene.top.plate), spectral(model)
    clock.lap("ablation_reference")
    rows = {"reference": ("no ablation: the main traces' first rays", two, spec)}
    for kind, what in (("conversion", f"spectral plate: no conversion above {ABLATION_ABOVE_NM:g} nm"),
                       ("reabsorption", f"spectral plate: no re-absorption above {ABLATION_ABOVE_NM:g} nm (the "
                                        "photons it converted there scattered elastically)")):
        rows[kind] = (what, two, spectral(ablated_model(model, kind)))
        clock.lap(f"ablation_{kind}")
    rows["led_spectrum"] = ("two-wavelength plate: pump TIS (bibs, biys) averaged over the LED spectrum instead of "
                            "the blue filter",
                            two_wavelength(led_averaged_plate(two_scene.top.plate, model_ds, two_scene.leds.spectrum)),
                            spec)
    clock.lap("ablation_led_spectrum")
    return {k: {"description": what, "rays": n, "seeds": seeds, "bands": _band_rows(rc, sr)}
            for k, (what, rc, sr) in rows.items()}


def comparison_outputs(result: SpectralComparison) -> dict[str, Callable[[Path, bool], object]]:
    """The stage's files (name → writer(path, force)): the figure and the spectra as CSV.

    Parameters
    ----------
    result : SpectralComparison
        Result of :func:`compare_tracer_modes`.

    Returns
    -------
    dict
        File name → ``writer(path, force)``.
    """
    fig = mode_spectra_figure(result.wavelength_nm, result.spectral, result.spectral_std, result.two_wavelength,
                              result.two_wavelength_std, {"near 470 nm": NEAR_PUMP_BAND_NM,
                                                          "module yellow": MODULE_YELLOW_BAND_NM})
    csv = result.to_csv()
    return {"spectral_comparison.png": FigureFile(fig),
            "spectral_comparison.csv": lambda p, force: write_text(p, csv, force)}


def comparison_lines(summary: dict) -> list[str]:
    """The run log's lines for the comparison (sizes with σ, direction check, ledger, seconds).

    Parameters
    ----------
    summary : dict
        ``SpectralComparison.summary``.

    Returns
    -------
    list of str
        The lines, without newlines.
    """
    b, chk = summary["bands"], summary["direction_check"]
    sp, tw = summary["spectral"], summary["two_wavelength"]
    led = sp["ledger"]["power_W"]
    source = Path(summary["measurement"]).name
    return [
        f"spectral vs two-wavelength mode ({summary['rays']} rays each, one plate from {source}): "
        f"{b['near_pump']['label']} {100 * b['near_pump']['relative_difference']:+.1f} ± "
        f"{100 * b['near_pump']['relative_difference_std']:.1f} %, yellow {b['yellow']['label']} "
        f"{100 * b['yellow']['relative_difference']:+.1f} ± {100 * b['yellow']['relative_difference_std']:.1f} % "
        f"(two-wavelength relative to spectral); paper direction {'holds' if chk['holds'] else 'DOES NOT HOLD'}",
        f"  LER {tw['LER']:.4f} (two-wavelength) vs {sp['LER']:.4f} ± {sp['LER_std']:.4f} (spectral); "
        f"spectral ledger: Stokes loss {led['stokes']:.4f} W, power error {led['error']:.1e}, photon error "
        f"{sp['ledger']['photons_per_s']['error']:.1e}; {sum(summary['stage_seconds'].values()):.1f} s",
        "  by band: " + "; ".join(f"{r['label']} {100 * r['relative_difference']:+.1f} ± "
                                  f"{100 * r['relative_difference_std']:.1f} %" for r in b.values())
        + (f"; against §4.2: {', '.join(chk['contradicting_bands'])}" if chk.get("contradicting_bands") else ""),
        *(f"  ablation, {a['description']} ({a['rays']} rays): " + "; ".join(
            f"{r['label']} {100 * r['relative_difference']:+.1f} ± {100 * r['relative_difference_std']:.1f} %"
            for r in a["bands"].values()) for a in summary.get("ablations", {}).values()),
    ]
