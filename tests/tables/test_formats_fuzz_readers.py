"""Every reader, fed damaged input, either parses or raises a bsdfkit error: no other exception, no hang.

Examples are bounded (hypothesis max_examples) and each example has a deadline, so a hang fails the test.
"""
import gzip
import shutil

import pytest
from conftest import ROOT, tiny_gonio, tiny_plan
from fuzzing import damaged
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bsdfkit.core.errors import BsdfkitError
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.tables.formats.asap import read_asap
from bsdfkit.tables.formats.tracepro import read_tracepro
from bsdfkit.tables.formats.zemax import read_zemax

GOLDEN = ROOT / "tests" / "data" / "golden"
FUZZ = settings(max_examples=60, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                        HealthCheck.too_slow], derandomize=True)


@pytest.fixture(scope="module")
def tiny_folder(tmp_path_factory):
    from bsdfkit.simulation import virtual_goniometer as virtual

    gonio = tiny_gonio()
    folder = tmp_path_factory.mktemp("fuzz") / "tiny"
    virtual.write_raw_export(virtual.simulate_scan(virtual.cl830_truth(gonio), tiny_plan(), gonio, seed=5), folder)
    return folder


def _parses_or_bsdfkit_error(fn, path):
    try:
        fn(path)
    except BsdfkitError as exc:
        assert "\n" not in str(exc)


@FUZZ
@given(data=st.data())
def test_raw_scan_file(tiny_folder, tmp_path_factory, data):
    work = tmp_path_factory.mktemp("case") / "scan"
    shutil.copytree(tiny_folder, work)
    target = data.draw(st.sampled_from(["scans/blue.csv.gz", "reference/yellow.csv.gz", "dark.csv.gz",
                                        "responsivity.csv"]))
    path = work / target
    raw = path.read_bytes()
    text = (gzip.decompress(raw) if target.endswith(".gz") else raw).decode()
    new = data.draw(damaged(text)).encode("utf-8", "surrogatepass")
    if target.endswith(".gz"):
        new = gzip.compress(new) if data.draw(st.booleans()) or len(new) == 0 else new[: len(new) // 2]
    path.write_bytes(new)
    _parses_or_bsdfkit_error(read_scan, work)


@FUZZ
@given(data=st.data())
def test_manifest(tiny_folder, tmp_path_factory, data):
    work = tmp_path_factory.mktemp("case") / "scan"
    shutil.copytree(tiny_folder, work)
    path = work / "manifest.toml"
    path.write_text(data.draw(damaged(path.read_text())), encoding="utf-8", errors="surrogatepass")
    _parses_or_bsdfkit_error(read_scan, work)


@pytest.mark.parametrize("name,reader", [("tracepro_lambert_table.txt", read_tracepro),
                                         ("tracepro_abg.txt", read_tracepro),
                                         ("zemax_lambert_brdf.bsdf", read_zemax),
                                         ("zemax_asymmetric_btdf.bsdf", read_zemax),
                                         ("asap_lambert.txt", read_asap)])
def test_table_readers(name, reader, tmp_path_factory):
    source = (GOLDEN / name).read_bytes().decode("utf-8")

    @FUZZ
    @given(data=st.data())
    def run(data):
        path = tmp_path_factory.mktemp("tbl") / name
        path.write_bytes(data.draw(damaged(source)).encode("utf-8", "surrogatepass"))
        _parses_or_bsdfkit_error(reader, path)

    run()


@settings(max_examples=40, deadline=5000, derandomize=True)
@given(blob=st.binary(max_size=2000))
def test_readers_on_arbitrary_bytes(blob, tmp_path_factory):
    folder = tmp_path_factory.mktemp("bytes")
    for reader, name in ((read_tracepro, "x.txt"), (read_zemax, "x.bsdf"), (read_asap, "x.asap")):
        path = folder / name
        path.write_bytes(blob)
        _parses_or_bsdfkit_error(reader, path)


SCENES = ROOT / "fitting" / "scenes"


@pytest.mark.parametrize("name", ["example.toml", "study_height.toml"])
def test_scene_toml(name):
    from bsdfkit.raytrace import loads_scene

    source = (SCENES / name).read_text()

    @FUZZ
    @given(data=st.data())
    def run(data):
        try:
            loads_scene(data.draw(damaged(source)), SCENES / name)
        except BsdfkitError as exc:
            assert "\n" not in str(exc)

    run()


def test_plate_json(tmp_path_factory):
    from bsdfkit.raytrace import PhosphorPlate, load_plate

    table2 = {"bibs_reflection": 0.109, "bibs_transmission": 0.054, "biys_reflection": 0.263,
              "biys_transmission": 0.257, "yiys_reflection": 0.457, "yiys_transmission": 0.471}
    source = PhosphorPlate.constant(table2, name="fuzz").to_json()

    @FUZZ
    @given(data=st.data())
    def run(data):
        path = tmp_path_factory.mktemp("plate") / "plate.json"
        path.write_bytes(data.draw(damaged(source)).encode("utf-8", "surrogatepass"))
        _parses_or_bsdfkit_error(load_plate, path)

    run()
