"""Raw export files (issue #44 point 5): a count too large for any spectrometer (1e308) is refused where it is
written, naming the file, line and wavelength column, as implausibly large; it used to reach the calibration and read
as "zero incident power ... peak inf"."""
from __future__ import annotations

import pytest
from conftest import cli, read_gz_lines, write_gz_lines

from bsdfkit.core.errors import ValidationError
from bsdfkit.measurement.raw_scan import MAX_ABS_COUNTS, read_scan


def _set_cell(path, line: int, column: str, text: str) -> None:
    """Cell ``column`` (a header name) of ``line`` (1-based) of the gzip CSV ``path`` set to ``text``."""
    lines = read_gz_lines(path)
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = text
    lines[line - 1] = ",".join(cells)
    write_gz_lines(path, lines)


@pytest.mark.parametrize(("name", "line"), [("reference/blue.csv.gz", 3), ("scans/yellow.csv.gz", 4),
                                            ("dark.csv.gz", 2)])
def test_a_huge_count_names_its_file_line_and_column(tiny_export, name, line):
    _set_cell(tiny_export / name, line, "480.0", "1e308")
    with pytest.raises(ValidationError) as err:
        read_scan(tiny_export)
    assert str(err.value) == (f"{tiny_export / name}:{line}: field '480.0': count implausibly large (an overflow or "
                              f"a corrupt cell); expected |count| <= {MAX_ABS_COUNTS:g}, got '1e308'")


def test_a_count_below_the_bound_is_read(tiny_export):
    _set_cell(tiny_export / "scans" / "blue.csv.gz", 2, "480.0", "65535")
    assert read_scan(tiny_export).sizes["wavelength"] == 81


def test_the_command_line_says_it_in_one_line_not_zero_power(tiny_export, tmp_path):
    _set_cell(tiny_export / "reference" / "blue.csv.gz", 3, "480.0", "1e308")
    res = cli("ingest", tiny_export, "-o", tmp_path / "scan.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert "reference/blue.csv.gz:3: field '480.0': count implausibly large" in res.stderr, res.stderr
    assert "zero incident power" not in res.stderr and "inf" not in res.stderr
    assert not (tmp_path / "scan.nc").exists()
