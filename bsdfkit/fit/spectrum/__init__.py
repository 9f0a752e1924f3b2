"""LED and phosphor spectrum fitting, measured-vs-fitted metrics, batch fits, and the two-band reconstruction.

* :func:`fit_spectrum` / :func:`fit_spectra` fit one model to one spectrum or to a batch (one compiled kernel
  per model and pass). Models: eq. (2) (``gaussian``) and eq. (3) (``split-gaussian``) of the
  cylindrical-module paper, fitted by the recipe of docs/fitting.md §2 (normalise by the maximum, start at
  the argmax and the half-maximum crossings, α = 0 first, then α free); the LED line shapes of
  :mod:`bsdfkit.models.led` (``ohno2005``, ``split-pseudo-voigt``, ``split-pearson7``, one pass from the
  measured peak, FWHM and asymmetry) and those lines with a split-Gaussian side band (``pseudo-voigt-shoulder``,
  ``pearson7-shoulder``: the shoulder of InGaN LEDs; three start points solved in one batch); and the pump +
  phosphor sums ``two-band`` (pump Gaussian + phosphor split Gaussian, the paper's §4.2 components) and
  ``two-band-led`` (pump Gaussian line + side band, phosphor split Gaussian) and ``two-band-wide`` (that pump,
  phosphor split Gaussian + Gaussian: a second phosphor such as a red nitride band, or the long tail of one;
  three start points from the measured phosphor band,
  :func:`~bsdfkit.fit.spectrum.starts._phosphor_pair_starts`), whose split between pump and phosphor is found
  from the data (:func:`find_two_band_split`). Every reported component peak is the maximum of the fitted
  component curve, not a parameter.
* :func:`analyse_spectra` is the batch front-end of ``bsdfkit fit spectrum``: it fits many spectra (different
  grids allowed: padded and masked), optionally every single-band model with the best chosen by AICc or BIC
  (``model="best"``), and returns one record per spectrum with the measured metrics
  (:mod:`bsdfkit.reduction.spectrum_metrics`), the same metrics of the fitted curve, their differences and a
  ``warnings`` list (R² < 0, parameters at a bound, no convergence, fitted peak/FWHM far from the measured).
* :func:`two_band_gains` and :func:`reconstruct_two_band_spectrum` implement §4.2 of the same paper:
  the blue and yellow radiant fluxes of a two-wavelength simulation are redistributed over normalised
  blue and yellow spectra by solving

      Φ_blue   = A1·Σ_{λi∈blue band} S_blue(λi)Δλi   + A2·Σ_{λi∈blue band} S_yellow(λi)Δλi
      Φ_yellow = A1·Σ_{λi∈yellow band} S_blue(λi)Δλi + A2·Σ_{λi∈yellow band} S_yellow(λi)Δλi

  for the gains A1, A2 (W/nm); the absolute spectral flux is A1·S_blue + A2·S_yellow. The paper's band
  limits are 380–500 nm (blue) and 501–780 nm (yellow), both inclusive; they are parameters here.
  (The printed equation is garbled by text extraction; the system above follows from the paper's
  definitions: each band flux is the band sum of the linear combination.)

Modules by role: :mod:`~bsdfkit.fit.spectrum.models` (names, parameters, bounds), :mod:`~bsdfkit.fit.spectrum.starts`
(start values and the two-band split from the data), :mod:`~bsdfkit.fit.spectrum.solver` (batch fits),
:mod:`~bsdfkit.fit.spectrum.reporting` (:func:`analyse_spectra`) and :mod:`~bsdfkit.fit.spectrum.reconstruction`
(§4.2). Wavelengths in nm throughout. Spectra cross the API as NumPy arrays (fitting) or
:class:`colour.SpectralDistribution` (reconstruction output).
"""
from __future__ import annotations

from bsdfkit.fit.spectrum.models import (
    CRITERIA,
    SINGLE_BAND_MODELS,
    SPECTRUM_MODELS,
    TWO_BAND_MODELS,
    spectrum_model_values,
)
from bsdfkit.fit.spectrum.reconstruction import (
    BLUE_BAND_NM,
    MAX_CONDITION,
    YELLOW_BAND_NM,
    TwoBandGains,
    band_integral,
    reconstruct_two_band_spectrum,
    two_band_gains,
)
from bsdfkit.fit.spectrum.reporting import analyse_spectra, information_criteria
from bsdfkit.fit.spectrum.solver import fit_spectra, fit_spectrum
from bsdfkit.fit.spectrum.starts import TwoBandSplit, find_two_band_split

__all__ = [
    "SPECTRUM_MODELS",
    "SINGLE_BAND_MODELS",
    "TWO_BAND_MODELS",
    "CRITERIA",
    "BLUE_BAND_NM",
    "YELLOW_BAND_NM",
    "MAX_CONDITION",
    "TwoBandSplit",
    "find_two_band_split",
    "fit_spectrum",
    "fit_spectra",
    "information_criteria",
    "analyse_spectra",
    "spectrum_model_values",
    "band_integral",
    "TwoBandGains",
    "two_band_gains",
    "reconstruct_two_band_spectrum",
]
