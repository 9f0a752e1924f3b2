"""xarray without dask on the command line's light paths: dask is imported when something uses it, not when an
array is wrapped.

xarray asks, for every array it wraps (``xr.DataArray(...)``, ``Variable.astype`` while decoding a netCDF
file), whether it is a dask array: ``isinstance(data, array_type("dask"))`` (``xarray.namedarray.pycompat``),
whose first call imports ``dask.array`` and with it ``scipy.sparse`` and ``scipy.fftpack``, and
``is_dask_collection(data)`` (``xarray.namedarray.utils``), which imports ``dask``: 0.5-0.8 s of every
``bsdfkit read``, ``info`` and ``tis`` (``python -X importtime``), none of which ever holds a dask array. No
object can be a dask array or collection before dask is imported, so "the types of ``dask.array`` if it is
imported, else none" and "``dask.base.is_dask_collection`` if dask is imported, else False" are the same
answers without the import.

:func:`deferred_dask` installs those answers in xarray when xarray is first imported within the block, for the
duration of a command (:func:`bsdfkit.cli.main.main`); a verb that uses dask (``sweep``) imports it and its
arrays are then recognised as before. Nothing happens on ``import bsdfkit``, nor in a process that imported
xarray before the command ran.
"""
from __future__ import annotations

import contextlib
import importlib.abc
import importlib.util
import sys
from collections.abc import Iterator
from typing import Any

#: the xarray module that keeps the record of duck-array modules (``_cached_duck_array_modules``)
PYCOMPAT = "xarray.namedarray.pycompat"
#: the xarray module of ``is_dask_collection`` (re-exported by ``xarray.core.utils`` when that is imported)
UTILS = "xarray.namedarray.utils"


class DeferredDask:
    """Stands for xarray's ``DuckArrayModule("dask")`` without importing dask: ``type`` is ``(dask.array.Array,)``
    once ``dask.array`` is imported and ``()`` before (no dask array can exist then); ``module``, ``version``
    and ``available`` are looked up when asked for."""

    @property
    def type(self) -> tuple[type, ...]:
        mod = sys.modules.get("dask.array")
        array = getattr(mod, "Array", None)
        return (array,) if isinstance(array, type) else ()

    @property
    def module(self) -> Any:
        try:
            import dask
        except ImportError:
            return None
        return dask

    @property
    def version(self) -> Any:
        from packaging.version import Version

        module = self.module
        return Version(module.__version__ if module is not None else "0.0.0")

    @property
    def available(self) -> bool:
        return importlib.util.find_spec("dask") is not None


def deferred_is_dask_collection(original: Any) -> Any:
    """xarray's ``is_dask_collection`` that answers False while dask is not imported (nothing can be a dask
    collection then) and asks dask (``original``) once it is.

    Parameters
    ----------
    original : callable
        xarray's own ``is_dask_collection``.

    Returns
    -------
    callable
        The replacement, with the original's docstring.
    """

    def is_dask_collection(x: object) -> bool:
        return "dask" in sys.modules and original(x)

    is_dask_collection.__doc__ = original.__doc__
    return is_dask_collection


def _patch(module: Any) -> None:
    if module.__name__ == PYCOMPAT:
        cache = getattr(module, "_cached_duck_array_modules", None)
        if isinstance(cache, dict) and "dask" not in cache:
            cache["dask"] = DeferredDask()
    elif callable(getattr(module, "is_dask_collection", None)):
        module.is_dask_collection = deferred_is_dask_collection(module.is_dask_collection)


class _Hook(importlib.abc.MetaPathFinder):
    """Changes xarray's two questions right after ``xarray.namedarray.pycompat`` and ``…utils`` are executed
    (before any other xarray module imports from them)."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name not in (PYCOMPAT, UTILS):
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
                run = spec.loader.exec_module

                def exec_module(module: Any, run: Any = run) -> None:
                    run(module)
                    _patch(module)

                spec.loader.exec_module = exec_module  # this module's loader object only
                return spec
            if spec is not None:
                return spec
        return None


@contextlib.contextmanager
def deferred_dask() -> Iterator[bool]:
    """Within the block, xarray (when first imported there) does not import dask to recognise dask arrays and
    collections.

    Yields whether the record was deferred: False when xarray was imported before the block (its record
    is left alone).
    """
    if "xarray" in sys.modules:
        yield False
        return
    hook = _Hook()
    sys.meta_path.insert(0, hook)
    try:
        yield True
    finally:
        with contextlib.suppress(ValueError):
            sys.meta_path.remove(hook)
