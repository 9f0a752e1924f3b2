"""bsdfkit.models.functions: spectrum shapes, direction cosines, BSDF models, TIS, and gradient safety at the edges."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bsdfkit.core.jaxconfig import x64
from bsdfkit.models import functions as models


def _np(f, *args):
    """Evaluate a model in float64 as one compiled function (much faster than op-by-op dispatch)."""
    with x64():
        return np.asarray(jax.jit(f)(*args))


# ---------------------------------------------------------------------------------------------- spectra
def test_gaussian_spectrum_fwhm_is_true_fwhm_and_matches_colour():
    import colour

    wl = np.arange(380.0, 781.0)
    s = _np(models.gaussian_spectrum, wl, 450.0, 22.0)
    assert s[wl == 450.0][0] == 1.0
    half = _np(models.gaussian_spectrum, np.array([439.0, 461.0]), 450.0, 22.0)
    np.testing.assert_allclose(half, 0.5, rtol=1e-14)
    # colour-science 0.4.7 sd_gaussian_fwhm is the same function (docs/fitting.md §1).
    ref = colour.sd_gaussian(450.0, 22.0, colour.SpectralShape(380, 780, 1), method="FWHM").values
    np.testing.assert_allclose(s, ref, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("alpha", [-0.9, -0.12, 0.0, 0.5])
def test_split_gaussian_half_widths_fwhm_and_area(alpha):
    peak, fwhm = 596.7, 154.3
    lo = peak - fwhm * (1 - alpha) / 2
    hi = peak + fwhm * (1 + alpha) / 2
    np.testing.assert_allclose(_np(models.split_gaussian_spectrum, np.array([lo, hi]), peak, fwhm, alpha), 0.5,
                               rtol=1e-13)
    assert hi - lo == pytest.approx(fwhm, rel=1e-14)  # FWHM independent of α
    wl = np.linspace(peak - 6 * fwhm, peak + 6 * fwhm, 200001)
    area = np.trapezoid(_np(models.split_gaussian_spectrum, wl, peak, fwhm, alpha), wl)
    assert area == pytest.approx(fwhm * math.sqrt(math.pi / models.C_FWHM), rel=1e-9)  # area independent of α


def test_split_gaussian_reduces_to_gaussian_at_alpha_zero():
    wl = np.linspace(380, 780, 401)
    np.testing.assert_allclose(_np(models.split_gaussian_spectrum, wl, 560.0, 90.0, 0.0),
                               _np(models.gaussian_spectrum, wl, 560.0, 90.0), rtol=1e-13)


# ---------------------------------------------------------------------------------------------- geometry
def test_direction_cosines_specular_and_in_plane():
    ti = math.radians(45.0)
    b0 = _np(lambda t: jnp.stack(models.specular_direction_cosines(t)), ti)
    np.testing.assert_allclose(b0, [math.sin(ti), 0.0])
    assert _np(models.delta_beta, ti, ti, 0.0) == pytest.approx(0.0, abs=1e-15)
    ts = np.radians(np.array([0.0, 10.0, 60.0, 88.0]))
    # in the plane of incidence |β − β0| = |sin θs − sin θi| on the specular side, sin θs + sin θi beyond the normal
    np.testing.assert_allclose(_np(models.delta_beta, ti, ts, 0.0), np.abs(np.sin(ts) - math.sin(ti)), atol=1e-15)
    np.testing.assert_allclose(_np(models.delta_beta, ti, ts, math.pi), np.sin(ts) + math.sin(ti), atol=1e-15)


def test_perpendicular_arc_direction_cosines():
    """The arc θs = acos(cos ε cos θi), φs = atan2(sin ε, cos ε sin θi) has β = (cos ε sin θi, sin ε)."""
    ti = math.radians(56.0)
    eps = np.radians(np.arange(-60.0, 61.0, 5.0))
    ts = np.arccos(np.cos(eps) * math.cos(ti))
    ps = np.arctan2(np.sin(eps), np.cos(eps) * math.sin(ti))
    d2 = _np(models.delta_beta_squared, ti, ts, ps)
    np.testing.assert_allclose(d2, (math.sin(ti) * (1 - np.cos(eps))) ** 2 + np.sin(eps) ** 2, atol=1e-15)


# ---------------------------------------------------------------------------------------------- BSDF models
def test_lambert_gaussian_and_abg_peak_and_far_values():
    ti = math.radians(30.0)
    assert _np(models.lambert_gaussian, ti, ti, 0.0, 0.1, 2.0, 0.05) == pytest.approx(0.1 / math.pi + 2.0)
    far = _np(models.lambert_gaussian, ti, math.radians(80.0), math.pi, 0.1, 2.0, 0.05)
    assert far == pytest.approx(0.1 / math.pi, rel=1e-12)
    assert _np(models.abg, 0.0, 0.01, 0.001, 1.8) == pytest.approx(10.0)  # peak A/B
    # far-field log-log slope −g
    d = np.array([0.1, 1.0])
    f = _np(models.abg, d, 0.01, 1e-8, 1.8)
    assert math.log(f[1] / f[0]) / math.log(10.0) == pytest.approx(-1.8, rel=1e-6)


def test_harvey_shack_equals_abg_for_g_2():
    """ABg with g = −S, B = L^g, A = b0·L^g equals Harvey–Shack exactly for g = 2 (docs/fitting.md §5)."""
    d = np.linspace(0.0, 1.5, 31)
    b0, L = 50.0, 0.02
    hs = _np(models.harvey_shack, d, b0, L, -2.0)
    ab = _np(models.abg, d, b0 * L**2, L**2, 2.0)
    np.testing.assert_allclose(hs, ab, rtol=1e-12)


# ---------------------------------------------------------------------------------------------- TIS
def test_tis_closed_forms_at_normal_incidence_match_reference_values():
    # docs/fitting.md §5, verified there by independent quadrature
    for (A, B, g), ref in [((0.0025, 0.001, 1.8), 0.041344), ((0.01, 0.01, 2.0), 0.144988),
                           ((0.001, 1e-4, 2.5), 0.072190)]:
        assert models.tis_abg_normal_incidence(A, B, g) == pytest.approx(ref, abs=5e-7)
        assert float(_np(models.tis_abg, 0.0, A, B, g)) == pytest.approx(models.tis_abg_normal_incidence(A, B, g),
                                                                          rel=1e-10)
    assert models.tis_abg_normal_incidence(0.3, 0.2, 0.0) == pytest.approx(math.pi * 0.3 / 1.2)


def test_tis_abg_oblique_falls_with_clipping():
    # docs/fitting.md §5: (0.0025, 0.001, 1.8) → 0.0413 at 0°, 0.0326 at 60°
    assert float(_np(models.tis_abg, math.radians(60.0), 0.0025, 0.001, 1.8)) == pytest.approx(0.0326, abs=5e-5)


def test_tis_gaussian_unclipped_and_clipped_against_brute_force():
    A, sigma = 3.0, 0.04
    inside = float(_np(models.tis_gaussian_lobe, math.radians(10.0), A, sigma))
    assert inside == pytest.approx(2 * math.pi * sigma**2 * A, rel=1e-12)
    # Strongly clipped lobe: brute-force ∫∫ f cos θ sin θ dθ dφ over the hemisphere (midpoint rule; on 600 x 1200
    # nodes it is within 1e-6 of its 4000 x 8000 value, a tenth of the tolerance, at a sixth of 1500 x 3000's cost).
    ti, A, sigma = math.radians(70.0), 1.5, 0.2
    n = 600
    th = (np.arange(n) + 0.5) * (math.pi / 2 / n)
    ph = (np.arange(2 * n) + 0.5) * (2 * math.pi / (2 * n)) - math.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    f = A * np.exp(-((np.sin(T) * np.cos(P) - math.sin(ti)) ** 2 + (np.sin(T) * np.sin(P)) ** 2) / (2 * sigma**2))
    brute = np.sum(f * np.cos(T) * np.sin(T)) * (math.pi / 2 / n) * (2 * math.pi / (2 * n))
    clipped = float(_np(models.tis_gaussian_lobe, ti, A, sigma))
    assert clipped == pytest.approx(brute, rel=1e-5)
    assert clipped < 2 * math.pi * sigma**2 * A * 0.8  # clipping removes a good part of the lobe
    assert float(_np(models.tis_lambert_gaussian, ti, 0.1, A, sigma)) == pytest.approx(0.1 + clipped, rel=1e-14)


# ---------------------------------------------------------------------------------------------- edge safety
def _value_and_grads(f, n_args):
    """jit(value_and_grad) of Σf w.r.t. every argument; built once per model so examples reuse one compile."""
    return jax.jit(jax.value_and_grad(lambda *a: jnp.sum(f(*a)), argnums=tuple(range(n_args))))


VG_ABG = _value_and_grads(models.abg, 4)
VG_SPLIT = _value_and_grads(models.split_gaussian_spectrum, 4)
VG_GAUSS = _value_and_grads(models.gaussian_spectrum, 3)
VG_LAMBERT_GAUSSIAN = _value_and_grads(models.lambert_gaussian, 6)
VG_LAMBERT_ABG = _value_and_grads(models.lambert_abg, 7)
VG_HARVEY_SHACK = _value_and_grads(models.harvey_shack, 4)


def _finite_everywhere(vg, *args):
    with x64():
        value, grads = vg(*(jnp.float64(a) for a in args))
        value = float(value)
        grads = [float(g) for g in grads]
    return value, np.isfinite(value) and all(np.isfinite(g) for g in grads)


EDGE = st.sampled_from([0.0, 1e-300, 1e-30, 1e-12, 1e-6, 0.5, 1.0, 2.0])


@settings(max_examples=40, deadline=None)
@given(d=EDGE, A=st.sampled_from([1e-3, 1.0, 50.0]), B=EDGE, g=st.sampled_from([0.0, 1e-12, 1e-3, 0.5, 2.0, 3.0]))
def test_abg_finite_with_nan_free_gradients(d, A, B, g):
    value, ok = _finite_everywhere(VG_ABG, d, A, B, g)
    assert ok and value > 0


@settings(max_examples=40, deadline=None)
@given(offset=st.sampled_from([0.0, 1e-9, 0.5, 30.0, 400.0]),
       fwhm=st.sampled_from([0.0, 1e-300, 1e-160, 1e-9, 1.0, 150.0]),
       alpha=st.sampled_from([-1.0, -0.999999, -0.12, 0.0, 0.3, 0.999999, 1.0]))
def test_spectrum_models_finite_with_nan_free_gradients(offset, fwhm, alpha):
    for vg, args in ((VG_SPLIT, (450.0 + offset, 450.0, fwhm, alpha)), (VG_GAUSS, (450.0 + offset, 450.0, fwhm))):
        value, ok = _finite_everywhere(vg, *args)
        assert ok and 0.0 <= value <= 1.0


@settings(max_examples=40, deadline=None)
@given(ts_deg=st.sampled_from([0.0, 30.0, 45.0, 89.9]), sigma=st.sampled_from([0.0, 1e-200, 1e-12, 0.03, 1.0]),
       B=st.sampled_from([0.0, 1e-30, 0.01]), g=st.sampled_from([0.0, 1e-9, 1.8]),
       L=st.sampled_from([0.0, 1e-200, 1e-9, 0.05]), S=st.sampled_from([-3.0, -1.0, 0.0]))
def test_bsdf_models_finite_with_nan_free_gradients_at_specular(ts_deg, sigma, B, g, L, S):
    """θi = 30°: θs = 30°, φs = 0 is exactly on specular (|β−β0| = 0), the worst case for every model."""
    ti, ts = math.radians(30.0), math.radians(ts_deg)
    assert _finite_everywhere(VG_LAMBERT_GAUSSIAN, ti, ts, 0.0, 0.1, 2.0, sigma)[1]
    assert _finite_everywhere(VG_LAMBERT_ABG, ti, ts, 0.0, 0.1, 0.01, B, g)[1]
    assert _finite_everywhere(VG_HARVEY_SHACK, abs(math.sin(ts) - math.sin(ti)), 10.0, L, S)[1]


def test_tis_gradients_finite_and_consistent():
    """d TIS/dA = TIS/A (TIS is linear in A); every derivative finite, also for a grazing lobe."""
    with x64():
        g = jax.jit(jax.grad(lambda a, s: models.tis_gaussian_lobe(1.2, a, s, n_psi=128), argnums=(0, 1)))
        h = jax.jit(jax.grad(lambda a, b, e: models.tis_abg(0.9, a, b, e, n_psi=64, n_panels=10), argnums=(0, 1, 2)))
        dg = [float(x) for x in g(1.0, 0.05)]
        dh = [float(x) for x in h(0.01, 1e-3, 1.5)]
        tis_g = float(models.tis_gaussian_lobe(1.2, 1.0, 0.05, n_psi=128))
    assert all(np.isfinite(x) for x in (*dg, *dh))
    assert dg[0] == pytest.approx(tis_g, rel=1e-12)
    assert dg[1] > 0 and dh[0] > 0 and dh[1] < 0  # wider lobe → more scatter; larger B → less
