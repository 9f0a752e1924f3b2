"""Which modules of bsdfkit a test run executes: a pytest plugin, not part of the suite.

    .venv/bin/python -m pytest -q -m "not slow" -p tests.audit.touched_modules

After the run it prints every module of ``bsdfkit/`` that the run never imported (the fast lane's promise,
README: it "touches every module", holds when the list is empty). With ``BSDFKIT_TOUCHED_CALLS=1`` it also
lists every imported module none of whose functions or methods ran (a module without any function counts as
run once imported): the C profiler (``cProfile``, in the main thread of each process) records every function
called, which slows the run down (take no timings from it). With pytest-xdist each worker writes its sets to a
folder that the controller merges.
"""
from __future__ import annotations

import ast
import cProfile
import json
import os
import pstats
import sys
import tempfile
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "bsdfkit"
_PREFIX = str(PACKAGE) + os.sep
_profiler: cProfile.Profile | None = None


def _calls_wanted() -> bool:
    return os.environ.get("BSDFKIT_TOUCHED_CALLS", "") not in ("", "0")


def _folder(config) -> Path:
    return Path(os.environ.get("BSDFKIT_TOUCHED_DIR") or Path(tempfile.gettempdir()) / "bsdfkit-touched")


def pytest_configure(config):
    if not hasattr(config, "workerinput"):  # the controller (or a run without xdist): a fresh folder
        folder = _folder(config)
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob("*.json"):
            old.unlink()
    global _profiler
    if _calls_wanted():
        _profiler = cProfile.Profile()
        _profiler.enable()


def pytest_sessionfinish(session, exitstatus):
    called: set[str] = set()
    if _profiler is not None:
        _profiler.disable()
        called = {f for f, _, name in pstats.Stats(_profiler).stats if f.startswith(_PREFIX) and name != "<module>"}
    imported = {str(Path(m.__file__)) for m in list(sys.modules.values())
                if getattr(m, "__file__", None) and str(m.__file__).startswith(_PREFIX)}
    worker = getattr(session.config, "workerinput", {}).get("workerid", "main")
    folder = _folder(session.config)
    (folder / f"{worker}.json").write_text(json.dumps({"called": sorted(called), "imported": sorted(imported)}))


def _has_function(path: Path) -> bool:
    return any(isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) for n in ast.walk(ast.parse(path.read_text())))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if hasattr(config, "workerinput"):
        return
    called: set[str] = set()
    imported: set[str] = set()
    for part in _folder(config).glob("*.json"):
        data = json.loads(part.read_text())
        called |= set(data["called"])
        imported |= set(data["imported"])
    modules = sorted(PACKAGE.rglob("*.py"))
    never = [p for p in modules if str(p) not in imported]
    calls = _calls_wanted()
    idle = [p for p in modules if calls and str(p) in imported and str(p) not in called and _has_function(p)]
    rel = PACKAGE.parent
    terminalreporter.write_line(f"bsdfkit modules: {len(modules)}; never imported: {len(never)}"
                                + (f"; imported but no function ran: {len(idle)}" if calls else ""))
    for p in never:
        terminalreporter.write_line(f"  never imported: {p.relative_to(rel)}")
    for p in idle:
        terminalreporter.write_line(f"  no function ran: {p.relative_to(rel)}")
