"""Fault injection (issue #13): a folder that is one command's output (``run``, ``simulate``) is a set.

An existing folder that holds anything is refused without ``--force`` (before any computing) and replaced as a
whole with it, never mixed with other files, and never when it is or holds an input of the command.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import no_staging_in

from bsdfkit.cli.main import main
from bsdfkit.io.atomic import OutputError, OutputExistsError, OutputSet, write_text

NAMES = ["a.txt", "sub/b.txt", "summary.json"]


def _write_set(folder: Path, force: bool, text: str = "new", **kw) -> None:
    with OutputSet(folder, NAMES, force, whole_folder=True, **kw) as out:
        for name in NAMES:
            write_text(out.path(name), text, True)


def _tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_non_empty_folder_is_refused_without_force_and_replaced_whole_with_it(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "notes.txt").write_text("someone else's")
    with pytest.raises(OutputExistsError, match="not empty.*--force.*notes.txt"):
        _write_set(folder, force=False)
    assert _tree(folder) == ["notes.txt"] and _tree(tmp_path) == ["out", "out/notes.txt"]  # nothing staged
    _write_set(folder, force=True)
    assert _tree(folder) == ["a.txt", "sub", "sub/b.txt", "summary.json"]  # a set, not a mix
    assert _tree(tmp_path) == ["out"] + [f"out/{p}" for p in _tree(folder)]  # no .old/.staging left
    # an empty folder (a user's mkdir) is a new output: no --force needed
    empty = tmp_path / "empty"
    empty.mkdir()
    _write_set(empty, force=False)
    assert (empty / "summary.json").read_text() == "new"


def test_folder_holding_an_input_is_refused_even_with_force(tmp_path):
    folder = tmp_path / "out"
    (folder / "data").mkdir(parents=True)
    recipe = folder / "data" / "recipe.toml"
    recipe.write_text("[recipe]\n")
    for inputs in ([recipe], [folder]):
        with pytest.raises(OutputError, match="is or holds an input"):
            _write_set(folder, force=True, inputs=inputs)
    assert recipe.read_text() == "[recipe]\n"


def test_folder_holding_the_current_folder_is_refused_even_with_force(tmp_path, monkeypatch):
    folder = tmp_path / "project"
    (folder / "src").mkdir(parents=True)
    monkeypatch.chdir(folder / "src")
    _write_set(Path("."), force=False)  # the empty current folder: filled in place, not replaced by a rename
    assert Path.cwd().samefile(folder / "src") and (folder / "src" / "summary.json").read_text() == "new"
    for target in (Path(".."), folder):
        with pytest.raises(OutputError, match="holds the current folder"):
            _write_set(target, force=True)
    assert _tree(folder)[:2] == ["src", "src/a.txt"]


def test_whole_folder_staged_inside_a_mount_point_replaces_its_content(tmp_path, monkeypatch):
    # the target's parent cannot take the staging folder (a read-only parent, or the target is a mount point)
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "old.txt").write_text("old")
    (folder / "olddir").mkdir()
    no_staging_in(monkeypatch, tmp_path)
    _write_set(folder, force=True)
    assert _tree(folder) == ["a.txt", "sub", "sub/b.txt", "summary.json"]


def test_simulate_into_a_non_empty_folder_is_one_line_before_simulating(tmp_path, capsys):
    folder = tmp_path / "sim"
    folder.mkdir()
    (folder / "keep.txt").write_text("x")
    code = main(["simulate", "-o", str(folder)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "not empty" in err and "--force" in err and str(folder) in err
    assert _tree(folder) == ["keep.txt"]


def test_netcdf_write_failing_on_a_full_device_is_no_space_not_a_traceback(tmp_path, monkeypatch):
    # netCDF4/HDF5 raise RuntimeError("NetCDF: HDF error") when the device fills up (found by the audit's tmpfs)
    from collections import namedtuple

    from bsdfkit.io import atomic

    def hdf_error(tmp):
        raise RuntimeError("NetCDF: HDF error")

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda folder: usage(1 << 30, (1 << 30) - 4096, 4096))
    with pytest.raises(OutputError, match=r"out\.nc: no space left on device while writing out\.nc \[ENOSPC\]"):
        atomic.write_with(tmp_path / "out.nc", hdf_error)
    assert _tree(tmp_path) == []
    monkeypatch.setattr(atomic.shutil, "disk_usage", lambda folder: usage(1 << 30, 0, 1 << 30))
    # with space left it is not a disk fault: the library is named
    with pytest.raises(OutputError, match=r"out\.nc: cannot write output: the netCDF library failed \(NetCDF: HDF"):
        atomic.write_with(tmp_path / "out.nc", hdf_error)
