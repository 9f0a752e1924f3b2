"""Figures for run reports. Uses matplotlib's object API (no pyplot, so no global backend state)."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bsdfkit.core.records import incidences, select, signed_in_plane_theta
from bsdfkit.fit.least_squares import bsdf_model_values
from bsdfkit.io.atomic import write_with


def save_figure(fig: Figure, path: str | Path, force: bool = False) -> Path:
    """Render ``fig`` to PNG atomically."""
    FigureCanvasAgg(fig)
    return write_with(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120), force)


def in_plane_bsdf_figure(ds: xr.Dataset, config: str = "blue", wavelength_nm: float = 460.0) -> Figure:
    """BSDF at one wavelength in the plane of incidence, reflection (R) and transmission (T), per incidence.

    The analogue of Fig. 6 of the power-budget paper (log scale; + angles on the specular side).
    """
    fig = Figure(figsize=(9, 4))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, side, tag in ((axes[0], "reflection", "R"), (axes[1], "transmission", "T")):
        for th in incidences(ds):
            sub = select(ds, config=config, theta_i=th, side=side, arc="in_plane")
            x = signed_in_plane_theta(sub)
            order = np.argsort(x)
            y = sub["bsdf"].sel(wavelength=wavelength_nm, method="nearest").values[order]
            e = sub["bsdf_std"].sel(wavelength=wavelength_nm, method="nearest").values[order]
            keep = np.isfinite(y) & (y > 0)
            ax.errorbar(x[order][keep], y[keep], yerr=e[keep], marker=".", ms=3, lw=1, capsize=0,
                        label=f"{tag}, θi = {th:g}°")
        ax.set_yscale("log")
        ax.set_xlabel("in-plane θs (deg, + = specular side)")
        ax.set_title(f"{side} at {wavelength_nm:g} nm ({config})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("BSDF (1/sr)")
    fig.suptitle(ds.attrs.get("sample_name", ""), fontsize=10)
    fig.tight_layout()
    return fig


def budget_figure(power, photons=None) -> Figure:
    """Cumulative extracted power and losses per plate interaction (Fig. 10 of the power-budget paper)."""
    fig = Figure(figsize=(6.5, 4))
    ax = fig.subplots()
    k = np.arange(1, len(power.iterations) + 1)
    for key, style in (("total", "-o"), ("yellow", "-s"), ("blue", "-^"), ("losses", "--x")):
        ax.plot(k, [row[key] for row in power.iterations], style, label=f"{key} (power)")
    if photons is not None:
        ax.plot(k, [row["total"] for row in photons.iterations], ":o", label="total (photons)")
    ax.axhline(power.converged["total"], color="grey", lw=0.8, ls=":")
    ax.set_xlabel("plate interaction (1 = direct pass from the LEDs)")
    ax.set_ylabel("cumulative % of LED output")
    ax.set_title(f"iterative module budget, η_MC = {power.eta_mc:g}")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def trace_studies_figure(device, studies: dict[str, list[dict]]) -> Figure:
    """LER, YBR and non-uniformity of the module studies (cf. Figs. 8, 11, 13 of the cylindrical-module paper)."""
    panels = [k for k in ("reflectance", "height_mm", "led_fwhm_deg", "specular_fraction") if studies.get(k)]
    fig = Figure(figsize=(3.2 * max(len(panels), 1), 6))
    axes = fig.subplots(2, max(len(panels), 1), squeeze=False)
    keys = {"reflectance": "wall.reflectance", "height_mm": "cavity.height_mm", "led_fwhm_deg": "leds.fwhm_deg",
            "specular_fraction": "wall.specular_fraction"}
    for c, name in enumerate(panels):
        rows = sorted(studies[name], key=lambda r: r["values"][keys[name]])
        x = [r["values"][keys[name]] for r in rows]
        ax = axes[0][c]
        ax.errorbar(x, [r["LER"] for r in rows], yerr=[r["LER_std"] for r in rows], marker="o", label="LER")
        ax.axhline(device.LER, color="grey", ls=":", lw=0.8, label="test device")
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("LER")
        ax.grid(True, alpha=0.3)
        ax2 = axes[1][c]
        ax2.plot(x, [r["YBR"] for r in rows], "s-", label="YBR")
        ax2.plot(x, [10 * r["non_uniformity"] for r in rows], "^--", label="10 × non-uniformity")
        ax2.set_xlabel(keys[name])
        ax2.grid(True, alpha=0.3)
        ax2.legend(fontsize=7)
    fig.tight_layout()
    return fig


def bsdf_fits_figure(fits: dict) -> Figure:
    """In-plane data vs fitted model for each interaction and side (one curve per incidence)."""

    keys = [k for k in (("bibs", "reflection"), ("bibs", "transmission"), ("yiys", "reflection"),
                        ("yiys", "transmission"), ("biys", "reflection"), ("biys", "transmission")) if k in fits]
    fig = Figure(figsize=(10, 3.2 * ((len(keys) + 1) // 2)))
    axes = fig.subplots((len(keys) + 1) // 2, 2, squeeze=False).ravel()
    for ax, key in zip(axes, keys):
        fit, prof = fits[key]
        model = fit.attrs.get("model", "lambert+gaussian")
        for th in fit["theta_i"].values:
            sel = (np.isclose(prof["theta_i"].values, th)) & (prof["arc"].values == "in_plane")
            sub = prof.isel(record=np.flatnonzero(sel))
            x = signed_in_plane_theta(sub)
            order = np.argsort(x)
            line = ax.plot(x[order], sub["bsdf"].values[order], ".", ms=4, label=f"θi = {th:g}° data")[0]
            grid = np.linspace(-88, 88, 353)
            params = {p: float(fit[p].sel(theta_i=th)) for p in ("rho", "A", "sigma", "B", "g") if p in fit}
            y = bsdf_model_values(model, params, th, np.abs(grid), np.where(grid >= 0, 0.0, 180.0))
            ax.plot(grid, y, "-", color=line.get_color(), lw=1)
        ax.set_yscale("log")
        ax.set_title(f"{key[0]} {key[1]} ({model}, aperture-averaged fit)", fontsize=9)
        ax.set_xlabel("in-plane θs (deg)")
        ax.set_ylabel("BSDF (1/sr)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig


def module_spectrum_figure(wavelength, s_blue, s_yellow, emission: dict, sd) -> Figure:
    """Fig. 7 of the cylindrical-module paper: normalised blue and yellow spectra (left) and the
    reconstructed absolute spectral flux of the module (right)."""
    fig = Figure(figsize=(10, 3.8))
    left, right = fig.subplots(1, 2)
    left.plot(wavelength, s_blue, label="S_blue (LED, Gaussian)")
    left.plot(wavelength, s_yellow, label="S_yellow (fitted split Gaussian)")
    conv = np.asarray(emission["wavelength"]) >= 470.0  # below: the elastic blue band of the same spectrum
    left.plot(np.asarray(emission["wavelength"])[conv], np.asarray(emission["measured"])[conv], ":", lw=1.5,
              label="measured converted light (hemisphere)")
    left.set_xlabel("wavelength (nm)")
    left.set_ylabel("normalised")
    left.legend(fontsize=8)
    left.grid(True, alpha=0.3)
    right.plot(sd.wavelengths, 1e3 * sd.values)
    right.set_xlabel("wavelength (nm)")
    right.set_ylabel("spectral flux (mW/nm)")
    right.set_title(sd.name, fontsize=9)
    right.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def sweep_figure(ds: xr.Dataset) -> Figure:
    """LER, YBR and non-uniformity vs the first parameter (one line per combination of the others)."""
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
