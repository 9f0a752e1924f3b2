"""Tallies: the kernel's exact fixed-point sums turned into powers and figures of merit.

The kernel (:mod:`bsdfkit.raytrace.kernel`) returns, per chunk, int64 limb sums of per-ray tallies rounded to
2⁻⁴⁰ ray weights (squares to 2⁻³²). :class:`FixedSum` adds chunks as Python ints, so totals are exact and
independent of chunking and order; values are converted to float once, at the end.

Figures of merit (definitions of §5.1 of the cylindrical-module paper):

* LER = extracted total / emitted;  YBR = extracted yellow / extracted blue.
* Standard errors from the per-ray sample variance: SE(x̄) = √((Σx² − (Σx)²/N) / (N(N − 1))); for the
  ratio YBR = ȳ/b̄ the delta method, Var ≈ (Var ȳ − 2 R Cov(ȳ, b̄) + R² Var b̄)/b̄².
* Irradiance non-uniformity = (E_max − E_min)/(E_max + E_min) over the map bins lying entirely inside the
  plate (all four corners within the radius), Fig. 10 / Fig. 12 of the cylindrical-module paper.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM, RAY_YBR_DEFINITION, band_label
from bsdfkit.core.spectra import LIGHT_C, PLANCK_H, band_mask
from bsdfkit.reduction.colorimetry import luminous_efficacy_of_radiation, spectral_distribution

#: The spectral mode's YBR: extracted power per band of the traced spectrum.
SPECTRAL_YBR_DEFINITION = (f"extracted power in {band_label(MODULE_YELLOW_BAND_NM)} / extracted power in "
                           f"{band_label(MODULE_BLUE_BAND_NM)} (spectral mode; bins by their centre wavelength)")


class FixedSum:
    """Exact running sum of fixed-point values given as int64 limb sums (hi·2^limb + lo) at a scale."""

    def __init__(self, scale: float, limb: int) -> None:
        self._scale = int(scale)
        self._limb = limb
        self._total = 0

    def add(self, hi: int, lo: int) -> None:
        """Add one limb pair: hi·2^limb + lo, in units of 1/scale.

        Parameters
        ----------
        hi, lo : int
            High and low limbs of a fixed-point sum.
        """
        self._total += (int(hi) << self._limb) + int(lo)

    @property
    def fraction(self) -> Fraction:
        return Fraction(self._total, self._scale)

    def __float__(self) -> float:
        return float(self.fraction)


def mean_and_se(s1: Fraction, s2: Fraction, n: int) -> tuple[float, float]:
    """Mean and its standard error from Σx and Σx² over n samples.

    Parameters
    ----------
    s1 : Fraction
        Σx.
    s2 : Fraction
        Σx².
    n : int
        Number of samples.

    Returns
    -------
    mean, se : float
        Mean and its standard error (NaN for n < 2), in the unit of x.
    """
    mean = s1 / n
    if n < 2:
        return float(mean), float("nan")
    var = (s2 - s1 * s1 / n) / (n - 1)
    return float(mean), math.sqrt(max(float(var), 0.0) / n)


def ratio_and_se(sy: Fraction, sb: Fraction, syy: Fraction, sbb: Fraction, syb: Fraction,
                 n: int) -> tuple[float, float]:
    """R = Σy/Σb and its delta-method standard error.

    Parameters
    ----------
    sy, sb : Fraction
        Σy and Σb.
    syy, sbb, syb : Fraction
        Σy², Σb² and Σyb.
    n : int
        Number of samples.

    Returns
    -------
    ratio, se : float
        R [-] and its standard error [-] (NaN when Σb = 0; se NaN for n < 2).
    """
    if sb == 0:
        return float("nan"), float("nan")
    r = sy / sb
    if n < 2:
        return float(r), float("nan")
    b = sb / n
    vy = (syy - sy * sy / n) / (n - 1)
    vb = (sbb - sb * sb / n) / (n - 1)
    cyb = (syb - sy * sb / n) / (n - 1)
    var = (vy - 2 * r * cyb + r * r * vb) / (b * b) / n
    return float(r), math.sqrt(max(float(var), 0.0))


def interior_bins(bins: int) -> np.ndarray:
    """Boolean (bins, bins) mask of the square bins of [−1, 1]² lying entirely inside the unit disk.

    Parameters
    ----------
    bins : int
        Bins per side.

    Returns
    -------
    ndarray
        Boolean mask, shape (bins, bins).
    """
    edges = np.linspace(-1.0, 1.0, bins + 1)
    far = np.maximum(np.abs(edges[:-1]), np.abs(edges[1:]))  # farthest |coordinate| within each bin row/col
    return far[:, None] ** 2 + far[None, :] ** 2 <= 1.0 + 1e-12


def non_uniformity(irradiance: np.ndarray) -> float:
    """(E_max − E_min)/(E_max + E_min) over bins entirely inside the plate (see module docstring).

    Parameters
    ----------
    irradiance : ndarray
        Square (n, n) irradiance map over [−R, R]² [W/mm²].

    Returns
    -------
    float
        Non-uniformity [-] (NaN for a dark map).
    """
    inside = irradiance[interior_bins(irradiance.shape[0])]
    hi, lo = float(np.max(inside)), float(np.min(inside))
    return (hi - lo) / (hi + lo) if hi + lo > 0 else float("nan")


def rebin_map(irradiance: np.ndarray, bins: int) -> np.ndarray:
    """A square irradiance map [W/mm²] on ``bins`` cells per side: the mean of blocks of the finer cells.

    Exact for the tallied power (a coarse cell is a block of fine ones); ``bins`` must divide the map's side.

    Parameters
    ----------
    irradiance : ndarray
        Maps (..., n, n) [W/mm²].
    bins : int
        Cells per side of the result; must divide n.

    Returns
    -------
    ndarray
        Maps (..., bins, bins) [W/mm²].
    """
    side = irradiance.shape[-1]
    if side % bins:
        raise ValueError(f"{bins} cells per side do not divide a {side}-cell map")
    k = side // bins
    shape = irradiance.shape[:-2] + (bins, k, bins, k)
    return irradiance.reshape(shape).mean(axis=(-3, -1))


def non_uniformity_std(irradiance: np.ndarray, draws: int = 200, seed: int = 0) -> float:
    """σ [1] of :func:`non_uniformity` of one Monte Carlo map, from the map alone (no second trace).

    The relative noise of a cell is estimated from the residual against the mean of its four neighbours
    (s = std(residual / E) / √1.25, cells whose neighbours all lie inside the plate); the map is redrawn ``draws``
    times with that relative Gaussian noise (generator ``seed``: reproducible) and the σ of the redrawn
    non-uniformities is returned. Structure on the scale of a cell (hot spots of mirror walls) counts as noise, so
    the estimate is conservative there; docs/tracer.md compares it with the spread over independent seeds.

    Parameters
    ----------
    irradiance : ndarray
        Square (n, n) irradiance map over [−R, R]² [W/mm²].
    draws : int
        Number of redrawn maps.
    seed : int
        Seed of the generator.

    Returns
    -------
    float
        σ of the non-uniformity [-] (NaN when too few cells qualify).
    """
    e = np.asarray(irradiance, dtype=np.float64)
    inside = interior_bins(e.shape[0])
    ok = inside.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            ok &= np.roll(inside, shift, axis)
    neighbours = sum(np.roll(e, shift, axis) for axis in (0, 1) for shift in (1, -1)) / 4.0
    ok &= e > 0
    if ok.sum() < 2:
        return float("nan")
    rel = float(np.std((e[ok] - neighbours[ok]) / e[ok]) / np.sqrt(1.25))
    rng = np.random.default_rng(seed)
    values = [non_uniformity(e * (1.0 + rel * rng.standard_normal(e.shape))) for _ in range(draws)]
    return float(np.std(values, ddof=1))


def split_half_non_uniformity(first: np.ndarray, second: np.ndarray) -> float:
    """(E_max − E_min)/(E_max + E_min) without the Monte Carlo noise maximum: two independent maps [W/mm²].

    The cells of the largest and smallest irradiance are chosen on one map and their irradiance is read on the
    other (and the other way round; the two estimates are averaged). A noisy cell that is extreme on one map is
    an ordinary cell on the other, so E_max is not raised (nor E_min lowered) by the noise of the selection.

    Parameters
    ----------
    first, second : ndarray
        Two independent (n, n) irradiance maps of the same scene [W/mm²].

    Returns
    -------
    float
        Non-uniformity [-] (NaN for dark maps).
    """
    inside = interior_bins(first.shape[0])
    a, b = first[inside], second[inside]
    hi = 0.5 * (b[np.argmax(a)] + a[np.argmax(b)])
    lo = 0.5 * (b[np.argmin(a)] + a[np.argmin(b)])
    return float((hi - lo) / (hi + lo)) if hi + lo > 0 else float("nan")


def symmetrise_square(maps: np.ndarray) -> np.ndarray:
    """The mean of a square map's eight images under the square's symmetries (rotations by 90°, mirrors) [W/mm²].

    For a scene that the symmetry group of the square maps onto itself (LEDs on a k × k grid centred on the
    cavity's axis, isotropic surfaces; :func:`bsdfkit.raytrace.scene.map_symmetry`), the eight images of a
    Monte Carlo map are equally likely maps of the same field, so their mean estimates the field with up to 8×
    fewer variance (cells on a mirror line have 4 distinct images, the central cells 1 or 4). Works on the last
    two axes, which must be square and centred on the axis.

    Parameters
    ----------
    maps : ndarray
        Maps (..., n, n) [W/mm²].

    Returns
    -------
    ndarray
        Symmetrised maps, same shape [W/mm²].
    """
    m = np.asarray(maps, dtype=np.float64)
    images = [np.rot90(m, k, axes=(-2, -1)) for k in range(4)]
    return np.mean(images + [im[..., ::-1] for im in images], axis=0)


def _split_half_on_grid(parts: np.ndarray, bins: int, symmetric: bool) -> tuple[float, np.ndarray]:
    """Split-half non-uniformity [1] on ``bins`` cells per side (even vs odd parts) and the per-pair estimates."""
    m = rebin_map(parts, bins)
    if symmetric:
        m = symmetrise_square(m)
    pairs = np.array([split_half_non_uniformity(m[i], m[i + 1]) for i in range(0, m.shape[0] - 1, 2)])
    return split_half_non_uniformity(m[0::2].sum(axis=0), m[1::2].sum(axis=0)), pairs


def converged_non_uniformity(parts: np.ndarray, symmetric: bool = False, coarsest: int = 8) -> dict[str, Any]:
    """Non-uniformity [1] by the paper's definition, converged in the map grid, from one trace's sub-maps.

    Parameters
    ----------
    parts : ndarray, shape (P, n, n)
        Irradiance maps [W/mm²] of interleaved rays (P even, the tracer's ``MAP_PARTS``; their sum is the map).
    symmetric : bool
        The scene is invariant under the square's symmetries (:func:`bsdfkit.raytrace.scene.map_symmetry`):
        every part is replaced by its :func:`symmetrise_square` mean first.
    coarsest : int
        Coarsest grid [cells per side] of the study (4 cells per side hold no cell inside the plate's circle).

    Returns
    -------
    dict
        ``value`` and ``std`` [1] on the chosen grid, ``bins`` (that grid), ``finer`` [1] (the next finer grid's
        value), ``change`` and ``change_std`` [1] (finer − chosen and its σ), ``converged`` and ``grids``
        ({cells: {value, std, change, change_std}}).

    Notes
    -----
    On every grid of n, n/2, n/4, … cells per side (down to ``coarsest``) the value is the split-half estimate
    (:func:`split_half_non_uniformity` of the even and odd parts' sums: the max − min of the noise is not
    selected), its σ the spread of the P/2 pair estimates (parts 0-1, 2-3, …) divided by √(P/2), and the change
    to the next finer grid has its σ from the spread of the pairs' own changes (the two grids share their rays, so
    the change is far less noisy than either value). A finer grid measures smaller cells with fewer rays each: its
    value is about twice as noisy, so a change judged against the coarser value's σ alone would fail at random even
    between two grids that agree. Rule: from the coarsest grid up, the chosen grid is the first whose value changes
    by less than the change's σ on the next finer grid; when none does, the finest grid that can still be checked
    is reported with ``converged`` False.
    """
    p = np.asarray(parts, dtype=np.float64)
    n = p.shape[-1]
    grids = [g for g in (n >> k for k in range(12)) if g >= coarsest and g >= 1 and n % g == 0][::-1]
    est = {g: _split_half_on_grid(p, g, symmetric) for g in grids}
    table: dict[int, dict[str, float]] = {}
    for g in grids:
        value, pairs = est[g]
        row = {"value": value, "std": _std_of_mean(pairs)}
        if 2 * g in est:
            row["change"] = est[2 * g][0] - value
            row["change_std"] = _std_of_mean(est[2 * g][1] - pairs)
        table[g] = row
    checked = [g for g in grids if "change" in table[g]]
    chosen = next((g for g in checked if abs(table[g]["change"]) < table[g]["change_std"]), None)
    converged = chosen is not None
    if chosen is None:
        chosen = checked[-1] if checked else grids[-1]
    row = table[chosen]
    return {"value": row["value"], "std": row["std"], "bins": int(chosen),
            "finer": est[2 * chosen][0] if 2 * chosen in est else float("nan"),
            "change": row.get("change", float("nan")), "change_std": row.get("change_std", float("nan")),
            "converged": converged, "symmetric": bool(symmetric), "grids": {int(g): v for g, v in table.items()}}


def _std_of_mean(samples: np.ndarray) -> float:
    """σ of the mean of independent estimates (NaN for fewer than two)."""
    return float(np.std(samples, ddof=1) / np.sqrt(samples.size)) if samples.size > 1 else float("nan")


def map_fields(parts: np.ndarray, symmetric: bool) -> dict[str, Any]:
    """The map fields of a :class:`TraceResult` from its sub-maps [W/mm²] (the tracer's, or merged ones).

    ``irradiance`` (their sum), ``irradiance_parts``, ``non_uniformity`` (the converged value of
    :func:`converged_non_uniformity`, whose dict is ``non_uniformity_converged``) and ``non_uniformity_map`` (the
    whole map's :func:`non_uniformity`).

    Parameters
    ----------
    parts : ndarray
        (P, n, n) sub-maps of interleaved rays [W/mm²].
    symmetric : bool
        The scene is invariant under the square's symmetries.

    Returns
    -------
    dict
        The fields named above.
    """
    irradiance = parts.sum(axis=0)
    conv = converged_non_uniformity(parts, symmetric=symmetric)
    return {"irradiance": irradiance, "irradiance_parts": parts, "non_uniformity": conv["value"],
            "non_uniformity_map": non_uniformity(irradiance), "non_uniformity_converged": conv}


def merge_maps(parts: np.ndarray, rays: int, more_parts: np.ndarray, more_rays: int) -> np.ndarray:
    """Sub-maps [W/mm²] of two independent traces of one scene, as the sub-maps of all their rays.

    Each trace's maps are power per ray times its own ray count, so the merged part k is the ray-weighted mean
    (rays·A_k + more_rays·B_k)/(rays + more_rays): its sum is the map of all rays, and the parts stay independent.

    Parameters
    ----------
    parts : ndarray
        (P, n, n) sub-maps of the first trace [W/mm²].
    rays : int
        Rays of the first trace.
    more_parts : ndarray
        Sub-maps of the second trace, same shape [W/mm²].
    more_rays : int
        Rays of the second trace.

    Returns
    -------
    ndarray
        Merged sub-maps [W/mm²].
    """
    a, b = np.asarray(parts, dtype=np.float64), np.asarray(more_parts, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"sub-maps of different shapes cannot be merged: {a.shape} and {b.shape}")
    return (rays * a + more_rays * b) / (rays + more_rays)


def grid_study(maps: np.ndarray, grids: tuple[int, ...]) -> dict[str, dict[str, float]]:
    """Non-uniformity of independent traces' maps on several grids (cells per side), with its σ.

    ``maps`` [W/mm²]: (seeds, n, n) irradiance maps of one scene traced with independent seeds (at least 2),
    ``n`` divisible by every grid. Per grid: ``mean`` and ``std`` [1] of the non-uniformity over the seeds (σ of
    one trace's value), ``pooled`` [1] (the map of all seeds summed), ``split_half`` [1]
    (:func:`split_half_non_uniformity` of the even and odd seeds' mean maps) and ``split_half_std`` [1] (its σ
    from the spread of the per-pair estimates, seeds paired 0-1, 2-3, …, divided by √pairs).

    Parameters
    ----------
    maps : ndarray
        (seeds, n, n) irradiance maps [W/mm²].
    grids : tuple of int
        Cells per side of each grid studied.

    Returns
    -------
    dict
        Grid (as a string) → the statistics above.
    """
    maps = np.asarray(maps, dtype=np.float64)
    if maps.ndim != 3 or maps.shape[0] < 2:
        raise ValueError("grid_study needs (seeds >= 2, n, n) maps")
    out: dict[str, dict[str, float]] = {}
    for bins in grids:
        m = rebin_map(maps, bins)
        per_seed = np.array([non_uniformity(x) for x in m])
        pairs = np.array([split_half_non_uniformity(m[i], m[i + 1]) for i in range(0, m.shape[0] - 1, 2)])
        out[str(bins)] = {
            "mean": float(per_seed.mean()), "std": float(per_seed.std(ddof=1)),
            "pooled": non_uniformity(m.mean(axis=0)),
            "split_half": split_half_non_uniformity(m[0::2].mean(axis=0), m[1::2].mean(axis=0)),
            "split_half_std": float(pairs.std(ddof=1) / np.sqrt(pairs.size)) if pairs.size > 1 else float("nan")}
    return out


POWER_LINES = ("extracted", "absorbed_wall", "absorbed_base", "absorbed_leds", "absorbed_plate", "stokes",
               "roulette", "discarded", "truncated")


def spectral_ledger(col: dict[str, Fraction], emitted_bins, photon_scale: np.ndarray, lam_nm: np.ndarray, n: int,
                    power_W: float) -> dict[str, dict[str, float]]:
    """The spectral mode's ledger in power [W] and in photons [1/s], each with its relative closing error.

    Power: emitted = extracted + absorbed (wall, base, LEDs, plate) + Stokes loss + roulette balance + threshold
    discarded + truncated. Photons: the same lines without the Stokes loss (a conversion keeps the photon, the
    plate's absorption line holds the photons it does not re-emit). Photon tallies are in units of photons of a
    unit-weight ray at the longest bin λ_max: N [1/s] = tally · (P/N_rays) · λ_max / (hc).

    ``conversions`` (outside both ledgers): photons converted at the plate [1/s], those converted to a shorter
    wavelength bin than they were absorbed at (anti-Stokes, the thermal tail of the emission table), their share
    [1], and the power those anti-Stokes conversions created [W] (the Stokes line is net of it); absent with
    an exit top.

    Parameters
    ----------
    col : dict of str to Fraction
        Kernel column → sum over rays, in unit-weight rays (photon columns in photons of a ray at λ_max).
    emitted_bins : sequence of int
        Rays emitted per bin.
    photon_scale : ndarray
        λ_k / λ_max per bin [-].
    lam_nm : ndarray
        Bin centres [nm].
    n : int
        Rays traced.
    power_W : float
        Emitted LED power [W].

    Returns
    -------
    dict
        ``power_W`` and ``photons_per_s`` (line → value, plus ``error`` [-]) and, with conversion, ``conversions``.
    """
    scale = power_W / n
    to_photons = scale * float(lam_nm[-1]) * 1e-9 / (PLANCK_H * LIGHT_C)
    ext = col["extracted_blue"] + col["extracted_yellow"] + col["extracted_other"]
    p_lines = {"extracted": ext, **{k: col[k] for k in ("absorbed_wall", "absorbed_base", "absorbed_leds",
                                                       "absorbed_plate", "stokes", "roulette", "discarded",
                                                       "truncated")}}
    ph_emitted = sum(Fraction(int(c)) * Fraction(float(f)) for c, f in zip(emitted_bins, photon_scale))
    ph_lines = {"extracted": col["photons_extracted"], "absorbed_wall": col["photons_wall"],
                "absorbed_base": col["photons_base"], "absorbed_leds": col["photons_leds"],
                "absorbed_plate": col["photons_plate"], "roulette": col["photons_roulette"],
                "discarded": col["photons_discarded"], "truncated": col["photons_truncated"]}
    power = {"emitted": power_W, **{k: float(v) * scale for k, v in p_lines.items()},
             "error": float(abs(n - sum(p_lines.values())) / n)}
    photons = {"emitted": float(ph_emitted) * to_photons, **{k: float(v) * to_photons for k, v in ph_lines.items()},
               "error": float(abs(ph_emitted - sum(ph_lines.values())) / ph_emitted)}
    out = {"power_W": power, "photons_per_s": photons}
    if "photons_converted" in col and col["photons_converted"] > 0:
        conv, anti = col["photons_converted"], col["photons_anti_stokes"]
        out["conversions"] = {"photons_per_s": float(conv) * to_photons,
                              "anti_stokes_photons_per_s": float(anti) * to_photons,
                              "anti_stokes_share": float(anti / conv),
                              "anti_stokes_gain_W": float(col["anti_stokes_gain"]) * scale}
    return out


def _ranges(values, step: float) -> list[list[float]]:
    """Consecutive grid values as [first, last] ranges (e.g. the bins below and above an excitation grid)."""
    out: list[list[float]] = []
    for v in values:
        if out and abs(v - out[-1][1] - step) <= 1e-9 * step:
            out[-1][1] = v
        else:
            out.append([v, v])
    return out


@dataclass(frozen=True)
class SpectralResult:
    """The spectral mode's tallies: extracted spectrum on the bin grid with standard errors, the LED spectrum as
    sampled, and the ledger in power and photons (:func:`spectral_ledger`).

    ``spectrum_W_per_nm`` = extracted power per bin / bin width; its standard error from the per-ray variance
    (each ray is extracted in one bin at most). ``extrapolated_nm``: bins outside the plate model's excitation
    grid whose TIS and emission rows are the nearest excitation's; ``yiys_nm``: bins above it that take the
    two-wavelength plate's yiys TIS and do not convert. ``capped``: cells (incidence [deg],
    excitation [nm], photons out per photon in) of a measured model above one photon out per photon in within its
    uncertainty, scaled down to one (:data:`bsdfkit.raytrace.spectral.NOISE_SIGMA`).
    """

    wavelength_nm: np.ndarray
    spectrum_W_per_nm: np.ndarray
    spectrum_std_err: np.ndarray
    emitted_W_per_nm: np.ndarray
    ledger: dict[str, dict[str, float]]
    extrapolated_nm: tuple[float, ...] = ()
    capped: tuple[tuple[float, float, float], ...] = ()
    yiys_nm: tuple[float, ...] = ()

    @property
    def step_nm(self) -> float:
        return float(self.wavelength_nm[1] - self.wavelength_nm[0])

    def band_power(self, band_nm: tuple[float, float]) -> tuple[float, float]:
        """Extracted power [W] of the bins whose centres lie in ``band`` (inclusive) and its standard error (the
        bins' errors add in quadrature: a ray is extracted in one bin, so bins are nearly independent; the
        covariance −x̄_i x̄_j/N is neglected, conservative).

        Parameters
        ----------
        band_nm : tuple of float
            (low, high) band edges [nm].

        Returns
        -------
        power, se : float
            Band power and its standard error [W].
        """
        inside = band_mask(self.wavelength_nm, band_nm)
        p = float(self.spectrum_W_per_nm[inside].sum() * self.step_nm)
        return p, float(np.sqrt(np.sum(self.spectrum_std_err[inside] ** 2)) * self.step_nm)

    def luminous_efficacy_lm_per_W(self) -> float:
        """Luminous efficacy of radiation of the extracted spectrum [lm/W] (CIE 1924 V(λ), K_m = 683 lm/W).

        :func:`bsdfkit.reduction.colorimetry.luminous_efficacy_of_radiation` of the bins (which imports
        colour-science on first use, so that tracing does not pay its import time).
        """
        return luminous_efficacy_of_radiation(spectral_distribution(self.wavelength_nm, self.spectrum_W_per_nm,
                                                                    "extracted spectrum"))

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready values: spectra [W/nm] on the bins [nm], blue and yellow band powers [W], luminous
        efficacy [lm/W] (None for an empty spectrum), ledger and the extrapolated, yiys and capped bins.
        """
        blue, se_b = self.band_power(MODULE_BLUE_BAND_NM)
        yellow, se_y = self.band_power(MODULE_YELLOW_BAND_NM)
        return {
            "wavelength_nm": self.wavelength_nm.tolist(),
            "spectrum_W_per_nm": self.spectrum_W_per_nm.tolist(),
            "spectrum_std_err_W_per_nm": self.spectrum_std_err.tolist(),
            "emitted_W_per_nm": self.emitted_W_per_nm.tolist(),
            "bands": {"blue": {"band_nm": list(MODULE_BLUE_BAND_NM), "label": band_label(MODULE_BLUE_BAND_NM),
                               "power_W": blue, "std_err_W": se_b},
                      "yellow": {"band_nm": list(MODULE_YELLOW_BAND_NM), "label": band_label(MODULE_YELLOW_BAND_NM),
                                 "power_W": yellow, "std_err_W": se_y}},
            "YBR_definition": SPECTRAL_YBR_DEFINITION,
            "luminous_efficacy_lm_per_W": self.luminous_efficacy_lm_per_W() if self.spectrum_W_per_nm.any() else None,
            "ledger": self.ledger,
            "extrapolated_bins_nm": _ranges(self.extrapolated_nm, self.step_nm),
            "yiys_bins_nm": _ranges(self.yiys_nm, self.step_nm),
            "photon_capped_cells": [{"incidence_deg": i, "excitation_nm": x, "photons_out_per_in": v}
                                    for i, x, v in self.capped],
        }


@dataclass(frozen=True)
class TraceResult:
    """Everything one trace produced. Powers in W; arrays as NumPy.

    ``ledger`` holds emitted, extracted, absorbed (per surface), roulette balance, discarded (threshold)
    and truncated power; ``ledger_error`` = |emitted − Σ others| / emitted computed from the exact sums.
    ``budget`` (bins, 5) holds, per plate interaction k = 1 … bins (last bin: k ≥ bins), the power
    extracted blue / yellow, absorbed in the cavity before interaction k, absorbed by the plate at k, and
    roulette/threshold/truncation balance (Fig. 10 of the power-budget paper).
    """

    rays: int
    seed: int
    chunk: int
    lanes: int
    emitted: float
    extracted: dict[str, float]
    absorbed: dict[str, float]
    roulette: float
    discarded: float
    truncated: float
    ledger_error: float
    LER: float
    YBR: float
    std_err: dict[str, float]
    interactions: int
    plate_interactions: int
    clamped_interactions: int
    irradiance: np.ndarray | None = field(default=None, repr=False)
    #: irradiance non-uniformity [1] by the paper's definition, converged in the map grid (``value`` of
    #: ``non_uniformity_converged``); the whole map's noisy max − min is ``non_uniformity_map``
    non_uniformity: float | None = None
    #: :func:`converged_non_uniformity` of the trace's sub-maps (None without a map)
    non_uniformity_converged: dict | None = field(default=None, repr=False)
    #: (E_max − E_min)/(E_max + E_min) of the whole map [1] (:func:`non_uniformity`: raised by the cells' noise)
    non_uniformity_map: float | None = None
    #: the map as MAP_PARTS sub-maps of interleaved rays [W/mm²] (their sum is ``irradiance``)
    irradiance_parts: np.ndarray | None = field(default=None, repr=False)
    #: rays behind the map (more than ``rays`` when :func:`merge_maps` added other traces' rays)
    map_rays: int | None = None
    incidence_histogram: np.ndarray | None = field(default=None, repr=False)
    budget: np.ndarray | None = field(default=None, repr=False)
    radius_mm: float = 0.0
    elapsed_s: float = 0.0
    compile_s: float = 0.0
    effects: Any = None
    spectral: SpectralResult | None = None

    @property
    def rays_per_s(self) -> float:
        t = self.elapsed_s - self.compile_s
        return self.rays / t if t > 0 else float("nan")

    @property
    def interactions_per_s(self) -> float:
        t = self.elapsed_s - self.compile_s
        return self.interactions / t if t > 0 else float("nan")

    def cumulative_budget(self) -> dict[str, np.ndarray] | None:
        """Cumulative extracted power and losses after each plate interaction (Fig. 10, power-budget paper)."""
        if self.budget is None:
            return None
        b = self.budget
        ext = np.cumsum(b[:, 0] + b[:, 1])
        loss = np.cumsum(b[:, 2] + b[:, 3])
        return {"extracted_blue": np.cumsum(b[:, 0]), "extracted_yellow": np.cumsum(b[:, 1]), "extracted": ext,
                "losses": loss, "in_flight": self.emitted - ext - loss - np.cumsum(b[:, 4])}

    def to_dict(self) -> dict[str, Any]:
        """The JSON report of ``bsdfkit trace --json``."""
        out: dict[str, Any] = {
            "extracted": dict(self.extracted),
            "LER": self.LER,
            "YBR": self.YBR,
            "YBR_definition": RAY_YBR_DEFINITION,
            "absorbed": dict(self.absorbed),
            "ledger_error": self.ledger_error,
            "std_err": dict(self.std_err),
            "non_uniformity": self.non_uniformity,
            "non_uniformity_std": (self.non_uniformity_converged or {}).get("std"),
            "non_uniformity_bins": (self.non_uniformity_converged or {}).get("bins"),
            "non_uniformity_converged": (self.non_uniformity_converged or {}).get("converged"),
            "non_uniformity_map": self.non_uniformity_map,
            "rays": self.rays,
            "elapsed_s": self.elapsed_s,
            "rays_per_s": self.rays_per_s,
            "interactions_per_s": self.interactions_per_s,
            "emitted": self.emitted,
            "ledger": {"emitted": self.emitted, "extracted": self.extracted["total"],
                       "absorbed": sum(self.absorbed.values()), "roulette_balance": self.roulette,
                       "threshold_discarded": self.discarded, "truncated": self.truncated},
            "interactions": self.interactions,
            "plate_interactions": self.plate_interactions,
            "clamped_incidences": {"count": self.clamped_interactions,
                                   "fraction_of_plate_interactions":
                                       (self.clamped_interactions / self.plate_interactions
                                        if self.plate_interactions else 0.0)},
            "seed": self.seed,
            "chunk": self.chunk,
            "compile_s": self.compile_s,
        }
        cb = self.cumulative_budget()
        if cb is not None:
            out["cumulative_budget"] = {k: v.tolist() for k, v in cb.items()}
        if self.spectral is not None:
            out["mode"] = "spectral"
            out["YBR_definition"] = SPECTRAL_YBR_DEFINITION
            out["spectral"] = self.spectral.to_dict()
            out["ledger"]["stokes"] = self.spectral.ledger["power_W"]["stokes"]
        else:
            out["mode"] = "two-wavelength"
        return out

    def to_dataset(self):
        """The result as an ``xarray.Dataset`` (scalars, irradiance map, incidence histogram, budget)."""
        data: dict[str, Any] = {
            "LER": ((), self.LER, {"units": "1", "long_name": "light extraction ratio"}),
            "YBR": ((), self.YBR, {"units": "1", "long_name": "yellow-to-blue ratio",
                                   "definition": RAY_YBR_DEFINITION}),
            "ledger_error": ((), self.ledger_error, {"units": "1"}),
        }
        for k, v in self.extracted.items():
            data[f"extracted_{k}"] = ((), v, {"units": "W"})
        for k, v in self.absorbed.items():
            data[f"absorbed_{k}"] = ((), v, {"units": "W"})
        for k, v in self.std_err.items():
            data[f"std_err_{k}"] = ((), v, {"units": "1" if k in ("LER", "YBR") else "W"})
        coords: dict[str, Any] = {}
        if self.irradiance is not None:
            n = self.irradiance.shape[0]
            centres = (np.arange(n) + 0.5) / n * 2 * self.radius_mm - self.radius_mm
            coords["y_mm"] = ("y_mm", centres, {"units": "mm"})
            coords["x_mm"] = ("x_mm", centres, {"units": "mm"})
            data["irradiance"] = (("y_mm", "x_mm"), self.irradiance,
                                  {"units": "W/mm^2", "long_name": "irradiance on the cavity side of the top"})
            conv = self.non_uniformity_converged or {}
            data["non_uniformity"] = ((), self.non_uniformity, {
                "units": "1", "long_name": "irradiance non-uniformity, split-half on the grid it converged on "
                "(converged_non_uniformity)", "std": conv.get("std", np.nan), "bins": conv.get("bins", 0),
                "converged": int(conv.get("converged", False)), "change": conv.get("change", np.nan),
                "change_std": conv.get("change_std", np.nan), "symmetric": int(conv.get("symmetric", False)),
                "map_rays": int(self.map_rays or self.rays)})
            data["non_uniformity_map"] = ((), self.non_uniformity_map, {
                "units": "1", "long_name": "(E_max - E_min)/(E_max + E_min) of the whole map (noise included)"})
        if self.incidence_histogram is not None:
            hb = self.incidence_histogram.shape[1]
            coords["theta_i"] = ("theta_i", (np.arange(hb) + 0.5) * 90.0 / hb, {"units": "deg"})
            coords["colour"] = ("colour", ["blue", "yellow"])
            data["incident_power"] = (("colour", "theta_i"), self.incidence_histogram,
                                      {"units": "W", "long_name": "power reaching the top per incidence bin"})
        if self.budget is not None:
            coords["interaction"] = ("interaction", np.arange(1, self.budget.shape[0] + 1))
            coords["budget_term"] = ("budget_term", ["extracted_blue", "extracted_yellow", "absorbed_cavity",
                                                     "absorbed_plate", "other"])
            data["budget"] = (("interaction", "budget_term"), self.budget, {"units": "W"})
        if self.spectral is not None:
            sp = self.spectral
            data["YBR"][2]["definition"] = SPECTRAL_YBR_DEFINITION
            coords["wavelength"] = ("wavelength", sp.wavelength_nm, {"units": "nm"})
            data["spectrum"] = (("wavelength",), sp.spectrum_W_per_nm,
                                {"units": "W/nm", "long_name": "extracted spectrum"})
            data["spectrum_std_err"] = (("wavelength",), sp.spectrum_std_err, {"units": "W/nm"})
            data["emitted_spectrum"] = (("wavelength",), sp.emitted_W_per_nm,
                                        {"units": "W/nm", "long_name": "LED spectrum as sampled"})
            data["stokes_loss"] = ((), sp.ledger["power_W"]["stokes"], {"units": "W"})
            data["photon_ledger_error"] = ((), sp.ledger["photons_per_s"]["error"], {"units": "1"})
        ds = xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                        coords={k: xr.Variable(*v) if len(v) == 3 else xr.Variable(*v) for k, v in coords.items()})
        ds.attrs.update(rays=self.rays, seed=self.seed, emitted_W=self.emitted)
        return ds
