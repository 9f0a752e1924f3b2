"""Speos anisotropic BSDF (text): third-party files read to their stated TIS; bsdfkit's files round-trip."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_bsdfxml import TRUTH, truth_fn

from bsdfkit.core.errors import FormatError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats.speos import read_speos

DATA = Path(__file__).parents[2] / "data"
BRDF = DATA / "ansys-speos-anisotropicbsdf" / "test_13_planesymmetric_brdf_speos_reference.anisotropicbsdf"
BTDF = DATA / "ansys-speos-anisotropicbsdf" / "test_13_planesymmetric_btdf_speos_reference.anisotropicbsdf"
ZEMAX = DATA / "ansys-radiant-zemax-bsdf" / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"


def test_ansys_files_give_their_stated_tis_and_agree_with_the_zemax_original():
    brdf, btdf = read_any(BRDF), read_any(BTDF)
    assert brdf.format == btdf.format == "speos" and brdf.incidences_deg == list(np.arange(15.0, 76.0, 5.0))
    # the stated 13.4506 % at 15 deg is the format's scale (the table is normalised to it)
    assert brdf.tis_computed["reflection"][0] == pytest.approx(0.134506, rel=1e-9)
    # the same data as BSDF (row 8 = 1) and as BSDF cos(theta) (row 8 = 0, theta 90..180): the grazing row of the
    # latter is 0 (cos 90 deg) and takes the 85 deg row's values, the largest difference 1.8 % (at 60 deg)
    np.testing.assert_allclose(btdf.tis_computed["transmission"], brdf.tis_computed["reflection"], rtol=0.02)
    # the Zemax file the Speos file was converted from states its TIS per incidence: within 2.5 % at every
    # incidence. The table is read as its own interpolant, linear in sin θs and φs (issue #43: a full table is not
    # reconstructed); the engine's lobe reconstruction of the grazing lobe on its 5° x 10° grid read 65-75° 1-8 %
    # low before
    stated = np.array(read_any(ZEMAX).tis_stated["reflection"])
    ratio = np.array(brdf.tis_computed["reflection"]) / stated
    assert np.all(np.abs(ratio - 1) < 0.025), ratio


@pytest.mark.slow
def test_round_trip_within_half_a_percent(tmp_path):
    # normal and one oblique incidence (70 deg): with a third (40, 45 or 50 deg) the auto table's re-read TIS
    # misses the re-check by 1-2 % of its limit (1.01e-3) and four tables are written and read back (7x longer)
    out = tmp_path / "rt.anisotropicbsdf"
    res = export(truth_fn, "speos", "elastic", "both", out,
                 settings=ExportSettings(theta_i_deg=(0.0, 70.0), wavelength_nm=550.0))
    assert res.incidences_deg == pytest.approx((0.0, 70.0))
    for side in ("reflection", "transmission"):
        exact = [TRUTH[side].tis(t) for t in (0.0, 70.0)]
        np.testing.assert_allclose(res.tis_source[side], exact, rtol=1e-3)
        np.testing.assert_allclose(res.tis_table[side], res.tis_source[side], rtol=5e-3)
    renamed = tmp_path / "renamed.txt"
    renamed.write_bytes(out.read_bytes())
    assert registry.sniff_format(renamed) == "speos"
    assert read_speos(out).wavelength_nm == 550.0


def test_bad_file_refused_naming_line_and_field(tmp_path):
    lines = BRDF.read_text().splitlines()
    lines[11] = lines[11].replace("20.0", "2x.0")
    bad = tmp_path / "bad.anisotropicbsdf"
    bad.write_text("\n".join(lines))
    with pytest.raises(FormatError, match=r"bad\.anisotropicbsdf:12: field 'reflection: incidences': not a number"):
        read_speos(bad)
