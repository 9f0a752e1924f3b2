"""Every bad-input class of the raw-scan reader gives a one-line error naming file and field."""
import re
from pathlib import Path

import pytest
from conftest import cli, read_gz_lines, write_gz_lines

from bsdfkit.core.errors import BsdfkitError, FormatError, InputError, ValidationError
from bsdfkit.measurement.raw_scan import read_scan


def _edit_scan(folder: Path, edit) -> Path:
    path = folder / "scans" / "blue.csv.gz"
    lines = read_gz_lines(path)
    write_gz_lines(path, edit(lines))
    return path


def _edit_manifest(folder: Path, old: str, new: str) -> Path:
    path = folder / "manifest.toml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    return path


def _set_cell(line: str, index: int, value: str) -> str:
    cells = line.split(",")
    cells[index] = value
    return ",".join(cells)


def _missing_file(f):
    (f / "scans" / "blue.csv.gz").unlink()
    return InputError, "manifest.toml", "configuration[0].scan_file"


def _unknown_column(f):
    _edit_scan(f, lambda ls: [ls[0].replace("arc,", "arcx,", 1)] + ls[1:])
    return FormatError, "blue.csv.gz", "arcx"


def _non_monotonic(f):
    def swap(ls):
        h = ls[0].split(",")
        h[8], h[9] = h[9], h[8]
        return [",".join(h)] + ls[1:]
    _edit_scan(f, swap)
    return ValidationError, "blue.csv.gz", "field"


def _mismatched_grid(f):
    _edit_scan(f, lambda ls: [ls[0].replace(",385.0,", ",386.0,", 1)] + ls[1:])
    return ValidationError, "blue.csv.gz", "wavelength header"


def _angle_out_of_range(f):
    _edit_scan(f, lambda ls: [ls[0], _set_cell(ls[1], 2, "95.0")] + ls[2:])
    return ValidationError, "blue.csv.gz", "theta_s_deg"


def _unknown_side(f):
    _edit_scan(f, lambda ls: [ls[0], _set_cell(ls[1], 4, "front")] + ls[2:])
    return ValidationError, "blue.csv.gz", "side"


def _duplicate_position(f):
    _edit_scan(f, lambda ls: ls + [ls[1]])
    return ValidationError, "blue.csv.gz", "theta_s_deg/phi_s_deg"


def _nan_counts(f):
    _edit_scan(f, lambda ls: [ls[0], _set_cell(ls[1], 20, "nan")] + ls[2:])
    return ValidationError, "blue.csv.gz", "field"


def _inf_counts(f):
    _edit_scan(f, lambda ls: [ls[0], ls[1], _set_cell(ls[2], 30, "inf")] + ls[3:])
    return ValidationError, "blue.csv.gz", "field"


def _text_count(f):
    _edit_scan(f, lambda ls: [ls[0], _set_cell(ls[1], 25, "12x")] + ls[2:])
    return FormatError, "blue.csv.gz", "field"


def _empty_file(f):
    (f / "scans" / "blue.csv.gz").write_bytes(b"")
    return InputError, "blue.csv.gz", None


def _header_only(f):
    _edit_scan(f, lambda ls: ls[:1])
    return InputError, "blue.csv.gz", None


def _manifest_key_missing(f):
    _edit_manifest(f, "detector_distance_mm = 886.0\n", "")
    return InputError, "manifest.toml", "instrument.detector_distance_mm"


def _manifest_wrong_type(f):
    _edit_manifest(f, "detector_distance_mm = 886.0", 'detector_distance_mm = "886"')
    return InputError, "manifest.toml", "instrument.detector_distance_mm"


def _wrong_field_count(f):
    _edit_scan(f, lambda ls: [ls[0], ls[1] + ",7"] + ls[2:])
    return FormatError, "blue.csv.gz", None


def _missing_dark_exposure(f):
    path = f / "dark.csv.gz"
    lines = read_gz_lines(path)
    write_gz_lines(path, [lines[0]] + [line for line in lines[1:] if line.split(",")[1] != "20"])
    return ValidationError, "dark.csv.gz", "exposure_s"


CASES = [_missing_file, _unknown_column, _non_monotonic, _mismatched_grid, _angle_out_of_range, _unknown_side,
         _duplicate_position, _nan_counts, _inf_counts, _text_count, _empty_file, _header_only, _manifest_key_missing,
         _manifest_wrong_type, _wrong_field_count, _missing_dark_exposure]


@pytest.mark.parametrize("case", CASES, ids=[c.__name__.strip("_") for c in CASES])
def test_bad_input_names_file_and_field(tiny_export, case):
    kind, filename, field = case(tiny_export)
    with pytest.raises(kind) as info:
        read_scan(tiny_export)
    message = str(info.value)
    assert "\n" not in message
    assert filename in message
    if field is not None:
        assert field in message
    assert "expected" in message or "empty" in message or "not found" in message or "no data" in message


def test_valid_export_reads(tiny_export):
    ds = read_scan(tiny_export)
    assert ds.sizes["wavelength"] == 81 and set(ds.side.values) == {"reflection", "transmission"}


@pytest.mark.parametrize("case", [_missing_file, _unknown_side, _manifest_wrong_type, _nan_counts],
                         ids=["missing_file", "unknown_side", "manifest_wrong_type", "nan_counts"])
def test_cli_ingest_reports_one_line(tiny_export, tmp_path, case):
    case(tiny_export)
    out = tmp_path / "scan.nc"
    proc = cli("ingest", tiny_export, "-o", out)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert re.match(r"bsdfkit ingest: error: ", lines[0])
    assert not out.exists()


def test_missing_manifest(tmp_path):
    with pytest.raises(InputError, match="manifest"):
        read_scan(tmp_path)


def test_errors_share_one_family():
    for kind in (InputError, FormatError, ValidationError):
        assert issubclass(kind, BsdfkitError)
