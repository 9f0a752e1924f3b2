"""Studies of the measurement and reduction chain (virtual goniometer → calibration → TIS)."""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from bsdfkit.bench.core import Row, Study
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.instrument import sample_direction
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.reduction import tis as angular
from bsdfkit.simulation import truth as synthetic
from bsdfkit.simulation import virtual_goniometer as virtual

ENTRIES = [(i, tag, side) for i in ("bibs", "biys", "yiys")
           for tag, side in (("B", "reflection"), ("F", "transmission"))]


def _measure_tis(truth, plan, gonio, seed: int, theta_i: float) -> tuple[float, float, float]:
    """(max relative TIS error over the six entries, wall time of calibration + TIS, instrument seconds)."""
    export = virtual.simulate_scan(truth, plan, gonio, seed=seed)
    instrument_s = sum(float(np.sum(s["columns"]["exposure_s"])) for s in export.scans.values())
    instrument_s += sum(float(r["exposure_s"]) * r["counts"].shape[0] for r in export.references.values())
    instrument_s += float(np.sum(export.dark["exposure_s"]))
    with tempfile.TemporaryDirectory() as tmp:
        virtual.write_raw_export(export, Path(tmp) / "scan")
        start = time.perf_counter()
        table = angular.tis_table(calibrate(read_scan(Path(tmp) / "scan")))
        wall = time.perf_counter() - start
    lam = gonio.spectrometer.wavelength
    exact = synthetic.exact_tis_table(truth, theta_i, lam, virtual.BLUE.incident_power(lam, 1),
                                      virtual.YELLOW.incident_power(lam, 1))
    err = max(abs(100 * float(table.tis.sel(interaction=i, side=s, theta_i=theta_i)) - exact[f"{t}_{i}"])
              / exact[f"{t}_{i}"]
              for i, t, s in ENTRIES)
    return err, wall, instrument_s


def tis_vs_step(quick: bool) -> Study:
    """TIS error against the goniometer's angular step (uniform steps on both arcs, 45° incidence).

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    gonio = virtual.VirtualGoniometer(spectrometer=virtual.Spectrometer(wavelength_step_nm=2.5 if quick else 1.0))
    truth = virtual.cl830_truth(gonio)
    rows = []
    for step in ((8.0, 4.0, 2.0) if quick else (16.0, 8.0, 4.0, 2.0, 1.0)):
        plan = virtual.ScanPlan(theta_i_deg=(45.0,), in_plane_deg=tuple(float(x) for x in np.arange(-88, 88.01, step)),
                                perpendicular_deg=tuple(float(x) for x in np.arange(-60, 60.01, step)),
                                fine_halfwidth_deg=0.0)
        err, wall, inst = _measure_tis(truth, plan, gonio, seed=11, theta_i=45.0)
        n = sum(len(plan.positions(45.0, s)) for s in plan.sides)
        rows.append(Row(f"step {step:g}°", err, wall, inst, {"positions": n}))
    return Study("tis_step", "TIS error vs goniometer angular step (θi = 45°, both arcs, no fine region)",
                 "max over the six TIS entries of |TIS − exact truth| / truth", "instrument time (s)", tuple(rows),
                 notes="Positions are counted per configuration; the instrument time sums every exposure, "
                       "reference and dark.")


def tis_vs_exposure(quick: bool) -> Study:
    """TIS error against total measurement time (exposure budget), default scan plan at 45°.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    base = virtual.default_plan()
    plan = virtual.ScanPlan(theta_i_deg=(45.0,), in_plane_deg=base.in_plane_deg,
                            perpendicular_deg=base.perpendicular_deg)
    rows = []
    for max_exp in ((0.005, 0.1, 20.0) if quick else (0.002, 0.01, 0.05, 0.5, 5.0, 20.0)):
        gonio = virtual.VirtualGoniometer(spectrometer=virtual.Spectrometer(wavelength_step_nm=2.5 if quick else 1.0),
                                          max_exposure_s=max_exp)
        truth = virtual.cl830_truth(gonio)
        err, wall, inst = _measure_tis(truth, plan, gonio, seed=12, theta_i=45.0)
        rows.append(Row(f"max exposure {max_exp:g} s", err, wall, inst))
    return Study("tis_exposure", "TIS error vs measurement time (exposure cap; default plan, θi = 45°)",
                 "max over the six TIS entries of |TIS − exact truth| / truth", "instrument time (s)", tuple(rows),
                 notes="Shorter exposures raise shot and read noise; the floor is the reconstruction error of the "
                       "two-arc scan.")


def quadrature(quick: bool) -> Study:
    """Eq. (7) rectangle sum vs the projected-solid-angle rule on the exact truth (no measurement).

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    truth = virtual.cl830_truth()
    th = np.radians(45.0)
    exact = truth.elastic_tis("bibs", "reflection", th)

    def f_sph(theta, phi):
        return truth.elastic_angular("bibs", "reflection", th, sample_direction(theta, phi))

    rows = []
    for step in ((5.0, 1.0, 0.25) if quick else (10.0, 5.0, 2.0, 1.0, 0.5, 0.25, 0.1)):
        start = time.perf_counter()
        value = angular.tis_rectangle_sum(f_sph, step, step)
        wall = time.perf_counter() - start
        n = (int(90 / step) + 1) * int(360 / step)
        rows.append(Row(f"Δθ = Δφ = {step:g}°", abs(value - exact) / exact, wall, n,
                        {"group": "eq. (7) rectangle sum"}))
    b0 = (np.sin(th), 0.0)
    for n_psi, n_r in (((16, 25), (32, 50), (64, 100), (128, 200)) if quick
                       else ((8, 12), (16, 25), (32, 50), (64, 100), (128, 200), (256, 400))):
        start = time.perf_counter()
        grid = angular.polar_grid(b0, n_psi, n_r)
        d = np.stack([b0[0] + grid.r * np.cos(grid.psi), grid.r * np.sin(grid.psi)], axis=-1)
        z = np.sqrt(np.clip(1 - (d**2).sum(-1), 0, None))
        value = float(np.sum(truth.elastic_angular("bibs", "reflection", th, np.concatenate([d, z[:, None]], -1))
                             * grid.w))
        wall = time.perf_counter() - start
        rows.append(Row(f"{n_psi} × {n_r} polar nodes", abs(value - exact) / exact, wall, n_psi * n_r,
                        {"group": "projected solid angle (polar about β0)"}))
    return Study("quadrature", "TIS quadrature: eq. (7) rectangle sum vs projected-solid-angle rule (bibs R, 45°)",
                 "|TIS − exact| / exact for the truth BSDF evaluated at the nodes", "BSDF evaluations", tuple(rows),
                 groups=("eq. (7) rectangle sum", "projected solid angle (polar about β0)"))


def spectral_resolution(quick: bool) -> Study:
    """Weighted means and photon conversions on coarser spectrometer grids, against a 0.05 nm reference.

    Parameters
    ----------
    quick : bool
        Fewer, cheaper settings (``bsdfkit bench --quick``).

    Returns
    -------
    Study
        One row per setting: error against the truth [-], wall time [s] and cost.
    """
    truth = virtual.cl830_truth()

    def quantities(step: float) -> dict[str, float]:
        lam = np.arange(380.0, 780.0 + 1e-9, step)
        blue = virtual.BLUE.incident_power(lam, 1.0)
        yellow = virtual.YELLOW.incident_power(lam, 1.0)
        th = np.radians(45.0)
        m_b = synthetic.weighted_mean(lam, truth.elastic_spectral("bibs", "reflection", th, lam), blue, (450, 470))
        m_y = synthetic.weighted_mean(lam, truth.elastic_spectral("yiys", "reflection", th, lam), yellow, (470, 740))
        em = truth.emission_density(lam)
        w_b = lam[(lam >= 450) & (lam <= 470)]
        lam_i = np.sum(blue[(lam >= 450) & (lam <= 470)] * w_b) / np.sum(blue[(lam >= 450) & (lam <= 470)])
        sel = (lam >= 470) & (lam <= 740)
        lam_s = np.sum(em[sel] * lam[sel]) / np.sum(em[sel])
        return {"bibs mean": m_b, "yiys mean": m_y, "photon ratio": lam_s / lam_i}

    ref = quantities(0.05)
    rows = []
    for step in ((0.5, 2.0, 5.0) if quick else (0.5, 1.0, 2.0, 5.0, 10.0)):
        start = time.perf_counter()
        q = quantities(step)
        wall = time.perf_counter() - start
        errs = {k: abs(q[k] - ref[k]) / ref[k] for k in q}
        rows.append(Row(f"{step:g} nm", max(errs.values()), wall, 400.0 / step + 1,
                        {k + " error": v for k, v in errs.items()}))
    return Study("spectral", "Spectral resolution vs error of weighted means and photon conversion",
                 "max relative error of ⟨q⟩_blue, ⟨q⟩_yellow (eqs. 5, 8) and λ̄s/λ̄i (eq. 16) vs a 0.05 nm grid",
                 "wavelength samples", tuple(rows),
                 notes="The 450-470 nm filter band holds only 21 samples at 1 nm and 5 at 5 nm: the band-edge "
                       "weights dominate.")
