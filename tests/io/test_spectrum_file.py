"""bsdfkit.io.spectrum_file: two-column spectra in their many spellings, multi-column tables, and every
bad-input class."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsdfkit.cli.main import main
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io.spectrum_file import read_spectrum, read_spectrum_arrays, read_spectrum_table, select_columns

BENKNER = Path(__file__).resolve().parent.parent / "data" / "benkner-led-spectra"


def write(tmp_path, text, name="s.txt", encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    return path


def test_reads_instrument_systems_isd_with_bom_tab_and_header():
    raw = (BENKNER / "blue_3.ISD").read_bytes()
    assert raw.startswith(b"\xef\xbb\xbfwl\tpwr")  # the fixture really has a BOM and a header
    wl, v, header = read_spectrum_arrays(BENKNER / "blue_3.ISD")
    assert header == "wl\tpwr"
    assert wl[0] == 280.0 and wl[-1] == 780.0 and wl.size == 501
    assert np.all(np.diff(wl) > 0) and np.all(np.isfinite(v))
    sd = read_spectrum(BENKNER / "blue_3.ISD")
    assert sd.name == "blue_3" and sd.wavelengths.size == 501


@pytest.mark.parametrize("text", [
    "450\t1.0\n451\t2.0\n452\t3.0\n",
    "wavelength,value\r\n450,1.0\r\n451,2.0\r\n452,3.0\r\n",
    "\ufeffnm;W/nm\n450;1.0\n451;2,0\n452;3e0\n",
    "# comment line\n\n450 1.0\n451   2.0\n  452 3.0  \n",
    "lambda (nm)\tvalue (a.u.)\n450,0\t1,0\n451,0\t2,0\n452\t3\n",
    '"wl","v"\n"450","1.0"\n451,2.0\n452,3.0\n',
])
def test_separators_headers_bom_crlf_decimal_comma(tmp_path, text):
    wl, v, _ = read_spectrum_arrays(write(tmp_path, text))
    np.testing.assert_array_equal(wl, [450.0, 451.0, 452.0])
    np.testing.assert_array_equal(v, [1.0, 2.0, 3.0])


@pytest.mark.parametrize("text, error, parts", [
    ("", FormatError, ["the file is empty", "expected a spectrum table"]),
    ("450,1.25\n451,2.25\n452,3.2", FormatError, [":3:", "ends inside a number", "452,3.2"]),
    ("wavelength,value\n", FormatError, ["no data rows", "header"]),
    ("450,1\n451,2\n", FormatError, ["too few data rows", "at least 3", "got 2"]),
    ("450,1\n451,2,3\n452,3\n", FormatError, [":2:", "wrong number of columns", "got 3"]),
    ("450,1\n451,abc\n452,3\n", FormatError, [":2:", "field 'value'", "non-numeric", "'abc'"]),
    ("450,1\n4x51,2\n452,3\n", FormatError, [":2:", "field 'wavelength'", "'4x51'"]),
    ("450,1\n451,nan\n452,3\n", FormatError, [":2:", "field 'value'", "not finite"]),
    ("450,1\ninf,2\n452,3\n", FormatError, [":2:", "field 'wavelength'", "not finite"]),
    ("450,1\n452,2\n451,3\n", ValidationError, [":3:", "increase strictly", "> 452", "got 451"]),
    ("450,1\n450,2\n451,3\n", ValidationError, [":2:", "increase strictly"]),
    ("-1,1\n450,2\n451,3\n", ValidationError, [":1:", "positive"]),
    ("h1,h2\n450,1\nh3,h4\n452,3\n", FormatError, [":3:", "non-numeric"]),
])
def test_bad_input_names_file_line_field(tmp_path, text, error, parts):
    path = write(tmp_path, text, name="bad.csv")
    with pytest.raises(error) as exc:
        read_spectrum_arrays(path)
    msg = str(exc.value)
    assert "\n" not in msg and "bad.csv" in msg
    for part in parts:
        assert part in msg, (part, msg)


def test_missing_file_directory_and_non_utf8(tmp_path):
    with pytest.raises(InputError, match="not found") as exc:
        read_spectrum_arrays(tmp_path / "nope.txt")
    assert "nope.txt" in str(exc.value)
    with pytest.raises(InputError, match="directory"):
        read_spectrum_arrays(tmp_path)
    with pytest.raises(FormatError, match="UTF-8"):
        read_spectrum_arrays(write(tmp_path, "450\t1\n451\t2\n452\t\xb5\n", encoding="latin-1"))


@pytest.mark.parametrize("text, names", [
    ("wl\tled A\tled B\n450\t1\t4\n451\t2\t5\n452\t3\t6\n", ["led A", "led B"]),
    ("\ufeffnm;a;b\r\n450;1,0;4\r\n451;2;5,0\r\n452;3;6\r\n", ["a", "b"]),  # BOM, CRLF, decimal comma
    ("450,1,4\n451,2,5\n452,3,6\n", ["column 2", "column 3"]),  # no header: file column numbers
    ("wl,x,x\n450,1,4\n451,2,5\n452,3,6\n", ["column 2", "column 3"]),  # duplicate names: numbers
    ("# two LEDs\nwl value1\n450 1 4\n451 2 5\n452 3 6\n", ["column 2", "column 3"]),  # header too short
])
def test_multi_column_table_names_and_values(tmp_path, text, names):
    wl, columns, _ = read_spectrum_table(write(tmp_path, text))
    np.testing.assert_array_equal(wl, [450.0, 451.0, 452.0])
    assert list(columns) == names
    np.testing.assert_array_equal(columns[names[0]], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(columns[names[1]], [4.0, 5.0, 6.0])


def test_two_column_file_is_a_one_column_table_and_isd_reads_alike():
    wl, columns, header = read_spectrum_table(BENKNER / "blue_3.ISD")
    wl2, v2, header2 = read_spectrum_arrays(BENKNER / "blue_3.ISD")
    assert list(columns) == ["pwr"] and header == header2
    np.testing.assert_array_equal(wl, wl2)
    np.testing.assert_array_equal(columns["pwr"], v2)


def test_table_errors_and_column_selection(tmp_path):
    path = write(tmp_path, "wl,a,b\n450,1,4\n451,2\n452,3,6\n", name="t.csv")
    with pytest.raises(FormatError) as exc:
        read_spectrum_table(path)
    assert "t.csv:3" in str(exc.value) and "expected 3 (as on the first data row)" in str(exc.value)
    with pytest.raises(FormatError, match="column 3"):
        read_spectrum_table(write(tmp_path, "450,1,4\n451,2,x\n452,3,6\n", name="u.csv"))
    with pytest.raises(FormatError, match="wrong number of columns"):  # the two-column reader stays strict
        read_spectrum_arrays(write(tmp_path, "450,1,4\n451,2,5\n452,3,6\n", name="v.csv"))
    ok = write(tmp_path, "wl,a,b\n450,1,4\n451,2,5\n452,3,6\n", name="w.csv")
    _, columns, _ = read_spectrum_table(ok)
    assert select_columns(ok, columns, None) == ["a", "b"]
    assert select_columns(ok, columns, ["b", "2"]) == ["b", "a"]
    with pytest.raises(ValidationError) as exc:
        select_columns(ok, columns, ["4"])
    msg = str(exc.value)
    assert "w.csv" in msg and "--column" in msg and "a | b" in msg and "'4'" in msg


def test_cli_reports_bad_file_as_one_line(tmp_path, capsys):
    path = write(tmp_path, "450,1\n451,x\n452,3\n", name="broken.txt")
    assert main(["color", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "broken.txt:2" in err and "Traceback" not in err
    assert main(["fit", "spectrum", str(tmp_path / "absent.txt")]) == 2
    assert "absent.txt" in capsys.readouterr().err


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.floats(0.01, 50.0, allow_nan=False), min_size=2, max_size=30),
    start=st.floats(200.0, 900.0),
    values=st.lists(st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False), min_size=31, max_size=31),
    sep=st.sampled_from(["\t", ",", ";", " ", "  "]),
    header=st.booleans(),
    crlf=st.booleans(),
    bom=st.booleans(),
)
def test_round_trip_property(tmp_path_factory, steps, start, values, sep, header, crlf, bom):
    wl = start + np.concatenate([[0.0], np.cumsum(steps)])
    v = np.asarray(values[: wl.size])
    lines = (["wavelength" + sep + "value"] if header else []) + [f"{a!r}{sep}{b!r}" for a, b in zip(wl, v)]
    text = ("\ufeff" if bom else "") + ("\r\n" if crlf else "\n").join(lines) + "\n"
    path = tmp_path_factory.mktemp("rt") / "s.txt"
    path.write_bytes(text.encode("utf-8"))
    got_wl, got_v, got_header = read_spectrum_arrays(path)
    np.testing.assert_array_equal(got_wl, wl)
    np.testing.assert_array_equal(got_v, v)
    assert (got_header is not None) == header
