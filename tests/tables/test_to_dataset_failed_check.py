"""A table that fails its TIS check never stands at the requested path (``bsdfkit convert``, :func:`convert`).

The table is written, re-read and checked under a hidden staging name in the output's folder
(:class:`bsdfkit.io.atomic.StagedFile`) and moved into place only when it passed: after a failed check nothing
is at the path, an earlier file there (``--force``) is byte-identical, and the table is gone or, with
``--keep-failed``, kept as ``<stem>.failed-check<suffix>``. The Radiant file converted to TracePro misses a
tolerance of 1e-9 (0.28 %) and passes the default 1 % (1-3 s each).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import cli

from bsdfkit.core.errors import OutputError
from bsdfkit.io import atomic
from bsdfkit.tables import to_dataset
from bsdfkit.tables.to_dataset import convert

RADIANT = (Path(__file__).parent.parent / "data" / "ansys-radiant-zemax-bsdf"
           / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf")
FAIL = ("--tis-tolerance", "1e-9")  # no table meets it: the check fails on purpose
ROOT = Path(__file__).resolve().parents[2]


def _convert(out: Path, *extra: str):
    return cli("convert", RADIANT, "--to", "tracepro", "-o", out, *extra)


def _names(folder: Path) -> list[str]:
    """Everything in ``folder``, hidden staging files included."""
    return sorted(p.name for p in folder.iterdir())


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_failed_check_leaves_nothing_at_the_path(tmp_path):
    out = tmp_path / "out.txt"
    done = _convert(out, *FAIL)
    assert done.returncode == 1, done.stderr
    line = _one_line(done.stderr)
    assert line.startswith("bsdfkit convert: TIS check failed") and f"nothing written to {out}" in line
    assert "--keep-failed" in line and "checked (not written)" in done.stdout
    assert _names(tmp_path) == []  # neither the table nor its staging file


def test_failed_check_with_force_leaves_the_earlier_file_byte_identical(tmp_path):
    out = tmp_path / "out.txt"
    earlier = b"an earlier, good table\r\n\x00\xff"
    out.write_bytes(earlier)
    os.utime(out, (1_000_000, 1_000_000))
    done = _convert(out, "--force", *FAIL)
    assert done.returncode == 1, done.stderr
    assert f"{out} left as it was" in _one_line(done.stderr)
    assert out.read_bytes() == earlier and out.stat().st_mtime == 1_000_000
    assert _names(tmp_path) == ["out.txt"]


def test_keep_failed_keeps_the_table_under_the_failing_name_only(tmp_path):
    out = tmp_path / "out.txt"
    out.write_bytes(b"earlier")
    done = _convert(out, "--force", "--keep-failed", *FAIL)
    assert done.returncode == 1, done.stderr
    failed = tmp_path / "out.failed-check.txt"
    assert f"kept as {failed}" in _one_line(done.stderr)
    assert _names(tmp_path) == ["out.failed-check.txt", "out.txt"]
    assert out.read_bytes() == b"earlier"
    assert failed.read_text().startswith("TracePro")  # the whole table, as it was checked


def test_keep_failed_refuses_an_existing_failed_table_before_computing(tmp_path, monkeypatch):
    out, failed = tmp_path / "out.txt", tmp_path / "out.failed-check.txt"
    failed.write_bytes(b"from an earlier run")
    monkeypatch.setattr(to_dataset, "export", lambda *a, **k: pytest.fail("computed before refusing"))
    done = _convert(out, "--keep-failed", *FAIL)
    assert done.returncode == 2 and "output exists" in _one_line(done.stderr) and str(failed) in done.stderr
    assert _names(tmp_path) == ["out.failed-check.txt"] and failed.read_bytes() == b"from an earlier run"


def test_keep_failed_refuses_a_name_too_long_for_the_failed_table(tmp_path, monkeypatch):
    out = tmp_path / ("n" * 246 + ".txt")  # valid (250 bytes); the failed table's name would not be
    monkeypatch.setattr(to_dataset, "export", lambda *a, **k: pytest.fail("computed before refusing"))
    done = _convert(out, "--keep-failed", *FAIL)
    assert done.returncode == 2 and "too long" in _one_line(done.stderr)
    assert _names(tmp_path) == []


def test_passing_conversion_lands_at_the_path(tmp_path):
    out = tmp_path / "good.txt"
    out.write_bytes(b"earlier")
    done = _convert(out, "--force", "--keep-failed")
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and f"wrote tracepro table {out}" in done.stdout
    assert out.read_text().startswith("TracePro")
    assert _names(tmp_path) == ["good.txt"]


def test_a_refused_command_makes_no_output_folder_and_a_passing_one_does(tmp_path):
    out = tmp_path / "new" / "deeper" / "out.txt"
    done = cli("convert", tmp_path / "absent.bsdf", "--to", "tracepro", "-o", out)
    assert done.returncode == 2 and "absent.bsdf" in _one_line(done.stderr)
    assert _names(tmp_path) == []  # the output's folder is made by the writer, not by the checks before it
    done = _convert(out)
    assert done.returncode == 0, done.stderr
    assert _names(out.parent) == ["out.txt"]


def test_library_convert_reports_the_table_not_committed(tmp_path):
    out = tmp_path / "lib.txt"
    result = convert(RADIANT, "tracepro", out, tolerance=1e-9)
    assert not result.ok and not result.committed and result.failed_path is None
    assert result.export.path == str(out)  # the output it was meant for, not the staging file
    assert result.to_dict()["committed"] is False and result.to_dict()["failed_path"] is None
    assert _names(tmp_path) == []
    kept = convert(RADIANT, "tracepro", out, tolerance=1e-9, keep_failed=True)
    assert kept.failed_path == str(tmp_path / "lib.failed-check.txt") and not kept.committed
    assert _names(tmp_path) == ["lib.failed-check.txt"]


def test_exit_status_of_the_process_is_1(tmp_path):
    out = tmp_path / "p.txt"
    done = subprocess.run([sys.executable, "-m", "bsdfkit", "convert", str(RADIANT), "--to", "tracepro", "-o",
                           str(out), *FAIL], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr
    assert _one_line(done.stderr).startswith("bsdfkit convert: TIS check failed")
    assert _names(tmp_path) == []


def test_an_exception_while_writing_removes_the_staging_file_and_names_the_output(tmp_path, monkeypatch):
    out = tmp_path / "out.txt"
    out.write_bytes(b"earlier")
    seen = []

    def broken(source, to, interaction, side, path, force, **kw):
        Path(path).write_text("half a table")  # the staging file, hidden in the output's folder
        seen.append(Path(path))
        raise OutputError("cannot write output: disk on fire", file=path)

    monkeypatch.setattr(to_dataset, "export", broken)
    done = _convert(out, "--force")
    assert done.returncode == 2
    line = _one_line(done.stderr)
    assert str(out) in line and str(seen[0]) not in line  # named by the output, not the hidden file
    assert seen[0].parent == tmp_path and seen[0].name.startswith(".") and seen[0].suffix == ".txt"
    assert _names(tmp_path) == ["out.txt"] and out.read_bytes() == b"earlier"
    assert seen[0] not in atomic._PARTIAL


SIGNALLED = """import sys
from bsdfkit.cli.main import main
import bsdfkit.tables.to_dataset
print('ready', flush=True)
sys.exit(main(sys.argv[1:]))
"""


def test_a_signal_while_converting_leaves_no_staging_file(tmp_path):
    """SIGTERM while the table is computed or checked: exit 143, nothing in the folder (the staging file is an
    unfinished output). Should the conversion finish first, the failed check still leaves nothing."""
    out = tmp_path / "out.txt"
    proc = subprocess.Popen([sys.executable, "-c", SIGNALLED, "convert", str(RADIANT), "--to", "tracepro", "-o",
                             str(out), *FAIL], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any(p.name.startswith(atomic.STAGED_PREFIX)
                                                      for p in tmp_path.iterdir()):
            time.sleep(0.01)  # until the staging file exists: the signal meets the table being checked
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert "Traceback" not in err
    assert proc.returncode in (128 + signal.SIGTERM, 1), err
    assert _names(tmp_path) == []


# ------------------------------------------------------------------------------------------ StagedFile
def test_a_signal_during_the_commit_waits_until_the_file_is_in_place(tmp_path, monkeypatch):
    out = tmp_path / "t.txt"
    out.write_text("earlier")
    ran, real_place = [], atomic._place

    def place(src, dst, force):
        assert atomic.defer_until_committed(lambda: ran.append(_names(tmp_path)))  # a signal arrives here
        real_place(src, dst, force)

    monkeypatch.setattr(atomic, "_place", place)
    with atomic.StagedFile(out, force=True) as staged:
        staged.path.write_text("checked")
        assert staged.path in atomic._PARTIAL  # removed by a signal handler until it is committed
        staged.commit()
    assert ran == [["t.txt"]]  # run once, after the move, with nothing beside the output
    assert out.read_text() == "checked" and staged.placed == out
    assert not any(p in atomic._PARTIAL for p in (out, staged.target))  # a later signal removes nothing of it


def test_without_force_the_commit_never_clobbers(tmp_path):
    out = tmp_path / "t.txt"
    with atomic.StagedFile(out) as staged:
        staged.path.write_text("mine")
        out.write_text("someone else's")  # appeared while computing
        with pytest.raises(atomic.OutputExistsError):
            staged.commit()
    assert out.read_text() == "someone else's" and _names(tmp_path) == ["t.txt"]


def test_failed_check_path_keeps_the_suffix():
    assert atomic.failed_check_path("/x/lobe.asap.txt") == Path("/x/lobe.asap.failed-check.txt")
    assert atomic.failed_check_path("plain") == Path("plain.failed-check")


def test_a_staging_file_of_a_killed_process_is_removed_by_the_next_write(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"{atomic.STAGED_PREFIX}{dead.pid}.0123abcd.txt"
    stale.write_text("left by kill -9")
    alive = tmp_path / f"{atomic.STAGED_PREFIX}{os.getpid()}.0123abcd.txt"
    alive.write_text("being checked by this process")
    atomic.write_text(tmp_path / "other.txt", "x")
    assert _names(tmp_path) == sorted([alive.name, "other.txt"])


@pytest.mark.parametrize("kind", ["fifo", "symlink", "folder"])
def test_force_refuses_outputs_that_are_not_regular_files(tmp_path, kind, monkeypatch):
    target = tmp_path / "real.txt"
    target.write_text("pointed to")
    out = tmp_path / "out.txt"
    if kind == "fifo":
        os.mkfifo(out)
    elif kind == "symlink":
        out.symlink_to(target)
    else:
        out.mkdir()
    monkeypatch.setattr(to_dataset, "export", lambda *a, **k: pytest.fail("computed before refusing"))
    done = _convert(out, "--force")
    assert done.returncode == 2, done.stderr
    assert str(out) in _one_line(done.stderr)
    assert out.is_fifo() if kind == "fifo" else out.is_symlink() if kind == "symlink" else out.is_dir()
    assert target.read_text() == "pointed to" and _names(tmp_path) == ["out.txt", "real.txt"]


def test_force_never_replaces_the_input(tmp_path):
    src = tmp_path / "src.bsdf"
    src.write_bytes(RADIANT.read_bytes())
    done = cli("convert", src, "--to", "zemax", "-o", src, "--force", "--keep-failed")
    assert done.returncode == 2 and "input" in _one_line(done.stderr)
    assert src.read_bytes() == RADIANT.read_bytes() and _names(tmp_path) == ["src.bsdf"]


# ------------------------------------------------------------------------------------------ bsdfkit export
def _fit(path: Path) -> Path:
    """A lambert+gaussian fit result (two incidences, reflection) as netCDF."""
    shape = (1, 1, 2)
    ds = xr.Dataset({"rho": (("interaction", "side", "theta_i"), np.full(shape, 0.2)),
                     "A": (("interaction", "side", "theta_i"), np.full(shape, 3.0)),
                     "sigma": (("interaction", "side", "theta_i"), np.full(shape, 0.04))},
                    coords={"interaction": ["bibs"], "side": ["reflection"], "theta_i": [0.0, 30.0]},
                    attrs={"model": "lambert+gaussian"})
    ds.to_netcdf(path)
    return path


def test_export_verb_stages_the_table_and_commits_it_whole(tmp_path, monkeypatch):
    from bsdfkit.tables import export as export_module

    src = _fit(tmp_path / "fit.nc")
    out = tmp_path / "t.bsdf"
    out.write_bytes(b"earlier")
    argv = ["export", src, "--to", "zemax", "--interaction", "bibs", "-o", out, "--force"]
    real, written = export_module._read_any, []

    def interrupted(path):  # the re-read of the written table fails: the export never finishes
        written.append(Path(path))
        raise OutputError("cannot read back", file=path)

    monkeypatch.setattr(export_module, "_read_any", interrupted)
    done = cli(*argv)
    assert done.returncode == 2 and str(out) in _one_line(done.stderr)
    assert written and written[0].parent == tmp_path and written[0] != out  # re-read at the staging file
    assert out.read_bytes() == b"earlier" and _names(tmp_path) == ["fit.nc", "t.bsdf"]
    monkeypatch.setattr(export_module, "_read_any", real)
    done = cli(*argv)
    assert done.returncode == 0, done.stderr
    assert f"wrote zemax table {out}" in done.stdout and "DataBegin" in out.read_text()
    assert _names(tmp_path) == ["fit.nc", "t.bsdf"]
