"""Names and bands shared by every layer: sides, interactions, configurations and spectral bands.

Each band has one name that says what it is for; the same numbers are never redefined elsewhere.
Wavelengths in nm, band limits inclusive.

References
----------
``docs/references.md``: [Power-budget] (§2 filter bands, eqs. (4)-(16)) and [Cylindrical-module] (§4.2
two-wavelength spectrum reconstruction, YBR).
"""
from __future__ import annotations

from dataclasses import dataclass

#: The two sides of a sample: light scattered back (reflection) or through it (transmission).
SIDES: tuple[str, str] = ("reflection", "transmission")

#: Interactions of the two-wavelength approach of [Power-budget]: blue in → blue scattered (bibs), blue in →
#: yellow emitted (biys, conversion), yellow in → yellow scattered (yiys).
INTERACTIONS: tuple[str, str, str] = ("bibs", "biys", "yiys")

#: The interaction of any non-converting sample: light scattered at the wavelength it came in with.
ELASTIC_INTERACTION = "elastic"

#: Names of the two incident-light configurations of a phosphor-plate measurement (manifest ``configuration``).
BLUE_CONFIGURATION = "blue"
YELLOW_CONFIGURATION = "yellow"

#: Blue (excitation) band of the power-budget measurement: the blue interference filter, [Power-budget] §2.
EXCITATION_BAND_NM: tuple[float, float] = (450.0, 470.0)
#: Yellow (converted-light) band of the power-budget measurement, [Power-budget] eqs. (8)-(13).
CONVERSION_BAND_NM: tuple[float, float] = (470.0, 740.0)



@dataclass(frozen=True)
class InteractionBands:
    """The bands [nm] of the two-wavelength reductions, one value for every quantity that uses them: the weighted
    means and bi-spectral integrals of :func:`bsdfkit.reduction.spectral.interaction_profile` (hence the TIS) and
    the photon ratios of :func:`bsdfkit.reduction.budget.interaction_table`.

    ``blue_nm``: excitation band (bibs mean; the incident spectrum's mean wavelength); ``yellow_nm``: converted
    band (yiys mean, biys integral; the scattered spectrum's mean wavelength); ``elastic_nm``: band of an elastic
    sample's mean, None = the whole measured range.
    """

    blue_nm: tuple[float, float] = EXCITATION_BAND_NM
    yellow_nm: tuple[float, float] = CONVERSION_BAND_NM
    elastic_nm: tuple[float, float] | None = None


#: Blue and yellow parts of a module spectrum for the two-band reconstruction and the tracer's YBR,
#: [Cylindrical-module] §4.2.
MODULE_BLUE_BAND_NM: tuple[float, float] = (380.0, 500.0)
MODULE_YELLOW_BAND_NM: tuple[float, float] = (501.0, 780.0)

#: Blue and yellow parts of a spectrum for the colorimetric yellow-to-blue ratio of ``bsdfkit color``.
COLORIMETRY_BLUE_BAND_NM: tuple[float, float] = (380.0, 470.0)
COLORIMETRY_YELLOW_BAND_NM: tuple[float, float] = (471.0, 780.0)

#: Peak of the CIE photopic luminous efficiency V(λ) [nm]: the wavelength vendor files give their photopic
#: (luminance, tristimulus Y) data and the one a many-wavelength vendor file is ingested at.
PHOTOPIC_NM = 555.0

#: Plausible wavelengths in nm, from the deep UV to the far IR: a grid in µm or m falls below, one in Å or pm above.
WAVELENGTH_RANGE_NM: tuple[float, float] = (100.0, 20000.0)


#: What the tracer's YBR is: the two-wavelength model has blue (pump) and yellow (converted) rays, not spectra.
RAY_YBR_DEFINITION = ("extracted yellow-ray power / extracted blue-ray power (two-wavelength model: blue rays = pump "
                      f"light, {EXCITATION_BAND_NM[0]:g}-{EXCITATION_BAND_NM[1]:g} nm as measured; yellow rays = "
                      f"converted light, {CONVERSION_BAND_NM[0]:g}-{CONVERSION_BAND_NM[1]:g} nm)")


def band_label(band_nm: tuple[float, float]) -> str:
    """``"380-500 nm"``: how a band is written next to every ratio that uses it.

    Parameters
    ----------
    band_nm : tuple of float
        Lower and upper wavelength of the band [nm].

    Returns
    -------
    str
        The band as text, e.g. ``"380-500 nm"``.
    """
    return f"{band_nm[0]:g}-{band_nm[1]:g} nm"

#: Information criteria of a spectrum fit with ``model="best"`` (:func:`bsdfkit.fit.spectrum.analyse_spectra`);
#: here so that the command line offers them without importing the fits (JAX, colour-science)
SPECTRUM_CRITERIA: tuple[str, str] = ("aicc", "bic")

# Names the command line offers as choices before it imports any engine (`bsdfkit --help`, issue #25); the
# readers and writers that give them their meaning import them from here.
#: Quantities a measured text table may hold (:mod:`bsdfkit.measurement.table`).
QUANTITIES: tuple[str, ...] = ("brdf", "btdf", "ccbrdf", "ccbtdf", "reflectance-factor", "transmittance-factor",
                               "bsdf")
#: Relative standard uncertainty assumed when a table states none (fraction of the value).
DEFAULT_RELATIVE_STD = 0.05
#: What a table reader does with zero values (:func:`bsdfkit.measurement.table.read_table`).
ZERO_POLICIES: tuple[str, ...] = ("auto", "keep", "missing")
