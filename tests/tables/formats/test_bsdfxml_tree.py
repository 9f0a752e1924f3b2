"""Radiance tensor-tree BSDF XML (TensorTree3 / TensorTree4) read by bsdfkit, checked against analytic truth and
Radiance's own library on files written by Radiance's bsdf2ttree (tests/data/radiance-bsdf2ttree/PROVENANCE.md);
and one answer per XML file: ``read``, ``ingest`` + ``tis`` and the API give the same hemispherical value (the basis
sum of :mod:`bsdfkit.reduction.basis`)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import cli
from hemisphere_truth import Truth

import bsdfkit
from bsdfkit.core.errors import FormatError
from bsdfkit.tables import registry
from bsdfkit.tables.export import ExportSettings, export, read_any
from bsdfkit.tables.formats import tensortree
from bsdfkit.tables.formats.bsdfxml import TreeBsdf, read_bsdfxml

ROOT = Path(__file__).resolve().parents[3]
TREES = ROOT / "tests" / "data" / "radiance-bsdf2ttree"
KLEMS = ROOT / "tests" / "data" / "radiance-bsdf2klems" / "lambertian_r030_t060_klems_full.xml"
TT3_FULL, TT3_CULLED = TREES / "tt3_quadratic_g4_full.xml", TREES / "tt3_quadratic_g4_culled.xml"
TT4_FULL, TT4_CULLED = TREES / "tt4_tilted_g2_full.xml", TREES / "tt4_tilted_g3_culled.xml"

_RADIANCE = """
import json, sys
import pyradiance.bsdf as rb
sd = rb.load_file(sys.argv[1])
flags = {"reflection": rb.SAMPLE_ALL & ~rb.SAMPLE_T, "transmission": rb.SAMPLE_ALL & ~rb.SAMPLE_R}
print(json.dumps({side: {str(p): [rb.direct_hemi(sd, float(t), p, f) for t in sys.argv[2:]] for p in (0.0, 180.0)}
                  for side, f in flags.items()}))
"""


def radiance_direct_hemi(path, thetas):
    """Radiance's direct-hemispherical values (pyradiance) per side and source azimuth (0, 180 deg) on the +Z side
    (the files' Back blocks), in a fresh interpreter (pyradiance keeps a global BSDF cache)."""
    pytest.importorskip("pyradiance.bsdf")
    done = subprocess.run([sys.executable, "-c", _RADIANCE, str(path), *map(str, thetas)], capture_output=True,
                          text=True, timeout=120, check=True)
    return json.loads(done.stdout)


def test_shirley_chiu_maps_are_inverse_and_area_preserving():
    rng = np.random.default_rng(1)
    a, b = rng.random(2000), rng.random(2000)
    x, y = tensortree.square_to_disk(a, b)
    assert np.all(np.hypot(x, y) <= 1 + 1e-12)
    a2, b2 = tensortree.disk_to_square(x, y)
    np.testing.assert_allclose(np.stack([a2, b2]), np.stack([a, b]), atol=1e-12)
    # equal areas: a uniform grid of the square gives uniform density on the disk (radius^2 uniform in [0, 1])
    bx, by = tensortree.grid_directions(64)
    r2 = np.sort(bx**2 + by**2)
    np.testing.assert_allclose(r2, (np.arange(r2.size) + 0.5) / r2.size, atol=2 / 64)


def test_isotropic_tree_reads_to_its_analytic_values():
    """TT3 of f = 0.5/pi (1 - 0.2 (sin^2 i + sin^2 o)) (reflection), 0.3/pi (transmission): reflectance
    0.45 - 0.1 sin^2 theta and transmittance 0.3 at the incident cell centres within 0.2 % (4 digits in the file and
    the midpoint rule over 16 x 16 outgoing cells: 8.4e-4 measured)."""
    summary = read_any(TT3_FULL)
    assert summary.format == "bsdfxml" and "TensorTree3" in summary.details["basis"]
    theta = np.array(summary.incidences_deg)
    centres = theta > 0  # normal incidence is reported too: it lies in the last cell (centre 3.58 deg)
    np.testing.assert_allclose(np.sin(np.radians(theta[centres])), 1 - (2 * np.arange(8)[::-1] + 1) / 16, atol=1e-9)
    truth = 0.45 - 0.1 * np.sin(np.radians(theta[centres])) ** 2
    np.testing.assert_allclose(np.array(summary.tis_computed["reflection@back"])[centres], truth, rtol=2e-3)
    np.testing.assert_allclose(summary.tis_computed["transmission@back"], 0.3, rtol=1e-3)


def test_anisotropic_tree_reads_to_its_analytic_values_with_the_source_at_azimuth_180():
    """TT4 of f = 0.5/pi (1 + 0.5 ix) (reflection), 0.2/pi (1 - 0.5 ix) (transmission), ix of the incident cell's
    centre: bsdfkit's source at azimuth 180 deg is Radiance's; within 0.1 % (4 digits)."""
    bsdf = read_bsdfxml(TT4_FULL)
    assert isinstance(bsdf, TreeBsdf) and bsdf.ndim == 4
    theta = np.array(bsdf.incidences_deg())
    px, py = tensortree.disk_to_square(np.sin(np.radians(theta)), np.zeros(theta.size))
    n = 4  # -g 2
    cx, _ = tensortree.square_to_disk((np.floor(px * n) + 0.5) / n, (np.floor(py * n) + 0.5) / n)
    ix = -cx  # the tree holds (-ix, -iy)
    assert np.all(ix[theta > 0] < -0.1)  # the source on the -x side
    for direction, truth in (("Reflection Back", 0.5 * (1 + 0.5 * ix)), ("Transmission Back", 0.2 * (1 - 0.5 * ix))):
        got = [bsdf.hemispherical(direction, t) for t in theta]
        np.testing.assert_allclose(got, truth, rtol=1e-3)


@pytest.mark.parametrize("path", [TT3_FULL, TT3_CULLED, TT4_FULL, TT4_CULLED], ids=lambda p: p.stem)
def test_trees_agree_with_radiances_own_direct_hemispherical_value(path):
    """bsdfkit's value equals pyradiance's direct_hemi with the source at azimuth 180 deg within 1e-5 (both sum the
    same leaves; Radiance in float32 and fixed point: 1.0e-6 measured); the anisotropic files differ at azimuth 0
    (the convention matters)."""
    summary = read_any(path)
    theta = summary.incidences_deg
    rad = radiance_direct_hemi(path, theta)
    for side in ("reflection", "transmission"):
        np.testing.assert_allclose(summary.tis_computed[f"{side}@back"], rad[side]["180.0"], rtol=1e-5)
        if "tilted" in path.stem:
            off = np.array(theta) > 10
            assert np.all(np.abs(np.array(rad[side]["0.0"])[off] / np.array(rad[side]["180.0"])[off] - 1) > 0.05)


def test_tree_is_sniffed_by_content_and_ingested_as_its_back_blocks(tmp_path):
    renamed = tmp_path / "tree.dat"
    renamed.write_bytes(TT3_CULLED.read_bytes())
    assert registry.sniff_format(renamed) == "bsdfxml"
    ds = bsdfkit.ingest(renamed)
    assert set(np.unique(ds["side"].values)) == {"reflection", "transmission"}
    assert "back-side blocks only" in ds.attrs["manifest_json"]


def _one_answer(path):
    """read's values and the engine's on the ingested records, per key of the read summary."""
    summary = read_any(path)
    tis = bsdfkit.tis(bsdfkit.ingest(path))
    out = {}
    for key, values in summary.tis_computed.items():
        side = key.split("@")[0]
        engine = tis["tis"].sel(side=side).squeeze().values
        out[key] = (np.asarray(values), np.asarray(engine))
    return summary, out


@pytest.mark.parametrize("path", [KLEMS, TT3_CULLED, TT4_CULLED], ids=lambda p: p.stem)
def test_read_and_ingest_tis_give_the_same_number(path):
    """Radiance-written Klems and tensor-tree files: the engine integrates the ingested records by the basis sum,
    the value ``read`` reports (to rounding, 1e-12)."""
    summary, pairs = _one_answer(path)
    for key, (read, engine) in pairs.items():
        assert engine.shape == (len(summary.incidences_deg),)
        np.testing.assert_allclose(engine, read, rtol=0, atol=1e-12, err_msg=key)


@pytest.mark.slow  # a Klems export, an ingest and a tis (4 s); the fast lane's one answer of read and ingest + tis:
# test_read_and_ingest_tis_give_the_same_number, and of the Klems writer: test_bsdfxml.py
def test_a_bsdfkit_written_xml_gives_one_answer(tmp_path):
    """A Klems XML written by bsdfkit from a diffuser with a specular lobe (not a flat file): read, ingest + tis
    (API) and ingest -o + tis (command line) agree to 1e-12."""
    def fn(theta_i_deg, side, d):
        b0 = np.sin(np.radians(theta_i_deg))
        return 0.5 / np.pi * (1 - 0.3 * (d[..., 0] ** 2 + d[..., 1] ** 2)) + 2.0 * np.exp(
            -((d[..., 0] - b0) ** 2 + d[..., 1] ** 2) / (2 * 0.1**2))

    path = tmp_path / "lobe.xml"
    export(fn, "bsdfxml", "elastic", "reflection", path, settings=ExportSettings(theta_i_deg=(0.0, 30.0, 60.0)))
    summary, pairs = _one_answer(path)
    read, engine = pairs["reflection"]
    np.testing.assert_allclose(engine, read, rtol=0, atol=1e-12)
    nc = tmp_path / "lobe.nc"
    assert cli("ingest", path, "-o", nc).returncode == 0
    done = cli("tis", nc, "--json")
    assert done.returncode == 0, done.stderr
    verb = {r["incidence_deg"]: r["value"][0] for r in json.loads(done.stdout)["hemispherical"]
            if r["side"] == "reflection"}
    np.testing.assert_allclose([verb[t] for t in summary.incidences_deg], read, rtol=0, atol=1e-12)


_BAD = {
    "missing '}'": lambda s: s.replace("}\n\t\t\t</ScatteringData>", "\n\t\t\t</ScatteringData>", 1),
    "wrong number of values": lambda s: s.replace("{ 1.203298e-01 }", "{ 1.203298e-01 0.1 }", 1),
    "finite number >= 0": lambda s: s.replace("{ 1.203298e-01 }", "{ -1.203298e-01 }", 1),
    "not a number": lambda s: s.replace("{ 1.203298e-01 }", "{ 1.2O3298e-01 }", 1),
    "extra characters": lambda s: s.replace("}\n\t\t\t</ScatteringData>", "} 7\n\t\t\t</ScatteringData>", 1),
    "TensorTree3 or TensorTree4": lambda s: s.replace("TensorTree3", "TensorTree5"),
    "LBNL/Shirley-Chiu": lambda s: s.replace("LBNL/Shirley-Chiu", "LBNL/Klems Full", 1),
}


@pytest.mark.parametrize("fault", list(_BAD))
def test_malformed_trees_are_refused_on_one_line(fault, tmp_path):
    text = TT3_CULLED.read_text()
    bad = _BAD[fault](text)
    assert bad != text
    path = tmp_path / "bad.xml"
    path.write_text(bad)
    with pytest.raises(FormatError, match=fault.replace("(", r"\(")) as err:
        read_bsdfxml(path)
    assert "bad.xml" in str(err.value) and "\n" not in str(err.value)


def test_malformed_tree_on_the_command_line_exits_2_with_one_line(tmp_path):
    path = tmp_path / "cut.xml"
    path.write_text(_BAD["wrong number of values"](TT3_CULLED.read_text()))
    for verb in ("read", "tis", "ingest"):
        done = cli(verb, path, *(["-o", tmp_path / "x.nc"] if verb == "ingest" else []))
        assert done.returncode == 2 and done.stderr.count("\n") == 1, (verb, done.stderr)
        assert "cut.xml" in done.stderr and "ScatteringData of Reflection Back" in done.stderr
        assert "2^(3k) values" in done.stderr and "got 2" in done.stderr


# the tree to every writable format; the Klems file (read by the same engine path, the basis sum) to one
# Harvey-Shack and one specular-centred format: every pair of frames is crossed without 14 slow conversions
XML_CONVERSIONS = [(TT3_CULLED, to) for to in registry.writable()] + [(KLEMS, "tracepro"), (KLEMS, "zemax")]


@pytest.mark.slow
@pytest.mark.parametrize("path, to", XML_CONVERSIONS, ids=lambda v: getattr(v, "stem", v))
def test_xml_converts_to_every_format_and_passes_its_tis_check(path, to, tmp_path):
    """Klems and tensor-tree XML (Radiance-written) to every writable format: the written table's TIS equals the
    source's (the basis sum, as ``read`` reports it) within the convert check (1 %)."""
    from bsdfkit.tables.to_dataset import convert

    both = registry.get(to).sides_per_file == 2
    own = read_any(path)
    read_theta, own = own.incidences_deg, own.tis_computed
    # ASAP on three of the tree's six incidences (normal, 38.7, 69.6 deg): its auto table then passes at once (4
    # tables written and re-read otherwise, 14 s); TracePro keeps all six and with them the re-check that writes
    # the fixed grid when the auto table fails on the written file.
    theta = [read_theta[k] for k in (0, 3, 5)] if to == "asap" and path == TT3_CULLED else None
    res = convert(path, to, tmp_path / f"out.{to}", side="both" if both else "reflection", wavelength_nm=550.0,
                  theta_i_deg=theta)
    assert res.ok, res.notes
    if theta is not None:
        assert list(res.incidences_deg) == pytest.approx(theta)
    for side, written in res.tis_written.items():
        original = res.tis_original[side]
        np.testing.assert_allclose(written, original, rtol=0.01)
        held = [own[f"{side}@back"][read_theta.index(t)] for t in res.incidences_deg]
        np.testing.assert_allclose(original, held, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------- tensor-tree writer
NARROW = {"reflection": Truth(rho=0.5, b=0.3, A=40.0, sx=0.02, sy=0.02),
          "transmission": Truth(rho=0.3, b=0.2, A=5.0, sx=0.03, sy=0.03)}


def narrow_fn(theta_i_deg, side, d):
    return NARROW[side].f(theta_i_deg, d[..., 0], d[..., 1])


def test_lobe_width_rule_measures_the_fwhm():
    """The in-plane FWHM of a Gaussian lobe of width sigma (direction cosines) at normal incidence is
    2 arcsin(1.1774 sigma) exactly; the rule's estimate is within 0.1 deg (its 0.001 sampling step)."""
    from bsdfkit.tables.formats.bsdfxml_tree import lobe_fwhm_deg

    for sigma in (0.02, 0.08):
        lobe = Truth(rho=0.5, b=0.0, A=10.0, sx=sigma, sy=sigma)
        got = lobe_fwhm_deg(lambda t, s, d, lobe=lobe: lobe.f(t, d[..., 0], d[..., 1]), 0.0, "reflection")
        assert got == pytest.approx(2 * np.degrees(np.arcsin(np.sqrt(2 * np.log(2)) * sigma)), abs=0.1)
    flat = Truth(rho=0.5, b=0.3, A=0.0)
    assert lobe_fwhm_deg(lambda t, s, d: flat.f(t, d[..., 0], d[..., 1]), 30.0, "reflection") is None


@pytest.fixture(scope="module")
def narrow_tree(tmp_path_factory):
    path = tmp_path_factory.mktemp("tree") / "narrow.xml"
    res = export(narrow_fn, "bsdfxml", "elastic", "both", path,
                 settings=ExportSettings(theta_i_deg=(0.0, 20.0, 40.0, 60.0), xml_basis="auto", wavelength_nm=550.0))
    return path, res


def test_auto_writes_a_tensor_tree_for_a_lobe_narrower_than_a_klems_patch(narrow_tree):
    """FWHM 2.7 deg < 10 deg: TensorTree3; its hemispherical values (bsdfkit read) equal the exact integral within
    0.1 % (0.06 % measured: cell averages by 6 x 6 sub-samples), and the lobe keeps its peak to a cell (at least half
    the source's peak in the tree, below a fifth of it in a Klems file of the same source)."""
    path, res = narrow_tree
    assert "TensorTree3" in res.grid["mode"] and "FWHM 2.69 deg" in res.grid["basis_rule"]
    assert res.size_bytes < 400_000
    for side in ("reflection", "transmission"):
        exact = [NARROW[side].tis(t) for t in res.incidences_deg]
        np.testing.assert_allclose(res.tis_source[side], exact, rtol=1e-3)
        np.testing.assert_allclose(res.tis_table[side], exact, rtol=1e-3)
    bsdf = read_bsdfxml(path)
    assert isinstance(bsdf, TreeBsdf) and bsdf.ndim == 3
    peak_source = NARROW["reflection"].f(20.0, np.array(np.sin(np.radians(20.0))), np.array(0.0))
    peak_tree = np.nanmax(bsdf.trees["Reflection Front"].out_grid(20.0, 64))
    assert peak_tree > 0.5 * peak_source
    klems = export(narrow_fn, "bsdfxml", "elastic", "reflection", path.with_name("klems.xml"),
                   settings=ExportSettings(theta_i_deg=(20.0,), xml_basis="klems"))
    assert "Klems" in klems.grid["mode"]
    assert read_bsdfxml(path.with_name("klems.xml")).blocks["Reflection Front"].max() < 0.2 * peak_source


def test_written_tree_loads_in_radiance_and_agrees_with_bsdfkit_tis(narrow_tree):
    """pyradiance loads the written tree; its front direct-hemispherical values (incidence 180 - theta) equal bsdfkit's
    tis of the source within 1 % (0.06 % measured)."""
    path, res = narrow_tree
    pytest.importorskip("pyradiance.bsdf")
    code = _RADIANCE.replace("for p in (0.0, 180.0)", "for p in (0.0,)")
    done = subprocess.run([sys.executable, "-c", code, str(path),
                           *[str(180.0 - t) for t in res.incidences_deg]], capture_output=True, text=True,
                          timeout=120, check=True)
    rad = json.loads(done.stdout)
    for side in ("reflection", "transmission"):
        np.testing.assert_allclose(rad[side]["0.0"], res.tis_source[side], rtol=0.01)


def test_auto_keeps_klems_for_a_broad_lobe(tmp_path):
    broad = Truth(rho=0.5, b=0.3, A=1.0, sx=0.15, sy=0.15)  # FWHM about 20 deg
    res = export(lambda t, s, d: broad.f(t, d[..., 0], d[..., 1]), "bsdfxml", "elastic", "reflection",
                 tmp_path / "broad.xml", settings=ExportSettings(theta_i_deg=(0.0, 30.0), xml_basis="auto"))
    assert "Klems" in res.grid["mode"] and res.grid["basis_rule"].startswith("klems: the narrowest")
