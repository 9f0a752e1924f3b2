"""The ``bsdfkit`` console command: answers Ctrl-C (and SIGTERM) from its first moment.

This module lies outside the :mod:`bsdfkit` package on purpose. ``import bsdfkit`` imports xarray (to register
the ``ds.bsdf`` accessor) and the command then imports its verb's libraries: a second or more in all, during
which a Ctrl-C would end the command with Python's ``KeyboardInterrupt`` traceback. Here a signal that comes
before :func:`bsdfkit.cli.main.main` takes over ends the process at once with one line on stderr and status
128 + signal (130 for Ctrl-C, 143 for SIGTERM), as :func:`bsdfkit.cli.main.exit_now` does later; nothing has
been written yet, so there is nothing to remove. A Ctrl-C that is ignored (``nohup``, a background job) stays
ignored.

``python -m bsdfkit`` imports the package before its ``__main__``: there ``bsdfkit/__init__.py`` installs the
same handlers first, when (and only when) :func:`is_bsdfkit_command` says that the process is that command.
"""
from __future__ import annotations

import os
import signal
import sys
from typing import NoReturn


def _early_signal(signum: int, frame: object) -> None:
    name = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"bsdfkit: {name}\n".encode())
    os._exit(128 + signum)


def install_early_handlers() -> None:
    """Ctrl-C and SIGTERM end the process at once with one line (status 130, 143) until
    :func:`bsdfkit.cli.main.main` installs its own handlers; a signal the shell ignores stays ignored."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(signum) != signal.SIG_IGN:
            signal.signal(signum, _early_signal)


def is_bsdfkit_command(orig_argv: list[str]) -> bool:
    """Whether the interpreter was started as ``python [options] -m bsdfkit ...`` (``sys.orig_argv``)."""
    k = 1
    while k < len(orig_argv):
        arg = orig_argv[k]
        if arg == "-m":
            return orig_argv[k + 1:k + 2] == ["bsdfkit"]
        if arg == "-c" or not arg.startswith("-"):  # a script or -c: not the module
            return False
        k += 2 if arg in ("-X", "-W") else 1  # the options that take a separate value
    return False


def main() -> NoReturn:
    """Install the early signal handlers, run :func:`bsdfkit.cli.main.main` (which installs its own), and end
    the process with its status without the interpreter's shutdown (:func:`bsdfkit.cli.main.exit_process`)."""
    install_early_handlers()
    from bsdfkit.cli.main import exit_process
    from bsdfkit.cli.main import main as cli_main

    exit_process(cli_main())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
