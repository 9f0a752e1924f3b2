"""Input plausibility (issue #26): values and units a table contradicts, dark frames above the signal, physical
line numbers, single-wavelength fits, exact fits, overflow of huge values.

Each refusal is one line on stderr naming the file, the line or field, what was expected and what was found,
with exit status 2 and no traceback; the tests check the wording, not only the status.
"""
from __future__ import annotations

import gzip
import json
import math
import os
import subprocess
import sys
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


# ------------------------------------------------------------------------------------- dark above the signal
def _hot_darks(folder: Path, exposures=("10", "20"), factor=3) -> None:
    """Dark frames of two exposures made ``factor`` times brighter (a light leak while the darks were taken)."""
    dark = folder / "dark.csv.gz"
    lines = gzip.decompress(dark.read_bytes()).decode().splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        if cells[1] in exposures:
            cells = cells[:2] + [str(int(float(c)) * factor) for c in cells[2:]]
        out.append(",".join(cells))
    dark.write_bytes(gzip.compress(("\n".join(out) + "\n").encode()))


def test_dark_above_signal_is_said_by_ingest_and_every_reduction(tiny_export, tmp_path, capsys):
    code, err = _cli(capsys, "ingest", str(tiny_export), "-o", str(tmp_path / "clean.nc"))
    assert code == 0 and "dark" not in err, err  # the untouched export: nothing said
    _hot_darks(tiny_export)
    scan = tmp_path / "hot.nc"
    for argv in (("ingest", str(tiny_export), "-o", str(scan)), ("tis", str(scan), "--incidence", "45"),
                 ("budget", str(scan), "--incidence", "45", "--eta-mc", "0.5")):
        code, err = _cli(capsys, *argv)
        assert code == 0, err
        lines = [x for x in err.strip().splitlines() if "dark" in x]
        assert len(lines) == 1, err
        line = lines[0]
        assert line.startswith(f"bsdfkit {argv[0]}: warning: "), line
        # names the records (their source lines) and the exposures whose darks are too bright
        assert "dark frames above the signal" in line and "exposures 10, 20 s" in line, line
        assert "lines 2," in line and "biased low" in line, line


# ------------------------------------------------------------------------------------- fits of plain tables
def _lambertian(rho):
    return lambda lam, th, ph: rho / math.pi


def test_fit_bsdf_of_a_single_wavelength_table_works(tmp_path, capsys):
    table = _long_table(tmp_path / "mono.csv", _lambertian(0.8), wavelengths=(550.0,))
    code = main(["fit", "bsdf", str(table), "--interaction", "elastic", "--side", "reflection", "--model", "lambert",
                 "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    fit = json.loads(out.out)
    text = json.dumps(fit)
    assert "empty wavelength band" not in text and "nan, nan" not in text
    rho = _find(fit, "rho")
    assert rho == pytest.approx(0.8, rel=1e-6)  # the table's own value: 0.8/π per sr


def _find(obj, key):
    """First value under ``key`` anywhere in a JSON object (a number or a one-element list)."""
    if isinstance(obj, dict):
        if key in obj:
            v = obj[key]
            return v[0] if isinstance(v, list) else v
        obj = list(obj.values())
    if isinstance(obj, list):
        for v in obj:
            found = _find(v, key)
            if found is not None:
                return found
    return None


@pytest.mark.parametrize("rho", [0.5, 1.0])
def test_a_perfect_lambertian_fit_is_not_flagged(tmp_path, capsys, rho):
    """Constant data (zero variance) fitted exactly: R² is 1, not NaN or −10¹⁴; ρ = 1 on its bound is the data's."""
    from bsdfkit import api
    from bsdfkit.fit.least_squares import fit_bsdf
    from bsdfkit.reduction.spectral import interaction_profile

    table = _long_table(tmp_path / "white.csv", _lambertian(rho))
    fit = fit_bsdf(interaction_profile(api.ingest(str(table)), "elastic", "reflection"), "lambert")
    assert float(fit["rho"][0]) == pytest.approx(rho, rel=1e-6)
    assert float(fit["r2"][0]) >= 1.0 - 1e-4
    assert bool(fit["plausible"][0]), fit.attrs["warnings"]
    code, err = _cli(capsys, "fit", "bsdf", str(table), "--interaction", "elastic", "--side", "reflection",
                     "--model", "lambert")
    assert code == 0 and err == "", err


def test_all_zero_table_fit_names_the_file(tmp_path, capsys):
    from bsdfkit import api

    # a scan zeroed after reading (the reader refuses an all-zero table itself): the fit refuses naming the
    # file and saying it is all zero, not "bsdf_std[record=0]"
    table = _long_table(tmp_path / "black.csv", _lambertian(0.5))
    ds = api.ingest(str(table))
    ds["bsdf"][:] = 0.0
    ds["bsdf_std"][:] = 0.0
    scan = tmp_path / "black.nc"
    api.save(ds, str(scan))
    _one_line_error(*_cli(capsys, "fit", "bsdf", str(scan), "--interaction", "elastic", "--side", "reflection",
                          "--model", "lambert"), "black.csv", "all-zero", "every BSDF value is 0")


# ------------------------------------------------------------------------------------- values and units
def test_all_negative_table_is_refused_naming_file_line_and_field(tmp_path, capsys):
    table = _long_table(tmp_path / "neg.csv", lambda lam, th, ph: -0.5 / math.pi)
    line = _one_line_error(*_cli(capsys, "ingest", str(table), "-o", str(tmp_path / "o.nc")),
                           "neg.csv:2:", "field 'brdf'", "negative beyond noise", "450 nm", "216 of 216")
    assert "expected >= 0" in line and "got 'mean -0.1592" in line, line
    assert not (tmp_path / "o.nc").exists()


def test_dark_subtraction_noise_around_zero_is_read(tmp_path):
    """A black sample: values scattered ±1e-4 around 0 (half of them negative) are noise, not refused."""
    from bsdfkit import api

    rng = np.random.default_rng(3)
    noise = iter(rng.normal(0.0, 1e-4, 10_000))
    ds = api.ingest(str(_long_table(tmp_path / "black.csv", lambda lam, th, ph: float(next(noise)))))
    assert ds.attrs["negative_values"] > 0.3 * ds["bsdf"].size  # negatives kept as read


def test_wavelengths_in_metres_are_refused_or_converted_when_declared(tmp_path, capsys):
    plain = _long_table(tmp_path / "m.csv", _lambertian(0.5), wavelengths=(4.5e-7, 5.5e-7, 6.5e-7))
    line = _one_line_error(*_cli(capsys, "ingest", str(plain), "-o", str(tmp_path / "o.nc")),
                           "m.csv:2:", "column 4 'wavelength'", "look like metres", "4.5e-07..6.5e-07")
    assert "expected 1..100000 nm" in line, line
    from bsdfkit import api

    declared = _long_table(tmp_path / "m2.csv", _lambertian(0.5), wavelengths=(4.5e-7, 5.5e-7, 6.5e-7),
                           header="theta_i,theta_s,phi_s,wavelength [m],brdf")
    assert api.ingest(str(declared))["wavelength"].values == pytest.approx([450.0, 550.0, 650.0], rel=1e-12)


def test_um_and_nm_mixed_in_one_column_names_the_rows(tmp_path, capsys):
    table = _long_table(tmp_path / "mix.csv", _lambertian(0.5), wavelengths=(450.0, 0.55, 650.0))
    # rows of the 0.55 block: 2 + 18·12 = 218 onwards
    _one_line_error(*_cli(capsys, "ingest", str(table), "-o", str(tmp_path / "o.nc")),
                    "mix.csv:218:", "column 4 'wavelength'", "two units", "0.55..0.55 on lines 218, 219")


def test_radians_under_a_degree_header_are_refused(tmp_path, capsys):
    lines = ["theta_i [deg],theta_s [deg],phi_s [deg],wavelength,brdf"]
    for th in np.linspace(0.0, 1.5, 16):
        for ph in np.linspace(0.0, 6.0, 12):
            lines.append(f"0.17,{float(th)!r},{float(ph)!r},550,{0.5 / math.pi!r}")
    (tmp_path / "rad.csv").write_text("\n".join(lines) + "\n")
    line = _one_line_error(*_cli(capsys, "ingest", str(tmp_path / "rad.csv"), "-o", str(tmp_path / "o.nc")),
                           "rad.csv:2:", "column 2 'theta_s [deg]'", "look like radians", "16 distinct")
    assert "[rad]" in line, line


@pytest.mark.parametrize("verb", ["ingest", "tis"])
def test_huge_values_are_one_line_without_numpy_warnings(tmp_path, capsys, verb):
    table = _long_table(tmp_path / "huge.csv", lambda lam, th, ph: 1e308)
    argv = (verb, str(table)) + (("-o", str(tmp_path / "o.nc")) if verb == "ingest" else ())
    line = _one_line_error(*_cli(capsys, *argv), "huge.csv:2:", "field 'brdf'", "implausibly large",
                           "got '1e+308'")
    assert "RuntimeWarning" not in line


def test_all_zero_table_is_refused_by_the_reader_naming_the_file(tmp_path, capsys):
    table = _long_table(tmp_path / "zero.csv", lambda lam, th, ph: 0.0)
    _one_line_error(*_cli(capsys, "ingest", str(table), "-o", str(tmp_path / "o.nc")), "zero.csv:2:",
                    "field 'brdf'", "all zero", "0 in all 648 cells")


def test_huge_values_in_a_netcdf_scan_are_one_line_before_computing(tmp_path, capsys):
    from bsdfkit import api

    ds = api.ingest(str(_long_table(tmp_path / "ok.csv", _lambertian(0.5))))
    ds["bsdf"][:] = 1e308  # written by another tool: no reader saw it
    api.save(ds, str(tmp_path / "huge.nc"))
    _one_line_error(*_cli(capsys, "tis", str(tmp_path / "huge.nc")), "huge.nc:", "bsdf of record 0 (source line 2)",
                    "implausibly large", "1e+308")


def test_library_warnings_never_reach_stderr():
    """A numpy RuntimeWarning inside a verb is not printed (bsdfkit says what matters in its own lines); run in a
    fresh interpreter with warnings on, as pytest would capture them itself."""
    code = ("import numpy as np, bsdfkit.cli.tis as t\n"
            "t._run = lambda args: int(np.isinf(np.float64(1e308) * np.float64(10.0))) - 1\n"
            "from bsdfkit.cli.main import main\nraise SystemExit(main(['tis', 'x.nc']))\n")
    done = subprocess.run([sys.executable, "-W", "default", "-c", code], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
