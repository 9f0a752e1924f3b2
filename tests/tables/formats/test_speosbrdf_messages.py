"""Speos spectral .brdf reader (issue #44 point 5): a wavelength in metres is the file's field, named with its file,
line and column, never an option the command was not given (``--wavelength-nm``)."""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import cli

from bsdfkit.core.errors import FormatError
from bsdfkit.tables.formats.speosbrdf import read_speos_brdf

BRDF = Path(__file__).parents[2] / "data" / "ansys-speos-anisotropicbsdf" / "test_13_brdf_one_wavelength_speos.brdf"


def _with_wavelengths(tmp_path: Path, text: str) -> Path:
    """The reference file (one wavelength, 550 nm on line 10) with line 10 replaced by ``text``."""
    lines = BRDF.read_text().splitlines()
    assert lines[9] == "550"
    lines[9] = text
    out = tmp_path / "bad.brdf"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize(("value", "looks"), [("5.5e-07", "looks like metres"), ("0.55", "looks like micrometres"),
                                              ("5500000", "is not in nanometres"), ("-550", "is not positive")])
def test_a_wavelength_not_in_nm_names_the_file_line_and_field(tmp_path, value, looks):
    bad = _with_wavelengths(tmp_path, value)
    with pytest.raises(FormatError) as err:
        read_speos_brdf(bad)
    text = str(err.value)
    assert text.startswith(f"{bad}:10: field 'wavelengths': wavelength in column 1 out of range"), text
    assert looks in text and text.endswith(f"expected a wavelength in nm, 100..20000, got {float(value)!r}"), text


@pytest.mark.parametrize("verb", [("read",), ("convert", "--to", "speos", "-o")])
def test_the_command_line_blames_the_file_not_wavelength_nm(tmp_path, verb):
    bad = _with_wavelengths(tmp_path, "5.5e-07")
    argv = (*verb, tmp_path / "out.anisotropicbsdf") if verb[0] == "convert" else verb
    res = cli(*argv, bad)
    assert res.returncode == 2 and "Traceback" not in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert f"{bad}:10: field 'wavelengths':" in res.stderr and "metres" in res.stderr, res.stderr
    assert "--wavelength-nm" not in res.stderr
    assert not (tmp_path / "out.anisotropicbsdf").exists()


def test_a_table_value_not_finite_is_named(tmp_path):
    lines = BRDF.read_text().splitlines()
    cells = lines[13].split("\t")  # line 14: the theta = 0 row of the first table
    cells[2] = "nan"
    lines[13] = "\t".join(cells)
    bad = tmp_path / "nan.brdf"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError, match=r"nan\.brdf:14: field 'reflection table at theta_i=0, 550 nm: row': value "
                                          r"not finite in column 3; expected finite numbers, got 'nan'"):
        read_speos_brdf(bad)
