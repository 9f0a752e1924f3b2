"""JAX helpers shared by the modules that use JAX.

bsdfkit never flips JAX's global ``jax_enable_x64`` flag on import (that would change every other JAX user
in the process). Processing and fitting need float64, so public entry points that run JAX code wrap their
work in :func:`x64`, a scoped switch; the tracer chooses float32 or float64 per scene the same way.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator

import jax


@contextlib.contextmanager
def x64(enabled: bool = True) -> Iterator[None]:
    """Scoped float64 mode for JAX (``jax.enable_x64``), restored on exit."""
    with jax.enable_x64(enabled):
        yield
