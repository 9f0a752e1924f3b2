"""bsdfkit.io.netcdf: lossless round trips, the storage of record strings, files written by earlier versions."""
from __future__ import annotations

import netCDF4
import numpy as np
import xarray as xr

from bsdfkit.io import netcdf

N_REC = 50_000


def _records(n: int = N_REC) -> xr.Dataset:
    """A table-like dataset: per-record angles and labels (repeating, as a goniometer's are), one matrix."""
    k = np.arange(n)
    side = np.where(k % 2 == 0, "reflection", "transmission").astype(object)
    arc = np.array(["in_plane", "perpendicular", "other", "θ-arc", ""], dtype=object)[k % 5]
    return xr.Dataset(
        {"bsdf": (("record", "wavelength"), np.outer(1.0 + k % 90, [1.0, 0.5, 0.25])),
         "grazing": ("record", k % 97 == 0)},
        coords={"wavelength": [450.0, 550.0, 650.0], "theta_s": ("record", (k % 90).astype(float)),
                "side": ("record", side), "arc": ("record", arc), "source_line": ("record", k + 2),
                "configuration": ("configuration", np.array(["blue", "yellow"], dtype=object))},
        attrs={"quantity": "bsdf", "manifest_json": '{"a": 1}'})


def test_record_strings_round_trip_as_deflated_characters(tmp_path):
    """Per-record labels are stored as deflated UTF-8 characters (non-ASCII and empty labels included) and come
    back as the same Python strings; a dimension's labels stay variable-length strings. These 50,000 records took
    8.1 MB with variable-length strings and undeflated 1-D variables (a 3 MB Speos table's 259,208 records: 61 MB)
    and take 43 kB now; the bound leaves room for other zlib builds."""
    ds = _records()
    path = netcdf.save(ds, tmp_path / "r.nc")
    back = netcdf.load(path, quantity="bsdf")
    xr.testing.assert_identical(ds, back)
    assert back["side"].dtype == object and back["arc"].values[3] == "θ-arc" and back["arc"].values[4] == ""
    with netCDF4.Dataset(path) as f:
        assert f.variables["side"].dtype == np.dtype("S1") and f.variables["side"].filters()["zlib"]
        assert f.variables["theta_s"].filters()["zlib"] and f.variables["source_line"].filters()["zlib"]
        assert f.variables["configuration"].dtype is str  # labels of a dimension: variable-length
    assert path.stat().st_size < 500_000


def test_a_dataset_read_back_from_a_file_is_written_again(tmp_path):
    """Variables read from a file carry that file's storage settings (contiguous 1-D variables in files of
    earlier versions); writing such a dataset again still deflates and round-trips."""
    ds = _records(2_000)
    old = tmp_path / "old.nc"
    # as earlier versions wrote it: strings variable-length, 1-D variables contiguous and not deflated
    encoding = {name: {"dtype": str} for name in ("side", "arc", "configuration")}
    encoding.update({name: {"contiguous": True} for name in ("theta_s", "source_line")})
    ds.to_netcdf(old, engine=netcdf.ENGINE, encoding=encoding)
    first = netcdf.load(old)
    xr.testing.assert_identical(ds, first)
    again = netcdf.save(first, tmp_path / "again.nc")
    xr.testing.assert_identical(ds, netcdf.load(again))
    with netCDF4.Dataset(again) as f:
        assert f.variables["theta_s"].filters()["zlib"] and f.variables["arc"].dtype == np.dtype("S1")


def test_saves_in_threads_all_succeed_and_leave_the_chunk_cache_as_they_found_it(tmp_path):
    """The HDF5 library is not thread-safe: 8 saves in 4 threads ended in "NetCDF: HDF error" or a segmentation
    fault before saves took turns. Each save uses a small chunk cache while it writes and restores the one it
    found (netcdf.WRITE_CHUNK_CACHE_BYTES)."""
    from concurrent.futures import ThreadPoolExecutor

    before = netCDF4.get_chunk_cache()
    netcdf.save(_records(2_000), tmp_path / "c.nc")
    assert netCDF4.get_chunk_cache() == before
    with ThreadPoolExecutor(4) as pool:
        paths = list(pool.map(lambda k: netcdf.save(_records(20_000), tmp_path / f"t{k}.nc"), range(8)))
    assert netCDF4.get_chunk_cache() == before
    xr.testing.assert_identical(netcdf.load(paths[-1]), _records(20_000))
