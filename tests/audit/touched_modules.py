"""Which modules of bsdfkit a test run executes: a pytest plugin, not part of the suite.

    .venv/bin/python -m pytest -q -m "not slow" -p tests.audit.touched_modules

After the run it prints every module of ``bsdfkit/`` that the run never imported, and every module that was
imported but none of whose functions or methods ran (a module without any function counts as run once
imported). The fast lane's promise (README: it "touches every module") holds when both lists are empty.
A profile hook (``sys.setprofile``, also in threads) records the source file of every Python call; with
pytest-xdist each worker writes its set to a folder that the controller merges. The hook slows the run down
(about 1.5x), so take no timings from it.
"""
from __future__ import annotations

import ast
import json
import os
import sys
import tempfile
import threading
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "bsdfkit"
_PREFIX = str(PACKAGE) + os.sep
_called: set[str] = set()


def _hook(frame, event, arg):
    if event == "call":
        name = frame.f_code.co_filename
        if name.startswith(_PREFIX) and frame.f_code.co_name != "<module>":
            _called.add(name)


def _folder(config) -> Path:
    return Path(os.environ.get("BSDFKIT_TOUCHED_DIR") or Path(tempfile.gettempdir()) / "bsdfkit-touched")


def pytest_configure(config):
    if not hasattr(config, "workerinput"):  # the controller (or a run without xdist): a fresh folder
        folder = _folder(config)
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob("*.json"):
            old.unlink()
    sys.setprofile(_hook)
    threading.setprofile(_hook)


def pytest_sessionfinish(session, exitstatus):
    sys.setprofile(None)
    threading.setprofile(None)
    imported = {str(Path(m.__file__)) for m in list(sys.modules.values())
                if getattr(m, "__file__", None) and str(m.__file__).startswith(_PREFIX)}
    worker = getattr(session.config, "workerinput", {}).get("workerid", "main")
    folder = _folder(session.config)
    (folder / f"{worker}.json").write_text(json.dumps({"called": sorted(_called), "imported": sorted(imported)}))


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
    idle = [p for p in modules if str(p) in imported and str(p) not in called and _has_function(p)]
    rel = PACKAGE.parent
    terminalreporter.write_line(f"bsdfkit modules: {len(modules)}; never imported: {len(never)}; imported but no "
                                f"function ran: {len(idle)}")
    for p in never:
        terminalreporter.write_line(f"  never imported: {p.relative_to(rel)}")
    for p in idle:
        terminalreporter.write_line(f"  no function ran: {p.relative_to(rel)}")
