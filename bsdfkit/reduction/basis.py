"""The hemispherical value of a BSDF given in an angle basis (Klems patches, tensor-tree leaves).

A file in a basis holds one BSDF value per cell of the outgoing hemisphere (a Klems patch, a tensor-tree leaf):
the BSDF is constant over each cell. Its directional-hemispherical value is then exactly the sum
ρ = Σ_k f_k Λ_k over the cells, Λ_k the projected solid angle of cell k [sr] (Σ_k Λ_k = π over the hemisphere),
which is what Radiance computes for such a file. The BSDF XML reader (``bsdfkit read``) and the hemispherical
engine (``bsdfkit tis`` on an ingested file, whose records carry the coordinate :data:`COORD`) both call
:func:`basis_sum`, so the two report one number.

Pointwise, such a BSDF is the value of the cell a direction lies in. Ingested records also carry the index of
their cell (coordinate :data:`CELL_COORD`) and the basis as a short text (its attribute ``basis``, written by
:func:`klems_spec` or :func:`shirley_chiu_spec`); :func:`cell_index` finds the cell of any direction exactly, so a
conversion samples the file's own piecewise-constant BSDF (a patch's value never leaks into its neighbour, as a
nearest-record lookup lets a direct-transmission patch of 200/sr do). Cells are found in the projected disk
(β = (sin θ cos φ, sin θ sin φ)):

* Klems bands (``klems``): band b holds sin²θ in [sin²θ_b, sin²θ_b+1), patch j of its n_b the azimuths within
  ±180°/n_b of j·360°/n_b (WINDOW's layout; the cells in file order, band by band);
* the Shirley–Chiu square (``shirley-chiu``) of a tensor tree read on an m × m uniform grid: cell (a, b), row-major,
  covers [a, a + 1)/m × [b, b + 1)/m of the square the concentric map :func:`disk_to_square` sends β to.

A full θs × φs table about the normal (Speos, LightTools: :data:`NORMAL_GRID`) is the other complete representation
a file can hold: its BSDF is the table interpolated linearly in ρ = sin θs and in φs (what ``bsdfkit read``'s engine
and the writers' yardstick both assume), whose integral is Σ_k w_k f_k with w_k the integral of node k's hat
function over the projected disk (:func:`normal_grid_weights`; Σ w_k = π). Ingested records carry w_k as their
``basis_psa``, so the same sum gives the table's own value, and the engine evaluates the table by the same
interpolation instead of reconstructing it.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["CELL_COORD", "COORD", "COVERAGE_RTOL", "NORMAL_GRID", "basis_sum", "cell_index", "covers_hemisphere",
           "cell_directions", "cells_on_normal_grid", "disk_to_square", "grid_directions", "klems_cell_directions",
           "klems_spec", "klems_on_normal_grid", "normal_grid_weights", "shirley_chiu_spec", "square_to_disk"]

#: name of the per-record coordinate [sr]: the projected solid angle of the basis cell (or of the part of it)
#: the record stands for
COORD = "basis_psa"
#: Σ Λ over the records must equal π within this relative tolerance for the basis sum to be the hemispherical value
COVERAGE_RTOL = 1e-6
#: name of the per-record coordinate: the index of the basis cell the record lies in (attribute ``basis``: the
#: basis, :func:`klems_spec` / :func:`shirley_chiu_spec`)
CELL_COORD = "basis_cell"
#: the ``basis`` of the records of a full θs × φs table about the normal (:func:`normal_grid_weights`)
NORMAL_GRID = "normal-grid"


def basis_sum(values: NDArray[np.float64], psa: NDArray[np.float64]) -> NDArray[np.float64]:
    """Σ_k f_k Λ_k [1] over the first axis of ``values`` (cells × ...) [1/sr], ``psa`` (cells,) [sr].

    Parameters
    ----------
    values : ndarray, shape (cells, ...)
        BSDF of each cell [1/sr].
    psa : ndarray, shape (cells,)
        Projected solid angle of each cell [sr].

    Returns
    -------
    ndarray, shape (...)
        Directional-hemispherical value [-].
    """
    return np.asarray(psa, dtype=np.float64) @ np.asarray(values, dtype=np.float64)


def covers_hemisphere(psa: NDArray[np.float64]) -> bool:
    """True when the cells' projected solid angles [sr] are finite, positive and sum to π (the whole hemisphere).

    Parameters
    ----------
    psa : ndarray, shape (cells,)
        Projected solid angle of each cell [sr].

    Returns
    -------
    bool
    """
    p = np.asarray(psa, dtype=np.float64)
    return bool(p.size and np.all(np.isfinite(p)) and np.all(p > 0)
                and abs(float(p.sum()) - np.pi) <= COVERAGE_RTOL * np.pi)


def klems_spec(edges_deg: tuple[float, ...] | list[float], n_phi: tuple[int, ...] | list[int]) -> str:
    """The text naming a Klems-type basis of theta bands (edges [deg], azimuth patches per band).

    Parameters
    ----------
    edges_deg : sequence of float
        Band edges θ [deg], from 0 to 90.
    n_phi : sequence of int
        Azimuth patches of each band.

    Returns
    -------
    str
        ``"klems edges=0,5,...,90 n_phi=1,8,..."``.
    """
    return ("klems edges=" + ",".join(f"{float(e):.12g}" for e in edges_deg)
            + " n_phi=" + ",".join(str(int(n)) for n in n_phi))


def shirley_chiu_spec(m: int) -> str:
    """The text naming the m × m uniform grid of the Shirley–Chiu square.

    Parameters
    ----------
    m : int
        Cells per side.

    Returns
    -------
    str
        ``"shirley-chiu m=M"``.
    """
    return f"shirley-chiu m={int(m)}"


def _parse_spec(spec: str) -> tuple[str, dict[str, list[float]]]:
    kind, *fields = str(spec).split()
    values = {}
    for f in fields:
        key, _, text = f.partition("=")
        values[key] = [float(v) for v in text.split(",") if v]
    if kind == "klems" and {"edges", "n_phi"} <= set(values) and len(values["edges"]) == len(values["n_phi"]) + 1:
        return kind, values
    if kind == "shirley-chiu" and len(values.get("m", ())) == 1 and values["m"][0] >= 1:
        return kind, values
    raise ValueError(f"unknown angle basis {spec!r}")


def cell_index(spec: str, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.int64]:
    """The basis cell each direction (x, y) = β of the projected disk lies in (module docstring).

    Parameters
    ----------
    spec : str
        The basis (:func:`klems_spec`, :func:`shirley_chiu_spec`).
    x, y : ndarray
        Direction cosines [-] (|β| ≤ 1; points just beyond the rim are put on it).

    Returns
    -------
    ndarray of int
        Cell index (file order: Klems patches band by band; the tree grid row-major).

    Raises
    ------
    ValueError
        For a text that names no known basis.
    """
    kind, p = _parse_spec(spec)
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if kind == "shirley-chiu":
        m = int(p["m"][0])
        r = np.hypot(x, y)
        scale = np.where(r > 1.0, 1.0 / np.where(r > 0, r, 1.0), 1.0)
        a, b = disk_to_square(x * scale, y * scale)
        ia = np.clip(np.floor(a * m).astype(np.int64), 0, m - 1)
        ib = np.clip(np.floor(b * m).astype(np.int64), 0, m - 1)
        return ia * m + ib
    edges = np.sin(np.radians(np.asarray(p["edges"]))) ** 2
    n_phi = np.asarray(p["n_phi"], dtype=np.int64)
    first = np.concatenate([[0], np.cumsum(n_phi)[:-1]])
    # sin²θ = |β|², compared without an arcsin (no loss of digits near the edges of the polar cap)
    band = np.clip(np.searchsorted(edges, x * x + y * y, side="right") - 1, 0, n_phi.size - 1)
    n = n_phi[band]
    phi = np.mod(np.degrees(np.arctan2(y, x)), 360.0)
    j = np.mod(np.floor(phi * n / 360.0 + 0.5).astype(np.int64), n)
    return first[band] + j


def square_to_disk(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Shirley–Chiu concentric map of the unit square onto the unit disk (area preserving up to the factor π).

    Parameters
    ----------
    a, b : ndarray
        Points of the unit square [-].

    Returns
    -------
    x, y : ndarray
        Points of the unit disk [-].
    """
    u, v = 2.0 * np.asarray(a, dtype=np.float64) - 1.0, 2.0 * np.asarray(b, dtype=np.float64) - 1.0
    first = np.abs(u) > np.abs(v)  # the wedges about the x axis
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(first, u, v)
        phi = np.where(first, np.pi / 4 * v / u, np.pi / 2 - np.pi / 4 * u / v)
    phi = np.where(r == 0.0, 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def grid_directions(m: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(βx, βy) of the centres of the m × m uniform grid of the Shirley–Chiu square (row-major, the order of
    :func:`cell_index` and of a tensor tree's ``out_grid``); each cell covers the projected solid angle π / m² [sr].

    Parameters
    ----------
    m : int
        Cells per side.

    Returns
    -------
    bx, by : ndarray
        (m·m,) direction cosines [-].
    """
    c = (np.arange(m) + 0.5) / m
    a, b = np.meshgrid(c, c, indexing="ij")
    return square_to_disk(a.ravel(), b.ravel())


def disk_to_square(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`square_to_disk`: unit-disk points to the unit square.

    Parameters
    ----------
    x, y : ndarray
        Points of the unit disk [-].

    Returns
    -------
    a, b : ndarray
        Points of the unit square [-].
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    r = np.hypot(x, y)
    phi = np.arctan2(y, x)
    phi = np.where(phi < -np.pi / 4, phi + 2 * np.pi, phi)  # in [-pi/4, 7pi/4]
    # an angle a rounding below -pi/4 comes back as 7pi/4: it belongs to the +x wedge at t = -1, not at t = 7
    phi = np.where(phi >= 7 * np.pi / 4, phi - 2 * np.pi, phi)
    q = np.floor((phi + np.pi / 4) / (np.pi / 2)).astype(int) % 4  # wedge: +x, +y, -x, -y
    t = (phi - q * np.pi / 2) / (np.pi / 4)  # in [-1, 1) within the wedge
    a = np.select([q == 0, q == 1, q == 2], [r, -t * r, -r], t * r)
    b = np.select([q == 0, q == 1, q == 2], [t * r, r, -t * r], -r)
    return 0.5 * (a + 1.0), 0.5 * (b + 1.0)


def normal_grid_weights(theta_deg: NDArray[np.float64], phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Projected solid angle [sr] of each node's hat function on a full θs × φs table about the normal: linear in
    ρ = sin θs between the θs rows, periodic and linear in φs between the columns, so that Σ w f is the integral of
    the table's piecewise-linear interpolant over the projected disk (Σ w = π when the rows run from 0 to 90°).

    Parameters
    ----------
    theta_deg : ndarray
        The θs rows, increasing from 0 [deg].
    phi_deg : ndarray
        The φs columns over [0, 360), increasing [deg].

    Returns
    -------
    ndarray
        (theta, phi) weights [sr]; the nodes of the row θs = 0 (one direction) share that row's weight equally.
    """
    rho = np.sin(np.radians(np.asarray(theta_deg, dtype=np.float64)))
    a, b = rho[:-1], rho[1:]
    w_rho = np.zeros(rho.size)
    w_rho[:-1] += (b - a) * (b + 2.0 * a) / 6.0  # ∫ ρ hat over the segment above the node (hat falling)
    w_rho[1:] += (b - a) * (2.0 * b + a) / 6.0  # and below it (hat rising)
    phi = np.radians(np.asarray(phi_deg, dtype=np.float64))
    nxt = np.roll(phi, -1) + np.where(np.arange(phi.size) == phi.size - 1, 2.0 * np.pi, 0.0)
    prv = np.roll(phi, 1) - np.where(np.arange(phi.size) == 0, 2.0 * np.pi, 0.0)
    w_phi = 0.5 * (nxt - prv)
    return w_rho[:, None] * w_phi[None, :]


def _klems_layout(spec: str) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    kind, p = _parse_spec(spec)
    if kind != "klems":
        raise ValueError(f"not a Klems basis: {spec!r}")
    return np.asarray(p["edges"], dtype=np.float64), np.asarray(p["n_phi"], dtype=np.int64)


def klems_cell_directions(spec: str) -> NDArray[np.float64]:
    """A direction inside each cell of a Klems-type basis (its centre in sin²θ and azimuth), file order.

    Parameters
    ----------
    spec : str
        The basis (:func:`klems_spec`).

    Returns
    -------
    ndarray
        (cells, 3) unit vectors [-].
    """
    edges, n_phi = _klems_layout(spec)
    s2 = np.sin(np.radians(edges)) ** 2
    r = np.repeat(np.sqrt(0.5 * (s2[:-1] + s2[1:])), n_phi)
    phi = np.radians(np.concatenate([np.arange(n) * 360.0 / n for n in n_phi]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=-1)


def _hat_overlaps(knots: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64], moment: bool
                  ) -> NDArray[np.float64]:
    """(nodes, intervals): ∫ hat_k(x) x^m dx over [lo, hi] ∩ the support of node k's hat on ``knots`` (m = 1 with
    ``moment``, else 0), exact (2-point Gauss–Legendre on each linear piece: the integrand is at most quadratic)."""
    z = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    out = np.zeros((knots.size, lo.size))
    for k in range(knots.size):
        for a, b, up in ((knots[k - 1] if k > 0 else None, knots[k], True),
                         (knots[k], knots[k + 1] if k + 1 < knots.size else None, False)):
            if a is None or b is None or b <= a:
                continue
            left, right = np.maximum(lo, a), np.minimum(hi, b)
            ok = right > left
            mid, half = 0.5 * (left + right), 0.5 * (right - left)
            x = mid[:, None] + half[:, None] * z[None, :]
            hat = (x - a) / (b - a) if up else (b - x) / (b - a)
            out[k] += np.where(ok, half * np.sum(hat * (x if moment else 1.0), axis=1), 0.0)
    return out


def klems_on_normal_grid(spec: str, values: NDArray[np.float64], theta_deg: NDArray[np.float64],
                         phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Exact node means of a Klems-type BSDF on a table about the normal: each node (θs, φs) the mean of the cell
    values over its hat function (linear in ρ = sin θs and in φs, periodic), weighted by the projected solid
    angle ρ dρ dφ. Klems cells are rectangles in (ρ, φs), so each mean is a sum of products of one-dimensional
    overlaps (:func:`_hat_overlaps`): no quadrature across the steps of the cells. With the weights of
    :func:`normal_grid_weights` the table integrates to the basis sum to rounding.

    Parameters
    ----------
    spec : str
        The Klems basis (:func:`klems_spec`).
    values : ndarray
        (cells,) BSDF of each cell [1/sr], file order.
    theta_deg : ndarray
        The table's θs rows, increasing from 0 [deg].
    phi_deg : ndarray
        The table's φs columns, increasing over one turn [deg] (a last column at 360° repeating 0° allowed).

    Returns
    -------
    ndarray
        (phi, theta) node means [1/sr].
    """
    edges, n_phi = _klems_layout(spec)
    phi = np.asarray(phi_deg, dtype=np.float64)
    closing = phi.size > 1 and abs(phi[-1] - phi[0] - 360.0) < 1e-9
    ring = phi[:-1] if closing else phi
    rho_edges = np.sin(np.radians(edges))
    knots = np.sin(np.radians(np.asarray(theta_deg, dtype=np.float64)))
    a_rho = _hat_overlaps(knots, rho_edges[:-1], rho_edges[1:], True)  # (rows, bands)
    # periodic azimuth hats: knots extended by one column each side
    ext = np.concatenate([[ring[-1] - 360.0], ring, [ring[0] + 360.0]])
    out = np.zeros((ring.size, knots.size))
    start = 0
    for b, n in enumerate(n_phi):
        centre = np.arange(n) * 360.0 / n
        lo, hi = centre - 180.0 / n, centre + 180.0 / n
        # the patches and their copies one turn either side, so that every hat meets its patches
        lo3, hi3 = np.concatenate([lo - 360.0, lo, lo + 360.0]), np.concatenate([hi - 360.0, hi, hi + 360.0])
        b_phi = _hat_overlaps(ext, lo3, hi3, False)[1:-1]  # (columns, 3 n)
        v = np.tile(np.asarray(values, dtype=np.float64)[start:start + n], 3)
        out += (b_phi @ v)[:, None] * a_rho[None, :, b]
        start += n
    w_rho = _hat_overlaps(knots, np.array([0.0]), np.array([1.0]), True)[:, 0]
    w_phi = 0.5 * (ext[2:] - ext[:-2])
    mean = np.divide(out, w_phi[:, None] * w_rho[None, :], out=np.zeros_like(out),
                     where=(w_phi[:, None] * w_rho[None, :]) > 0)
    return np.concatenate([mean, mean[:1]], axis=0) if closing else mean


#: sub-points per cell side with which :func:`cells_on_normal_grid` shares a cell among the hats it meets
CELL_SHARE_POINTS = 4


def _square_cells(spec: str) -> int:
    kind, p = _parse_spec(spec)
    if kind != "shirley-chiu":
        raise ValueError(f"not a Shirley-Chiu grid: {spec!r}")
    return int(p["m"][0])


def cell_directions(spec: str) -> NDArray[np.float64]:
    """A direction inside each cell of a basis (Klems: the patch centre; Shirley–Chiu: the cell centre), in the
    order of :func:`cell_index`.

    Parameters
    ----------
    spec : str
        The basis (:func:`klems_spec`, :func:`shirley_chiu_spec`).

    Returns
    -------
    ndarray
        (cells, 3) unit vectors [-].
    """
    if spec.startswith("klems"):
        return klems_cell_directions(spec)
    x, y = grid_directions(_square_cells(spec))
    return np.stack([x, y, np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, None))], axis=-1)


def cells_on_normal_grid(spec: str, values: NDArray[np.float64], theta_deg: NDArray[np.float64],
                         phi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Node means of a BSDF constant over the cells of a Shirley–Chiu grid (a tensor tree) on a table about the
    normal: each cell's power (value × π/m²) is shared among the hats of the table's nodes (linear in sin θs and φs)
    in proportion to the hats' values at :data:`CELL_SHARE_POINTS`² points spread evenly over the cell's area (the
    concentric map preserves area), and each node's share is divided by its hat's projected solid angle
    (:func:`normal_grid_weights`). The hats sum to one everywhere, so the table read as its own interpolant
    integrates to the basis sum exactly, whatever the cells' sizes; a cell's power stays in the nodes around it.

    Parameters
    ----------
    spec : str
        The basis (:func:`shirley_chiu_spec`).
    values : ndarray
        (cells,) BSDF of each cell [1/sr], in the order of :func:`cell_index`.
    theta_deg : ndarray
        The table's θs rows, from 0 to 90, increasing [deg].
    phi_deg : ndarray
        The table's φs columns, increasing over one turn [deg] (a last column at 360° repeating 0° allowed).

    Returns
    -------
    ndarray
        (phi, theta) node means [1/sr].
    """
    m, q = _square_cells(spec), CELL_SHARE_POINTS
    phi = np.asarray(phi_deg, dtype=np.float64)
    closing = phi.size > 1 and abs(phi[-1] - phi[0] - 360.0) < 1e-9
    ring = phi[:-1] if closing else phi
    knots = np.sin(np.radians(np.asarray(theta_deg, dtype=np.float64)))
    sub = (np.arange(m * q) + 0.5) / (m * q)
    a, b = np.meshgrid(sub, sub, indexing="ij")
    cell = (np.floor(a * m).astype(np.int64) * m + np.floor(b * m).astype(np.int64)).ravel()
    x, y = square_to_disk(a.ravel(), b.ravel())
    power = np.asarray(values, dtype=np.float64)[cell] * (np.pi / (m * q) ** 2)
    rho = np.clip(np.hypot(x, y), 0.0, knots[-1])
    i = np.clip(np.searchsorted(knots, rho, side="right") - 1, 0, knots.size - 2)
    t = (rho - knots[i]) / (knots[i + 1] - knots[i])
    az = np.mod(np.degrees(np.arctan2(y, x)) - ring[0], 360.0) + ring[0]
    ext = np.concatenate([ring, [ring[0] + 360.0]])
    j = np.clip(np.searchsorted(ext, az, side="right") - 1, 0, ring.size - 1)
    u = (az - ext[j]) / (ext[j + 1] - ext[j])
    share = np.zeros((knots.size, ring.size))
    for di, wi in ((0, 1.0 - t), (1, t)):
        for dj, wj in ((0, 1.0 - u), (1, u)):
            np.add.at(share, (i + di, (j + dj) % ring.size), power * wi * wj)
    w = normal_grid_weights(np.asarray(theta_deg, dtype=np.float64), ring)
    mean = np.divide(share, w, out=np.zeros_like(share), where=w > 0)
    if knots[0] == 0.0:  # the row at the normal is one direction: one value
        mean[0] = share[0].sum() / w[0].sum()
    out = mean.T
    return np.concatenate([out, out[:1]], axis=0) if closing else out
