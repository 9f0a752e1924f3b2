"""Issue #44.8: no process outlives the command that started it.

The helper process of ``bsdfkit run`` (:func:`bsdfkit.pipeline.helper.helper_process`) was found alive, adopted by
PID 1, hours after its run had ended. Here the helper is started through the same code path in a small parent
script (and by ``bsdfkit run`` itself), the parent is ended (SIGKILL, SIGTERM, a normal exit, an error) and every
process it had started must be gone within a few seconds. Only processes these tests start are signalled.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from conftest import ROOT

#: the parent: starts the helper as ``bsdfkit run`` does, keeps it busy (or idle), prints its pid, then waits
PARENT = """import os, sys, time
import bsdfkit.core.children as children
import bsdfkit.pipeline.helper as helper
if __name__ == "__main__":
    children.USE_DEATH_SIGNAL = sys.argv[1] == "signal"
    with helper.helper_process(True, preload=()) as pool:
        pid = pool.submit(os.getpid).result()
        if sys.argv[2] == "busy":
            pool.submit(time.sleep, 120)
        print(pid, flush=True)
        if sys.argv[3] == "error":
            raise SystemExit(3)
        if sys.argv[3] == "wait":
            time.sleep(120)
"""

#: how long the children of an ended parent may take to end [s]
GRACE_S = 5.0


def _start_parent(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, int, list[psutil.Process]]:
    script = tmp_path / "parent.py"
    script.write_text(PARENT)
    proc = subprocess.Popen([sys.executable, str(script), *args], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    assert line.isdigit(), proc.communicate(timeout=30)
    return proc, int(line), psutil.Process(proc.pid).children(recursive=True)


def _gone(process: psutil.Process) -> bool:
    try:
        return process.status() == psutil.STATUS_ZOMBIE  # ended; only its exit status is left to collect
    except psutil.NoSuchProcess:
        return True


def _wait_gone(children: list[psutil.Process], grace_s: float = GRACE_S) -> list[psutil.Process]:
    """The processes of ``children`` still running after ``grace_s`` seconds."""
    end = time.monotonic() + grace_s
    while time.monotonic() < end:
        alive = [c for c in children if not _gone(c)]
        if not alive:
            return []
        time.sleep(0.1)
    return [c for c in children if not _gone(c)]


def _kill(children: list[psutil.Process]) -> None:
    for child in children:  # a failed test leaves nothing behind either (only processes this test started)
        try:
            child.kill()
        except psutil.NoSuchProcess:
            pass


@pytest.mark.parametrize("death_signal", ["signal", "poll"])
@pytest.mark.parametrize("work", ["busy", "idle"])
def test_helper_ends_when_its_parent_is_killed(tmp_path, death_signal, work):
    proc, helper_pid, children = _start_parent(tmp_path, death_signal, work, "wait")
    assert helper_pid in [c.pid for c in children]
    try:
        proc.kill()  # SIGKILL: the parent runs no handler
        proc.communicate(timeout=10)
        alive = _wait_gone(children)
        assert not alive, f"still running {GRACE_S} s after the parent's SIGKILL: {alive}"
    finally:
        _kill(children)


@pytest.mark.parametrize("ending", ["normal", "error"])
def test_helper_ends_with_the_block(tmp_path, ending):
    proc, helper_pid, children = _start_parent(tmp_path, "signal", "busy", ending)
    try:
        proc.communicate(timeout=30)
        assert proc.returncode == (0 if ending == "normal" else 3)
        assert helper_pid in [c.pid for c in children]
        assert not _wait_gone(children)
    finally:
        _kill(children)


def _run_command(tmp_path: Path) -> tuple[subprocess.Popen, list[psutil.Process]]:
    """``bsdfkit run`` of the bundled recipe, once its helper has started: (process, its children)."""
    proc = subprocess.Popen([str(Path(sys.executable).with_name("bsdfkit")), "run",
                             str(ROOT / "fitting" / "cl830.toml"), "-o", str(tmp_path / "out")], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    parent = psutil.Process(proc.pid)
    end = time.monotonic() + 60
    children: list[psutil.Process] = []
    while time.monotonic() < end and proc.poll() is None:
        with_helper = [c for c in parent.children(recursive=True) if "multiprocessing" in " ".join(c.cmdline())]
        if any("spawn_main" in " ".join(c.cmdline()) for c in with_helper):
            children = parent.children(recursive=True)
            break
        time.sleep(0.05)
    assert children, proc.communicate(timeout=60)
    time.sleep(1.0)  # the helper is importing the pipeline, the command its own modules
    return proc, children + [c for c in parent.children(recursive=True) if c not in children]


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM])
def test_run_command_leaves_no_process(tmp_path, signum):
    proc, children = _run_command(tmp_path)
    try:
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=20)
        assert proc.returncode == -signal.SIGKILL if signum == signal.SIGKILL else 128 + signum, err
        alive = _wait_gone(children)
        assert not alive, f"still running {GRACE_S} s after `bsdfkit run` got signal {signum}: {alive}"
    finally:
        proc.kill()
        _kill(children)


@pytest.mark.slow
def test_sweep_workers_end_when_the_command_is_killed(tmp_path):
    # the other place that starts processes: the local dask cluster of `bsdfkit sweep --workers N`, whose workers
    # watch a pipe from their parent (dask.distributed) and end when it closes
    proc = subprocess.Popen([str(Path(sys.executable).with_name("bsdfkit")), "sweep",
                             str(ROOT / "fitting" / "scenes" / "example.toml"), "--param",
                             "wall.reflectance=0.8:0.98:6", "--rays", "20000000", "--workers", "2", "--no-plots",
                             "-o", str(tmp_path / "sweep.nc")], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    parent = psutil.Process(proc.pid)
    end = time.monotonic() + 90
    children: list[psutil.Process] = []
    while time.monotonic() < end and proc.poll() is None and len(children) < 3:  # two workers, a resource tracker
        children = parent.children(recursive=True)
        time.sleep(0.1)
    try:
        assert len(children) >= 3, proc.communicate(timeout=60)
        time.sleep(2.0)  # the workers are importing and starting their tasks
        proc.kill()
        proc.communicate(timeout=10)
        alive = _wait_gone(children)
        assert not alive, f"still running {GRACE_S} s after the sweep's SIGKILL: {alive}"
    finally:
        proc.kill()
        _kill(children)


def _marked(mark: str) -> list[psutil.Process]:
    """The running processes whose environment carries ``mark`` (inherited from a command this test started)."""
    found = []
    for process in psutil.process_iter():
        try:
            if process.environ().get(MARK_VAR) == mark and not _gone(process):
                found.append(process)
        except (psutil.AccessDenied, psutil.NoSuchProcess, psutil.ZombieProcess):
            continue
    return found


#: an environment variable that marks the processes a command of these tests starts (they inherit it)
MARK_VAR = "BSDFKIT_TEST_LIFETIME_MARK"


@pytest.mark.parametrize("ending", ["error", pytest.param("success", marks=pytest.mark.slow)])
def test_run_command_leaves_no_process_when_it_ends(tmp_path, ending):
    recipe = tmp_path / "recipe.toml"
    text = (ROOT / "fitting" / "cl830.toml").read_text().replace('"../', f'"{ROOT.as_posix()}/').replace(
        'scene = "scenes/', f'scene = "{ROOT.as_posix()}/fitting/scenes/')
    if ending == "error":  # refused as it starts (after the helper has been started)
        text = text.replace("figure_wavelength_nm = 460.0", "figure_wavelength_nm = 2000")
    recipe.write_text(text)
    mark = f"{tmp_path.name}-{time.monotonic_ns()}"
    done = subprocess.run([str(Path(sys.executable).with_name("bsdfkit")), "run", str(recipe), "-o",
                           str(tmp_path / "out")], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          env={**os.environ, MARK_VAR: mark})
    assert done.returncode == (2 if ending == "error" else 0), done.stderr
    alive = _wait_gone(_marked(mark))
    try:
        assert not alive, f"still running {GRACE_S} s after `bsdfkit run` ended ({ending}): {alive}"
    finally:
        _kill(alive)
