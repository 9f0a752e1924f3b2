"""Input plausibility (issue #26): values and units a table contradicts, dark frames above the signal, physical
line numbers, single-wavelength fits, exact fits, overflow of huge values.

Each refusal is one line on stderr naming the file, the line or field, what was expected and what was found,
with exit status 2 and no traceback; the tests check the wording, not only the status.
"""
from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from bsdfkit.cli.main import main


def _cli(capsys, *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    return code, capsys.readouterr().err


def _one_line_error(code: int, err: str, *needles: str) -> str:
    assert code == 2, err
    assert "Traceback" not in err and "Warning" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def _long_table(path: Path, value, wavelengths=(450.0, 550.0, 650.0), header="theta_i,theta_s,phi_s,wavelength,brdf",
                thetas=range(0, 90, 5)) -> Path:
    """A long-format table at θi = 10° on a (θs, φs) grid; ``value(lam, th, ph)`` gives each BRDF [1/sr]."""
    lines = [header]
    for lam in wavelengths:
        for th in thetas:
            for ph in range(0, 360, 30):
                lines.append(f"10,{th},{ph},{lam!r},{value(lam, th, ph)!r}")
    path.write_text("\n".join(lines) + "\n")
    return path


# ------------------------------------------------------------------------------------- physical line numbers
def test_raw_scan_error_names_the_physical_line_past_a_comment(tiny_export, capsys):
    scan = tiny_export / "scans" / "blue.csv.gz"
    lines = gzip.decompress(scan.read_bytes()).decode().splitlines()
    # a comment and a blank line between data rows, then a bad side on the 4th data row
    cells = lines[3].split(",")
    cells[4] = "sideways"
    lines[3] = ",".join(cells)
    text = [lines[0], lines[1], "# operator note", "", lines[2], lines[3]] + lines[4:]
    scan.write_bytes(gzip.compress(("\n".join(text) + "\n").encode()))
    line = _one_line_error(*_cli(capsys, "info", str(tiny_export)), "blue.csv.gz", "side", "sideways")
    assert "blue.csv.gz:6:" in line, line  # physical line 6 (header 1, rows 2, 5, 6), not the 4th row's 5
