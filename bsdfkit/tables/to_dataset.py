"""Vendor BSDF files into the calibrated dataset schema, and the ``ingest`` / ``convert`` front ends.

* :func:`source_kind` tells a raw-scan folder, a netCDF dataset, a vendor file and a text table apart;
  :func:`ingest` reads any of them into the calibrated dataset (``bsdfkit ingest``, :func:`bsdfkit.api.ingest`;
  vendor files by :func:`bsdfkit.tables.vendor.vendor_dataset`).
* :func:`convert` writes any readable source as a table of any registered format (``bsdfkit convert``)
  and checks the TIS of the re-read file against the source's. Elastic data — a vendor file, a text table, a
  dataset — are reconstructed once by :mod:`bsdfkit.reduction.hemispherical` (``elastic_source``): the written
  table samples that reconstruction, the source TIS is the value ``bsdfkit tis`` and ``bsdfkit read`` report,
  and the written file is integrated as ``bsdfkit read`` integrates it. A phosphor scan's interaction goes
  through :func:`bsdfkit.reduction.tis.hemisphere_bsdf_fn`.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from bsdfkit.core.conventions import SIDES
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io import atomic
from bsdfkit.io.text import existing_source
from bsdfkit.measurement.calibrate import calibrate
from bsdfkit.measurement.raw_scan import read_scan
from bsdfkit.measurement.table import read_table
from bsdfkit.reduction.hemispherical import elastic_source, reduction_kind
from bsdfkit.reduction.tis import hemisphere_bsdf_fn
from bsdfkit.tables import registry
from bsdfkit.tables.export import FORMATS, ExportResult, ExportSettings, export, open_bsdf_dataset, read_any
from bsdfkit.tables.grids import GridTolerance, PiecewiseConstant, Pointwise, piecewise_per_side
from bsdfkit.tables.registry import sniff_format
from bsdfkit.tables.vendor import checked_vendor_dataset, vendor_dataset

__all__ = ["VENDOR_FORMATS", "ConvertResult", "source_kind", "vendor_dataset", "ingest",
           "convert", "TABLE_OPTIONS"]

#: the readable formats of the registry (:mod:`bsdfkit.tables.registry`)
VENDOR_FORMATS: tuple[str, ...] = registry.names()
#: Options :func:`ingest` passes to the text-table and vendor readers.
TABLE_OPTIONS = ("quantity", "side", "relative_std", "wavelength_nm", "incidence_deg", "phi_i_deg", "zeros",
                 "sample", "face", "block")
_NETCDF_MAGIC = (b"\x89HDF", b"CDF\x01", b"CDF\x02")
_MATCH_DEG = 1e-6

BsdfFn = Callable[[float, str, NDArray[np.float64]], NDArray[np.float64]]


# ------------------------------------------------------------------------------------------- sniffing
def source_kind(path: str | Path) -> str:
    """What kind of source ``path`` is, sniffed from its contents.

    Parameters
    ----------
    path
        A file or a raw export folder.

    Returns
    -------
    str
        ``raw-scan`` (a folder) | ``netcdf`` | a registered table format (``zemax``, ``tracepro``, ``asap`` …,
        :mod:`bsdfkit.tables.registry`) | ``table`` (any other text file).
    """
    p = existing_source(path)
    if p.is_dir():
        return "raw-scan"
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=p) from None
    if head.startswith(_NETCDF_MAGIC):
        return "netcdf"
    try:
        return sniff_format(p)
    except FormatError:
        return "table"


# ------------------------------------------------------------------------------------------- ingest
def ingest(path: str | Path, **options: Any) -> xr.Dataset:
    """Any measurement into the calibrated BSDF dataset: a raw export folder (read + calibrate), a text table
    (:func:`bsdfkit.measurement.table.read_table`), a vendor file (:func:`vendor_dataset`) or a bsdfkit
    netCDF dataset.

    Parameters
    ----------
    path
        The source (kind sniffed by :func:`source_kind`).
    **options
        Reader options (:data:`TABLE_OPTIONS`; ``None`` values are dropped), for text tables and vendor files
        only; vendor files take no ``incidence_deg`` or ``phi_i_deg``.

    Returns
    -------
    xarray.Dataset
        The calibrated BSDF dataset (``bsdf``/``bsdf_std`` [1/sr], angles [deg]). A vendor file that states a
        TIS gets ``attrs['tis_stated_json']``, stated vs integrated, and a
        :class:`bsdfkit.core.errors.StatedTisWarning` where they disagree
        (:func:`bsdfkit.tables.vendor.check_stated_tis`).
    """
    kind = source_kind(path)
    given = {k: v for k, v in options.items() if v is not None}
    unknown = [k for k in given if k not in TABLE_OPTIONS]
    if unknown:
        raise InputError("unknown ingest option", field=", ".join(unknown), expected=", ".join(TABLE_OPTIONS))
    if kind in ("raw-scan", "netcdf") and given:
        raise InputError(f"options apply to text tables and vendor files, not to a {kind}", file=path,
                         field=", ".join(_flag(k) for k in given), expected="no options")
    if kind == "raw-scan":
        return calibrate(read_scan(path))
    if kind == "netcdf":
        return open_bsdf_dataset(path)  # schema, units, quantity and values checked (docs/errors.md)
    if kind in VENDOR_FORMATS:
        bad = [k for k in given if k in ("incidence_deg", "phi_i_deg")]
        if bad:
            raise InputError("vendor files state their incidences", file=path, field=", ".join(bad),
                             expected="no --incidence/--phi-i")
        # a file whose own TIS lines disagree with its data warns (StatedTisWarning) and records both
        return checked_vendor_dataset(path, **given)
    for key in ("face", "block"):
        if key in given:
            raise InputError(f"a measured table holds one {key}", file=path, field=f"--{key}",
                             expected=f"no --{key} (it chooses the {key} of a BSDF XML file)", got=given[key])
    return read_table(path, **given)


def _flag(option: str) -> str:
    """The command-line flag of an ingest option: ``incidence_deg`` → ``--incidence`` (the flag states no unit)."""
    return "--" + option.removesuffix("_deg").removesuffix("_nm").replace("_", "-")


# ------------------------------------------------------------------------------------------- convert
@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert` wrote and how the TIS of the written table compares with the source's.

    ``tis_original`` maps side → TIS per incidence of the source (the hemispherical engine's value, as ``bsdfkit
    tis`` and ``bsdfkit read`` report it; a phosphor interaction: the direct integral of its reconstruction);
    ``tis_written`` the same for the re-read output. ``worst_relative_difference`` is the largest |written/original − 1|
    over sides and incidences with a TIS above 1e-12.

    The table is checked before it takes its name: ``committed`` is True when it passed and stands at
    ``export.path`` (the requested output); after a failed check nothing was written there (an earlier file is
    untouched), and the table is either gone or, when asked for, kept at ``failed_path``.
    """

    source: str
    source_kind: str
    export: ExportResult
    incidences_deg: tuple[float, ...]
    tis_original: dict[str, list[float]]
    tis_written: dict[str, list[float]]
    worst_relative_difference: float
    tolerance: float
    wavelength_nm: float | None
    notes: tuple[str, ...] = ()
    #: True when the table passed its check and was moved to ``export.path``
    committed: bool = True
    #: where a table that failed its check was kept (``keep_failed``), else None
    failed_path: str | None = None

    @property
    def ok(self) -> bool:
        """True when every TIS of the written table is within ``tolerance`` of the source's."""
        return self.worst_relative_difference <= self.tolerance

    def to_dict(self) -> dict[str, Any]:
        """The result as a JSON-ready dict.

        Returns
        -------
        dict
            The fields (``incidences_deg`` [deg], ``wavelength_nm`` [nm], TIS values [-]), ``ok``,
            ``committed`` and ``failed_path``, and the export's ``format``, ``path`` (the requested output),
            ``sides``, ``size_bytes``, ``grid``, peak errors and ``tis_reference_of_callable``.
        """
        return {"source": self.source, "source_kind": self.source_kind, "format": self.export.format,
                "path": self.export.path, "sides": list(self.export.sides),
                "incidences_deg": list(self.incidences_deg), "tis_original": self.tis_original,
                "tis_written": self.tis_written, "tis_reference_of_callable": self.export.tis_source,
                "worst_relative_difference": self.worst_relative_difference, "tolerance": self.tolerance,
                "ok": self.ok, "committed": self.committed, "failed_path": self.failed_path,
                "wavelength_nm": self.wavelength_nm, "notes": list(self.notes),
                "size_bytes": self.export.size_bytes, "grid": self.export.grid,
                "peak_error": self.export.peak_error, "worst_peak_error": self.export.worst_peak_error}


def _dispatch(fns: dict[str, BsdfFn]) -> BsdfFn:
    def fn(theta_i_deg: float, side: str, directions: NDArray[np.float64]) -> NDArray[np.float64]:
        if side not in fns:
            raise ValidationError("the source holds no data for this side", field="side",
                                  expected=" or ".join(fns), got=side)
        return np.asarray(fns[side](theta_i_deg, side, directions), dtype=np.float64)

    # the sources here are NumPy reconstructions (the hemispherical engine, a phosphor scan's hemisphere): each
    # direction's value is its own, so the grids evaluate them without padding; a basis file's cells stay cells
    return piecewise_per_side(fns, fn) or Pointwise(fn)


class _Asked(NamedTuple):
    """What :func:`convert` was asked for about its source: its label and kind, the side, wavelength, band and
    interaction."""

    label: str
    kind: str
    side: str | None
    wavelength: float | None
    band: tuple[float, float] | None
    interaction: str | None


class _Sourced(NamedTuple):
    """The source's BSDF per side, the incidences per side, the engine's TIS and its incidences (elastic
    datasets), the wavelength written [nm] and the notes."""

    fns: dict[str, Any]
    theta_sets: list[set]
    engine_tis: dict[str, list[float]] | None
    src_t: dict[str, list[float]]
    chosen_lambda: float | None
    notes: list[str]


def _source_dataset(source: str | Path | xr.Dataset, asked: _Asked, table_options: dict[str, Any]) -> xr.Dataset:
    """The source as a calibrated dataset (a vendor file or text table ingested)."""
    if asked.kind in VENDOR_FORMATS:
        extra = {k: v for k, v in table_options.items() if v is not None}
        face = extra.pop("face", None)  # the face and spectral block of a BSDF XML file
        block = extra.pop("block", None)
        if extra or asked.band is not None or asked.interaction is not None:
            raise InputError("options apply to datasets and text tables, not to a vendor file", file=asked.label,
                             field=", ".join([*extra, *(["band"] if asked.band else []),
                                              *(["interaction"] if asked.interaction else [])]))
        # a vendor file is integrated and written through the same reconstruction as its ingested dataset:
        # what bsdfkit read and bsdfkit tis report for it is what the written table is checked against
        return vendor_dataset(source, wavelength_nm=asked.wavelength, face=face, block=block)
    if isinstance(source, xr.Dataset):
        return source
    opts = {k: v for k, v in table_options.items() if v is not None}
    if asked.kind == "table" and "side" not in opts and asked.side in SIDES:
        opts["side"] = asked.side
    return ingest(source, **opts)


def _source_fns(ds: xr.Dataset, asked: _Asked) -> _Sourced:
    """The dataset's BSDF per asked side: the hemispherical engine's (elastic scatter) or an interaction's."""
    label, side, wavelength, interaction = asked.label, asked.side, asked.wavelength, asked.interaction
    sides_ds = [s for s in SIDES if s in set(map(str, ds["side"].values))]
    use_sides = sides_ds if side in (None, "both") else [side]
    for s in use_sides:
        if s not in sides_ds:
            raise InputError("the source holds no data for this side", file=label, field="--side",
                             expected=" or ".join(sides_ds), got=s)
    fns, theta_sets = {}, []
    if reduction_kind(ds) != "hemispherical":
        if interaction is None:
            raise InputError("a calibrated scan holds several interactions; choose one", file=label,
                             field="--interaction", expected="bibs, biys or yiys")
        for s in use_sides:
            fns[s] = hemisphere_bsdf_fn(ds, interaction, s)
            theta_sets.append(set(np.round(fns[s].incidences_deg, 9)))  # type: ignore[attr-defined]
        return _Sourced(fns, theta_sets, None, {}, None,
                        [f"interaction {interaction}, reconstructed by bsdfkit.reduction.tis.hemisphere_bsdf_fn"])
    if interaction is not None:
        raise InputError("--interaction applies to calibrated phosphor scans with blue/yellow "
                         "configurations", file=label, field="--interaction", got=interaction)
    if ds.sizes.get("wavelength", 0) == 1 and not np.isfinite(ds["wavelength"].values[0]) \
            and wavelength is not None:
        ds = ds.assign_coords(wavelength=[float(wavelength)])
    src = elastic_source(ds, use_sides, wavelength, asked.band)
    # a file in an angle basis (every profile integrated by its basis sum) is piecewise constant: written as such
    for s in use_sides:  # a file in an angle basis is written as piecewise constant, checked against its basis sum
        fns[s] = PiecewiseConstant(src.fn, src.exact_tis, src.basis) if src.piecewise_constant else src.fn
        theta_sets.append(set(np.round(src.incidences_deg[s], 9)))
    if src.piecewise_constant:  # the file's own cells, not a reconstruction
        note = (f"values at {src.what}; resampled from the file's own angle basis (exact cell lookup, each table "
                "node the projected-solid-angle mean of the cells under it; no reconstruction)")
    else:
        note = (f"values at {src.what}; reconstructed by the hemispherical engine "
                "(bsdfkit.reduction.hemispherical: " + ", ".join(sorted(set(
                    m for ms in src.methods.values() for m in ms))) + ")")
    return _Sourced(fns, theta_sets, src.tis, src.incidences_deg, src.wavelength_nm, [note])


def _back_face(source: Any, to: str, asked: _Asked, table_options: dict[str, Any], settings: ExportSettings,
               sides: list[str]) -> tuple[Any, dict[str, dict[float, float]]] | None:
    """The back face of a BSDF XML source that holds both faces, for a BSDF XML output that would otherwise lose
    it: its BSDF callable (exact cell lookup) and its hemispherical values per side and incidence [-]; None when
    the output is not BSDF XML, a face was chosen, the back is mirrored or the source holds one face."""
    if to != "bsdfxml" or asked.kind != "bsdfxml" or table_options.get("face") is not None \
            or settings.xml_back != "none" or settings.xml_back_fn is not None:
        return None
    try:
        ds = vendor_dataset(source, wavelength_nm=asked.wavelength, face="back", block=table_options.get("block"))
    except InputError:  # no back face in the file
        return None
    if ds.attrs.get("faces_note", "").startswith("the file holds back-side blocks only"):
        return None  # those are already the face written as the front
    sourced = _source_fns(ds, _Asked(asked.label, asked.kind, "both", asked.wavelength, None, None))
    if any(s not in sourced.fns for s in sides):
        return None
    values = {s: {round(t, 6): v for t, v in zip(sourced.src_t[s], sourced.engine_tis[s])} for s in sides}
    return _dispatch({s: sourced.fns[s] for s in sides}), values


def _written_sides_and_incidences(to: str, asked: _Asked, sourced: _Sourced,
                                  theta_i_deg: Sequence[float] | None) -> tuple[list[str], list[float]]:
    """The sides and incidences [deg] to write: the source's common incidences, or those asked for."""
    label, side, fns = asked.label, asked.side, sourced.fns
    common = sorted(set.intersection(*sourced.theta_sets))
    if not common:
        raise InputError("the sides share no incidence", file=label, field="theta_i",
                         expected="a common incidence, or --side")
    thetas = [float(t) for t in common]
    sides = list(fns) if side in (None, "both") else [side]
    for s in sides:
        if s not in fns:
            raise InputError("the source holds no data for this side", file=label, field="--side",
                             expected=" or ".join(fns), got=s)
    if registry.get(to).sides_per_file == 1 and len(sides) > 1:
        raise InputError(f"a {registry.get(to).title} file holds one side; the source has both", file=label,
                         field="--side", expected="--side reflection or --side transmission", got="both")
    if theta_i_deg is not None:
        wanted = [float(t) for t in theta_i_deg]
        missing = [t for t in wanted if not any(abs(t - u) <= _MATCH_DEG for u in thetas)]
        if missing:
            raise InputError("incidence not in the source", file=label, field="--incidences",
                             expected="some of " + ", ".join(f"{t:g}" for t in thetas), got=missing[0])
        thetas = sorted(wanted)
    return sides, thetas


def _table_settings(settings: ExportSettings, to: str, chosen_lambda: float | None, thetas: list[float],
                    label: str) -> tuple[ExportSettings, list[str]]:
    """The export settings of the converted table (incidences, wavelength label, comment) and a note on them."""
    notes = []
    tp = settings.tracepro
    if chosen_lambda is not None and np.isfinite(chosen_lambda) and to == "tracepro":
        tp = replace(tp, wavelength_um=float(chosen_lambda) / 1000.0)
    elif to == "tracepro":
        notes.append(f"wavelength unknown: TracePro Wavelength column set to {tp.wavelength_um:g} um")
    if chosen_lambda is not None and np.isfinite(chosen_lambda) and settings.wavelength_nm is None:
        settings = replace(settings, wavelength_nm=float(chosen_lambda))  # the label of a one-wavelength table
    settings = replace(settings, theta_i_deg=tuple(thetas), tracepro=tp,
                       comments=tuple(settings.comments) + (f"converted by bsdfkit from {Path(label).name}",))
    return settings, notes


def _worst_difference(tis_original: dict[str, list[float]], tis_written: dict[str, list[float]],
                      thetas: list[float], read_thetas: list[float]) -> float:
    """Largest |TIS written / TIS original − 1| over the sides and incidences (inf: written where 0 was)."""
    worst = 0.0
    for s in tis_original:
        for k, t in enumerate(thetas):
            j = int(np.argmin(np.abs(np.asarray(read_thetas) - t)))
            a, b = tis_original[s][k], tis_written[s][j]
            if abs(a) > 1e-12:
                worst = max(worst, abs(b / a - 1.0))
            elif abs(b) > 1e-9:
                worst = max(worst, float("inf"))
    return worst


def convert(source: str | Path | xr.Dataset, to: str, path: str | Path, force: bool = False, *,
            side: str | None = None, wavelength_nm: float | None = None, band_nm: tuple[float, float] | None = None,
            interaction: str | None = None, theta_i_deg: Sequence[float] | None = None,
            settings: ExportSettings | None = None, tolerance: float = 0.01, keep_failed: bool = False,
            **table_options: Any) -> ConvertResult:
    """Write any readable source as a ``to`` (tracepro | zemax | asap) table and check its TIS.

    The table is written to a hidden staging file in the output's folder, re-read and checked there, and moved to
    ``path`` only when it passed (:class:`bsdfkit.io.atomic.StagedFile`). A table that fails its check never
    stands at ``path`` and an earlier file there stays as it was, even with ``force``; the result says so
    (``ok`` and ``committed`` False).

    Parameters
    ----------
    source
        A vendor file or a text table or raw export (ingested first; table options
        such as ``quantity``, ``side``, ``relative_std`` go to :func:`ingest`), a netCDF dataset or a Dataset.
    to, path, force
        Target format and file; an existing file is replaced only with ``force``.
    side
        ``reflection`` | ``transmission`` | ``both`` (default: every side of the source; Zemax holds one).
    wavelength_nm, band_nm
        For spectral datasets: the wavelength [nm] to write, or a (low, high) band whose wavelengths are
        averaged; a monochrome table without wavelength takes ``wavelength_nm`` as its label.
    interaction
        For calibrated raw scans (configurations blue/yellow): bibs, biys or yiys, reconstructed by
        :func:`bsdfkit.reduction.tis.hemisphere_bsdf_fn`.
    theta_i_deg
        Incidences to write [deg] (default: all of the source).
    settings
        Further :class:`bsdfkit.tables.export.ExportSettings` (axes, grid, Zemax symmetry, TracePro options).
        Without settings the auto grid's TIS tolerance is half of ``tolerance`` (docs/exports.md, Grid resolution).
        ``settings.allow_nonphysical`` writes a source the plausibility gate refuses (:mod:`bsdfkit.tables.plausible`:
        a hemispherical value, or R + T, above 1 beyond measurement noise; refused before anything is written).
    tolerance
        Largest accepted |TIS written / TIS original − 1| [-] (default 0.01): a table beyond it is not committed.
    keep_failed
        Keep a table that failed its check as ``<stem>.failed-check<suffix>`` beside ``path``
        (:func:`bsdfkit.io.atomic.failed_check_path`; checked like ``path`` before computing) instead of removing
        it.
    **table_options
        Reader options for a text table or raw export, passed to :func:`ingest` (``None`` values dropped);
        refused for a vendor file.

    Returns
    -------
    ConvertResult
        What was written (``committed``, ``failed_path``) and the TIS of the written table against the source's.
    """
    if to not in FORMATS:
        raise ValidationError("unknown target format", field="--to", expected=" | ".join(FORMATS), got=to)
    if side is not None and side not in ("reflection", "transmission", "both"):
        raise ValidationError("unknown side", field="--side", expected="reflection | transmission | both", got=side)
    inputs = [source] if isinstance(source, (str, Path)) else ()
    failed = atomic.failed_check_path(path) if keep_failed else None
    if failed is not None:  # a second possible output: refused before computing, as the first
        atomic.check_writable(failed, force, inputs=inputs)
    # the table is written, re-read and checked under a hidden name beside path, and takes the name only if it
    # passed: a failed table never stands at path, and an earlier output there is replaced only by a checked one
    with atomic.StagedFile(path, force, inputs=inputs) as staged:  # path checked here, before computing
        if settings is None and 0.0 < tolerance < 2.0:  # the auto grid's TIS error: half of the check it must pass
            settings = ExportSettings(grid_tolerance=GridTolerance(tis_rtol=0.5 * float(tolerance)),
                                      zemax_symmetry="auto")
        # a converted table keeps the source's own symmetry (Zemax), as the command line's default does
        settings = settings or ExportSettings(zemax_symmetry="auto")
        label = "dataset" if isinstance(source, xr.Dataset) else str(source)
        kind = "dataset" if isinstance(source, xr.Dataset) else source_kind(source)
        asked = _Asked(label, kind, side, wavelength_nm, band_nm, interaction)
        source_ds = _source_dataset(source, asked, table_options)
        sourced_ds_attrs = dict(source_ds.attrs)
        sourced = _source_fns(source_ds, asked)
        fns, engine_tis, src_t, chosen_lambda = sourced.fns, sourced.engine_tis, sourced.src_t, sourced.chosen_lambda
        sides, thetas = _written_sides_and_incidences(to, asked, sourced, theta_i_deg)
        settings, settings_notes = _table_settings(settings, to, chosen_lambda, thetas, label)
        notes = sourced.notes + settings_notes
        block = str(sourced_ds_attrs.get("block", "")) if asked.kind == "bsdfxml" else ""
        if to == "bsdfxml" and block and block.lower() != "visible":  # never called Visible when it is not
            settings = replace(settings, xml_label=block)
            notes.append(f"the source's {block} block written under its own label (Radiance reads the Visible one)")
        back = _back_face(source, to, asked, table_options, settings, sides)
        if back is not None:  # a BSDF XML file's back face, kept in a BSDF XML output
            settings = replace(settings, xml_back_fn=back[0])
            notes.append("the source's back face written as the Back blocks (its own values, not the front's)")
        # force: the staging file is this process's own (path itself was checked above)
        exported = export(_dispatch({s: fns[s] for s in sides}), to, "", "both" if len(sides) > 1 else sides[0],
                          staged.path, True, settings=settings)
        exported = replace(exported, path=str(path))  # named by the output it was written for, not its staging file
        dropped = [t for t in thetas if not any(abs(t - u) <= _MATCH_DEG for u in exported.incidences_deg)]
        if dropped:  # a format on its own incidences (BSDF XML: the Klems band centres) holds only some of them
            notes.append(f"incidences not held by the {to} grid (not compared): "
                         + ", ".join(f"{t:g}" for t in dropped))
            thetas = [t for t in thetas if t not in dropped]
        if engine_tis is not None:  # a dataset: what bsdfkit tis reports for it, at the written wavelength
            tis_original = {s: [engine_tis[s][[round(u, 6) for u in src_t[s]].index(round(t, 6))] for t in thetas]
                            for s in sides}
        else:  # a phosphor interaction: the direct integral of its reconstruction
            tis_original = {s: list(exported.tis_source[s]) for s in sides}
        read_thetas = list(exported.incidences_deg)  # export re-read the written file as bsdfkit read does
        tis_written = {s: [float(v) for v in exported.tis_table[s]] for s in sides}
        if back is not None:  # the Back blocks are checked as the front ones, against the source's back face
            reread = read_any(staged.path)
            for s in sides:
                tis_original[f"{s}@back"] = [back[1][s][round(t, 6)] for t in thetas]
                tis_written[f"{s}@back"] = [reread.tis_computed[f"{s}@back"][int(np.argmin(np.abs(
                    np.asarray(reread.incidences_deg) - t)))] for t in read_thetas]
        worst = _worst_difference(tis_original, tis_written, thetas, read_thetas)
        result = ConvertResult(source=label, source_kind=kind, export=exported, incidences_deg=tuple(thetas),
                               tis_original=tis_original, tis_written=tis_written, worst_relative_difference=worst,
                               tolerance=float(tolerance), wavelength_nm=chosen_lambda, notes=tuple(notes))
        if result.ok:
            staged.commit()
            return result
        kept = staged.keep_as(failed) if failed is not None else None
        # not kept: the staged table is removed on leaving the block
    return replace(result, committed=False, failed_path=None if kept is None else str(kept))
