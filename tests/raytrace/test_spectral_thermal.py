"""Emission conditioned on the excitation wavelength (issue 27): the thermal (anti-Stokes) tail of the spectral mode.

A measured-style excitation-emission set whose emission does not depend on the excitation (as a phosphor's, by
Kasha's rule, and as the bundled eem-synthetic truth's) overlaps the excitation band: taken row by row it would
send 2-27 % of the photons absorbed at 500-560 nm out at shorter wavelengths. The tracer weights the emission below
the excitation wavelength by the Boltzmann factor at the plate temperature; these tests check the traced share
against the share computed here from that rule (with CODATA constants, independently of the module's), the
energy the anti-Stokes conversions create, and that the rule leaves an excitation far below the emission alone.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from conftest import TRACE_LANES
from scipy import constants

from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.raytrace import loads_scene, trace
from bsdfkit.raytrace.scene import scene_spectral_tables
from bsdfkit.raytrace.spectral import (
    PLATE_TEMPERATURE_K,
    anti_stokes_share,
    conditional_emission_pdf,
    model_on_bins,
    spectral_model_from_dataset,
)

STEP = 2.0
EMISSION = np.arange(380.0, 781.0, STEP)
EXCITATION = np.arange(400.0, 561.0, 20.0)
#: converted power per incident power, all forward (transmission): a ray converts once and leaves
CONVERTED_T = 0.5


def measured_style_model():
    """Rows measured every 20 nm of excitation, each the same emission (onset at 470 nm, peak 560 nm): the rows at
    500-560 nm carry photons below their excitation wavelength, as a row-by-row reading of a scan does."""
    onset = 1.0 / (1.0 + np.exp(-(EMISSION - 490.0) / 6.0)) * (EMISSION > 470.0)
    photons = onset * np.exp(-0.5 * ((EMISSION - 560.0) / 50.0) ** 2)
    row = photons / (photons.sum() * STEP)
    K = EXCITATION.size
    zero = np.zeros((2, 1, K))
    ds = xr.Dataset(
        {"elastic_tis": (("side", "incidence", "excitation"), zero),
         "converted_tis": (("side", "incidence", "excitation"),
                           np.stack([np.zeros((1, K)), np.full((1, K), CONVERTED_T)])),
         "emission_pdf": (("excitation", "emission"), np.tile(row, (K, 1)))},
        coords={"side": ["reflection", "transmission"], "incidence": [45.0], "excitation": EXCITATION,
                "emission": EMISSION})
    return spectral_model_from_dataset(ds)


def expected_share(pdf_row: np.ndarray, k: int, temperature_K: float) -> tuple[float, float]:
    """Anti-Stokes share of excitation bin k under the Boltzmann rule, and the mean relative energy gain
    (λ_k/λ_j − 1) of those anti-Stokes photons, from the constants (not the module's)."""
    lam = EMISSION
    gap = constants.h * constants.c * (1.0 / lam - 1.0 / lam[k]) * 1e9 / (constants.k * temperature_K)
    w = pdf_row * np.where(lam < lam[k], np.exp(-gap), 1.0)
    below = np.arange(lam.size) < k
    share = w[below].sum() / w.sum()
    gain = (w[below] * (lam[k] / lam[below] - 1.0)).sum() / w[below].sum()
    return float(share), float(gain)


def scene(tmp_path, model, peak_nm: float, temperature_K: float | None = None):
    path = tmp_path / "model.nc"
    model.save(path, force=True)
    temp = "" if temperature_K is None else f"temperature_K = {temperature_K}\n"
    return loads_scene(f"""
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
reflectance = 0.0
[base]
reflectance = 0.0
[leds]
count = 4
spectrum_peak_nm = {peak_nm}
spectrum_fwhm_nm = 0.4
[top]
kind = "phosphor"
spectral = "{path}"
{temp}[trace]
mode = "spectral"
""")


def test_the_data_rows_are_anti_stokes_beyond_any_thermal_tail():
    """The set is a real test bed: read row by row, 10-40 % of the photons absorbed at 520-560 nm would leave
    at a shorter wavelength; the conditional table keeps each row to the Boltzmann tail (under a quarter)."""
    model = measured_style_model()
    _, _, pdf = model_on_bins(model)
    cond = conditional_emission_pdf(pdf, EMISSION, PLATE_TEMPERATURE_K)
    data, traced = anti_stokes_share(pdf), anti_stokes_share(cond)
    for x in (520.0, 540.0, 560.0):
        k = int(np.flatnonzero(EMISSION == x)[0])
        assert data[k] > 0.1
        assert traced[k] == pytest.approx(expected_share(pdf[k], k, PLATE_TEMPERATURE_K)[0], rel=1e-9)
        assert traced[k] < 0.25 * data[k]
    np.testing.assert_allclose(cond.sum(axis=1) * STEP, pdf.sum(axis=1) * STEP, rtol=1e-12)  # rows stay pdfs


def test_a_cold_plate_keeps_every_row_and_emits_nothing_shorter():
    """At 1 K the Boltzmann factors underflow (exp(−10⁴)); the rows still sum to the data's, rows with emission
    above the excitation send nothing below it, and a row whose emission lies wholly below its excitation (700 nm
    here, taken from the 520 nm row shifted down) keeps its photons in its longest-wavelength bin with mass."""
    model = measured_style_model()
    _, _, pdf = model_on_bins(model)
    k700 = int(np.flatnonzero(EMISSION == 700.0)[0])
    pdf = pdf.copy()
    pdf[k700] = np.where(EMISSION < 600.0, pdf[int(np.flatnonzero(EMISSION == 520.0)[0])], 0.0)
    pdf[k700] /= pdf[k700].sum() * STEP
    cond = conditional_emission_pdf(pdf, EMISSION, 1.0)
    assert np.all(np.isfinite(cond))
    np.testing.assert_allclose(cond.sum(axis=1), pdf.sum(axis=1), rtol=1e-12)
    share = anti_stokes_share(cond)
    for x in (500.0, 520.0, 560.0):
        assert share[int(np.flatnonzero(EMISSION == x)[0])] < 1e-12
    assert cond[k700, int(np.flatnonzero(EMISSION == 598.0)[0])] * STEP == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("peak_nm, temperature_K", [(520.0, None), (540.0, 600.0)])
def test_traced_anti_stokes_share_is_the_thermal_tail(tmp_path, peak_nm, temperature_K):
    """One excitation bin (LED FWHM 0.4 nm on 2 nm bins), no cavity reflection, conversion forward only: every
    converted ray carries the same weight, so the traced share is binomial; within 4 σ of the Boltzmann rule's.
    The power those anti-Stokes photons gain is the rule's mean gain (within 4 σ), and both ledgers close."""
    s = scene(tmp_path, measured_style_model(), peak_nm, temperature_K)
    T = PLATE_TEMPERATURE_K if temperature_K is None else temperature_K
    assert s.top.temperature_K == T
    tab = scene_spectral_tables(s)
    k = int(np.argmax(tab.led_power))
    assert tab.led_power[k] > 0.999
    _, _, pdf = model_on_bins(s.top.spectral_model)
    share, gain = expected_share(pdf[k], k, T)
    data_share = anti_stokes_share(pdf)[k]
    assert share < 0.5 * data_share  # what the test tells apart (many σ apart, below)

    r = trace(s, 120_000, 7, chunk=60_000, lanes=TRACE_LANES)
    led = r.spectral.ledger
    assert led["power_W"]["error"] <= 1e-9 and led["photons_per_s"]["error"] <= 1e-9
    conv = led["conversions"]
    photon_J = constants.h * constants.c / (EMISSION[k] * 1e-9)
    y = conv["photons_per_s"] * photon_J / s.leds.power_W  # photons converted, in power at the excitation
    per_ray = CONVERTED_T * EMISSION[k] * (pdf[k] * STEP / EMISSION).sum()  # photon yield Y of one ray
    n = y / per_ray * 120_000
    assert n > 20_000
    sigma = math.sqrt(share * (1.0 - share) / n)
    assert abs(conv["anti_stokes_share"] - share) <= 4.0 * sigma, (conv["anti_stokes_share"], share, sigma)
    # energy created per anti-Stokes photon: only the thermal tail's
    n_anti = n * conv["anti_stokes_share"]
    lam_below = EMISSION[:k]
    g = EMISSION[k] / lam_below - 1.0
    traced_gain = conv["anti_stokes_gain_W"] / (conv["anti_stokes_photons_per_s"] * photon_J)
    assert traced_gain == pytest.approx(gain, abs=4.0 * g.max() / math.sqrt(n_anti))
    assert traced_gain < 4.0 * constants.k * T / photon_J  # a few kT per anti-Stokes photon, never more


def test_excitation_below_the_emission_band_samples_the_unconditional_spectrum(tmp_path):
    """Excited at 420 nm, 50 nm below the emission onset, the conditional sampler draws the data's own row: the
    traced module spectrum has the shape of the unconditional emission (power ∝ photons/λ) within 4 σ per bin."""
    model = measured_style_model()
    s = scene(tmp_path, model, 420.0)
    tab = scene_spectral_tables(s)
    _, _, pdf = model_on_bins(model)
    k = int(np.argmax(tab.led_power))
    np.testing.assert_allclose(tab.emission_pdf[k], pdf[k], rtol=1e-12, atol=0)
    r = trace(s, 60_000, 3, chunk=60_000, lanes=TRACE_LANES)
    got, se = r.spectral.spectrum_W_per_nm, r.spectral.spectrum_std_err
    power = pdf[k] / EMISSION
    total = float(got.sum())
    expected = power / power.sum() * total
    signal = se > 0
    z = (got[signal] - expected[signal]) / se[signal]
    assert np.all(np.abs(z) <= 4.5), float(np.abs(z).max())
    assert np.mean(z ** 2) < 1.5
    assert np.all(got[EMISSION < 470.0] == 0.0)
    assert r.spectral.ledger["conversions"]["anti_stokes_share"] == 0.0


def test_plate_temperature_is_checked(tmp_path):
    model = measured_style_model()
    with pytest.raises(ValidationError, match="temperature_K"):
        scene(tmp_path, model, 520.0, -5.0)
    with pytest.raises(InputError, match="temperature_K"):
        loads_scene("[cavity]\nradius_mm = 35.0\nheight_mm = 43.0\n[wall]\nreflectance = 0.9\n[base]\n"
                    "reflectance = 0.9\n[leds]\ncount = 4\n[top]\nkind = \"exit\"\ntemperature_K = 300.0\n")
