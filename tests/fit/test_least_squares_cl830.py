"""Acceptance: lobe fits on cl830-synthetic recover the truth, and the fitted models carry the measured TIS."""
import numpy as np
import pytest

from bsdfkit.fit.least_squares import fit_bsdf
from bsdfkit.reduction import spectral
from bsdfkit.reduction import tis as angular
from bsdfkit.simulation import truth as synthetic
from bsdfkit.simulation import virtual_goniometer as virtual

BANDS = {"bibs": (virtual.BLUE, (450.0, 470.0)), "yiys": (virtual.YELLOW, (470.0, 740.0))}
# 36 z-scores are tested (2 interactions x 2 sides x 3 incidences x 3 parameters) on one noise realisation:
# |z| < 3.64 keeps the family-wise false-alarm rate at 1 % (Bonferroni, two-sided), and the RMS of the nine
# z-scores of each test below 2 keeps the test sensitive to a bias shared by the parameters.
Z_LIMIT = 3.64
Z_RMS_LIMIT = 2.0


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
    zs = []
    for th in (5.0, 45.0, 56.0):
        row = fit.sel(theta_i=th)
        assert bool(row["converged"])
        # the profile is the spectrally weighted mean (eq. 5/8): the truth's amplitudes carry ⟨m(λ)⟩
        m = synthetic.weighted_mean(lam, truth.elastic_spectral(interaction, side, np.radians(th), lam),
                                    config.incident_power(lam, 1.0), band)
        p = truth.lobe(interaction, side, np.radians(th))
        for name, value in (("rho", p.rho * m), ("A", p.A * m), ("sigma", p.sigma)):
            z = (float(row[name]) - value) / float(row[f"{name}_std"])
            zs.append(z)
            assert abs(z) < Z_LIMIT, (interaction, side, th, name, z)
        measured = float(tis_table["tis"].sel(interaction=interaction, side=side, theta_i=th))
        assert abs(float(row["tis"]) - measured) < 0.01
    assert float(np.sqrt(np.mean(np.square(zs)))) < Z_RMS_LIMIT, zs
