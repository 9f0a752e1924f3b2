"""Traced kernel programs kept on disk (bsdfkit.raytrace.programs): the exported program computes bit for bit
what the traced one does, is read back instead of traced, and a damaged or unwritable cache costs nothing."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import jax
import pytest
from conftest import TRACE_SIZES, fast_lane
from test_kernel import scene
from test_tracer_batch import full, plate_scene

from bsdfkit.raytrace import programs, trace
from bsdfkit.raytrace.tracer import compiled_kernel

RAYS = 3000  # in the kernels of test_kernel.py (TRACE_SIZES)
#: The scenes whose programs are kept: the fast lane's the minimal kernel (a diffuse cavity, exit top; the program
#: file's handling does not depend on what the kernel holds), the full suite's also the phosphor plate's (an
#: interaction budget, the conversion and its while loops: 5-10 times the tracing and compilation)
SCENES = fast_lane(["cavity", "plate"], {"cavity"})


def make_scene(kind, tmp_path):
    return scene() if kind == "cavity" else plate_scene(tmp_path)


@pytest.fixture
def program_cache(monkeypatch, tmp_path):
    """The program folder in tmp_path, with the per-process kernel cache emptied before and after."""
    folder = tmp_path / "programs"
    monkeypatch.setattr(programs, "program_folder", lambda: folder)
    compiled_kernel.cache_clear()
    yield folder
    compiled_kernel.cache_clear()


def test_without_a_compilation_cache_no_program_is_kept():
    before = jax.config.jax_compilation_cache_dir  # the suite shares the command line's cache (conftest.py)
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        assert programs.program_folder() is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


@pytest.mark.parametrize("kind", SCENES)
def test_exported_program_is_bit_identical_and_read_back(program_cache, tmp_path, monkeypatch, kind):
    sc = make_scene(kind, tmp_path)
    compiled_kernel.cache_clear()
    with monkeypatch.context() as m:
        m.setattr(programs, "program_folder", lambda: None)
        traced = full(trace(sc, RAYS, seed=3, **TRACE_SIZES))
    compiled_kernel.cache_clear()
    first = full(trace(sc, RAYS, seed=3, **TRACE_SIZES))  # traces, exports, writes
    files = list(program_cache.glob("*" + programs.SUFFIX))
    assert len(files) == 1 and not list(program_cache.glob("*.part"))
    compiled_kernel.cache_clear()

    def no_tracing(*args, **kwargs):
        raise AssertionError("the program was traced again instead of read back")

    monkeypatch.setattr(jax.export, "export", no_tracing)
    again = full(trace(sc, RAYS, seed=3, **TRACE_SIZES))
    assert traced == first == again


@pytest.mark.parametrize("kind", SCENES)
def test_damaged_program_file_is_traced_again_and_replaced(program_cache, tmp_path, kind):
    sc = make_scene(kind, tmp_path)
    reference = full(trace(sc, RAYS, seed=5, **TRACE_SIZES))
    (path,) = program_cache.glob("*" + programs.SUFFIX)
    path.write_bytes(path.read_bytes()[:100])  # a cut file
    compiled_kernel.cache_clear()
    assert full(trace(sc, RAYS, seed=5, **TRACE_SIZES)) == reference
    jax.export.deserialize(bytearray(path.read_bytes()))  # replaced by a whole program


def test_unwritable_program_folder_still_traces(monkeypatch, tmp_path):
    """The minimal kernel's scene, as the fast lane's other program tests (the folder's handling does not depend on
    what the kernel holds; the phosphor plate's kernel took 5-10 times as long to trace and compile)."""
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(programs, "program_folder", lambda: blocker / "programs")
    compiled_kernel.cache_clear()
    try:
        result = trace(scene(), RAYS, seed=1, **TRACE_SIZES)
    finally:
        compiled_kernel.cache_clear()
    assert result.ledger_error < 1e-12 and not (blocker / "programs").exists()


def test_program_names_separate_what_the_program_is_made_from():
    a = programs.program_name(("trace_chunk", "effects A", 256))
    assert a == programs.program_name(("trace_chunk", "effects A", 256))
    assert a != programs.program_name(("trace_chunk", "effects B", 256))
    assert a != programs.program_name(("trace_chunk", "effects A", 512))
    assert a.endswith(programs.SUFFIX)


def test_the_program_digest_covers_every_module_a_trace_loads_and_not_the_layers_above():
    # what the tracer's import loads beyond the package's lazy API, and what tracing loads on first use (the
    # test's own scene helpers not counted)
    code = """
import sys
import bsdfkit
base = set(sys.modules)
from bsdfkit.raytrace import trace
loaded = set(sys.modules) - base
from test_kernel import scene
sc = scene()
before = set(sys.modules)
trace(sc, 200, 0, lanes=64)  # one narrow loop level: the cheapest kernel to compile
loaded |= set(sys.modules) - before
print("\\n".join(sys.modules[n].__file__ for n in loaded if (n == "bsdfkit" or n.startswith("bsdfkit."))
                and getattr(sys.modules[n], "__file__", None)))
"""
    tests = Path(__file__).resolve().parent
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True,
                          cwd=tests, env={**os.environ, "PYTHONPATH": os.pathsep.join([str(tests), str(tests.parent)])})
    loaded = {Path(line).resolve() for line in done.stdout.split()}
    covered = {p.resolve() for p in programs.traced_modules()}
    assert "raytrace/kernel.py" in {p.as_posix()[-len("raytrace/kernel.py"):] for p in loaded}
    assert loaded <= covered, sorted(map(str, loaded - covered))
    root = Path(programs.__file__).resolve().parents[1]
    names = {p.relative_to(root).as_posix() for p in covered}
    assert {"raytrace/kernel.py", "raytrace/sampling.py", "raytrace/tracer.py", "core/jaxconfig.py"} <= names
    assert not any(n.startswith(("pipeline/", "cli/", "plotting/", "tables/")) for n in names)
