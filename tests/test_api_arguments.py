"""Issue #44.6: the public functions of :mod:`bsdfkit.api` check their arguments before computing.

A list or a path where a dataset is expected raised ``AttributeError: 'list' object has no attribute 'attrs'`` from
inside a reduction. Now a value of the wrong type is a ``TypeError`` (:class:`bsdfkit.core.errors.ArgumentTypeError`,
also an ``InputError`` so that the command line prints it as one line), and the right type with the wrong content
(a dataset without ``bsdf``, an angle in degrees outside [0, 90]) a ``ValidationError``; both name the function, the
argument, what was expected and what was given (:func:`bsdfkit.api.check_argument`).
"""
from __future__ import annotations

from pathlib import Path

import pytest
import xarray as xr

import bsdfkit
from bsdfkit.api import check_argument
from bsdfkit.core.errors import ArgumentTypeError, InputError, ValidationError

NO_BSDF = xr.Dataset({"a": ("x", [1.0, 2.0])})


@pytest.mark.parametrize(("call", "name", "given"), [
    (lambda: bsdfkit.tis(["a"]), "tis(): argument 'ds'", "list ['a']"),
    (lambda: bsdfkit.budget("scan.nc", 45), "budget(): argument 'ds'", "str 'scan.nc'"),
    (lambda: bsdfkit.fit_bsdf([1, 2], "bibs", "reflection"), "fit_bsdf(): argument 'ds'", "list [1, 2]"),
    (lambda: bsdfkit.profile({"bsdf": 1}, "bibs"), "profile(): argument 'ds'", "dict {'bsdf': 1}"),
    (lambda: bsdfkit.describe(Path("scan.nc")), "describe(): argument 'ds'", "PosixPath"),
    (lambda: bsdfkit.save([1], "out.nc"), "save(): argument 'ds'", "list [1]"),
    (lambda: bsdfkit.export([1], "zemax", "bibs", "reflection", "out.bsdf"), "export(): argument 'source'", "list [1]"),
    (lambda: bsdfkit.export(3, "zemax", "bibs", "reflection", "out.bsdf"), "export(): argument 'source'", "int 3"),
    (lambda: bsdfkit.ingest(["measurements/cl830-synthetic"]), "ingest(): argument 'path'", "list"),
    (lambda: bsdfkit.read(7), "read(): argument 'path'", "int 7"),
    (lambda: bsdfkit.load_scene(None), "load_scene(): argument 'path'", "NoneType None"),
    (lambda: bsdfkit.trace(["scene.toml"], 100), "trace(): argument 'scene'", "list ['scene.toml']"),
    (lambda: bsdfkit.trace("scene.toml", "100"), "trace(): argument 'rays'", "str '100'"),
    (lambda: bsdfkit.run(["cl830.toml"], "out"), "run(): argument 'recipe'", "list ['cl830.toml']"),
])
def test_wrong_type_is_a_type_error_naming_the_argument(call, name, given):
    with pytest.raises(TypeError) as caught:
        call()
    assert isinstance(caught.value, ArgumentTypeError) and isinstance(caught.value, InputError)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"bsdfkit.{name} of the wrong type; expected ")
    assert f"got {given}" in message


def test_a_path_where_a_dataset_is_expected_says_how_to_read_it():
    with pytest.raises(TypeError, match=r"read the file first: bsdfkit\.ingest\(path\)"):
        bsdfkit.tis("scan.nc")


@pytest.mark.parametrize("call", [
    lambda: bsdfkit.tis(NO_BSDF), lambda: NO_BSDF.bsdf.tis(), lambda: NO_BSDF.bsdf.profile("bibs"),
    lambda: NO_BSDF.bsdf.fit("bibs", "reflection"), lambda: bsdfkit.budget(NO_BSDF, 45),
])
def test_dataset_without_bsdf_is_a_validation_error(call):
    with pytest.raises(ValidationError, match=r"\(\): argument 'ds' is missing bsdf, bsdf_std, .*; expected an "
                                              r"xarray\.Dataset with bsdf, bsdf_std, .*, got variables a$"):
        call()


def test_accessor_describe_of_a_dataset_without_angles():
    with pytest.raises(ValidationError, match=r"bsdfkit\.describe\(\): argument 'ds' is missing side, theta_i, "
                                              r"wavelength;"):
        NO_BSDF.bsdf.describe()


@pytest.mark.parametrize(("call", "fragment"), [
    (lambda ds: bsdfkit.tis(ds, "45"), "tis(): argument 'incidence_deg' of the wrong type"),
    (lambda ds: bsdfkit.tis(ds, True), "tis(): argument 'incidence_deg' of the wrong type"),
    (lambda ds: bsdfkit.budget(ds, None), "budget(): argument 'incidence_deg' of the wrong type"),
    (lambda ds: bsdfkit.fit_bsdf(ds, "bibs", "reflection", 3), "fit_bsdf(): argument 'model' of the wrong type"),
    (lambda ds: bsdfkit.fit_bsdf(ds, "bibs", "reflection", fallback="no"),
     "fit_bsdf(): argument 'fallback' of the wrong type"),
    (lambda ds: bsdfkit.profile(ds, 3), "profile(): argument 'interaction' of the wrong type"),
    (lambda ds: bsdfkit.export(ds, "zemax", "bibs", "reflection", "out.bsdf", wavelength_nm="460"),
     "export(): argument 'wavelength_nm' of the wrong type"),
    (lambda ds: bsdfkit.save(ds, 3), "save(): argument 'path' of the wrong type"),
])
def test_wrong_type_of_the_other_arguments(bundled_scan, call, fragment):
    with pytest.raises(TypeError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        call(bundled_scan)


@pytest.mark.parametrize("incidence_deg", [100.0, -5.0, 720.0, float("nan"), float("inf")])
def test_incidence_outside_0_to_90_degrees_is_refused(bundled_scan, incidence_deg):
    for call in (lambda: bsdfkit.tis(bundled_scan, incidence_deg), lambda: bsdfkit.budget(bundled_scan, incidence_deg),
                 lambda: bundled_scan.bsdf.fit("bibs", "reflection", incidence_deg=incidence_deg)):
        with pytest.raises(ValidationError, match=r"argument 'incidence_deg' out of range; expected an angle of "
                                                  r"incidence \[deg\] in \[0, 90\], got"):
            call()


def test_small_degrees_are_degrees(bundled_scan):
    # 0.785 deg cannot be told from π/4 rad: it is an angle in degrees, and not measured
    with pytest.raises(InputError, match="no records at this incidence; expected one of 5, 45, 56 deg, got 0.785"):
        bsdfkit.tis(bundled_scan, 0.785)


def test_check_argument_passes_what_is_right():
    assert check_argument("f", "x", 45, (int, float), "a number", bounds=(0, 90)) == 45
    assert check_argument("f", "x", None, (int,), "a number", optional=True) is None
    assert check_argument("f", "ds", NO_BSDF, (xr.Dataset,), "a dataset", needs=("a",)) is NO_BSDF
    with pytest.raises(ArgumentTypeError, match=r"bsdfkit\.f\(\): argument 'x' of the wrong type; expected a "
                                                r"number, got bool True"):
        check_argument("f", "x", True, (int,), "a number")
