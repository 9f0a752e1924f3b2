"""Parameter sweeps over a scene: the studies of §5 of the cylindrical-module paper ([Cylindrical-module]).

A parameter spec is ``KEYS=VALUES``:

* ``KEYS`` is one scene key ``section.key`` (``wall.reflectance``, ``cavity.height_mm``, ``leds.fwhm_deg``,
  ``leds.pitch_mm`` …) or several comma-separated keys set together (``wall.reflectance,base.reflectance``
  for "the reflectance of the mixing cavity");
* ``VALUES`` is ``start:stop:count`` (``count`` evenly spaced values, both ends included) or a
  comma-separated list (``10,43,80``; integers stay integers, other words stay strings).

Each spec is one dimension of the result (named after its first key); the grid is the outer product. Every
grid point is a full trace at the same seed (common random numbers, so differences between points are
smoother than their individual errors). Points that share an :class:`~bsdfkit.raytrace.effects.Effects`
reuse one compiled kernel.

Beyond one process: with ``workers`` (a ``distributed.LocalCluster`` of that many single-threaded worker
processes on the loopback interface) or ``scheduler`` (the address of an existing dask.distributed
scheduler) every grid point is one task. A task traces its point with the same function, rays and seed as
the serial sweep, so the dataset is identical bit for bit (the tallies are exact integers; on a cluster of
different CPUs the float32 arithmetic of the kernel could differ in the last bits). Tasks that fail are
reported, never dropped: the dataset gets NaN there and a ``failed_points`` attribute, and
:class:`SweepPointsFailed` is raised after the outputs are written.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import distributed
import numpy as np
import xarray as xr

from bsdfkit.core.errors import BsdfkitError, InputError, ValidationError
from bsdfkit.core.jaxconfig import DEVICES_FLAG
from bsdfkit.io.atomic import OutputSet, write_with
from bsdfkit.raytrace.scene import Scene, dumps_scene, with_values
from bsdfkit.raytrace.tracer import trace

_INT = re.compile(r"^[+-]?\d+$")
#: Most grid points of one sweep (each is a full trace): checked before any value array is allocated.
MAX_SWEEP_POINTS = 10_000


@dataclass(frozen=True)
class SweepParameter:
    """One swept dimension: the scene keys it sets and its values."""

    keys: tuple[str, ...]
    values: tuple

    @property
    def name(self) -> str:
        return self.keys[0]


def _token(text: str):
    text = text.strip()
    if _INT.match(text):
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text


def parse_parameter(spec: str, source: str = "--param") -> SweepParameter:
    """Parse ``KEYS=VALUES`` (see module docstring).

    Parameters
    ----------
    spec : str
        ``KEYS=VALUES``: comma-separated ``section.key`` names, then ``start:stop:count`` or a comma list.
    source : str
        Field named in errors.

    Returns
    -------
    SweepParameter
        The keys and their values.
    """
    if "=" not in spec:
        raise InputError("a sweep parameter is KEYS=VALUES", field=source, expected="e.g. wall.reflectance=0.80:0.98:5",
                         got=spec)
    lhs, rhs = spec.split("=", 1)
    keys = tuple(k.strip() for k in lhs.split(","))
    if not all(re.match(r"^[a-z]+\.[A-Za-z_]+$", k) for k in keys):
        raise InputError("sweep keys are section.key", field=source, expected="e.g. cavity.height_mm", got=lhs)
    rhs = rhs.strip()
    if ":" in rhs:
        parts = rhs.split(":")
        try:
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
        except (ValueError, IndexError):
            raise InputError("a range is start:stop:count", field=source, expected="e.g. 0.80:0.98:5",
                             got=rhs) from None
        if len(parts) != 3 or count < 1 or not (np.isfinite(start) and np.isfinite(stop)):
            raise InputError("a range is start:stop:count with finite ends and count >= 1", field=source,
                             expected="e.g. 0.80:0.98:5", got=rhs)
        if count > MAX_SWEEP_POINTS:
            raise InputError("too many sweep values", field=source, expected=f"count <= MAX_SWEEP_POINTS "
                             f"({MAX_SWEEP_POINTS})", got=count)
        values = tuple(float(v) for v in np.linspace(start, stop, count))
    else:
        values = tuple(_token(v) for v in rhs.split(",") if v.strip())
    if not values:
        raise InputError("no values", field=source, expected="start:stop:count or a list", got=rhs)
    return SweepParameter(keys, values)


@dataclass(frozen=True)
class SweepSpec:
    """The parameters and run settings of a sweep."""

    parameters: tuple[SweepParameter, ...]
    rays: int
    seed: int
    chunk: int | None = None


@dataclass(frozen=True)
class Cluster:
    """Where sweep points run: ``workers`` local worker processes, or an existing ``scheduler`` address."""

    workers: int | None = None
    scheduler: str | None = None
    #: dask's own log (worker "Compute Failed" records with tracebacks, nanny restarts) on stderr; off by
    #: default: a failed point is reported once, in the one line of :class:`SweepPointsFailed`
    verbose: bool = False

    def __post_init__(self) -> None:
        if self.workers is not None and (not isinstance(self.workers, int) or self.workers < 1):
            raise ValidationError("worker count must be positive", field="--workers", expected="an integer >= 1",
                                  got=self.workers)
        if self.scheduler is not None:
            check_scheduler_address(self.scheduler)


#: Seconds a sweep waits for an existing scheduler (``--scheduler``) to answer before it gives up.
SCHEDULER_TIMEOUT_S = 30.0


def check_scheduler_address(address: str) -> None:
    """Refuse a scheduler address dask cannot connect to: a TCP/TLS address needs ``host:port``.

    Parameters
    ----------
    address : str
        ``tcp://host:port`` (or ``host:port``, ``tls://host:port``, another dask scheme).

    Raises
    ------
    InputError
        The address has no port, or a port that is not a number.
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(str(address))
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(location)
    except ValueError as exc:
        what = "has no port" if "missing port" in str(exc) else "has a port that is not a number"
        raise InputError(f"the dask scheduler address {what}: it needs host:port", field="--scheduler",
                         expected="an address such as tcp://127.0.0.1:8786", got=address) from None


def _connect(address: str) -> distributed.Client:
    """A client of the scheduler at ``address``; one line naming it when it cannot be reached within
    :data:`SCHEDULER_TIMEOUT_S` (connection refused, no answer, or something that does not speak dask's protocol
    there: its answer can read as a frame of any size, a MemoryError)."""
    try:
        return distributed.Client(address, timeout=f"{SCHEDULER_TIMEOUT_S:g}s")
    except (OSError, TimeoutError, MemoryError) as exc:
        reason = ("what answers there is no dask scheduler" if isinstance(exc, MemoryError)
                  else (str(exc).splitlines() or [type(exc).__name__])[0])
        raise InputError(f"the dask scheduler at {address} could not be reached ({reason})", field="--scheduler",
                         expected="a running dask.distributed scheduler at this address (dask scheduler --port "
                                  "PORT), or --workers N for a local cluster", got=address) from None


class SweepPointsFailed(BsdfkitError):
    """Some sweep points failed on the cluster (the others were computed and written)."""


def trace_point(scene: Scene, values: dict, rays: int, seed: int, chunk: int | None):
    """One grid point: ``scene`` with ``values`` set, traced (the task of a distributed sweep).

    Parameters
    ----------
    scene : Scene
        The base scene.
    values : dict
        ``section.key`` → value to set (empty: the scene itself).
    rays : int
        Rays to trace.
    seed : int
        Seed of the random numbers.
    chunk : int or None
        Rays per compiled call (None: the scene's).

    Returns
    -------
    TraceResult
        The point's trace.
    """
    point = with_values(scene, values) if values else scene
    return trace(point, rays, seed, chunk=chunk)


def _describe(values: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in values.items()) or "the scene"


def _worker_env(workers: int) -> dict[str, str]:
    """Environment of local workers: the cores shared out as JAX CPU devices (the tracer runs a chunk on each),
    so N workers on N cores do not oversubscribe them; the rest of ``XLA_FLAGS`` is kept."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(DEVICES_FLAG)]
    return {"XLA_FLAGS": " ".join(flags + [f"{DEVICES_FLAG}={max(1, cores // workers)}"])}


#: level of the ``distributed`` loggers (scheduler, workers, nannies) of a sweep unless ``verbose``: above ERROR,
#: so a failing task's "Compute Failed" record and traceback never reach stderr (the failure is in the one line)
QUIET_LOG_LEVEL = logging.CRITICAL + 10


@contextlib.contextmanager
def _dask_logs(verbose: bool):
    """The parent's ``distributed`` loggers at :data:`QUIET_LOG_LEVEL` for the block (restored on exit)."""
    if verbose:
        yield
        return
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "asyncio")]
    saved = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(QUIET_LOG_LEVEL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, saved):
            lg.setLevel(level)


def _run_distributed(scene: Scene, spec: SweepSpec, points: list, cluster: Cluster,
                     progress: Callable[[int, int], None] | None) -> tuple[dict, list[str]]:
    """Trace ``points`` [(index, values)] as tasks on dask.distributed; returns (results, failures)."""
    with _dask_logs(cluster.verbose):
        return _run_on_cluster(scene, spec, points, cluster, progress)


def _run_on_cluster(scene: Scene, spec: SweepSpec, points: list, cluster: Cluster,
                    progress: Callable[[int, int], None] | None) -> tuple[dict, list[str]]:
    local = None
    if cluster.scheduler:
        client = _connect(cluster.scheduler)
    else:
        # single-threaded worker processes on the loopback interface, no dashboard; workers inherit the
        # environment (JAX's compilation cache settings of the command line). silence_logs is the level of the
        # workers' and nannies' distributed loggers (in their processes, whose stderr is ours)
        local = distributed.LocalCluster(n_workers=cluster.workers or 1, threads_per_worker=1, processes=True,
                                         host="127.0.0.1", dashboard_address=None,
                                         silence_logs=logging.WARNING if cluster.verbose else QUIET_LOG_LEVEL,
                                         env=_worker_env(cluster.workers or 1))
        client = distributed.Client(local)
    results, failures = {}, []
    try:
        futures = {}
        for index, values in points:
            fut = client.submit(trace_point, scene, values, spec.rays, spec.seed, spec.chunk, pure=False)
            futures[fut] = (index, values)
        done = 0
        for fut in distributed.as_completed(list(futures)):
            index, values = futures[fut]
            if fut.status == "finished":
                results[index] = fut.result()
            else:
                exc = fut.exception()
                text = (str(exc).splitlines() or [""])[0]
                failures.append(f"{_describe(values)}: {type(exc).__name__}: {text}")
            done += 1
            if progress is not None:
                progress(done, len(points))
    finally:
        client.close()
        if local is not None:
            local.close()
    return results, failures


def sweep_dataset(scene: Scene, spec: SweepSpec, progress: Callable[[int, int], None] | None = None,
                  cluster: Cluster | None = None):
    """Run every grid point and return an ``xarray.Dataset`` with one dimension per parameter.

    Variables: LER, YBR, extracted_{blue,yellow,total} (W), absorbed_{wall,base,leds,plate} (W), their
    standard errors (``std_err_*``), ledger_error, non_uniformity and, when the scene tallies it, the
    irradiance map (dims …, y_mm, x_mm). With ``cluster`` the points run as dask.distributed tasks (module
    docstring); failed points are NaN and listed in the ``failed_points`` attribute.

    Parameters
    ----------
    scene : Scene
        The base scene.
    spec : SweepSpec
        Parameters, rays, seed and chunk.
    progress : callable, optional
        Called with (points done, total points) as points finish.
    cluster : Cluster, optional
        Run the points on dask.distributed; None traces them in this process.

    Returns
    -------
    xarray.Dataset
        One dimension per parameter.
    """
    names = [p.name for p in spec.parameters]
    if len(set(names)) != len(names):
        raise ValidationError("two sweep parameters start with the same key", field="--param",
                              expected="distinct first keys", got=names)
    total = check_point_count(spec.parameters)
    points = _points(scene, spec.parameters)
    failures: list[str] = []
    if cluster is None:
        results = {}
        for n, (index, values) in enumerate(points):
            results[index] = trace_point(scene, values, spec.rays, spec.seed, spec.chunk)
            if progress is not None:
                progress(n + 1, total)
    else:
        results, failures = _run_distributed(scene, spec, points, cluster, progress)
        if not results:
            raise SweepPointsFailed(f"all {total} sweep points failed; first: {failures[0]}")
    ds = _results_dataset(results, spec.parameters, scene.cavity.radius_mm)
    ds.attrs.update(rays=spec.rays, seed=spec.seed, scene_toml=dumps_scene(scene),
                    parameters=";".join(",".join(p.keys) + "=" + ",".join(str(v) for v in p.values)
                                        for p in spec.parameters),
                    source="bsdfkit sweep")
    if failures:
        ds.attrs["failed_points"] = "\n".join(failures)  # one line per failed point
    return ds


def _points(scene: Scene, parameters: Sequence[SweepParameter]) -> list[tuple[tuple[int, ...], dict]]:
    """Every grid point: its index and the values it sets, each point's scene checked before anything is traced."""
    points = []
    for index in itertools.product(*[range(len(p.values)) for p in parameters]):
        values = {}
        for p, i in zip(parameters, index):
            for key in p.keys:
                values[key] = p.values[i]
        points.append((index, values))
    for _, values in points:
        # every point's scene is checked here, before anything is traced: a value out of range is one error
        # line naming the key, the same with or without a cluster (not a failed task and a NaN point)
        if values:
            with_values(scene, values)
    return points


def _results_dataset(results: dict, parameters: Sequence[SweepParameter], radius_mm: float) -> xr.Dataset:
    """The traced points' results on the parameter grid (points not in ``results``: NaN), maps on a cavity of
    ``radius_mm``."""
    shape = tuple(len(p.values) for p in parameters)
    first = next(iter(results.values()))

    def grid(getter) -> np.ndarray:
        out = np.full(shape, np.nan, dtype=float)
        for idx, r in results.items():
            v = getter(r)
            out[idx] = np.nan if v is None else v
        return out

    dims = tuple(p.name for p in parameters)
    data = {
        "LER": (dims, grid(lambda r: r.LER), {"units": "1", "long_name": "light extraction ratio"}),
        "YBR": (dims, grid(lambda r: r.YBR), {"units": "1", "long_name": "yellow-to-blue ratio",
                                              "definition": first.to_dict()["YBR_definition"]}),
        "std_err_LER": (dims, grid(lambda r: r.std_err["LER"]), {"units": "1"}),
        "std_err_YBR": (dims, grid(lambda r: r.std_err["YBR"]), {"units": "1"}),
        "ledger_error": (dims, grid(lambda r: r.ledger_error), {"units": "1"}),
        "non_uniformity": (dims, grid(lambda r: r.non_uniformity), {
            "units": "1", "long_name": "irradiance non-uniformity, split-half on the grid it converged on "
            "(converged_non_uniformity)"}),
        "non_uniformity_map": (dims, grid(lambda r: r.non_uniformity_map), {
            "units": "1", "long_name": "(E_max - E_min)/(E_max + E_min) of the whole map (noise included)"}),
    }
    for k in ("blue", "yellow", "total"):
        data[f"extracted_{k}"] = (dims, grid(lambda r, k=k: r.extracted[k]), {"units": "W"})
        data[f"std_err_{k}"] = (dims, grid(lambda r, k=k: r.std_err[k]), {"units": "W"})
    for k in ("wall", "base", "leds", "plate"):
        data[f"absorbed_{k}"] = (dims, grid(lambda r, k=k: r.absorbed[k]), {"units": "W"})
    coords = {}
    for p in parameters:
        vals = np.asarray(p.values) if not any(isinstance(v, str) for v in p.values) else np.asarray(
            [str(v) for v in p.values])
        coords[p.name] = (p.name, vals, {"keys": ",".join(p.keys)})
    if first.irradiance is not None:
        bins = first.irradiance.shape[0]
        maps = np.full(shape + (bins, bins), np.nan)
        for idx, r in results.items():
            maps[idx] = r.irradiance
        centres = (np.arange(bins) + 0.5) / bins * 2 * radius_mm - radius_mm
        coords["y_mm"] = ("y_mm", centres, {"units": "mm"})
        coords["x_mm"] = ("x_mm", centres, {"units": "mm"})
        data["irradiance"] = (dims + ("y_mm", "x_mm"), maps, {"units": "W/mm^2"})
    return xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                      coords={k: xr.Variable(*v) for k, v in coords.items()})


def check_point_count(parameters: Sequence[SweepParameter]) -> int:
    """The number of grid points, refused above :data:`MAX_SWEEP_POINTS` (before anything is traced).

    Parameters
    ----------
    parameters : sequence of SweepParameter
        The swept parameters.

    Returns
    -------
    int
        Product of the parameters' value counts.
    """
    total = 1
    for p in parameters:
        total *= len(p.values)  # Python integers: no overflow
    if total > MAX_SWEEP_POINTS:
        raise InputError("too many sweep points", field="--param",
                         expected=f"a grid of at most MAX_SWEEP_POINTS ({MAX_SWEEP_POINTS}) points",
                         got=" x ".join(str(len(p.values)) for p in parameters) + f" = {total}")
    return total


def plot_paths(out: Path) -> list[Path]:
    """PNG files written next to the netCDF output ``out``.

    Parameters
    ----------
    out : Path
        The netCDF output file.

    Returns
    -------
    list of Path
        The PNG paths.
    """
    return [out.with_name(out.stem + "_LER_YBR.png")]


def sweep_spec(parameters: Sequence[str], rays: int, seed: int, chunk: int | None = None) -> SweepSpec:
    """The sweep of parameter specs ``parameters`` (``KEYS=VALUES``, :func:`parse_parameter`) with ``rays`` rays
    per point, checked to have at most :data:`MAX_SWEEP_POINTS` points.

    Parameters
    ----------
    parameters : sequence of str
        ``KEYS=VALUES`` specs.
    rays : int
        Rays per point.
    seed : int
        Seed of every point.
    chunk : int, optional
        Rays per compiled call (None: the scene's).

    Returns
    -------
    SweepSpec
        The parsed sweep.
    """
    params = tuple(parse_parameter(p) for p in parameters)
    check_point_count(params)
    return SweepSpec(params, rays, seed, chunk)


def run_sweep(scene: Scene, spec: SweepSpec, out: str | Path, *, force: bool = False,
              figure: Callable[[xr.Dataset], Any] | None = None, progress: Callable[[int, int], None] | None = None,
              cluster: Cluster | None = None):
    """Sweep ``scene`` as ``spec`` says (:func:`sweep_spec`), write ``out`` (netCDF) and, with ``figure``, a PNG
    beside it.

    ``figure(ds)`` returns a matplotlib figure (e.g. :func:`bsdfkit.plotting.figures.sweep_figure`); the tracer
    itself draws nothing. Existing outputs are kept unless ``force`` and the scene file is never replaced; this
    is checked before any tracing. The files are one :class:`~bsdfkit.io.atomic.OutputSet`: an interrupted
    sweep leaves the previous files or none, and a rerun needs no ``force``.
    ``cluster`` runs the points on dask.distributed (module docstring). Returns the dataset.

    Parameters
    ----------
    scene : Scene
        The base scene.
    spec : SweepSpec
        Parameters, rays, seed and chunk.
    out : str or Path
        The netCDF file to write.
    force : bool
        Replace existing outputs.
    figure : callable, optional
        ``figure(ds)`` → matplotlib figure, saved as a PNG beside ``out``.
    progress : callable, optional
        Called with (points done, total points) as points finish.
    cluster : Cluster, optional
        Run the points on dask.distributed; None traces them in this process.

    Returns
    -------
    xarray.Dataset
        The sweep dataset as written.

    Raises
    ------
    SweepPointsFailed
        After writing, if some points failed (they are NaN in the outputs).
    """
    out = Path(out)
    names = [out.name] + ([p.name for p in plot_paths(out)] if figure is not None else [])
    # the netCDF file and its plots are one output set: a kill or a fault leaves all of them or none
    with OutputSet(out.parent, names, force, inputs=[scene.path]) as outputs:
        ds = sweep_dataset(scene, spec, progress, cluster)
        write_with(outputs.path(out.name), lambda tmp: ds.to_netcdf(tmp, format="NETCDF4"), True)
        if figure is not None:
            fig = figure(ds)
            write_with(outputs.path(names[1]), lambda tmp: fig.savefig(tmp, dpi=110, format="png"), True)
    if "failed_points" in ds.attrs:
        failed = ds.attrs["failed_points"].splitlines()
        raise SweepPointsFailed(f"{len(failed)} sweep point(s) failed, written as NaN: " + " | ".join(failed), file=out)
    return ds
