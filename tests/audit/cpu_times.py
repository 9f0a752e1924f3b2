"""The CPU time of every test: a pytest plugin, not part of the suite.

    .venv/bin/python -m pytest -q -m "not slow" -p tests.audit.cpu_times

Wall times of a shared 2-core machine vary with its load; the CPU a test uses (user + system of the worker and of
the commands it waited for, over setup, call and teardown) hardly does. After the run it prints the sum over the
tests and the 20 most expensive; ``BSDFKIT_CPU_TIMES=FILE`` also writes every test's figure to FILE (tab
separated: seconds, node id). Start-up and collection of the workers are not in it. With pytest-xdist each
worker sends its figures to the controller in the test reports.
"""
from __future__ import annotations

import os

import pytest

_KEY = "cpu_seconds"


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    item.stash.setdefault(_stash_key, [_cpu()])
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if call.when == "teardown":
        start = item.stash.get(_stash_key, [_cpu()])[0]
        report.user_properties.append((_KEY, _cpu() - start))


_stash_key = pytest.StashKey[list]()
_seen: dict[str, float] = {}


def pytest_runtest_logreport(report):
    if report.when == "teardown":
        for key, value in report.user_properties:
            if key == _KEY:
                _seen[report.nodeid] = value


def pytest_terminal_summary(terminalreporter):
    if hasattr(terminalreporter.config, "workerinput") or not _seen:
        return
    total = sum(_seen.values())
    tr = terminalreporter
    tr.write_sep("=", f"test CPU: {total:.1f} s over {len(_seen)} tests")
    for node, value in sorted(_seen.items(), key=lambda kv: -kv[1])[:20]:
        tr.write_line(f"{value:8.1f} s  {node}")
    out = os.environ.get("BSDFKIT_CPU_TIMES")
    if out:
        with open(out, "w", encoding="utf-8") as fh:
            for node, value in sorted(_seen.items(), key=lambda kv: -kv[1]):
                fh.write(f"{value:.3f}\t{node}\n")
