"""Public functions document their parameters in numpydoc form, physical quantities with a unit in brackets.

A public function is a module-level function or a method of a class, not named with a leading underscore, in a
module without one. The modules of COVERED are checked; those of PENDING are not yet (their docstrings are being
written) and move to COVERED as they are finished. Every module with a public function is in one of the two.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from conftest import ROOT

# scipy's copy of numpydoc's parser (numpydoc itself is not a dependency)
from scipy._lib._docscrape import NumpyDocString

PACKAGE = ROOT / "bsdfkit"

COVERED = [
    "accessor.py",
    "api.py",
    "bench/core.py", "bench/fitting.py", "bench/measurement.py", "bench/run.py", "bench/tracing.py",
    "cli/bench.py", "cli/budget.py", "cli/color.py", "cli/fit.py", "cli/info.py", "cli/ingest.py", "cli/main.py",
    "cli/read.py", "cli/run.py", "cli/simulate.py", "cli/sweep.py", "cli/tis.py", "cli/trace.py",
    "cli/convert.py", "cli/export.py",
    "core/conventions.py", "core/frames.py", "core/jaxconfig.py", "core/quadrature.py", "core/records.py",
    "core/hemisphere.py", "core/spectra.py", "core/collector.py", "core/children.py",
    "fit/lambertian.py", "fit/least_squares.py", "fit/lm.py", "fit/plausibility.py",
    "fit/spectrum/models.py", "fit/spectrum/reconstruction.py",
    "fit/spectrum/reporting.py", "fit/spectrum/solver.py", "fit/spectrum/starts.py",
    "io/atomic.py", "io/jsonout.py", "io/netcdf.py", "io/recipe_head.py",
    "io/spectrum_file.py", "io/text.py", "io/toml_write.py",
    "io/xarray_dask.py",
    "measurement/calibrate.py", "measurement/describe.py", "measurement/instrument.py", "measurement/manifest.py",
    "measurement/raw_scan.py", "measurement/schema.py", "measurement/table.py",
    "models/functions.py", "models/led.py", "models/registry.py",
    "pipeline/helper.py", "pipeline/plate_from_scan.py", "pipeline/recipe.py", "pipeline/report.py",
    "pipeline/spectral_comparison.py",
    "plotting/figures.py", "plotting/layout.py", "plotting/maps.py", "plotting/render.py", "plotting/spectra.py",
    "plotting/ticks.py",
    "raytrace/effects.py", "raytrace/geometry.py", "raytrace/kernel.py", "raytrace/oracles/numpy_reference.py",
    "raytrace/oracles/radiosity.py", "raytrace/oracles/spectral_budget.py", "raytrace/plate.py",
    "raytrace/programs.py", "raytrace/rayfile.py", "raytrace/sampling.py",
    "raytrace/scene.py", "raytrace/sweep.py", "raytrace/tallies.py", "raytrace/tracer.py",
    "raytrace/spectral.py",
    "reduction/any_sample.py", "reduction/basis.py", "reduction/budget.py", "reduction/colorimetry.py",
    "reduction/excitation_emission.py",
    "reduction/spectral.py", "reduction/spectrum_metrics.py", "reduction/tis.py", "reduction/disk.py",
    "reduction/hemispherical.py",
    "simulation/truth.py", "simulation/virtual_goniometer.py",
    "tables/axes_choice.py", "tables/format_spec.py", "tables/formats/asap.py", "tables/formats/bsdfxml.py",
    "tables/formats/bsdfxml_tree.py",
    "tables/formats/lighttools.py", "tables/formats/speos.py", "tables/formats/speosbrdf.py",
    "tables/formats/tensortree.py", "tables/formats/tracepro.py", "tables/formats/xml_document.py",
    "tables/formats/zemax.py", "tables/normal_axes.py", "tables/plausible.py", "tables/registry.py",
    "tables/export.py", "tables/to_dataset.py", "tables/vendor.py", "tables/grids.py",
]

# pending: docstrings not yet complete
PENDING = [
]

# a name's suffix states its unit, which its description must give in brackets
SUFFIX_UNITS = {"_deg": "[deg]", "_rad": "[rad]", "_nm": "[nm]", "_mm": "[mm]", "_W": "[W]", "_sr": "[sr]"}
# names of angles and wavelengths without a unit suffix: any unit in brackets (theta_s is an angle, not seconds;
# any other name ending in _s is a time in seconds)
QUANTITY_NAME = re.compile(r"^(theta|phi|wavelength|incidence)(_|$)|wavelength")
UNIT = re.compile(r"\[[^\[\]]+\]")


def _public_functions(tree: ast.Module):
    """(qualified name, node) of the module-level functions and public methods of public classes."""
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for sub in node.body:
                if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)) and not sub.name.startswith("_"):
                    decorators = [ast.unparse(d) for d in sub.decorator_list]
                    if "property" in decorators or any(d.endswith((".setter", ".deleter")) for d in decorators):
                        continue  # an attribute, documented as one
                    yield f"{node.name}.{sub.name}", sub


def _signature(node: ast.FunctionDef) -> list[str]:
    a = node.args
    names = [x.arg for x in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
    names += [f"*{a.vararg.arg}"] if a.vararg else []
    names += [f"**{a.kwarg.arg}"] if a.kwarg else []
    if names and names[0] in ("self", "cls") and not any(isinstance(d, ast.Name) and d.id == "staticmethod"
                                                         for d in node.decorator_list):
        names = names[1:]
    return names


def _documented(doc: NumpyDocString) -> dict[str, str]:
    """Parameter name → description; ``a, b : float`` documents both names."""
    out = {}
    for entry in doc["Parameters"]:
        for name in entry.name.split(","):
            out[name.strip().replace("\\", "")] = " ".join(entry.desc)
    return out


def _unit_needed(name: str) -> str | None:
    """The unit text a parameter's description must hold: its suffix's unit, any bracket, or None."""
    bare = name.lstrip("*")
    for suffix, unit in SUFFIX_UNITS.items():
        if bare.endswith(suffix) and bare != suffix.lstrip("_"):
            return unit
    if QUANTITY_NAME.search(bare):
        return "["
    return "[s]" if bare.endswith("_s") else None


def problems(path: Path, label: str | None = None) -> list[str]:
    """What the docstrings of ``path``'s public functions lack, one line each (empty when complete)."""
    rel = label or path.relative_to(ROOT).as_posix()
    found = []
    for qualname, node in _public_functions(ast.parse(path.read_text(), filename=str(path))):
        where = f"{rel}:{node.lineno} {qualname}"
        text = ast.get_docstring(node)
        if not text:
            found.append(f"{where}: no docstring")
            continue
        params = _signature(node)
        if not params:
            continue
        doc = NumpyDocString(text)
        if not doc["Parameters"]:
            found.append(f"{where}: no Parameters section")
            continue
        documented = _documented(doc)
        for name in params:
            desc = documented.get(name, documented.get(name.lstrip("*")))
            if desc is None:
                found.append(f"{where}: parameter {name} not documented")
                continue
            unit = _unit_needed(name)
            if unit == "[" and not UNIT.search(desc):
                found.append(f"{where}: {name} has no unit in brackets")
            elif unit not in (None, "[") and unit not in desc:
                found.append(f"{where}: {name} does not state {unit}")
        for name in documented:
            if name not in params and f"*{name}" not in params and f"**{name}" not in params:
                found.append(f"{where}: documents {name}, which is not a parameter")
    return found


def _modules_with_public_functions() -> set[str]:
    out = set()
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if any(part.startswith("_") for part in rel.parts if part != "__init__.py"):
            continue
        if any(True for _ in _public_functions(ast.parse(path.read_text()))):
            out.add(rel.as_posix())
    return out


def test_every_module_is_covered_or_pending():
    assert not set(COVERED) & set(PENDING)
    assert sorted(_modules_with_public_functions()) == sorted({*COVERED, *PENDING})


@pytest.mark.parametrize("module", COVERED)
def test_public_functions_document_parameters_with_units(module):
    assert problems(PACKAGE / module) == []


def test_the_checker_finds_what_is_missing(tmp_path):
    sample = tmp_path / "bsdfkit_sample.py"
    sample.write_text('''
def nothing(a):
    pass


def no_section(theta_i):
    """Summary."""


def half(theta_i, wavelength_nm, count, wait_s, extra=None):
    """Summary.

    Parameters
    ----------
    theta_i : float
        Angle of incidence.
    wavelength_nm : float
        Wavelength [um].
    count : int
        How many.
    wait_s : float
        Time to wait.
    gone : int
        Removed long ago.
    """


class Thing:
    def method(self, theta_s, phi_s_deg, *values, **options):
        """Summary.

        Parameters
        ----------
        theta_s : float
            Scatter polar angle [rad].
        phi_s_deg : float
            Scatter azimuth [deg].
        *values
            Values [-].
        **options
            Options.
        """

    @property
    def size(self):
        return 0


def _private(x):
    pass
''')
    found = [line.split(" ", 1)[1] for line in problems(sample, "sample.py")]
    assert found == [
        "nothing: no docstring",
        "no_section: no Parameters section",
        "half: theta_i has no unit in brackets",
        "half: wavelength_nm does not state [nm]",
        "half: wait_s does not state [s]",
        "half: parameter extra not documented",
        "half: documents gone, which is not a parameter",
    ]
