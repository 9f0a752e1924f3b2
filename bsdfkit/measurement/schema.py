"""The calibrated BSDF dataset, declared once: its dimensions, variables, coordinates, units and attributes.

Every reader that gives a BSDF dataset builds it with :func:`new_bsdf_dataset` (:func:`calibrate
<bsdfkit.measurement.calibrate.calibrate>` from a raw scan, :func:`records_dataset
<bsdfkit.measurement.table.records_dataset>` for measured tables and vendor files) and the ``ds.bsdf``
accessor checks any dataset with :func:`validate_bsdf_dataset`. ``docs/architecture.md`` ("The calibrated BSDF
dataset") documents the same table; ``tests/measurement/test_schema.py`` compares the two.

Dimensions: ``record`` (one detector position of one configuration), ``wavelength`` [nm] (the scattered,
detected wavelength), ``configuration`` (one incident-light set-up) and ``band_edge`` (``low``, ``high``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import ValidationError

__all__ = ["DIMS", "VARIABLES", "ATTRIBUTES", "Variable", "ANGLE_RANGES_DEG", "READ_REQUIRED", "new_bsdf_dataset",
           "validate_bsdf_dataset"]

#: The dimensions of a BSDF dataset.
DIMS: tuple[str, ...] = ("record", "wavelength", "configuration", "band_edge")

#: dtype kinds (numpy ``dtype.kind``) each declared type accepts; text is object or fixed-width unicode.
_KINDS = {"float": "f", "bool": "b", "int": "iu", "text": "OUS"}


@dataclass(frozen=True)
class Variable:
    """One data variable or coordinate of the BSDF dataset.

    Attributes
    ----------
    name
        Name in the dataset.
    dims
        Its dimensions, in order.
    units
        The ``units`` attribute every dataset carries for it (None for flags and text).
    type
        ``float``, ``bool``, ``int`` or ``text`` (numpy dtype kinds of :data:`_KINDS`).
    coord
        A coordinate (True) or a data variable.
    required
        Every BSDF dataset has it (False: only some sources, see ``meaning``).
    meaning
        One line: what the values are.
    """

    name: str
    dims: tuple[str, ...]
    units: str | None
    type: str
    coord: bool = False
    required: bool = True
    meaning: str = ""


_RW = ("record", "wavelength")
_CW = ("configuration", "wavelength")
#: The variables and coordinates of a BSDF dataset, in the order a reader writes them.
VARIABLES: tuple[Variable, ...] = (
    Variable("bsdf", _RW, "1/sr", "float", meaning="f = P_s/(P_i Ω cos θs); NaN where no incident light or grazing"),
    Variable("bsdf_std", _RW, "1/sr", "float", meaning="standard uncertainty of bsdf"),
    Variable("noise_floor", _RW, "1/sr", "float", meaning="noise-equivalent BSDF (dark noise; NaN when not stated)"),
    Variable("bsdf_bispectral", _RW, "1/(sr nm)", "float",
             meaning="⟨q_λ⟩(λs) for the configuration's incident band, eq. (10) (NaN for elastic data)"),
    Variable("bsdf_bispectral_std", _RW, "1/(sr nm)", "float", meaning="standard uncertainty of bsdf_bispectral"),
    Variable("noise_floor_bispectral", _RW, "1/(sr nm)", "float", meaning="noise-equivalent bi-spectral BSDF"),
    Variable("saturated", _RW, None, "bool", meaning="raw counts at full scale"),
    Variable("below_dark", _RW, None, "bool", required=False,
             meaning="raw scans only: signal far below the dark level (dark frames above the signal?)"),
    Variable("grazing", ("record",), None, "bool", meaning="aperture within one diameter of the horizon; BSDF masked"),
    Variable("incident_spectrum", _CW, "1/nm", "float", meaning="measured incident spectrum, unit integral"),
    Variable("incident_relative_std", _CW, "1", "float",
             meaning="relative standard uncertainty of the reference-beam power per pixel"),
    Variable("incident_valid", _CW, None, "bool", meaning="incident light present (> 1e-3 of peak and > 10σ)"),
    Variable("incident_power_relative_std", ("configuration",), "1", "float",
             meaning="relative standard uncertainty of the band-integrated incident power Φ_i"),
    Variable("incident_band", ("configuration", "band_edge"), "nm", "float",
             meaning="nominal incident band (low, high)"),
    Variable("configuration_description", ("configuration",), None, "text", meaning="what the configuration is"),
    Variable("band_series", ("configuration",), None, "text", required=False,
             meaning="only with a [[band_series]]: its name ('' for a [[configuration]])"),
    Variable("excitation_wavelength", ("configuration",), "nm", "float", required=False,
             meaning="only with a [[band_series]]: nominal band centre"),
    Variable("config", ("record",), None, "text", coord=True, meaning="configuration of the record"),
    Variable("theta_i", ("record",), "deg", "float", coord=True, meaning="incidence polar angle"),
    Variable("phi_i", ("record",), "deg", "float", coord=True, meaning="incidence azimuth (source side)"),
    Variable("theta_s", ("record",), "deg", "float", coord=True,
             meaning="scatter polar angle (transmission: from the back normal)"),
    Variable("phi_s", ("record",), "deg", "float", coord=True, meaning="scatter azimuth (specular at φi − 180°)"),
    Variable("side", ("record",), None, "text", coord=True, meaning="reflection or transmission"),
    Variable("arc", ("record",), None, "text", coord=True, meaning="in_plane, perpendicular or other"),
    Variable("exposure", ("record",), "s", "float", coord=True, meaning="integration time (NaN for tables)"),
    Variable("source_line", ("record",), None, "int", coord=True, meaning="line of the record in its source file"),
    Variable("wavelength", ("wavelength",), "nm", "float", coord=True, meaning="scattered (detected) wavelength"),
    Variable("configuration", ("configuration",), None, "text", coord=True, meaning="configuration names"),
    Variable("band_edge", ("band_edge",), None, "text", coord=True, meaning="low, high"),
)

_BY_NAME = {v.name: v for v in VARIABLES}

#: Attributes every BSDF dataset carries (instrument geometry is NaN for tables and vendor files).
ATTRIBUTES: tuple[str, ...] = (
    "quantity", "frame", "side", "units", "angle_convention", "sample_name", "synthetic", "source",
    "solid_angle_sr", "aperture_half_angle_deg", "gain_e_per_count", "detector_distance_mm",
    "aperture_diameter_mm", "beam_diameter_mm", "manifest_json",
)
#: Attributes whose value is fixed.
FIXED_ATTRIBUTES: dict[str, str] = {"quantity": "bsdf", "frame": "sample", "units": "1/sr"}
#: The angle convention every BSDF dataset states.
ANGLE_CONVENTION = ("sample frame; source at phi_i (deg), specular at phi_s = phi_i - 180; "
                    "transmission angles from the back normal")


def new_bsdf_dataset(data: Mapping[str, Any], coords: Mapping[str, Any], attrs: Mapping[str, Any]) -> xr.Dataset:
    """A BSDF dataset from its values: dims and ``units`` from :data:`VARIABLES`, the fixed attributes
    (:data:`FIXED_ATTRIBUTES`, :data:`ANGLE_CONVENTION`), validated.

    Parameters
    ----------
    data, coords
        Values by name: arrays (given the schema's dims) or DataArrays (kept with their attributes); only names
        of :data:`VARIABLES`, in the order to write them.
    attrs
        The dataset's attributes: those of :data:`ATTRIBUTES` not fixed by the schema, and any more.

    Returns
    -------
    xarray.Dataset
        The dataset; each variable with a declared unit carries it as ``units``.
    """
    def entry(name: str, value: Any) -> Any:
        if isinstance(value, (xr.DataArray, xr.Variable)):
            return value
        return (_BY_NAME[name].dims, value)

    ds = xr.Dataset({k: entry(k, v) for k, v in data.items()},
                    coords={k: entry(k, v) for k, v in coords.items()},
                    attrs={**FIXED_ATTRIBUTES, "angle_convention": ANGLE_CONVENTION, **attrs})
    for name in (*data, *coords):
        units = _BY_NAME[name].units
        if units is not None and ds[name].attrs.get("units") != units:
            ds[name].attrs["units"] = units
    return validate_bsdf_dataset(ds)


def _refuse(ds: xr.Dataset, message: str, field: str, expected: str, got: object,
            file: str | Path | None = None) -> ValidationError:
    return ValidationError(f"not a BSDF dataset: {message}", file=file or ds.attrs.get("source") or None, field=field,
                           expected=expected, got=got)


def validate_bsdf_dataset(ds: xr.Dataset, file: str | Path | None = None) -> xr.Dataset:
    """``ds`` when it follows the schema of :data:`VARIABLES` and :data:`ATTRIBUTES`, else a one-line
    :class:`~bsdfkit.core.errors.ValidationError` naming the variable, what was expected and what was found.

    Checked: the dimensions; each required variable and each optional one present, its dims, dtype kind, being
    a coordinate or not, and its ``units``; the required attributes and their fixed values; the side names.
    Further variables and attributes are allowed.

    A dataset read from a file (``file`` given) is checked as the file's reader must (docs/errors.md, "netCDF
    datasets"): a ``quantity`` attribute other than ``bsdf`` is refused naming both, a missing one is ``bsdf``; a
    missing variable is named with the variables the file holds (a file without bsdfkit's attributes, written by
    plain xarray or another tool, needs only :data:`READ_REQUIRED`); a variable without ``units`` takes the schema's
    unit unless another unit attribute of it (``unit``, ``Units`` …, or the dataset's ``units`` for the 1/sr
    variables) contradicts it, a stated unit must be the schema's; a file that lacks bsdfkit's attributes (written
    by plain xarray or another tool) gets their neutral values; and the values must be plausible: angles within
    their ranges (θ in [0, 90] deg, φ in [−360, 360] deg), wavelengths positive (NaN: not stated), ``bsdf_std``
    ≥ 0, and some finite BSDF value.

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to check (raw or calibrated scan, or a table read as one).
    file : str or Path, optional
        The file ``ds`` was read from (named in every refusal); None for a dataset a reader has just built.

    Returns
    -------
    xarray.Dataset
        ``ds`` itself, unchanged; read from a file: ``ds`` with the schema's units and the neutral attributes it
        lacked (a copy when any was added).

    Raises
    ------
    ValidationError
        The first departure from the schema found.
    """
    required, dims = {v.name for v in VARIABLES if v.required}, DIMS
    if file is not None:
        if not all(name in ds.attrs for name in ATTRIBUTES):  # another tool's file: what the reductions read
            required, dims = set(READ_REQUIRED), ("record", "wavelength")
        ds = _completed(ds, file)
    missing = [d for d in dims if d not in ds.dims]
    if missing:
        raise _refuse(ds, "dimension missing", missing[0], f"dims {', '.join(dims)}", tuple(ds.dims), file)
    for var in VARIABLES:
        if var.name not in ds.variables:
            if var.name in required:
                held = ", ".join(map(str, ds.data_vars)) or "none"
                raise _refuse(ds, f"variable missing (data variables held: {held})", var.name,
                              f"{var.type} on ({', '.join(var.dims)})", "nothing", file)
            continue
        _check_variable(ds, var, file)
    for name in ATTRIBUTES:
        if name not in ds.attrs:
            raise _refuse(ds, "attribute missing", name, "the attributes of docs/architecture.md", "nothing", file)
    for name, value in FIXED_ATTRIBUTES.items():
        if ds.attrs[name] != value:
            raise _refuse(ds, "attribute of another value", name, repr(value), ds.attrs[name], file)
    sides = [str(s) for s in pd.unique(ds["side"].values)]  # hashing: no sort of a million strings
    odd = [s for s in sides + str(ds.attrs["side"]).split() if s not in SIDES]
    if odd:
        raise _refuse(ds, "unknown side", "side", " or ".join(SIDES), odd[0], file)
    if file is not None:
        _check_ranges(ds, file)
    return ds


def _check_variable(ds: xr.Dataset, var: Variable, file: str | Path | None) -> None:
    """Refuse ``ds[var.name]`` on other dims, of another type, misplaced (coordinate / data) or in other units."""
    x = ds[var.name]
    if x.dims != var.dims:
        raise _refuse(ds, "variable on other dims", var.name, f"({', '.join(var.dims)})", x.dims, file)
    if x.dtype.kind not in _KINDS[var.type]:
        raise _refuse(ds, "variable of another type", var.name, var.type, str(x.dtype), file)
    if var.coord != (var.name in ds.coords):
        raise _refuse(ds, "coordinate and data variable mixed up", var.name,
                      "a coordinate" if var.coord else "a data variable",
                      "a data variable" if var.coord else "a coordinate", file)
    if var.units is not None and x.attrs.get("units") != var.units:
        said = "variable in other units" if "units" in x.attrs else "variable states no units attribute"
        raise _refuse(ds, said, var.name, f"units '{var.units}'", x.attrs.get("units"), file)


#: The variables a dataset file written by another tool (plain xarray, without bsdfkit's attributes) must hold:
#: those the reductions read; the other variables of :data:`VARIABLES` are checked when it holds them.
READ_REQUIRED: tuple[str, ...] = ("bsdf", "bsdf_std", "config", "theta_i", "phi_i", "theta_s", "phi_s", "side",
                                  "arc", "wavelength")
#: Attribute names that state a variable's unit besides ``units`` (a file of another tool).
_UNIT_ATTRIBUTES = ("unit", "Units", "UNITS", "Unit", "UNIT")
#: Inclusive ranges [deg] of the angle coordinates of a dataset read from a file.
ANGLE_RANGES_DEG: dict[str, tuple[float, float]] = {
    "theta_i": (0.0, 90.0), "theta_s": (0.0, 90.0), "phi_i": (-360.0, 360.0), "phi_s": (-360.0, 360.0)}


def _completed(ds: xr.Dataset, file: str | Path) -> xr.Dataset:
    """``ds`` read from ``file`` with its quantity checked, the schema's units where it states none (and nothing
    contradicts them) and, when it lacks bsdfkit's attributes, their neutral values."""
    quantity = ds.attrs.get("quantity")
    if quantity is not None and quantity != FIXED_ATTRIBUTES["quantity"]:
        raise ValidationError("dataset holds another quantity", file=file, field="quantity",
                              expected=repr(FIXED_ATTRIBUTES["quantity"]), got=quantity)
    ds = ds.copy()
    ours = all(name in ds.attrs for name in ATTRIBUTES)  # written by bsdfkit: it states every unit
    for var in VARIABLES:
        if var.name not in ds.variables:
            continue
        if var.coord and var.name not in ds.coords:
            ds = ds.set_coords(var.name)  # another tool stored it as a data variable
        attrs = ds[var.name].attrs
        if ours or var.units is None or "units" in attrs:
            continue
        stated = [(k, attrs[k]) for k in _UNIT_ATTRIBUTES if k in attrs]
        if var.units == FIXED_ATTRIBUTES["units"] and "units" in ds.attrs:
            stated.append(("units", ds.attrs["units"]))  # the dataset's: the unit of its BSDF
        for key, unit in stated:
            if str(unit).strip() != var.units:
                owner = "dataset" if key == "units" else "variable"
                raise _refuse(ds, f"variable in other units (attribute {key!r} of the {owner})", var.name,
                              f"units '{var.units}'", unit, file)
        attrs["units"] = var.units
    if not ours:  # the neutral values of bsdfkit's attributes
        sides = " ".join(s for s in SIDES if "side" in ds.variables and s in set(map(str, ds["side"].values)))
        neutral = {**FIXED_ATTRIBUTES, "angle_convention": ANGLE_CONVENTION, "side": sides,
                   "sample_name": Path(file).stem, "synthetic": 0, "source": str(file), "manifest_json": "{}"}
        ds.attrs = {**{name: neutral.get(name, float("nan")) for name in ATTRIBUTES}, **ds.attrs}
        if "bsdf_bispectral" in ds.variables and not np.isfinite(ds["bsdf_bispectral"].values).any():
            ds.attrs.setdefault("elastic", 1)
    return ds


def _check_ranges(ds: xr.Dataset, file: str | Path) -> None:
    """Refuse angles outside :data:`ANGLE_RANGES_DEG`, wavelengths <= 0, negative ``bsdf_std`` and a dataset
    without any finite BSDF value (read from ``file``)."""
    for name, (lo, hi) in ANGLE_RANGES_DEG.items():
        v = np.asarray(ds[name].values, dtype=np.float64)
        bad = ~((v >= lo) & (v <= hi))
        if bad.any():
            k = int(np.argmax(bad))
            raise _refuse(ds, f"angle out of range at record {k}", name, f"{lo:g} <= {name} <= {hi:g} deg",
                          float(v[k]), file)
    lam = np.asarray(ds["wavelength"].values, dtype=np.float64)
    if (lam <= 0).any() or np.isinf(lam).any():
        k = int(np.argmax((lam <= 0) | np.isinf(lam)))
        raise _refuse(ds, "wavelength not positive", "wavelength", "> 0 nm (NaN: not stated)", float(lam[k]), file)
    std = np.asarray(ds["bsdf_std"].values, dtype=np.float64)
    if (std < 0).any():
        k = np.unravel_index(int(np.argmax(std < 0)), std.shape)
        raise _refuse(ds, f"negative uncertainty at record {k[0]}", "bsdf_std", ">= 0 1/sr", float(std[k]), file)
    if not any(np.isfinite(ds[name].values).any() for name in ("bsdf", "bsdf_bispectral") if name in ds):
        raise _refuse(ds, "no finite BSDF value", "bsdf", "finite values where the sample was measured",
                      f"NaN in all {ds['bsdf'].size} values", file)
