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
from conftest import cli

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


# the fast lane keeps `read` (the stricter -m checks below cover --help and tis in it); the rest run in the full suite
@pytest.mark.parametrize("args", [a if a == ("read", "/nonexistent") else pytest.param(a, marks=pytest.mark.slow)
                                  for a in [("--help",), ("tis", "/nonexistent"), ("read", "/nonexistent"),
                                            ("convert", "/nonexistent", "--to", "zemax", "-o", "/nonexistent/out.bsdf"),
                                            ("fit", "--help"), ("trace", "--help")]],
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


@pytest.mark.parametrize("args", [("--help",), ("tis", "--bogus"), ("convert", "x.bsdf", "--to", "nope", "-o", "y")],
                         ids=lambda a: " ".join(a))
def test_help_and_usage_errors_import_not_even_numpy(args):
    """The verbs' help names the table formats and models from lists written out in bsdfkit.tables.registry and
    bsdfkit.cli.fit (checked below), not by importing them: numpy and the format modules stay unloaded. Run as
    the command runs (``python -m bsdfkit``), the imports listed by ``-X importtime``."""
    loaded = _imported("-m", "bsdfkit", *args)[1]
    assert "bsdfkit" in loaded
    assert not loaded & {"numpy", "xarray", "scipy", *HEAVY}


def _imported(*args: str, cwd: Path = ROOT) -> tuple[subprocess.CompletedProcess, set[str]]:
    """A fresh interpreter run with ``-X importtime`` and the top-level packages it imported."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run([sys.executable, "-X", "importtime", *args], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=300)
    loaded = {line.split("|")[-1].strip().split(".")[0] for line in done.stderr.splitlines()
              if line.startswith("import time:")}
    return done, loaded


def test_the_written_out_names_are_the_registries():
    from bsdfkit.cli import fit
    from bsdfkit.models.registry import BSDF_MODELS, SPECTRUM_MODELS
    from bsdfkit.tables import registry

    assert registry.names() == tuple(f.name for f in registry.FORMATS)
    assert registry.writable() == tuple(f.name for f in registry.FORMATS if f.can_write)
    assert fit.BSDF_MODELS == tuple(BSDF_MODELS) and fit.SPECTRUM_MODELS == tuple(SPECTRUM_MODELS)


KLEMS = ROOT / "tests" / "data" / "radiance-bsdf2klems" / "lambertian_r030_t060_klems_full.xml"


def test_light_verbs_on_real_files_do_not_import_dask_or_jax(tmp_path):
    """xarray wraps arrays and decodes netCDF variables without importing dask (bsdfkit.io.xarray_dask): a
    vendor file read and a netCDF dataset reduced by the command load neither dask nor JAX, and the numbers
    are those of the same call with dask imported (the library's own answer)."""
    nc = tmp_path / "k.nc"
    # (writing a netCDF file asks dask for its scheduler: ingest is not among the verbs checked, so it runs here)
    made = cli("ingest", KLEMS, "-o", nc)
    assert made.returncode == 0, made.stderr[-2000:]
    for args in (("read", str(KLEMS), "--json"), ("tis", str(nc), "--json")):
        done, loaded = _imported("-m", "bsdfkit", *args, cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-2000:]
        assert "xarray" in loaded and not loaded & {"dask", *HEAVY}, args
    # the same reduction in this process with dask imported gives the same numbers
    import dask.array  # noqa: F401

    import bsdfkit
    from bsdfkit.io.jsonout import dumps
    from bsdfkit.reduction.any_sample import hemispherical_json

    got = json.loads(done.stdout)
    want = json.loads(dumps(hemispherical_json(bsdfkit.tis(bsdfkit.ingest(nc)))))
    assert [r["value"] for r in got["band_averaged"]] == [r["value"] for r in want["band_averaged"]]


RADIANT = ROOT / "tests" / "data" / "ansys-radiant-zemax-bsdf" / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"


def test_read_triangulates_without_the_scipy_spatial_package(tmp_path):
    """`bsdfkit read` of a vendor file triangulates with scipy's Qhull extension and its LAPACK routines alone
    (:func:`bsdfkit.reduction.disk.qhull`): the scipy.spatial package, whose import also loads scipy.special,
    distance and transform, and the scipy.linalg package stay unloaded; the TIS are those of the same reading in
    a process that imported scipy.spatial first (its Delaunay, by the package's own import)."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "bsdfkit", "read", str(RADIANT), "--json"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")})
    assert done.returncode == 0, done.stderr[-2000:]
    names = {line.split("|")[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")}
    # the extension and the LAPACK routines it calls (scipy.linalg.cython_lapack), both loaded from their files,
    # are not listed by -X importtime; neither package is imported (scipy.linalg alone was 0.07 s)
    assert "bsdfkit.reduction.disk" in names
    assert not names & {"scipy.spatial", "scipy.special", "scipy.spatial.distance", "scipy.linalg"}
    # the reference in this process, once scipy.spatial is imported (json round trips the floats exactly)
    import scipy.spatial  # noqa: F401

    from bsdfkit.tables.export import read_any

    assert json.loads(done.stdout)["tis_computed"] == json.loads(json.dumps(read_any(RADIANT).tis_computed))
