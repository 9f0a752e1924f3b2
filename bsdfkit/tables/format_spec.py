"""What a BSDF table format declares (:class:`TableFormat`) and the objects its hooks exchange with
:mod:`bsdfkit.tables.export`, :mod:`bsdfkit.tables.vendor` and :mod:`bsdfkit.tables.to_dataset`; the list of formats
is :mod:`bsdfkit.tables.registry`."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["FileSummary", "TableFormat", "VendorGrid", "VendorTable", "WriteJob", "WriteOutcome", "first_line_is"]


@dataclass(frozen=True)
class FileSummary:
    """Summary of a table file: its format, incidences and TIS (recomputed and, where stated, as stated).

    ``tis_computed`` / ``tis_stated`` map a key to one value per entry of ``incidences_deg``. Keys are the
    sides (``reflection``, ``transmission``); TracePro files state only the total scatter implied by their
    energy balance (1 − Abso − Refl − Tran), reported under ``total`` (``tis_computed['total']`` is the
    sum of the sides, for comparison). Several Zemax sample rotations get keys ``<side>@rotation=<deg>``;
    files with a front and a back face (BSDF XML) get ``<side>@back`` for the back face.
    """

    format: str
    path: str
    incidences_deg: list[float]
    tis_computed: dict[str, list[float]]
    tis_stated: dict[str, list[float]]
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The summary as a JSON-ready dict (incidences [deg], TIS [-])."""
        return {"format": self.format, "path": self.path, "incidences_deg": self.incidences_deg,
                "tis_computed": self.tis_computed, "tis_stated": self.tis_stated, "details": self.details}


@dataclass(frozen=True)
class VendorGrid:
    """One side of a vendor table in its native coordinates.

    ``kind``: ``specular`` (Zemax: radial [deg] and azimuth [deg] about the specular direction),
    ``harvey_shack`` (TracePro, ASAP: rho and psi [deg]) or ``directions`` (any scattered directions:
    ``first`` holds the polar angle θs [deg] and ``azimuth`` φs [deg] in the sample frame, ``values`` is then
    (theta_i, node), the nodes listed once per incidence).
    """

    kind: str
    side: str
    theta_i: Any  # [deg]
    first: Any  # radial [deg], rho, or theta_s [deg] (directions)
    azimuth: Any  # table azimuth [deg], or phi_s [deg] (directions)
    values: Any  # (theta_i, azimuth, first) or (theta_i, node) [1/sr]
    plane_symmetric: bool = False
    zero_azimuth_deg: float = 0.0  # harvey_shack: sample azimuth of table azimuth 0
    #: directions in an angle basis (BSDF XML): (theta_i, node) projected solid angle [sr] of the basis cell (or
    #: the part of it) each node stands for, summing to π per incidence; the ingested records carry it
    #: (:mod:`bsdfkit.reduction.basis`) and the hemispherical engine integrates them by the basis sum
    solid_angle: Any = None
    #: directions in an angle basis: (theta_i, node) index of the basis cell each node lies in, and the basis
    #: (:func:`bsdfkit.reduction.basis.klems_spec` / ``shirley_chiu_spec``): the ingested records carry both, and
    #: a conversion evaluates the file's BSDF by exact cell lookup (:func:`bsdfkit.reduction.basis.cell_index`)
    cell: Any = None
    basis: str | None = None
    #: the face of the sample the light is incident on: ``front`` or ``back`` (a BSDF XML file holds both)
    face: str = "front"
    #: the spectral block's label (BSDF XML: ``Visible``, ``Solar``, …; '' for one-block formats)
    block: str = ""


@dataclass(frozen=True)
class VendorTable:
    format: str
    grids: tuple[VendorGrid, ...]
    wavelength_nm: float | None
    details: dict[str, Any] = field(default_factory=dict)
    #: side -> (theta_i [deg], TIS [1]): the format's own scale rule (Speos): every value of the side is scaled so
    #: that the hemispherical engine's TIS at that incidence equals the stated TIS
    normalise: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: side -> [(theta_i [deg], TIS [1]), ...]: every incidence scaled to its own stated TIS (Speos .brdf)
    normalise_each: dict[str, list[tuple[float, float]]] = field(default_factory=dict)


@dataclass(frozen=True)
class WriteJob:
    """Everything a writer needs: the BSDF callable ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr], the
    incidences ``theta`` [deg], the ``sides`` to write (``side`` as asked: reflection, transmission or both), the
    export settings (:class:`bsdfkit.tables.export.ExportSettings`), fitted ABg parameters of the source (if any),
    the allowed excess of total scatter over 1, comment lines, the output path and the write options."""

    fn: Callable[..., Any]
    theta: Any
    side: str
    sides: tuple[str, ...]
    settings: Any
    abg: tuple[Any, ...]
    tis_excess_allowed: Any
    comments: tuple[str, ...]
    path: str | Path
    force: bool
    generated_at: Any = None


@dataclass(frozen=True)
class WriteOutcome:
    """What a writer chose: its axes (re-written finer by the export's re-check when ``auto``), the grid
    description of :class:`bsdfkit.tables.export.ExportResult` and the plane-symmetry deviation (Zemax)."""

    axes: Any = None
    grid: dict[str, Any] = field(default_factory=dict)
    plane_symmetry_deviation: float | None = None


@dataclass(frozen=True)
class TableFormat:
    """The declaration of one format (see the module docstring)."""

    name: str
    title: str
    extensions: tuple[str, ...]
    guess_can_open: Callable[[str, Path], bool]
    summarise: Callable[[str], FileSummary]
    vendor_table: Callable[[str], VendorTable]
    write: Callable[[WriteJob], WriteOutcome] | None = None
    sides_per_file: int = 2
    #: the grid a writer samples on (``harvey_shack`` | ``specular`` | ``klems`` …), for the export's re-check
    grid_kind: str = ""
    #: ``summarise`` and ``vendor_table`` from one read of the file (the table None when the file holds no table of
    #: nodes), for formats whose two readers would parse the same text: the export's re-check needs both
    summary_and_table: Callable[[str], tuple[FileSummary, VendorTable | None]] | None = None

    @property
    def can_write(self) -> bool:
        return self.write is not None


def first_line_is(magic: str) -> Callable[[str, Path], bool]:
    """A content sniffer (``TableFormat.guess_can_open``) for formats whose first line is a fixed header.

    Parameters
    ----------
    magic : str
        The header line, compared after stripping whitespace.

    Returns
    -------
    callable
        ``guess_can_open(head, path) -> bool``.
    """

    def guess_can_open(head: str, path: Path) -> bool:
        lines = head.splitlines()
        return bool(lines) and lines[0].strip() == magic

    return guess_can_open
