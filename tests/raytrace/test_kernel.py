"""Kernel properties: chunk invariance, compiled effects, samplers, plate rules, termination, ray files."""
from __future__ import annotations

import math
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TRACE_LANES, TRACE_SIZES, TRACE_WIDTH

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.raytrace import (
    LambertGaussian,
    Lambertian,
    PhosphorPlate,
    PlateChannel,
    Tabulated,
    kernel,
    loads_scene,
    sampling,
    scene_effects,
    threshold_bias,
    trace,
)
from bsdfkit.raytrace.effects import kernel_params
from bsdfkit.raytrace.oracles.radiosity import module_radiosity
from bsdfkit.raytrace.rayfile import RaySet, format_rays
from bsdfkit.raytrace.tallies import non_uniformity

TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def scene(top='kind = "exit"', h=43.0, rho=0.9, spec=0.0, extra="", leds_extra=""):
    return loads_scene(f"""
[cavity]
radius_mm = 35.0
height_mm = {h}
[wall]
reflectance = {rho}
specular_fraction = {spec}
[base]
reflectance = {rho}
specular_fraction = 0.0
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
power_W = 1.0
{leds_extra}
[top]
{top}
{extra}
""")


def comparable(result):
    d = result.to_dict()
    for k in ("elapsed_s", "rays_per_s", "interactions_per_s", "compile_s", "chunk"):
        d.pop(k)
    return d


def test_same_seed_same_result_for_chunks_1e4_and_1e5():
    s = scene()
    wide = 4 * TRACE_WIDTH  # one kernel for the four traces (chunks up to 1e5)
    a = trace(s, 100_000, seed=9, chunk=10_000, lanes=TRACE_LANES, width=wide)
    b = trace(s, 100_000, seed=9, chunk=100_000, lanes=TRACE_LANES, width=wide)
    assert comparable(a) == comparable(b)
    assert a.ledger_error <= 1e-9
    c = trace(s, 20_000, seed=9, chunk=20_000, lanes=TRACE_LANES, width=wide)
    d = trace(s, 20_000, seed=10, chunk=20_000, lanes=TRACE_LANES, width=wide)
    assert c.LER != d.LER  # the seed matters


@pytest.mark.slow
def test_chunk_invariance_with_plate_map_and_budget(tmp_path):
    PhosphorPlate.constant(TABLE2).save(tmp_path / "p.json")
    s = scene(f'kind = "phosphor"\nplate = "{tmp_path / "p.json"}"', spec=0.3)
    a = trace(s, 20_000, seed=3, chunk=5_000, **TRACE_SIZES)
    b = trace(s, 20_000, seed=3, chunk=20_000, **TRACE_SIZES)
    assert comparable(a) == comparable(b)
    np.testing.assert_array_equal(a.irradiance, b.irradiance)
    np.testing.assert_array_equal(a.incidence_histogram, b.incidence_histogram)
    np.testing.assert_array_equal(a.budget, b.budget)
    assert a.ledger_error <= 1e-9
    assert 0 < a.non_uniformity < 1
    # the sub-maps follow the ray index, not the chunk: the converged non-uniformity is chunk-invariant too
    assert a.non_uniformity_converged == b.non_uniformity_converged
    conv = a.non_uniformity_converged
    assert 0 < conv["value"] < 1 and conv["std"] > 0 and conv["bins"] in conv["grids"]
    # one quantity under one name: the result, its JSON and its dataset report the converged value; the whole
    # map's noisy max − min is non_uniformity_map everywhere
    ds = a.to_dataset()
    assert a.non_uniformity == conv["value"] == a.to_dict()["non_uniformity"] == float(ds["non_uniformity"])
    assert a.non_uniformity_map == non_uniformity(a.irradiance) == float(ds["non_uniformity_map"])
    assert ds["non_uniformity"].attrs["bins"] == conv["bins"] and a.to_dict()["non_uniformity_std"] == conv["std"]


SCOPES = ("specular_reflection", "phosphor_conversion", "plate", "lobe_sampling", "table_sampling",
          "irradiance_map", "incidence_histogram", "interaction_budget")


def lowered_text(s, full=False, effects=None):
    eff = scene_effects(s, full=full) if effects is None else effects
    with x64():
        params = kernel_params(s, eff)
        low = kernel.trace_chunk_jit.lower(params, np.zeros(2, np.uint32), np.uint32(0), np.int32(256),
                                          effects=eff, lanes=256)
        return eff, low.as_text(debug_info=True)


def test_minimal_kernel_carries_no_optional_code():
    s = scene()  # diffuse cavity, exit top
    _, minimal = lowered_text(s, full=False)
    _, full = lowered_text(s, full=True)
    for scope in SCOPES:
        assert scope not in minimal, scope
        assert scope in full, scope
    assert minimal.count("stablehlo.while") < full.count("stablehlo.while")  # lobe rejection loop
    assert minimal.count("stablehlo.scatter") == 0 < full.count("stablehlo.scatter")
    assert len(minimal) < 0.6 * len(full)


@pytest.mark.slow  # four more kernels lowered (4 s); the fast lane's minimal and full kernels: the test above
def test_each_switch_brings_in_its_own_code_and_no_other_optional_code():
    s = scene()  # diffuse cavity, exit top
    eff = scene_effects(s)
    for flag, scope in (("specular", "specular_reflection"), ("irradiance_map", "irradiance_map"),
                        ("incidence_histogram", "incidence_histogram"), ("interaction_budget", "interaction_budget")):
        _, one = lowered_text(s, effects=replace(eff, **{flag: True}))
        assert [name for name in SCOPES if name in one] == [scope], flag


def test_effects_follow_the_scene(tmp_path):
    assert scene_effects(scene(spec=0.2)).specular
    assert not scene_effects(scene(spec=0.2, rho=0.0)).specular  # nothing is reflected at all
    eff = scene_effects(scene('kind = "lambertian"\nreflectance = 0.3\ntransmittance = 0.6'))
    assert eff.top == "plate" and not eff.conversion and eff.irradiance_map
    PhosphorPlate.constant(TABLE2).save(tmp_path / "p.json")
    eff = scene_effects(scene(f'kind = "phosphor"\nplate = "{tmp_path / "p.json"}"',
                              extra="[tallies]\nirradiance_map = false"))
    assert eff.conversion and not eff.irradiance_map and eff.incidence_histogram
    assert not (eff.plate_lobe or eff.plate_table or eff.plate_clamp)


@pytest.mark.slow
def test_forcing_the_full_kernel_changes_nothing_but_speed():
    s = scene()
    a = trace(s, 20_000, seed=5, chunk=20_000, lanes=512)
    b = trace(s, 20_000, seed=5, chunk=20_000, lanes=512, full_kernel=True)
    assert b.effects != a.effects
    assert (a.LER, a.absorbed, a.roulette, a.interactions) == (b.LER, b.absorbed, b.roulette, b.interactions)


def test_table_sampler_matches_its_pdf():
    s_nodes = np.array([0.0, 0.25, 0.75, 1.0])
    f = np.array([1.0, 3.0, 0.5, 0.0])
    mass = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(s_nodes))])
    f, cdf = f / mass[-1], mass / mass[-1]
    n = 200_000
    u = (np.arange(n) + 0.5) / n  # stratified: the sampled quantiles must reproduce the CDF
    with x64():
        s = np.asarray(sampling.table_s(jnp.asarray(u), jnp.tile(s_nodes, (n, 1)), jnp.tile(f, (n, 1)),
                                        jnp.tile(cdf, (n, 1))))

    def exact_cdf(x):
        k = np.clip(np.searchsorted(s_nodes, x, side="right") - 1, 0, 2)
        d = x - s_nodes[k]
        kappa = (f[k + 1] - f[k]) / (s_nodes[k + 1] - s_nodes[k])
        return cdf[k] + f[k] * d + 0.5 * kappa * d * d

    np.testing.assert_allclose(exact_cdf(s), u, atol=1e-12)


def test_azimuth_cos_sin_are_accurate_on_the_float32_uniform_grid():
    """cos 2πu, sin 2πu by quarter-turn reduction and polynomials: within 1.2e-7 (float32; libm on a float32 2πu
    is 4e-7 off) and 4e-16 (float64) of the exact values, on to_unit's 24-bit grid of uniforms."""
    k = np.arange(2 ** 24, step=13)  # spread over the grid, plus every value near the octant switches
    near = (np.arange(9)[:, None] * 2 ** 21 + np.arange(-2000, 2000)[None, :]).ravel()
    k = np.unique(np.clip(np.concatenate([k, near]), 0, 2 ** 24 - 1))
    u = k * 2.0 ** -24
    exact = 2 * np.pi * u.astype(np.longdouble)
    cos_exact, sin_exact = np.cos(exact), np.sin(exact)  # once for both dtypes (long double: 2 s per pair)
    for dtype, tol in ((jnp.float32, 1.2e-7), (jnp.float64, 4e-16)):
        with x64():
            c, s = map(np.asarray, jax.jit(sampling.cos_sin_turn)(jnp.asarray(u, dtype)))
        assert c.dtype == s.dtype == np.dtype(dtype)
        assert np.abs(c.astype(np.longdouble) - cos_exact).max() < tol
        assert np.abs(s.astype(np.longdouble) - sin_exact).max() < tol


@pytest.mark.slow
def test_lobe_sampler_is_a_gaussian_truncated_to_the_unit_disk():
    n = 40_000
    ray = jnp.arange(n, dtype=jnp.uint32)
    event = jnp.ones(n, jnp.int32)
    key = jnp.asarray([1, 2], jnp.uint32)
    with x64():
        for b0, sigma in ((0.3, 0.05), (0.95, 0.3)):
            bx, by, ok = sampling.lobe_beta(key, ray, event, jnp.ones(n, bool), jnp.full(n, b0), jnp.zeros(n),
                                            jnp.full(n, sigma), jnp.float64)
            bx, by, ok = map(np.asarray, (bx, by, ok))
            assert ok.all() and np.all(bx ** 2 + by ** 2 < 1)
            # reference: NumPy rejection sampling of the same truncated Gaussian
            rng = np.random.default_rng(0)
            g = rng.normal([b0, 0.0], sigma, size=(4 * n, 2))
            g = g[(g ** 2).sum(axis=1) < 1][:n]
            for ours, ref in ((bx, g[:, 0]), (by, g[:, 1])):
                se = np.hypot(ours.std(), ref.std()) / math.sqrt(n)
                assert abs(ours.mean() - ref.mean()) < 4 * se
                assert ours.std() == pytest.approx(ref.std(), rel=0.03)


def test_tabulated_lambertian_plate_matches_the_lambertian_budget(tmp_path):
    """A tabulated constant BSDF is Lambertian: same answer as the radiosity budget (tests in-kernel sampling)."""
    lam = PhosphorPlate.constant(TABLE2)
    tab = Tabulated((0.0, 30.0, 90.0), (1 / math.pi,) * 3)
    chans = {c: replace(lam.channel(c), distributions=(tab, tab)) for c in
             ("bibs_reflection", "biys_reflection", "yiys_reflection")}
    replace(lam, **chans).save(tmp_path / "tab.json")
    lam.save(tmp_path / "lam.json")
    s = scene(f'kind = "phosphor"\nplate = "{tmp_path / "tab.json"}"')
    assert scene_effects(s).plate_table
    ref = module_radiosity(scene(f'kind = "phosphor"\nplate = "{tmp_path / "lam.json"}"'))
    r = trace(s, 50_000, seed=8, chunk=25_000, lanes=512)
    assert abs(r.LER - ref.LER) <= 3 * r.std_err["LER"]
    assert abs(r.YBR - ref.YBR) <= 3 * r.std_err["YBR"]


def test_angle_dependent_fixture_plate_clamps_and_closes_the_ledger(tmp_path):
    """TEST FIXTURE (made-up angle dependence, not a measurement): incidences 5/45/56 deg as measured by the
    goniometer of the power-budget paper, bibs transmission falling with incidence, a Lambert+Gaussian lobe and
    a tabulated distribution; incidences outside 5–56 deg are clamped and counted."""
    lobe = LambertGaussian(rho_per_sr=0.05, a_per_sr=1.5, sigma=0.25)
    tab = Tabulated((0.0, 40.0, 80.0, 90.0), (0.4, 0.3, 0.05, 0.0))
    grid = (5.0, 45.0, 56.0)

    def ch(tis, dist):
        return PlateChannel(tuple(tis), (dist,) * 3)

    plate = PhosphorPlate(
        grid,
        bibs_reflection=ch((0.10, 0.109, 0.12), lobe), bibs_transmission=ch((0.08, 0.054, 0.04), Lambertian()),
        biys_reflection=ch((0.26, 0.263, 0.265), tab), biys_transmission=ch((0.26, 0.257, 0.25), Lambertian()),
        yiys_reflection=ch((0.45, 0.457, 0.46), lobe), yiys_transmission=ch((0.48, 0.471, 0.46), Lambertian()),
        name="test fixture: made-up angle dependence",
    )
    plate.save(tmp_path / "fixture.json")
    s = scene(f'kind = "phosphor"\nplate = "{tmp_path / "fixture.json"}"', spec=0.5)
    eff = scene_effects(s)
    assert eff.plate_lobe and eff.plate_table and eff.plate_clamp and eff.specular and eff.conversion
    r = trace(s, 20_000, seed=2, chunk=20_000, lanes=512)
    assert r.ledger_error <= 1e-9
    assert 0 < r.clamped_interactions < r.plate_interactions
    # power reaching the plate outside the grid (histogram) is clamped; inside is not
    hist = r.incidence_histogram.sum(axis=0)
    centres = (np.arange(hist.size) + 0.5) * 90 / hist.size
    assert hist[(centres < 5) | (centres > 56)].sum() > 0
    assert 0.2 < r.LER < 0.8 and r.YBR > 1


def test_threshold_termination_is_biased_low_and_accounted(tmp_path):
    PhosphorPlate.constant(TABLE2).save(tmp_path / "p.json")
    s = scene(f'kind = "phosphor"\nplate = "{tmp_path / "p.json"}"', spec=0.3)
    rows = threshold_bias(s, 20_000, 6, [0.3], chunk=20_000, lanes=512)
    row = rows[0]
    assert row["discarded"] > 0.01
    assert row["bias"] < -3 * row["se_roulette"]


def test_ray_file_source_samples_rays_by_power(tmp_path):
    rays = RaySet(origin=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
                  direction=np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.01]]) / np.array([[1.0], [math.hypot(1, 0.01)]]),
                  power=np.array([3.0, 1.0]))
    (tmp_path / "rays.txt").write_text(format_rays(rays))
    s = scene(rho=0.0, leds_extra=f'ray_file = "{tmp_path / "rays.txt"}"')
    s = replace(s, leds=replace(s.leds, power_W=4.0))
    r = trace(s, 20_000, seed=1, chunk=20_000, lanes=512)
    assert r.emitted == 4.0 and r.ledger_error <= 1e-9
    assert abs(r.LER - 0.75) <= 3 * r.std_err["LER"]
    assert r.absorbed["wall"] == pytest.approx(4.0 - r.extracted["total"], rel=1e-12)


def test_bad_run_arguments_are_bsdfkit_errors():
    s = scene()
    with pytest.raises(ValidationError, match="rays"):
        trace(s, 0)
    with pytest.raises(ValidationError, match="seed"):
        trace(s, 10, seed=-1)
    bad = replace(s, trace=replace(s.trace, max_events=10 ** 6, roulette_threshold=0.5))
    with pytest.raises(ValidationError, match="max_events"):
        trace(bad, 10)


def test_x64_is_scoped():
    trace(scene(), 1000, seed=0, chunk=1000, lanes=512)
    assert jnp.zeros(1).dtype == jnp.float32
    assert not jax.config.jax_enable_x64


def test_float64_geometry_agrees_with_float32():
    s = scene()
    a = trace(s, 20_000, seed=4, chunk=20_000, lanes=512)
    b = trace(replace(s, trace=replace(s.trace, precision="float64")), 20_000, seed=4, chunk=20_000, lanes=512)
    assert b.effects.precision == "float64" and b.ledger_error <= 1e-9
    # same random numbers, paths differ only by rounding: far closer than the statistical error
    assert abs(a.LER - b.LER) < 0.1 * a.std_err["LER"]
