"""Installs are locked: every dependency that pyproject.toml names is pinned in requirements.lock.

The lock is made by ``uv pip compile pyproject.toml --extra test --extra bench --python-version 3.11
-o requirements.lock --no-header`` (README, "Refreshing the lock"); both README commands install with
``-c requirements.lock``.
"""
from __future__ import annotations

import re
import tomllib

from conftest import ROOT
from packaging.requirements import Requirement
from packaging.version import Version

LOCK = ROOT / "requirements.lock"


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def pinned_versions(lock_text: str) -> dict[str, Version]:
    """``name==version`` lines of a pip-compile style lock (comments and markers ignored)."""
    pins = {}
    for line in lock_text.splitlines():
        line = line.split("#", 1)[0].split(";", 1)[0].strip()
        if "==" in line:
            name, version = line.split("==", 1)
            pins[_normalise(name.split("[", 1)[0])] = Version(version.strip())
    return pins


def unlocked_dependencies(pyproject_text: str, lock_text: str) -> list[str]:
    """Dependencies of the project and its extras that the lock does not pin at a version they accept."""
    project = tomllib.loads(pyproject_text)["project"]
    requirements = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        requirements += extra
    pins = pinned_versions(lock_text)
    problems = []
    for text in requirements:
        req = Requirement(text)
        version = pins.get(_normalise(req.name))
        if version is None:
            problems.append(f"{req.name}: not pinned in requirements.lock")
        elif not req.specifier.contains(version, prereleases=True):
            problems.append(f"{req.name}: lock pins {version}, pyproject asks {req.specifier}")
    return problems


def test_every_dependency_is_pinned_by_the_lock():
    assert unlocked_dependencies((ROOT / "pyproject.toml").read_text(), LOCK.read_text()) == []


def test_the_lock_check_fails_for_a_dependency_added_without_the_lock():
    pyproject = (ROOT / "pyproject.toml").read_text()
    added = pyproject.replace('dependencies = [\n', 'dependencies = [\n    "a-package-nobody-locked>=1",\n', 1)
    assert added != pyproject
    assert unlocked_dependencies(added, LOCK.read_text()) == [
        "a-package-nobody-locked: not pinned in requirements.lock"]
    # a pin outside the range that pyproject asks for is caught too
    assert unlocked_dependencies(pyproject.replace('"numpy>=1.26"', '"numpy>=99"'), LOCK.read_text())


def test_every_pin_is_exact():
    lines = [ln.split("#", 1)[0].strip() for ln in LOCK.read_text().splitlines()]
    requirement_lines = [ln for ln in lines if ln]
    assert requirement_lines and all("==" in ln for ln in requirement_lines)


def test_readme_commands_and_ci_install_through_the_lock():
    readme = (ROOT / "README.md").read_text()
    setup = readme.split("## Set-up", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```bash\n(.*?)\n```", setup, flags=re.S)
    assert len(blocks) == 2 and all("-c requirements.lock" in b for b in blocks)
