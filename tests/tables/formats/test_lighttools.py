"""LightTools .bsdf: bsdfkit writes, bsdfkit reads (TIS within 0.5 %, the stated TIS lines, the lobe where the
convention puts it); told apart from Zemax files by content; bad files refused on one line."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_bsdfxml import TRUTH, truth_fn

from bsdfkit.core.errors import FormatError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats.lighttools import read_lighttools

ZEMAX = Path(__file__).parents[2] / "data" / "ansys-radiant-zemax-bsdf" / (
    "radiant_imaging_sphere_planesymmetric_BRDF.bsdf")
THETA = (0.0, 45.0, 70.0)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("lt") / "diffuser.bsdf"
    return path, export(truth_fn, "lighttools", "elastic", "both", path,
                        settings=ExportSettings(theta_i_deg=THETA, wavelength_nm=550.0))


@pytest.mark.slow
def test_round_trip_and_stated_tis(written):
    path, res = written
    summary = read_any(path)
    assert summary.format == "lighttools" and summary.incidences_deg == list(THETA)
    for side in ("reflection", "transmission"):
        exact = [TRUTH[side].tis(t) for t in THETA]
        np.testing.assert_allclose(summary.tis_stated[side], exact, rtol=1e-3)
        np.testing.assert_allclose(summary.tis_computed[side], exact, rtol=5e-3)
    assert read_lighttools(path).wavelength_nm == 550.0


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Reflection at 0 and 45 deg only: enough for the fast tests."""
    path = tmp_path_factory.mktemp("lt") / "small.bsdf"
    return path, export(truth_fn, "lighttools", "elastic", "reflection", path,
                        settings=ExportSettings(theta_i_deg=(0.0, 45.0), wavelength_nm=550.0))


def test_the_lobe_sits_at_azimuth_270(small):
    path, _ = small
    bsdf = read_lighttools(path)
    theta, values, _ = bsdf.blocks[("Front", "reflection")]
    k = int(np.flatnonzero(theta == 45.0)[0])
    a, r = np.unravel_index(int(np.argmax(values[k])), values[k].shape)
    assert (bsdf.azimuth[a], bsdf.radial[r]) == (270.0, 45.0)


def test_sniffed_apart_from_zemax(small, tmp_path):
    path, _ = small
    renamed = tmp_path / "x.txt"
    renamed.write_bytes(path.read_bytes())
    assert registry.sniff_format(renamed) == "lighttools"
    assert registry.sniff_format(ZEMAX) == "zemax"
    head = path.read_text()[:4096]
    assert [f.name for f in registry.FORMATS if f.guess_can_open(head, path)] == ["lighttools"]


def test_bad_values_are_refused_naming_the_line(small, tmp_path):
    path, _ = small
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("TIS")) + 3
    lines[k] = lines[k].replace(lines[k].split()[2], "abc", 1)
    bad = tmp_path / "bad.bsdf"
    bad.write_text("\n".join(lines))
    with pytest.raises(FormatError, match=rf"bad\.bsdf:{k + 1}: field 'block AOI 0.0 values': not a number"):
        read_lighttools(bad)


def test_a_plane_symmetrical_file_is_completed_by_its_mirror_images(small, tmp_path):
    """``Symmetry PlaneSymmetrical`` (read by other LightTools readers, e.g. libbsdf's): a file holding only the
    azimuths on one side of the plane of incidence (90°-270°, the specular side's half) reads to the same BSDF on the
    full circle and to the same TIS as the full file (the sample is mirror-symmetric: diffuse + Gaussian lobe)."""
    from bsdfkit.tables.formats.lighttools import LightToolsBsdf, lighttools_text

    path, _ = small
    full = read_lighttools(path)
    half = (full.azimuth >= 90.0) & (full.azimuth <= 270.0)
    one_side = LightToolsBsdf(full.azimuth[half], full.radial,
                              {k: (t, v[:, half, :], tis) for k, (t, v, tis) in full.blocks.items()},
                              full.wavelength_nm, full.spectral)
    text = lighttools_text(one_side).replace("Symmetry Asymmetric", "Symmetry PlaneSymmetrical")
    assert "Symmetry PlaneSymmetrical" in text
    mirrored = tmp_path / "half.bsdf"
    mirrored.write_text(text)
    back = read_lighttools(mirrored)
    keep = full.azimuth < 360.0
    np.testing.assert_array_equal(back.azimuth, full.azimuth[keep])
    key = ("Front", "reflection")
    np.testing.assert_allclose(back.blocks[key][1], full.blocks[key][1][:, keep], rtol=1e-6, atol=0)
    np.testing.assert_allclose(read_any(mirrored).tis_computed["reflection"], read_any(path).tis_computed["reflection"],
                               rtol=1e-6)
    with pytest.raises(FormatError, match="Asymmetric or PlaneSymmetrical"):
        bad = tmp_path / "bad.bsdf"
        bad.write_text(text.replace("Symmetry PlaneSymmetrical", "Symmetry Rotational"))
        read_lighttools(bad)
