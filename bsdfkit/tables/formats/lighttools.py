"""LightTools tabular BSDF (``.bsdf``, the layout of Light Tec MiniDiff exports): writer and reader.

Layout (whitespace-separated tokens, ``#`` starts a comment)::

    # comments                            bsdfkit writes "# bsdfkit <version>" and its conventions
    Symmetry Asymmetric                   (read also: PlaneSymmetrical, azimuths on one side of the plane of
                                          incidence, completed by their mirror images φ → 180° − φ)
    SpectralContent Monochrome            (or XYZ: blocks carry TristimulusValue TrisX | TrisY | TrisZ)
    ScatterAzimuth <n>  <n azimuths, deg>
    ScatterRadial <m>  <m polar angles, deg>
    DataBegin
    AOI <deg>  POI <deg>  Side Front|Back  Wavelength <nm>  ScatterType BRDF|BTDF  [TristimulusValue TrisY]
    TIS <t>
    <n x m values, azimuth outer, radial inner>
    ... (one block per AOI, side and scatter type)
    DataEnd

Angles [deg] are ordinary spherical angles about the surface normal (ScatterRadial = θs, about the back normal for
BTDF); the plane of incidence is at azimuth 90°: the source is at φ = 90°, the specular and straight-through
directions at φ = 270°. bsdfkit's frame has the source at 180°, so φ_LightTools = φ_bsdfkit − 90° (mod 360).
Values are the BSDF [1/sr] (not cosine-weighted).

What is NOT known from a vendor document (no LightTools manual or vendor-written file was available): the
wavelength unit (bsdfkit writes and reads nm), the meaning of POI (bsdfkit writes 0 and refuses other values), and
whether values are cosine-weighted (bsdfkit assumes not). The TIS line is the hemispherical integral of the block
(bsdfkit writes the source's direct integral, :func:`bsdfkit.tables.grids.tis_reference`).

**Spectral rule.** Monochrome: one wavelength per file (the exported one). Reading an XYZ file, bsdfkit takes the
``TrisY`` blocks (the photopic, luminance-weighted BSDF) and labels them 555 nm.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.conventions import PHOTOPIC_NM
from bsdfkit.core.errors import FormatError
from bsdfkit.core.version import __version__
from bsdfkit.io import atomic
from bsdfkit.io.text import read_text
from bsdfkit.tables import grids, normal_axes
from bsdfkit.tables.format_spec import FileSummary, TableFormat, VendorGrid, VendorTable, WriteJob, WriteOutcome

__all__ = ["LightToolsBsdf", "read_lighttools", "write_lighttools"]

_VALUE_FMT = ".7g"
_TYPE = {"reflection": "BRDF", "transmission": "BTDF"}
_SIDE = {v: k for k, v in _TYPE.items()}


@dataclass(frozen=True, eq=False)
class LightToolsBsdf:
    """Azimuth and radial axes [deg, LightTools frame] and blocks keyed by (face, side): incidences [deg],
    values (incidence, azimuth, radial) [1/sr] and stated TIS per incidence."""

    azimuth: NDArray[np.float64]
    radial: NDArray[np.float64]
    blocks: dict[tuple[str, str], tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]]
    wavelength_nm: float | None
    spectral: str = "Monochrome"
    details: dict = field(default_factory=dict)


def lighttools_bsdf(fn: grids.BsdfFn, theta_i_deg: NDArray[np.float64], sides: tuple[str, ...],
                    wavelength_nm: float | None = None,
                    axes: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None) -> LightToolsBsdf:
    """Blocks of a BSDF callable on ``axes`` (θs, φs [deg], bsdfkit's frame: specular at φs = 0; default: the fixed
    grid), written in the LightTools frame (azimuth φs − 90°).

    Parameters
    ----------
    fn : callable
        ``fn(theta_i_deg, side, directions) -> bsdf`` [1/sr].
    theta_i_deg : ndarray
        Incidences [deg].
    sides : tuple of str
        ``reflection`` and/or ``transmission``.
    wavelength_nm : float, optional
        Wavelength stated in the blocks [nm].
    axes : tuple of ndarray, optional
        (θs [deg], φs [deg]) axes.

    Returns
    -------
    LightToolsBsdf
        Front blocks with values [1/sr] and TIS [-].
    """
    theta_i = np.asarray(theta_i_deg, dtype=np.float64)
    rad, az = axes if axes is not None else normal_axes.fixed_normal_axes()
    rad = np.asarray(rad, dtype=np.float64)
    az = np.sort(np.mod(np.round(np.asarray(az, dtype=np.float64) - 90.0, 9), 360.0))  # the LightTools frame
    blocks = {}
    for side in sides:
        values = np.stack([normal_axes.node_values(fn, float(t), side, rad, az + 90.0) for t in theta_i])
        tis = np.array([grids.tis_reference(fn, float(t), side) for t in theta_i])
        blocks[("Front", side)] = (theta_i, values, tis)
    return LightToolsBsdf(az, rad, blocks, wavelength_nm)


def lighttools_text(bsdf: LightToolsBsdf) -> str:
    """The file text of ``bsdf`` (values to 7 significant digits; 550 nm when no wavelength is given).

    Parameters
    ----------
    bsdf : LightToolsBsdf
        The blocks.

    Returns
    -------
    str
        The ``.bsdf`` text.
    """
    lam = bsdf.wavelength_nm
    out = [f"# bsdfkit {__version__} LightTools BSDF: BSDF in 1/sr (not cosine-weighted); angles in deg about the",
           "# surface normal, plane of incidence at azimuth 90 (specular at 270); wavelength in nm",
           "Symmetry Asymmetric", "SpectralContent Monochrome",
           f"ScatterAzimuth {bsdf.azimuth.size}", " ".join(f"{v:g}" for v in bsdf.azimuth),
           f"ScatterRadial {bsdf.radial.size}", " ".join(f"{v:g}" for v in bsdf.radial), "DataBegin"]
    for (face, side), (theta, values, tis) in bsdf.blocks.items():
        for k, t in enumerate(theta):
            out += [f"AOI {t:g}", "POI 0", f"Side {face}", f"Wavelength {lam if lam is not None else 550.0:g}",
                    f"ScatterType {_TYPE[side]}", f"TIS {tis[k]:{_VALUE_FMT}}"]
            out += [" ".join(format(float(v), _VALUE_FMT) for v in row) for row in values[k]]
    out += ["DataEnd", ""]
    return "\n".join(out)


def write_lighttools(path: str | Path, bsdf: LightToolsBsdf, *, force: bool = False) -> Path:
    """Write atomically; an existing file is replaced only with ``force``.

    Parameters
    ----------
    path : str or Path
        The file to write.
    bsdf : LightToolsBsdf
        The blocks.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        The file written.
    """
    return atomic.write_text(path, lighttools_text(bsdf), force=force)


def _tokens(text: str) -> list[tuple[int, str]]:
    out = []
    for n, line in enumerate(text.splitlines(), start=1):
        for tok in line.split("#", 1)[0].split():
            out.append((n, tok))
    return out


def read_lighttools(path: str | Path) -> LightToolsBsdf:
    """Read a LightTools ``.bsdf``; FormatError names the file, line and keyword.

    Parameters
    ----------
    path : str or Path
        The ``.bsdf`` file.

    Returns
    -------
    LightToolsBsdf
        Axes [deg] and blocks: incidences [deg], values [1/sr], stated TIS [-].
    """
    path = str(path)
    cursor = _Cursor(_tokens(read_text(path, expected="a LightTools BSDF file", legacy="latin-1")), path)
    header = _read_header(cursor)
    symmetry = str(header.get("symmetry", "")).lower()
    if symmetry not in ("asymmetric", "planesymmetrical"):
        raise FormatError("unsupported symmetry", file=path, field="Symmetry",
                          expected="Asymmetric or PlaneSymmetrical", got=str(header.get("symmetry")))
    spectral = str(header.get("spectralcontent", "Monochrome"))
    if spectral.lower() not in ("monochrome", "xyz"):
        raise FormatError("unsupported spectral content", file=path, field="SpectralContent",
                          expected="Monochrome or XYZ", got=spectral)
    if "scatterazimuth" not in header or "scatterradial" not in header:
        raise FormatError("missing axis", file=path, field="ScatterAzimuth/ScatterRadial", expected="both axes")
    az, rad = np.asarray(header["scatterazimuth"]), np.asarray(header["scatterradial"])
    if np.any(np.diff(az) <= 0) or az[0] < 0 or az[-1] > 360 or np.any(np.diff(rad) <= 0) or rad[0] < 0 \
            or rad[-1] > 90:
        raise FormatError("axes must increase within azimuth [0, 360] and radial [0, 90] deg", file=path,
                          field="ScatterAzimuth/ScatterRadial", expected="increasing angles")
    rows, lams = _read_blocks(cursor, (az.size, rad.size), spectral.lower() == "xyz")
    if not rows:
        raise FormatError("no data block", file=path, field="DataBegin", expected="at least one block")
    blocks = {}
    for key, entries in rows.items():
        entries.sort(key=lambda e: e[0])
        blocks[key] = (np.array([e[0] for e in entries]), np.stack([e[1] for e in entries]),
                       np.array([e[2] for e in entries]))
    lam = PHOTOPIC_NM if spectral.lower() == "xyz" else (lams.pop() if len(lams) == 1 else None)
    if symmetry == "planesymmetrical":
        az, blocks = _mirrored(az, blocks)
    return LightToolsBsdf(az, rad, blocks, lam, spectral, {"wavelengths": sorted(lams), "symmetry": symmetry})


class _Cursor:
    """The tokens of a file read one at a time; running out or a bad number is a FormatError on its line."""

    def __init__(self, toks: list[tuple[int, str]], path: str):
        self.toks, self.path, self.k = toks, path, 0

    def take(self, what: str) -> tuple[int, str]:
        if self.k >= len(self.toks):
            raise FormatError("file ends early", file=self.path, line=self.toks[-1][0] if self.toks else 1,
                              field=what, expected=what, got="end of file")
        self.k += 1
        return self.toks[self.k - 1]

    def number(self, what: str) -> float:
        line, tok = self.take(what)
        try:
            v = float(tok)
        except ValueError:
            raise FormatError("not a number", file=self.path, line=line, field=what, expected="a number",
                              got=tok[:40]) from None
        if not np.isfinite(v):
            raise FormatError("not a finite number", file=self.path, line=line, field=what, expected="finite",
                              got=tok)
        return v


def _read_header(cursor: _Cursor) -> dict[str, object]:
    """The keywords up to DataBegin, by lower-case keyword (the axes as arrays of degrees)."""
    header: dict[str, object] = {}
    while True:
        line, key = cursor.take("header keyword")
        low = key.lower()
        if low == "databegin":
            return header
        if low in ("symmetry", "spectralcontent"):
            header[low] = cursor.take(key)[1]
        elif low in ("scatterazimuth", "scatterradial"):
            n = cursor.number(f"{key} count")
            if n != int(n) or n < 1:
                raise FormatError("bad count", file=cursor.path, line=line, field=key, expected="an integer >= 1",
                                  got=n)
            header[low] = np.array([cursor.number(f"{key} values") for _ in range(int(n))])
        else:
            raise FormatError("unknown header keyword", file=cursor.path, line=line, field="header",
                              expected="Symmetry, SpectralContent, ScatterAzimuth, ScatterRadial or DataBegin",
                              got=key[:40])


def _read_blocks(cursor: _Cursor, shape: tuple[int, int], xyz: bool):
    """The data blocks up to DataEnd: rows (AOI, values (azimuth, radial) of ``shape``, stated TIS) per (face,
    side), and the wavelengths stated; of an XYZ file only the photopic (TrisY) blocks."""
    rows: dict[tuple[str, str], list[tuple[float, NDArray[np.float64], float]]] = {}
    lams: set[float] = set()
    block: dict[str, str | float] = {}
    while True:
        line, key = cursor.take("block keyword or DataEnd")
        low = key.lower()
        if low == "dataend":
            return rows, lams
        if low in ("aoi", "poi", "wavelength"):
            block[low] = cursor.number(key)
        elif low in ("side", "scattertype", "tristimulusvalue"):
            block[low] = cursor.take(key)[1]
        elif low == "tis":
            face, side, values, stated = _block(cursor, block, line, shape)
            tri = str(block.get("tristimulusvalue", "")).lower()
            if xyz and tri != "trisy":
                block = {}
                continue  # the photopic (TrisY) blocks only
            t = float(block["aoi"])
            if not 0 <= t < 90:
                raise FormatError("AOI out of range", file=cursor.path, line=line, field=f"block AOI {t}",
                                  expected="[0, 90) deg", got=t)
            if "wavelength" in block:
                lams.add(float(block["wavelength"]))
            rows.setdefault((face, side), []).append((t, values, stated))
            block = {}
        else:
            raise FormatError("unknown block keyword", file=cursor.path, line=line, field="data block",
                              expected="AOI, POI, Side, Wavelength, ScatterType, TristimulusValue, TIS or DataEnd",
                              got=key[:40])


def _block(cursor: _Cursor, block: dict[str, str | float], line: int, shape: tuple[int, int]):
    """The TIS and values of the block whose keywords are ``block`` (TIS keyword on ``line``), checked: returns
    (face, side, values, stated TIS)."""
    path = cursor.path
    stated = cursor.number("TIS")
    where = f"block AOI {block.get('aoi', '?')}"
    for need in ("aoi", "scattertype"):
        if need not in block:
            raise FormatError("block without " + need.upper(), file=path, line=line, field=where,
                              expected=f"{need} before TIS")
    if float(block.get("poi", 0.0)) != 0.0:
        raise FormatError("POI other than 0 is not supported (its meaning is not documented)", file=path,
                          line=line, field=where, expected="POI 0", got=block["poi"])
    stype = str(block["scattertype"]).upper()
    if stype not in _SIDE:
        raise FormatError("unknown scatter type", file=path, line=line, field=where, expected="BRDF or BTDF",
                          got=stype)
    face = str(block.get("side", "Front")).capitalize()
    if face not in ("Front", "Back"):
        raise FormatError("unknown side", file=path, line=line, field=where, expected="Front or Back", got=face)
    values = np.array([cursor.number(f"{where} values") for _ in range(shape[0] * shape[1])]).reshape(shape)
    if np.any(values < 0):
        raise FormatError("negative BSDF value", file=path, line=line, field=where, expected=">= 0",
                          got=float(values.min()))
    return face, _SIDE[stype], values, stated


def _mirrored(az: NDArray[np.float64], blocks: dict) -> tuple[NDArray[np.float64], dict]:
    """A PlaneSymmetrical file's azimuths [deg] completed by their mirror images about the plane of incidence
    (azimuths 90°/270°: φ → 180° − φ), each mirrored azimuth holding its original's values; where a file gives both
    an azimuth and its mirror, its own value is kept."""
    every = np.concatenate([az, np.mod(180.0 - az, 360.0)])
    source = np.concatenate([np.arange(az.size), np.arange(az.size)])
    _, first = np.unique(np.round(every, 9), return_index=True)  # sorted; the file's own azimuths come first
    take = source[first]
    return every[first], {k: (t, v[:, take, :], tis) for k, (t, v, tis) in blocks.items()}


# ------------------------------------------------------------------------------------------- registry hooks
def _write_job(job: WriteJob) -> WriteOutcome:
    theta_i = np.asarray(job.theta, dtype=np.float64)
    theta, phi, info = normal_axes.normal_axes(job.fn, theta_i, job.sides, job.settings)
    bsdf = lighttools_bsdf(job.fn, theta_i, tuple(job.sides), job.settings.wavelength_nm, axes=(theta, phi))
    write_lighttools(job.path, bsdf, force=job.force)
    info = normal_axes.describe(info, bsdf.radial.size, bsdf.azimuth.size)
    return WriteOutcome(None, dict(info, azimuth=info.pop("phi"), radial_nodes=info.pop("theta")))


def _key(face: str, side: str) -> str:
    return side if face == "Front" else f"{side}@back"


def _summarise(path: str) -> FileSummary:
    bsdf = read_lighttools(path)
    theta = sorted({float(t) for v in bsdf.blocks.values() for t in v[0]})
    stated = {}
    for (face, side), (t, _, tis) in bsdf.blocks.items():
        stated[_key(face, side)] = [float(tis[list(t).index(u)]) if u in list(t) else float("nan") for u in theta]
    front = [_key(f, s) for f, s in bsdf.blocks if f == "Front"]
    return FileSummary(format="lighttools", path=path, incidences_deg=theta,
                       tis_computed={k: [float("nan")] * len(theta) for k in front}, tis_stated=stated,
                       details={"own_quadrature": False, "spectral_content": bsdf.spectral,
                                "wavelength_nm": bsdf.wavelength_nm,
                                "back_blocks": [_key(f, s) for f, s in bsdf.blocks if f == "Back"]})


def _vendor_table(path: str) -> VendorTable:
    bsdf = read_lighttools(path)
    a, r = np.meshgrid(bsdf.azimuth, bsdf.radial, indexing="ij")
    keep = (a < 360.0 - 1e-9) | (r < 1e-9)  # azimuth 360 repeats 0
    out = []
    for (face, side), (theta, values, _) in bsdf.blocks.items():
        if face != "Front":
            continue
        out.append(VendorGrid("directions", side, theta, r[keep], np.mod(a[keep] + 90.0, 360.0), values[:, keep]))
    if not out:
        raise FormatError("the file holds back-side blocks only", file=path, field="Side", expected="Front blocks")
    return VendorTable("lighttools", tuple(out), bsdf.wavelength_nm, {"spectral_content": bsdf.spectral})


def header_words(head: str) -> list[str]:
    """The lower-case header keywords and values of a Zemax-like keyword file, up to ``ScatterAzimuth``.

    Parameters
    ----------
    head : str
        The start of the file.

    Returns
    -------
    list of str
        The words before ``ScatterAzimuth`` (empty without one).
    """
    words = [t.lower() for _, t in _tokens(head)]
    return words[:words.index("scatterazimuth")] if "scatterazimuth" in words else []


def is_lighttools_header(head: str) -> bool:
    """A LightTools header: ``ScatterAzimuth`` comes before any Zemax-only keyword (SampleRotation,
    AngleOfIncidence, ScatterType, Source: a LightTools file states those per block or not at all).

    Parameters
    ----------
    head : str
        The start of the file.

    Returns
    -------
    bool
        True for a LightTools header.
    """
    words = header_words(head)
    return bool(words) and words[0] in ("symmetry", "spectralcontent") and not any(
        w in ("samplerotation", "angleofincidence", "scattertype", "source") for w in words)


def _guess_can_open(head: str, path: Path) -> bool:
    return is_lighttools_header(head)


FORMAT = TableFormat(name="lighttools", title="LightTools BSDF", extensions=(".bsdf",),
                     guess_can_open=_guess_can_open, summarise=_summarise, vendor_table=_vendor_table,
                     write=_write_job, sides_per_file=2, grid_kind="normal")
