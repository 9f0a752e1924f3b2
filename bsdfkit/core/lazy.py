"""A module imported on first attribute access, for the layers that must stay light on import.

``bsdfkit --help``, a one-line input error and ``import bsdfkit; bsdfkit.ingest`` must not import JAX
(about 1-2 s, ``docs/performance.md``). The model registry is read by light verbs (its names and parameter
bounds for ``--model`` choices and the export's plausibility gate) yet its functions are JAX code, so it
names JAX through a :class:`LazyModule` that imports it when a model is first evaluated.
"""
from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any


class LazyModule:
    """Stands for the module ``name``; the first attribute access imports it (later ones go straight to it).

    Parameters
    ----------
    name
        Dotted module name, e.g. ``"jax.numpy"``.
    """

    def __init__(self, name: str) -> None:
        self._name = name
        self._module: ModuleType | None = None

    def _load(self) -> ModuleType:
        if self._module is None:
            self._module = importlib.import_module(self._name)
        return self._module

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("_"):  # own slots not yet set (copy, pickle): never import for them
            raise AttributeError(attr)
        return getattr(self._load(), attr)

    def __repr__(self) -> str:
        state = "imported" if self._module is not None else "not imported yet"
        return f"<lazy module {self._name!r} ({state})>"
