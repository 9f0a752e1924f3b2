"""``bsdfkit run`` feedback: stage lines and rich progress bars on stderr only, off with --quiet or without a TTY
(the stage lines on with --verbose)."""
from __future__ import annotations

import io
import re

import pytest

from bsdfkit.cli import run as run_verb


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_quiet_run_says_nothing(monkeypatch, capsys):
    with run_verb.run_feedback(quiet=True) as (log, progress):
        log("stage ingest ...")
        assert progress is None
    out, err = capsys.readouterr()
    assert out == "" and err == ""


def test_without_a_terminal_stderr_stays_for_errors(monkeypatch, capsys):
    with run_verb.run_feedback(quiet=False) as (log, progress):
        log("stage ingest ...")
        assert progress is None  # a log file or a pipe gets no bars
    out, err = capsys.readouterr()
    assert out == "" and err == ""  # a failed run's stderr is its one error line


def test_without_a_terminal_verbose_writes_the_stage_lines(monkeypatch, capsys):
    with run_verb.run_feedback(quiet=False, verbose=True) as (log, progress):
        log("stage ingest ...")
        assert progress is None
    out, err = capsys.readouterr()
    assert out == "" and err == "stage ingest ...\n"


def test_on_a_terminal_progress_bars_go_to_stderr_never_to_stdout(monkeypatch, capsys):
    tty = _Tty()
    monkeypatch.setattr("sys.stderr", tty)
    with run_verb.run_feedback(quiet=False) as (log, progress):
        assert progress is not None
        log("stage trace ... [Cylindrical-module]")
        for done in range(4):
            progress("trace", done, 3)
    out, _ = capsys.readouterr()
    assert out == ""
    shown = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", tty.getvalue())  # without the terminal's control sequences
    assert "module traces" in shown and "3/3" in shown
    assert "stage trace ... [Cylindrical-module]\n" in shown  # the line as written, brackets kept


@pytest.mark.parametrize("flag", ["--quiet", "--json"])
def test_run_accepts_quiet_and_json(flag):
    import argparse

    parser = argparse.ArgumentParser()
    run_verb.register(parser.add_subparsers())
    args = parser.parse_args(["run", "r.toml", "-o", "out", flag])
    assert args.quiet == (flag == "--quiet") and args.json == (flag == "--json")
