"""Fault injection (issue #13): a long trace answers Ctrl-C and SIGTERM within two seconds, leaving nothing.

A chunk of the tracer is one call into XLA that can run for many seconds; the command line's signal watcher
(:func:`bsdfkit.cli.main.prompt_signals`) ends the process while it runs. Measured in a subprocess: the
signal is sent about three seconds into a trace of 2e9 rays (hours of work), and the process must be gone
within two seconds with no output and no temporary file left.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

SCENE = ROOT / "fitting" / "scenes" / "example.toml"


TRACE = """import sys
import jax
import bsdfkit.cli.trace
from bsdfkit.cli.main import main
print("ready", flush=True)
sys.exit(main(["trace", sys.argv[1], "--rays", "2000000000", "-o", sys.argv[2]]))
"""


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*"))


def _default_sigint() -> None:
    # a background job of a non-interactive shell inherits SIGINT ignored; a user's terminal does not
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("signum", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_long_trace_answers_signal_within_two_seconds(tmp_path, signum):
    out = tmp_path / "out.nc"
    proc = subprocess.Popen([sys.executable, "-c", TRACE, str(SCENE), str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    assert proc.stdout.readline().strip() == "ready"  # imports done: the trace starts now
    time.sleep(3.0)
    assert proc.poll() is None, proc.communicate()
    sent = time.perf_counter()
    proc.send_signal(signum)
    try:
        _, err = proc.communicate(timeout=10)
    finally:
        proc.kill()
    waited = time.perf_counter() - sent
    assert waited < 2.0, f"exit took {waited:.2f} s"
    assert proc.returncode == 128 + signum, err
    assert "Traceback" not in err
    assert _leftovers(tmp_path) == []


EARLY_DELAYS_S = (0.1, 0.2, 0.3)


def _before_any_bsdfkit_code(returncode: int, err: str) -> bool:
    """Whether the signal ended the interpreter's own start-up, before any code of bsdfkit ran: killed by the
    default SIGINT disposition (Python's handler not yet installed), or a traceback with no frame in bsdfkit's
    files (site, the editable install's finder, runpy looking the package up)."""
    if returncode == -signal.SIGINT or "init_import_site" in err:
        return True
    frames = [line for line in err.splitlines() if line.lstrip().startswith("File ")]
    ours = [f for f in frames if "/bsdfkit/" in f or "bsdfkit_console.py" in f]
    return "Traceback" in err and not ours


@pytest.mark.parametrize("module", ["bsdfkit_console", "bsdfkit"])
@pytest.mark.parametrize("delay", EARLY_DELAYS_S)
def test_ctrl_c_while_importing_is_one_line_and_status_130(tmp_path, delay, module):
    # the console command (bsdfkit_console:main) answers Ctrl-C before `import bsdfkit` (xarray, ~1 s) is done,
    # and so does `python -m bsdfkit`, whose package is imported before its __main__
    out = tmp_path / "out.nc"
    argv = [sys.executable, "-m", module, "trace", str(SCENE), "--rays", "2000000000", "-o", str(out)]
    for wait in delay + 0.2 * np.arange(10):  # a loaded machine can take a second or more to start Python
        proc = subprocess.Popen(argv, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=_default_sigint)
        time.sleep(wait)
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=20)
        finally:
            proc.kill()
        if not _before_any_bsdfkit_code(proc.returncode, err):
            break
        # the signal came while the interpreter itself was starting (its site module, or runpy looking up the
        # package), before any bsdfkit code ran: nothing a package can answer; wait a little longer
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("bsdfkit: interrupted"), err
    assert _leftovers(tmp_path) == []


def test_early_handlers_only_for_the_bsdfkit_command():
    # importing bsdfkit changes no signal handler in any other program (here: pytest)
    code = ("import signal, sys; before = signal.getsignal(signal.SIGINT); import bsdfkit; "
            "sys.exit(0 if signal.getsignal(signal.SIGINT) is before else 1)")
    assert subprocess.run([sys.executable, "-c", code], cwd=ROOT).returncode == 0
    import bsdfkit_console

    assert bsdfkit_console.is_bsdfkit_command(["python", "-X", "importtime", "-m", "bsdfkit", "trace"])
    assert not bsdfkit_console.is_bsdfkit_command(["python", "-m", "pytest", "-m", "bsdfkit"])
    assert not bsdfkit_console.is_bsdfkit_command(["python", "tool.py", "-m", "bsdfkit"])


def test_console_command_is_the_early_signal_launcher():
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["bsdfkit"] == "bsdfkit_console:main"


SEMAPHORES = """import multiprocessing, signal, sys, time
from bsdfkit.cli.main import exit_now
signal.signal(signal.SIGTERM, lambda signum, frame: exit_now(signum))
ctx = multiprocessing.get_context("spawn")
held = [ctx.Lock() for _ in range(3)] + [ctx.Queue()]  # what a dask LocalCluster holds: named semaphores
held[-1].put(1)
child = ctx.Process(target=time.sleep, args=(60,), daemon=True)
child.start()
print("ready", flush=True)
time.sleep(60)
"""


def test_signal_exit_releases_semaphores_so_stderr_is_one_line(tmp_path):
    # after a signal exit of `sweep --workers 2` multiprocessing's resource tracker warned of leaked semaphores
    proc = subprocess.Popen([sys.executable, "-c", SEMAPHORES], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 143, err
    # nothing was being written: the message says so (issue #44.9: an interrupt after a commit said "removed")
    assert err.strip().splitlines() == ["bsdfkit: terminated; no unfinished output (what was written is complete)"], err
