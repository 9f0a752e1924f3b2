"""A Lambertian model from a measured reflectance standard (Spectralon 8°/h): exported, re-read, band-weighted."""
from pathlib import Path

import numpy as np
import pytest
from conftest import fast_lane

from bsdfkit.core.errors import InputError
from bsdfkit.fit.lambertian import at_wavelength, band_weighted_reflectance, lambertian_from_reflectance
from bsdfkit.tables.export import export, read_any

SPECTRALON = Path(__file__).parent.parent / "data" / "grit-spectralon" / "Spectralon_Num4.txt"


@pytest.fixture(scope="module")
def spectralon():
    wl, rho, std = np.loadtxt(SPECTRALON, unpack=True)
    return lambertian_from_reflectance(wl, rho, std, source=SPECTRALON.name), (wl, rho)


@pytest.mark.parametrize("wavelength", fast_lane([380.0, 450.0, 555.5, 700.0, 1650.0], {555.5}))
def test_zemax_export_re_reads_the_reflectance_within_0p1_percent(tmp_path, spectralon, wavelength):
    model, (wl, rho) = spectralon
    out = tmp_path / f"spectralon_{wavelength:g}.bsdf"
    export(at_wavelength(model, wavelength), "zemax", "elastic", "reflection", out)
    stated = np.asarray(read_any(out).tis_computed["reflection"])
    expected = np.interp(wavelength, wl, rho)
    np.testing.assert_allclose(stated, expected, rtol=1e-3)
    assert 0.95 < expected < 1.0


def test_band_weighted_reflectance_for_blue_and_yellow_rays(spectralon):
    model, (wl, rho) = spectralon
    lam = np.arange(380.0, 781.0)
    flat = np.ones_like(lam)
    blue = band_weighted_reflectance(model, lam, flat, (450.0, 470.0))
    # a flat spectrum weights every sample alike: the band mean of the calibration values
    inside = (wl >= 450) & (wl <= 470)
    assert blue == pytest.approx(rho[inside].mean(), rel=1e-12)
    led = np.exp(-4 * np.log(2) * ((lam - 455.0) / 20.0) ** 2)
    weighted = band_weighted_reflectance(model, lam, led, (380.0, 500.0))
    assert rho[(wl >= 380) & (wl <= 500)].min() <= weighted <= rho[(wl >= 380) & (wl <= 500)].max()
    with pytest.raises(InputError, match="negative power"):
        band_weighted_reflectance(model, lam, led - 0.5, (380.0, 500.0))


def test_bad_spectra_are_refused_with_one_clear_line():
    wl = np.arange(400.0, 410.0)
    with pytest.raises(InputError, match="percent"):
        lambertian_from_reflectance(wl, np.full(wl.size, 98.0))
    with pytest.raises(InputError, match="not in nm"):
        lambertian_from_reflectance(wl / 1000.0, np.full(wl.size, 0.9))
    with pytest.raises(InputError, match="strictly increasing"):
        lambertian_from_reflectance(wl[::-1], np.full(wl.size, 0.9))
    with pytest.raises(InputError, match="outside the measured"):
        at_wavelength(lambertian_from_reflectance(wl, np.full(wl.size, 0.9)), 300.0)
