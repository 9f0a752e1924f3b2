"""Scene TOML, phosphor-plate JSON and ray-file I/O of the tracer: round trips and one-line errors."""
from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsdfkit.core.errors import BsdfkitError, InputError, OutputExistsError, ValidationError
from bsdfkit.io.toml_write import dumps
from bsdfkit.raytrace import (
    LambertGaussian,
    Lambertian,
    PhosphorPlate,
    PlateChannel,
    Tabulated,
    dumps_scene,
    load_plate,
    load_scene,
    loads_scene,
    read_ray_file,
    save_scene,
    with_values,
)
from bsdfkit.raytrace.rayfile import RaySet, format_rays

EXAMPLE = """
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = 0.90
specular_fraction = 0.0      # share of the reflectance that is mirror-like
[base]
reflectance = 0.90
specular_fraction = 0.0
[leds]
count = 4
pitch_mm = 20.0              # centres on a square of this side, centred on the axis
emitter_radius_mm = 1.0      # Lambertian emitting disks in the base plane
distribution = "lambertian"  # or: fwhm_deg = 30
power_W = 1.0                # total; LED disks reflect like the base unless led_reflectance is set
[top]
kind = "exit"                # all light reaching the top leaves the module
"""

TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}


def test_example_scene_loads_with_documented_meaning(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(EXAMPLE)
    s = load_scene(path)
    assert s.cavity.radius_mm == 35.0 and s.cavity.height_mm == 43.0
    assert s.leds.count == 4 and s.leds.fwhm is None and s.leds.cos_exponent == 1.0
    assert sorted(s.leds.centres()) == [(-10.0, -10.0), (-10.0, 10.0), (10.0, -10.0), (10.0, 10.0)]
    assert s.top.kind == "exit"
    assert s.led_surface.reflectance == 0.90  # LEDs reflect like the base
    assert not s.tally_enabled("irradiance_map")  # exit top: tallies off unless asked


def test_fwhm_is_radians_inside_and_degrees_in_toml():
    s = loads_scene(EXAMPLE.replace('distribution = "lambertian"', "fwhm_deg = 30"))
    assert s.leds.fwhm == pytest.approx(math.radians(30))
    assert math.cos(s.leds.fwhm / 2) ** s.leds.cos_exponent == pytest.approx(0.5)
    doc = tomllib.loads(dumps_scene(s))
    assert doc["leds"]["fwhm_deg"] == pytest.approx(30.0)
    # FWHM 120 deg is the Lambertian cos^1 law
    s120 = loads_scene(EXAMPLE.replace('distribution = "lambertian"', "fwhm_deg = 120"))
    assert s120.leds.cos_exponent == pytest.approx(1.0)


def test_scene_toml_round_trip(tmp_path):
    plate = PhosphorPlate.constant(TABLE2, name="Table 2")
    (tmp_path / "plate.json").write_text(plate.to_json())
    text = EXAMPLE.replace('kind = "exit"                # all light reaching the top leaves the module',
                           'kind = "phosphor"\nplate = "plate.json"')
    text = text.replace('distribution = "lambertian"', "fwhm_deg = 70")
    path = tmp_path / "scene.toml"
    path.write_text(text + "\n[trace]\ntermination = \"threshold\"\nthreshold = 0.02\n[tallies]\nmap_bins = 16\n")
    s = load_scene(path)
    out = tmp_path / "again.toml"
    save_scene(s, out)
    again = load_scene(out)
    assert again.top.plate == s.top.plate and again.trace == s.trace and again.tallies == s.tallies
    assert again.leds.fwhm == pytest.approx(s.leds.fwhm, rel=1e-15)
    assert replace(again, leds=s.leds) == s
    with pytest.raises(OutputExistsError):
        save_scene(s, out)
    # inline plate round trip
    inline = replace(s, top=replace(s.top, plate_file=None))
    assert loads_scene(dumps_scene(inline)).top.plate == plate


@pytest.mark.parametrize("edit, field, expected", [
    (("reflectance = 0.90\nspecular_fraction = 0.0      #", "reflectance = 1.2\nspecular_fraction = 0.0      #"),
     "wall.reflectance", "<= 1"),
    (("count = 4", "count = 3"), "leds.count", "perfect square"),
    (("pitch_mm = 20.0", "pitch_mm = 60.0"), "leds.pitch_mm", "radius"),
    (("height_mm = 43.0", "height_mm = \"tall\""), "cavity.height_mm", "a number"),
    (("[top]", "[top]\ncolour = 1"), "top.colour", "one of"),
    (('kind = "exit"', 'kind = "window"'), "top.kind", "'exit'"),
    (('distribution = "lambertian"', 'distribution = "lambertian"\nfwhm_deg = 30'), "leds.fwhm_deg", "no fwhm_deg"),
    (("[cavity]", "[cavity]\nwidth_mm = 3"), "cavity.width_mm", "one of"),
])
def test_bad_scene_errors_name_file_key_expected_got(tmp_path, edit, field, expected):
    path = tmp_path / "bad.toml"
    path.write_text(EXAMPLE.replace(*edit, 1))
    with pytest.raises(InputError) as info:
        load_scene(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg and f"field '{field}'" in msg
    assert "expected" in msg and expected in msg and "got" in msg


def test_unknown_section_and_missing_section(tmp_path):
    with pytest.raises(InputError, match="unknown section.*expected one of"):
        loads_scene(EXAMPLE + "\n[mirror]\nx = 1\n", "s.toml")
    with pytest.raises(InputError, match="missing section"):
        loads_scene(EXAMPLE.replace("[top]", "[tallies]").replace('kind = "exit"', ""), "s.toml")
    with pytest.raises(BsdfkitError, match="not valid TOML"):
        loads_scene("[cavity\n", "s.toml")


FROM_RECIPE = EXAMPLE.replace('kind = "exit"                # all light reaching the top leaves the module',
                              'kind = "phosphor"\nfrom = "fitting/cl830.toml"')


def test_phosphor_from_recipe_is_resolved_by_the_callers_plate_resolver(tmp_path):
    calls = []

    def from_recipe(path):
        calls.append(path)
        return PhosphorPlate.constant(TABLE2, name="from recipe")

    s = loads_scene(FROM_RECIPE, tmp_path / "s.toml", plate_resolver=from_recipe)
    assert s.top.plate.name == "from recipe" and s.top.plate_recipe == "fitting/cl830.toml"
    assert calls == [Path("fitting/cl830.toml")]  # resolved against the scene's folder (not there: as written)
    assert tomllib.loads(dumps_scene(s))["top"]["from"] == "fitting/cl830.toml"
    # a sweep point reuses the plate: no second resolution, none needed
    assert with_values(s, {"cavity.height_mm": 20.0}).top.plate is s.top.plate and len(calls) == 1


def test_a_recipe_plate_without_a_resolver_is_refused_in_one_line_naming_top_from(tmp_path):
    with pytest.raises(InputError) as err:
        loads_scene(FROM_RECIPE, tmp_path / "s.toml")
    msg = str(err.value)
    assert "\n" not in msg and "top.from" in msg and "s.toml" in msg and "fitting/cl830.toml" in msg
    assert "plate_resolver" in msg  # what would be accepted


def test_a_recipe_without_a_measurement_gives_one_clear_error(tmp_path):
    from bsdfkit.pipeline.plate_from_scan import plate_from_recipe

    (tmp_path / "r.toml").write_text('[recipe]\nname = "x"\n')
    with pytest.raises(InputError, match="recipe.measurement"):
        plate_from_recipe(tmp_path / "r.toml")
    with pytest.raises(InputError, match="recipe not found"):
        plate_from_recipe(tmp_path / "missing.toml")


def test_the_trace_verb_resolves_a_recipe_plate(tmp_path, capsys):
    """``bsdfkit trace`` passes the pipeline's resolver: a faulty recipe is reported as the recipe's fault."""
    from bsdfkit.cli.main import main

    (tmp_path / "r.toml").write_text('[recipe]\nname = "x"\n')
    (tmp_path / "s.toml").write_text(FROM_RECIPE.replace("fitting/cl830.toml", "r.toml"))
    assert main(["trace", str(tmp_path / "s.toml"), "--rays", "100"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "recipe.measurement" in err and "r.toml" in err


def test_plate_json_round_trip_with_every_distribution_kind(tmp_path):
    lobe = LambertGaussian(rho_per_sr=0.05, a_per_sr=2.0, sigma=0.2)
    tab = Tabulated((0.0, 30.0, 60.0, 90.0), (0.3, 0.25, 0.1, 0.0))
    ch = PlateChannel((0.1, 0.12, 0.2), (Lambertian(), lobe, tab))
    plate = PhosphorPlate((5.0, 45.0, 56.0), ch, ch, ch, ch, ch, ch, name="test fixture", notes="made up")
    plate.validate()
    path = tmp_path / "p.json"
    plate.save(path)
    assert load_plate(path) == plate
    with pytest.raises(OutputExistsError):
        plate.save(path)


def test_plate_validation_errors(tmp_path):
    data = PhosphorPlate.constant(TABLE2).to_mapping()
    data["bibs"]["reflection"]["tis"] = [0.6, 0.6]
    data["biys"]["reflection"]["tis"] = [0.5, 0.5]
    path = tmp_path / "p.json"
    import json
    path.write_text(json.dumps(data))
    with pytest.raises(ValidationError, match="exceeds 1"):
        load_plate(path)
    data = PhosphorPlate.constant(TABLE2).to_mapping()
    data["yiys"]["transmission"]["distribution"] = {"kind": "lambert_gaussian", "rho_per_sr": 0.1, "a_per_sr": 1,
                                                    "sigma": 3.0}
    path.write_text(json.dumps(data))
    with pytest.raises(ValidationError) as info:
        load_plate(path)
    assert "yiys.transmission.distribution.sigma" in str(info.value)
    bad = replace(PhosphorPlate.constant(TABLE2), bibs_reflection=PlateChannel(
        (0.1, 0.1), (LambertGaussian(rho_per_sr=-0.1, a_per_sr=1.0, sigma=0.1),) * 2))
    with pytest.raises(ValidationError, match="bibs.reflection.distribution"):
        bad.validate()
    path.write_text("{not json")
    with pytest.raises(BsdfkitError, match="not valid JSON"):
        load_plate(path)
    data = PhosphorPlate.constant(TABLE2).to_mapping()
    data["bibs"]["forward"] = data["bibs"].pop("transmission")
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match="bibs.forward"):
        load_plate(path)


def test_ray_file_round_trip_and_errors(tmp_path):
    rays = RaySet(origin=np.array([[0.0, 0.0, 0.0], [10.0, -3.0, 5.0]]),
                  direction=np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]), power=np.array([0.25, 0.75]))
    path = tmp_path / "rays.txt"
    path.write_text(format_rays(rays))
    back = read_ray_file(path)
    np.testing.assert_array_equal(back.origin, rays.origin)
    np.testing.assert_allclose(back.direction, rays.direction, rtol=1e-15)
    assert back.total_power == 1.0
    path.write_text("# header\n0 0 0 0 0 1\n")
    with pytest.raises(BsdfkitError) as info:
        read_ray_file(path)
    assert ":2" in str(info.value) and "seven numbers" in str(info.value)
    path.write_text("0 0 0 0 0 1 -1\n")
    with pytest.raises(ValidationError, match="positive"):
        read_ray_file(path)
    # a ray starting outside the cavity is rejected when the scene is loaded
    path.write_text("50 0 1 0 0 1 1\n")
    scene_path = tmp_path / "s.toml"
    scene_path.write_text(EXAMPLE.replace("power_W = 1.0 ", 'ray_file = "rays.txt"\n#'))
    with pytest.raises(ValidationError, match="leds.ray_file"):
        load_scene(scene_path)


def test_with_values_sets_keys_and_revalidates():
    s = loads_scene(EXAMPLE)
    t = with_values(s, {"wall.reflectance": 0.8, "base.reflectance": 0.8, "leds.fwhm_deg": 30})
    assert t.wall.reflectance == 0.8 and t.base.reflectance == 0.8
    assert t.leds.fwhm == pytest.approx(math.radians(30))
    with pytest.raises(ValidationError, match="wall.reflectance"):
        with_values(s, {"wall.reflectance": 1.5})
    with pytest.raises(InputError, match="section.key"):
        with_values(s, {"reflectance": 0.5})


toml_scalars = st.one_of(st.booleans(), st.integers(-2 ** 62, 2 ** 62),
                         st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20))
toml_keys = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=1, max_size=8)
toml_docs = st.recursive(
    st.dictionaries(toml_keys, st.one_of(toml_scalars, st.lists(st.floats(allow_nan=False, allow_infinity=False),
                                                                 max_size=4)), max_size=4),
    lambda children: st.dictionaries(toml_keys, children, min_size=1, max_size=3), max_leaves=12)


@settings(max_examples=60, deadline=None)
@given(toml_docs)
def test_toml_writer_round_trips(doc):
    assert tomllib.loads(dumps(doc)) == doc
