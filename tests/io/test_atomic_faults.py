"""Fault injection (issue #13): output faults, undecodable inputs, atomic output sets, no-clobber, plausibility.

Every failure a user can cause is one line on stderr naming the file (line, key or option), what was expected
and what was found, with exit status 2 and no traceback. Tests run as root, where chmod does not stop writes,
so read-only targets and full disks are simulated by patching the operating-system calls.
"""
from __future__ import annotations

import errno
import gzip
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import colour
import numpy as np
import pytest
from conftest import BUNDLED, ROOT, no_staging_in

from bsdfkit.cli.main import main
from bsdfkit.core.errors import BsdfkitError, InputError, OutputExistsError, ValidationError
from bsdfkit.io import atomic
from bsdfkit.io.atomic import OutputError, OutputSet, check_writable, write_text, write_with
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.manifest import read_manifest
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.pipeline.recipe import load_recipe, run
from bsdfkit.reduction.budget import module_budget, table_from_json
from bsdfkit.reduction.colorimetry import colorimetric_summary
from bsdfkit.simulation import virtual_goniometer as virtual


def _cli(capsys, *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    err = capsys.readouterr().err
    return code, err


def _one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], lines[0]


def _leftovers(folder: Path) -> list[str]:
    return [p.name for p in folder.rglob("*") if p.name.endswith((".part", ".staging", ".old"))]


# ---------------------------------------------------------------------------------------------- output faults
def test_full_disk_mid_write_leaves_old_file_and_no_temp(tmp_path):
    target = tmp_path / "table.txt"
    target.write_text("OLD")

    def writer(tmp):
        with open(tmp, "wb") as fh:
            fh.write(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OutputError, match=r"no space left on device while writing table\.txt \[ENOSPC\]") as info:
        write_with(target, writer, force=True)
    assert str(target) in str(info.value)
    assert target.read_text() == "OLD"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("full,expected", [(True, "no space left on device while writing map.nc [ENOSPC]"),
                                           (False, "cannot write output: permission denied [EACCES]")])
def test_a_library_saying_eacces_on_a_full_device_is_told_no_space(tmp_path, monkeypatch, full, expected):
    """HDF5 reports a full device as EACCES when writing into the temporary file this process has just created
    (a 256 KiB tmpfs with 8 KiB free): the folder took that file, so a full device is the cause; on a device with
    room, EACCES stays "permission denied"."""
    from bsdfkit.io import atomic

    monkeypatch.setattr(atomic, "_device_full", lambda folder: full)

    def writer(tmp):
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp))

    with pytest.raises(OutputError) as info:
        write_with(tmp_path / "map.nc", writer, force=False)
    assert expected in str(info.value)
    assert _leftovers(tmp_path) == [] and not (tmp_path / "map.nc").exists()


@pytest.mark.parametrize("code,text", [(errno.EROFS, "read-only file system"), (errno.EACCES, "permission denied")])
def test_unwritable_folder_is_found_before_computing(tmp_path, monkeypatch, code, text):
    real_open = os.open

    def guarded(path, flags, *args, **kw):
        if str(path).startswith(str(tmp_path)) and flags & os.O_CREAT:
            raise OSError(code, os.strerror(code), str(path))
        return real_open(path, flags, *args, **kw)

    monkeypatch.setattr(os, "open", guarded)
    with pytest.raises(OutputError, match=text):
        check_writable(tmp_path / "out.nc", force=False)
    # a verb refuses before any work: simulate would otherwise spend its time simulating first
    started = time.perf_counter()
    assert main(["simulate", "-o", str(tmp_path / "sim")]) == 2
    assert time.perf_counter() - started < 5.0


def test_cli_output_faults_are_one_line(tmp_path, capsys):
    a_file = tmp_path / "plain.txt"
    a_file.write_text("x")
    a_dir = tmp_path / "folder"
    a_dir.mkdir()
    # output folder is a file
    _one_line_error(*_cli(capsys, "simulate", "-o", str(a_file)), str(a_file), "is a file")
    # output path is a folder
    with pytest.raises(OutputError, match="is a folder"):
        check_writable(a_dir, force=True)
    # an output set whose folder is a file
    with pytest.raises(OutputError, match="output folder is a file"):
        OutputSet(a_file, ["a.txt"], force=True)
    assert _leftovers(tmp_path) == []


def test_safety_net_turns_escaped_faults_into_one_line(monkeypatch, capsys, tmp_path):
    from bsdfkit import api

    def boom(path):
        raise OSError(errno.EIO, "Input/output error", str(path))

    monkeypatch.setattr(api, "read", boom)
    _one_line_error(*_cli(capsys, "read", str(tmp_path / "x.bsdf")), "x.bsdf", "EIO")

    def undecodable(path):
        b"\xff\xfe".decode("utf-8")

    monkeypatch.setattr(api, "read", undecodable)
    _one_line_error(*_cli(capsys, "read", "x"), "not UTF-8", "0xff")


# ------------------------------------------------------------------------------ undecodable or binary inputs
@pytest.fixture
def tiny_copy(tiny_export):
    return tiny_export


def test_binary_manifest(tiny_copy, capsys):
    (tiny_copy / "manifest.toml").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00binary")
    _one_line_error(*_cli(capsys, "info", str(tiny_copy)), "manifest.toml", "not UTF-8")


def test_corrupt_gzip_scan(tiny_copy, capsys):
    scan = next((tiny_copy / "scans").glob("*.csv.gz"))
    data = bytearray(scan.read_bytes())
    data[20:60] = b"\x00" * 40  # keeps the gzip magic, breaks the deflate stream (zlib.error)
    scan.write_bytes(bytes(data))
    _one_line_error(*_cli(capsys, "info", str(tiny_copy)), scan.name, "gzip")


def test_truncated_gzip_and_binary_csv(tiny_copy, capsys):
    dark = tiny_copy / "dark.csv.gz"
    dark.write_bytes(dark.read_bytes()[:40])
    _one_line_error(*_cli(capsys, "info", str(tiny_copy)), "dark.csv.gz", "gzip")
    dark.write_bytes(gzip.compress(b"frame,exposure_s\x00\x00\n"))
    _one_line_error(*_cli(capsys, "info", str(tiny_copy)), "dark.csv.gz")


def test_undecodable_recipe_budget_table_and_spectrum(tmp_path, capsys):
    recipe = tmp_path / "r.toml"
    recipe.write_bytes(b"[recipe]\nname = '\xff\xfe'\n")
    _one_line_error(*_cli(capsys, "run", str(recipe), "-o", str(tmp_path / "out")), "r.toml", "UTF-8")
    table = tmp_path / "t.json"
    table.write_bytes(b'{"power": \xff}')
    _one_line_error(*_cli(capsys, "budget", "--table", str(table), "--eta-mc", "0.9"), "t.json", "UTF-8")
    spectrum = tmp_path / "s.txt"
    spectrum.write_bytes(bytes(range(256)) * 4)
    code, err = _cli(capsys, "color", str(spectrum))
    _one_line_error(code, err, "s.txt")


# --------------------------------------------------------------------------------- no-clobber, inputs
def test_concurrent_writers_exactly_one_wins(tmp_path):
    target = tmp_path / "scan.nc"
    results: list[str] = []
    barrier = threading.Barrier(2)

    def writer(tag: str) -> None:
        def slow(tmp):
            barrier.wait(timeout=10)  # both have passed the existence check and are writing
            Path(tmp).write_text(tag)

        try:
            write_with(target, slow, force=False)
            results.append("ok")
        except OutputExistsError:
            results.append("exists")

    threads = [threading.Thread(target=writer, args=(t,)) for t in "AB"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=20)
    assert sorted(results) == ["exists", "ok"]
    assert target.read_text() in ("A", "B")
    assert _leftovers(tmp_path) == []


def test_output_that_is_an_input_is_refused_even_with_force(tmp_path, capsys):
    source = tmp_path / "in.nc"
    source.write_bytes(b"not really netcdf")
    _one_line_error(*_cli(capsys, "export", str(source), "--to", "zemax", "--interaction", "bibs", "-o",
                          str(source), "--force"), "in.nc", "input")
    link = tmp_path / "alias.nc"
    os.link(source, link)
    with pytest.raises(OutputError, match="input"):
        check_writable(link, force=True, inputs=[source])
    assert source.read_bytes() == b"not really netcdf"


def test_stale_temporary_files_of_dead_processes_are_removed(tmp_path):
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(proc.stdout)
    stale = tmp_path / f".out.txt.{dead}.deadbeef.part"
    stale.write_bytes(b"x" * 1000)
    alive = tmp_path / f".out.txt.{os.getpid()}.cafecafe.part"
    alive.write_bytes(b"mine")
    short_stale = tmp_path / f".bsdfkit-{dead}.deadbeef.part"  # today's short temporary names
    short_stale.write_bytes(b"x")
    write_text(tmp_path / "out.txt", "done")
    assert not stale.exists() and not short_stale.exists()
    assert alive.exists()  # a live process's temporary file is left alone
    alive.unlink()


# ------------------------------------------------------------------------------------------ output sets
def test_output_set_fault_leaves_previous_set(tmp_path):
    folder = tmp_path / "out"
    with OutputSet(folder, ["a.txt", "sub/b.txt", "summary.json"]) as out:
        for name in ("a.txt", "sub/b.txt", "summary.json"):
            write_text(out.path(name), "v1 " + name, True)
    before = {p.relative_to(folder): p.read_text() for p in folder.rglob("*") if p.is_file()}
    with pytest.raises(OutputError, match="ENOSPC"):
        with OutputSet(folder, ["a.txt", "sub/b.txt", "summary.json"], force=True) as out:
            write_text(out.path("a.txt"), "v2", True)
            raise OutputError(f"cannot write output: {atomic.describe_os_error(OSError(errno.ENOSPC, 'x'))}")
    after = {p.relative_to(folder): p.read_text() for p in folder.rglob("*") if p.is_file()}
    assert after == before
    assert _leftovers(tmp_path) == []
    # without force the complete set is refused before computing
    with pytest.raises(OutputExistsError):
        OutputSet(folder, ["a.txt"], force=False)
    # with force a set made only of the previous outputs is swapped as a whole
    with OutputSet(folder, ["a.txt", "sub/b.txt", "summary.json"], force=True) as out:
        for name in ("a.txt", "sub/b.txt", "summary.json"):
            write_text(out.path(name), "v3", True)
    assert {p.read_text() for p in folder.rglob("*") if p.is_file()} == {"v3"}


def test_output_set_keeps_other_files_and_no_clobber(tmp_path):
    folder = tmp_path / "docs"
    folder.mkdir()
    (folder / "README.md").write_text("mine")
    with OutputSet(folder, ["accuracy.md"]) as out:
        write_text(out.path("accuracy.md"), "report", True)
    assert (folder / "README.md").read_text() == "mine"
    assert (folder / "accuracy.md").read_text() == "report"
    # an output that appears while computing is not overwritten without force
    with pytest.raises(OutputExistsError):
        with OutputSet(folder, ["fig.png"]) as out:
            write_text(out.path("fig.png"), "new", True)
            (folder / "fig.png").write_text("someone else's")
    assert (folder / "fig.png").read_text() == "someone else's"


KILLED_SET = r"""
import sys, time
from bsdfkit.io.atomic import OutputSet, write_text
with OutputSet(sys.argv[1], [f"f{k}.txt" for k in range(26)]) as out:
    for k in range(26):
        write_text(out.path(f"f{k}.txt"), "x" * 1000, True)
        if k == 10:
            print("half", flush=True)
            time.sleep(60)
"""


def test_killed_output_set_leaves_nothing_and_rerun_needs_no_force(tmp_path):
    folder = tmp_path / "run_out"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_SET, str(folder)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "half"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert not folder.exists()
    # the rerun works without --force and removes the dead process's staging folder
    with OutputSet(folder, ["f0.txt"]) as out:
        write_text(out.path("f0.txt"), "ok", True)
    assert (folder / "f0.txt").read_text() == "ok"
    assert _leftovers(tmp_path) == []


@pytest.mark.slow
def test_sigterm_runs_cleanup(tmp_path):
    """`bsdfkit simulate` terminated while simulating: exit 143, no output folder, no staging folder. The signal
    can meet the end of the run (the command takes about 1.5 s): a set being moved into place is finished first
    (atomic.defer_until_committed), so the folder then exists whole (exit 143, or the signal's own status once
    bsdfkit's handler is gone, or 0), never part of it, and no staging folder is left."""
    out = tmp_path / "sim"
    script = ("import sys\nfrom bsdfkit.cli.main import main\nimport bsdfkit.cli.simulate\n"
              "print('ready', flush=True)\nsys.exit(main(['simulate', '-o', sys.argv[1]]))\n")
    proc = subprocess.Popen([sys.executable, "-c", script, str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"  # imports done: main() installs its handler at once
    time.sleep(1.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err
    assert proc.returncode in (0, 128 + signal.SIGTERM, -signal.SIGTERM), err
    if proc.returncode == 128 + signal.SIGTERM:
        assert "terminated" in err
    if out.exists():  # finished: every file of the simulated export is there
        assert {"manifest.toml", "dark.csv.gz", "responsivity.csv", "scans", "reference"} <= {
            p.name for p in out.iterdir()}
    else:
        assert proc.returncode == 128 + signal.SIGTERM
    assert _leftovers(tmp_path) == []


def test_a_signal_handler_inside_a_forced_swap_waits_until_the_set_is_in_place(tmp_path, monkeypatch):
    """The handler's exit is deferred while the main thread moves a set into place: interrupted between the two
    renames of a --force swap, it used to leave the previous outputs under a hidden ``.old`` name and nothing in
    their place."""
    folder = tmp_path / "out"
    with OutputSet(folder, ["a.txt"]) as out:
        write_text(out.path("a.txt"), "old", True)
    ran, real_rename = [], os.rename

    def rename(src, dst):
        if str(dst).endswith(".old"):  # the first rename of the swap: a signal arrives here
            assert atomic.defer_until_committed(lambda: ran.append(sorted(p.name for p in tmp_path.iterdir())))
        real_rename(src, dst)

    monkeypatch.setattr(atomic.os, "rename", rename)
    with OutputSet(folder, ["a.txt"], force=True) as out:
        write_text(out.path("a.txt"), "new", True)
    assert ran == [["out"]]  # run once, after the swap, with nothing beside the output
    assert (folder / "a.txt").read_text() == "new" and _leftovers(tmp_path) == []
    assert not atomic.defer_until_committed(lambda: None)  # no commit in progress: the caller acts at once


# ------------------------------------------------------------------------------------ recipe checks first
def _recipe(tmp_path: Path, **sections) -> Path:
    text = ROOT.joinpath("fitting", "cl830.toml").read_text()
    text = text.replace('measurement = "../measurements/cl830-synthetic"', f'measurement = "{BUNDLED}"')
    text = text.replace('measurement = "../measurements/eem-synthetic"',
                        f'measurement = "{ROOT / "measurements" / "eem-synthetic"}"')
    text = text.replace('scene = "scenes/cl830_device.toml"', f'scene = "{ROOT / "fitting/scenes/cl830_device.toml"}"')
    for old, new in sections.items():
        text = text.replace(old, new)
    path = tmp_path / "recipe.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("old,new,field", [
    ("eta_mc = 0.94", "eta_mc = 2.0", "reductions.eta_mc"),
    ("iterations = 7", "iterations = 0", "reductions.iterations"),
    ("rays = 400000", "rays = 0", "trace.rays"),
    ("rays = 400000", "rays = 1000000000000", "trace.rays"),
    ("tolerance = 0.005", "tolerance = nan", "exports.tolerance"),
    ('bsdf_model = "lambert+gaussian"', 'bsdf_model = "phong"', "fits.bsdf_model"),
    ("led_fwhm_nm = 22.9", "led_fwhm_nm = -1.0", "fits.led_fwhm_nm"),
    ("reflectance = [0.80,", "reflectance = [1.5,", "trace.reflectance[0]"),
])
def test_recipe_options_are_range_checked(tmp_path, old, new, field):
    with pytest.raises(ValidationError, match=field.replace("[", r"\[").replace("]", r"\]")):
        load_recipe(_recipe(tmp_path, **{old: new}))


def test_run_refuses_existing_outputs_and_inputs_before_computing(tmp_path):
    recipe = _recipe(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "tis.nc").write_text("previous")
    started = time.perf_counter()
    with pytest.raises(OutputExistsError, match="tis.nc"):
        run(recipe, out)
    # an output that is the recipe itself is refused even with force
    clash = tmp_path / "summary.json"
    clash.write_text(recipe.read_text())
    with pytest.raises(OutputError, match="input"):
        run(clash, tmp_path, force=True)
    assert time.perf_counter() - started < 10.0
    assert _leftovers(tmp_path) == []


# ----------------------------------------------------------------------------------------------- plausibility
def _edit_manifest(folder: Path, old: str, new: str) -> None:
    m = folder / "manifest.toml"
    text = m.read_text()
    assert old in text, old
    m.write_text(text.replace(old, new))


@pytest.mark.parametrize("old,new,field", [
    ("reference_attenuation = 0.001", "reference_attenuation = 1000.0", "reference_attenuation"),
    ("full_scale_counts = 65535", "full_scale_counts = -1", "full_scale_counts"),
    ("wavelength_step_nm = 5.0", "wavelength_step_nm = 1e-9", "MAX_WAVELENGTHS"),
    ("wavelength_min_nm = 380.0", "wavelength_min_nm = 0.38", "wavelength_min_nm"),
])
def test_implausible_manifest_values(tiny_copy, old, new, field):
    _edit_manifest(tiny_copy, old, new)
    with pytest.raises(ValidationError, match=field):
        read_manifest(tiny_copy)


def test_dark_above_signal_is_flagged_and_counted(tiny_copy, capsys):
    raw = read_scan(tiny_copy)
    clean = calibrate(raw)
    assert clean.attrs["below_dark_pixels"] == 0
    hot = raw.copy()
    hot["dark_counts"] = raw["dark_counts"] * 3.0
    ds = calibrate(hot)
    assert ds.attrs["below_dark_pixels"] == int(ds["below_dark"].sum()) > 0
    from bsdfkit.measurement.describe import describe
    assert describe(ds)["calibration"]["below_dark_pixels"] > 0


def _sd(values, wl, name="s"):
    return colour.SpectralDistribution(np.asarray(values, dtype=float), np.asarray(wl, dtype=float), name=name)


def test_implausible_spectra():
    wl = np.arange(380.0, 781.0, 5.0)
    peak = np.exp(-0.5 * ((wl - 550) / 20) ** 2)
    with pytest.raises(ValidationError, match="negative spectral power"):
        colorimetric_summary(_sd(peak - 0.5 * np.exp(-0.5 * ((wl - 450) / 20) ** 2), wl))
    noise = np.random.default_rng(1).normal(0, 1, wl.size)
    with pytest.raises(ValidationError, match="negative spectral power"):
        colorimetric_summary(_sd(noise, wl))
    with pytest.raises(ValidationError, match="not in nm"):
        colorimetric_summary(_sd(peak, wl / 1000.0))
    with pytest.raises(ValidationError, match="too few samples"):
        colorimetric_summary(_sd([1.0, 2.0, 1.0], [450.0, 550.0, 650.0]))
    # a little dark noise below zero is fine
    c = colorimetric_summary(_sd(peak + 0.001 * noise, wl))
    assert math.isfinite(c.x)


@pytest.mark.parametrize("argv,needle", [
    (["budget", "--table", "T", "--eta-mc", "nan"], "--eta-mc"),
    (["budget", "--table", "T", "--eta-mc", "0.9", "--iterations", "0"], "--iterations"),
    (["budget", "--table", "T", "--eta-mc", "0.9", "--iterations", "1000000000"], "--iterations"),
    (["simulate", "--seed", "-1", "-o", "X"], "--seed"),
    (["export", "S", "--to", "tracepro", "--interaction", "bibs", "-o", "O", "--zero-azimuth", "nan"],
     "zero_azimuth_deg"),
    (["export", "S", "--to", "zemax", "--interaction", "bibs", "-o", "O", "--symmetry-tolerance", "-1"],
     "symmetry_tolerance"),
    (["bench", "--only", "nonsense", "-o", "X"], "--only"),
    (["ingest", "S", "--incidence", "nan", "-o", "O"], "--incidence"),
    (["ingest", "S", "--phi-i", "inf", "-o", "O"], "--phi-i"),
    (["ingest", "S", "--wavelength", "-1", "-o", "O"], "--wavelength"),
    (["convert", "S", "--to", "zemax", "--relative-std", "1e308", "-o", "O"], "--relative-std"),
    (["convert", "S", "--to", "zemax", "--tis-tolerance", "nan", "-o", "O"], "--tis-tolerance"),
    (["tis", str(BUNDLED), "--incidence", "45", "--band", "nan", "500"], "--band"),
])
def test_options_out_of_range_are_errors_not_defaults(tmp_path, capsys, argv, needle):
    argv = [str(tmp_path / a) if a in ("T", "X", "S", "O") else a for a in argv]
    _one_line_error(*_cli(capsys, *argv), needle)


def test_usage_errors_are_one_line(capsys):
    with pytest.raises(SystemExit) as info:
        main(["fit", "bsdf", "x", "--interaction", "bibs", "--side", "reflection", "--incidence", "abc"])
    assert info.value.code == 2
    _one_line_error(2, capsys.readouterr().err, "--incidence", "invalid float")
    for argv in ([], ["--no-compile-cache"]):  # no verb at all: one line too, not the help on stdout
        with pytest.raises(SystemExit) as info:
            main(argv)
        captured = capsys.readouterr()
        assert captured.out == ""
        _one_line_error(info.value.code, captured.err, "no verb given", "trace")


def test_budget_table_out_of_range_and_iteration_bound(tmp_path):
    good = {"B_bibs": 10.9, "F_bibs": 6.5, "B_biys": 26.3, "F_biys": 26.9, "B_yiys": 45.0, "F_yiys": 48.0}
    with pytest.raises(InputError, match="percentage"):
        table_from_json({"power": {**good, "B_bibs": 1000.0}}, "t.json")
    with pytest.raises(InputError, match="MAX_ITERATIONS"):
        module_budget(good, 0.9, 10**12)
    assert json.loads(json.dumps(table_from_json({"power": good})))


def test_bounds_before_allocation():
    with pytest.raises(ValidationError, match="MAX_WAVELENGTHS"):
        virtual.Spectrometer(wavelength_step_nm=1e-9)
    with pytest.raises(ValidationError, match="MAX_POSITIONS_PER_ARC"):
        virtual.ScanPlan(fine_step_deg=1e-9)
    with pytest.raises(BsdfkitError):
        virtual.ScanPlan(fine_step_deg=0.0)


def test_output_set_stages_inside_an_existing_folder_whose_parent_is_read_only(tmp_path, monkeypatch):
    folder = tmp_path / "out"
    folder.mkdir()
    no_staging_in(monkeypatch, tmp_path)
    with OutputSet(folder, ["a.txt", "sub/b.txt"]) as out:
        assert out.staging.parent == folder
        write_text(out.path("a.txt"), "A", True)
        write_text(out.path("sub/b.txt"), "B", True)
    assert sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) == ["a.txt", "sub", "sub/b.txt"]
    # a new folder under a read-only parent is refused before computing
    with pytest.raises(OutputError, match="read-only"):
        OutputSet(tmp_path / "new", ["a.txt"])


def test_output_set_errors_name_the_final_path_and_space_is_checked_first(tmp_path):
    folder = tmp_path / "out"

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OutputError) as info:
        with OutputSet(folder, ["scan.nc"]) as out:
            write_with(out.path("scan.nc"), full, True)
    assert str(folder / "scan.nc") in str(info.value) and ".staging" not in str(info.value)
    with pytest.raises(OutputError, match="not enough free space"):
        OutputSet(folder, ["scan.nc"], min_free_bytes=10**18)
    assert not folder.exists() and _leftovers(tmp_path) == []
