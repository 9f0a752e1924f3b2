"""Grids from BSDF callables and the TIS quadratures of the table readers (formats.md §1, §6)."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.core import frames
from bsdfkit.core.errors import ValidationError
from bsdfkit.models.functions import tis_abg_normal_incidence
from bsdfkit.tables import grids


def lambert(rho):
    return lambda theta_i_deg, side, d: np.full(d.shape[:-1], rho / np.pi)


def gaussian(a, sigma):
    def fn(theta_i_deg, side, d):
        r, _ = frames.harvey_shack_from_direction(d, np.radians(theta_i_deg))
        return a * np.exp(-(r**2) / (2 * sigma**2))

    return fn


def abg(a, b, g):
    def fn(theta_i_deg, side, d):
        r, _ = frames.harvey_shack_from_direction(d, np.radians(theta_i_deg))
        return a / (b + r**g)

    return fn


ABG_CHECKED = [((0.0025, 0.001, 1.8), 0.041344), ((0.01, 0.01, 2.0), 0.144988), ((0.001, 1e-4, 2.5), 0.072190)]


@pytest.mark.parametrize(("params", "tis"), ABG_CHECKED)
def test_abg_closed_form_and_reference_integral(params, tis):
    assert tis_abg_normal_incidence(*params) == pytest.approx(tis, abs=5e-7)
    assert grids.tis_reference(abg(*params), 0.0, "reflection") == pytest.approx(tis, abs=5e-7)


def test_reference_integral_other_closed_forms():
    assert tis_abg_normal_incidence(0.01, 0.5, 0.0) == pytest.approx(np.pi * 0.01 / 1.5)
    assert tis_abg_normal_incidence(0.01, 0.01, 2.0) == pytest.approx(np.pi * 0.01 * np.log(1 + 1 / 0.01))
    # formats.md §6: (0.0025, 0.001, 1.8) falls to 0.0326 at 60 deg (unit-disk clipping)
    assert grids.tis_reference(abg(0.0025, 0.001, 1.8), 60.0, "reflection") == pytest.approx(0.0326, abs=5e-5)
    for theta in (0.0, 45.0, 85.0):
        assert grids.tis_reference(lambert(0.3), theta, "transmission") == pytest.approx(0.3, rel=1e-12)
    assert grids.tis_reference(gaussian(2.0, 0.05), 20.0, "reflection") == pytest.approx(
        2 * np.pi * 0.05**2 * 2.0, rel=1e-10)


def test_default_axes():
    hs = grids.HarveyShackAxes.default()
    rho = np.asarray(hs.rho)
    assert rho[0] == 0.0 and rho[1] == pytest.approx(1e-3) and rho[-1] == 2.0
    assert np.all(np.diff(rho) <= 0.025 + 1e-12)
    ratios = rho[2:][: 50] / rho[1:][: 50]
    np.testing.assert_allclose(ratios, 1.05)
    assert len(hs.azimuth_deg) == 72 and hs.azimuth_deg[-1] == 355.0
    sp = grids.SpecularAxes.default()
    assert sp.radial_deg[0] == 0.0 and sp.radial_deg[-1] == 180.0
    assert sp.azimuth_deg[0] == 0.0 and sp.azimuth_deg[-1] == 180.0 and len(sp.azimuth_deg) == 37
    assert grids.SpecularAxes.default(plane_symmetric=False).azimuth_deg[-1] == 355.0


@pytest.mark.parametrize(
    "bad",
    [dict(rho=(0.1, 0.5), azimuth_deg=(0.0,)), dict(rho=(0.0, 0.5, 0.4), azimuth_deg=(0.0,)),
     dict(rho=(0.0, 2.5), azimuth_deg=(0.0,)), dict(rho=(0.0, 1.0), azimuth_deg=(0.0, 360.0))],
)
def test_invalid_axes_are_refused(bad):
    with pytest.raises(ValidationError):
        grids.HarveyShackAxes(**bad)


def test_harvey_shack_grid_nodes_and_zero_outside_disk():
    axes = grids.HarveyShackAxes((0.0, 0.5, 1.0, 1.5, 2.0), (0.0, 90.0, 180.0, 270.0), zero_azimuth_deg=270.0)

    def forwardness(theta_i_deg, side, d):  # 1 + beta_x: distinguishes forward from backward nodes
        return 1.0 + d[..., 0]

    g = grids.harvey_shack_grid(forwardness, [30.0], ["reflection"], axes)
    assert g.dims == ("side", "theta_i", "rho", "psi")
    v = g.sel(side="reflection", theta_i=30.0)
    # table psi 90 = sample psi 0 (forward, +x): beta = (0.5 + rho, 0) -> inside up to rho 0.5
    np.testing.assert_allclose(v.sel(psi=90.0).values, [1.5, 2.0, 0.0, 0.0, 0.0], atol=1e-12)
    # table psi 270 = sample psi 180 (toward the source): beta = (0.5 - rho, 0) -> inside up to rho 1.5
    np.testing.assert_allclose(v.sel(psi=270.0).values, [1.5, 1.0, 0.5, 0.0, 0.0], atol=1e-12)
    # table psi 0 = sample -y: beta = (0.5, -rho) -> inside while rho <= sqrt(0.75)
    np.testing.assert_allclose(v.sel(psi=0.0).values, [1.5, 1.5, 0.0, 0.0, 0.0], atol=1e-12)


def test_specular_grid_zero_below_horizon():
    axes = grids.SpecularAxes((0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0), (0.0, 90.0, 180.0))
    g = grids.specular_grid(lambert(0.1), [40.0], "reflection", axes).values[0, 0]
    f = 0.1 / np.pi
    np.testing.assert_allclose(g[0], [f, f, f, f, f, 0, 0])  # toward the normal: horizon at 130 deg
    np.testing.assert_allclose(g[1], [f, f, f, f, 0, 0, 0])  # sideways: horizon at 90 deg
    np.testing.assert_allclose(g[2], [f, f, 0, 0, 0, 0, 0])  # away from the normal: horizon at 50 deg


@pytest.mark.parametrize("theta", [0.0, 20.0, 50.0, 70.0])
def test_table_quadratures_exact_for_lambertian(theta):
    hs = grids.HarveyShackAxes((0.0, 0.3, 0.7, 1.2, 2.0), tuple(np.arange(0, 360, 30.0)))
    g = grids.harvey_shack_grid(lambert(0.2), [theta], "reflection", hs)
    tis = grids.tis_harvey_shack_table(g.values, hs.rho, hs.azimuth_deg, [theta])
    assert tis[0, 0] == pytest.approx(0.2, rel=1e-12)
    sp = grids.SpecularAxes.default()
    z = grids.specular_grid(lambert(0.2), [theta], "reflection", sp)
    tis = grids.tis_specular_table(z.values, sp.radial_deg, sp.azimuth_deg, [theta], True)
    assert tis[0, 0] == pytest.approx(0.2, rel=1e-12)


def test_specular_quadrature_of_a_coarse_table_by_hand():
    # constant f on radial 0..180 step 30, azimuths 0/90/180 (mirrored: 0/90/180/270), theta0 = 40 deg:
    # G(a) = f [cos t0 sin^2(r_h)/2 + cos a sin t0 (r_h/2 - sin(2 r_h)/4)], r_h = 130/90/50 deg,
    # TIS = (pi/2) [G(0) + 2 G(90) + G(180)]
    t0, f = np.radians(40.0), 0.1 / np.pi
    rh = np.radians([130.0, 90.0, 50.0])
    ca = np.array([1.0, 0.0, -1.0])
    G = f * (np.cos(t0) * np.sin(rh) ** 2 / 2 + ca * np.sin(t0) * (rh / 2 - np.sin(2 * rh) / 4))
    expected = np.pi / 2 * (G[0] + 2 * G[1] + G[2])
    axes = grids.SpecularAxes((0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.0), (0.0, 90.0, 180.0))
    g = grids.specular_grid(lambert(0.1), [40.0], "reflection", axes)
    tis = grids.tis_specular_table(g.values, axes.radial_deg, axes.azimuth_deg, [40.0], True)
    assert tis[0, 0] == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.09904, abs=1e-5)


@pytest.mark.parametrize("fn", [gaussian(2.0, 0.05), gaussian(10.0, 0.02), abg(0.0025, 0.001, 1.8),
                                abg(0.001, 1e-4, 2.5)])
def test_default_grids_resolve_peaked_lobes(fn):
    thetas = [0.0, 45.0, 75.0]
    ref = np.array([grids.tis_reference(fn, t, "reflection") for t in thetas])
    hs = grids.HarveyShackAxes.default()
    g = grids.harvey_shack_grid(fn, thetas, "reflection", hs)
    tis_hs = grids.tis_harvey_shack_table(g.values[0], hs.rho, hs.azimuth_deg, thetas)
    sp = grids.SpecularAxes.default()
    z = grids.specular_grid(fn, thetas, "reflection", sp)
    tis_sp = grids.tis_specular_table(z.values[0], sp.radial_deg, sp.azimuth_deg, thetas, True)
    np.testing.assert_allclose(tis_hs, ref, rtol=2.5e-3)
    np.testing.assert_allclose(tis_sp, ref, rtol=2.5e-3)


def test_bad_callables_are_named_errors():
    with pytest.raises(ValidationError, match="negative"):
        grids.tis_reference(lambda t, s, d: -np.ones(d.shape[:-1]), 0.0, "reflection")
    with pytest.raises(ValidationError, match="non-finite"):
        grids.tis_reference(lambda t, s, d: np.full(d.shape[:-1], np.nan), 10.0, "reflection")
    with pytest.raises(ValidationError, match="wrong shape"):
        grids.tis_reference(lambda t, s, d: np.ones(3), 10.0, "reflection")
    with pytest.raises(ValidationError, match="theta_i"):
        grids.harvey_shack_grid(lambert(0.1), [95.0], "reflection", grids.HarveyShackAxes.default())
    with pytest.raises(ValidationError, match="side"):
        grids.specular_grid(lambert(0.1), [10.0], "sideways", grids.SpecularAxes.default())
