"""``ds.bsdf``: the toolkit on any BSDF dataset, registered as an xarray accessor when bsdfkit is imported.

>>> import bsdfkit, xarray as xr
>>> ds = bsdfkit.ingest("measurements/cl830-synthetic")   # doctest: +SKIP
>>> ds.bsdf.tis(45)                                        # doctest: +SKIP
>>> ds.bsdf.profile("bibs", "reflection")                  # doctest: +SKIP
>>> ds.bsdf.save("scan.nc")                                # doctest: +SKIP

Attribute access ``ds.bsdf`` therefore means the accessor: the BSDF data variable is ``ds["bsdf"]``.

The accessor is registered by ``import bsdfkit``, which must stay cheap (no JAX): its methods therefore import
:mod:`bsdfkit.api` when first called, one of the two deferred imports of the package (the other is the CLI's
per-verb import).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import xarray as xr

from bsdfkit.measurement.schema import validate_bsdf_dataset


@xr.register_dataset_accessor("bsdf")
class BsdfAccessor:
    """Methods of bsdfkit on a dataset read by :func:`bsdfkit.ingest` (or any dataset of the same schema)."""

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    def tis(self, incidence_deg: float | None = None, band_nm: tuple[float, float] | None = None) -> xr.Dataset:
        """TIS [fraction]: hemispherical values of elastic data, the interaction TIS of a phosphor plate
        (:func:`bsdfkit.tis`).

        Parameters
        ----------
        incidence_deg : float, optional
            One measured angle of incidence [deg]: only it is reduced. ``None`` reduces every incidence.
        band_nm : tuple of float, optional
            (low, high) [nm]: the band of the band average of elastic data (refused for a phosphor plate);
            the measured range by default.

        Returns
        -------
        xarray.Dataset
            ``tis`` and its standard uncertainties [-] (and, for elastic data, band averages), as
            :func:`bsdfkit.tis`.
        """
        from bsdfkit import api

        return api.tis(self._ds, incidence_deg, band_nm)

    def profile(self, interaction: str, side: str | None = None) -> xr.Dataset:
        """Band-averaged BSDF profile [1/sr] of one interaction (:func:`bsdfkit.profile`).

        Parameters
        ----------
        interaction : {"bibs", "biys", "yiys", "elastic"}
            Interaction of a phosphor plate, or ``"elastic"`` for any other sample.
        side : {"reflection", "transmission"}, optional
            Keep only this side; both by default.

        Returns
        -------
        xarray.Dataset
            ``bsdf`` and ``bsdf_std`` [1/sr] on ``record``, with the records' angles [deg].
        """
        from bsdfkit import api

        return api.profile(self._ds, interaction, side)

    def describe(self) -> dict:
        """Incidences, sides, positions per arc, wavelength range and configurations.

        Returns
        -------
        dict
            JSON-ready summary (:func:`bsdfkit.measurement.describe.describe`).
        """
        from bsdfkit import api

        return api.describe(self._ds)

    def fit(self, interaction: str, side: str, model: str = "lambert+gaussian", **options: Any) -> xr.Dataset:
        """Fit a BSDF model (:func:`bsdfkit.fit_bsdf`), one fit per incidence.

        Parameters
        ----------
        interaction : {"bibs", "biys", "yiys", "elastic"}
            Interaction to fit.
        side : {"reflection", "transmission"}
            Scattering side.
        model : str, optional
            Registered BSDF model, e.g. ``"lambert+gaussian"`` or ``"abg"``.
        **options
            Keyword arguments of :func:`bsdfkit.fit_bsdf`: ``options`` (masks and weights,
            :class:`bsdfkit.fit.least_squares.BsdfFitOptions`) and ``incidence_deg`` (fit only this angle of
            incidence [deg]).

        Returns
        -------
        xarray.Dataset
            On ``theta_i`` [deg]: each model parameter and its ``_std``, fit statistics, ``tis`` and ``tis_std``
            [-] and the plausibility verdict.
        """
        from bsdfkit import api

        return api.fit_bsdf(self._ds, interaction, side, model, **options)

    def validate(self) -> xr.Dataset:
        """The dataset when it follows the BSDF dataset schema, else a one-line
        :class:`~bsdfkit.core.errors.ValidationError` naming the variable, what was expected and what was found
        (:func:`bsdfkit.measurement.schema.validate_bsdf_dataset`).

        Returns
        -------
        xarray.Dataset
            The dataset itself.
        """
        return validate_bsdf_dataset(self._ds)

    def save(self, path: str | Path, force: bool = False) -> Path:
        """Write the dataset to netCDF atomically (never overwrites without ``force``).

        Parameters
        ----------
        path : str or Path
            Output netCDF file.
        force : bool, optional
            Replace an existing file.

        Returns
        -------
        Path
            ``path``.
        """
        from bsdfkit import api

        return api.save(self._ds, path, force)
