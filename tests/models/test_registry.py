"""The model registry: one definition per model, used by fits, exports and the command line."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bsdfkit.core.errors import ValidationError
from bsdfkit.models.functions import tis_abg_normal_incidence
from bsdfkit.models.registry import BSDF_MODELS, bsdf_model
from bsdfkit.tables import export

PARAMS = {"lambert": {"rho": 0.3}, "lambert+gaussian": {"rho": 0.3, "A": 2.0, "sigma": 0.05},
          "abg": {"A": 0.0025, "B": 0.001, "g": 1.8}, "lambert+abg": {"rho": 0.3, "A": 0.0025, "B": 0.001, "g": 1.8}}


def test_every_model_has_parameters_with_units_and_bounds():
    assert set(BSDF_MODELS) == set(PARAMS)
    for name, model in BSDF_MODELS.items():
        assert model.parameter_names == tuple(PARAMS[name])
        assert all(p.unit and p.lower < p.upper for p in model.parameters)


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_numpy_evaluator_matches_the_formula(name):
    model = bsdf_model(name)
    theta_i, theta_s = 30.0, np.array([0.0, 10.0, 30.0, 31.0, 60.0])
    values = model.values(PARAMS[name], theta_i, theta_s, 0.0)
    d = np.abs(np.sin(np.radians(theta_s)) - np.sin(np.radians(theta_i)))  # in-plane, specular side
    p = PARAMS[name]
    expected = p.get("rho", 0.0) / np.pi + np.zeros_like(d)
    if "sigma" in p:
        expected += p["A"] * np.exp(-d**2 / (2 * p["sigma"] ** 2))
    if "g" in p:
        expected += p["A"] / (p["B"] + d ** p["g"])
    np.testing.assert_allclose(values, expected, rtol=1e-12)
    np.testing.assert_allclose(model.values_at_distance(p, d), expected, rtol=1e-12)


def test_tis_closed_forms():
    assert float(bsdf_model("lambert").total_integrated_scatter({"rho": 0.37}, 40.0)) == pytest.approx(0.37)
    # a narrow lobe far from the horizon: 2πσ²A (exact to exp(−t_max²/2σ²), i.e. to double precision here)
    tis = float(bsdf_model("lambert+gaussian").total_integrated_scatter({"rho": 0.0, "A": 2.0, "sigma": 0.02}, 10.0))
    assert tis == pytest.approx(2 * math.pi * 0.02**2 * 2.0, rel=1e-10)
    # ABg at normal incidence: (πA/B)·2F1(1, 2/g; 1 + 2/g; −1/B), checked value 0.041344
    abg = float(bsdf_model("abg").total_integrated_scatter(PARAMS["abg"], 0.0))
    assert abg == pytest.approx(tis_abg_normal_incidence(0.0025, 0.001, 1.8), rel=1e-9)
    assert abg == pytest.approx(0.041344, abs=5e-7)


def test_exports_and_fits_take_their_models_from_the_registry():
    assert export.FIT_MODELS == {name: m.parameter_names for name, m in BSDF_MODELS.items()}
    with pytest.raises(ValidationError, match="unknown BSDF model"):
        bsdf_model("phong")
    with pytest.raises(ValidationError, match="lacks parameters"):
        bsdf_model("abg").values({"A": 1.0}, 0.0, 0.0, 0.0)


def test_spectrum_models_are_registered_once_with_the_fits_parameters():
    from bsdfkit.fit.spectrum import models as spectrum
    from bsdfkit.models.registry import SPECTRUM_MODELS

    assert tuple(SPECTRUM_MODELS) == spectrum.SPECTRUM_MODELS
    for name, model in SPECTRUM_MODELS.items():
        fitted = spectrum._parameters(name, 380.0, 780.0)
        assert model.parameter_names == tuple(p.name for p in fitted), name
        assert tuple(u for _, u in model.parameters) == tuple(p.unit for p in fitted), name
        assert spectrum._FUNCTIONS[name] is model.function


@pytest.mark.parametrize("b", [0.0, 0.1, 0.7, 0.99, 0.9998])
@pytest.mark.parametrize("sigma", [0.002, 0.03, 0.6])
def test_the_tracers_lobe_integral_is_the_registry_formula(b, sigma):
    """Oracle: the same integral about the origin, ∫_0^1 2πr exp(−(r−b)²/2σ²) I0e(rb/σ²) dr, by adaptive quad."""
    import scipy.integrate
    import scipy.special

    from bsdfkit.raytrace.plate import lobe_disk_integral

    s2 = sigma * sigma

    def integrand(r):
        return 2 * math.pi * r * math.exp(-(r - b) ** 2 / (2 * s2)) * float(scipy.special.i0e(r * b / s2))

    ref = scipy.integrate.quad(integrand, 0.0, 1.0, points=[min(max(b, 1e-12), 1 - 1e-12)], limit=200,
                               epsabs=0.0, epsrel=1e-12)[0]
    assert lobe_disk_integral(b, sigma) == pytest.approx(ref, rel=1e-11)
