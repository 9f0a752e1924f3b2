"""The tracer against exact answers: radiosity with exact view factors, white furnaces, the two-wavelength
module budget, and the independent NumPy implementation. Every comparison is within 3 standard errors and
every trace closes its energy ledger to 1e-9 (relative).

The full 9-case acceptance grid at 1e6 rays is benchmarks/bench_trace.py --oracle; here a subset at 1e5.
"""
from __future__ import annotations

import pytest

from bsdfkit.raytrace import PhosphorPlate, loads_scene, trace
from bsdfkit.raytrace.oracles.numpy_reference import trace_numpy
from bsdfkit.raytrace.oracles.radiosity import module_radiosity

CHUNK, LANES = 20_000, 512  # one compiled kernel per effects record for the whole module

TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def scene(h=43.0, rho=0.9, top='kind = "exit"', extra=""):
    return loads_scene(f"""
[cavity]
radius_mm = 35.0
height_mm = {h}
[wall]
reflectance = {rho}
specular_fraction = 0.0
[base]
reflectance = {rho}
specular_fraction = 0.0
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
distribution = "lambertian"
power_W = 2.0
[top]
{top}
{extra}
""")


def run(s, rays, seed):
    r = trace(s, rays, seed, chunk=CHUNK, lanes=LANES)
    assert r.ledger_error <= 1e-9
    return r


@pytest.mark.parametrize("h, rho, seed", [(10.0, 0.80, 11), (43.0, 0.90, 12), (80.0, 0.985, 13)])
def test_exit_top_matches_radiosity(h, rho, seed):
    s = scene(h, rho)
    ref = module_radiosity(s)
    r = run(s, 100_000, seed)
    se = r.std_err["LER"]
    assert 0 < se < 0.002
    assert abs(r.LER - ref.LER) <= 3 * se, (r.LER, ref.LER, se)
    # absorption per surface too (LED disks are part of the base in the oracle); powers are in W
    P = s.leds.power_W
    assert abs(r.absorbed["wall"] / P - ref.absorbed_wall) <= 3 * r.std_err["absorbed_wall"] / P + 1e-12
    base = (r.absorbed["base"] + r.absorbed["leds"]) / P
    se_base = (r.std_err["absorbed_base"] + r.std_err["absorbed_leds"]) / P
    assert abs(base - ref.absorbed_base) <= 3 * se_base
    assert r.extracted["total"] == pytest.approx(r.LER * P, rel=1e-12)


def test_white_furnace_exit_top_extracts_everything():
    r = run(scene(43.0, 1.0), 20_000, 3)
    assert r.LER == 1.0 and r.std_err["LER"] == 0.0
    assert r.roulette == 0.0 and r.truncated == 0.0 and sum(r.absorbed.values()) == 0.0
    assert r.interactions > r.rays  # rays did bounce


def test_closed_white_furnace_truncates_everything():
    s = scene(43.0, 1.0, 'kind = "lambertian"\nreflectance = 1.0\ntransmittance = 0.0', "[trace]\nmax_events = 40")
    r = run(s, 20_000, 4)
    assert r.extracted["total"] == 0.0 and sum(r.absorbed.values()) == 0.0 and r.roulette == 0.0
    assert r.truncated == pytest.approx(s.leds.power_W, rel=1e-12)
    assert r.interactions == 40 * r.rays


def test_diffuser_top_matches_radiosity():
    s = scene(43.0, 0.9, 'kind = "lambertian"\nreflectance = 0.37\ntransmittance = 0.63')
    ref = module_radiosity(s)
    r = run(s, 100_000, 5)
    assert abs(r.LER - ref.LER) <= 3 * r.std_err["LER"]
    assert r.extracted["yellow"] == 0.0
    P = s.leds.power_W
    assert abs(r.absorbed["plate"] / P - ref.absorbed_plate) <= 3 * r.std_err["absorbed_plate"] / P


@pytest.mark.parametrize("h, rho, seed", [(43.0, 0.90, 21), (10.0, 0.985, 22)])
def test_phosphor_plate_matches_two_wavelength_budget(tmp_path, h, rho, seed):
    """Angle-independent Table-2 plate with Lambertian distributions: the radiosity budget is exact."""
    plate = PhosphorPlate.constant(TABLE2, name="Table 2 of the power-budget paper, 45 deg")
    path = tmp_path / "plate.json"
    plate.save(path)
    s = scene(h, rho, f'kind = "phosphor"\nplate = "{path}"')
    ref = module_radiosity(s)
    r = run(s, 100_000, seed)
    assert abs(r.LER - ref.LER) <= 3 * r.std_err["LER"], (r.LER, ref.LER, r.std_err["LER"])
    assert abs(r.YBR - ref.YBR) <= 3 * r.std_err["YBR"], (r.YBR, ref.YBR, r.std_err["YBR"])
    P = s.leds.power_W
    assert abs(r.absorbed["plate"] / P - ref.absorbed_plate) <= 3 * r.std_err["absorbed_plate"] / P
    # the per-interaction budget (Fig. 10 of the power-budget paper) adds up to the totals
    cb = r.cumulative_budget()
    assert cb["extracted"][-1] == pytest.approx(r.extracted["total"], abs=1e-9 * P)
    assert cb["in_flight"][-1] == pytest.approx(0.0, abs=1e-9 * P)
    first = r.budget[0]
    assert first[0] == pytest.approx(TABLE2["bibs_transmission"] / TABLE2["biys_transmission"] * first[1], rel=0.1)


def test_numpy_reference_agrees_with_kernel():
    for s in (scene(43.0, 0.9), scene(43.0, 0.9, 'kind = "lambertian"\nreflectance = 0.37\ntransmittance = 0.63')):
        r = run(s, 60_000, 7)
        ref = trace_numpy(s, 60_000, seed=7)
        assert ref.ledger_error < 1e-12
        se = (r.std_err["LER"] ** 2 + ref.se_LER ** 2) ** 0.5
        assert abs(r.LER - ref.LER) <= 3 * se
