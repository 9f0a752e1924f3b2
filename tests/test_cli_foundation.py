"""The foundation verbs through the command line: ingest, info --json, run."""
import json
import subprocess
import sys

from conftest import BUNDLED, ROOT


def _bsdfkit(*args, **kw):
    return subprocess.run([sys.executable, "-m", "bsdfkit", *map(str, args)], capture_output=True, text=True,
                          timeout=300, **kw)


def test_ingest_then_info_json(tmp_path):
    out = tmp_path / "scan.nc"
    proc = _bsdfkit("ingest", BUNDLED, "-o", out)
    assert proc.returncode == 0, proc.stderr
    info = json.loads(_bsdfkit("info", out, "--json").stdout)
    assert info["incidences_deg"] == [5.0, 45.0, 56.0]
    assert info["sides"] == ["reflection", "transmission"]
    assert info["positions"]["45"]["reflection"]["in_plane"] > 30
    assert info["positions"]["45"]["transmission"]["perpendicular"] > 20
    assert info["wavelength_nm"] == {"min": 380.0, "max": 780.0, "step": 0.5, "count": 801}
    names = [c["name"] for c in info["configurations"]]
    assert names == ["blue", "yellow"]
    assert "450-470" in info["configurations"][0]["description"]
    # ingest refuses to overwrite without --force, and keeps the file
    before = out.stat().st_mtime_ns
    proc = _bsdfkit("ingest", BUNDLED, "-o", out)
    assert proc.returncode != 0 and "--force" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert out.stat().st_mtime_ns == before


def test_info_on_raw_folder():
    proc = _bsdfkit("info", BUNDLED)
    assert proc.returncode == 0 and "SYNTHETIC" in proc.stdout


def test_run_writes_outputs_and_refuses_to_clobber(tmp_path):
    out = tmp_path / "out"
    proc = _bsdfkit("run", ROOT / "fitting" / "cl830.toml", "-o", out)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert {"scan.nc", "inplane_bsdf.png", "summary.json"} <= set(summary["outputs"])
    assert (out / "inplane_bsdf.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    proc = _bsdfkit("run", ROOT / "fitting" / "cl830.toml", "-o", out)
    assert proc.returncode != 0 and "--force" in proc.stderr
