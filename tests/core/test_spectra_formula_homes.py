"""One home per formula (issue #28): the shared spectral and hemisphere formulas against independent values, and
the reductions' bands reaching both the TIS and the photon ratios."""
import math

import numpy as np
import pytest

from bsdfkit.core.conventions import InteractionBands
from bsdfkit.core.errors import InputError
from bsdfkit.core.hemisphere import linear_weights, unit_disk_reach
from bsdfkit.core.spectra import (
    FWHM_PER_SIGMA,
    gaussian,
    mean_wavelength_nm,
    photon_pdf_from_power,
    split_gaussian,
)
from bsdfkit.reduction import budget
from bsdfkit.reduction import tis as angular
from bsdfkit.reduction.spectrum_metrics import centroid_wavelength


def test_gaussian_half_maximum_is_at_half_the_fwhm():
    peak, fwhm = 550.0, 37.0
    assert gaussian(np.array([peak - fwhm / 2, peak, peak + fwhm / 2]), peak, fwhm) == pytest.approx(
        [0.5, 1.0, 0.5], rel=1e-15)
    # the split Gaussian keeps the total FWHM: half widths fwhm(1 ∓ α)/2
    alpha = 0.3
    left, right = peak - fwhm * (1 - alpha) / 2, peak + fwhm * (1 + alpha) / 2
    assert split_gaussian(np.array([left, right]), peak, fwhm, alpha) == pytest.approx([0.5, 0.5], rel=1e-14)


def test_fwhm_per_sigma_matches_a_normal_density():
    # a normal density with σ = 1 falls to half its maximum at ±FWHM/2
    assert math.exp(-0.5 * (FWHM_PER_SIGMA / 2) ** 2) == pytest.approx(0.5, rel=1e-15)
    assert FWHM_PER_SIGMA == pytest.approx(2.354820045, rel=1e-9)


def test_mean_wavelength_is_one_rule_for_the_centroid_too():
    wl = np.linspace(300.0, 900.0, 601)  # both lines fall below 1e-30 at the ends
    s = gaussian(wl, 520.0, 40.0) + 0.3 * gaussian(wl, 610.0, 60.0)
    # independent value: the two Gaussians' areas are ∝ their FWHMs, their centroids their peaks
    expected = (520.0 * 40.0 + 0.3 * 610.0 * 60.0) / (40.0 + 0.3 * 60.0)
    assert mean_wavelength_nm(wl, s) == pytest.approx(expected, abs=1e-6)
    assert centroid_wavelength(wl, s) == mean_wavelength_nm(wl, s)


def test_photon_pdf_integrates_to_one_and_weights_by_wavelength():
    wl = np.arange(400.0, 701.0, 5.0)
    p = photon_pdf_from_power(wl, np.ones_like(wl))
    assert p.sum() * 5.0 == pytest.approx(1.0, rel=1e-14)
    assert p[-1] / p[0] == pytest.approx(700.0 / 400.0, rel=1e-14)  # equal power, more photons at long λ
    banded = photon_pdf_from_power(wl, np.ones_like(wl), (400.0, 700.0))
    assert np.sum(banded * np.gradient(wl)) == pytest.approx(1.0, rel=1e-14)


def test_unit_disk_reach_lands_on_the_unit_circle():
    rng = np.random.default_rng(28)
    r, phi, psi = np.sqrt(rng.uniform(0, 0.99, 500)), rng.uniform(0, 2 * np.pi, 500), rng.uniform(0, 2 * np.pi, 500)
    b0 = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)
    u = np.stack([np.cos(psi), np.sin(psi)], axis=-1)
    t = unit_disk_reach((b0 * u).sum(-1), (b0**2).sum(-1))
    assert np.all(t >= 0)
    np.testing.assert_allclose(np.hypot(*(b0 + t[:, None] * u).T), 1.0, rtol=0, atol=1e-14)


def test_linear_weights_reproduce_numpy_interp():
    x = np.array([0.0, 0.5, 2.0, 3.5])
    f = np.array([1.0, -2.0, 4.0, 0.5])
    q = np.linspace(-1.0, 4.0, 41)
    lo, hi, w_lo, w_hi = linear_weights(x, q)
    np.testing.assert_allclose(w_lo * f[lo] + w_hi * f[hi], np.interp(q, x, f), rtol=0, atol=1e-15)


def test_the_bands_reach_the_tis_and_the_photon_ratio(bundled_scan):
    bands = InteractionBands(yellow_nm=(480.0, 740.0))
    narrow = angular.tis_table(bundled_scan, ("biys",), theta_i_deg=[45.0], bands=bands)
    table = budget.interaction_table(bundled_scan, 45.0, bands=bands)
    assert table.power["B_biys"] == pytest.approx(100 * float(narrow["tis"].sel(side="reflection")[0, 0]), rel=1e-12)
    default = angular.tis_table(bundled_scan, ("biys",), theta_i_deg=[45.0])
    assert float(narrow["tis"].sum()) < float(default["tis"].sum())  # less of the converted band
    with pytest.raises(InputError, match="other bands"):
        budget.interaction_table(bundled_scan, 45.0, tis=default, bands=bands)
