"""The run report: one self-contained ``report.html`` a lab can hand over (issue #16).

:func:`write_report` turns a finished run folder (``bsdfkit run RECIPE -o OUT/``: ``summary.json``, the PNG
figures, ``trace.json``, ``trace_*.nc``) into ``OUT/report.html``: one file, every figure embedded as a base64
PNG data URI, inline CSS, no script and no reference to anything outside the file. It opens with what was
measured and what was found, lists where the run disagrees with the papers, then gives one section per stage
with this run's figure and numbers beside the published numbers of [Power-budget] and [Cylindrical-module]
(``paper_values.json``, shipped with the package). Each section is one ``_Report.sec_*`` method; ``build()``
numbers them in order, so a new stage adds a method and one entry there.

Agreement rule (stated in the report): a run value agrees with a printed paper value when
|run − paper| ≤ sqrt(h² + (k σ)²), h = half a unit of the paper's last printed digit (:func:`_printed_half_unit`),
σ = the run's standard uncertainty (0 when the run gives none), k = :data:`K_SIGMA` = 2; otherwise the verdict is
"differs by Δ (Δ/σ σ; criterion c)" and the comparison is in the disagreement list. A §5 trend "holds" only when
its direction is the paper's and its size agrees by the same rule with the paper's printed difference, or with
the stated numeric reading of the paper's words (:data:`READINGS`: "negligible", "slightly"). The papers give no
uncertainty for their printed values, so this rule tells whether the run reproduces the printed number.
"""
from __future__ import annotations

import base64
import html
import json
import math
import re
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from bsdfkit.core.conventions import COLORIMETRY_BLUE_BAND_NM, COLORIMETRY_YELLOW_BAND_NM, band_label
from bsdfkit.core.errors import InputError
from bsdfkit.core.version import __version__
from bsdfkit.io import netcdf
from bsdfkit.io.atomic import check_writable, write_text
from bsdfkit.plotting.maps import (
    MAP_DIMS,
    find_map_variable,
    irradiance_map_figure,
    irradiance_maps_figure,
    map_non_uniformity,
)
from bsdfkit.plotting.render import PendingPng, PngRenderer, png_results
from bsdfkit.raytrace.tallies import non_uniformity_std, rebin_map

__all__ = ["REPORT_NAME", "paper_values", "write_report"]

REPORT_NAME = "report.html"

#: Table 2 keys in the paper's order, with readable names.
TABLE2_KEYS = {
    "B_bibs": "backward blue→blue (B bibs)", "F_bibs": "forward blue→blue (F bibs)",
    "B_biys": "backward blue→yellow (B biys)", "F_biys": "forward blue→yellow (F biys)",
    "blue_losses": "blue losses", "B_yiys": "backward yellow→yellow (B yiys)",
    "F_yiys": "forward yellow→yellow (F yiys)", "yellow_losses": "yellow losses",
}

#: Where each run figure goes and what it is (other PNGs land in "Other figures").
FIGURE_CAPTIONS = {
    "inplane_bsdf.png": "In-plane BSDF at the recipe's wavelength, reflection and transmission, per incidence, with "
                        "standard uncertainties (cf. Fig. 6 of [Power-budget]).",
    "module_budget.png": "Cumulative extracted power and losses per plate interaction (cf. Fig. 10 of "
                         "[Power-budget]).",
    "bsdf_fits.png": "Aperture-averaged BSDF fits per interaction and side: measured points (± 1σ) and fitted "
                     "model curves (cf. Figs. 6-8 of [Power-budget], Fig. 4 of [Cylindrical-module]).",
    "trace_studies.png": "LER, YBR (± 1σ) and irradiance non-uniformity of the module studies, one quantity per "
                         "row, with the values [Cylindrical-module] prints (open squares; Figs. 8-14 and their "
                         "text); the dotted line is the traced device.",
    "trace_incidence.png": "Left: where the blue light meets the plate, per degree of incidence, for the three "
                           "cavity heights (all passes, power-weighted; grey: the measured incidences). Right: the "
                           "plate's blue-light TIS vs incidence, measured (± 1σ) and as traced (dashed where "
                           "model-extrapolated).",
    "module_spectrum.png": "Left: pump-LED and converted-light spectra (normalised). Right: the module spectrum "
                           "rebuilt from the two-wavelength trace (cf. Fig. 7 of [Cylindrical-module]).",
}

#: The irradiance-map figures of [Cylindrical-module]: the study dimension and the three panels' values.
PAPER_MAP_FIGURES = (
    ("Fig. 10", "wall finish", ("wall.specular_fraction", "specular_fraction"),
     ((1.0, "specular reflector"), (0.6, "diffuse-to-specular 40 %"), (0.0, "perfect diffuser"))),
    ("Fig. 12", "cavity height", ("cavity.height_mm", "height_mm"),
     ((10.0, "h = 10 mm"), (43.0, "h = 43 mm"), (80.0, "h = 80 mm"))),
    ("Fig. 14", "LED FWHM", ("leds.fwhm_deg", "led_fwhm_deg"),
     ((30.0, "FWHM 30°"), (70.0, "FWHM 70°"), (120.0, "FWHM 120° (Lambertian)"))),
)

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;margin:0;color:#1d232a;
background:#f4f5f7;line-height:1.45}
main{max-width:1180px;margin:0 auto;padding:24px 28px 48px;background:#fff}
h1{font-size:1.7em;margin:0 0 4px}h2{font-size:1.3em;border-bottom:2px solid #2b5d8a;padding-bottom:3px;
margin-top:38px}h3{font-size:1.05em;margin:20px 0 6px}
.sub{color:#55606b;margin:0 0 14px}
.banner{background:#fff4d6;border:1px solid #e0b443;border-left:6px solid #e0b443;padding:10px 14px;margin:12px 0}
.disagree{background:#fdecea;border:1px solid #e3a19a;border-left:6px solid #c0392b;padding:8px 14px;margin:12px 0}
.agree{color:#1e7b34}.differs{color:#b02a1a;font-weight:600}
.cards{display:grid;grid-template-columns:repeat(auto-fit,minmax(210px,1fr));gap:10px;margin:10px 0}
.card{border:1px solid #d5dbe1;border-radius:6px;padding:8px 12px;background:#f9fbfc}
.card .v{font-size:1.35em;font-weight:600}.card .k{color:#55606b;font-size:.86em}
.pair{display:grid;grid-template-columns:minmax(0,1.25fr) minmax(0,1fr);gap:22px;align-items:start}
.pair>div,.wide{min-width:0;overflow-x:auto}.absent{color:#6b7580;font-style:italic}
@media (max-width:900px){.pair{grid-template-columns:1fr}}
figure{margin:8px 0 14px}figure img{display:block;box-sizing:border-box;max-width:100%;height:auto;
border:1px solid #e3e6ea}
figcaption{font-size:.86em;color:#414b55;margin-top:3px}
table{border-collapse:collapse;font-size:.88em;margin:6px 0 12px}
th,td{border:1px solid #d5dbe1;padding:3px 7px;text-align:right;vertical-align:top}
th{background:#eef2f6}td.l,th.l{text-align:left}
caption{caption-side:top;text-align:left;font-weight:600;padding-bottom:4px}
nav ol{columns:2;font-size:.95em}code{font-size:.92em;background:#f1f3f5;padding:0 3px}
pre{font-size:.8em;background:#f6f8fa;border:1px solid #e3e6ea;padding:8px;overflow-x:auto}
.note{font-size:.88em;color:#414b55}
@media print{body{background:#fff}main{padding:0}h2{break-before:auto}figure,table{break-inside:avoid}}
"""


# --------------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------------
def paper_values() -> dict:
    """The papers' published numbers bsdfkit compares against (``bsdfkit/pipeline/paper_values.json``)."""
    text = resources.files("bsdfkit.pipeline").joinpath("paper_values.json").read_text(encoding="utf-8")
    return json.loads(text)


def _esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _num(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _f(value: Any, digits: int = 2, scale: float = 1.0) -> str:
    x = _num(value)
    return "—" if x is None else f"{x * scale:.{digits}f}"


def _pm(value: Any, std: Any, digits: int = 2, scale: float = 1.0) -> str:
    s = _num(std)
    return _f(value, digits, scale) + ("" if s is None or _num(value) is None else f" ± {s * scale:.{digits}f}")


def _pm_sig(value: Any, std: Any, max_decimals: int = 8) -> str:
    """Value ± standard error with the error to two significant figures and the value to the same decimals."""
    x, s = _num(value), _num(std)
    if x is None:
        return "—"
    if s is None or s <= 0:
        return f"{x:.4g}"
    decimals = min(max(0, 1 - math.floor(math.log10(s))), max_decimals)
    return f"{x:.{decimals}f} ± {s:.{decimals}f}"


def _printed_half_unit(value: float) -> float:
    """Half a unit of the last printed digit of a paper value (0.1 → 0.05, 58 → 0.5, 0.80 → 0.005)."""
    text = repr(float(value)).rstrip("0").rstrip(".") if "e" not in repr(float(value)) else repr(float(value))
    decimals = len(text.split(".")[1]) if "." in text else 0
    return 0.5 * 10.0 ** (-decimals)


#: Coverage factor k of the agreement criterion sqrt(half_unit² + (k σ)²) (σ: the run's standard uncertainty).
K_SIGMA = 2.0

#: Numeric readings of the cylindrical-module paper's words, from its own text. §6: 63 % "slightly surpasses"
#: 61 %, so "slightly" is a change of at most 2 pp of LER (``slightly_pp``), or 2/61 = 3.3 % of a value
#: (``slightly_relative``, for YBR); "negligible" (§5.4) is below "slightly" and below the paper's own LER
#: resolution (whole percent): a change of less than 1 pp (``negligible_pp``).
READINGS = {"slightly_pp": 2.0, "slightly_relative": 2.0 / 61.0, "negligible_pp": 1.0}


def agreement_criterion(half_unit: float, std: Any = None) -> float:
    """Largest |run − paper| that agrees: sqrt(half_unit² + (K_SIGMA σ)²), σ = 0 when the run gives none [unit of
    the value].

    Parameters
    ----------
    half_unit : float
        Half the last printed digit of the paper's value, or the half-width of a reading of its words [unit of the
        value].
    std : float, optional
        The run's standard uncertainty [unit of the value]; None or NaN counts as 0.

    Returns
    -------
    float
        The criterion [unit of the value].
    """
    s = _num(std)
    return math.hypot(half_unit, K_SIGMA * (s or 0.0))


def magnitude_verdict(diff: float, std: Any, paper: float, half_unit: float, reading: str, unit: str) -> dict:
    """A trend's size against the paper's: this run's difference ``diff`` (σ ``std``, NaN or None when the run
    gives none) vs ``paper`` (a printed difference, or the centre of a reading of the paper's words, of half-width
    ``half_unit``), with :func:`agreement_criterion`. Units as given [pp or 1].

    Parameters
    ----------
    diff : float
        This run's difference [pp or 1].
    std : float or None
        Its standard uncertainty [pp or 1]; NaN or None when the run gives none.
    paper : float
        The paper's difference, or the centre of the reading [pp or 1].
    half_unit : float
        Half-width of the paper's value [pp or 1].
    reading : str
        How the paper's value was read from it (shown in the report).
    unit : str
        Unit label of the values (``"pp"`` or ``""``).

    Returns
    -------
    dict
        The run's value and σ, the paper's, the reading, the unit, the criterion and ``agrees``.
    """
    crit = agreement_criterion(half_unit, std)
    d = _num(diff)
    return {"run": d, "run_std": _num(std), "paper": float(paper), "half_unit": float(half_unit), "criterion": crit,
            "agrees": d is not None and abs(d - paper) <= crit, "reading": reading, "unit": unit}


def _sigma_text(diff: float, std: float | None) -> str:
    return f"{diff / std:+.1f} σ" if std else "no run σ"


class Verdicts:
    """Comparisons of run values with paper values; collects the disagreements for the report's opening.

    Every comparison is kept in :attr:`comparisons` (``what``, ``run``, ``paper``, ``std``, ``criterion``,
    ``agrees``, ``kind``): a value agrees when |run − paper| ≤ :func:`agreement_criterion`, a trend holds when its
    direction is the paper's and its size agrees; every other comparison is in :attr:`disagreements`.
    """

    def __init__(self) -> None:
        self.disagreements: list[str] = []
        self.comparisons: list[dict] = []

    def check(self, what: str, run: Any, paper: Any, std: Any = None, unit: str = "", digits: int = 2,
              half_unit: float | None = None, note: str = "") -> str:
        """HTML verdict: 'agrees (|Δ| ≤ criterion)' or 'differs by Δ (z σ; criterion c)' (remembered).

        Parameters
        ----------
        what : str
            What is compared (the label in the list of disagreements).
        run, paper : float or None
            This run's value and the paper's [``unit``]; "—" when either is missing.
        std : float, optional
            The run's standard uncertainty [``unit``].
        unit : str
            Unit label of the values.
        digits : int
            Decimals shown.
        half_unit : float, optional
            Half-width of the paper's value [``unit``]; None takes half the last printed digit of ``paper``.
        note : str
            Added to the disagreement's line.

        Returns
        -------
        str
            HTML of the verdict.
        """
        r, p = _num(run), _num(paper)
        if r is None or p is None:
            return "—"
        s = _num(std)
        crit = agreement_criterion(half_unit if half_unit is not None else _printed_half_unit(p), s)
        diff = r - p
        u = f" {unit}" if unit else ""
        agrees = abs(diff) <= crit
        self.comparisons.append({"what": what, "run": r, "paper": p, "std": s, "criterion": crit, "agrees": agrees,
                                 "kind": "value"})
        if agrees:
            return f'<span class="agree">agrees</span> (|Δ| {abs(diff):.{digits}f} ≤ {crit:.{digits}f}{u})'
        text = f"differs by {diff:+.{digits}f}{u} ({_sigma_text(diff, s)}; criterion {crit:.{digits}f}{u})"
        printed = f"{p:g}" if abs(p - round(p, digits)) < 1e-12 else f"{p:.{digits}f}"
        self.disagreements.append(f"{what}: this run {r:.{digits}f}{u}, paper {printed}{u} ({text})"
                                  f"{'; ' + note if note else ''}")
        return f'<span class="differs">{_esc(text)}</span>'

    def trend(self, name: str, t: dict) -> str:
        """HTML verdict of a trend (:func:`bsdfkit.pipeline.recipe._trends`): 'holds' only with the paper's
        direction and, where the paper gives one, its size within the criterion (remembered).

        Parameters
        ----------
        name : str
            The trend's name (the label in the list of disagreements).
        t : dict
            The trend's entry in trace.json (``direction``, ``magnitude``, ...).

        Returns
        -------
        str
            HTML of the verdict.
        """
        m = t.get("magnitude")
        direction = t.get("direction", t.get("holds"))
        size_ok = m is None or bool(m.get("agrees"))
        holds = bool(direction) and size_ok
        self.comparisons.append({"what": name, "run": None if m is None else m.get("run"),
                                 "paper": None if m is None else m.get("paper"),
                                 "std": None if m is None else m.get("run_std"),
                                 "criterion": None if m is None else m.get("criterion"), "agrees": holds,
                                 "direction": bool(direction), "kind": "trend"})
        parts = [] if direction else ["the direction is not the paper's"]
        if m is not None and not size_ok and _num(m.get("run")) is not None:
            diff = m["run"] - m["paper"]
            unit = f" {m['unit']}" if m.get("unit") else ""
            parts.append(f"its size differs by {diff:+.2f}{unit} ({_sigma_text(diff, _num(m.get('run_std')))}; "
                         f"criterion {m['criterion']:.2f}{unit})")
        if holds:
            return '<span class="agree">holds</span>' + ("" if m is not None else
                                                         " (direction; the paper gives no size)")
        text = "does not hold: " + "; ".join(parts)
        self.disagreements.append(f"trend of [Cylindrical-module] not reproduced: {name} ({'; '.join(parts)}; "
                                  f"{t.get('detail')})")
        return f'<span class="differs">{_esc(text)}</span>'


def _gate_cell(fit: dict) -> str:
    """The plausibility-gate cell of a BSDF fit row: 'passes', the reasons it fails, or '—' (older summaries)."""
    if "plausible" not in fit:
        return "—"
    if fit.get("plausible"):
        return "passes"
    reasons = "; ".join(fit.get("gate_reasons") or ["see summary.json"])
    return f'<span class="differs">fails: {_esc(reasons)}</span>'


def _table(headers: Sequence[str], rows: Iterable[Sequence[Any]], caption: str = "", left: int = 1,
           text_cols: Iterable[int] = ()) -> str:
    """An HTML table; cells are HTML already (escape text before).

    The first ``left`` columns and the columns ``text_cols`` align left, the others (numbers) right.
    """
    lefts = set(range(left)) | set(text_cols)
    out = ["<table>"]
    if caption:
        out.append(f"<caption>{caption}</caption>")
    out.append("<tr>" + "".join(f'<th class="{"l" if i in lefts else ""}">{h}</th>' for i, h in enumerate(headers))
               + "</tr>")
    for row in rows:
        out.append("<tr>" + "".join(f'<td class="{"l" if i in lefts else ""}">{c}</td>' for i, c in enumerate(row))
                   + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _png_uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


#: resolution of the report's own figures [dots per inch]
REPORT_DPI = 110


def _figure(png: bytes, caption: str, alt: str) -> str:
    return (f'<figure><img src="{_png_uri(png)}" alt="{_esc(alt)}">'
            f"<figcaption>{caption}</figcaption></figure>")


def _pair(left: str, right: str) -> str:
    return f'<div class="pair"><div>{left}</div><div>{right}</div></div>'


def _section(anchor: str, title: str, body: str) -> str:
    return f'<section id="{anchor}"><h2>{_esc(title)}</h2>\n{body}\n</section>'


def _missing(what: str) -> str:
    return f'<p class="note">{_esc(what)}</p>'


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


# --------------------------------------------------------------------------------------------------
# figures drawn for the report (run beside paper)
# --------------------------------------------------------------------------------------------------
def _table2_figure(row: dict, paper: dict, theta: float) -> Figure:
    """Table 2 at one incidence: this run's power TIS with error bars beside the paper's printed values."""
    keys = [k for k in TABLE2_KEYS if _num(row.get("power", {}).get(k)) is not None]
    x = np.arange(len(keys))
    run = [row["power"][k] for k in keys]
    err = [_num(row.get("power_std", {}).get(k)) or 0.0 for k in keys]
    pap = [_num(paper.get(k)) for k in keys]
    fig = Figure(figsize=(7.2, 3.8))
    ax = fig.subplots()
    ax.bar(x - 0.2, run, 0.4, yerr=err, capsize=3, color="#2b5d8a", label=f"this run, θi = {theta:g}° (± 1σ)")
    ax.bar(x + 0.2, [np.nan if p is None else p for p in pap], 0.4, color="#e0a040",
           label="[Power-budget] Table 2 (45°)")
    ax.set_xticks(x, [k.replace("_", " ") for k in keys], rotation=30, ha="right")
    ax.set_ylabel("TIS (% of incident power)")
    ax.set_title("interaction table: this run vs the paper", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _budget_figure(power: dict, paper: dict) -> Figure:
    """Cumulative extracted total per plate interaction with the paper's Table 3 values at the last iteration."""
    its = power.get("iterations", [])
    k = np.arange(1, len(its) + 1)
    fig = Figure(figsize=(8.4, 3.8))
    ax = fig.subplots()
    for key, style in (("total", "-o"), ("yellow", "-s"), ("blue", "-^")):
        ax.plot(k, [r.get(key, np.nan) for r in its], style, ms=4, label=f"this run: extracted {key}")
    last = len(its) if its else 7
    for src, marker, name in (("iteration_model_45deg", "D", "Table 3 model (45°)"),
                              ("experiments", "*", "Table 3 experiment")):
        vals = paper.get(src, {})
        ax.plot([last] * 3, [vals.get("total"), vals.get("yellow"), vals.get("blue")], marker, ls="none", ms=9,
                mfc="none", mew=1.5, label=f"[Power-budget] {name}")
    ax.set_xlabel("plate interaction k (1 = direct pass from the LEDs)")
    ax.set_ylabel("cumulative extracted power (% of LED output)")
    ax.set_title(f"module budget, η_MC = {power.get('eta_mc', float('nan')):g}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside: no curve hidden
    fig.tight_layout()
    return fig


def _study_rows(studies: dict, name: str, key: str) -> list[dict]:
    rows = [r for r in studies.get(name, []) if _num(r.get("values", {}).get(key)) is not None]
    return sorted(rows, key=lambda r: r["values"][key])


# --------------------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------------------
def _rebinned(da: xr.DataArray, bins: int) -> xr.DataArray | None:
    """A square map summed on ``bins`` cells per side (None for a map that is not square or not divisible)."""
    values = np.asarray(da.transpose(*MAP_DIMS).values, dtype=float)
    n = values.shape[-1]
    if values.ndim != 2 or values.shape[0] != n or n % bins or bins < 2:
        return None
    coords = {d: np.asarray(da[d].values, dtype=float).reshape(bins, n // bins).mean(axis=1) for d in MAP_DIMS}
    return xr.DataArray(rebin_map(values, bins), dims=MAP_DIMS, coords=coords, attrs=da.attrs)


def _coarser_non_uniformity(da: xr.DataArray) -> float | None:
    """Non-uniformity [1] of a square map summed on half its cells per side (None for an odd or non-square map)."""
    n = da.sizes[MAP_DIMS[-1]]
    coarse = _rebinned(da, n // 2) if n % 2 == 0 and n >= 4 else None
    return None if coarse is None else map_non_uniformity(coarse)


#: Cells per side of the maps drawn in the report (finer tallies are summed onto this grid for the figures)
DISPLAY_MAP_BINS = 32


def _display_map(da: xr.DataArray) -> xr.DataArray:
    """The map as drawn: summed onto :data:`DISPLAY_MAP_BINS` cells per side when it is finer and divisible."""
    n = da.sizes.get(MAP_DIMS[-1], 0)
    coarse = _rebinned(da, DISPLAY_MAP_BINS) if n > DISPLAY_MAP_BINS else None
    return da if coarse is None else coarse


def _grid_check(fine: float | None, coarse: float | None, std: float | None) -> str:
    """Cell of the maps table: the value on half the cells per side [%] and whether halving the cells changes the
    value by less than the fine map's σ (the convergence rule of docs/tracer.md)."""
    if fine is None or coarse is None:
        return _f(coarse, 1, 100.0)
    change = 100.0 * (fine - coarse)
    if std is None:
        return f"{100 * coarse:.1f} (Δ {change:+.1f})"
    ok = abs(change) < 100.0 * std
    return (f"{100 * coarse:.1f} (Δ {change:+.1f} {'<' if ok else '>'} σ {100 * std:.1f}: "
            f"{'converged' if ok else 'not converged'})")


def _device_grid_text(dev: dict) -> str:
    """How the device's non-uniformity was estimated (split-half on its converged grid; see the maps)."""
    if not dev.get("non_uniformity_bins"):
        return " (max − min of the map; see the maps)"
    state = "converged" if dev.get("non_uniformity_converged") else "NOT converged"
    whole = _num(dev.get("non_uniformity_map"))
    sym = ", the map averaged over the square's 8 symmetries" if dev.get("non_uniformity_symmetric") else ""
    return (f" (split-half{sym}, {dev['non_uniformity_bins']} cells per side, {state} in the grid"
            + (f"; the whole map's max − min {100 * whole:.1f} %" if whole is not None else "") + "; see the maps)")


def _conv_cell(row: dict) -> str:
    """Cell of the maps table for a tracer value: the grid it converged on, the next finer grid's value [%] and the
    change with its σ (the convergence rule of :func:`bsdfkit.raytrace.tallies.converged_non_uniformity`)."""
    bins, finer = row["non_uniformity_bins"], _num(row.get("non_uniformity_finer"))
    change, change_std = _num(row.get("non_uniformity_change")), _num(row.get("non_uniformity_change_std"))
    whole = _num(row.get("non_uniformity_map"))
    text = f"split-half on {bins} cells per side"
    if finer is not None and math.isfinite(finer) and change is not None and change_std is not None:
        text += (f"; {100 * finer:.1f} on {2 * bins} (Δ {100 * change:+.1f} "
                 f"{'<' if abs(change) < change_std else '≥'} its σ {100 * change_std:.1f})")
    text += ": converged" if row.get("non_uniformity_converged") else ": NOT converged"
    rays = _num(row.get("non_uniformity_rays"))
    text += f"; map of {rays:.3g} rays" if rays is not None else ""
    return text + (f"; whole map {100 * whole:.1f}" if whole is not None else "")


def _map_nu_std(da: xr.DataArray) -> float | None:
    """σ [1] of a square map's non-uniformity from the map itself (None for a map that is not the tracer's)."""
    values = np.asarray(da.transpose(*MAP_DIMS).values, dtype=float)
    if values.ndim != 2 or values.shape[0] != values.shape[1] or values.shape[0] < 4:
        return None
    return _num(non_uniformity_std(values))


#: What the maps section says about the non-uniformity's grid, σ and the paper's level (issue #27).
_MAPS_GRID_NOTE = (
    "<p><b>Non-uniformity, converged in the map grid.</b> The max − min of one Monte Carlo map grows with the cells' "
    "noise (finer cells, fewer rays each): the whole map's value (last part of column 5) is not a converged "
    "quantity. The tracer therefore tallies each map as 16 sub-maps of interleaved rays; where the scene has the "
    "square's symmetries (LEDs on a grid centred on the axis, isotropic surfaces) every sub-map is averaged over its 8 "
    "symmetric images first, which keeps the field and cuts the noise's variance up to 8-fold. The value compared "
    "with the paper (column 4) is the split-half estimate (extreme cells chosen on one half of the rays, read on the "
    "other), σ from the spread of the 8 pairs of sub-maps, on the coarsest grid of 8, 16, 32, 64 or 128 cells per side "
    "whose value changes by less than the change's own σ on the next finer grid (column 5; the change's σ from the "
    "pairs' own changes, the two grids sharing their rays; bsdfkit.raytrace.tallies.converged_non_uniformity). A "
    "map that has not converged gets more rays (new traces of its scene, merged into its sub-maps, up to 4 × the "
    "recipe's rays; LER and YBR stay those of the first trace), and a panel that still converges on no grid says so. "
    "The paper prints neither its grid nor its ray count; the device's grid "
    "study at 16 million rays and the level difference are in docs/tracer.md, “Non-uniformity and the map grid”, "
    "and the differences stay listed.</p>")


def _maps_note(missing: list[str]) -> str:
    """The maps section's text: the panels without a map, the grid and what the grid does to the value."""
    return ("<p>Maps of the paper not in this run: " + _esc("; ".join(missing) or "none") + ". The paper prints no "
            "non-uniformity for the 40 % diffuse, 80 mm and 70° panels; for FWHM 120° (Lambertian LEDs, the device) "
            "it is the device's 36 % of Fig. 12. The maps are tallied on a 128 × 128 grid of the plate's square and "
            f"drawn summed onto {DISPLAY_MAP_BINS} × {DISPLAY_MAP_BINS} (each panel's title: that drawn map's max − "
            "min); the non-uniformity counts bins entirely inside the plate only.</p>" + _MAPS_GRID_NOTE)


def _relative_difference(row: dict) -> str:
    r, s = _num(row.get("relative_difference")), _num(row.get("relative_difference_std"))
    if r is None:
        return "—"
    return f"{100 * r:+.2f} ± {100 * (s or 0):.2f} % (z {r / s:+.1f})" if s else f"{100 * r:+.2f} %"


class _Report:
    def __init__(self, run_dir: Path, summary: dict, pv: dict, renderer: PngRenderer | None = None) -> None:
        self.dir = run_dir
        self.renderer = renderer or PngRenderer(helper=False)
        self.pending: list[tuple[str, PendingPng, str, str]] = []  # (placeholder, png, caption, alt)
        self.s = summary
        self.pv = pv
        self.pb = pv["power_budget"]
        self.cm = pv["cylindrical_module"]
        self.v = Verdicts()
        self.used_png: set[str] = set()
        self.images = 0
        trace_json = _read_json(run_dir / "trace.json")
        self.trace_json = trace_json if isinstance(trace_json, dict) else {}

    # -- figures -------------------------------------------------------------------------------
    def run_png(self, name: str) -> str:
        path = self.dir / name
        if not path.is_file():
            return _missing(f"{name} is not in the run folder.")
        self.used_png.add(name)
        self.images += 1
        return _figure(path.read_bytes(), f"<code>{_esc(name)}</code> (this run). {FIGURE_CAPTIONS.get(name, '')}",
                       f"figure {name}")

    def drawn(self, fig: Figure | None, caption: str, alt: str) -> str:
        if fig is None:
            return ""
        self.images += 1
        # drawn while the rest of the report is built; the placeholder cannot occur in escaped HTML
        token = f"\0figure-{len(self.pending)}\0"
        self.pending.append((token, self.renderer.submit(fig, REPORT_DPI), caption, alt))
        return token

    # -- pieces ------------------------------------------------------------------------------------
    def scan(self) -> dict:
        return self.s.get("scan") or {}

    def table2_incidence(self) -> str | None:
        tables = self.s.get("interaction_tables") or {}
        if not tables:
            return None
        for want in ("45", "45.0"):
            if want in tables:
                return want
        budget_inc = _num((self.s.get("module_budget") or {}).get("incidence_deg"))
        for key, row in tables.items():
            if budget_inc is not None and _num(row.get("theta_i_deg")) == budget_inc:
                return key
        return next(iter(tables))

    def study_points(self) -> list[dict]:
        """The studies' points for which the cylindrical-module paper prints a number."""
        studies = self.trace_json.get("studies") or {}
        cm = self.cm
        fig8 = cm["fig8_reflectance"]
        h = cm["fig11_fig12_height"]
        fw = cm["fig13_fig14_led_fwhm"]
        f10 = cm["fig10_non_uniformity_percent"]
        wanted = [
            ("reflectance", "wall.reflectance", fig8["reflectance"][0], "ρ 0.80",
             {"LER": fig8["LER_percent"][0], "YBR": fig8["YBR"][0]}, "Fig. 8"),
            ("reflectance", "wall.reflectance", fig8["reflectance"][1], "ρ 0.98",
             {"LER": fig8["LER_percent"][1], "YBR": fig8["YBR"][1]}, "Fig. 8"),
            ("specular_fraction", "wall.specular_fraction", 1.0, "mirror walls",
             {"non_uniformity": f10["mirror"]}, "Fig. 10 (specular reflector)"),
            ("specular_fraction", "wall.specular_fraction", 0.0, "diffuse walls",
             {"non_uniformity": f10["perfect_diffuser"]}, "Fig. 10 (perfect diffuser)"),
            ("height_mm", "cavity.height_mm", h["best_LER_height_mm"], "h 10 mm",
             {"LER": h["best_LER_percent"], "non_uniformity": h["non_uniformity_percent"]["10"]},
             "Figs. 11-12, §6 (best LER)"),
            ("height_mm", "cavity.height_mm", 43.0, "h 43 mm", {"non_uniformity": h["non_uniformity_percent"]["42"]},
             "Fig. 12 (the text says 42 mm)"),
            ("led_fwhm_deg", "leds.fwhm_deg", 30.0, "FWHM 30°", {"non_uniformity": fw["non_uniformity_percent"]["30"]},
             "Fig. 14"),
        ]
        out = []
        for study, key, value, short, paper, where in wanted:
            match = [r for r in _study_rows(studies, study, key) if abs(r["values"][key] - value) < 1e-9]
            out.append({"study": study, "key": key, "value": value, "short": short, "paper": paper, "where": where,
                        "run": match[0] if match else None})
        return out

    # -- sections ------------------------------------------------------------------------------
    def sec_measurement(self) -> str:
        sc = self.scan()
        if not sc:
            return _section("measurement", "Measurement (ingest)", _missing("No scan summary in summary.json."))
        inst = sc.get("instrument") or {}
        gon = self.pb["goniometer_section2"]
        v = self.v
        rows = [
            ["beam diameter (mm)", _f(inst.get("beam_diameter_mm"), 1), _f(gon["beam_diameter_mm"], 0),
             v.check("beam diameter", inst.get("beam_diameter_mm"), gon["beam_diameter_mm"], unit="mm", digits=1)],
            ["detector aperture diameter (mm)", _f(inst.get("aperture_diameter_mm"), 1),
             _f(gon["detector_aperture_diameter_mm"], 1) + " (max.)",
             v.check("detector aperture", inst.get("aperture_diameter_mm"), gon["detector_aperture_diameter_mm"],
                     unit="mm", digits=1)],
            ["detector distance (mm)", _f(inst.get("detector_distance_mm"), 0), _f(gon["detector_distance_mm"], 0),
             v.check("detector distance", inst.get("detector_distance_mm"), gon["detector_distance_mm"], unit="mm",
                     digits=0)],
            ["detector solid angle (1e-4 sr)", _f(inst.get("solid_angle_sr"), 3, 1e4),
             _f(gon["detector_solid_angle_sr"], 2, 1e4),
             v.check("detector solid angle (1e-4 sr)", _num(inst.get("solid_angle_sr")) and
                     1e4 * inst["solid_angle_sr"], 1e4 * gon["detector_solid_angle_sr"], unit="× 1e-4 sr",
                     digits=2, half_unit=0.005,
                     note="a 25.4 mm aperture at 886 mm subtends 6.45e-4 sr (exact cone); the paper's 6.25e-4 sr "
                          "corresponds to a 25 mm aperture")],
            ["incidences (deg)", _esc(", ".join(f"{x:g}" for x in sc.get("incidences_deg", []))),
             _esc(", ".join(f"{x:g}" for x in gon["incidence_angles_deg"])), ""],
        ]
        cal = sc.get("calibration") or {}
        wl = sc.get("wavelength_nm") or {}
        cal_rows = [[_esc(k.replace("_", " ")), _esc(cal[k])] for k in cal]
        configs = "".join(f"<li><b>{_esc(c.get('name'))}</b>: {_esc(c.get('description', ''))}, incident band "
                          f"{_esc('–'.join(f'{b:g}' for b in c.get('incident_band_nm', [])))} nm, "
                          f"{_esc(c.get('records'))} records</li>" for c in sc.get("configurations", []))
        right = (_table(["goniometer", "this run", "[Power-budget] §2", "comparison"], rows,
                        "Instrument geometry beside the paper's goniometer")
                 + f"<p>{_esc(sc.get('records'))} records, sides {_esc(', '.join(sc.get('sides', [])))}, spectrometer "
                   f"{_f(wl.get('min'), 0)}–{_f(wl.get('max'), 0)} nm in steps of {_f(wl.get('step'), 1)} nm.</p>"
                 + (f"<ul>{configs}</ul>" if configs else "")
                 + _table(["calibration check", "count"], cal_rows, "Calibration counts (docs/summary.md)"))
        body = _pair(self.run_png("inplane_bsdf.png"), right)
        return _section("measurement", "Measurement (ingest)", body)

    def truth_note(self, truth: dict) -> str:
        """For synthetic data: how far the measured table is from the generator's exact values."""
        key = self.table2_incidence()
        if not truth or key is None:
            return ""
        power = (self.s["interaction_tables"][key].get("power") or {})
        diffs = [abs(_num(power.get(k)) - _num(truth.get(k))) for k in TABLE2_KEYS
                 if _num(power.get(k)) is not None and _num(truth.get(k)) is not None]
        if not diffs:
            return ""
        return (f"<p>Synthetic data: the generator's exact TIS (last column of the table) is recovered within "
                f"{max(diffs):.2f} percentage points by the calibration and the two-arc hemisphere reconstruction. "
                "The generator was built from Table 2 with a blue-loss entry that adds up (31.7 %).</p>")

    def sec_table2(self) -> str:
        key = self.table2_incidence()
        if key is None:
            return _section("table2", "Interaction table (Table 2 of [Power-budget])",
                            _missing("No interaction tables in summary.json."))
        tables = self.s["interaction_tables"]
        row = tables[key]
        theta = _num(row.get("theta_i_deg")) or float(key)
        t2 = self.pb["table2_tis_45deg_percent"]
        truth = ((self.scan().get("truth_tis_percent") or {}).get(key)) or {}
        v = self.v
        at45 = abs(theta - 45.0) < 1e-9
        rows = []
        for k, name in TABLE2_KEYS.items():
            cells = [_esc(name)]
            for q in ("power", "photons"):
                run, std = (row.get(q) or {}).get(k), (row.get(f"{q}_std") or {}).get(k)
                note = "the paper's row does not add up (see the note below)" if k == "blue_losses" else ""
                cells += [_pm(run, std), _f(t2[q].get(k), 1),
                          v.check(f"Table 2 {q} {k} at {theta:g}°", run, t2[q].get(k), std, "%", note=note)
                          if at45 else "(paper: 45° only)"]
            if truth:
                cells.append(_f(truth.get(k), 2))
            rows.append(cells)
        headers = ["interaction", "power, this run (%)", "power, paper (%)", "comparison", "photons, this run (%)",
                   "photons, paper (%)", "comparison"] + (["generator truth, power (%)"] if truth else [])
        eqe = self.pb["eqe_section6"]["EQE"]
        eqe_html = (f"<p><b>EQE</b> (converted photons out per blue photon absorbed): this run "
                    f"{_pm(row.get('eqe'), row.get('eqe_std'), 3)}, [Power-budget] §6: {eqe:.2f} — "
                    + v.check(f"EQE at {theta:g}°", row.get("eqe"), eqe, row.get("eqe_std"), digits=3,
                              half_unit=0.005) + ".</p>")
        other = []
        for k2, r2 in tables.items():
            if not isinstance(r2, dict) or "power" not in r2:
                continue
            other.append([_esc(_f(r2.get("theta_i_deg"), 0) if _num(r2.get("theta_i_deg")) is not None else k2)]
                         + [_pm((r2.get("power") or {}).get(k), (r2.get("power_std") or {}).get(k))
                            for k in TABLE2_KEYS] + [_pm(r2.get("eqe"), r2.get("eqe_std"), 3)])
        tab = _table(headers, rows, f"TIS at θi = {theta:g}°, % of the incident power and photons (± 1σ), beside "
                                    "Table 2 of [Power-budget] (45°)")
        fig = self.drawn(_table2_figure(row, t2["power"], theta),
                         "This run's power TIS (blue, ± 1σ error bars) beside Table 2 of [Power-budget] (orange).",
                         "bar chart of Table 2, run vs paper")
        body = (_pair(fig, eqe_html + self.truth_note(truth)) + f'<div class="wide">{tab}</div>'
                + f'<p class="note">Paper note: {_esc(t2["note"])} Agreement rule: |run − paper| ≤ half a unit of the '
                  "paper's last printed digit + 2σ of the run.</p>"
                + _table(["θi (deg)"] + [k.replace("_", " ") for k in TABLE2_KEYS] + ["EQE"], other,
                         "Every measured incidence: power TIS (% ± 1σ) and EQE (± 1σ)"))
        return _section("table2", "Interaction table (Table 2 of [Power-budget])", body)

    @staticmethod
    def budget_value(row: dict, key: str) -> float | None:
        """A Table 3 quantity of one budget row [%]: losses as the paper defines them, 100 − extracted total
        (the run's own ``losses`` line excludes the power still in flight after the last interaction)."""
        if key == "losses":
            total = _num(row.get("total"))
            return None if total is None else 100.0 - total
        return _num(row.get(key))

    def sec_budget(self) -> str:
        mb = self.s.get("module_budget") or {}
        power = mb.get("power") or {}
        if not power.get("iterations"):
            return _section("budget", "Module budget (Table 3 of [Power-budget])",
                            _missing("No module budget in summary.json."))
        t3 = self.pb["table3_power_budget_percent"]
        it = self.pb["iterative_model_section5"]
        last = power["iterations"][-1]
        n = len(power["iterations"])
        conv = power.get("converged") or {}
        v = self.v
        rows = []
        for k in ("blue", "yellow", "total", "losses"):
            six = self.budget_value(power["iterations"][5], k) if n >= 6 else None
            note = (f"Table 3 follows from Table 2 after six plate interactions, not seven (docs/reductions.md); "
                    f"after six this run gives {_f(six)} %") if six is not None and n != 6 else ""
            rows.append([k + (" (100 − total, the paper's definition)" if k == "losses" else ""),
                         _f(self.budget_value(last, k)), _f(self.budget_value(conv, k)),
                         _f(t3["iteration_model_45deg"][k], 1),
                         v.check(f"Table 3 {k} (model, {n} interactions)", self.budget_value(last, k),
                                 t3["iteration_model_45deg"][k], unit="%", note=note),
                         _f(t3["experiments"][k], 1), _f(it["text_cumulative_percent"][k], 1)])
        tab = _table(["extracted", f"this run, {n} plate interactions (%)", "this run, converged (%)",
                      "Table 3 model, 45° (%)", "comparison", "Table 3 experiment (%)", "paper §5 text (%)"], rows,
                     f"Module budget at θi = {_f(mb.get('incidence_deg'), 0)}°, η_MC = {_f(power.get('eta_mc'), 2)}, "
                     "% of the LED output")
        first = power.get("first_iteration") or {}
        f_rows = [["forward (extracted)", _f(first.get("forward")), _f(it["first_iteration_forward_percent"], 1),
                   v.check("first iteration forward", first.get("forward"), it["first_iteration_forward_percent"],
                           unit="%")],
                  ["backscattered", _f(first.get("backscattered")),
                   _f(it["first_iteration_backscattered_percent"], 1),
                   v.check("first iteration backscattered", first.get("backscattered"),
                           it["first_iteration_backscattered_percent"], unit="%")],
                  ["lost", _f(first.get("lost")), _f(it["first_iteration_lost_percent"], 1),
                   v.check("first iteration lost", first.get("lost"), it["first_iteration_lost_percent"], unit="%")]]
        ftab = _table(["first plate interaction", "this run (%)", "[Power-budget] §5 (%)", "comparison"], f_rows,
                      "The first pass")
        tab += f'<p class="note">Paper note: {_esc(it["note"])}</p>'
        figs = self.run_png("module_budget.png") + self.drawn(
            _budget_figure(power, t3), "This run's cumulative extracted power per plate interaction with the "
                                       "values of Table 3 of [Power-budget] at the last interaction.",
            "module budget, run vs Table 3")
        return _section("budget", "Module budget (Table 3 of [Power-budget])",
                        f'<div class="wide">{tab}</div>' + _pair(figs, ftab))

    def sec_exports(self) -> str:
        checks = self.s.get("export_checks") or []
        if not checks:
            return _section("exports", "Ray-tracer tables", _missing("No export checks in summary.json."))
        files = sorted({c.get("file") for c in checks})
        worst = max(checks, key=lambda c: abs(_num(c.get("relative_difference")) or 0.0))
        bad = [c for c in checks if not c.get("ok")]
        rows = [[f"<code>{_esc(f)}</code>",
                 _esc(", ".join(f"{_num(c.get('theta_i_deg')) or 0:g}" for c in checks if c.get("file") == f)),
                 _f(max(abs(_num(c.get("relative_difference")) or 0.0) for c in checks if c.get("file") == f), 4,
                    100.0),
                 "yes" if all(c.get("ok") for c in checks if c.get("file") == f) else
                 '<span class="differs">NO</span>'] for f in files]
        text = (f"<p>{len(files)} tables written and re-read; TIS of the table as read back vs its source: worst "
                f"{100 * abs(_num(worst.get('relative_difference')) or 0):.3f} % "
                f"(<code>{_esc(worst.get('file'))}</code>"
                f" at {_f(worst.get('theta_i_deg'), 0)}°). "
                + (f'<span class="differs">{len(bad)} checks outside the tolerance.</span>' if bad else
                   "Every check within the recipe's tolerance.") + " The papers print no such check.</p>")
        return _section("exports", "Ray-tracer tables", text + _table(
            ["file", "θi (deg)", "largest |Δ TIS| (% of source)", "within tolerance"], rows, "Re-read checks"))

    def sec_fits(self) -> str:
        fits = self.s.get("bsdf_fits") or []
        ef = self.s.get("emission_fit") or {}
        rows = []
        for f in fits:
            p, sd = f.get("params") or {}, f.get("std") or {}
            rows.append([_esc(f.get("interaction")), _esc(f.get("side")), _f(f.get("theta_i_deg"), 0),
                         _esc(f.get("model")), _pm_sig(p.get("rho"), sd.get("rho")),
                         _pm_sig(p.get("A"), sd.get("A")) if "A" in p else "—",
                         _pm_sig(p.get("sigma"), sd.get("sigma")) if "sigma" in p else "—", _f(f.get("r2"), 4),
                         _f(f.get("tis_difference_pp"), 3),
                         "yes" if f.get("converged") else '<span class="differs">no</span>', _gate_cell(f)])
        failing = sum(1 for f in fits if f.get("plausible") is False)
        gate = self.s.get("bsdf_fit_gate") or {}
        th = gate.get("thresholds") or {}
        rule = (f"TIS above 1 by more than {_f(th.get('tis_sigma'), 0)} σ, a parameter at a bound or with a standard "
                f"error above {_f(th.get('undetermined_ratio'), 0)}× its value, R² below {_f(th.get('min_r2'), 1)}"
                if th else "see bsdfkit.fit.plausibility")
        caption = (f"BSDF fits (± 1σ); ρ/π is the Lambertian term. Plausibility gate ({rule}): "
                   + (f"{failing} of {len(fits)} fits fail it; exports refuse such a fit." if failing else
                      "every fit passes it."))
        tab = _table(["interaction", "side", "θi (deg)", "model", "ρ (1)", "A (1/sr)", "σ (direction cosines)", "R²",
                      "TIS model − data (pp)", "converged", "plausibility gate"], rows,
                     _esc(caption)) if rows else _missing("No BSDF fits.")
        if failing:
            tab = (f'<p><span class="differs">{failing} of {len(fits)} BSDF fits fail the plausibility gate</span> '
                   "(flagged in the last column; converged means only that the solver stopped).</p>") + tab
        biys = [f for f in fits if f.get("interaction") == "biys"]
        note = ("<p>[Power-budget] §4.2: converted light (biys) is Lambertian, without a specular peak; this run fits "
                f"biys with <b>{_esc(', '.join(sorted({f.get('model', '?') for f in biys})))}</b>.</p>") if biys else ""
        t2 = self.cm["table2_spectrum_fit"]
        v = self.v
        if ef:
            e_rows = [
                ["peak (nm)", _pm(ef.get("peak_nm"), ef.get("peak_nm_std"), 1), _f(t2["yellow_peak_nm"], 1),
                 v.check("converted-light peak", ef.get("peak_nm"), t2["yellow_peak_nm"], ef.get("peak_nm_std"), "nm",
                         1)],
                ["FWHM (nm)", _pm(ef.get("fwhm_nm"), ef.get("fwhm_nm_std"), 1), _f(t2["yellow_fwhm_nm"], 1),
                 v.check("converted-light FWHM", ef.get("fwhm_nm"), t2["yellow_fwhm_nm"], ef.get("fwhm_nm_std"), "nm",
                         1)],
                ["asymmetry α (1)", _pm(ef.get("alpha"), ef.get("alpha_std"), 3), _f(t2["yellow_alpha"], 2),
                 v.check("converted-light asymmetry α", ef.get("alpha"), t2["yellow_alpha"], ef.get("alpha_std"),
                         digits=3)],
                ["R² (1)", _f(ef.get("r2"), 4), "0.99", ""],
            ]
            etab = _table(["converted-light spectrum", f"this run ({_esc(ef.get('model', ''))}, θi = "
                                                       f"{_f(ef.get('incidence_deg'), 0)}°)",
                           "[Cylindrical-module] Table 2", "comparison"], e_rows,
                          "Emission fit (eq. (3) of [Cylindrical-module]), ± 1σ")
            if self.scan().get("synthetic"):
                etab += ("<p class=\"note\">Synthetic data: the generator's emission truth is Table 2 of "
                         f"[Cylindrical-module] ({_f(t2['yellow_peak_nm'], 1)} nm, {_f(t2['yellow_fwhm_nm'], 1)} nm, "
                         f"α {_f(t2['yellow_alpha'], 2)}) times a smooth onset from 470 to 500 nm, so the fitted "
                         "split Gaussian differs from it by that onset and the measurement's noise, not by chance."
                         "</p>")
        else:
            etab = _missing("No emission fit in summary.json.")
        body = _pair(self.run_png("bsdf_fits.png"), note + etab) + f'<div class="wide">{tab}</div>'
        return _section("fits", "BSDF and emission fits", body)

    def sec_trace(self) -> str:
        """The module-trace section: Table 1's flux split, the device, the trends and the paper's study points."""
        tr = self.s.get("trace") or {}
        dev = tr.get("device") or {}
        se = tr.get("device_std_err") or {}
        if not dev:
            return _section("trace", "Module trace ([Cylindrical-module])", _missing("No trace in summary.json."))
        cm = self.cm
        # the verdicts are booked in the order of the page: Table 1, the device, the study points, the trends
        t1tab, t1note = self._table1_flux(se)
        devtab = self._device_table(dev, se)
        ptab = self._study_point_table()
        ttab = self.trend_table(tr.get("trends") or {})
        first = cm["first_interaction_percent_section4"]
        body = (_pair(devtab, t1tab + t1note) + self.run_png("trace_studies.png")
                + f'<div class="wide">{ttab}</div>' + f'<div class="wide">{ptab}</div>'
                + f'<p class="note">[Cylindrical-module] §4: after the first plate interaction {first["forward"]} % '
                  f"forward and {first['backward']} % backward; {first['extracted_total']} % extracted in total. The "
                  "paper's device: r = 35 mm, h = 43 mm, wall ρ = 0.985 with 1.5 % specular, four Lambertian LEDs. "
                  "Study points equal to the device (h = 43 mm; FWHM 120°, which is a Lambertian LED's) are the "
                  "device's trace.</p>")
        return _section("trace", "Module trace ([Cylindrical-module])", body)

    def _table1_flux(self, se: dict) -> tuple[str, str]:
        """The extracted flux beside Table 1 of [Cylindrical-module] and its note with the yellow/blue checks."""
        v = self.v
        t1 = self.cm["table1_flux_W"]
        ms = self.s.get("module_spectrum") or {}
        flux = ms.get("flux_W") or (self.trace_json.get("device") or {}).get("extracted") or {}
        b, y = _num(flux.get("blue")), _num(flux.get("yellow"))
        t1_rows = []
        for label, src in (("simulation", t1["simulation"]), ("measurement", t1["measurement"])):
            t1_rows.append([f"paper Table 1, {label}", _f(src["blue"], 3), _f(src["yellow"], 3), _f(src["total"], 3),
                            _f(src["yellow"] / src["blue"], 2), _f(src["blue"] / src["total"], 1, 100.0)])
        if b is not None and y is not None:
            t1_rows.append(["this run (1 W emitted)", _f(b, 4), _f(y, 4), _f(b + y, 4), _f(y / b, 2),
                            _f(b / (b + y), 1, 100.0)])
        t1tab = _table(["", "blue (W)", "yellow (W)", "total (W)", "yellow / blue (1)", "blue share (%)"], t1_rows,
                       "Extracted flux beside Table 1 of [Cylindrical-module]")
        t1note = ('<p class="note">The paper\'s fluxes are those of its four LEDs, whose emitted flux Table 1 does not '
                  "give; this run's are for 1 W emitted. Compare the split (yellow/blue, blue share), not the watts."
                  "</p>")
        if b is not None and y is not None:
            t1note += (f"<p>Yellow/blue of the extracted flux: this run {y / b:.2f} ± {_f(se.get('YBR'), 2)}, paper "
                       f"simulation {t1['simulation']['yellow'] / t1['simulation']['blue']:.2f} — "
                       + v.check("yellow/blue vs Table 1 simulation", y / b,
                                 t1["simulation"]["yellow"] / t1["simulation"]["blue"], se.get("YBR"),
                                 half_unit=0.005, note="ratio of the printed Table 1 fluxes")
                       + f"; paper measurement {t1['measurement']['yellow'] / t1['measurement']['blue']:.2f} — "
                       + v.check("yellow/blue vs Table 1 measurement", y / b,
                                 t1["measurement"]["yellow"] / t1["measurement"]["blue"], se.get("YBR"),
                                 half_unit=0.005, note="ratio of the printed Table 1 fluxes") + ".</p>")
        return t1tab, t1note

    def _device_table(self, dev: dict, se: dict) -> str:
        """The traced device's LER (checked against §4's 53 %), YBR, non-uniformity, ledger error and rays."""
        v = self.v
        defs = self.cm["definitions_section5_1"]
        extracted = self.cm["first_interaction_percent_section4"]["extracted_total"]
        ler = _num(dev.get("LER"))
        ler_se = _num(se.get("LER"))
        dev_rows = [
            ["LER (%)", _pm(dev.get("LER"), se.get("LER"), 2, 100.0), _esc(defs["LER"]) + f"; [Cylindrical-module] §4: "
             f"only {extracted} % extracted from the test device — " + v.check(
                 "device LER vs §4 of [Cylindrical-module] ('only 53 % extracted')", None if ler is None else 100 * ler,
                 extracted, None if ler_se is None else 100 * ler_se, "%", 2)],
            ["YBR (1)", _pm(dev.get("YBR"), se.get("YBR"), 2),
             "extracted yellow ray power / extracted blue ray power of the two-wavelength trace; the paper's "
             f"definition: {_esc(defs['YBR'])}"],
            ["non-uniformity (%)", _pm(dev.get("non_uniformity"), se.get("non_uniformity"), 1, 100.0),
             _esc(defs["non_uniformity"]) + _esc(_device_grid_text(dev))],
            ["ledger error (1)", f"{_num(dev.get('ledger_error')) or float('nan'):.1e}",
             "|emitted − extracted − absorbed − terminated| / emitted"],
            ["rays", _esc(dev.get("rays")), f"in {_f(dev.get('elapsed_s'), 1)} s"],
        ]
        return _table(["device", "this run (± 1σ)", "definition"], dev_rows, "The traced device", text_cols=[2])

    def _study_point_table(self) -> str:
        """The study points the paper prints an LER or YBR for, each checked against this run's."""
        v = self.v
        p_rows = []
        for p in self.study_points():
            r = p["run"]
            for q, unit, scale in (("LER", "%", 100.0), ("YBR", "", 1.0)):  # non-uniformity: the maps' section
                if p["paper"].get(q) is None:
                    continue
                name = {"LER": "LER (%)", "YBR": "YBR (1)", "non_uniformity": "non-uniformity (%)"}[q]
                if r is None:
                    p_rows.append([_esc(p["short"]), name, "not in this run", _f(p["paper"][q], 0), _esc(p["where"]),
                                   "—", "—"])
                    continue
                std = r.get(f"{q}_std")
                run_val = _num(r.get(q))
                p_rows.append([_esc(p["short"]), name, _pm(run_val, std, 2, scale),
                               _f(p["paper"][q], 0), _esc(p["where"]),
                               v.check(f"{p['short']} {q}", None if run_val is None else run_val * scale, p["paper"][q],
                                       None if _num(std) is None else _num(std) * scale, unit, 1),
                               _f((r.get("plate_incidence") or {}).get("extrapolated"), 0, 100.0) + " %"])
        if not p_rows:
            return _missing("trace.json with the studies is not in the run folder.")
        return _table(["study point", "quantity", "this run (± 1σ)", "paper", "where in the paper", "comparison",
                       "plate power on extrapolated incidences"],
                      p_rows, "Study points the paper prints an LER or YBR for (non-uniformity: see the irradiance "
                              "maps)", text_cols=[1, 4])

    def trend_table(self, trends: dict) -> str:
        """The §5 trends: the paper's size (or the reading of its words), this run's with σ, the criterion, the
        verdict, and the share of plate power on model-extrapolated incidences per study point."""
        rows = []
        for name, t in trends.items():
            m = t.get("magnitude") or {}
            unit = f" {m.get('unit')}" if m.get("unit") else ""
            size = "—" if not m else f"{_f(m.get('paper'), 2)}{unit}: {_esc(m.get('reading', ''))}"
            run = "—" if not m else (_pm(m.get("run"), m.get("run_std"), 2) if _num(m.get("run_std")) is not None
                                     else _f(m.get("run"), 2) + " (no σ)") + unit
            shares = t.get("extrapolated_share") or {}
            share = ", ".join(f"{_esc(k)}: {_f(x, 0, 100.0)} %" for k, x in shares.items() if _num(x) is not None)
            rows.append([_esc(name), _esc(t.get("paper", "")), size, run,
                         "—" if not m else _f(m.get("criterion"), 2) + unit, self.v.trend(name, t),
                         (share or "—") + ' (<a href="#plate">clamped alternative</a>)', _esc(t.get("detail", ""))])
        if not rows:
            return ""
        return _table(["trend of the paper", "what the paper finds", "paper's size (reading)", "this run's size (± 1σ)",
                       f"criterion (half unit ⊕ {K_SIGMA:g}σ)", "this run", "plate power on extrapolated incidences",
                       "this run's numbers"], rows,
                      "Trends of §5 of [Cylindrical-module], judged by direction and size", text_cols=[1, 2, 5, 6, 7])

    def map_files(self) -> list[tuple[str, xr.Dataset, str]]:
        found = []
        for path in sorted(self.dir.glob("trace_*.nc")):
            try:
                ds = netcdf.load(path)
            except InputError:
                continue
            name = find_map_variable(ds)
            if name is not None:
                found.append((path.name, ds, name))
        return found

    def sec_plate(self) -> str:
        """The plate's incidences: measured vs model-extrapolated, and why YBR moves with height as it does."""
        plate = self.trace_json.get("plate") or {}
        studies = self.trace_json.get("studies") or {}
        if not plate:
            return ""
        dev = self.trace_json.get("device") or {}
        measured = plate.get("measured_incidences_deg") or []
        extra = plate.get("extrapolated_incidences_deg") or []
        rows = [["device" if r is dev else _esc(", ".join(f"{k} = {x:g}" for k, x in (r.get("values") or {}).items()
                                                          if not k.startswith("base."))),
                 _f((r.get("plate_incidence") or {}).get("measured"), 1, 100.0),
                 _f((r.get("plate_incidence") or {}).get("extrapolated"), 1, 100.0),
                 _f(r.get("clamped_share", (r.get("clamped_incidences") or {}).get("fraction_of_plate_interactions")),
                    1, 100.0),
                 _f((r.get("plate_incidence") or {}).get("mean_blue_incidence_deg"), 1)]
                for r in [dev] + [x for rows_ in studies.values() for x in rows_ if not x.get("same_trace_as_device")]]
        tab = _table(["trace", "power on measured incidences (%)", "power on model-extrapolated incidences (%)",
                      "clamped plate interactions (%)", "mean incidence of blue power (deg)"], rows,
                     "Where the plate is lit, per trace (incidence histogram of the tracer, 1° bins)")
        clamped = _num(plate.get("clamped_share_max"))
        text = (f"<p>The goniometer measured the plate at {_esc(', '.join(f'{x:g}°' for x in measured))}; the cavity "
                "lights it from 0° to grazing. Outside the measured range the traced plate is <b>model-extrapolated"
                "</b>: each channel keeps the fitted parameters of the nearest measured incidence (Lambert + "
                "Gaussian lobe for bibs and yiys, Lambertian for biys) and its TIS follows the model's own dependence "
                "on incidence, scaled to the measured TIS at the edge; TIS sums stay ≤ 1 at every incidence. Grid "
                f"points added: {_esc(', '.join(f'{x:g}°' for x in extra) or 'none')}. Clamped plate interactions: "
                f"<b>{_f(clamped, 1, 100.0)} %</b> (largest over all traces; with the measured incidences alone the "
                "tracer would clamp every interaction outside them to the nearest one). Share of the power "
                "reaching the plate on model-extrapolated "
                f"incidences: <b>{_f(plate.get('device_extrapolated_power_share'), 1, 100.0)} %</b> for the device, "
                f"at most {_f(plate.get('extrapolated_power_share_max'), 1, 100.0)} % over the studies. The model "
                "has no Fresnel rise of the specular reflection towards grazing incidence: a lobe that the horizon "
                "clips loses its clipped part to absorption, so results that depend on light beyond 56° carry "
                "this assumption.</p><p><b>The alternative</b> — the plate on its measured incidences only, clamped by "
                "the tracer — is traced once for every study point by <code>benchmarks/study_checks.py --clamp</code> "
                "(too costly for this job); for the bundled cl830 recipe no trend verdict moves (docs/tracer.md, "
                "“Trends with the plate clamped”). The trend table gives each study point's share of plate power on "
                "model-extrapolated incidences beside its verdict.</p>")
        why = ""
        trends = (self.s.get("trace") or {}).get("trends") or {}
        height = trends.get("YBR slightly lower for short cavities (Fig. 11)")
        rows_h = sorted(studies.get("height_mm", []), key=lambda r: r["values"].get("cavity.height_mm", 0.0))
        if height is not None and len(rows_h) >= 2:
            grid = plate.get("grid_deg") or []
            f_bibs = (plate.get("tis") or {}).get("bibs_transmission") or []
            at = {f"{g:g}": 100 * t for g, t in zip(grid, f_bibs)}
            inc = [(r["values"]["cavity.height_mm"], _num((r.get("plate_incidence") or {}).get(
                "mean_blue_incidence_deg")), r.get("YBR"), r.get("YBR_std")) for r in rows_h]
            verdict = "agrees with" if height.get("holds") else "<b>disagrees</b> with"
            why = ("<h3>YBR vs cavity height</h3><p>This run " + verdict + " the paper here: YBR "
                   + ", ".join(f"{_pm(y, e, 2)} at {h:g} mm" for h, _, y, e in inc)
                   + ". The paper's explanation (§5.3) is that in a short cavity the blue light meets the plate at "
                     "<i>smaller</i> incidences, where bibs transmits more blue, so less of it is converted. In this "
                     "model the opposite happens: the mean incidence of the blue power on the plate is "
                   + ", ".join(f"{a:.1f}° at {h:g} mm" for h, a, _, _ in inc if a is not None)
                   + " (figure: left). Without walls in between, the LEDs' Lambertian light reaches a close plate "
                     "directly, spread like cos θ·sin θ around 45° and out to grazing; a tall cavity sends the "
                     "oblique part to the walls first, and what the diffuse walls return is spread over the plate. "
                     "The plate's forward blue TIS falls with incidence (F bibs "
                   + ", ".join(f"{at[k]:.2f} % at {k}°" for k in ("5", "45", "56") if k in at)
                   + ", figure: right), so the short cavity transmits less blue and YBR rises. The paper traced "
                     "the measured ray file of its LEDs, whose far field need not be Lambertian at large angles, "
                     "and its plate was measured up to 60°; this run's device has ideal Lambertian LEDs and "
                     "the synthetic plate's incidence dependence.</p>")
        body = text + self.run_png("trace_incidence.png") + why + f'<div class="wide">{tab}</div>'
        return _section("plate", "The plate's incidences: measured and model-extrapolated", body)

    def _map_panel(self, files: list[tuple[str, xr.Dataset, str]], dims: tuple[str, ...],
                   value: float) -> tuple[xr.DataArray, str] | None:
        """The map of one study value from the study files, or the device's when the device is that point."""
        for fname, ds, var in files:
            for d in dims:
                if d in ds[var].dims:
                    hit = [i for i, x in enumerate(np.atleast_1d(ds[d].values)) if abs(float(x) - value) < 1e-9]
                    if hit:
                        return ds[var].isel({d: hit[0]}).squeeze(drop=True), fname
        dev = self.device_configuration()
        for fname, ds, var in files:
            if fname == "trace_device.nc" and any(abs(dev.get(d, math.nan) - value) < 1e-9 for d in dims):
                return ds[var], fname
        return None

    def sec_maps(self) -> str:
        found = self.map_files()
        studies = self.trace_json.get("studies") or {}
        nu_paper = {"Fig. 10": {1.0: self.cm["fig10_non_uniformity_percent"]["mirror"],
                                0.0: self.cm["fig10_non_uniformity_percent"]["perfect_diffuser"]},
                    "Fig. 12": {10.0: self.cm["fig11_fig12_height"]["non_uniformity_percent"]["10"],
                                43.0: self.cm["fig11_fig12_height"]["non_uniformity_percent"]["42"]},
                    "Fig. 14": {30.0: self.cm["fig13_fig14_led_fwhm"]["non_uniformity_percent"]["30"],
                                120.0: self.cm["fig11_fig12_height"]["non_uniformity_percent"]["42"]}}
        parts, rows, missing_text, used = [], [], [], set()
        for fig_no, what, dims, panels in PAPER_MAP_FIGURES:
            maps: dict[str, xr.DataArray] = {}
            sources: list[str] = []
            for value, label in panels:
                hit = self._map_panel(found, dims, value)
                paper = nu_paper[fig_no].get(value)
                if hit is None:
                    missing_text.append(f"{fig_no} {label}")
                else:
                    da, fname = hit
                    used.add(fname)
                    sources += [fname] if fname not in sources else []
                    maps[f"{label} ({fname})" + (f"\npaper: {paper:g} %" if paper is not None else "")] = \
                        _display_map(da)
                row_nu = [r for r in _study_rows(studies, dims[1], dims[0]) if abs(r["values"][dims[0]] - value) < 1e-9]
                row = row_nu[0] if row_nu else {}
                if _num(row.get("non_uniformity")) is not None and row.get("non_uniformity_bins"):
                    # the tracer's split-half value on the grid it converged on (the quantity of the paper)
                    nu, nu_std, grid = _num(row["non_uniformity"]), _num(row.get("non_uniformity_std")), _conv_cell(row)
                elif hit is not None:  # a map without the tracer's sub-maps: its max − min, σ from the map
                    nu, nu_std = map_non_uniformity(hit[0]), _map_nu_std(hit[0])
                    grid = _grid_check(nu, _coarser_non_uniformity(hit[0]), nu_std)
                else:
                    nu = nu_std = None
                    grid = _grid_check(None, None, None)
                rows.append([fig_no, _esc(label), "yes" if hit else '<span class="absent">not in this run</span>',
                             _pm(nu, nu_std, 1, 100.0), grid,
                             "—" if paper is None else f"{paper:g}", "—" if paper is None or nu is None else
                             self.v.check(f"{fig_no} {label} irradiance non-uniformity", 100 * nu, paper,
                                          None if nu_std is None else 100 * nu_std, unit="%", digits=1)])
            if maps:
                emitted = _num(found[0][1].attrs.get("emitted_W")) if found else None
                parts.append(self.drawn(irradiance_maps_figure(maps, ncols=3, emitted_W=emitted,
                                                               title=f"{fig_no} of [Cylindrical-module]: {what}"),
                                        f"This run's irradiance on the cavity side of the plate for the panels of "
                                        f"{fig_no} of [Cylindrical-module] ({_esc(what)}), one colour scale from the "
                                        "smallest E_min to the largest E_max; each panel's non-uniformity in its "
                                        "title, the paper's where it prints one. From "
                                        + ", ".join(f"<code>{_esc(f)}</code>" for f in sources) + ".",
                                        f"{fig_no} maps"))
        for fname, ds, var in found:  # maps of other files (a sweep of other parameters, or a lone device)
            if fname in used:
                continue
            da = ds[var]
            emitted = _num(ds.attrs.get("emitted_W"))
            if [d for d in da.dims if d not in MAP_DIMS]:
                fig = irradiance_maps_figure(da, emitted_W=emitted, title=f"{fname}: {var}")
            else:
                nu = _num(ds["non_uniformity"].values) if "non_uniformity" in ds and ds["non_uniformity"].ndim == 0 \
                    else None
                fig = irradiance_map_figure(da, title=f"{fname}: {da.attrs.get('long_name', var)}", non_uniformity=nu,
                                            emitted_W=emitted)
            parts.append(self.drawn(fig, f"Irradiance map from <code>{_esc(fname)}</code> (variable "
                                         f"<code>{_esc(var)}</code>): bins entirely inside the plate (dashed circle: "
                                         "plate edge).", f"irradiance map {fname}"))
        if not found:
            parts.append(_missing("No trace_*.nc file with an irradiance map in the run folder."))
        cov = _table(["paper figure", "panel", "map in this run", "non-uniformity, this run (± 1σ, %)",
                      "grid: value on the next finer grid (%), change vs σ", "non-uniformity, paper (%)",
                      "comparison"], rows,
                     "The irradiance maps of [Cylindrical-module] and this run: (E_max − E_min)/(E_max + E_min)",
                     left=2)
        text = _maps_note(missing_text)
        body = f'<div class="wide">{cov}</div>' + text + "".join(parts)
        return _section("maps", "Irradiance maps (Figs. 10, 12, 14 of [Cylindrical-module])", body)

    def device_configuration(self) -> dict[str, float]:
        """Study parameters the device shares with a study point: the point whose trace is the device's exactly."""
        dev = (self.trace_json.get("device") or {})
        ler = _num(dev.get("LER"))
        out: dict[str, float] = {}
        if ler is None:
            return out
        for rows in (self.trace_json.get("studies") or {}).values():
            for r in rows:
                if _num(r.get("LER")) == ler:
                    for k, x in (r.get("values") or {}).items():
                        if _num(x) is not None:
                            out[k] = float(x)
        return out

    def sec_spectrum(self) -> str:
        ms = self.s.get("module_spectrum") or {}
        col = ms.get("colour") or {}
        if not col:
            return _section("spectrum", "Module spectrum and colour",
                            _missing("No module spectrum in summary.json."))
        led = ms.get("led_spectrum") or {}
        t2 = self.cm["table2_spectrum_fit"]
        rows = [["x (1)", _f(col.get("x"), 4)], ["y (1)", _f(col.get("y"), 4)], ["CCT (K)", _f(col.get("cct_K"), 0)],
                ["Duv (1)", _f(col.get("duv"), 4)],
                ["luminous efficacy of radiation (lm/W)", _f(col.get("luminous_efficacy_lm_per_W"), 1)],
                [f"YBR of the spectrum ({band_label(COLORIMETRY_YELLOW_BAND_NM)} / "
                 f"{band_label(COLORIMETRY_BLUE_BAND_NM)})", _f(col.get("ybr"), 2)]]
        tab = _table(["colour of the rebuilt spectrum", "this run"], rows, "CIE 1931 2°, CCT and Duv (Ohno 2013)")
        v = self.v
        led_rows = [["LED peak (nm)", _f(led.get("peak_nm"), 1), _f(t2["blue_peak_nm"], 1),
                     v.check("pump LED peak", led.get("peak_nm"), t2["blue_peak_nm"], unit="nm", digits=1)],
                    ["LED FWHM (nm)", _f(led.get("fwhm_nm"), 1), _f(t2["blue_fwhm_nm"], 1),
                     v.check("pump LED FWHM", led.get("fwhm_nm"), t2["blue_fwhm_nm"], unit="nm", digits=1)]]
        tab += _table(["pump LED spectrum", "this run", "[Cylindrical-module] Table 2", "comparison"], led_rows,
                      "Blue LED spectrum used for the rebuild")
        ybr_dev = _num(((self.s.get("trace") or {}).get("device") or {}).get("YBR"))
        tab += ("<p><b>Two YBRs.</b> The spectrum's YBR = Σ 471–780 nm / Σ 380–470 nm of the rebuilt spectrum "
                f"({_f(col.get('ybr'), 2)}), the paper's §5.1 definition; the trace's YBR = yellow / blue ray power of "
                f"the two-wavelength model ({_f(ybr_dev, 2)}). They differ because the trace counts all pump light as "
                "blue and all converted light as yellow, while the spectral YBR splits the rebuilt spectrum at 470 nm, "
                "where the LED's tail and the phosphor emission overlap (the rebuild itself matches the band sums "
                "380–500 / 501–780 nm of Table 2 of [Cylindrical-module]). The paper prints no colour point or CCT "
                "for the module.</p>"
                f"<p class=\"note\">Fluxes from {_esc(ms.get('flux_source', '?'))}.</p>")
        return _section("spectrum", "Module spectrum and colour", _pair(self.run_png("module_spectrum.png"), tab))

    def sec_spectral_comparison(self) -> str:
        """HTML section: the figure, band powers with relative differences, the direction check, LER/YBR/efficacy,
        the spectral trace's ledgers, and the stage's seconds and share of the run. Empty without the stage."""
        sc = self.s.get("spectral_comparison")
        if not sc:
            return ""
        b, chk = sc.get("bands") or {}, sc.get("direction_check") or {}
        tw, sp = sc.get("two_wavelength") or {}, sc.get("spectral") or {}
        holds = chk.get("holds")
        above = "above" if chk.get("near_pump_overestimated") else "NOT above"
        below = "below" if chk.get("yellow_underestimated") else "NOT below"
        verdict = (f'<span class="{"agree" if holds else "differs"}">'
                   f'{"the direction holds" if holds else "the direction does NOT hold"}</span>: in '
                   f'{_esc((b.get("near_pump") or {}).get("label", "460-500 nm"))} the two-wavelength spectrum is '
                   f'{above} the spectral one, in the yellow band it is {below}'
                   + (f'; against §4.2 beyond 1 σ in {_esc(", ".join(chk["contradicting_bands"]))} (sub-band table)'
                      if chk.get("contradicting_bands") else "") + '.')
        if not holds:
            self.v.disagreements.append("spectral vs two-wavelength mode: the direction of §4.2 of "
                                        "[Cylindrical-module] does not hold on this plate (see its section)")
        rows = []
        for key, what in (("near_pump", "power near 470 nm"), ("yellow", "yellow power (module yellow band)")):
            row = b.get(key) or {}
            rows.append([f"{_esc(what)}, {_esc(row.get('label', '?'))} (W)",
                         _pm_sig(row.get("two_wavelength_W"), row.get("two_wavelength_std_W")),
                         _pm_sig(row.get("spectral_W"), row.get("spectral_std_W")), _relative_difference(row)])
        rows += [["LER: extracted / emitted power (1)", _pm_sig(tw.get("LER"), tw.get("LER_std")),
                  _pm_sig(sp.get("LER"), sp.get("LER_std")), "—"],
                 ["YBR (1), " + _esc(sp.get("YBR_definition", "")), _pm_sig(tw.get("YBR_spectrum"),
                                                                         tw.get("YBR_spectrum_std")),
                  _pm_sig(sp.get("YBR"), sp.get("YBR_std")), "—"],
                 ["luminous efficacy of radiation (lm/W)", _f(tw.get("luminous_efficacy_lm_per_W"), 1),
                  _f(sp.get("luminous_efficacy_lm_per_W"), 1), "—"]]
        tab = _table(["quantity", "two-wavelength", "spectral", "two-wavelength / spectral − 1"], rows,
                     "Module spectra of the two modes on the same plate (± standard errors of the traces)")
        ledger = sp.get("ledger") or {}
        power, photons = ledger.get("power_W") or {}, ledger.get("photons_per_s") or {}
        lines = [k for k in power if k != "error"] + [k for k in photons if k not in power and k != "error"]
        tab += _table(["ledger line (spectral trace)", "power (W)", "photons (1/s)"],
                      [[_esc(k), _f(power.get(k), 6) if k in power else "—",
                        f"{photons[k]:.5e}" if _num(photons.get(k)) is not None else "—"] for k in lines]
                      + [["relative error", f"{power.get('error', float('nan')):.1e}",
                          f"{photons.get('error', float('nan')):.1e}"]],
                      "Spectral trace: power and photon ledgers (the Stokes loss is a power line only)")
        seconds = self.s.get("stage_seconds") or {}
        own = _num(seconds.get("spectral comparison"))
        total = sum(v for v in (_num(x) for x in seconds.values()) if v is not None)
        parts = ", ".join(f"{_esc(k)} {v:g} s" for k, v in (sc.get("stage_seconds") or {}).items())
        time_note = (f"<p class=\"note\">Stage time {own:.1f} s of {total:.1f} s of stages "
                     f"({100 * own / total:.0f} %): {parts}.</p>" if own is not None and total > 0 else "")
        text = (f"<p>One plate, two descriptions, both from <code>{_esc(sc.get('measurement', '?'))}</code>: the "
                "two-wavelength plate (blue and yellow configurations) and the plate spectral model (monochromator "
                f"scan); the device scene traced in both modes with {_esc(sc.get('rays'))} rays each and the same LED "
                "spectrum. The two-wavelength spectrum is built as the paper builds it: extracted blue power × the LED "
                f"spectrum shape + extracted yellow power × the emission shape ({_esc(sc.get('emission_shape', '?'))})."
                "</p><p><b>[Cylindrical-module] §4.2</b>: the two-wavelength model overestimates the power near "
                f"470 nm and underestimates the yellow emission. This run: {verdict}</p>")
        return _section("spectral-modes", "Spectral mode vs two-wavelength mode (§4.2 of [Cylindrical-module])",
                        text + _pair(self.run_png("spectral_comparison.png"), tab) + self._sub_bands(sc)
                        + time_note)

    def _sub_bands(self, sc: dict) -> str:
        """The mode difference per sub-band with σ, its ablations, the bands against §4.2 (added to the
        disagreements) and the emission table's anti-Stokes shares."""
        bands, abl = sc.get("bands") or {}, sc.get("ablations") or {}
        if not bands:
            return ""
        names = {-1: "below", 1: "above", 0: "not stated"}
        head = ["band", f"this run ({_esc(sc.get('rays'))} rays per mode)"]
        head += [f"{_esc(a.get('description', k))} ({_esc(a.get('rays'))} rays)" for k, a in abl.items()]
        head.append("§4.2: two-wavelength … spectral")
        rows = []
        for key, row in bands.items():
            direction = row.get("paper_direction", 0)
            cells = [_esc(row.get("label", key)), _relative_difference(row)]
            cells += [_relative_difference((a.get("bands") or {}).get(key) or {}) for a in abl.values()]
            against = row.get("contradicts_paper")
            cells.append(f'{names.get(direction, "?")}'
                         + (' <span class="differs">(contradicted)</span>' if against else ""))
            rows.append(cells)
            if against:
                self.v.disagreements.append(
                    f"spectral vs two-wavelength mode, {row.get('label', key)}: two-wavelength "
                    f"{100 * row['relative_difference']:+.1f} ± {100 * row['relative_difference_std']:.1f} % "
                    f"relative to spectral, but §4.2 of [Cylindrical-module] has it {names[direction]}")
        tab = _table(head, rows, "Two-wavelength / spectral − 1 per band (± σ of both traces), and with one cause "
                                 "switched off at a time (ablations: fewer rays, their own σ)")
        sh = (sc.get("spectral") or {}).get("anti_stokes_share") or {}
        if sh.get("excitation_nm"):
            pairs = ", ".join(f"{x:g} nm {100 * d:.1f} → {100 * c:.1f} %" for x, d, c in
                              zip(sh["excitation_nm"], sh.get("data", []), sh.get("conditional", [])))
            conv = ((sc.get("spectral") or {}).get("ledger") or {}).get("conversions") or {}
            traced = (f" In the trace {100 * conv['anti_stokes_share']:.2f} % of the converted photons left at a "
                      f"shorter wavelength, creating {conv['anti_stokes_gain_W']:.2e} W."
                      if "anti_stokes_share" in conv else "")
            tab += (f"<p>Emission given the excitation: below the excitation wavelength only the thermal tail at "
                    f"{_f(sh.get('temperature_K'), 2)} K (Boltzmann factor). Share of converted photons leaving at a "
                    f"shorter wavelength, measured rows → traced table: {_esc(pairs)}.{_esc(traced)}</p>")
        return tab

    def sec_other_figures(self) -> str:
        rest = [p.name for p in sorted(self.dir.glob("*.png")) if p.name not in self.used_png]
        if not rest:
            return ""
        return _section("other", "Other figures of the run", "".join(self.run_png(n) for n in rest))

    def sec_details(self) -> str:
        st = self.s.get("stage_seconds") or {}
        rows = [[_esc(k), _f(x, 2)] for k, x in st.items()]
        outs = "".join(f"<li><code>{_esc(o)}</code></li>" for o in self.s.get("outputs", []))
        lines = "\n".join(str(x) for x in self.s.get("report_lines", []))
        body = (_table(["stage", "wall time (s)"], rows, "Stage timings") if rows else "") + (
            f"<h3>Files of the run</h3><ul>{outs}</ul>" if outs else "") + (
            f"<h3>What the run printed</h3><pre>{_esc(lines)}</pre>" if lines else "")
        return _section("details", "Run details", body or _missing("No run details in summary.json."))

    def sec_sources(self) -> str:
        src = self.pv["source"]
        items = "".join(f"<li>[{_esc(p['key'])}] “{_esc(p['title'])}”, <i>{_esc(p['journal'])}</i>. Used: "
                        f"{_esc(p['used'])}.</li>" for p in (src["power_budget"], src["cylindrical_module"]))
        return _section("sources", "Sources", f"<p>{_esc(src['about'])}</p><ul>{items}</ul>"
                                               f'<p class="note">Written by bsdfkit {_esc(__version__)}.</p>')

    # -- opening -------------------------------------------------------------------------------
    def opening(self) -> str:
        sc = self.scan()
        s = self.s
        sample = sc.get("sample") or s.get("recipe") or self.dir.name
        synthetic = bool(sc.get("synthetic"))
        when = ""
        with_summary = self.dir / "summary.json"
        if with_summary.is_file():
            when = datetime.fromtimestamp(with_summary.stat().st_mtime, UTC).strftime("%Y-%m-%d %H:%M UTC")
        head = (f"<h1>BSDF and module report: {_esc(sample)}</h1>"
                f'<p class="sub">recipe <code>{_esc(s.get("recipe", "?"))}</code> ({_esc(s.get("recipe_file", ""))}), '
                f"measurement <code>{_esc(Path(str(s.get('measurement', '?'))).name)}</code>, run finished {when}</p>")
        if synthetic:
            head += ('<div class="banner"><b>Synthetic data.</b> This measurement was made by bsdfkit\'s virtual '
                     "goniometer from a known truth, not measured on a real plate: agreement with the papers' numbers "
                     "that the generator was built from (Table 2 of [Power-budget]) is by construction.</div>")
        else:
            head += '<div class="banner"><b>Measured data</b> (not synthetic).</div>'
        inc = ", ".join(f"{x:g}°" for x in sc.get("incidences_deg", []))
        wl = sc.get("wavelength_nm") or {}
        configs = ", ".join(f"{c.get('name')} ({c.get('description', '')})" for c in sc.get("configurations", []))
        measured = (f"<h2>What was measured</h2><p>Sample <b>{_esc(sample)}</b> "
                    f"({'synthetic' if synthetic else 'measured'}): goniometric BSDF at incidences {_esc(inc or '?')}, "
                    f"sides {_esc(', '.join(sc.get('sides', [])) or '?')}, {_esc(sc.get('records', '?'))} detector "
                    f"positions, spectra {_f(wl.get('min'), 0)}–{_f(wl.get('max'), 0)} nm; incident light: "
                    f"{_esc(configs or '?')}. From it the run computed the interaction table and module budget "
                    "([Power-budget]), ray-tracer tables, BSDF and emission fits, a Monte Carlo of the module and its "
                    "rebuilt spectrum ([Cylindrical-module]).</p>")
        return head + measured

    def found(self) -> str:
        cards = []

        def card(key: str, value: str, note: str = "") -> None:
            cards.append(f'<div class="card"><div class="k">{key}</div><div class="v">{value}</div>'
                         f'<div class="k">{note}</div></div>')

        key = self.table2_incidence()
        t2html = ""
        if key is not None:
            row = self.s["interaction_tables"][key]
            t2 = self.pb["table2_tis_45deg_percent"]["power"]
            t2html = _table(["TIS at " + _esc(f"{_num(row.get('theta_i_deg')) or float(key):g}") + "°",
                             "this run (% power, ± 1σ)", "paper Table 2 (%)"],
                            [[_esc(k.replace("_", " ")), _pm((row.get("power") or {}).get(k),
                                                             (row.get("power_std") or {}).get(k)), _f(t2.get(k), 1)]
                             for k in TABLE2_KEYS], "Interaction table")
            card("EQE (1)", _pm(row.get("eqe"), row.get("eqe_std"), 3), "paper §6: 0.80")
        power = (self.s.get("module_budget") or {}).get("power") or {}
        if power.get("iterations"):
            last = power["iterations"][-1]
            card(f"module budget, {len(power['iterations'])} plate interactions", f"{_f(last.get('total'), 1)} %",
                 f"blue {_f(last.get('blue'), 2)} %, yellow {_f(last.get('yellow'), 2)} %, losses "
                 f"{_f(last.get('losses'), 1)} %; converged {_f((power.get('converged') or {}).get('total'), 1)} %; "
                 "paper Table 3: 53.6 %")
        tr = self.s.get("trace") or {}
        dev, se = tr.get("device") or {}, tr.get("device_std_err") or {}
        if dev:
            card("LER: extracted / emitted LED power", f"{_pm(dev.get('LER'), se.get('LER'), 2, 100.0)} %",
                 "Monte Carlo of the device with this run's plate")
            card("YBR, yellow / blue ray power", _pm(dev.get("YBR"), se.get("YBR"), 2),
                 "yellow / blue extracted ray power of the two-wavelength trace")
            card("irradiance non-uniformity", f"{_pm(dev.get('non_uniformity'), se.get('non_uniformity'), 1, 100.0)} %",
                 "(E_max − E_min)/(E_max + E_min) on the plate" + _device_grid_text(dev))
        col = (self.s.get("module_spectrum") or {}).get("colour") or {}
        if col:
            card("colour of the module", f"x {_f(col.get('x'), 4)}, y {_f(col.get('y'), 4)}",
                 f"CCT {_f(col.get('cct_K'), 0)} K, Duv {_f(col.get('duv'), 4)}, "
                 f"{_f(col.get('luminous_efficacy_lm_per_W'), 0)} lm/W; spectrum YBR {_f(col.get('ybr'), 2)} "
                 "(Σ 471–780 nm / Σ 380–470 nm)")
        trends = tr.get("trends") or {}
        if trends:
            held = sum(1 for t in trends.values() if t.get("holds"))
            failed = [name for name, t in trends.items() if not t.get("holds")]
            card("trends of [Cylindrical-module] §5", f"{held} of {len(trends)} hold",
                 ("not reproduced: " + "; ".join(_esc(n) for n in failed) + " (explained in the plate section)")
                 if failed else "every trend has the paper's direction and size")
        plate = tr.get("plate") or {}
        if plate:
            card("plate incidences", f"{_f(plate.get('clamped_share_max'), 1, 100.0)} % clamped",
                 f"measured {_esc(', '.join(f'{x:g}°' for x in plate.get('measured_incidences_deg', [])))}; "
                 f"{_f(plate.get('device_extrapolated_power_share'), 1, 100.0)} % of the device's plate power on "
                 "model-extrapolated incidences")
        return ("<h2>What was found</h2>" + _pair(t2html or _missing("No interaction table."),
                                                 f'<div class="cards">{"".join(cards)}</div>'))

    def build(self) -> str:
        # one function per section, numbered in this order (a new stage adds its function here)
        numbered = [self.sec_measurement(), self.sec_table2(), self.sec_budget(), self.sec_exports(), self.sec_fits(),
                    self.sec_trace(), self.sec_plate(), self.sec_maps(), self.sec_spectrum(),
                    self.sec_spectral_comparison(), self.sec_other_figures()]
        numbered = [sec.replace("<h2>", f"<h2>{k}. ", 1) for k, sec in enumerate((x for x in numbered if x), 1)]
        sections = numbered + [self.sec_details(), self.sec_sources()]
        if self.v.disagreements:
            dis = ('<div class="disagree"><b>Where this run disagrees with the papers</b> (|run − paper| larger than '
                   f"√(half the paper's last printed digit² + ({K_SIGMA:g}σ of the run)²); a trend whose direction or "
                   "size is not the paper's):<ul>"
                   + "".join(f"<li>{_esc(d)}</li>" for d in self.v.disagreements) + "</ul></div>")
        else:
            dis = "<p>This run agrees with every paper number it is compared with.</p>"
        titles = [(m.group(1), html.unescape(m.group(2))) for m in
                  (re.match(r'<section id="([^"]+)"><h2>([^<]+)</h2>', s) for s in sections) if m]
        nav = "<nav><h2>Contents</h2><ol>" + "".join(f'<li><a href="#{a}">{_esc(t)}</a></li>' for a, t in titles) + \
              "</ol></nav>"
        title = _esc(f"bsdfkit report: {self.scan().get('sample') or self.s.get('recipe') or self.dir.name}")
        text = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
                f"<title>{title}</title><style>{_CSS}</style></head><body><main>\n"
                + self.opening() + self.found() + dis + nav + "\n".join(sections)
                + "\n</main></body></html>\n")
        for (token, _, caption, alt), png in zip(self.pending, png_results([p[1] for p in self.pending])):
            text = text.replace(token, _figure(png, caption, alt), 1)
        return text


def write_report(run_dir: str | Path, force: bool = False, renderer: PngRenderer | None = None) -> Path:
    """Write ``run_dir/report.html`` from a finished run folder; return its path.

    One self-contained HTML file (figures as base64 PNG data URIs, inline CSS, no script, no external
    reference), written atomically; an existing report is replaced only with ``force``. Needs
    ``run_dir/summary.json``; every other input (PNG figures, ``trace.json``, ``trace_*.nc`` maps) is used
    when present and said to be missing otherwise.

    Parameters
    ----------
    run_dir : str or pathlib.Path
        Folder of a finished run.
    force : bool
        Replace an existing report.
    renderer : PngRenderer, optional
        Draws the report's own figures (by default in this process).

    Returns
    -------
    pathlib.Path
        The report written.
    """
    run_dir = Path(run_dir)
    target = check_writable(run_dir / REPORT_NAME, force)
    summary_path = run_dir / "summary.json"
    if not summary_path.is_file():
        raise InputError("not a finished run folder: summary.json is missing", file=run_dir,
                         expected="the output folder of `bsdfkit run`")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"summary.json cannot be read ({type(exc).__name__})", file=summary_path) from None
    if not isinstance(summary, dict):
        raise InputError("summary.json does not hold an object", file=summary_path, expected="a JSON object")
    text = _Report(run_dir, summary, paper_values(), renderer).build()
    return write_text(target, text, force)
