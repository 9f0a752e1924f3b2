"""JAX helpers shared by the modules that use JAX.

bsdfkit never flips JAX's global ``jax_enable_x64`` flag on import (that would change every other JAX user
in the process). Processing and fitting need float64, so public entry points that run JAX code wrap their
work in :func:`x64`, a scoped switch; the tracer chooses float32 or float64 per scene the same way.
"""
from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator

#: the ``XLA_FLAGS`` entry that sets how many CPU devices JAX's host platform has (one when it is absent)
DEVICES_FLAG = "--xla_force_host_platform_device_count"


@contextlib.contextmanager
def x64(enabled: bool = True) -> Iterator[None]:
    """Scoped float64 mode for JAX (``jax.enable_x64``), restored on exit.

    Parameters
    ----------
    enabled : bool, optional
        True for float64 inside the block, False for float32.
    """
    import jax  # here, not on import: light modules name these helpers without starting JAX

    with jax.enable_x64(enabled):
        yield


@functools.cache
def jitted(fn: Callable) -> Callable:
    """``jax.jit(fn)``, one per function for the whole process.

    A model function called op by op compiles each of its primitives for every new argument shape, in every
    new process (about 25 ms per call of a TIS function, 2.2 s for two spectrum evaluations of the main job);
    jitted, it is one compiled program per argument shape, also found in the persistent compilation cache.

    Parameters
    ----------
    fn : callable
        A JAX-traceable function (hashable: the cache key).

    Returns
    -------
    callable
        The compiled function, the same object for every call with ``fn``.
    """
    import jax

    return jax.jit(fn)
