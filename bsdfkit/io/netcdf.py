"""Lossless netCDF round trip for bsdfkit datasets (engine: netCDF4).

Strings stay strings (a dimension's labels and scalars variable-length; every other string variable as deflated
characters), booleans are restored by xarray's encoding, and all attributes are
flat (nested metadata is stored as JSON text, e.g. ``manifest_json``), so ``load(save(ds))`` is identical to
``ds`` (asserted in the tests with ``xarray.testing.assert_identical``). Writes are atomic.
"""
from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path

import netCDF4
import xarray as xr
from xarray.backends.netCDF4_ import NETCDF4_PYTHON_LOCK  # the lock xarray itself takes for netCDF4-python

from bsdfkit.core.errors import FormatError, InputError
from bsdfkit.io.atomic import write_with

ENGINE = "netcdf4"


#: variables of at least this many values are deflated (lossless): the record × wavelength matrices (mostly
#: smooth spectra and NaN masks) and the per-record angles, flags and labels, which repeat. A 3 MB Speos table's
#: 259,208 records took 62 MB with variable-length strings and undeflated angles, 3.5 MB so, and load in half the time
DEFLATE_MIN_SIZE = 1024


def _encodable(ds: xr.Dataset) -> tuple[xr.Dataset, list[str]]:
    """The dataset with its encodings set, and the names of its deflated record × wavelength matrices."""
    out = ds.copy()
    deflated = []
    for name, var in out.variables.items():
        encoding = out[name].encoding
        text = var.dtype == object or var.dtype.kind == "U"
        if var.size < DEFLATE_MIN_SIZE or name in out.dims or not (text or var.dtype.kind in "fiub"):
            if text:
                encoding["dtype"] = str
            continue
        encoding.pop("contiguous", None)  # a variable read from a file may carry it; HDF5 deflates chunks only
        encoding.update(zlib=True, complevel=4, shuffle=True)
        if text:
            encoding["dtype"] = "S1"  # UTF-8 characters (xarray adds the string-length dimension)
        elif var.dtype.kind == "f" and var.ndim >= 2 and name in out.data_vars:
            deflated.append(name)
    return out, deflated


#: HDF5 chunk cache [bytes] of each variable a write creates. netCDF-C's default (64 MB a variable) kept every
#: written chunk of every deflated matrix until the file was closed: six 32 MB matrices raised a save's peak by 6.5
#: matrices, 0.5 with this cache. A save writes each chunk once, so the cache holds the chunk being filled and no
#: more (the save's time is unchanged).
WRITE_CHUNK_CACHE_BYTES = 4 * 1024 ** 2


#: one save at a time in a process: the HDF5 library of the netCDF4 wheels is not thread-safe (8 saves in 4 threads
#: ended in "NetCDF: HDF error" or a segmentation fault), and the chunk cache of a save is a process-wide setting
_SAVE_LOCK = threading.Lock()


@contextlib.contextmanager
def _write_chunk_cache() -> Iterator[None]:
    """netCDF4's chunk cache for new variables at :data:`WRITE_CHUNK_CACHE_BYTES` for the block, restored on exit
    (process-wide: a file another thread opens meanwhile gets the small cache, which costs it time only)."""
    size, elements, preemption = netCDF4.get_chunk_cache()
    netCDF4.set_chunk_cache(WRITE_CHUNK_CACHE_BYTES, elements, preemption)
    try:
        yield
    finally:
        netCDF4.set_chunk_cache(size, elements, preemption)


def save(ds: xr.Dataset, path: str | Path, force: bool = False, inputs=()) -> Path:
    """Write ``ds`` to netCDF atomically; refuse to overwrite without ``force`` (or an input, ever).

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to write.
    path : str or Path
        Output netCDF file.
    force : bool, optional
        Replace an existing file.
    inputs : iterable of (str or Path or None), optional
        Input files the output must not replace.

    Returns
    -------
    Path
        ``path``.
    """
    enc, deflated = _encodable(ds)

    def writer(tmp: Path) -> None:
        # a failed write of the netCDF/HDF5 library (RuntimeError "NetCDF: HDF error") is told apart by
        # atomic_path: a full device is said as such, anything else names the library.
        # The record x wavelength matrices go one at a time, after the rest: xarray encodes every variable of a
        # write before storing any, and each encoded copy of a matrix is as large as the matrix (a 200 MB
        # table's dataset needed 330 MB more to be written in one call, nothing more this way).
        # One open file for all of it, through xarray's netCDF4 store: ``to_netcdf`` would open and close the
        # file once per matrix (about 45 ms each) and asks dask for its scheduler on every call (importing
        # dask.distributed, about 0.9 s, in a process that holds no dask array).
        with _SAVE_LOCK, _write_chunk_cache():
            store = xr.backends.NetCDF4DataStore.open(str(tmp), mode="w", lock=NETCDF4_PYTHON_LOCK)
            try:
                enc.drop_vars(deflated).dump_to_store(store)
                for name in deflated:
                    enc[[name]].dump_to_store(store)
            finally:
                store.close()

    return write_with(path, writer, force, inputs)


def load(path: str | Path, quantity: str | tuple[str, ...] | None = None) -> xr.Dataset:
    """Read a bsdfkit netCDF file fully into memory; optionally require ``attrs['quantity']``.

    Parameters
    ----------
    path : str or Path
        netCDF file written by bsdfkit.
    quantity : str or tuple of str, optional
        Accepted values of ``attrs['quantity']``; None accepts any, and a file without the attribute (a BSDF
        dataset's readers leave it to :func:`bsdfkit.measurement.schema.validate_bsdf_dataset`, which reads such a
        file as ``bsdf``).

    Returns
    -------
    xarray.Dataset
        The dataset, loaded into memory.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", file=path, expected="a netCDF file written by bsdfkit")
    try:
        with xr.open_dataset(path, engine=ENGINE) as handle:
            ds = handle.load()
    except (OSError, ValueError, RuntimeError, KeyError, UnicodeDecodeError) as exc:
        raise FormatError(f"not a readable netCDF file ({type(exc).__name__})", file=path,
                          expected="a netCDF file written by bsdfkit") from None
    for name, var in ds.variables.items():
        if var.dtype.kind == "U":  # keep strings as Python objects, as the library creates them
            ds[name] = var.astype(object) if name not in ds.dims else ds[name]
    if quantity is not None:
        wanted = (quantity,) if isinstance(quantity, str) else quantity
        got = ds.attrs.get("quantity")
        if got is None:
            raise FormatError("dataset states no quantity (no attribute 'quantity')", file=path, field="quantity",
                              expected=" or ".join(wanted), got=None)
        if got not in wanted:
            raise FormatError("dataset holds another quantity", file=path, field="quantity",
                              expected=" or ".join(wanted), got=got)
    return ds
