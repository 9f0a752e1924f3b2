"""Measured text tables (issue #44 point 5): each refusal names its real cause and the value's own line.

- a table negative beyond noise names the first negative value of the file, also when the wavelengths are not listed
  in increasing order (they were tried sorted, and the line named was that of a later block);
- ``--side`` asking for a side the table does not hold names the side asked and the sides it holds;
- a value column named twice is refused, naming both columns (it was read as a second measurement of every
  direction).
"""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import cli

from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.measurement.table import read_table

HEADER = "theta_i,theta_s,phi_s,wavelength,brdf"


def _long(path: Path, value, wavelengths=(650.0, 550.0), header: str = HEADER) -> Path:
    """A long table at θi = 10° on a 9 x 12 (θs, φs) grid per wavelength, in the order given; ``value(line)`` gives
    the BRDF of the row written on ``line`` (the header is line 1)."""
    lines = [header]
    for lam in wavelengths:
        for th in range(0, 90, 10):
            for ph in range(0, 360, 30):
                lines.append(f"10,{th},{ph},{lam:g},{value(len(lines) + 1)!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _wide(path: Path, value, header: str = "theta_i,theta_s,phi_s,brdf 450,brdf 550") -> Path:
    """A wide table (one value column per wavelength); ``value(line, column)`` gives each cell."""
    lines = [header]
    n_values = header.count(",") - 2
    for th in range(0, 90, 10):
        for ph in range(0, 360, 30):
            cells = [value(len(lines) + 1, j) for j in range(n_values)]
            lines.append(f"10,{th},{ph}," + ",".join(map(repr, cells)))
    path.write_text("\n".join(lines) + "\n")
    return path


# ------------------------------------------------------------------------------------- the line of a negative value
@pytest.mark.parametrize("first", [21, 15, 2])
def test_negative_values_name_their_own_line_when_wavelengths_decrease(tmp_path, first):
    # 650 nm on lines 2-109, 550 nm on lines 110-217; every value from line `first` on is negative, so both
    # wavelengths are refused: the line named is the first negative one of the file, not the first of 550 nm (110)
    table = _long(tmp_path / "neg.csv", lambda line: -0.1 if line >= first else 0.1)
    with pytest.raises(ValidationError) as err:
        read_table(table)
    text = str(err.value)
    assert text.startswith(f"{table}:{first}: field 'brdf': BSDF negative beyond noise at 650 nm:"), text
    assert "first negative -0.1" in text


def test_one_wavelength_refused_names_its_first_negative(tmp_path):
    # only 550 nm (lines 110-217) negative from line 120 on: 650 nm is fine and is not the one named
    table = _long(tmp_path / "neg.csv", lambda line: -0.1 if line >= 120 else 0.1)
    with pytest.raises(ValidationError, match=r"neg\.csv:120: field 'brdf': BSDF negative beyond noise at 550 nm"):
        read_table(table)


def test_negative_values_of_a_wide_table_name_line_and_column(tmp_path):
    table = _wide(tmp_path / "wide.csv", lambda line, j: -0.1 if (j == 1 and line >= 15) else 0.1)
    res = cli("ingest", table, "-o", tmp_path / "o.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert f"error: {table}:15: field 'brdf 550': BSDF negative beyond noise at 550 nm" in res.stderr, res.stderr
    assert not (tmp_path / "o.nc").exists()


# ------------------------------------------------------------------------------------- a side the table does not hold
def test_side_not_in_a_reflection_table_names_both_sides(tmp_path):
    table = _long(tmp_path / "r.csv", lambda line: 0.1)
    with pytest.raises(InputError) as err:
        read_table(table, side="transmission")
    assert str(err.value) == (f"{table}:2: field '--side': the table holds no transmission data, only reflection "
                              "(its values are brdf: column 5 'brdf'); expected --side reflection (or no --side), "
                              "got 'transmission'")
    assert read_table(table, side="reflection")["side"].values.tolist() == ["reflection"] * 108


def test_side_not_in_the_side_column_names_both_sides(tmp_path):
    lines = ["theta_i,theta_s,phi_s,wavelength,side,bsdf"]
    lines += [f"10,{th},{ph},550,R,0.1" for th in range(0, 90, 10) for ph in range(0, 360, 30)]
    table = tmp_path / "sides.csv"
    table.write_text("\n".join(lines) + "\n")
    res = cli("ingest", table, "--side", "transmission", "-o", tmp_path / "o.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert (":2: field '--side': the table holds no transmission data, only reflection (the rows of its side column, "
            "column 5 'side')") in res.stderr, res.stderr
    assert "expected --side reflection" in res.stderr and "got []" not in res.stderr, res.stderr


def test_side_not_in_a_real_table_names_both_sides(tmp_path):
    real = Path(__file__).parents[1] / "data" / "ansys-radiant-zemax-bsdf" / "inplane_spectral_goniometric_2D_data.csv"
    res = cli("ingest", real, "--quantity", "brdf", "--side", "transmission", "-o", tmp_path / "o.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert (f"{real}:2: field '--side': the table holds no transmission data, only reflection (its values are "
            "brdf: column 3 '390nm' and 34 more); expected --side reflection (or no --side), got 'transmission'"
            in res.stderr), res.stderr


# ------------------------------------------------------------------------------------- a value column named twice
@pytest.mark.parametrize(("header", "names", "same"), [
    ("theta_i,theta_s,phi_s,wavelength,brdf,brdf", "column 5 'brdf' and column 6 'brdf'", "the same header"),
    ("theta_i,theta_s,phi_s,wavelength,BRDF,brdf [1/sr]", "column 5 'BRDF' and column 6 'brdf [1/sr]'",
     "the same quantity"),
])
def test_a_value_column_named_twice_is_refused_naming_both(tmp_path, header, names, same):
    lines = [header] + [f"10,{th},{ph},550,0.1,0.1" for th in range(0, 90, 10) for ph in range(0, 360, 30)]
    table = tmp_path / "dup.csv"
    table.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError) as err:
        read_table(table)
    text = str(err.value)
    assert text.startswith(f"{table}:1: field ") and f"value column given twice: {names} name {same}" in text, text
    assert "two measurements of every direction" in text


def test_an_incidence_column_named_twice_is_refused(tmp_path):
    lines = ["theta_s,phi_s,AOI 10,AOI 10"]
    lines += [f"{th},{ph},0.1,0.1" for th in range(0, 90, 10) for ph in range(0, 360, 30)]
    table = tmp_path / "aoi.csv"
    table.write_text("\n".join(lines) + "\n")
    res = cli("ingest", table, "--quantity", "brdf", "-o", tmp_path / "o.nc")
    assert res.returncode == 2 and "column 3 'AOI 10' and column 4 'AOI 10'" in res.stderr, res.stderr


def test_a_wavelength_column_named_twice_names_both(tmp_path):
    table = _wide(tmp_path / "wl.csv", lambda line, j: 0.1, header="theta_i,theta_s,phi_s,brdf 550,brdf 550")
    with pytest.raises(FormatError, match=r"wavelength given twice in the header: column 4 'brdf 550' and column 5 "
                                          r"'brdf 550' would be read as two measurements"):
        read_table(table)


def test_reflection_and_transmission_columns_are_still_read(tmp_path):
    lines = ["theta_i,theta_s,phi_s,wavelength,brdf,btdf"]
    lines += [f"10,{th},{ph},550,0.1,0.05" for th in range(0, 90, 10) for ph in range(0, 360, 30)]
    table = tmp_path / "rt.csv"
    table.write_text("\n".join(lines) + "\n")
    assert sorted(set(read_table(table)["side"].values.tolist())) == ["reflection", "transmission"]
