"""The HTML run report (issue #16): one self-contained file, written atomically, readable in a browser."""
from __future__ import annotations

import base64
import itertools
import json
import math
import re
import shutil
import subprocess
import tomllib
from html import escape as html_escape
from html import unescape as html_unescape

import numpy as np
import pytest
import xarray as xr
from conftest import ROOT, fast_lane
from matplotlib import image as mpimg
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bsdfkit.core.errors import InputError, OutputExistsError
from bsdfkit.io import netcdf
from bsdfkit.pipeline import report as report_module
from bsdfkit.pipeline.report import REPORT_NAME, paper_values, write_report
from bsdfkit.plotting.maps import (
    find_map_variable,
    irradiance_map_figure,
    irradiance_maps_figure,
    map_non_uniformity,
)
from bsdfkit.raytrace.tallies import non_uniformity

SMALL_SUMMARY = ROOT / "tests" / "data" / "run_summary_small.json"
DATA_URI = '<img src="data:image/png;base64,'
RADIUS_MM = 35.0
BINS = 16


def _map(scale: float = 1.0, tilt: float = 0.0) -> np.ndarray:
    """A smooth irradiance map (W/mm^2 for 1 W emitted) peaked in the centre."""
    c = (np.arange(BINS) + 0.5) / BINS * 2 * RADIUS_MM - RADIUS_MM
    x, y = np.meshgrid(c, c)
    return scale * 2e-4 * (1.0 + 0.3 * np.exp(-(x ** 2 + y ** 2) / 400.0) + tilt * x / RADIUS_MM)


def _coords() -> dict:
    c = (np.arange(BINS) + 0.5) / BINS * 2 * RADIUS_MM - RADIUS_MM
    return {"y_mm": ("y_mm", c, {"units": "mm"}), "x_mm": ("x_mm", c, {"units": "mm"})}


def _device_dataset() -> xr.Dataset:
    """Like ``TraceResult.to_dataset()``: the map and its non-uniformity as the tracer computes it."""
    e = _map()
    ds = xr.Dataset({"irradiance": (("y_mm", "x_mm"), e, {"units": "W/mm^2",
                                                          "long_name": "irradiance on the cavity side of the top"}),
                     "non_uniformity": ((), non_uniformity(e), {"units": "1"}),
                     "LER": ((), 0.56, {"units": "1"})}, coords=_coords())
    ds.attrs.update(rays=1000, seed=1, emitted_W=1.0)
    return ds


def _sweep_dataset() -> xr.Dataset:
    """Like ``sweep_dataset``: maps with a swept parameter (wall finish: diffuse and mirror walls)."""
    maps = np.stack([_map(), _map(1.1, tilt=0.4)])
    coords = _coords() | {"wall.specular_fraction": ("wall.specular_fraction", [0.0, 1.0])}
    ds = xr.Dataset({"irradiance": (("wall.specular_fraction", "y_mm", "x_mm"), maps, {"units": "W/mm^2"})},
                    coords=coords)
    ds.attrs.update(emitted_W=1.0)
    return ds


def _png(path, colour: str) -> None:
    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot([0, 1, 2], [1, 3, 2], color=colour, label="data")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (1)")
    ax.legend()
    fig.savefig(path, format="png", dpi=60)


def _trace_json(summary: dict) -> dict:
    device_ler = summary["trace"]["device"]["LER"]

    def row(values, ler, nu):
        return {"values": values, "LER": ler, "LER_std": 4e-4, "YBR": 6.0 + 3 * ler, "YBR_std": 0.05,
                "non_uniformity": nu, "ledger_error": 1e-14}

    return {"device": {"LER": device_ler},
            "studies": {"reflectance": [row({"wall.reflectance": 0.8, "base.reflectance": 0.8}, 0.30, 0.23),
                                        row({"wall.reflectance": 0.98, "base.reflectance": 0.98}, 0.55, 0.16)],
                        "height_mm": [row({"cavity.height_mm": 10.0}, 0.59, 0.70),
                                      row({"cavity.height_mm": 43.0}, device_ler, 0.16)],
                        "specular_fraction": [row({"wall.specular_fraction": 0.0}, 0.56, 0.16),
                                              row({"wall.specular_fraction": 1.0}, 0.57, 0.47)]}}


def _make_run(folder):
    """A small finished run folder: summary, trace.json, two map files, one file without a map, two figures."""
    folder.mkdir(parents=True)
    summary = json.loads(SMALL_SUMMARY.read_text(encoding="utf-8"))
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    (folder / "trace.json").write_text(json.dumps(_trace_json(summary)), encoding="utf-8")
    netcdf.save(_device_dataset(), folder / "trace_device.nc")
    netcdf.save(_sweep_dataset(), folder / "trace_specular_fraction.nc")
    netcdf.save(xr.Dataset({"LER": ((), 0.5)}), folder / "trace_nomap.nc")
    _png(folder / "inplane_bsdf.png", "tab:blue")
    _png(folder / "extra_figure.png", "tab:red")
    return folder


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = _make_run(tmp_path_factory.mktemp("report") / "run")
    path = write_report(folder)
    return folder, path, path.read_text(encoding="utf-8")


def test_report_is_one_self_contained_file(built):
    folder, path, text = built
    assert path == folder / REPORT_NAME
    # every image is an embedded PNG: the run's figures, the drawn Table 2 and budget comparisons, and the map
    # grids of Fig. 10 (the wall-finish sweep file) and Fig. 12 (h = 43 mm: the device's map)
    images = re.findall(r"<img\b", text)
    assert len(images) == text.count(DATA_URI)
    pngs = sorted(folder.glob("*.png"))
    assert text.count(DATA_URI) == len(pngs) + 2 + 2
    for png in pngs:
        assert base64.b64encode(png.read_bytes()).decode("ascii") in text, png.name
    for uri in re.findall(r'src="data:image/png;base64,([^"]+)"', text):
        assert base64.b64decode(uri)[:8] == b"\x89PNG\r\n\x1a\n"
    # nothing leaves the file: no URL, no script, no external stylesheet or font
    assert not re.search(r"https?://", text, re.IGNORECASE)
    assert "<script" not in text.lower()
    assert "<link" not in text.lower() and "@import" not in text and "url(" not in text
    assert not re.search(r'\bsrc="(?!data:image/png;base64,)', text)


def test_report_opens_with_the_measurement_and_findings_and_compares_with_the_papers(built):
    _, _, text = built
    opening = text[:text.index('<section id="measurement">')]
    for needle in ("What was measured", "What was found", "cl830-synthetic", "Synthetic data", "5°, 45°, 56°",
                   "10.91 ± 0.06", "0.802 ± 0.001", "53.8 %", "56.17 ± 0.02 %", "8.47 ± 0.05",
                   "yellow / blue extracted ray power", "x 0.4411, y 0.4413", "CCT 3213 K",
                   "Where this run disagrees with the papers"):
        assert needle in opening, needle
    # Table 2's printed blue-loss entry does not add up: the report says the run differs there
    assert re.search(r"Table 2 power blue_losses at 45°: this run 31\.67 %, paper 32\.7 %", text)
    for section in ("Table 2 of [Power-budget]", "Table 3 of [Power-budget]", "Table 1 of [Cylindrical-module]",
                    "Fig. 8", "Figs. 10, 12, 14"):
        assert section in text, section
    # the maps: the sweep file covers Fig. 10's mirror and diffuser panels; the missing panels are named
    assert "trace_device.nc" in text and "trace_specular_fraction.nc" in text and "trace_nomap.nc" not in text
    missing = re.search(r"Maps of the paper not in this run: ([^<]*)</p>", text).group(1)
    assert "Fig. 12 h = 10 mm" in missing and "Fig. 14 FWHM 30°" in missing
    assert "Fig. 10 specular reflector" not in missing and "Fig. 10 perfect diffuser" not in missing
    assert "Fig. 12 h = 43 mm" not in missing  # the device is the h = 43 mm study point (same trace)
    assert "extra_figure.png" in text[text.index('id="other"'):]


def test_report_is_written_atomically_and_never_overwritten_without_force(tmp_path, monkeypatch):
    folder = _make_run(tmp_path / "run")
    (folder / REPORT_NAME).write_text("previous report", encoding="utf-8")
    with pytest.raises(OutputExistsError):
        write_report(folder)
    assert (folder / REPORT_NAME).read_text(encoding="utf-8") == "previous report"

    def boom(self):
        raise RuntimeError("killed while writing")

    # a failure while the report is built leaves the previous report and no temporary file
    monkeypatch.setattr(report_module._Report, "build", boom)
    with pytest.raises(RuntimeError):
        write_report(folder, force=True)
    assert (folder / REPORT_NAME).read_text(encoding="utf-8") == "previous report"
    monkeypatch.undo()
    path = write_report(folder, force=True)
    assert path.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")
    assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == []


def test_report_needs_a_finished_run_folder(tmp_path):
    with pytest.raises(InputError, match="summary.json"):
        write_report(tmp_path)
    assert not (tmp_path / REPORT_NAME).exists()


def test_report_of_a_run_without_trace_or_figures_says_what_is_missing(tmp_path):
    summary = json.loads(SMALL_SUMMARY.read_text(encoding="utf-8"))
    for key in ("trace", "module_spectrum", "bsdf_fits", "emission_fit"):
        summary.pop(key)
    (tmp_path / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    text = write_report(tmp_path).read_text(encoding="utf-8")
    assert "No trace in summary.json." in text and "No trace_*.nc file with an irradiance map" in text
    assert "inplane_bsdf.png is not in the run folder." in text
    assert text.count(DATA_URI) == len(re.findall(r"<img\b", text)) >= 2  # the drawn Table 2 and budget figures


def test_paper_values_ship_with_the_package_and_name_their_sources():
    values = paper_values()
    titles = {p["title"] for p in values["source"].values() if isinstance(p, dict)}
    assert "Power and photon budget of a remote phosphor LED module" in titles
    assert ("Impact of the Geometrical and Optical Parameters on the Performance of a Cylindrical Remote Phosphor "
            "LED") in titles
    assert values["power_budget"]["table2_tis_45deg_percent"]["power"]["B_bibs"] == 10.9
    assert values["cylindrical_module"]["table1_flux_W"]["simulation"]["total"] == 0.530
    raw = (ROOT / "bsdfkit" / "pipeline" / "paper_values.json").read_text(encoding="utf-8")
    assert "/work" not in raw and "seed" not in raw.lower()
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert "pipeline/*.json" in setuptools["package-data"]["bsdfkit"]


def test_irradiance_map_figure_reads_like_an_engineering_figure():
    ds = _device_dataset()
    assert find_map_variable(ds) == "irradiance"
    assert map_non_uniformity(ds["irradiance"]) == pytest.approx(float(ds["non_uniformity"]), rel=1e-12)
    fig = irradiance_map_figure(ds["irradiance"], emitted_W=1.0)
    ax, bar = fig.axes
    assert "(mm)" in ax.get_xlabel() and "(mm)" in ax.get_ylabel()
    assert ax.get_aspect() == 1.0
    assert f"{100 * float(ds['non_uniformity']):.1f} %" in ax.get_title()
    assert "W/m²" in bar.get_ylabel()
    # the colour bar spans exactly E_min … E_max of the bins inside the plate (W/mm^2 → W/m^2)
    lo, hi = ax.collections[0].get_clim()
    assert (hi - lo) / (hi + lo) == pytest.approx(float(ds["non_uniformity"]), rel=1e-9)


def test_irradiance_maps_grid_of_a_sweep_shares_one_colour_bar():
    da = _sweep_dataset()["irradiance"]
    fig = irradiance_maps_figure(da, emitted_W=1.0)
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.get_xlabel()]
    assert len(panels) == 2
    assert all("wall.specular_fraction" in ax.get_title() and "non-uniformity" in ax.get_title() for ax in panels)
    assert len({ax.collections[0].get_clim() for ax in panels}) == 1
    grid = irradiance_maps_figure({f"h = {h} mm": _device_dataset()["irradiance"] for h in (10, 43, 80)},
                                  shared_scale=False)
    assert len([ax for ax in grid.axes if "W/m²" in ax.get_ylabel()]) == 3  # one colour bar per panel



def _overlap(a, b) -> float:
    """Area [px²] two display boxes share."""
    return max(0.0, min(a.x1, b.x1) - max(a.x0, b.x0)) * max(0.0, min(a.y1, b.y1) - max(a.y0, b.y0))


def _inside_and_apart(fig, dpi: float) -> None:
    """Drawn at ``dpi``, every visible axes with its ticks, labels and title, and the figure title, lie inside the
    figure, and no two of them share a pixel (what a layout engine would ensure)."""
    fig.set_dpi(dpi)
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    boxes = [ax.get_tightbbox(renderer) for ax in fig.axes if ax.get_visible()]
    if fig._suptitle is not None:
        boxes.append(fig._suptitle.get_window_extent(renderer))
    frame = fig.bbox
    for box in boxes:
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1, box
    assert all(_overlap(a, b) == 0.0 for k, a in enumerate(boxes) for b in boxes[k + 1:])


@pytest.mark.parametrize("count, ncols", fast_lane([(3, 3), (5, 3), (5, 5)], fast=[(5, 3)]))
def test_irradiance_maps_fixed_margins_keep_every_text_inside_and_apart(count, ncols):
    """The map grid's fixed margins (no layout engine), at the report's dpi: panels with three-line titles and
    the shared colour bar with its two-line label."""
    da = _device_dataset()["irradiance"]
    maps = {f"panel {k} (trace_device.nc)\npaper: 36 %": da * (1.0 + 0.1 * k) for k in range(count)}
    fig = irradiance_maps_figure(maps, ncols=ncols, emitted_W=1.0, title="Fig. 12 of [Cylindrical-module]: height")
    assert len([ax for ax in fig.axes if ax.get_visible()]) == count + 1  # the panels and the colour bar
    _inside_and_apart(fig, 110)


def _fits_of_the_run() -> dict:
    """Fits and in-plane profiles shaped like the main job's (three incidences; biys Lambertian): values whose log
    axes carry the widest minor labels of the run ('8.8×10⁻²')."""
    from bsdfkit.fit.least_squares import bsdf_model_values

    theta_s = np.linspace(0.0, 88.0, 45)
    out = {}
    for inter, side in itertools.product(("bibs", "yiys", "biys"), ("reflection", "transmission")):
        lam = inter == "biys"
        model = "lambert" if lam else "lambert+gaussian"
        th = np.array([5.0, 45.0, 56.0])
        params = {"rho": 0.25 + 0.01 * th / 56} if lam else {"rho": 0.08 + 0 * th, "A": 0.5 + th / 20,
                                                               "sigma": 0.05 + 0 * th}
        fit = xr.Dataset({k: ("theta_i", v) for k, v in params.items()}, coords={"theta_i": th},
                         attrs={"model": model})
        records = [(t, ts, ps) for t in th for ts in theta_s for ps in (0.0, 180.0)]
        t_i, t_s, p_s = (np.array(c) for c in zip(*records))
        bsdf = np.concatenate([bsdf_model_values(model, {k: float(v[i]) for k, v in params.items()}, t,
                                                 theta_s, np.array([ps] * theta_s.size))
                               for i, t in enumerate(th) for ps in (0.0, 180.0)])
        prof = xr.Dataset({"bsdf": ("record", bsdf), "bsdf_std": ("record", 0.01 * bsdf)},
                          coords={"theta_i": ("record", t_i), "phi_i": ("record", np.full(t_i.size, 180.0)),
                                  "theta_s": ("record", t_s), "phi_s": ("record", p_s),
                                  "arc": ("record", np.full(t_i.size, "in_plane"))})
        out[(inter, side)] = (fit, prof)
    return out


def test_fits_figure_fixed_margins_keep_every_text_inside_and_apart():
    from bsdfkit.plotting.figures import bsdf_fits_figure

    fig = bsdf_fits_figure(_fits_of_the_run())
    assert len(fig.axes) == 6
    _inside_and_apart(fig, 120)


@pytest.mark.slow  # twelve panels drawn (3-4 s); its fast check: test_study_and_incidence_figures_label_every_...
def test_studies_figure_fixed_margins_keep_every_text_inside_and_apart():
    from bsdfkit.plotting.figures import trace_studies_figure

    class Device:
        LER, YBR, non_uniformity = 0.558, 8.46, 0.11

    def row(key, v, k):
        return {"values": {key: v}, "LER": 0.3 + 0.05 * k, "LER_std": 2e-4, "YBR": 6.2 + 0.4 * k, "YBR_std": 0.05,
                "non_uniformity": 0.145 - 0.007 * k}

    keys = {"reflectance": ("wall.reflectance", (0.8, 0.85, 0.9, 0.95, 0.98)),
            "height_mm": ("cavity.height_mm", (10.0, 43.0, 80.0)),
            "led_fwhm_deg": ("leds.fwhm_deg", (10.0, 30.0, 70.0, 120.0)),
            "specular_fraction": ("wall.specular_fraction", (0.0, 0.6, 1.0))}
    studies = {name: [row(key, v, k) for k, v in enumerate(values)] for name, (key, values) in keys.items()}
    fig = trace_studies_figure(Device, studies, {("reflectance", "LER"): [(0.8, 28.0), (0.98, 58.0)]})
    assert len(fig.axes) == 12
    _inside_and_apart(fig, 120)

@pytest.mark.slow
def test_report_renders_in_headless_chromium(built, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("chromium is not on PATH (Debian: apt-get install chromium): the report is not rendered")
    _, path, _ = built
    shot = tmp_path / "report.png"
    profile = tmp_path / "profile"
    profile.mkdir()
    done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                           "--no-first-run", "--disable-background-networking", "--disable-component-update",
                           "--disable-sync", f"--user-data-dir={profile}", f"--screenshot={shot}",
                           "--window-size=1200,3000", path.resolve().as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert shot.is_file(), done.stderr[-2000:]
    assert shot.stat().st_size > 20_000
    pixels = mpimg.imread(shot)
    assert pixels.shape[0] >= 2000 and pixels.shape[1] >= 1000
    colours = np.unique((pixels[..., :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 100  # text, tables and embedded figures, not one blank colour
    assert float(pixels[..., :3].std()) > 0.05


# ---- the main job's studies on the paper's values (issue #16) ---------------------------------------------------
PAPER_PANELS = {"wall.specular_fraction": (1.0, 0.6, 0.0), "cavity.height_mm": (10.0, 43.0, 80.0),
                "leds.fwhm_deg": (30.0, 70.0, 120.0)}
STUDY_OF = {"wall.specular_fraction": "specular_fraction", "cavity.height_mm": "height_mm",
            "leds.fwhm_deg": "led_fwhm_deg"}


def _full_run(folder):
    """A run folder with the three map studies of the paper (one file per study) and a failed YBR-height trend."""
    folder = _make_run(folder)
    (folder / "trace_specular_fraction.nc").unlink()
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    device_ler = summary["trace"]["device"]["LER"]
    studies = {}
    for dim, values in PAPER_PANELS.items():
        rows = []
        maps = []
        for k, value in enumerate(values):
            e = _map(1.0 + 0.05 * k, tilt=0.1 * k)
            maps.append(e)
            is_device = (dim, value) in (("cavity.height_mm", 43.0), ("leds.fwhm_deg", 120.0))
            rows.append({"values": {dim: value}, "LER": device_ler if is_device else 0.5 + 0.01 * k,
                         "LER_std": 4e-4, "YBR": 8.8 - 0.2 * k if dim == "cavity.height_mm" else 8.0, "YBR_std": 0.05,
                         "non_uniformity": non_uniformity(e), "ledger_error": 1e-14, "clamped_share": 0.0,
                         "plate_incidence": {"measured": 0.7, "extrapolated": 0.3,
                                             "mean_blue_incidence_deg": 43.0 - 2 * k},
                         "same_trace_as_device": is_device})
        studies[STUDY_OF[dim]] = rows
        ds = xr.Dataset({"irradiance": ((dim, "y_mm", "x_mm"), np.stack(maps), {"units": "W/mm^2"})},
                        coords=_coords() | {dim: (dim, list(values))})
        ds.attrs.update(emitted_W=1.0)
        netcdf.save(ds, folder / f"trace_{STUDY_OF[dim]}.nc")
    from bsdfkit.pipeline.recipe import _trends

    class Device:
        LER = device_ler

    trends = _trends(Device, studies)
    plate = {"measured_incidences_deg": [5.0, 45.0, 56.0], "extrapolated_incidences_deg": [0.0, 60.0, 90.0],
             "grid_deg": [0.0, 5.0, 45.0, 56.0, 60.0, 90.0], "clamped_share_max": 0.0,
             "device_extrapolated_power_share": 0.256, "extrapolated_power_share_max": 0.43,
             "tis": {"bibs_transmission": [0.064, 0.064, 0.054, 0.047, 0.046, 0.045]}}
    trace = {"device": {"LER": device_ler, "plate_incidence": {"measured": 0.74, "extrapolated": 0.26,
                                                                "mean_blue_incidence_deg": 39.0}},
             "studies": studies, "trends": trends, "plate": plate}
    (folder / "trace.json").write_text(json.dumps(trace), encoding="utf-8")
    summary["trace"]["trends"] = trends
    summary["trace"]["plate"] = {k: plate[k] for k in ("measured_incidences_deg", "extrapolated_incidences_deg",
                                                       "clamped_share_max", "device_extrapolated_power_share",
                                                       "extrapolated_power_share_max")}
    (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
    return folder, trends


# The tests of the full run are in the slow lane (its report draws the three map grids of the paper's figures: 9 s);
# the fast lane writes and reads the report of the small run (`built`) and checks the criteria, trends and grid
# check without it (test_readings_of_the_papers_words_are_stated_numbers, test_trends_follow_the_papers_direction,
# test_maps_table_says_whether_halving_the_cells_moves_the_value_by_less_than_its_sigma).
@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """The run folder of ``_full_run`` with its report written (``write_report``), and the report's comparisons
    (``_Report.build``): ``(folder, trends, html, (report, its built text))``. The tests only read them."""
    folder, trends = _full_run(tmp_path_factory.mktemp("full") / "run")
    html = write_report(folder).read_text(encoding="utf-8")
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    rep = report_module._Report(folder, summary, paper_values())
    return folder, trends, html, (rep, rep.build())


@pytest.mark.slow
def test_report_sets_every_map_panel_of_figs_10_12_14_beside_the_papers_non_uniformity(full_run):
    _, _, text, _ = full_run
    maps = text[text.index('<section id="maps">'):text.index('<section id="spectrum">')]
    assert re.search(r"Maps of the paper not in this run: none\.", maps)
    # one grid of three maps per paper figure, plus the lone device map
    for fig_no in ("Fig. 10", "Fig. 12", "Fig. 14"):
        assert f'alt="{fig_no} maps"' in maps
    for label, paper in (("specular reflector", "56"), ("perfect diffuser", "36"), ("h = 10 mm", "91"),
                         ("h = 43 mm", "36"), ("FWHM 30°", "76"), ("FWHM 120° (Lambertian)", "36")):
        row = re.search(rf"<td class=\"l\">{re.escape(label)}</td><td class=\"\">yes</td><td class=\"\">"
                        rf"([\d.]+) ± [\d.]+</td><td class=\"\">[\d.]+ \(Δ [^<]*converged\)</td>"
                        rf"<td class=\"\">{paper}</td>", maps)
        assert row is not None, label
    for label in ("diffuse-to-specular 40 %", "h = 80 mm", "FWHM 70°"):
        assert re.search(rf"{re.escape(label)}</td><td class=\"\">yes</td><td class=\"\">[\d.]+ ± [\d.]+</td>"
                         r"<td class=\"\">[\d.]+ \(Δ [^<]*\)</td><td class=\"\">—</td>", maps), label
    # this run's value in the table is the map's own (E_max − E_min)/(E_max + E_min)
    nu = 100 * map_non_uniformity(xr.DataArray(_map(1.05, tilt=0.1), dims=("y_mm", "x_mm"), coords=_coords()))
    # the 40 % diffuse panel (k = 1), with the same map on half the cells per side beside it
    assert re.search(rf"<td class=\"\">{nu:.1f} ± [\d.]+</td><td class=\"\">[\d.]+ \(Δ [^<]*\)</td>"
                     r"<td class=\"\">—</td>", maps)


@pytest.mark.slow
def test_a_trend_the_run_does_not_reproduce_is_said_and_explained(full_run):
    _, trends, text, _ = full_run
    name = "YBR slightly lower for short cavities (Fig. 11)"
    assert trends[name]["holds"] is False and "Fig. 11" in name
    assert "lower for small heights" in trends[name]["paper"]
    opening = text[:text.index('<section id="measurement">')]
    assert f"trend of [Cylindrical-module] not reproduced: {name}" in opening
    plate = text[text.index('<section id="plate">'):text.index('<section id="maps">')]
    assert "This run <b>disagrees</b> with the paper here" in plate
    assert "43.0° at 10 mm" in plate and "41.0° at 43 mm" in plate  # the mean blue incidences that explain it
    assert "0.0 %" in plate and "25.6 %" in plate and "model-extrapolated" in plate


def test_trends_follow_the_papers_direction():
    from bsdfkit.pipeline.recipe import _trends

    def rows(key, values, **series):
        return [{"values": {key: v}, **{q: s[k] for q, s in series.items()},
                 "plate_incidence": {"mean_blue_incidence_deg": 40.0}} for k, v in enumerate(values)]

    class Device:
        LER = 0.56

    # the paper's sizes: Fig. 8 30 pp and 3; 63 % at 10 mm vs 53 % at 43 mm; 91 vs 36 %; 'slightly' (YBR within
    # 3.3 %); 'negligible' (LER span below 1 pp); 76 vs 36 %
    studies = {"reflectance": rows("wall.reflectance", [0.8, 0.98], LER=[0.28, 0.58], YBR=[6.0, 9.0],
                                   non_uniformity=[0.2, 0.16]),
               "height_mm": rows("cavity.height_mm", [10.0, 43.0, 80.0], LER=[0.63, 0.53, 0.50],
                                 YBR=[8.3, 8.4, 8.5], non_uniformity=[0.91, 0.36, 0.3]),
               "led_fwhm_deg": rows("leds.fwhm_deg", [30.0, 120.0], LER=[0.565, 0.56], YBR=[7.6, 8.4],
                                    non_uniformity=[0.76, 0.36])}
    t = _trends(Device, studies)
    assert all(x["holds"] for x in t.values()), {k: v for k, v in t.items() if not v["holds"]}
    # the right direction with the wrong size does not hold: LER moved by 3.1 pp by the FWHM is not negligible,
    # a 24.5 pp reflectance effect is not the paper's 30 pp, a YBR 20 % lower is not 'slightly' lower
    studies["led_fwhm_deg"] = rows("leds.fwhm_deg", [30.0, 120.0], LER=[0.589, 0.558], YBR=[7.6, 8.4],
                                   non_uniformity=[0.76, 0.36])
    studies["reflectance"] = rows("wall.reflectance", [0.8, 0.98], LER=[0.300, 0.545], YBR=[6.0, 9.0],
                                  non_uniformity=[0.2, 0.16])
    studies["height_mm"] = rows("cavity.height_mm", [10.0, 43.0, 80.0], LER=[0.63, 0.53, 0.50],
                                YBR=[6.7, 8.4, 8.5], non_uniformity=[0.91, 0.36, 0.3])
    t = _trends(Device, studies)
    for name in ("LER barely moves with LED FWHM (Fig. 13)", "LER rises with wall reflectance (Fig. 8)",
                 "YBR slightly lower for short cavities (Fig. 11)"):
        assert t[name]["direction"] and not t[name]["holds"], name
    assert t["LER barely moves with LED FWHM (Fig. 13)"]["magnitude"]["run"] == pytest.approx(3.1, abs=1e-9)
    studies["height_mm"] = rows("cavity.height_mm", [10.0, 43.0, 80.0], LER=[0.52, 0.56, 0.59],
                                YBR=[8.8, 8.4, 8.3], non_uniformity=[0.3, 0.36, 0.9])
    t = _trends(Device, studies)
    assert not t["LER falls with cavity height (Fig. 11)"]["holds"]
    assert not t["YBR slightly lower for short cavities (Fig. 11)"]["holds"]
    assert not t["non-uniformity larger for short cavities (Fig. 12)"]["holds"]


def test_plate_incidence_shares_from_the_histogram():
    from bsdfkit.pipeline.recipe import incidence_shares

    class Result:
        incidence_histogram = np.vstack([np.ones(90), 3 * np.ones(90)])  # 1° bins, blue and yellow

    shares = incidence_shares(Result, (5.0, 56.0))
    # bin centres 5.5 … 55.5 lie in [5, 56]: 51 of 90 bins
    assert shares["measured"] == pytest.approx(51 / 90, rel=1e-12)
    assert shares["measured"] + shares["extrapolated"] == pytest.approx(1.0, rel=1e-12)
    assert shares["mean_blue_incidence_deg"] == pytest.approx(45.0, rel=1e-12)


def _axes_read_like_engineering_figures(fig) -> None:
    for ax in fig.axes:
        if not ax.get_visible() or ax.get_label() == "<colorbar>":
            continue
        assert re.search(r"\(.+\)", ax.get_xlabel()), ax.get_xlabel()
        assert re.search(r"\(.+\)", ax.get_ylabel()), ax.get_ylabel()
        assert ax.get_legend() is not None and ax.get_legend().get_texts(), ax.get_title()


def test_study_and_incidence_figures_label_every_axis_with_units_and_name_data_and_model():
    from bsdfkit.plotting.figures import plate_incidence_figure, trace_studies_figure

    class Device:
        LER, YBR, non_uniformity = 0.56, 8.5, 0.16

    def row(key, v, k):
        return {"values": {key: v}, "LER": 0.5 + 0.01 * k, "LER_std": 2e-4, "YBR": 8 + 0.1 * k, "YBR_std": 0.05,
                "non_uniformity": 0.2 - 0.01 * k}

    studies = {"reflectance": [row("wall.reflectance", v, k) for k, v in enumerate((0.8, 0.9, 0.98))],
               "height_mm": [row("cavity.height_mm", v, k) for k, v in enumerate((10.0, 43.0, 80.0))]}
    fig = trace_studies_figure(Device, studies, {("reflectance", "LER"): [(0.8, 28.0), (0.98, 58.0)]})
    assert len(fig.axes) == 6
    _axes_read_like_engineering_figures(fig)
    # LER and YBR carry error bars (± 1σ), one quantity per axis: each row's label names one quantity
    ler_ax = fig.axes[0]
    assert ler_ax.containers and "LER" in ler_ax.get_ylabel() and "YBR" not in ler_ax.get_ylabel()
    assert "[Cylindrical-module]" in [t.get_text() for t in ler_ax.get_legend().get_texts()]
    grid = [0.0, 5.0, 45.0, 56.0, 90.0]
    tis = {k: [0.1, 0.1, 0.11, 0.12, 0.09] for k in ("bibs_transmission", "bibs_reflection", "biys_transmission",
                                                      "biys_reflection")}
    fig = plate_incidence_figure({"h = 10 mm": np.ones(90)}, (5.0, 56.0), grid, tis,
                                 {"bibs_transmission": ([5.0, 45.0, 56.0], [0.1, 0.11, 0.12], [0.01] * 3)})
    _axes_read_like_engineering_figures(fig)
    labels = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert any("measured ± 1σ" in x for x in labels) and "plate, model-extrapolated" in labels


# ---- issue #27: every comparison states its criterion, and the verdicts follow it ----------------------------
@pytest.mark.slow
def test_every_verdict_follows_its_stated_criterion_and_every_difference_is_listed(full_run):
    """Rule: a value agrees iff |run − paper| ≤ sqrt(half_unit² + (kσ)²); a trend holds iff its direction is the
    paper's and its size agrees by the same rule; every other comparison is in the disagreement list, and no
    verdict in the HTML says 'agrees' or 'holds' where the numbers exceed the criterion."""
    _, _, _, (rep, text) = full_run
    comps = rep.v.comparisons
    kinds = {c["kind"] for c in comps}
    assert kinds == {"value", "trend"} and len(comps) > 30
    opening = html_unescape(text[:text.index('<section id="measurement">')])
    for c in comps:
        if c["criterion"] is not None:
            within = abs(c["run"] - c["paper"]) <= c["criterion"]
            expected = within and c.get("direction", True)
            assert c["agrees"] == expected, c
            assert c["criterion"] > 0
        else:  # a trend the paper gives no size for: its direction decides
            assert c["kind"] == "trend" and c["agrees"] == c["direction"], c
        if not c["agrees"]:
            assert any(c["what"] in d for d in rep.v.disagreements), c["what"]
            assert html_escape(c["what"]) in text
    assert len(rep.v.disagreements) == sum(not c["agrees"] for c in comps)
    assert "device LER vs §4 of [Cylindrical-module]" in opening
    # the HTML: one 'agrees'/'holds' mark per agreeing comparison (the spectral section's own mark aside), and each
    # 'agrees' states |Δ| ≤ criterion with numbers that satisfy it
    marks = re.findall(r'<span class="agree">(agrees|holds)</span>', text)
    assert len(marks) == sum(c["agrees"] for c in comps)
    for diff, crit in re.findall(r'<span class="agree">agrees</span> \(\|Δ\| ([\d.]+) ≤ ([\d.]+)', text):
        assert float(diff) <= float(crit)


@pytest.mark.slow
def test_table3_losses_are_the_papers_100_minus_extracted(full_run):
    folder, _, _, (rep, _) = full_run
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    power = summary["module_budget"]["power"]
    last = power["iterations"][-1]
    losses = [c for c in rep.v.comparisons if c["what"].startswith("Table 3 losses")]
    assert len(losses) == 1 and losses[0]["run"] == pytest.approx(100.0 - last["total"], abs=1e-12)
    assert losses[0]["run"] != pytest.approx(last["losses"], abs=1e-3)  # the run's own line keeps in-flight power


def test_readings_of_the_papers_words_are_stated_numbers():
    from bsdfkit.pipeline.report import K_SIGMA, READINGS, agreement_criterion, magnitude_verdict

    assert READINGS["negligible_pp"] < READINGS["slightly_pp"] == 63 - 61  # §6: 63 % 'slightly surpasses' 61 %
    assert agreement_criterion(0.5, 0.1) == pytest.approx(math.hypot(0.5, K_SIGMA * 0.1), rel=1e-15)
    assert agreement_criterion(0.5, None) == 0.5
    # the LED-FWHM study of the main job moves LER by 3.1 pp: not negligible
    m = magnitude_verdict(3.1, 0.03, 0.0, READINGS["negligible_pp"], "negligible", "pp")
    assert not m["agrees"] and m["criterion"] == pytest.approx(math.hypot(1.0, 0.06), rel=1e-12)
    assert magnitude_verdict(0.9, 0.03, 0.0, READINGS["negligible_pp"], "negligible", "pp")["agrees"]


def test_maps_table_says_whether_halving_the_cells_moves_the_value_by_less_than_its_sigma():
    from bsdfkit.pipeline.report import _grid_check

    # the main job's device: 16.4 % on 32 cells (σ 1.2 pp), 12.3 % on 16: not converged
    assert _grid_check(0.164, 0.123, 0.012) == "12.3 (Δ +4.1 > σ 1.2: not converged)"
    assert _grid_check(0.464, 0.460, 0.008).endswith("< σ 0.8: converged)")
    assert _grid_check(0.164, 0.123, None) == "12.3 (Δ +4.1)"
