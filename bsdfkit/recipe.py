"""Fit/run recipes: ``bsdfkit run fitting/<name>.toml -o OUT/`` — the main job.

A recipe names a measurement folder and the stages to run on it. Each stage is a function of the recipe and
the products of earlier stages; it returns its part of the run summary and the files it wants written. All
outputs are collected first and written atomically at the end, after checking that none exists (unless
``force``), so a failed or interrupted run never leaves a half-written output set behind.
"""
from __future__ import annotations

import json
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bsdfkit.errors import FormatError, InputError, NumericalError
from bsdfkit.io import atomic, netcdf

KNOWN_SECTIONS = {
    "recipe": {"name", "measurement", "description"},
    "report": {"figure_config", "figure_wavelength_nm"},
    "reductions": {"budget_incidence_deg", "eta_mc", "iterations"},
    "exports": {"interactions", "sides", "formats", "tolerance"},
}


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
    sides: tuple[str, ...] = ("reflection", "transmission")
    formats: tuple[str, ...] = ("tracepro", "zemax")
    tolerance: float = 0.005  # relative: re-read table TIS vs the source's TIS


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
        raise InputError("recipe value of the wrong type", file=path, field=dotted, expected=getattr(kind, "__name__", str(kind)), got=value)
    return value


def load_recipe(path: str | Path) -> Recipe:
    """Parse and validate a recipe TOML file."""
    path = Path(path)
    if not path.is_file():
        raise InputError("recipe not found", file=path, expected="a TOML recipe file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"not valid TOML ({exc})", file=path) from None
    _check_keys(data, path)
    head = data.get("recipe")
    if head is None:
        raise InputError("recipe section missing", file=path, field="recipe")
    measurement = (path.parent / _typed(head, "measurement", str, path, "recipe.measurement")).resolve()
    rep = data.get("report", {})
    report = ReportOptions(
        figure_config=_typed(rep, "figure_config", str, path, "report.figure_config", "blue"),
        figure_wavelength_nm=float(_typed(rep, "figure_wavelength_nm", (int, float), path, "report.figure_wavelength_nm", 460.0)),
    )
    red = data.get("reductions", {})
    reductions = ReductionOptions(
        budget_incidence_deg=float(_typed(red, "budget_incidence_deg", (int, float), path, "reductions.budget_incidence_deg", 45.0)),
        eta_mc=float(_typed(red, "eta_mc", (int, float), path, "reductions.eta_mc", 0.94)),
        iterations=int(_typed(red, "iterations", int, path, "reductions.iterations", 7)),
    )
    exp = data.get("exports", {})
    exports = ExportOptions(
        interactions=tuple(_choices(exp, "interactions", ("bibs", "biys", "yiys"), path)),
        sides=tuple(_choices(exp, "sides", ("reflection", "transmission"), path)),
        formats=tuple(_choices(exp, "formats", ("tracepro", "zemax", "asap"), path, default=("tracepro", "zemax"))),
        tolerance=float(_typed(exp, "tolerance", (int, float), path, "exports.tolerance", 0.005)),
    )
    return Recipe(path=path, name=_typed(head, "name", str, path, "recipe.name"), measurement=measurement,
                  description=_typed(head, "description", str, path, "recipe.description", ""), report=report,
                  reductions=reductions, exports=exports, raw=data)


def _choices(table: dict, key: str, allowed: tuple[str, ...], path: Path, default: tuple[str, ...] | None = None) -> list[str]:
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
    tables: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    outputs: dict[str, Callable[[Path, bool], object]] = field(default_factory=dict)
    log: Callable[[str], None] = lambda message: None


def stage_ingest(state: RunState) -> None:
    """Read the raw export, calibrate it, and queue ``scan.nc``."""
    from bsdfkit.calibrate import calibrate
    from bsdfkit.io.goniometer import read_scan
    from bsdfkit.summary import describe

    state.scan = calibrate(read_scan(state.recipe.measurement))
    scan = state.scan
    state.summary["scan"] = describe(scan)
    state.outputs["scan.nc"] = lambda p, force: netcdf.save(scan, p, force)


def stage_report(state: RunState) -> None:
    """Queue the in-plane BSDF figure (Fig. 6 analogue)."""
    from bsdfkit.report import in_plane_bsdf_figure, save_figure

    opts = state.recipe.report
    fig = in_plane_bsdf_figure(state.scan, opts.figure_config, opts.figure_wavelength_nm)
    state.outputs["inplane_bsdf.png"] = lambda p, force: save_figure(fig, p, force)


def stage_reductions(state: RunState) -> None:
    """TIS with error bars, the Table-2-style interaction tables, EQE, and the iterative module budget."""
    from bsdfkit import angular, budget
    from bsdfkit.io.atomic import write_text
    from bsdfkit.records import incidences
    from bsdfkit.report import budget_figure, save_figure
    from bsdfkit.commands._common import dumps

    opts = state.recipe.reductions
    scan = state.scan
    state.tis = angular.tis_table(scan)
    tables = {f"{th:g}": budget.interaction_table(scan, th, state.tis) for th in incidences(scan)}
    state.tables = tables
    key = f"{opts.budget_incidence_deg:g}"
    if key not in tables:
        raise InputError("budget incidence not measured", file=state.recipe.path, field="reductions.budget_incidence_deg",
                         expected="one of " + ", ".join(tables), got=opts.budget_incidence_deg)
    t = tables[key]
    power = budget.module_budget(t.power, opts.eta_mc, opts.iterations)
    photons = budget.module_budget(t.photons, opts.eta_mc, opts.iterations)
    from bsdfkit.calibrate import truth_tis

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
    state.outputs["module_budget.png"] = lambda p, force: save_figure(fig, p, force)
    lines = [f"interaction table at {key} deg (percent of incident power / photons):"]
    for k in budget.KEYS:
        extra = f"   truth {truth[key][k]:6.2f}" if truth and key in truth else ""
        lines.append(f"  {k:14s} {t.power[k]:6.2f} ± {t.power_std[k]:.2f}   {t.photons[k]:6.2f}{extra}")
    lines.append(f"  EQE {t.eqe:.3f} ± {t.eqe_std:.3f}")
    last = power.iterations[-1]
    lines.append(f"module budget (η_MC = {opts.eta_mc:g}, {opts.iterations} plate interactions): blue {last['blue']:.2f}, "
                 f"yellow {last['yellow']:.2f}, total {last['total']:.2f} %; converged total {power.converged['total']:.2f} %")
    state.summary.setdefault("report_lines", []).extend(lines)


def stage_exports(state: RunState) -> None:
    """Queue TracePro/Zemax tables of each interaction and side; each is re-read and its TIS checked.

    The tables go into OUT/exports/. Their writer runs with the other outputs (atomic, no clobbering); it
    records, per file, the source TIS (direct integral of the reconstructed hemisphere) and the TIS recomputed
    from the file as read back, and fails the run if they differ by more than the recipe's tolerance.
    """
    from bsdfkit import export as exporter

    opts = state.recipe.exports
    scan = state.scan
    checks: list[dict] = []
    state.summary["export_checks"] = checks
    suffix = {"tracepro": "tracepro.txt", "zemax": "zemax.bsdf", "asap": "asap.txt"}

    def writer(inter: str, side: str, fmt: str):
        def write(path: Path, force: bool) -> None:
            result = exporter.export(scan, fmt, inter, side, path, force)
            summary = exporter.read_any(path)
            for k, th in enumerate(summary.incidences_deg):
                src = result.tis_source[side][k]
                got = summary.tis_computed[side][k]
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
                state.outputs[f"exports/{inter}_{side}.{suffix[fmt]}"] = writer(inter, side, fmt)


STAGES: tuple[tuple[str, Callable[[RunState], None]], ...] = (
    ("ingest", stage_ingest),
    ("report", stage_report),
    ("reductions", stage_reductions),
    ("exports", stage_exports),
)


def run(recipe: Recipe | str | Path, out_dir: str | Path, force: bool = False,
        log: Callable[[str], None] = lambda message: None) -> dict:
    """Run every stage of ``recipe`` and write its outputs into ``out_dir``; returns the run summary."""
    recipe = recipe if isinstance(recipe, Recipe) else load_recipe(recipe)
    out_dir = Path(out_dir)
    state = RunState(recipe=recipe, log=log)
    timings = {}
    for name, stage in STAGES:
        start = time.perf_counter()
        log(f"stage {name} ...")
        stage(state)
        timings[name] = round(time.perf_counter() - start, 3)
    names = list(state.outputs) + ["summary.json"]
    for name in names:
        atomic.check_writable(out_dir / name, force)
    for name, writer in state.outputs.items():
        writer(out_dir / name, force)
    checks = state.summary.get("export_checks")
    if checks:
        worst = max(checks, key=lambda c: c["relative_difference"])
        state.summary.setdefault("report_lines", []).append(
            f"exports: {len({c['file'] for c in checks})} tables re-read; TIS of every table within "
            f"{100 * worst['relative_difference']:.3f} % of its source (worst: {worst['file']} at {worst['theta_i_deg']:g} deg)")
    summary = {"recipe": recipe.name, "recipe_file": str(recipe.path), "measurement": str(recipe.measurement),
               "outputs": names, "stage_seconds": timings, **state.summary}
    from bsdfkit.commands._common import dumps

    atomic.write_text(out_dir / "summary.json", dumps(summary), force)
    return summary


# ------------------------------------------------------------------------------------- the plate
def plate_from_scan(scan: xr.Dataset, tis: xr.Dataset | None = None, name: str = ""):
    """A :class:`bsdfkit.trace.PhosphorPlate` from a calibrated scan: the toolkit's own TIS per interaction,
    side and measured incidence, with angular shapes from lambert+gaussian fits for the elastic
    interactions (bibs, yiys) and Lambertian for the converted light (biys, §4.2 of the power-budget paper)."""
    from bsdfkit import angular, spectral
    from bsdfkit.fit import fit_bsdf
    from bsdfkit.trace.plate import LambertGaussian, Lambertian, PhosphorPlate, PlateChannel

    tis = tis if tis is not None else angular.tis_table(scan)
    grid = tuple(float(t) for t in tis["theta_i"].values)
    channels = {}
    for inter in ("bibs", "biys", "yiys"):
        for side in ("reflection", "transmission"):
            values = tuple(float(np.clip(tis["tis"].sel(interaction=inter, side=side, theta_i=t), 0.0, 1.0)) for t in grid)
            if inter == "biys":
                dists = (Lambertian(),) * len(grid)
            else:
                prof = spectral.interaction_profile(scan, inter, side)
                prof = prof.isel(record=np.flatnonzero(np.isfinite(prof["bsdf"].values)))
                fit = fit_bsdf(prof, "lambert+gaussian")
                dists = tuple(LambertGaussian(rho_per_sr=float(fit["rho"].sel(theta_i=t)) / np.pi,
                                              a_per_sr=float(fit["A"].sel(theta_i=t)),
                                              sigma=float(fit["sigma"].sel(theta_i=t))) for t in grid)
            channels[f"{inter}_{side}"] = PlateChannel(values, dists)
    plate = PhosphorPlate(theta_i_deg=grid, name=name or scan.attrs.get("sample_name", ""),
                          notes=f"from {scan.attrs.get('source', '')}: bsdfkit TIS (two-arc reconstruction) and "
                                "lambert+gaussian fits", **channels)
    plate.validate()
    return plate


def phosphor_plate(recipe_path: str | Path):
    """The phosphor plate of a recipe's measurement (for scenes with ``[top] from = "fitting/<recipe>.toml"``)."""
    from bsdfkit.calibrate import calibrate
    from bsdfkit.io.goniometer import read_scan

    recipe = load_recipe(recipe_path)
    return plate_from_scan(calibrate(read_scan(recipe.measurement)), name=recipe.name)
