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
