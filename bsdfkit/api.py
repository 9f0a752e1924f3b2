"""The public API: a scan to an exported table in a handful of calls.

Every CLI verb is a thin wrapper over one of these functions, and ``import bsdfkit`` exposes them lazily
(``bsdfkit.ingest`` …) so that the import itself stays cheap.

>>> import bsdfkit
>>> ds = bsdfkit.ingest("measurements/cl830-synthetic")            # doctest: +SKIP
>>> table = bsdfkit.tis(ds, incidence_deg=45)                      # doctest: +SKIP
>>> fit = bsdfkit.fit_bsdf(ds, "bibs", "reflection")               # doctest: +SKIP
>>> bsdfkit.export(fit, "zemax", "bibs", "reflection", "out.bsdf")  # doctest: +SKIP
"""
from __future__ import annotations

import math
import numbers
import os
import reprlib
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bsdfkit.core.errors import ArgumentTypeError, InputError, ValidationError

if TYPE_CHECKING:  # the names of the signatures only; each function imports its engine when called
    import xarray as xr

    from bsdfkit.fit.least_squares import BsdfFitOptions
    from bsdfkit.fit.spectrum import fit_spectrum
    from bsdfkit.pipeline.recipe import Recipe
    from bsdfkit.raytrace import TraceResult
    from bsdfkit.raytrace.scene import Scene
    from bsdfkit.reduction.budget import InteractionTable
    from bsdfkit.tables.export import ExportResult, ExportSettings, FileSummary

#: public names that are another module's function, imported on first use (PEP 562) so that ``bsdfkit.ingest``
#: loads neither JAX nor matplotlib: ``run`` pulls in the pipeline and its report
_REEXPORTS = {"fit_spectrum": "bsdfkit.fit.spectrum"}


def __getattr__(name: str) -> Any:
    if name in _REEXPORTS:
        value = getattr(import_module(_REEXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bsdfkit.api' has no attribute {name!r}")


__all__ = ["ingest", "tis", "budget", "profile", "describe", "save", "fit_bsdf", "fit_spectrum", "export", "read",
           "load_scene", "trace", "run"]

#: what the arguments of the public functions are checked against, before anything is computed (issue #44.6)
PATH = (str, os.PathLike)
REAL = (numbers.Real,)
#: the variables a calibrated scan of :func:`ingest` has and a reduction of it reads (a monochrome scan may have no
#: ``wavelength``)
SCAN_VARIABLES = ("bsdf", "bsdf_std", "config", "side", "theta_i")
#: what a fit reads of a scan or of a profile (:func:`profile`)
PROFILE_VARIABLES = ("bsdf", "bsdf_std", "side", "theta_i")
#: the polar angle of incidence [deg] an ``incidence_deg`` argument may take
INCIDENCE_RANGE_DEG = (0.0, 90.0)


class _Shown:
    """A value as an error message shows it: its type and a short representation."""

    def __init__(self, value: Any, text: str | None = None) -> None:
        self.text = text if text is not None else f"{type(value).__name__} {reprlib.repr(value)}"

    def __repr__(self) -> str:
        return self.text


def check_argument(call: str, name: str, value: Any, kinds: tuple, expected: str, *, optional: bool = False,
                   needs: tuple[str, ...] = (), bounds: tuple[float, float] | None = None) -> Any:
    """``value`` of the argument ``name`` of ``bsdfkit.<call>`` when it is what the function takes; else one line.

    The one check of the public functions' arguments (issue #44.6), made before anything is computed: a list or a
    path where a dataset is expected is a :class:`TypeError` (:class:`~bsdfkit.core.errors.ArgumentTypeError`),
    never an ``AttributeError`` from inside; the right type with the wrong content (a dataset without ``bsdf``, an
    angle out of its range) is a :class:`~bsdfkit.core.errors.ValidationError`. Both name the function, the
    argument, what was expected and what was given.

    Parameters
    ----------
    call : str
        The public function, e.g. ``"tis"``.
    name : str
        The argument.
    value : object
        What was given.
    kinds : tuple of type
        The types accepted (a ``bool`` is no number unless ``bool`` is one of them).
    expected : str
        What the function takes, in words.
    optional : bool, optional
        None is accepted too.
    needs : tuple of str, optional
        Variables (or coordinates) a dataset must have.
    bounds : tuple of float, optional
        Closed range ``(low, high)`` of a number, in the unit of the argument's name.

    Returns
    -------
    object
        ``value``.

    Raises
    ------
    ArgumentTypeError
        The value is of another type (a ``TypeError``).
    ValidationError
        The value lacks a variable of ``needs`` or lies outside ``bounds``.
    """
    if value is None and optional:
        return value
    where = f"bsdfkit.{call}(): argument '{name}'"
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        hint = " (read the file first: bsdfkit.ingest(path))" if "Dataset" in expected and isinstance(value, PATH) \
            else ""
        raise ArgumentTypeError(f"{where} of the wrong type", expected=expected + hint, got=_Shown(value))
    missing = [n for n in needs if n not in value.variables]
    if missing:
        raise ValidationError(f"{where} is missing {', '.join(missing)}",
                              expected=f"{expected} with {', '.join(needs)}",
                              got=_Shown(value, "variables " + ", ".join(map(str, value.variables)) or "none"))
    if bounds is not None and not (math.isfinite(value) and bounds[0] <= value <= bounds[1]):
        raise ValidationError(f"{where} out of range", expected=f"{expected} in [{bounds[0]:g}, {bounds[1]:g}]",
                              got=value)
    return value


def _dataset(call: str, ds: Any, needs: tuple[str, ...] = SCAN_VARIABLES, name: str = "ds") -> xr.Dataset:
    """:func:`check_argument` of a dataset argument."""
    import xarray as xr

    return check_argument(call, name, ds, (xr.Dataset,), "an xarray.Dataset", needs=needs)


def _incidence(call: str, incidence_deg: Any, optional: bool = True) -> Any:
    """:func:`check_argument` of an ``incidence_deg`` argument [deg]."""
    return check_argument(call, "incidence_deg", incidence_deg, REAL, "an angle of incidence [deg]",
                          optional=optional, bounds=INCIDENCE_RANGE_DEG)


def _names(call: str, optional: tuple[str, ...] = (), **names: Any) -> None:
    """:func:`check_argument` of arguments that are names (interaction, side, model, format)."""
    for name, value in names.items():
        check_argument(call, name, value, (str,), "a name (str)", optional=name in optional)


def ingest(path: str | Path, **options: Any) -> xr.Dataset:
    """Read a measurement into a calibrated BSDF dataset.

    Parameters
    ----------
    path
        A raw goniometer export (folder with ``manifest.toml``; read and calibrated), a measured text table
        (:func:`bsdfkit.measurement.table.read_table`), a Zemax/Radiant ``.bsdf``, TracePro or ASAP-style file
        (:func:`bsdfkit.tables.to_dataset.vendor_dataset`) or a netCDF file written by bsdfkit.
    **options
        For text tables and vendor files: ``quantity`` (brdf, btdf, ccbrdf, ccbtdf, reflectance-factor,
        transmittance-factor), ``side``, ``relative_std``, ``wavelength_nm`` [nm], ``incidence_deg`` /
        ``phi_i_deg`` [deg], ``zeros`` (auto, keep, missing), ``sample``; ``face`` (front, back) for a BSDF XML
        file that holds both faces; refused for raw exports and netCDF files.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` [1/sr] per record and wavelength, with angles [deg] and wavelengths [nm].
    """
    from bsdfkit.tables.to_dataset import ingest as _ingest_any

    check_argument("ingest", "path", path, PATH, "a path (str or pathlib.Path) of a measurement")
    return _ingest_any(path, **options)


def tis(ds: xr.Dataset, incidence_deg: float | None = None,
        band_nm: tuple[float, float] | None = None) -> xr.Dataset:
    """TIS [fraction] of any sample: the hemispherical values of elastic data, the interaction TIS of a phosphor
    plate; the same function as ``bsdfkit tis`` (:func:`bsdfkit.reduction.any_sample.tis`).

    Which reduction runs is decided by what the dataset holds
    (:func:`bsdfkit.reduction.hemispherical.reduction_kind`).

    Parameters
    ----------
    ds
        Calibrated dataset from :func:`ingest`.
    incidence_deg
        Incidence angle [deg], one of the measured ones: only that incidence is reduced and ``theta_i`` is a
        scalar coordinate of the result. ``None`` reduces every measured incidence.
    band_nm
        (low, high) [nm], closed. Elastic data: the band of the Δλ-weighted band average (default: the measured
        range). A phosphor plate: refused (:class:`~bsdfkit.core.errors.InputError`, field ``band``), since
        each of its interactions has its own band (bibs 450-470 nm, biys and yiys 470-740 nm).

    Returns
    -------
    xarray.Dataset
        Elastic data (any sample): on (config, side, theta_i [deg], wavelength [nm]) ``tis`` (directional-
        hemispherical reflectance on the reflection side, transmittance on the transmission side), ``tis_std``,
        ``tis_std_measurement``, ``tis_std_reconstruction`` and ``lobe`` [1]; on (config, side, theta_i) their
        band averages ``tis_band``, ``tis_band_std``, ``tis_band_std_measurement``,
        ``tis_band_std_reconstruction``, ``lobe_band`` [1]; method, assumptions and warnings in the JSON attrs
        ``entries`` and ``warnings`` (:func:`bsdfkit.reduction.any_sample.hemispherical_table`).
        A phosphor plate: ``tis`` and its standard uncertainties [1] on (interaction, side, theta_i), the
        two-arc hemisphere reconstruction of ``docs/reductions.md``. The power and photon budget of Table 2 of
        the power-budget paper [1]_ is :func:`budget`.

    References
    ----------
    .. [1] ``docs/references.md``, [Power-budget].
    """
    from bsdfkit.reduction.any_sample import tis as _tis_any

    _dataset("tis", ds)
    _incidence("tis", incidence_deg)
    return _tis_any(ds, incidence_deg, band_nm)


def budget(ds: xr.Dataset, incidence_deg: float) -> InteractionTable:
    """Table 2 of the power-budget paper [1]_ at one measured incidence: TIS in % of the initial power
    and photons per interaction and side, losses and EQE.

    Parameters
    ----------
    ds
        A calibrated phosphor scan (configurations ``blue`` and ``yellow``, both sides, bi-spectral BSDF).
        Elastic data is refused with one line saying why (:class:`~bsdfkit.core.errors.InputError`): its
        hemispherical values are :func:`tis`.
    incidence_deg
        Incidence angle [deg], one of the measured ones.

    Returns
    -------
    InteractionTable
        Power and photon entries [%] with standard uncertainties [%], EQE [1] and the photon ratio of biys.

    References
    ----------
    .. [1] ``docs/references.md``, [Power-budget].
    """
    from bsdfkit.reduction.any_sample import budget as _budget_any

    _dataset("budget", ds)
    _incidence("budget", incidence_deg, optional=False)
    return _budget_any(ds, incidence_deg)


def profile(ds: xr.Dataset, interaction: str, side: str | None = None) -> xr.Dataset:
    """The band-averaged BSDF profile [1/sr] of one interaction (bibs, biys, yiys) per record.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset (:func:`ingest`).
    interaction : {"bibs", "biys", "yiys", "elastic"}
        Interaction of a phosphor plate, or ``"elastic"`` for any other sample.
    side : {"reflection", "transmission"}, optional
        Keep only this side; both by default.

    Returns
    -------
    xarray.Dataset
        ``bsdf`` and ``bsdf_std`` [1/sr] on ``record``, with the records' angles [deg].
    """
    from bsdfkit.reduction.spectral import interaction_profile

    _dataset("profile", ds)
    _names("profile", ("side",), interaction=interaction, side=side)
    return interaction_profile(ds, interaction, side)


def save(ds: xr.Dataset, path: str | Path, force: bool = False) -> Path:
    """Write a dataset to netCDF atomically; an existing file is replaced only with ``force``.

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to write.
    path : str or Path
        Output netCDF file.
    force : bool, optional
        Replace an existing file.

    Returns
    -------
    Path
        ``path``.
    """
    from bsdfkit.io import netcdf

    _dataset("save", ds, needs=())
    check_argument("save", "path", path, PATH, "a path (str or pathlib.Path)")
    check_argument("save", "force", force, (bool,), "True or False")
    return netcdf.save(ds, path, force)


def fit_bsdf(ds: xr.Dataset, interaction: str, side: str, model: str = "lambert+gaussian", *,
             options: BsdfFitOptions | None = None, incidence_deg: float | None = None,
             fallback: bool | None = None) -> xr.Dataset:
    """Fit a BSDF model to one interaction and side of a calibrated dataset, one fit per incidence.

    ``ds`` may also be a profile (a dataset on ``record`` with ``bsdf``, ``bsdf_std`` and one side), which is
    fitted as it is. Models and parameters: :mod:`bsdfkit.models.registry`.

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated dataset, or a profile of one side (:func:`profile`).
    interaction : {"bibs", "biys", "yiys", "elastic"}
        Interaction to fit (ignored for a profile).
    side : {"reflection", "transmission"}
        Scattering side.
    model : str, optional
        Registered BSDF model, e.g. ``"lambert+gaussian"`` or ``"abg"``.
    options : BsdfFitOptions, optional
        Masks and weights of the fit (:class:`bsdfkit.fit.least_squares.BsdfFitOptions`).
    incidence_deg : float, optional
        Fit only the records at this angle of incidence [deg]; all incidences by default.
    fallback : bool, optional
        Whether a lobe model (``lambert+gaussian``, ``lambert+abg``) falls back to ``lambert`` when the data do not
        determine its lobe at any incidence; default ``options.fallback`` (True). False: the requested model or an
        error.

    Returns
    -------
    xarray.Dataset
        On ``theta_i`` [deg]: each parameter and its ``_std`` (ρ [-], A [1/sr], σ, B, g [-]), fit statistics,
        ``tis`` and ``tis_std`` [-] and the plausibility verdict. ``attrs['model']`` (and ``model_used``) is the model
        fitted, ``attrs['model_requested']`` the one asked for, ``attrs['fallback_reason']`` why they differ ("" when
        they do not).

    Raises
    ------
    InputError
        The data hold no finite BSDF value, or values the fit refuses (:func:`bsdfkit.fit.least_squares.fit_bsdf`).
    FitError
        Too few usable points, or a lobe the data show but do not determine (one line naming incidence and cause).
    """
    import dataclasses

    import numpy as np

    from bsdfkit.fit.least_squares import BsdfFitOptions as _Options
    from bsdfkit.fit.least_squares import fit_bsdf as _fit_bsdf_profile
    from bsdfkit.reduction.spectral import interaction_profile

    _dataset("fit_bsdf", ds, needs=PROFILE_VARIABLES)
    _names("fit_bsdf", interaction=interaction, side=side, model=model)
    check_argument("fit_bsdf", "options", options, (_Options,), "a BsdfFitOptions", optional=True)
    _incidence("fit_bsdf", incidence_deg)
    check_argument("fit_bsdf", "fallback", fallback, (bool,), "True, False or None", optional=True)
    prof = ds if "wavelength" not in ds.dims else interaction_profile(ds, interaction, side)
    finite = np.flatnonzero(np.isfinite(prof["bsdf"].values))
    if prof.sizes.get("record", 0) and finite.size == 0:  # NaN are gaps of a spectral grid; all NaN is no data
        raise InputError("no finite BSDF value to fit", file=str(ds.attrs.get("source", "")) or None, field="bsdf",
                         expected=f"finite values of {interaction} {side}", got=f"NaN on all {prof.sizes['record']} "
                         "records")
    options = options or _Options()
    if fallback is not None:
        options = dataclasses.replace(options, fallback=fallback)
    return _fit_bsdf_profile(prof.isel(record=finite), model, options=options, incidence_deg=incidence_deg)


def export(source: Any, to: str, interaction: str, side: str, path: str | Path, force: bool = False, *,
           settings: ExportSettings | None = None, wavelength_nm: float | None = None) -> ExportResult:
    """Write a table of a registered format (TracePro, Zemax, ASAP-style, BSDF XML …) of a dataset or fit, with the
    TIS check of the written file.

    ``wavelength_nm`` [nm] picks one wavelength of a model with a wavelength dimension (e.g. the Lambertian
    model of a reflectance standard, :func:`bsdfkit.fit.lambertian.lambertian_from_reflectance`) or of a
    measured spectral dataset (reconstructed by :mod:`bsdfkit.reduction.hemispherical`); the tables are
    monochrome. A measured elastic dataset takes ``interaction="elastic"``.

    Parameters
    ----------
    source : xarray.Dataset or str or Path
        A calibrated dataset, a fit (:func:`fit_bsdf`) or a netCDF file of either.
    to : str
        Registered format, e.g. ``"tracepro"``, ``"zemax"``, ``"asap"``, ``"bsdfxml"``, ``"speos"``.
    interaction : {"bibs", "biys", "yiys", "elastic"}
        Interaction written.
    side : {"reflection", "transmission"}
        Scattering side written.
    path : str or Path
        Output file.
    force : bool, optional
        Replace an existing file.
    settings : ExportSettings, optional
        Grid and options of the table (:class:`bsdfkit.tables.export.ExportSettings`).
    wavelength_nm : float, optional
        Wavelength picked from a per-wavelength model or a measured spectral dataset [nm].

    Returns
    -------
    ExportResult
        The written file with its grid and the TIS of the table against the source's [-].
    """
    from dataclasses import replace

    import xarray as xr

    from bsdfkit.fit.lambertian import at_wavelength
    from bsdfkit.io import netcdf
    from bsdfkit.tables.export import ExportSettings, check_wavelength_nm
    from bsdfkit.tables.export import export as _export

    if not callable(source):  # a BSDF callable is a source of the engine too
        check_argument("export", "source", source, (xr.Dataset, *PATH), "an xarray.Dataset (a scan or a fit) or the "
                       "path of its netCDF file")
    _names("export", to=to, interaction=interaction, side=side)
    check_argument("export", "path", path, PATH, "a path (str or pathlib.Path)")
    check_argument("export", "force", force, (bool,), "True or False")
    check_argument("export", "settings", settings, (ExportSettings,), "an ExportSettings", optional=True)
    check_argument("export", "wavelength_nm", wavelength_nm, REAL, "a wavelength [nm]", optional=True)
    if wavelength_nm is not None:
        check_wavelength_nm(wavelength_nm)
        model = source if isinstance(source, xr.Dataset) else netcdf.load(source)
        if "model" not in model.attrs and "bsdf" in model:  # a measured dataset: the engine picks the wavelength
            settings = replace(settings or ExportSettings(), wavelength_nm=float(wavelength_nm))
            return _export(model, to, interaction, side, path, force, settings=settings)
        if "wavelength" not in model.dims or "model" not in model.attrs:
            raise InputError("--wavelength-nm applies to a model with a wavelength dimension or a measured dataset",
                             file=None if isinstance(source, xr.Dataset) else source, field="wavelength",
                             expected="a per-wavelength model (bsdfkit fit reflectance)", got=wavelength_nm)
        source = at_wavelength(model, float(wavelength_nm))
    return _export(source, to, interaction, side, path, force, settings=settings)


def read(path: str | Path) -> FileSummary:
    """Read a table of any registered format back (sniffed by content): its grid, stated TIS and recomputed TIS.

    Parameters
    ----------
    path : str or Path
        Table of a registered format.

    Returns
    -------
    FileSummary
        Format, grid, stated TIS and TIS recomputed from the values [-].
    """
    from bsdfkit.tables.export import read_any

    check_argument("read", "path", path, PATH, "a path (str or pathlib.Path) of a table")
    return read_any(path)


def trace(scene: Scene | str | Path, rays: int, seed: int = 0, **options: Any) -> TraceResult:
    """Monte Carlo of a mixing cavity with a phosphor plate (a scene object or a scene TOML path).

    Parameters
    ----------
    scene : Scene or str or Path
        Scene object, or a scene TOML file.
    rays : int
        Number of rays, ≥ 1.
    seed : int, optional
        Key of the random numbers, in [0, 2**63).
    **options
        Keyword arguments of :func:`bsdfkit.raytrace.trace` (``chunk``, ``lanes``, ``progress`` …).

    Returns
    -------
    TraceResult
        Extracted power [W], budget, tallies and timings.
    """
    from bsdfkit.raytrace import trace as _trace
    from bsdfkit.raytrace.scene import Scene

    check_argument("trace", "scene", scene, (Scene, *PATH), "a Scene or the path of a scene TOML file")
    check_argument("trace", "rays", rays, (numbers.Integral,), "a number of rays (int)")
    check_argument("trace", "seed", seed, (numbers.Integral,), "a seed (int)")
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    return _trace(scene, rays, seed, **options)


def load_scene(path: str | Path) -> Scene:
    """A scene TOML file as a :class:`bsdfkit.raytrace.scene.Scene`; a phosphor top given as ``from =
    "<recipe>.toml"`` gets the plate of that fitting recipe's measurement (read, calibrated and fitted).

    Parameters
    ----------
    path : str or Path
        The scene TOML file.

    Returns
    -------
    Scene
        The scene, validated.
    """
    from bsdfkit.raytrace import load_scene as _load_scene

    check_argument("load_scene", "path", path, PATH, "a path (str or pathlib.Path) of a scene TOML file")
    return _load_scene(path, plate_resolver=_recipe_plate)


def describe(ds: xr.Dataset) -> dict:
    """Incidences, sides, positions per arc, wavelength range and configurations of a raw or calibrated scan
    (:func:`bsdfkit.measurement.describe.describe`).

    Parameters
    ----------
    ds : xarray.Dataset
        Raw scan or calibrated one (:func:`ingest`).

    Returns
    -------
    dict
        JSON-ready summary: incidences [deg], sides, positions, wavelength range [nm], configurations.
    """
    from bsdfkit.measurement.describe import describe as _describe

    _dataset("describe", ds, needs=("side", "theta_i", "wavelength"))
    return _describe(ds)


def run(recipe: Recipe | str | Path, out_dir: str | Path, force: bool = False, **options: Any) -> dict:
    """Run every stage of a fitting recipe and write its outputs into ``out_dir``; the same function as ``bsdfkit
    run`` (:func:`bsdfkit.pipeline.recipe.run`, whose docstring has the options).

    Parameters
    ----------
    recipe : Recipe or str or Path
        A recipe (:func:`bsdfkit.pipeline.recipe.load_recipe`), or its TOML file.
    out_dir : str or Path
        Output folder.
    force : bool, optional
        Replace an existing, non-empty output folder as a whole.
    **options
        ``log``, ``progress`` and ``helper_processes`` of :func:`bsdfkit.pipeline.recipe.run`.

    Returns
    -------
    dict
        The run summary (as written to summary.json).
    """
    from bsdfkit.pipeline.recipe import Recipe
    from bsdfkit.pipeline.recipe import run as _run

    check_argument("run", "recipe", recipe, (Recipe, *PATH), "a Recipe or the path of a recipe TOML file")
    check_argument("run", "out_dir", out_dir, PATH, "a path (str or pathlib.Path) of the output folder")
    check_argument("run", "force", force, (bool,), "True or False")
    return _run(recipe, out_dir, force, **options)


def _recipe_plate(recipe: Path) -> Any:
    # the plate resolver of scenes: the pipeline (read, calibrate, fit) is imported only when a scene names a
    # recipe, so loading any other scene (and `bsdfkit trace` of it) does not import it
    from bsdfkit.pipeline.plate_from_scan import plate_from_recipe

    return plate_from_recipe(recipe)

