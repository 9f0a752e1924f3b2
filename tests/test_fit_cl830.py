"""Acceptance: lobe fits on cl830-synthetic recover the truth, and the fitted models carry the measured TIS."""
import numpy as np
import pytest

from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.reduction import spectral
from bsdfkit.reduction import tis as angular
from bsdfkit.simulation import truth as synthetic
from bsdfkit.simulation import virtual_goniometer as virtual

BANDS = {"bibs": (virtual.BLUE, (450.0, 470.0)), "yiys": (virtual.YELLOW, (470.0, 740.0))}


@pytest.fixture(scope="module")
def tis_table(bundled_scan):
    return angular.tis_table(bundled_scan)


@pytest.mark.parametrize("interaction", ["bibs", "yiys"])
@pytest.mark.parametrize("side", ["reflection", "transmission"])
def test_lambert_gaussian_recovers_truth_and_tis(bundled_scan, tis_table, interaction, side):
    prof = spectral.interaction_profile(bundled_scan, interaction, side)
    prof = prof.isel(record=np.flatnonzero(np.isfinite(prof["bsdf"].values)))
    fit = fit_bsdf(prof, "lambert+gaussian")
    assert fit.attrs["aperture_averaged"] == 1
    gonio = virtual.VirtualGoniometer()
    truth = virtual.cl830_truth(gonio)
    lam = gonio.spectrometer.wavelength
    config, band = BANDS[interaction]
    for th in (5.0, 45.0, 56.0):
        row = fit.sel(theta_i=th)
        assert bool(row["converged"])
        # the profile is the spectrally weighted mean (eq. 5/8): the truth's amplitudes carry ⟨m(λ)⟩
        m = synthetic.weighted_mean(lam, truth.elastic_spectral(interaction, side, np.radians(th), lam),
                                    config.incident_power(lam, 1.0), band)
        p = truth.lobe(interaction, side, np.radians(th))
        for name, value in (("rho", p.rho * m), ("A", p.A * m), ("sigma", p.sigma)):
            z = (float(row[name]) - value) / float(row[f"{name}_std"])
            assert abs(z) < 3, (interaction, side, th, name, z)
        measured = float(tis_table["tis"].sel(interaction=interaction, side=side, theta_i=th))
        assert abs(float(row["tis"]) - measured) < 0.01
