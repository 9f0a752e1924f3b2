"""Selecting records of a scan dataset by their labels (configuration, incidence, side, arc)."""
from __future__ import annotations

import numpy as np
import xarray as xr

from bsdfkit.core.errors import InputError


def select(ds: xr.Dataset, *, config: str | None = None, theta_i_deg: float | None = None, side: str | None = None,
           arc: str | None = None, atol_deg: float = 1e-6) -> xr.Dataset:
    """Records matching every given label; raises :class:`InputError` naming the label when none match.

    Parameters
    ----------
    ds : xarray.Dataset
        Scan dataset with a ``record`` dimension (angles in degrees).
    config : str, optional
        Configuration label (e.g. ``"blue"``); None matches all.
    theta_i_deg : float, optional
        Angle of incidence from the sample normal [deg]; None matches all.
    side : {"reflection", "transmission"}, optional
        Scattering side; None matches all.
    arc : str, optional
        Arc label of the scan; None matches all.
    atol_deg : float, optional
        Absolute tolerance of the incidence match [deg].

    Returns
    -------
    xarray.Dataset
        The matching records.
    """
    mask = np.ones(ds.sizes["record"], dtype=bool)
    for name, value in (("config", config), ("side", side), ("arc", arc)):
        if value is not None:
            mask &= ds[name].values == value
            if not mask.any():
                raise InputError("no records with this label", file=ds.attrs.get("source"), field=name,
                                 expected="one of " + ", ".join(sorted(set(map(str, ds[name].values)))), got=value)
    if theta_i_deg is not None:
        mask &= np.isclose(ds["theta_i"].values, theta_i_deg, atol=atol_deg, rtol=0)
        if not mask.any():
            raise InputError("no records at this incidence", file=ds.attrs.get("source"), field="theta_i",
                             expected="one of " + ", ".join(f"{t:g}" for t in incidences(ds)) + " deg", got=theta_i_deg)
    return ds.isel(record=np.flatnonzero(mask))


def incidences(ds: xr.Dataset) -> list[float]:
    """Distinct incidence angles (deg), sorted.

    Parameters
    ----------
    ds : xarray.Dataset
        Scan dataset with a ``record`` dimension (angles in degrees).

    Returns
    -------
    list of float
        Distinct angles of incidence, ascending [deg].
    """
    return sorted(set(np.round(ds["theta_i"].values, 9).tolist()))


def signed_in_plane_theta(ds: xr.Dataset) -> np.ndarray:
    """Signed in-plane scatter angle (deg): + on the specular side (φs = φi − 180°), − on the source side.

    Parameters
    ----------
    ds : xarray.Dataset
        Scan dataset with a ``record`` dimension (angles in degrees).

    Returns
    -------
    ndarray, shape (record,)
        Signed in-plane scatter angle per record [deg].
    """
    specular_phi = (ds["phi_i"].values - 180.0) % 360.0
    on_specular = np.isclose((ds["phi_s"].values - specular_phi + 180.0) % 360.0 - 180.0, 0.0, atol=1e-6)
    return np.where(on_specular | (ds["theta_s"].values < 1e-9), ds["theta_s"].values, -ds["theta_s"].values)
