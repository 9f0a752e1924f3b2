"""The main job's one spawned helper process, started before the pipeline is imported.

The helper computes the spectral comparison from the start of the run and then draws the figures
(:mod:`bsdfkit.pipeline.recipe`). Spawned, it imports the pipeline again (about 1.5 s); started by the command line
before this process imports the pipeline itself, the two imports run on the two cores at once instead of one after
the other (the second core idled through this process's imports). This module imports no more than the standard
library and :mod:`bsdfkit.core.collector`.

The helper never outlives the process that started it (issue #44): it is stopped when the block that started it
ends (success, error), terminated with the command's other children on Ctrl-C or SIGTERM
(:func:`bsdfkit.cli.main.exit_now`), and it ends by itself when its parent is gone without a word (SIGKILL, a crash):
:func:`end_with_parent`, run as it starts, asks Linux for a SIGKILL when the parent dies (``PR_SET_PDEATHSIG``) and
watches ``os.getppid()`` in a daemon thread everywhere.
"""
from __future__ import annotations

import contextlib
import importlib
import multiprocessing
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from bsdfkit.core.children import (  # noqa: F401  (the helper's parent watch, named here too)
    PARENT_POLL_S,
    USE_DEATH_SIGNAL,
    child_initializer,
    end_with_parent,
)

#: what the main job's helper imports as soon as it starts (what the pipeline's tasks need)
PIPELINE = ("bsdfkit.pipeline.recipe",)


def _import(names: Sequence[str]) -> None:
    for name in names:
        importlib.import_module(name)


@contextlib.contextmanager
def helper_process(enabled: bool, preload: Sequence[str] = PIPELINE) -> Iterator[ProcessPoolExecutor | None]:
    """One spawned helper process (None when not ``enabled``) that starts importing ``preload`` at once.

    On leaving the block the helper is stopped at once: after an error, whatever it is doing (its unfinished
    work is not wanted any more); otherwise its work is done, and stopping it spares the caller the wait for its
    interpreter's own ending (1.1 s of the main job with JAX loaded). A spawned process imports the caller's
    main script again: a script must guard its entry point (``if __name__ == "__main__":``).

    Parameters
    ----------
    enabled : bool
        Start a helper.
    preload : sequence of str
        Modules the helper imports first.

    Yields
    ------
    ProcessPoolExecutor or None
        The helper, one worker process.
    """
    if not enabled:
        yield None
        return
    initializer, initargs = child_initializer()
    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=initializer,
                               initargs=initargs)
    try:
        with contextlib.suppress(BrokenProcessPool, RuntimeError):  # a dead helper: its work is done here
            pool.submit(_import, tuple(preload))
        yield pool
    finally:
        processes = list(getattr(pool, "_processes", {}).values())
        for process in processes:
            process.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        for process in processes:
            process.join()
