"""Export a BSDF to a table of any registered format (bsdfkit.tables.registry) and read such tables back.

The data flow is one direction::

    source ──► BSDF callable(s) per side ──► grid (bsdfkit.tables.grids) ──► property/table object ──► file
                                                                                         (bsdfkit.io.*)
    file ──► reader ──► table object ──► TIS recomputed with the writer's quadrature ──► summary

A *source* is one of

* a BSDF callable ``bsdf_fn(theta_i_deg, side, directions) -> bsdf`` (contract in :mod:`bsdfkit.tables.grids`);
  the incidences must then be given;
* a **fit result**: an :class:`xarray.Dataset` (or a netCDF path) with attribute ``model`` =
  ``"lambert"`` | ``"lambert+gaussian"`` | ``"abg"`` | ``"lambert+abg"`` (the models of
  :mod:`bsdfkit.fit.least_squares`) and parameter variables over ``theta_i`` (degrees): ``rho`` (Lambert fraction,
  f = ρ/π), ``A`` and ``sigma`` (Gaussian lobe A·exp(−|β−β0|²/2σ²)), ``A``, ``B``, ``g`` (ABg
  A/(B + |β−β0|^g)); optional ``side`` and ``interaction`` dimensions (or attributes) select the data;
* a **calibrated scan** (a Dataset without ``model``): the hemisphere is reconstructed by
  ``bsdfkit.reduction.tis.hemisphere_bsdf_fn(ds, interaction, side)``, imported only when needed.

Every write is atomic and refuses to overwrite an existing file unless ``force`` (bsdfkit.io.atomic).
"""
from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core import frames
from bsdfkit.core.conventions import WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.fit import plausibility
from bsdfkit.io import atomic, netcdf
from bsdfkit.measurement.schema import validate_bsdf_dataset
from bsdfkit.measurement.table import MAX_ABS_BSDF, _check_values, _Rows
from bsdfkit.models.registry import BSDF_MODELS, bsdf_model
from bsdfkit.reduction.hemispherical import elastic_source, hemispherical, reduction_kind
from bsdfkit.reduction.tis import CENTER, hemisphere_bsdf_fn
from bsdfkit.tables import grids, plausible, registry
from bsdfkit.tables.axes_choice import (
    FALLBACK,  # noqa: F401  (re-exported: the grid modes ExportResult.grid reports)
    FALLBACK_RECHECK,
    RECHECK_FACTOR,
    RECHECK_ROUNDS,
    RECHECK_TIGHTEN,
    VALUES_LABEL,
    plane_symmetric_grid,
)
from bsdfkit.tables.formats import asap, tracepro
from bsdfkit.tables.registry import FileSummary, VendorTable, WriteJob, sniff_format
from bsdfkit.tables.vendor import vendor_dataset

__all__ = [
    "FORMATS",
    "FIT_MODELS",
    "ExportResult",
    "ExportSettings",
    "FileSummary",
    "check_wavelength_nm",
    "export",
    "fit_bsdf_fn",
    "read_any",
    "sniff_format",
]

#: the writable formats of the registry (:mod:`bsdfkit.tables.registry`)
FORMATS: tuple[str, ...] = registry.writable()
#: Parameter names of every registered BSDF model (:mod:`bsdfkit.models.registry`).
FIT_MODELS: dict[str, tuple[str, ...]] = {name: m.parameter_names for name, m in BSDF_MODELS.items()}
_SIDE_CHOICES = ("reflection", "transmission", "both")
_THETA_MATCH_DEG = 1e-9

#: a name of :func:`bsdfkit.tables.registry.writable`
ExportFormat = str
#: ``auto``: tolerance-driven axes (:class:`grids.GridTolerance`); ``fixed``: the fine default axes.
GRID_MODES: tuple[str, ...] = ("auto", "fixed")


def check_wavelength_nm(wavelength_nm: float, field: str = "--wavelength-nm") -> float:
    """``value`` [nm] if it is a wavelength an optical BSDF table can hold; else one clear error.

    Parameters
    ----------
    wavelength_nm : float
        Wavelength [nm].
    field : str
        Option named in the error.

    Returns
    -------
    float
        ``value`` [nm], within :data:`bsdfkit.core.conventions.WAVELENGTH_RANGE_NM`.

    Raises
    ------
    ValidationError
        When ``value`` is not finite or lies outside that range.
    """
    lo, hi = WAVELENGTH_RANGE_NM
    if not (np.isfinite(wavelength_nm) and lo <= wavelength_nm <= hi):
        raise ValidationError("wavelength out of range", field=field, expected=f"a wavelength in {lo:g}-{hi:g} nm",
                              got=wavelength_nm)
    return float(wavelength_nm)


#: what a Harvey–Shack table holds at its nodes (:attr:`ExportSettings.node_values`)
NODE_VALUES = ("point", "edge", "cell")


@dataclass(frozen=True)
class ExportSettings:
    """Choices of an export beyond source, format, side and path. ``None`` means the documented default.

    ``theta_i_deg``: incidences to export (default: those of the fit result or scan).
    ``grid``: ``auto`` (default: axes as fine as the source needs to meet ``grid_tolerance``,
    :func:`grids.auto_harvey_shack_axes` / :func:`grids.auto_specular_axes`; docs/exports.md "Grid
    resolution") or ``fixed`` (the fine default axes :meth:`grids.HarveyShackAxes.default` with TracePro's
    ``zero_azimuth_deg`` or 0 for ASAP, and :meth:`grids.SpecularAxes.default`).
    ``grid_tolerance``: TIS and peak tolerances of the auto grid (:class:`grids.GridTolerance`); its
    ``peak_rtol`` is also the limit of the peak re-check of the written file (``ExportResult.peak_error``).
    ``harvey_shack_axes`` / ``specular_axes``: explicit table axes (override ``grid``).
    ``zemax_symmetry``: ``PlaneSymmetrical`` (the mirror average of the source, refused when the source
    deviates from plane symmetry by more than ``symmetry_tolerance`` of the block maximum),
    ``Asymmetrical`` or ``auto`` (PlaneSymmetrical when the source is, else Asymmetrical; ``convert``'s
    default). ``tracepro_scatter``: ``table`` (Scatter 5) or ``abg`` (Scatter 1, ABg fit results only).
    ``specular_reflectance``/``specular_transmittance`` enter TracePro's energy balance.
    """

    theta_i_deg: tuple[float, ...] | None = None
    harvey_shack_axes: grids.HarveyShackAxes | None = None
    specular_axes: grids.SpecularAxes | None = None
    zemax_symmetry: str = "PlaneSymmetrical"
    tracepro: tracepro.TraceProOptions = field(default_factory=tracepro.TraceProOptions)
    tracepro_scatter: str = "table"
    specular_reflectance: float = 0.0
    specular_transmittance: float = 0.0
    comments: tuple[str, ...] = ()
    symmetry_tolerance: float = 0.01
    #: the wavelength [nm] to write from a spectral elastic dataset (a ray-tracer table holds one)
    wavelength_nm: float | None = None
    grid: str = "auto"
    grid_tolerance: grids.GridTolerance = field(default_factory=grids.GridTolerance)
    #: BSDF XML: ``none`` (front blocks only) or ``mirror`` (Back blocks = Front: a sample symmetric between faces)
    xml_back: str = "none"
    #: BSDF XML: the BSDF of the back face, ``fn(theta_i_deg, side, directions)`` [1/sr] (a source file's own Back
    #: blocks, which ``convert`` passes on), written as the Back blocks; None: ``xml_back`` decides
    xml_back_fn: Any = None
    #: BSDF XML: the label of the written spectral block (``Visible``, what Radiance reads; ``convert`` keeps a
    #: source block's own label, e.g. ``Solar``, rather than call it Visible)
    xml_label: str = "Visible"
    #: BSDF XML basis: ``auto`` (default: a TensorTree3 when the source's specular lobe is narrower than a Klems
    #: patch, else Klems; docs/exports.md §2.4), ``klems`` (always: WINDOW reads only Klems) or ``tree``
    xml_basis: str = "auto"
    #: what a Harvey–Shack table (TracePro, ASAP-style) holds at its nodes: ``edge`` (default: point samples, each
    #: row's last node inside the disk holding its edge value, :func:`grids.harvey_shack_edge_values`), ``point``
    #: samples or ``cell`` averages (:func:`grids.harvey_shack_cell_grid`; auto axes then refined by the lobe's peak
    #: only)
    node_values: str = "edge"
    #: write a source the plausibility gate refuses (a hemispherical value, or R + T, above 1 beyond measurement
    #: noise; :mod:`bsdfkit.tables.plausible`), with a :class:`~bsdfkit.tables.plausible.NonphysicalWarning`
    allow_nonphysical: bool = False

    def __post_init__(self) -> None:
        if self.grid not in GRID_MODES:
            raise ValidationError("unknown grid resolution", field="grid", expected=" or ".join(GRID_MODES),
                                  got=self.grid)
        if self.xml_back not in ("none", "mirror"):
            raise ValidationError("unknown BSDF XML back-side rule", field="xml_back", expected="none or mirror",
                                  got=self.xml_back)
        if not self.xml_label or any(c in self.xml_label for c in "<>&"):
            raise ValidationError("unusable spectral block label", field="xml_label", expected="a plain label",
                                  got=self.xml_label)
        if self.xml_back_fn is not None and (self.xml_back != "none" or not callable(self.xml_back_fn)):
            raise ValidationError("the back face is either the source's own or the front mirrored",
                                  field="xml_back_fn", expected="a BSDF callable with xml_back = none",
                                  got=self.xml_back)
        if self.node_values not in NODE_VALUES:
            raise ValidationError("unknown node values", field="node_values", expected=" or ".join(NODE_VALUES),
                                  got=self.node_values)
        if self.xml_basis not in ("klems", "tree", "auto"):
            raise ValidationError("unknown BSDF XML basis", field="xml_basis", expected="klems, tree or auto",
                                  got=self.xml_basis)
        if self.zemax_symmetry not in ("PlaneSymmetrical", "Asymmetrical", "auto"):
            raise ValidationError("unsupported Zemax symmetry", field="zemax_symmetry",
                                  expected="PlaneSymmetrical, Asymmetrical or auto", got=self.zemax_symmetry)
        if self.tracepro_scatter not in ("table", "abg"):
            raise ValidationError("unknown TracePro scatter mode", field="tracepro_scatter",
                                  expected="table or abg", got=self.tracepro_scatter)
        if not (np.isfinite(self.symmetry_tolerance) and 0.0 <= self.symmetry_tolerance <= 1.0):
            raise ValidationError("symmetry tolerance out of range", field="symmetry_tolerance",
                                  expected="a fraction of the block maximum in [0, 1]", got=self.symmetry_tolerance)
        for t in self.theta_i_deg or ():
            if not (np.isfinite(t) and 0.0 <= t < 90.0):
                raise ValidationError("incidence angle out of range", field="theta_i_deg", expected="[0, 90) deg",
                                      got=t)
        if self.wavelength_nm is not None:
            check_wavelength_nm(self.wavelength_nm)
        for key in ("specular_reflectance", "specular_transmittance"):
            v = getattr(self, key)
            if not (np.isfinite(v) and 0.0 <= v <= 1.0):
                raise ValidationError("specular fraction out of range", field=key, expected="a number in [0, 1]",
                                      got=v)


@dataclass(frozen=True)
class ExportResult:
    """What was written: TIS of the source and of the written table (as `bsdfkit read` integrates it), per side
    and incidence."""

    format: str
    path: str
    sides: tuple[str, ...]
    incidences_deg: tuple[float, ...]
    tis_source: dict[str, list[float]]
    tis_table: dict[str, list[float]]
    plane_symmetry_deviation: float | None = None
    #: size of the written file [bytes]
    size_bytes: int = 0
    #: how the axes were chosen: ``mode`` (auto | fixed | given), ``radial`` and ``azimuth`` node counts,
    #: and for auto the tolerances ``tis_rtol`` and ``peak_rtol``
    grid: dict[str, Any] = field(default_factory=dict)
    #: per side and incidence: the peak of the lobe — the largest BSDF in its core, from the specular direction
    #: outward while the BSDF stays at least half its specular value (:func:`grids.lobe_core`) — of the source
    #: (on the written nodes and the midpoints of their radial segments) [1/sr] and of the table as re-read
    #: [1/sr], and the peak error |peak table / peak source − 1| [1]
    peak_source: dict[str, list[float]] = field(default_factory=dict)
    peak_table: dict[str, list[float]] = field(default_factory=dict)
    peak_error: dict[str, list[float]] = field(default_factory=dict)

    @property
    def worst_peak_error(self) -> float:
        """The largest peak error over sides and incidences [1] (0 for a table-less TracePro ABg property)."""
        return max((v for vals in self.peak_error.values() for v in vals), default=0.0)

    def to_dict(self) -> dict[str, Any]:
        """The result as a JSON-ready dict.

        Returns
        -------
        dict
            The fields (``incidences_deg`` [deg], TIS values [-], ``size_bytes``, ``grid``, peaks [1/sr] and
            peak errors [-]) and ``worst_peak_error`` [-].
        """
        return {"format": self.format, "path": self.path, "sides": list(self.sides),
                "incidences_deg": list(self.incidences_deg), "tis_source": self.tis_source,
                "tis_table": self.tis_table, "plane_symmetry_deviation": self.plane_symmetry_deviation,
                "size_bytes": self.size_bytes, "grid": self.grid, "peak_source": self.peak_source,
                "peak_table": self.peak_table, "peak_error": self.peak_error,
                "worst_peak_error": self.worst_peak_error}


# --------------------------------------------------------------------------------------------------
# sources
# --------------------------------------------------------------------------------------------------
BsdfFn = grids.BsdfFn


def open_bsdf_dataset(path: str | Path, fit_results: bool = False, raw_counts: bool = False) -> xr.Dataset:
    """A netCDF BSDF dataset read and checked before anything is computed from it: the one reader of every verb
    that takes a dataset file (``ingest``/``tis``/``budget``/``fit bsdf``/``convert`` through
    :func:`bsdfkit.tables.to_dataset.ingest`, ``info``, ``export``).

    The schema (:func:`bsdfkit.measurement.schema.validate_bsdf_dataset`: variables, dims, units, quantity,
    ranges) and the values as a measured table's (:func:`check_bsdf_values`); docs/errors.md, "netCDF datasets".

    Parameters
    ----------
    path : str or Path
        The netCDF file (written by bsdfkit, plain xarray or another tool).
    fit_results : bool, optional
        Also accept a fit result (attribute ``model``; its own layout, returned as read).
    raw_counts : bool, optional
        Also accept a raw scan (``quantity = "raw_counts"``; its own layout, returned as read).

    Returns
    -------
    xarray.Dataset
        The dataset in memory (a file without bsdfkit's attributes gets their neutral values).

    Raises
    ------
    InputError
        One line naming the file, the variable or attribute, what was expected and what was found.
    """
    ds = netcdf.load(path)
    if (fit_results and "model" in ds.attrs) or (raw_counts and ds.attrs.get("quantity") == "raw_counts"):
        return ds
    return check_bsdf_values(validate_bsdf_dataset(ds, file=path), path)


def check_bsdf_values(ds: xr.Dataset, path: str | Path) -> xr.Dataset:
    """``ds`` when its ``bsdf`` values pass a measured table's value checks
    (:func:`bsdfkit.measurement.table._check_values`, one rule for both): each value and uncertainty within
    :data:`~bsdfkit.measurement.table.MAX_ABS_BSDF` [1/sr], and at each wavelength a mean not below zero beyond
    the noise (``NEGATIVE_SIGMA`` standard errors of the mean and the median ``bsdf_std``). An all-zero dataset
    (a black sample) is read, unlike an all-zero table: its uncertainties are checked alone.

    Parameters
    ----------
    ds : xarray.Dataset
        A BSDF dataset (schema-checked).
    path : str or Path
        The file it was read from (named in a refusal).

    Returns
    -------
    xarray.Dataset
        ``ds``.

    Raises
    ------
    ValidationError
        The first value refused, naming the record (and the line of its own source, when stated).
    """
    v = np.ascontiguousarray(ds["bsdf"].values, dtype=np.float64)
    n_rec, n_lam = v.shape
    n = v.size
    zeros = np.broadcast_to(np.float64(0.0), (n,))
    rows = _Rows(theta_i=zeros, phi_i=zeros, theta_s=zeros, phi_s=zeros,
                 wavelength=np.tile(np.asarray(ds["wavelength"].values, dtype=np.float64), n_rec),
                 value=v.reshape(-1), std=np.asarray(ds["bsdf_std"].values, dtype=np.float64).reshape(-1),
                 std_relative=np.broadcast_to(np.False_, (n,)), side=np.broadcast_to(np.int8(0), (n,)),
                 spec=np.broadcast_to(np.int16(0), (n,)), line=np.repeat(np.arange(n_rec), n_lam),
                 quantities=["bsdf"], headers=["bsdf"])
    # an all-zero dataset is read (a black sample; the fit says so itself): its uncertainties are checked alone
    scatters = bool(np.any(v[np.isfinite(v)] != 0.0))
    try:
        if scatters:
            _check_values(str(path), rows, None)
        elif np.nanmax(rows.std, initial=0.0) > MAX_ABS_BSDF:
            k = int(np.nanargmax(rows.std))
            raise ValidationError("uncertainty implausibly large", file=path, line=k // n_lam, field="bsdf_std",
                                  expected=f"<= {MAX_ABS_BSDF:g}", got=f"{rows.std[k]:g}")
    except ValidationError as exc:  # said of the record, not of a line of the netCDF file
        record = int(exc.line or 0)
        prefix = f"{path}:{exc.line}: field '{exc.field}': "
        line = int(ds["source_line"].values[record]) if "source_line" in ds.coords else 0
        name = "bsdf" if exc.field == "bsdf" else "bsdf_std"  # the table reader says "uncertainty of 'bsdf'"
        where = f"{name} of record {record}" + (f" (source line {line})" if line > 0 else "")
        raise ValidationError(str(exc).removeprefix(prefix), file=path, field=where) from None
    return ds


def _open_dataset(path: str | Path) -> xr.Dataset:
    return open_bsdf_dataset(path, fit_results=True)


def _select(ds: xr.Dataset, dim: str, value: str, what: str) -> xr.Dataset:
    """Select ``value`` along ``dim`` if present, else check the attribute of that name."""
    if dim in ds.dims:
        values = [str(v) for v in ds[dim].values]
        if value not in values:
            raise ValidationError(f"{what} not in the source", field=dim, expected=" or ".join(values), got=value)
        return ds.sel({dim: value})
    stated = ds.attrs.get(dim)
    if stated is not None and str(stated) != value:
        raise ValidationError(f"source holds another {what}", field=dim, expected=str(stated), got=value)
    return ds


def _fit_parameters(ds: xr.Dataset, model: str) -> dict[float, dict[str, float]]:
    if "theta_i" not in ds.coords:
        raise ValidationError("fit result has no theta_i coordinate", field="theta_i",
                              expected="parameters over theta_i (degrees)", got=list(ds.coords))
    theta = np.atleast_1d(np.asarray(ds["theta_i"].values, dtype=np.float64))
    params: dict[float, dict[str, float]] = {float(t): {} for t in theta}
    for name in FIT_MODELS[model]:
        if name not in ds.data_vars:
            raise ValidationError(f"fit result lacks parameter '{name}' of model {model}", field=name,
                                  expected=", ".join(FIT_MODELS[model]), got=sorted(ds.data_vars))
        var = ds[name]
        extra = [d for d in var.dims if d != "theta_i"]
        if extra:
            raise ValidationError(f"parameter '{name}' has extra dimensions", field=name,
                                  expected="dims (theta_i,)", got=str(var.dims))
        values = np.broadcast_to(np.asarray(var.values, dtype=np.float64), theta.shape)
        for t, v in zip(theta, values):
            if not np.isfinite(v):
                raise ValidationError(f"parameter '{name}' is not finite", field=f"{name}[theta_i={t:g}]",
                                      expected="a finite number", got=float(v))
            params[float(t)][name] = float(v)
    for t, p in params.items():
        where = f"[theta_i={t:g}]"
        if "rho" in p and not 0.0 <= p["rho"] <= 1.0:
            raise ValidationError("Lambert fraction out of range", field="rho" + where, expected="0..1", got=p["rho"])
        if "sigma" in p and p["sigma"] <= 0:
            raise ValidationError("Gaussian width must be positive", field="sigma" + where, expected="> 0",
                                  got=p["sigma"])
        if "A" in p and p["A"] < 0:
            raise ValidationError("lobe amplitude must be >= 0", field="A" + where, expected=">= 0", got=p["A"])
        if "B" in p and (p["B"] < 0 or (p["B"] == 0 and p["g"] != 0)):
            raise ValidationError("ABg B must be > 0 unless g = 0", field="B" + where, expected="> 0", got=p["B"])
    return params


def _model_bsdf_fn(model: str, params: Mapping[float, Mapping[str, float]], side: str) -> BsdfFn:
    thetas = np.array(sorted(params))

    def lookup(theta_i_deg: float) -> Mapping[str, float]:
        k = int(np.argmin(np.abs(thetas - theta_i_deg)))
        if abs(thetas[k] - theta_i_deg) > _THETA_MATCH_DEG:
            raise ValidationError("no fitted parameters at this incidence", field="theta_i",
                                  expected=f"one of {thetas.tolist()}", got=theta_i_deg)
        return params[float(thetas[k])]

    def bsdf_fn(theta_i_deg: float, side_: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        if side_ != side:
            raise ValidationError("fit result does not describe this side", field="side", expected=side, got=side_)
        p = lookup(theta_i_deg)
        distance, _ = frames.harvey_shack_from_direction(directions, np.radians(theta_i_deg))
        return bsdf_model(model).values_at_distance(p, distance)

    return bsdf_fn


def fit_bsdf_fn(ds: xr.Dataset, interaction: str, side: str) -> BsdfFn:
    """BSDF callable of a fit result (see the module docstring for the dataset layout).

    Parameters
    ----------
    ds : xarray.Dataset
        Fit result with attribute ``model`` and parameter variables over ``theta_i`` [deg].
    interaction : str
        Interaction selected along the ``interaction`` dimension (or checked against the attribute).
    side : str
        ``reflection`` or ``transmission``, selected likewise.

    Returns
    -------
    callable
        ``bsdf_fn(theta_i_deg, side, directions)`` → BSDF [1/sr] of the fitted model.
    """
    model = str(ds.attrs.get("model", ""))
    if model not in FIT_MODELS:
        raise ValidationError("unknown fit model", field="model", expected=" | ".join(FIT_MODELS), got=model)
    sub = _select(_select(ds, "interaction", interaction, "interaction"), "side", side, "side")
    return _model_bsdf_fn(model, _fit_parameters(sub, model), side)


@dataclass(frozen=True)
class _Source:
    fns: dict[str, BsdfFn]
    theta_i_deg: NDArray[np.float64]
    abg: tuple[asap.AbgParameters, ...]
    description: str
    #: per exported incidence, how far the table's total scatter may exceed 1 (the gate's k·u(TIS) for a fit)
    tis_excess_allowed: NDArray[np.float64] | float = 0.0
    #: the engine's hemispherical value per side and incidence (elastic datasets): the TIS the table is checked
    #: against, the number ``bsdfkit tis`` reports for the same data
    engine_tis: dict[str, dict[float, float]] | None = None


def _resolve_source(source: Any, interaction: str, sides: tuple[str, ...],
                    theta_i_deg: Sequence[float] | None, wavelength_nm: float | None = None) -> _Source:
    if callable(source) and not isinstance(source, xr.Dataset):
        if theta_i_deg is None:
            raise ValidationError("a BSDF callable needs explicit incidences", field="theta_i_deg",
                                  expected="a list of incidence angles (deg)", got=None)
        return _Source({s: source for s in sides}, np.asarray(theta_i_deg, dtype=np.float64), (),
                       "BSDF callable")
    label = "dataset"
    if isinstance(source, (str, Path)):
        label = Path(source).name
        source = _open_dataset(source)
    if not isinstance(source, xr.Dataset):
        raise ValidationError("unsupported export source", field="source",
                              expected="a BSDF callable, an xarray Dataset or a netCDF path", got=type(source).__name__)
    ds = source
    if "model" in ds.attrs:
        model = str(ds.attrs["model"])
        fns = {s: fit_bsdf_fn(ds, interaction, s) for s in sides}
        theta = np.atleast_1d(np.asarray(ds["theta_i"].values, dtype=np.float64))
        chosen = theta if theta_i_deg is None else np.asarray(theta_i_deg, dtype=np.float64)
        # the one plausibility gate, on exactly what is written (these sides, these incidences); every format alike
        written = [_select(_select(ds, "interaction", interaction, "interaction"), "side", s, "side") for s in sides]
        written = [w.sel(theta_i=[t for t in theta if np.any(np.abs(chosen - t) <= _THETA_MATCH_DEG)])
                   if "theta_i" in w.dims else w for w in written]
        for w in written:
            plausibility.refuse_implausible(w, label)
        allowed = np.sqrt(sum(plausibility.tis_excess_allowed(w, chosen) ** 2 for w in written))
        abg: list[asap.AbgParameters] = []
        if model == "abg":
            for s in sides:
                sub = _select(_select(ds, "interaction", interaction, "interaction"), "side", s, "side")
                for t, p in _fit_parameters(sub, model).items():
                    abg.append(asap.AbgParameters(s, t, p["A"], p["B"], p["g"]))
        return _Source(fns, chosen, tuple(abg), f"fit result ({model}) from {label}, interaction {interaction}",
                       allowed)
    if reduction_kind(ds) == "hemispherical":
        return _elastic(ds, label, interaction, sides, theta_i_deg, wavelength_nm)
    if interaction not in CENTER:
        raise InputError("unknown interaction for a phosphor scan", file=label, field="--interaction",
                         expected=" | ".join(CENTER), got=interaction)
    if wavelength_nm is not None:  # never ignored: each interaction of a phosphor plate has its own band
        raise InputError("--wavelength-nm does not apply to a phosphor interaction (its band is fixed)", file=label,
                         field="--wavelength-nm", expected="no wavelength (or an elastic dataset or a "
                         "per-wavelength model)", got=wavelength_nm)
    fns = {s: hemisphere_bsdf_fn(ds, interaction, s) for s in sides}
    if theta_i_deg is None:
        measured = [set(np.round(np.asarray(f.incidences_deg, dtype=float), 9))
                    for f in fns.values() if hasattr(f, "incidences_deg")]
        if measured:
            common = sorted(set.intersection(*measured))
            if not common:
                raise ValidationError("the sides share no measured incidence; give the incidences",
                                      field="theta_i_deg", expected="incidence angles (deg)", got=None)
            theta_i_deg = np.asarray(common)
        elif "theta_i" not in ds.coords:
            raise ValidationError("scan has no theta_i coordinate; give the incidences", field="theta_i_deg",
                                  expected="incidence angles (deg)", got=None)
        else:
            theta_i_deg = np.unique(np.asarray(ds["theta_i"].values, dtype=np.float64))
    return _Source({s: grids.Pointwise(f) for s, f in fns.items()}, np.asarray(theta_i_deg, dtype=np.float64), (),
                   f"calibrated scan {label}, interaction {interaction}")


#: Interaction names that mean "the elastic scatter of the sample" for a dataset that is not a phosphor scan.
ELASTIC_INTERACTIONS = ("", "elastic")


def _elastic(ds: xr.Dataset, label: str, interaction: str, sides: tuple[str, ...],
             theta_i_deg: Sequence[float] | None, wavelength_nm: float | None) -> _Source:
    """An elastic dataset (any sample) through the hemispherical engine's reconstruction."""
    if interaction not in ELASTIC_INTERACTIONS:
        raise InputError("this dataset holds elastic scatter, not the interactions of a phosphor scan", file=label,
                         field="--interaction", expected="elastic", got=interaction)
    have = sorted(set(map(str, ds["side"].values)))
    for s in sides:
        if s not in have:
            raise InputError("the source holds no data for this side", file=label, field="--side",
                             expected=" or ".join(have), got=s)
    src = elastic_source(ds, sides, wavelength_nm=wavelength_nm,
                         theta_i_deg=None if theta_i_deg is None else [float(t) for t in theta_i_deg])
    common = sorted(set.intersection(*[set(np.round(src.incidences_deg[s], 9)) for s in sides]))
    if not common:
        raise InputError("the sides share no measured incidence", file=label, field="theta_i",
                         expected="a common incidence, or one side")
    engine = {s: {round(t, 6): v for t, v in zip(src.incidences_deg[s], src.tis[s])} for s in sides}
    fns = {s: grids.PiecewiseConstant(src.fn, src.exact_tis, src.basis) if src.piecewise_constant
           else grids.Pointwise(src.fn) for s in sides}
    return _Source(fns, np.asarray(common, dtype=np.float64), (),
                   f"measured dataset {label} at {src.what} (hemispherical engine)", engine_tis=engine)


def _gate(src: _Source, fn: BsdfFn, theta: NDArray[np.float64], sides: tuple[str, ...],
          allow_nonphysical: bool) -> _Source:
    """The source after :func:`bsdfkit.tables.plausible.check` on the sides and incidences written: refused (one
    line) when not physical, else returned; with ``allow_nonphysical`` a warning and, for the writers that check
    energy themselves (TracePro's absorptance), the excess allowed.

    Parameters
    ----------
    src : _Source
        The resolved source.
    fn : callable
        Its BSDF ``fn(theta_i_deg, side, directions)`` [1/sr].
    theta : ndarray
        Incidences written [deg].
    sides : tuple of str
        Sides written.
    allow_nonphysical : bool
        Write anyway, with a :class:`~bsdfkit.tables.plausible.NonphysicalWarning`.

    Returns
    -------
    _Source
        ``src``, with ``tis_excess_allowed`` raised to the source's own excess when it was let through.
    """
    if src.engine_tis is not None:  # a measured dataset: the engine's value, what bsdfkit tis reports
        values = {s: [src.engine_tis[s][round(float(t), 6)] for t in theta] for s in sides}
    elif isinstance(fn, grids.PiecewiseConstant) and fn.exact_tis is not None:  # a file's cells: their basis sum
        values = {s: [fn.exact_tis(float(t), s) for t in theta] for s in sides}
    else:
        values = {s: [grids.tis_reference(fn, float(t), s) for t in theta] for s in sides}
    # a fit keeps its own gate's k·u(TIS) (which already refused its sides in _resolve_source); here it is the margin
    # of the sum and of each side as integrated for the table
    message = plausible.check(values, theta, allowed=src.tis_excess_allowed, allow_nonphysical=allow_nonphysical)
    if message is None:
        return src
    warnings.warn(plausible.NonphysicalWarning(message), stacklevel=3)
    return replace(src, tis_excess_allowed=plausible.excess_to_allow(values, src.tis_excess_allowed))


def _dispatch(fns: Mapping[str, BsdfFn]) -> BsdfFn:
    def bsdf_fn(theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(fns[side](theta_i_deg, side, directions), dtype=np.float64)

    piecewise = grids.piecewise_per_side(fns, bsdf_fn)
    if piecewise is not None:
        return piecewise
    return grids.Pointwise(bsdf_fn) if all(isinstance(f, grids.Pointwise) for f in fns.values()) else bsdf_fn


# --------------------------------------------------------------------------------------------------
# export
# --------------------------------------------------------------------------------------------------
def _peak_check(fn: BsdfFn, to: str, theta: NDArray[np.float64], sides: Sequence[str], path: str | Path,
                settings: ExportSettings, vendor: VendorTable | None = None) -> dict[str, dict[str, list[float]]]:
    """Peak of the lobe of the written file against the source's (see :attr:`ExportResult.peak_error`).

    The table is read back with its format's reader (its registry ``vendor_table``); the source is evaluated at
    the table's nodes and at the
    midpoints of its radial segments on every written azimuth (the mirror average for a PlaneSymmetrical Zemax
    file, which is what that file holds). Both peaks are maxima over the lobe's core
    (:func:`bsdfkit.tables.grids.lobe_core`: from the specular direction outward while the BSDF stays at least
    half its specular value), so a peak the table's nodes step over is seen. ``vendor``: the file's nodes when
    already read (the re-check's re-read of the same file).
    """
    vendor = vendor if vendor is not None else registry.get(to).vendor_table(str(path))
    by_side = {g.side: g for g in vendor.grids}
    first = vendor.grids[0]
    # (side, theta, azimuth, radial); a side the file leaves all zero (TracePro's other column) is zero
    table = np.stack([np.asarray(by_side[s].values, dtype=np.float64) if s in by_side
                      else np.zeros_like(np.asarray(first.values, dtype=np.float64)) for s in sides])
    radial = np.asarray(first.first, dtype=np.float64)
    mids = 0.5 * (radial[:-1] + radial[1:])
    probe_radial = tuple(np.sort(np.concatenate([radial, mids])).tolist())
    if first.kind == "specular":
        azimuth = tuple(float(a) for a in first.azimuth)
        probe = grids.SpecularAxes(probe_radial, azimuth)
        if first.plane_symmetric:
            src = np.stack([plane_symmetric_grid(fn, theta, s, probe, 1.0)[0].values[0] for s in sides])
        else:
            src = grids.specular_grid(fn, theta, sides, probe).values
        horizon = grids.horizon_radial(theta[:, None, None], np.asarray(azimuth)[None, :, None])
        inside = np.radians(radial)[None, None, :] <= horizon
        mid_in = np.radians(mids)[None, None, :] <= horizon
    elif first.kind == "harvey_shack":
        psi = np.asarray(first.azimuth, dtype=np.float64)
        zero = float(first.zero_azimuth_deg)
        probe = grids.HarveyShackAxes(probe_radial, tuple(psi.tolist()), zero)
        src = np.swapaxes(grids.harvey_shack_grid(fn, theta, sides, probe).values, -1, -2)
        edge = grids.rho_max(theta[:, None, None], psi[None, :, None] + zero)
        inside, mid_in = radial[None, None, :] <= edge, mids[None, None, :] <= edge
    else:
        return {}
    # the lobe's core on the written nodes; its midpoints belong to it when both ends do
    core = grids.lobe_core(table, np.broadcast_to(inside, table.shape))
    if first.kind == "harvey_shack" and settings.node_values == "edge":
        # a row's last node inside the disk holds its edge value (the strip up to the edge integrated as the
        # source does, grids.harvey_shack_edge_values), not a sample of the source: the peak is compared on the
        # point samples
        last = np.cumsum(np.broadcast_to(inside, table.shape), axis=-1) == np.sum(inside, axis=-1, keepdims=True)
        core = core & ~(last & np.broadcast_to(inside, table.shape))
    core_src = np.zeros(src.shape, dtype=bool)
    core_src[..., ::2] = core
    core_src[..., 1::2] = core[..., :-1] & core[..., 1:] & mid_in
    peak_src = np.max(np.where(core_src, src, 0.0), axis=(-1, -2))
    peak_tab = np.max(np.where(core, table, 0.0), axis=(-1, -2))
    scale = np.where(peak_src > 0, peak_src, 1.0)
    err = np.abs(peak_tab - peak_src) / scale
    out: dict[str, dict[str, list[float]]] = {"source": {}, "table": {}, "error": {}}
    for k, s in enumerate(sides):
        out["source"][s] = [float(v) for v in peak_src[k]]
        out["table"][s] = [float(v) for v in peak_tab[k]]
        out["error"][s] = [float(v) for v in err[k]]
    return out


@dataclass(frozen=True)
class _Job:
    """What every table written by one :func:`export` call shares: the format, the source and the file."""

    fmt: Any  # the registry's format
    fn: BsdfFn
    theta: NDArray[np.float64]  # exported incidences [deg]
    side: str
    sides: tuple[str, ...]
    src: _Source
    comments: tuple[str, ...]
    path: str | Path
    generated_at: datetime | None


class _Written(NamedTuple):
    """One table written: its axes, its grid description and the last plane-symmetry deviation reported."""

    axes: Any
    grid: dict[str, Any]
    deviation: float | None


class _Rechecked(NamedTuple):
    """The auto grid's re-check: the kept table's grid description, its re-read (None: to read again) and
    nodes, the direct integral per side and incidence, and the last plane-symmetry deviation reported."""

    grid: dict[str, Any]
    summary: FileSummary | None
    nodes: VendorTable | None
    reference: dict[str, list[float]]
    deviation: float | None


def _write(job: _Job, settings: ExportSettings, force: bool, deviation: float | None = None) -> _Written:
    """Write the table with ``settings``; ``deviation``: the one reported by an earlier write of this export."""
    assert job.fmt.write is not None
    outcome = job.fmt.write(WriteJob(fn=job.fn, theta=job.theta, side=job.side, sides=job.sides, settings=settings,
                                     abg=job.src.abg, tis_excess_allowed=job.src.tis_excess_allowed,
                                     comments=job.comments, path=job.path, force=force,
                                     generated_at=job.generated_at))
    if outcome.plane_symmetry_deviation is not None:
        deviation = outcome.plane_symmetry_deviation
    return _Written(outcome.axes, dict(outcome.grid), deviation)


def _doubled(settings: ExportSettings, axes: Any) -> ExportSettings | None:
    """The first auto axes with every azimuth interval bisected (None: no polar axes, or more nodes than the fixed
    grid)."""
    a = np.asarray(getattr(axes, "azimuth_deg", ()), dtype=np.float64)
    if isinstance(axes, grids.HarveyShackAxes):
        both = np.sort(np.concatenate([a, grids.azimuth_midpoints_deg(a)]))
        if len(axes.rho) * both.size > len(grids.HarveyShackAxes.default().rho) * 72:
            return None
        return replace(settings, harvey_shack_axes=grids.HarveyShackAxes(
            axes.rho, tuple(both.tolist()), axes.zero_azimuth_deg))
    if isinstance(axes, grids.SpecularAxes):
        plane = settings.zemax_symmetry == "PlaneSymmetrical" or (
            settings.zemax_symmetry == "auto" and float(a.max(initial=0.0)) <= 180.0 + 1e-9)
        both = np.sort(np.concatenate([a, grids.azimuth_midpoints_deg(a, periodic=not plane)]))
        fixed = grids.SpecularAxes.default(plane_symmetric=plane)
        if len(axes.radial_deg) * both.size > len(fixed.radial_deg) * len(fixed.azimuth_deg):
            return None
        return replace(settings, specular_axes=grids.SpecularAxes(axes.radial_deg, tuple(both.tolist())))
    return None


def _recheck(job: _Job, settings: ExportSettings, first: _Written) -> _Rechecked:
    """The auto table re-checked on the written file, written again (point samples instead of edge values, finer
    axes) until it passes; the table closest to the source is kept (on disk at the end)."""
    # the re-check on the written file: its TIS as bsdfkit read integrates it (the hemispherical engine) against
    # the direct integral of what it samples; the engine interpolates between the spokes otherwise than the
    # format's quadrature the grid was chosen with, so a lobe cut by the horizon may need more azimuths
    theta, sides = job.theta, job.sides
    reference = {s: [grids.tis_reference(job.fn, float(t), s) for t in theta] for s in sides}
    limit = RECHECK_FACTOR * settings.grid_tolerance.tis_rtol
    cell = first.grid.get("values") == VALUES_LABEL["cell"]
    # candidates after the first auto table, in order, until one passes: the axes chosen again for a tighter TIS
    # tolerance (not for cell averages, whose TIS needs no refinement), the first axes with doubled azimuths
    # (the engine interpolates between spokes), the fixed grid; the table closest to the source is kept
    steps: list[tuple[str, Any]] = []
    if first.grid.get("values") == VALUES_LABEL["edge"]:
        # edge values make each row integrate as the source does by the format's rule, but the engine interpolates
        # between spokes otherwise: for a source flat to the horizon (the cl830 biys reconstruction, 5 deg: -0.25 %)
        # it can read point samples closer to the source
        steps.append(("point", None))
    if not cell:
        steps += [("tighter", k) for k in range(1, RECHECK_ROUNDS)]
    steps += [("doubled", None), ("fixed", None)]
    tried = []  # (worst, settings written, grid info) of each table written
    current, written, grid_info = settings, first, first.grid
    summary = nodes = None
    for step, k in [("auto", None)] + steps:
        if step == "point":
            current = replace(settings, node_values="point")
            written = _write(job, current, True, written.deviation)
            grid_info = written.grid
            if grid_info.get("mode") != "auto":
                continue
        elif step == "tighter":
            tighter = replace(settings.grid_tolerance, tis_rtol=settings.grid_tolerance.tis_rtol
                              * RECHECK_TIGHTEN ** k)
            current = replace(settings, grid_tolerance=tighter)
            written = _write(job, current, True, written.deviation)
            grid_info = written.grid
            if grid_info.get("mode") != "auto":  # needs more nodes than the fixed grid: the fixed grid
                continue
            grid_info = dict(grid_info, tis_rtol=tighter.tis_rtol)
        elif step == "doubled":
            candidate = _doubled(settings, first.axes)
            if candidate is None:
                continue
            current = candidate
            written = _write(job, current, True, written.deviation)
            grid_info = dict(tried[0][2], azimuth=int(written.grid.get("azimuth", 0)))
        elif step == "fixed":
            current = replace(settings, grid="fixed")
            written = _write(job, current, True, written.deviation)
            grid_info = dict(written.grid, mode=FALLBACK_RECHECK)
        summary, nodes = _read_any(job.path)
        computed = summary.tis_computed
        worst = max(abs(computed[s][k_] / reference[s][k_] - 1.0) if reference[s][k_] > 0 else 0.0
                    for s in sides for k_ in range(theta.size))
        tried.append((worst, current, dict(grid_info, rechecks=len(tried))))
        if worst <= limit:
            break
    best = min(range(len(tried)), key=lambda i: tried[i][0])
    if best != len(tried) - 1:  # an earlier table was closer to the source: written again
        written = _write(job, tried[best][1], True, written.deviation)
        summary = nodes = None  # both belong to the last file read, which is no longer on disk
    grid_info = dict(tried[best][2])
    if len(tried) > 1:
        grid_info["recheck_worst"] = float(tried[best][0])
    return _Rechecked(grid_info, summary, nodes, reference, written.deviation)


def _format_for(to: str, side: str) -> Any:
    """The registry's format ``to`` after checking it and the side it is asked for."""
    if to not in FORMATS:
        raise ValidationError("unknown export format", field="to", expected=" | ".join(FORMATS), got=to)
    if side not in _SIDE_CHOICES:
        raise ValidationError("unknown side", field="side", expected=" | ".join(_SIDE_CHOICES), got=side)
    fmt = registry.get(to)
    if fmt.sides_per_file == 1 and side == "both":
        raise ValidationError(f"a {fmt.title} file holds one side (one ScatterType); export each side to its own "
                              "file",
                              field="side", expected="reflection or transmission", got=side)
    return fmt


def _table_tis(reread: FileSummary, theta: NDArray[np.float64], sides: Sequence[str],
               held: Mapping[float, float] | None) -> dict[str, list[float]]:
    """The re-read table's TIS per side at each exported incidence."""
    tis_table = {s: reread.tis_computed[s] for s in sides if s in reread.tis_computed}
    if len(reread.incidences_deg) != theta.size or not np.allclose(reread.incidences_deg, theta):
        # a file on its own incidences (BSDF XML: the Klems band centres): each exported incidence is compared
        # with the file incidence that holds it (else the nearest)
        file_theta = np.asarray(reread.incidences_deg, dtype=np.float64)
        index = []
        for t in theta:
            holding = [k for k, c in enumerate(file_theta) if held and abs(held.get(float(c), np.nan) - t) <= 1e-9]
            index.append(holding[0] if holding else int(np.argmin(np.abs(file_theta - t))))
        tis_table = {s: [vals[k] for k in index] for s, vals in tis_table.items()}
    return tis_table


def _write_and_read(job: _Job, settings: ExportSettings, force: bool, let_through: bool
                    ) -> tuple[dict[str, Any], FileSummary, VendorTable | None, dict[str, list[float]] | None,
                               float | None]:
    """Write the table (re-checked and written again by the auto grid) and read it back as ``bsdfkit read`` does.

    ``let_through``: a non-physical source the user let through (``allow_nonphysical``); a format whose own reader
    then refuses the table (a percentage above 100 %) cannot hold it: the file is removed and that is the error.

    Returns
    -------
    tuple
        Grid description, the re-read summary, its nodes (None: the format's own rule), the direct integral per
        side and incidence [-] (None when not computed) and the last plane-symmetry deviation.
    """
    try:
        written = _write(job, settings, force)
        deviation, grid_info = written.deviation, written.grid
        reference: dict[str, list[float]] | None = None
        summary = None  # the written file as read_any read it, while it is the file on disk (its re-read, 3-4 s)
        nodes = None  # and its nodes as the engine integrated them (the peak check reads the same file)
        if grid_info.get("mode") == "auto":
            grid_info, summary, nodes, reference, deviation = _recheck(job, settings, written)
        # the written table, integrated as bsdfkit read integrates it (one number for one file, whatever the path)
        reread, nodes = (summary, nodes) if summary is not None else _read_any(job.path)
    except FormatError as exc:
        if not let_through:
            raise
        Path(job.path).unlink(missing_ok=True)  # never leave a file its own format's reader refuses
        raise ValidationError(f"the {job.fmt.title} format cannot hold this non-physical source: its reader refuses "
                              f"the table written ({exc}); nothing written", field="allow_nonphysical",
                              expected="a source within the format's range") from None
    return grid_info, reread, nodes, reference, deviation


def export(
    source: Any,
    to: ExportFormat,
    interaction: str,
    side: str,
    path: str | Path,
    force: bool = False,
    *,
    settings: ExportSettings | None = None,
    generated_at: datetime | None = None,
) -> ExportResult:
    """Write ``source`` as a ``to`` table for ``side`` (reflection, transmission or both) at ``path``.

    TracePro takes both sides in one file (BRDF and BTDF columns; a side not exported is zero); Zemax
    holds one ScatterType per file (``both`` is refused); ASAP-style tables list the sides as rows.
    Returns the TIS of the source (the hemispherical engine's value for a measured dataset, else the direct
    integral :func:`bsdfkit.tables.grids.tis_reference`) and of the written table as :func:`read_any` integrates
    it (the value ``bsdfkit read`` reports), so that grid adequacy is visible.

    Parameters
    ----------
    source
        A BSDF callable ``bsdf_fn(theta_i_deg, side, directions)`` [1/sr] (incidences then required in
        ``settings``), a fit result or calibrated scan as a Dataset, or a netCDF path (module docstring).
    to
        Target format (a name of :func:`bsdfkit.tables.registry.writable`).
    interaction
        Interaction to select in a fit result or to reconstruct from a phosphor scan (e.g. bibs, biys, yiys).
    side
        ``reflection``, ``transmission`` or ``both``.
    path
        Output file.
    force
        Replace an existing file.
    settings
        Further choices (:class:`ExportSettings`; default: its documented defaults).
    generated_at
        Time stamp of formats that write one (default: now).

    Returns
    -------
    ExportResult
        Sides, incidences [deg], TIS of source and table [-], file size, grid and peak check.
    """
    settings = settings or ExportSettings()
    fmt = _format_for(to, side)
    # before computing: existing output, output that is the source itself (refused even with force), writability
    atomic.check_writable(path, force, inputs=[source] if isinstance(source, (str, Path)) else ())
    sides = frames.SIDES if side == "both" else (side,)
    src = _resolve_source(source, interaction, sides, settings.theta_i_deg, settings.wavelength_nm)
    theta = np.asarray(src.theta_i_deg, dtype=np.float64)
    fn = _dispatch(src.fns)
    if isinstance(fn, grids.PiecewiseConstant) and settings.node_values == "edge":
        # a file's cells: Harvey–Shack nodes hold cell means (steps point-sampled integrate 1-4 % off)
        settings = replace(settings, node_values="cell")
    # the plausibility gate, before anything is written: one rule and one message for every format
    checked = _gate(src, fn, theta, tuple(sides), settings.allow_nonphysical)
    let_through, src = checked is not src, checked  # another object: a non-physical source let through
    job = _Job(fmt=fmt, fn=fn, theta=theta, side=side, sides=tuple(sides), src=src,
               comments=(f"source: {src.description}",) + tuple(settings.comments), path=path,
               generated_at=generated_at)
    grid_info, reread, nodes, reference, deviation = _write_and_read(job, settings, force, let_through)
    held = grid_info.get("klems_incidence_map_deg")
    tis_table = _table_tis(reread, theta, sides, held)
    written_mask = np.ones(theta.size, dtype=bool)
    if held:  # incidences the format's grid does not hold (a Klems band holds the source incidence nearest it)
        written_mask = np.array([any(abs(v - t) <= 1e-9 for v in held.values()) for t in theta])
    if src.engine_tis is not None:
        tis_source = {s: [src.engine_tis[s][round(float(t), 6)] for t in theta] for s in sides}
    else:
        tis_source = reference or {s: [grids.tis_reference(fn, float(t), s) for t in theta] for s in sides}
    kept = replace(settings, node_values=next((k for k, v in VALUES_LABEL.items() if v == grid_info.get("values")),
                                              settings.node_values))  # what the file on disk holds
    peaks = _peak_check(fn, to, theta, sides, path, kept, nodes) if "radial" in grid_info else {}
    if not written_mask.all():
        grid_info["incidences_not_held_deg"] = [float(t) for t in theta[~written_mask]]
        tis_source = {s: [v for v, w in zip(vals, written_mask) if w] for s, vals in tis_source.items()}
        tis_table = {s: [v for v, w in zip(vals, written_mask) if w] for s, vals in tis_table.items()}
        theta = theta[written_mask]
    return ExportResult(
        format=to, path=str(path), sides=tuple(sides), incidences_deg=tuple(float(t) for t in theta),
        tis_source={s: [float(v) for v in vals] for s, vals in tis_source.items()},
        tis_table={s: [float(v) for v in np.asarray(vals)] for s, vals in tis_table.items()},
        plane_symmetry_deviation=deviation, size_bytes=Path(path).stat().st_size, grid=grid_info,
        peak_source=peaks.get("source", {}), peak_table=peaks.get("table", {}), peak_error=peaks.get("error", {}),
    )


# --------------------------------------------------------------------------------------------------
# reading any table
# --------------------------------------------------------------------------------------------------
def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]


def file_tis(path: str | Path, incidences_deg: Sequence[float],
             table: VendorTable | None = None) -> dict[str, list[float]]:
    """Hemispherical TIS per side and incidence of a vendor file by the engine of
    :mod:`bsdfkit.reduction.hemispherical` on the file's nodes (:func:`bsdfkit.tables.vendor.vendor_dataset`): the
    same integral ``bsdfkit tis`` computes for the ingested file. A side the file leaves all zero gives 0.

    Parameters
    ----------
    path
        The vendor file.
    incidences_deg
        Incidences [deg] of the result's lists; each reduced incidence goes to the nearest one.
    table
        The file's nodes when already read by its format's reader (not read again).

    Returns
    -------
    dict of str to list of float
        Side → TIS [-] per entry of ``incidences_deg`` (band average over the file's wavelengths).
    """
    ds = vendor_dataset(path, table=table)
    out: dict[str, list[float]] = {}
    for res in hemispherical(ds, errors=False):
        values = out.setdefault(res.side, [0.0] * len(incidences_deg))
        k = int(np.argmin(np.abs(np.asarray(incidences_deg, dtype=float) - res.theta_i)))
        values[k] = float(res.band_average()["value"])
    return out


def read_any(path: str | Path) -> FileSummary:
    """Read a table of any registered format (:mod:`bsdfkit.tables.registry`) and summarise incidences and TIS
    (see :class:`FileSummary`).

    ``tis_computed`` is the engine's integral of the file's nodes (:func:`file_tis`, one number for one BSDF
    whatever the path); the format's own quadrature on its native grid is kept in
    ``details['tis_format_quadrature']`` (files with several Zemax sample rotations use it as ``tis_computed``).

    Parameters
    ----------
    path
        The table file (format sniffed by content).

    Returns
    -------
    FileSummary
        Format, incidences [deg] and TIS [-] computed and, where the file states it, stated.
    """
    return _read_any(path)[0]


def _read_any(path: str | Path) -> tuple[FileSummary, VendorTable | None]:
    """:func:`read_any` and the file's nodes the engine integrated (None when the format's own rule gives the TIS),
    the file read once (``summary_and_table``) or once by each of its format's two readers."""
    fmt = sniff_format(path)
    both = registry.get(fmt).summary_and_table
    summary, table = both(str(path)) if both is not None else (_read_format(path, fmt), None)
    if any("@rotation=" in k for k in summary.tis_computed):
        summary.details["tis_rule"] = "format quadrature (several sample rotations)"
        return summary, None
    if "tis_rule" in summary.details:  # the format's own rule (a TracePro ABg property holds no table)
        return summary, None
    table = table if table is not None else registry.get(fmt).vendor_table(str(path))
    engine = file_tis(path, summary.incidences_deg, table)
    computed = {k: engine.get(k, [0.0] * len(summary.incidences_deg)) for k in summary.tis_computed
                if k != "total"}
    if "total" in summary.tis_computed:
        computed["total"] = [float(sum(v)) for v in zip(*[computed[k] for k in computed])]
    own = {} if summary.details.get("own_quadrature") is False else {"tis_format_quadrature": summary.tis_computed}
    details = dict(summary.details, **own,
                   tis_rule="bsdfkit.reduction.hemispherical on the file's nodes (as bsdfkit tis)")
    return replace(summary, tis_computed=computed, details=details), table


def _read_format(path: str | Path, fmt: str | None = None) -> FileSummary:
    """The summary of the file's own format ``fmt`` (default: sniffed by content,
    :func:`bsdfkit.tables.registry.sniff_format`)."""
    return registry.get(fmt or sniff_format(path)).summarise(str(path))
