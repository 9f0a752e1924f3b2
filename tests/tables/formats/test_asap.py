"""ASAP-style Harvey-Shack tables: golden output, honest header, round trips, malformed input."""
from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bsdfkit.core import frames
from bsdfkit.core.errors import FormatError, OutputExistsError
from bsdfkit.tables import grids
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats import asap

GOLDEN = Path(__file__).parents[2] / "data" / "golden"
WHEN = datetime(2020, 1, 23, 15, 24, 9)


def normalise(text: str) -> str:
    return re.sub(r"(?m)^# bsdfkit \S+ \S+$", "# bsdfkit <version> <time>", text)


def golden_table() -> asap.AsapTable:
    """R 0.1/pi and T 0.05/pi at 0 and 30 deg on rho 0..2 step 0.5 x psi 0/90/180/270, plus parameters.

    Hand check: at 30 deg (beta0 = (0.5, 0)) the psi-0 row (+x, forward) is non-zero up to rho 0.5, the
    psi-180 row (toward the source) up to 1.5, the psi-90/270 rows up to 0.5 (rho <= sqrt(0.75));
    tis = 0.1 and 0.05 exactly.
    """
    axes = grids.HarveyShackAxes((0.0, 0.5, 1.0, 1.5, 2.0), (0.0, 90.0, 180.0, 270.0))

    def fn(theta_i_deg, side, d):
        return np.full(d.shape[:-1], (0.1 if side == "reflection" else 0.05) / np.pi)

    grid = grids.harvey_shack_grid(fn, [0.0, 30.0], ["reflection", "transmission"], axes)
    return asap.asap_table(
        grid,
        abg=[asap.AbgParameters("reflection", 0.0, 0.0025, 0.001, 1.8)],
        harvey=[asap.HarveyParameters("reflection", 0.0, 2.5, -2.0, 0.05)],
        comments=["golden file: Lambertian R 10 % + T 5 %"],
    )


def test_golden_file_byte_for_byte(tmp_path):
    out = asap.write_asap(tmp_path / "asap.txt", golden_table(), generated_at=WHEN)
    assert normalise(out.read_text()) == normalise((GOLDEN / "asap_lambert.txt").read_text())


def test_golden_hand_checked_values_and_honest_header():
    text = (GOLDEN / "asap_lambert.txt").read_text()
    assert "NO ASAP MANUAL WAS AVAILABLE" in text and "NOT an ASAP command deck" in text
    t = asap.read_asap(GOLDEN / "asap_lambert.txt")
    f = float(format(0.1 / np.pi, ".7g"))
    r30 = t.table.sel(side="reflection", theta_i=30.0)
    np.testing.assert_array_equal(r30.sel(psi=0.0).values, [f, f, 0, 0, 0])
    np.testing.assert_array_equal(r30.sel(psi=180.0).values, [f, f, f, f, 0])
    np.testing.assert_array_equal(r30.sel(psi=90.0).values, [f, f, 0, 0, 0])
    np.testing.assert_allclose(t.tis_stated.values, [[0.1, 0.1], [0.05, 0.05]], rtol=1e-6)
    np.testing.assert_allclose(t.tis_computed().values, t.tis_stated.values, rtol=1e-6)
    assert t.abg == (asap.AbgParameters("reflection", 0.0, 0.0025, 0.001, 1.8),)
    assert t.harvey == (asap.HarveyParameters("reflection", 0.0, 2.5, -2.0, 0.05),)
    assert t.comments == ("golden file: Lambertian R 10 % + T 5 %",)


def abg(a, b, g):
    def fn(theta_i_deg, side, d):
        r, _ = frames.harvey_shack_from_direction(d, np.radians(theta_i_deg))
        return a / (b + r**g)

    return fn


def test_round_trip_from_abg_fit_result(tmp_path):
    theta = [0.0, 40.0]
    fit = xr.Dataset({"A": ("theta_i", [0.001, 0.001]), "B": ("theta_i", [1e-4, 1e-4]),
                      "g": ("theta_i", [2.5, 2.5])}, coords={"theta_i": theta},
                     attrs={"model": "abg", "side": "reflection", "interaction": "bibs"})
    path = tmp_path / "abg.txt"
    result = export(fit, "asap", "bibs", "reflection", path)
    summary = read_any(path)
    assert summary.format == "asap" and summary.incidences_deg == theta
    source = [grids.tis_reference(abg(0.001, 1e-4, 2.5), t, "reflection") for t in theta]
    assert source[0] == pytest.approx(0.072190, abs=5e-7)
    np.testing.assert_allclose(summary.tis_computed["reflection"], source, rtol=5e-3)
    np.testing.assert_allclose(result.tis_table["reflection"], summary.tis_computed["reflection"], rtol=1e-12)
    assert [p["theta_i_deg"] for p in summary.details["abg"]] == theta
    assert summary.details["abg"][0]["g"] == 2.5


def test_refuses_to_overwrite_without_force(tmp_path):
    path = tmp_path / "a.txt"
    asap.write_asap(path, golden_table())
    with pytest.raises(OutputExistsError):
        export(abg(0.001, 1e-4, 2.5), "asap", "bibs", "reflection", path,
               settings=ExportSettings(theta_i_deg=(0.0,)))
    assert asap.read_asap(path).table.sizes["theta_i"] == 2


def golden_lines() -> list[str]:
    return (GOLDEN / "asap_lambert.txt").read_text().splitlines()


def expect_error(tmp_path, lines, line: int, field: str, match: str) -> None:
    path = tmp_path / "broken.txt"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError) as info:
        asap.read_asap(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}:{line}: field '{field}'"), message
    assert match in message, message


def test_truncated(tmp_path):
    lines = golden_lines()[:-5]
    expect_error(tmp_path, lines, len(lines), "end", "truncated")


def test_wrong_counts(tmp_path):
    lines = golden_lines()
    k = lines.index("R 30 1 180 0.03183099")
    lines[k] = "R 30 1 180"
    expect_error(tmp_path, lines, k + 1, "data row", "expected 5 values, got 4")
    lines = golden_lines()
    del lines[k]
    expect_error(tmp_path, lines, len(lines) - 1, "data", "not rectangular")


def test_non_numeric_and_missing_records(tmp_path):
    lines = golden_lines()
    k = lines.index("R 30 1 180 0.03183099")
    lines[k] = "R 30 1 180 0.0318x"
    expect_error(tmp_path, lines, k + 1, "bsdf", "got '0.0318x'")
    lines = golden_lines()
    k = next(i for i, line in enumerate(lines) if line.startswith("tis T 30"))
    del lines[k]
    first_row = next(i for i, line in enumerate(lines) if line.startswith("R 0 0 0"))
    expect_error(tmp_path, lines, first_row + 1, "tis", "expected 'tis T 30 <value>'")
    lines = golden_lines()
    k = lines.index("side theta_i_deg rho psi_deg bsdf")
    del lines[k]
    expect_error(tmp_path, lines, k + 1, "record", "unexpected line")
    lines = golden_lines()
    lines[0] = "# some other table"
    expect_error(tmp_path, lines, 1, "magic", "not a bsdfkit ASAP-style table")
