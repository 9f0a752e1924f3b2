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
"""
from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.io.atomic import check_writable, write_with
from bsdfkit.raytrace.scene import Scene, dumps_scene, with_values
from bsdfkit.raytrace.tracer import trace

_INT = re.compile(r"^[+-]?\d+$")


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
    """Parse ``KEYS=VALUES`` (see module docstring)."""
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
        if len(parts) != 3 or count < 1:
            raise InputError("a range is start:stop:count with count >= 1", field=source,
                             expected="e.g. 0.80:0.98:5", got=rhs)
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


def sweep_dataset(scene: Scene, spec: SweepSpec, progress: Callable[[int, int], None] | None = None):
    """Run every grid point and return an ``xarray.Dataset`` with one dimension per parameter.

    Variables: LER, YBR, extracted_{blue,yellow,total} (W), absorbed_{wall,base,leds,plate} (W), their
    standard errors (``std_err_*``), ledger_error, non_uniformity and, when the scene tallies it, the
    irradiance map (dims …, y_mm, x_mm).
    """
    names = [p.name for p in spec.parameters]
    if len(set(names)) != len(names):
        raise ValidationError("two sweep parameters start with the same key", field="--param",
                              expected="distinct first keys", got=names)
    shape = tuple(len(p.values) for p in spec.parameters)
    results = {}
    total = int(np.prod(shape)) if shape else 1
    for n, index in enumerate(itertools.product(*[range(s) for s in shape])):
        values = {}
        for p, i in zip(spec.parameters, index):
            for key in p.keys:
                values[key] = p.values[i]
        point = with_values(scene, values) if values else scene
        results[index] = trace(point, spec.rays, spec.seed, chunk=spec.chunk)
        if progress is not None:
            progress(n + 1, total)

    first = next(iter(results.values()))

    def grid(getter) -> np.ndarray:
        out = np.empty(shape, dtype=float)
        for idx, r in results.items():
            v = getter(r)
            out[idx] = np.nan if v is None else v
        return out

    dims = tuple(names)
    data = {
        "LER": (dims, grid(lambda r: r.LER), {"units": "1", "long_name": "light extraction ratio"}),
        "YBR": (dims, grid(lambda r: r.YBR), {"units": "1", "long_name": "yellow-to-blue ratio"}),
        "std_err_LER": (dims, grid(lambda r: r.std_err["LER"]), {"units": "1"}),
        "std_err_YBR": (dims, grid(lambda r: r.std_err["YBR"]), {"units": "1"}),
        "ledger_error": (dims, grid(lambda r: r.ledger_error), {"units": "1"}),
        "non_uniformity": (dims, grid(lambda r: r.non_uniformity), {"units": "1",
                                                                    "long_name": "irradiance non-uniformity"}),
    }
    for k in ("blue", "yellow", "total"):
        data[f"extracted_{k}"] = (dims, grid(lambda r, k=k: r.extracted[k]), {"units": "W"})
        data[f"std_err_{k}"] = (dims, grid(lambda r, k=k: r.std_err[k]), {"units": "W"})
    for k in ("wall", "base", "leds", "plate"):
        data[f"absorbed_{k}"] = (dims, grid(lambda r, k=k: r.absorbed[k]), {"units": "W"})
    coords = {}
    for p in spec.parameters:
        vals = np.asarray(p.values) if not any(isinstance(v, str) for v in p.values) else np.asarray(
            [str(v) for v in p.values])
        coords[p.name] = (p.name, vals, {"keys": ",".join(p.keys)})
    if first.irradiance is not None:
        bins = first.irradiance.shape[0]
        maps = np.empty(shape + (bins, bins))
        for idx, r in results.items():
            maps[idx] = r.irradiance
        R = scene.cavity.radius_mm
        centres = (np.arange(bins) + 0.5) / bins * 2 * R - R
        coords["y_mm"] = ("y_mm", centres, {"units": "mm"})
        coords["x_mm"] = ("x_mm", centres, {"units": "mm"})
        data["irradiance"] = (dims + ("y_mm", "x_mm"), maps, {"units": "W/mm^2"})
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                    coords={k: xr.Variable(*v) for k, v in coords.items()})
    ds.attrs.update(rays=spec.rays, seed=spec.seed, scene_toml=dumps_scene(scene),
                    parameters=";".join(",".join(p.keys) + "=" + ",".join(str(v) for v in p.values)
                                        for p in spec.parameters),
                    source="bsdfkit sweep")
    return ds


def plot_paths(out: Path) -> list[Path]:
    """PNG files written next to the netCDF output ``out``."""
    return [out.with_name(out.stem + "_LER_YBR.png")]


def run_sweep(scene: Scene, parameters: Sequence[str], out: str | Path, *, rays: int, seed: int,
              chunk: int | None = None, force: bool = False, figure: Callable[[xr.Dataset], Any] | None = None,
              progress: Callable[[int, int], None] | None = None):
    """Sweep ``scene`` over ``parameters`` (specs), write ``out`` (netCDF) and, with ``figure``, a PNG beside it.

    ``figure(ds)`` returns a matplotlib figure (e.g. :func:`bsdfkit.plotting.figures.sweep_figure`); the tracer
    itself draws nothing. Existing outputs are kept unless ``force``; this is checked before any tracing.
    Returns the dataset.
    """
    plots = figure is not None
    out = Path(out)
    check_writable(out, force)
    if plots:
        for p in plot_paths(out):
            check_writable(p, force)
    params = tuple(parse_parameter(p) for p in parameters)
    ds = sweep_dataset(scene, SweepSpec(params, rays, seed, chunk), progress)
    write_with(out, lambda tmp: ds.to_netcdf(tmp, format="NETCDF4"), force)
    if figure is not None:
        fig = figure(ds)
        write_with(plot_paths(out)[0], lambda tmp: fig.savefig(tmp, dpi=110, format="png"), force)
    return ds
