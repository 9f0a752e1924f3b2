"""The spectrum models of :mod:`bsdfkit.fit.spectrum`: names, parameters and their bounds, evaluation.

The model functions are the registry's (:mod:`bsdfkit.models.registry`); here they get their fit parameters
(natural parameters, absolute peaks) and bounds, the two-band models also a relative form (peaks as offsets from
the spectrum's pump maximum and valley) so that bounds shared by a batch hold each component on its own side of
its own spectrum's valley. Wavelengths in nm.
"""
from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from bsdfkit.core.conventions import SPECTRUM_CRITERIA
from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import jitted, x64
from bsdfkit.fit.least_squares import Parameter
from bsdfkit.models.registry import SPECTRUM_MODELS as _REGISTERED_SPECTRUM_MODELS

#: Single-band line shapes; ``model="best"`` of :func:`analyse_spectra` chooses among them.
SINGLE_BAND_MODELS = ("gaussian", "split-gaussian", "ohno2005", "split-pseudo-voigt", "split-pearson7",
                      "pseudo-voigt-shoulder", "pearson7-shoulder")
#: Single-band models with a split-Gaussian side band (InGaN LEDs have a shoulder ~10-15 nm above their peak).
SHOULDER_MODELS = ("pseudo-voigt-shoulder", "pearson7-shoulder")
#: Bound [nm] of the side band's offset from the main peak.
SIDE_OFFSET_MAX_NM: float = 40.0


#: Smallest side-band FWHM [nm] and largest |α| of the side band: with them each half width is ≥ 1 nm, so the
#: band cannot collapse into a spike between samples (all-zero or collinear Jacobian columns: a singular fit).
SIDE_FWHM_MIN_NM: float = 8.0
SIDE_ALPHA_MAX: float = 0.75
#: Largest |α| of the main line of the shoulder models.
SHOULDER_ALPHA_MAX: float = 0.9
#: Largest side-band FWHM [nm]: a band much wider than the spectrum is a flat offset whose width and asymmetry
#: the data cannot separate (a singular fit).
SIDE_FWHM_MAX_NM: float = 120.0
#: Pump + phosphor sums, fitted jointly with a data-derived split (:func:`find_two_band_split`).
TWO_BAND_MODELS = ("two-band", "two-band-led", "two-band-wide")
#: Two-band models whose pump is a line with a side band.
PUMP_SIDE_MODELS = ("two-band-led", "two-band-wide")
SPECTRUM_MODELS = SINGLE_BAND_MODELS + TWO_BAND_MODELS
#: Information criteria for ``model="best"``.
CRITERIA = SPECTRUM_CRITERIA


#: The paper's blue/yellow limit [nm]: the pump peak must lie below it (:func:`find_two_band_split`).
DEFAULT_SPLIT_NM: float = 500.0


#: The pump peak may move this far [nm] from the measured pump maximum during a two-band fit; its FWHM is
#: bounded by :data:`PUMP_MAX_FWHM_NM` (InGaN pumps have 15-35 nm), so it cannot absorb the phosphor band.
PUMP_PEAK_WINDOW_NM: float = 10.0
PUMP_MAX_FWHM_NM: float = 40.0
#: ``two-band-led``: smallest FWHM [nm] of the pump line and of its side band (no spikes between samples).
PUMP_MIN_FWHM_NM: float = 2.0
#: ``two-band-led``: the pump's side band (the InGaN shoulder, cf. the ``*-shoulder`` models) lies up to this far
#: [nm] above the pump line; further out it would take over the phosphor's rising edge.
PUMP_SIDE_OFFSET_MAX_NM: float = 20.0
#: ``two-band-wide``: the phosphor's second band (a Gaussian) lies within this distance [nm] of the first (a split
#: Gaussian) and has an FWHM [nm] in this range (narrower would be a spike, wider a flat offset).
PHOSPHOR2_OFFSET_MAX_NM: float = 200.0
PHOSPHOR2_FWHM_NM: tuple[float, float] = (10.0, 200.0)


# The model functions are the registry's (:mod:`bsdfkit.models.registry`); module-level names for the solver.
_FUNCTIONS = {name: m.function for name, m in _REGISTERED_SPECTRUM_MODELS.items()}
_gaussian = _FUNCTIONS["gaussian"]
_split_gaussian = _FUNCTIONS["split-gaussian"]
_two_band = _FUNCTIONS["two-band"]
_two_band_led = _FUNCTIONS["two-band-led"]
_two_band_wide = _FUNCTIONS["two-band-wide"]


# Two-band fits in relative coordinates: x = {"wl": λ, "pump": measured pump peak, "valley": split} (per point,
# constant per spectrum), θ[0] = pump peak − pump and θ[k] = phosphor peak − valley, so that bounds shared by a
# batch hold each component on its own side of its own spectrum's valley.
def _two_band_rel(theta, x):
    return _two_band(_absolute(theta, x, 3), x["wl"])


def _two_band_led_rel(theta, x):
    return _two_band_led(_absolute(theta, x, 6), x["wl"])


def _two_band_wide_rel(theta, x):
    return _two_band_wide(_absolute(theta, x, 6), x["wl"])


def _absolute(theta, x, k_phosphor):
    shift = jnp.zeros_like(theta).at[0].set(x["pump"][0]).at[k_phosphor].set(x["valley"][0])
    return theta + shift


_RELATIVE = {"two-band": (_two_band_rel, 3), "two-band-led": (_two_band_led_rel, 6),
             "two-band-wide": (_two_band_wide_rel, 6)}


def _parameters(model: str, lo: float, hi: float, split_nm: float = DEFAULT_SPLIT_NM) -> tuple[Parameter, ...]:
    """Parameters and bounds (natural parameters, absolute peaks). A single band's peak may lie up to one span
    outside the grid (truncated spectra)."""
    span = hi - lo
    peak = dict(lower=lo - span, upper=hi + span, unit="nm")
    width = dict(lower=0.0, unit="nm")
    alpha = dict(lower=-1.0, upper=1.0, unit="1")
    amp = dict(lower=0.0, unit="input units")
    if model.startswith("two-band"):
        blue = [Parameter("blue_peak_nm", lo, split_nm, "nm"), Parameter("blue_fwhm_nm", 0.0, split_nm - lo, "nm")]
        blue.append(Parameter("blue_amplitude", **amp))
        if model in PUMP_SIDE_MODELS:
            blue += [Parameter("blue_side_offset_nm", 0.0, PUMP_SIDE_OFFSET_MAX_NM, "nm"),
                     Parameter("blue_side_fwhm_nm", PUMP_MIN_FWHM_NM, PUMP_MAX_FWHM_NM, "nm"),
                     Parameter("blue_side_amplitude", **amp)]
        yellow = [Parameter("yellow_peak_nm", split_nm, hi + span, "nm"), Parameter("yellow_fwhm_nm", **width),
                  Parameter("yellow_alpha", **alpha)]
        yellow.append(Parameter("yellow_amplitude", **amp))
        if model == "two-band-wide":
            yellow += [Parameter("phosphor2_offset_nm", -PHOSPHOR2_OFFSET_MAX_NM, PHOSPHOR2_OFFSET_MAX_NM, "nm"),
                       Parameter("phosphor2_fwhm_nm", PHOSPHOR2_FWHM_NM[0], PHOSPHOR2_FWHM_NM[1], "nm"),
                       Parameter("phosphor2_amplitude", **amp)]
        return tuple(blue + yellow)
    head = (Parameter("peak_nm", **peak), Parameter("fwhm_nm", **width))
    tail = (Parameter("amplitude", **amp),)
    if model in ("gaussian", "ohno2005"):
        return head + tail
    if model == "split-gaussian":
        return head + (Parameter("alpha", **alpha),) + tail
    side = (Parameter("side_offset_nm", -SIDE_OFFSET_MAX_NM, SIDE_OFFSET_MAX_NM, "nm"),
            Parameter("side_fwhm_nm", SIDE_FWHM_MIN_NM, SIDE_FWHM_MAX_NM, "nm"), Parameter("side_amplitude", **amp),
            Parameter("side_alpha", -SIDE_ALPHA_MAX, SIDE_ALPHA_MAX, "1"))
    if model in SHOULDER_MODELS:
        # Line + side band: a main line narrower than ~2 samples, or one-sided (|α| → 1), leaves parameters the
        # data cannot separate (a singular fit); the side band takes what such a line would describe.
        head = (head[0], Parameter("fwhm_nm", PUMP_MIN_FWHM_NM, math.inf, "nm"))
        alpha = dict(lower=-SHOULDER_ALPHA_MAX, upper=SHOULDER_ALPHA_MAX, unit="1")
    if model.startswith("split-pseudo-voigt") or model == "pseudo-voigt-shoulder":
        main = head + (Parameter("alpha", **alpha), Parameter("eta", 0.0, 1.0, "1")) + tail
        return main + side if model.endswith("shoulder") else main
    if model.startswith("split-pearson7") or model == "pearson7-shoulder":
        main = head + (Parameter("alpha", **alpha), Parameter("shape_m", 0.5, 1000.0, "1")) + tail
        return main + side if model.endswith("shoulder") else main
    raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS), got=model)


def _relative_parameters(model: str) -> tuple[Parameter, ...]:
    """Parameters of the relative two-band functions (peaks as offsets from the pump maximum / the valley)."""
    names = [p.name for p in _parameters(model, 380.0, 780.0)]
    out = []
    for p in _parameters(model, 380.0, 780.0):
        if p.name == "blue_peak_nm":
            out.append(Parameter("blue_peak_nm", -PUMP_PEAK_WINDOW_NM, PUMP_PEAK_WINDOW_NM, "nm"))
        elif p.name == "blue_fwhm_nm":
            low = PUMP_MIN_FWHM_NM if model in PUMP_SIDE_MODELS else 0.0
            out.append(Parameter("blue_fwhm_nm", low, PUMP_MAX_FWHM_NM, "nm"))
        elif p.name == "yellow_peak_nm":
            out.append(Parameter("yellow_peak_nm", 0.0, math.inf, "nm"))
        else:
            out.append(p)
    assert [p.name for p in out] == names
    return tuple(out)


def spectrum_model_values(model: str, params: dict[str, float], wavelength_nm: np.ndarray) -> np.ndarray:
    """Evaluate a fitted spectrum model (parameter names as in :func:`fit_spectrum`) at λ [nm].

    Parameters
    ----------
    model : str
        One of :data:`SPECTRUM_MODELS`.
    params : dict of str to float
        Model parameters by name (peaks and widths [nm], ``alpha`` and shape parameters [-], amplitudes in the
        spectrum's unit); extra keys are ignored.
    wavelength_nm : ndarray
        Wavelengths λ [nm].

    Returns
    -------
    ndarray
        Model values at ``wavelength``, in the unit of the amplitudes.

    Raises
    ------
    ValidationError
        If ``model`` is unknown or a parameter is missing.
    """
    if model not in SPECTRUM_MODELS:
        raise ValidationError("unknown spectrum model", field="model", expected=" | ".join(SPECTRUM_MODELS),
                              got=model)
    wl = np.asarray(wavelength_nm, dtype=float)
    names = [p.name for p in _parameters(model, float(wl.min()), float(wl.max()) + 1.0)]
    missing = [n for n in names if n not in params]
    if missing:
        raise ValidationError("missing model parameters", field="params", expected=", ".join(names), got=missing)
    theta = np.array([params[n] for n in names], dtype=float)
    with x64():
        return np.asarray(jitted(_FUNCTIONS[model])(jnp.asarray(theta), jnp.asarray(wl)))
