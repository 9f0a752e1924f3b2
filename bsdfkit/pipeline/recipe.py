"""Fit/run recipes: ``bsdfkit run fitting/<name>.toml -o OUT/`` — the main job.

A recipe names a measurement folder and the stages to run on it. Each stage is a function of the recipe and
the products of earlier stages; it returns its part of the run summary and the files it wants written.

Everything that can be checked is checked before computing: the recipe's options (types and ranges), the trace
scene, the output folder (a folder that exists and is not empty is refused without ``force`` and replaced as a
whole with it, never when it is or holds an input; writable). The outputs are then written into a staging
folder beside the output folder and moved into place at the end (:class:`bsdfkit.io.atomic.OutputSet`), so a
failed, killed or out-of-disk run leaves the previous complete set or nothing, and a rerun after an
interruption needs no ``--force``.
"""
from __future__ import annotations

import contextlib
import gzip
import math
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import (
    COLORIMETRY_BLUE_BAND_NM,
    COLORIMETRY_YELLOW_BAND_NM,
    RAY_YBR_DEFINITION,
    SIDES,
    band_label,
)
from bsdfkit.core.errors import FormatError, InputError, NumericalError, ValidationError
from bsdfkit.core.records import incidences
from bsdfkit.fit import plausibility
from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.fit.spectrum import SPECTRUM_MODELS, fit_spectrum, reconstruct_two_band_spectrum, spectrum_model_values
from bsdfkit.io import netcdf
from bsdfkit.io.atomic import OutputSet, write_bytes, write_text
from bsdfkit.io.jsonout import dumps
from bsdfkit.io.recipe_head import recipe_head
from bsdfkit.io.text import read_toml
from bsdfkit.measurement.calibrate import BELOW_DARK_SIGMA, calibrate, truth_tis
from bsdfkit.measurement.describe import describe
from bsdfkit.measurement.manifest import read_manifest
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.models.registry import BSDF_MODELS
from bsdfkit.pipeline.helper import helper_process
from bsdfkit.pipeline.plate_from_scan import plate_from_scan
from bsdfkit.pipeline.report import READINGS, magnitude_verdict, paper_values, write_report
from bsdfkit.pipeline.spectral_comparison import (
    SpectralComparison,
    SpectralComparisonOptions,
    compare_tracer_modes,
    comparison_lines,
    comparison_outputs,
)
from bsdfkit.plotting.figures import (
    bsdf_fits_figure,
    budget_figure,
    in_plane_bsdf_figure,
    module_spectrum_figure,
    plate_incidence_figure,
    trace_studies_figure,
)
from bsdfkit.plotting.render import FigureFile, PendingPng, PngRenderer, png_results
from bsdfkit.raytrace import trace, with_values
from bsdfkit.raytrace.plate import CHANNELS
from bsdfkit.raytrace.scene import parse_scene
from bsdfkit.raytrace.spectral import PLATE_TEMPERATURE_K
from bsdfkit.raytrace.tallies import map_fields, merge_maps
from bsdfkit.raytrace.tracer import common_chunk
from bsdfkit.reduction import budget, spectral
from bsdfkit.reduction import tis as angular
from bsdfkit.reduction.colorimetry import colorimetric_summary
from bsdfkit.tables import export as exporter
from bsdfkit.tables import registry

KNOWN_SECTIONS = {
    "recipe": {"name", "measurement", "description"},
    "report": {"figure_config", "figure_wavelength_nm"},
    "reductions": {"budget_incidence_deg", "eta_mc", "iterations"},
    "exports": {"interactions", "sides", "formats", "tolerance"},
    "trace": {"scene", "rays", "study_rays", "seed", "reflectance", "height_mm", "led_fwhm_deg", "specular_fraction"},
    "fits": {"bsdf_model", "emission_model", "emission_incidence_deg", "led_peak_nm", "led_fwhm_nm",
             "fallback_flux_W"},
    "spectral": {"measurement", "scene", "rays", "seed", "incidence_deg", "ablation_rays",
                 "temperature_K"},
}

#: Upper bounds of the recipe's sizes (checked before anything is computed).
MAX_RAYS = 100_000_000
MAX_STUDY_POINTS = 50
MAX_ITERATIONS = 1000
#: file suffix per writable format of the registry (the first three as before: tracepro.txt, zemax.bsdf, asap.txt)
EXPORT_SUFFIX = {**{name: name + registry.get(name).extensions[0] for name in registry.writable()},
                 "tracepro": "tracepro.txt", "zemax": "zemax.bsdf", "asap": "asap.txt"}


@dataclass(frozen=True)
class ReportOptions:
    figure_config: str = "blue"
    figure_wavelength_nm: float = 460.0


@dataclass(frozen=True)
class ReductionOptions:
    """Stage options of the reductions (power-budget paper: 45° incidence, η_MC = 0.94, 7 iterations)."""

    budget_incidence_deg: float = 45.0
    eta_mc: float = 0.94
    iterations: int = 7


@dataclass(frozen=True)
class ExportOptions:
    """Which tables the run writes (into OUT/exports/) and the TIS agreement each re-read must show."""

    interactions: tuple[str, ...] = ("bibs", "biys", "yiys")
    sides: tuple[str, ...] = SIDES
    formats: tuple[str, ...] = ("tracepro", "zemax")
    tolerance: float = 0.005  # relative: re-read table TIS vs the source's TIS


@dataclass(frozen=True)
class FitStageOptions:
    """Model fits of the run and the module-spectrum reconstruction (§4.2 of the cylindrical-module paper).

    The blue LED spectrum defaults to Table 2 of that paper (450.1 nm, FWHM 22.9 nm); the phosphor emission is
    fitted to this run's measured converted light. The two-wavelength fluxes come from the run's module trace,
    or, without a trace stage, from ``fallback_flux_W`` (Table 1 of that paper: 0.058 W blue, 0.472 W yellow).
    """

    bsdf_model: str = "lambert+gaussian"
    emission_model: str = "split-gaussian"
    emission_incidence_deg: float = 45.0
    led_peak_nm: float = 450.1
    led_fwhm_nm: float = 22.9
    fallback_flux_W: tuple[float, float] = (0.058, 0.472)


@dataclass(frozen=True)
class TraceStudyOptions:
    """The module trace of the run: a scene whose plate comes from this recipe, and §5 studies around it."""

    scene: Path | None = None
    rays: int = 400_000
    #: rays of each study point (None: ``rays``); a map that has not converged in the grid gets more
    #: (:func:`converge_map`)
    study_rays: int | None = None
    seed: int = 1
    reflectance: tuple[float, ...] = ()
    height_mm: tuple[float, ...] = ()
    led_fwhm_deg: tuple[float, ...] = ()
    specular_fraction: tuple[float, ...] = ()


@dataclass(frozen=True)
class Recipe:
    """A parsed recipe file. Paths are resolved relative to the recipe file."""

    path: Path
    name: str
    measurement: Path
    description: str = ""
    report: ReportOptions = ReportOptions()
    reductions: ReductionOptions = ReductionOptions()
    exports: ExportOptions = ExportOptions()
    trace: TraceStudyOptions = TraceStudyOptions()
    fits: FitStageOptions = FitStageOptions()
    spectral: SpectralComparisonOptions | None = None
    raw: dict = field(default_factory=dict, compare=False, hash=False)


def _check_keys(data: dict, path: Path) -> None:
    for section, value in data.items():
        if section not in KNOWN_SECTIONS:
            raise FormatError("unknown recipe section", file=path, field=section,
                              expected="one of " + ", ".join(sorted(KNOWN_SECTIONS)))
        if not isinstance(value, dict):
            raise FormatError("recipe section must be a table", file=path, field=section, got=value)
        for key in value:
            if key not in KNOWN_SECTIONS[section]:
                raise FormatError("unknown recipe key", file=path, field=f"{section}.{key}",
                                  expected="one of " + ", ".join(sorted(KNOWN_SECTIONS[section])))


def _typed(table: dict, key: str, kind: type | tuple, path: Path, dotted: str, default: Any = None) -> Any:
    if key not in table:
        if default is None:
            raise InputError("recipe key missing", file=path, field=dotted)
        return default
    value = table[key]
    ok = isinstance(value, kind) and not (isinstance(value, bool) and kind is not bool)
    if not ok:
        raise InputError("recipe value of the wrong type", file=path, field=dotted,
                         expected=getattr(kind, "__name__", str(kind)), got=value)
    return value


def _ranged(value: Any, path: Path, dotted: str, lo: float, hi: float, lo_open: bool = False,
            hi_open: bool = False) -> Any:
    """``value`` if finite and inside the interval, else a ValidationError naming the key and the range."""
    ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
          and (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi))
    if not ok:
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise ValidationError("recipe value out of range", file=path, field=dotted, expected=f"a number in {rng}",
                              got=value)
    return value


def load_recipe(path: str | Path) -> Recipe:
    """Parse and validate a recipe TOML file (types and ranges of every option, and its trace scene).

    Parameters
    ----------
    path : str or pathlib.Path
        The recipe TOML file; relative paths inside it are resolved against its folder.

    Returns
    -------
    Recipe
        The validated recipe.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("recipe not found", file=path, expected="a TOML recipe file")
    data = read_toml(path, expected="a recipe TOML file")
    _check_keys(data, path)
    name, measurement = recipe_head(data, path)
    rep = data.get("report", {})
    report = ReportOptions(
        figure_config=_typed(rep, "figure_config", str, path, "report.figure_config", "blue"),
        figure_wavelength_nm=float(_typed(rep, "figure_wavelength_nm", (int, float), path,
                                          "report.figure_wavelength_nm", 460.0)),
    )
    red = data.get("reductions", {})
    reductions = ReductionOptions(
        budget_incidence_deg=float(_typed(red, "budget_incidence_deg", (int, float), path,
                                          "reductions.budget_incidence_deg", 45.0)),
        eta_mc=float(_typed(red, "eta_mc", (int, float), path, "reductions.eta_mc", 0.94)),
        iterations=int(_typed(red, "iterations", int, path, "reductions.iterations", 7)),
    )
    exp = data.get("exports", {})
    exports = ExportOptions(
        interactions=tuple(_choices(exp, "interactions", ("bibs", "biys", "yiys"), path)),
        sides=tuple(_choices(exp, "sides", SIDES, path)),
        formats=tuple(_choices(exp, "formats", registry.writable(), path, default=("tracepro", "zemax"))),
        tolerance=float(_typed(exp, "tolerance", (int, float), path, "exports.tolerance", 0.005)),
    )
    tr = data.get("trace")
    trace = TraceStudyOptions()
    if tr is not None:
        scene = path.parent / _typed(tr, "scene", str, path, "trace.scene")
        if not scene.is_file():
            raise InputError("trace scene not found", file=path, field="trace.scene", expected="an existing scene TOML",
                             got=str(scene))
        trace = TraceStudyOptions(
            scene=scene, rays=int(_typed(tr, "rays", int, path, "trace.rays", 400_000)),
            study_rays=_typed(tr, "study_rays", int, path, "trace.study_rays") if "study_rays" in tr else None,
            seed=int(_typed(tr, "seed", int, path, "trace.seed", 1)),
            **{k: tuple(float(v) for v in _numbers(tr, k, path)) for k in
               ("reflectance", "height_mm", "led_fwhm_deg", "specular_fraction")})
    ft = data.get("fits", {})
    fallback = _numbers(ft, "fallback_flux_W", path, section="fits") or [0.058, 0.472]
    if len(fallback) != 2:
        raise InputError("two fluxes expected", file=path, field="fits.fallback_flux_W", expected="[blue_W, yellow_W]",
                         got=fallback)
    fits = FitStageOptions(
        bsdf_model=_typed(ft, "bsdf_model", str, path, "fits.bsdf_model", "lambert+gaussian"),
        emission_model=_typed(ft, "emission_model", str, path, "fits.emission_model", "split-gaussian"),
        emission_incidence_deg=float(_typed(ft, "emission_incidence_deg", (int, float), path,
                                            "fits.emission_incidence_deg", 45.0)),
        led_peak_nm=float(_typed(ft, "led_peak_nm", (int, float), path, "fits.led_peak_nm", 450.1)),
        led_fwhm_nm=float(_typed(ft, "led_fwhm_nm", (int, float), path, "fits.led_fwhm_nm", 22.9)),
        fallback_flux_W=(float(fallback[0]), float(fallback[1])),
    )
    recipe = Recipe(path=path, name=name, measurement=measurement,
                    description=_typed(data["recipe"], "description", str, path, "recipe.description", ""),
                    report=report,
                    reductions=reductions, exports=exports, trace=trace, fits=fits,
                    spectral=_spectral_options(data.get("spectral"), path, trace, fits), raw=data)
    _check_ranges(recipe)
    if not measurement.is_dir():
        raise InputError("measurement folder not found", file=path, field="recipe.measurement",
                         expected="an existing raw measurement folder", got=str(measurement))
    _check_against_data(recipe)
    if trace.scene is not None:
        _scene_with_plate(trace.scene, None)  # the scene's own errors now, not after minutes of computing
    return recipe


def _spectral_options(table: dict | None, path: Path, trace: TraceStudyOptions,
                      fits: FitStageOptions) -> SpectralComparisonOptions | None:
    """The ``[spectral]`` table: the spectral comparison stage (one excitation-emission measurement, both modes)."""
    if table is None:
        return None
    measurement = (path.parent / _typed(table, "measurement", str, path, "spectral.measurement")).resolve()
    if not measurement.is_dir():
        raise InputError("measurement folder not found", file=path, field="spectral.measurement",
                         expected="an existing excitation-emission raw export", got=str(measurement))
    scene = path.parent / _typed(table, "scene", str, path, "spectral.scene") if "scene" in table else trace.scene
    if scene is None or not scene.is_file():
        raise InputError("spectral comparison scene not found", file=path, field="spectral.scene",
                         expected="an existing scene TOML (or a [trace] scene)",
                         got=None if scene is None else str(scene))
    rays = _ranged(_typed(table, "rays", int, path, "spectral.rays", 200_000), path, "spectral.rays", 1, MAX_RAYS)
    seed = _ranged(_typed(table, "seed", int, path, "spectral.seed", trace.seed), path, "spectral.seed", 0,
                   2**63 - 2)
    incidence = tuple(float(_ranged(v, path, f"spectral.incidence_deg[{k}]", 0.0, 90.0, hi_open=True))
                      for k, v in enumerate(_numbers(table, "incidence_deg", path, section="spectral")))
    ablation_rays = _ranged(_typed(table, "ablation_rays", int, path, "spectral.ablation_rays", 50_000), path,
                            "spectral.ablation_rays", 1, MAX_RAYS)
    temperature = float(_ranged(_typed(table, "temperature_K", (int, float), path, "spectral.temperature_K",
                                       PLATE_TEMPERATURE_K), path, "spectral.temperature_K", 0.0, 5000.0,
                                lo_open=True))
    if "scene" in table:
        _scene_with_plate(scene, None)
    return SpectralComparisonOptions(measurement=measurement, scene=scene, rays=rays, seed=seed,
                                     incidence_deg=incidence, ablation_rays=ablation_rays, temperature_K=temperature,
                                     led_peak_nm=fits.led_peak_nm, led_fwhm_nm=fits.led_fwhm_nm,
                                     emission_incidence_deg=fits.emission_incidence_deg)


def _check_ranges(r: Recipe) -> None:
    """Every numeric option of the recipe in its physical range, and every size bounded."""
    p = r.path
    _ranged(r.report.figure_wavelength_nm, p, "report.figure_wavelength_nm", 100.0, 5000.0)
    red = r.reductions
    _ranged(red.budget_incidence_deg, p, "reductions.budget_incidence_deg", 0.0, 90.0, hi_open=True)
    _ranged(red.eta_mc, p, "reductions.eta_mc", 0.0, 1.0, lo_open=True)
    _ranged(red.iterations, p, "reductions.iterations", 1, MAX_ITERATIONS)
    _ranged(r.exports.tolerance, p, "exports.tolerance", 0.0, 1.0, lo_open=True)
    for key in ("interactions", "sides", "formats"):
        if not getattr(r.exports, key):
            raise ValidationError("empty list", file=p, field=f"exports.{key}", expected="at least one name", got=[])
    t = r.trace
    if t.scene is not None:
        _ranged(t.rays, p, "trace.rays", 1, MAX_RAYS)
        if t.study_rays is not None:
            _ranged(t.study_rays, p, "trace.study_rays", 1, MAX_RAYS)
        _ranged(t.seed, p, "trace.seed", 0, 2**63 - 1)
        for key, lo, hi, lo_open in (("reflectance", 0.0, 1.0, False), ("specular_fraction", 0.0, 1.0, False),
                                     ("height_mm", 0.0, 10_000.0, True), ("led_fwhm_deg", 0.0, 180.0, True)):
            values = getattr(t, key)
            if len(values) > MAX_STUDY_POINTS:
                raise ValidationError("too many study points", file=p, field=f"trace.{key}",
                                      expected=f"at most {MAX_STUDY_POINTS} values", got=len(values))
            for k, v in enumerate(values):
                _ranged(v, p, f"trace.{key}[{k}]", lo, hi, lo_open=lo_open)
    f = r.fits
    if f.bsdf_model not in BSDF_MODELS:
        raise ValidationError("unknown BSDF model", file=p, field="fits.bsdf_model",
                              expected=" | ".join(BSDF_MODELS), got=f.bsdf_model)
    if f.emission_model not in SPECTRUM_MODELS:
        raise ValidationError("unknown emission model", file=p, field="fits.emission_model",
                              expected=" | ".join(SPECTRUM_MODELS), got=f.emission_model)
    _ranged(f.emission_incidence_deg, p, "fits.emission_incidence_deg", 0.0, 90.0, hi_open=True)
    _ranged(f.led_peak_nm, p, "fits.led_peak_nm", 380.0, 780.0)
    _ranged(f.led_fwhm_nm, p, "fits.led_fwhm_nm", 0.0, 400.0, lo_open=True)
    for k, v in enumerate(f.fallback_flux_W):
        _ranged(v, p, f"fits.fallback_flux_W[{k}]", 0.0, 1e6)
    if sum(f.fallback_flux_W) <= 0:
        raise ValidationError("no light", file=p, field="fits.fallback_flux_W", expected="a positive total flux",
                              got=list(f.fallback_flux_W))


class MeasuredAxes(NamedTuple):
    """What a raw export measured: its wavelength range [nm], configurations and incidences [deg]."""

    wavelength_nm: tuple[float, float]
    configurations: tuple[str, ...]
    incidences_deg: tuple[float, ...]


def _scan_incidences(path: Path) -> set[float]:
    """The distinct values of a raw scan table's ``theta_i_deg`` column [deg], read without its spectra."""
    opener = gzip.open if path.suffix == ".gz" else open
    found: set[float] = set()
    column = None
    with opener(path, "rt", encoding="utf-8-sig") as lines:
        for line in lines:
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            if column is None:
                column = [c.strip() for c in line.split(",")].index("theta_i_deg")  # ValueError: no such column
                continue
            found.add(float(line.split(",", column + 1)[column]))
    return found


def measured_axes(folder: Path) -> MeasuredAxes | None:
    """The wavelength range, configurations and incidences of the raw export ``folder``, from its manifest and the
    incidence column of its scans (tens of milliseconds: the spectra are not parsed).

    Parameters
    ----------
    folder : Path
        The raw export (a folder with ``manifest.toml``).

    Returns
    -------
    MeasuredAxes or None
        None when the export cannot be read so: its reader names the fault when the run reads it.
    """
    try:
        manifest = read_manifest(folder)
        incidences: set[float] = set()
        for scan in sorted({cfg.scan_file for cfg in manifest.configurations}):
            incidences |= _scan_incidences(Path(scan))
    except (InputError, OSError, ValueError, EOFError, UnicodeDecodeError, IndexError):
        return None
    return MeasuredAxes((manifest.wavelength_min_nm, manifest.wavelength_max_nm),
                        tuple(cfg.name for cfg in manifest.configurations), tuple(sorted(incidences)))


def _measured_incidence(value: float, axes: MeasuredAxes, path: Path, dotted: str, folder: Path) -> None:
    if not any(abs(value - th) < 1e-6 for th in axes.incidences_deg):
        raise ValidationError("incidence not measured", file=path, field=dotted,
                              expected=f"one of {', '.join(f'{th:g}' for th in axes.incidences_deg)} deg (the "
                              f"incidences of {folder.name})", got=value)


def _check_against_data(r: Recipe) -> None:
    """Every key that selects from the measurement (a wavelength, a configuration, an incidence) inside what it
    measured: a recipe asking for 2000 nm of a 380-780 nm scan is refused before the run, naming the key, the
    measured range and the value (issue #44.7)."""
    axes = measured_axes(r.measurement)
    if axes is not None:
        lo, hi = axes.wavelength_nm
        wavelength = r.report.figure_wavelength_nm
        if not lo <= wavelength <= hi:
            raise ValidationError("wavelength outside the measured range", file=r.path,
                                  field="report.figure_wavelength_nm", expected=f"a wavelength in [{lo:g}, {hi:g}] nm "
                                  f"(the range of {r.measurement.name})", got=wavelength)
        if r.report.figure_config not in axes.configurations:
            raise ValidationError("configuration not measured", file=r.path, field="report.figure_config",
                                  expected=f"one of {', '.join(axes.configurations)}", got=r.report.figure_config)
        _measured_incidence(r.reductions.budget_incidence_deg, axes, r.path, "reductions.budget_incidence_deg",
                            r.measurement)
        _measured_incidence(r.fits.emission_incidence_deg, axes, r.path, "fits.emission_incidence_deg", r.measurement)
    spectral = r.spectral
    axes = None if spectral is None else measured_axes(spectral.measurement)
    if axes is not None:
        for k, value in enumerate(spectral.incidence_deg):
            _measured_incidence(value, axes, r.path, f"spectral.incidence_deg[{k}]", spectral.measurement)


def expected_outputs(recipe: Recipe) -> list[str]:
    """The files a run of ``recipe`` writes (relative to the output folder), known before computing.

    Parameters
    ----------
    recipe : Recipe
        A validated recipe.

    Returns
    -------
    list of str
        Output file names, relative to the output folder.
    """
    e = recipe.exports
    names = ["scan.nc", "inplane_bsdf.png", "tis.nc", "interaction_tables.json", "module_budget.png"]
    names += [f"exports/{i}_{s}.{EXPORT_SUFFIX[f]}" for i in e.interactions for s in e.sides for f in e.formats]
    names += ["bsdf_fits.json", "bsdf_fits.png"]
    if recipe.trace.scene is not None:
        names += ["trace.json", "trace_device.nc", "trace_studies.png", "trace_incidence.png"]
        names += [f"trace_{study}.nc" for study in STUDIES if getattr(recipe.trace, study)]
    names += ["module_spectrum.csv", "module_spectrum.png", "module_spectrum.json"]
    if recipe.spectral is not None:
        names += ["spectral_comparison.png", "spectral_comparison.csv"]
    return names + ["summary.json", "report.html"]


def _numbers(table: dict, key: str, path: Path, section: str = "trace") -> list[float]:
    value = table.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError("recipe value must be a list of numbers", file=path, field=f"{section}.{key}", got=value)
    return value


def _choices(table: dict, key: str, allowed: tuple[str, ...], path: Path,
             default: tuple[str, ...] | None = None) -> list[str]:
    value = table.get(key, list(default or allowed))
    if not isinstance(value, list) or not all(isinstance(v, str) and v in allowed for v in value):
        raise InputError("recipe value must be a list of names", file=path, field=f"exports.{key}",
                         expected="a subset of " + ", ".join(allowed), got=value)
    return value


@dataclass
class RunState:
    """What stages hand on: the calibrated scan, summary parts and pending outputs (name → writer)."""

    recipe: Recipe
    scan: xr.Dataset | None = None
    tis: xr.Dataset | None = None
    fits: dict = field(default_factory=dict)
    emission: dict = field(default_factory=dict)
    device: object = None
    tables: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    outputs: dict[str, Callable[[Path, bool], object]] = field(default_factory=dict)
    log: Callable[[str], None] = lambda message: None
    #: progress of a long stage: (task, done, total), e.g. ("trace", 3, 14) after the third of 14 traces
    progress: Callable[[str, int, int], None] = lambda task, done, total: None
    #: the spectral comparison being computed by the run's helper process (:func:`_spectral_ahead`)
    spectral_ahead: Future | None = None


def stage_ingest(state: RunState) -> None:
    """Read the raw export, calibrate it, and queue ``scan.nc``.

    Parameters
    ----------
    state : RunState
        The run so far (its recipe's measurement); the calibrated scan and its summary are added.
    """

    state.scan = calibrate(read_scan(state.recipe.measurement))
    scan = state.scan
    state.summary["scan"] = describe(scan)
    below, negative = int(scan.attrs.get("below_dark_pixels", 0)), int(scan.attrs.get("negative_raw_counts", 0))
    if below or negative:  # plausibility: counted in the dataset and the summary, and said out loud
        state.summary.setdefault("report_lines", []).append(
            f"WARNING: {below} of {scan['bsdf'].size} pixels lie more than {BELOW_DARK_SIGMA:g} standard "
            f"uncertainties below the dark level (dark frames above the signal?) and {negative} raw counts are "
            "negative; see the below_dark flag in scan.nc")
    state.outputs["scan.nc"] = lambda p, force: netcdf.save(scan, p, force)


def stage_report(state: RunState) -> None:
    """Queue the in-plane BSDF figure (Fig. 6 analogue).

    Parameters
    ----------
    state : RunState
        The run so far (the recipe's figure configuration and wavelength [nm], the calibrated scan).
    """

    opts = state.recipe.report
    fig = in_plane_bsdf_figure(state.scan, opts.figure_config, opts.figure_wavelength_nm)
    state.outputs["inplane_bsdf.png"] = FigureFile(fig)


def stage_reductions(state: RunState) -> None:
    """TIS with error bars, the Table-2-style interaction tables, EQE, and the iterative module budget.

    Parameters
    ----------
    state : RunState
        The run so far (the recipe's ``[reductions]``, the calibrated scan); the TIS, interaction tables,
        budgets and their summary are added.
    """

    opts = state.recipe.reductions
    scan = state.scan
    state.tis = angular.tis_table(scan)
    tables = {f"{th:g}": budget.interaction_table(scan, th, state.tis) for th in incidences(scan)}
    state.tables = tables
    key = f"{opts.budget_incidence_deg:g}"
    if key not in tables:
        raise InputError("budget incidence not measured", file=state.recipe.path,
                         field="reductions.budget_incidence_deg",
                         expected="one of " + ", ".join(tables), got=opts.budget_incidence_deg)
    t = tables[key]
    power = budget.module_budget(t.power, opts.eta_mc, opts.iterations)
    photons = budget.module_budget(t.photons, opts.eta_mc, opts.iterations)

    truth = truth_tis(scan)
    table_json = {k: v.as_dict() for k, v in tables.items()}
    if truth:
        table_json["truth_power_percent"] = truth
    state.summary["interaction_tables"] = table_json
    state.summary["module_budget"] = {"incidence_deg": opts.budget_incidence_deg, "power": power.as_dict(),
                                      "photons": photons.as_dict()}
    tis = state.tis
    state.outputs["tis.nc"] = lambda p, force: netcdf.save(tis, p, force)
    state.outputs["interaction_tables.json"] = lambda p, force: write_text(p, dumps(table_json), force)
    fig = budget_figure(power, photons)
    state.outputs["module_budget.png"] = FigureFile(fig)
    lines = [f"interaction table at {key} deg (percent of incident power / photons):"]
    for k in budget.KEYS:
        extra = f"   truth {truth[key][k]:6.2f}" if truth and key in truth else ""
        lines.append(f"  {k:14s} {t.power[k]:6.2f} ± {t.power_std[k]:.2f}   {t.photons[k]:6.2f}{extra}")
    lines.append(f"  EQE {t.eqe:.3f} ± {t.eqe_std:.3f}")
    last = power.iterations[-1]
    lines.append(f"module budget (η_MC = {opts.eta_mc:g}, {opts.iterations} plate interactions): "
                 f"blue {last['blue']:.2f}, yellow {last['yellow']:.2f}, total {last['total']:.2f} %; "
                 f"converged total {power.converged['total']:.2f} %")
    state.summary.setdefault("report_lines", []).extend(lines)


def stage_exports(state: RunState) -> None:
    """Queue TracePro/Zemax tables of each interaction and side; each is re-read and its TIS checked.

    The tables go into OUT/exports/. Their writer runs with the other outputs (atomic, no clobbering); it
    records, per file, the source TIS (direct integral of the reconstructed hemisphere) and the TIS recomputed
    from the file as read back, and fails the run if they differ by more than the recipe's tolerance.

    Parameters
    ----------
    state : RunState
        The run so far (the recipe's ``[exports]``, the calibrated scan); the table writers are queued.
    """

    opts = state.recipe.exports
    scan = state.scan
    checks: list[dict] = []
    state.summary["export_checks"] = checks
    suffix = EXPORT_SUFFIX

    def writer(inter: str, side: str, fmt: str):
        def write(path: Path, force: bool) -> None:
            result = exporter.export(scan, fmt, inter, side, path, force)
            # the export re-read the file as bsdfkit read does (ExportResult.tis_table, per exported incidence the
            # value of the file incidence that holds it: the same numbers as read_any for the table formats)
            for k, th in enumerate(result.incidences_deg):
                src = result.tis_source[side][k]
                got = result.tis_table[side][k]
                rel = abs(got - src) / src if src else abs(got)
                checks.append({"file": f"exports/{path.name}", "interaction": inter, "side": side, "format": fmt,
                               "theta_i_deg": th, "tis_source": src, "tis_reread": got, "relative_difference": rel,
                               "ok": rel <= opts.tolerance})
                if rel > opts.tolerance:
                    raise NumericalError("exported table does not carry the source's TIS", file=path,
                                         field=f"theta_i {th:g}", expected=f"relative difference ≤ {opts.tolerance:g}",
                                         got=f"{rel:.3g}")
        return write

    for inter in opts.interactions:
        for side in opts.sides:
            for fmt in opts.formats:
                state.outputs[f"exports/{inter}_{side}.{suffix[fmt]}"] = EarlyWriter(writer(inter, side, fmt))


@dataclass(frozen=True)
class EarlyWriter:
    """An output that needs nothing from later stages: :func:`_run_stages` writes it (into the staging folder of
    the output set) in a background thread while the later stages run, in the order queued.

    Parameters
    ----------
    write : callable
        ``write(path, force)``, the writer.
    """

    write: Callable[[Path, bool], object]

    def __call__(self, path: Path, force: bool = False) -> object:
        return self.write(path, force)


#: The §5 studies of [Cylindrical-module]: recipe key → (the scene keys a study value sets, the dimension of its
#: saved maps). Wall finish sets walls and base alike, as reflectance does.
STUDIES = {
    "reflectance": (("wall.reflectance", "base.reflectance"), "wall.reflectance"),
    "height_mm": (("cavity.height_mm",), "cavity.height_mm"),
    "led_fwhm_deg": (("leds.fwhm_deg",), "leds.fwhm_deg"),
    "specular_fraction": (("wall.specular_fraction", "base.specular_fraction"), "wall.specular_fraction"),
}
#: Cells per side of the traces' irradiance maps: the non-uniformity's grid study runs on 8, 16, 32, 64 and 128 cells
#: (:func:`bsdfkit.raytrace.tallies.converged_non_uniformity`; docs/tracer.md, "Non-uniformity and the map grid")
MAP_STUDY_BINS = 128
#: FWHM of a Lambertian emitter, I ∝ cos θ: half the peak at θ = 60° [deg]
LAMBERTIAN_FWHM_DEG = 120.0


def _is_device_value(scene, study: str, value: float) -> bool:
    """Whether the study point ``value`` is the device itself (then its trace is the device's, not repeated)."""
    if study == "reflectance":
        return scene.wall.reflectance == value == scene.base.reflectance
    if study == "height_mm":
        return scene.cavity.height_mm == value
    if study == "led_fwhm_deg":
        fwhm = LAMBERTIAN_FWHM_DEG if scene.leds.fwhm is None else math.degrees(scene.leds.fwhm)
        return abs(fwhm - value) < 1e-9
    return scene.wall.specular_fraction == value == scene.base.specular_fraction


def _nu(result) -> dict[str, Any]:
    """A trace's non-uniformity [1] for the summary: ``non_uniformity`` ± ``non_uniformity_std`` is the split-half
    value on the grid it converged on (``non_uniformity_bins`` cells per side, ``non_uniformity_converged``, the
    change to the next finer grid ``non_uniformity_change`` ± ``non_uniformity_change_std``, every grid in
    ``non_uniformity_grids``; :func:`bsdfkit.raytrace.tallies.converged_non_uniformity`), the quantity compared
    with the papers; ``non_uniformity_map`` is the max − min of the whole map (noise included; no σ: nothing
    reads one, and its 200 redrawn maps per trace cost about 1 s of the run)."""
    if result.irradiance is None:
        return {"non_uniformity": None, "non_uniformity_std": None}
    conv = result.non_uniformity_converged
    return {"non_uniformity": conv["value"], "non_uniformity_std": conv["std"], "non_uniformity_bins": conv["bins"],
            "non_uniformity_converged": conv["converged"], "non_uniformity_finer": conv["finer"],
            "non_uniformity_change": conv["change"], "non_uniformity_change_std": conv["change_std"],
            "non_uniformity_symmetric": conv["symmetric"], "non_uniformity_rays": result.map_rays or result.rays,
            "non_uniformity_grids": {str(g): v for g, v in conv["grids"].items()},
            "non_uniformity_map": result.non_uniformity_map}


#: A map whose non-uniformity has not converged in the grid gets more rays (more traces of the same scene with new
#: seeds, each of the recipe's ray count) until it converges or it holds this many times the recipe's rays
MAP_RAYS_FACTOR = 4
#: seed offset of those extra traces (far from the seeds a recipe or sweep uses)
MAP_SEED_OFFSET = 1_000_003


def converge_map(scene, result, rays: int, seed: int, factor: int = MAP_RAYS_FACTOR, chunk: int | None = None):
    """``result`` with its irradiance map's non-uniformity converged in the grid, when more rays can do it.

    While :func:`bsdfkit.raytrace.tallies.converged_non_uniformity` finds no grid whose value changes by less than
    the change's σ on the next finer grid, the scene is traced again with ``rays`` new rays (seed ``seed`` +
    k·:data:`MAP_SEED_OFFSET`) and the sub-maps are merged (:func:`bsdfkit.raytrace.tallies.merge_maps`), up to
    ``factor`` × ``rays`` rays in the map. Only the map changes (``map_rays`` says how many rays it holds); LER,
    YBR and the ledger stay those of ``result``. A result without sub-maps, or converged already, is returned as is.

    Parameters
    ----------
    scene : Scene
        The traced scene.
    result : TraceResult
        Its trace of ``rays`` rays with seed ``seed``.
    rays : int
        Rays per extra trace [-].
    seed : int
        Seed of ``result``'s trace.
    factor : int
        Most rays in the map, in multiples of ``rays`` [-].
    chunk : int, optional
        Rays per device and call of the extra traces (:func:`bsdfkit.raytrace.tracer.trace`).

    Returns
    -------
    TraceResult
        ``result`` with the merged map and ``map_rays``, or ``result`` itself.
    """
    conv = result.non_uniformity_converged
    if result.irradiance_parts is None or conv is None or conv["converged"]:
        return result
    fields, n, k = {"irradiance_parts": result.irradiance_parts}, rays, 0
    while not conv["converged"] and n + rays <= factor * rays:
        k += 1
        more = trace(scene, rays, seed + k * MAP_SEED_OFFSET, chunk=chunk)
        fields = map_fields(merge_maps(fields["irradiance_parts"], n, more.irradiance_parts, rays), conv["symmetric"])
        conv = fields["non_uniformity_converged"]
        n += rays
    return replace(result, **fields, map_rays=n)


def incidence_shares(result, measured_deg: tuple[float, float]) -> dict[str, float]:
    """How the power reaching the plate splits between measured and model-extrapolated incidences.

    From the tracer's incidence histogram (power per 90/bins-degree bin, blue and yellow): a bin counts as
    measured when its centre lies in ``measured_deg`` (inclusive). Returns the shares [1] of the total power
    on the plate and the power-weighted mean incidence [deg] of the blue light reaching it.

    Parameters
    ----------
    result : TraceResult
        A trace with an incidence histogram (blue, yellow over incidence bins).
    measured_deg : tuple of float
        (first, last) measured incidence [deg].

    Returns
    -------
    dict
        ``measured`` and ``extrapolated`` [-], ``mean_blue_incidence_deg`` [deg]; NaN where nothing reaches the plate.
    """
    hist = np.asarray(result.incidence_histogram, dtype=float)
    centres = (np.arange(hist.shape[1]) + 0.5) * 90.0 / hist.shape[1]
    inside = (centres >= measured_deg[0]) & (centres <= measured_deg[1])
    total = float(hist.sum())
    blue = hist[0]
    return {"measured": float(hist[:, inside].sum()) / total if total else float("nan"),
            "extrapolated": float(hist[:, ~inside].sum()) / total if total else float("nan"),
            "mean_blue_incidence_deg": float((blue * centres).sum() / blue.sum()) if blue.sum() else float("nan")}


def stage_trace(state: RunState) -> None:
    """Trace the module with the plate built from this run's own results, and the §5 studies around it.

    The plate covers 0–90° (measured TIS at the measured incidences, model-extrapolated elsewhere,
    :func:`bsdfkit.pipeline.plate_from_scan.plate_from_scan`); the shares of the plate's incident power on
    measured and extrapolated incidences are reported per trace. A study point equal to the device (h = 43 mm,
    a Lambertian LED = FWHM 120°) reuses the device's trace. Each study's maps and incidence histograms are
    saved (``trace_<study>.nc``). Trends of the cylindrical-module paper are checked and reported, not assumed
    (:func:`_trends`).

    Parameters
    ----------
    state : RunState
        The run so far: its recipe's ``[trace]`` table (nothing is done without a scene), calibrated scan, TIS
        and fits. The device trace, the ``trace`` summary, the run lines and the outputs are added to it.
    """
    opts = state.recipe.trace
    if opts.scene is None:
        return
    plate = plate_from_scan(state.scan, state.tis, name=state.recipe.name,
                            fits={k: v[0] for k, v in state.fits.items()})
    measured = (float(state.tis["theta_i"].values[0]), float(state.tis["theta_i"].values[-1]))
    # the report needs every trace's irradiance map and incidence histogram, whatever the scene file says
    scene = with_values(_scene_with_plate(opts.scene, plate),
                        {"tallies.irradiance_map": True, "tallies.map_bins": MAP_STUDY_BINS,
                         "tallies.incidence_histogram": True})
    traced = _trace_points(state, scene, measured)
    device, studies = traced.device, traced.studies
    results = {"device": device.to_dict() | {"plate_incidence": incidence_shares(device, measured)} | _nu(device)}
    results["studies"] = studies
    results["trends"] = _trends(device, studies)
    results["plate"] = _plate_summary(plate, state.tis, measured, [results["device"]]
                                      + [r for rs in studies.values() for r in rs])
    state.summary["trace"] = _trace_summary(results)
    _queue_trace_outputs(state, plate, traced, results, measured)
    lines = _trace_lines(opts.rays, device, results, measured)
    if opts.study_rays is not None and any(getattr(opts, k) for k in STUDIES):
        more = [f"{study} {r['values'][STUDIES[study][0][0]]:g}: {r['non_uniformity_rays']}"
                for study, rs in studies.items() for r in rs
                if not r["same_trace_as_device"] and (r["non_uniformity_rays"] or 0) > opts.study_rays]
        lines.insert(2, f"  study points: {opts.study_rays} rays each ([trace] study_rays); maps traced further to "
                        f"converge in the grid: {', '.join(more) or 'none'}")
    state.summary.setdefault("report_lines", []).extend(lines)


class _Traced(NamedTuple):
    """The traces of :func:`stage_trace`: the device's and every study point's."""

    device: Any                                # the device's TraceResult (map converged where rays allow)
    studies: dict[str, list[dict]]             # study → one JSON row per study value
    datasets: dict[str, list[xr.Dataset]]      # study → one trace dataset per study value
    blue_on_plate: dict[str, np.ndarray]       # height label → blue incidence histogram on the plate [W per bin]


def _trace_points(state: RunState, scene, measured: tuple[float, float]) -> _Traced:
    """Trace the device (stored as ``state.device``) and every study point, reporting progress per trace."""
    opts = state.recipe.trace
    rays = opts.study_rays or opts.rays
    points = [(study, v) for study in STUDIES for v in getattr(opts, study) if not _is_device_value(scene, study, v)]
    total = 1 + len(points)
    state.progress("trace", 0, total)
    chunk = common_chunk(scene, (opts.rays, rays) if points else (opts.rays,))  # one kernel for every trace
    device = converge_map(scene, trace(scene, opts.rays, opts.seed, chunk=chunk), opts.rays, opts.seed, chunk=chunk)
    done = 1
    state.progress("trace", done, total)
    state.device = device
    traced = _Traced(device, {}, {}, {})
    for study in STUDIES:
        keys, dim = STUDIES[study]
        for value in getattr(opts, study):
            values = dict.fromkeys(keys, value)
            if _is_device_value(scene, study, value):
                r, same = device, True
            else:
                point = with_values(scene, values)
                r, same = converge_map(point, trace(point, rays, opts.seed, chunk=chunk), rays, opts.seed,
                                       chunk=chunk), False
                done += 1
                state.progress("trace", done, total)
            row = {"values": values, "rays": r.rays, "LER": r.LER, "LER_std": r.std_err["LER"], "YBR": r.YBR,
                   "YBR_std": r.std_err["YBR"], **_nu(r), "ledger_error": r.ledger_error,
                   "clamped_share": r.clamped_interactions / r.plate_interactions if r.plate_interactions else 0.0,
                   "plate_incidence": incidence_shares(r, measured), "same_trace_as_device": same}
            traced.studies.setdefault(study, []).append(row)
            traced.datasets.setdefault(study, []).append(r.to_dataset().expand_dims({dim: [value]}))
            if study == "height_mm" and r.incidence_histogram is not None:
                traced.blue_on_plate[f"h = {value:g} mm" + (" (device)" if same else "")] = r.incidence_histogram[0]
    return traced


def _plate_summary(plate, tis: xr.Dataset, measured: tuple[float, float], rows: list[dict]) -> dict:
    """The ``plate`` entry of trace.json: its incidences, clamped and extrapolated shares over ``rows`` (the
    device's first) and its TIS per channel."""
    worst_clamped = max(r["clamped_share"] if "clamped_share" in r else
                        r["clamped_incidences"]["fraction_of_plate_interactions"] for r in rows)
    worst_extra = max(rows, key=lambda r: r["plate_incidence"]["extrapolated"])
    return {
        "measured_incidences_deg": [float(t) for t in tis["theta_i"].values],
        "grid_deg": list(plate.theta_i_deg), "notes": plate.notes,
        "extrapolated_incidences_deg": [t for t in plate.theta_i_deg if not measured[0] <= t <= measured[1]],
        "clamped_share_max": worst_clamped,
        "device_extrapolated_power_share": rows[0]["plate_incidence"]["extrapolated"],
        "extrapolated_power_share_max": worst_extra["plate_incidence"]["extrapolated"],
        "extrapolated_power_share_max_at": worst_extra.get("values", "device"),
        "tis": {c: list(plate.channel(c).tis) for c in CHANNELS}}


def _trace_summary(results: dict) -> dict:
    """The run summary's ``trace`` entry: the device's numbers, the plate's shares and the trends."""
    return {"device": {k: results["device"][k] for k in (
                "LER", "YBR", "non_uniformity", "non_uniformity_bins", "non_uniformity_converged",
                "non_uniformity_change", "non_uniformity_change_std", "non_uniformity_symmetric",
                "non_uniformity_map", "ledger_error", "rays", "elapsed_s", "interactions_per_s")},
            "device_std_err": {k: results["device"]["std_err"][k] for k in ("LER", "YBR")}
            | {"non_uniformity": results["device"]["non_uniformity_std"]},
            "YBR_definition": RAY_YBR_DEFINITION,
            "plate": {k: results["plate"][k] for k in (
                "measured_incidences_deg", "extrapolated_incidences_deg", "clamped_share_max",
                "device_extrapolated_power_share", "extrapolated_power_share_max")},
            "trends": results["trends"]}


def _queue_trace_outputs(state: RunState, plate, traced: _Traced, results: dict,
                         measured: tuple[float, float]) -> None:
    """Queue trace.json, the traces' netCDF files and the studies' and incidences' figures."""
    device = traced.device
    state.outputs["trace.json"] = lambda p, force: write_text(p, dumps(results), force)
    device_ds = device.to_dataset()
    state.outputs["trace_device.nc"] = lambda p, force: netcdf.save(device_ds, p, force)
    for study, parts in traced.datasets.items():
        ds = xr.concat(parts, dim=STUDIES[study][1], combine_attrs="override")
        state.outputs[f"trace_{study}.nc"] = lambda p, force, ds=ds: netcdf.save(ds, p, force)
    fig = trace_studies_figure(device, traced.studies, _paper_study_points())
    state.outputs["trace_studies.png"] = FigureFile(fig)
    tis = state.tis
    meas = {f"{i}_{side}": (tis["theta_i"].values, tis["tis"].sel(interaction=i, side=side).values,
                            tis["tis_std"].sel(interaction=i, side=side).values)
            for i in ("bibs", "biys") for side in SIDES}
    inc_fig = plate_incidence_figure(traced.blue_on_plate or {"device": device.incidence_histogram[0]}, measured,
                                     plate.theta_i_deg, results["plate"]["tis"], meas,
                                     title=f"plate {plate.name}: incidences of the traces and the plate's TIS")
    state.outputs["trace_incidence.png"] = FigureFile(inc_fig)


def _trace_lines(rays: int, device, results: dict, measured: tuple[float, float]) -> list[str]:
    """The run log's lines for the module trace: the device's numbers, the plate's incidences and the trends."""
    dev, plate = results["device"], results["plate"]
    lines = [f"module trace ({rays} rays, plate from this run): "
             f"LER {device.LER:.4f} ± {device.std_err['LER']:.4f}, "
             f"YBR {device.YBR:.2f} ± {device.std_err['YBR']:.2f} (yellow / blue extracted ray power), "
             f"non-uniformity {dev['non_uniformity']:.3f} ± {dev['non_uniformity_std']:.3f} "
             f"(split-half, {dev['non_uniformity_bins']} cells per side, "
             f"{'converged' if dev['non_uniformity_converged'] else 'NOT converged'}: "
             f"{dev['non_uniformity_change']:+.3f} ± {dev['non_uniformity_change_std']:.3f} on "
             f"{2 * dev['non_uniformity_bins']}; whole map "
             f"{device.non_uniformity_map:.3f}), "
             f"ledger error {device.ledger_error:.1e}",
             f"  plate incidences: measured {measured[0]:g}-{measured[1]:g} deg, model-extrapolated elsewhere; "
             f"clamped {100 * plate['clamped_share_max']:.1f} % of plate interactions (largest of all traces); power "
             f"on extrapolated incidences {100 * plate['device_extrapolated_power_share']:.1f} % (device), "
             f"at most {100 * plate['extrapolated_power_share_max']:.1f} %"]
    lines += [f"  trend {name}: {'holds' if t['holds'] else 'DOES NOT HOLD'} ({_trend_size(t)}{t['detail']})"
              for name, t in results["trends"].items()]
    return lines


def _trend_size(t: dict) -> str:
    """'direction …, size … vs paper … (criterion …); ' of a trend for the run's printed lines."""
    m = t.get("magnitude")
    head = f"direction {'as' if t['direction'] else 'NOT as'} the paper's"
    if not m or m.get("run") is None:
        return head + "; "
    sd = f" ± {m['run_std']:.2f}" if m.get("run_std") is not None else ""
    unit = f" {m['unit']}" if m.get("unit") else ""
    return f"{head}, size {m['run']:.2f}{sd}{unit} vs {m['paper']:.2f}{unit}, criterion {m['criterion']:.2f}; "


def _paper_study_points() -> dict[tuple[str, str], list[tuple[float, float]]]:
    """The numbers [Cylindrical-module] prints for the studies, in the units of :func:`trace_studies_figure`."""
    cm = paper_values()["cylindrical_module"]
    fig8, h, fw, f10 = (cm["fig8_reflectance"], cm["fig11_fig12_height"], cm["fig13_fig14_led_fwhm"],
                        cm["fig10_non_uniformity_percent"])
    return {("reflectance", "LER"): list(zip(fig8["reflectance"], fig8["LER_percent"])),
            ("reflectance", "YBR"): list(zip(fig8["reflectance"], fig8["YBR"])),
            ("height_mm", "LER"): [(h["best_LER_height_mm"], h["best_LER_percent"])],
            ("height_mm", "non_uniformity"): [(float(k), v) for k, v in h["non_uniformity_percent"].items()],
            ("led_fwhm_deg", "non_uniformity"): [(float(k), v) for k, v in fw["non_uniformity_percent"].items()],
            ("specular_fraction", "non_uniformity"): [(1.0, f10["mirror"]), (0.0, f10["perfect_diffuser"])]}


def _scene_with_plate(path: Path, plate):
    """The scene at ``path`` with its phosphor plate given (instead of recomputing it from ``from = ...``).

    With ``plate=None`` this only validates the scene (before a run computes anything).
    """
    data = read_toml(path, expected="a trace scene TOML file")
    top = data.get("top", {})
    if not isinstance(top, dict):
        top = {}
    key = "from" if "from" in top else "plate" if "plate" in top else None
    if top.get("kind") != "phosphor" or key is None:
        raise InputError("trace scene must have a phosphor top taken from a recipe or plate file", file=path,
                         field="top", expected='kind = "phosphor" and from = "..."')
    return parse_scene(data, path, preloaded={"plate": ((key, top[key]), plate)})


def _sorted_rows(studies: dict[str, list[dict]], study: str) -> list[dict]:
    key = STUDIES[study][1]
    return sorted(studies.get(study, []), key=lambda r: r["values"][key])


def _at(rows: list[dict], study: str, value: float) -> dict | None:
    key = STUDIES[study][1]
    hit = [r for r in rows if abs(r["values"][key] - value) < 1e-9]
    return hit[0] if hit else None


def _difference(a: dict | None, b: dict | None, quantity: str) -> tuple[float, float]:
    """a − b of a quantity [LER, non-uniformity: pp; YBR: 1] and its σ (independent traces; 0 for the same one)."""
    if a is None or b is None:
        return float("nan"), float("nan")
    scale = 1.0 if quantity == "YBR" else 100.0
    same = a is b or (a.get("same_trace_as_device") and b.get("same_trace_as_device"))
    sa, sb = (_num_or_nan(a.get(f"{quantity}_std")), _num_or_nan(b.get(f"{quantity}_std")))
    std = 0.0 if same else math.hypot(sa, sb)
    return scale * (a[quantity] - b[quantity]), scale * std


def _num_or_nan(x: Any) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def _trend(direction: bool, paper: str, rows: list[dict], study: str, quantity: str, fmt: str, extra: str = "",
           magnitude: dict | None = None) -> dict:
    """One trend: ``holds`` = the paper's direction AND (when the paper gives one) its magnitude within the
    criterion of :func:`bsdfkit.pipeline.report.magnitude_verdict`; ``extrapolated_share`` [1] per study value."""
    key = STUDIES[study][1]
    unit = {"height_mm": " mm", "led_fwhm_deg": "°"}.get(study, "")
    scale = 100.0 if quantity in ("LER", "non_uniformity") else 1.0
    pct = " %" if scale == 100.0 else ""
    numbers = ", ".join(f"{r['values'][key]:g}{unit}: {scale * r[quantity]:{fmt}}{pct}" for r in rows)
    holds = bool(direction) and (magnitude is None or bool(magnitude["agrees"]))
    shares = {f"{r['values'][key]:g}": (r.get("plate_incidence") or {}).get("extrapolated") for r in rows}
    return {"holds": holds, "direction": bool(direction), "magnitude": magnitude, "paper": paper,
            "quantity": quantity, "study": study, "extrapolated_share": shares,
            "detail": numbers + (f"; {extra}" if extra else "")}


def _magnitude(rows: list[dict], study: str, quantity: str, a: float, b: float, paper: float, half_unit: float,
               reading: str) -> dict:
    """This run's a − b of ``quantity`` against the paper's (or its reading's centre), with the criterion."""
    diff, std = _difference(_at(rows, study, a), _at(rows, study, b), quantity)
    return magnitude_verdict(diff, std, paper, half_unit, reading, "pp" if quantity != "YBR" else "")


def _trends(device, studies: dict[str, list[dict]]) -> dict[str, dict]:
    """The §5 trends of [Cylindrical-module], each judged on this run's studies by direction AND magnitude.

    Each entry: ``holds`` (direction and magnitude), ``direction``, ``magnitude`` (run difference [pp or 1] with
    σ, the paper's difference or the numeric reading of its words, the criterion and the verdict; ``None`` where
    the paper gives neither), ``paper``, ``quantity``, ``study``, ``extrapolated_share`` and ``detail``.
    Readings of the paper's words: :data:`bsdfkit.pipeline.report.READINGS`. A trend needs two study points.
    """
    out: dict[str, dict] = {}
    refl = _sorted_rows(studies, "reflectance")
    if len(refl) >= 2:
        out["LER rises with wall reflectance (Fig. 8)"] = _trend(
            all(np.diff([r["LER"] for r in refl]) > 0), "LER 28 % at ρ = 0.80 to 58 % at ρ = 0.98", refl,
            "reflectance", "LER", ".1f", magnitude=_magnitude(refl, "reflectance", "LER", 0.98, 0.80, 30.0,
                                                              math.hypot(0.5, 0.5), "58 − 28 = 30 pp (Fig. 8 text)"))
        out["YBR rises with wall reflectance (Fig. 8)"] = _trend(
            refl[-1]["YBR"] > refl[0]["YBR"], "YBR 6 at ρ = 0.80 to 9 at ρ = 0.98", refl, "reflectance", "YBR",
            ".2f", magnitude=_magnitude(refl, "reflectance", "YBR", 0.98, 0.80, 3.0, math.hypot(0.5, 0.5),
                                        "9 − 6 = 3 (Fig. 8 text)"))
    _height_trends(out, _sorted_rows(studies, "height_mm"))
    _fwhm_trends(out, studies, _sorted_rows(studies, "led_fwhm_deg"))
    _finish_trends(out, _sorted_rows(studies, "specular_fraction"))
    return out


def _height_trends(out: dict[str, dict], height: list[dict]) -> None:
    if len(height) < 2:
        return
    out["LER falls with cavity height (Fig. 11)"] = _trend(
        all(np.diff([r["LER"] for r in height]) < 0), "LER decreases with height; best 63 % at 10 mm", height,
        "height_mm", "LER", ".1f", magnitude=_magnitude(
            height, "height_mm", "LER", 10.0, 43.0, 10.0, math.hypot(0.5, 0.5),
            "63 % at 10 mm (§6) − 53 % extracted by the 43 mm device of Fig. 11's conditions (§4) = 10 pp"))
    shortest, rest = height[0], height[1:]
    ybr43 = (_at(height, "height_mm", 43.0) or height[-1])["YBR"]
    bound = READINGS["slightly_relative"] * ybr43
    out["YBR slightly lower for short cavities (Fig. 11)"] = _trend(
        all(shortest["YBR"] < r["YBR"] for r in rest),
        "YBR slightly lower for small heights: blue light meets the plate at smaller incidences, where more "
        "blue is transmitted (bibs, Fig. 4)", height, "height_mm", "YBR", ".2f",
        "mean incidence of the blue power on the plate: " + ", ".join(
            f"{r['values']['cavity.height_mm']:g} mm: {r['plate_incidence']['mean_blue_incidence_deg']:.1f}°"
            for r in height),
        magnitude=_magnitude(height, "height_mm", "YBR", 43.0, 10.0, bound / 2, bound / 2,
                             f"'slightly' = 0 to {100 * READINGS['slightly_relative']:.1f} % of the YBR at 43 mm "
                             f"(0 to {bound:.2f})"))
    out["non-uniformity larger for short cavities (Fig. 12)"] = _trend(
        height[0]["non_uniformity"] > height[-1]["non_uniformity"], "91 % at 10 mm vs 36 % at 42 mm", height,
        "height_mm", "non_uniformity", ".1f", magnitude=_magnitude(
            height, "height_mm", "non_uniformity", 10.0, 43.0, 55.0, math.hypot(0.5, 0.5), "91 − 36 = 55 pp (§5.3)"))


def _fwhm_trends(out: dict[str, dict], studies: dict[str, list[dict]], fwhm: list[dict]) -> None:
    if len(fwhm) < 2:
        return
    lo, hi = min(fwhm, key=lambda r: r["LER"]), max(fwhm, key=lambda r: r["LER"])
    span, span_std = _difference(hi, lo, "LER")
    out["LER barely moves with LED FWHM (Fig. 13)"] = _trend(
        True, "negligible influence of the FWHM on the LER", fwhm, "led_fwhm_deg", "LER", ".1f",
        f"LER span {span:.1f} pp over the FWHM points",
        magnitude_verdict(span, span_std, 0.0, READINGS["negligible_pp"], f"'negligible' = LER span below "
                          f"{READINGS['negligible_pp']:g} pp", "pp"))
    out["YBR lower for narrow LED beams (Fig. 13)"] = _trend(
        fwhm[0]["YBR"] < fwhm[-1]["YBR"],
        "bibs transmits more blue at small incidences, which lowers the YBR of collimated LEDs", fwhm,
        "led_fwhm_deg", "YBR", ".2f")
    out["non-uniformity larger for narrow LED beams (Fig. 14)"] = _trend(
        all(np.diff([r["non_uniformity"] for r in fwhm]) < 0), "76 % at FWHM 30° (Lambertian: 36 %)", fwhm,
        "led_fwhm_deg", "non_uniformity", ".1f", magnitude=_magnitude(
            fwhm, "led_fwhm_deg", "non_uniformity", 30.0, 120.0, 40.0, math.hypot(0.5, 0.5),
            "76 − 36 = 40 pp (§5.4, Fig. 12)"))


def _finish_trends(out: dict[str, dict], spec: list[dict]) -> None:
    if len(spec) < 2:
        return
    out["non-uniformity larger for more specular walls (Fig. 10)"] = _trend(
        all(np.diff([r["non_uniformity"] for r in spec]) > 0), "56 % for a mirror, 36 % for a perfect diffuser",
        spec, "specular_fraction", "non_uniformity", ".1f", magnitude=_magnitude(
            spec, "specular_fraction", "non_uniformity", 1.0, 0.0, 20.0, math.hypot(0.5, 0.5),
            "56 − 36 = 20 pp (§5.2)"))
    bound = READINGS["slightly_pp"]
    out["LER slightly higher with more specular walls (Fig. 9)"] = _trend(
        spec[-1]["LER"] >= spec[0]["LER"], "the wall finish has no relevant effect on LER and YBR; a more specular "
        "reflector performs slightly better", spec, "specular_fraction", "LER", ".1f",
        magnitude=_magnitude(spec, "specular_fraction", "LER", 1.0, 0.0, bound / 2, bound / 2,
                             f"'slightly' = 0 to {bound:g} pp"))


def stage_fits(state: RunState) -> None:
    """Lobe fits of every elastic interaction and side (aperture-averaged), a Lambert fit of the converted light,
    and an emission-spectrum fit of the measured converted light (eq. (3) of the cylindrical-module paper).

    Parameters
    ----------
    state : RunState
        The run so far (the recipe's ``[fits]``, the calibrated scan and TIS); the fits, emission fit, their
        summary and outputs are added.
    """

    opts = state.recipe.fits
    scan, tis = state.scan, state.tis
    rows = []
    for inter in ("bibs", "biys", "yiys"):
        model = "lambert" if inter == "biys" else opts.bsdf_model
        for side in SIDES:
            prof = spectral.interaction_profile(scan, inter, side)
            prof = prof.isel(record=np.flatnonzero(np.isfinite(prof["bsdf"].values)))
            fit = fit_bsdf(prof, model)
            state.fits[(inter, side)] = (fit, prof)
            verdict = plausibility.evaluate(fit)  # the one gate of the exports, the CLI and the report
            for k, th in enumerate(fit["theta_i"].values):
                row = fit.sel(theta_i=th)
                params = {p: float(row[p]) for p in ("rho", "A", "sigma", "B", "g") if p in row}
                stds = {p: float(row[f"{p}_std"]) for p in params}
                measured = float(tis["tis"].sel(interaction=inter, side=side, theta_i=th))
                where = f"incidence {th:g} deg: "
                rows.append({"interaction": inter, "side": side, "theta_i_deg": float(th), "model": model,
                             "params": params, "std": stds, "r2": float(row["r2"]), "converged": bool(row["converged"]),
                             "model_tis": float(row["tis"]), "measured_tis": measured,
                             "tis_difference_pp": 100 * (float(row["tis"]) - measured),
                             "plausible": bool(verdict.plausible.values[k]),
                             "physically_possible": bool(verdict.physically_possible.values[k]),
                             "determined": bool(verdict.determined.values[k]),
                             "gate_reasons": [r[len(where):] for r in verdict.reasons if r.startswith(where)]})
    # the converted light's spectrum, both hemispheres, at the chosen incidence
    th = opts.emission_incidence_deg
    density = sum(angular.hemispherical_spectrum(scan, "blue", th, side) for side in SIDES)
    lam = density["wavelength"].values
    region = (lam >= 470.0) & (lam <= 780.0)
    peak = float(density.values[region].max())
    fit = fit_spectrum(lam[region], density.values[region] / peak, opts.emission_model)
    emission = {k: float(fit[k]) for k in ("peak_nm", "fwhm_nm", "alpha") if k in fit}
    emission.update({f"{k}_std": float(fit[f"{k}_std"]) for k in ("peak_nm", "fwhm_nm", "alpha") if f"{k}_std" in fit})
    emission.update(r2=float(fit["r2"]), converged=bool(fit["converged"]), incidence_deg=th, model=opts.emission_model)
    state.emission = {"fit": emission, "wavelength": lam, "measured": density.values / peak}
    state.summary["bsdf_fits"] = rows
    state.summary["emission_fit"] = emission
    state.outputs["bsdf_fits.json"] = lambda p, force: write_text(p, dumps(rows), force)
    fig = bsdf_fits_figure(state.fits)
    state.outputs["bsdf_fits.png"] = FigureFile(fig)
    worst = max(rows, key=lambda r: abs(r["tis_difference_pp"]))
    failing = [r for r in rows if not r["plausible"]]
    gate = (f"{len(failing)}/{len(rows)} FAIL the plausibility gate (" + "; ".join(
        f"{r['interaction']} {r['side']} {r['theta_i_deg']:g} deg: {r['gate_reasons'][0]}" for r in failing[:3])
        + ("; ..." if len(failing) > 3 else "") + ")") if failing else "all pass the plausibility gate"
    state.summary["bsdf_fit_gate"] = {
        "thresholds": asdict(plausibility.THRESHOLDS), "failing": len(failing), "fits": len(rows),
        "exported": "no fit is exported by this job (its tables are written from the calibrated scan)"}
    state.summary.setdefault("report_lines", []).extend([
        f"BSDF fits: {sum(r['converged'] for r in rows)}/{len(rows)} converged, {gate}; fitted-model TIS within "
        f"{abs(worst['tis_difference_pp']):.3f} pp of the measured TIS (worst {worst['interaction']} {worst['side']} "
        f"{worst['theta_i_deg']:g} deg)",
        f"emission fit ({opts.emission_model}, θi = {th:g}°): peak {emission['peak_nm']:.1f} nm, "
        f"FWHM {emission['fwhm_nm']:.1f} nm, "
        f"α {emission.get('alpha', 0.0):.3f}, R² {emission['r2']:.4f}"])


def stage_spectrum(state: RunState) -> None:
    """The module's absolute spectrum from the two-wavelength result (§4.2, Fig. 7 of the cylindrical-module
    paper) and its colour (colour-science): x, y, CCT, Duv, luminous efficacy of radiation, YBR.

    Parameters
    ----------
    state : RunState
        The run so far (the emission fit; the device trace's extracted flux [W], else the recipe's
        ``fits.fallback_flux_W``); the module spectrum [W/nm], its colour and outputs are added.
    """

    opts = state.recipe.fits
    if not state.emission:
        return
    lam = np.arange(380.0, 780.0 + 1e-9, 1.0)
    s_blue = spectrum_model_values("gaussian", {"peak_nm": opts.led_peak_nm, "fwhm_nm": opts.led_fwhm_nm,
                                                "amplitude": 1.0}, lam)
    e = state.emission["fit"]
    s_yellow = spectrum_model_values(opts.emission_model, {"peak_nm": e["peak_nm"], "fwhm_nm": e["fwhm_nm"],
                                                           "alpha": e.get("alpha", 0.0), "amplitude": 1.0}, lam)
    if state.device is not None:
        flux = (float(state.device.extracted["blue"]), float(state.device.extracted["yellow"]))
        source = f"module trace ({state.recipe.trace.rays} rays, LED power {state.device.emitted:g} W)"
    else:
        flux = opts.fallback_flux_W
        source = "fits.fallback_flux_W (Table 1 of the cylindrical-module paper)"
    sd = reconstruct_two_band_spectrum(lam, s_blue, s_yellow, flux[0], flux[1], name=f"{state.recipe.name} module")
    colour_ = colorimetric_summary(sd)
    result = {"flux_W": {"blue": flux[0], "yellow": flux[1]}, "flux_source": source,
              "led_spectrum": {"peak_nm": opts.led_peak_nm, "fwhm_nm": opts.led_fwhm_nm},
              "colour": {"x": colour_.x, "y": colour_.y, "cct_K": colour_.cct_K, "duv": colour_.duv,
                         "luminous_efficacy_lm_per_W": colour_.luminous_efficacy_lm_per_W, "ybr": colour_.ybr,
                                     "ybr_bands_nm": {"yellow": list(COLORIMETRY_YELLOW_BAND_NM),
                                                      "blue": list(COLORIMETRY_BLUE_BAND_NM)}}}
    state.summary["module_spectrum"] = result
    csv = "wavelength_nm,spectral_flux_W_per_nm\n" + "".join(f"{w:.1f},{v:.8e}\n"
                                                             for w, v in zip(sd.wavelengths, sd.values))
    state.outputs["module_spectrum.csv"] = lambda p, force: write_text(p, csv, force)
    fig = module_spectrum_figure(lam, s_blue, s_yellow, state.emission, sd)
    state.outputs["module_spectrum.png"] = FigureFile(fig)
    state.outputs["module_spectrum.json"] = lambda p, force: write_text(p, dumps(result), force)
    c = result["colour"]
    state.summary.setdefault("report_lines", []).append(
        f"module spectrum from {source}: x {c['x']:.4f}, y {c['y']:.4f}, CCT {c['cct_K']:.0f} K, Duv {c['duv']:.4f}, "
        f"{c['luminous_efficacy_lm_per_W']:.0f} lm/W, spectrum YBR {c['ybr']:.2f} "
        f"({band_label(COLORIMETRY_YELLOW_BAND_NM)} / {band_label(COLORIMETRY_BLUE_BAND_NM)})")


def stage_spectral_comparison(state: RunState) -> None:
    """Both tracer modes on one plate from the ``[spectral]`` measurement (issue 17; module
    :mod:`bsdfkit.pipeline.spectral_comparison`).

    Parameters
    ----------
    state : RunState
        The run so far (the recipe's ``[spectral]``; nothing is done without one); the comparison's summary,
        lines and outputs are added.
    """
    opts = state.recipe.spectral
    if opts is None:
        return
    result = None
    if state.spectral_ahead is not None:
        try:
            result = state.spectral_ahead.result()
        except Exception as exc:  # the helper failed or died: computed here (a real error is raised here)
            state.log(f"spectral comparison: the helper process failed ({type(exc).__name__}); computing it here")
    if result is None:
        result = compare_tracer_modes(opts, _scene_with_plate)
    state.summary["spectral_comparison"] = result.summary
    state.outputs.update(comparison_outputs(result))
    state.summary.setdefault("report_lines", []).extend(comparison_lines(result.summary))


STAGES: tuple[tuple[str, Callable[[RunState], None]], ...] = (
    ("ingest", stage_ingest),
    ("report", stage_report),
    ("reductions", stage_reductions),
    ("exports", stage_exports),
    ("fits", stage_fits),
    ("trace", stage_trace),
    ("spectrum", stage_spectrum),
    ("spectral comparison", stage_spectral_comparison),
)


def run(recipe: Recipe | str | Path, out_dir: str | Path, force: bool = False,
        log: Callable[[str], None] = lambda message: None,
        progress: Callable[[str, int, int], None] | None = None,
        helper_processes: bool | ProcessPoolExecutor = False) -> dict:
    """Run every stage of ``recipe`` and write its outputs into ``out_dir``; returns the run summary.

    ``log(message)`` receives one line per stage; ``progress(task, done, total)`` is called as the stages
    (task ``"stages"``) and the traces of the trace stage (task ``"trace"``) complete.

    Parameters
    ----------
    recipe : Recipe or str or pathlib.Path
        A recipe, or its TOML file.
    out_dir : str or pathlib.Path
        Output folder.
    force : bool
        Overwrite existing outputs.
    log : callable
        ``log(message)``, called with one line per stage.
    progress : callable, optional
        ``progress(task, done, total)``, called as stages and traces complete.
    helper_processes : bool or ProcessPoolExecutor
        Use a spawned helper process (what the command line does): it computes the spectral comparison from
        the start of the run, beside the stages before it, then draws the figures with this process. The
        results are those of the same stages in this process. A spawned process imports the caller's main
        script again, so a script that calls this without an ``if __name__ == "__main__":`` guard would run
        twice: off by default. A helper of :func:`bsdfkit.pipeline.helper.helper_process` is used as given
        (the command line starts it before importing the pipeline; the caller ends it).

    Returns
    -------
    dict
        The run summary (as written to summary.json).
    """
    recipe = recipe if isinstance(recipe, Recipe) else load_recipe(recipe)
    out_dir = Path(out_dir)
    inputs = (recipe.path, recipe.measurement, recipe.trace.scene,
              *((recipe.spectral.measurement, recipe.spectral.scene) if recipe.spectral else ()))
    # checked before computing: existing outputs (without force), outputs that are inputs, a writable folder
    with OutputSet(out_dir, expected_outputs(recipe), force, inputs, min_free_bytes=_output_estimate(recipe),
                   whole_folder=True) as out:
        return _run_stages(recipe, out, log, progress, helper_processes)


def _output_estimate(recipe: Recipe) -> int:
    """A conservative estimate of a run's output size (outputs are ~17x the raw measurement; 10x is asked)."""
    size = 0
    for path in recipe.measurement.rglob("*"):
        with contextlib.suppress(OSError):
            size += path.stat().st_size if path.is_file() else 0
    return 10 * size


def _spectral_comparison(options: SpectralComparisonOptions) -> SpectralComparison:
    """:func:`compare_tracer_modes` with this recipe module's scene builder (a module-level function: what a
    spawned helper process is given to call)."""
    return compare_tracer_modes(options, _scene_with_plate)


def _spectral_ahead(recipe: Recipe, helper: ProcessPoolExecutor | None) -> Future | None:
    """The spectral comparison started in the ``helper`` process (None without a helper or a ``[spectral]``
    table).

    It needs nothing from the other stages (its own measurement, plates and traces): started with the run, it
    uses the core that ingest, reductions and fits leave idle, and its traces share both cores with the trace
    stage's. The helper inherits this process's environment (JAX's compilation cache, the CPU device count).
    """
    if helper is None or recipe.spectral is None:
        return None
    try:
        return helper.submit(_spectral_comparison, recipe.spectral)
    except (BrokenProcessPool, RuntimeError):
        return None  # computed by the stage itself


def _run_stages(recipe: Recipe, out: OutputSet, log: Callable[[str], None],
                progress: Callable[[str, int, int], None] | None = None,
                helper_processes: bool | ProcessPoolExecutor = False) -> dict:
    state = RunState(recipe=recipe, log=log)
    if progress is not None:
        state.progress = progress
    timings: dict[str, float] = {}
    given = helper_processes if isinstance(helper_processes, ProcessPoolExecutor) else None
    with contextlib.nullcontext(given) if given else helper_process(bool(helper_processes)) as helper:
        state.spectral_ahead = _spectral_ahead(recipe, helper)
        # the figures are drawn by the helper process once it has computed the spectral comparison (each as soon
        # as its stage has queued it), and by both processes after the stages (after the traces, one core drew
        # them all while the other idled)
        with PngRenderer(helper=helper is not None, pool=helper) as renderer:
            figures = _stages(state, out, timings, renderer)
            summary = _write_outputs(state, out, timings, figures)
            log("stage html report ...")
            # reads the staged outputs; part of the same set
            write_report(out.path("summary.json").parent, force=True, renderer=renderer)
    return summary


def _stages(state: RunState, out: OutputSet, timings: dict[str, float], renderer: PngRenderer
            ) -> dict[str, PendingPng]:
    """Every stage in turn (their seconds into ``timings``); :class:`EarlyWriter` outputs are written by a
    background thread, and :class:`FigureFile` outputs submitted to ``renderer``, as soon as their stage has
    queued them. Returns the figures being drawn."""
    early: dict[str, Future] = {}
    figures: dict[str, PendingPng] = {}
    # the tables (auto grids, each re-read and checked: a quarter of the run's CPU after the stages) are written
    # by a thread while the fits and traces run: the traces' kernels hold no interpreter lock
    with ThreadPoolExecutor(1) as background:
        try:
            for k, (name, stage) in enumerate(STAGES):
                start = time.perf_counter()
                state.log(f"stage {name} ...")
                state.progress("stages", k, len(STAGES))
                stage(state)
                timings[name] = round(time.perf_counter() - start, 3)
                early.update({n: background.submit(w, out.path(n), True) for n, w in state.outputs.items()
                              if isinstance(w, EarlyWriter) and n not in early})
                figures.update({n: renderer.submit(w.figure, w.dpi) for n, w in state.outputs.items()
                                if isinstance(w, FigureFile) and n not in figures})
            for future in early.values():
                future.result()  # a failed table fails the run here, as it would have when written below
        except BaseException:
            for future in early.values():
                future.cancel()  # a failed run does not wait for the tables not yet begun
            raise
    state.progress("stages", len(STAGES), len(STAGES))
    return figures


def _write_outputs(state: RunState, out: OutputSet, timings: dict, figures: dict[str, PendingPng]) -> dict:
    """Every queued output and summary.json into the staging folder (moved into place when the set is complete);
    ``figures`` are the figures being drawn. Returns the summary."""
    recipe = state.recipe
    names = list(state.outputs) + ["summary.json", "report.html"]
    for name, writer in state.outputs.items():
        if name not in figures and not isinstance(writer, EarlyWriter):  # early writers have written already
            writer(out.path(name), True)
    for name, png in zip(figures, png_results(list(figures.values()))):
        write_bytes(out.path(name), png, True)
    checks = state.summary.get("export_checks")
    if checks:
        worst = max(checks, key=lambda c: c["relative_difference"])
        state.summary.setdefault("report_lines", []).append(
            f"exports: {len({c['file'] for c in checks})} tables re-read; TIS of every table within "
            f"{100 * worst['relative_difference']:.3f} % of its source "
            f"(worst: {worst['file']} at {worst['theta_i_deg']:g} deg)")
    summary = {"recipe": recipe.name, "recipe_file": str(recipe.path), "measurement": str(recipe.measurement),
               "outputs": names, "stage_seconds": timings, **state.summary}

    write_text(out.path("summary.json"), dumps(summary), True)
    return summary
