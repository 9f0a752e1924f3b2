"""Hard cases that must stay numerically stable: each asserts a finite, correct value or a clear bsdfkit error.

Tracer hard cases (rays grazing the wall, aimed at the rim or seam, float32 vs float64) are at the end of this
file. Model and fit hard cases live beside their models: α → ±1 and FWHM → 0 in spectrum fits and the
near-singular two-band system in tests/fit/test_spectrum.py; ABg with g, B → 0 and NaN-free gradients through every
model (hypothesis) in tests/models/test_functions.py.
"""
import numpy as np
import pytest
from conftest import TRACE_SIZES, fast_lane

from bsdfkit.core.errors import BsdfkitError, InputError
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.instrument import Instrument
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.reduction import tis as angular
from bsdfkit.simulation import truth as synthetic
from bsdfkit.simulation import virtual_goniometer as virtual


def _mirror_like_truth(A: float, sigma: float) -> synthetic.PhosphorPlateTruth:
    lobe = synthetic.LobeParams(rho=0.1, A=A, sigma=sigma)
    flat = synthetic.LobeParams(rho=0.1, A=0.0, sigma=0.1)
    return synthetic.PhosphorPlateTruth(
        name="glossy", theta_i_deg=(30.0,), bibs={"reflection": (lobe,), "transmission": (flat,)},
        yiys={"reflection": (lobe,), "transmission": (flat,)},
        biys={s: (synthetic.ConversionParams(T=0.0),) for s in synthetic.SIDES})


def test_specular_peak_six_decades_above_diffuse(tmp_path):
    """A near-mirror lobe (peak 6.6 decades above the diffuse level) through the whole signal chain:
    auto-exposure spans 1 ms to 20 s, and every value stays finite and within 3σ of the ideal instrument."""
    A, sigma = 1.2e5, 5e-4  # lobe TIS 2πσ²A = 0.19
    truth = _mirror_like_truth(A, sigma)
    gonio = virtual.VirtualGoniometer(instrument=Instrument(886.0, 0.5, 0.3),
                                      spectrometer=virtual.Spectrometer(wavelength_step_nm=5.0),
                                      dark_frames=4, reference_frames=4)
    plan = virtual.ScanPlan(theta_i_deg=(30.0,), in_plane_deg=(-60.0, -20.0, 10.0, 50.0, 80.0),
                            perpendicular_deg=(-30.0, 30.0), sides=("reflection",), fine_halfwidth_deg=0.04,
                            fine_step_deg=0.01)
    virtual.write_raw_export(virtual.simulate_scan(truth, plan, gonio, configurations=(virtual.BLUE,), seed=4),
                             tmp_path / "glossy")
    ds = calibrate(read_scan(tmp_path / "glossy"))
    q = ds["bsdf"].sel(wavelength=460.0).values
    assert np.isfinite(q).all()
    expected = gonio.expected_bsdf(truth, virtual.BLUE, 30.0, "reflection", ds.theta_s.values, ds.phi_s.values)["bsdf"]
    expected = expected[:, list(gonio.spectrometer.wavelength).index(460.0)]
    diffuse = np.abs(expected / (0.1 / np.pi) - 1) < 0.05  # positions far from the lobe
    assert diffuse.sum() >= 5
    assert q.max() / np.mean(q[diffuse]) > 1e6
    exposures = ds.exposure.values
    assert exposures.max() / exposures.min() >= 1e3
    z = (q - expected) / ds.bsdf_std.sel(wavelength=460.0).values
    assert np.all(np.abs(z) < 4)


def test_tis_of_a_narrow_lobe_on_dense_arcs():
    """TIS of a lobe 1e6 above the diffuse level is integrated correctly (log-interpolation, polar quadrature)."""
    import xarray as xr

    from bsdfkit.measurement.instrument import sample_direction

    A, sigma, rho, th = 4e4, 1.3e-3, 0.1, 30.0  # lobe TIS 0.42, peak 6.1 decades above ρ/π
    s0 = np.sin(np.radians(th))
    r = np.concatenate([[0.0], np.geomspace(1e-5, 1.5, 600)])
    a = np.concatenate([s0 + r, s0 - r[1:]])
    a = a[np.abs(a) < 0.99999]
    ts, ps = np.degrees(np.arcsin(np.abs(a))), np.where(a >= 0, 0.0, 180.0)
    d = sample_direction(np.radians(ts), np.radians(ps))
    f = rho / np.pi + A * np.exp(-((d[:, 0] - s0) ** 2 + d[:, 1] ** 2) / (2 * sigma**2))
    n = f.size
    prof = xr.Dataset({"bsdf": ("record", f), "bsdf_std": ("record", np.zeros(n))},
                      coords={"theta_i": ("record", np.full(n, th)), "phi_i": ("record", np.full(n, 180.0)),
                              "theta_s": ("record", ts), "phi_s": ("record", ps),
                              "side": ("record", np.array(["reflection"] * n, dtype=object)),
                              "arc": ("record", np.array(["in_plane"] * n, dtype=object))})
    assert f.max() / f.min() > 1e6
    t = angular.tis_from_profile(prof)
    exact = rho + 2 * np.pi * sigma**2 * A
    assert np.isfinite(t.value) and t.value == pytest.approx(exact, rel=2e-3)


@pytest.mark.parametrize("theta_s", [89.0, 89.9, 90.0])
def test_grazing_scatter_is_masked_or_finite(tiny_export, theta_s):
    raw = read_scan(tiny_export)
    raw = raw.assign_coords(theta_s=("record", np.where(np.arange(raw.sizes["record"]) == 0, theta_s,
                                                        raw.theta_s.values)))
    ds = calibrate(raw)
    half = np.degrees(Instrument(886.0, 25.4, 14.0).half_angle_rad)
    row = ds["bsdf"].values[0]
    if theta_s > 90 - 2 * half:
        assert bool(ds.grazing.values[0]) and np.isnan(row).all()
    else:
        assert np.isfinite(row[ds.incident_valid.sel(configuration=ds.config.values[0]).values]).all()
    assert not np.isinf(ds["bsdf"].values).any() and not np.isinf(ds.bsdf_std.values).any()


def test_pure_dark_record_gives_unbiased_negative_values(tiny_export):
    raw = read_scan(tiny_export)
    t = raw.exposure.values[0]
    darks = raw.dark_counts.values[raw.dark_exposure.values == t]
    counts = raw.counts.values.copy()
    rng = np.random.default_rng(0)
    counts[0] = darks.mean(axis=0) + rng.normal(0, 8.0, counts.shape[1])  # no light at all
    raw["counts"] = (("record", "wavelength"), counts)
    ds = calibrate(raw)
    v = ds.bsdf_bispectral.values[0]
    assert (v < 0).any() and (v > 0).any()
    assert np.all(np.isfinite(v)) and np.all(ds.bsdf_bispectral_std.values[0] > 0)


@pytest.mark.parametrize("theta_i", [85.0, 89.0])
def test_near_grazing_incidence_truth_stays_physical(theta_i):
    truth = virtual.cl830_truth()
    lam = np.arange(380.0, 780.01, 5.0)
    tis = synthetic.exact_tis_table(truth, theta_i, lam, virtual.BLUE.incident_power(lam, 1),
                                    virtual.YELLOW.incident_power(lam, 1))
    assert all(np.isfinite(v) for v in tis.values())
    assert tis["blue_losses"] >= 0 and tis["yellow_losses"] >= 0


def test_incidence_at_90_is_a_clear_error():
    import xarray as xr
    prof = xr.Dataset({"bsdf": ("record", [0.1, 0.1])},
                      coords={"theta_i": ("record", [90.0, 90.0]), "phi_i": ("record", [180.0, 180.0]),
                              "theta_s": ("record", [10.0, 20.0]), "phi_s": ("record", [0.0, 0.0]),
                              "side": ("record", ["reflection"] * 2), "arc": ("record", ["in_plane"] * 2)})
    with pytest.raises(BsdfkitError, match="unit disk"):
        angular.tis_from_profile(prof)


def test_profile_without_usable_values_is_a_clear_error():
    import xarray as xr
    prof = xr.Dataset({"bsdf": ("record", [np.nan, np.nan])},
                      coords={"theta_i": ("record", [30.0, 30.0]), "phi_i": ("record", [180.0, 180.0]),
                              "theta_s": ("record", [10.0, 20.0]), "phi_s": ("record", [0.0, 0.0]),
                              "side": ("record", ["reflection"] * 2), "arc": ("record", ["in_plane"] * 2)})
    with pytest.raises(InputError, match="no usable records"):
        angular.tis_from_profile(prof)


# ---------------------------------------------------------------------------------------------- tracer
# Rays grazing the cylinder wall, aimed at the rim (wall ∩ top) or the seam (wall ∩ base), or running up the
# axis: the next hit must be finite, on a real surface and inside the cavity, in float32 and float64.
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

#: the fast lane: the tracer's default float32 (the harder case); float64 geometry in the full suite and, end to end,
#: in test_float32_tracing_agrees_with_float64
DTYPES = fast_lane(["float32", "float64"], {"float32"})


def _next_hit(p, d, dtype, radius=35.0, height=43.0):
    import jax.numpy as jnp

    from bsdfkit.core.jaxconfig import x64
    from bsdfkit.raytrace.geometry import next_hit

    with x64(dtype == "float64"):
        arrays = [jnp.asarray(np.asarray(v), dtype=dtype) for v in (*p, *d)]
        surface, x, y, z = next_hit(*arrays, jnp.asarray(radius, dtype), jnp.asarray(height, dtype))
        return np.asarray(surface), np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)


def _check_hits(surface, x, y, z, radius=35.0, height=43.0, rtol=2e-6):
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(z))
    assert set(np.unique(surface)) <= {0, 1, 2}
    assert np.all(np.hypot(x, y) <= radius * (1 + rtol))
    assert np.all((z >= -height * rtol) & (z <= height * (1 + rtol)))


@pytest.mark.parametrize("dtype", DTYPES)
@settings(max_examples=60, deadline=None, derandomize=True)
@given(phi=st.floats(0, 2 * np.pi), z=st.floats(0.0, 43.0), tilt=st.floats(-1e-6, 1e-6),
       up=st.floats(-1.0, 1.0), inset=st.sampled_from([0.0, 1e-9, 1e-4]))
def test_rays_grazing_the_wall(dtype, phi, z, tilt, up, inset):
    r = 35.0 * (1 - inset)
    p = (np.array([r * np.cos(phi)]), np.array([r * np.sin(phi)]), np.array([z]))
    # tangent to the wall (plus a tiny inward/outward tilt), any elevation
    t = np.array([-np.sin(phi), np.cos(phi), 0.0]) + tilt * np.array([-np.cos(phi), -np.sin(phi), 0.0])
    d = np.array([t[0] * np.sqrt(1 - up**2), t[1] * np.sqrt(1 - up**2), up])
    d /= np.linalg.norm(d)
    _check_hits(*_next_hit(p, ([d[0]], [d[1]], [d[2]]), dtype))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("target_z", [43.0, 0.0], ids=["rim", "seam"])
def test_rays_aimed_at_the_rim_and_the_seam(dtype, target_z):
    rng = np.random.default_rng(0)
    n = 500
    phi = rng.uniform(0, 2 * np.pi, n)
    start = np.stack([rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), np.full(n, 21.5)])
    target = np.stack([35.0 * np.cos(phi), 35.0 * np.sin(phi), np.full(n, target_z)])
    d = (target - start) / np.linalg.norm(target - start, axis=0)
    surface, x, y, z = _next_hit(tuple(start), tuple(d), dtype)
    _check_hits(surface, x, y, z)
    # the hit is the aimed corner (to rounding), whichever of the two surfaces claims it
    assert np.allclose(np.hypot(x, y), 35.0, rtol=1e-5) and np.allclose(z, target_z, atol=1e-4)


@pytest.mark.parametrize("dtype", DTYPES)
def test_rays_up_the_axis_and_parallel_to_the_wall(dtype):
    p = (np.array([0.0, 34.999999]), np.array([0.0, 0.0]), np.array([0.0, 10.0]))
    d = (np.array([0.0, 0.0]), np.array([0.0, 0.0]), np.array([1.0, -1.0]))
    surface, x, y, z = _next_hit(p, d, dtype)
    _check_hits(surface, x, y, z)
    assert surface.tolist() == [2, 1]  # top, base


def test_float32_tracing_agrees_with_float64():
    """End to end: the same scene and seed traced with float32 and float64 ray geometry agree within 3σ."""
    from dataclasses import replace

    from conftest import ROOT

    from bsdfkit.raytrace import load_scene, trace

    scene = load_scene(ROOT / "fitting" / "scenes" / "example.toml")
    # in the kernels of tests/raytrace/test_kernel.py (TRACE_SIZES)
    r32 = trace(replace(scene, trace=replace(scene.trace, precision="float32")), 20000, 4, **TRACE_SIZES)
    r64 = trace(replace(scene, trace=replace(scene.trace, precision="float64")), 20000, 4, **TRACE_SIZES)
    assert abs(r32.LER - r64.LER) <= 3 * np.hypot(r32.std_err["LER"], r64.std_err["LER"]) + 1e-12
    assert r32.ledger_error < 1e-9 and r64.ledger_error < 1e-9
