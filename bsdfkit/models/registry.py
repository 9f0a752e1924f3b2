"""One registry of the parametric models: each BSDF and spectrum model once, with parameters and JAX function.

Every consumer takes a model from here: the fits (:mod:`bsdfkit.fit.least_squares`), the exports
(:mod:`bsdfkit.tables.export`), the TracePro ABg property (:mod:`bsdfkit.tables.formats.tracepro`), the
figures and the command line (``--model`` choices). A model is a function of the Harvey–Shack distance
d = |β − β0| from the specular (or undeviated) direction, β0 = (sin θi, 0), [1]_; its TIS over the unit disk
is exact for the clipped lobe (:mod:`bsdfkit.models.functions`).

>>> from bsdfkit.models.registry import bsdf_model
>>> m = bsdf_model("lambert+gaussian")
>>> [p.name for p in m.parameters]
['rho', 'A', 'sigma']

References
----------
.. [1] ``docs/references.md``, [Harvey-Shack] and [Power-budget] §4.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import jitted, x64
from bsdfkit.core.lazy import LazyModule

# the names, parameters and bounds of the models are read by light verbs (--model choices, the export's
# plausibility gate on a vendor table): JAX and the model functions are imported when a model is evaluated
jnp = LazyModule("jax.numpy")
f = LazyModule("bsdfkit.models.functions")
led = LazyModule("bsdfkit.models.led")

__all__ = ["Parameter", "BsdfModel", "BSDF_MODELS", "bsdf_model", "SpectrumModel", "SPECTRUM_MODELS",
           "spectrum_model"]


@dataclass(frozen=True)
class Parameter:
    """A model parameter: name, bounds (inclusive limits never reached; ±inf for none) and unit."""

    name: str
    lower: float = -math.inf
    upper: float = math.inf
    unit: str = ""

    def __post_init__(self) -> None:
        if not (self.lower < self.upper):
            raise ValidationError(
                "parameter bounds are empty", field=self.name, expected="lower < upper",
                got=(self.lower, self.upper),
            )

    @property
    def transform(self) -> str:
        """'logit', 'log', 'neglog' or 'identity': the map to unconstrained space used by the fits."""
        lo, hi = math.isfinite(self.lower), math.isfinite(self.upper)
        if lo and hi:
            return "logit"
        if lo:
            return "log"
        if hi:
            return "neglog"
        return "identity"


@dataclass(frozen=True)
class BsdfModel:
    """A BSDF model of the registry.

    Attributes
    ----------
    name
        Registry key, e.g. ``"lambert+gaussian"``.
    parameters
        Parameters in the order of the parameter vector, with bounds and units.
    radial
        JAX function ``radial(p, d) -> f [1/sr]`` of the parameter vector ``p`` and d = |β − β0|.
    tis
        JAX function ``tis(theta_i [rad], *p) -> TIS [1]`` over the unit disk (clipped lobe, exact).
    description
        One line for help texts.
    """

    name: str
    parameters: tuple[Parameter, ...]
    radial: Callable
    tis: Callable
    description: str

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def function(self, p: jnp.ndarray, x: Mapping[str, jnp.ndarray]) -> jnp.ndarray:
        """JAX model at angles ``x`` = {theta_i, theta_s, phi_s} [rad] (source at φi = π), in 1/sr.

        Parameters
        ----------
        p : jax.Array
            Parameter vector in the order of ``parameters`` (ρ [-], A [1/sr], σ, B, g [-]).
        x : Mapping of str to jax.Array
            ``theta_i``, ``theta_s`` and ``phi_s`` [rad].

        Returns
        -------
        jax.Array
            BSDF [1/sr].
        """
        d = f.delta_beta(x["theta_i"], x["theta_s"], x["phi_s"])
        return self.radial(p, d)

    def vector(self, params: Mapping[str, float]) -> NDArray[np.float64]:
        """The parameter vector of a name → value mapping (raises naming a missing parameter).

        Parameters
        ----------
        params : Mapping of str to float
            Parameter name → value (ρ [-], A [1/sr], σ, B, g [-]).

        Returns
        -------
        ndarray
            Parameter vector in the order of ``parameters``.
        """
        missing = [n for n in self.parameter_names if n not in params]
        if missing:
            raise ValidationError(f"model {self.name} lacks parameters", field=", ".join(missing),
                                  expected=", ".join(self.parameter_names), got=sorted(params))
        return np.array([float(params[n]) for n in self.parameter_names], dtype=np.float64)

    def values_at_distance(self, params: Mapping[str, float], d: ArrayLike) -> NDArray[np.float64]:
        """NumPy evaluator: the BSDF [1/sr] at Harvey–Shack distances d = |β − β0| (float64).

        Parameters
        ----------
        params : Mapping of str to float
            Parameter name → value (ρ [-], A [1/sr], σ, B, g [-]).
        d : array_like
            Harvey–Shack distance |β − β0| in direction cosines [-].

        Returns
        -------
        ndarray
            BSDF [1/sr].
        """
        with x64():
            return np.asarray(self.radial(jnp.asarray(self.vector(params)), jnp.asarray(d, dtype=jnp.float64)))

    def values(self, params: Mapping[str, float], theta_i_deg: ArrayLike, theta_s_deg: ArrayLike,
               phi_s_deg: ArrayLike) -> NDArray[np.float64]:
        """NumPy evaluator: the BSDF [1/sr] at angles in degrees (source at φi = 180°).

        Parameters
        ----------
        params : Mapping of str to float
            Parameter name → value (ρ [-], A [1/sr], σ, B, g [-]).
        theta_i_deg : array_like
            Angle of incidence [deg].
        theta_s_deg : array_like
            Scatter polar angle [deg].
        phi_s_deg : array_like
            Scatter azimuth [deg].

        Returns
        -------
        ndarray
            BSDF [1/sr] (broadcast shape of the angles).
        """
        with x64():
            d = f.delta_beta(*(jnp.radians(jnp.asarray(a, dtype=jnp.float64))
                               for a in (theta_i_deg, theta_s_deg, phi_s_deg)))
            return np.asarray(self.radial(jnp.asarray(self.vector(params)), d))

    def total_integrated_scatter(self, params: Mapping[str, ArrayLike], theta_i_deg: ArrayLike) -> NDArray:
        """TIS [1] over the unit disk at incidences [deg]; parameters may be arrays over the incidences.

        Parameters
        ----------
        params : Mapping of str to array_like
            Parameter name → value or values, one per incidence (ρ [-], A [1/sr], σ, B, g [-]).
        theta_i_deg : array_like
            Angle of incidence [deg].

        Returns
        -------
        ndarray
            TIS [-] (fraction of the incident power).
        """
        with x64():
            args = [jnp.asarray(params[n], dtype=jnp.float64) for n in self.parameter_names]
            return np.asarray(jitted(self.tis)(jnp.radians(jnp.asarray(theta_i_deg, dtype=jnp.float64)), *args))


def _lambert(p, d):
    return jnp.broadcast_to(f.lambert(p[0]), jnp.shape(d))


def _lambert_gaussian(p, d):
    return f.lambert(p[0]) + f.gaussian_lobe(d, p[1], p[2])


def _abg(p, d):
    return f.abg(d, p[0], p[1], p[2])


def _lambert_abg(p, d):
    return f.lambert(p[0]) + f.abg(d, p[1], p[2], p[3])


def _tis_lambert_gaussian(theta_i, rho, A, sigma):
    return f.tis_lambert_gaussian(theta_i, rho, A, sigma)


def _tis_abg(theta_i, A, B, g):
    return f.tis_abg(theta_i, A, B, g)


def _tis_lambert_abg(theta_i, rho, A, B, g):
    return f.tis_lambert_abg(theta_i, rho, A, B, g)


def _tis_lambert(theta_i, rho):
    return jnp.broadcast_to(f.tis_lambert(rho), jnp.broadcast_shapes(jnp.shape(theta_i), jnp.shape(rho)))


_RHO = Parameter("rho", 0.0, 1.0, "1")
_A = Parameter("A", 0.0, math.inf, "1/sr")
_SIGMA = Parameter("sigma", 0.0, math.inf, "1")
_B = Parameter("B", 0.0, math.inf, "1")
_G = Parameter("g", 0.0, 3.0, "1")

#: The BSDF models, by name.
BSDF_MODELS: dict[str, BsdfModel] = {
    m.name: m for m in (
        BsdfModel("lambert", (_RHO,), _lambert, _tis_lambert, "Lambertian: rho/pi"),
        BsdfModel("lambert+gaussian", (_RHO, _A, _SIGMA), _lambert_gaussian, _tis_lambert_gaussian,
                  "rho/pi + A exp(-d^2 / 2 sigma^2) (Gaussian lobe in direction cosines)"),
        BsdfModel("abg", (_A, _B, _G), _abg, _tis_abg, "A / (B + d^g)"),
        BsdfModel("lambert+abg", (_RHO, _A, _B, _G), _lambert_abg, _tis_lambert_abg, "rho/pi + A / (B + d^g)"),
    )
}


def bsdf_model(name: str) -> BsdfModel:
    """The registered BSDF model ``name`` (raises naming the known models otherwise).

    Parameters
    ----------
    name : str
        Registry key, e.g. ``"lambert+gaussian"``.

    Returns
    -------
    BsdfModel
    """
    try:
        return BSDF_MODELS[name]
    except KeyError:
        raise ValidationError("unknown BSDF model", field="model", expected=" | ".join(BSDF_MODELS),
                              got=name) from None


# ------------------------------------------------------------------------------------------------
# Spectrum models: S(λ) in the input's units; θ the parameter vector in the order of ``parameters``
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpectrumModel:
    """An emission-spectrum model of the registry.

    Attributes
    ----------
    name
        Registry key, e.g. ``"split-gaussian"``.
    parameters
        (name, unit) of each entry of the parameter vector. Bounds depend on the data (the fitted
        wavelength range) and are set by :mod:`bsdfkit.fit.spectrum`.
    function
        JAX function ``function(theta, wavelength [nm]) -> S`` (module level: hashable, compiled once).
    description
        One line for help texts.
    """

    name: str
    parameters: tuple[tuple[str, str], ...]
    function: Callable
    description: str

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.parameters)


def _gaussian(theta, wavelength):
    return theta[2] * f.gaussian_spectrum(wavelength, theta[0], theta[1])


def _split_gaussian(theta, wavelength):
    return theta[3] * f.split_gaussian_spectrum(wavelength, theta[0], theta[1], theta[2])


def _ohno2005(theta, wavelength):
    return theta[2] * led.ohno2005_fwhm_spectrum(wavelength, theta[0], theta[1])


def _split_pseudo_voigt(theta, wavelength):
    return theta[4] * led.split_pseudo_voigt_spectrum(wavelength, theta[0], theta[1], theta[2], theta[3])


def _split_pearson7(theta, wavelength):
    return theta[4] * led.split_pearson7_spectrum(wavelength, theta[0], theta[1], theta[2], theta[3])


def _side_band(theta, wavelength):
    """The split-Gaussian side band of the ``*-shoulder`` models (offset from the main peak)."""
    return theta[7] * f.split_gaussian_spectrum(wavelength, theta[0] + theta[5], theta[6], theta[8])


def _pseudo_voigt_shoulder(theta, wavelength):
    return _split_pseudo_voigt(theta[:5], wavelength) + _side_band(theta, wavelength)


def _pearson7_shoulder(theta, wavelength):
    return _split_pearson7(theta[:5], wavelength) + _side_band(theta, wavelength)


def _two_band(theta, wavelength):
    return f.two_band_spectrum(wavelength, theta[0], theta[1], theta[2], theta[3], theta[4], theta[5], theta[6])


def pump_two_band(theta, wavelength_nm):
    """The pump (blue) component of ``two-band``: a Gaussian.

    Parameters
    ----------
    theta : jax.Array
        Parameter vector of the model: peaks, widths and offsets [nm], asymmetries [-], amplitudes in the
        unit of the spectrum.
    wavelength_nm : jax.Array
        Wavelength [nm].

    Returns
    -------
    jax.Array
        Spectral value, in the unit of the amplitudes.
    """
    return theta[2] * f.gaussian_spectrum(wavelength_nm, theta[0], theta[1])


def pump_two_band_led(theta, wavelength_nm):
    """The pump component of ``two-band-led``: a Gaussian line plus its Gaussian side band.

    Parameters
    ----------
    theta : jax.Array
        Parameter vector of the model: peaks, widths and offsets [nm], asymmetries [-], amplitudes in the
        unit of the spectrum.
    wavelength_nm : jax.Array
        Wavelength [nm].

    Returns
    -------
    jax.Array
        Spectral value, in the unit of the amplitudes.
    """
    return pump_two_band(theta, wavelength_nm) + theta[5] * f.gaussian_spectrum(wavelength_nm, theta[0] + theta[3],
                                                                                 theta[4])


def _two_band_led(theta, wavelength):
    return pump_two_band_led(theta, wavelength) + theta[9] * f.split_gaussian_spectrum(
        wavelength, theta[6], theta[7], theta[8])


def phosphor_two_band_wide(theta, wavelength_nm):
    """The phosphor component of ``two-band-wide``: a split Gaussian plus a Gaussian at an offset from it (a
    second phosphor, or the long tail of one).

    Parameters
    ----------
    theta : jax.Array
        Parameter vector of the model: peaks, widths and offsets [nm], asymmetries [-], amplitudes in the
        unit of the spectrum.
    wavelength_nm : jax.Array
        Wavelength [nm].

    Returns
    -------
    jax.Array
        Spectral value, in the unit of the amplitudes.
    """
    return theta[9] * f.split_gaussian_spectrum(wavelength_nm, theta[6], theta[7], theta[8]) + theta[12] * (
        f.gaussian_spectrum(wavelength_nm, theta[6] + theta[10], theta[11]))


def _two_band_wide(theta, wavelength):
    return pump_two_band_led(theta, wavelength) + phosphor_two_band_wide(theta, wavelength)


_NM, _ONE, _AMP = "nm", "1", "input units"
_LINE = (("peak_nm", _NM), ("fwhm_nm", _NM))
_SIDE = (("side_offset_nm", _NM), ("side_fwhm_nm", _NM), ("side_amplitude", _AMP), ("side_alpha", _ONE))
_PUMP = (("blue_peak_nm", _NM), ("blue_fwhm_nm", _NM), ("blue_amplitude", _AMP))
_PHOSPHOR = (("yellow_peak_nm", _NM), ("yellow_fwhm_nm", _NM), ("yellow_alpha", _ONE), ("yellow_amplitude", _AMP))

#: The spectrum models, by name.
SPECTRUM_MODELS: dict[str, SpectrumModel] = {
    m.name: m for m in (
        SpectrumModel("gaussian", (*_LINE, ("amplitude", _AMP)), _gaussian,
                      "Gaussian, eq. (2) of [Cylindrical-module]"),
        SpectrumModel("split-gaussian", (*_LINE, ("alpha", _ONE), ("amplitude", _AMP)), _split_gaussian,
                      "asymmetric Gaussian, eq. (3) of [Cylindrical-module]"),
        SpectrumModel("ohno2005", (*_LINE, ("amplitude", _AMP)), _ohno2005, "Ohno's LED model [Ohno-2005]"),
        SpectrumModel("split-pseudo-voigt", (*_LINE, ("alpha", _ONE), ("eta", _ONE), ("amplitude", _AMP)),
                      _split_pseudo_voigt, "split pseudo-Voigt line"),
        SpectrumModel("split-pearson7", (*_LINE, ("alpha", _ONE), ("shape_m", _ONE), ("amplitude", _AMP)),
                      _split_pearson7, "split Pearson VII line"),
        SpectrumModel("pseudo-voigt-shoulder", (*_LINE, ("alpha", _ONE), ("eta", _ONE), ("amplitude", _AMP), *_SIDE),
                      _pseudo_voigt_shoulder, "split pseudo-Voigt line with a split-Gaussian side band"),
        SpectrumModel("pearson7-shoulder", (*_LINE, ("alpha", _ONE), ("shape_m", _ONE), ("amplitude", _AMP), *_SIDE),
                      _pearson7_shoulder, "split Pearson VII line with a split-Gaussian side band"),
        SpectrumModel("two-band", (*_PUMP, *_PHOSPHOR), _two_band,
                      "Gaussian pump + split-Gaussian phosphor, §4.2 of [Cylindrical-module]"),
        SpectrumModel("two-band-led", (*_PUMP, ("blue_side_offset_nm", _NM), ("blue_side_fwhm_nm", _NM),
                                       ("blue_side_amplitude", _AMP), *_PHOSPHOR), _two_band_led,
                      "pump line with side band + split-Gaussian phosphor"),
        SpectrumModel("two-band-wide", (*_PUMP, ("blue_side_offset_nm", _NM), ("blue_side_fwhm_nm", _NM),
                                        ("blue_side_amplitude", _AMP), *_PHOSPHOR, ("phosphor2_offset_nm", _NM),
                                        ("phosphor2_fwhm_nm", _NM), ("phosphor2_amplitude", _AMP)), _two_band_wide,
                      "pump line with side band + phosphor of a split Gaussian and a Gaussian"),
    )
}


def spectrum_model(name: str) -> SpectrumModel:
    """The registered spectrum model ``name`` (raises naming the known models otherwise).

    Parameters
    ----------
    name : str
        Registry key, e.g. ``"split-gaussian"``.

    Returns
    -------
    SpectrumModel
    """
    try:
        return SPECTRUM_MODELS[name]
    except KeyError:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=name) from None
