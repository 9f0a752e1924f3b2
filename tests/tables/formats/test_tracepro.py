"""TracePro surface-property files: golden output, export -> read TIS round trips, malformed input."""
from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from conftest import fast_lane

from bsdfkit.core import frames
from bsdfkit.core.errors import FormatError, OutputExistsError, ValidationError
from bsdfkit.tables import grids
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats import tracepro

GOLDEN = Path(__file__).parents[2] / "data" / "golden"
WHEN = datetime(2020, 1, 23, 15, 24, 9)


def normalise(text: str) -> str:
    """Blank out the timestamp line (the only line that depends on when the file was written)."""
    return re.sub(r"(?m)^Data generated at .*$", "Data generated at <time>", text)


def lambert(rho):
    return lambda theta_i_deg, side, d: np.full(d.shape[:-1], rho / np.pi)


def lobe(kind, *p):
    def fn(theta_i_deg, side, d):
        r, _ = frames.harvey_shack_from_direction(d, np.radians(theta_i_deg))
        value = p[0] * np.exp(-(r**2) / (2 * p[1] ** 2)) if kind == "gauss" else p[0] / (p[1] + r ** p[2])
        return value if side == "reflection" else 0.5 * value

    return fn


def golden_lambert_property() -> tracepro.TraceProProperty:
    """BRDF 0.1/pi and BTDF 0.05/pi on a 5 x 4 table at 0 and 30 deg: absorptance 0.85 exactly."""
    axes = grids.HarveyShackAxes((0.0, 0.5, 1.0, 1.5, 2.0), (0.0, 90.0, 180.0, 270.0), zero_azimuth_deg=270.0)

    def fn(theta_i_deg, side, d):
        return np.full(d.shape[:-1], (0.1 if side == "reflection" else 0.05) / np.pi)

    grid = grids.harvey_shack_grid(fn, [0.0, 30.0], ["reflection", "transmission"], axes)
    options = tracepro.TraceProOptions(name="golden_lambert", catalog="bsdfkit_tests",
                                       description="Lambertian R 10 % + T 5 %")
    return tracepro.table_property(grid, options=options)


def golden_abg_property() -> tracepro.TraceProProperty:
    """ABg (0.0025, 0.001, 1.8) BRDF at normal incidence with 50 % specular reflectance (formats.md §6)."""
    options = tracepro.TraceProOptions(name="golden_abg", catalog="bsdfkit_tests", description="ABg checked value")
    return tracepro.abg_property([0.0], [0.0025, 0.001, 1.8], None, options=options, specular_reflectance=0.5)


@pytest.mark.parametrize(("name", "build"), [("tracepro_lambert_table.txt", golden_lambert_property),
                                             ("tracepro_abg.txt", golden_abg_property)])
def test_golden_files_byte_for_byte(tmp_path, name, build):
    out = tracepro.write_tracepro(tmp_path / name, build(), generated_at=WHEN)
    written = out.read_bytes().decode("utf-8")
    golden = (GOLDEN / name).read_bytes().decode("utf-8")
    assert "\r\n" in written and written.count("\r\n") == written.count("\n")
    assert normalise(written) == normalise(golden)


def test_golden_lambert_hand_checked_values():
    prop = tracepro.read_tracepro(GOLDEN / "tracepro_lambert_table.txt")
    np.testing.assert_array_equal(prop.absorptance, [0.85, 0.85])  # 1 - 0.1 - 0.05
    t = prop.table.sel(theta_i=30.0)
    f_r = 0.1 / np.pi
    # beta0 = (0.5, 0); table psi 90 = forward (+x), 270 = toward the source (-x), 0/180 = -y/+y
    np.testing.assert_allclose(t.sel(side="reflection", psi=90.0).values, [f_r, f_r, 0, 0, 0], rtol=1e-6)
    np.testing.assert_allclose(t.sel(side="reflection", psi=270.0).values, [f_r, f_r, f_r, f_r, 0], rtol=1e-6)
    np.testing.assert_allclose(t.sel(side="reflection", psi=0.0).values, [f_r, f_r, 0, 0, 0], rtol=1e-6)
    tis = prop.tis_computed()
    np.testing.assert_allclose(tis["reflection"], [0.1, 0.1], rtol=1e-6)
    np.testing.assert_allclose(tis["transmission"], [0.05, 0.05], rtol=1e-6)
    assert prop.options.zero_azimuth_deg == 270.0 and prop.options.description == "Lambertian R 10 % + T 5 %"


def test_golden_abg_hand_checked_values():
    prop = tracepro.read_tracepro(GOLDEN / "tracepro_abg.txt")
    assert prop.scatter == 1
    np.testing.assert_allclose(prop.abg.sel(side="reflection").values, [[0.0025, 0.001, 1.8]])
    assert prop.absorptance[0] == pytest.approx(1 - 0.5 - 0.041344, abs=1e-6)
    assert prop.tis_computed()["reflection"][0] == pytest.approx(0.041344, abs=5e-7)
    assert prop.tis_stated()[0] == pytest.approx(0.041344, abs=1e-6)


MODELS = {
    "lambertian": lambert(0.3),
    "gaussian": lobe("gauss", 2.0, 0.05),
    "abg_1": lobe("abg", 0.0025, 0.001, 1.8),
    "abg_2": lobe("abg", 0.01, 0.01, 2.0),
    "abg_3": lobe("abg", 0.001, 1e-4, 2.5),
}
THETAS = (0.0, 30.0, 60.0, 80.0)


# fast lane: the Lambertian and the broadest ABg lobe (abg_1: 2.3x cheaper than abg_3, whose narrow lobe makes the auto
# grid refine most; the fast lane's narrow lobe: test_grids_resolution.py::test_auto_grid_of_a_narrow_lobe_...)
@pytest.mark.parametrize("model", fast_lane(sorted(MODELS), {"lambertian", "abg_1"}))
def test_export_read_tis_round_trip(tmp_path, model):
    fn = MODELS[model]
    path = tmp_path / f"{model}.txt"
    result = export(fn, "tracepro", "bibs", "both", path, settings=ExportSettings(theta_i_deg=THETAS))
    summary = read_any(path)
    assert summary.format == "tracepro" and summary.incidences_deg == list(THETAS)
    for side in ("reflection", "transmission"):
        source = np.array([grids.tis_reference(fn, t, side) for t in THETAS])
        np.testing.assert_allclose(summary.tis_computed[side], source, rtol=5e-3)
        np.testing.assert_allclose(result.tis_source[side], source, rtol=1e-12)
    # the absorptance closes the energy balance with the table's own TIS (the format's quadrature)
    np.testing.assert_allclose(summary.tis_stated["total"], summary.details["tis_format_quadrature"]["total"],
                               atol=2e-7)


def test_abg_scatter_1_round_trip(tmp_path):
    prop = tracepro.abg_property([0.0, 45.0], [[0.01, 0.01, 2.0], [0.001, 1e-4, 2.5]], [0.0025, 0.001, 1.8])
    path = tracepro.write_tracepro(tmp_path / "abg.txt", prop)
    back = tracepro.read_tracepro(path)
    tis = back.tis_computed()
    assert tis["reflection"][0] == pytest.approx(0.144988, abs=5e-7)
    assert tis["transmission"][0] == pytest.approx(0.041344, abs=5e-7)
    np.testing.assert_allclose(back.tis_stated(), tis["reflection"] + tis["transmission"], atol=2e-7)


def test_energy_above_one_is_refused_and_nothing_is_written(tmp_path):
    axes = grids.HarveyShackAxes((0.0, 1.0, 2.0), (0.0, 180.0), zero_azimuth_deg=270.0)
    grid = grids.harvey_shack_grid(lambert(0.8), [0.0], ["reflection", "transmission"], axes)
    with pytest.raises(ValidationError, match="energy balance exceeds 1 at IncAngle 0"):
        tracepro.table_property(grid)
    with pytest.raises(ValidationError, match="energy"):
        export(lambert(0.8), "tracepro", "bibs", "both", tmp_path / "x.txt",
               settings=ExportSettings(theta_i_deg=(0.0,)))
    assert not (tmp_path / "x.txt").exists()


def test_refuses_to_overwrite_without_force(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text("keep me")
    with pytest.raises(OutputExistsError):
        tracepro.write_tracepro(path, golden_lambert_property())
    assert path.read_text() == "keep me"
    tracepro.write_tracepro(path, golden_lambert_property(), force=True)
    assert path.read_text().startswith(tracepro.MAGIC)


# ------------------------------------------------------------------------------------------------
# malformed files
# ------------------------------------------------------------------------------------------------
def golden_lines() -> list[str]:
    return (GOLDEN / "tracepro_lambert_table.txt").read_text().splitlines()


def line_no(lines: list[str], prefix: str, occurrence: int = 0) -> int:
    hits = [k for k, line in enumerate(lines) if line.startswith(prefix)]
    return hits[occurrence]


def broken(tmp_path, lines: list[str]) -> Path:
    path = tmp_path / "broken.txt"
    path.write_text("\r\n".join(lines) + "\r\n")
    return path


def expect_error(path: Path, line: int, field: str, match: str = "") -> FormatError:
    with pytest.raises(FormatError) as info:
        tracepro.read_tracepro(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}:{line}: field '{field}'"), message
    assert match in message
    return info.value


def test_truncated_mid_row(tmp_path):
    lines = golden_lines()
    k = len(lines) - 6
    cut = lines[: k] + [lines[k][: lines[k].rindex("\t")]]
    expect_error(broken(tmp_path, cut), k + 1, "Temperature..BTDF", "wrong number of columns; expected 8 values, got 7")


def test_truncated_at_a_row_boundary(tmp_path):
    lines = golden_lines()[:-6]
    expect_error(broken(tmp_path, lines), len(lines), "Table_BSDF_Data", "not rectangular")


def test_missing_table_row(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t30\t0\t1\t")
    del lines[k]
    err = expect_error(broken(tmp_path, lines), len(lines) - 1, "Table_BSDF_Data", "not rectangular")
    assert "no row for IncAngle 30, ScatterBeta 1, ScatterAzimuth 0" in str(err)


def test_duplicate_table_row(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t0\t0\t0.5\t")
    lines.insert(k + 1, lines[k])
    expect_error(broken(tmp_path, lines), k + 2, "IncAngle/ScatterBeta/ScatterAzimuth", f"same cell as line {k + 1}")


def test_wrong_surface_column_count(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t30\t0\t0.85")
    lines[k] = lines[k].rsplit("\t", 1)[0]
    expect_error(broken(tmp_path, lines), k + 1, "Temperature..BTDF_gy", "expected 22 values, got 21")


def test_non_numeric_cell(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t30\t0\t0.5\t90")
    cells = lines[k].split("\t")
    cells[6] = "0.03x"
    lines[k] = "\t".join(cells)
    expect_error(broken(tmp_path, lines), k + 1, "BRDF", "not a number; expected a number, got '0.03x'")


def test_negative_bsdf(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t0\t0\t0\t0")
    cells = lines[k].split("\t")
    cells[7] = "-0.01"
    lines[k] = "\t".join(cells)
    expect_error(broken(tmp_path, lines), k + 1, "BTDF", "negative BSDF")


@pytest.mark.parametrize("keyword", ["Scatter", "Catalog", "Solve"])
def test_missing_keyword(tmp_path, keyword):
    lines = golden_lines()
    k = line_no(lines, keyword + (" " if keyword == "Scatter" else "\t"))
    del lines[k]
    expect_error(broken(tmp_path, lines), k + 1, keyword, f"expected a line starting with '{keyword}'")


def test_unsupported_scatter_and_magic(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "Scatter ")
    lines[k] = "Scatter    4"
    expect_error(broken(tmp_path, lines), k + 1, "Scatter", "not supported")
    lines[k] = "Scatter    3.5"
    expect_error(broken(tmp_path, lines), k + 1, "Scatter", "not an integer")
    lines = golden_lines()
    lines[0] = "TracePro Material Data"
    expect_error(broken(tmp_path, lines), 1, "magic")


def test_scatter_5_without_table(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "Table_BSDF_Data")
    expect_error(broken(tmp_path, lines[:k] + ["SAVE-DATA"]), k + 1, "Table_BSDF_Data", "needs a Table_BSDF_Data")


def test_reads_tracepro_style_whitespace(tmp_path):
    """Multiple tabs between numbers and spaces in keyword lines, as in a genuine TracePro 19.6 export."""
    lines = golden_lines()
    out = []
    for line in lines:
        if line and line[0].isdigit():
            line = line.replace("\t", "\t\t\t") + "\t"
        out.append(line)
    prop = tracepro.read_tracepro(broken(tmp_path, out))
    ref = tracepro.read_tracepro(GOLDEN / "tracepro_lambert_table.txt")
    np.testing.assert_array_equal(prop.table.values, ref.table.values)


def test_invalid_header_values_name_the_line(tmp_path):
    lines = golden_lines()
    k = line_no(lines, "Name\t")
    lines[k] = "Name\t"
    expect_error(broken(tmp_path, lines), k + 1, "Name", "invalid header value; expected one line of text")
    lines = golden_lines()
    k = line_no(lines, "300\t0.55\t0\t0\t0.85")
    lines[k] = lines[k].replace("0.55", "-0.55", 1)
    # the first surface row sets the pair; the next row (30 deg) is the one reported
    expect_error(broken(tmp_path, lines), k + 2, "Temperature/Wavelength", "several Temperature/Wavelength")
    lines = [line.replace("\t0.55\t", "\t-0.55\t") for line in golden_lines()]
    expect_error(broken(tmp_path, lines), line_no(lines, "300\t-0.55\t0\t0\t0.85") + 1, "wavelength_um",
                 "expected 0.1-100 micrometres, got -0.55")


def test_invalid_abg_parameters_name_the_line(tmp_path):
    lines = (GOLDEN / "tracepro_abg.txt").read_text().splitlines()
    k = line_no(lines, "300\t0.55\t0\t0")
    lines[k] = lines[k].replace("\t0.001\t0.001\t", "\t0\t0\t")
    expect_error(broken(tmp_path, lines), k + 1, "BRDF_A/BRDF_B", "A=0.0025, B=0, g=1.8")
