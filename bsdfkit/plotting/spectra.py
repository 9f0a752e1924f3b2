"""Module spectra of the tracer's two modes side by side (issue 17, the main job's spectral comparison)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure


def mode_spectra_figure(wavelength_nm, spectral, spectral_std, two_wavelength, two_wavelength_std,
                        bands: Mapping[str, tuple[float, float]] | None = None) -> Figure:
    """Both module spectra (top, mW/nm, ±1σ bands) and their difference two-wavelength − spectral (bottom).

    ``bands`` (label → (start, stop) nm) are shaded in both panels.

    Parameters
    ----------
    wavelength_nm : array_like, shape (n,)
        Wavelength [nm].
    spectral : array_like, shape (n,)
        Extracted spectral power of the spectral mode [W/nm].
    spectral_std : array_like, shape (n,)
        Its standard uncertainty [W/nm].
    two_wavelength : array_like, shape (n,)
        Extracted spectral power of the two-wavelength mode [W/nm].
    two_wavelength_std : array_like, shape (n,)
        Its standard uncertainty [W/nm].
    bands : Mapping of str to tuple of float, optional
        Label → (start, stop) wavelength of a shaded band [nm].

    Returns
    -------
    matplotlib.figure.Figure
    """
    lam = np.asarray(wavelength_nm, dtype=float)
    s, ss = 1e3 * np.asarray(spectral), 1e3 * np.asarray(spectral_std)
    t, ts = 1e3 * np.asarray(two_wavelength), 1e3 * np.asarray(two_wavelength_std)
    d, ds = t - s, np.hypot(ts, ss)
    fig = Figure(figsize=(8.0, 6.0))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    top.plot(lam, t, color="tab:orange", lw=1.2, label="two-wavelength mode (blue × LED shape + yellow × emission "
                                                       "shape, §4.2 of the cylindrical-module paper)")
    top.fill_between(lam, t - ts, t + ts, color="tab:orange", alpha=0.3, lw=0)
    top.plot(lam, s, color="tab:blue", lw=1.0, label="spectral mode (traced per wavelength, re-absorption)")
    top.fill_between(lam, s - ss, s + ss, color="tab:blue", alpha=0.3, lw=0)
    top.set_ylabel("extracted spectral power (mW/nm)")
    bottom.plot(lam, d, color="k", lw=1.0, label="two-wavelength − spectral")
    bottom.fill_between(lam, d - ds, d + ds, color="0.5", alpha=0.4, lw=0, label="±1σ")
    bottom.axhline(0.0, color="0.3", lw=0.6)
    bottom.set_ylabel("difference (mW/nm)")
    bottom.set_xlabel("wavelength (nm)")
    for k, (label, (lo, hi)) in enumerate((bands or {}).items()):
        for ax in (top, bottom):
            ax.axvspan(lo, hi, color=("tab:green", "tab:olive")[k % 2], alpha=0.08, lw=0,
                       label=f"{label} ({lo:g}-{hi:g} nm)" if ax is bottom else None)
    top.legend(fontsize=7, loc="upper right")
    bottom.legend(fontsize=7, loc="upper right")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig
