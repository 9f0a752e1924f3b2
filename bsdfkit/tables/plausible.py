"""The physical-plausibility gate every export and conversion passes before any file is written (issue #44).

A BSDF whose hemispherical value (TIS) exceeds 1 at some incidence, or whose reflection and transmission together
exceed 1 at one incidence, sends more power out than came in. Before this gate each writer answered it its own way
(TracePro refused it through its absorptance, Speos wrote a file its own reader refused, the others wrote it
silently). :func:`check` is the one rule, on exactly what is written (these sides, these incidences), with the same
one-line :class:`~bsdfkit.core.errors.ValidationError` whatever the format; ``allow_nonphysical`` writes anyway
with one :class:`NonphysicalWarning`.

**Rule.** For each side and incidence written, the source's hemispherical value T [-] (the engine's value for a
measured dataset, the direct integral :func:`bsdfkit.tables.grids.tis_reference` for a callable or a fit) must be
at most ``1 + TIS_TOLERANCE + allowed``, and when both sides are written, T_R + T_T at one incidence too.
``TIS_TOLERANCE`` = 0.01 is measurement noise: a white reflectance standard (Spectralon, 0.99) calibrated to 1 %
reads up to 1.01, and the engine's reconstruction and the writers' quadratures agree to well below 1 %
(docs/exports.md §3, §6), so only a source above 1 by more than its noise is refused. ``allowed`` is a fit's own
k·u(TIS) (:func:`bsdfkit.fit.plausibility.tis_excess_allowed`): a fit is judged by its own gate first
(:func:`bsdfkit.fit.plausibility.refuse_implausible`, when the fit is resolved; ``allow_nonphysical`` does not
lift it), and this one adds the sum of its sides within the same allowance.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core.errors import BsdfkitWarning, ValidationError

__all__ = ["TIS_TOLERANCE", "NonphysicalWarning", "check", "excess_to_allow"]

#: How far [-] a hemispherical value (or R + T) may exceed 1 before it is refused: measurement noise (module doc).
TIS_TOLERANCE = 0.01
#: The option that writes a refused source anyway, named in the message.
OPTION = "--allow-nonphysical"


class NonphysicalWarning(BsdfkitWarning):
    """A table written from a source above 1 (``allow_nonphysical``): the gate's message, said as a warning."""


def _violations(values: Mapping[str, Sequence[float]], theta_i_deg: Sequence[float], allowed: NDArray[np.float64]
                ) -> list[tuple[str, float, float, float, str]]:
    """(what, incidence [deg], value [-], limit [-], rule) of every violation, per side first, then the sums."""
    found = []
    theta = [float(t) for t in theta_i_deg]
    limit = 1.0 + TIS_TOLERANCE + allowed
    for side, vals in values.items():
        for k, (t, v) in enumerate(zip(theta, vals)):
            if float(v) > limit[k]:  # a NaN (no value) is not judged here
                found.append((side, t, float(v), float(limit[k]), "the hemispherical value exceeds 1"))
    if len(values) > 1:
        for k, t in enumerate(theta):
            total = float(sum(float(vals[k]) for vals in values.values()))
            if total > limit[k]:
                found.append((" + ".join(values), t, total, float(limit[k]), "reflection + transmission exceeds 1"))
    return found


def check(values: Mapping[str, Sequence[float]], theta_i_deg: Sequence[float], *, allowed: ArrayLike = 0.0,
          allow_nonphysical: bool = False) -> str | None:
    """Refuse a source whose hemispherical values are not physical (module docstring), before anything is written.

    Parameters
    ----------
    values : mapping of str to sequence of float
        Side → hemispherical value [-] per incidence of ``theta_i_deg`` (the sides written).
    theta_i_deg : sequence of float
        The incidences written [deg].
    allowed : float or array_like
        Further excess [-] allowed per incidence (a fit's k·u(TIS)); 0 for data and callables.
    allow_nonphysical : bool
        Do not refuse: return the message, to be said as a warning.

    Returns
    -------
    str or None
        None when the source is physical; with ``allow_nonphysical``, the one-line message of the first violation.

    Raises
    ------
    ValidationError
        One line naming the side (or sides), the incidence, the value and the rule, without ``allow_nonphysical``.
    """
    limits = np.broadcast_to(np.asarray(allowed, dtype=np.float64), (len(theta_i_deg),))
    found = _violations(values, theta_i_deg, limits)
    if not found:
        return None
    what, t, v, limit, rule = found[0]
    more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
    error = ValidationError(
        f"not a physical BSDF (energy conservation): {rule} (by more than {TIS_TOLERANCE:g} of measurement noise)"
        f"{more}; nothing written "
        f"({OPTION} writes it anyway)", field=f"{what} at theta_i={t:g} deg",
        expected=f"<= {limit:.6g}", got=round(v, 6))
    if not allow_nonphysical:
        raise error
    return str(error).replace(f"nothing written ({OPTION} writes it anyway)", f"written anyway ({OPTION})")


def excess_to_allow(values: Mapping[str, Sequence[float]], allowed: ArrayLike) -> NDArray[np.float64]:
    """The excess [-] over 1 a writer that checks energy itself (TracePro) must accept to write a source the user
    let through (``allow_nonphysical``): the sides' sum above 1 plus 10 % of it (the table's own TIS differs
    from the source's by the grid's error, well below that), never less than ``allowed``.

    Parameters
    ----------
    values : mapping of str to sequence of float
        Side → hemispherical value [-] per incidence.
    allowed : float or array_like
        The excess already allowed per incidence [-].

    Returns
    -------
    ndarray
        Allowed excess per incidence [-].
    """
    total = np.sum([np.asarray(v, dtype=np.float64) for v in values.values()], axis=0)
    total = np.where(np.isfinite(total), total, 0.0)
    return np.maximum(np.asarray(allowed, dtype=np.float64), np.maximum(1.1 * total - 1.0, 0.0))
