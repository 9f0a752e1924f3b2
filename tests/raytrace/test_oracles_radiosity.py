"""The radiosity oracle itself: closed-form view factors, summation and reciprocity, convergence."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bsdfkit.raytrace import loads_scene
from bsdfkit.raytrace.oracles.radiosity import (
    BASE,
    TOP,
    WALL,
    cylinder_patches,
    disk_to_disk,
    element_to_disk,
    led_direct,
    module_radiosity,
    view_factors,
)

SCENE = """
[cavity]
radius_mm = 35.0
height_mm = {h}
[wall]
reflectance = {rho}
[base]
reflectance = {rho}
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
[top]
kind = "exit"
"""


def test_disk_and_element_closed_forms():
    # equal coaxial disks one radius apart: F = (3 − √5)/2 (Howell C-41)
    assert disk_to_disk(1.0, 1.0, 1.0) == pytest.approx((3 - math.sqrt(5)) / 2, rel=1e-14)
    # a vanishing first disk tends to the on-axis element factor a²/(a² + h²)
    assert disk_to_disk(1e-9, 2.0, 3.0) == pytest.approx(4.0 / 13.0, rel=1e-12)
    assert element_to_disk(0.0, 2.0, 3.0) == pytest.approx(4.0 / 13.0, rel=1e-14)
    # the element factor averaged over a disk is the disk-to-disk factor (polar midpoint rule, fine grid)
    r = (np.arange(4000) + 0.5) / 4000 * 1.5
    avg = np.sum(element_to_disk(r, 2.0, 1.0) * 2 * r) * (1.5 / 4000) / 1.5 ** 2
    assert avg == pytest.approx(disk_to_disk(1.5, 2.0, 1.0), rel=1e-6)
    # reciprocity of unequal disks
    assert 1.0 * disk_to_disk(1.0, 2.0, 0.7) == pytest.approx(4.0 * disk_to_disk(2.0, 1.0, 0.7), rel=1e-13)


@pytest.mark.parametrize("height", [10.0, 43.0, 80.0])
def test_view_factor_matrix_summation_and_reciprocity(height):
    p = cylinder_patches(35.0, height, 7, 13, 9)
    F = view_factors(p)
    A = p.area
    assert np.all(F >= -1e-15)
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-13)
    AF = A[:, None] * F
    np.testing.assert_allclose(AF, AF.T, atol=1e-12 * A.max())
    assert np.all(F[np.ix_(p.kind == BASE, p.kind == BASE)] == 0)
    assert np.all(F[np.ix_(p.kind == TOP, p.kind == TOP)] == 0)
    # whole-wall self view factor of a cylinder: 1 + H/2R − √(1 + (H/2R)²)
    w = p.kind == WALL
    x = height / 70.0
    assert np.sum(AF[np.ix_(w, w)]) / np.sum(A[w]) == pytest.approx(1 + x - math.sqrt(1 + x * x), rel=1e-12)


def test_led_direct_power_is_conserved_and_symmetric():
    s = loads_scene(SCENE.format(h=43.0, rho=0.9))
    p = cylinder_patches(35.0, 43.0, 8, 16, 8)
    D = led_direct(p, s.leds.centres(), 1.0)
    assert D.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(D[p.kind == BASE] == 0)
    # a centred emitter sees the top as an element-to-disk factor averaged over its area
    Dc = led_direct(p, [(0.0, 0.0)], 1.0)
    assert Dc[p.kind == TOP].sum() == pytest.approx(
        np.mean(element_to_disk(np.sqrt((np.arange(200) + 0.5) / 200), 35.0, 43.0)), rel=1e-5)


def test_radiosity_converges_and_balances():
    s = loads_scene(SCENE.format(h=43.0, rho=0.9))
    coarse = module_radiosity(s, 24, 48, 24)
    fine = module_radiosity(s, 48, 96, 48)
    assert abs(coarse.LER - fine.LER) < 5e-6
    assert fine.LER + fine.absorbed_wall + fine.absorbed_base + fine.absorbed_plate == pytest.approx(1.0, abs=1e-12)
    white = module_radiosity(loads_scene(SCENE.format(h=43.0, rho=1.0)))
    assert white.LER == pytest.approx(1.0, abs=1e-12)
