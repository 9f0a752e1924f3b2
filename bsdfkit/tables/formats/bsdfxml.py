"""Radiance / LBNL WINDOW BSDF XML: writer (Klems full angle basis, 145 patches; a ``TensorTree3`` by the rule of
:mod:`bsdfkit.tables.formats.bsdfxml_tree`) and reader (any Klems-type basis, and Radiance's tensor trees
``TensorTree3`` / ``TensorTree4``, :mod:`bsdfkit.tables.formats.tensortree`).

Layout written (the WINDOW 6 schema, ``WindowElement`` → ``Optical`` → ``Layer``)::

    <WindowElement xmlns="http://windows.lbl.gov">
      <WindowElementType>System</WindowElementType> <FileType>BSDF</FileType>
      <Optical><Layer>
        <Material> Name, Manufacturer, Thickness, DeviceType </Material>
        <DataDefinition> IncidentDataStructure Columns; AngleBasis "LBNL/Klems Full" (9 theta blocks) </DataDefinition>
        <WavelengthData> Wavelength "Visible" (unit Integral), one WavelengthDataBlock per
          "Reflection Front" | "Transmission Front" [| "Reflection Back" | "Transmission Back"]:
          ScatteringDataType BRDF|BTDF, ScatteringData: 145 x 145 numbers [1/sr], one line per OUTGOING patch,
          one column per INCIDENT patch (IncidentDataStructure Columns) </WavelengthData>
      </Layer></Optical>
    </WindowElement>

Klems full basis: theta bands with edges 0, 5, 15, 25, 35, 45, 55, 65, 75, 90 deg and 1, 8, 16, 20, 24, 24, 24,
16, 12 azimuth patches; patch j of a band is centred on azimuth j·360°/n (the first on azimuth 0); the incident
patch of a band is at its centre theta (0 for the polar cap, 82.5 for the last band). A patch's projected solid
angle is Λ = π (sin²θ_hi − sin²θ_lo) / n [sr]. The diagonal holds the mirror (reflection) and straight-through
(transmission) direction of each incident patch: outgoing patch (θ, φ) has the direction cosines
β = sin θ (cos φ, sin φ) that the specular direction of incident patch (θ, φ) has. So a BSDF
``fn(theta_i, side, directions)`` of bsdfkit (source at azimuth 180, specular at β0 = (sin θi, 0)) gives
column (θ_b, φ_j) as ``fn(θ_b, side, R(−φ_j)·d)``: the sample is taken as **isotropic about its normal**
(a bsdfkit table source knows one plane of incidence, as every other writer assumes).

Rules (docs/exports.md, "Radiance / WINDOW BSDF XML"):

* **Values**: each matrix entry is the projected-solid-angle average of the source BSDF over the outgoing patch
  (16 Gauss–Legendre nodes in sin²θ times 16 uniform azimuths per patch), so Σ_out f Λ is the integral of the
  source over the hemisphere: the direct-hemispherical value Radiance computes equals the source's TIS at the
  patch's incidence up to that quadrature.
* **Incidences**: incident band b holds the source at the source incidence nearest its centre θ_b (ties: the
  lower); an XML comment lists the mapping. Exact when the source holds the Klems centres (0, 10, …, 70, 82.5).
* **Spectral**: Radiance's loader reads the block labelled ``Visible``; bsdfkit writes the BSDF at ONE wavelength
  (the exported one, e.g. 550 nm) under that label and records it in the comment ``bsdfkit wavelength_nm=…``.
  It is the photopic value exactly when the sample is spectrally flat across the visible.
* **Resolution (Klems rule)**: the basis resolves nothing finer than a patch (5° polar cap, 10° bands, 15° at
  grazing; azimuth 15°–45°): a lobe is smeared over its patch (its integral is kept, its shape is not), and the
  incidence is quantised to the 9 band centres. A specular lobe narrower than a patch (FWHM below ~10°) needs a
  tensor tree: ``ExportSettings.xml_basis`` ``auto`` (the default) writes a TensorTree3 exactly then (FWHM below
  10°, :mod:`bsdfkit.tables.formats.bsdfxml_tree`), ``tree`` always, ``klems`` (what WINDOW reads) never; in
  Klems such a lobe keeps its TIS, not its angular distribution.
* **One answer**: a file in a basis is piecewise constant; its hemispherical value is the basis sum Σ f Λ
  (:mod:`bsdfkit.reduction.basis`). ``read`` reports it; ingested records carry their cell's projected solid angle
  (``basis_psa``) and the hemispherical engine integrates them by the same sum.
* **Back side**: a bsdfkit source describes incidence on the front face. ``Back`` blocks are written only on
  request (``ExportSettings.xml_back = "mirror"``: the front data, for a sample symmetric between its faces).
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io import atomic
from bsdfkit.io.text import is_float, read_text
from bsdfkit.measurement.table import MAX_ABS_BSDF
from bsdfkit.reduction.basis import basis_sum, klems_spec, shirley_chiu_spec
from bsdfkit.tables import grids
from bsdfkit.tables.format_spec import FileSummary, TableFormat, VendorGrid, VendorTable, WriteJob, WriteOutcome
from bsdfkit.tables.formats import bsdfxml_tree as bt
from bsdfkit.tables.formats import tensortree, xml_document

__all__ = ["KLEMS_FULL", "KlemsBasis", "KlemsBsdf", "TreeBsdf", "klems_bsdf", "read_bsdfxml", "write_bsdfxml",
           "xml_text"]

_DIRECTIONS = ("Reflection Front", "Transmission Front", "Reflection Back", "Transmission Back")
_VALUE_FMT = ".7g"
_WAVELENGTH_TAG = re.compile(r"bsdfkit wavelength_nm=([-+0-9.eE]+|nan)")
#: sub-samples per patch (sin²θ Gauss–Legendre nodes × azimuths) for the patch averages
SUB_SAMPLES = 16


@dataclass(frozen=True)
class KlemsBasis:
    """An angle basis of theta bands: edges [deg] and azimuth patches per band."""

    name: str
    edges_deg: tuple[float, ...]
    n_phi: tuple[int, ...]

    @property
    def size(self) -> int:
        return int(sum(self.n_phi))

    @property
    def centres_deg(self) -> NDArray[np.float64]:
        e = np.asarray(self.edges_deg)
        c = 0.5 * (e[:-1] + e[1:])
        if e[0] == 0.0:
            c[0] = 0.0
        return c

    def patches(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """(band index, centre azimuth [deg]) of every patch, in file order."""
        band = np.repeat(np.arange(len(self.n_phi)), self.n_phi)
        phi = np.concatenate([np.arange(n) * 360.0 / n for n in self.n_phi])
        return band, phi

    def lambdas(self) -> NDArray[np.float64]:
        """Projected solid angle of every patch [sr]."""
        s2 = np.sin(np.radians(np.asarray(self.edges_deg))) ** 2
        per_band = np.pi * np.diff(s2) / np.asarray(self.n_phi)
        return np.repeat(per_band, self.n_phi)


KLEMS_FULL = KlemsBasis("LBNL/Klems Full", (0.0, 5.0, 15.0, 25.0, 35.0, 45.0, 55.0, 65.0, 75.0, 90.0),
                        (1, 8, 16, 20, 24, 24, 24, 16, 12))


@dataclass(frozen=True, eq=False)
class KlemsBsdf:
    """One BSDF XML: ``blocks`` maps a direction (``Reflection Front`` …) to its matrix [1/sr] of shape
    (outgoing, incident); ``source_incidence_deg`` the source incidence each incident band holds (written files)."""

    basis: KlemsBasis
    blocks: dict[str, NDArray[np.float64]]
    wavelength_nm: float | None = None
    name: str = "bsdfkit"
    comments: tuple[str, ...] = ()
    source_incidence_deg: tuple[float, ...] | None = None
    wavelength_label: str = "Visible"
    details: dict[str, Any] = field(default_factory=dict)

    def hemispherical(self, direction: str) -> NDArray[np.float64]:
        """Σ_out f Λ per incident patch [1]: the file's own direct-hemispherical value (Radiance's), by the basis
        sum the hemispherical engine uses for ingested records (:func:`bsdfkit.reduction.basis.basis_sum`).

        Parameters
        ----------
        direction : str
            A block name, e.g. ``Reflection Front``.

        Returns
        -------
        ndarray
            Hemispherical value per incident patch [-].
        """
        return basis_sum(self.blocks[direction], self.basis.lambdas())

    def band_tis(self, direction: str) -> NDArray[np.float64]:
        """The hemispherical value at the first patch (azimuth 0) of every incident band [1].

        Parameters
        ----------
        direction : str
            A block name, e.g. ``Reflection Front``.

        Returns
        -------
        ndarray
            One value per incident band [-].
        """
        first = np.concatenate([[0], np.cumsum(self.basis.n_phi)[:-1]])
        return self.hemispherical(direction)[first]


@dataclass(frozen=True, eq=False)
class TreeBsdf:
    """One BSDF XML holding tensor trees (``TensorTree3`` isotropic, ``TensorTree4`` anisotropic): ``trees`` maps a
    direction (``Reflection Back`` …) to its :class:`~bsdfkit.tables.formats.tensortree.TensorTree`."""

    ndim: int
    trees: dict[str, tensortree.TensorTree]
    wavelength_nm: float | None = None
    name: str = "bsdfkit"
    details: dict[str, Any] = field(default_factory=dict)

    def hemispherical(self, direction: str, theta_deg: float) -> float:
        """π Σ f s² over the leaves at the incidence [deg] (source at azimuth 180°) [1]: Radiance's value.

        Parameters
        ----------
        direction : str
            A block name, e.g. ``Reflection Front``.
        theta_deg : float
            Incidence [deg].

        Returns
        -------
        float
            The hemispherical value [-].
        """
        return self.trees[direction].hemispherical(theta_deg)

    def incidences_deg(self) -> list[float]:
        """Normal incidence and the centres of the incident cells of every tree in the plane of incidence [deg],
        ascending (:func:`~bsdfkit.tables.formats.tensortree.incidences_deg`)."""
        edges = np.concatenate([t.incident_edges() for t in self.trees.values()])
        return tensortree.incidences_deg(edges, self.ndim)


def _side_of(direction: str) -> str:
    return "reflection" if direction.startswith("Reflection") else "transmission"


def _patch_nodes(basis: KlemsBasis, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """β (patch, n·n, 2) sub-samples and their weights (patch, n·n) summing to 1 per patch (projected solid
    angle measure: uniform in sin²θ and azimuth)."""
    x, w = np.polynomial.legendre.leggauss(n)
    band, phi_c = basis.patches()
    s2 = np.sin(np.radians(np.asarray(basis.edges_deg))) ** 2
    lo, hi = s2[band], s2[band + 1]
    u = 0.5 * (lo[:, None] + hi[:, None]) + 0.5 * (hi - lo)[:, None] * x[None, :]  # (patch, n) sin²θ
    dphi = 360.0 / np.asarray(basis.n_phi)[band]
    phi = phi_c[:, None] + dphi[:, None] * ((np.arange(n) + 0.5) / n - 0.5)[None, :]  # (patch, n) deg
    r = np.sqrt(u)[:, :, None]
    a = np.radians(phi)[:, None, :]
    beta = np.stack([np.broadcast_to(r * np.cos(a), (len(band), n, n)),
                     np.broadcast_to(r * np.sin(a), (len(band), n, n))], axis=-1).reshape(len(band), n * n, 2)
    weights = np.broadcast_to((0.5 * w)[:, None] / n, (n, n)).reshape(1, n * n)
    return beta, np.broadcast_to(weights, (len(band), n * n))


def _direction(beta: NDArray[np.float64]) -> NDArray[np.float64]:
    z = np.sqrt(np.clip(1.0 - np.sum(beta**2, axis=-1), 0.0, None))
    return np.concatenate([beta, z[..., None]], axis=-1)


def klems_bsdf(fn: grids.BsdfFn, theta_deg: NDArray[np.float64], sides: tuple[str, ...], *,
               basis: KlemsBasis = KLEMS_FULL, wavelength_nm: float | None = None, back: str = "none",
               comments: tuple[str, ...] = (), back_fn: grids.BsdfFn | None = None) -> KlemsBsdf:
    """Klems matrices of a BSDF callable (see the module docstring for the rules), each patch averaged over its
    :data:`SUB_SAMPLES` × :data:`SUB_SAMPLES` sub-samples.

    Parameters
    ----------
    fn
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr] (source at azimuth 180°).
    theta_deg
        The source's incidences [deg]; band b takes the one nearest its centre.
    sides
        ``reflection`` and/or ``transmission`` (front blocks).
    basis
        The angle basis (default LBNL/Klems Full).
    wavelength_nm
        The single wavelength of the ``Visible`` block [nm] (None: unknown, written as ``nan``).
    back
        ``none`` or ``mirror`` (Back blocks = Front blocks).
    back_fn : callable, optional
        The back face's BSDF [1/sr], written as the Back blocks (with ``back`` = ``none``).
    comments
        Comment lines written into the file.

    Returns
    -------
    KlemsBsdf
        The matrices [1/sr] and the source incidence [deg] each incident band takes.
    """
    theta = np.sort(np.asarray(theta_deg, dtype=np.float64))
    if theta.size == 0:
        raise ValidationError("no incidence to write", field="theta_i_deg", expected="at least one incidence")
    if back not in ("none", "mirror"):
        raise ValidationError("unknown back-side rule", field="xml_back", expected="none or mirror", got=back)
    centres = basis.centres_deg
    chosen = np.array([theta[int(np.argmin(np.abs(theta - c)))] for c in centres])
    blocks: dict[str, NDArray[np.float64]] = {}
    for side in sides:
        blocks[f"{side.capitalize()} Front"] = _klems_matrix(fn, chosen, side, basis)
    if back == "mirror":
        for side in sides:
            blocks[f"{side.capitalize()} Back"] = blocks[f"{side.capitalize()} Front"].copy()
    if back_fn is not None:  # the back face's own BSDF (a source file's Back blocks)
        for side in sides:
            blocks[f"{side.capitalize()} Back"] = _klems_matrix(back_fn, chosen, side, basis)
    return KlemsBsdf(basis, blocks, wavelength_nm, "bsdfkit", tuple(comments), tuple(float(t) for t in chosen))


def _klems_matrix(fn: grids.BsdfFn, chosen: NDArray[np.float64], side: str, basis: KlemsBasis
                  ) -> NDArray[np.float64]:
    """One (outgoing, incident) matrix [1/sr]: each patch the mean of ``fn`` at its sub-samples, incident band b at
    the source incidence ``chosen[b]`` [deg]."""
    beta, weights = _patch_nodes(basis, SUB_SAMPLES)
    band, phi_c = basis.patches()
    m = np.zeros((basis.size, basis.size))
    for j in range(basis.size):
        a = np.radians(phi_c[j])
        c, s = np.cos(a), np.sin(a)
        # rotate the outgoing sub-samples by -phi_j: the source's plane of incidence
        rot = np.stack([c * beta[..., 0] + s * beta[..., 1], -s * beta[..., 0] + c * beta[..., 1]], axis=-1)
        values = grids.evaluate_bsdf(fn, float(chosen[band[j]]), side, _direction(rot))
        m[:, j] = np.sum(values * weights, axis=-1)
    return m


def xml_text(bsdf: KlemsBsdf, generated_at: datetime | None = None) -> str:
    """The XML document of ``bsdf`` (values to 7 significant digits).

    Parameters
    ----------
    bsdf : KlemsBsdf
        The matrices.
    generated_at : datetime, optional
        Time stamp of the first comment (default: now).

    Returns
    -------
    str
        The XML text.
    """
    comments = list(bsdf.comments)
    if bsdf.source_incidence_deg is not None:
        mapping = ", ".join(f"{c:g}<-{t:g}" for c, t in zip(bsdf.basis.centres_deg, bsdf.source_incidence_deg))
        comments.insert(0, f"bsdfkit incident band centre <- source incidence [deg]: {mapping}")
    out = xml_document.head("Klems full basis", bsdf.name, bsdf.wavelength_nm, "Columns", comments, generated_at)
    out += ["<AngleBasis>", f"<AngleBasisName>{bsdf.basis.name}</AngleBasisName>"]
    for k, n in enumerate(bsdf.basis.n_phi):
        out += ["<AngleBasisBlock>", f"<Theta>{bsdf.basis.centres_deg[k]:g}</Theta>", f"<nPhis>{n}</nPhis>",
                f"<ThetaBounds><LowerTheta>{bsdf.basis.edges_deg[k]:g}</LowerTheta>"
                f"<UpperTheta>{bsdf.basis.edges_deg[k + 1]:g}</UpperTheta></ThetaBounds>", "</AngleBasisBlock>"]
    out += ["</AngleBasis>", "</DataDefinition>"]
    basis_lines = (f"<ColumnAngleBasis>{bsdf.basis.name}</ColumnAngleBasis>",
                   f"<RowAngleBasis>{bsdf.basis.name}</RowAngleBasis>")
    for direction in _DIRECTIONS:
        if direction in bsdf.blocks:
            rows = [", ".join(format(float(v), _VALUE_FMT) for v in row) + "," for row in bsdf.blocks[direction]]
            out += xml_document.wavelength_data(direction, bsdf.wavelength_label, basis_lines, rows)
    return "\n".join(out + list(xml_document.TAIL))


def write_bsdfxml(path: str | Path, bsdf: KlemsBsdf, *, force: bool = False,
                  generated_at: datetime | None = None) -> Path:
    """Write atomically; an existing file is replaced only with ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    bsdf : KlemsBsdf
        The matrices.
    force : bool
        Replace an existing file.
    generated_at : datetime, optional
        Time stamp of the first comment (default: now).

    Returns
    -------
    Path
        The file written.
    """
    return atomic.write_text(path, xml_text(bsdf, generated_at), force=force)


# ------------------------------------------------------------------------------------------- reader
def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _child(node: ET.Element, name: str) -> ET.Element | None:
    for c in node:
        if _local(c.tag) == name:
            return c
    return None


def _children(node: ET.Element, name: str) -> list[ET.Element]:
    return [c for c in node if _local(c.tag) == name]


def _text(node: ET.Element | None) -> str:
    return "" if node is None or node.text is None else node.text.strip()


def _line_of(text: str, needle: str) -> int:
    k = text.find(needle)
    return 0 if k < 0 else text.count("\n", 0, k) + 1


def _xml_start(text: str) -> int:
    """Where the XML document begins: after the lines genBSDF writes before it ("Recover using: genBSDF -recover
    …"), which Radiance's loader skips too; 0 for a file that starts with its XML."""
    k = text.find("<")
    return k if k > 0 and "<" not in text[:k] else 0


def _open_layer(path: str) -> tuple[str, ET.Element]:
    """The file's text and its ``Optical/Layer`` element (one-line :class:`FormatError` otherwise)."""
    text = read_text(path, expected="a BSDF XML file")
    start = _xml_start(text)
    try:
        root = ET.fromstring(text[start:])
    except ET.ParseError as exc:
        raise FormatError(f"not well-formed XML ({exc.msg if hasattr(exc, 'msg') else exc})", file=path,
                          line=exc.position[0] + text.count("\n", 0, start), field="XML",
                          expected="a BSDF XML document") from None
    if _local(root.tag) != "WindowElement":
        raise FormatError("not a BSDF XML file", file=path, line=1, field="root element",
                          expected="WindowElement", got=_local(root.tag))
    layer = None
    optical = _child(root, "Optical")
    if optical is not None:
        layer = _child(optical, "Layer")
    if layer is None:
        raise FormatError("no Optical/Layer element", file=path, field="Optical/Layer", expected="one layer")
    return text, layer


def read_bsdfxml(path: str | Path, block: str | None = None) -> KlemsBsdf | TreeBsdf:
    """Read a BSDF XML: a Klems-type angle basis (any basis of theta bands; the WINDOW schema) as a
    :class:`KlemsBsdf`, a Radiance tensor tree (``TensorTree3`` / ``TensorTree4``) as a :class:`TreeBsdf`.

    Raises :class:`FormatError` naming the file, line and element for what cannot be read: a missing basis, a
    matrix of the wrong size, a malformed tree, a value that is not a finite number ≥ 0.

    Parameters
    ----------
    path : str or Path
        The BSDF XML file.
    block : str, optional
        The spectral block to read by its label (``Visible``, ``Solar``, …; default: ``Visible`` when the file has
        it, else the first).

    Returns
    -------
    KlemsBsdf or TreeBsdf
        The file's BSDF [1/sr].
    """
    path = str(path)
    text, layer = _open_layer(path)
    definition = _child(layer, "DataDefinition")
    structure = _text(None if definition is None else _child(definition, "IncidentDataStructure"))
    if structure.lower().startswith("tensortree"):
        if structure.lower() not in ("tensortree3", "tensortree4"):
            raise FormatError("unknown tensor tree rank", file=path, line=_line_of(text, structure),
                              field="IncidentDataStructure", expected="TensorTree3 or TensorTree4", got=structure)
        return _read_tree(path, text, layer, 3 if structure.lower() == "tensortree3" else 4, block)
    return _read_klems(path, text, layer, definition, block)


def _refuse_huge(path: str, text: str, raw: str, where: str, largest: float) -> None:
    """Refuse a ScatteringData body ``raw`` holding a value above :data:`bsdfkit.measurement.table.MAX_ABS_BSDF`
    [1/sr], as text tables are: no measurement holds it, and its square overflows every uncertainty (1e300 read as
    a TIS of 2.4e298). The line is the value's own line in the file; ``largest`` [1/sr], the parsed maximum, spares
    the search of a body within the limit."""
    if not largest > MAX_ABS_BSDF:
        return
    numbers = list(re.finditer(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", raw))
    big = next((m for m in numbers if abs(float(m.group())) > MAX_ABS_BSDF), None)
    if big is None:
        return
    at = text.find(raw) if raw else -1
    line = text.count("\n", 0, at + big.start()) + 1 if at >= 0 else None
    raise FormatError("value implausibly large for a BSDF", file=path, line=line, field=where,
                      expected=f"|value| <= {MAX_ABS_BSDF:g} (1/sr)", got=big.group()[:40])


def _chosen_block(path: str, labels: list[str], block: str | None) -> str:
    """The spectral block to read: ``block`` (which the file must hold), else ``Visible`` (what Radiance reads)
    when the file has it, else the first; one block, never a mix."""
    if block is not None:
        if block not in labels:
            raise InputError("the file holds no spectral block of this label", file=path, field="--block",
                             expected=" or ".join(dict.fromkeys(labels)) or "a labelled block", got=block)
        return block
    return next((lb for lb in labels if lb.lower() == "visible"), labels[0] if labels else "")


def _read_klems(path: str, text: str, layer: ET.Element, definition: ET.Element | None, wanted: str | None = None
                ) -> KlemsBsdf:
    """The Klems part of :func:`read_bsdfxml`."""
    basis_el = None if definition is None else _child(definition, "AngleBasis")
    if basis_el is None:
        kind = _text(None if definition is None else _child(definition, "IncidentDataStructure")) or "none"
        raise FormatError("no angle basis (an AngleBasis or a tensor tree)", file=path,
                          line=_line_of(text, "IncidentDataStructure"), field="DataDefinition",
                          expected="an AngleBasis of theta blocks (LBNL/Klems Full, Half, Quarter) or "
                                   "IncidentDataStructure TensorTree3/TensorTree4", got=kind)
    structure = _text(_child(definition, "IncidentDataStructure")) or "Columns"
    if structure.lower() not in ("columns", "rows"):
        raise FormatError("unknown incident data structure", file=path, line=_line_of(text, structure),
                          field="IncidentDataStructure", expected="Columns or Rows", got=structure)
    name = _text(_child(basis_el, "AngleBasisName"))
    edges: list[float] = []
    n_phi: list[int] = []
    for block in _children(basis_el, "AngleBasisBlock"):
        bounds = _child(block, "ThetaBounds")
        try:
            lo, hi = float(_text(_child(bounds, "LowerTheta"))), float(_text(_child(bounds, "UpperTheta")))
            n = int(_text(_child(block, "nPhis")))
        except (TypeError, ValueError):
            raise FormatError("unreadable angle basis block", file=path, line=_line_of(text, "AngleBasisBlock"),
                              field="AngleBasisBlock", expected="LowerTheta, UpperTheta and nPhis numbers") from None
        if edges and abs(edges[-1] - lo) > 1e-6:
            raise FormatError("angle basis bands are not contiguous", file=path, field="ThetaBounds",
                              expected=f"LowerTheta {edges[-1]:g}", got=lo)
        if not edges:
            edges.append(lo)
        edges.append(hi)
        n_phi.append(n)
    if not n_phi or edges[0] != 0.0 or abs(edges[-1] - 90.0) > 1e-6 or min(n_phi) < 1:
        raise FormatError("incomplete angle basis", file=path, field="AngleBasis",
                          expected="theta bands from 0 to 90 deg with nPhis >= 1", got=f"{len(n_phi)} blocks")
    basis = KlemsBasis(name or "Klems", tuple(edges), tuple(n_phi))
    size = basis.size
    blocks: dict[str, NDArray[np.float64]] = {}
    labels: list[str] = []
    present = [_text(_child(wld, "Wavelength")) for wld in _children(layer, "WavelengthData")]
    chosen = _chosen_block(path, present, wanted)
    for wld in _children(layer, "WavelengthData"):
        label = _text(_child(wld, "Wavelength"))
        for block in _children(wld, "WavelengthDataBlock"):
            direction = " ".join(_text(_child(block, "WavelengthDataDirection")).split()).title()
            if direction not in _DIRECTIONS:
                raise FormatError("unknown data direction", file=path, line=_line_of(text, "WavelengthDataDirection"),
                                  field="WavelengthDataDirection", expected=" | ".join(_DIRECTIONS), got=direction)
            if label != chosen:
                continue
            raw = _text(_child(block, "ScatteringData"))
            tokens = [t for t in re.split(r"[,\s]+", raw) if t]
            where = f"ScatteringData of {direction}"
            if len(tokens) != size * size:
                raise FormatError("wrong number of values", file=path, line=_line_of(text, direction), field=where,
                                  expected=f"{size} x {size} = {size * size}", got=len(tokens))
            try:
                values = np.array([float(t) for t in tokens], dtype=np.float64)
            except ValueError:
                bad = next(t for t in tokens if not is_float(t))
                raise FormatError("not a number", file=path, line=_line_of(text, bad), field=where,
                                  expected="a number (1/sr)", got=bad[:40]) from None
            if not np.all(np.isfinite(values)) or np.any(values < 0):
                bad_v = values[~(np.isfinite(values) & (values >= 0))][0]
                raise FormatError("BSDF value not a finite number >= 0", file=path, line=_line_of(text, direction),
                                  field=where, expected="finite >= 0 (1/sr)", got=float(bad_v))
            _refuse_huge(path, text, raw, where, float(values.max(initial=0.0)))
            m = values.reshape(size, size)  # Columns: one line per outgoing patch, one column per incident
            blocks[direction] = m.T.copy() if structure.lower() == "rows" else m
            labels.append(label)
    if not blocks:
        raise FormatError("no scattering data", file=path, field="WavelengthData", expected="a WavelengthDataBlock")
    lam, mat_name = _wavelength_and_name(path, text, layer)
    return KlemsBsdf(basis, blocks, lam, mat_name, details={"wavelength_label": chosen,
                                                             "wavelength_labels_in_file": sorted(set(present)),
                                                             "incident_data_structure": structure})


def _wavelength_and_name(path: str, text: str, layer: ET.Element) -> tuple[float | None, str]:
    tag = _WAVELENGTH_TAG.search(text)
    lam = float(tag.group(1)) if tag else None
    material = _child(layer, "Material")
    return (None if lam is None or not np.isfinite(lam) else lam,
            _text(None if material is None else _child(material, "Name")) or Path(path).stem)


#: Wavelength labels of the colour trees of a tensor-tree file (chromaticity, not BSDF values): not read
_CHROMA = ("cie-u", "cie-v")


def _read_tree(path: str, text: str, layer: ET.Element, ndim: int, wanted: str | None = None) -> TreeBsdf:
    """The tensor-tree part of :func:`read_bsdfxml`: the ``Visible`` (else the first) BSDF tree of every block."""
    data_starts = [m.end() for m in re.finditer(r"<ScatteringData\b[^>]*>", text)]
    trees: dict[str, tensortree.TensorTree] = {}
    labels: list[str] = []
    present = [_text(_child(wld, "Wavelength")) for wld in _children(layer, "WavelengthData")]
    chosen = _chosen_block(path, [lb for lb in present if lb.lower() not in _CHROMA], wanted)
    k = -1
    for wld in _children(layer, "WavelengthData"):
        label = _text(_child(wld, "Wavelength"))
        for block in _children(wld, "WavelengthDataBlock"):
            k += 1
            direction = " ".join(_text(_child(block, "WavelengthDataDirection")).split()).title()
            if direction not in _DIRECTIONS:
                raise FormatError("unknown data direction", file=path, line=_line_of(text, "WavelengthDataDirection"),
                                  field="WavelengthDataDirection", expected=" | ".join(_DIRECTIONS), got=direction)
            if label != chosen:
                continue
            basis_name = _text(_child(block, "AngleBasis"))
            if basis_name.lower() != "lbnl/shirley-chiu":
                raise FormatError("unsupported angle basis for a tensor tree", file=path,
                                  line=_line_of(text, "AngleBasis"), field=f"AngleBasis of {direction}",
                                  expected="LBNL/Shirley-Chiu", got=basis_name or "none")
            data = _child(block, "ScatteringData")
            raw = "" if data is None or data.text is None else data.text
            try:
                trees[direction] = tensortree.parse_tree(raw, ndim)
            except tensortree.TreeSyntaxError as exc:
                at = data_starts[k] + exc.offset if k < len(data_starts) else 0
                raise FormatError(str(exc), file=path, line=text.count("\n", 0, at) + 1 if at else None,
                                  field=f"ScatteringData of {direction} (TensorTree{ndim})", expected=exc.expected,
                                  got=exc.got) from None
            _refuse_huge(path, text, raw, f"ScatteringData of {direction} (TensorTree{ndim})",
                         float(np.max(trees[direction].value, initial=0.0)))
            labels.append(label)
    if not trees:
        raise FormatError("no scattering data", file=path, field="WavelengthData",
                          expected="a WavelengthDataBlock with a Visible tensor tree")
    lam, name = _wavelength_and_name(path, text, layer)
    return TreeBsdf(ndim, trees, lam, name, details={"wavelength_label": chosen,
                                                     "wavelength_labels_in_file": sorted(set(present)),
                                                     "incident_data_structure": f"TensorTree{ndim}"})


# ------------------------------------------------------------------------------------------- registry hooks
def _basis_rule(job: WriteJob) -> str:
    """The basis to write, ``klems`` or ``tree``, as the first word of the reason (``ExportSettings.xml_basis``;
    ``auto``: a tree for a specular lobe narrower than a Klems patch, :mod:`bsdfkit.tables.formats.bsdfxml_tree`)."""
    basis = job.settings.xml_basis
    if basis != "auto":
        return f"{basis}: --xml-basis {basis}"
    source_basis = getattr(job.fn, "basis", None)  # a file's own basis is kept: its cells are not lobes
    if isinstance(job.fn, grids.PiecewiseConstant) and source_basis:
        kind = "tree" if source_basis.startswith("shirley-chiu") else "klems"
        return f"{kind}: the source is a {'tensor tree' if kind == 'tree' else 'Klems'} file (its own basis kept)"
    width = bt.narrowest_lobe_deg(job.fn, np.asarray(job.theta, dtype=np.float64), tuple(job.sides))
    if width is None:
        return "klems: no specular lobe"
    if width < bt.KLEMS_PATCH_DEG:
        return f"tree: the specular lobe's FWHM {width:.3g} deg < {bt.KLEMS_PATCH_DEG:g} deg (a Klems patch)"
    return f"klems: the narrowest specular lobe's FWHM {width:.3g} deg >= {bt.KLEMS_PATCH_DEG:g} deg"


def _write_job(job: WriteJob) -> WriteOutcome:
    settings = job.settings
    rule = _basis_rule(job)
    if rule.startswith("tree"):
        return bt.write_tree_job(job, rule)
    bsdf = klems_bsdf(job.fn, np.asarray(job.theta, dtype=np.float64), tuple(job.sides),
                      wavelength_nm=settings.wavelength_nm, back=settings.xml_back, comments=job.comments,
                      back_fn=settings.xml_back_fn)
    bsdf = replace(bsdf, wavelength_label=settings.xml_label)
    write_bsdfxml(job.path, bsdf, force=job.force, generated_at=job.generated_at)
    return WriteOutcome(None, {"mode": f"{KLEMS_FULL.name} ({KLEMS_FULL.size} patches)", "basis_rule": rule,
                               "klems_incidence_map_deg": dict(zip([float(c) for c in KLEMS_FULL.centres_deg],
                                                                   bsdf.source_incidence_deg or ()))})


def _key(direction: str) -> str:
    side = _side_of(direction)
    return side if direction.endswith("Front") else f"{side}@back"


def _summarise(path: str) -> FileSummary:
    bsdf = read_bsdfxml(path)
    if isinstance(bsdf, TreeBsdf):
        return _summarise_tree(path, bsdf)
    theta = [float(t) for t in bsdf.basis.centres_deg]
    computed = {_key(d): [float(v) for v in bsdf.band_tis(d)] for d in _DIRECTIONS if d in bsdf.blocks}
    spread = klems_anisotropy(bsdf)
    notes = [] if spread <= ANISOTROPY_RTOL else [
        f"anisotropic: the hemispherical values of the incident patches of one band differ by up to "
        f"{100 * spread:.3g} %; the values are those of the incident patch at Klems azimuth 0, bsdfkit's plane of "
        "incidence (Radiance: direct_hemi(sd, 180 - theta, 180) on the front, (theta, 180) on the back)"]
    return FileSummary(
        format="bsdfxml", path=path, incidences_deg=theta, tis_computed=computed, tis_stated={},
        details={"basis": bsdf.basis.name, "patches": bsdf.basis.size, "blocks": list(bsdf.blocks),
                 "wavelength_nm": bsdf.wavelength_nm, **bsdf.details, "anisotropy": spread,
                 "azimuth_convention": "incidence theta = the Klems incident patch (theta, azimuth 0) = Radiance's "
                                       "front direction (180 - theta, 180)", "notes": notes,
                 "tis_rule": "the file's own direct-hemispherical value sum_out f * Lambda at the azimuth-0 patch of "
                             "each incident band (as Radiance computes it): a Klems matrix holds patch averages, "
                             "whose integral is exactly this sum (the basis sum `bsdfkit tis` also uses on the "
                             "ingested file)"},
    )


#: Relative spread of the hemispherical values over the incident azimuths of a band above which a Klems file is
#: reported as anisotropic (the Monte Carlo noise of bsdf2klems' isotropic files is about 1e-4)
ANISOTROPY_RTOL = 1e-3


def klems_anisotropy(bsdf: KlemsBsdf) -> float:
    """The largest relative spread (max − min)/max of the hemispherical value Σ_out f Λ over the incident patches
    of one theta band, over the bands and blocks [-]: 0 for a file isotropic about its normal.

    Parameters
    ----------
    bsdf : KlemsBsdf
        The file's matrices [1/sr].

    Returns
    -------
    float
        The spread [-].
    """
    band, _ = bsdf.basis.patches()
    lam = bsdf.basis.lambdas()
    worst = 0.0
    for m in bsdf.blocks.values():
        tis = basis_sum(m, lam)  # per incident patch
        for b in np.unique(band):
            v = tis[band == b]
            if v.size > 1 and v.max() > 0:
                worst = max(worst, float((v.max() - v.min()) / v.max()))
    return worst


def _summarise_tree(path: str, bsdf: TreeBsdf) -> FileSummary:
    theta = bsdf.incidences_deg()
    computed = {_key(d): [bsdf.hemispherical(d, t) for t in theta] for d in _DIRECTIONS if d in bsdf.trees}
    return FileSummary(
        format="bsdfxml", path=path, incidences_deg=theta, tis_computed=computed, tis_stated={},
        details={"basis": f"LBNL/Shirley-Chiu tensor tree (TensorTree{bsdf.ndim})", "blocks": list(bsdf.trees),
                 "leaves": {d: int(t.value.size) for d, t in bsdf.trees.items()},
                 "wavelength_nm": bsdf.wavelength_nm, **bsdf.details,
                 "tis_rule": "the file's own direct-hemispherical value pi * sum f * s^2 over the tree's leaves at "
                             "each incidence (source at azimuth 180 deg; as Radiance computes it), at the centres "
                             "of the tree's incident cells (the basis sum `bsdfkit tis` also uses on the ingested "
                             "file)"},
    )


#: nodes per patch side for ingest: each Klems patch value is placed at n × n points inside its patch, each
#: standing for Λ/n² of the patch (coordinate ``basis_psa``): the hemispherical engine integrates them by the
#: basis sum, exactly the file's own value
INGEST_NODES = 2


def _face_of(direction: str) -> str:
    return "back" if direction.endswith("Back") else "front"


def _klems_grids(bsdf: KlemsBsdf, directions: list[str]) -> list[VendorGrid]:
    n = INGEST_NODES
    beta, _ = _patch_nodes(bsdf.basis, n)
    r = np.clip(np.hypot(beta[..., 0], beta[..., 1]).ravel(), 0.0, 1.0)
    theta_s = np.degrees(np.arcsin(r))
    phi_s = np.mod(np.degrees(np.arctan2(beta[..., 1], beta[..., 0])).ravel(), 360.0)
    first = np.concatenate([[0], np.cumsum(bsdf.basis.n_phi)[:-1]])
    psa = np.repeat(bsdf.basis.lambdas() / (n * n), n * n)
    cells = np.repeat(np.arange(bsdf.basis.size), n * n)
    spec = klems_spec(bsdf.basis.edges_deg, bsdf.basis.n_phi)
    out = []
    for direction in directions:
        m = bsdf.blocks[direction]
        # the source at azimuth 180 in bsdfkit's frame: incident patch (theta_b, 0), outgoing patches as they are
        out.append(VendorGrid("directions", _side_of(direction), bsdf.basis.centres_deg.copy(), theta_s, phi_s,
                              np.stack([np.repeat(m[:, j], n * n) for j in first]),
                              solid_angle=np.tile(psa, (first.size, 1)), cell=np.tile(cells, (first.size, 1)),
                              basis=spec, face=_face_of(direction)))
    return out


def _tree_grids(bsdf: TreeBsdf, directions: list[str]) -> list[VendorGrid]:
    theta = np.asarray(bsdf.incidences_deg())
    out = []
    for direction in directions:
        tree = bsdf.trees[direction]
        m = tree.cells_per_side()
        bx, by = tensortree.grid_directions(m)
        theta_s = np.degrees(np.arcsin(np.clip(np.hypot(bx, by), 0.0, 1.0)))
        phi_s = np.mod(np.degrees(np.arctan2(by, bx)), 360.0)
        values = np.stack([tree.out_grid(t, m).ravel() for t in theta])
        out.append(VendorGrid("directions", _side_of(direction), theta.copy(), theta_s, phi_s, values,
                              solid_angle=np.full(values.shape, np.pi / (m * m)),
                              cell=np.tile(np.arange(m * m), (theta.size, 1)), basis=shirley_chiu_spec(m),
                              face=_face_of(direction)))
    return out


def _vendor_table(path: str) -> VendorTable:
    """Every face and spectral block of the file as grids (``face``, ``block`` name each): ingest chooses one."""
    first = read_bsdfxml(path)
    tree = isinstance(first, TreeBsdf)
    labels = [lb for lb in first.details["wavelength_labels_in_file"] if not tree or lb.lower() not in _CHROMA]
    grids_: list[VendorGrid] = []
    for label in [first.details["wavelength_label"]] + [lb for lb in labels if lb != first.details["wavelength_label"]]:
        bsdf = first if label == first.details["wavelength_label"] else read_bsdfxml(path, block=label)
        present = list(bsdf.trees if tree else bsdf.blocks)
        directions = [d for d in _DIRECTIONS if d in present]  # both faces: ingest chooses one (vendor_dataset)
        if not directions:
            raise FormatError("the file holds no reflection or transmission block", file=path,
                              field="WavelengthDataDirection", expected="Reflection or Transmission, Front or Back")
        found = _tree_grids(bsdf, directions) if tree else _klems_grids(bsdf, directions)
        grids_ += [replace(g, block=label) for g in found]
    details = {"basis": f"LBNL/Shirley-Chiu tensor tree (TensorTree{first.ndim})" if tree else first.basis.name,
               "blocks_read": [d for d in _DIRECTIONS if d in (first.trees if tree else first.blocks)],
               "wavelength_label": first.details["wavelength_label"], "wavelength_labels_in_file": labels}
    return VendorTable("bsdfxml", tuple(grids_), first.wavelength_nm, details)


def _guess_can_open(head: str, path: Path) -> bool:
    body = re.sub(r"<\?xml[^>]*\?>|<!--.*?-->", "", head[_xml_start(head):], flags=re.S).lstrip()
    return body.startswith("<WindowElement") or (body.startswith("<") and "<WindowElement" in head[:2048])


FORMAT = TableFormat(name="bsdfxml", title="Radiance/WINDOW BSDF XML (Klems, tensor tree)",
                     extensions=(".xml",),
                     guess_can_open=_guess_can_open, summarise=_summarise, vendor_table=_vendor_table,
                     write=_write_job, sides_per_file=2, grid_kind="klems")
