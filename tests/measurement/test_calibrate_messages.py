"""Calibration (issue #44 point 5): a reference beam whose power overflows (a count of 1e308 in a raw dataset made
in memory) is said as an overflow naming the reference file and the wavelength, not as "zero incident power" with
an infinite peak; a reference without light still is."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.core.errors import NumericalError
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan


@pytest.fixture
def tiny_raw(tiny_export):
    return read_scan(tiny_export)


def _blue_reference(raw):
    return np.flatnonzero(raw["reference_config"].values == "blue")


@pytest.mark.parametrize("value", [1e308, 1e200, np.inf])
def test_an_overflowing_reference_names_its_file_and_wavelength(tiny_raw, tiny_export, value):
    k = int(np.flatnonzero(tiny_raw["wavelength"].values == 480.0)[0])
    tiny_raw["reference_counts"].values[_blue_reference(tiny_raw)[1], k] = value
    with pytest.raises(NumericalError) as err:
        calibrate(tiny_raw)
    text = str(err.value)
    assert text.startswith(f"{tiny_export}/reference/blue.csv.gz: field 'configuration 'blue': reference counts at "
                           "480 nm': reference counts implausibly large: the incident power is not finite (an "
                           "overflow, not zero light)"), text
    assert text.endswith(f"got '{value:g} counts'") and "zero incident power" not in text, text


def test_a_reference_power_overflowing_by_its_attenuation_is_said_so(tiny_raw):
    tiny_raw["reference_attenuation"].loc[{"configuration": "blue"}] = 1e-320  # counts / attenuation: inf
    with pytest.raises(NumericalError, match=r"reference/blue\.csv\.gz: .*reference power overflows \(counts divided "
                                             r"by a tiny exposure_s or reference_attenuation\)"), \
            np.errstate(over="ignore", divide="ignore"):  # numpy's own word on the overflow, the subject here
        calibrate(tiny_raw)


def test_a_dark_reference_is_still_zero_incident_power(tiny_raw):
    tiny_raw["reference_counts"].values[_blue_reference(tiny_raw)] = 0.0
    with pytest.raises(NumericalError, match=r"field 'configuration 'blue'': zero incident power in the reference "
                                             r"beam"):
        calibrate(tiny_raw)
