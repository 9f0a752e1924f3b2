"""Shared fixtures: the bundled measurement (calibrated once per session) and a tiny raw export to mutate."""
from __future__ import annotations

import os

# The suite's parallelism is its pytest-xdist workers (one per core): a BLAS thread pool in each worker would only
# oversubscribe the cores (and its threads' hand-offs make every small LAPACK call slow). Set before numpy loads;
# commands the tests start inherit it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import contextlib
import errno
import gzip
import io
import shutil
from pathlib import Path
from types import MappingProxyType, SimpleNamespace

import pytest

from bsdfkit.core.collector import use_fewer_collections
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.simulation import virtual_goniometer as virtual

# each test process runs Python's garbage collector as the command line's processes do (bsdfkit.core.collector)
use_fewer_collections()

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "measurements" / "cl830-synthetic"

#: Lanes and emission width of the in-process traces whose lanes and width are not what the test checks. Below 1024
#: lanes a kernel has one loop level (bsdfkit.raytrace.kernel), half the XLA compilation of the default 16384 lanes,
#: and one width lets the tests of an effects record share one compiled kernel; a result depends on neither.
TRACE_LANES, TRACE_WIDTH = 512, 32768
TRACE_SIZES = MappingProxyType({"lanes": TRACE_LANES, "width": TRACE_WIDTH})  # trace(..., **TRACE_SIZES)


@pytest.fixture(scope="session", autouse=True)
def shared_compile_cache():
    """JAX's persistent compilation cache, as the command line uses it (its folder and settings), for the tests
    that trace or fit in this process: a kernel is compiled once for both xdist workers and every command a test
    starts, not once per process (20 000 rays of the example scene: 61 s cold, 7.6 s warm on a loaded machine).
    ``BSDFKIT_NO_COMPILE_CACHE=1`` runs the suite without it, as the command line would."""
    from bsdfkit.cli.main import CACHE_SETTINGS, compile_cache_dir, compile_cache_wanted

    if not compile_cache_wanted():
        yield None
        return
    import jax

    folder = os.environ.get("JAX_COMPILATION_CACHE_DIR") or str(compile_cache_dir())
    before = {k: getattr(jax.config, k) for k in ("jax_compilation_cache_dir", *CACHE_SETTINGS)}
    jax.config.update("jax_compilation_cache_dir", folder)
    for key, value in CACHE_SETTINGS.items():
        jax.config.update(key, value)
    # unlike the command line, every compilation is kept, however short: the fast lane compiles about 800 small
    # programs (fits, reductions) in its processes, 27 s of CPU, which a filled cache spares (wall 0.90)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    yield Path(folder)
    for key, value in before.items():
        jax.config.update(key, value)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """The modules that hold slow tests first, each module's tests together and in their order (the sort is
    stable): the long end-to-end tests start early instead of keeping one worker busy while the other idles at
    the end of the run (longest first is the classic rule for two machines)."""
    slow = {item.nodeid.split("::", 1)[0] for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.nodeid.split("::", 1)[0] not in slow)


@pytest.fixture(scope="session")
def bundled_raw():
    return read_scan(BUNDLED)


@pytest.fixture(scope="session")
def bundled_scan(bundled_raw):
    return calibrate(bundled_raw)


def fast_lane(values, fast) -> list:
    """``values`` as pytest parameters, those not in ``fast`` marked slow: the fast lane keeps one case of each
    code path (the ones named), the full suite runs the whole matrix."""
    return [v if v in fast else pytest.param(*(v if isinstance(v, tuple) else (v,)), marks=pytest.mark.slow)
            for v in values]


def cli(*args) -> SimpleNamespace:
    """``bsdfkit ARGS`` run in this process, as ``subprocess.run`` would report it (``returncode``, ``stdout``,
    ``stderr``): for the tests whose subject is the verb, not the process (no interpreter start-up and imports
    of 1-3 s per call; the compiled kernels of this process are reused). A usage error exits argparse's way."""
    from bsdfkit.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def no_staging_in(monkeypatch, parent: Path) -> None:
    """Make ``parent`` refuse the staging folders of output sets (a read-only parent; as root, chmod cannot)."""
    real_mkdir = Path.mkdir

    def guarded(self, *args, **kw):
        if self.name.endswith(".staging") and self.parent == parent:
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real_mkdir(self, *args, **kw)

    monkeypatch.setattr(Path, "mkdir", guarded)


def tiny_gonio() -> virtual.VirtualGoniometer:
    return virtual.VirtualGoniometer(spectrometer=virtual.Spectrometer(wavelength_step_nm=5.0), dark_frames=3,
                                     reference_frames=3)


def tiny_plan() -> virtual.ScanPlan:
    return virtual.ScanPlan(theta_i_deg=(45.0,), in_plane_deg=(-60.0, -30.0, 0.0, 30.0, 60.0),
                            perpendicular_deg=(-20.0, 20.0), fine_halfwidth_deg=2.0, fine_step_deg=2.0)


@pytest.fixture(scope="session")
def _tiny_export_made(tmp_path_factory) -> Path:
    """The small raw export, simulated once per session (0.1-1 s each time, for some 40 tests)."""
    gonio = tiny_gonio()
    truth = virtual.cl830_truth(gonio)
    export = virtual.simulate_scan(truth, tiny_plan(), gonio, seed=1)
    folder = tmp_path_factory.mktemp("tiny-made") / "tiny"
    virtual.write_raw_export(export, folder)
    return folder


@pytest.fixture
def tiny_export(tmp_path, _tiny_export_made) -> Path:
    """A small valid raw export (one incidence, few positions, 5 nm grid) copied to a temp folder (to mutate)."""
    return Path(shutil.copytree(_tiny_export_made, tmp_path / "tiny"))


def read_gz_lines(path: Path) -> list[str]:
    return gzip.decompress(path.read_bytes()).decode().splitlines()


def write_gz_lines(path: Path, lines: list[str]) -> None:
    path.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
