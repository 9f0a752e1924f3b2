"""Calibration against the virtual goniometer's noise-free truth, and the hard cases of the signal chain."""
import numpy as np
import pytest
import xarray as xr

from bsdfkit.core.errors import NumericalError
from bsdfkit.io import netcdf
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.simulation import virtual_goniometer as virtual

CONFIGS = {"blue": virtual.BLUE, "yellow": virtual.YELLOW}


def _pulls(scan, config, theta_i, side, var="bsdf"):
    gonio = virtual.VirtualGoniometer()
    truth = virtual.cl830_truth(gonio)
    sel = (scan.config.values == config) & np.isclose(scan.theta_i.values, theta_i) & (scan.side.values == side)
    sub = scan.isel(record=np.flatnonzero(sel))
    expected = gonio.expected_bsdf(truth, CONFIGS[config], theta_i, side, sub.theta_s.values, sub.phi_s.values)[var]
    value = sub[var].values
    std = sub[f"{var}_std"].values
    floor = sub["noise_floor" if var == "bsdf" else "noise_floor_bispectral"].values
    strong = np.isfinite(value) & (value > 10 * floor) & ~sub.saturated.values
    return (value[strong] - expected[strong]) / std[strong]


@pytest.mark.parametrize("theta_i", [5.0, 45.0, 56.0])
@pytest.mark.parametrize("side", ["reflection", "transmission"])
def test_recovered_bsdf_within_3_sigma(bundled_scan, theta_i, side):
    """Acceptance: ≥ 99 % of strong-signal values within 3 standard uncertainties of the truth."""
    for config in ("blue", "yellow"):
        z = _pulls(bundled_scan, config, theta_i, side)
        assert z.size > 1000
        assert np.mean(np.abs(z) <= 3) >= 0.99
        # and the uncertainty is not inflated: the pulls have unit spread
        assert 0.9 < np.std(z) < 1.1
    z = _pulls(bundled_scan, "blue", theta_i, side, var="bsdf_bispectral")
    assert np.mean(np.abs(z) <= 3) >= 0.99


def test_dataset_tags_and_units(bundled_scan):
    ds = bundled_scan
    assert ds.attrs["quantity"] == "bsdf" and ds.attrs["frame"] == "sample"
    assert ds.attrs["units"] == "1/sr" and set(ds.attrs["side"].split()) == {"reflection", "transmission"}
    for key in ("detector_distance_mm", "aperture_diameter_mm", "beam_diameter_mm", "solid_angle_sr"):
        assert key in ds.attrs
    assert ds["bsdf"].attrs["units"] == "1/sr"
    assert ds["bsdf_bispectral"].attrs["units"] == "1/(sr nm)"
    assert ds["theta_s"].attrs["units"] == "deg"
    # incident spectra are normalised to a unit integral
    for c in ds.configuration.values:
        spec = ds.incident_spectrum.sel(configuration=c).values
        assert np.sum(spec * np.gradient(ds.wavelength.values)) == pytest.approx(1.0, rel=1e-12)
    # bsdf is defined exactly where the incident light is (and nowhere else)
    blue = ds.isel(record=np.flatnonzero(ds.config.values == "blue"))
    defined = np.isfinite(blue["bsdf"].values).any(axis=0)
    assert np.array_equal(defined, ds.incident_valid.sel(configuration="blue").values)
    assert not np.isinf(ds["bsdf"].values).any()


def test_netcdf_round_trip_is_lossless(bundled_scan, tmp_path):
    path = netcdf.save(bundled_scan, tmp_path / "scan.nc")
    back = netcdf.load(path, quantity="bsdf")
    xr.testing.assert_identical(bundled_scan, back)
    assert back.attrs == bundled_scan.attrs


def test_negative_values_after_dark_subtraction_are_kept(bundled_scan):
    """Where no light arrives (blue configuration, 600-700 nm at grazing-free diffuse positions is converted
    light; 380-440 nm is dark) the net signal scatters around zero and negatives survive unclipped."""
    blue = bundled_scan.isel(record=np.flatnonzero(bundled_scan.config.values == "blue"))
    dark_band = blue.bsdf_bispectral.sel(wavelength=slice(380, 430)).values
    assert (dark_band < 0).mean() > 0.3
    # unbiased: the mean of pure-noise values is compatible with zero
    z = dark_band / blue.bsdf_bispectral_std.sel(wavelength=slice(380, 430)).values
    assert abs(z.mean()) < 5 / np.sqrt(z.size) + 0.05


def test_grazing_positions_are_masked_not_infinite(tiny_export):
    raw = read_scan(tiny_export)
    raw = raw.assign_coords(theta_s=("record", np.where(np.arange(raw.sizes["record"]) == 0, 90.0, raw.theta_s.values)))
    ds = calibrate(raw)
    assert bool(ds.grazing.values[0]) and not ds.grazing.values[1:].any()
    assert np.isnan(ds["bsdf"].values[0]).all()
    assert np.isfinite(ds["bsdf"].values[1:]).any() and not np.isinf(ds["bsdf"].values).any()


def test_zero_incident_power_is_a_clear_error(tiny_export):
    raw = read_scan(tiny_export)
    t_ref = raw.reference_exposure.values[0]
    dark_level = raw.dark_counts.values[raw.dark_exposure.values == t_ref].mean(axis=0)
    raw["reference_counts"] = (("reference_record", "wavelength"),
                               np.broadcast_to(dark_level, raw.reference_counts.shape).copy())
    with pytest.raises(NumericalError, match="zero incident power"):
        calibrate(raw)


def test_saturated_pixels_are_flagged(tiny_export):
    raw = read_scan(tiny_export)
    counts = raw.counts.values.copy()
    counts[0, 10] = raw.attrs["full_scale_counts"]
    raw["counts"] = (("record", "wavelength"), counts)
    ds = calibrate(raw)
    assert bool(ds.saturated.values[0, 10]) and ds.saturated.values.sum() == 1
