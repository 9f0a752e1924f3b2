"""One name, one unit: a public function's parameter in degrees ends in ``_deg``, one in nanometres in ``_nm``, and a
name with either suffix is documented in that unit: a bare angle name (``theta_i``, ``phi_s`` …) is never degrees.

The unit of a parameter is the one unit in brackets of its numpydoc description (test_docstrings.py requires it).
A description with several bracketed units describes several quantities (a pair of axes, records, a spectrum as
(wavelength [nm], values [-])), each labelled in the text, and a parameter of a labelled type (an xarray object,
a colour-science distribution, a dataclass whose fields carry their units) names its quantities itself: neither is
one quantity with one unit, so neither is checked. Dataset coordinates (``theta_i`` [deg] on ``record``) keep their
labelled names; only function parameters are named here.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest
from scipy._lib._docscrape import NumpyDocString
from test_docstrings import COVERED, PACKAGE, UNIT, _documented, _public_functions, _signature

SUFFIX = {"[deg]": "_deg", "[nm]": "_nm"}
# annotations of a plain number, array or sequence of numbers: the unit is the parameter's alone
PLAIN_TYPES = {"float", "int", "None", "ArrayLike", "NDArray", "np", "ndarray", "float64", "tuple", "list", "Sequence",
               "Band"}


def _annotations(node: ast.FunctionDef) -> dict[str, ast.expr | None]:
    a = node.args
    return {x.arg: x.annotation for x in (*a.posonlyargs, *a.args, *a.kwonlyargs)}


def _plain(annotation: ast.expr | None) -> bool:
    """True for no annotation or one of plain numbers, arrays and sequences only."""
    if annotation is None:
        return True
    if isinstance(annotation, ast.Constant) and isinstance(annotation.value, str):  # a string annotation
        annotation = ast.parse(annotation.value, mode="eval").body
    names = {n.id for n in ast.walk(annotation) if isinstance(n, ast.Name)}
    names |= {n.attr for n in ast.walk(annotation) if isinstance(n, ast.Attribute)}
    return names <= PLAIN_TYPES


def problems(path: Path, label: str) -> list[str]:
    """Parameters of ``path``'s public functions whose name and documented unit disagree, one line each."""
    found = []
    for qualname, node in _public_functions(ast.parse(path.read_text(), filename=str(path))):
        documented = _documented(NumpyDocString(ast.get_docstring(node) or ""))
        annotations = _annotations(node)
        for name in _signature(node):
            bare = name.lstrip("*")
            units = UNIT.findall(documented.get(bare, ""))
            where = f"{label}:{node.lineno} {qualname}({bare})"
            for unit, suffix in SUFFIX.items():
                if bare.endswith(suffix) and unit not in units:
                    found.append(f"{where}: named {suffix} but documented in {', '.join(units) or 'no unit'}")
            if bare.endswith("_deg") and "[deg]" in units and "[rad]" in units:
                found.append(f"{where}: named _deg but documented in [rad] too")
            if len(units) != 1 or units[0] not in SUFFIX or not _plain(annotations.get(bare)):
                continue
            if bare.endswith(SUFFIX[units[0]]):
                continue
            found.append(f"{where}: documented in {units[0]}, so named …{SUFFIX[units[0]]}")
    return found


@pytest.mark.parametrize("module", COVERED)
def test_parameter_names_state_their_unit(module):
    assert problems(PACKAGE / module, module) == []


def test_the_checker_finds_a_unit_its_name_does_not_state(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text('''
def angles(theta_i, phi_i_deg, wavelength, band_nm, tilt_deg, lean_deg, theta, axes, spectrum, grid: Grid,
           kept_nm=None):
    """Summary.

    Parameters
    ----------
    theta_i : float
        Angle of incidence [deg].
    phi_i_deg : float
        Source azimuth [deg].
    wavelength : float
        Wavelength [nm].
    band_nm : tuple of float
        (low, high) [um].
    tilt_deg : float
        Tilt [rad].
    lean_deg : float
        Lean [deg], that is π/180 [rad].
    theta : ndarray
        Parameter vector θ of a fit [nm], [-].
    axes : tuple
        (θs [deg], φs [deg]).
    spectrum : tuple
        (wavelength [nm], values [-]).
    grid : Grid
        Axes of the table [deg].
    kept_nm : float, optional
        Kept wavelength [nm].
    """
''')
    assert [line.split(" ", 1)[1] for line in problems(sample, "sample.py")] == [
        "angles(theta_i): documented in [deg], so named …_deg",
        "angles(wavelength): documented in [nm], so named …_nm",
        "angles(band_nm): named _nm but documented in [um]",
        "angles(tilt_deg): named _deg but documented in [rad]",
        "angles(lean_deg): named _deg but documented in [rad] too",
    ]
