"""The parts of a WINDOW-schema BSDF XML document that bsdfkit's two XML writers share (the Klems matrix,
:mod:`bsdfkit.tables.formats.bsdfxml`, and the tensor tree, :mod:`bsdfkit.tables.formats.bsdfxml_tree`): the
document head up to the incident data structure, one ``WavelengthData`` element, and the tail. Each writer adds
only what its basis needs (the Klems ``AngleBasis`` blocks, the rows of the matrix or the tree text)."""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime
from xml.sax.saxutils import escape

from bsdfkit.core.version import __version__

__all__ = ["TAIL", "head", "wavelength_data"]

#: the closing elements of the document
TAIL = ("</Layer>", "</Optical>", "</WindowElement>", "")


def head(basis_note: str, name: str, wavelength_nm: float | None, structure: str, comments: Iterable[str],
         generated_at: datetime | None = None) -> list[str]:
    """Lines from the XML declaration to ``<IncidentDataStructure>`` inside the open ``<DataDefinition>``.

    Parameters
    ----------
    basis_note
        What the file holds, for the first comment (e.g. ``"Klems full basis"``).
    name
        Material name (escaped here).
    wavelength_nm
        The single wavelength [nm] of the ``Visible`` block (None: unknown, written as ``nan``).
    structure
        ``IncidentDataStructure`` (``Columns``, ``TensorTree3``).
    comments
        bsdfkit's own facts, one XML comment each (``--`` is not allowed inside a comment).
    generated_at
        Time stamp of the first comment (default: now).
    """
    when = (generated_at or datetime.now()).replace(microsecond=0).isoformat()
    lam = "nan" if wavelength_nm is None else f"{wavelength_nm:g}"
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<WindowElement xmlns="http://windows.lbl.gov" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
           'xsi:schemaLocation="http://windows.lbl.gov BSDF-v1.4.xsd">',
           f"<!-- written by bsdfkit {__version__} on {when}; {basis_note}, BSDF in 1/sr -->",
           f"<!-- bsdfkit wavelength_nm={lam} (the single wavelength held by the Visible block) -->"]
    out += ["<!-- " + line.replace("--", "- -") + " -->" for line in comments]
    out += ["<WindowElementType>System</WindowElementType>", "<FileType>BSDF</FileType>", "<Optical>", "<Layer>",
            "<Material>", f"<Name>{escape(name)}</Name>", "<Manufacturer>bsdfkit</Manufacturer>",
            '<Thickness unit="Millimeter">0</Thickness>', "<DeviceType>Other</DeviceType>", "</Material>",
            "<DataDefinition>", f"<IncidentDataStructure>{structure}</IncidentDataStructure>"]
    return out


def wavelength_data(direction: str, label: str, basis_lines: Sequence[str], data_lines: Sequence[str]) -> list[str]:
    """One ``WavelengthData`` element: the block of ``direction`` (``Reflection Front`` …) under the wavelength
    ``label``, its basis elements and the lines of its ``ScatteringData`` (BRDF or BTDF by the direction).

    Parameters
    ----------
    direction : str
        ``Reflection Front``, ``Transmission Back`` …
    label : str
        Text of the ``Wavelength`` element (e.g. ``Visible``).
    basis_lines : sequence of str
        The block's basis elements.
    data_lines : sequence of str
        Lines of the ``ScatteringData`` element (BSDF in 1/sr).

    Returns
    -------
    list of str
        The element's lines.
    """
    kind = "BRDF" if direction.startswith("Reflection") else "BTDF"
    return ["<WavelengthData>", "<LayerNumber>System</LayerNumber>",
            f'<Wavelength unit="Integral">{label}</Wavelength>',
            "<SourceSpectrum>CIE Illuminant D65 1nm.ssp</SourceSpectrum>",
            "<DetectorSpectrum>ASTM E308 1931 Y.dsp</DetectorSpectrum>", "<WavelengthDataBlock>",
            f"<WavelengthDataDirection>{direction}</WavelengthDataDirection>", *basis_lines,
            f"<ScatteringDataType>{kind}</ScatteringDataType>", "<ScatteringData>", *data_lines,
            "</ScatteringData>", "</WavelengthDataBlock>", "</WavelengthData>"]
