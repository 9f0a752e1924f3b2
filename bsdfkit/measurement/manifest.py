"""``manifest.toml`` of a raw goniometer export: parse and validate (docs/raw-format.md).

Each problem raises :class:`bsdfkit.core.errors.InputError` naming the manifest file and the dotted key.
Besides types, values are checked for physical plausibility (docs/raw-format.md "Plausibility checks"):
attenuator transmittance in (0, 1], full scale and gain > 0, wavelengths in nm, and a bounded grid size.
A ``[[band_series]]`` entry (a monochromator scan) expands into one configuration per band.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bsdfkit.core.conventions import WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io.text import read_toml
from bsdfkit.measurement.instrument import Instrument

FORMAT_NAME = "bsdfkit-raw-scan"
SUPPORTED_VERSIONS = (1,)
#: Largest spectrometer grid accepted (pixels); real spectrometers have a few thousand.
MAX_WAVELENGTHS = 100_000
#: Most bands of one ``[[band_series]]`` (a monochromator scan in 0.5 nm steps over 380-780 nm has 801).
MAX_BAND_SERIES = 1000
#: The placeholder for the band centre in a band series' file names.
CENTER_PLACEHOLDER = "{center}"


@dataclass(frozen=True)
class ConfigurationEntry:
    name: str
    description: str
    incident_band_nm: tuple[float, float]
    scan_file: Path
    reference_file: Path
    reference_attenuation: float
    series: str = ""
    excitation_nm: float = math.nan  # nominal band centre of a band-series configuration


@dataclass(frozen=True)
class Manifest:
    path: Path
    sample_name: str
    synthetic: bool
    instrument: Instrument
    wavelength_min_nm: float
    wavelength_max_nm: float
    wavelength_step_nm: float
    gain_e_per_count: float
    full_scale_counts: int
    responsivity_file: Path | None
    dark_file: Path
    configurations: tuple[ConfigurationEntry, ...]
    raw: dict

    @property
    def folder(self) -> Path:
        return self.path.parent


_NUMBER = (int, float)


def _get(table: Any, key: str, kind: type | tuple, path: Path, dotted: str, required: bool = True) -> Any:
    if not isinstance(table, dict):
        raise InputError("expected a table", file=path, field=dotted.rsplit(".", 1)[0], expected="a TOML table",
                         got=type(table).__name__)
    if key not in table:
        if required:
            raise InputError("manifest key missing", file=path, field=dotted, expected=_kind_name(kind))
        return None
    value = table[key]
    if kind is float:
        kind = _NUMBER
    if isinstance(value, bool) and kind is not bool:
        raise InputError("manifest value of the wrong type", file=path, field=dotted, expected=_kind_name(kind),
                         got=value)
    if not isinstance(value, kind):
        raise InputError("manifest value of the wrong type", file=path, field=dotted, expected=_kind_name(kind),
                         got=value)
    return value


def _kind_name(kind: type | tuple) -> str:
    names = {str: "a string", bool: "true/false", int: "an integer", float: "a number", list: "an array",
             dict: "a table", _NUMBER: "a number"}
    return names.get(kind, str(kind))


def _positive(value: float, path: Path, dotted: str) -> float:
    if not (value > 0 and math.isfinite(value)):
        raise ValidationError("must be positive", file=path, field=dotted, expected="a finite number > 0", got=value)
    return float(value)


def _in_nm(value: float, path: Path, dotted: str) -> float:
    lo, hi = WAVELENGTH_RANGE_NM
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValidationError("wavelength not plausible in nm", file=path, field=dotted,
                              expected=f"nanometres in [{lo:g}, {hi:g}] (not µm, m or Å)", got=value)
    return float(value)


def _transmittance(value: float, path: Path, dotted: str) -> float:
    if not (math.isfinite(value) and 0 < value <= 1):
        raise ValidationError("attenuator transmittance out of range (it scales every BSDF by its inverse)",
                              file=path, field=dotted, expected="a transmittance T_ND in (0, 1]", got=value)
    return float(value)


def _file(folder: Path, name: str, path: Path, dotted: str) -> Path:
    target = folder / name
    if not target.is_file():
        raise InputError("file named in the manifest is missing", file=path, field=dotted,
                         expected=f"an existing file {target}", got=name)
    return target


def read_manifest(folder_or_file: str | Path) -> Manifest:
    """Read and validate the manifest of a raw export folder (or the manifest file itself).

    Parameters
    ----------
    folder_or_file : str or Path
        Export folder (its ``manifest.toml`` is read) or a manifest file.

    Returns
    -------
    Manifest
        Sample, instrument geometry [mm], spectrometer grid [nm], gain [e⁻/count], full scale [counts], the
        data files (checked to exist) and the incident configurations, ``[[band_series]]`` expanded into one
        configuration per band; the parsed TOML in ``raw``.

    Raises
    ------
    InputError
        No manifest, a missing file it names, or (as ``FormatError``/``ValidationError``) an unknown format or
        version, a missing or mistyped key, or an implausible value, naming the dotted key.
    """
    path = Path(folder_or_file)
    if path.is_dir():
        path = path / "manifest.toml"
    if not path.is_file():
        raise InputError("no manifest", file=path, expected="a manifest.toml in the measurement folder")
    data = read_toml(path, expected="a TOML manifest")
    fmt = _get(data, "format", str, path, "format")
    if fmt != FORMAT_NAME:
        raise FormatError("unknown format", file=path, field="format", expected=repr(FORMAT_NAME), got=fmt)
    version = _get(data, "format_version", int, path, "format_version")
    if version not in SUPPORTED_VERSIONS:
        raise FormatError("unsupported format version", file=path, field="format_version",
                          expected=f"one of {SUPPORTED_VERSIONS}", got=version)
    sample = _get(data, "sample", dict, path, "sample")
    name = _get(sample, "name", str, path, "sample.name")
    synthetic = bool(_get(sample, "synthetic", bool, path, "sample.synthetic", required=False) or False)
    instrument = _instrument(data, path)
    spec = _spectrometer(data, path)
    folder = path.parent
    resp = _file(folder, spec.responsivity, path, "spectrometer.responsivity_file") if spec.responsivity else None
    dark = _get(data, "dark", dict, path, "dark")
    dark_file = _file(folder, _get(dark, "file", str, path, "dark.file"), path, "dark.file")
    series_raw = _get(data, "band_series", list, path, "band_series", required=False) or []
    configs_raw = _get(data, "configuration", list, path, "configuration", required=not series_raw) or []
    if not configs_raw and not series_raw:
        raise InputError("no incident configuration", file=path, field="configuration",
                         expected="at least one [[configuration]] or [[band_series]]")
    seen: set[str] = set()
    configs = [_configuration(c, k, folder, path, seen) for k, c in enumerate(configs_raw)]
    for k, entry in enumerate(series_raw):
        configs.extend(_band_series(entry, k, folder, path, seen))
    return Manifest(path=path, sample_name=name, synthetic=synthetic, instrument=instrument,
                    wavelength_min_nm=spec.wavelength_min_nm, wavelength_max_nm=spec.wavelength_max_nm,
                    wavelength_step_nm=spec.wavelength_step_nm, gain_e_per_count=spec.gain_e_per_count,
                    full_scale_counts=spec.full_scale_counts, responsivity_file=resp, dark_file=dark_file,
                    configurations=tuple(configs), raw=data)


def _instrument(data: Any, path: Path) -> Instrument:
    """The ``[instrument]`` table: detector distance, aperture and beam diameters [mm]."""
    inst = _get(data, "instrument", dict, path, "instrument")
    try:
        return Instrument(
            detector_distance_mm=float(_get(inst, "detector_distance_mm", float, path,
                                            "instrument.detector_distance_mm")),
            aperture_diameter_mm=float(_get(inst, "aperture_diameter_mm", float, path,
                                            "instrument.aperture_diameter_mm")),
            beam_diameter_mm=float(_get(inst, "beam_diameter_mm", float, path, "instrument.beam_diameter_mm")),
        )
    except ValidationError as exc:
        raise ValidationError(str(exc), file=path) from None


@dataclass(frozen=True)
class _Spectrometer:
    """The ``[spectrometer]`` table, checked (wavelengths [nm])."""

    wavelength_min_nm: float
    wavelength_max_nm: float
    wavelength_step_nm: float
    gain_e_per_count: float
    full_scale_counts: int
    responsivity: str | None  # the responsivity file's name as written, if any


def _spectrometer(data: Any, path: Path) -> _Spectrometer:
    """Read and check ``[spectrometer]``: a non-empty wavelength grid of at most :data:`MAX_WAVELENGTHS`, a
    positive gain and full scale."""
    spec = _get(data, "spectrometer", dict, path, "spectrometer")
    wmin = _in_nm(float(_get(spec, "wavelength_min_nm", float, path, "spectrometer.wavelength_min_nm")), path,
                  "spectrometer.wavelength_min_nm")
    wmax = _in_nm(float(_get(spec, "wavelength_max_nm", float, path, "spectrometer.wavelength_max_nm")), path,
                  "spectrometer.wavelength_max_nm")
    step = _positive(_get(spec, "wavelength_step_nm", float, path, "spectrometer.wavelength_step_nm"), path,
                     "spectrometer.wavelength_step_nm")
    if not wmax > wmin:
        raise ValidationError("empty wavelength range", file=path, field="spectrometer.wavelength_max_nm",
                              expected=f"> wavelength_min_nm = {wmin}", got=wmax)
    n_grid = (wmax - wmin) / step + 1
    if n_grid > MAX_WAVELENGTHS:  # before anything is allocated
        raise ValidationError("wavelength grid too fine", file=path, field="spectrometer.wavelength_step_nm",
                              expected=f"at most {MAX_WAVELENGTHS} wavelengths (limit MAX_WAVELENGTHS), i.e. a step "
                                       f"≥ {(wmax - wmin) / (MAX_WAVELENGTHS - 1):.3g} nm",
                              got=f"{step:g} nm ({n_grid:.3g} wavelengths)")
    gain = _positive(_get(spec, "gain_e_per_count", float, path, "spectrometer.gain_e_per_count"), path,
                     "spectrometer.gain_e_per_count")
    full_scale = _get(spec, "full_scale_counts", int, path, "spectrometer.full_scale_counts")
    if not full_scale > 0:
        raise ValidationError("full scale must be positive (every pixel would be saturated)", file=path,
                              field="spectrometer.full_scale_counts", expected="an integer > 0", got=full_scale)
    resp_name = _get(spec, "responsivity_file", str, path, "spectrometer.responsivity_file", required=False)
    return _Spectrometer(wmin, wmax, step, gain, int(full_scale), resp_name)


def _configuration(c: Any, k: int, folder: Path, path: Path, seen: set[str]) -> ConfigurationEntry:
    """The ``k``-th ``[[configuration]]``, checked; its name is added to ``seen`` (names are unique)."""
    pre = f"configuration[{k}]"
    cname = _get(c, "name", str, path, f"{pre}.name")
    if cname in seen:
        raise ValidationError("duplicate configuration name", file=path, field=f"{pre}.name", got=cname)
    seen.add(cname)
    band = _get(c, "incident_band_nm", list, path, f"{pre}.incident_band_nm")
    if (len(band) != 2 or not all(isinstance(b, _NUMBER) and not isinstance(b, bool) for b in band)
            or not band[1] > band[0]):
        raise ValidationError("bad incident band", file=path, field=f"{pre}.incident_band_nm",
                              expected="[low_nm, high_nm] with low < high", got=band)
    return ConfigurationEntry(
        name=cname,
        description=_get(c, "description", str, path, f"{pre}.description", required=False) or "",
        incident_band_nm=(float(band[0]), float(band[1])),
        scan_file=_file(folder, _get(c, "scan_file", str, path, f"{pre}.scan_file"), path, f"{pre}.scan_file"),
        reference_file=_file(folder, _get(c, "reference_file", str, path, f"{pre}.reference_file"), path,
                             f"{pre}.reference_file"),
        reference_attenuation=_transmittance(_get(c, "reference_attenuation", float, path,
                                                  f"{pre}.reference_attenuation"),
                                             path, f"{pre}.reference_attenuation"),
    )


def _band_series(entry: Any, k: int, folder: Path, path: Path, seen: set[str]) -> list[ConfigurationEntry]:
    """The configurations of one ``[[band_series]]``: bands centred first, first + step, …, last (nm), each
    centre ± bandwidth/2, files named by replacing ``{center}`` with the centre (``%g``, e.g. 450)."""
    pre = f"band_series[{k}]"
    name = _get(entry, "name", str, path, f"{pre}.name")
    first = _in_nm(float(_get(entry, "first_center_nm", float, path, f"{pre}.first_center_nm")), path,
                   f"{pre}.first_center_nm")
    last = _in_nm(float(_get(entry, "last_center_nm", float, path, f"{pre}.last_center_nm")), path,
                  f"{pre}.last_center_nm")
    step = _positive(_get(entry, "center_step_nm", float, path, f"{pre}.center_step_nm"), path,
                     f"{pre}.center_step_nm")
    width = _positive(_get(entry, "bandwidth_nm", float, path, f"{pre}.bandwidth_nm"), path, f"{pre}.bandwidth_nm")
    if not last >= first:
        raise ValidationError("band series runs backwards", file=path, field=f"{pre}.last_center_nm",
                              expected=f"≥ first_center_nm = {first:g}", got=last)
    n = (last - first) / step
    if n + 1 > MAX_BAND_SERIES:  # before anything is allocated
        raise ValidationError("too many bands in a series", file=path, field=f"{pre}.center_step_nm",
                              expected=f"at most {MAX_BAND_SERIES} bands (limit MAX_BAND_SERIES)",
                              got=f"{step:g} nm ({n + 1:.3g} bands)")
    if abs(n - round(n)) > 1e-6:
        raise ValidationError("band series is not a whole number of steps", file=path, field=f"{pre}.center_step_nm",
                              expected=f"(last − first)/step integral ({first:g}..{last:g} nm)", got=step)
    templates = {}
    for key in ("scan_file", "reference_file"):
        template = _get(entry, key, str, path, f"{pre}.{key}")
        if CENTER_PLACEHOLDER not in template:
            raise ValidationError("file name of a band series without the band centre", file=path,
                                  field=f"{pre}.{key}", expected=f"a name containing {CENTER_PLACEHOLDER}",
                                  got=template)
        templates[key] = template
    description = _get(entry, "description", str, path, f"{pre}.description", required=False) or ""
    attenuation = _transmittance(_get(entry, "reference_attenuation", float, path, f"{pre}.reference_attenuation"),
                                 path, f"{pre}.reference_attenuation")
    out = []
    for c in first + step * np.arange(int(round(n)) + 1):
        label = f"{c:g}"
        cname = f"{name}-{label}"
        if cname in seen:
            raise ValidationError("duplicate configuration name", file=path, field=f"{pre}.name",
                                  expected="names unique across [[configuration]] and [[band_series]] bands",
                                  got=cname)
        seen.add(cname)
        files = {key: _file(folder, t.replace(CENTER_PLACEHOLDER, label), path, f"{pre}.{key}")
                 for key, t in templates.items()}
        out.append(ConfigurationEntry(name=cname, description=f"{description}, centre {label} nm".lstrip(", "),
                                      incident_band_nm=(float(c) - width / 2, float(c) + width / 2),
                                      scan_file=files["scan_file"], reference_file=files["reference_file"],
                                      reference_attenuation=attenuation, series=name, excitation_nm=float(c)))
    return out
