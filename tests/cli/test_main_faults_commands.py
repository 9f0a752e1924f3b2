"""Issue #26, command/tracer/output part: nothing silent, nothing cryptic.

Each fault is one line on stderr naming its cause (the wording is checked, not only the exit status 2), and
never a traceback: degenerate LED beam widths, closed lossless cavities under a plate, worker failures of a
sweep, output folders (mode, mount points, full disks, long names), ``--force`` on an input, usage errors.
"""
from __future__ import annotations

import math
import time

import pytest

from bsdfkit.cli.main import main
from bsdfkit.core.errors import ValidationError
from bsdfkit.raytrace import loads_scene, trace
from bsdfkit.raytrace.scene import COLLIMATED_EXPONENT, LOSSLESS_MAX_EVENTS, events_per_ray

SCENE = """
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = {rho}
[base]
reflectance = {rho}
[leds]
count = 4
pitch_mm = 20.0
emitter_radius_mm = 1.0
{beam}
power_W = 1.0
[top]
{top}
[trace]
lanes = 512
{trace}
"""

LAMBERTIAN = 'distribution = "lambertian"'


def scene_text(rho: float = 0.9, beam: str = LAMBERTIAN, top: str = 'kind = "exit"', trace_opts: str = "") -> str:
    return SCENE.format(rho=rho, beam=beam, top=top, trace=trace_opts)


def plate_top(reflection: float, transmission: float = 0.0) -> str:
    """A Lambertian plate that reflects ``reflection`` and transmits ``transmission`` of blue and yellow."""
    lines = ['kind = "phosphor"', "[top.plate]", "theta_i_deg = [0.0, 90.0]"]
    for inter, (r, t) in (("bibs", (reflection, transmission)), ("biys", (0.0, 0.0)),
                          ("yiys", (reflection, transmission))):
        for side, value in (("reflection", r), ("transmission", t)):
            lines += [f"[top.plate.{inter}.{side}]", f"tis = [{value}, {value}]",
                      'distribution = {kind = "lambertian"}']
    return "\n".join(lines)


def one_line(code: int, err: str, *needles: str) -> None:
    """Exit status 2, one line on stderr, no traceback, and every needle (the cause) in that line."""
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


# ----------------------------------------------------------------------------------------- beam widths
@pytest.mark.parametrize("fwhm_deg", [1e-6, 1e-12, 1e-300])
def test_narrowest_beam_is_its_collimated_limit(fwhm_deg):
    """FWHM below float resolution: m is finite (no ZeroDivisionError) and the beam is traced collimated:
    under an exit top every ray leaves at its first event, LER = 1 exactly."""
    s = loads_scene(scene_text(beam=f"fwhm_deg = {fwhm_deg}"))
    m = s.leds.cos_exponent
    assert math.isfinite(m) and 1e15 < m <= COLLIMATED_EXPONENT
    r = trace(s, 2000)
    assert r.LER == 1.0 and r.absorbed["wall"] == 0.0


def test_narrow_but_resolvable_beam_keeps_its_half_maximum():
    """cos(FWHM/2)^m = 1/2 to 1e-9 for beams from 1e-4 to 179 deg; below 1 deg checked against the series
    ln cos h = -h²/2 - h⁴/12 - h⁶/45 (plain ln cos loses digits there)."""
    for fwhm_deg in (1e-4, 0.01, 0.5, 30.0, 120.0, 179.0):
        s = loads_scene(scene_text(beam=f"fwhm_deg = {fwhm_deg}"))
        h = math.radians(fwhm_deg) / 2
        log_cos = -(h**2 / 2 + h**4 / 12 + h**6 / 45) if fwhm_deg < 1 else math.log(math.cos(h))
        assert math.exp(s.leds.cos_exponent * log_cos) == pytest.approx(0.5, rel=1e-9)


def test_narrow_beam_trace_command_succeeds(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(scene_text(beam="fwhm_deg = 1e-06"))
    assert main(["trace", str(path), "--rays", "1000"]) == 0
    assert "Traceback" not in capsys.readouterr().err


# ------------------------------------------------------------------------------ closed lossless cavities
def test_closed_lossless_cavity_under_a_plate_is_refused_at_once(tmp_path, capsys):
    """White walls under a plate that reflects everything: formerly 2e6 rays x 1e4 events (>100 s); now refused
    at scene validation with the reason and the allowed max_events."""
    path = tmp_path / "s.toml"
    path.write_text(scene_text(1.0, top=plate_top(1.0)))
    started = time.perf_counter()
    code = main(["trace", str(path), "--rays", "2000000"])
    one_line(code, capsys.readouterr().err, "s.toml", "trace.max_events", "no ray can ever leave or be absorbed",
             "a plate that reflects everything", f"max_events <= LOSSLESS_MAX_EVENTS ({LOSSLESS_MAX_EVENTS})")
    assert time.perf_counter() - started < 10.0


def test_plate_that_loses_a_little_is_bounded_and_its_ledger_closes():
    """A plate transmitting 1 % is not closed; its events per ray are bounded by the roulette, and a run
    capped at max_events reports the truncated power so that emitted = extracted + absorbed + roulette +
    discarded + truncated to float64 rounding."""
    s = loads_scene(scene_text(1.0, top=plate_top(0.99, 0.01), trace_opts="max_events = 50"))
    n = events_per_ray(s.wall, s.base, s.leds, s.top, s.trace)
    assert n == 50.0  # 1/(1 - 0.99) = 100 roulette events on average > cap
    r = trace(s, 4000)
    assert r.truncated > 0
    total = r.extracted["total"] + sum(r.absorbed.values()) + r.roulette + r.discarded + r.truncated
    assert total == pytest.approx(r.emitted, rel=1e-12, abs=1e-12)
    assert r.ledger_error < 1e-12
    # the closed plate with a short cap is accepted as a test of the truncation ledger: everything truncated
    closed = loads_scene(scene_text(1.0, top=plate_top(1.0), trace_opts="max_events = 20"))
    rc = trace(closed, 1000)
    assert rc.truncated == pytest.approx(rc.emitted, rel=1e-12) and rc.extracted["total"] == 0.0


def test_lossless_plate_scene_built_in_python_is_refused_by_the_tracer():
    from dataclasses import replace

    ok = loads_scene(scene_text(1.0, top=plate_top(1.0), trace_opts="max_events = 20"))
    with pytest.raises(ValidationError, match="LOSSLESS_MAX_EVENTS"):
        trace(replace(ok, trace=replace(ok.trace, max_events=10**6)), 10)


# ------------------------------------------------------------------------------------ --force and inputs
VERB_ARGS = {
    "fit bsdf": ["fit", "bsdf", "{i}", "--interaction", "bibs", "--side", "reflection", "-o", "{o}"],
    "fit reflectance": ["fit", "reflectance", "{i}", "-o", "{o}"],
    "ingest": ["ingest", "{i}", "-o", "{o}"],
    "convert": ["convert", "{i}", "--to", "zemax", "-o", "{o}"],
    "export": ["export", "{i}", "--to", "zemax", "-o", "{o}"],
    "trace": ["trace", "{i}", "-o", "{o}"],
    "sweep": ["sweep", "{i}", "--param", "wall.reflectance=0.8,0.9", "-o", "{o}"],
}


@pytest.mark.parametrize("verb", sorted(VERB_ARGS))
@pytest.mark.parametrize("how", ["same path", "other spelling", "hard link"])
def test_force_never_replaces_an_input_of_any_verb(tmp_path, monkeypatch, capsys, verb, how):
    monkeypatch.chdir(tmp_path)
    src = tmp_path / "IN.nc"
    src.write_bytes(b"measured scan\n")
    out = {"same path": "IN.nc", "other spelling": f"../{tmp_path.name}/./IN.nc", "hard link": "link.nc"}[how]
    if how == "hard link":
        (tmp_path / "link.nc").hardlink_to(src)
    argv = [a.format(i="IN.nc", o=out) for a in VERB_ARGS[verb]] + ["--force"]
    one_line(main(argv), capsys.readouterr().err, "output would overwrite an input of this command",
             "refused even with --force")
    assert src.read_bytes() == b"measured scan\n"


def test_sweep_plot_beside_the_output_is_an_output_too(tmp_path, monkeypatch, capsys):
    """``sweep -o out.nc`` also writes out_LER_YBR.png: an input at that path is refused with --force."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out_LER_YBR.png").write_bytes(b"not a scene")
    code = main(["sweep", "out_LER_YBR.png", "--param", "wall.reflectance=0.8,0.9", "-o", "out.nc", "--force"])
    one_line(code, capsys.readouterr().err, "out_LER_YBR.png", "output would overwrite an input")


# ------------------------------------------------------------------------------------------ usage errors
def test_fit_without_a_sub_verb_is_a_usage_error_on_stderr(capsys):
    with pytest.raises(SystemExit) as info:
        main(["fit"])
    assert info.value.code == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    one_line(2, cap.err, "bsdfkit fit: error: no sub-verb given; expected one of spectrum, bsdf, reflectance")


# ------------------------------------------------------------------------------------------ output folders
def _trace(tmp_path, out, *extra, tallies: str = "") -> list[str]:
    scene = tmp_path / "s.toml"
    scene.write_text(scene_text() + tallies)
    return ["trace", str(scene), "--rays", "1000", "-o", str(out), *extra]


def _has_root_mount() -> bool:
    import os
    import shutil
    return os.geteuid() == 0 and shutil.which("mount") is not None


def test_read_only_output_folder_is_refused_and_kept(tmp_path, capsys):
    """An empty folder of mode 555: formerly replaced by a new mode-755 folder (for root); now refused with the
    permission named, and left as it was."""
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        code = main(_trace(tmp_path, folder / "x.nc"))
        one_line(code, capsys.readouterr().err, str(folder), "not writable (permission denied, mode 555)",
                 "chmod u+w")
        assert oct(folder.stat().st_mode & 0o777) == "0o555" and list(folder.iterdir()) == []
    finally:
        folder.chmod(0o755)


@pytest.mark.parametrize("verb", ["trace", "sweep"])
def test_output_folder_keeps_its_owner_and_mode(tmp_path, verb):
    import os

    folder = tmp_path / "out"
    folder.mkdir()
    folder.chmod(0o750)
    owner = (folder.stat().st_uid, folder.stat().st_gid)
    if os.geteuid() == 0:
        os.chown(folder, 1234, 1234)
        owner = (1234, 1234)
    if verb == "trace":
        argv = _trace(tmp_path, folder / "x.nc")
    else:
        scene = tmp_path / "s.toml"
        scene.write_text(scene_text())
        argv = ["sweep", str(scene), "--param", "wall.reflectance=0.8,0.9", "--rays", "500", "--no-plots",
                "-o", str(folder / "x.nc")]
    assert main(argv) == 0
    st = folder.stat()
    assert (st.st_mode & 0o777, st.st_uid, st.st_gid) == (0o750, *owner)
    assert [p.name for p in folder.iterdir()] == ["x.nc"]
    assert main(argv + ["--force"]) == 0  # replacing the previous set keeps them too
    st = folder.stat()
    assert (st.st_mode & 0o777, st.st_uid, st.st_gid) == (0o750, *owner)


def test_a_250_byte_output_name_is_written(tmp_path, capsys):
    """Temporary names are at most 33 bytes: any valid output name (here 250 bytes) can be written, as a
    single file and inside an output set; a name over NAME_MAX is refused as too long."""
    from bsdfkit.io.atomic import write_text

    name = "a" * 247 + ".nc"
    assert len(name.encode()) == 250
    assert main(_trace(tmp_path, tmp_path / name)) == 0
    assert (tmp_path / name).is_file()
    write_text(tmp_path / ("b" * 250), "x")
    assert (tmp_path / ("b" * 250)).read_text() == "x"
    code = main(_trace(tmp_path, tmp_path / ("c" * 253 + ".nc")))
    one_line(code, capsys.readouterr().err, "file name too long [ENAMETOOLONG]")
    assert not [p for p in tmp_path.iterdir() if p.name.endswith((".part", ".staging"))]


@pytest.fixture
def mounted(tmp_path):
    """Mount helper (root only): yields mount(kind, path) and unmounts everything afterwards."""
    import subprocess

    if not _has_root_mount():
        pytest.skip("needs root and mount")
    done = []

    def mount(*args) -> None:
        proc = subprocess.run(["mount", *args], capture_output=True)
        if proc.returncode != 0:
            pytest.skip(f"mount failed: {proc.stderr.decode().strip()}")
        done.append(args[-1])

    yield mount
    for point in reversed(done):
        subprocess.run(["umount", point], capture_output=True)


def test_bind_mounted_output_folder_is_written_in_place(tmp_path, mounted, capsys):
    """A writable bind mount of the same file system (os.path.ismount says False): formerly "device or resource
    busy" (the folder cannot be renamed); now staged inside it and written file by file, atomically."""
    src, dst = tmp_path / "src", tmp_path / "dst"
    src.mkdir()
    dst.mkdir()
    mounted("--bind", str(src), str(dst))
    assert main(_trace(tmp_path, dst / "x.nc")) == 0
    assert [p.name for p in dst.iterdir()] == ["x.nc"] and (src / "x.nc").is_file()
    code = main(_trace(tmp_path, dst / "x.nc"))
    one_line(code, capsys.readouterr().err, "output exists; pass --force")
    assert main(_trace(tmp_path, dst / "x.nc", "--force")) == 0
    assert [p.name for p in dst.iterdir()] == ["x.nc"]


def test_full_device_says_no_space_and_names_the_file(tmp_path, mounted, capsys):
    """A 256 KiB tmpfs and a 0.55 MB netCDF file (a 256² irradiance map; 512² bins took 3× as long): formerly "the
    netCDF library failed (NetCDF: HDF error)"."""
    full = tmp_path / "full"
    full.mkdir()
    mounted("-t", "tmpfs", "-o", "size=256k", "tmpfs", str(full))
    code = main(_trace(tmp_path, full / "m.nc", tallies="[tallies]\nirradiance_map = true\nmap_bins = 256\n"))
    one_line(code, capsys.readouterr().err, "no space left on device while writing m.nc [ENOSPC]", str(full))
    assert list(full.iterdir()) == []


def test_a_trace_mostly_truncated_says_so(tmp_path, capsys):
    """A closed white cavity capped at 20 events: all its power is truncated; the result is printed with one
    warning line naming max_events (nothing silent)."""
    path = tmp_path / "s.toml"
    path.write_text(scene_text(1.0, top=plate_top(1.0), trace_opts="max_events = 20"))
    assert main(["trace", str(path), "--rays", "1000"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "100 % of the emitted power was truncated at trace.max_events = 20" in err[0], err
