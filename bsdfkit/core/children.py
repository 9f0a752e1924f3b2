"""Child processes that end with the process that started them (issue #44: a helper was found alive, parent PID
1, two hours after its run had ended).

:func:`end_with_parent`, run in a child as it starts, asks Linux for a SIGKILL when the parent dies
(``PR_SET_PDEATHSIG``) and watches ``os.getppid()`` in a daemon thread everywhere; :func:`child_initializer` gives a
process pool the initializer that does it (and runs Python's collector less often, :mod:`bsdfkit.core.collector`).
Used by the main job's helper (:mod:`bsdfkit.pipeline.helper`) and the figure renderer's own pool
(:mod:`bsdfkit.plotting.render`). Standard library only, besides the collector setting.
"""
from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

from bsdfkit.core.collector import use_fewer_collections

__all__ = ["PARENT_POLL_S", "USE_DEATH_SIGNAL", "child_initializer", "end_with_parent"]

#: how often [s] a child process checks that the process that started it is still alive
PARENT_POLL_S = 0.5
#: ask Linux to SIGKILL a helper when its parent dies (``PR_SET_PDEATHSIG``); the poll runs in any case
USE_DEATH_SIGNAL = sys.platform.startswith("linux")
#: ``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``
_PR_SET_PDEATHSIG = 1


def _death_signal() -> bool:
    """Ask the kernel to SIGKILL this process when its parent thread ends; False where that cannot be done."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent_pid: int, poll_s: float) -> None:
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    os._exit(128 + signal.SIGHUP)  # the parent is gone: nothing of this process is wanted any more


def end_with_parent(parent_pid: int, death_signal: bool = USE_DEATH_SIGNAL, poll_s: float = PARENT_POLL_S) -> None:
    """End this (child) process as soon as the process ``parent_pid`` that started it is gone.

    A daemon thread compares ``os.getppid()`` with ``parent_pid`` every ``poll_s`` seconds and ends the process
    (status 129) when they differ: a child whose parent died is adopted by another process. On Linux
    ``death_signal`` also asks the kernel for a SIGKILL at the parent's death, which needs no interpreter lock (a
    child busy in a long compiled call ends at once). The kernel sends it when the parent's *thread* that started
    the child ends, so it is only asked for a child started by its parent's main thread.

    Parameters
    ----------
    parent_pid : int
        Process id of the parent, taken in the parent (``os.getpid()``) before the child started.
    death_signal : bool, optional
        Also ask Linux for a SIGKILL at the parent's death.
    poll_s : float, optional
        Interval of the check [s].
    """
    if death_signal:
        _death_signal()
    if os.getppid() != parent_pid:  # the parent died before this process got here
        os._exit(128 + signal.SIGHUP)
    threading.Thread(target=_watch_parent, args=(parent_pid, poll_s), name="bsdfkit-parent-watch",
                     daemon=True).start()


def _start_helper(parent_pid: int, death_signal: bool) -> None:
    """The initializer of the helper process: Python's collector less often, and the end of the parent watched."""
    use_fewer_collections()
    end_with_parent(parent_pid, death_signal)


def child_initializer() -> tuple:
    """``(initializer, initargs)`` for a process pool whose processes must end with this process.

    Called in the thread that will start the processes (their first ``submit``).

    Returns
    -------
    tuple
        The initializer (:func:`end_with_parent` and Python's collector less often) and its arguments.
    """
    main_thread = threading.current_thread() is threading.main_thread()
    return _start_helper, (os.getpid(), USE_DEATH_SIGNAL and main_thread)
