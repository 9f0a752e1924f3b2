"""A vendor file whose own stated TIS disagrees with the integral of its data is ingested with a warning naming both
values (bsdfkit.tables.vendor.check_stated_tis; docs/exports.md §2.0).

Files: the FDTD → Speos → Zemax export of ansys/optical-automation (tests/data/ansys-optical-automation-fdtd, stored
gzip-compressed; decompressed into tmp_path), the well-behaved Radiant Zemax file and an edited copy of it whose TIS
lines are doubled (in tmp_path).
"""
from __future__ import annotations

import gzip
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import cli

import bsdfkit
from bsdfkit.core.errors import StatedTisWarning
from bsdfkit.tables.format_spec import FileSummary
from bsdfkit.tables.vendor import STATED_TIS_ATOL, STATED_TIS_RTOL, check_stated_tis, vendor_dataset

DATA = Path(__file__).resolve().parents[1] / "data"
FDTD_GZ = DATA / "ansys-optical-automation-fdtd" / "fdtd_speos_to_zemax_BRDF_550nm.bsdf.gz"
RADIANT = DATA / "ansys-radiant-zemax-bsdf" / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"

#: the FDTD file's TIS lines [-] at 0, 22.5, 45, 67.5 deg, and the engine's integral of its table (bsdfkit read,
#: 2026-12-05: 0.000697, 0.000406, 0.03329, 0.1158), compared within 3 % (the engine's quadrature may be refined)
FDTD_THETA = [0.0, 22.5, 45.0, 67.5]
FDTD_STATED = [0.023, 0.019, 0.137, 0.183]
FDTD_INTEGRATED = [0.000697, 0.000406, 0.03329, 0.1158]
ENGINE_RTOL = 0.03

#: "<key> at theta_i <deg> deg: stated <S>, integrated <I>" in the warning
ENTRY = re.compile(r"(\w+) at theta_i ([0-9.]+) deg: stated ([0-9.eE+-]+), integrated ([0-9.eE+-]+)")


@pytest.fixture(scope="module")
def fdtd_file(tmp_path_factory) -> Path:
    """The upstream file, byte for byte (PROVENANCE.md: sha256 48a6c379…4fcde1), in a tmp folder."""
    path = tmp_path_factory.mktemp("fdtd") / "fdtd_speos_to_zemax_BRDF_550nm.bsdf"
    path.write_bytes(gzip.decompress(FDTD_GZ.read_bytes()))
    return path


def _radiant_tis_scaled(tmp_path: Path, factor: float) -> tuple[Path, list[float]]:
    """A copy of the Radiant file with every ``TIS`` line multiplied by ``factor``; the original TIS values."""
    lines, original = [], []
    for line in RADIANT.read_text().splitlines(keepends=True):
        if line.split() and line.split()[0] == "TIS":
            original.append(float(line.split()[1]))
            line = f"TIS {factor * original[-1]:.7g}\n"
        lines.append(line)
    out = tmp_path / "radiant_tis_edited.bsdf"
    out.write_text("".join(lines))
    return out, original


def _entries(message: str) -> list[tuple[str, float, float, float]]:
    return [(k, float(t), float(s), float(i)) for k, t, s, i in ENTRY.findall(message)]


def test_real_fdtd_file_warns_with_both_values(fdtd_file):
    with pytest.warns(StatedTisWarning) as caught:
        ds = bsdfkit.ingest(fdtd_file)
    ours = [w for w in caught if issubclass(w.category, StatedTisWarning)]
    assert len(ours) == 1  # one warning per file, naming every incidence
    message = str(ours[0].message)
    assert str(fdtd_file) in message and "zemax" in message and "not rescaled" in message
    entries = _entries(message)
    assert [e[0] for e in entries] == ["reflection"] * 4
    assert [e[1] for e in entries] == FDTD_THETA
    assert [e[2] for e in entries] == FDTD_STATED
    np.testing.assert_allclose([e[3] for e in entries], FDTD_INTEGRATED, rtol=ENGINE_RTOL)

    record = json.loads(ds.attrs["tis_stated_json"])
    assert record["disagrees"] is True and record["rtol"] == STATED_TIS_RTOL and record["atol"] == STATED_TIS_ATOL
    row = record["tis"]["reflection"]
    assert row["theta_i_deg"] == FDTD_THETA and row["stated"] == FDTD_STATED and all(row["disagrees"])
    np.testing.assert_allclose(row["integrated"], FDTD_INTEGRATED, rtol=ENGINE_RTOL)
    # the data are used as they are: the records equal those of the plain reader
    plain = vendor_dataset(fdtd_file)
    np.testing.assert_array_equal(ds["bsdf"].values, plain["bsdf"].values)


def test_real_fdtd_file_cli_read_one_warning_line(fdtd_file):
    res = cli("read", str(fdtd_file))
    assert res.returncode == 0
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("bsdfkit read: warning: ")
    entries = _entries(lines[0])
    assert [e[2] for e in entries] == FDTD_STATED
    np.testing.assert_allclose([e[3] for e in entries], FDTD_INTEGRATED, rtol=ENGINE_RTOL)


def test_well_behaved_radiant_file_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", StatedTisWarning)
        ds = bsdfkit.ingest(RADIANT)
    record = json.loads(ds.attrs["tis_stated_json"])
    row = record["tis"]["reflection"]
    assert record["disagrees"] is False and len(row["theta_i_deg"]) == 13 and not any(row["disagrees"])
    # the engine integrates the coarse vendor grid 0.9-7.4 % above the stated TIS: inside the 10 % tolerance
    rel = np.asarray(row["integrated"]) / np.asarray(row["stated"]) - 1.0
    assert np.abs(rel).max() < STATED_TIS_RTOL


def test_doubled_stated_tis_warns(tmp_path):
    edited, original = _radiant_tis_scaled(tmp_path, 2.0)
    with pytest.warns(StatedTisWarning, match="radiant_tis_edited.bsdf") as caught:
        ds = bsdfkit.ingest(edited)
    entries = _entries(str(next(w for w in caught if issubclass(w.category, StatedTisWarning)).message))
    assert len(entries) == 13  # every incidence: the integral is ~0.52 of the doubled TIS
    np.testing.assert_allclose([e[2] for e in entries], 2.0 * np.asarray(original), rtol=1e-5)  # printed to 6 digits
    record = json.loads(ds.attrs["tis_stated_json"])["tis"]["reflection"]
    np.testing.assert_allclose(np.asarray(record["integrated"]) / np.asarray(record["stated"]), 0.5, atol=0.04)


def test_doubled_stated_tis_cli_ingest_one_line_exit_zero(tmp_path):
    edited, _ = _radiant_tis_scaled(tmp_path, 2.0)
    res = cli("ingest", str(edited), "-o", str(tmp_path / "edited.nc"))
    assert res.returncode == 0 and (tmp_path / "edited.nc").is_file()
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("bsdfkit ingest: warning: ") and "stated 0.269012" in lines[0]


def test_rule_needs_both_relative_and_absolute_excess():
    summary = FileSummary(format="zemax", path="x.bsdf", incidences_deg=[0.0, 10.0, 20.0, 30.0],
                          tis_stated={"reflection": [0.2, 0.01, 0.01, float("nan")]},
                          tis_computed={"reflection": [0.21, 0.014, 0.016, 0.3]})
    with pytest.warns(StatedTisWarning) as caught:
        record = check_stated_tis(summary)
    # 5 % off: quiet; 40 % but 0.004 absolute: quiet; 60 % and 0.006: warns; no stated value: not compared
    assert record["tis"]["reflection"]["disagrees"] == [False, False, True]
    assert [e[1] for e in _entries(str(caught[0].message))] == [20.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", StatedTisWarning)
        check_stated_tis(summary, {"reflection": [0.2, 0.01, 0.01, 0.0]})
        # a format that scales its table to the stated TIS (Speos) is never flagged
        check_stated_tis(FileSummary("speos", "x", [0.0], {"reflection": [0.5]}, {"reflection": [0.1]},
                                     details={"normalisation": "scaled"}))
