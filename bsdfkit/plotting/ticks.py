"""Tick labels of logarithmic axes in plain text.

matplotlib labels a log axis in mathtext, parsed once per label and figure: half of a log figure's drawing time.
Kept apart from :mod:`bsdfkit.plotting.figures` so that a pickled figure (:mod:`bsdfkit.plotting.render`) needs
matplotlib and this module only to be drawn again.
"""
from __future__ import annotations

import math
import re

from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation

_SUPERSCRIPTS = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def decade_label(value: float, _pos: int | None = None) -> str:
    """'10⁻²' at a power of ten, '' elsewhere: plain text (the default labels are mathtext, one parse each).

    Parameters
    ----------
    value : float
        Tick value [axis units].
    _pos : int, optional
        Tick position (matplotlib's formatter argument, unused).

    Returns
    -------
    str
        The label.
    """
    if not value > 0.0 or not math.isfinite(value):
        return ""
    exponent = math.log10(value)
    if abs(exponent - round(exponent)) > 1e-9:
        return ""
    return "10" + str(int(round(exponent))).translate(_SUPERSCRIPTS)


_MATHTEXT = re.compile(r"^\$\\mathdefault\{(?:(-?[0-9.e+-]+)\\times)?([0-9.]+)\^\{(-?\d+)\}\}\$$")


class PlainLogFormatter(LogFormatterSciNotation):
    """matplotlib's minor-tick labels of a log axis ('3×10⁻²' where it labels one), in plain text: each
    mathtext label is parsed once per figure, a sixth of the drawing time of a figure with six log axes."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        label = super().__call__(x, pos)
        match = _MATHTEXT.match(label)
        if match is None:
            return label
        coeff, base, exponent = match.groups()
        power = base + exponent.translate(_SUPERSCRIPTS)
        return f"{coeff}×{power}" if coeff else power


def log_y(ax) -> None:
    """A logarithmic y axis labelled in plain text.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes.
    """
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(decade_label))
    ax.yaxis.set_minor_formatter(PlainLogFormatter(labelOnlyBase=False))
