"""Traced kernel programs kept on disk (``jax.export``), so that a new process does not trace them again.

JAX's persistent compilation cache (switched on by the command line) spares a new process XLA's compilation of
a kernel, but not the tracing of the kernel's Python code into a program, which JAX repeats in every process:
about 0.9 s of the 1.5-2.1 s that the phosphor kernel of the main job took to get ready in a new process.
So wherever the compilation cache is on, the tracer also keeps each traced program, serialised by
``jax.export``, in the folder ``bsdfkit-programs`` inside the compilation cache; a new process deserialises it
(a few milliseconds) and lowers it (about 0.1 s) instead of tracing it. docs/tracer.md has the measurements.

A program's file name is a hash of everything the program is made from: the source of every bsdfkit module the
tracer imports, directly or through others (:func:`traced_modules`; the layers above it, which a program never
runs, are left out, so a change to the pipeline, the report or the command line keeps the programs), the versions
of JAX and jaxlib, the backend, whether float64 is on, and the caller's key (effects, shapes, device count). A
changed kernel therefore never meets an old program. A file that cannot be read back is
traced again and replaced; a cache folder that cannot be written leaves the program in this process only.
With the cache on, the program always runs through its exported form, the first time included, so a result
never depends on whether the file existed (and the exported form computes bit for bit what the traced
program does; tests/raytrace/test_programs.py).
"""
from __future__ import annotations

import ast
import contextlib
import functools
import hashlib
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jaxlib

#: sub-folder of JAX's compilation cache that holds the exported programs
FOLDER = "bsdfkit-programs"
SUFFIX = ".jaxexport"


#: the module whose imports, followed through the package, hold every line a traced program can run
TRACER = "bsdfkit.raytrace.tracer"


def traced_modules(start: str = TRACER) -> list[Path]:
    """The source files of ``start`` and of every bsdfkit module it imports, directly or through others, with the
    packages' ``__init__.py`` files: every bsdfkit line a traced program can run (lower layers never import
    higher ones, and the package imports nothing by a computed name below the command line). Not followed: the
    imports of ``bsdfkit/__init__.py`` (the lazy public API, loaded on first use) and those under ``if
    TYPE_CHECKING:`` (never run).

    Parameters
    ----------
    start : str
        Dotted name of a bsdfkit module.

    Returns
    -------
    list of Path
        The source files, sorted.
    """
    root = Path(__file__).resolve().parents[2]  # the folder holding the package

    def files(name: str) -> list[Path]:
        parts = name.split(".")
        found = [root.joinpath(*parts[:k], "__init__.py") for k in range(1, len(parts) + 1)]
        found.append(root.joinpath(*parts).with_suffix(".py"))
        return [p for p in found if p.is_file()]

    top = root / "bsdfkit" / "__init__.py"
    seen: set[Path] = set()
    todo = [start]
    while todo:
        name = todo.pop()
        for path in files(name):
            if path in seen:
                continue
            seen.add(path)
            if path == top:
                continue
            for node in _run_imports(ast.parse(path.read_bytes(), filename=str(path))):
                if isinstance(node, ast.Import):
                    todo += [a.name for a in node.names if a.name.split(".")[0] == "bsdfkit"]
                elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "bsdfkit":
                    # ``from bsdfkit.x import y``: y is a module of x or a name in it (both files, where they exist)
                    todo += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return sorted(seen)


def _run_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


@functools.cache
def source_digest() -> str:
    """SHA-256 of the sources of :func:`traced_modules` (names and contents), computed once per process."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for path in traced_modules():
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def program_folder() -> Path | None:
    """The folder of exported programs, or None when JAX's persistent compilation cache is off."""
    cache = jax.config.jax_compilation_cache_dir
    return Path(cache) / FOLDER if cache else None


def program_name(key: tuple) -> str:
    """File name of the program identified by ``key`` in this bsdfkit source, JAX version and backend.

    Parameters
    ----------
    key : tuple
        What identifies the program, by its ``repr``.

    Returns
    -------
    str
        A SHA-256 hex digest plus the program suffix.
    """
    parts = (source_digest(), jax.__version__, jaxlib.__version__, jax.default_backend(),
             bool(jax.config.jax_enable_x64), repr(key))
    return hashlib.sha256(repr(parts).encode()).hexdigest() + SUFFIX


def cached_program(program: Callable, abstract_args: Sequence, key: tuple) -> Callable:
    """``program`` (a ``jax.jit`` function) as a jitted call of its exported form, read from the program folder
    when it is there and written there when not; ``program`` itself when the compilation cache is off.

    ``abstract_args`` are the ``jax.ShapeDtypeStruct`` arguments (with shardings) to export for; ``key`` must
    identify everything else the traced program depends on (static arguments, closure values) by its ``repr``.

    Parameters
    ----------
    program : callable
        A ``jax.jit`` function.
    abstract_args : sequence of jax.ShapeDtypeStruct
        The arguments to export for.
    key : tuple
        Identifies the program's static arguments and closure values.

    Returns
    -------
    callable
        The jitted exported program, or ``program`` itself.
    """
    folder = program_folder()
    if folder is None:
        return program
    path = folder / program_name(key)
    try:
        exported = jax.export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # noqa: BLE001 - missing, or a cut or foreign file in our own cache: trace (again)
        exported = None
    if exported is None:
        exported = jax.export.export(program)(*abstract_args)
        _write(path, exported.serialize())
    return jax.jit(exported.call)


def _write(path: Path, blob: bytes | bytearray) -> None:
    """Write ``blob`` to ``path`` atomically (a temporary file renamed into place). A cache folder that cannot
    be written (read-only, full) is passed over: the program is still used in this process."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=path.name[:16] + ".", suffix=".part", dir=path.parent)
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.replace(tmp, path)
        tmp = None
    except OSError:
        pass
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
