"""Spectral reductions: eqs. (3)-(16) of the power-budget paper."""
import colour
import numpy as np
import pytest
import xarray as xr

from bsdfkit.core.errors import InputError
from bsdfkit.measurement.instrument import sample_direction
from bsdfkit.reduction import spectral
from bsdfkit.simulation import virtual_goniometer as virtual


def test_weighted_mean_uses_only_the_relative_spectrum(bundled_scan):
    e = spectral.incident_spectrum(bundled_scan, "blue")
    a = spectral.weighted_mean_bsdf(bundled_scan, "blue", (450, 470), e)
    b = spectral.weighted_mean_bsdf(bundled_scan, "blue", (450, 470), e * 123.0)
    c = spectral.weighted_mean_bsdf(bundled_scan, "blue", (450, 470))
    np.testing.assert_allclose(a["bsdf"].values, b["bsdf"].values, rtol=1e-12)
    np.testing.assert_allclose(a["bsdf"].values, c["bsdf"].values, rtol=1e-9)


def test_weighted_mean_of_a_constant_is_the_constant():
    """Eq. (5) with q independent of λ returns q for any weighting spectrum."""
    lam = np.arange(440, 481, 1.0)
    ds = xr.Dataset(
        {"bsdf": (("record", "wavelength"), np.full((3, lam.size), 0.25)),
         "bsdf_std": (("record", "wavelength"), np.full((3, lam.size), 0.01)),
         "incident_spectrum": (("configuration", "wavelength"), [np.exp(-((lam - 460) / 8) ** 2)]),
         "incident_valid": (("configuration", "wavelength"), [np.ones(lam.size, bool)])},
        coords={"wavelength": lam, "configuration": ["blue"], "config": ("record", ["blue"] * 3),
                "theta_i": ("record", [45.0] * 3), "phi_i": ("record", [180.0] * 3),
                "theta_s": ("record", [0, 10, 20.0]),
                "phi_s": ("record", [0.0] * 3), "side": ("record", ["reflection"] * 3),
                "arc": ("record", ["in_plane"] * 3)})
    led = colour.SpectralDistribution(dict(zip(lam, np.linspace(1, 3, lam.size))))
    out = spectral.weighted_mean_bsdf(ds, "blue", (450, 470), led)
    np.testing.assert_allclose(out["bsdf"].values, 0.25, rtol=1e-12)
    # std of a weighted mean of 21 equal-uncertainty pixels is below the single-pixel std
    assert (out.bsdf_std.values < 0.01).all()


def test_band_with_no_signal_is_a_clear_error(bundled_scan):
    with pytest.raises(InputError, match="band with no signal"):
        spectral.weighted_mean_bsdf(bundled_scan, "blue", (600, 700))


def test_bispectral_mean_is_integral_over_band_width(bundled_scan):
    i = spectral.bispectral_band_integral(bundled_scan, "blue", (470, 740))
    m = spectral.bispectral_band_mean(bundled_scan, "blue", (470, 740))
    np.testing.assert_allclose(m["bsdf"].values * 270.0, i["bsdf"].values, rtol=1e-12)
    assert m["bsdf"].attrs["units"] == "1/(sr nm)" and i["bsdf"].attrs["units"] == "1/sr"


def test_donaldson_reduction_agrees_with_band_averages():
    """A Donaldson matrix reduced with the blue incident spectrum (eq. 10) equals the band-averaged bi-spectral
    BSDF the calibration reports, and its yellow-band integral equals the eq. (13) integrand."""
    g = virtual.VirtualGoniometer()
    truth = virtual.cl830_truth(g)
    lam = g.spectrometer.wavelength
    th = np.radians(45.0)
    d = sample_direction(np.radians([0.0, 30.0, 60.0]), np.radians([0.0, 180.0, 0.0]))
    q = truth.donaldson("reflection", th, d, lam, lam)
    don = xr.DataArray(q, dims=["record", "wavelength_i", "wavelength"],
                       coords={"wavelength_i": lam, "wavelength": lam})
    incident = virtual.BLUE.incident_power(lam, 1.0)
    reduced = spectral.bispectral_weighted_mean(don, xr.DataArray(incident, dims=["wavelength"],
                                                                  coords={"wavelength": lam}))
    # the same quantity from its definition: elastic f(λ)·p_i(λ) + converted f_conv·e(λ)·⟨g⟩
    p_i = incident / np.sum(incident * np.gradient(lam))
    blue = lam < truth.elastic_split_nm
    f_el = np.where(blue,
                    truth.elastic_angular("bibs", "reflection", th, d)[:, None]
                    * truth.elastic_spectral("bibs", "reflection", th, lam),
                    truth.elastic_angular("yiys", "reflection", th, d)[:, None]
                    * truth.elastic_spectral("yiys", "reflection", th, lam))
    g_mean = np.sum(truth.excitation(lam) * p_i * np.gradient(lam))
    expected = (f_el * p_i
                + truth.conversion_angular("reflection", th, d)[:, None] * truth.emission_density(lam) * g_mean)
    np.testing.assert_allclose(reduced.values, expected, rtol=1e-10, atol=1e-15)
    # its band integral over 470-740 nm is the conversion TIS density (the eq. 13 integrand): T/π(...)·1
    inside = (lam >= 470) & (lam <= 740)
    integral = (reduced.values[:, inside] * np.gradient(lam)[inside]).sum(axis=1)
    np.testing.assert_allclose(integral, truth.conversion_angular("reflection", th, d), rtol=2e-3)


def test_photon_energy_of_a_line():
    lam = np.arange(500.0, 700.0, 0.5)
    line = xr.DataArray(np.where(np.isclose(lam, 600.0), 1.0, 0.0), dims=["wavelength"], coords={"wavelength": lam})
    assert spectral.mean_wavelength(line, (500, 700)) == pytest.approx(600.0)
    assert spectral.mean_photon_energy(line, (500, 700)) == pytest.approx(6.62607015e-34 * 299792458 / 600e-9,
                                                                          rel=1e-12)


def test_photon_ratio_is_ratio_of_mean_wavelengths():
    lam = np.arange(400.0, 800.0, 0.5)
    a = xr.DataArray(np.exp(-((lam - 460) / 10) ** 2), dims=["wavelength"], coords={"wavelength": lam})
    b = xr.DataArray(np.exp(-((lam - 600) / 60) ** 2), dims=["wavelength"], coords={"wavelength": lam})
    r = spectral.photon_ratio(a, (440, 480), b, (470, 740))
    assert r == pytest.approx(spectral.mean_wavelength(b, (470, 740)) / spectral.mean_wavelength(a, (440, 480)),
                              rel=1e-12)


def test_a_side_the_data_do_not_hold_is_named_with_the_sides_they_hold():
    # issue #44.5: `fit bsdf --side transmission` on a reflection-only file said "got []"
    from pathlib import Path

    from bsdfkit.tables.vendor import vendor_dataset

    ds = vendor_dataset(Path(__file__).resolve().parents[1] / "data" / "ansys-radiant-zemax-bsdf"
                        / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf")
    with pytest.raises(InputError, match="expected reflection, got 'transmission'"):
        spectral.interaction_profile(ds, "elastic", "transmission")
