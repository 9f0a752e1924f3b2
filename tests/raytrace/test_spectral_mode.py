"""The tracer's spectral mode (issue 17): equivalence with the two-wavelength mode, the exact spectral module
budget with re-absorption at every 10 nm, ledgers in power and photons, photons at a conversion, spectral
surfaces (the Spectralon standard of tests/data/grit-spectralon) and the scene's errors."""
from __future__ import annotations

import functools
import json
import math
from dataclasses import replace
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TRACE_LANES

from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.fit.lambertian import band_weighted_reflectance, lambertian_from_reflectance
from bsdfkit.raytrace import PhosphorPlate, dumps_scene, kernel, loads_scene, trace
from bsdfkit.raytrace.effects import kernel_params, scene_effects
from bsdfkit.raytrace.oracles.spectral_budget import spectral_module_budget
from bsdfkit.raytrace.scene import band_reflectances, scene_spectral_tables, surface_reflectance_table
from bsdfkit.raytrace.spectral import (
    SpectralPlateModel,
    model_on_bins,
    photon_pdf_from_power,
    spectral_model_from_dataset,
    spectral_plate_from_two_colour,
)

ROOT = Path(__file__).resolve().parents[2]
SPECTRALON = Path(__file__).parent.parent / "data" / "grit-spectralon" / "Spectralon_Num4.txt"
TABLE2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
          "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}
CHUNK, LANES = 50_000, TRACE_LANES
PLATE_TOP = ('kind = "phosphor"\n[top.plate]\ntheta_i_deg = [0.0, 90.0]\n'
             + "".join(f'{i} = {{reflection = {{tis = [{TABLE2[i + "_reflection"]}, {TABLE2[i + "_reflection"]}]}}, '
                       f'transmission = {{tis = [{TABLE2[i + "_transmission"]}, {TABLE2[i + "_transmission"]}]}}}}\n'
                       for i in ("bibs", "biys", "yiys")))


def scene_text(top: str, mode: str = "spectral", wall: str = "reflectance = 0.9", extra: str = "") -> str:
    return f"""
[cavity]
radius_mm = 35.0
height_mm = 43.0
[wall]
{wall}
[base]
reflectance = 0.9
[leds]
count = 4
spectrum_peak_nm = 455.0
spectrum_fwhm_nm = 20.0
[top]
{top}
[trace]
mode = "{mode}"
{extra}
"""


def model_file(tmp_path, model: SpectralPlateModel, name="model.nc") -> Path:
    path = tmp_path / name
    model.save(path)
    return path


def run(s, rays, seed):
    r = trace(s, rays, seed, chunk=CHUNK, lanes=LANES)
    assert r.ledger_error <= 1e-9
    if r.spectral is not None:
        assert r.spectral.ledger["power_W"]["error"] <= 1e-9
        assert r.spectral.ledger["photons_per_s"]["error"] <= 1e-9
    return r


def no_overlap_model() -> SpectralPlateModel:
    """Table 2 plate, emission zero at and below 500 nm: one emission spectrum times one absorption value."""
    wl = np.arange(380.0, 781.0, 5.0)
    emission = np.where(wl > 505.0, np.exp(-4 * math.log(2) * ((wl - 580.0) / 100.0) ** 2), 0.0)
    return spectral_plate_from_two_colour(PhosphorPlate.constant(TABLE2), wl, emission)


@pytest.mark.slow
def test_spectral_mode_equals_the_two_wavelength_mode_without_overlap(tmp_path):
    path = PhosphorPlate.constant(TABLE2).save(tmp_path / "plate.json")
    spectral = loads_scene(scene_text(f'kind = "phosphor"\nplate = "{path}"\n'
                                      f'spectral = "{model_file(tmp_path, no_overlap_model())}"'))
    two = replace(spectral, trace=replace(spectral.trace, mode="two-wavelength"))
    a, b = run(spectral, 200_000, 31), run(two, 200_000, 32)
    for colour in ("blue", "yellow"):
        se = math.hypot(a.std_err[colour], b.std_err[colour])
        z = (a.extracted[colour] - b.extracted[colour]) / se
        assert abs(z) <= 3, (colour, a.extracted[colour], b.extracted[colour], se)
    # the band powers of the spectrum are the same blue and yellow powers
    bands = a.to_dict()["spectral"]["bands"]
    assert bands["blue"]["power_W"] == pytest.approx(a.extracted["blue"], rel=1e-9)
    assert bands["yellow"]["power_W"] == pytest.approx(a.extracted["yellow"], rel=1e-9)
    assert a.spectral.ledger["power_W"]["stokes"] > 0


@pytest.mark.slow
def test_spectral_mode_matches_the_spectral_budget_with_reabsorption_at_every_10nm(tmp_path):
    """An emission overlapping the pump band (re-absorption), a Spectralon wall, 10 nm bins: exact oracle."""
    top = (PLATE_TOP + "[top.spectral]\nemission_peak_nm = 540.0\nemission_fwhm_nm = 130.0\nstep_nm = 10.0\n")
    s = loads_scene(scene_text(top, wall=f'reflectance_spectrum = "{SPECTRALON}"'))
    ref = spectral_module_budget(s, n_base=24, n_wall=48, n_top=24)
    r = run(s, 150_000, 41)
    sp = r.spectral
    assert sp.step_nm == 10.0
    got, se = sp.spectrum_W_per_nm * 10.0 / s.leds.power_W, sp.spectrum_std_err * 10.0 / s.leds.power_W
    traced = se > 0
    z = (got[traced] - ref.extracted[traced]) / se[traced]
    assert np.all(np.abs(z) <= 3), (sp.wavelength_nm[traced][np.argmax(np.abs(z))], np.abs(z).max())
    assert np.all(ref.extracted[~traced] < 1e-4)  # bins no traced ray reached carry (almost) nothing exactly
    assert abs(r.LER - ref.extracted.sum()) <= 3 * r.std_err["LER"]
    loss = (r.absorbed["plate"] + sp.ledger["power_W"]["stokes"]) / s.leds.power_W
    assert abs(loss - ref.plate_loss) <= 3 * r.std_err["absorbed_plate"] / s.leds.power_W + 1e-3 * ref.plate_loss
    # re-absorption matters here: converted light below 500 nm is absorbed again, so the blue band holds less than
    # a plate that would pass it through
    assert ref.extracted[sp.wavelength_nm <= 500].sum() > 0


def test_photons_never_increase_at_a_plate_interaction():
    """The kernel's spectral plate step on random lanes: photons out ≤ photons in; a conversion keeps the photon."""
    wl = np.arange(380.0, 781.0, 5.0)
    model = spectral_plate_from_two_colour(PhosphorPlate.constant(TABLE2), wl,
                                           np.exp(-4 * math.log(2) * ((wl - 540.0) / 130.0) ** 2))
    s = loads_scene(scene_text(PLATE_TOP + "[top.spectral]\nemission_peak_nm = 540.0\nemission_fwhm_nm = 130.0\n"))
    s = replace(s, top=replace(s.top, spectral_model=model))
    eff = scene_effects(s)
    L = 20_000
    rng = np.random.default_rng(5)
    with x64():
        params = jax.tree_util.tree_map(jnp.asarray, kernel_params(s, eff))
        u = [jnp.asarray(rng.random(L)) for _ in range(8)]
        k = jnp.asarray(rng.integers(0, wl.size, L), jnp.int32)
        w = jnp.asarray(rng.random(L) + 0.05)
        t = jnp.asarray(rng.random(L))
        j = jnp.zeros(L, jnp.int32)
        key = jnp.zeros(2, jnp.uint32)
        w_out, absorbed, conversions, forward, new_k, channel, g = kernel._spectral_channel(
            params, key, u, w, k, t, j)
    stokes = conversions[0]
    lam = np.asarray(params.spectral.lam)
    w, w_out, k, new_k = (np.asarray(a) for a in (w, w_out, k, new_k))
    photons_in, photons_out = w * lam[k], w_out * lam[new_k]
    assert np.all(photons_out <= photons_in * (1 + 1e-15))
    converted = new_k != k
    assert converted.sum() > 1000
    kept = (w - np.asarray(absorbed)) * lam[k]
    np.testing.assert_allclose(photons_out, kept, rtol=1e-14)  # the converted photon keeps its number
    np.testing.assert_allclose(np.asarray(absorbed) + np.asarray(stokes) + w_out, w, rtol=1e-14)
    # new bins follow the conditional emission row of their excitation bin: mean wavelength within 4 SE
    rows = scene_spectral_tables(s).emission_pdf[k[converted]] * 5.0
    drawn = lam[new_k][converted]
    means = (rows * lam).sum(axis=1)
    var = ((rows * lam ** 2).sum(axis=1) - means ** 2).mean()
    assert abs(drawn.mean() - means.mean()) <= 4 * math.sqrt(var / drawn.size)
    assert np.mean(np.asarray(stokes)[converted] > 0) > 0.9  # mostly down-conversion
    # the conversion tallies: photons converted, of them to a shorter bin, and the power those created
    ph_conv, ph_anti, gain = (np.asarray(a) for a in conversions[1:])
    scale = lam / lam[-1]
    kept_w = w - np.asarray(absorbed)
    channel_converted = np.asarray(channel) == 1  # conversions, into the same bin included
    assert np.all(channel_converted[converted])
    np.testing.assert_allclose(ph_conv, np.where(channel_converted, kept_w * scale[k], 0.0), rtol=1e-14)
    anti = converted & (new_k < k)
    np.testing.assert_allclose(ph_anti, np.where(anti, kept_w * scale[k], 0.0), rtol=1e-14)
    np.testing.assert_allclose(gain, np.where(anti, w_out - kept_w, 0.0), rtol=1e-12, atol=1e-15)
    assert anti.any() and np.all(gain >= 0)


def test_photon_pdf_and_two_colour_model():
    wl = np.arange(400.0, 701.0, 10.0)
    power = np.ones_like(wl)
    p = photon_pdf_from_power(wl, power)
    assert p.sum() * 10.0 == pytest.approx(1.0, rel=1e-14)
    assert p[-1] / p[0] == pytest.approx(700.0 / 400.0, rel=1e-14)  # photons ∝ S·λ
    m = spectral_plate_from_two_colour(PhosphorPlate.constant(TABLE2), wl, power)
    ds = m.to_dataset()
    assert float(ds["converted_tis"].sel(side="transmission", excitation=450.0).isel(incidence=0)) == 0.257
    assert float(ds["converted_tis"].sel(side="reflection", excitation=600.0).isel(incidence=0)) == 0.0
    assert float(ds["elastic_tis"].sel(side="reflection", excitation=600.0).isel(incidence=0)) == 0.457


def test_unphysical_and_malformed_models_are_refused(tmp_path):
    m = no_overlap_model().to_dataset()
    bad = m.copy(deep=True)
    bad["converted_tis"][:] = bad["converted_tis"] * 1.9  # converted photons beyond the incident ones
    with pytest.raises(ValidationError, match="more photons than it receives"):
        spectral_model_from_dataset(bad, source="bad.nc")
    bad = m.copy(deep=True)
    bad["emission_pdf"][:] = bad["emission_pdf"] * 2.0
    with pytest.raises(ValidationError, match="integrate to 1"):
        spectral_model_from_dataset(bad, source="bad.nc")
    with pytest.raises(InputError, match="missing variable"):
        spectral_model_from_dataset(m.drop_vars("emission_pdf"), source="bad.nc")


def test_measured_model_within_its_noise_is_capped_and_listed():
    """A measured model a little above one photon out per photon in, within 3 standard uncertainties, is scaled
    down to exactly one (and listed); the sides may come in any order."""
    wl = np.arange(380.0, 781.0, 5.0)
    plate = PhosphorPlate.constant({"bibs_reflection": 0.10, "bibs_transmission": 0.05, "biys_reflection": 0.12,
                                    "biys_transmission": 0.08, "yiys_reflection": 0.5, "yiys_transmission": 0.5})
    ds = spectral_plate_from_two_colour(plate, wl, np.where(wl > 505, 1.0, 0.0)).to_dataset()
    ds["converted_tis"] = ds["converted_tis"] * 2.75  # biys 0.33 / 0.22: too many photons at short pump wavelengths
    harmonic = 1.0 / (photon_pdf_from_power(wl, np.where(wl > 505, 1.0, 0.0)) * 5.0 / wl).sum()
    kept = 0.15 + 0.55 * harmonic / wl  # photons out per photon in at each pump wavelength
    assert kept[wl <= 500].max() > 1.0
    noisy = ds.isel(side=[1, 0]).assign(converted_tis_std=ds["converted_tis"].isel(side=[1, 0]) * 0.2,
                                        elastic_tis_std=ds["elastic_tis"].isel(side=[1, 0]) * 0.0)
    m = spectral_model_from_dataset(noisy, source="measured.nc")
    assert m.capped and all(v > 1 for *_, v in m.capped)
    ph = (m.elastic_tis + m.converted_tis * (harmonic / wl)).sum(axis=0)
    assert ph.max() == pytest.approx(1.0, abs=1e-12)
    assert m.elastic_tis[0, 0, -1] == 0.5 and m.converted_tis[1, 0, -1] == 0.0  # reflection first again
    assert m.converted_tis[0, 0, 20] == pytest.approx(0.33) and m.converted_tis[1, 0, 20] == pytest.approx(0.22)
    with pytest.raises(ValidationError, match="more photons"):
        spectral_model_from_dataset(ds, source="measured.nc")  # the same excess without uncertainties


def test_scene_errors_name_the_key(tmp_path):
    with pytest.raises(InputError, match="leds.spectrum"):
        loads_scene(scene_text('kind = "exit"').replace("spectrum_peak_nm = 455.0\nspectrum_fwhm_nm = 20.0\n", ""))
    with pytest.raises(InputError, match="wall.reflectance"):
        loads_scene(scene_text('kind = "exit"', wall=f'reflectance = 0.9\nreflectance_spectrum = "{SPECTRALON}"'))
    with pytest.raises(InputError, match="top.spectral"):
        plate = PhosphorPlate.constant(TABLE2).save(tmp_path / "p.json")
        loads_scene(scene_text(f'kind = "phosphor"\nplate = "{plate}"'))
    with pytest.raises(ValidationError, match="trace.mode"):
        loads_scene(scene_text('kind = "exit"', mode="rainbow"))


def test_spectralon_wall_band_weighted_in_two_wavelength_mode():
    s = loads_scene(scene_text('kind = "exit"', mode="two-wavelength", wall=f'reflectance_spectrum = "{SPECTRALON}"'))
    wl, rho, std = np.loadtxt(SPECTRALON, unpack=True)
    model = lambertian_from_reflectance(wl, rho, std)
    led_wl, led = s.leds.spectrum
    blue = band_weighted_reflectance(model, led_wl, led, (380.0, 500.0))
    lam = np.arange(501.0, 781.0)
    yellow = band_weighted_reflectance(model, lam, np.ones_like(lam), (501.0, 780.0))
    assert band_reflectances(s.wall, s.leds) == pytest.approx((blue, yellow), rel=1e-12)
    assert s.wall.reflectance == pytest.approx(blue, rel=1e-12)
    table = surface_reflectance_table(s).reshape(3, 2)
    assert table[0] == pytest.approx([blue, yellow], rel=1e-12) and np.all(table[1:] == 0.9)
    eff = scene_effects(s)
    assert eff.surface_spectra and not eff.spectral
    assert 0.97 < blue < 1.0 and 0.97 < yellow < 1.0


@pytest.mark.slow  # 60 000 rays against the spectral budget oracle (4 s); the fast lane's spectral traces:
# test_spectral_budget_books_the_stokes_loss_with_the_plate and test_example_spectral_scene_runs_from_the_command_line
def test_spectral_exit_top_with_spectralon_walls_matches_the_budget():
    """No plate: the extracted spectrum is the LED spectrum times the cavity's efficiency at each wavelength."""
    s = loads_scene(scene_text('kind = "exit"', wall=f'reflectance_spectrum = "{SPECTRALON}"',
                               extra="spectral_grid_nm = [400.0, 520.0, 10.0]"))
    ref = spectral_module_budget(s, n_base=24, n_wall=48, n_top=24)
    r = run(s, 60_000, 7)
    sp = r.spectral
    got, se = sp.spectrum_W_per_nm * sp.step_nm, sp.spectrum_std_err * sp.step_nm
    traced = se > 0
    assert np.all(np.abs(got[traced] - ref.extracted[traced]) <= 3 * se[traced])
    assert r.spectral.ledger["power_W"]["stokes"] == 0.0
    # the LED's bins as sampled follow its spectrum
    assert sp.emitted_W_per_nm.sum() * sp.step_nm == pytest.approx(1.0, rel=1e-12)


def test_two_wavelength_kernel_carries_no_spectral_code(tmp_path):
    path = PhosphorPlate.constant(TABLE2).save(tmp_path / "plate.json")
    two = loads_scene(scene_text(f'kind = "phosphor"\nplate = "{path}"', mode="two-wavelength"))
    spectral = loads_scene(scene_text(f'kind = "phosphor"\nplate = "{path}"\n'
                                      f'spectral = "{model_file(tmp_path, no_overlap_model())}"'))
    texts = []
    for s in (two, spectral):
        eff = scene_effects(s)
        with x64():
            low = kernel.trace_chunk_jit.lower(kernel_params(s, eff), np.zeros(2, np.uint32), np.uint32(0),
                                               np.int32(256), effects=eff, lanes=256)
        texts.append(low.as_text(debug_info=True))
    for scope in ("spectral_conversion", "extracted_spectrum"):
        assert scope not in texts[0] and scope in texts[1], scope
    assert "surface_spectra" not in texts[0] + texts[1]


def test_example_spectral_scene_runs_from_the_command_line(tmp_path, capsys):
    from bsdfkit.cli.main import main

    code = main(["trace", str(ROOT / "fitting" / "scenes" / "spectral_example.toml"), "--rays", "4000",
                 "--json", "--chunk", "4000", "--lanes", "512"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "spectral"
    sp = out["spectral"]
    assert sp["ledger"]["power_W"]["error"] <= 1e-9 and sp["ledger"]["photons_per_s"]["error"] <= 1e-9
    assert len(sp["wavelength_nm"]) == len(sp["spectrum_W_per_nm"]) == len(sp["spectrum_std_err_W_per_nm"])
    assert 150 < sp["luminous_efficacy_lm_per_W"] < 500
    assert sp["bands"]["blue"]["label"] == "380-500 nm"


def _overlap_scene():
    return loads_scene(scene_text(PLATE_TOP + "[top.spectral]\nemission_peak_nm = 540.0\nemission_fwhm_nm = 130.0\n",
                                  wall=f'reflectance_spectrum = "{SPECTRALON}"'))


@functools.cache
def _overlap_traced():
    """12 000 rays of the re-absorbing plate in chunks of 3 000 (traced once per process: two tests read it)."""
    return trace(_overlap_scene(), 12_000, 9, chunk=3_000, lanes=512)


def test_spectral_budget_books_the_stokes_loss_with_the_plate():
    """The interaction budget books the Stokes loss with the plate: nothing is left in flight."""
    a = _overlap_traced()
    assert a.cumulative_budget()["in_flight"][-1] == pytest.approx(0.0, abs=1e-9)
    assert a.cumulative_budget()["extracted"][-1] == pytest.approx(a.extracted["total"], abs=1e-9)


@pytest.mark.slow  # two more compilations; the fast lane's chunk invariance: test_kernel.py (1e4 and 1e5)
def test_spectral_results_do_not_depend_on_chunks_or_the_full_kernel():
    """Exact fixed-point sums: chunking and compiling every optional branch change nothing, bit for bit."""
    s = _overlap_scene()
    a = _overlap_traced()
    b = trace(s, 12_000, 9, chunk=12_000, lanes=256)
    c = trace(s, 12_000, 9, chunk=12_000, lanes=512, full_kernel=True)
    for r in (b, c):
        assert r.extracted == a.extracted and r.absorbed == a.absorbed
        np.testing.assert_array_equal(r.spectral.spectrum_W_per_nm, a.spectral.spectrum_W_per_nm)
        np.testing.assert_array_equal(r.spectral.spectrum_std_err, a.spectral.spectrum_std_err)
        assert r.spectral.ledger == a.spectral.ledger


def test_spectral_scene_round_trips_through_toml(tmp_path):
    path = model_file(tmp_path, no_overlap_model())
    s = loads_scene(scene_text(f'kind = "phosphor"\nspectral = "{path}"',
                               wall=f'reflectance_spectrum = "{SPECTRALON}"'))
    assert s.top.plate is None  # a model file alone: Lambertian angular distributions
    again = loads_scene(dumps_scene(s))
    assert again.trace.mode == "spectral" and again.top.spectral_file == str(path)
    assert again.wall.spectrum_file == str(SPECTRALON) and again.wall.reflectance == s.wall.reflectance
    assert (again.leds.spectrum_peak_nm, again.leds.spectrum_fwhm_nm) == (455.0, 20.0)
    with pytest.raises(InputError, match="top.plate"):  # the two-wavelength mode needs the plate itself
        loads_scene(dumps_scene(s).replace('mode = "spectral"', 'mode = "two-wavelength"'))


def test_bins_above_an_excitation_scan_take_the_plates_yiys():
    """A monochromator-style model (excitation 400-500 nm only) traced on a 380-780 nm grid: above 500 nm the
    plate's yiys, no conversion; below 400 nm the first excitation's values."""
    wl = np.arange(380.0, 781.0, 10.0)
    full = spectral_plate_from_two_colour(PhosphorPlate.constant(TABLE2), wl,
                                          np.exp(-4 * math.log(2) * ((wl - 560.0) / 100.0) ** 2)).to_dataset()
    scan = spectral_model_from_dataset(full.sel(excitation=slice(400.0, 500.0)))
    plate = PhosphorPlate.constant(TABLE2)
    elastic, converted, pdf = model_on_bins(scan, plate)
    above, below = wl > 500, wl < 400
    assert np.all(elastic[0][:, above] == 0.457) and np.all(elastic[1][:, above] == 0.471)
    assert np.all(converted[:, :, above] == 0.0)
    assert np.all(elastic[0][:, below] == 0.109) and np.all(converted[1][:, below] == 0.257)
    np.testing.assert_allclose(pdf[below].sum(axis=1) * 10.0, 1.0, rtol=1e-12)
    clamped, _, _ = model_on_bins(scan)  # no plate: the last excitation's values
    assert np.all(clamped[0][:, above] == 0.109)


def test_unphysical_model_file_is_one_line_error_exit_2(tmp_path, capsys):
    from bsdfkit.cli.main import main

    ds = no_overlap_model().to_dataset()
    ds["converted_tis"] = ds["converted_tis"] * 1.9
    bad = tmp_path / "bad.nc"
    ds.to_netcdf(bad)
    scene = tmp_path / "scene.toml"
    scene.write_text(scene_text(f'kind = "phosphor"\nspectral = "{bad}"'))
    assert main(["trace", str(scene), "--rays", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "bad.nc" in err and "more photons" in err and "excitation=" in err
