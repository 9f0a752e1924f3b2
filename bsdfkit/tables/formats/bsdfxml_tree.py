"""BSDF XML with a Radiance tensor tree (``TensorTree3``, isotropic): the writer and its rule.

Rule (docs/exports.md §2.4, "Writer rule")
    ``ExportSettings.xml_basis`` (``--xml-basis``): ``auto`` (the default): a tensor tree when the source's specular
    lobe is narrower than a Klems patch — its in-plane full width at half maximum above the floor of the arc is below
    :data:`KLEMS_PATCH_DEG` (10°, the width of a Klems band) at some incidence and side — else Klems; ``klems``
    (always: WINDOW and most daylighting tools read the Klems basis only) or ``tree`` (always a tensor tree).
    Radiance reads both; a tree keeps the lobe's shape to a cell (about 1.8° at the normal), Klems to a patch.

Tree written
    2^:data:`~bsdfkit.tables.formats.tensortree.LOG2_CELLS` (64) cells per dimension; incident cell ix holds the
    source at the source incidence nearest its centre θ = arcsin(1 − 2 (ix + ½)/64) (an XML comment and
    ``WriteOutcome.grid['klems_incidence_map_deg']`` give the map for the incidences a reader reports); every
    outgoing cell holds the projected-solid-angle average of the source over it
    (:func:`~bsdfkit.tables.formats.tensortree.cell_averages`), so π Σ f s² is the source's integral up to that
    quadrature; 2 × 2 × 2 cells uniform within 5 % are merged into their mean (the sum is kept exactly, the
    shape to 5 %; about 90 % of a smooth body's cells, as Radiance's own bsdf2ttree culls by default). The sample
    is taken as isotropic about its normal (TT3), as the Klems writer does; the same blocks are written (Front,
    Back on request).
"""
from __future__ import annotations

from datetime import datetime

import numpy as np
from numpy.typing import NDArray

from bsdfkit.io import atomic
from bsdfkit.tables import grids
from bsdfkit.tables.format_spec import WriteJob, WriteOutcome
from bsdfkit.tables.formats import tensortree, xml_document

__all__ = ["KLEMS_PATCH_DEG", "lobe_fwhm_deg", "narrowest_lobe_deg", "tree_grids", "write_tree_job"]

#: a lobe narrower than this (in-plane FWHM [deg]) is finer than a Klems patch: ``auto`` writes a tensor tree
KLEMS_PATCH_DEG = 10.0


def lobe_fwhm_deg(fn: grids.BsdfFn, theta_deg: float, side: str) -> float | None:
    """In-plane FWHM [deg] of the specular lobe at the incidence: the contiguous arc about the highest value within
    0.1 (direction cosines) of β0 = (sin θi, 0) where f stays above halfway between that peak and the arc's floor
    (its minimum within 0.3 of β0); None when the peak is less than twice the floor (no lobe).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_deg : float
        Incidence [deg].
    side : str
        ``reflection`` or ``transmission``.

    Returns
    -------
    float or None
        FWHM [deg], or None.
    """
    b0 = float(np.sin(np.radians(theta_deg)))
    t = np.arange(-0.3, 0.3 + 1e-12, 0.001)
    bx = b0 + t
    ok = np.abs(bx) < 0.999
    t, bx = t[ok], bx[ok]
    d = np.stack([bx, np.zeros_like(bx), np.sqrt(1.0 - bx * bx)], axis=-1)
    f = grids.evaluate_bsdf(fn, theta_deg, side, d)
    near = np.flatnonzero(np.abs(t) <= 0.1)
    p = int(near[np.argmax(f[near])])
    peak, floor = float(f[p]), float(f.min())
    if not peak > 2.0 * floor or peak <= 0.0:
        return None
    half = 0.5 * (peak + floor)
    lo, hi = p, p
    while lo > 0 and f[lo - 1] >= half:
        lo -= 1
    while hi < f.size - 1 and f[hi + 1] >= half:
        hi += 1
    edges = np.clip([bx[lo] - 0.0005, bx[hi] + 0.0005], -1.0, 1.0)  # half a step beyond the last samples
    return float(np.degrees(np.arcsin(edges[1]) - np.arcsin(edges[0])))


def narrowest_lobe_deg(fn: grids.BsdfFn, theta_deg: NDArray[np.float64], sides: tuple[str, ...]) -> float | None:
    """The smallest :func:`lobe_fwhm_deg` [deg] over the incidences [deg] and sides (None: no lobe anywhere).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_deg : ndarray
        Incidences [deg].
    sides : tuple of str
        Sides to look at.

    Returns
    -------
    float or None
        FWHM [deg], or None.
    """
    widths = [w for s in sides for t in theta_deg if (w := lobe_fwhm_deg(fn, float(t), s)) is not None]
    return min(widths) if widths else None


def tree_grids(fn: grids.BsdfFn, theta_deg: NDArray[np.float64], side: str, log2_cells: int = tensortree.LOG2_CELLS
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The full (n, n, n) TT3 grid [1/sr] of one side (incident cells ≥ n/2 zero: Radiance does not use them) and
    the source incidence [deg] each incident cell holds (the nearest to its centre).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_deg : ndarray
        Source incidences, ascending [deg].
    side : str
        ``reflection`` or ``transmission``.
    log2_cells : int
        log₂ of the cells per dimension n.

    Returns
    -------
    grid : ndarray
        (n, n, n) cell averages [1/sr].
    held : ndarray
        (n/2,) source incidence of each incident cell [deg].
    """
    n = 2**log2_cells
    centre = np.degrees(np.arcsin(1.0 - 2.0 * (np.arange(n // 2) + 0.5) / n))
    held = np.array([theta_deg[int(np.argmin(np.abs(theta_deg - c)))] for c in centre])
    grid = np.zeros((n, n, n))
    cache: dict[float, NDArray[np.float64]] = {}
    for ix, t in enumerate(held):
        if float(t) not in cache:
            cache[float(t)] = tensortree.cell_averages(lambda d, t=t: grids.evaluate_bsdf(fn, float(t), side, d), n)
        grid[ix] = cache[float(t)]
    return grid, held


def _incidence_map(texts: list[str], held: NDArray[np.float64], n: int) -> dict[float, float]:
    """Incidence a reader reports [deg] (:func:`~bsdfkit.tables.formats.tensortree.incidences_deg` of the written
    trees together) -> the source incidence its incident cell holds."""
    edges = np.concatenate([tensortree.parse_tree(t, 3).incident_edges() for t in texts])
    out = {}
    for t in tensortree.incidences_deg(edges, 3):
        x0 = min(0.5 - 0.5 * np.sin(np.radians(t)), 0.5 - 1e-6)
        out[float(t)] = float(held[min(int(x0 * n), n // 2 - 1)])
    return out


def tree_xml_text(blocks: dict[str, str], name: str, wavelength_nm: float | None, comments: tuple[str, ...],
                  generated_at: datetime | None = None, label: str = "Visible") -> str:
    """The XML document of tensor-tree ``blocks`` (direction -> ScatteringData text).

    Parameters
    ----------
    blocks : dict of str to str
        Direction → ScatteringData text of its tree.
    name : str
        Material name.
    wavelength_nm : float or None
        The single wavelength of the ``Visible`` block [nm] (None: written as ``nan``).
    comments : tuple of str
        Comment lines.
    generated_at : datetime, optional
        Time stamp of the first comment (default: now).
    label : str
        The spectral block's label (``Visible``: what Radiance reads).

    Returns
    -------
    str
        The XML text.
    """
    out = xml_document.head("Radiance tensor tree (TensorTree3)", name, wavelength_nm, "TensorTree3", comments,
                            generated_at)
    out.append("</DataDefinition>")
    for direction, tree in blocks.items():
        out += xml_document.wavelength_data(direction, label, ("<AngleBasis>LBNL/Shirley-Chiu</AngleBasis>",),
                                            (tree,))
    return "\n".join(out + list(xml_document.TAIL))


def write_tree_job(job: WriteJob, rule: str) -> WriteOutcome:
    """Write ``job`` as a TensorTree3 BSDF XML (module docstring); ``rule`` says why (for the outcome).

    Parameters
    ----------
    job : WriteJob
        The export's write job.
    rule : str
        Why a tensor tree was chosen.

    Returns
    -------
    WriteOutcome
        The grid description and the incidence map [deg].
    """
    theta = np.sort(np.asarray(job.theta, dtype=np.float64))
    n = 2**tensortree.LOG2_CELLS
    blocks: dict[str, str] = {}
    held = theta
    for side in job.sides:
        grid, held = tree_grids(job.fn, theta, side)
        blocks[f"{side.capitalize()} Front"] = tensortree.tree_text(grid)
    mapping = _incidence_map(list(blocks.values()), held, n)
    if job.settings.xml_back == "mirror":
        blocks.update({d.replace("Front", "Back"): t for d, t in list(blocks.items())})
    if job.settings.xml_back_fn is not None:  # the back face's own BSDF (a source file's Back blocks)
        for side in job.sides:
            blocks[f"{side.capitalize()} Back"] = tensortree.tree_text(tree_grids(job.settings.xml_back_fn, theta,
                                                                                  side)[0])
    note = ", ".join(f"{c:g}<-{t:g}" for c, t in mapping.items())
    comments = (f"bsdfkit incidence read <- source incidence [deg]: {note}", *job.comments)
    atomic.write_text(job.path, tree_xml_text(blocks, "bsdfkit", job.settings.wavelength_nm, comments,
                                              job.generated_at, label=job.settings.xml_label), force=job.force)
    return WriteOutcome(None, {"mode": f"LBNL/Shirley-Chiu TensorTree3 ({n} cells per dimension)",
                               "basis_rule": rule, "klems_incidence_map_deg": mapping})
