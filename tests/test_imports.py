"""Light commands and the light API import none of the heavy libraries (issue #25, point 1).

Each case runs in a fresh interpreter (what a user's shell does) and lists the heavy top-level packages left in
``sys.modules``: JAX, colour-science, matplotlib and dask.distributed load only in the verbs that use them.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("jax", "colour", "matplotlib", "distributed")

# the command line as `bsdfkit ARGS` runs it (main returns; the heavy modules loaded by then are listed)
_CLI = """
import json, sys
from bsdfkit.cli.main import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})), file=sys.stderr)
"""
_API = """
import json, sys
import bsdfkit
bsdfkit.ingest, bsdfkit.tis, bsdfkit.read, bsdfkit.export, bsdfkit.describe
print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})), file=sys.stderr)
"""


def _loaded(code: str, *args: str) -> set[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=120)
    return set(json.loads(done.stderr.strip().splitlines()[-1]))


@pytest.mark.parametrize("args", [("--help",), ("tis", "/nonexistent"), ("read", "/nonexistent"),
                                  ("convert", "/nonexistent", "--to", "zemax", "-o", "/nonexistent/out.bsdf"),
                                  ("fit", "--help"), ("trace", "--help")],
                         ids=lambda a: " ".join(a))
def test_light_commands_import_no_heavy_library(args):
    assert not _loaded(_CLI, *args) & set(HEAVY)


def test_light_api_names_import_no_heavy_library():
    assert not _loaded(_API) & set(HEAVY)


@pytest.mark.parametrize("args", [("tis", "/nonexistent"),
                                  ("budget", "/nonexistent", "--incidence", "5", "--eta-mc", "0.9"),
                                  ("ingest", "/nonexistent", "-o", "/nonexistent.nc"), ("info", "/nonexistent")],
                         ids=lambda a: a[0])
def test_a_mistyped_input_path_is_answered_before_any_numerical_library(args):
    """The path is checked before the verb imports its engine (xarray, scipy): the one-line error comes
    in a fraction of a second (0.1 s user instead of 1.1-1.5 s). Run as the command runs (``python -m bsdfkit``,
    which does not register the ``ds.bsdf`` accessor), the imports listed by ``-X importtime``."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "bsdfkit", *args], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=120)
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert lines[-1].startswith(f"bsdfkit {args[0]}: error: /nonexistent: no such file or folder")
    loaded = {line.split("|")[-1].strip().split(".")[0] for line in lines if line.startswith("import time:")}
    assert "bsdfkit" in loaded
    # numpy may load (the format registry, read by the verbs' help texts, imports it); the engines may not
    assert not loaded & {"xarray", "scipy", "pandas", *HEAVY}
