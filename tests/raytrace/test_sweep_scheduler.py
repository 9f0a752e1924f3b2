"""``sweep --scheduler`` (issue #44 point 5): a scheduler that cannot be reached, or an address without a port, is
one line naming the address, never "not enough memory" or a traceback. Only 127.0.0.1 with a port nothing listens
on (port 1, which needs root to bind) is ever tried, with a short timeout."""
from __future__ import annotations

import socket

import distributed
import pytest
from conftest import ROOT, cli

from bsdfkit.core.errors import InputError
from bsdfkit.raytrace import sweep
from bsdfkit.raytrace.sweep import Cluster, check_scheduler_address

EXAMPLE = ROOT / "fitting" / "scenes" / "example.toml"
ARGS = ["--param", "cavity.height_mm=10,43", "--rays", "1000", "--seed", "5", "--no-plots"]
UNUSED = "tcp://127.0.0.1:1"


def _nothing_listens_on_port_1() -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(1.0)
        return s.connect_ex(("127.0.0.1", 1)) != 0


@pytest.mark.parametrize(("address", "what"), [("127.0.0.1", "has no port"), ("tcp://127.0.0.1", "has no port"),
                                               ("tcp://127.0.0.1:port", "has a port that is not a number")])
def test_an_address_without_a_port_is_refused_before_anything_runs(tmp_path, address, what):
    res = cli("sweep", EXAMPLE, *ARGS, "--scheduler", address, "-o", tmp_path / "x.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr == (f"bsdfkit sweep: error: field '--scheduler': the dask scheduler address {what}: it needs "
                          f"host:port; expected an address such as tcp://127.0.0.1:8786, got '{address}'\n")
    assert not (tmp_path / "x.nc").exists()


def test_valid_addresses_pass_the_check():
    for address in ("tcp://127.0.0.1:8786", "127.0.0.1:8786", "tcp://[::1]:8786"):
        check_scheduler_address(address)
    assert Cluster(scheduler=UNUSED).scheduler == UNUSED


@pytest.mark.skipif(not _nothing_listens_on_port_1(), reason="something listens on 127.0.0.1:1")
def test_an_unreachable_scheduler_is_named(tmp_path, monkeypatch):
    monkeypatch.setattr(sweep, "SCHEDULER_TIMEOUT_S", 1.0)
    res = cli("sweep", EXAMPLE, *ARGS, "--scheduler", UNUSED, "-o", tmp_path / "x.nc")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr.startswith(f"bsdfkit sweep: error: field '--scheduler': the dask scheduler at {UNUSED} could "
                                 "not be reached ("), res.stderr
    assert res.stderr.endswith("expected a running dask.distributed scheduler at this address (dask scheduler --port "
                               f"PORT), or --workers N for a local cluster, got '{UNUSED}'\n"), res.stderr
    assert "memory" not in res.stderr
    assert not (tmp_path / "x.nc").exists()


@pytest.mark.parametrize("fault", [MemoryError(), OSError("Timed out trying to connect"), TimeoutError()])
def test_what_the_connection_raises_becomes_the_one_line(monkeypatch, fault):
    # something answering at the address in another protocol: dask reads its bytes as a frame length (MemoryError)
    def refuse(*args, **kwargs):
        raise fault

    monkeypatch.setattr(distributed, "Client", refuse)
    with pytest.raises(InputError, match=rf"field '--scheduler': the dask scheduler at {UNUSED} could not be reached"):
        sweep._connect(UNUSED)
