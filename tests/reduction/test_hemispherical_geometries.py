"""One hemispherical engine for every sampling geometry: synthetic tables of exact truth (hemisphere_truth.py).

Each case: the value within 1 % of the exact integral and the truth within 3 standard uncertainties, at 0, 20 and
50 deg. Cases an instrument's sampling cannot determine are excluded by name and asserted to be stated instead:
a lobe measured on the in-plane arc only is assumed rotationally symmetric (an elliptical lobe is then not
measured), one or two arcs cannot see a body's azimuthal anisotropy at oblique incidence, and several planes
through the specular point leave azimuths near the normal unmeasured (the gap is stated, and the body's azimuthal
variation measured elsewhere enters the error bar: the truth within 3 σ, not within 1 %). Two arcs are reduced
by the half-profile method (tests/reduction/test_hemispherical.py holds its transmission cases).
"""
import numpy as np
import pytest
from conftest import fast_lane
from hemisphere_truth import Truth, table

from bsdfkit.reduction.hemispherical import elastic_source, hemispherical
from bsdfkit.tables import grids

INCIDENCES = (0.0, 20.0, 50.0)
TRUTHS = {
    "isotropic": Truth(),
    "anisotropic_body": Truth(a=0.3),
    "elliptical_lobe": Truth(sx=0.05, sy=0.09),
    "both": Truth(a=0.3, sx=0.05, sy=0.09),
    "broad_lobe": Truth(rho=0.3, b=0.5, a=0.2, A=0.8, sx=0.15, sy=0.15),
}
#: geometry -> truths it determines (module docstring)
CASES = {
    "grid": ("isotropic", "anisotropic_body", "elliptical_lobe", "both", "broad_lobe"),
    "cplanes": ("isotropic", "anisotropic_body", "broad_lobe"),
    "multiplane": ("isotropic", "elliptical_lobe"),
    "phi90": ("isotropic",),
    "one_arc": ("isotropic",),
    "two_arcs": ("isotropic",),
}


def _check(ds, truth, side):
    results = hemispherical(ds)
    assert [r.theta_i for r in results] == list(INCIDENCES)
    for r in results:
        assert r.side == side
        true = truth.tis(r.theta_i)
        value, std = float(r.value[0]), float(r.std[0])
        assert abs(value / true - 1) < 0.01, (r.theta_i, value, true, r.method)
        assert abs(value - true) < 3 * std, (r.theta_i, value, true, std)
    return results


#: the fast lane's case of each geometry: the truth that asks most of it (the full suite runs every case)
FAST = {("grid", "both"), ("cplanes", "broad_lobe"), ("multiplane", "elliptical_lobe"), ("phi90", "isotropic"),
        ("one_arc", "isotropic"), ("two_arcs", "isotropic")}


@pytest.mark.parametrize("geometry,name", fast_lane([(g, t) for g, ts in CASES.items() for t in ts], FAST))
def test_reflection_within_one_percent_and_three_sigma(geometry, name):
    _check(table(TRUTHS[name], geometry, INCIDENCES), TRUTHS[name], "reflection")


@pytest.mark.parametrize("geometry", fast_lane(["grid", "cplanes"], {"grid"}))  # C-planes' fast case: reflection
def test_transmission_within_one_percent_and_three_sigma(geometry):
    truth = Truth(rho=0.4, b=0.2, A=1.5, sx=0.08, sy=0.08)
    _check(table(truth, geometry, INCIDENCES, side="transmission"), truth, "transmission")


def test_noisy_grid_truth_within_three_sigma():
    truth = TRUTHS["both"]
    results = hemispherical(table(truth, "grid", INCIDENCES, relative_std=0.02, noise=0.02, seed=4))
    for r in results:
        assert abs(float(r.value[0]) - truth.tis(r.theta_i)) < 3 * float(r.std[0])


def test_every_record_enters_off_the_arcs():
    """A record off the two arcs changes the value (it used to be ignored)."""
    ds = table(TRUTHS["anisotropic_body"], "grid", (20.0,))
    base = float(hemispherical(ds)[0].value[0])
    other = np.flatnonzero(ds["arc"].values == "other")
    bumped = ds.copy(deep=True)
    bumped["bsdf"].values[other[::7], 0] *= 3.0
    assert float(hemispherical(bumped)[0].value[0]) > base * 1.01


def test_unmeasurable_cases_are_stated():
    lobe = hemispherical(table(TRUTHS["elliptical_lobe"], "cplanes", (20.0,)))[0]
    assert any("in-plane arc only" in a for a in lobe.assumptions)
    gap = hemispherical(table(TRUTHS["anisotropic_body"], "multiplane", (50.0,)))[0]
    assert any("unmeasured" in a and "error bar: the body over the gaps" in a for a in gap.assumptions)


@pytest.mark.parametrize("name", fast_lane(["anisotropic_body", "both"], {"both"}))
def test_azimuth_gap_of_an_anisotropic_body_is_in_the_error_bar(name):
    """Planes through the specular point leave azimuths near the normal unmeasured: the value assumes the body
    symmetric there (+1.3 % at 20 deg, +8.9 % at 50 deg for a cos 2φ body of 30 %), and the error bar takes the
    body's azimuthal variation measured where the planes cover it: the truth within 3 σ at every incidence."""
    truth = TRUTHS[name]
    for r in hemispherical(table(truth, "multiplane", INCIDENCES)):
        assert abs(float(r.value[0]) - truth.tis(r.theta_i)) < 3 * float(r.std[0]), r.theta_i


@pytest.mark.parametrize("name", fast_lane(["anisotropic_body", "both", "broad_lobe"], {"both"}))
def test_two_arcs_anisotropic_body_is_in_the_error_bar(name):
    """Two arcs see a body's anisotropy as a perpendicular arc that departs from the in-plane body at the same
    distance from the normal (+7.9 % at 20 deg, +21 % at 50 deg for a cos 2φ body of 30 %): the departure, noise
    removed, scales the whole body in the error bar and is stated; an isotropic body gets no such term."""
    truth = TRUTHS[name]
    for r in hemispherical(table(truth, "two_arcs", INCIDENCES)):
        assert abs(float(r.value[0]) - truth.tis(r.theta_i)) < 3 * float(r.std[0]), r.theta_i
        assert any("perpendicular arc departs" in a for a in r.assumptions)
    for r in hemispherical(table(TRUTHS["isotropic"], "two_arcs", INCIDENCES, noise=0.01, seed=2)):
        assert float(r.components.get("anisotropy", [0.0])[0]) < 3e-3 * float(r.value[0]), r.theta_i


def test_azimuth_gap_term_is_small_for_an_isotropic_body():
    """The gap term measures anisotropy, not sampling: an isotropic body's gap term is below 0.1 % of the value."""
    for r in hemispherical(table(TRUTHS["isotropic"], "multiplane", (20.0, 50.0))):
        assert float(r.components["azimuth_gap"][0]) < 1e-3 * float(r.value[0])


def test_cplane_nadirs_merged_and_conflicts_said():
    """The nadir of every C-plane is one direction: merged, not refused; duplicates that disagree are said."""
    ds = table(TRUTHS["isotropic"], "cplanes", (20.0,))
    nadir = np.flatnonzero(ds["theta_s"].values == 0.0)
    assert nadir.size == 6
    r = hemispherical(ds)[0]
    assert not r.warnings
    bad = ds.copy(deep=True)
    bad["bsdf"].values[nadir[2], 0] *= 1.5
    warned = hemispherical(bad)[0].warnings
    assert len(warned) == 1 and "measured 6 times" in warned[0] and "beyond their uncertainties" in warned[0]


@pytest.mark.parametrize("geometry", ["grid", "cplanes", "two_arcs"])
def test_the_exported_function_integrates_to_the_reported_value(geometry):
    """What a table samples (ElasticSource.fn) integrates to what tis reports (one reconstruction)."""
    ds = table(TRUTHS["broad_lobe"], geometry, (20.0, 50.0))
    src = elastic_source(ds, ["reflection"])
    for t, value in zip(src.incidences_deg["reflection"], src.tis["reflection"]):
        direct = grids.tis_reference(src.fn, t, "reflection")
        assert direct == pytest.approx(value, rel=2e-3)
