"""Regular hemisphere grids of a BSDF for the ray-tracer tables, and the TIS each table reader computes.

A *BSDF callable* is the common currency between models, measured-data reconstructions and the
exporters::

    bsdf_fn(theta_i_deg: float, side: str, directions: ndarray[..., 3]) -> ndarray[...]

returns the BSDF (1/sr, not cosine-weighted) for scattered unit vectors in the frame of ``side``
(z ≥ 0; see :mod:`bsdfkit.core.frames`) for a source at φi = 180°.

Two table geometries are built from it:

* **Harvey–Shack grid** (TracePro asymmetric table, ASAP-style table; docs/exports.md §2.1): |β − β0| × azimuth
  of β − β0, one pair of axes for all incidences (TracePro cannot use per-incidence ScatterBeta lists,
  [TracePro-examples] in docs/references.md). Nodes with |β| > 1 are not directions and hold 0.
* **Specular grid** (Zemax tabular BSDF; docs/exports.md §2.2): radial angle × azimuth about the specular
  direction. Nodes below the horizon hold 0.

TIS = ∫∫ BSDF cos θs dΩ = ∫∫_{|β|≤1} BSDF dβx dβy (docs/exports.md §3). Each table format has exactly one
quadrature, used by its writer (for the stated TIS / absorptance) and by its reader (for the recomputed
TIS), so a file is self-consistent by construction:

* :func:`tis_harvey_shack_table`: in polar coordinates about β0, each azimuth row is integrated exactly
  as the piecewise-linear interpolant in ρ times ρ dρ, up to the unit-circle edge ρmax(ψ) (the last
  node inside the disk is held constant up to the edge); rows are summed with periodic trapezoid
  weights in ψ.
* :func:`tis_specular_table`: each azimuth row, piecewise linear in the radial angle r, is integrated
  against the exact weight cos θs · sin r dr up to the horizon (Gauss–Legendre, 8 nodes per segment,
  exact to rounding for the smooth weight); rows are summed with periodic trapezoid weights in azimuth
  (PlaneSymmetrical rows mirrored to φ → 360° − φ).

For a Lambertian table (constant BSDF) the Harvey–Shack rule is exact on any uniform azimuth grid with
an even number of nodes (the mean of ρmax(ψ)² over such a grid is exactly 1); the specular rule is exact
at normal incidence and converges geometrically in the number of azimuths otherwise (default 5° grid:
< 1e-13 up to 70°, 2e-8 at 80°, 5e-6 at 85°, 3e-4 at 89°). Peaked lobes need dense radial nodes near the specular
point: the default axes use
log-spaced radii there (see :class:`HarveyShackAxes` and :class:`SpecularAxes`, and docs/exports.md
for the measured round-trip errors).

:func:`tis_reference` integrates a callable directly (polar coordinates centred on β0 with log-spaced
radius; docs/exports.md §3) and is the reference for the tables; the closed forms of the models' TIS live in
:mod:`bsdfkit.models.functions`.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bsdfkit.core import frames
from bsdfkit.core.errors import NumericalError, ValidationError
from bsdfkit.core.hemisphere import unit_disk_reach
from bsdfkit.core.lazy import LazyModule
from bsdfkit.core.quadrature import gauss_legendre

#: xarray on first use: the verbs' registration reads the format registry, which imports this module
xr = LazyModule("xarray")

__all__ = [
    "BsdfFn",
    "GridTolerance",
    "HarveyShackAxes",
    "PiecewiseConstant",
    "Pointwise",
    "piecewise_per_side",
    "SpecularAxes",
    "evaluate_bsdf",
    "auto_harvey_shack_axes",
    "auto_specular_axes",
    "azimuth_midpoints_deg",
    "quantize",
    "value_digits",
    "harvey_shack_cell_grid",
    "harvey_shack_grid",
    "harvey_shack_row_weights",
    "node_means",
    "horizon_radial",
    "lobe_core",
    "rho_max",
    "specular_grid",
    "tis_harvey_shack_table",
    "tis_reference",
    "tis_specular_table",
]


BsdfFn = Callable[[float, str, NDArray[np.float64]], ArrayLike]
"""BSDF callable: ``bsdf_fn(theta_i_deg, side, directions[..., 3]) -> bsdf[...]`` in 1/sr."""


# --------------------------------------------------------------------------------------------------
# axes
# --------------------------------------------------------------------------------------------------
def _strictly_increasing(name: str, values: Sequence[float], lo: float, hi: float) -> tuple[float, ...]:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise ValidationError("axis must be a non-empty list of finite numbers", field=name, got=list(values)[:8])
    if np.any(np.diff(arr) <= 0):
        raise ValidationError("axis must be strictly increasing", field=name, got=list(values)[:8])
    if arr[0] < lo or arr[-1] > hi:
        raise ValidationError("axis out of range", field=name, expected=f"values in [{lo:g}, {hi:g}]",
                              got=[float(arr[0]), float(arr[-1])])
    return tuple(float(v) for v in arr)


def _uniform_azimuths(step_deg: float) -> tuple[float, ...]:
    n = int(round(360.0 / step_deg))
    if n < 1 or abs(n * step_deg - 360.0) > 1e-9:
        raise ValidationError("azimuth step must divide 360", field="azimuth_step_deg", got=step_deg)
    return tuple(float(v) for v in np.arange(n) * (360.0 / n))


def _geometric_then_linear(first: float, ratio: float, max_step: float, last: float) -> NDArray[np.float64]:
    """0, then nodes first·ratio^k while the step stays below ``max_step``, then steps of at most
    ``max_step`` up to ``last`` (the final linear part is evenly divided so that ``last`` is a node).

    Constant *relative* spacing resolves peaks of any width above ``first`` with the same relative
    accuracy (piecewise-linear interpolation error ∝ (ratio − 1)²); the step cap keeps tails resolved.
    """
    if not (0.0 < first < last and ratio > 1.0 and max_step > 0.0):
        raise ValidationError("invalid radial axis parameters", field="axes",
                              expected="0 < first < last, ratio > 1, max_step > 0",
                              got=dict(first=first, ratio=ratio, max_step=max_step, last=last))
    nodes = [0.0, first]
    while nodes[-1] * (ratio - 1.0) < max_step and nodes[-1] * ratio < last:
        nodes.append(nodes[-1] * ratio)
    start = nodes[-1]
    n_lin = max(1, int(np.ceil((last - start) / max_step - 1e-9)))
    return np.concatenate([nodes, np.linspace(start, last, n_lin + 1)[1:]])


@dataclass(frozen=True)
class HarveyShackAxes:
    """Axes of a Harvey–Shack table: ρ = |β − β0| nodes and azimuth-of-(β − β0) nodes.

    ``azimuth_deg`` is measured in the *table* frame, whose 0 axis lies at sample-frame azimuth
    ``zero_azimuth_deg`` (counter-clockwise from the sample +x axis). ASAP-style tables use 0 (sample x
    axis); TracePro's floating zero-azimuth axis is orthogonal to the plane of incidence
    ([TracePro-UM]; docs/exports.md §2.1), i.e. 90° or 270° — see :mod:`bsdfkit.tables.formats.tracepro`.
    """

    rho: tuple[float, ...]
    azimuth_deg: tuple[float, ...]
    zero_azimuth_deg: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "rho", _strictly_increasing("rho", self.rho, 0.0, 2.0))
        object.__setattr__(self, "azimuth_deg", _strictly_increasing("azimuth_deg", self.azimuth_deg, 0.0, 360.0))
        if self.rho[0] != 0.0:
            raise ValidationError("the first |beta-beta0| node must be 0 (the specular point)",
                                  field="rho", got=self.rho[0])
        if self.azimuth_deg[-1] >= 360.0:
            raise ValidationError("azimuths must lie in [0, 360)", field="azimuth_deg", got=self.azimuth_deg[-1])

    @classmethod
    def default(
        cls,
        *,
        rho_first: float = 1e-3,
        ratio: float = 1.05,
        max_step: float = 0.025,
        azimuth_step_deg: float = 5.0,
        zero_azimuth_deg: float = 0.0,
    ) -> HarveyShackAxes:
        """ρ = 0, geometric nodes from ``rho_first`` with ``ratio`` until the step reaches ``max_step``,
        then linear up to 2; uniform azimuths every ``azimuth_step_deg``.

        The defaults give 187 radii × 72 azimuths; docs/exports.md lists the resulting table-TIS errors
        for Lambertian, Gaussian and ABg lobes (all < 0.25 %).

        Parameters
        ----------
        rho_first : float
            First non-zero radius ρ in direction cosines [-].
        ratio : float
            Ratio of consecutive geometric radial steps [-].
        max_step : float
            Largest radial step in direction cosines [-]; the linear step beyond the geometric part.
        azimuth_step_deg : float
            Azimuth step [deg].
        zero_azimuth_deg : float
            Sample-frame azimuth of the table's 0 azimuth [deg].

        Returns
        -------
        HarveyShackAxes
        """
        rho = _geometric_then_linear(rho_first, ratio, max_step, 2.0)
        return cls(tuple(rho), _uniform_azimuths(azimuth_step_deg), zero_azimuth_deg)


@dataclass(frozen=True)
class SpecularAxes:
    """Axes of a specular-centred (Zemax) table: radial angles and azimuths in degrees.

    ``azimuth_deg`` covers [0, 180] for PlaneSymmetrical tables and [0, 360) for Asymmetrical ones.
    """

    radial_deg: tuple[float, ...]
    azimuth_deg: tuple[float, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "radial_deg", _strictly_increasing("radial_deg", self.radial_deg, 0.0, 180.0))
        object.__setattr__(self, "azimuth_deg", _strictly_increasing("azimuth_deg", self.azimuth_deg, 0.0, 360.0))
        if self.radial_deg[0] != 0.0:
            raise ValidationError("the first radial node must be 0 (the specular direction)",
                                  field="radial_deg", got=self.radial_deg[0])

    @classmethod
    def default(
        cls,
        *,
        plane_symmetric: bool = True,
        radial_first_deg: float = 0.05,
        ratio: float = 1.05,
        max_step_deg: float = 2.0,
        azimuth_step_deg: float = 5.0,
    ) -> SpecularAxes:
        """radial = 0, geometric nodes from ``radial_first_deg`` with ``ratio`` until the step reaches
        ``max_step_deg``, then linear up to 180° (the horizon lies up to 90° + θi from the specular
        direction); azimuths 0…180 (plane symmetric, both ends included) or 0…360 − step.

        Parameters
        ----------
        plane_symmetric : bool
            Azimuths over the half circle 0…180° (else the full circle).
        radial_first_deg : float
            First non-zero radial angle [deg].
        ratio : float
            Ratio of consecutive geometric radial steps [-].
        max_step_deg : float
            Largest radial step [deg]; the linear step beyond the geometric part.
        azimuth_step_deg : float
            Azimuth step [deg].

        Returns
        -------
        SpecularAxes
        """
        radial = _geometric_then_linear(radial_first_deg, ratio, max_step_deg, 180.0)
        full = _uniform_azimuths(azimuth_step_deg)
        azimuth = tuple(a for a in full if a <= 180.0) + ((180.0,) if 180.0 not in full else ())
        return cls(tuple(radial), azimuth if plane_symmetric else full)


# --------------------------------------------------------------------------------------------------
# evaluating a callable
# --------------------------------------------------------------------------------------------------
#: Values below zero by at most this fraction of the block's largest |f| are round-off and taken as 0.
ROUND_OFF = 1e-9


def evaluate_bsdf(bsdf_fn: BsdfFn, theta_i_deg: float, side: str,
                  directions: NDArray[np.float64]) -> NDArray[np.float64]:
    """Call ``bsdf_fn`` and check its answer: shape ``directions.shape[:-1]``, finite, ≥ 0.

    Raises :class:`~bsdfkit.core.errors.ValidationError` naming the incidence, side and offending value
    (exporters need a finite, non-negative BSDF; tools reject or mis-sample anything else).

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : float
        Incidence angle [deg].
    side : str
        ``reflection`` or ``transmission``.
    directions : ndarray
        Unit scatter directions (..., 3) in the sample frame [-].

    Returns
    -------
    ndarray
        BSDF [1/sr], shape ``directions.shape[:-1]``.
    """
    if directions.shape[:-1] == (0,) or directions.size == 0:
        return np.zeros(directions.shape[:-1])
    values = _call_chunked(bsdf_fn, theta_i_deg, side, directions)
    where = f"BSDF callable at theta_i={theta_i_deg:g} deg, side={side}"
    if values.shape != directions.shape[:-1]:
        values = np.broadcast_to(values, directions.shape[:-1]) if values.ndim == 0 else values
        if values.shape != directions.shape[:-1]:
            raise ValidationError(f"{where} returned the wrong shape", field="bsdf",
                                  expected=str(directions.shape[:-1]), got=str(values.shape))
    if not np.all(np.isfinite(values)):
        bad = directions[~np.isfinite(values)][0]
        raise ValidationError(f"{where} returned a non-finite value", field="bsdf", expected="finite BSDF in 1/sr",
                              got=f"direction {np.round(bad, 6).tolist()}")
    # round-off below zero (interpolating non-negative data) is zero, not an error
    floor = ROUND_OFF * max(float(np.max(np.abs(values))) if values.size else 0.0, 1e-300)
    values = np.where((values < 0.0) & (values >= -floor), 0.0, values)
    if np.any(values < 0.0):
        raise ValidationError(f"{where} returned a negative BSDF", field="bsdf", expected=">= 0",
                              got=float(values.min()))
    return np.array(values, dtype=np.float64)


#: Directions per call of a BSDF callable (:func:`_call_chunked`).
CHUNK = 4096


@dataclass(frozen=True)
class Pointwise:
    """A BSDF callable (:data:`BsdfFn`) whose value at a direction depends on that direction alone, not on the
    other directions of the call nor on their number (a NumPy reconstruction such as the hemispherical engine's).
    :func:`evaluate_bsdf` calls it on the directions as they are, in chunks of at most :data:`CHUNK`, without
    padding the last chunk: the padding serves JAX models (one compilation per array shape), and a NumPy source
    would evaluate it (the auto grids ask for a few hundred directions at a time: padded to 4096, most of the
    work of a reconstruction's table was the padding).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr].
    """

    fn: BsdfFn

    def __call__(self, theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> ArrayLike:
        """``fn`` at the directions (unit vectors (..., 3) [-]) → BSDF [1/sr]."""
        return self.fn(theta_i_deg, side, directions)


#: Gauss–Legendre nodes on each side of a table node, in each coordinate, of :func:`node_means` (36 source values a
#: node: a Klems patch edge inside a hat is placed to a sixth of the node spacing)
NODE_MEAN_POINTS = 3


def _hat_nodes(x: NDArray[np.float64], before: NDArray[np.float64], after: NDArray[np.float64], n_half: int
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gauss–Legendre nodes and weights of ∫ g(s) hat(s) ds for the hat of each node ``x`` (1 at x, 0 at its
    neighbours ``before`` and ``after``; NaN: no neighbour on that side, the hat ends at x): shape (x, 2 n_half)."""
    z, w = np.polynomial.legendre.leggauss(n_half)
    u = 0.5 * (z + 1.0)  # (0, 1): distance from the node as a fraction of the step
    nodes, weights = [], []
    for other, sign in ((before, -1.0), (after, 1.0)):
        step = np.where(np.isfinite(other), np.abs(other - x), 0.0)
        nodes.append(x[:, None] + sign * step[:, None] * u[None, :])
        weights.append(step[:, None] * (0.5 * w * (1.0 - u))[None, :])
    return np.concatenate(nodes, axis=1), np.concatenate(weights, axis=1)


@dataclass(frozen=True)
class PiecewiseConstant(Pointwise):
    """A :class:`Pointwise` BSDF callable that is constant over the cells of an angle basis (a Klems or tensor-tree
    file evaluated by exact cell lookup, :func:`bsdfkit.reduction.basis.cell_index`). Point samples of a function
    with steps integrate to the wrong value on any grid whose nodes do not follow the steps (a direct-transmission
    patch of 30/sr beside patches of 0.01/sr: 3-28 % on the 1° Speos grid); a writer given such a source stores at
    each node the projected-solid-angle mean of the source over the node's share of the reader's quadrature
    (:func:`node_means`), so that the table integrates to the source's value and a patch's power stays where the
    patch is.

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr].
    exact_tis : callable, optional
        ``exact_tis(theta_i_deg, side)`` → the source's own hemispherical value [-] (the basis sum), which
        :func:`tis_reference` returns instead of a quadrature across the steps.
    basis : str, optional
        The source's angle basis (:func:`bsdfkit.reduction.basis.klems_spec` / ``shirley_chiu_spec``): a BSDF XML
        writer keeps it (a Klems file stays Klems, a tree a tree).
    """

    exact_tis: Callable[[float, str], float] | None = None
    basis: str | None = None


def piecewise_per_side(fns: Mapping[str, BsdfFn], bsdf_fn: BsdfFn) -> PiecewiseConstant | None:
    """``bsdf_fn`` (which dispatches to ``fns[side]``) as a :class:`PiecewiseConstant` when every side's source is
    one: its exact TIS is the side's own (else :func:`tis_reference` of it), its basis the sides' common one; None
    when some side is not piecewise constant.

    Parameters
    ----------
    fns : mapping of str to callable
        Side → BSDF callable [1/sr].
    bsdf_fn : callable
        The callable that dispatches to them by side.

    Returns
    -------
    PiecewiseConstant or None
    """
    if not fns or not all(isinstance(f, PiecewiseConstant) for f in fns.values()):
        return None

    def exact(theta_i_deg: float, side: str) -> float:
        f = fns[side]
        return f.exact_tis(theta_i_deg, side) if f.exact_tis is not None else tis_reference(Pointwise(f),
                                                                                             theta_i_deg, side)

    bases = {f.basis for f in fns.values()}
    return PiecewiseConstant(bsdf_fn, exact, bases.pop() if len(bases) == 1 else None)


def node_means(bsdf_fn: BsdfFn, theta_i_deg: float, side: str, first_deg: NDArray[np.float64],
               azimuth_deg: NDArray[np.float64], direction_of: Callable[[NDArray, NDArray], NDArray],
               tent: str, density: Callable[[NDArray, NDArray, NDArray], NDArray]) -> NDArray[np.float64]:
    """The BSDF on a table's (azimuth, first) nodes as means over each node's hat function: the weighted mean of
    the source over the region between the node's neighbours, weight (1 − |u|) in the reader's interpolation
    coordinate (``tent``) and in azimuth (periodic) times the projected-solid-angle density. The hats of
    all nodes sum to 1, so a reader that interpolates the nodes linearly in those coordinates integrates the table
    to the source's integral whatever steps the source has.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr].
    theta_i_deg : float
        Incidence [deg].
    side : str
        ``reflection`` or ``transmission``.
    first_deg : ndarray
        The table's first (polar or radial) axis, increasing [deg].
    azimuth_deg : ndarray
        The table's azimuths [deg] over the full circle, increasing (a last one at 360° repeating 0° allowed).
    direction_of : callable
        ``direction_of(first, azimuth)`` [deg] → unit directions (..., 3) in the sample frame.
    tent : str
        The reader's interpolation coordinate of ``first``: ``sin`` (sin θ, tables about the normal: the engine
        interpolates linearly in the projected radius) or ``angle`` (the angle itself).
    density : callable
        ``density(first_deg, azimuth_deg, directions)`` → projected solid angle per unit of tent coordinate and
        radian of azimuth [sr] (0 below the horizon).

    Returns
    -------
    ndarray
        (azimuth, first) node means [1/sr]; nodes at first = 0 (one direction for every azimuth) share the mean over
        the whole cap.
    """
    first = np.asarray(first_deg, dtype=np.float64)
    az = np.asarray(azimuth_deg, dtype=np.float64)
    closing = az.size > 1 and abs(az[-1] - az[0] - 360.0) < 1e-9  # a column at 360° repeating 0°
    ring = az[:-1] if closing else az
    if tent not in ("sin", "angle"):
        raise ValueError(f"unknown tent coordinate {tent!r}")
    t = np.sin(np.radians(first)) if tent == "sin" else first
    n_half = NODE_MEAN_POINTS
    t_sub, w_sub = _hat_nodes(t, np.concatenate([[np.nan], t[:-1]]), np.concatenate([t[1:], [np.nan]]), n_half)
    f_sub = np.degrees(np.arcsin(np.clip(t_sub, 0.0, 1.0))) if tent == "sin" else t_sub
    # azimuth: periodic neighbours
    last = np.arange(ring.size) == ring.size - 1
    a_sub, wa_sub = _hat_nodes(ring, np.roll(ring, 1) - np.where(np.arange(ring.size) == 0, 360.0, 0.0),
                               np.roll(ring, -1) + np.where(last, 360.0, 0.0), n_half)
    fa, ff = np.broadcast_arrays(a_sub[:, None, :, None], f_sub[None, :, None, :])
    d = direction_of(ff, fa)
    weight = (wa_sub[:, None, :, None] * w_sub[None, :, None, :]) * density(ff, fa, d)
    values = evaluate_bsdf(bsdf_fn, theta_i_deg, side, d)
    total = np.sum(weight, axis=(2, 3))
    mean = np.divide(np.sum(weight * values, axis=(2, 3)), total, out=np.zeros_like(total), where=total > 0)
    pole = np.abs(first) < 1e-12
    if pole.any():  # one direction for every azimuth: the mean over the whole cap
        cap = np.sum(total[:, pole], axis=0)
        mean[:, pole] = np.divide(np.sum(mean[:, pole] * total[:, pole], axis=0), cap, out=np.zeros_like(cap),
                                  where=cap > 0)
    return np.concatenate([mean, mean[:1]], axis=0) if closing else mean


def _call_chunked(bsdf_fn: BsdfFn, theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray:
    """``bsdf_fn`` on the directions flattened, in chunks of :data:`CHUNK` (the last padded with the first
    direction, unless the callable is :class:`Pointwise`).

    The auto grids evaluate the callable on arrays of ever new lengths; a JAX model compiles each operation
    once per array shape, so every call gets the same shape. The answer is reshaped to
    ``directions.shape[:-1]`` (a scalar answer is broadcast).
    """
    flat = directions.reshape(-1, 3)
    n = flat.shape[0]
    # a Pointwise callable gets the directions as they are (its last chunk shorter); others a multiple of CHUNK
    size = n if isinstance(bsdf_fn, Pointwise) else -(-n // CHUNK) * CHUNK
    padded = np.concatenate([flat, np.broadcast_to(flat[:1], (size - n, 3))]) if size > n else flat
    parts = []
    for k in range(0, size, CHUNK):
        chunk = padded[k:k + CHUNK]
        out = np.asarray(bsdf_fn(float(theta_i_deg), side, chunk), dtype=np.float64)
        if out.ndim == 0:
            return np.broadcast_to(out, directions.shape[:-1])
        if out.shape != (chunk.shape[0],):
            return out  # the shape check of evaluate_bsdf names the mismatch
        parts.append(out)
    return np.concatenate(parts)[:n].reshape(directions.shape[:-1])


def rho_max(theta_i_deg: ArrayLike, sample_azimuth_deg: ArrayLike) -> NDArray[np.float64]:
    """Distance from β0 = (sin θi, 0) to the unit circle along sample-frame azimuth ψ:
    ρmax = −b cos ψ + √(1 − b² sin² ψ), b = sin θi (broadcast; :func:`bsdfkit.core.hemisphere.unit_disk_reach`).

    Parameters
    ----------
    theta_i_deg : array_like
        Incidence angle θi [deg].
    sample_azimuth_deg : array_like
        Sample-frame azimuth ψ about β0 [deg].

    Returns
    -------
    ndarray
        ρmax in direction cosines [-], broadcast shape of the inputs.
    """
    b = np.sin(np.radians(np.asarray(theta_i_deg, dtype=np.float64)))
    # ψ reduced to [−180°, 180°) first: mirror azimuths ±ψ (a plane-symmetric table's, whose table azimuths are
    # offset by its zero azimuth) then meet the same edge to the last bit (cos is even), so a node on the edge
    # is inside on both sides or on neither (cos(450°) and cos(−90°) differ by 3e-16)
    psi = np.radians(np.remainder(np.asarray(sample_azimuth_deg, dtype=np.float64) + 180.0, 360.0) - 180.0)
    return unit_disk_reach(b * np.cos(psi), b * b)


def horizon_radial(theta_i_deg: ArrayLike, azimuth_deg: ArrayLike) -> NDArray[np.float64]:
    """Radial angle (radians) of the horizon about a specular direction at θ0, along azimuth a:
    r_h = atan2(cos θ0, −cos a · sin θ0), where ω_z = cos r cos θ0 + sin r cos a sin θ0 = 0 (broadcast).
    r_h = 90° + θ0 toward the normal (a = 0) and 90° − θ0 away from it (a = 180°).

    Parameters
    ----------
    theta_i_deg : array_like
        Specular angle θ0 [deg].
    azimuth_deg : array_like
        Azimuth a about the specular direction [deg].

    Returns
    -------
    ndarray
        r_h [rad], broadcast shape of the inputs.
    """
    t = np.radians(np.asarray(theta_i_deg, dtype=np.float64))
    a = np.radians(np.asarray(azimuth_deg, dtype=np.float64))
    return np.arctan2(np.cos(t), -np.cos(a) * np.sin(t))


def _check_incidences(theta_i_deg: Sequence[float]) -> NDArray[np.float64]:
    arr = np.atleast_1d(np.asarray(theta_i_deg, dtype=np.float64))
    if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise ValidationError("incidence angles must be a non-empty list of finite numbers",
                              field="theta_i", got=list(np.ravel(arr))[:8])
    if np.any(arr < 0.0) or np.any(arr >= 90.0):
        raise ValidationError("incidence angle out of range", field="theta_i", expected="0 <= theta_i < 90 deg",
                              got=float(arr[(arr < 0) | (arr >= 90)][0]))
    if np.any(np.diff(arr) <= 0):
        raise ValidationError("incidence angles must be strictly increasing", field="theta_i", got=arr.tolist())
    return arr


def _check_sides(sides: Sequence[str]) -> tuple[str, ...]:
    if isinstance(sides, str):
        sides = (sides,)
    out = tuple(sides)
    for s in out:
        if s not in frames.SIDES:
            raise ValidationError("unknown scattering side", field="side", expected=" or ".join(frames.SIDES), got=s)
    if not out or len(set(out)) != len(out):
        raise ValidationError("sides must be a non-empty list without repeats", field="side", got=list(out))
    return out


def harvey_shack_grid(
    bsdf_fn: BsdfFn, theta_i_deg: Sequence[float], sides: Sequence[str] | str, axes: HarveyShackAxes
) -> xr.DataArray:
    """BSDF on the Harvey–Shack table nodes, dims ``(side, theta_i, rho, psi)``.

    Node (ρ, ψ) is the direction β = β0 + ρ(cos ψs, sin ψs), ψs = ψ + ``axes.zero_azimuth_deg`` (sample
    frame); nodes with |β| > 1 hold 0.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Incidence angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    axes : HarveyShackAxes
        Table axes: ρ = |β − β0| [-] and table-frame azimuths [deg].

    Returns
    -------
    xarray.DataArray
        BSDF [1/sr] on the nodes.
    """
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)
    rho = np.asarray(axes.rho)
    psi_table = np.asarray(axes.azimuth_deg)
    psi_sample = np.radians(psi_table + axes.zero_azimuth_deg)
    out = np.zeros((len(sides), thetas.size, rho.size, psi_table.size))
    for t, theta in enumerate(thetas):
        b0 = frames.beta0(np.radians(theta))
        beta = b0 + rho[:, None, None] * np.stack([np.cos(psi_sample), np.sin(psi_sample)], axis=-1)[None]
        # the reader's criterion (tis_harvey_shack_table), so writer and reader agree on every node
        inside = rho[:, None] <= rho_max(theta, psi_table + axes.zero_azimuth_deg)[None, :]
        directions = frames.direction_from_beta(beta[inside])
        for s, side in enumerate(sides):
            out[s, t][inside] = evaluate_bsdf(bsdf_fn, theta, side, directions)
    return xr.DataArray(
        out,
        dims=("side", "theta_i", "rho", "psi"),
        coords={"side": list(sides), "theta_i": thetas, "rho": rho, "psi": psi_table},
        name="bsdf",
        attrs={"units": "1/sr", "quantity": "bsdf", "frame": "harvey_shack",
               "zero_azimuth_deg": float(axes.zero_azimuth_deg)},
    )


#: Gauss–Legendre points per cell and direction of :func:`harvey_shack_cell_grid` (exact for polynomials of degree
#: 7 in ρ and ψ on each clipped cell)
CELL_ORDER = 4


def harvey_shack_row_weights(rho: NDArray[np.float64], azimuth_deg: NDArray[np.float64], theta_i_deg: float,
                             zero_azimuth_deg: float) -> NDArray[np.float64]:
    """W[k, j] [sr, projected]: the weight of node (ρ_j, ψ_k) in :func:`tis_harvey_shack_table`, which is linear
    in the values: TIS = Σ W·f. Row k: ∫ hat_j(ρ) ρ dρ over the segments wholly inside the disk, and for the
    last inside node also ½(ρmax² − ρ_J²) (held to the edge); times the periodic trapezoid weight of ψ_k.

    Parameters
    ----------
    rho : ndarray
        Radial nodes ρ in direction cosines [-], increasing.
    azimuth_deg : ndarray
        Table-frame azimuths [deg].
    theta_i_deg : float
        Incidence angle [deg].
    zero_azimuth_deg : float
        Sample-frame azimuth of the table's 0 azimuth [deg].

    Returns
    -------
    ndarray
        W (azimuth × ρ) [sr, projected].
    """
    w_row = _azimuth_row_weights(azimuth_deg, plane_symmetric=False)
    rmax = np.minimum(rho_max(theta_i_deg, azimuth_deg + zero_azimuth_deg), rho[-1])  # (psi,)
    r0, r1 = rho[:-1], rho[1:]
    full = r1[None, :] <= rmax[:, None]
    part = (r0[None, :] < rmax[:, None]) & ~full
    m = np.zeros((azimuth_deg.size, rho.size))
    m[:, :-1] += np.where(full, (r1 - r0) / 6.0 * (2.0 * r0 + r1), 0.0)
    m[:, 1:] += np.where(full, (r1 - r0) / 6.0 * (r0 + 2.0 * r1), 0.0)
    m[:, :-1] += np.where(part, 0.5 * (rmax[:, None] ** 2 - r0[None, :] ** 2), 0.0)
    return m * w_row[:, None]


def harvey_shack_cell_grid(
    bsdf_fn: BsdfFn, theta_i_deg: Sequence[float], sides: Sequence[str] | str, axes: HarveyShackAxes,
    order: int = CELL_ORDER,
) -> xr.DataArray:
    """The BSDF's weighted averages about the Harvey–Shack table nodes, dims ``(side, theta_i, rho, psi)``: a table
    that integrates, by its format's own rule (:func:`tis_harvey_shack_table`), to the integral of the BSDF itself
    on any axes, however coarse.

    Node (ρ_j, ψ_k) holds v = ∫∫ f φ_jk dβ / W_jk: φ_jk = hat_k(ψ) · hat_j(ρ) are the functions by which the table
    interpolates between its nodes (piecewise linear in ρ along a row, held from the row's last node inside the
    disk to its edge; linear in ψ between rows) and W_jk = ∫∫ φ_jk dβ is the node's weight in the table's TIS
    (:func:`harvey_shack_row_weights`). The φ_jk sum to 1 over the disk, so Σ W·v = ∫∫_{|β|≤1} f dβ: the table's
    TIS is the BSDF's, to the accuracy of the ``order`` × ``order`` Gauss–Legendre points per cell (cells clipped
    to the disk's edge). A constant BSDF gives that constant at every node but the last of a row, which takes up
    the difference between the disk's edge and the rule's (trapezoid between rows). Point samples
    (:func:`harvey_shack_grid`) reach that only when the grid resolves every kink of the BSDF, which for a measured
    reconstruction took 7 MB (docs/exports.md, "Grid resolution"). Where the
    BSDF is linear across a node's cells the average is the point value; a peak is smoothed over its cells,
    which the auto grid's peak criterion keeps within ``peak_rtol``. Nodes outside the disk hold 0.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Incidence angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    axes : HarveyShackAxes
        Table axes: ρ = |β − β0| [-] and table-frame azimuths [deg].
    order : int
        Gauss–Legendre points per cell along each of ρ and ψ.

    Returns
    -------
    xarray.DataArray
        Weighted cell averages of the BSDF [1/sr] on the nodes.
    """
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)
    rho = np.asarray(axes.rho, dtype=np.float64)
    az = np.asarray(axes.azimuth_deg, dtype=np.float64)
    zero = float(axes.zero_azimuth_deg)
    x, gw = gauss_legendre(int(order))
    x, gw = 0.5 * (x + 1.0), 0.5 * gw
    # azimuth sub-points: q per interval [ψ_k, ψ_k+1) of the periodic grid, with their two rows and hat weights
    nxt = np.append(az[1:], az[0] + 360.0)
    width = np.radians(nxt - az)  # (psi,)
    psi_p = (az[:, None] + (nxt - az)[:, None] * x[None, :]).ravel()  # table frame [deg]
    row_lo = np.repeat(np.arange(az.size), x.size)
    row_hi = (row_lo + 1) % az.size
    t_a = np.tile(x, az.size)
    w_a = (width[:, None] * gw[None, :]).ravel()  # [rad]
    out = np.zeros((len(sides), thetas.size, rho.size, az.size))
    n_seg = rho.size - 1
    for t, theta in enumerate(thetas):
        # ρ sub-points of each sub-azimuth up to the disk's edge there: q per axis segment, clipped (p, seg, q)
        edge_p = np.minimum(rho_max(theta, psi_p + zero), rho[-1])
        lo = np.minimum(rho[None, :-1], edge_p[:, None])
        hi = np.minimum(rho[None, 1:], edge_p[:, None])
        length = hi - lo
        r = lo[..., None] + length[..., None] * x[None, None, :]
        keep = np.broadcast_to(length[..., None] > 0.0, r.shape)
        p_idx = np.broadcast_to(np.arange(psi_p.size)[:, None, None], r.shape)[keep]
        r_pts = r[keep]
        w_pts = (length[..., None] * gw[None, None, :] * r)[keep] * w_a[p_idx]  # ρ dρ dψ
        psi_s = np.radians(psi_p[p_idx] + zero)
        beta = frames.beta0(np.radians(theta)) + r_pts[:, None] * np.stack([np.cos(psi_s), np.sin(psi_s)], axis=-1)
        norm = np.hypot(beta[:, 0], beta[:, 1])  # rounding at the edge
        beta = np.where((norm > 1.0)[:, None], beta / np.maximum(norm, 1.0)[:, None], beta)
        directions = frames.direction_from_beta(beta)
        # each row interpolates in ρ up to its last node inside the disk and holds it from there
        rmax_row = np.minimum(rho_max(theta, az + zero), rho[-1])
        last = np.searchsorted(rho, rmax_row, side="right") - 1
        weights = harvey_shack_row_weights(rho, az, float(theta), zero)  # (psi, rho)
        hats = []
        for row, share in ((row_lo[p_idx], 1.0 - t_a[p_idx]), (row_hi[p_idx], t_a[p_idx])):
            rc = np.minimum(r_pts, rho[last[row]])
            j = np.clip(np.searchsorted(rho, rc, side="right") - 1, 0, max(n_seg - 1, 0))
            span = rho[j + 1] - rho[j] if n_seg > 0 else np.ones_like(rc)
            u = np.clip((rc - rho[j]) / span, 0.0, 1.0)
            hats += [(row * rho.size + j, share * (1.0 - u)), (row * rho.size + j + 1, share * u)]
        for s, side in enumerate(sides):
            fw = evaluate_bsdf(bsdf_fn, theta, side, directions) * w_pts
            num = np.zeros(az.size * rho.size)
            for node, h in hats:
                num += np.bincount(node, weights=fw * h, minlength=num.size)
            num = num.reshape(az.size, rho.size)
            vals = np.where(weights > 0.0, num / np.where(weights > 0.0, weights, 1.0), 0.0)
            out[s, t] = np.maximum(vals, 0.0).T
    return xr.DataArray(
        out,
        dims=("side", "theta_i", "rho", "psi"),
        coords={"side": list(sides), "theta_i": thetas, "rho": rho, "psi": az},
        name="bsdf",
        attrs={"units": "1/sr", "quantity": "bsdf", "frame": "harvey_shack", "zero_azimuth_deg": zero,
               "values": "cell averages"},
    )


class _PolarMemo:
    """Values ``[..., azimuth, radius]`` known at some (azimuth, radius) pairs of growing, sorted axes: the memo of
    the auto grids, which ask again and again for values at nodes (and edge strips) they have already evaluated.
    Looked up by index arrays, not key by key (a candidate grid asks for thousands of pairs). ``lead``: the leading
    dimensions of the values; ``known_lead``: those of the known-mask (the values of every side known at once, of
    each incidence on its own or not)."""

    def __init__(self, lead: tuple[int, ...], known_lead: tuple[int, ...] = ()) -> None:
        self.lead, self.known_lead = lead, known_lead
        self.r = np.empty(0)
        self.a = np.empty(0)
        self.values = np.zeros(lead + (0, 0))
        self.known = np.zeros(known_lead + (0, 0), dtype=bool)

    def index(self, r: NDArray[np.float64], a: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Positions of the radii ``r`` and azimuths ``a`` on the memo's axes, which grow to hold them (equal floats
        are one node)."""
        at_r, at_a = np.searchsorted(self.r, r), np.searchsorted(self.a, a)
        if _all_found(self.r, r, at_r) and _all_found(self.a, a, at_a):
            return at_r, at_a
        r_all, a_all = np.union1d(self.r, r), np.union1d(self.a, a)
        pos_a, pos_r = np.searchsorted(a_all, self.a), np.searchsorted(r_all, self.r)
        values = np.zeros(self.lead + (a_all.size, r_all.size))
        known = np.zeros(self.known_lead + (a_all.size, r_all.size), dtype=bool)
        values[..., pos_a[:, None], pos_r[None, :]] = self.values
        known[..., pos_a[:, None], pos_r[None, :]] = self.known
        self.r, self.a, self.values, self.known = r_all, a_all, values, known
        return np.searchsorted(self.r, r), np.searchsorted(self.a, a)


def _all_found(axis: NDArray[np.float64], values: NDArray[np.float64], at: NDArray[np.intp]) -> bool:
    """Whether every value is on the sorted ``axis`` at its insertion position ``at``."""
    if axis.size == 0:
        return values.size == 0
    return bool(np.all((at < axis.size) & (axis[np.minimum(at, axis.size - 1)] == values)))


#: Gauss–Legendre points along a row's edge strip of :func:`harvey_shack_edge_values`
EDGE_ORDER = 16


def harvey_shack_edge_values(
    values: ArrayLike, bsdf_fn: BsdfFn, theta_i_deg: Sequence[float], sides: Sequence[str] | str,
    axes: HarveyShackAxes, order: int = EDGE_ORDER, strips: _PolarMemo | None = None,
) -> NDArray[np.float64]:
    """Point samples of a Harvey–Shack table with each row's last node inside the disk replaced by its *edge value*.

    Parameters
    ----------
    values
        The table ``[side, theta_i, rho, psi]`` [1/sr] as :func:`harvey_shack_grid` samples it.
    bsdf_fn, theta_i_deg, sides, axes
        The source [1/sr], incidences [deg], sides and axes the table was sampled with.
    order
        Gauss–Legendre points along each row's edge strip.
    strips
        Memo of the strips' integrals ``[side, theta, azimuth, strip start]`` for these sides and incidences, filled
        here: the auto grid asks for the edge values of many candidate axes that share most rows and strips.

    Returns
    -------
    numpy.ndarray
        The table [1/sr]: every node the point sample, but node (ρ_J, ψ_k), the last of row k with ρ_J ≤ ρmax(ψ_k),
        which holds the value v ≥ 0 for which the row integrates the strip [ρ_{J−1}, ρmax] as the source does::

            ∫_{ρ_{J−1}}^{ρ_J} lin(f_{J−1}, v) ρ dρ + v (ρmax² − ρ_J²)/2 = ∫_{ρ_{J−1}}^{ρmax} f ρ dρ

    Notes
    -----
    A table reader cannot follow the disk's edge between the nodes of one ρ list shared by every azimuth and
    incidence: the format's rule (:func:`tis_harvey_shack_table`) and the hemispherical engine behind ``bsdfkit
    read`` both hold a row's last node inside the disk out to the edge. A point sample held across a strip up to
    one radial step wide misses the source's slope there — for a source that rises or falls toward the horizon
    (a lobe at grazing incidence, a reconstruction held beyond its last measured angle) that strip carried most of
    the table's TIS error (docs/exports.md, "Grid resolution"). The edge value makes the held strip integrate as
    the source does, row by row, on any axes; a constant source keeps its constant. Rows whose edge falls on a
    node, and rows with one node inside, keep their point samples.
    """
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)
    out = np.array(values, dtype=np.float64, copy=True)
    rho = np.asarray(axes.rho, dtype=np.float64)
    az = np.asarray(axes.azimuth_deg, dtype=np.float64)
    zero = float(axes.zero_azimuth_deg)
    x, w = gauss_legendre(int(order))
    x, w = 0.5 * (x + 1.0), 0.5 * w
    # every incidence's rows at once; rho_max incidence by incidence, as the quadrature's and the grid's nodes take it
    rmax = np.stack([np.minimum(rho_max(theta, az + zero), rho[-1]) for theta in thetas])  # (theta, psi)
    last = np.searchsorted(rho, rmax, side="right") - 1  # the reader's "inside" (ρ ≤ ρmax), as the quadrature
    t_of, rows = np.nonzero((last >= 1) & (rho[np.maximum(last, 0)] < rmax))  # incidence by incidence, rows in order
    if rows.size == 0:
        return out
    j = last[t_of, rows]
    a, b, r_j = rho[j - 1], rmax[t_of, rows], rho[j]
    memo = strips if strips is not None else _PolarMemo((len(sides), thetas.size), (thetas.size,))
    if memo.lead != (len(sides), thetas.size):
        raise ValidationError("edge-strip memo of other incidences or sides", field="strips",
                              expected=str((len(sides), thetas.size)), got=str(memo.lead))
    at_r, at_a = memo.index(a, az[rows])  # the strip of (t_of[i], rows[i]): memo node (t_of[i], at_a[i], at_r[i])
    new = ~memo.known[t_of, at_a, at_r]
    for t in np.unique(t_of[new]):
        theta = thetas[t]
        now = new & (t_of == t)
        an, bn = a[now], b[now]
        r = an[:, None] + (bn - an)[:, None] * x[None, :]
        psi_s = np.radians(az[rows[now]] + zero)
        beta = (frames.beta0(np.radians(theta))
                + r[..., None] * np.stack([np.cos(psi_s), np.sin(psi_s)], -1)[:, None])
        norm = np.hypot(beta[..., 0], beta[..., 1])  # rounding at the edge
        beta = np.where((norm > 1.0)[..., None], beta / np.maximum(norm, 1.0)[..., None], beta)
        directions = frames.direction_from_beta(beta.reshape(-1, 2))
        integrals = np.stack([(bn - an) * np.sum(evaluate_bsdf(bsdf_fn, float(theta), side, directions)
                                                 .reshape(r.shape) * r * w[None, :], axis=1)
                              for side in sides])  # (side, row)
        memo.values[:, t, at_a[now], at_r[now]] = integrals
        memo.known[t, at_a[now], at_r[now]] = True
    strip = memo.values[:, t_of, at_a, at_r]  # (side, row)
    c_prev = (r_j - a) / 6.0 * (2.0 * a + r_j)  # weight of f_{J-1} in the strip's integral by the rule
    c_last = (r_j - a) / 6.0 * (a + 2.0 * r_j) + 0.5 * (b * b - r_j * r_j)  # weight of the edge value
    for s in range(len(sides)):
        out[s, t_of, j, rows] = np.maximum((strip[s] - out[s, t_of, j - 1, rows] * c_prev) / c_last, 0.0)
    return out


def harvey_shack_edge_grid(
    bsdf_fn: BsdfFn, theta_i_deg: Sequence[float], sides: Sequence[str] | str, axes: HarveyShackAxes
) -> xr.DataArray:
    """:func:`harvey_shack_grid` with each row's last node inside the disk holding its edge value
    (:func:`harvey_shack_edge_values`), dims ``(side, theta_i, rho, psi)`` [1/sr].

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Incidence angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    axes : HarveyShackAxes
        Table axes: ρ = |β − β0| [-] and table-frame azimuths [deg].

    Returns
    -------
    xarray.DataArray
        BSDF [1/sr] on the nodes.
    """
    grid = harvey_shack_grid(bsdf_fn, theta_i_deg, sides, axes)
    values = harvey_shack_edge_values(grid.values, bsdf_fn, grid["theta_i"].values, tuple(grid["side"].values), axes)
    return grid.copy(data=values).assign_attrs(values="point samples, edge values at the disk's edge")


def specular_grid(
    bsdf_fn: BsdfFn, theta_i_deg: Sequence[float], sides: Sequence[str] | str, axes: SpecularAxes
) -> xr.DataArray:
    """BSDF on the specular-centred table nodes, dims ``(side, theta_i, azimuth, radial)`` (file order).

    Node (radial, azimuth) is :func:`bsdfkit.core.frames.direction_from_specular`; nodes below the horizon
    (ω_z < 0) hold 0. ``theta_i`` is the specular (= direct-transmission) angle, which is what Zemax
    calls AngleOfIncidence ([Zemax-BSDF]; docs/exports.md §2.2).

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Specular angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    axes : SpecularAxes
        Radial angles [deg] and azimuths [deg] about the specular direction.

    Returns
    -------
    xarray.DataArray
        BSDF [1/sr] on the nodes.
    """
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)
    radial = np.radians(np.asarray(axes.radial_deg))
    azimuth = np.radians(np.asarray(axes.azimuth_deg))
    out = np.zeros((len(sides), thetas.size, azimuth.size, radial.size))
    for t, theta in enumerate(thetas):
        if isinstance(bsdf_fn, PiecewiseConstant):  # a file's cells: each node the mean under its hat
            out[:, t] = [_specular_node_means(bsdf_fn, float(theta), side, axes) for side in sides]
            continue
        v = frames.direction_from_specular(radial[None, :], azimuth[:, None], np.radians(theta))
        # the reader's criterion (tis_specular_table), so writer and reader agree on every node
        inside = radial[None, :] <= horizon_radial(theta, np.asarray(axes.azimuth_deg))[:, None]
        directions = v[inside]
        directions[:, 2] = np.maximum(directions[:, 2], 0.0)
        directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
        for s, side in enumerate(sides):
            out[s, t][inside] = evaluate_bsdf(bsdf_fn, theta, side, directions)
    return xr.DataArray(
        out,
        dims=("side", "theta_i", "azimuth", "radial"),
        coords={"side": list(sides), "theta_i": thetas, "azimuth": np.asarray(axes.azimuth_deg),
                "radial": np.asarray(axes.radial_deg)},
        name="bsdf",
        attrs={"units": "1/sr", "quantity": "bsdf", "frame": "specular"},
    )


# --------------------------------------------------------------------------------------------------
# table quadratures (one per format, shared by writer and reader)
# --------------------------------------------------------------------------------------------------
def _specular_node_means(bsdf_fn: BsdfFn, theta_i_deg: float, side: str, axes: SpecularAxes) -> NDArray[np.float64]:
    """:func:`node_means` on the specular-centred nodes (azimuth, radial) of a piecewise-constant source: hats in the
    radial angle and azimuth about the specular direction, over the full circle of azimuths (a plane-symmetric
    half taken from it), projected solid angle sin r cos θs dr dφ; nodes beyond the horizon hold 0 as the reader
    takes them."""
    wanted = np.asarray(axes.azimuth_deg, dtype=np.float64)
    ring = np.unique(np.round(np.mod(np.concatenate([wanted, 360.0 - wanted]), 360.0), 9))
    theta = np.radians(theta_i_deg)

    def directions(r_deg: NDArray, a_deg: NDArray) -> NDArray:
        # unit vectors as they are: those below the horizon (z < 0) get no weight (density), their value is unused
        return frames.direction_from_specular(np.radians(r_deg), np.radians(a_deg), theta)

    def density(r_deg: NDArray, a_deg: NDArray, d: NDArray) -> NDArray:
        return np.where(d[..., 2] <= 0.0, 0.0, np.sin(np.radians(r_deg)) * d[..., 2])

    means = node_means(bsdf_fn, theta_i_deg, side, np.asarray(axes.radial_deg, dtype=np.float64), ring, directions,
                       "angle", density)
    rows = np.searchsorted(ring, np.round(np.mod(wanted, 360.0), 9))
    inside = np.radians(np.asarray(axes.radial_deg))[None, :] <= horizon_radial(theta_i_deg, wanted)[:, None]
    return np.where(inside, means[rows], 0.0)


def _periodic_weights(angles_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """Trapezoid weights of a periodic function sampled at sorted, distinct angles in [0, 2π)."""
    n = angles_rad.size
    if n == 1:
        return np.array([2.0 * np.pi])
    nxt = np.roll(angles_rad, -1)
    nxt[-1] += 2.0 * np.pi
    prv = np.roll(angles_rad, 1)
    prv[0] -= 2.0 * np.pi
    return 0.5 * (nxt - prv)


def _azimuth_row_weights(azimuth_deg: NDArray[np.float64], plane_symmetric: bool) -> NDArray[np.float64]:
    """Quadrature weight (radians) of each azimuth row over the full circle.

    Plane-symmetric rows (0…180°) also stand for their mirror images 360° − φ. Rows that repeat an
    angle modulo 360° (0 and 360) get weight only once, on the first occurrence.
    """
    az = np.mod(np.asarray(azimuth_deg, dtype=np.float64), 360.0)
    owners: dict[float, int] = {}
    for k, a in enumerate(az):
        key = round(float(a), 9)
        owners.setdefault(key, k)
        if plane_symmetric:
            owners.setdefault(round(float(np.mod(360.0 - a, 360.0)), 9), k)
    angles = np.array(sorted(owners))
    w = _periodic_weights(np.radians(angles))
    row_w = np.zeros(az.size)
    for angle, weight in zip(angles, w):
        row_w[owners[float(angle)]] += weight
    return row_w


def _segment_rho_moment(r0: NDArray, r1: NDArray, f0: NDArray, f1: NDArray) -> NDArray:
    """∫_{r0}^{r1} f ρ dρ for f linear from f0 to f1: (r1 − r0)/6 · [f0(2r0 + r1) + f1(r0 + 2r1)]."""
    return (r1 - r0) / 6.0 * (f0 * (2.0 * r0 + r1) + f1 * (r0 + 2.0 * r1))


def tis_harvey_shack_table(
    values: ArrayLike,
    rho: ArrayLike,
    azimuth_deg: ArrayLike,
    theta_i_deg: ArrayLike,
    zero_azimuth_deg: float = 0.0,
) -> NDArray[np.float64]:
    """TIS of Harvey–Shack tables ``values[..., theta_i, rho, psi]`` → ``tis[..., theta_i]``.

    TIS(θi) = Σ_k w_k ∫_0^{min(ρmax(ψ_k), ρ_last)} f_k(ρ) ρ dρ, with f_k the piecewise-linear
    interpolant of row k over the nodes inside the unit disk (ρ_j ≤ ρmax), held constant from the last
    inside node to the edge; ρmax from :func:`rho_max` at sample azimuth ψ_k + ``zero_azimuth_deg``;
    w_k periodic trapezoid weights in ψ (radians). This is ∫∫_{|β|≤1} BSDF dβx dβy of docs/exports.md §3.
    Used by the TracePro and ASAP-style writers and readers.

    Parameters
    ----------
    values : array_like
        BSDF [1/sr], last three axes (theta_i, rho, psi).
    rho : array_like
        Radial nodes ρ in direction cosines [-], increasing.
    azimuth_deg : array_like
        Table-frame azimuths [deg].
    theta_i_deg : array_like
        Incidence angles [deg].
    zero_azimuth_deg : float
        Sample-frame azimuth of the table's 0 azimuth [deg].

    Returns
    -------
    ndarray
        TIS [-], shape ``values.shape[:-2]``.
    """
    f = np.asarray(values, dtype=np.float64)
    rho = np.asarray(rho, dtype=np.float64)
    az = np.asarray(azimuth_deg, dtype=np.float64)
    thetas = np.atleast_1d(np.asarray(theta_i_deg, dtype=np.float64))
    if f.shape[-3:] != (thetas.size, rho.size, az.size):
        raise ValidationError("table shape does not match its axes", field="values",
                              expected=str((thetas.size, rho.size, az.size)), got=str(f.shape[-3:]))
    weights = _azimuth_row_weights(az, plane_symmetric=False)
    rmax = rho_max(thetas[:, None], az[None, :] + zero_azimuth_deg)  # (theta, psi)
    rmax = np.minimum(rmax, rho[-1])
    fr = np.moveaxis(f, -1, -2)  # (..., theta, psi, rho)
    r0, r1 = rho[:-1], rho[1:]
    full = r1[None, None, :] <= rmax[..., None]  # (theta, psi, seg): segment wholly inside
    part = (r0[None, None, :] < rmax[..., None]) & ~full  # segment cut by the edge
    seg_full = _segment_rho_moment(r0, r1, fr[..., :-1], fr[..., 1:])
    seg_part = fr[..., :-1] * 0.5 * (rmax[..., None] ** 2 - r0**2)
    row = np.sum(np.where(full, seg_full, 0.0) + np.where(part, seg_part, 0.0), axis=-1)
    return np.sum(row * weights, axis=-1)


_GL_NODES, _GL_WEIGHTS = gauss_legendre(8)


def tis_specular_table(
    values: ArrayLike,
    radial_deg: ArrayLike,
    azimuth_deg: ArrayLike,
    theta_i_deg: ArrayLike,
    plane_symmetric: bool,
) -> NDArray[np.float64]:
    """TIS of specular-centred tables ``values[..., theta_i, azimuth, radial]`` → ``tis[..., theta_i]``.

    With ω_z(r, a) = cos r cos θ0 + sin r cos a sin θ0 (the cosine of the scatter angle at radial r,
    azimuth a about a specular direction at θ0) and the horizon r_h(a) = atan2(cos θ0, −cos a sin θ0):

        TIS(θ0) = Σ_k w_k ∫_0^{min(r_h(a_k), r_last)} f_k(r) ω_z(r, a_k) sin r dr

    f_k is the piecewise-linear interpolant of row k in r over the nodes above the horizon, held constant
    from the last such node to the horizon; each segment is integrated with 8-point Gauss–Legendre
    (exact to rounding for this smooth weight); w_k are periodic trapezoid weights in azimuth, plane
    symmetric rows counting for a and 360° − a. Beyond the last radial node the table says nothing and
    contributes nothing. Used by the Zemax writer (TIS line) and reader.

    Parameters
    ----------
    values : array_like
        BSDF [1/sr], last three axes (theta_i, azimuth, radial).
    radial_deg : array_like
        Radial angles from the specular direction [deg], increasing.
    azimuth_deg : array_like
        Azimuths about the specular direction [deg].
    theta_i_deg : array_like
        Specular angles θ0 [deg].
    plane_symmetric : bool
        Rows stand for a and 360° − a (PlaneSymmetrical tables).

    Returns
    -------
    ndarray
        TIS [-], shape ``values.shape[:-2]``.
    """
    f = np.asarray(values, dtype=np.float64)
    r = np.radians(np.asarray(radial_deg, dtype=np.float64))
    az_deg = np.asarray(azimuth_deg, dtype=np.float64)
    theta_deg = np.atleast_1d(np.asarray(theta_i_deg, dtype=np.float64))
    thetas = np.radians(theta_deg)
    if f.shape[-3:] != (thetas.size, az_deg.size, r.size):
        raise ValidationError("table shape does not match its axes", field="values",
                              expected=str((thetas.size, az_deg.size, r.size)), got=str(f.shape[-3:]))
    weights = _azimuth_row_weights(az_deg, plane_symmetric)
    a = np.radians(az_deg)
    ct, st = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    horizon = horizon_radial(theta_deg[:, None], az_deg[None, :])  # (theta, az)
    if r.size == 1:
        return np.zeros(f.shape[:-2])
    r0, r1 = r[:-1], r[1:]
    end = np.minimum(horizon, r[-1])[..., None]  # (theta, az, 1)
    full = r1 <= end  # (theta, az, seg)
    part = (r0 < end) & ~full
    lo = np.broadcast_to(r0, full.shape)
    hi = np.where(full, r1, np.where(part, end, r0))
    half = 0.5 * (hi - lo)
    t = 0.5 * (hi + lo)[..., None] + half[..., None] * _GL_NODES  # (theta, az, seg, m)
    cos_a = np.cos(a)[None, :, None, None]
    wz = np.cos(t) * ct[..., None, None] + np.sin(t) * cos_a * st[..., None, None]
    kernel = np.maximum(wz, 0.0) * np.sin(t) * half[..., None] * _GL_WEIGHTS  # (theta, az, seg, m)
    frac = (t - r0[:, None]) / (r1 - r0)[:, None]
    f0, f1 = f[..., :-1][..., None], f[..., 1:][..., None]  # (..., theta, az, seg, 1)
    f_lin = np.where(full[..., None], f0 + (f1 - f0) * frac, f0)
    row = np.sum(f_lin * kernel, axis=(-1, -2))  # (..., theta, az)
    return np.sum(row * weights, axis=-1)


# --------------------------------------------------------------------------------------------------
# reference integrals
# --------------------------------------------------------------------------------------------------
def tis_reference(
    bsdf_fn: BsdfFn,
    theta_i_deg: float,
    side: str,
    *,
    n_azimuth: int = 256,
    n_panels: int = 36,
    t_min: float = 1e-7,
) -> float:
    """∫∫_{|β|≤1} BSDF dβx dβy of a callable, accurate for sharply peaked lobes (docs/exports.md §3).

    Polar coordinates centred on β0: for each of ``n_azimuth`` uniform ψ (periodic trapezoid) the
    radius runs from 0 to the edge ρmax(ψ); with ρ = ρmax·e^s the row integral ∫ f ρ dρ = ∫ f ρ² ds is
    done with ``n_panels`` 8-point Gauss–Legendre panels over s ∈ [ln t_min, 0] plus a Gauss–Legendre
    panel in ρ over [0, t_min·ρmax]. This resolves lobes from the specular point to the disk edge
    without knowing where they are. It is the reference against which table TIS are checked. A piecewise-constant
    source that knows its own value (:class:`PiecewiseConstant` ``exact_tis``) gives that value.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : float
        Incidence angle [deg].
    side : str
        ``reflection`` or ``transmission``.
    n_azimuth : int
        Number of azimuths ψ.
    n_panels : int
        Number of Gauss–Legendre panels in s = ln(ρ/ρmax).
    t_min : float
        Smallest ρ/ρmax of the logarithmic panels [-].

    Returns
    -------
    float
        TIS [-].
    """
    side = _check_sides((side,))[0]
    if isinstance(bsdf_fn, PiecewiseConstant) and bsdf_fn.exact_tis is not None:
        # the basis sum is exact; a quadrature across a patch's steps is not (-4.5 % on a direct-transmission patch)
        return float(bsdf_fn.exact_tis(float(theta_i_deg), side))
    psi = (np.arange(n_azimuth) + 0.5) * (2.0 * np.pi / n_azimuth)
    rmax = rho_max(theta_i_deg, np.degrees(psi))  # (psi,)
    edges = np.linspace(np.log(t_min), 0.0, n_panels + 1)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * (edges[1:] - edges[:-1])
    s = (mid[:, None] + half[:, None] * _GL_NODES).ravel()
    ws = (half[:, None] * _GL_WEIGHTS).ravel()
    rho_log = rmax[:, None] * np.exp(s)[None, :]  # (psi, n)
    w_log = rho_log**2 * ws
    rho_in = rmax[:, None] * t_min * 0.5 * (1.0 + _GL_NODES)[None, :]
    w_in = rho_in * (rmax[:, None] * t_min * 0.5) * _GL_WEIGHTS
    rho_all = np.concatenate([rho_in, rho_log], axis=1)
    w_all = np.concatenate([w_in, w_log], axis=1)
    b0 = frames.beta0(np.radians(theta_i_deg))
    beta = b0 + rho_all[..., None] * np.stack([np.cos(psi), np.sin(psi)], axis=-1)[:, None, :]
    norm = np.hypot(beta[..., 0], beta[..., 1])
    beta = np.where((norm > 1.0)[..., None], beta / np.maximum(norm, 1.0)[..., None], beta)
    values = evaluate_bsdf(bsdf_fn, theta_i_deg, side, frames.direction_from_beta(beta))
    total = float(np.sum(values * w_all) * (2.0 * np.pi / n_azimuth))
    if not np.isfinite(total):
        raise NumericalError(f"TIS of the BSDF callable is not finite at theta_i={theta_i_deg:g} deg")
    return total


# --------------------------------------------------------------------------------------------------
# tolerance-driven ("auto") axes
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GridTolerance:
    """What an automatic (tolerance-driven) table grid must reproduce of its BSDF callable.

    ``tis_rtol`` [1]: largest relative change of every block's table TIS (the format's own quadrature, per
    side and incidence) when every radial segment is bisected, and again when the azimuth step is halved;
    i.e. the estimated TIS error of the written grid (default 1e-3 = 0.1 %).
    ``peak_rtol`` [1]: largest miss of the piecewise-linear table (in the radial and in the azimuthal
    direction) at the midpoints of its cells, relative to the block's peak (the lobe maximum, at or near
    the specular direction); this holds the lobe's peak and shape (default 1e-2 = 1 %).
    ``max_rounds``: refinement rounds at most (each bisects flagged radial segments and/or doubles the azimuths).
    ``max_azimuths``: cap on the number of azimuth nodes over the full circle (default 360, a 1° step).
    """

    tis_rtol: float = 1e-3
    peak_rtol: float = 1e-2
    max_rounds: int = 16
    max_azimuths: int = 360

    def __post_init__(self) -> None:
        for name in ("tis_rtol", "peak_rtol"):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0.0 < v < 1.0):
                raise ValidationError("grid tolerance out of range", field=name,
                                      expected="a relative tolerance in (0, 1)", got=v)
        if not (1 <= int(self.max_rounds) <= 64):
            raise ValidationError("refinement rounds out of range", field="max_rounds", expected="1..64",
                                  got=self.max_rounds)
        if not (8 <= int(self.max_azimuths) <= 4096):
            raise ValidationError("azimuth cap out of range", field="max_azimuths", expected="8..4096",
                                  got=self.max_azimuths)


#: Azimuths over the full circle an auto grid starts from (15°): the hemispherical engine that re-reads a file
#: (``bsdfkit read``) integrates a table on its own spokes from 24 spokes on
#: (:data:`bsdfkit.reduction.hemispherical.MIN_SPOKES`); with fewer it reconstructs the nodes as scattered records,
#: which misses narrow lobes. An even count also keeps the Harvey–Shack rule exact for a Lambertian table.
MIN_AZIMUTHS = 24


def _tidy(values: NDArray[np.float64]) -> tuple[float, ...]:
    """Nodes rounded to 9 significant digits (the files print 10): what is evaluated is what is written."""
    return tuple(float(f"{v:.9g}") for v in values)


#: Share of a block's estimated TIS error that one refinement round marks (:func:`bulk_marking`)
BULK_SHARE = 0.5
#: Indicators within this relative difference of the last marked one are marked with it (:func:`bulk_marking`)
TIE_RTOL = 1e-6


def bulk_marking(indicators: ArrayLike, share: float = BULK_SHARE) -> NDArray[np.bool_]:
    """Intervals to refine so that each block's refinement addresses ``share`` of its estimated error.

    Parameters
    ----------
    indicators
        ``[block, interval]`` [1]: each interval's share of a block's TIS error (relative to the block's TIS),
        for the blocks that miss their tolerance.
    share
        Fraction of each block's summed indicators the marked intervals must hold.

    Returns
    -------
    numpy.ndarray
        ``[interval]`` bool: the union over blocks of the fewest intervals, largest indicator first, whose
        indicators add up to ``share`` of the block's sum (Dörfler's bulk criterion of adaptive quadrature and
        finite elements), and the intervals tied with the last of them (within :data:`TIE_RTOL`). Refining where
        the error is, block by block, rather than every interval above an average share: a grid shared by many
        incidences grows only where one of them needs it.
    """
    ind = np.atleast_2d(np.asarray(indicators, dtype=np.float64))
    flag = np.zeros(ind.shape[-1], dtype=bool)
    for row in ind.reshape(-1, ind.shape[-1]):
        total = float(np.sum(row))
        if not total > 0.0:
            continue
        order = np.argsort(-row, kind="stable")
        count = int(np.searchsorted(np.cumsum(row[order]), share * total)) + 1
        cut = row[order[min(count, row.size) - 1]]
        # ties with the last marked interval are marked too (to rounding): a source symmetric about the plane of
        # incidence keeps symmetric axes
        flag |= row >= cut * (1.0 - TIE_RTOL)
    return flag


#: Share of an auto grid's TIS tolerance that printing its values may take (:func:`value_digits`)
PRINT_SHARE = 0.01


def value_digits(tis_rtol: float, most: int = 7) -> int:
    """Significant digits a table's values need so that printing them moves no TIS by more than
    :data:`PRINT_SHARE` × ``tis_rtol``.

    Rounding to d significant digits moves each value by at most 0.5·10^(1−d) of itself, so a TIS (a positive
    weighted sum of the values) by at most as much: d is the smallest with 0.5·10^(1−d) ≤ PRINT_SHARE × tis_rtol
    (0.005, ``convert``'s default: 5 digits, at most 5e-5; 0.001, ``export``'s: 6 digits), and at most ``most``
    (the writer's own format).

    Parameters
    ----------
    tis_rtol : float
        The grid's TIS tolerance [1].
    most : int
        Digits of the writer's format.

    Returns
    -------
    int
        Significant digits.
    """
    need = int(np.ceil(1.0 - np.log10(2.0 * PRINT_SHARE * float(tis_rtol)) - 1e-12))
    return max(1, min(int(most), need))


#: format spec of the angles every text table writer prints (``format(v, ANGLE_FORMAT)``): ten significant digits,
#: within 5e-9 degree of the computed angle below 100 degrees
ANGLE_FORMAT = ".10g"


def quantize(values: ArrayLike, fmt: str) -> NDArray[np.float64]:
    """``values`` as a table writes them with the format spec ``fmt`` and reads them back (float64, same shape):
    the writers' TIS and checks are computed from what the file holds.

    Parameters
    ----------
    values : array_like
        Values as computed (a BSDF [1/sr] or any other table entry).
    fmt : str
        Format spec of the writer (as in ``format(v, fmt)``).

    Returns
    -------
    ndarray
        The values as read back from their text, same shape and unit.
    """
    flat = np.asarray(values, dtype=np.float64).ravel()
    return np.array([format(v, fmt) for v in flat], dtype=np.float64).reshape(np.shape(values))


def azimuth_midpoints_deg(azimuth_deg: ArrayLike, periodic: bool = True) -> NDArray[np.float64]:
    """Midpoints [deg] of consecutive azimuths ``azimuth_deg`` [deg] (increasing from 0); ``periodic``: the last one
    between the last azimuth and 360° (full circle), else only between neighbours (a half plane, 0…180°).

    Parameters
    ----------
    azimuth_deg : array_like
        Azimuths [deg], increasing from 0.
    periodic : bool
        Add the midpoint between the last azimuth and 360°.

    Returns
    -------
    ndarray
        Midpoints [deg].
    """
    a = np.asarray(azimuth_deg, dtype=np.float64)
    inner = 0.5 * (a[:-1] + a[1:])
    return np.append(inner, 0.5 * (a[-1] + 360.0)) if periodic else inner


class _PolarProblem(NamedTuple):
    """The polar table :func:`_refine_polar` chooses nodes for (both geometries).

    ``evaluate(r, a)`` → (values[side, theta, a, r], inside[theta, a, r]); ``quad(values, r, a)`` → TIS
    [side, theta] with the format's quadrature; ``measure(r)`` the radial area weight (ρ or sin r);
    ``azimuth_midpoints(a)`` the azimuths between the nodes; ``finish(values, r, a)``, if given, turns the point
    samples of a candidate grid into the values the table would hold (edge values:
    :func:`harvey_shack_edge_values`)."""

    evaluate: Callable[[NDArray, NDArray], tuple[NDArray, NDArray]]
    quad: Callable[[NDArray, NDArray, NDArray], NDArray]
    measure: Callable[[NDArray], NDArray]
    azimuth_midpoints: Callable[[NDArray], NDArray]
    finish: Callable[[NDArray, NDArray, NDArray], NDArray] | None = None

    def done(self, values: NDArray, r: NDArray, a: NDArray) -> NDArray:
        """The values the table would hold at these nodes."""
        return values if self.finish is None else self.finish(values, r, a)


class _RefineLimits(NamedTuple):
    """Limits of :func:`_refine_polar`: the finest radial step, the most azimuths, the most radial × azimuth nodes
    (None: no limit) and whether the TIS criteria apply (not for cell averages)."""

    min_step: float
    azimuth_cap: int
    max_nodes: int | None = None
    tis_criteria: bool = True


class _RadialCheck(NamedTuple):
    """One round's samples on the current grid and at its radial midpoints, and what they say."""

    f: NDArray  # values at the nodes (side, theta, a, r)
    inside: NDArray
    f_done: NDArray  # the coarse table as written (its own edge values)
    tis_coarse: NDArray
    norm: NDArray
    core: NDArray
    limit: NDArray  # the lobe's peak per (side, theta) with the peak tolerance
    mid_r: NDArray
    err_r: NDArray  # relative TIS change of bisecting every radial segment, per block
    ind_block: NDArray  # each segment's share of that change (side, theta, seg)
    peak_r: NDArray  # (seg,): a higher peak in the segment


class _AzimuthCheck(NamedTuple):
    """One round's samples at the azimuth midpoints and what they say."""

    mid_a: NDArray
    f_a: NDArray
    in_a: NDArray
    f_a_done: NDArray
    err_a: NDArray  # relative TIS change of halving the azimuth step, per block
    core_a: NDArray


def _radial_check(problem: _PolarProblem, radial: NDArray, azimuth: NDArray, tolerance: GridTolerance
                  ) -> _RadialCheck:
    """The grid's values, its TIS and the TIS and peak misses of bisecting every radial segment."""
    mid_r = 0.5 * (radial[:-1] + radial[1:])
    both_r = np.sort(np.concatenate([radial, mid_r]))
    f_both, in_both = problem.evaluate(both_r, azimuth)
    f, inside = f_both[..., ::2], in_both[..., ::2]
    f_mid, in_mid = f_both[..., 1::2], in_both[..., 1::2]
    core = _lobe_core(f, inside)
    top = np.max(np.where(core, f, 0.0), axis=(-1, -2))[..., None, None]  # the lobe's peak per (side, theta)
    limit = (1.0 + tolerance.peak_rtol) * top
    f_done = problem.done(f, radial, azimuth)
    tis_fine = problem.quad(problem.done(f_both, both_r, azimuth), both_r, azimuth)
    tis_coarse = problem.quad(f_done, radial, azimuth)
    norm = np.where(np.abs(tis_fine) > 0, np.abs(tis_fine), 1.0)
    err_r = np.abs(tis_fine - tis_coarse) / norm
    # the coarse table at the radial midpoints, as the quadratures interpolate it (held at the edge)
    lin = np.where(inside[..., 1:], 0.5 * (f[..., :-1] + f[..., 1:]), f[..., :-1])
    miss = np.where(in_mid & inside[..., :-1], np.abs(f_mid - lin), 0.0)  # (side, theta, a, seg)
    w_az = _azimuth_row_weights_for(azimuth, problem.quad)
    ind_block = (np.einsum("ptak,a->ptk", miss, w_az) * (problem.measure(mid_r) * 0.5 * np.diff(radial))
                 / norm[..., None])
    in_core = core[..., :-1] & core[..., 1:]
    peak_r = np.any(in_core & in_mid & (f_mid > limit), axis=(0, 1, 2))
    return _RadialCheck(f, inside, f_done, tis_coarse, norm, core, limit, mid_r, err_r, ind_block, peak_r)


def _azimuth_check(problem: _PolarProblem, radial: NDArray, azimuth: NDArray, rc: _RadialCheck) -> _AzimuthCheck:
    """The TIS change and the peaks of halving the azimuth step."""
    mid_a = problem.azimuth_midpoints(azimuth)
    f_a, in_a = problem.evaluate(radial, mid_a)
    both_a = np.sort(np.concatenate([azimuth, mid_a]))
    order = np.argsort(np.concatenate([azimuth, mid_a]), kind="stable")
    f_a_done = problem.done(f_a, radial, mid_a)
    tis_a = problem.quad(np.concatenate([rc.f_done, f_a_done], axis=-2)[..., order, :], radial, both_a)
    err_a = np.abs(tis_a - rc.tis_coarse) / rc.norm
    core_a = rc.core[..., : mid_a.size, :] & np.roll(rc.core, -1, axis=-2)[..., : mid_a.size, :]
    return _AzimuthCheck(mid_a, f_a, in_a, f_a_done, err_a, core_a)


def _bisected_radial(radial: NDArray, rc: _RadialCheck, fix_r: NDArray, min_step: float) -> NDArray:
    """The radial nodes with the segments that hide a higher peak or carry the TIS error bisected."""
    long_enough = np.diff(radial) >= 2.0 * min_step
    flag = rc.peak_r.copy()
    if np.any(fix_r):  # the segments that carry the error of the blocks that miss the tolerance
        flag |= bulk_marking(np.where(long_enough, rc.ind_block[fix_r], 0.0))
    flag &= long_enough
    if np.any(flag):
        radial = np.sort(np.concatenate([radial, rc.mid_r[flag]]))
    return radial


def _bisected_azimuth(problem: _PolarProblem, radial: NDArray, azimuth: NDArray, checks: tuple, fix_a: NDArray,
                      cap: int) -> NDArray:
    """The azimuths with the intervals that carry more than their share of the TIS change or hide a higher peak
    bisected, the worst first up to ``cap``; ``checks`` the round's (radial, azimuth) checks."""
    rc, ac = checks
    mid_a = ac.mid_a
    # interval k adds (Δ_k/2)·[I(f_mid) − (I(f_k) + I(f_k+1))/2] (trapezoid rule, I = row integral)
    rows = np.stack([problem.quad(rc.f_done[..., k:k + 1, :], radial, azimuth[k:k + 1])
                     for k in range(azimuth.size)], -1)
    rows_mid = np.stack([problem.quad(ac.f_a_done[..., k:k + 1, :], radial, mid_a[k:k + 1])
                         for k in range(mid_a.size)], -1)
    width = np.radians(np.diff(np.append(azimuth, azimuth[0] + 360.0)))[: mid_a.size]
    change = (width / 2.0) * np.abs(rows_mid - 0.5 * (rows[..., : mid_a.size]
                                                      + np.roll(rows, -1, axis=-1)[..., : mid_a.size]))
    change_block = change / (2.0 * np.pi) / rc.norm[..., None]  # (side, theta, interval)
    change = np.max(change_block, axis=(0, 1))  # (interval,)
    flag_a = np.any(ac.core_a & ac.in_a & (ac.f_a > rc.limit), axis=(0, 1, 3))
    if np.any(fix_a):
        flag_a |= bulk_marking(change_block[fix_a])
    room = cap - azimuth.size
    if np.count_nonzero(flag_a) > room:  # the cap: the worst intervals first
        flag_a &= change >= np.sort(change)[-room]
    return np.sort(np.concatenate([azimuth, mid_a[flag_a]]))


def _refine_polar(problem: _PolarProblem, radial: NDArray[np.float64], azimuth: NDArray[np.float64],
                  tolerance: GridTolerance, limits: _RefineLimits
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Coarse-to-fine choice of a polar table's radial and azimuth nodes (shared by both geometries).

    Each round evaluates ``problem`` (:class:`_PolarProblem`) at the radial midpoints and at the azimuth midpoints
    of the current grid. It stops when (i) bisecting every radial segment changes no block's TIS by more than
    ``tis_rtol``/2, (ii) halving the azimuth step changes none by more than ``tis_rtol``/2, and (iii) the
    linear table misses the callable at no midpoint by more than ``peak_rtol`` × the block's peak.
    Otherwise it bisects the radial segments that miss (iii) and, in each block that misses (i), the segments that
    carry half its estimated TIS error (:func:`bulk_marking` of Σ_a w_a |f_mid − f_lin| · measure(r_mid) · Δr/2,
    the quadrature of the miss), and likewise the azimuth intervals when (ii) or (iii) fails in azimuth.
    Deterministic; no node finer than ``limits.min_step``. With ``problem.finish`` the TIS criteria compare
    finished tables, each grid finished on its own axes.
    Returns None as soon as the grid would hold more than ``limits.max_nodes`` radial × azimuth nodes.
    ``limits.tis_criteria=False`` drops (i) and (ii): a table of cell averages (:func:`harvey_shack_cell_grid`)
    integrates to the callable's TIS on any axes, so its grid is as fine as the lobe's shape (iii) needs.
    """
    half = 0.5 * tolerance.tis_rtol if limits.tis_criteria else np.inf
    for _ in range(int(tolerance.max_rounds)):
        rc = _radial_check(problem, radial, azimuth, tolerance)
        ac = _azimuth_check(problem, radial, azimuth, rc)
        peak_a = bool(np.any(ac.core_a & ac.in_a & (ac.f_a > rc.limit)))
        fix_r, fix_a = rc.err_r > half, ac.err_a > half  # the blocks whose TIS changes by more than tis_rtol/2
        radial_ok = not np.any(rc.peak_r) and not np.any(fix_r)
        azimuth_ok = not peak_a and not np.any(fix_a)
        if radial_ok and azimuth_ok:
            break
        before, radial_now = (radial.size, azimuth.size), radial
        if not radial_ok:
            radial = _bisected_radial(radial, rc, fix_r, limits.min_step)
        if not azimuth_ok and azimuth.size < limits.azimuth_cap:
            azimuth = _bisected_azimuth(problem, radial_now, azimuth, (rc, ac), fix_a, limits.azimuth_cap)
        if (radial.size, azimuth.size) == before:  # nothing left to refine (step floor, azimuth cap)
            break
        if limits.max_nodes is not None and radial.size * azimuth.size > limits.max_nodes:
            return None
    return radial, azimuth


#: Share of ``tis_rtol`` that removing radial nodes after the refinement may move any block's TIS
#: (:func:`_coarsened_radial`)
COARSEN_TIS_SHARE = 0.25
#: Share of ``peak_rtol`` by which removing radial nodes may lower a block's peak of the lobe
#: (:func:`_coarsened_radial`)
COARSEN_PEAK_SHARE = 0.5


def _coarsened_radial(problem: _PolarProblem, radial: NDArray[np.float64], azimuth: NDArray[np.float64],
                      tolerance: GridTolerance) -> NDArray[np.float64]:
    """The refined radial nodes without those the table does not need (coarsening after refinement).

    Bisection only adds nodes: the starting nodes a narrow lobe would need (ρ = 1e-3·2^k) and the intermediate
    nodes of a chase toward a kink or of an edge strip stay although the final grid no longer needs them; on a ρ
    list shared by every azimuth and incidence each costs a full ring of rows. Interior nodes are removed one at a
    time (the smallest TIS change first) while (i) no block's TIS (the format's quadrature of the finished table,
    each candidate with its own edge values) moves by more than :data:`COARSEN_TIS_SHARE` × ``tis_rtol`` from the
    refined table's, (ii) the peak of the lobe of no block falls by more than :data:`COARSEN_PEAK_SHARE` ×
    ``peak_rtol`` and (iii) no midpoint of the kept segments in the lobe's core holds more than (1 + ``peak_rtol``)
    × the kept table's peak (the refinement's own peak criterion). The peak is taken as the export's check of the
    written file takes it: over :func:`lobe_core` of the finished values, without a row's last node inside the
    domain when it holds a finished (edge) value. Every row keeps a node inside the domain beyond the specular one:
    the engine behind ``bsdfkit read`` needs records along every spoke (a constant source left with the specular
    node alone was read as scattered records and failed its re-check).
    """
    f, inside = problem.evaluate(radial, azimuth)
    floor_inside = np.minimum(np.sum(inside, axis=-1), 2)  # every row keeps a node inside beyond the specular one

    def peak(keep: NDArray[np.bool_], finished: NDArray) -> tuple[NDArray, NDArray]:
        """The lobe's core of the finished table on the kept nodes and its peak per block."""
        ins = inside[..., keep]
        core = _lobe_core(finished, ins)
        if problem.finish is not None:  # a row's last node inside holds its edge value, no sample of the source
            core &= ~(ins & (np.cumsum(ins, axis=-1) == np.sum(ins, axis=-1, keepdims=True)))
        return core, np.max(np.where(core, finished, 0.0), axis=(-1, -2))

    every = np.ones(radial.size, dtype=bool)
    done = problem.done(f, radial, azimuth)
    base = problem.quad(done, radial, azimuth)
    norm = np.where(np.abs(base) > 0, np.abs(base), 1.0)
    floor = (1.0 - COARSEN_PEAK_SHARE * tolerance.peak_rtol) * peak(every, done)[1]
    budget = COARSEN_TIS_SHARE * tolerance.tis_rtol

    def change_of(keep: NDArray[np.bool_], finished: NDArray) -> float:
        return float(np.max(np.abs(problem.quad(finished, radial[keep], azimuth) - base) / norm))

    def acceptable(keep: NDArray[np.bool_]) -> bool:
        r = radial[keep]
        if np.any(np.sum(inside[..., keep], axis=-1) < floor_inside):
            return False
        finished = problem.done(f[..., keep], r, azimuth)
        core, top = peak(keep, finished)
        if not np.all(top >= floor) or change_of(keep, finished) > budget:
            return False
        f_mid, in_mid = problem.evaluate(0.5 * (r[:-1] + r[1:]), azimuth)
        limit = (1.0 + tolerance.peak_rtol) * top[..., None, None]
        return not bool(np.any(core[..., :-1] & core[..., 1:] & in_mid & (f_mid > limit)))

    candidates = np.arange(1, radial.size - 1)
    alone = []  # each node's TIS change alone, the finished values of the others as they are (an ordering only)
    for j in candidates:
        k = every.copy()
        k[j] = False
        alone.append(change_of(k, done[..., k]))
    order = [int(j) for j in candidates[np.argsort(alone, kind="stable")]]
    keep = every
    while order:
        # each candidate is tried once, in order, in batches at least 3 kept nodes apart: the source is evaluated for
        # a batch at once (the edge strips and merged midpoints its removals need; a call costs the same for 1 or
        # 1000 directions), and each removal is then tried on its own
        position = np.cumsum(keep) - 1
        batch: list[int] = []
        for j in order:
            if all(abs(position[j] - position[b]) >= 3 for b in batch):
                batch.append(j)
        order = [j for j in order if j not in batch]
        k = keep.copy()
        k[batch] = False
        problem.done(f[..., k], radial[k], azimuth)
        kept = np.flatnonzero(keep)
        ends = [(kept[position[j] - 1], kept[position[j] + 1]) for j in batch]
        problem.evaluate(np.array([0.5 * (radial[a] + radial[b]) for a, b in ends]), azimuth)
        for j in batch:
            k = keep.copy()
            k[j] = False
            if acceptable(k):
                keep = k
    return radial[keep]


def lobe_core(values: ArrayLike, inside: ArrayLike) -> NDArray[np.bool_]:
    """Nodes of a polar table ``values[..., azimuth, radial]`` (radial node 0 = the specular direction) in the
    core of the lobe: along each azimuth row, from the specular node outward up to the first node (exclusive)
    where the BSDF falls below half its specular value or leaves the domain (``inside``). The *peak of the lobe*
    is the largest BSDF there (docs/exports.md, "Grid resolution").

    Parameters
    ----------
    values : array_like
        BSDF [1/sr] of a polar table, last two axes (azimuth, radial).
    inside : array_like
        Whether each node lies in the domain (broadcast against ``values``).

    Returns
    -------
    ndarray of bool
        True for nodes in the lobe's core, shape of ``values``.
    """
    f = np.asarray(values, dtype=np.float64)
    half_spec = 0.5 * f[..., :1]
    keep = (f >= half_spec) & np.asarray(inside, dtype=bool)
    return np.cumprod(keep, axis=-1).astype(bool)


_lobe_core = lobe_core


def _azimuth_row_weights_for(azimuth: NDArray, quad: Callable) -> NDArray:
    return _azimuth_row_weights(azimuth, plane_symmetric=bool(getattr(quad, "plane_symmetric", False)))


def _coarse_radial(first: float, last: float, max_step: float) -> NDArray[np.float64]:
    """0, then first·2^k while the step stays below ``max_step``, then even steps ≤ ``max_step`` to ``last``."""
    return _geometric_then_linear(first, 2.0, max_step, last)


def _coarse_radial_round(first: float, last: float, max_step: float) -> NDArray[np.float64]:
    """0, then first·2^k below ``max_step``, then the multiples of ``max_step`` up to ``last`` (when ``last`` is
    one; else :func:`_coarse_radial`). Round nodes, and their bisections, print in few digits: a Harvey–Shack
    table (TracePro, ASAP-style) repeats its radial node on every row, so its length is part of the file's size."""
    nodes = [0.0, first]
    while nodes[-1] * 2.0 < max_step:
        nodes.append(nodes[-1] * 2.0)
    count = last / max_step
    if abs(count - round(count)) > 1e-9 or nodes[-1] >= last:
        return _coarse_radial(first, last, max_step)
    return np.concatenate([nodes, max_step * np.arange(1, int(round(count)) + 1)])


class _NodeValues:
    """The BSDF at Harvey–Shack nodes (ρ, ψ) as :func:`harvey_shack_grid` samples it (the same directions, 0 beyond
    the disk), each node evaluated once: every round of :func:`_refine_polar` asks again for most of the nodes of
    the round before (the radial nodes and the unsplit segments' midpoints on the old azimuths, the radial nodes on
    the new ones), and a reconstruction's evaluation is the cost of the auto grid."""

    def __init__(self, bsdf_fn: BsdfFn, thetas: NDArray[np.float64], sides: tuple[str, ...], zero: float) -> None:
        self.fn, self.thetas, self.sides, self.zero = bsdf_fn, thetas, sides, zero
        self.memo = _PolarMemo((len(sides), thetas.size))  # f[s, t, ψ, ρ]

    def __call__(self, r: NDArray[np.float64], a: NDArray[np.float64]) -> NDArray[np.float64]:
        """f[side, theta, a, r] [1/sr] on the grid ``r`` × ``a`` (ρ, table azimuths [deg])."""
        at_r, at_a = self.memo.index(r, a)
        # the nodes not yet known, azimuth by azimuth in the order of a, each azimuth's radii in the order of r
        k_a, k_r = np.nonzero(~self.memo.known[at_a[:, None], at_r[None, :]])
        if k_a.size:
            r_p, a_p = r[k_r], a[k_a]
            f_p = np.zeros((len(self.sides), self.thetas.size, r_p.size))
            psi_sample = np.radians(a_p + self.zero)
            unit = np.stack([np.cos(psi_sample), np.sin(psi_sample)], axis=-1)
            for t, theta in enumerate(self.thetas):
                # harvey_shack_grid's directions and inside test, node by node
                inside = r_p <= rho_max(theta, a_p + self.zero)
                beta = frames.beta0(np.radians(theta)) + r_p[:, None] * unit
                directions = frames.direction_from_beta(beta[inside])
                for s, side in enumerate(self.sides):
                    f_p[s, t, inside] = evaluate_bsdf(self.fn, theta, side, directions)
            self.memo.values[..., at_a[k_a], at_r[k_r]] = f_p
            self.memo.known[at_a[k_a], at_r[k_r]] = True
        return self.memo.values[:, :, at_a[:, None], at_r[None, :]]


def auto_harvey_shack_axes(
    bsdf_fn: BsdfFn,
    theta_i_deg: Sequence[float],
    sides: Sequence[str] | str,
    tolerance: GridTolerance | None = None,
    zero_azimuth_deg: float = 0.0,
    max_nodes: int | None = None,
    cell_average: bool = False,
    edge_values: bool = False,
) -> HarveyShackAxes | None:
    """Harvey–Shack axes as fine as ``bsdf_fn`` needs to meet ``tolerance`` (see :class:`GridTolerance`).

    ``cell_average``: the axes of a table of cell averages (:func:`harvey_shack_cell_grid`), whose TIS needs no
    refinement: only the peak criterion of :class:`GridTolerance` refines them (the export's re-check of the
    written file still holds its TIS to ``tis_rtol``). ``edge_values``: the axes of a table whose rows end in
    their edge values (:func:`harvey_shack_edge_values`): every TIS the refinement compares is that of such a
    table (each candidate grid with its own edge values).

    Starts from ρ = 0, 1e-3·2^k (below 0.25), then 0.25, 0.5, … 2, and
    :data:`MIN_AZIMUTHS` uniform azimuths (15°), and refines
    (:func:`_refine_polar`): radial segments are bisected where needed (down to 1e-7 in ρ), the azimuth
    step halved; then the radial nodes the table does not need are removed (:func:`_coarsened_radial`; not for cell
    averages). One pair of axes serves every side and incidence (as TracePro requires). None when meeting
    the tolerance takes more than ``max_nodes`` radial × azimuth nodes.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Incidence angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    tolerance : GridTolerance, optional
        What the grid must reproduce (default: :class:`GridTolerance` defaults).
    zero_azimuth_deg : float
        Sample-frame azimuth of the table's 0 azimuth [deg].
    max_nodes : int, optional
        Largest number of radial × azimuth nodes (default: no limit).
    cell_average : bool
        Axes for a table of cell averages.
    edge_values : bool
        Axes for a table whose rows end in their edge values.

    Returns
    -------
    HarveyShackAxes or None
        The refined axes, or None beyond ``max_nodes``.
    """
    tolerance = tolerance or GridTolerance()
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)

    memo = _NodeValues(bsdf_fn, thetas, sides, zero_azimuth_deg)

    def evaluate(r: NDArray, a: NDArray) -> tuple[NDArray, NDArray]:
        inside = r[None, None, :] <= rho_max(thetas[:, None, None], a[None, :, None] + zero_azimuth_deg)
        return memo(r, a), inside

    def quad(values: NDArray, r: NDArray, a: NDArray) -> NDArray:
        return tis_harvey_shack_table(np.swapaxes(values, -1, -2), r, a, thetas, zero_azimuth_deg)

    strips = _PolarMemo((len(sides), thetas.size), (thetas.size,))  # the edge strips' integrals, for every candidate

    def edges(values: NDArray, r: NDArray, a: NDArray) -> NDArray:
        table = harvey_shack_edge_values(np.swapaxes(values, -1, -2), bsdf_fn, thetas, sides,
                                         HarveyShackAxes(tuple(r), tuple(a), zero_azimuth_deg), strips=strips)
        return np.swapaxes(table, -1, -2)

    problem = _PolarProblem(evaluate, quad, lambda r: r, azimuth_midpoints_deg, edges if edge_values else None)
    chosen = _refine_polar(problem, _coarse_radial_round(1e-3, 2.0, 0.25),
                           np.arange(MIN_AZIMUTHS) * (360.0 / MIN_AZIMUTHS), tolerance,
                           _RefineLimits(1e-7, int(tolerance.max_azimuths), max_nodes, tis_criteria=not cell_average))
    if chosen is None:
        return None
    radial = chosen[0] if cell_average else _coarsened_radial(problem, chosen[0], chosen[1], tolerance)
    return HarveyShackAxes(_tidy(radial), _tidy(chosen[1]), zero_azimuth_deg)


def auto_specular_axes(
    bsdf_fn: BsdfFn,
    theta_i_deg: Sequence[float],
    sides: Sequence[str] | str,
    tolerance: GridTolerance | None = None,
    plane_symmetric: bool = True,
    max_nodes: int | None = None,
) -> SpecularAxes | None:
    """Specular (Zemax) axes as fine as ``bsdf_fn`` needs to meet ``tolerance`` (see :class:`GridTolerance`).

    Starts from radial = 0, 0.05°·2^k (until the step reaches 15°), then steps ≤ 15° to 180°, and azimuths
    0…180° by 15° (plane symmetric) or 0…345° by 15° (:data:`MIN_AZIMUTHS`), and refines (:func:`_refine_polar`): radial
    segments bisected where needed (down to 1e-5°), the azimuth step halved. For a plane-symmetric table
    the callable is evaluated on 0…180° only (the writer averages the mirror images). None when meeting the
    tolerance takes more than ``max_nodes`` radial × azimuth nodes.

    Parameters
    ----------
    bsdf_fn : callable
        ``bsdf_fn(theta_i_deg, side, directions[..., 3])`` → BSDF [1/sr] (:data:`BsdfFn`).
    theta_i_deg : sequence of float
        Specular angles [deg].
    sides : str or sequence of str
        ``reflection`` and/or ``transmission``, without repeats.
    tolerance : GridTolerance, optional
        What the grid must reproduce (default: :class:`GridTolerance` defaults).
    plane_symmetric : bool
        Azimuths 0…180° for a PlaneSymmetrical table (else the full circle).
    max_nodes : int, optional
        Largest number of radial × azimuth nodes (default: no limit).

    Returns
    -------
    SpecularAxes or None
        The refined axes, or None beyond ``max_nodes``.
    """
    tolerance = tolerance or GridTolerance()
    thetas = _check_incidences(theta_i_deg)
    sides = _check_sides(sides)

    def evaluate(r: NDArray, a: NDArray) -> tuple[NDArray, NDArray]:
        grid = specular_grid(bsdf_fn, thetas, sides, SpecularAxes(tuple(r), tuple(a)))
        inside = np.radians(r)[None, None, :] <= horizon_radial(thetas[:, None, None], a[None, :, None])
        return grid.values, inside

    def quad(values: NDArray, r: NDArray, a: NDArray) -> NDArray:
        return tis_specular_table(values, r, a, thetas, plane_symmetric)

    quad.plane_symmetric = plane_symmetric  # type: ignore[attr-defined]

    if plane_symmetric:
        start = np.arange(MIN_AZIMUTHS // 2 + 1) * (360.0 / MIN_AZIMUTHS)
        cap = int(tolerance.max_azimuths) // 2 + 1
    else:
        start = np.arange(MIN_AZIMUTHS) * (360.0 / MIN_AZIMUTHS)
        cap = int(tolerance.max_azimuths)

    problem = _PolarProblem(evaluate, quad, lambda r: np.sin(np.radians(r)) * (np.pi / 180.0),
                            lambda a: azimuth_midpoints_deg(a, periodic=not plane_symmetric))
    chosen = _refine_polar(problem, _coarse_radial(0.05, 180.0, 15.0), start, tolerance,
                           _RefineLimits(1e-5, cap, max_nodes))
    if chosen is None:
        return None
    return SpecularAxes(_tidy(chosen[0]), _tidy(chosen[1]))
