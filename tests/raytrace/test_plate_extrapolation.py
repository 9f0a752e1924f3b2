"""The main job's plate beyond the measured incidences (issue #16): model-extrapolated, energy-conserving.

The bundled measurement has incidences 5, 45 and 56 deg; the cavity lights the plate from 0 to 90 deg. The plate
keeps the measured TIS where measured and takes the fitted models' incidence dependence elsewhere
(:func:`bsdfkit.pipeline.plate_from_scan.extrapolated_tis`), so the tracer never clamps.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from bsdfkit.pipeline.plate_from_scan import EXTRAPOLATED_NOTE, extrapolated_tis, plate_from_scan
from bsdfkit.raytrace.plate import CHANNELS, PhosphorPlate, plate_tables
from bsdfkit.reduction.tis import tis_table
from bsdfkit.simulation import truth as synthetic
from bsdfkit.simulation.virtual_goniometer import BLUE, YELLOW, VirtualGoniometer, cl830_truth

TAGS = {"bibs_reflection": "B_bibs", "bibs_transmission": "F_bibs", "biys_reflection": "B_biys",
        "biys_transmission": "F_biys", "yiys_reflection": "B_yiys", "yiys_transmission": "F_yiys"}


@pytest.fixture(scope="module")
def plates(bundled_scan):
    tis = tis_table(bundled_scan)
    return tis, plate_from_scan(bundled_scan, tis), plate_from_scan(bundled_scan, tis, extrapolate=False)


def test_extended_plate_covers_the_hemisphere_and_keeps_the_measured_tis(plates):
    tis, plate, measured_only = plates
    assert measured_only.theta_i_deg == (5.0, 45.0, 56.0)
    assert plate.theta_i_deg[0] == 0.0 and plate.theta_i_deg[-1] == 90.0
    assert plate_tables(plate).covers_hemisphere and not plate_tables(measured_only).covers_hemisphere
    assert EXTRAPOLATED_NOTE in plate.notes and EXTRAPOLATED_NOTE not in measured_only.notes
    for name in CHANNELS:
        inter, side = name.split("_")
        for t in (5.0, 45.0, 56.0):
            k = plate.theta_i_deg.index(t)
            assert plate.channel(name).tis[k] == pytest.approx(
                float(tis["tis"].sel(interaction=inter, side=side, theta_i=t)), abs=1e-15)
            assert plate.channel(name).distributions[k] == measured_only.channel(name).distributions[
                measured_only.theta_i_deg.index(t)]


def test_extended_plate_conserves_energy_at_every_incidence(plates):
    _, plate, _ = plates
    tables = plate_tables(plate)
    blue = tables.tis[:, :4].sum(axis=1)
    yellow = tables.tis[:, 4:].sum(axis=1)
    assert np.all(tables.tis >= 0.0)
    assert np.all(blue <= 1.0 + 1e-12) and np.all(yellow <= 1.0 + 1e-12)
    # the plate absorbs: losses 0.3 (blue) and 0.07 (yellow) at 45 deg stay positive everywhere
    assert blue.max() < 0.8 and yellow.max() < 0.97


def test_a_colour_that_would_scatter_more_than_it_receives_is_scaled_to_one(bundled_scan, plates):
    """A lossless yellow channel at the grid edge: extrapolated sums must not exceed 1 (they are scaled down)."""
    tis = plates[0].copy(deep=True)  # tis_table(bundled_scan), made once for the module
    sel = {"interaction": "yiys", "theta_i": 5.0}
    # nearly all yellow light scattered at 5 deg: the lobe grows towards normal incidence, so 0 deg would exceed 1
    r, t = (float(tis["tis"].sel(side=s, **sel)) for s in ("reflection", "transmission"))
    tis["tis"].loc[{"interaction": "yiys", "side": "transmission", "theta_i": 5.0}] = 1.0 - r
    plate = plate_from_scan(bundled_scan, tis)
    k0 = plate.theta_i_deg.index(0.0)
    total = plate.yiys_reflection.tis[k0] + plate.yiys_transmission.tis[k0]
    assert total <= 1.0 + 1e-12
    assert t < 1.0 - r  # the edit did raise the measured sum to 1


def test_a_narrow_lobe_keeps_half_its_scatter_at_grazing_incidence():
    """Closed form: a Gaussian lobe of width σ ≪ 1 centred on the rim of the unit disk has half its mass inside
    (the rim is straight on the scale of σ, to O(σ)); its Lambertian part is independent of incidence."""
    rho, a, sigma = 0.05, 3.0, 0.01
    lobe_full = 2 * math.pi * sigma ** 2 * a
    measured = rho + lobe_full  # the lobe is well inside the disk at 30 deg
    got = extrapolated_tis(measured, "lambert+gaussian", {"rho": rho, "A": a, "sigma": sigma}, 30.0,
                           np.array([30.0, 90.0]))
    assert got[0] == pytest.approx(measured, rel=1e-9)
    assert (got[1] - rho) / lobe_full == pytest.approx(0.5, abs=2 * sigma)
    assert extrapolated_tis(0.26, "lambert", {"rho": 0.26}, 56.0, np.array([70.0, 90.0])) == pytest.approx(0.26)


def test_extrapolated_plate_reproduces_the_generators_truth_outside_the_measured_range(plates):
    """The synthetic plate's truth keeps its 5/56 deg parameters outside 5-56 deg, as the extrapolation does;
    fitted from the noisy measurement, the plate's TIS must match the truth's exact TIS within 0.5 pp."""
    _, plate, _ = plates
    truth = cl830_truth()
    lam = VirtualGoniometer().spectrometer.wavelength
    blue, yellow = BLUE.incident_power(lam, 1.0), YELLOW.incident_power(lam, 1.0)
    for t in (0.0, 70.0, 85.0):
        exact = synthetic.exact_tis_table(truth, t, lam, blue, yellow)
        k = plate.theta_i_deg.index(t)
        for name, tag in TAGS.items():
            assert 100 * plate.channel(name).tis[k] == pytest.approx(exact[tag], abs=0.5), (t, name)
    assert isinstance(plate, PhosphorPlate)
