"""Issue #25: exported tables of the Radiant file and of the ansys scan, with `bsdfkit convert` defaults, pass their
TIS check; their sizes are recorded (docs/exports.md, "Grid resolution"). Edge values and the bulk marking of the
auto grids are checked on closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.tables import grids
from bsdfkit.tables.export import ExportSettings
from bsdfkit.tables.registry import WRITABLE
from bsdfkit.tables.to_dataset import convert

DATA = "tests/data/ansys-radiant-zemax-bsdf/"
RADIANT = DATA + "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"
ANSYS = DATA + "inplane_spectral_goniometric_2D_data.csv"
#: 1 MB
LIMIT = 1_000_000
#: pairs above the limit with `convert` defaults (point samples): the Radiant file's Harvey–Shack tables, auto grid
#: 76 x 84 nodes for 13 incidences (measured 3,082,907 and 2,087,107 bytes; before issue #25 the fixed grid, 7.47 and
#: 5.34 MB; docs/exports.md §6, "Falls short"); with --node-values edge they are checked below
OVER = {("radiant", "tracepro"): 3_200_000, ("radiant", "asap"): 2_200_000}


def test_edge_values_integrate_the_strip_to_the_disks_edge():
    """A BSDF rising linearly toward the horizon: point samples held from the last node to the edge miss the strip;
    edge values make the rule integrate each row as the source does (to the row's Gauss points), a constant stays."""
    def ramp(theta_i, side, d):
        return 0.1 + 0.5 * np.hypot(d[..., 0], d[..., 1])

    axes = grids.HarveyShackAxes((0.0, 0.3, 0.6, 0.9, 1.2, 1.5, 1.8), tuple(np.arange(24) * 15.0), 0.0)
    theta = (0.0, 40.0)
    point = grids.harvey_shack_grid(ramp, theta, "reflection", axes)
    edge = grids.harvey_shack_edge_grid(ramp, theta, "reflection", axes)
    exact = np.array([grids.tis_reference(ramp, t, "reflection") for t in theta])
    rho, psi = np.asarray(axes.rho), np.asarray(axes.azimuth_deg)
    t_point = grids.tis_harvey_shack_table(point.values[0], rho, psi, theta)
    t_edge = grids.tis_harvey_shack_table(edge.values[0], rho, psi, theta)
    assert np.all(np.abs(t_point / exact - 1.0) > 0.005)  # measured 1.1 % (0 deg), 0.77 % (40 deg)
    # at normal incidence every row is the same: the edge values make the rule exact; at 40 deg the trapezoid rule in
    # azimuth between rows of different lengths remains (measured +0.56 %)
    assert t_edge[0] == pytest.approx(exact[0], rel=1e-6)
    assert abs(t_edge[1] / exact[1] - 1.0) < 0.006
    const = grids.harvey_shack_edge_grid(lambda t, s, d: np.full(d.shape[:-1], 0.3), theta, "reflection", axes)
    inside = grids.harvey_shack_grid(lambda t, s, d: np.ones(d.shape[:-1]), theta, "reflection", axes).values > 0
    np.testing.assert_allclose(const.values[inside], 0.3, rtol=1e-12)


def test_bulk_marking_marks_the_largest_share_and_its_ties():
    flag = grids.bulk_marking([[5.0, 1.0, 1.0, 3.0, 0.0]], share=0.5)
    assert flag.tolist() == [True, False, False, False, False]
    flag = grids.bulk_marking([[5.0, 1.0, 1.0, 3.0, 0.0]], share=0.6)
    assert flag.tolist() == [True, False, False, True, False]
    # a symmetric block keeps symmetric marks; blocks add their marks
    assert grids.bulk_marking([[1.0, 4.0, 4.0, 1.0]], share=0.3).tolist() == [False, True, True, False]
    assert grids.bulk_marking([[4.0, 0.0, 0.0], [0.0, 0.0, 4.0]]).tolist() == [True, False, True]


@pytest.mark.slow
@pytest.mark.parametrize("to", WRITABLE)
@pytest.mark.parametrize("source", ["radiant", "ansys"])
def test_exported_tables_pass_their_tis_check_within_a_megabyte(tmp_path, source, to):
    """`bsdfkit convert` defaults: the re-read TIS within the check (1 %) and the file at most 1 MB, but for the
    Radiant file's TracePro and ASAP-style tables (:data:`OVER`; below, the edge-value variant)."""
    out = tmp_path / f"{source}.{to}"
    if source == "radiant":
        result = convert(RADIANT, to, out)
    else:
        result = convert(ANSYS, to, out, wavelength_nm=550.0, quantity="reflectance-factor")
    assert result.ok, (result.worst_relative_difference, result.export.grid)
    assert result.export.size_bytes == out.stat().st_size
    assert result.export.size_bytes <= OVER.get((source, to), LIMIT), result.export.grid


@pytest.mark.slow
@pytest.mark.parametrize("to, limit", [("tracepro", 1_250_000), ("asap", LIMIT)])
def test_radiant_harvey_shack_tables_with_edge_values(tmp_path, to, limit):
    """--node-values edge: the Radiant file's auto table passes its TIS check within issue #23's 0.5 % (measured
    0.31 %); ASAP-style 817,936 bytes, TracePro 1,223,428 bytes (above 1 MB: docs/exports.md §6)."""
    settings = ExportSettings(node_values="edge", grid_tolerance=grids.GridTolerance(tis_rtol=0.005))  # as convert's
    result = convert(RADIANT, to, tmp_path / to, settings=settings)
    assert result.ok and result.worst_relative_difference < 0.005, result.export.grid
    assert result.export.grid["mode"] == "auto" and result.export.size_bytes <= limit
