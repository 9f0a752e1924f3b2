"""`bsdfkit run` writes the new table formats on request (exports.formats), each re-read and TIS-checked."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import ROOT
from test_cli_foundation import _small_recipe

from bsdfkit.tables import registry


@pytest.mark.slow
def test_run_writes_every_registered_format_on_request(tmp_path):
    import tomllib

    from bsdfkit.io.toml_write import dumps

    recipe = _small_recipe(tmp_path)
    data = tomllib.loads(recipe.read_text())
    data["exports"]["formats"] = list(registry.writable())
    recipe.write_text(dumps(data))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "bsdfkit", "run", str(recipe), "-o", str(out)], capture_output=True,
                          text=True, cwd=ROOT, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    checks = summary["export_checks"]
    assert {c["format"] for c in checks} == set(registry.writable())
    assert all(c["ok"] for c in checks), [c for c in checks if not c["ok"]]
    assert (out / "exports" / "bibs_reflection.bsdfxml.xml").stat().st_size > 0
