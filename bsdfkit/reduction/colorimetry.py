"""Colorimetry of emission spectra through colour-science (no re-implemented CMFs or CCT).

* Chromaticity: CIE 1931 2° standard observer, ``colour.sd_to_XYZ`` with its default method
  (ASTM E308-15 practice; illuminant E, i.e. the spectrum itself is the stimulus), then
  ``colour.XYZ_to_xy``.
* CCT and Duv: ``colour.uv_to_CCT(uv, method="Ohno 2013")`` on CIE 1960 UCS uv
  (``colour.xy_to_UCS_uv``): Ohno, "Practical use and calculation of CCT and Duv", LEUKOS 10(1), 2014
  (combined triangular/parabolic solution over a cascade of Planckian tables). CIE 015 regards a CCT as
  meaningful only for |Duv| ≤ 0.05 (:data:`DUV_LIMIT`); the value is returned regardless and
  :func:`cct_is_meaningful` says whether it is.
* Luminous flux (lm, for a spectrum in W/nm) and luminous efficacy of radiation (lm/W):
  ``colour.luminous_flux`` and ``colour.luminous_efficacy`` (CIE 1924 photopic V(λ), K_m = 683 lm/W).
* Yellow-to-blue ratio YBR = ∫_yellow S dλ / ∫_blue S dλ with blue = 380–470 nm and yellow = 471–780 nm
  by default (definitions of §5.1 of the cylindrical-module paper, [Cylindrical-module] in docs/references.md); band
  sums as :func:`bsdfkit.reduction.spectral.band_sum`.

Grids: uniform 5, 10 or 20 nm grids starting on a whole nanometre are passed to colour unchanged
(ASTM E308 practice, weighting-factor method). Any other grid (1 nm, or an irregular
spectroradiometer grid, interpolated by colour onto 1 nm over its own range) is put on exactly
360-780 nm at 1 nm (the ASTM practice range of the CMFs) with zeros outside the measured range, an
emission spectrum having no light where it was not measured (colour would otherwise repeat the end
values). Photometry (V(λ), 360-830 nm) integrates the spectrum over its own range.
Spectra cross the API as :class:`colour.SpectralDistribution` (wavelength in nm).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bsdfkit.core.conventions import (
    COLORIMETRY_BLUE_BAND_NM,
    COLORIMETRY_YELLOW_BAND_NM,
    WAVELENGTH_RANGE_NM,
    band_label,
)
from bsdfkit.core.errors import InputError, NumericalError, ValidationError
from bsdfkit.core.lazy import LazyModule
from bsdfkit.reduction.spectral import band_sum

if TYPE_CHECKING:
    from colour import SpectralDistribution

#: colour-science on first use (about 1 s with matplotlib): the tracer reports a luminous efficacy through this
#: module and must not pay that import before it does
colour = LazyModule("colour")

__all__ = [
    "CMFS_NAME",
    "DUV_LIMIT",
    "COLORIMETRY_BLUE_BAND_NM",
    "COLORIMETRY_YELLOW_BAND_NM",
    "chromaticity_xy",
    "cct_duv",
    "cct_is_meaningful",
    "CCT_RANGE_K",
    "luminous_flux_lm",
    "luminous_efficacy_of_radiation",
    "spectral_distribution",
    "yellow_blue_ratio",
    "ybr_label",
    "check_power_spectrum",
    "check_wavelengths_nm",
    "WAVELENGTH_RANGE_NM",
    "ColorimetricSummary",
    "colorimetric_summary",
]

CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
#: |Duv| above which a CCT is not meaningful (CIE 015:2018 §9.5).
DUV_LIMIT = 0.05
#: Planckian table range of colour's Ohno (2013) solver (its defaults ``start`` and ``end``), in K.
CCT_RANGE_K: tuple[float, float] = (1000.0, 100000.0)

_ASTM_INTERVALS = (1.0, 5.0, 10.0, 20.0)


def _checked(sd):
    """Validate a SpectralDistribution (finite values, some positive power) and return (λ, values)."""
    if not isinstance(sd, colour.SpectralDistribution):
        raise InputError("spectrum must be a colour.SpectralDistribution", field="sd",
                         got=type(sd).__name__)
    wl = np.asarray(sd.wavelengths, dtype=float)
    values = np.asarray(sd.values, dtype=float)
    if wl.size < 3:
        raise InputError("spectrum needs at least 3 samples", field=sd.name, got=wl.size)
    bad = ~np.isfinite(values)
    if bad.any():
        raise InputError("spectral value is not finite", field=f"{sd.name} at {wl[bad][0]:g} nm",
                         got=float(values[bad][0]))
    if not np.any(values > 0):
        raise NumericalError(f"{sd.name}: spectrum has no positive value; colorimetry is undefined")
    check_power_spectrum(wl, values, sd.name)
    return wl, values


#: Fewest samples inside the CMF range (360-830 nm) for a colorimetric result.
MIN_VISIBLE_SAMPLES = 5
#: Negative spectral power beyond this fraction of the peak (or of the positive integral) is not noise. The 19
#: Benkner LED spectra (dark-subtracted spectroradiometer data) reach −0.1 % of the peak and −0.11 % of the
#: positive integral, 50× inside this limit; a sign error or a noise-only file reaches tens of per cent.
NEGATIVE_TOLERANCE = 0.05
#: Where the CIE 1931 colour-matching functions weigh (x̄ + ȳ + z̄ ≥ 1 % of its maximum) [nm], and the largest
#: share of its peak a spectrum may still have at an end inside that range (else it is cut off).
CMF_SIGNIFICANT_NM: tuple[float, float] = (390.0, 694.0)
END_FRACTION = 0.05


def check_wavelengths_nm(wavelength_nm, name: str) -> None:
    """Refuse a grid outside :data:`WAVELENGTH_RANGE_NM` (µm, m or Å values): one line naming ``name``.

    Parameters
    ----------
    wavelength_nm : array_like
        Wavelengths, expected in [nm].
    name : str
        What the message names (a file or spectrum name).

    Raises
    ------
    ValidationError
        If a wavelength lies outside :data:`WAVELENGTH_RANGE_NM`.
    """
    wl = np.asarray(wavelength_nm, dtype=float)
    lo, hi = WAVELENGTH_RANGE_NM
    if wl.min() < lo or wl.max() > hi:
        unit = "µm or m" if wl.max() < lo else "Å or pm" if wl.min() > hi else "another unit"
        raise ValidationError(f"wavelengths are not in nm (they look like {unit})", field=name,
                              expected=f"wavelengths in nm within [{lo:g}, {hi:g}]",
                              got=f"{wl.min():g}..{wl.max():g}")


def check_power_spectrum(wavelength_nm, values, name: str, *, colorimetry: bool = True) -> None:
    """Plausibility of a spectral *power* (an emission spectrum), or a one-line :class:`ValidationError`.

    Rules: wavelengths in nm (:func:`check_wavelengths_nm`); with ``colorimetry``, at least
    :data:`MIN_VISIBLE_SAMPLES` samples in 360-830 nm (the CMFs' range); negative values only as noise: the
    most negative value above −:data:`NEGATIVE_TOLERANCE` × the peak and the negative integral (Σ over
    negative samples of S·Δλ, central-difference Δλ) below :data:`NEGATIVE_TOLERANCE` × the positive one.
    A mixed-sign spectrum (a sign error) or zero-mean noise fails the last rule.

    Parameters
    ----------
    wavelength_nm
        Wavelengths λ [nm], 1-D, strictly increasing.
    values
        Spectral values of the same length [any radiometric unit].
    name
        What the message names (a file or spectrum name).
    colorimetry
        Also require the samples a colorimetric result needs.
    """
    wl = np.asarray(wavelength_nm, dtype=float)
    values = np.asarray(values, dtype=float)
    check_wavelengths_nm(wl, name)
    visible = int(np.count_nonzero((wl >= 360.0) & (wl <= 830.0)))
    if colorimetry and visible < MIN_VISIBLE_SAMPLES:
        raise ValidationError("too few samples in the visible range for colorimetry", field=name,
                              expected=f"at least {MIN_VISIBLE_SAMPLES} wavelengths in 360-830 nm",
                              got=f"{visible} (spectrum {wl.min():g}..{wl.max():g} nm, {wl.size} samples)")
    peak = float(values.max())
    if colorimetry and peak > 0:
        # A spectrum cut off where the colour-matching functions still weigh (x̄ + ȳ + z̄ above 1 % of its
        # maximum in 390-694 nm) while it is still bright gives a colour of the cut, not of the source.
        lo, hi = CMF_SIGNIFICANT_NM
        for end, k, inside in (("short", 0, wl[0] > lo), ("long", -1, wl[-1] < hi)):
            if inside and values[k] > END_FRACTION * peak:
                raise ValidationError(f"spectrum cut off at its {end}-wavelength end (truncated?)",
                                      field=f"{name} at {wl[k]:g} nm",
                                      expected=f"samples over {lo:g}-{hi:g} nm "
                                               f"or values ≤ {END_FRACTION:g} × peak at the ends",
                                      got=f"{values[k] / peak:.3g} × peak")
    negative = values < 0
    if negative.any():
        weights = np.gradient(wl) if wl.size > 1 else np.ones(1)
        neg_area = float(-(values[negative] * weights[negative]).sum())
        pos_area = float((values[~negative] * weights[~negative]).sum())
        if float(-values.min()) > NEGATIVE_TOLERANCE * peak or neg_area > NEGATIVE_TOLERANCE * pos_area:
            k = int(np.argmin(values))
            raise ValidationError("negative spectral power beyond the noise (a power spectrum is required)",
                                  field=f"{name} at {wl[k]:g} nm",
                                  expected=f"values ≥ −{NEGATIVE_TOLERANCE:g} × peak ({peak:.3g}) and a negative "
                                           f"integral ≤ {NEGATIVE_TOLERANCE:g} × the positive one "
                                           f"(here {neg_area / pos_area if pos_area > 0 else math.inf:.3g})",
                                  got=float(values[k]))


def _uniform_sd(sd):
    """The spectrum on a uniform grid: unchanged if already uniform, else interpolated by colour onto
    1 nm over its own (whole-nanometre) range."""
    wl, _ = _checked(sd)
    steps = np.diff(wl)
    if np.allclose(steps, steps[0], rtol=0, atol=1e-9):
        return sd
    shape = colour.SpectralShape(math.ceil(wl[0]), math.floor(wl[-1]), 1.0)
    if shape.end - shape.start < 2:
        raise InputError("spectrum spans less than 2 nm", field=sd.name, got=(wl[0], wl[-1]))
    with warnings.catch_warnings():
        # colour notes that an irregular grid "is not uniform": resampling it onto 1 nm is this function's job
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        return sd.copy().interpolate(shape)


def _colorimetric_sd(sd):
    """The spectrum on a grid colour's ASTM E308 path accepts without re-aligning it (module docstring)."""
    wl, _ = _checked(sd)
    steps = np.diff(wl)
    uniform = np.allclose(steps, steps[0], rtol=0, atol=1e-9)
    on_whole_nm = abs(wl[0] - round(wl[0])) < 1e-9
    if uniform and on_whole_nm and any(abs(steps[0] - s) < 1e-9 for s in _ASTM_INTERVALS[1:]):
        return sd
    # 1 nm path: exactly the practice range 360-780 nm of the CMFs, zero outside the measured range,
    # so colour neither warns nor extrapolates the end values as constants.
    out = _uniform_sd(sd).copy()
    if out.shape.interval != 1.0 or not on_whole_nm:
        out = out.interpolate(colour.SpectralShape(math.ceil(wl[0]), math.floor(wl[-1]), 1.0))
    target = colour.SpectralShape(360.0, 780.0, 1.0)
    values = np.interp(target.wavelengths, out.wavelengths, out.values, left=0.0, right=0.0)
    return colour.SpectralDistribution(values, target.wavelengths, name=sd.name)


def _xyz(sd) -> np.ndarray:
    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    with warnings.catch_warnings():
        # colour reports each internal re-alignment of illuminant E / the 5 nm ASTM tables as a runtime
        # warning; those steps are its documented ASTM E308 practice, not a problem with the input.
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        xyz = np.asarray(colour.sd_to_XYZ(_colorimetric_sd(sd), cmfs), dtype=float)
    if not (np.all(np.isfinite(xyz)) and xyz.sum() > 0):
        raise NumericalError(f"{sd.name}: tristimulus values are not positive ({xyz.tolist()}); "
                             "is the spectrum inside 360-830 nm?")
    return xyz


def chromaticity_xy(sd: SpectralDistribution) -> tuple[float, float]:
    """CIE 1931 2° chromaticity (x, y) of an emission spectrum (wavelength in nm, any radiometric unit).

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Emission spectrum, wavelengths [nm], values in any radiometric unit.

    Returns
    -------
    x, y : float
        CIE 1931 chromaticity coordinates [-].

    Raises
    ------
    NumericalError
        If the tristimulus values are not positive.
    """
    x, y = np.asarray(colour.XYZ_to_xy(_xyz(sd)), dtype=float)
    return float(x), float(y)


def cct_duv(sd: SpectralDistribution) -> tuple[float, float]:
    """Correlated colour temperature (K) and Duv by Ohno (2013) via ``colour.uv_to_CCT``.

    Duv is the signed distance from the Planckian locus in CIE 1960 uv (positive above the locus).

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Emission spectrum, wavelengths [nm], values in any radiometric unit.

    Returns
    -------
    cct : float
        Correlated colour temperature [K].
    duv : float
        Signed distance from the Planckian locus in CIE 1960 uv [-].

    Raises
    ------
    NumericalError
        If the CCT is undefined for the spectrum's chromaticity.
    """
    xy = np.array(chromaticity_xy(sd))
    uv = colour.xy_to_UCS_uv(xy)
    with warnings.catch_warnings():
        # colour warns when the nearest Planckian point is on its table bound (CCT outside
        # 1000-100000 K); cct_is_meaningful() reports that case, so the warning is redundant.
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        cct, duv = np.asarray(colour.uv_to_CCT(uv, method="Ohno 2013"), dtype=float)
    if not (math.isfinite(cct) and math.isfinite(duv)):
        raise NumericalError(f"{sd.name}: CCT is undefined for chromaticity x={xy[0]:.4f}, y={xy[1]:.4f}")
    return float(cct), float(duv)


def cct_is_meaningful(duv: float, cct_K: float | None = None) -> bool:
    """True when |Duv| ≤ :data:`DUV_LIMIT` (CIE 015) and, if given, the CCT lies inside the Planckian
    table of the Ohno (2013) solver (:data:`CCT_RANGE_K`); otherwise the CCT should not be quoted.

    Parameters
    ----------
    duv : float
        Distance from the Planckian locus in CIE 1960 uv [-].
    cct_K : float, optional
        Correlated colour temperature [K]; None skips the range check.

    Returns
    -------
    bool
        Whether the CCT may be quoted.
    """
    inside = cct_K is None or CCT_RANGE_K[0] <= cct_K <= CCT_RANGE_K[1]
    return abs(duv) <= DUV_LIMIT and inside


def spectral_distribution(wavelength_nm: np.ndarray, values: np.ndarray, name: str = "") -> SpectralDistribution:
    """Samples ``values`` on ``wavelength_nm`` [nm] as a ``colour.SpectralDistribution`` (float64).

    Parameters
    ----------
    wavelength_nm : ndarray
        Sample wavelengths [nm].
    values : ndarray
        Spectral values at ``wavelength_nm`` (any unit, e.g. [W/nm]).
    name : str, optional
        Name of the distribution (appears in error messages).

    Returns
    -------
    colour.SpectralDistribution
        The samples, float64.
    """
    return colour.SpectralDistribution(np.asarray(values, dtype=np.float64),
                                       np.asarray(wavelength_nm, dtype=np.float64), name=name)


def luminous_flux_lm(sd: SpectralDistribution) -> float:
    """Luminous flux in lm of a spectral radiant flux in W/nm (``colour.luminous_flux``, K_m = 683 lm/W).

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Spectral radiant flux, wavelengths [nm], values [W/nm].

    Returns
    -------
    float
        Luminous flux [lm].
    """
    return float(colour.luminous_flux(_uniform_sd(sd)))


def luminous_efficacy_of_radiation(sd: SpectralDistribution) -> float:
    """Luminous efficacy of radiation K = Φ_v/Φ_e in lm/W (``colour.luminous_efficacy``); unit-free input.

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Emission spectrum, wavelengths [nm], values in any radiometric unit.

    Returns
    -------
    float
        Luminous efficacy of radiation [lm/W].

    Raises
    ------
    NumericalError
        If the radiant flux is zero.
    """
    value = float(colour.luminous_efficacy(_uniform_sd(sd)))
    if not math.isfinite(value):
        raise NumericalError(f"{sd.name}: luminous efficacy is undefined (zero radiant flux)")
    return value


def yellow_blue_ratio(
    sd: SpectralDistribution,
    blue_band_nm: tuple[float, float] = COLORIMETRY_BLUE_BAND_NM,
    yellow_band_nm: tuple[float, float] = COLORIMETRY_YELLOW_BAND_NM,
) -> float:
    """YBR = Σ_yellow S Δλ / Σ_blue S Δλ (inclusive band limits in nm; defaults 380–470 and 471–780 nm).

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Emission spectrum, wavelengths [nm], values in any radiometric unit.
    blue_band_nm : tuple of float, optional
        (low, high) blue band [nm], inclusive, low < high.
    yellow_band_nm : tuple of float, optional
        (low, high) yellow band [nm], inclusive, low < high.

    Returns
    -------
    float
        Yellow-to-blue ratio [-].

    Raises
    ------
    ValidationError
        If a band is empty.
    NumericalError
        If the blue band carries no flux.
    """
    for name, band in (("blue_band_nm", blue_band_nm), ("yellow_band_nm", yellow_band_nm)):
        if not band[0] < band[1]:
            raise ValidationError("empty band", field=name, expected="lower < upper [nm]", got=band)
    wl, values = _checked(sd)
    blue = band_sum(wl, values, blue_band_nm)
    yellow = band_sum(wl, values, yellow_band_nm)
    if not blue > 0:
        raise NumericalError(f"{sd.name}: no flux in the blue band {blue_band_nm[0]:g}-{blue_band_nm[1]:g} nm; "
                             "YBR is undefined")
    return yellow / blue


@dataclass(frozen=True)
class ColorimetricSummary:
    """Chromaticity, CCT/Duv (Ohno 2013), luminous efficacy of radiation and YBR of one spectrum; the YBR's band
    edges [nm] travel with it (:attr:`ybr_label` is how every printout names it)."""

    x: float
    y: float
    cct_K: float
    duv: float
    luminous_efficacy_lm_per_W: float
    ybr: float | None
    ybr_yellow_band_nm: tuple[float, float] = COLORIMETRY_YELLOW_BAND_NM
    ybr_blue_band_nm: tuple[float, float] = COLORIMETRY_BLUE_BAND_NM

    @property
    def cct_meaningful(self) -> bool:
        return cct_is_meaningful(self.duv, self.cct_K)

    @property
    def ybr_label(self) -> str:
        """``"YBR (471-780 nm / 380-470 nm)"``: the ratio's name with its yellow and blue band edges."""
        return ybr_label(self.ybr_yellow_band_nm, self.ybr_blue_band_nm)


def ybr_label(yellow_band_nm: tuple[float, float] = COLORIMETRY_YELLOW_BAND_NM,
              blue_band_nm: tuple[float, float] = COLORIMETRY_BLUE_BAND_NM) -> str:
    """A yellow-to-blue ratio's name with its band edges, e.g. ``"YBR (471-780 nm / 380-470 nm)"``.

    Parameters
    ----------
    yellow_band_nm : tuple of float, optional
        (low, high) yellow band [nm].
    blue_band_nm : tuple of float, optional
        (low, high) blue band [nm].

    Returns
    -------
    str
        The label.
    """
    return f"YBR ({band_label(yellow_band_nm)} / {band_label(blue_band_nm)})"


def colorimetric_summary(
    sd: SpectralDistribution,
    blue_band_nm: tuple[float, float] = COLORIMETRY_BLUE_BAND_NM,
    yellow_band_nm: tuple[float, float] = COLORIMETRY_YELLOW_BAND_NM,
) -> ColorimetricSummary:
    """All colour quantities of :class:`ColorimetricSummary`; YBR over the given bands [nm] (default
    380–470 and 471–780 nm), None if the blue band is empty.

    Parameters
    ----------
    sd : colour.SpectralDistribution
        Emission spectrum, wavelengths [nm], values in any radiometric unit.
    blue_band_nm : tuple of float, optional
        (low, high) blue band of the YBR [nm], inclusive.
    yellow_band_nm : tuple of float, optional
        (low, high) yellow band of the YBR [nm], inclusive.

    Returns
    -------
    ColorimetricSummary
        x, y [-], CCT [K], Duv [-], luminous efficacy of radiation [lm/W], YBR [-] (None without blue flux) and
        the YBR's bands [nm].
    """
    x, y = chromaticity_xy(sd)
    cct, duv = cct_duv(sd)
    try:
        ybr: float | None = yellow_blue_ratio(sd, blue_band_nm, yellow_band_nm)
    except NumericalError:
        ybr = None
    return ColorimetricSummary(x, y, cct, duv, luminous_efficacy_of_radiation(sd), ybr,
                               tuple(yellow_band_nm), tuple(blue_band_nm))
