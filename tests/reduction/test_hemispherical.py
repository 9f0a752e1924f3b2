"""Hemispherical reflectance/transmittance of elastic scans (`bsdfkit.reduction.hemispherical`, `bsdfkit tis`).

Truths: a Lambertian body plus a Harvey–Shack Gaussian lobe, whose hemispherical integral is exact (ρ + the
lobe clipped by the unit disk, integrated analytically in r); a body that darkens toward grazing; the real
ansys in-plane scan of a glossy white sample (tests/data/ansys-radiant-zemax-bsdf, read with
`bsdfkit.measurement.table.read_table`).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from bsdfkit.cli.main import main
from bsdfkit.io import netcdf
from bsdfkit.measurement.table import read_table
from bsdfkit.reduction.hemispherical import hemispherical, hemispherical_profile, reduction_kind

ANSYS_CSV = Path(__file__).parent.parent / "data" / "ansys-radiant-zemax-bsdf" / (
    "inplane_spectral_goniometric_2D_data.csv")
GRID = {"n_psi": 128, "n_r": 200}  # half the library's default per axis: the tests stay fast
INCIDENCES = (0.0, 10.0, 30.0, 45.0, 60.0, 70.0, 80.0)


# --------------------------------------------------------------------------------------------- helpers
def directions(theta_i: float, two_arcs: bool, side: str = "reflection", max_deg: float = 85.0,
               step: float = 5.0, fine: float = 1.0, fine_half: float = 10.0, block: float = 3.0):
    """(θs, φs, arc) of a goniometer plan: the in-plane arc (signed angle, + on the specular side) every
    ``step`` degrees, every ``fine`` degree within ``fine_half`` of the specular direction, the source-blocked
    positions removed in reflection; with ``two_arcs`` the perpendicular arc through the specular direction
    (points β = (sin θi cos ε, sin ε))."""
    signed = np.union1d(np.arange(-max_deg, max_deg + 1e-9, step),
                        np.arange(theta_i - fine_half, theta_i + fine_half + 1e-9, fine))
    signed = signed[np.abs(signed) <= max_deg + 1e-9]
    if side == "reflection" and theta_i > 0:
        signed = signed[np.abs(signed + theta_i) > block]
    theta_s = list(np.abs(signed))
    phi_s = list(np.where(signed >= 0, 0.0, 180.0))
    arc = ["in_plane"] * signed.size
    if two_arcs:
        eps = np.radians(np.setdiff1d(np.union1d(np.arange(-60.0, 61.0, 5.0),
                                                 np.arange(-fine_half, fine_half + 1e-9, fine)), [0.0]))
        bx, by = np.sin(np.radians(theta_i)) * np.cos(eps), np.sin(eps)
        theta_s += list(np.degrees(np.arcsin(np.hypot(bx, by))))
        phi_s += list(np.degrees(np.arctan2(by, bx)) % 360.0)
        arc += ["perpendicular"] * eps.size
    return np.array(theta_s), np.array(phi_s), np.array(arc)


def make_dataset(truth, incidences=INCIDENCES, side="reflection", two_arcs=False, wavelengths=(550.0,),
                 rel_noise=0.0, seed=0, config="lamp", **plan) -> xr.Dataset:
    """A dataset in the calibrated schema (record × wavelength) from ``truth(θi, θs, φs, λ)`` [1/sr, deg, nm]."""
    rows = []
    for th in incidences:
        for ts, ps, arc in zip(*directions(th, two_arcs, side, **plan)):
            rows.append((th, ts, ps, arc))
    th, ts, ps = (np.array([r[k] for r in rows], dtype=float) for k in range(3))
    arc = np.array([r[3] for r in rows], dtype=object)
    wl = np.asarray(wavelengths, dtype=float)
    f = np.stack([truth(th, ts, ps, w) for w in wl], axis=1)
    std = rel_noise * np.abs(f)
    f = f + np.random.default_rng(seed).normal(size=f.shape) * std
    n = th.size
    ds = xr.Dataset({"bsdf": (("record", "wavelength"), f), "bsdf_std": (("record", "wavelength"), std)},
                    coords={"theta_i": ("record", th), "phi_i": ("record", np.full(n, 180.0)),
                            "theta_s": ("record", ts), "phi_s": ("record", ps),
                            "side": ("record", np.array([side] * n, dtype=object)), "arc": ("record", arc),
                            "config": ("record", np.array([config] * n, dtype=object)), "wavelength": wl})
    ds.attrs.update(quantity="bsdf", units="1/sr", source="synthetic")
    return ds


def lambert_gaussian(rho, amplitude, sigma):
    """f = ρ/π + A exp(−|β − β0|²/2σ²) with β0 = (sin θi, 0); ρ may depend on λ (a callable)."""
    def truth(th, ts, ps, wl):
        r = rho(wl) if callable(rho) else rho
        b0 = np.sin(np.radians(th))
        bx = np.sin(np.radians(ts)) * np.cos(np.radians(ps))
        by = np.sin(np.radians(ts)) * np.sin(np.radians(ps))
        return r / np.pi + amplitude * np.exp(-((bx - b0) ** 2 + by**2) / (2 * sigma**2))
    return truth


def exact_lambert_gaussian(rho, amplitude, sigma, theta_i, n_psi=4096):
    """ρ + ∫∫_{|β|≤1} A e^{−|β−β0|²/2σ²}: in polar coordinates about β0 the radial integral is analytic."""
    psi = (np.arange(n_psi) + 0.5) * 2 * np.pi / n_psi
    b0 = np.sin(np.radians(theta_i))
    t = -b0 * np.cos(psi) + np.sqrt((b0 * np.cos(psi)) ** 2 + 1 - b0 * b0)
    return rho + amplitude * sigma**2 * np.sum(-np.expm1(-t * t / (2 * sigma**2))) * 2 * np.pi / n_psi


def lobe(tis_lobe, sigma):
    """Amplitude A of a Gaussian lobe of (unclipped) integral ``tis_lobe``."""
    return tis_lobe / (2 * np.pi * sigma**2)


# --------------------------------------------------------------------------------------------- exact truths
@pytest.mark.parametrize("side, two_arcs, rho, tis_lobe, sigma", [
    ("reflection", False, 0.8, 0.05, 0.02),
    ("reflection", True, 0.5, 0.10, 0.06),
    ("transmission", False, 0.5, 0.10, 0.06),
    ("transmission", True, 0.3, 0.20, 0.15),
    ("reflection", False, 0.3, 0.20, 0.15),
])
def test_lambert_plus_lobe_within_one_percent_at_every_incidence(side, two_arcs, rho, tis_lobe, sigma):
    amp = lobe(tis_lobe, sigma)
    ds = make_dataset(lambert_gaussian(rho, amp, sigma), side=side, two_arcs=two_arcs)
    results = hemispherical(ds, **GRID)
    assert [r.theta_i for r in results] == list(INCIDENCES)
    for r in results:
        exact = exact_lambert_gaussian(rho, amp, sigma, r.theta_i)
        err = float(r.value[0] - exact)
        assert abs(err) < 0.01 * exact, (r.theta_i, r.value[0], exact)
        assert abs(err) <= r.std[0], (r.theta_i, err, r.std[0])  # the error bar covers the error
        assert r.std[0] < 0.04 * exact  # and is not a blanket
        assert r.side == side and r.lobe_region_deg is not None


def test_single_centre_reconstructions_fail_where_the_decomposition_holds():
    # a body that darkens toward grazing (symmetric about the normal) plus a lobe (symmetric about β0)
    c, a, sigma, tis_lobe = 0.9 / np.pi, 0.35, 0.03, 0.04
    amp = lobe(tis_lobe, sigma)
    gauss = lambert_gaussian(0.0, amp, sigma)

    def truth(th, ts, ps, wl):
        return c * (1 - a * np.sin(np.radians(ts)) ** 6) + gauss(th, ts, ps, wl)

    ds = make_dataset(truth, incidences=(10.0, 40.0, 60.0, 80.0))
    for r in hemispherical(ds, **GRID):
        exact = np.pi * c * (1 - a / 4) + exact_lambert_gaussian(0.0, amp, sigma, r.theta_i)
        err = abs(float(r.value[0]) - exact)
        assert err < 0.015 * exact and err <= r.std[0], (r.theta_i, r.value[0], exact)
        if r.theta_i >= 40:  # about β0 the body is read at the wrong radius
            assert abs(r.components["specular_centred"][0] - exact) > 0.03 * exact
        assert abs(r.components["normal_centred"][0] - exact) > 0.1 * exact  # the lobe smeared over a ring


def test_in_plane_only_states_its_assumptions_and_extrapolation():
    ds = make_dataset(lambert_gaussian(0.6, lobe(0.05, 0.03), 0.03), incidences=(30.0,), max_deg=80.0)
    r = hemispherical_profile(ds, "lamp", 30.0, "reflection", **GRID)
    assert r.extrapolated_beyond_deg == pytest.approx(80.0)
    text = " ".join(r.assumptions)
    assert "in-plane data only" in text and "normal" in text and "extrapolated beyond 80" in text
    assert r.components["tail"][0] > 0  # the extrapolation enters the error
    assert r.lobe_region_deg[0] < 30.0 < r.lobe_region_deg[1]
    d = r.as_dict()
    assert {"incidence_deg", "side", "wavelength_nm", "value", "std", "assumptions"} <= set(d)
    reaching = hemispherical_profile(make_dataset(lambert_gaussian(0.6, 0.0, 0.03), incidences=(30.0,),
                                                  max_deg=90.0, block=0.0), "lamp", 30.0, "reflection", **GRID)
    assert reaching.extrapolated_beyond_deg is None and "tail" not in reaching.components
    assert reaching.method == "everything about the normal (no separable specular lobe)"
    assert reaching.value[0] == pytest.approx(0.6, rel=1e-6)


def test_per_wavelength_and_band_average():
    def rho(wl):
        return 0.5 + 0.3 * (wl - 400.0) / 300.0

    wl = np.arange(400.0, 701.0, 50.0)
    amp, sigma = lobe(0.04, 0.04), 0.04
    ds = make_dataset(lambert_gaussian(rho, amp, sigma), incidences=(20.0,), two_arcs=True, wavelengths=wl)
    r = hemispherical_profile(ds, "lamp", 20.0, "reflection", **GRID)
    exact = np.array([exact_lambert_gaussian(rho(w), amp, sigma, 20.0) for w in wl])
    np.testing.assert_allclose(r.value, exact, rtol=0.01)
    band = r.band_average((450.0, 600.0))
    inside = (wl >= 450) & (wl <= 600)
    weights = np.gradient(wl[inside])
    assert band["value"] == pytest.approx(np.sum(weights * r.value[inside]) / weights.sum(), rel=1e-12)
    assert band["wavelengths"] == 4 and band["band_nm"] == [450.0, 600.0]
    assert r.band_average()["wavelengths"] == wl.size
    with pytest.raises(Exception, match="no measured wavelength in the band"):
        r.band_average((800.0, 900.0))


def test_measurement_noise_is_propagated_and_covered():
    amp, sigma = lobe(0.05, 0.03), 0.03
    z = []
    for seed in range(4):
        ds = make_dataset(lambert_gaussian(0.7, amp, sigma), incidences=(20.0, 50.0), two_arcs=True,
                          rel_noise=0.02, seed=seed)
        for r in hemispherical(ds, **GRID):
            assert r.std_measurement[0] > 0
            z.append((r.value[0] - exact_lambert_gaussian(0.7, amp, sigma, r.theta_i)) / r.std[0])
    assert np.max(np.abs(z)) < 3.0


def test_a_lobe_as_broad_as_the_arc_is_reconstructed_about_the_specular_point():
    # forward scatter of a diffuser in transmission: no floor to separate, symmetric about β0, not the normal
    amp, sigma = 0.6, 0.4
    ds = make_dataset(lambert_gaussian(0.1, amp, sigma), incidences=(30.0, 60.0), side="transmission",
                      two_arcs=True)
    for r in hemispherical(ds, **GRID):
        exact = exact_lambert_gaussian(0.1, amp, sigma, r.theta_i)
        assert r.method.startswith("everything about the specular direction")
        assert abs(r.value[0] - exact) < 0.01 * exact and abs(r.value[0] - exact) <= r.std[0] + 1e-4 * exact
        assert abs(r.components["normal_centred"][0] - exact) > 0.05 * exact


def test_which_reduction_is_decided_by_the_data():
    ds = make_dataset(lambert_gaussian(0.5, 0.0, 0.1), incidences=(45.0,))
    assert reduction_kind(ds) == "hemispherical"
    both = xr.concat([ds, make_dataset(lambert_gaussian(0.5, 0.0, 0.1), incidences=(45.0,),
                                       side="transmission")], dim="record")
    phosphor = both.assign_coords(config=("record", np.where(np.arange(both.sizes["record"]) % 2, "blue",
                                                             "yellow").astype(object)))
    phosphor["bsdf_bispectral"] = phosphor["bsdf"] / 100.0
    assert reduction_kind(phosphor) == "interactions"
    assert reduction_kind(phosphor.isel(record=np.flatnonzero(phosphor["side"].values == "reflection"))) \
        == "hemispherical"
    assert reduction_kind(phosphor.assign_attrs(elastic=1)) == "hemispherical"
    phosphor["bsdf_bispectral"] = phosphor["bsdf"] * np.nan
    assert reduction_kind(phosphor) == "hemispherical"


# --------------------------------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def ansys():
    ds = read_table(ANSYS_CSV, quantity="reflectance-factor")
    return {r.theta_i: r for r in hemispherical(ds, **GRID)}


def test_ansys_in_plane_scan_full_hemisphere_reflectance(ansys):
    assert sorted(ansys) == [10.0, 25.0, 40.0, 60.0, 80.0]
    at550 = {th: int(np.flatnonzero(r.wavelength == 550.0)[0]) for th, r in ansys.items()}
    for th in (10.0, 25.0, 40.0):
        r, j = ansys[th], at550[th]
        value, std, body = r.value[j], r.std[j], r.value[j] - r.lobe[j]
        # issue #12: 0.90-0.95 (an independent integration of the diffuse part gives 0.89 over 0-78° and about
        # 0.92 extrapolated); the specular lobe adds 0.031-0.035 on top of that body
        assert 0.90 - std <= value <= 0.95 + std, (th, value, std)
        assert 0.90 <= body <= 0.95, (th, body)
        assert 0.025 < r.lobe[j] < 0.04
        assert 0.005 < std < 0.03  # sane error bar (the specular-centred one was ±34 on 0.97)
        assert r.extrapolated_beyond_deg == pytest.approx(78.0)
        assert r.lobe_region_deg[0] < th < r.lobe_region_deg[1]
        # the specular-centred reconstruction reads the darkening body high
        assert r.components["specular_centred"][j] > value
    for th, end in ((60.0, 78.0), (80.0, 69.0)):
        r, j = ansys[th], at550[th]
        assert r.extrapolated_beyond_deg == pytest.approx(end)
        assert any("extrapolated beyond" in a for a in r.assumptions)
        assert 0.0 < r.std[j] < 0.1 * r.value[j]
    assert 0.80 < ansys[60.0].value[at550[60.0]] < 0.92
    assert 0.45 < ansys[80.0].value[at550[80.0]] < 0.65


def test_cli_hemispherical_json_for_a_measured_table(capsys):
    assert main(["tis", str(ANSYS_CSV), "--quantity", "reflectance-factor", "--incidence", "25",
                 "--band", "540", "560", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reduction"] == "hemispherical"
    (rec,) = out["hemispherical"]
    assert rec["incidence_deg"] == 25.0 and rec["side"] == "reflection"
    assert len(rec["wavelength_nm"]) == len(rec["value"]) == len(rec["std"]) == 35
    assert rec["extrapolated_beyond_deg"] == 78.0 and rec["assumptions"]
    (band,) = out["band_averaged"]
    assert band["band_nm"] == [540.0, 560.0] and band["wavelengths"] == 3
    assert 0.9 < band["value"] < 1.0 and 0 < band["std"] < 0.03


def test_cli_transmission_only_monochrome_netcdf(tmp_path, capsys):
    amp, sigma = lobe(0.1, 0.05), 0.05
    ds = make_dataset(lambert_gaussian(0.4, amp, sigma), incidences=(0.0, 40.0), side="transmission",
                      two_arcs=True, config="he-ne")
    path = netcdf.save(ds, tmp_path / "t.nc")
    assert main(["tis", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["incidence_deg"] for r in out["hemispherical"]] == [0.0, 40.0]
    for rec, band in zip(out["hemispherical"], out["band_averaged"]):
        exact = exact_lambert_gaussian(0.4, amp, sigma, rec["incidence_deg"])
        assert rec["side"] == "transmission" and rec["config"] == "he-ne"
        assert rec["value"][0] == pytest.approx(exact, rel=0.01) and band["value"] == rec["value"][0]
    assert main(["tis", str(path)]) == 0
    assert "transmission" in capsys.readouterr().out
    assert main(["tis", str(path), "--mode", "interactions"]) == 2  # one line, exit 2
    assert "incidence" in capsys.readouterr().err


def test_an_under_sampled_lobe_is_integrated_as_its_gaussian():
    # uniform 5° steps, lobe σ = 0.05 in β (2.9°): samples 1.7σ apart, where ln-f interpolation reads 4-9 % low
    amp = lobe(0.2, 0.05)
    ds = make_dataset(lambert_gaussian(0.3, amp, 0.05), incidences=(0.0, 10.0, 30.0, 45.0), step=5.0, fine=5.0,
                      fine_half=0.0)
    for r in hemispherical(ds, **GRID):
        exact = exact_lambert_gaussian(0.3, amp, 0.05, r.theta_i)
        assert abs(r.value[0] - exact) < 0.01 * exact and abs(r.value[0] - exact) <= r.std[0], (r.theta_i, r.value)


def test_a_broad_lobe_sampled_coarsely_beyond_a_fine_window_stays_out_of_the_body():
    # 1° steps within ±10° of specular, 10° steps elsewhere, lobe σ = 0.2 in β: the edge walk stops on the fine
    # samples; the body outside must be grown until symmetric about the normal (it read 0.94 as 1.54 at 60°)
    amp = lobe(0.2, 0.2)
    ds = make_dataset(lambert_gaussian(0.8, amp, 0.2), incidences=(45.0, 60.0, 70.0), step=10.0)
    for r in hemispherical(ds, **GRID):
        exact = exact_lambert_gaussian(0.8, amp, 0.2, r.theta_i)
        assert abs(r.value[0] - exact) < 0.015 * exact and abs(r.value[0] - exact) <= 2 * r.std[0], (r.theta_i,
                                                                                                    r.value)


def test_a_lobe_narrower_than_the_sampling_is_bounded_not_interpolated():
    # σ 0.01 in β (0.6°) sampled every 5°: one sample on the lobe. Interpolated as a cone it read 2.83 for 0.50.
    amp = lobe(0.2, 0.01)
    ds = make_dataset(lambert_gaussian(0.3, amp, 0.01), incidences=(0.0, 10.0), step=5.0, fine=5.0, fine_half=0.0)
    for r in hemispherical(ds, **GRID):
        exact = exact_lambert_gaussian(0.3, amp, 0.01, r.theta_i)
        assert abs(r.value[0] - exact) <= r.std[0], (r.theta_i, r.value, r.std)
        assert r.value[0] - r.std[0] <= 1.0  # never an impossible reflectance
        assert any("narrower than the sampling" in a for a in r.assumptions)


def test_an_impossible_value_is_flagged(tmp_path, capsys):
    # a Lambertian table stated as BRDF but holding reflectance factors: ρ = π·0.95 ≈ 3, far above 1
    ds = make_dataset(lambert_gaussian(0.95 * np.pi, 0.0, 0.05), incidences=(20.0,))
    r = hemispherical(ds, **GRID)[0]
    assert r.value[0] > 2.5 and r.warnings and "exceeds 1" in r.warnings[0]
    assert r.as_dict()["warnings"] == r.warnings
    ok = hemispherical(make_dataset(lambert_gaussian(0.95, 0.0, 0.05), incidences=(20.0,)), **GRID)[0]
    assert ok.warnings == []
