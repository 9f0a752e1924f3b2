"""The package layout is a checked contract: layers, no cycles, module-level imports, a cheap top-level import."""
from __future__ import annotations

import ast
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import grimp
from conftest import ROOT

PACKAGE = ROOT / "bsdfkit"
# The places where an import is deferred on purpose (issue #25): the command line imports only the verb it runs
# and each verb its engine when it runs (so `bsdfkit --help` and a one-line input error import no JAX, colour or
# matplotlib); the top-level package, the ds.bsdf accessor and the API resolve each engine on first use (so that
# `import bsdfkit; bsdfkit.ingest` imports no JAX); core.lazy is the lazy module the model registry names JAX by.
# the format registry imports a format's module when the format is used (the verbs' help names them unimported)
DEFERRED_OK = {*(PACKAGE / "cli").glob("*.py"), PACKAGE / "__init__.py", PACKAGE / "accessor.py",
               PACKAGE / "api.py", PACKAGE / "core" / "lazy.py", PACKAGE / "tables" / "registry.py",
               # the main job's helper process imports the pipeline by name as soon as it starts
               PACKAGE / "pipeline" / "helper.py"}


# import-linter's own command (the `lint-imports` console script) run by the interpreter running the tests, so that
# it needs no script beside that interpreter: any virtual environment (or none) with the test extra installed
LINT_IMPORTS = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"


def test_import_linter_contracts_hold():
    assert importlib.util.find_spec("importlinter") is not None, f"import-linter is not importable by {sys.executable}"
    done = subprocess.run([sys.executable, "-c", LINT_IMPORTS, str(ROOT / "pyproject.toml")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert re.search(r"Contracts: [1-9]\d* kept, 0 broken", done.stdout), done.stdout[-3000:]


def _cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found = []
    counter = 0
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.find_modules_directly_imported_by(child)))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_import_cycle_among_bsdfkit_modules():
    graph = grimp.build_graph("bsdfkit")
    # package __init__ modules that only re-export their children are not edges of the data flow
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    graph = grimp.ImportGraph()
    for name in ("p", "p.a", "p.b", "p.c"):
        graph.add_module(name)
    graph.add_import(importer="p.a", imported="p.b")
    graph.add_import(importer="p.b", imported="p.a")
    graph.add_import(importer="p.b", imported="p.c")
    assert _cycles(graph) == [["p.a", "p.b"]]


def _deferred_internal_imports(path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for inner in ast.walk(node):
                if isinstance(inner, ast.ImportFrom) and (inner.module or "").startswith("bsdfkit"):
                    found.append(f"{path.relative_to(ROOT)}:{inner.lineno}")
                elif isinstance(inner, ast.Import) and any(a.name.startswith("bsdfkit") for a in inner.names):
                    found.append(f"{path.relative_to(ROOT)}:{inner.lineno}")
    return found


def test_dependencies_are_module_level_imports():
    deferred = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path not in DEFERRED_OK:
            deferred += _deferred_internal_imports(path)
        assert "import_module(" not in path.read_text() or path in DEFERRED_OK, path
    assert deferred == []


def test_import_bsdfkit_is_cheap_and_imports_no_jax():
    code = "import sys, bsdfkit; print(sorted(m for m in ('jax', 'matplotlib', 'colour', 'scipy') if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"


def test_no_global_state_changed_by_the_library():
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text()
        assert not re.search(r"matplotlib\.use\(|plt\.switch_backend|jax_enable_x64\", *True|config\.update\(",
                             text), path


def test_nothing_points_outside_the_repository():
    pattern = re.compile(r"metrology\.md|formats\.md|shared/|\.\./")
    offenders = []
    for path in [*PACKAGE.rglob("*.py"), *(ROOT / "docs").glob("*.md"), ROOT / "README.md"]:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}")
    assert offenders == []


def test_no_machine_path_in_code_or_docs():
    """Docs, benchmarks and the package name no folder of one machine (a temporary folder, a home, a checkout)."""
    pattern = re.compile(r"(?<![\w.$~-])/(tmp|work|home|root|Users|private/var)(/|\b)")
    offenders = []
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "docs").glob("*.md"), *(ROOT / "benchmarks").glob("*.py"),
             ROOT / "README.md"]
    for path in files:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}")
    assert offenders == []
    assert pattern.search("cd /tmp") and pattern.search("`/work/main/.venv/bin/python`")
    assert not pattern.search("git worktree add \"$TMPDIR/base\"") and not pattern.search("W/mm^2 /tmpfs")


def test_every_module_imports():
    """The fast lane (-m "not slow") touches every module at least through its import."""
    import importlib
    import pkgutil

    import bsdfkit

    names = [m.name for m in pkgutil.walk_packages(bsdfkit.__path__, "bsdfkit.") if not m.name.endswith("__main__")]
    assert len(names) > 60
    for name in names:
        importlib.import_module(name)


#: tests of the package as a whole, at the top of tests/ (no single module is their subject)
PACKAGE_WIDE_TESTS = {
    "test_architecture.py": "layers, import contracts, global state, no pointer outside the repository",
    "test_docstrings.py": "numpydoc Parameters with units on every public function",
    "test_function_size.py": "function length and parameter count",
    "test_imports.py": "what each command and public name imports",
    "test_lock.py": "the locked installs",
    "test_names.py": "one name and unit per quantity (_deg, _nm)",
    "test_readme.py": "the README's two commands",
}


def _module_names(folder: Path) -> set[str]:
    return ({p.stem for p in folder.glob("*.py") if p.stem != "__init__"}
            | {p.name for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").is_file()})


def test_test_files_mirror_the_package():
    """tests/<subpackage>/test_<module>.py or test_<module>_<topic>.py, with <module> a module (or subpackage) of
    bsdfkit/<subpackage>/; at the top of tests/, bsdfkit's own top-level modules and the package-wide tests."""
    tests = ROOT / "tests"
    astray = []
    for path in sorted(tests.rglob("test_*.py")):
        rel = path.relative_to(tests)
        folder = PACKAGE.joinpath(*rel.parts[:-1])
        if len(rel.parts) == 1 and rel.name in PACKAGE_WIDE_TESTS:
            continue
        stem = path.stem.removeprefix("test_")
        names = _module_names(folder) if folder.is_dir() else set()
        if not any(stem == n or stem.startswith(n + "_") for n in names):
            astray.append(rel.as_posix())
    assert astray == []
    assert all((tests / name).is_file() for name in PACKAGE_WIDE_TESTS)
