"""bsdfkit.fit.spectrum: spectrum fits (synthetic Table 2, measured Benkner LEDs, hard cases) and the §4.2
two-band reconstruction of the cylindrical-module paper."""
from pathlib import Path

import numpy as np
import pytest

from bsdfkit.core.errors import FitError, InputError, NumericalError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit import spectrum as spectra
from bsdfkit.io.spectrum_file import read_spectrum_arrays
from bsdfkit.models import functions as models

DATA = Path(__file__).resolve().parent.parent / "data" / "benkner-led-spectra"
WL = np.arange(380.0, 781.0)  # 1 nm grid, 380-780 nm
# Table 2 of the cylindrical-module paper
BLUE = dict(peak_nm=450.1, fwhm_nm=22.9)
YELLOW = dict(peak_nm=596.7, fwhm_nm=154.3, alpha=-0.12)


def table2_spectra(wl=WL):
    with x64():
        s_blue = np.asarray(models.gaussian_spectrum(wl, BLUE["peak_nm"], BLUE["fwhm_nm"]))
        s_yellow = np.asarray(models.split_gaussian_spectrum(wl, YELLOW["peak_nm"], YELLOW["fwhm_nm"], YELLOW["alpha"]))
    return s_blue, s_yellow


def assert_within_3_std(ds, truth):
    for name, true in truth.items():
        value, std = float(ds[name]), float(ds[f"{name}_std"])
        assert 0 < std and abs(value - true) < 3 * std, (name, value, true, std)


# ---------------------------------------------------------------------------------------------- Table 2
def test_table2_spectra_with_1_percent_noise_recovered_within_3_standard_errors(capsys):
    rng = np.random.default_rng(2024)
    s_blue, s_yellow = table2_spectra()
    blue = spectra.fit_spectrum(WL, s_blue + 0.01 * rng.standard_normal(WL.size), "gaussian", sigma=0.01)
    yellow = spectra.fit_spectrum(WL, s_yellow + 0.01 * rng.standard_normal(WL.size), "split-gaussian", sigma=0.01)
    assert bool(blue.converged) and bool(yellow.converged)
    assert_within_3_std(blue, {**BLUE, "amplitude": 1.0})
    assert_within_3_std(yellow, {**YELLOW, "amplitude": 1.0})
    # R² of a correct model with 1 % noise: 1 − σ²/var(S); the paper reports 0.98 / 0.99 on measured spectra.
    for ds, s in ((blue, s_blue), (yellow, s_yellow)):
        expected = 1 - 0.01**2 / np.var(s)
        # SS_res/n fluctuates by ≈ √(2/n) ≈ 7 % around σ²; allow 30 % of (1 − R²)
        assert abs(float(ds.r2) - expected) < 0.3 * (1 - expected)
    with capsys.disabled():
        print(f"\n[Table 2 synthetic, 1 % noise] R² blue = {float(blue.r2):.5f}, R² yellow = {float(yellow.r2):.5f}")


def test_two_band_joint_fit_recovers_both_components():
    rng = np.random.default_rng(7)
    s_blue, s_yellow = table2_spectra()
    y = 0.35 * s_blue + s_yellow + 0.01 * rng.standard_normal(WL.size)
    ds = spectra.fit_spectrum(WL, y, "two-band", sigma=0.01)
    assert bool(ds.converged)
    assert_within_3_std(ds, {"blue_peak_nm": 450.1, "blue_fwhm_nm": 22.9, "blue_amplitude": 0.35,
                             "yellow_peak_nm": 596.7, "yellow_fwhm_nm": 154.3, "yellow_alpha": -0.12,
                             "yellow_amplitude": 1.0})


def test_batched_spectrum_fits_match_single_fits():
    rng = np.random.default_rng(3)
    peaks = np.array([445.0, 452.0, 460.0])
    with x64():
        y = np.stack([np.asarray(models.gaussian_spectrum(WL, p, 20.0 + i)) for i, p in enumerate(peaks)])
    y = y * np.array([[1.0], [2.5], [0.3]]) + 0.003 * rng.standard_normal(y.shape)
    batch = spectra.fit_spectra(WL, y, "gaussian")
    for b in range(3):
        one = spectra.fit_spectrum(WL, y[b], "gaussian")
        assert float(batch.peak_nm[b]) == pytest.approx(float(one.peak_nm), abs=1e-9)
        assert float(batch.amplitude[b]) == pytest.approx(float(one.amplitude), rel=1e-9)
    np.testing.assert_allclose(batch.amplitude.values, [1.0, 2.5, 0.3], rtol=0.01)  # input units restored


# ---------------------------------------------------------------------------------------------- measured
def test_measured_blue_led_fits_gaussian():
    wl, v, header = read_spectrum_arrays(DATA / "blue_3.ISD")
    visible = (wl >= 380) & (wl <= 780)
    wl, v = wl[visible], v[visible]  # the visible range, 380-780 nm
    ds = spectra.fit_spectrum(wl, v, "gaussian")
    measured_peak = wl[np.argmax(v)]
    assert float(ds.r2) >= 0.98
    assert abs(float(ds.peak_nm) - measured_peak) <= 1.0
    assert 15.0 < float(ds.fwhm_nm) < 30.0  # InGaN blue LED


def test_measured_white_phosphor_band_fits_split_gaussian():
    """Phosphor band = from the spectral minimum between the pump peak and 560 nm (the 'valley') to 780 nm."""
    wl, v, _ = read_spectrum_arrays(DATA / "white_3000K.ISD")
    visible = (wl >= 380) & (wl <= 780)
    wl, v = wl[visible], v[visible]
    pump = (wl >= 400) & (wl <= 480)
    pump_peak = wl[pump][np.argmax(v[pump])]
    between = (wl >= pump_peak) & (wl <= 560)
    valley = wl[between][np.argmin(v[between])]
    band = (wl >= valley) & (wl <= 780)
    ds = spectra.fit_spectrum(wl, v, "split-gaussian", mask=band)
    assert 460 < valley < 500
    assert bool(ds.converged) and float(ds.r2) >= 0.97
    assert 560 < float(ds.peak_nm) < 660 and 100 < float(ds.fwhm_nm) < 220
    assert float(ds.alpha) < 0  # broader on the short-wavelength side, the sign of Table 2's α


# ---------------------------------------------------------------------------------------------- hard cases
@pytest.mark.parametrize("alpha", [0.98, -0.98, 1.0])
def test_alpha_near_or_at_plus_minus_one_gives_finite_result_or_fit_error(alpha):
    rng = np.random.default_rng(11)
    with x64():
        y = np.asarray(models.split_gaussian_spectrum(WL, 560.0, 100.0, alpha)) + 0.01 * rng.standard_normal(WL.size)
    try:
        ds = spectra.fit_spectrum(WL, y, "split-gaussian")
    except FitError as exc:
        assert "\n" not in str(exc)
        return
    values = [float(ds[n]) for n in ds.parameter.values] + [float(ds[f"{n}_std"]) for n in ds.parameter.values]
    assert np.all(np.isfinite(values))
    assert np.sign(float(ds.alpha)) == np.sign(alpha) and abs(float(ds.alpha)) > 0.95
    assert float(ds.fwhm_nm) == pytest.approx(100.0, rel=0.02)


@pytest.mark.parametrize("fwhm", [0.0, 0.3])
def test_fwhm_below_the_grid_gives_finite_result_or_fit_error(fwhm):
    """A spike narrower than the 1 nm sampling: the width is unresolved. Either a finite result that
    reproduces the data or a one-line FitError naming the undetermined parameters."""
    with x64():
        y = np.asarray(models.gaussian_spectrum(WL, 450.0, fwhm))
    for model in ("gaussian", "split-gaussian"):
        try:
            ds = spectra.fit_spectrum(WL, y, model)
        except FitError as exc:
            assert "singular" in str(exc) and "\n" not in str(exc)
            continue
        assert np.all(np.isfinite([float(ds[n]) for n in ds.parameter.values]))
        assert float(ds.fwhm_nm) < 1.0 and float(ds.r2) > 0.999


def test_spectrum_fit_input_errors():
    with pytest.raises(FitError, match="no positive value"):
        spectra.fit_spectrum(WL, np.zeros(WL.size), "gaussian")
    with pytest.raises(InputError, match="increase strictly"):
        spectra.fit_spectrum(WL[::-1], np.ones(WL.size), "gaussian")
    with pytest.raises(ValidationError, match="unknown spectrum model"):
        spectra.fit_spectrum(WL, np.ones(WL.size), "lorentzian")


# ---------------------------------------------------------------------------------------------- §4.2
def test_reconstruction_reproduces_band_fluxes_and_documented_gains():
    s_blue, s_yellow = table2_spectra()
    sd = spectra.reconstruct_two_band_spectrum(WL, s_blue, s_yellow, 0.058, 0.472)
    assert spectra.band_integral(sd.wavelengths, sd.values, (380, 500)) == pytest.approx(0.058, rel=1e-12)
    assert spectra.band_integral(sd.wavelengths, sd.values, (501, 780)) == pytest.approx(0.472, rel=1e-12)
    g = spectra.two_band_gains(WL, s_blue, s_yellow, 0.058, 0.472)
    # docs/fitting.md: eqs. (2)-(3) with Table 2 and Table 1 give these, not the published 1.22e-3 / 2.80e-3.
    assert g.a1_W_per_nm == pytest.approx(1.108e-4, rel=1e-3)
    assert g.a2_W_per_nm == pytest.approx(3.218e-3, rel=1e-3)
    # The published A2 would need Σ_501..780 S_yellow Δλ ≥ 0.472/2.80e-3 = 168.6 nm, more than the whole
    # area of the Table 2 yellow curve (Δλ2·√(π/C) = 164.3 nm): inconsistent with these inputs.
    assert 0.472 / 2.80e-3 > YELLOW["fwhm_nm"] * np.sqrt(np.pi / models.C_FWHM)


def test_reconstruction_with_disjoint_bands_is_exact_and_bands_are_parameters():
    wl = np.arange(300.0, 901.0)
    with x64():
        s_b = np.asarray(models.gaussian_spectrum(wl, 450.0, 10.0))
        s_y = np.asarray(models.gaussian_spectrum(wl, 650.0, 30.0))
    g = spectra.two_band_gains(wl, s_b, s_y, 0.1, 0.5, blue_band_nm=(300, 550), yellow_band_nm=(551, 900))
    # no overlap: A1 = Φb/ΣS_b, A2 = Φy/ΣS_y, and ΣS = FWHM·√(π/C) on a fine grid
    assert g.a1_W_per_nm == pytest.approx(0.1 / (10.0 * np.sqrt(np.pi / models.C_FWHM)), rel=1e-9)
    assert g.a2_W_per_nm == pytest.approx(0.5 / (30.0 * np.sqrt(np.pi / models.C_FWHM)), rel=1e-9)
    assert g.condition == pytest.approx(max(g.matrix_nm[0][0], g.matrix_nm[1][1]) /
                                        min(g.matrix_nm[0][0], g.matrix_nm[1][1]), rel=1e-6)


def test_near_singular_two_band_system_raises_numerical_error():
    s_blue, _ = table2_spectra()
    with x64():
        nearly_same = np.asarray(models.gaussian_spectrum(WL, BLUE["peak_nm"] + 0.01, BLUE["fwhm_nm"]))
    with pytest.raises(NumericalError, match="near-singular") as exc:
        spectra.two_band_gains(WL, s_blue, nearly_same, 0.058, 0.472)
    assert "\n" not in str(exc.value)
    # a negative gain is refused too: the yellow tail alone carries more than this blue-band flux
    _, s_yellow = table2_spectra()
    with pytest.raises(NumericalError, match="negative"):
        spectra.two_band_gains(WL, s_blue, s_yellow, 0.001, 0.472)


# ---------------------------------------------------------------------------------------------- CLI
def test_fit_spectrum_cli_json_and_non_convergence_warning(tmp_path, capsys):
    import json

    from bsdfkit.cli.main import main

    _, s_yellow = table2_spectra()
    path = tmp_path / "phosphor.txt"
    path.write_text("wavelength_nm\tvalue\n" + "".join(f"{w:g}\t{v!r}\n" for w, v in zip(WL, 0.2 * s_yellow)))
    assert main(["fit", "spectrum", str(path), "--model", "split-gaussian", "--json"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["model"] == "split-gaussian" and out["converged"] is True and captured.err == ""
    assert set(out["params"]) == set(out["std"]) == {"peak_nm", "fwhm_nm", "alpha", "amplitude"}
    assert out["params"]["peak_nm"] == pytest.approx(596.7, abs=1e-6)
    assert out["params"]["alpha"] == pytest.approx(-0.12, abs=1e-8)
    assert out["params"]["amplitude"] == pytest.approx(0.2, rel=1e-8)
    assert out["r2"] == pytest.approx(1.0, abs=1e-12)
    # an iteration limit too small to converge: still a result, flagged, with one warning line per warning
    # (here also the fitted peak, 7 nm from the measured one after one step)
    assert main(["fit", "spectrum", str(path), "--model", "gaussian", "--maxiter", "1"]) == 0
    captured = capsys.readouterr()
    assert "NOT converged" in captured.out
    lines = captured.err.splitlines()
    assert all(line.startswith("bsdfkit fit: warning: phosphor.txt: ") for line in lines)
    assert sum("did not converge" in line for line in lines) == 1
