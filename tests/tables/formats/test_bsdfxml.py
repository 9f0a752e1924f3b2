"""Radiance / LBNL WINDOW BSDF XML (Klems full basis): written from sources with exact truth, checked by
Radiance's own library (pyradiance, optional) and by bsdfkit's reader; bad files are refused on one line."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import cli
from hemisphere_truth import Truth
from radiance_check import radiance_direct_hemi

import bsdfkit
from bsdfkit.core.errors import FormatError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats.bsdfxml import KLEMS_FULL, read_bsdfxml
from bsdfkit.tables.to_dataset import convert

ROOT = Path(__file__).resolve().parents[3]
ANSYS = ROOT / "tests" / "data" / "ansys-radiant-zemax-bsdf" / "inplane_spectral_goniometric_2D_data.csv"
CENTRES = tuple(float(c) for c in KLEMS_FULL.centres_deg)
# diffuse body (1 - b|beta|^2) + Gaussian lobe about the specular / straight-through direction
TRUTH = {"reflection": Truth(rho=0.5, b=0.3, A=3.0, sx=0.08, sy=0.08),
         "transmission": Truth(rho=0.3, b=0.2, A=1.0, sx=0.15, sy=0.15)}


def truth_fn(theta_i_deg, side, d):
    return TRUTH[side].f(theta_i_deg, d[..., 0], d[..., 1])


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    path = tmp_path_factory.mktemp("xml") / "diffuser.xml"
    result = export(truth_fn, "bsdfxml", "elastic", "both", path,
                    settings=ExportSettings(theta_i_deg=CENTRES, xml_back="mirror", wavelength_nm=550.0))
    return path, result


def test_klems_basis_has_145_patches_covering_the_hemisphere():
    assert KLEMS_FULL.size == 145
    np.testing.assert_allclose(KLEMS_FULL.lambdas().sum(), np.pi, rtol=1e-12)  # projected solid angle of 2pi sr


def test_written_xml_integrates_to_the_exact_truth(written):
    path, result = written
    for side in ("reflection", "transmission"):
        exact = np.array([TRUTH[side].tis(t) for t in CENTRES])
        np.testing.assert_allclose(result.tis_table[side], exact, rtol=1e-3)
        np.testing.assert_allclose(result.tis_source[side], exact, rtol=1e-3)


def test_round_trip_reads_front_and_back(written):
    path, result = written
    summary = read_any(path)
    assert summary.format == "bsdfxml" and summary.incidences_deg == list(CENTRES)
    for side in ("reflection", "transmission"):
        for key in (side, f"{side}@back"):
            np.testing.assert_allclose(summary.tis_computed[key], result.tis_source[side], rtol=5e-3)
    assert read_bsdfxml(path).wavelength_nm == 550.0


def test_pyradiance_loads_it_and_agrees_with_bsdfkit(written):
    path, result = written
    rad = radiance_direct_hemi(path, CENTRES)
    for side in ("reflection", "transmission"):
        # Radiance's +Z side is WINDOW's back (interior): front incidence is theta > 90 deg
        np.testing.assert_allclose(rad[side]["front"], result.tis_source[side], rtol=0.01)
        np.testing.assert_allclose(rad[side]["back"], result.tis_source[side], rtol=0.01)
    # the mirror direction is where the reflected lobe peaks (the diagonal of the Klems matrix)
    assert rad["mirror_over_opposite"] > 5


@pytest.mark.slow
def test_ansys_scan_at_550nm_agrees_with_pyradiance(tmp_path):
    out = tmp_path / "ansys.xml"
    res = convert(ANSYS, "bsdfxml", out, wavelength_nm=550.0, quantity="reflectance-factor")
    assert res.ok
    ds = bsdfkit.ingest(ANSYS, quantity="reflectance-factor")
    held = res.export.grid["klems_incidence_map_deg"]
    centres = sorted(held)
    rad = dict(zip(centres, radiance_direct_hemi(out, centres)["reflection"]["front"]))
    for t in res.incidences_deg:
        value = float(bsdfkit.tis(ds, incidence_deg=t)["tis"].sel(wavelength=550.0).squeeze())
        for centre in [c for c, s in held.items() if s == t]:
            assert rad[centre] == pytest.approx(value, rel=0.01), (t, centre)


def test_sniffed_by_content_and_bad_files_are_refused_on_one_line(written, tmp_path):
    path, _ = written
    renamed = tmp_path / "table.dat"
    renamed.write_bytes(path.read_bytes())
    assert registry.sniff_format(renamed) == "bsdfxml"
    text = path.read_text()
    short = tmp_path / "short.xml"
    start = text.index("<ScatteringData>") + len("<ScatteringData>\n")
    short.write_text(text[:start] + text[text.index("\n", start) + 1:])  # one outgoing row missing
    with pytest.raises(FormatError, match="wrong number of values"):
        read_bsdfxml(short)
    tree = tmp_path / "tree.xml"
    tree.write_text(text.replace(text[text.index("<AngleBasis>"):text.index("</AngleBasis>") + 13], "")
                    .replace("Columns", "TensorTree3"))
    done = cli("read", tree)
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "tree.xml" in done.stderr and "tensor tree" in done.stderr


def test_ingested_xml_integrates_to_the_files_own_sum(written):
    path, _ = written
    own = read_any(path).tis_computed
    ds = bsdfkit.ingest(path)
    assert "basis_psa" in ds.coords
    tis = bsdfkit.tis(ds)
    for side in ("reflection", "transmission"):
        engine = tis["tis"].sel(side=side).squeeze().values
        # the records carry their Klems patch's projected solid angle: the engine integrates them by the basis sum,
        # the file's own value (docs/exports.md §2.4), to rounding
        np.testing.assert_allclose(engine, own[side], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_cli_convert_writes_back_blocks_on_request_and_read_reports_them(tmp_path):
    zemax = ROOT / "tests" / "data" / "ansys-radiant-zemax-bsdf" / "radiant_imaging_sphere_planesymmetric_BRDF.bsdf"
    out = tmp_path / "vinyl.xml"
    done = cli("convert", zemax, "--to", "bsdfxml", "-o", out, "--xml-back", "mirror", "--xml-basis", "klems",
               "--wavelength", "550", "--json")
    assert done.returncode == 0, done.stderr
    res = json.loads(done.stdout)
    assert res["ok"] and "not held" in res["notes"][-1]
    read = cli("read", out, "--json")
    assert read.returncode == 0, read.stderr
    summary = json.loads(read.stdout)
    np.testing.assert_allclose(summary["tis_computed"]["reflection@back"], summary["tis_computed"]["reflection"])
    assert summary["details"]["wavelength_nm"] == 550.0


def test_a_radiance_written_klems_file_reads_to_its_analytic_values():
    """A file written by Radiance's own bsdf2klems (tests/data/radiance-bsdf2klems/PROVENANCE.md) of a Lambertian
    with reflectance 0.3 and transmittance 0.6: bsdfkit's reader gives both at every Klems incidence band within
    0.1 % (Radiance samples each patch by Monte Carlo: 3e-5 measured)."""
    path = ROOT / "tests" / "data" / "radiance-bsdf2klems" / "lambertian_r030_t060_klems_full.xml"
    summary = read_any(path)
    assert summary.format == "bsdfxml"
    assert summary.incidences_deg == [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 82.5]
    for key, truth in (("reflection@back", 0.3), ("transmission@back", 0.6)):
        np.testing.assert_allclose(summary.tis_computed[key], truth, rtol=1e-3)
