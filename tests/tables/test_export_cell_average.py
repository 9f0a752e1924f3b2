"""Harvey–Shack tables of cell averages (issue #25.3, bsdfkit.tables.grids.harvey_shack_cell_grid): a table that
integrates, by its format's own rule, to the BSDF's own TIS on any axes, however coarse; point samples reach that
only on grids fine enough to resolve the lobe."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.core import frames
from bsdfkit.tables import grids
from bsdfkit.tables.export import ExportSettings, export

THETA = np.array([0.0, 30.0, 60.0])
A, SIGMA = 50.0, 0.02  # Gaussian lobe in |β − β0| [1/sr]; TIS = 2πσ²A inside the disk (closed form)
GAUSS_TIS = 2.0 * np.pi * SIGMA**2 * A
COARSE = grids.HarveyShackAxes((0.0, 0.01, 0.03, 0.1, 0.3, 0.6, 1.0, 1.5, 2.0), tuple(np.arange(24) * 15.0), 270.0)


def gaussian(theta_i_deg, side, directions):
    distance, _ = frames.harvey_shack_from_direction(directions, np.radians(theta_i_deg))
    return A * np.exp(-(distance**2) / (2.0 * SIGMA**2))


def lambertian(theta_i_deg, side, directions):
    return np.full(directions.shape[:-1], 0.3 / np.pi)


def _tis(values, axes):
    return grids.tis_harvey_shack_table(values, axes.rho, axes.azimuth_deg, THETA, axes.zero_azimuth_deg)[0]


def test_cell_averages_keep_the_tis_of_a_lobe_the_grid_does_not_resolve():
    """9 radii, the lobe's 1/e² radius (2σ = 0.04) spanning two cells: the averaged table's TIS is the closed form
    to 1e-3 (the Gauss points per cell: 3.5e-4), the point-sampled table misses it by more than 10 %."""
    cell = grids.harvey_shack_cell_grid(gaussian, THETA, "reflection", COARSE).values
    point = grids.harvey_shack_grid(gaussian, THETA, "reflection", COARSE).values
    np.testing.assert_allclose(_tis(cell, COARSE), GAUSS_TIS, rtol=1e-3)
    assert np.all(np.abs(_tis(point, COARSE) / GAUSS_TIS - 1.0) > 0.1)


def test_cell_averages_of_a_constant_integrate_exactly_and_nodes_outside_the_disk_hold_zero():
    """Away from the disk's edge every node holds the constant; the row's last nodes take up the difference
    between the disk and the rule's edge (the trapezoid rule between rows), so the TIS stays exact."""
    cell = grids.harvey_shack_cell_grid(lambertian, THETA, "reflection", COARSE).values[0]
    rho = np.asarray(COARSE.rho)
    edge = grids.rho_max(THETA[:, None, None], np.asarray(COARSE.azimuth_deg)[None, None, :] + 270.0)
    inside = rho[None, :, None] <= edge
    # two segments or more from every row's edge
    interior = np.broadcast_to(rho[None, :, None] <= edge.min(axis=-1, keepdims=True) - 0.35, cell.shape)
    np.testing.assert_allclose(cell[interior], 0.3 / np.pi, rtol=1e-12)
    assert np.all(cell[inside] > 0.0)
    assert np.all(cell[~inside] == 0.0)
    np.testing.assert_allclose(_tis(cell[None], COARSE), 0.3, rtol=1e-12)


def test_row_weights_are_the_table_quadrature():
    """Σ W·f over the nodes is tis_harvey_shack_table of f, for arbitrary node values (the rule is linear)."""
    rng = np.random.default_rng(3)
    f = rng.uniform(0.0, 2.0, (1, THETA.size, len(COARSE.rho), len(COARSE.azimuth_deg)))
    for t, theta in enumerate(THETA):
        w = grids.harvey_shack_row_weights(np.asarray(COARSE.rho), np.asarray(COARSE.azimuth_deg), float(theta),
                                           270.0)
        assert np.sum(w.T * f[0, t]) == pytest.approx(_tis(f, COARSE)[t], rel=1e-12)


@pytest.mark.parametrize("to", ["tracepro", "asap"])
def test_cell_averages_on_given_axes_pass_the_tis_check_where_point_samples_fail(tmp_path, to):
    """On the coarse axes, written as cell averages (ExportSettings.node_values), the file read back as bsdfkit
    read integrates it keeps the closed-form TIS within 0.5 %; point samples on the same axes miss it by > 10 %."""
    axes = COARSE if to == "tracepro" else grids.HarveyShackAxes(COARSE.rho, COARSE.azimuth_deg, 0.0)
    cell = export(gaussian, to, "", "reflection", tmp_path / "cell",
                  settings=ExportSettings(theta_i_deg=(0.0, 30.0), harvey_shack_axes=axes, node_values="cell"))
    point = export(gaussian, to, "", "reflection", tmp_path / "point",
                   settings=ExportSettings(theta_i_deg=(0.0, 30.0), harvey_shack_axes=axes, node_values="point"))
    assert cell.grid["values"] == "cell averages" and point.grid["values"] == "point samples"
    np.testing.assert_allclose(cell.tis_table["reflection"], GAUSS_TIS, rtol=5e-3)
    assert np.all(np.abs(np.asarray(point.tis_table["reflection"]) / GAUSS_TIS - 1.0) > 0.1)
