"""Python's cyclic garbage collector run less often in the processes of the command line.

A run allocates millions of short-lived containers (JAX tracing its programs, xarray building coordinates,
matplotlib laying out ticks), and with CPython's default thresholds (700, 10, 10) the collector walked the
young objects every 700 net allocations and the whole heap every 70 000: in a sampled profile of the spectral
comparison's process, 11 % of its CPU time was the collector (``gc_collect_main`` and its visitors). The
command line raises the thresholds for the duration of a command (:func:`fewer_collections`), and a helper
process it spawns does the same for its life (:func:`use_fewer_collections`). Reference counting still frees
every object without a cycle at once; objects in cycles wait at most a young generation of 50 000 allocations.
docs/performance.md has the paired timings.
"""
from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

#: the collector's thresholds in the command line's processes (generation 0, 1, 2; CPython's are 700, 10, 10)
THRESHOLDS = (50_000, 20, 100)


@contextlib.contextmanager
def fewer_collections() -> Iterator[None]:
    """The collector at :data:`THRESHOLDS` for the duration of the block; the previous thresholds are restored.

    Yields
    ------
    None
    """
    previous = gc.get_threshold()
    gc.set_threshold(*THRESHOLDS)
    try:
        yield
    finally:
        gc.set_threshold(*previous)


def use_fewer_collections() -> None:
    """The collector at :data:`THRESHOLDS` for the rest of this process: the initializer of a spawned helper
    process, which lives only for the command that started it."""
    gc.set_threshold(*THRESHOLDS)
