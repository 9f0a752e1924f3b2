"""Frames: round trips to 1e-12 (hypothesis) and known points (docs/reductions.md, docs/exports.md)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsdfkit.core import frames
from bsdfkit.core.errors import ValidationError

TOL = 1e-12
DEG = np.pi / 180.0

unit = st.floats(0.0, 1.0, allow_nan=False)
theta_any = st.floats(0.0, np.pi, allow_nan=False)  # both hemispheres
phi_any = st.floats(0.0, 2.0 * np.pi, allow_nan=False, exclude_max=True)
theta_inc = st.floats(0.0, 89.0 * DEG, allow_nan=False)


def angle_diff(a, b):
    """Smallest signed difference of two angles (radians)."""
    return np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))


@settings(max_examples=300, deadline=None)
@given(theta=theta_any, phi=phi_any)
def test_angles_direction_round_trip(theta, phi):
    v = frames.direction_from_angles(theta, phi)
    assert abs(np.linalg.norm(v) - 1.0) < TOL
    t2, p2 = frames.angles_from_direction(v)
    assert np.linalg.norm(frames.direction_from_angles(t2, p2) - v) < TOL
    assert abs(t2 - theta) < TOL
    if np.sin(theta) > 1e-3:  # azimuth is defined (and well conditioned) off the poles
        assert abs(angle_diff(p2, phi)) < TOL


def test_poles_and_antipode_have_zero_azimuth():
    theta, phi = frames.angles_from_direction(np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 2.0]]))
    np.testing.assert_array_equal(theta, [0.0, np.pi, 0.0])
    np.testing.assert_array_equal(phi, [0.0, 0.0, 0.0])
    # precision near the pole: acos would give ~1e-8 here
    theta, _ = frames.angles_from_direction(frames.direction_from_angles(1e-9, 0.3))
    assert abs(theta - 1e-9) < 1e-20


@settings(max_examples=300, deadline=None)
@given(theta=theta_any, phi=phi_any, theta_i=theta_inc)
def test_harvey_shack_round_trip_both_hemispheres(theta, phi, theta_i):
    v_front = frames.direction_from_angles(theta, phi)
    side = "transmission" if v_front[2] < 0 else "reflection"
    v = frames.to_side_frame(v_front, side)
    assert v[2] >= 0
    rho, psi = frames.harvey_shack_from_direction(v, theta_i)
    back = frames.to_side_frame(frames.direction_from_harvey_shack(rho, psi, theta_i), side)
    # omega_z = sqrt(1 - |beta|^2) is ill-conditioned at grazing angles: delta z ~ eps / z
    if abs(v[2]) > 1e-3:
        assert np.linalg.norm(back - v_front) < TOL
    else:
        assert np.linalg.norm(back[:2] - v_front[:2]) < TOL
    # and the other way round, (rho, psi) -> direction -> (rho, psi)
    rho2, psi2 = frames.harvey_shack_from_direction(frames.direction_from_harvey_shack(rho, psi, theta_i), theta_i)
    assert abs(rho2 - rho) < TOL
    if rho > 1e-3:
        assert abs(angle_diff(psi2, psi)) < TOL


@settings(max_examples=300, deadline=None)
@given(theta=theta_any, phi=phi_any, theta_i=theta_inc)
def test_specular_round_trip_both_hemispheres(theta, phi, theta_i):
    v = frames.direction_from_angles(theta, phi)
    radial, azimuth = frames.specular_from_direction(v, theta_i)
    assert 0.0 <= radial <= np.pi and 0.0 <= azimuth < 2 * np.pi
    assert np.linalg.norm(frames.direction_from_specular(radial, azimuth, theta_i) - v) < TOL
    r2, a2 = frames.specular_from_direction(frames.direction_from_specular(radial, azimuth, theta_i), theta_i)
    assert abs(r2 - radial) < TOL
    if 1e-3 < radial < np.pi - 1e-3:
        assert abs(angle_diff(a2, azimuth)) < TOL


@settings(max_examples=300, deadline=None)
@given(theta_r=theta_inc, gamma=st.floats(-np.pi, np.pi, allow_nan=False),
       epsilon=st.floats(-89.9 * DEG, 89.9 * DEG, allow_nan=False))
def test_instrument_round_trip(theta_r, gamma, epsilon):
    g = frames.sample_from_instrument(theta_r, gamma, epsilon)
    back = frames.instrument_from_sample(g.theta_i, g.theta_s, g.phi_s, g.transmission)
    assert abs(back.theta_r - theta_r) < TOL
    assert abs(back.epsilon - epsilon) < TOL
    assert abs(angle_diff(back.gamma, gamma)) < TOL
    # closed forms of the front frame (docs/reductions.md)
    cos_front = np.cos(epsilon) * np.cos(gamma - theta_r)
    assert bool(g.transmission) == (cos_front < 0)
    assert abs(np.cos(g.theta_s) - abs(cos_front)) < TOL
    assert g.phi_i == pytest.approx(np.pi)


@settings(max_examples=200, deadline=None)
@given(theta_i=theta_inc, theta=theta_any, phi=phi_any)
def test_sample_to_instrument_to_sample(theta_i, theta, phi):
    transmission = theta > np.pi / 2
    theta_s = np.pi - theta if transmission else theta
    inst = frames.instrument_from_sample(theta_i, theta_s, phi, transmission)
    g = frames.sample_from_instrument(inst.theta_r, inst.gamma, inst.epsilon)
    v = frames.direction_from_angles(theta_s, phi)
    v2 = frames.direction_from_angles(g.theta_s, g.phi_s)
    assert np.linalg.norm(v2 - v) < TOL
    if abs(np.cos(theta_s)) > 1e-9:
        assert bool(g.transmission) == bool(transmission)


# ------------------------------------------------------------------------------------------------
# known points
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta_i_deg", [0.0, 10.0, 45.0, 80.0])
def test_specular_point_in_all_frames(theta_i_deg):
    ti = theta_i_deg * DEG
    r0 = frames.specular_direction(ti)
    np.testing.assert_allclose(r0, [np.sin(ti), 0.0, np.cos(ti)], atol=1e-15)
    rho, psi = frames.harvey_shack_from_direction(r0, ti)
    assert rho == pytest.approx(0.0, abs=1e-15) and psi == 0.0
    radial, _ = frames.specular_from_direction(r0, ti)
    assert radial == pytest.approx(0.0, abs=1e-15)
    # instrument: in-plane detector at gamma = 2 theta_r sees the specular direction
    g = frames.sample_from_instrument(ti, 2 * ti, 0.0)
    assert g.theta_s == pytest.approx(ti, abs=1e-15) and g.phi_s == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("theta_i_deg", [5.0, 30.0, 60.0, 85.0])
def test_normal_is_radial_theta_spec_azimuth_zero(theta_i_deg):
    ti = theta_i_deg * DEG
    radial, azimuth = frames.specular_from_direction(np.array([0.0, 0.0, 1.0]), ti)
    assert radial == pytest.approx(ti, abs=1e-14)
    assert azimuth == pytest.approx(0.0, abs=1e-14)
    # beyond the specular direction (away from the normal) the azimuth is 180 deg
    _, away = frames.specular_from_direction(frames.direction_from_angles(ti + 0.1, 0.0), ti)
    assert away == pytest.approx(np.pi, abs=1e-14)


def test_specular_azimuth_matches_ansys_formula_and_is_counter_clockwise():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(200, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    t0 = 35 * DEG
    _, az = frames.specular_from_direction(v, t0)
    ansys = np.mod(np.arctan2(-v[:, 1], -v[:, 0] * np.cos(t0) + v[:, 2] * np.sin(t0)), 2 * np.pi)
    np.testing.assert_allclose(angle_diff(az, ansys), 0.0, atol=1e-13)
    e1, e2, r0 = frames.specular_axes(t0)
    np.testing.assert_allclose(np.cross(e1, e2), r0, atol=1e-15)  # right-handed: counter-clockwise about r0


def test_normal_incidence_uses_sample_x_axis():
    r = 20 * DEG
    _, a_x = frames.specular_from_direction(frames.direction_from_angles(r, 0.0), 0.0)
    _, a_y = frames.specular_from_direction(frames.direction_from_angles(r, np.pi / 2), 0.0)
    assert a_x == pytest.approx(0.0, abs=1e-15)
    assert a_y == pytest.approx(np.pi / 2, abs=1e-15)


def test_harvey_shack_in_plane_and_perpendicular_plane():
    ti, ts = 30 * DEG, 50 * DEG
    rho, psi = frames.harvey_shack_from_direction(frames.direction_from_angles(ts, 0.0), ti)
    assert rho == pytest.approx(abs(np.sin(ts) - np.sin(ti)), abs=1e-15) and psi == 0.0
    rho, psi = frames.harvey_shack_from_direction(frames.direction_from_angles(ts, np.pi), ti)
    assert rho == pytest.approx(np.sin(ts) + np.sin(ti), abs=1e-15) and psi == pytest.approx(np.pi)
    # docs/reductions.md: perpendicular scan through the specular point (gamma = 2 theta_r)
    eps = 25 * DEG
    g = frames.sample_from_instrument(ti, 2 * ti, eps)
    rho, _ = frames.harvey_shack_from_direction(frames.direction_from_angles(g.theta_s, g.phi_s), ti)
    expected = np.hypot(np.sin(ti) * (1 - np.cos(eps)), np.sin(eps))
    assert rho == pytest.approx(expected, abs=1e-15)


def test_transmission_frame_shares_beta0():
    ti = 40 * DEG
    direct = np.array([np.sin(ti), 0.0, -np.cos(ti)])  # straight through a plate, front frame
    back = frames.to_side_frame(direct, "transmission")
    np.testing.assert_allclose(back, frames.specular_direction(ti), atol=1e-15)
    g = frames.sample_from_instrument(ti, np.pi, 0.0)  # detector opposite the source
    assert g.transmission and g.theta_s == pytest.approx(ti) and g.phi_s == pytest.approx(0.0, abs=1e-15)


def test_beta_outside_unit_disk_is_an_error():
    with pytest.raises(ValidationError, match="unit disk"):
        frames.direction_from_beta(np.array([0.8, 0.8]))
    with pytest.raises(ValidationError, match="side"):
        frames.to_side_frame(np.array([0.0, 0.0, 1.0]), "front")
    # rounding excursions are clamped onto the horizon
    v = frames.direction_from_beta(np.array([1.0 + 1e-13, 0.0]))
    assert v[2] == 0.0 and v[0] == pytest.approx(1.0)
