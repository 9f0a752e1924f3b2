"""Detector geometry: exact aperture solid angle and its quadrature."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsdfkit.core.errors import ValidationError
from bsdfkit.measurement.calibrate import aperture_solid_angle, aperture_solid_angle_small
from bsdfkit.measurement.instrument import Instrument, aperture_quadrature


@given(d=st.floats(1.0, 5000.0), a=st.floats(1e-3, 1000.0))
@settings(max_examples=200, deadline=None)
def test_solid_angle_equals_cone_formula(d, a):
    # to 1e-12 absolute (the reference form itself loses relative precision for tiny a/d)
    exact = 2 * np.pi * (1 - np.cos(np.arctan(a / d)))
    assert abs(aperture_solid_angle(d, a) - exact) < 1e-12


def test_solid_angle_paper_geometry_and_small_angle_difference():
    # §2 of the power-budget paper: 25.4 mm aperture at 886 mm.
    d, a = 886.0, 12.7
    exact = aperture_solid_angle(d, a)
    assert abs(exact - 2 * np.pi * (1 - np.cos(np.arctan(a / d)))) < 1e-12
    small = aperture_solid_angle_small(d, a)
    # small-angle form over-estimates by (3/4)(a/d)^2 to leading order (docs/raw-format.md, measurement equation)
    rel = small / exact - 1
    assert rel > 0
    assert rel == pytest.approx(0.75 * (a / d) ** 2, rel=1e-3)
    # at a/d = 0.1 the difference is 0.75 %
    assert aperture_solid_angle_small(1.0, 0.1) / aperture_solid_angle(1.0, 0.1) - 1 == pytest.approx(0.0075, rel=0.01)


def test_quadrature_weights_sum_to_solid_angle():
    inst = Instrument(886.0, 25.4, 14.0)
    q = aperture_quadrature(np.radians([0.0, 30.0, 88.0]), np.radians([0.0, 45.0, 180.0]), inst)
    assert q.weights.sum() == pytest.approx(inst.solid_angle_sr, rel=1e-12)
    assert np.allclose(np.linalg.norm(q.directions, axis=-1), 1.0)
    # every node lies within the aperture half-angle of its centre
    centre = np.array([0.0, 0.0, 1.0])
    ang = np.arccos(np.clip(q.directions[0] @ centre, -1, 1))
    assert ang.max() <= inst.half_angle_rad + 1e-12


@pytest.mark.parametrize("field,value", [("detector_distance_mm", 0.0), ("aperture_diameter_mm", -1.0),
                                         ("beam_diameter_mm", float("nan"))])
def test_instrument_rejects_bad_geometry(field, value):
    args = {"detector_distance_mm": 886.0, "aperture_diameter_mm": 25.4, "beam_diameter_mm": 14.0, field: value}
    with pytest.raises(ValidationError, match=field):
        Instrument(**args)
