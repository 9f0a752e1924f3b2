"""Speos spectral .brdf: bsdfkit writes, bsdfkit reads (TIS within 0.5 % at every incidence and side; every table
normalised to its stated percentage); bad files refused naming the line."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_bsdfxml import TRUTH, truth_fn

from bsdfkit.core.errors import FormatError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats.speosbrdf import read_speos_brdf

THETA = (0.0, 45.0, 70.0)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("brdf") / "diffuser.brdf"
    return path, export(truth_fn, "speosbrdf", "elastic", "both", path,
                        settings=ExportSettings(theta_i_deg=THETA, wavelength_nm=550.0))


@pytest.mark.slow
def test_round_trip_within_half_a_percent(written):
    path, res = written
    summary = read_any(path)
    assert summary.format == "speosbrdf" and summary.details["wavelengths_nm"] == [550.0]
    for side in ("reflection", "transmission"):
        exact = [TRUTH[side].tis(t) for t in THETA]
        np.testing.assert_allclose(summary.tis_stated[side], exact, rtol=1e-3)
        np.testing.assert_allclose(res.tis_table[side], exact, rtol=5e-3)


@pytest.mark.slow
def test_every_table_is_scaled_to_its_own_percentage(written, tmp_path):
    path, _ = written
    text = path.read_text().splitlines()
    b = read_speos_brdf(path)
    # halve the percentage of the 45 deg reflection table: its TIS halves, the others stay
    k = text.index(f"{b.percent['reflection'][1, 0]:.7g}")
    text[k] = f"{0.5 * b.percent['reflection'][1, 0]:.7g}"
    edited = tmp_path / "edited.brdf"
    edited.write_text("\n".join(text))
    before, after = read_any(path).tis_computed["reflection"], read_any(edited).tis_computed["reflection"]
    np.testing.assert_allclose(np.array(after) / np.array(before), [1.0, 0.5, 1.0], rtol=1e-9)
    assert registry.sniff_format(edited) == "speosbrdf"


def test_bad_percentage_refused_naming_the_line(tmp_path):
    good = ["OPTIS - brdf surface file v8.0", "0", "hand-made", "1", "x", "1\t0", "1", "1\t1", "0", "550", "40",
            "2\t3", "\t0\t180\t360", "0\t0.2\t0.2\t0.2", "90\t0.1\t0.1\t0.1", "End of file"]
    ok = tmp_path / "ok.brdf"
    ok.write_text("\n".join(good))
    assert read_speos_brdf(ok).percent["reflection"][0, 0] == 40.0
    bad = tmp_path / "bad.brdf"
    bad.write_text("\n".join(good[:10] + ["140"] + good[11:]))
    with pytest.raises(FormatError, match=r"bad\.brdf:11: field 'reflection table at theta_i=0, 550 nm: percent'"):
        read_speos_brdf(bad)


LUMERICAL = (Path(__file__).resolve().parents[2] / "data" / "ansys-speos-anisotropicbsdf"
             / "test_13_brdf_one_wavelength_speos.brdf")


@pytest.mark.slow
def test_a_lumerical_written_brdf_reads_to_its_stated_percentages():
    """A third-party .brdf (Ansys/Lumerical FDTD 8.28 export, vendored with provenance): sniffed by content, both
    sides and its 4 incidences read, every table's integral equal to the percentage its header states (the format's
    normalisation rule), and reflection + transmission ≤ 1 at every incidence (energy, independent of the rule)."""
    assert registry.sniff_format(LUMERICAL) == "speosbrdf"
    summary = read_any(LUMERICAL)
    assert summary.incidences_deg == [0.0, 22.5, 45.0, 67.5]
    stated = {"reflection": [2.3, 1.932, 13.66, 18.28], "transmission": [4.33, 5.08, 5.61, 0.91]}
    for side, percent in stated.items():
        np.testing.assert_allclose(summary.tis_computed[side], np.asarray(percent) / 100.0, rtol=1e-9)
    total = np.add(summary.tis_computed["reflection"], summary.tis_computed["transmission"])
    assert np.all((total > 0) & (total <= 1.0))
