"""Speos anisotropic BSDF reader (issue #44 point 5): a refusal names its real cause, the file, the line and the
column; a value that is not finite is said as such, not as a wrong count of values."""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import cli

from bsdfkit.core.errors import FormatError
from bsdfkit.tables.formats.speos import read_speos

DATA = Path(__file__).parents[2] / "data" / "ansys-speos-anisotropicbsdf"
BRDF = DATA / "test_13_planesymmetric_brdf_speos_reference.anisotropicbsdf"


def _edited(tmp_path: Path, line: int, column: int | None, text: str) -> Path:
    """The reference BRDF with cell ``column`` (0-based, tab-separated) of ``line`` (1-based) replaced by ``text``;
    ``column`` None: the whole line."""
    lines = BRDF.read_text().splitlines()
    if column is None:
        lines[line - 1] = text
    else:
        cells = lines[line - 1].split("\t")
        cells[column] = text
        lines[line - 1] = "\t".join(cells)
    out = tmp_path / "bad.anisotropicbsdf"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize("token", ["nan", "inf", "-inf", "NaN"])
def test_a_value_not_finite_is_named_with_its_line_and_column(tmp_path, token):
    bad = _edited(tmp_path, 22, 5, token)  # line 22: the theta = 10 row of the first table
    with pytest.raises(FormatError) as err:
        read_speos(bad)
    text = str(err.value)
    assert "bad.anisotropicbsdf:22: field 'reflection table at theta_i=15: row': value not finite in column 6" in text
    assert text.endswith(f"expected finite numbers, got '{token}'"), text
    assert "wrong number" not in text


def test_a_value_not_finite_in_the_header_fields_too(tmp_path):
    bad = _edited(tmp_path, 12, 2, "nan")  # the incidence list
    with pytest.raises(FormatError, match=r"bad\.anisotropicbsdf:12: field 'reflection: incidences': value not "
                                          r"finite in column 3; expected finite numbers, got 'nan'"):
        read_speos(bad)


def test_a_row_with_a_missing_value_says_the_count(tmp_path):
    lines = BRDF.read_text().splitlines()
    row = lines[21].rstrip("\t").split("\t")
    bad = _edited(tmp_path, 22, None, "\t".join(row[:-1]))
    with pytest.raises(FormatError, match=r"bad\.anisotropicbsdf:22: field 'reflection table at theta_i=15: row': "
                                          r"wrong number of values; expected 38 numbers, got 37$"):
        read_speos(bad)


def test_a_word_among_the_numbers_is_named_with_its_column(tmp_path):
    bad = _edited(tmp_path, 22, 3, "0.1x")
    with pytest.raises(FormatError, match=r"bad\.anisotropicbsdf:22: .*not a number in column 4; expected numbers, "
                                          r"got '0\.1x'"):
        read_speos(bad)


def test_a_comment_wavelength_in_metres_names_the_comment_not_an_option(tmp_path):
    bad = _edited(tmp_path, 3, None, "bsdfkit 1.0 wavelength_nm=5.5e-07")
    with pytest.raises(FormatError, match=r"bad\.anisotropicbsdf:3: field 'comment: wavelength_nm': .*stated in nm; "
                                          r"expected a wavelength in nm, 100\.\.20000, got '5\.5e-07'"):
        read_speos(bad)
    good = _edited(tmp_path, 3, None, "bsdfkit 1.0 wavelength_nm=550")
    assert read_speos(good).wavelength_nm == 550.0


def test_the_command_line_says_it_in_one_line(tmp_path):
    bad = _edited(tmp_path, 22, 5, "nan")
    res = cli("read", bad)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr.startswith(f"bsdfkit read: error: {bad}:22: field 'reflection table at theta_i=15: row': "
                                 "value not finite in column 6"), res.stderr


def test_a_side_the_file_does_not_hold_is_named_with_the_side_it_holds(tmp_path):
    res = cli("ingest", BRDF, "--side", "transmission", "-o", tmp_path / "o.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert res.stderr == (f"bsdfkit ingest: error: {BRDF}: field '--side': the file holds no data for this side; "
                          "expected reflection, got 'transmission'\n")
