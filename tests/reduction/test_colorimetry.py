"""bsdfkit.reduction.colorimetry and ``bsdfkit color``: CIE LED reference chromaticities/CCTs, photometry, YBR."""
import json
from pathlib import Path

import colour
import numpy as np
import pytest
from conftest import cli

from bsdfkit.cli.main import main
from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.reduction import colorimetry

DATA = Path(__file__).resolve().parent.parent / "data"
CIE_CSV = DATA / "colour-cie-nist-led-spd" / "cie_led_illuminants_and_nist_cqs_led_spd_5nm.csv"
# tests/data/colour-cie-nist-led-spd/PROVENANCE.md (CIE 015:2018 Table 12 LED illuminants)
REFERENCE = {
    "B1": (0.4560, 0.4078, 2733.0),
    "B2": (0.4357, 0.4012, 2998.0),
    "B3": (0.3756, 0.3723, 4102.0),
    "B4": (0.3422, 0.3502, 5109.0),
    "B5": (0.3118, 0.3236, 6598.0),
}


def cie_led(name: str) -> colour.SpectralDistribution:
    table = np.genfromtxt(CIE_CSV, delimiter=",", names=True)
    return colour.SpectralDistribution(table[f"CIE_LED{name}"], table["wavelength_nm"], name=f"LED-{name}")


@pytest.mark.parametrize("name", list(REFERENCE))
def test_cie_led_illuminants_chromaticity_and_cct(name):
    x_ref, y_ref, cct_ref = REFERENCE[name]
    sd = cie_led(name)
    x, y = colorimetry.chromaticity_xy(sd)
    cct, duv = colorimetry.cct_duv(sd)
    # references are rounded to 4 decimals / 1 K: |error| ≤ 5e-5 rounding + computation
    assert abs(x - x_ref) <= 1e-4 and abs(y - y_ref) <= 1e-4
    assert abs(cct - cct_ref) <= 2.0
    assert colorimetry.cct_is_meaningful(duv)


def test_color_cli_reproduces_cie_led_b3(tmp_path):
    sd = cie_led("B3")
    path = tmp_path / "led_b3.csv"
    path.write_text("wavelength_nm,relative\n" + "".join(f"{w:g},{v!r}\n" for w, v in zip(sd.wavelengths, sd.values)))
    proc = cli("color", path, "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    x_ref, y_ref, cct_ref = REFERENCE["B3"]
    assert abs(out["x"] - x_ref) <= 1e-4 and abs(out["y"] - y_ref) <= 1e-4
    assert abs(out["cct_K"] - cct_ref) <= 2.0
    assert {"duv", "luminous_efficacy_lm_per_W"} <= set(out)
    assert 250 < out["luminous_efficacy_lm_per_W"] < 400  # white LED range (max 683 lm/W)


def test_blackbody_cct_and_duv():
    for T in (2700.0, 4000.0, 6500.0):
        sd = colour.sd_blackbody(T, colour.SpectralShape(360, 830, 1))
        cct, duv = colorimetry.cct_duv(sd)
        assert cct == pytest.approx(T, abs=1.0) and abs(duv) < 1e-4


def test_irregular_grid_is_resampled_consistently():
    rng = np.random.default_rng(0)
    wl = np.sort(np.concatenate([[360.0, 830.0], rng.uniform(360, 830, 900)]))
    ref = colour.sd_blackbody(3000.0, colour.SpectralShape(360, 830, 1))
    irregular = colour.SpectralDistribution(np.interp(wl, ref.wavelengths, ref.values), wl, name="irregular")
    cct, _ = colorimetry.cct_duv(irregular)
    assert cct == pytest.approx(3000.0, abs=3.0)


def test_luminous_efficacy_and_flux():
    wl = np.arange(360.0, 831.0)
    narrow = colour.SpectralDistribution(np.exp(-0.5 * ((wl - 555.0) / 1.0) ** 2), wl, name="555 nm")
    # K_m·V(555 nm) = 683 lm/W at the peak of V(λ); a 2.4 nm wide line loses < 0.1 %
    assert colorimetry.luminous_efficacy_of_radiation(narrow) == pytest.approx(683.0, rel=2e-3)
    scaled = colour.SpectralDistribution(2.0 * narrow.values, wl, name="x2")
    assert colorimetry.luminous_flux_lm(scaled) == pytest.approx(2 * colorimetry.luminous_flux_lm(narrow), rel=1e-12)
    radiant = np.trapezoid(narrow.values, wl)
    assert colorimetry.luminous_flux_lm(narrow) == pytest.approx(
        colorimetry.luminous_efficacy_of_radiation(narrow) * radiant, rel=1e-9)


def test_yellow_blue_ratio_band_sums():
    wl = np.arange(380.0, 781.0)
    flat = colour.SpectralDistribution(np.ones(wl.size), wl, name="flat")
    # 1 nm grid: blue 380..470 = 91 samples, yellow 471..780 = 310 samples, Δλ = 1
    assert colorimetry.yellow_blue_ratio(flat) == pytest.approx(310 / 91, rel=1e-14)
    assert colorimetry.yellow_blue_ratio(flat, (380, 500), (501, 780)) == pytest.approx(280 / 121, rel=1e-14)


def test_colorimetry_errors():
    wl = np.arange(380.0, 781.0)
    with pytest.raises(NumericalError, match="no positive value"):
        colorimetry.chromaticity_xy(colour.SpectralDistribution(np.zeros(wl.size), wl, name="dark"))
    values = np.ones(wl.size)
    values[10] = np.nan
    with pytest.warns(colour.utilities.ColourRuntimeWarning):  # colour itself notices the NaN
        with_nan = colour.SpectralDistribution(values, wl, name="nan")
    with pytest.raises(InputError, match="390 nm"):
        colorimetry.cct_duv(with_nan)
    red = colour.SpectralDistribution(np.where(wl > 600, 1.0, 0.0), wl, name="red")
    with pytest.raises(NumericalError, match="blue band"):
        colorimetry.yellow_blue_ratio(red)


def test_color_cli_text_warns_for_meaningless_cct(capsys):
    path = DATA / "benkner-led-spectra" / "blue_3.ISD"
    assert main(["color", str(path)]) == 0
    captured = capsys.readouterr()
    assert "x = 0.1" in captured.out and "lm/W" in captured.out
    assert captured.err.count("\n") == 1 and "not meaningful" in captured.err
