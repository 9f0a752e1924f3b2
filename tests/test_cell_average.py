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


def test_cell_averages_of_a_constant_are_the_constant_and_nodes_outside_the_disk_hold_zero():
    cell = grids.harvey_shack_cell_grid(lambertian, THETA, "reflection", COARSE).values[0]
    rho = np.asarray(COARSE.rho)
    edge = grids.rho_max(THETA[:, None, None], np.asarray(COARSE.azimuth_deg)[None, None, :] + 270.0)
    inside = rho[None, :, None] <= edge
    np.testing.assert_allclose(cell[inside], 0.3 / np.pi, rtol=1e-12)
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
def test_auto_export_writes_cell_averages_within_the_tis_check(tmp_path, to):
    """The auto grid of a Harvey–Shack format holds cell averages; the written file, read back as bsdfkit read
    integrates it, keeps the closed-form TIS within the grid tolerance's re-check (2 × 0.1 %), and --grid fixed
    still writes point samples."""
    res = export(gaussian, to, "", "reflection", tmp_path / "auto", settings=ExportSettings(theta_i_deg=(0.0, 30.0)))
    assert res.grid["mode"] == "auto" and res.grid["values"] == "cell averages"
    np.testing.assert_allclose(res.tis_table["reflection"], GAUSS_TIS, rtol=2e-3)
    fixed = export(gaussian, to, "", "reflection", tmp_path / "fixed",
                   settings=ExportSettings(theta_i_deg=(0.0, 30.0), grid="fixed"))
    assert fixed.grid["values"] == "point samples"
    assert res.size_bytes < fixed.size_bytes
