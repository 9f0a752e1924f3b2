"""An export or run killed mid-write leaves the old file or none — never a partial file."""
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import BUNDLED, fast_lane

SLOW_WRITER = r"""
import sys, time
from bsdfkit.io.atomic import write_with
def slow(tmp):
    with open(tmp, "wb") as fh:
        for _ in range(10_000):
            fh.write(b"new data " * 1000)
            fh.flush()
            time.sleep(0.001)
write_with(sys.argv[1], slow, force=True)
"""


def _wait_for_part(folder: Path, timeout: float = 60.0) -> None:
    start = time.time()
    while time.time() - start < timeout:
        if any(p.name.endswith(".part") for p in folder.iterdir()):
            return
        time.sleep(0.01)
    raise AssertionError("writer never started")


@pytest.mark.parametrize("existing", fast_lane([True, False], {True}))  # a fresh interpreter each (2 s)
def test_killed_writer_leaves_old_file_or_none(tmp_path, existing):
    target = tmp_path / "table.txt"
    if existing:
        target.write_bytes(b"OLD COMPLETE FILE")
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WRITER, str(target)])
    _wait_for_part(tmp_path)
    time.sleep(0.2)  # well inside the write
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    if existing:
        assert target.read_bytes() == b"OLD COMPLETE FILE"
    else:
        assert not target.exists()


@pytest.mark.slow
def test_killed_cli_export_leaves_nothing_behind(tmp_path):
    """A real verb: `bsdfkit ingest` killed while writing its netCDF."""
    out = tmp_path / "scan.nc"
    proc = subprocess.Popen([sys.executable, "-m", "bsdfkit", "ingest", str(BUNDLED), "-o", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _wait_for_part(tmp_path, timeout=120)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert not out.exists(), "partial output left at the target path"
    # the killed run's temporary file does not block the next run
    done = subprocess.run([sys.executable, "-m", "bsdfkit", "ingest", str(BUNDLED), "-o", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert out.stat().st_size > 0
    # and no temporary file outlives its process: the rerun removed the killed run's .part file
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")] == []


def test_killed_output_set_leaves_previous_set(tmp_path):
    """A multi-file output set (as `bsdfkit run` writes) killed while writing: the previous set stays whole."""
    folder = tmp_path / "out"
    folder.mkdir()
    for k in range(5):
        (folder / f"f{k}.txt").write_text("OLD")
    script = (
        "import sys, time\n"
        "from bsdfkit.io.atomic import OutputSet, write_text\n"
        "with OutputSet(sys.argv[1], [f'f{k}.txt' for k in range(5)], force=True) as out:\n"
        "    for k in range(5):\n"
        "        write_text(out.path(f'f{k}.txt'), 'NEW', True)\n"
        "        if k == 2:\n"
        "            print('half', flush=True); time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", script, str(folder)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "half"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert sorted(p.read_text() for p in folder.iterdir()) == ["OLD"] * 5
