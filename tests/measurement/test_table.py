"""Measured text tables → the calibrated dataset (bsdfkit.measurement.table), against exact synthetic truths.

Truth: a Lambertian body plus a Harvey–Shack Gaussian lobe, f = ρ(λ)/π + A(λ)·exp(−|β − β0|²/2σ²) [1/sr],
written in every layout the reader accepts (wide/long, in-plane/two arcs, reflection/transmission,
comma/semicolon/tab, BOM, decimal comma, units in headers, cosine-corrected values and factors) with
``repr`` floats, and read back to a relative 1e-12 (the only error is the rounding of π·f/π or f·cos/cos).
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from bsdfkit.cli.main import main
from bsdfkit.core.errors import BsdfkitError, InputError
from bsdfkit.io import netcdf
from bsdfkit.measurement.describe import describe
from bsdfkit.measurement.table import DEFAULT_RELATIVE_STD, guess_can_open, read_table
from bsdfkit.tables.to_dataset import ingest, source_kind

DATA = Path(__file__).parent.parent / "data" / "ansys-radiant-zemax-bsdf"
ANSYS_CSV = DATA / "inplane_spectral_goniometric_2D_data.csv"
RADIANT = DATA / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"
RTOL = 1e-12
LAMBDAS = (450.0, 550.0, 650.0)
INCIDENCES = (0.0, 20.0, 45.0)


def truth(theta_i, theta_s, phi_s, lam):
    """f [1/sr] of a Lambertian body plus a Gaussian lobe about β0, wavelength-dependent."""
    rho = 0.3 + 0.2 * (lam - 450.0) / 200.0
    amp = 2.0 + 0.01 * (lam - 450.0)
    sigma = 0.08
    bx = np.sin(np.radians(theta_s)) * np.cos(np.radians(phi_s)) - np.sin(np.radians(theta_i))
    by = np.sin(np.radians(theta_s)) * np.sin(np.radians(phi_s))
    return rho / np.pi + amp * np.exp(-(bx**2 + by**2) / (2 * sigma**2))


def in_plane(theta_i):
    """Signed in-plane angles (deg), positive on the specular side."""
    return [a for a in range(-85, 90, 5)]


def two_arcs(theta_i):
    """(θs, φs) of the in-plane arc and of the perpendicular arc through the specular direction."""
    out = [(abs(a), 0.0 if a >= 0 else 180.0) for a in in_plane(theta_i)]
    ti = math.radians(theta_i)
    for e in range(-60, 61, 10):
        if e == 0:
            continue
        eps = math.radians(e)
        d = (math.cos(eps) * math.sin(ti), math.sin(eps), math.cos(eps) * math.cos(ti))
        out.append((math.degrees(math.atan2(math.hypot(d[0], d[1]), d[2])),
                    math.degrees(math.atan2(d[1], d[0])) % 360.0))
    return out


def write(path: Path, lines: list[str], encoding: str = "utf-8", newline: str = "\n") -> Path:
    path.write_bytes((newline.join(lines) + newline).encode(encoding))
    return path


def check_truth(ds, transform=lambda f, th: f):
    """Every finite bsdf equals the truth at its record and wavelength."""
    f = ds["bsdf"].values
    expected = truth(ds["theta_i"].values[:, None], ds["theta_s"].values[:, None], ds["phi_s"].values[:, None],
                     ds["wavelength"].values[None, :])
    ok = np.isfinite(f)
    assert ok.sum() > 0
    np.testing.assert_allclose(f[ok], expected[ok], rtol=RTOL, atol=0)


# ------------------------------------------------------------------------------------------- layouts
def test_wide_in_plane_comma_reflection_exact(tmp_path):
    lines = ["# quantity: BRDF", "# sample: truth plate",
             "theta_i,scatter angle," + ",".join(f"{x:g}nm" for x in LAMBDAS)]
    for ti in INCIDENCES:
        for a in in_plane(ti):
            phi = 0.0 if a >= 0 else 180.0
            lines.append(f"{ti:g},{a:g}," + ",".join(repr(float(truth(ti, abs(a), phi, lam))) for lam in LAMBDAS))
    ds = read_table(write(tmp_path / "wide.csv", lines))
    check_truth(ds)
    assert ds.sizes["wavelength"] == 3 and ds.sizes["record"] == len(INCIDENCES) * 35
    assert set(ds["arc"].values) == {"in_plane"} and set(ds["side"].values) == {"reflection"}
    assert ds.attrs["quantity"] == "bsdf" and ds.attrs["source_quantity"] == "brdf"
    assert ds.attrs["sample_name"] == "truth plate"
    # signed angle: negative = source side (phi_s = 180), positive = specular side (phi_s = 0)
    neg = ds.isel(record=int(np.flatnonzero(ds["source_line"].values == 4)[0]))
    assert float(neg["theta_s"]) == 85.0 and float(neg["phi_s"]) == 180.0
    np.testing.assert_allclose(ds["bsdf_std"].values, DEFAULT_RELATIVE_STD * np.abs(ds["bsdf"].values))
    # a table with its own incidences refuses --incidence instead of ignoring it silently
    with pytest.raises(InputError, match="--incidence"):
        read_table(tmp_path / "wide.csv", incidence_deg=45.0)


def test_long_two_arcs_semicolon_decimal_comma_transmission_exact(tmp_path):
    lines = ["AOI (deg);theta_s (deg);phi_s (deg);wavelength (nm);BTDF (1/sr)"]
    for ti in INCIDENCES:
        for ts, ps in two_arcs(ti):
            for lam in LAMBDAS:
                cells = [repr(float(x)).replace(".", ",") for x in (ti, ts, ps, lam, truth(ti, ts, ps, lam))]
                lines.append(";".join(cells))
    ds = read_table(write(tmp_path / "long.csv", lines, newline="\r\n"))
    check_truth(ds)
    assert set(ds["side"].values) == {"transmission"}
    arcs = ds["arc"].values
    assert (arcs == "in_plane").sum() == len(INCIDENCES) * 35 and (arcs == "perpendicular").sum() > 0
    assert (arcs == "other").sum() == 0
    assert ds.attrs["manifest_json"].count('"decimal_comma": true') == 1


def test_tab_bom_cosine_corrected_microns_exact(tmp_path):
    lines = ["Incidence angle (deg)\tθs [deg]\tφs [deg]\tλ (µm)\tccBRDF"]
    for ti in INCIDENCES:
        for ts, ps in two_arcs(ti):
            if ts >= 89.0:
                continue
            for lam in LAMBDAS:
                cc = truth(ti, ts, ps, lam) * math.cos(math.radians(ts))
                lines.append("\t".join([repr(ti), repr(ts), repr(ps), repr(lam / 1000.0), repr(float(cc))]))
    ds = read_table(write(tmp_path / "tab.txt", lines, encoding="utf-8-sig"))
    np.testing.assert_allclose(ds["wavelength"].values, LAMBDAS, rtol=1e-15)
    check_truth(ds)
    assert ds.attrs["source_quantity"] == "ccbrdf"


def test_reflectance_factor_percent_and_quantity_option(tmp_path):
    lines = ["theta_i;theta_s;value (%)"]
    for a in in_plane(20.0):
        lines.append(f"20;{a};{repr(100.0 * math.pi * float(truth(20.0, abs(a), 0.0 if a >= 0 else 180.0, 550.0)))}")
    path = write(tmp_path / "rf.csv", lines)
    with pytest.raises(InputError, match="does not say which quantity"):
        read_table(path)
    ds = read_table(path, quantity="reflectance-factor", wavelength_nm=550.0)
    check_truth(ds)
    assert ds["wavelength"].values.tolist() == [550.0]


def test_wide_by_incidence_monochrome_without_wavelength(tmp_path):
    lines = ["# BRDF of a monochrome scan", "scatter angle,AOI 0,AOI 20,AOI 45"]
    for a in in_plane(0.0):
        lines.append(f"{a}," + ",".join(repr(float(truth(ti, abs(a), 0.0 if a >= 0 else 180.0, 550.0)))
                                         for ti in INCIDENCES))
    ds = read_table(write(tmp_path / "byinc.csv", lines), quantity="brdf")
    assert np.isnan(ds["wavelength"].values).all() and "wavelength_note" in ds.attrs
    f = ds["bsdf"].values[:, 0]
    expected = truth(ds["theta_i"].values, ds["theta_s"].values, ds["phi_s"].values, 550.0)
    np.testing.assert_allclose(f, expected, rtol=RTOL)
    assert sorted(set(ds["theta_i"].values.tolist())) == list(INCIDENCES)


def test_side_column_bsdf_radians_and_std_columns(tmp_path):
    lines = ["thetai [rad],thetas [rad],phis [rad],side,BSDF,BSDF std"]
    for side in ("R", "T"):
        for ts, ps in two_arcs(45.0):
            f = float(truth(45.0, ts, ps, 550.0))
            lines.append(",".join([repr(math.radians(45.0)), repr(math.radians(ts)), repr(math.radians(ps)), side,
                                   repr(f), repr(0.01 * f)]))
    ds = read_table(write(tmp_path / "sides.csv", lines), wavelength_nm=550.0)
    assert sorted(set(ds["side"].values)) == ["reflection", "transmission"]
    np.testing.assert_allclose(ds["theta_i"].values, 45.0, rtol=1e-14)
    expected = truth(ds["theta_i"].values, ds["theta_s"].values, ds["phi_s"].values, 550.0)
    np.testing.assert_allclose(ds["bsdf"].values[:, 0], expected, rtol=1e-12)
    np.testing.assert_allclose(ds["bsdf_std"].values[:, 0], 0.01 * expected, rtol=1e-12)
    assert "uncertainty column" in ds.attrs["bsdf_std_origin"]


def test_relative_std_option_and_relative_column(tmp_path):
    lines = ["theta_i,theta_s,BRDF,rel. uncertainty (%)", "10,5,0.5,2", "10,-5,0.25,"]
    ds = read_table(write(tmp_path / "rel.csv", lines), relative_std=0.1)
    np.testing.assert_allclose(ds["bsdf_std"].values[:, 0], [0.01, 0.025])  # 2 % of 0.5; 10 % of 0.25


def test_gaps_are_gaps_not_zeros(tmp_path):
    lines = ["theta_i,theta_s,500,600",
             "10,-30,0.1,0.2",
             "10,-15,,",  # empty cells: record dropped
             "10,-10,0,0",  # all zero: the source blocking the detector -> gap (zeros=auto)
             "10,0,NaN,0.3",  # one wavelength missing
             "10,5,0.0,0.7",  # a zero next to a non-zero value is a value
             "10,10,0.4,0.5"]
    path = write(tmp_path / "gaps.csv", lines)
    ds = read_table(path, quantity="brdf")
    assert ds.sizes["record"] == 4 and ds.attrs["gap_records_dropped"] == 2 and ds.attrs["zero_records_as_gaps"] == 1
    f = ds["bsdf"].values
    assert np.isnan(f[1, 0]) and f[1, 1] == 0.3 and f[2, 0] == 0.0 and f[2, 1] == 0.7
    assert np.isnan(ds["bsdf_std"].values[1, 0])
    keep = read_table(path, quantity="brdf", zeros="keep")
    assert keep.sizes["record"] == 5
    missing = read_table(path, quantity="brdf", zeros="missing")
    assert missing.sizes["record"] == 4 and np.isnan(missing["bsdf"].values[2, 0])


def test_ansys_csv_reflectance_factor():
    ds = read_table(ANSYS_CSV, quantity="reflectance-factor")
    assert ds.sizes["wavelength"] == 35 and ds["wavelength"].values[0] == 390.0 and ds["wavelength"].values[-1] == 730
    assert ds.attrs["zero_records_as_gaps"] == 26 and ds.sizes["record"] == 329 - 26
    assert incidences_of(ds) == [10.0, 25.0, 40.0, 60.0, 80.0]
    # line 2 of the file: 10,-78,0.7165,... -> theta_s 78 on the source side, BRDF = R/pi
    rec = ds.isel(record=int(np.flatnonzero(ds["source_line"].values == 2)[0]))
    assert float(rec["theta_s"]) == 78.0 and float(rec["phi_s"]) == 180.0
    assert float(rec["bsdf"].sel(wavelength=390.0)) == pytest.approx(0.7165 / np.pi, rel=1e-15)
    # the specular peak sits at +theta_i (phi_s = 0)
    sub = ds.isel(record=np.flatnonzero(ds["theta_i"].values == 25.0))
    peak = int(np.argmax(sub["bsdf"].sel(wavelength=550.0).values))
    assert float(sub["theta_s"].values[peak]) == 25.0 and float(sub["phi_s"].values[peak]) == 0.0
    info = describe(ds)
    assert info["records"] == 303 and info["sides"] == ["reflection"]


def incidences_of(ds):
    return sorted(set(ds["theta_i"].values.tolist()))


def test_netcdf_round_trip_and_dispatch(tmp_path):
    ds = ingest(ANSYS_CSV, quantity="reflectance-factor")
    out = netcdf.save(ds, tmp_path / "a.nc")
    back = netcdf.load(out, quantity="bsdf")
    np.testing.assert_array_equal(back["bsdf"].values, ds["bsdf"].values)
    assert list(back["arc"].values) == list(ds["arc"].values)
    assert source_kind(ANSYS_CSV) == "table" and source_kind(RADIANT) == "zemax" and source_kind(out) == "netcdf"
    assert guess_can_open(ANSYS_CSV) and not guess_can_open(RADIANT) and not guess_can_open(out)
    assert not guess_can_open(tmp_path) and not guess_can_open(tmp_path / "nothing.csv")
    with pytest.raises(InputError, match="options apply to text tables"):
        ingest(ROOT / "measurements" / "cl830-synthetic", quantity="brdf")


def test_cli_ingest_table_and_info(tmp_path, capsys):
    out = tmp_path / "a.nc"
    assert main(["ingest", str(ANSYS_CSV), "--quantity", "reflectance-factor", "-o", str(out)]) == 0
    assert "303 records" in capsys.readouterr().out
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "390-730 nm" in text and "θi = 80°" in text
    assert main(["ingest", str(ANSYS_CSV), "--quantity", "reflectance-factor", "-o", str(out)]) == 2  # exists
    assert "--force" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------- malformed tables
GOOD_HEADER = "theta_i,theta_s,500nm,600nm"
MALFORMED = [
    # (name, lines, options, substrings the one-line message must contain)
    ("text_cell", [GOOD_HEADER, "10,5,0.1,0.2", "10,10,abc,0.2"], {"quantity": "brdf"},
     [":3", "column 3 '500nm'", "not a number"]),
    ("field_count", [GOOD_HEADER, "10,5,0.1,0.2", "10,10,0.1"], {"quantity": "brdf"}, [":3", "wrong number of fields"]),
    ("incidence_range", [GOOD_HEADER, "95,5,0.1,0.2"], {"quantity": "brdf"}, [":2", "theta_i", "out of range"]),
    ("scatter_range", [GOOD_HEADER, "10,120,0.1,0.2"], {"quantity": "brdf"}, [":2", "theta_s", "out of range"]),
    ("no_quantity", [GOOD_HEADER, "10,5,0.1,0.2"], {}, [":1", "500nm", "--quantity"]),
    ("quantity_conflict", ["theta_i,theta_s,BRDF", "10,5,0.1"], {"quantity": "btdf"}, [":1", "BRDF", "btdf"]),
    ("side_conflict", ["theta_i,theta_s,BRDF", "10,5,0.1"], {"side": "transmission"}, [":2", "BRDF", "side"]),
    ("wavelength_twice", ["theta_i,theta_s,550,550nm", "10,5,0.1,0.2"], {"quantity": "brdf"}, [":1", "550nm", "twice"]),
    ("wavelength_order", ["theta_i,theta_s,600,550", "10,5,0.1,0.2"], {"quantity": "brdf"},
     [":1", "550", "increasing"]),
    ("infinite", [GOOD_HEADER, "10,5,inf,0.2"], {"quantity": "brdf"}, [":2", "500nm", "finite"]),
    ("header_only", ["# comment", GOOD_HEADER], {"quantity": "brdf"}, [":2", "header only"]),
    ("empty", ["# nothing here"], {}, [":1", "empty"]),
    ("data_first", ["10,5,0.1,0.2", GOOD_HEADER], {"quantity": "brdf"}, [":1", "data before a header"]),
    ("no_scatter_angle", ["theta_i,phi_i,BRDF", "10,180,0.1"], {}, [":1", "scatter-angle"]),
    ("number_header", ["theta_i,theta_s,10,20", "10,5,0.1,0.2"], {"quantity": "brdf"}, [":1", "10", "wavelength"]),
    ("side_value", ["theta_i,theta_s,side,BSDF", "10,5,X,0.1"], {}, [":2", "side", "'X'"]),
    ("negative_std", ["theta_i,theta_s,BRDF,std", "10,5,0.1,-0.01"], {}, [":2", "std", "negative"]),
    ("all_gaps", [GOOD_HEADER, "10,5,,", "10,6,nan,-"], {"quantity": "brdf"}, ["no values"]),
    ("angle_unit", ["theta_i (grad),theta_s,BRDF", "10,5,0.1"], {}, [":1", "grad", "unit"]),
    ("missing_angle", [GOOD_HEADER, "10,,0.1,0.2"], {"quantity": "brdf"}, [":2", "theta_s", "missing"]),
    ("no_value_column", ["theta_i,theta_s,comment", "10,5,x"], {}, [":1", "value column"]),
]


@pytest.mark.parametrize("name,lines,options,parts", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_tables_give_one_line_errors(tmp_path, name, lines, options, parts):
    path = write(tmp_path / f"{name}.csv", lines)
    with pytest.raises(BsdfkitError) as info:
        read_table(path, **options)
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message
    for part in parts:
        assert part in message, (part, message)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_table(tmp_path / "absent.csv", quantity="brdf")
    with pytest.raises(InputError, match="folder"):
        read_table(tmp_path, quantity="brdf")


@pytest.mark.parametrize("name", ["text_cell", "no_quantity", "field_count"])
def test_cli_errors_exit_2_one_line(tmp_path, capsys, name):
    _, lines, options, parts = next(m for m in MALFORMED if m[0] == name)
    path = write(tmp_path / f"{name}.csv", lines)
    argv = ["ingest", str(path), "-o", str(tmp_path / "out.nc")]
    for key, value in options.items():
        argv += [f"--{key.replace('_', '-')}", str(value)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("bsdfkit ingest: error: ") and "Traceback" not in err
    assert all(p in err for p in parts)
    assert not (tmp_path / "out.nc").exists()


@pytest.mark.slow
def test_cli_error_in_a_subprocess_has_no_traceback(tmp_path):
    path = write(tmp_path / "bad.csv", [GOOD_HEADER, "10,5,0.1,0.2", "10,10,abc,0.2"])
    done = subprocess.run([sys.executable, "-m", "bsdfkit", "ingest", str(path), "--quantity", "brdf", "-o",
                           str(tmp_path / "o.nc")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip().count("\n") == 0 and "bad.csv:3" in done.stderr


OTHER_LAYOUTS = [
    # (name, text, encoding, options, expected (theta_i, theta_s, phi_s, side, bsdf) of the first two records)
    ("whitespace", "AOI theta_s phi_s BRDF\n10 5 0 0.1\n10 20 180 0.2\n", "utf-8", {}, None),
    ("preamble", "Sample: X\nDate: 2024-01-01\n\nAOI,theta_s,BRDF\n10,5,0.1\n10,-20,0.2\n", "utf-8", {}, None),
    ("cp1252_degree", "Incidence (°);Scatter angle (°);BRDF\n10;5;0,1\n10;-20;0,2\n", "cp1252", {}, None),
    ("utf16_tab_crlf", "theta_i\ttheta_s\tBRDF\r\n10\t5\t0.1\r\n10\t-20\t0.2\r\n", "utf-16", {}, None),
    ("quoted", '"theta_i","theta_s","BRDF [1/sr]"\n"10","5","0.1"\n"10","-20","0.2"\n', "utf-8", {}, None),
    ("trailing_separator", "theta_i;theta_s;BRDF;\n10;5;0,1;\n10;-20;0,2;\n", "utf-8", {}, None),
    ("units_row", "theta_i,theta_s,BRDF\ndeg,deg,1/sr\n10,5,0.1\n10,-20,0.2\n", "utf-8", {}, None),
    ("old_mac_cr", "theta_i,theta_s,BRDF\r10,5,0.1\r10,-20,0.2\r", "utf-8", {}, None),
    ("blocks_by_comment", "# wavelength: 633 nm\n# incidence: 10\ntheta_s,BRDF\n5,0.1\n-20,0.2\n# incidence: 30\n"
     "theta_s,BRDF\n5,0.3\n", "utf-8", {}, None),
    ("blocks_by_lines", "Incidence: 10 deg\nAOV\tBRDF\n5\t0.1\n-20\t0.2\nIncidence: 30 deg\nAOV\tBRDF\n5\t0.3\n",
     "utf-8", {}, None),
    ("camel_case", "IncidentAngle;ScatterAngle;BRDF\n10;5;0.1\n10;-20;0.2\n", "utf-8", {}, None),
    ("signed_suffix_per_sr", "aoi_deg,theta_s_signed,brdf_sr-1\n10,5,0.1\n10,-20,0.2\n", "utf-8", {}, None),
    ("per_sr_words", "theta_i\tsigned scatter angle\tBRDF 1/sr\n10\t5\t0.1\n10\t-20\t0.2\n", "utf-8", {}, None),
]


@pytest.mark.parametrize("name,text,encoding,options,_", OTHER_LAYOUTS, ids=[c[0] for c in OTHER_LAYOUTS])
def test_other_instrument_layouts(tmp_path, name, text, encoding, options, _):
    path = tmp_path / f"{name}.txt"
    path.write_bytes(text.encode(encoding))
    assert guess_can_open(path)
    ds = read_table(path, **options)
    assert ds["theta_i"].values[:2].tolist() == [10.0, 10.0]
    assert ds["theta_s"].values[:2].tolist() == [5.0, 20.0]
    assert ds["phi_s"].values[:2].tolist() == [0.0, 180.0]
    assert ds["bsdf"].values[:2, 0].tolist() == [0.1, 0.2] and set(ds["side"].values) == {"reflection"}
    if name.startswith("blocks"):
        assert ds["theta_i"].values.tolist() == [10.0, 10.0, 30.0]


def test_brdf_and_btdf_columns_give_both_sides(tmp_path):
    path = write(tmp_path / "both.csv", ["theta_i,theta_s,BRDF,BTDF", "10,5,0.1,0.05", "10,-20,0.2,"])
    ds = read_table(path, wavelength_nm=550.0)
    assert ds["side"].values.tolist() == ["reflection", "transmission", "reflection"]
    assert ds["bsdf"].values[:, 0].tolist() == [0.1, 0.05, 0.2]


def _long_rows(phi_i: float, specular_at: float, lam: float = 550.0, lobe: bool = True) -> list[str]:
    """LONG rows θi, φi, θs, φs, λ, BRDF of the truth on the in-plane arc, the specular side at φs = specular_at."""
    rows = ["theta_i,phi_i,theta_s,phi_s,wavelength,BRDF"]
    for ti in (20.0, 45.0):
        for a in in_plane(ti):
            if -ti - 5 < a < -ti + 5:  # the source blocks the detector near retro-reflection
                continue
            f = truth(ti, abs(a), 0.0 if a >= 0 else 180.0, lam)
            if not lobe:
                f = truth(ti, 80.0, 90.0, lam)  # the body alone (the lobe is negligible there)
            phi = specular_at if a >= 0 else (specular_at + 180.0) % 360.0
            rows.append(f"{ti!r},{phi_i!r},{float(abs(a))!r},{phi!r},{lam!r},{float(f)!r}")
    return rows


@pytest.mark.parametrize("phi_i, specular_at, note", [
    (0.0, 180.0, False),   # the documented sample frame: specular at φi − 180°
    (0.0, 0.0, True),      # φs from the specular direction although φi = 0: decided by where the peaks are
    (90.0, 0.0, True),
    (180.0, 0.0, False),   # both conventions agree
])
def test_azimuth_origin_is_decided_by_the_peaks(tmp_path, phi_i, specular_at, note):
    ds = read_table(write(tmp_path / "long.csv", _long_rows(phi_i, specular_at)))
    assert ("azimuth_note" in ds.attrs) is note
    relative = (ds["phi_s"].values - (ds["phi_i"].values - 180.0)) % 360.0  # back to φs = 0 on the specular side
    expected = truth(ds["theta_i"].values, ds["theta_s"].values, relative, 550.0)
    np.testing.assert_allclose(ds["bsdf"].values[:, 0], expected, rtol=RTOL)
    assert set(ds["arc"].values) == {"in_plane"}


def test_azimuth_origin_of_a_table_without_peaks_is_the_documented_one(tmp_path):
    rows = _long_rows(0.0, 0.0, lobe=False)
    ds = read_table(write(tmp_path / "flat.csv", rows))
    assert "azimuth_note" not in ds.attrs
    written = [float(r.split(",")[3]) for r in rows[1:]]
    assert ds["phi_s"].values.tolist() == written  # kept as written


def test_angles_in_radians_with_few_decimals_stay_on_their_arcs(tmp_path):
    rows = ["theta_i (rad),theta_s (rad),phi_s (rad),BRDF"]
    for ts, ps in two_arcs(20.0):
        rows.append(f"{math.radians(20.0):.8f},{math.radians(ts):.8f},{math.radians(ps):.8f},"
                    f"{truth(20.0, ts, ps, 550.0):.10g}")
    ds = read_table(write(tmp_path / "rad.csv", rows), wavelength_nm=550.0)
    arcs = ds["arc"].values.tolist()
    assert arcs.count("in_plane") == len(in_plane(20.0)) and arcs.count("perpendicular") == 12


def test_full_sphere_polar_angles_from_the_front_normal(tmp_path):
    # θs from the front normal up to 180°: beyond 90° a transmitted direction, 180° − θs from the back normal
    rows = ["theta_i,theta_s,phi_s,BSDF"]
    for ti in INCIDENCES:
        for ts, ps in two_arcs(ti):
            f = float(truth(ti, ts, ps, 550.0))  # a number, not an np.float64 repr (refused as text)
            rows.append(f"{ti!r},{ts!r},{ps!r},{f!r}")
            rows.append(f"{ti!r},{180.0 - ts!r},{ps!r},{2 * f!r}")
    ds = read_table(write(tmp_path / "sphere.csv", rows), wavelength_nm=550.0)
    refl = ds["side"].values == "reflection"
    assert refl.sum() == (~refl).sum() > 0
    check_truth(ds.isel(record=np.flatnonzero(refl)))
    trans = ds.isel(record=np.flatnonzero(~refl))  # at 180° − θs from the back normal, same azimuth
    np.testing.assert_allclose(trans["bsdf"].values[:, 0] / 2, truth(trans["theta_i"].values, trans["theta_s"].values,
                                                                     trans["phi_s"].values, 550.0), rtol=RTOL)


@pytest.mark.parametrize("rows, message", [
    (["theta_i,theta_s,phi_s,BRDF", "10,95,0,0.1"], "out of range for the reflection side"),
    (["theta_i,theta_s,phi_s,BTDF", "10,20,0,0.1", "10,150,0,0.1"], "transmission scatter angles in two frames"),
])
def test_polar_angles_beyond_90_that_contradict(tmp_path, rows, message):
    with pytest.raises(BsdfkitError, match=message):
        read_table(write(tmp_path / "bad.csv", rows), wavelength_nm=550.0)


def test_a_direction_measured_twice_is_kept_for_the_engine_to_merge(tmp_path):
    """Repeated directions (every C-plane's nadir, a repeated point) are records, not an error: the
    hemispherical engine merges them with their spread (tests/reduction/test_hemispherical_geometries.py)."""
    path = write(tmp_path / "twice.csv", [GOOD_HEADER, "10,5,0.1,0.2", "10,6,0.1,0.2", "10,5,0.3,0.2"])
    ds = read_table(path, quantity="brdf")
    same = (ds["theta_s"].values == 5.0)
    assert int(same.sum()) == 2
    assert sorted(ds["bsdf"].values[same][:, 0].tolist()) == pytest.approx([0.1, 0.3])



# ------------------------------------------------------------------------------------------- streamed reading
def streamed_table(path: Path, rows: int = 2400, bad_row: int | None = None) -> tuple[Path, dict, int | None]:
    """A long table (θi 10/30°, θs, φs, two wavelengths) with '#' comments every 97 rows, blank lines every 53
    rows, a gap every 41 rows, and optionally the text 'abc' as the value of row ``bad_row``.

    Returns the path, {(θi, θs, φs, λ): value or None (gap)} and the physical line of the bad row."""
    lines = ["# sample: streamed", "theta_i,theta_s,phi_s,wavelength,brdf"]
    truth, bad_line = {}, None
    for k in range(rows):
        if k % 97 == 0:
            lines.append(f"# comment before row {k}")
        if k % 53 == 0:
            lines.append("")
        th_i, rest = (10.0, k) if k < rows // 2 else (30.0, k - rows // 2)
        th_s, ph_s = float(rest // 2 // 24 % 80 + 1), float(rest // 2 % 24 * 15)  # θs > 0: φs tells apart
        lam = 450.0 if rest % 2 == 0 else 650.0
        value = 0.1 + 1e-4 * k + 1e-9 / 3.0
        cell = repr(value)
        if k % 41 == 7:
            cell, value = "", None
        if k == bad_row:
            cell, bad_line = "abc", len(lines) + 1
        truth[(th_i, th_s, ph_s, lam)] = value
        lines.append(f"{th_i!r},{th_s!r},{ph_s!r},{lam!r},{cell}")
    write(path, lines)
    return path, truth, bad_line


@pytest.mark.parametrize("block_lines", [5, 64, 1 << 15])
def test_streamed_reader_gives_the_written_values_across_blocks(tmp_path, monkeypatch, block_lines):
    from bsdfkit.measurement import table

    monkeypatch.setattr(table, "_BLOCK_LINES", block_lines)
    monkeypatch.setattr(table, "_SLICE", 100)  # the whole-table checks and the assembly in many slices
    path, truth, _ = streamed_table(tmp_path / "streamed.csv")
    ds = read_table(path)
    lam = ds["wavelength"].values.tolist()
    assert lam == [450.0, 650.0]
    found = 0
    for r in range(ds.sizes["record"]):
        key = tuple(float(ds[n].values[r]) for n in ("theta_i", "theta_s", "phi_s"))
        for j, w in enumerate(lam):
            expected = truth.get((*key, w), "absent")
            got = float(ds["bsdf"].values[r, j])
            if expected is None or expected == "absent":
                assert math.isnan(got)
            else:
                assert got == expected  # tolerance 0
                found += 1
    assert found == sum(v is not None for v in truth.values())
    assert ds.attrs["sample_name"] == "streamed"


@pytest.mark.parametrize("block_lines", [5, 1 << 15])
def test_streamed_reader_names_the_physical_line_of_a_bad_cell(tmp_path, monkeypatch, block_lines):
    from bsdfkit.measurement import table

    monkeypatch.setattr(table, "_BLOCK_LINES", block_lines)
    path, _, bad_line = streamed_table(tmp_path / "bad.csv", bad_row=2000)
    with pytest.raises(InputError) as info:
        read_table(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{bad_line}: ") and "\n" not in message
    assert "brdf" in message and "'abc'" in message


@pytest.mark.slow
def test_streamed_reader_memory_is_a_small_multiple_of_the_file(tmp_path):
    """Peak RSS of read_table above the interpreter that has read a tiny table (bsdfkit and its lazy imports
    loaded) stays ≤ 3× the file (a 20 MB table: 2.4× with the streaming reader, 22× before it)."""
    path = tmp_path / "large.csv"
    # the lines np.savetxt(fmt=["%g", "%g", "%g", "%.6g", "%.7e"]) writes for θs × φs × λ (90 × 72 × 98), byte for
    # byte, but each distinct number formatted once (10x faster than savetxt's per-row formatting)
    ts, ps, lam = np.arange(0.0, 90.0), np.arange(0.0, 360.0, 5.0), np.linspace(380.0, 780.0, 98)
    f = 0.1 + 0.01 * np.cos(np.radians(ts))[:, None] * (lam / 550.0)  # θs × λ: the brdf repeats over φs
    lam_txt = ["%.6g" % x for x in lam]
    with open(path, "w") as out:
        out.write("theta_i,theta_s,phi_s,wavelength,brdf\n")
        for i, t in enumerate(ts):
            tail = [f"{w},{v:.7e}\n" for w, v in zip(lam_txt, f[i])]
            for p in ps:
                out.write("".join(f"10,{t:g},{p:g}," + x for x in tail))
    tiny = write(tmp_path / "tiny.csv", ["theta_i,theta_s,phi_s,wavelength,brdf", "10,5,0,550,0.1", "10,10,0,550,0.2"])
    measure = f"""
import resource
from bsdfkit.measurement.table import read_table
read_table({str(tiny)!r})
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
ds = read_table({str(path)!r})
print(base, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, ds.sizes["record"])
"""
    done = subprocess.run([sys.executable, "-c", measure], capture_output=True, text=True, timeout=120,
                          env={**__import__("os").environ, "OPENBLAS_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr
    base_kb, peak_kb, records = map(int, done.stdout.split())
    assert records == 90 * 72
    size = path.stat().st_size
    assert size > 19e6
    assert (peak_kb - base_kb) * 1024 <= 3 * size, (peak_kb - base_kb) * 1024 / size


@pytest.mark.slow
def test_saving_a_large_dataset_needs_about_one_matrix_more(tmp_path):
    """netcdf.save stores the record × wavelength matrices one at a time: writing six 32 MB matrices raises the
    peak by at most 2.5 of them (1.0-1.5 measured; in one xarray call every encoded copy existed at once: 6.0).

    The matrices hold a repeating ramp, not random numbers: xarray's encoded copies are as large whatever the
    values, but zlib spends about 7× longer on incompressible doubles (measured 12-14 s against 1.8 s for the
    save), and the ramp, distinct at every position of a 1021-element period, still checks the round trip."""
    out = tmp_path / "big.nc"
    measure = f"""
import resource
import numpy as np, xarray as xr
from bsdfkit.io import netcdf
n_rec, n_wl = 40_000, 100
rng = np.random.default_rng(1)
names = ["bsdf", "bsdf_std", "noise_floor", "bsdf_bispectral", "bsdf_bispectral_std", "noise_floor_bispectral"]
ramp = np.arange(n_rec * n_wl).reshape(n_rec, n_wl) % 1021 / 1024.0
ds = xr.Dataset({{k: (("record", "wavelength"), ramp + j) for j, k in enumerate(names)}},
                coords={{"wavelength": np.linspace(380.0, 780.0, n_wl), "theta_s": ("record", rng.random(n_rec))}})
netcdf.save(ds.isel(record=slice(0, 10)), {str(tmp_path / "warm.nc")!r})
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
netcdf.save(ds, {str(out)!r})
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
assert netcdf.load({str(out)!r}).identical(ds), "round trip"
print(base, peak, ds["bsdf"].nbytes)
"""
    done = subprocess.run([sys.executable, "-c", measure], capture_output=True, text=True, timeout=300,
                          env={**__import__("os").environ, "OPENBLAS_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr
    base_kb, peak_kb, matrix = map(int, done.stdout.split())
    assert (peak_kb - base_kb) * 1024 <= 2.5 * matrix, (peak_kb - base_kb) * 1024 / matrix


def test_a_large_table_cut_inside_its_last_number_names_the_last_line(tmp_path):
    """Beyond 512 kB only the file's tail is read for this check; the message still names the physical line."""
    rows = ["theta_i,theta_s,phi_s,wavelength,brdf"]
    rows += [f"10,{k // 72 % 90},{k % 72 * 5},{550 + k // 6480},{0.1 + k * 1e-7:.7e}" for k in range(24000)]
    text = "\n".join(rows)
    text = text[: text.rindex("e-")]  # the last value stops before its exponent (every row above has e-01)
    path = tmp_path / "cut.csv"
    path.write_text(text)
    assert path.stat().st_size > 600_000
    with pytest.raises(InputError) as info:
        read_table(path)
    assert str(info.value).startswith(f"{path}:{len(rows)}: the file ends inside a number")
