"""Fault injection (issue #13): text inputs in other encodings, binary, empty and truncated.

Every text reader decodes through :mod:`bsdfkit.io.text`: UTF-16/UTF-32 with a byte-order mark (Excel's
"Unicode text" export is UTF-16LE, tab-separated) and unmarked UTF-16 read exactly like UTF-8; binary, empty
and undecodable files, a file that ends inside a number and a TracePro file cut before ``SAVE-DATA`` are one
line naming the file (and line) and what was expected.
"""
from __future__ import annotations

import codecs
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from bsdfkit.cli.main import child_warnings_off, main
from bsdfkit.core.errors import FormatError
from bsdfkit.io.spectrum_file import read_spectrum_arrays
from bsdfkit.io.text import decode_text, refuse_cut_last_line, text_and_encoding
from bsdfkit.measurement.table import read_table
from bsdfkit.raytrace.plate import load_plate
from bsdfkit.raytrace.rayfile import read_ray_file
from bsdfkit.raytrace.scene import load_scene
from bsdfkit.tables.formats.tracepro import read_tracepro
from bsdfkit.tables.formats.zemax import read_zemax

GOLDEN = ROOT / "tests" / "data" / "golden"
TABLE = "theta_i,theta_s,phi_s,brdf\n" + "".join(f"0,{t},0,{0.3183 + t * 1e-4:.4f}\n" for t in range(0, 90, 5))
RAYS = "".join(f"{x} 0 0 0 0 1 0.25\n" for x in (-10, -5, 5, 10))
SPECTRUM = "wavelength,value\n" + "".join(f"{w},{1 + 0.01 * w:.3f}\n" for w in range(400, 700, 10))

ENCODINGS = {
    "utf-8": lambda t: t.encode("utf-8"),
    "utf-8 BOM": lambda t: codecs.BOM_UTF8 + t.encode("utf-8"),
    "utf-16le BOM (Excel unicode text)": lambda t: codecs.BOM_UTF16_LE + t.encode("utf-16-le"),
    "utf-16be BOM": lambda t: codecs.BOM_UTF16_BE + t.encode("utf-16-be"),
    "utf-16le unmarked": lambda t: t.encode("utf-16-le"),
    "utf-32 BOM": lambda t: t.encode("utf-32"),
}


def _write(tmp_path: Path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("encoding", list(ENCODINGS))
def test_every_unicode_encoding_decodes_to_the_same_text(encoding):
    text = "θ_i\tBRDF [sr⁻¹]\r\n45\t0.3183\r\n"
    assert decode_text(ENCODINGS[encoding](text), "f.txt") == text


def test_excel_unicode_text_table_reads_like_the_utf8_csv(tmp_path):
    utf8 = read_table(_write(tmp_path, "t.csv", TABLE.encode()))
    tabbed = TABLE.replace(",", "\t").replace("\n", "\r\n")
    excel = read_table(_write(tmp_path, "t.txt", ENCODINGS["utf-16le BOM (Excel unicode text)"](tabbed)))
    np.testing.assert_array_equal(excel["bsdf"].values, utf8["bsdf"].values)
    np.testing.assert_array_equal(excel["theta_s"].values, utf8["theta_s"].values)


@pytest.mark.parametrize("encoding", ["utf-16le BOM (Excel unicode text)", "utf-16be BOM", "utf-32 BOM"])
def test_ray_file_spectrum_and_vendor_file_read_in_utf16_and_utf32(tmp_path, encoding):
    enc = ENCODINGS[encoding]
    rays = read_ray_file(_write(tmp_path, "rays.txt", enc(RAYS)))
    np.testing.assert_array_equal(rays.power, [0.25] * 4)
    wl, values, _ = read_spectrum_arrays(_write(tmp_path, "s.csv", enc(SPECTRUM)))
    np.testing.assert_allclose(values, 1 + 0.01 * wl, rtol=0, atol=5e-4)
    golden = GOLDEN / "zemax_lambert_brdf.bsdf"
    again = read_zemax(_write(tmp_path, "z.bsdf", enc(golden.read_text())))
    np.testing.assert_array_equal(again.table.values, read_zemax(golden).table.values)


READERS = {
    "table": (read_table, "t.csv"),
    "ray file": (read_ray_file, "rays.txt"),
    "spectrum": (read_spectrum_arrays, "s.csv"),
    "zemax": (read_zemax, "z.bsdf"),
    "tracepro": (read_tracepro, "tp.txt"),
    "plate": (load_plate, "plate.json"),
    "scene": (load_scene, "scene.toml"),
}
BROKEN = {
    "empty": (b"", "empty"),
    "binary": (bytes(range(256)) * 4, "not UTF-8 text"),
    "NUL bytes": (b"# a header\n1 2 3\n\x00\x00\x00\x00 4 5\n", ":3: binary data (NUL byte)"),
    "cut UTF-16": (codecs.BOM_UTF16_LE + "45\t0.31\n".encode("utf-16-le")[:-1], "cut or invalid character"),
    "Latin-1 in a UTF-8 format": ("r = 0.9 # réflectance\n".encode("latin-1"), "byte 0xe9"),
}


#: vendor formats and measured tables fall back to a Windows code page: Latin-1 there is read, not refused
CODE_PAGE_READERS = ("zemax", "tracepro", "table")


@pytest.mark.parametrize("reader, broken", [(r, b) for r in READERS for b in BROKEN
                                            if not (b == "Latin-1 in a UTF-8 format" and r in CODE_PAGE_READERS)])
def test_broken_text_is_one_line_naming_the_file(tmp_path, reader, broken):
    fn, name = READERS[reader]
    data, needle = BROKEN[broken]
    path = _write(tmp_path, name, data)
    with pytest.raises(FormatError) as info:
        fn(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and needle in message, message


@pytest.mark.parametrize("text, cut", [
    ("1 0.3183\n2 0.3184\n3 0.3185\n4 0.318", True),  # decimals lost
    ("1 1.25E-005\n2 1.5E-005\n3 2.125E-005\n4 3.5E-00", True),  # exponent digits lost
    ("1 1.25E-005\n2 1.5E-005\n3 2.125E-005\n4 3.5E-", True),  # exponent sign without digits
    ("1,0.5\n2,0.25\n3,0.75\n4,", False),  # empty last cell: judged with delimiter ","
    ("1 0.3183\n2 0.3184\n3 0.3185\n4 0.3186", False),  # complete, no final line break
    ("1 0.3\n2 0.25\n3 0.125\n4 0.5", False),  # no common layout: nothing to judge
    ("1 0.3183\n2 0.3184\n3 0.3185\n4 0.318\n", False),  # ends with a line break: rows are whole
])
def test_cut_last_number_is_recognised(text, cut):
    if cut:
        with pytest.raises(FormatError, match=r"f\.txt:4: the file ends inside a number"):
            refuse_cut_last_line(text, "f.txt", None, expected="two numbers")
    else:
        refuse_cut_last_line(text, "f.txt", None, expected="two numbers")
    with pytest.raises(FormatError, match="ends inside a number"):
        refuse_cut_last_line("1,0.5\n2,0.25\n3,0.75\n4,", "f.txt", ",", expected="two numbers")


@pytest.mark.parametrize("reader, text", [("table", TABLE), ("ray file", RAYS), ("spectrum", SPECTRUM)])
def test_readers_refuse_a_file_cut_inside_its_last_number(tmp_path, reader, text):
    fn, name = READERS[reader]
    path = _write(tmp_path, name, text.rstrip("\n")[:-1].encode())
    with pytest.raises(FormatError, match="ends inside a number"):
        fn(path)


def test_tracepro_file_cut_before_save_data_is_refused(tmp_path):
    lines = (GOLDEN / "tracepro_abg.txt").read_bytes().rstrip(b"\r\n").split(b"\r\n")
    assert lines[-1] == b"SAVE-DATA"
    path = _write(tmp_path, "tp.txt", b"\r\n".join(lines[:-1]) + b"\r\n")
    with pytest.raises(FormatError, match=r"tp\.txt:\d+: field 'SAVE-DATA': the file ends before 'SAVE-DATA'"):
        read_tracepro(path)


def test_cli_reads_utf16_budget_table_and_refuses_a_cut_one(tmp_path, capsys):
    table = {"power": {"B_bibs": 10.9, "F_bibs": 6.5, "B_biys": 26.3, "F_biys": 26.9, "B_yiys": 45.0,
                       "F_yiys": 48.0}}
    text = json.dumps(table)
    outputs = []
    for name, data in (("budget16.json", ENCODINGS["utf-16le BOM (Excel unicode text)"](text)),
                       ("budget8.json", text.encode())):
        assert main(["budget", "--table", str(_write(tmp_path, name, data)), "--eta-mc", "0.9", "--json"]) == 0
        outputs.append(json.loads(capsys.readouterr().out))
    assert outputs[0] == outputs[1] and outputs[0]["converged"]["total"] > 0
    cut = _write(tmp_path, "cut.json", text[:-3].encode())
    code = main(["budget", "--table", str(cut), "--eta-mc", "0.9"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cut.json" in err and "Traceback" not in err


def test_text_and_encoding_names_what_it_read():
    assert text_and_encoding(b"a", "f") == ("a", "utf-8")
    assert text_and_encoding(codecs.BOM_UTF8 + b"a", "f") == ("a", "utf-8-sig")
    assert text_and_encoding("a".encode("utf-16"), "f")[1] == "utf-16-le"
    assert text_and_encoding(b"caf\xe9", "f", legacy="cp1252") == ("café", "cp1252")


BLOCKS = ["theta_i,theta_s,phi_s,brdf"] + [f"{ti},{t},0,0.3183" for ti in (0, 20, 40) for t in range(0, 90, 5)]


@pytest.mark.parametrize("kept, found", [(len(BLOCKS) - 1, 17), (len(BLOCKS) - 9, 9), (len(BLOCKS) - 17, 1)])
def test_table_whose_last_incidence_block_stops_early_is_refused(tmp_path, kept, found):
    path = _write(tmp_path, "t.csv", ("\n".join(BLOCKS[:kept]) + "\n").encode())
    with pytest.raises(FormatError, match=rf"t\.csv:{kept}: field 'theta_i=40': the last block stops early.*"
                                          rf"expected 18 scatter angles like every other block, got {found}"):
        read_table(path)


def test_blocks_of_their_own_sizes_are_read(tmp_path):
    # a shorter last block that is not the beginning of the others (or others that differ) is a measurement
    rows = BLOCKS[:-18] + [f"40,{t},0,0.3183" for t in range(0, 90, 10)]
    assert read_table(_write(tmp_path, "t.csv", ("\n".join(rows) + "\n").encode())).sizes["record"] == 36 + 9


def test_processes_a_command_starts_print_no_library_warnings():
    # dask workers and the run's helper inherit it: JAX warned in a sweep's workers of a concurrent write to an
    # empty compilation cache, and the command's one error line became seven
    before = os.environ.get("PYTHONWARNINGS")
    with child_warnings_off():
        done = subprocess.run([sys.executable, "-c", "import warnings; warnings.warn('a library warning')"],
                              capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stderr == ""
    assert os.environ.get("PYTHONWARNINGS") == before
