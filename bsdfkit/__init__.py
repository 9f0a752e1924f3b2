"""bsdfkit: goniophotometer spectral scans in, validated BSDF models and ray-tracer tables out.

The package follows the data flow (``docs/architecture.md``)::

    core → io → measurement → models → reduction → fit → tables → simulation → raytrace → plotting
         → pipeline / bench → cli

The public API (:mod:`bsdfkit.api`) is importable from here: ``ingest``, ``tis``, ``budget``, ``profile``, ``describe``,
``save``, ``fit_bsdf``, ``fit_spectrum``, ``export``, ``read``, ``load_scene``, ``trace`` and ``run``. Names
are resolved on first use, so ``import bsdfkit`` is cheap and does not import JAX. Importing bsdfkit
registers the ``ds.bsdf`` accessor on xarray datasets (:mod:`bsdfkit.accessor`), except in the ``bsdfkit``
command itself, which does not use it.
"""
from __future__ import annotations

import sys as _sys
from typing import Any

import bsdfkit_console as _console

_MODULE_COMMAND = _console.is_bsdfkit_command(getattr(_sys, "orig_argv", []))
if _MODULE_COMMAND:
    # this process is the `python -m bsdfkit` command, importing its package before its __main__: answer
    # Ctrl-C from here on with one line (the imports below take a second); never for any other program
    _console.install_early_handlers()

from bsdfkit.core.version import __version__  # noqa: E402

API = ("ingest", "tis", "budget", "profile", "describe", "save", "fit_bsdf", "fit_spectrum", "export", "read",
       "load_scene", "trace", "run")
__all__ = ["__version__", *API]


def __getattr__(name: str) -> Any:
    # PEP 562: the API module (and with it numpy, xarray, JAX …) is imported on first use of a public name.
    if name in API:
        import bsdfkit.api

        return getattr(bsdfkit.api, name)
    raise AttributeError(f"module 'bsdfkit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *API])


if not (_MODULE_COMMAND or _sys.argv[0].rsplit("/", 1)[-1] == "bsdfkit"):
    # registers ds.bsdf on xarray datasets; not in the bsdfkit command (`python -m bsdfkit`, the console script),
    # whose verbs call the library directly: importing xarray for it was 0.5-1.5 s of every `bsdfkit --help`
    from bsdfkit import accessor as accessor  # noqa: E402
