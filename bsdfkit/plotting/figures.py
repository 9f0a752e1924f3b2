"""Figures for run reports. Uses matplotlib's object API (no pyplot, so no global backend state)."""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bsdfkit.core.jaxconfig import jitted, x64
from bsdfkit.core.records import incidences, select, signed_in_plane_theta
from bsdfkit.models.registry import bsdf_model
from bsdfkit.plotting.layout import Margins, fixed_margins
from bsdfkit.plotting.ticks import log_y


def _model_at(p, theta_i, theta_s, phi_s, *, model: str):
    """The registry model's JAX function at angles [rad]."""
    return bsdf_model(model).function(p, {"theta_i": theta_i, "theta_s": theta_s, "phi_s": phi_s})


@functools.cache
def _model_fn(model: str):
    """One callable per model, so that :func:`bsdfkit.core.jaxconfig.jitted` compiles it once."""
    return functools.partial(_model_at, model=model)


def _model_curve(model: str, params: dict[str, float], theta_i_deg: float, theta_s_deg, phi_s_deg) -> np.ndarray:
    """:func:`bsdfkit.fit.least_squares.bsdf_model_values` (the same model function) as one compiled call: op by
    op, each JAX operation was compiled on first use (1.9 s CPU for the fits figure, 0.2 s compiled)."""
    with x64():
        return np.asarray(jitted(_model_fn(model))(
            bsdf_model(model).vector(params), math.radians(theta_i_deg), np.radians(theta_s_deg),
            np.radians(phi_s_deg)))


def in_plane_bsdf_figure(ds: xr.Dataset, config: str = "blue", wavelength_nm: float = 460.0) -> Figure:
    """BSDF at one wavelength in the plane of incidence, reflection (R) and transmission (T), per incidence.

    The analogue of Fig. 6 of the power-budget paper (log scale; + angles on the specular side).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated scan with ``bsdf`` and ``bsdf_std`` [1/sr] over ``wavelength``.
    config : str
        Configuration to plot (``blue`` or ``yellow``).
    wavelength_nm : float
        Wavelength plotted (nearest in the data) [nm].

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    fig = Figure(figsize=(9, 4))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, side, tag in ((axes[0], "reflection", "R"), (axes[1], "transmission", "T")):
        for th in incidences(ds):
            sub = select(ds, config=config, theta_i_deg=th, side=side, arc="in_plane")
            x = signed_in_plane_theta(sub)
            order = np.argsort(x)
            y = sub["bsdf"].sel(wavelength=wavelength_nm, method="nearest").values[order]
            e = sub["bsdf_std"].sel(wavelength=wavelength_nm, method="nearest").values[order]
            keep = np.isfinite(y) & (y > 0)
            ax.errorbar(x[order][keep], y[keep], yerr=e[keep], marker=".", ms=3, lw=1, capsize=0,
                        label=f"data, {tag}, θi = {th:g}° (± 1σ)")
        log_y(ax)
        ax.set_xlabel("in-plane θs (deg, + = specular side)")
        ax.set_title(f"{side} at {wavelength_nm:g} nm ({config})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("BSDF (1/sr)")
    fig.suptitle(ds.attrs.get("sample_name", ""), fontsize=10)
    fig.tight_layout()
    return fig


def budget_figure(power, photons=None) -> Figure:
    """Cumulative extracted power and losses per plate interaction (Fig. 10 of the power-budget paper).

    With ``photons`` a second panel gives the same in photons (% of the LEDs' photons): one quantity per axis.

    Parameters
    ----------
    power : ModuleBudget
        Budget in power (% of the LEDs' power).
    photons : ModuleBudget, optional
        Budget in photons (% of the LEDs' photons).

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    budgets = [("power", power)] + ([("photons", photons)] if photons is not None else [])
    fig = Figure(figsize=(6.0 * len(budgets) + 2.0, 4))
    axes = fig.subplots(1, len(budgets), squeeze=False)[0]
    k = np.arange(1, len(power.iterations) + 1)
    for ax, (unit, budget) in zip(axes, budgets):
        for key, style in (("total", "-o"), ("yellow", "-s"), ("blue", "-^"), ("losses", "--x")):
            ax.plot(k, [row[key] for row in budget.iterations], style, label=f"{key}, iterative model")
        ax.axhline(budget.converged["total"], color="grey", lw=0.8, ls=":", label="total, converged (closed form)")
        ax.set_xlabel("plate interaction k (1 = direct pass from the LEDs)")
        ax.set_ylabel(f"cumulative share of the LEDs' {unit} (%)")
        ax.set_title(f"module budget in {unit}, η_MC = {budget.eta_mc:g}", fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[-1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside: no curve hidden
    fig.tight_layout()
    return fig


#: The studies' x axes: recipe key → (scene key of the x value, axis label).
STUDY_AXES = {
    "reflectance": ("wall.reflectance", "wall and base reflectance ρ (1)"),
    "height_mm": ("cavity.height_mm", "cavity height h (mm)"),
    "led_fwhm_deg": ("leds.fwhm_deg", "LED beam FWHM (deg; 120° = Lambertian)"),
    "specular_fraction": ("wall.specular_fraction", "specular fraction of the wall reflectance (1)"),
}
#: Column titles: the study and the figures of the cylindrical-module paper it stands beside.
STUDY_TITLES = {"reflectance": "wall reflectance (Fig. 8)", "height_mm": "cavity height (Figs. 11-12)",
                "led_fwhm_deg": "LED beam width (Figs. 13-14)", "specular_fraction": "wall finish (Figs. 9-10)"}
#: The figure's rows: quantity → (axis label, scale from the trace's value to the axis unit, error key).
STUDY_QUANTITIES = {
    "LER": ("LER (% of LED power)", 100.0, "LER_std"),
    "YBR": ("YBR, yellow / blue ray power (1)", 1.0, "YBR_std"),
    "non_uniformity": ("irradiance non-uniformity (%)", 100.0, None),
}


#: Margins and gaps of the studies' grid [in] (tick labels at 10 pt, axis labels at 8 pt, titles at 9 pt)
STUDY_MARGINS_IN = Margins(left=0.75, right=0.1, bottom=0.5, top=0.3, wspace=0.8, hspace=0.75)


def trace_studies_figure(device, studies: dict[str, list[dict]], paper: dict | None = None) -> Figure:
    """LER, YBR and irradiance non-uniformity of the module studies, one quantity per row and one study per
    column (cf. Figs. 8-14 of the cylindrical-module paper).

    ``studies`` maps a study (keys of :data:`STUDY_AXES`) to rows with ``values``, ``LER``, ``LER_std``, ``YBR``,
    ``YBR_std`` and ``non_uniformity`` (fractions); LER and YBR carry ± 1σ error bars (the non-uniformity of a
    map has none). The grey dotted line is the traced device. ``paper`` maps (study, quantity) to a list of
    (x, y) values printed by the paper, in the axis units, drawn as open squares.

    Parameters
    ----------
    device : TraceResult
        The traced device (its LER, YBR, non_uniformity [-]).
    studies : dict of str to list of dict
        Study → rows, as above.
    paper : dict, optional
        (study, quantity) → printed (x, y) points.

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    panels = [k for k in STUDY_AXES if studies.get(k)]
    ncol = max(len(panels), 1)
    fig = Figure(figsize=(3.5 * ncol, 8.8))
    fixed_margins(fig, len(STUDY_QUANTITIES), ncol, STUDY_MARGINS_IN)
    axes = fig.subplots(len(STUDY_QUANTITIES), ncol, squeeze=False)
    for c, name in enumerate(panels):
        key, xlabel = STUDY_AXES[name]
        rows = sorted(studies[name], key=lambda r: r["values"][key])
        x = [r["values"][key] for r in rows]
        for r_i, (q, (label, scale, err)) in enumerate(STUDY_QUANTITIES.items()):
            ax = axes[r_i][c]
            y = [scale * r[q] for r in rows]
            yerr = [scale * r[err] for r in rows] if err else None
            ax.errorbar(x, y, yerr=yerr, marker="o", ms=4, capsize=3,
                        label="this run (± 1σ)" if err else "this run")
            dev = getattr(device, q, None)
            if dev is not None and np.isfinite(dev):
                ax.axhline(scale * dev, color="grey", ls=":", lw=0.9, label="traced device")
            pts = (paper or {}).get((name, q)) or []
            if pts:
                ax.plot([p[0] for p in pts], [p[1] for p in pts], "s", ms=8, mfc="none", mew=1.5, color="#c0392b",
                        label="[Cylindrical-module]")
            ax.set_ylabel(label, fontsize=8)
            ax.set_xlabel(xlabel, fontsize=8)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
            if r_i == 0:
                ax.set_title(STUDY_TITLES[name], fontsize=9)
    return fig


def plate_incidence_figure(histograms: dict[str, np.ndarray], measured_deg: tuple[float, float],
                           plate_grid_deg, plate_tis: dict[str, list[float]], measured_tis: dict | None = None,
                           title: str = "") -> Figure:
    """Where the plate is lit, and what it does there: why YBR moves with the cavity (cf. §5.3 of the
    cylindrical-module paper).

    Left: the blue power reaching the plate per degree of incidence (% of all blue power on the plate per deg),
    one curve per trace in ``histograms`` (label → (90/bins-degree) histogram of the blue power). Right: the
    plate's TIS (%) vs incidence for the blue channels, the tracer's grid (line; dashed where model-extrapolated)
    with the measured values ± 1σ (``measured_tis``: channel → (incidences, TIS, σ)). The measured range is
    shaded on both panels.

    Parameters
    ----------
    histograms : dict of str to ndarray
        Trace label → blue power on the plate per incidence bin over 0-90° (any scale).
    measured_deg : tuple of float
        (first, last) measured incidence [deg].
    plate_grid_deg : array_like
        Incidence grid of the tracer's plate [deg].
    plate_tis : dict of str to list of float
        Channel → TIS on that grid [-].
    measured_tis : dict, optional
        Channel → (incidences [deg], TIS [-], σ [-]).
    title : str
        Figure title.

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    fig = Figure(figsize=(13.5, 4.2))
    left, right = fig.subplots(1, 2)
    for label, hist in histograms.items():
        h = np.asarray(hist, dtype=float)
        width = 90.0 / h.size
        centres = (np.arange(h.size) + 0.5) * width
        left.plot(centres, 100.0 * h / h.sum() / width, lw=1.4, label=label)
    grid = np.asarray(plate_grid_deg, dtype=float)
    inside = (grid >= measured_deg[0]) & (grid <= measured_deg[1])
    names = {"bibs_transmission": "F bibs (blue out)", "bibs_reflection": "B bibs (blue back)",
             "biys_transmission": "F biys (converted out)", "biys_reflection": "B biys (converted back)"}
    for key, label in names.items():
        tis = 100.0 * np.asarray(plate_tis[key], dtype=float)
        line = right.plot(grid, tis, "--", lw=1.0)[0]
        lo, hi = np.flatnonzero(inside)[[0, -1]]
        right.plot(grid[lo:hi + 1], tis[lo:hi + 1], "-", lw=1.6, color=line.get_color(), label=f"{label}, plate")
        if measured_tis and key in measured_tis:
            th, val, std = (np.asarray(v, dtype=float) for v in measured_tis[key])
            right.errorbar(th, 100.0 * val, yerr=100.0 * std, fmt="o", ms=4, capsize=3, color=line.get_color(),
                           label=f"{label}, measured ± 1σ")
    right.plot([], [], "k--", lw=1.0, label="plate, model-extrapolated")
    for ax in (left, right):
        ax.axvspan(*measured_deg, color="0.85", alpha=0.5, lw=0, label="measured incidences")
        ax.set_xlabel("incidence on the plate θi (deg)")
        ax.set_xlim(0, 90)
        ax.grid(True, alpha=0.3)
    left.set_ylabel("blue power reaching the plate (% per deg)")
    left.set_title("where the blue light meets the plate (all passes)", fontsize=9)
    left.legend(fontsize=7)
    right.set_ylabel("TIS of the plate (% of incident power)")
    right.set_title("the plate's TIS for blue light vs incidence", fontsize=9)
    right.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))  # outside: no curve hidden
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


#: Margins and gaps of the fits' grid [in]: log tick labels as wide as '8.8×10⁻²' at 10 pt, titles at 9 pt
FITS_MARGINS_IN = Margins(left=1.0, right=0.15, bottom=0.55, top=0.3, wspace=1.0, hspace=0.9)


def bsdf_fits_figure(fits: dict) -> Figure:
    """In-plane data vs fitted model for each interaction and side (one curve per incidence).

    Parameters
    ----------
    fits : dict
        (interaction, side) → (fit dataset, profile dataset with ``bsdf`` [1/sr]).

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """

    keys = [k for k in (("bibs", "reflection"), ("bibs", "transmission"), ("yiys", "reflection"),
                        ("yiys", "transmission"), ("biys", "reflection"), ("biys", "transmission")) if k in fits]
    fig = Figure(figsize=(10, 3.2 * ((len(keys) + 1) // 2)))
    fixed_margins(fig, (len(keys) + 1) // 2, 2, FITS_MARGINS_IN)
    axes = fig.subplots((len(keys) + 1) // 2, 2, squeeze=False).ravel()
    for ax, key in zip(axes, keys):
        fit, prof = fits[key]
        model = fit.attrs.get("model", "lambert+gaussian")
        for th in fit["theta_i"].values:
            sel = (np.isclose(prof["theta_i"].values, th)) & (prof["arc"].values == "in_plane")
            sub = prof.isel(record=np.flatnonzero(sel))
            x = signed_in_plane_theta(sub)
            order = np.argsort(x)
            err = sub["bsdf_std"].values[order] if "bsdf_std" in sub else None
            line = ax.errorbar(x[order], sub["bsdf"].values[order], yerr=err, fmt=".", ms=4, capsize=0, lw=0.8,
                               label=f"data, θi = {th:g}° (± 1σ)")[0]
            grid = np.linspace(-88, 88, 353)
            params = {p: float(fit[p].sel(theta_i=th)) for p in ("rho", "A", "sigma", "B", "g") if p in fit}
            y = _model_curve(model, params, th, np.abs(grid), np.where(grid >= 0, 0.0, 180.0))
            ax.plot(grid, y, "-", color=line.get_color(), lw=1, label=f"{model} model, θi = {th:g}°")
        log_y(ax)
        ax.set_title(f"{key[0]} {key[1]} ({model}, aperture-averaged fit)", fontsize=9)
        ax.set_xlabel("in-plane θs (deg, + = specular side)")
        ax.set_ylabel("BSDF (1/sr)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, ncol=2)
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    return fig


def module_spectrum_figure(wavelength_nm, s_blue, s_yellow, emission: dict, sd) -> Figure:
    """Fig. 7 of the cylindrical-module paper: normalised blue and yellow spectra (left) and the
    reconstructed absolute spectral flux of the module (right).

    Parameters
    ----------
    wavelength_nm : ndarray
        Wavelength grid of the two spectra [nm].
    s_blue, s_yellow : ndarray
        Normalised blue and yellow spectra [-] (peak 1).
    emission : dict
        Measured converted light: ``wavelength`` [nm] and ``measured`` (relative).
    sd : colour.SpectralDistribution
        Reconstructed module spectrum [W/nm].

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    fig = Figure(figsize=(10, 3.8))
    left, right = fig.subplots(1, 2)
    left.plot(wavelength_nm, s_blue, label="S_blue (LED, Gaussian)")
    left.plot(wavelength_nm, s_yellow, label="S_yellow (fitted split Gaussian)")
    conv = np.asarray(emission["wavelength"]) >= 470.0  # below: the elastic blue band of the same spectrum
    left.plot(np.asarray(emission["wavelength"])[conv], np.asarray(emission["measured"])[conv], ":", lw=1.5,
              label="measured converted light (hemisphere)")
    left.set_xlabel("wavelength (nm)")
    left.set_ylabel("relative spectral power (1, peak = 1)")
    left.legend(fontsize=8)
    left.grid(True, alpha=0.3)
    right.plot(sd.wavelengths, 1e3 * sd.values, label="rebuilt module spectrum (two-band model)")
    right.legend(fontsize=8)
    right.set_xlabel("wavelength (nm)")
    right.set_ylabel("spectral flux (mW/nm)")
    right.set_title(sd.name, fontsize=9)
    right.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def sweep_figure(ds: xr.Dataset) -> Figure:
    """LER, YBR and non-uniformity vs the first parameter (one line per combination of the others).

    Parameters
    ----------
    ds : xarray.Dataset
        Sweep dataset (:func:`bsdfkit.raytrace.sweep.sweep_dataset`).

    Returns
    -------
    Figure
        The figure (not attached to pyplot).
    """
    dims = [d for d in ds["LER"].dims]
    panels = [("LER", "std_err_LER"), ("YBR", "std_err_YBR")]
    if np.any(np.isfinite(ds["non_uniformity"].values)):
        panels.append(("non_uniformity", None))
    fig = Figure(figsize=(4.2 * len(panels), 3.6))
    axes = fig.subplots(1, len(panels), squeeze=False)
    x_dim = dims[0] if dims else None
    others = dims[1:]
    combos = list(itertools.product(*[range(ds.sizes[d]) for d in others])) or [()]
    for ax, (var, err) in zip(axes[0], panels):
        for combo in combos:
            sel = dict(zip(others, combo))
            y = ds[var].isel(sel)
            label = ", ".join(f"{d}={ds[d].values[i]}" for d, i in sel.items()) or None
            if x_dim is None:
                ax.errorbar([0], [float(y)], yerr=None if err is None else [float(ds[err].isel(sel))], fmt="o")
                continue
            xv = ds[x_dim].values
            ax.errorbar(xv, y.values, yerr=None if err is None else ds[err].isel(sel).values, marker="o",
                        capsize=2, label=label)
        ax.set_xlabel(x_dim or "")
        ax.set_ylabel(var)
        ax.grid(True, alpha=0.3)
        if len(combos) > 1:
            ax.legend(fontsize=7)
    fig.suptitle(f"bsdfkit sweep ({ds.attrs.get('rays')} rays per point)", fontsize=9)
    fig.tight_layout()
    FigureCanvasAgg(fig)
    return fig
