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
from typing import Any

import pandas as pd
import xarray as xr

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import ValidationError

__all__ = ["DIMS", "VARIABLES", "ATTRIBUTES", "Variable", "new_bsdf_dataset", "validate_bsdf_dataset"]

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


def _refuse(ds: xr.Dataset, message: str, field: str, expected: str, got: object) -> ValidationError:
    return ValidationError(f"not a BSDF dataset: {message}", file=ds.attrs.get("source") or None, field=field,
                           expected=expected, got=got)


def validate_bsdf_dataset(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` when it follows the schema of :data:`VARIABLES` and :data:`ATTRIBUTES`, else a one-line
    :class:`~bsdfkit.core.errors.ValidationError` naming the variable, what was expected and what was found.

    Checked: the dimensions; each required variable and each optional one present, its dims, dtype kind, being
    a coordinate or not, and its ``units``; the required attributes and their fixed values; the side names.
    Further variables and attributes are allowed.

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to check (raw or calibrated scan, or a table read as one).

    Returns
    -------
    xarray.Dataset
        ``ds`` itself, unchanged.

    Raises
    ------
    ValidationError
        The first departure from the schema found.
    """
    missing = [d for d in DIMS if d not in ds.dims]
    if missing:
        raise _refuse(ds, "dimension missing", missing[0], f"dims {', '.join(DIMS)}", tuple(ds.dims))
    for var in VARIABLES:
        if var.name not in ds.variables:
            if var.required:
                raise _refuse(ds, "variable missing", var.name, f"{var.type} on ({', '.join(var.dims)})", "nothing")
            continue
        x = ds[var.name]
        if x.dims != var.dims:
            raise _refuse(ds, "variable on other dims", var.name, f"({', '.join(var.dims)})", x.dims)
        if x.dtype.kind not in _KINDS[var.type]:
            raise _refuse(ds, "variable of another type", var.name, var.type, str(x.dtype))
        if var.coord != (var.name in ds.coords):
            raise _refuse(ds, "coordinate and data variable mixed up", var.name,
                          "a coordinate" if var.coord else "a data variable",
                          "a data variable" if var.coord else "a coordinate")
        if var.units is not None and x.attrs.get("units") != var.units:
            raise _refuse(ds, "variable in other units", var.name, f"units '{var.units}'", x.attrs.get("units"))
    for name in ATTRIBUTES:
        if name not in ds.attrs:
            raise _refuse(ds, "attribute missing", name, "the attributes of docs/architecture.md", "nothing")
    for name, value in FIXED_ATTRIBUTES.items():
        if ds.attrs[name] != value:
            raise _refuse(ds, "attribute of another value", name, repr(value), ds.attrs[name])
    sides = [str(s) for s in pd.unique(ds["side"].values)]  # hashing: no sort of a million strings
    odd = [s for s in sides + str(ds.attrs["side"]).split() if s not in SIDES]
    if odd:
        raise _refuse(ds, "unknown side", "side", " or ".join(SIDES), odd[0])
    return ds
