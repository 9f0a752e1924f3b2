"""Issue #44 (points 2 and 3): one physical-plausibility gate for every writer, before anything is written, and a
BSDF XML reader that refuses values no measurement holds (docs/exports.md §2.0, "Plausibility gate")."""
from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hemisphere_truth import Truth, table

from bsdfkit.cli.main import main
from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.plausible import NonphysicalWarning
from bsdfkit.tables.to_dataset import convert

FORMATS = registry.writable()
THETA = (0.0, 30.0)
#: the gate's one message for the source of TIS 1.5 at both incidences (reflection), whatever the format
MESSAGE = ("field 'reflection at theta_i=0 deg': not a physical BSDF (energy conservation): the hemispherical "
           "value exceeds 1 (by more than 0.01 of measurement noise) (and 1 more); nothing written "
           "(--allow-nonphysical writes it anyway); "
           "expected <= 1.01, got 1.5")
#: formats that state each table's TIS as a percentage of 0..100 % (Speos): they cannot hold a source above 1
PERCENT_FORMATS = ("speos", "speosbrdf")


def lambertian(tis_by_theta: dict[float, float]):
    """A Lambertian BSDF callable whose hemispherical value at incidence θ [deg] is ``tis_by_theta[θ]``."""

    def fn(theta_i_deg, side, directions):
        return np.full(np.asarray(directions).shape[:-1], tis_by_theta[float(theta_i_deg)] / np.pi)

    return fn


def _export(tis: float | dict[float, float], fmt: str, path: Path, *, allow: bool = False, force: bool = False):
    values = tis if isinstance(tis, dict) else dict.fromkeys(THETA, tis)
    return export(lambertian(values), fmt, "", "reflection", path, force,
                  settings=ExportSettings(theta_i_deg=THETA, allow_nonphysical=allow))


def _dataset(path: Path, rho: float) -> Path:
    """A measured Lambertian dataset (grid of directions, 550 nm) of hemispherical value ``rho``, as netCDF."""
    ds = table(Truth(rho=rho, b=0.0, A=0.0), "grid", THETA, patch=False)
    ds.to_netcdf(path)
    return path


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_refuses_nonphysical_with_one_message_and_writes_nothing(fmt, tmp_path):
    path = tmp_path / f"out.{fmt}"
    with pytest.raises(ValidationError) as err:
        _export(1.5, fmt, path)
    assert str(err.value) == MESSAGE
    assert list(tmp_path.iterdir()) == []  # no file, no staging file


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_refused_with_force_keeps_the_earlier_file(fmt, tmp_path):
    path = tmp_path / f"out.{fmt}"
    path.write_bytes(b"earlier table\n")
    with pytest.raises(ValidationError, match="not a physical BSDF"):
        _export(1.5, fmt, path, force=True)
    assert path.read_bytes() == b"earlier table\n"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


@pytest.mark.parametrize("fmt", FORMATS)
def test_allow_nonphysical_writes_with_a_warning(fmt, tmp_path):
    path = tmp_path / f"out.{fmt}"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if fmt in PERCENT_FORMATS:  # a percentage above 100 %: the format cannot hold it, said before the reader
            with pytest.raises(ValidationError, match="cannot hold"):
                _export(1.5, fmt, path, allow=True)
            assert list(tmp_path.iterdir()) == []
        else:
            result = _export(1.5, fmt, path, allow=True)
            assert path.is_file()
            assert result.tis_table["reflection"] == pytest.approx([1.5, 1.5], rel=0.02)
    said = [str(w.message) for w in caught if issubclass(w.category, NonphysicalWarning)]
    assert said == [MESSAGE.replace("nothing written (--allow-nonphysical writes it anyway)",
                                    "written anyway (--allow-nonphysical)")]


def test_speos_with_allow_nonphysical_states_an_incidence_it_can_hold(tmp_path):
    # TIS 1.5 at 0 deg, 0.5 at 30 deg: the spectrum is stated at 30 deg, and the file reads back at its own scale
    path = tmp_path / "out.anisotropicbsdf"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonphysicalWarning)
        result = _export({0.0: 1.5, 30.0: 0.5}, "speos", path, allow=True)
    assert result.tis_table["reflection"] == pytest.approx([1.5, 0.5], rel=0.02)
    assert read_any(path).details["spectrum"]["reflection"][0] == 30.0


@pytest.mark.parametrize("fmt", FORMATS)
def test_physical_source_exports_to_every_format(fmt, tmp_path):
    result = _export(0.5, fmt, tmp_path / f"out.{fmt}")
    assert result.tis_table["reflection"] == pytest.approx([0.5, 0.5], rel=0.02)


def test_sum_of_both_sides_is_checked(tmp_path):
    # 0.6 + 0.6 per side is physical alone, not together
    def fn(theta_i_deg, side, directions):
        return np.full(np.asarray(directions).shape[:-1], 0.6 / np.pi)

    with pytest.raises(ValidationError, match=r"reflection \+ transmission exceeds 1.*got 1\.2"):
        export(fn, "asap", "", "both", tmp_path / "both.asap", settings=ExportSettings(theta_i_deg=THETA))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt", FORMATS)
def test_convert_refuses_a_measured_dataset_above_one(fmt, tmp_path):
    source = _dataset(tmp_path / "src.nc", 1.5)
    out = tmp_path / "out" / f"out.{fmt}"
    out.parent.mkdir()
    with pytest.raises(ValidationError) as err:
        convert(source, fmt, out)
    assert ("reflection at theta_i=0 deg': not a physical BSDF (energy conservation): the hemispherical value "
            "exceeds 1") in str(err.value)
    assert list(out.parent.iterdir()) == []


def test_convert_and_export_cli_exit_2_with_one_line_for_every_format(tmp_path, capsys):
    source = _dataset(tmp_path / "src.nc", 1.5)
    lines = set()
    for fmt in FORMATS:
        for verb in ("export", "convert"):
            out = tmp_path / f"{verb}.{fmt}"
            out.write_bytes(b"earlier\n")
            extra = ["--interaction", "elastic"] if verb == "export" else []
            code = main([verb, str(source), "--to", fmt, "-o", str(out), "--force", *extra])
            captured = capsys.readouterr()
            assert code == 2, (verb, fmt, captured.err)
            assert captured.out == ""
            err = captured.err.strip().splitlines()
            assert len(err) == 1, err
            lines.add(re.sub(r"^bsdfkit (export|convert): error: ", "", err[0]))
            assert out.read_bytes() == b"earlier\n"
    assert len(lines) == 1, lines  # one message, every format, both verbs
    assert "not a physical BSDF" in lines.pop()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["src.nc"] + [f"{v}.{f}" for f in FORMATS for v in ("export", "convert")])


def test_cli_allow_nonphysical_writes_with_one_warning_line(tmp_path, capsys):
    source = _dataset(tmp_path / "src.nc", 1.5)
    for verb in ("export", "convert"):
        out = tmp_path / f"{verb}.zemax"
        extra = ["--interaction", "elastic"] if verb == "export" else []
        code = main([verb, str(source), "--to", "zemax", "-o", str(out), "--allow-nonphysical", *extra])
        captured = capsys.readouterr()
        assert code == 0, captured.err
        assert out.is_file()
        warning = [line for line in captured.err.splitlines() if "warning" in line]
        assert len(warning) == 1 and "written anyway (--allow-nonphysical)" in warning[0], captured.err


def test_physical_dataset_converts(tmp_path):
    source = _dataset(tmp_path / "src.nc", 0.5)
    result = convert(source, "zemax", tmp_path / "out.zemax")
    assert result.committed


def _klems_file(tmp_path: Path) -> tuple[Path, str]:
    path = tmp_path / "klems.xml"
    export(lambertian(dict.fromkeys(THETA, 0.5)), "bsdfxml", "", "reflection", path,
           settings=ExportSettings(theta_i_deg=THETA, xml_basis="klems"))
    return path, path.read_text()


def test_bsdfxml_reader_refuses_a_klems_value_above_the_bsdf_limit(tmp_path, capsys):
    path, text = _klems_file(tmp_path)
    start = text.index("<ScatteringData>") + len("<ScatteringData>")
    first = re.compile(r"[0-9.eE+-]+").search(text, start)
    bad = text[:first.start()] + "1e300" + text[first.end():]
    path.write_text(bad)
    with pytest.raises(FormatError) as err:
        read_any(path)
    line = bad.count("\n", 0, first.start()) + 1
    assert str(err.value).startswith(f"{path}:{line}: field 'ScatteringData of Reflection Front'")
    assert "value implausibly large for a BSDF" in str(err.value) and "1e300" in str(err.value)
    code = main(["read", str(path)])
    captured = capsys.readouterr()
    assert code == 2 and len(captured.err.strip().splitlines()) == 1 and "1e300" in captured.err


def test_bsdfxml_reader_keeps_reading_values_within_the_limit(tmp_path):
    path, _ = _klems_file(tmp_path)
    assert read_any(path).tis_computed["reflection"][0] == pytest.approx(0.5, rel=0.02)
