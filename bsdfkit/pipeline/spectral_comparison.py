"""The main job's spectral comparison (issue 17, Build 4): one plate, both tracer modes, two module spectra.

From ONE excitation-emission measurement (a raw export with a ``[[band_series]]``, docs/spectral.md) the stage
builds both descriptions of the same plate — the two-wavelength plate of the papers from its blue and yellow
configurations (:func:`bsdfkit.raytrace.plate_from_scan.plate_from_scan`) and the plate spectral model from its
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
  photon ledgers of the spectral trace (Stokes loss on its own line).

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
from colour import SpectralDistribution

from bsdfkit.core.conventions import (
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
from bsdfkit.plotting.figures import save_figure
from bsdfkit.plotting.spectra import mode_spectra_figure
from bsdfkit.raytrace import trace
from bsdfkit.raytrace.plate import PhosphorPlate
from bsdfkit.raytrace.plate_from_scan import plate_from_scan
from bsdfkit.raytrace.scene import Scene
from bsdfkit.raytrace.spectral import gaussian_led_spectrum, led_bin_power, spectral_model_from_dataset
from bsdfkit.raytrace.tallies import SPECTRAL_YBR_DEFINITION
from bsdfkit.reduction import tis as angular
from bsdfkit.reduction.colorimetry import luminous_efficacy_of_radiation
from bsdfkit.reduction.excitation_emission import plate_spectral_model

#: Where §4.2 of [Cylindrical-module] sees the two-wavelength spectrum too high ("near 470 nm") [nm]: the pump's
#: long-wave tail and the emission's short-wave onset, where excitation and emission overlap.
NEAR_PUMP_BAND_NM: tuple[float, float] = (460.0, 500.0)

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
    """

    measurement: Path
    scene: Path
    rays: int = 200_000
    seed: int = 1
    led_peak_nm: float = 450.1
    led_fwhm_nm: float = 22.9
    emission_incidence_deg: float = 45.0
    incidence_deg: tuple[float, ...] = ()


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
        return np.hypot(self.two_wavelength_std, self.spectral_std)

    def to_csv(self) -> str:
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
    return (wavelength_nm >= band[0]) & (wavelength_nm <= band[1])


def _relative(a: float, sa: float, b: float, sb: float) -> tuple[float, float]:
    """a/b − 1 and its σ (a, b independent)."""
    return a / b - 1.0, math.hypot(sa / b, a * sb / b**2)


def compare_tracer_modes(options: SpectralComparisonOptions,
                         scene_with_plate: Callable[[Path, PhosphorPlate], Scene]) -> SpectralComparison:
    """Build both plates from ``options.measurement``, trace the device in both modes, compare the spectra.

    ``scene_with_plate(path, plate)`` returns the scene at ``path`` with its phosphor top's plate replaced (the
    recipe's :func:`bsdfkit.pipeline.recipe._scene_with_plate`). See the module docstring for what is computed.
    """
    seconds: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds[name] = round(now - clock, 3)
        clock = now

    raw = read_scan(options.measurement)
    if options.incidence_deg:  # calibrate only the records used (the plates' and the emission shape's incidences)
        raw = _at_incidences(raw, tuple(sorted({*options.incidence_deg, options.emission_incidence_deg})),
                             options.measurement)
    measured = calibrate(raw)
    scan = _at_incidences(measured, options.incidence_deg, options.measurement) if options.incidence_deg else measured
    lap("ingest")
    plate = plate_from_scan(scan, name=f"{scan.attrs.get('sample_name', '')} (two-wavelength)")
    lap("two_wavelength_plate")
    model = spectral_model_from_dataset(plate_spectral_model(scan), source=options.measurement)
    lap("plate_spectral_model")

    scene = scene_with_plate(options.scene, plate)
    leds = scene.leds
    if leds.spectrum is None:  # the same LED spectrum in both modes and in the reconstruction
        leds = replace(leds, spectrum_peak_nm=options.led_peak_nm, spectrum_fwhm_nm=options.led_fwhm_nm,
                       spectrum=gaussian_led_spectrum(options.led_peak_nm, options.led_fwhm_nm))
    two_scene = replace(scene, leds=leds, trace=replace(scene.trace, mode="two-wavelength"))
    spec_scene = replace(two_scene, top=replace(two_scene.top, spectral_model=model),
                         trace=replace(scene.trace, mode="spectral"))
    two = trace(two_scene, options.rays, options.seed)
    lap("trace_two_wavelength")
    spec = trace(spec_scene, options.rays, options.seed + 1)
    lap("trace_spectral")

    sr = spec.spectral
    lam, step = sr.wavelength_nm, sr.step_nm
    led_shape = led_bin_power(leds.spectrum, lam, leds.spectrum_file) / step
    yellow_shape = emission_shape(measured, lam, options.emission_incidence_deg)
    blue_W, yellow_W = two.extracted["blue"], two.extracted["yellow"]
    blue_se, yellow_se = two.std_err["blue"], two.std_err["yellow"]
    recon = blue_W * led_shape + yellow_W * yellow_shape
    recon_std = np.hypot(blue_se * led_shape, yellow_se * yellow_shape)

    def two_band(band: tuple[float, float]) -> tuple[float, float]:
        inside = _in_band(lam, band)
        fb, fy = led_shape[inside].sum() * step, yellow_shape[inside].sum() * step
        return float(blue_W * fb + yellow_W * fy), float(math.hypot(blue_se * fb, yellow_se * fy))

    bands = {}
    for name, band in (("near_pump", NEAR_PUMP_BAND_NM), ("yellow", MODULE_YELLOW_BAND_NM)):
        p2, s2 = two_band(band)
        ps, ss = sr.band_power(band)
        rel, rel_std = _relative(p2, s2, ps, ss)
        bands[name] = {"band_nm": list(band), "label": band_label(band), "two_wavelength_W": p2,
                       "two_wavelength_std_W": s2, "spectral_W": ps, "spectral_std_W": ss,
                       "relative_difference": rel, "relative_difference_std": rel_std,
                       "z": rel / rel_std if rel_std > 0 else float("nan")}
    over = bands["near_pump"]["relative_difference"] > 0
    under = bands["yellow"]["relative_difference"] < 0
    blue2, blue2_std = two_band(MODULE_BLUE_BAND_NM)
    yellow2, yellow2_std = two_band(MODULE_YELLOW_BAND_NM)

    def efficacy(values: np.ndarray, name: str) -> float:
        return luminous_efficacy_of_radiation(SpectralDistribution(dict(zip(lam.tolist(), values.tolist())),
                                                                   name=name))

    summary = {
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
        "bands": bands,
        "direction_check": {"observation": PAPER_OBSERVATION, "near_pump_overestimated": bool(over),
                            "yellow_underestimated": bool(under), "holds": bool(over and under)},
        "two_wavelength": {
            "extracted_W": dict(two.extracted), "std_err_W": {"blue": blue_se, "yellow": yellow_se},
            "LER": two.LER, "LER_std": two.std_err["LER"],
            "YBR_rays": two.YBR, "YBR_rays_std": two.std_err["YBR"], "YBR_rays_definition": RAY_YBR_DEFINITION,
            "YBR_spectrum": yellow2 / blue2,
            "YBR_spectrum_std": yellow2 / blue2 * math.hypot(yellow2_std / yellow2, blue2_std / blue2),
            "YBR_spectrum_definition": SPECTRAL_YBR_DEFINITION.replace("spectral mode", "reconstructed spectrum"),
            "luminous_efficacy_lm_per_W": efficacy(recon, "two-wavelength module spectrum"),
            "spectrum_integral_W": float(recon.sum() * step), "ledger_error": two.ledger_error},
        "spectral": {
            "extracted_W": dict(spec.extracted), "LER": spec.LER, "LER_std": spec.std_err["LER"],
            "YBR": spec.YBR, "YBR_std": spec.std_err["YBR"], "YBR_definition": SPECTRAL_YBR_DEFINITION,
            "luminous_efficacy_lm_per_W": efficacy(sr.spectrum_W_per_nm, "spectral-mode module spectrum"),
            "spectrum_integral_W": float(sr.spectrum_W_per_nm.sum() * step), "ledger": sr.ledger,
            "photon_capped_cells": len(sr.capped), "extrapolated_bins_nm": sr.to_dict()["extrapolated_bins_nm"]},
        "LER_definition": "extracted / emitted LED power",
        "stage_seconds": seconds,
    }
    return SpectralComparison(lam, sr.spectrum_W_per_nm, sr.spectrum_std_err, recon, recon_std, summary)


def comparison_outputs(result: SpectralComparison) -> dict[str, Callable[[Path, bool], object]]:
    """The stage's files (name → writer(path, force)): the figure and the spectra as CSV."""
    fig = mode_spectra_figure(result.wavelength_nm, result.spectral, result.spectral_std, result.two_wavelength,
                              result.two_wavelength_std, {"near 470 nm": NEAR_PUMP_BAND_NM,
                                                          "module yellow": MODULE_YELLOW_BAND_NM})
    csv = result.to_csv()
    return {"spectral_comparison.png": lambda p, force: save_figure(fig, p, force),
            "spectral_comparison.csv": lambda p, force: write_text(p, csv, force)}


def comparison_lines(summary: dict) -> list[str]:
    """The run log's lines for the comparison (sizes with σ, direction check, ledger, seconds)."""
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
    ]
