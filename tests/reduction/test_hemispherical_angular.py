"""Hemisphere reconstruction and TIS: closed forms, the bundled truth, honest error bars, grazing incidence."""
import json

import numpy as np
import pytest
import xarray as xr
from scipy import integrate

from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.instrument import sample_direction
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.reduction import tis as angular
from bsdfkit.simulation import virtual_goniometer as virtual


def _profile(theta_i, theta_s, phi_s, arc, values, side="reflection", interaction="bibs"):
    n = len(values)
    return xr.Dataset(
        {"bsdf": ("record", np.asarray(values, float)), "bsdf_std": ("record", np.zeros(n))},
        coords={"theta_i": ("record", np.full(n, theta_i)), "phi_i": ("record", np.full(n, 180.0)),
                "theta_s": ("record", np.asarray(theta_s, float)), "phi_s": ("record", np.asarray(phi_s, float)),
                "side": ("record", np.array([side] * n, dtype=object)), "arc": ("record", np.array(arc, dtype=object))},
        attrs={"interaction": interaction})


def _dense_arcs(theta_i, radii):
    """In-plane and perpendicular samples at the given |Δ| radii about β0 (exactly on the arcs)."""
    s0 = np.sin(np.radians(theta_i))
    ts, ps, arc = [], [], []
    for sign in (1, -1):
        a = s0 + sign * radii
        a = a[np.abs(a) < 1]
        th = np.degrees(np.arcsin(np.abs(a)))
        ts += th.tolist()
        ps += np.where(a >= 0, 0.0, 180.0).tolist()
        arc += ["in_plane"] * th.size
    # perpendicular arc: ε chosen so that |Δ| = r: solve sin²θi (1 − cos ε)² + sin² ε = r²
    for sign in (1, -1):
        for r in radii:
            if r == 0:
                continue
            eps = _solve_eps(s0, r)
            if eps is None:
                continue
            e = sign * eps
            t = np.arccos(np.cos(e) * np.cos(np.radians(theta_i)))
            ts.append(np.degrees(t))
            ps.append(np.degrees(np.arctan2(np.sin(e), np.cos(e) * s0)))
            arc.append("perpendicular")
    return np.array(ts), np.array(ps), arc


def _solve_eps(s0, r):
    from scipy.optimize import brentq

    fn = lambda e: (s0 * (1 - np.cos(e))) ** 2 + np.sin(e) ** 2 - r * r  # noqa: E731
    top = np.radians(89.9)
    if fn(top) < 0:
        return None
    return brentq(fn, 0.0, top)


def _integrate_model(theta_i, fn, radii, interaction="bibs"):
    """TIS on the default quadrature grid (256 x 400, as tis_from_profile): the closed forms below are met to
    rounding (Lambertian) and within 8.4e-6 (Gaussian lobe), 7.2e-6 (ABG), errors set by the arcs' sampling: on a
    512 x 2000 grid (5-10x slower) they were 8.3e-6 and 7.1e-6."""
    ts, ps, arc = _dense_arcs(theta_i, radii)
    d = sample_direction(np.radians(ts), np.radians(ps))
    prof = _profile(theta_i, ts, ps, arc, fn(d), interaction=interaction)
    return angular.Hemisphere.from_profile(prof).tis("log", n_psi=256, n_r=400)


def test_lambertian_integrates_to_rho():
    radii = np.linspace(0, 2, 41)
    for theta_i in (0.0, 30.0, 70.0):
        t = _integrate_model(theta_i, lambda d: np.full(d.shape[:-1], 0.37 / np.pi), radii)
        assert t == pytest.approx(0.37, rel=1e-6)


def test_gaussian_lobe_closed_form():
    """A·exp(−|β−β0|²/2σ²) inside the disk integrates to 2πσ²A (formats.md §6) — to 1e-4 relative."""
    A, sigma, theta_i = 3.0, 0.05, 20.0
    s0 = np.sin(np.radians(theta_i))
    fn = lambda d: A * np.exp(-((d[..., 0] - s0) ** 2 + d[..., 1] ** 2) / (2 * sigma**2))  # noqa: E731
    radii = np.concatenate([np.linspace(0, 0.4, 801), np.linspace(0.41, 1.9, 150)])
    t = _integrate_model(theta_i, fn, radii)
    assert t == pytest.approx(2 * np.pi * sigma**2 * A, rel=1e-4)


@pytest.mark.parametrize("A,B,g,expected", [(0.0025, 0.001, 1.8, 0.041344), (0.01, 0.01, 2.0, 0.144988),
                                            (0.001, 1e-4, 2.5, 0.072190)])
def test_abg_closed_form_at_normal_incidence(A, B, g, expected):
    """TIS = 2πA∫₀¹ β/(B+β^g) dβ (formats.md §6); g = 2: πA ln(1 + 1/B)."""
    exact = 2 * np.pi * A * integrate.quad(lambda b: b / (B + b**g), 0, 1, points=[B ** (1 / g)], limit=200)[0]
    assert exact == pytest.approx(expected, rel=2e-5)
    if g == 2.0:
        assert exact == pytest.approx(np.pi * A * np.log(1 + 1 / B), rel=1e-10)
    fn = lambda d: A / (B + np.hypot(d[..., 0], d[..., 1]) ** g)  # noqa: E731
    radii = np.concatenate([[0.0], np.geomspace(1e-5, 0.999999, 1500)])
    t = _integrate_model(0.0, fn, radii)
    assert t == pytest.approx(exact, rel=1e-4)


def test_linear_weights_reproduce_linear_reconstruction():
    g = virtual.VirtualGoniometer()
    truth = virtual.cl830_truth(g)
    pos = virtual.default_plan().positions(45.0, "reflection")
    ts, ps, arc = (np.array([p[k] for p in pos]) for k in range(3))
    f = truth.elastic_angular("bibs", "reflection", np.radians(45.0), sample_direction(np.radians(ts), np.radians(ps)))
    hemi = angular.Hemisphere.from_profile(_profile(45.0, ts, ps, list(arc), f))
    assert hemi.weights() @ f == pytest.approx(hemi.tis("linear"), rel=1e-12)


@pytest.mark.parametrize("use", ["both", "in_plane"])
def test_weights_of_one_geometry_are_shared_and_independent_of_the_values(use):
    # the weights depend on the sampled directions only (cached by geometry): two profiles with the same records
    # and other values get equal weights, each reproducing its own linear reconstruction, and each caller its own
    # writable copy; "in_plane" fills the perpendicular half-axes with the mean of the in-plane halves (share 1/2)
    radii = np.linspace(0.0, 0.9, 19)
    ts, ps, arc = _dense_arcs(30.0, radii)
    d = sample_direction(np.radians(ts), np.radians(ps))
    lobe = 0.25 / np.pi + 3.0 * np.exp(-((d[:, 0] - 0.5) ** 2 + d[:, 1] ** 2) / 0.02)
    flat = np.full(ts.size, 0.25 / np.pi)
    hemis = [angular.Hemisphere.from_profile(_profile(30.0, ts, ps, arc, v), use=use) for v in (lobe, flat)]
    w = [h.weights(128, 200) for h in hemis]
    assert np.array_equal(w[0], w[1]) and w[0] is not w[1]
    w[0][:] = 0.0  # a caller's own copy: the next call is not changed by it
    assert np.array_equal(hemis[0].weights(128, 200), w[1])
    for h, v in zip(hemis, (lobe, flat)):
        assert h.weights(128, 200) @ v == pytest.approx(h.tis("linear", 128, 200), rel=1e-12)
    assert w[1] @ flat == pytest.approx(0.25, rel=1e-3)  # a Lambertian's albedo, whatever the grid


def test_bundled_tis_within_half_a_point_of_truth(bundled_scan):
    """Acceptance: every TIS entry at 5°, 45° and 56° within 0.5 percentage points of the recorded truth."""
    table = angular.tis_table(bundled_scan)
    truth = json.loads(bundled_scan.attrs["manifest_json"])["truth"]["tis_percent"]
    for th in (5.0, 45.0, 56.0):
        for inter in ("bibs", "biys", "yiys"):
            for tag, side in (("B", "reflection"), ("F", "transmission")):
                got = 100 * float(table.tis.sel(interaction=inter, side=side, theta_i=th))
                assert abs(got - truth[f"{th:g}"][f"{tag}_{inter}"]) < 0.5, (th, inter, side, got)


def test_rectangle_sum_eq7_converges_to_rho_for_lambert():
    f = lambda th, ph: np.full(np.broadcast(th, ph).shape, 0.5 / np.pi)  # noqa: E731
    coarse = angular.tis_rectangle_sum(f, 10.0, 10.0)
    fine = angular.tis_rectangle_sum(f, 0.5, 5.0)
    assert abs(fine - 0.5) < abs(coarse - 0.5)
    assert fine == pytest.approx(0.5, rel=1e-4)


@pytest.mark.slow
def test_error_bars_are_honest_over_20_realisations(tmp_path):
    """Acceptance: over ≥ 20 virtual-goniometer realisations ≥ 90 % of TIS entries lie within 2σ of the truth."""
    g = virtual.VirtualGoniometer(spectrometer=virtual.Spectrometer(wavelength_step_nm=5.0), dark_frames=4,
                                  reference_frames=4)
    truth = virtual.cl830_truth(g)
    plan = virtual.ScanPlan(theta_i_deg=(45.0,), in_plane_deg=virtual.default_plan().in_plane_deg,
                            perpendicular_deg=virtual.default_plan().perpendicular_deg)
    lam = g.spectrometer.wavelength
    from bsdfkit.simulation import truth as synthetic
    exact = synthetic.exact_tis_table(truth, 45.0, lam, virtual.BLUE.incident_power(lam, 1),
                                      virtual.YELLOW.incident_power(lam, 1))
    inside = []
    for seed in range(20):
        folder = tmp_path / f"s{seed}"
        virtual.write_raw_export(virtual.simulate_scan(truth, plan, g, seed=seed), folder)
        table = angular.tis_table(calibrate(read_scan(folder)))
        for inter in ("bibs", "biys", "yiys"):
            for tag, side in (("B", "reflection"), ("F", "transmission")):
                sel = dict(interaction=inter, side=side, theta_i=45.0)
                z = ((100 * float(table.tis.sel(**sel)) - exact[f"{tag}_{inter}"])
                     / (100 * float(table.tis_std.sel(**sel))))
                inside.append(abs(z) <= 2)
    assert len(inside) == 120
    assert np.mean(inside) >= 0.9


def test_grazing_incidence_85_is_finite_and_bounded(tmp_path):
    g = virtual.VirtualGoniometer(spectrometer=virtual.Spectrometer(wavelength_step_nm=5.0), dark_frames=3,
                                  reference_frames=3)
    truth = virtual.cl830_truth(g)
    plan = virtual.ScanPlan(theta_i_deg=(85.0,), in_plane_deg=tuple(float(x) for x in np.arange(-88, 89, 4.0)),
                            perpendicular_deg=tuple(float(x) for x in np.arange(-60, 61, 5.0)))
    virtual.write_raw_export(virtual.simulate_scan(truth, plan, g, seed=3), tmp_path / "g")
    ds = calibrate(read_scan(tmp_path / "g"))
    table = angular.tis_table(ds)
    for var in ("tis", "tis_std"):
        assert np.isfinite(table[var].values).all()
    assert (table.tis.values <= 1.0).all() and (table.tis.values >= -1e-3).all()
    blue = table.tis.sel(interaction=["bibs", "biys"]).sum(["interaction", "side"]).values
    assert (blue <= 1.0).all()


@pytest.mark.parametrize("zero_tail", [False, True])
def test_tis_variants_equal_separate_blends_bit_for_bit(zero_tail):
    # tis_from_profile's error budget evaluates four blends on one grid through tis_variants; each must be the
    # number tis() gives alone, also when a half-profile has a zero sample (the ln-f interpolant's fallback)
    radii = np.linspace(0.0, 0.9, 19)
    ts, ps, arc = _dense_arcs(30.0, radii)
    d = sample_direction(np.radians(ts), np.radians(ps))
    values = 0.25 / np.pi + 3.0 * np.exp(-((d[:, 0] - 0.5) ** 2 + d[:, 1] ** 2) / 0.02)
    if zero_tail:
        values[np.argmax(ts)] = 0.0
    hemi = angular.Hemisphere.from_profile(_profile(30.0, ts, ps, arc, values))
    variants = [(2.0, True), (1.0, True), (4.0, True), (2.0, False)]
    for mode in ("log", "linear"):
        together = hemi.tis_variants(mode, 128, 200, variants)
        alone = [hemi.tis(mode, 128, 200, p=p, borrow=b) for p, b in variants]
        assert together == alone
    assert 0.2 < together[0] < 0.5  # a real integral: the Lambertian 0.25 plus the lobe


def test_tis_without_single_arc_components_keeps_value_and_error_bars():
    # plate_spectral_model asks for no single-arc components (singles=False): the value, both σ and the weights
    # must be those of the full reduction, bit for bit; only the two single-arc reconstructions are left out
    radii = np.linspace(0.0, 0.9, 19)
    ts, ps, arc = _dense_arcs(30.0, radii)
    d = sample_direction(np.radians(ts), np.radians(ps))
    values = 0.25 / np.pi + 3.0 * np.exp(-((d[:, 0] - 0.5) ** 2 + d[:, 1] ** 2) / 0.02)
    prof = _profile(30.0, ts, ps, arc, values)
    prof["bsdf_std"] = ("record", 0.02 * values)
    full, lean = angular.tis_from_profile(prof), angular.tis_from_profile(prof, singles=False)
    assert (lean.value, lean.std_measurement, lean.std_reconstruction) == \
        (full.value, full.std_measurement, full.std_reconstruction)
    assert np.array_equal(lean.weights, full.weights)
    assert {"in_plane_only", "perpendicular_only"} <= set(full.components)
    assert set(lean.components) == set(full.components) - {"in_plane_only", "perpendicular_only"}
    assert 0.2 < full.components["in_plane_only"] < 0.6  # the full reduction still reconstructs each arc
