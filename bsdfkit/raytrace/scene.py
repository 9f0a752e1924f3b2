"""Scenes: a cylindrical mixing cavity with LEDs on its base and a top (exit, diffuser or phosphor plate).

A scene is a tree of frozen dataclasses read from / written to TOML (see docs/tracer.md for every key)::

    [cavity]
    radius_mm = 35.0
    height_mm = 43.0
    [wall]
    reflectance = 0.90
    specular_fraction = 0.0      # share of the reflectance that is mirror-like
    [base]
    reflectance = 0.90
    specular_fraction = 0.0
    [leds]
    count = 4
    pitch_mm = 20.0              # centres on a square of this side, centred on the axis
    emitter_radius_mm = 1.0      # Lambertian emitting disks in the base plane
    distribution = "lambertian"  # or: fwhm_deg = 30
    power_W = 1.0
    [top]
    kind = "exit"                # or "lambertian" (reflectance, transmittance) or "phosphor"

Geometry (the cylindrical-module paper, §2 and Fig. 5): the cavity axis is z, the base is the disk z = 0,
the wall the cylinder r = radius for 0 < z < height, the top (exit plane or phosphor plate, its cavity side)
the disk z = height. ``count`` LEDs (a perfect square k²) sit on a k × k grid of spacing ``pitch_mm``
centred on the axis (4 LEDs: the corners of a square of side ``pitch_mm``).

Angles are degrees in TOML and radians inside. Every error names the file, the key, what was expected and
what was found; unknown keys are errors.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from bsdfkit.core.conventions import MODULE_BLUE_BAND_NM, MODULE_YELLOW_BAND_NM, WAVELENGTH_RANGE_NM
from bsdfkit.core.errors import InputError, ValidationError
from bsdfkit.core.spectra import gaussian
from bsdfkit.fit.lambertian import band_weighted_reflectance, lambertian_from_reflectance
from bsdfkit.io import toml_write
from bsdfkit.io.atomic import write_text
from bsdfkit.io.spectrum_file import read_spectrum_table
from bsdfkit.io.text import loads_toml, read_text
from bsdfkit.raytrace.plate import PhosphorPlate, load_plate
from bsdfkit.raytrace.rayfile import RaySet, read_ray_file
from bsdfkit.raytrace.spectral import (
    PLATE_TEMPERATURE_K,
    SpectralPlateModel,
    SpectralTables,
    gaussian_led_spectrum,
    load_spectral_model,
    spectral_plate_from_two_colour,
    spectral_tables,
    surface_reflectance_on_bins,
)

TOP_KINDS = ("exit", "lambertian", "phosphor")
MODES = ("two-wavelength", "spectral")
TERMINATIONS = ("roulette", "threshold")
PRECISIONS = ("float32", "float64")


@dataclass(frozen=True)
class Cavity:
    """Cylinder of ``radius_mm`` and ``height_mm`` (base at z = 0, top at z = height)."""

    radius_mm: float
    height_mm: float


@dataclass(frozen=True)
class Surface:
    """A reflector: total ``reflectance``; ``specular_fraction`` of it is mirror-like, the rest Lambertian.

    With ``spectrum_file`` (``reflectance_spectrum`` in TOML: wavelength [nm] and reflectance [1] columns, e.g. a
    reflectance standard's calibration) the surface is Lambertian per wavelength
    (:func:`bsdfkit.fit.lambertian.lambertian_from_reflectance`): the spectral mode uses ρ(λ) at each bin; the
    two-wavelength mode gives blue rays ρ weighted by the LED spectrum over the module blue band and yellow rays
    ρ averaged over the module yellow band (:func:`band_weighted_reflectance`). ``reflectance`` is then the blue
    value. ``spectrum`` holds (wavelength, reflectance) once read.
    """

    reflectance: float
    specular_fraction: float = 0.0
    spectrum_file: str | None = None
    spectrum: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class Leds:
    """Pump LEDs: Lambertian disks (or a cos^m intensity of given FWHM) in the base plane.

    ``fwhm`` (radians) is None for a Lambertian source; otherwise I(θ) ∝ cos^m θ with
    m = ln ½ / ln cos(FWHM/2) (m = 1 at FWHM = 120°, the Lambertian case). ``led_reflectance`` and
    ``led_specular_fraction`` default to the base's. ``ray_file`` replaces the emission model by rays
    read from a file (the disks still reflect); ``rays`` holds them once loaded. The LED spectrum (needed by the
    spectral mode; it also weights spectral surfaces for blue rays) is ``spectrum_file`` (``spectrum`` in TOML,
    read by :func:`bsdfkit.io.spectrum_file.read_spectrum_table`, first value column, any scale) or a Gaussian of
    ``spectrum_peak_nm`` and ``spectrum_fwhm_nm`` (eq. (2) of [Cylindrical-module]); ``spectrum`` holds
    (wavelength [nm], values) once read.
    """

    count: int = 4
    pitch_mm: float = 20.0
    emitter_radius_mm: float = 1.0
    fwhm: float | None = None
    power_W: float = 1.0
    led_reflectance: float | None = None
    led_specular_fraction: float | None = None
    ray_file: str | None = None
    rays: RaySet | None = field(default=None, compare=False, repr=False)
    spectrum_file: str | None = None
    spectrum_peak_nm: float | None = None
    spectrum_fwhm_nm: float | None = None
    spectrum: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)

    @property
    def grid(self) -> int:
        """k for a k × k grid of LEDs."""
        return math.isqrt(self.count)

    @property
    def cos_exponent(self) -> float:
        """m of the cos^m intensity (1 for Lambertian), at most :data:`COLLIMATED_EXPONENT`.

        ln cos(FWHM/2) is taken as log1p(−2 sin²(FWHM/4)), exact down to the narrowest beams (plain
        ln cos(x) is 0 in float64 below x ≈ 1e-8 rad, which divided by zero). A beam narrower than the tracer
        can resolve is its collimated limit: m is capped at :data:`COLLIMATED_EXPONENT`, for which every
        sampled cos θ rounds to 1 (a legitimate scene, traced exactly as a collimated beam).
        """
        if self.fwhm is None:
            return 1.0
        log_cos = math.log1p(-2.0 * math.sin(self.fwhm / 4.0) ** 2)
        if log_cos == 0.0:
            return COLLIMATED_EXPONENT
        return min(math.log(0.5) / log_cos, COLLIMATED_EXPONENT)

    def centres(self) -> list[tuple[float, float]]:
        """LED centres (x, y) in mm, row-major over the k × k grid."""
        k = self.grid
        off = [(i - (k - 1) / 2.0) * self.pitch_mm for i in range(k)]
        return [(x, y) for x in off for y in off]


#: cos^m exponent of the collimated limit of an LED beam: cos θ = (1 − u)^{1/(m+1)} with m = 1e30 is 1 to within
#: 2e-29 for every u a float32 or float64 sampler draws, i.e. exactly 1 (θ = 0) in the tracer; finite in float32.
COLLIMATED_EXPONENT = 1e30


@dataclass(frozen=True)
class Top:
    """The top of the cavity.

    ``exit``: all light reaching it leaves the module. ``lambertian``: a non-converting diffuser with
    ``reflectance`` and ``transmittance`` (both Lambertian). ``phosphor``: the plate of
    :mod:`bsdfkit.raytrace.plate`, from ``plate_file`` (JSON), ``plate_recipe`` (a fitting recipe, resolved
    by the caller's :data:`PlateResolver`, e.g. :func:`bsdfkit.pipeline.plate_from_scan.plate_from_recipe`) or
    given inline. In the spectral mode
    ``spectral_model`` is the plate spectral model (:mod:`bsdfkit.raytrace.spectral`), from ``spectral_file``
    (netCDF; the plate is then optional and gives only the angular distributions, Lambertian without it) or built
    from the plate with a Gaussian emission spectrum ``spectral_emission`` = (peak, FWHM, start, stop, step) [nm].
    ``temperature_K`` [K] is the plate temperature of the spectral mode's thermal (anti-Stokes) tail: emission
    below the excitation wavelength is weighted by its Boltzmann factor (:mod:`bsdfkit.raytrace.spectral`).
    """

    kind: str = "exit"
    reflectance: float = 0.0
    transmittance: float = 0.0
    plate: PhosphorPlate | None = None
    plate_file: str | None = None
    plate_recipe: str | None = None
    spectral_file: str | None = None
    spectral_emission: tuple[float, float, float, float, float] | None = None
    spectral_model: SpectralPlateModel | None = field(default=None, compare=False, repr=False)
    temperature_K: float = PLATE_TEMPERATURE_K


@dataclass(frozen=True)
class TraceOptions:
    """How rays are traced and terminated.

    ``termination = "roulette"`` (unbiased): a ray whose weight w drops below ``roulette_threshold`` (of
    its emitted weight 1) survives with probability p = w/roulette_threshold and then carries weight
    roulette_threshold. ``"threshold"``: the flux threshold Th of Fig. 6 of the cylindrical-module paper,
    per ray: a ray whose weight drops below ``threshold`` is dropped (biased; the dropped power is a
    ledger line). ``max_events`` caps surface interactions per ray (the rest is tallied as truncated).
    ``precision`` is the float type of positions and directions; weights and tallies are float64.
    ``lanes`` rays are in flight at once; ``chunk`` rays are emitted and traced per call of the compiled
    kernel (memory ∝ lanes + chunk; progress granularity). Neither changes results. ``mode``:
    ``"two-wavelength"`` (blue and yellow rays, the papers' approach) or ``"spectral"`` (rays carry a wavelength
    bin, :mod:`bsdfkit.raytrace.spectral`); ``spectral_grid_nm`` = (start, stop, step) is the bin grid of a
    spectral scene without a plate model (with one, its emission grid).
    """

    termination: str = "roulette"
    roulette_threshold: float = 0.1
    threshold: float = 0.01
    max_events: int = 10000
    precision: str = "float32"
    lanes: int = 16384
    chunk: int = 1048576
    mode: str = "two-wavelength"
    spectral_grid_nm: tuple[float, float, float] = (380.0, 780.0, 5.0)


@dataclass(frozen=True)
class Tallies:
    """Optional tallies; None means "on for a plate or diffuser top, off for an exit top"."""

    irradiance_map: bool | None = None
    map_bins: int = 32
    incidence_histogram: bool | None = None
    histogram_bins: int = 90
    interaction_budget: bool | None = None
    budget_bins: int = 16


@dataclass(frozen=True)
class SweepDefaults:
    """Defaults for ``bsdfkit sweep``: parameter specs (see :mod:`bsdfkit.raytrace.sweep`), rays, seed."""

    params: tuple[str, ...] = ()
    rays: int | None = None
    seed: int | None = None


@dataclass(frozen=True)
class Scene:
    """A complete scene. ``path`` is the file it was read from (for relative paths and messages)."""

    cavity: Cavity
    wall: Surface
    base: Surface
    leds: Leds
    top: Top = Top()
    trace: TraceOptions = TraceOptions()
    tallies: Tallies = Tallies()
    sweep: SweepDefaults | None = None
    path: Path | None = field(default=None, compare=False, repr=False)

    @property
    def led_surface(self) -> Surface:
        """Optical properties of the LED disks (the base's unless set)."""
        spec = (self.base.specular_fraction if self.leds.led_specular_fraction is None
                else self.leds.led_specular_fraction)
        if self.leds.led_reflectance is None:
            return replace(self.base, specular_fraction=spec)
        return Surface(self.leds.led_reflectance, spec)

    def tally_enabled(self, name: str) -> bool:
        """Whether the optional tally ``name`` is on: its setting, or by default on unless the top is an exit.

        Parameters
        ----------
        name : str
            ``irradiance_map``, ``incidence_histogram`` or ``interaction_budget``.

        Returns
        -------
        bool
            True when the tally is traced.
        """
        value = getattr(self.tallies, name)
        return (self.top.kind != "exit") if value is None else bool(value)


# ---- reading ----------------------------------------------------------------------------------------------
class _Reader:
    """Typed access to one TOML table with bsdfkit errors (file, key, expected, got)."""

    def __init__(self, table: Any, section: str, file: str | Path | None, allowed: set[str]):
        self.file = file
        self.section = section
        if not isinstance(table, Mapping):
            raise InputError("expected a table", file=file, field=section, expected="a [table]", got=table)
        self.table = table
        for key in table:
            if key not in allowed:
                raise InputError("unknown key", file=file, field=f"{section}.{key}",
                                 expected="one of " + ", ".join(sorted(allowed)), got=key)

    def where(self, key: str) -> str:
        return f"{self.section}.{key}"

    def has(self, key: str) -> bool:
        return key in self.table

    def number(self, key: str, default: float | None = None, *, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, hi_open: bool = False, required: bool = False) -> float | None:
        if key not in self.table:
            if required:
                raise InputError("missing key", file=self.file, field=self.where(key), expected="a number")
            return default
        value = self.table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError("wrong type", file=self.file, field=self.where(key), expected="a number", got=value)
        value = float(value)
        bad = not math.isfinite(value)
        if lo is not None:
            bad |= value <= lo if lo_open else value < lo
        if hi is not None:
            bad |= value >= hi if hi_open else value > hi
        if bad:
            lo_s = "" if lo is None else (f"> {lo:g}" if lo_open else f">= {lo:g}")
            hi_s = "" if hi is None else (f"< {hi:g}" if hi_open else f"<= {hi:g}")
            expected = " and ".join(s for s in (lo_s, hi_s) if s) or "a finite number"
            raise ValidationError("value out of range", file=self.file, field=self.where(key),
                                  expected=f"a number {expected}" if (lo_s or hi_s) else expected, got=value)
        return value

    def integer(self, key: str, default: int | None = None, *, lo: int | None = None,
                required: bool = False) -> int | None:
        if key not in self.table:
            if required:
                raise InputError("missing key", file=self.file, field=self.where(key), expected="an integer")
            return default
        value = self.table[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError("wrong type", file=self.file, field=self.where(key), expected="an integer", got=value)
        if lo is not None and value < lo:
            raise ValidationError("value out of range", file=self.file, field=self.where(key),
                                  expected=f"an integer >= {lo}", got=value)
        return value

    def string(self, key: str, default: str | None = None, *, choices: tuple[str, ...] | None = None,
               required: bool = False) -> str | None:
        if key not in self.table:
            if required:
                raise InputError("missing key", file=self.file, field=self.where(key),
                                 expected="one of " + ", ".join(choices) if choices else "a string")
            return default
        value = self.table[key]
        if not isinstance(value, str):
            raise InputError("wrong type", file=self.file, field=self.where(key), expected="a string", got=value)
        if choices is not None and value not in choices:
            raise ValidationError("unknown value", file=self.file, field=self.where(key),
                                  expected="one of " + ", ".join(repr(c) for c in choices), got=value)
        return value

    def boolean(self, key: str, default: bool | None = None) -> bool | None:
        if key not in self.table:
            return default
        value = self.table[key]
        if not isinstance(value, bool):
            raise InputError("wrong type", file=self.file, field=self.where(key), expected="true or false",
                             got=value)
        return value


def _resolve(path_text: str, base_dir: Path | None) -> Path:
    """Resolve a path written in a scene: relative to the scene's folder, else to the working directory."""
    p = Path(path_text)
    if p.is_absolute():
        return p
    if base_dir is not None and (base_dir / p).exists():
        return base_dir / p
    return p


#: Turns the fitting recipe a scene's ``[top] from`` names (its path, resolved against the scene's folder) into
#: the plate. The tracer reads no measurements: the layer that owns recipes passes one in
#: (:func:`bsdfkit.pipeline.plate_from_scan.plate_from_recipe`, by ``bsdfkit trace`` and ``bsdfkit sweep``).
PlateResolver = Callable[[Path], PhosphorPlate]


def parse_scene(data: Mapping[str, Any], file: str | Path | None = None, *,
                preloaded: Mapping[str, Any] | None = None, plate_resolver: PlateResolver | None = None) -> Scene:
    """Build a :class:`Scene` from a TOML mapping; relative paths resolve against ``file``'s folder.

    ``preloaded`` may hold ``{"ray_file": (text, RaySet), "plate": (key, PhosphorPlate)}`` to skip
    re-reading unchanged files (used by sweeps). A ``[top] from = "<recipe>.toml"`` not in ``preloaded`` needs
    ``plate_resolver``; without one it is refused in one line naming ``top.from``.

    Parameters
    ----------
    data : mapping
        The parsed TOML document.
    file : str or Path, optional
        The scene file, named in errors.
    preloaded : mapping, optional
        Files already read, keyed as above.
    plate_resolver : PlateResolver, optional
        Builds the plate of the recipe a ``[top] from`` names.

    Returns
    -------
    Scene
        The validated scene.
    """
    preloaded = preloaded or {}
    base_dir = Path(file).parent if file is not None else None
    sections = {"cavity", "wall", "base", "leds", "top", "trace", "tallies", "sweep"}
    for key in data:
        if key not in sections:
            raise InputError("unknown section", file=file, field=key,
                             expected="one of " + ", ".join(sorted(sections)), got=key)
    for key in ("cavity", "wall", "base", "leds", "top"):
        if key not in data:
            raise InputError("missing section", file=file, field=key, expected=f"a [{key}] table")

    r = _Reader(data["cavity"], "cavity", file, {"radius_mm", "height_mm"})
    cavity = Cavity(r.number("radius_mm", lo=0, lo_open=True, required=True),
                    r.number("height_mm", lo=0, lo_open=True, required=True))
    wall, base = (_surface(data[name], name, file, base_dir) for name in ("wall", "base"))
    leds = _leds(data["leds"], cavity, file, base_dir, preloaded)
    top = _top(data["top"], file, base_dir, preloaded, plate_resolver)
    trace = _trace_options(data["trace"], file) if "trace" in data else TraceOptions()
    tallies = _tallies(data["tallies"], file) if "tallies" in data else Tallies()
    sweep = None
    if "sweep" in data:
        r = _Reader(data["sweep"], "sweep", file, {"params", "rays", "seed"})
        params = r.table.get("params", [])
        if not isinstance(params, list) or not all(isinstance(p, str) for p in params):
            raise InputError("wrong type", file=file, field="sweep.params",
                             expected="a list of strings like 'wall.reflectance=0.80:0.98:5'", got=params)
        sweep = SweepDefaults(tuple(params), r.integer("rays", None, lo=1), r.integer("seed", None, lo=0))
    _check_sizes(cavity, leds, trace, tallies, file)
    _check_spectral(trace, leds, top, file)
    wall, base = (_with_blue_reflectance(sf, leds) for sf in (wall, base))
    check_termination(wall, base, leds, top, trace, file)
    return Scene(cavity, wall, base, leds, top, trace, tallies, sweep, Path(file) if file is not None else None)


def _surface(table: Any, name: str, file: str | Path | None, base_dir: Path | None) -> Surface:
    """The [wall] or [base] section: a reflectance (and its specular share) or a reflectance spectrum file."""
    s = _Reader(table, name, file, {"reflectance", "specular_fraction", "reflectance_spectrum"})
    spec = s.string("reflectance_spectrum", None)
    if spec is None:
        return Surface(s.number("reflectance", lo=0, hi=1, required=True),
                       s.number("specular_fraction", 0.0, lo=0, hi=1))
    if s.has("reflectance"):
        raise InputError("conflicting keys: a reflectance spectrum sets the reflectance", file=file,
                         field=f"{name}.reflectance", expected="reflectance or reflectance_spectrum, not both",
                         got=s.table["reflectance"])
    return Surface(math.nan, s.number("specular_fraction", 0.0, lo=0, hi=1), spectrum_file=spec,
                   spectrum=read_reflectance_spectrum(_resolve(spec, base_dir), f"{name}.reflectance_spectrum"))


def _leds(table: Any, cavity: Cavity, file: str | Path | None, base_dir: Path | None,
          preloaded: Mapping[str, Any]) -> Leds:
    """The [leds] section (a ray file from ``preloaded`` when unchanged), checked to fit on the cavity's base."""
    r = _Reader(table, "leds", file, {"count", "pitch_mm", "emitter_radius_mm", "distribution", "fwhm_deg",
                                      "power_W", "led_reflectance", "led_specular_fraction", "ray_file",
                                      "spectrum", "spectrum_peak_nm", "spectrum_fwhm_nm"})
    count = r.integer("count", 4, lo=1)
    if math.isqrt(count) ** 2 != count:
        raise ValidationError("LEDs sit on a k x k grid", file=file, field="leds.count",
                              expected="a perfect square (1, 4, 9, 16, ...)", got=count)
    distribution = r.string("distribution", None, choices=("lambertian", "fwhm"))
    fwhm_deg = r.number("fwhm_deg", None, lo=0, hi=180, lo_open=True, hi_open=True)
    if distribution == "lambertian" and fwhm_deg is not None:
        raise ValidationError("conflicting keys: a Lambertian source has no FWHM", file=file, field="leds.fwhm_deg",
                              expected="no fwhm_deg with distribution = 'lambertian'", got=fwhm_deg)
    if distribution == "fwhm" and fwhm_deg is None:
        raise InputError("missing key", file=file, field="leds.fwhm_deg", expected="a FWHM in degrees (0, 180)")
    ray_file = r.string("ray_file", None)
    rays = None
    if ray_file is not None:
        pre = preloaded.get("ray_file")
        if pre is not None and pre[0] == ray_file:
            rays = pre[1]
        else:
            rays = read_ray_file(_resolve(ray_file, base_dir))
    power = r.number("power_W", None if rays is not None else 1.0, lo=0, lo_open=True)
    leds = Leds(
        count=count,
        pitch_mm=r.number("pitch_mm", 20.0, lo=0, lo_open=True),
        emitter_radius_mm=r.number("emitter_radius_mm", 1.0, lo=0, lo_open=True),
        fwhm=None if fwhm_deg is None else math.radians(fwhm_deg),
        power_W=power if power is not None else rays.total_power,
        led_reflectance=r.number("led_reflectance", None, lo=0, hi=1),
        led_specular_fraction=r.number("led_specular_fraction", None, lo=0, hi=1),
        ray_file=ray_file,
        rays=rays,
        **_led_spectrum(r, base_dir),
    )
    R = cavity.radius_mm
    reach = max(math.hypot(x, y) for x, y in leds.centres()) + leds.emitter_radius_mm
    if reach > R:
        raise ValidationError("LED disks extend beyond the base", file=file, field="leds.pitch_mm",
                              expected=f"centre distance + emitter radius <= radius {R:g} mm", got=reach)
    if leds.grid > 1 and leds.pitch_mm < 2 * leds.emitter_radius_mm:
        raise ValidationError("LED disks overlap", file=file, field="leds.pitch_mm",
                              expected=f">= 2 x emitter_radius_mm = {2 * leds.emitter_radius_mm:g}",
                              got=leds.pitch_mm)
    if rays is not None:
        rays.check_inside(R, cavity.height_mm, file=file, field="leds.ray_file")
    return leds


def _top(table: Any, file: str | Path | None, base_dir: Path | None, preloaded: Mapping[str, Any],
         plate_resolver: PlateResolver | None) -> Top:
    """The [top] section: an exit, a Lambertian diffuser or a phosphor plate (:func:`_phosphor_top`)."""
    r = _Reader(table, "top", file, {"kind", "reflectance", "transmittance", "plate", "from", "spectral",
                                     "temperature_K"})
    if r.has("temperature_K") and not r.has("spectral"):
        raise InputError("the plate temperature belongs to a spectral plate model", file=file,
                         field="top.temperature_K", expected="a [top] with spectral = ...",
                         got=r.table["temperature_K"])
    if r.has("spectral") and r.table["kind"] != "phosphor":
        raise InputError("a spectral plate model belongs to a phosphor top", file=file, field="top.spectral",
                         expected="kind = 'phosphor'", got=r.table["kind"])
    kind = r.string("kind", required=True, choices=TOP_KINDS)
    if kind == "exit":
        for key in ("reflectance", "transmittance", "plate", "from"):
            if r.has(key):
                raise InputError("key not used by an exit top", file=file, field=f"top.{key}",
                                 expected="no such key with kind = 'exit'", got=r.table[key])
        top = Top("exit")
    elif kind == "lambertian":
        for key in ("plate", "from"):
            if r.has(key):
                raise InputError("key not used by a lambertian top", file=file, field=f"top.{key}",
                                 expected="reflectance and transmittance only", got=r.table[key])
        rho = r.number("reflectance", lo=0, hi=1, required=True)
        tau = r.number("transmittance", lo=0, hi=1, required=True)
        if rho + tau > 1 + 1e-12:
            raise ValidationError("reflectance + transmittance exceeds 1", file=file, field="top.transmittance",
                                  expected=f"<= {1 - rho:g}", got=tau)
        top = Top("lambertian", reflectance=rho, transmittance=tau)
    else:
        top = _phosphor_top(r, file, base_dir, preloaded, plate_resolver)
    return top


def _phosphor_top(r: _Reader, file: str | Path | None, base_dir: Path | None, preloaded: Mapping[str, Any],
                  plate_resolver: PlateResolver | None) -> Top:
    """A phosphor top: its plate from exactly one of a plate file, a recipe (built by ``plate_resolver``), an
    inline [top.plate] (or a spectral model alone), reused from ``preloaded`` when unchanged; and the spectral
    plate model if given."""
    for key in ("reflectance", "transmittance"):
        if r.has(key):
            raise InputError("a phosphor top takes its TIS from the plate", file=file, field=f"top.{key}",
                             expected="plate = 'file.json', from = 'recipe.toml' or [top.plate]",
                             got=r.table[key])
    given = [k for k in ("plate", "from") if r.has(k)]
    if not given and isinstance(r.table.get("spectral"), str):  # a spectral model alone: Lambertian shapes
        given = ["spectral"]
    if len(given) != 1:
        raise InputError("a phosphor top needs exactly one plate source", file=file, field="top.plate",
                         expected="one of plate = 'file.json' | from = 'fitting/<recipe>.toml' | [top.plate]",
                         got=given or None)
    key = given[0]
    value = r.table[key]
    pre = preloaded.get("plate")
    if key == "spectral":
        top = Top("phosphor")
    elif isinstance(value, Mapping):
        if key != "plate":
            raise InputError("wrong type", file=file, field="top.from", expected="a recipe path", got=value)
        plate = PhosphorPlate.from_mapping(value, file, prefix="top.plate.")
        top = Top("phosphor", plate=plate)
    elif not isinstance(value, str):
        raise InputError("wrong type", file=file, field=f"top.{key}", expected="a path string or a table",
                         got=value)
    elif pre is not None and pre[0] == (key, value):
        plate = pre[1]
        top = Top("phosphor", plate=plate, plate_file=value if key == "plate" else None,
                  plate_recipe=value if key == "from" else None)
    elif key == "plate":
        top = Top("phosphor", plate=load_plate(_resolve(value, base_dir)), plate_file=value)
    elif plate_resolver is None:
        raise InputError("a plate from a fitting recipe is built by the caller that owns recipes", file=file,
                         field="top.from", expected="plate = 'file.json' or [top.plate] here (or bsdfkit trace / "
                         "sweep, or load_scene(..., plate_resolver=bsdfkit.pipeline.plate_from_scan."
                         "plate_from_recipe))", got=value)
    else:
        top = Top("phosphor", plate=plate_resolver(_resolve(value, base_dir)), plate_recipe=value)
    if r.has("spectral"):
        top = _spectral_top(top, r, base_dir, preloaded)
        top = replace(top, temperature_K=r.number("temperature_K", PLATE_TEMPERATURE_K, lo=0, lo_open=True))
    return top


def _trace_options(table: Any, file: str | Path | None) -> TraceOptions:
    """The [trace] section (defaults: :class:`TraceOptions`)."""
    default = TraceOptions()
    r = _Reader(table, "trace", file, {"termination", "roulette_threshold", "threshold", "max_events",
                                       "precision", "lanes", "chunk", "mode", "spectral_grid_nm"})
    trace = TraceOptions(
        termination=r.string("termination", default.termination, choices=TERMINATIONS),
        roulette_threshold=r.number("roulette_threshold", default.roulette_threshold, lo=0, hi=1, lo_open=True),
        threshold=r.number("threshold", default.threshold, lo=0, hi=1, lo_open=True, hi_open=True),
        max_events=r.integer("max_events", default.max_events, lo=1),
        precision=r.string("precision", default.precision, choices=PRECISIONS),
        lanes=r.integer("lanes", default.lanes, lo=1),
        chunk=r.integer("chunk", default.chunk, lo=1),
        mode=r.string("mode", default.mode, choices=MODES),
        spectral_grid_nm=_grid(r, default.spectral_grid_nm),
    )
    if trace.max_events >= 2 ** 29:
        raise ValidationError("too many events per ray for the random-number counter", file=file,
                              field="trace.max_events", expected="< 2**29", got=trace.max_events)
    return trace


def _tallies(table: Any, file: str | Path | None) -> Tallies:
    """The [tallies] section (defaults: :class:`Tallies`)."""
    default = Tallies()
    r = _Reader(table, "tallies", file, {"irradiance_map", "map_bins", "incidence_histogram",
                                         "histogram_bins", "interaction_budget", "budget_bins"})
    return Tallies(
        irradiance_map=r.boolean("irradiance_map"),
        map_bins=r.integer("map_bins", default.map_bins, lo=2),
        incidence_histogram=r.boolean("incidence_histogram"),
        histogram_bins=r.integer("histogram_bins", default.histogram_bins, lo=1),
        interaction_budget=r.boolean("interaction_budget"),
        budget_bins=r.integer("budget_bins", default.budget_bins, lo=1),
    )


def read_reflectance_spectrum(path: Path, field_name: str) -> tuple[np.ndarray, np.ndarray]:
    """(wavelength [nm], reflectance [1]) of a reflectance spectrum file: the first value column of a table read
    by :func:`bsdfkit.io.spectrum_file.read_spectrum_table`, checked by
    :func:`bsdfkit.fit.lambertian.lambertian_from_reflectance` (fractions in [0, 1], wavelengths in nm).

    Parameters
    ----------
    path : Path
        The spectrum file.
    field_name : str
        The scene key that names the file (not used by the reading itself).

    Returns
    -------
    wavelength : ndarray
        Wavelengths [nm].
    reflectance : ndarray
        Reflectance [-].
    """
    wl, columns, _ = read_spectrum_table(path)
    rho = next(iter(columns.values()))
    model = lambertian_from_reflectance(wl, rho, source=str(path))
    return wl, model["rho"].isel(interaction=0, side=0, theta_i=0).values


def _led_spectrum(r: _Reader, base_dir: Path | None) -> dict[str, Any]:
    """The LED spectrum keys: a spectrum file, or a Gaussian (peak and FWHM in nm), or none."""
    path = r.string("spectrum", None)
    peak = r.number("spectrum_peak_nm", None, lo=WAVELENGTH_RANGE_NM[0], hi=WAVELENGTH_RANGE_NM[1])
    fwhm = r.number("spectrum_fwhm_nm", None, lo=0, lo_open=True)
    if path is not None and (peak is not None or fwhm is not None):
        raise InputError("conflicting keys: a spectrum file or a Gaussian spectrum", file=r.file,
                         field="leds.spectrum_peak_nm", expected="spectrum = 'file' or spectrum_peak_nm + "
                         "spectrum_fwhm_nm", got=peak if peak is not None else fwhm)
    if (peak is None) != (fwhm is None):
        raise InputError("missing key", file=r.file, field="leds.spectrum_fwhm_nm" if fwhm is None
                         else "leds.spectrum_peak_nm", expected="both spectrum_peak_nm and spectrum_fwhm_nm [nm]")
    if path is not None:
        wl, columns, _ = read_spectrum_table(_resolve(path, base_dir))
        return {"spectrum_file": path, "spectrum": (wl, next(iter(columns.values())))}
    if peak is not None:
        return {"spectrum_peak_nm": peak, "spectrum_fwhm_nm": fwhm, "spectrum": gaussian_led_spectrum(peak, fwhm)}
    return {}


def _grid(r: _Reader, default: tuple[float, float, float]) -> tuple[float, float, float]:
    if not r.has("spectral_grid_nm"):
        return default
    value = r.table["spectral_grid_nm"]
    ok = isinstance(value, list) and len(value) == 3 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok or not (WAVELENGTH_RANGE_NM[0] <= value[0] < value[1] <= WAVELENGTH_RANGE_NM[1] and value[2] > 0) \
            or not 2 <= round((value[1] - value[0]) / value[2]) + 1 <= 1024:
        raise ValidationError("bad spectral grid", file=r.file, field="trace.spectral_grid_nm",
                              expected="[start, stop, step] in nm with 2-1024 bins", got=value)
    return (float(value[0]), float(value[1]), float(value[2]))


def _spectral_top(top: Top, r: _Reader, base_dir: Path | None, preloaded: Mapping[str, Any]) -> Top:
    """The phosphor top with its plate spectral model: a netCDF file, or the two-colour plate with a Gaussian
    emission spectrum ({emission_peak_nm, emission_fwhm_nm, start_nm, stop_nm, step_nm})."""
    value = r.table["spectral"]
    pre = preloaded.get("spectral")
    if isinstance(value, str):
        if pre is not None and pre[0] == value:
            return replace(top, spectral_file=value, spectral_model=pre[1])
        return replace(top, spectral_file=value, spectral_model=load_spectral_model(_resolve(value, base_dir)))
    g = _Reader(value, "top.spectral", r.file, {"emission_peak_nm", "emission_fwhm_nm", "start_nm", "stop_nm",
                                                "step_nm"})
    peak = g.number("emission_peak_nm", lo=WAVELENGTH_RANGE_NM[0], hi=WAVELENGTH_RANGE_NM[1], required=True)
    fwhm = g.number("emission_fwhm_nm", lo=0, lo_open=True, required=True)
    start = g.number("start_nm", 380.0, lo=WAVELENGTH_RANGE_NM[0], hi=WAVELENGTH_RANGE_NM[1])
    stop = g.number("stop_nm", 780.0, lo=WAVELENGTH_RANGE_NM[0], hi=WAVELENGTH_RANGE_NM[1])
    step = g.number("step_nm", 5.0, lo=0, lo_open=True)
    n = round((stop - start) / step) + 1
    if not (stop > start and 2 <= n <= 1024):
        raise ValidationError("bad spectral grid", file=r.file, field="top.spectral.step_nm",
                              expected="start_nm < stop_nm with 2-1024 steps", got=(start, stop, step))
    wl = start + step * np.arange(n)
    emission = gaussian(wl, peak, fwhm)
    model = spectral_plate_from_two_colour(top.plate, wl, emission,
                                           name=f"{top.plate.name} with a Gaussian emission ({peak:g}, {fwhm:g} nm)")
    return replace(top, spectral_emission=(peak, fwhm, start, stop, step), spectral_model=model)


def _check_spectral(trace: TraceOptions, leds: Leds, top: Top, file) -> None:
    if trace.mode != "spectral":
        # (a recipe validates its scene before the plate exists: a plate source given is enough here)
        if top.kind == "phosphor" and top.plate is None and top.plate_file is None and top.plate_recipe is None:
            raise InputError("the two-wavelength mode needs the plate", file=file, field="top.plate",
                             expected="plate = 'file.json', from = 'recipe.toml' or [top.plate]")
        return
    if leds.spectrum is None:
        raise InputError("the spectral mode needs the LED spectrum", file=file, field="leds.spectrum",
                         expected="spectrum = 'file' or spectrum_peak_nm and spectrum_fwhm_nm")
    if top.kind == "lambertian" or (top.kind == "phosphor" and top.spectral_model is None):
        raise InputError("the spectral mode needs an exit top or a phosphor top with a spectral model", file=file,
                         field="top.spectral", expected="spectral = 'model.nc' or a [top.spectral] table",
                         got=top.kind)


def _with_blue_reflectance(surface: Surface, leds: Leds) -> Surface:
    if surface.spectrum is None:
        return surface
    return replace(surface, reflectance=band_reflectances(surface, leds)[0])


def band_reflectances(surface: Surface, leds: Leds) -> tuple[float, float]:
    """(blue, yellow) reflectance of a spectral surface for the two-wavelength mode: ρ weighted by the LED spectrum
    (flat without one) over the module blue band and flat over the module yellow band.

    Parameters
    ----------
    surface : Surface
        A surface with a reflectance spectrum.
    leds : Leds
        The LEDs, whose spectrum (if any) weights the blue band.

    Returns
    -------
    blue, yellow : float
        Band reflectances [-].
    """
    wl, rho = surface.spectrum
    model = lambertian_from_reflectance(wl, rho, source=surface.spectrum_file or "")
    out = []
    for band, weighting in ((MODULE_BLUE_BAND_NM, leds.spectrum), (MODULE_YELLOW_BAND_NM, None)):
        if weighting is None:
            lam = np.arange(band[0], band[1] + 0.5)
            weight = np.ones_like(lam)
        else:
            lam, weight = weighting
        out.append(band_weighted_reflectance(model, lam, weight, band))
    return out[0], out[1]


def spectral_grid(scene: Scene) -> np.ndarray:
    """Bin centres [nm] of a spectral scene: the plate model's emission grid, else ``[trace] spectral_grid_nm``.

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    ndarray
        Bin centres [nm].
    """
    if scene.top.spectral_model is not None:
        return scene.top.spectral_model.emission_nm
    start, stop, step = scene.trace.spectral_grid_nm
    return start + step * np.arange(round((stop - start) / step) + 1)


def scene_spectral_tables(scene: Scene) -> SpectralTables:
    """The spectral kernel's tables of ``scene`` (:func:`bsdfkit.raytrace.spectral.spectral_tables`).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    SpectralTables
        The kernel's spectral tables (bins in [nm]).
    """
    source = None if scene.path is None else str(scene.path)
    return spectral_tables(scene.top.spectral_model, scene.top.plate, spectral_grid(scene), scene.leds.spectrum,
                           source=source, temperature_K=scene.top.temperature_K)


#: the cavity surfaces in the order of the kernel's per-surface inputs (reflectance rows, ``rho_table`` blocks)
CAVITY_SURFACES = ("wall", "base", "leds")


def surface_reflectance_table(scene: Scene) -> np.ndarray:
    """Reflectance of wall, base and LED disks per colour (two-wavelength: blue, yellow) or per bin (spectral),
    flattened row-major (surface, colour) for the kernel.

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    ndarray
        Reflectances [-], 3 × (2 colours or K bins), flattened.
    """
    rows = []
    spectral = scene.trace.mode == "spectral"
    lam = spectral_grid(scene) if spectral else None
    surfaces = {"wall": scene.wall, "base": scene.base, "leds": scene.led_surface}
    for name in CAVITY_SURFACES:
        sf = surfaces[name]
        if sf.spectrum is None:
            rows.append(np.full(lam.size if spectral else 2, sf.reflectance))
        elif spectral:
            rows.append(surface_reflectance_on_bins(sf.spectrum, lam, f"{name}.reflectance_spectrum",
                                                    sf.spectrum_file))
        else:
            rows.append(np.asarray(band_reflectances(sf, scene.leds)))
    return np.concatenate(rows).astype(np.float64)


#: Largest irradiance-map side (bins): the map is an int64 array of MAP_PARTS (16) × side² per device (32 MiB at
#: 512), and bin indices must stay in int32.
MAX_MAP_BINS = 512
#: Largest incidence histogram (bins over 0-90 deg: 0.01 deg) and interaction budget (plate visits per ray).
MAX_HISTOGRAM_BINS = 9000
MAX_BUDGET_BINS = 10_000
#: Most events per ray in a closed lossless cavity, where every ray runs to ``max_events`` (see check_termination).
LOSSLESS_MAX_EVENTS = 1000
#: float32 positions keep ~7 digits: the cavity must stay below this size [mm] and its smallest feature (the LED
#: emitter) above this fraction of it, or hits near the rim and the emitters are misplaced.
FLOAT32_MAX_EXTENT_MM = 1e5
FLOAT32_MIN_FEATURE_RATIO = 1e-4


def _check_sizes(cavity: Cavity, leds: Leds, trace: TraceOptions, tallies: Tallies, file) -> None:
    """Bounds that protect memory and accuracy, checked before anything is allocated or traced."""
    if tallies.map_bins > MAX_MAP_BINS:
        raise InputError("irradiance map too fine", file=file, field="tallies.map_bins",
                         expected=f"<= MAX_MAP_BINS ({MAX_MAP_BINS})", got=tallies.map_bins)
    for name, value, limit, limit_name in (
            ("histogram_bins", tallies.histogram_bins, MAX_HISTOGRAM_BINS, "MAX_HISTOGRAM_BINS"),
            ("budget_bins", tallies.budget_bins, MAX_BUDGET_BINS, "MAX_BUDGET_BINS")):
        if value > limit:
            raise InputError("tally too fine", file=file, field=f"tallies.{name}",
                             expected=f"<= {limit_name} ({limit})", got=value)
    if trace.precision == "float32":
        extent = max(cavity.radius_mm, cavity.height_mm, abs(leds.pitch_mm) * max(leds.grid, 1))
        feature = leds.emitter_radius_mm if leds.ray_file is None else extent
        if extent > FLOAT32_MAX_EXTENT_MM or feature < FLOAT32_MIN_FEATURE_RATIO * extent:
            raise InputError("float32 geometry would lose accuracy at this scene's size", file=file,
                             field="trace.precision",
                             expected=f'"float64" for cavities above {FLOAT32_MAX_EXTENT_MM:g} mm or emitters '
                                      f"below {FLOAT32_MIN_FEATURE_RATIO:g} of the cavity size",
                             got=f"float32 with extent {extent:g} mm, emitter {feature:g} mm")


def loads_scene(text: str, file: str | Path | None = None, *, plate_resolver: PlateResolver | None = None) -> Scene:
    """Parse scene TOML text (``file`` is used for messages and relative paths).

    Parameters
    ----------
    text : str
        The scene TOML text.
    file : str or Path, optional
        The file it came from.
    plate_resolver : PlateResolver, optional
        Builds the plate of the recipe a ``[top] from`` names (:func:`parse_scene`).

    Returns
    -------
    Scene
        The validated scene.
    """
    return parse_scene(loads_toml(text, file), file, plate_resolver=plate_resolver)


def load_scene(path: str | Path, *, plate_resolver: PlateResolver | None = None) -> Scene:
    """Read a scene TOML file.

    Parameters
    ----------
    path : str or Path
        The scene TOML file.
    plate_resolver : PlateResolver, optional
        Builds the plate of the recipe a ``[top] from`` names (:func:`parse_scene`).

    Returns
    -------
    Scene
        The validated scene.
    """
    path = Path(path)
    return loads_scene(read_text(path, expected="a scene TOML file"), path, plate_resolver=plate_resolver)


# ---- writing ----------------------------------------------------------------------------------------------
def scene_to_mapping(scene: Scene) -> dict[str, Any]:
    """The TOML mapping of ``scene`` (inverse of :func:`parse_scene`).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    dict
        Section → table; lengths in [mm], angles in [deg], power in [W].
    """
    leds = scene.leds
    led_map: dict[str, Any] = {"count": leds.count, "pitch_mm": leds.pitch_mm,
                               "emitter_radius_mm": leds.emitter_radius_mm}
    if leds.fwhm is None:
        led_map["distribution"] = "lambertian"
    else:
        led_map["distribution"] = "fwhm"
        led_map["fwhm_deg"] = math.degrees(leds.fwhm)
    led_map["power_W"] = leds.power_W
    led_map["led_reflectance"] = leds.led_reflectance
    led_map["led_specular_fraction"] = leds.led_specular_fraction
    led_map["ray_file"] = leds.ray_file
    led_map["spectrum"] = leds.spectrum_file
    led_map["spectrum_peak_nm"] = leds.spectrum_peak_nm
    led_map["spectrum_fwhm_nm"] = leds.spectrum_fwhm_nm
    top = scene.top
    top_map: dict[str, Any] = {"kind": top.kind}
    if top.kind == "lambertian":
        top_map.update(reflectance=top.reflectance, transmittance=top.transmittance)
    elif top.kind == "phosphor":
        if top.plate_file is not None:
            top_map["plate"] = top.plate_file
        elif top.plate_recipe is not None:
            top_map["from"] = top.plate_recipe
        elif top.plate is not None:
            top_map["plate"] = top.plate.to_mapping()
        if top.spectral_file is not None:
            top_map["spectral"] = top.spectral_file
        elif top.spectral_emission is not None:
            top_map["spectral"] = dict(zip(("emission_peak_nm", "emission_fwhm_nm", "start_nm", "stop_nm", "step_nm"),
                                           top.spectral_emission))
        if top.spectral_file is not None or top.spectral_emission is not None:
            top_map["temperature_K"] = top.temperature_K
    t = scene.trace
    doc: dict[str, Any] = {
        "cavity": {"radius_mm": scene.cavity.radius_mm, "height_mm": scene.cavity.height_mm},
        "wall": _surface_mapping(scene.wall),
        "base": _surface_mapping(scene.base),
        "leds": led_map,
        "top": top_map,
        "trace": {"termination": t.termination, "roulette_threshold": t.roulette_threshold,
                  "threshold": t.threshold, "max_events": t.max_events, "precision": t.precision,
                  "lanes": t.lanes, "chunk": t.chunk, "mode": t.mode, "spectral_grid_nm": list(t.spectral_grid_nm)},
        "tallies": {k: getattr(scene.tallies, k) for k in ("irradiance_map", "map_bins", "incidence_histogram",
                                                           "histogram_bins", "interaction_budget", "budget_bins")},
    }
    if scene.sweep is not None:
        doc["sweep"] = {"params": list(scene.sweep.params), "rays": scene.sweep.rays, "seed": scene.sweep.seed}
    return doc


def _surface_mapping(surface: Surface) -> dict[str, Any]:
    if surface.spectrum_file is not None:
        return {"reflectance_spectrum": surface.spectrum_file, "specular_fraction": surface.specular_fraction}
    return {"reflectance": surface.reflectance, "specular_fraction": surface.specular_fraction}


def dumps_scene(scene: Scene) -> str:
    """The scene as TOML text.

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    str
        TOML text.
    """
    return toml_write.dumps(scene_to_mapping(scene))


def save_scene(scene: Scene, path: str | Path, force: bool = False) -> Path:
    """Write the scene as TOML, atomically; an existing file is kept unless ``force``.

    Parameters
    ----------
    scene : Scene
        The scene.
    path : str or Path
        The TOML file to write.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        The file written.
    """
    return write_text(path, dumps_scene(scene), force)


def map_symmetry(scene: Scene) -> int:
    """How many symmetries of the square map the scene's irradiance on the plate has: 8 or 1.

    The cavity is a cylinder, its surfaces and the plate scatter isotropically and the analytic LEDs sit on a
    k × k grid centred on the axis with rotation-symmetric emission: rotations by 90° and the mirrors of the square
    map the scene onto itself, so they map the irradiance field onto itself (8). LEDs from a ray file carry their
    own far field and positions: no symmetry is assumed (1).

    Parameters
    ----------
    scene : Scene
        The scene.

    Returns
    -------
    int
        8 or 1.
    """
    return 1 if scene.leds.ray_file is not None else 8


def with_values(scene: Scene, values: Mapping[str, Any]) -> Scene:
    """A copy of ``scene`` with ``{"section.key": value}`` set, re-validated like a file.

    Setting ``leds.fwhm_deg`` also sets ``leds.distribution = "fwhm"``; setting ``leds.distribution`` to
    ``"lambertian"`` drops ``fwhm_deg``.

    Parameters
    ----------
    scene : Scene
        The base scene.
    values : mapping of str to object
        ``section.key`` → new value, in the units of the TOML key (e.g. ``cavity.height_mm`` in mm).

    Returns
    -------
    Scene
        The modified, validated scene (same path).
    """
    doc = scene_to_mapping(scene)
    for dotted, value in values.items():
        section, _, key = dotted.partition(".")
        if not key or section not in doc or not isinstance(doc[section], dict):
            raise InputError("parameter must name a scene key as section.key", field=dotted,
                             expected="e.g. wall.reflectance, cavity.height_mm, leds.fwhm_deg", got=dotted)
        doc[section][key] = value
        if dotted == "leds.fwhm_deg":
            doc["leds"]["distribution"] = "fwhm"
        if dotted == "leds.distribution" and value == "lambertian":
            doc["leds"].pop("fwhm_deg", None)
    doc = _drop_none(doc)
    preloaded: dict[str, Any] = {}
    if scene.leds.ray_file is not None:
        preloaded["ray_file"] = (scene.leds.ray_file, scene.leds.rays)
    if scene.top.plate_file is not None:
        preloaded["plate"] = (("plate", scene.top.plate_file), scene.top.plate)
    elif scene.top.plate_recipe is not None:
        preloaded["plate"] = (("from", scene.top.plate_recipe), scene.top.plate)
    if scene.top.spectral_file is not None:
        preloaded["spectral"] = (scene.top.spectral_file, scene.top.spectral_model)
    return replace(parse_scene(doc, scene.path, preloaded=preloaded), path=scene.path)


def _drop_none(node: Any) -> Any:
    if isinstance(node, dict):
        return {k: _drop_none(v) for k, v in node.items() if v is not None}
    return node


#: Most surface events one trace may cost (about three hours at 1e7 events/s on a CPU): bounds, before anything
#: is compiled, the work of a cavity that absorbs so slowly that its rays bounce for a very long time.
MAX_TRACE_EVENTS = 10 ** 11


def _max_reflectance(surface: Surface) -> float:
    """The largest fraction [1] of the incident power ``surface`` returns at any wavelength it is traced at."""
    if surface.spectrum is None:
        return float(surface.reflectance)
    return max(float(surface.reflectance), float(np.max(surface.spectrum[1])))


def top_reflectance(top: Top, mode: str = "two-wavelength", least: bool = False) -> float | None:
    """The largest (``least``: the smallest) fraction [1] of the power meeting the top that it sends back into
    the cavity, over every incidence, colour (and excitation wavelength in the spectral mode); None for an exit
    (everything leaves).

    Lambertian top: its ``reflectance``. Phosphor plate: the reflection-side TIS, bibs + biys for blue and yiys
    for yellow rays (two-wavelength mode; yellow only counts when blue converts, biys > 0), elastic + converted
    reflection TIS of the spectral model (spectral mode); the rest is transmitted out of the module or absorbed.
    The largest bounds the events of a ray (:func:`events_per_ray`); the smallest is 1 only for a top that loses
    nothing at any incidence (:func:`check_termination`).

    Parameters
    ----------
    top : Top
        The scene's top.
    mode : str
        ``two-wavelength`` or ``spectral``.
    least : bool
        Return the smallest instead of the largest.

    Returns
    -------
    float or None
        The fraction [-], or None for an exit top.
    """
    pick = np.min if least else np.max
    if top.kind == "exit":
        return None
    if top.kind == "lambertian":
        return float(top.reflectance)
    if mode == "spectral" and top.spectral_model is not None:
        m = top.spectral_model
        return float(pick(m.elastic_tis[0] + m.converted_tis[0]))
    if top.plate is None:
        return None
    p = top.plate
    values = [pick(np.asarray(p.bibs_reflection.tis) + np.asarray(p.biys_reflection.tis))]
    if np.any(np.asarray(p.biys_reflection.tis) > 0) or np.any(np.asarray(p.biys_transmission.tis) > 0):
        values.append(pick(p.yiys_reflection.tis))
    return float(pick(values))


def events_per_ray(wall: Surface, base: Surface, leds: Leds, top: Top, trace: TraceOptions) -> float | None:
    """Events one ray costs at most (on average, with the roulette) in a cavity closed by a reflecting top.

    Every event multiplies a ray's weight by at most ρ_max (the largest reflectance of wall, base, LEDs and
    top, :func:`top_reflectance`: a Lambertian top or a phosphor plate; light the top transmits leaves), so
    the flux threshold Th ends it after ln Th / ln ρ_max events and the roulette, once the weight is at its
    threshold, after 1/(1 − ρ_max) more on average; ``max_events`` caps both. None for an exit top, through
    which rays leave at a rate the geometry sets.

    Parameters
    ----------
    wall, base : Surface
        The cavity's wall and base.
    leds : Leds
        The LEDs (their reflectance).
    top : Top
        The top.
    trace : TraceOptions
        Termination, thresholds, ``max_events`` and mode.

    Returns
    -------
    float or None
        Events per ray [-], or None for an exit top.
    """
    rho_top = top_reflectance(top, trace.mode)
    if rho_top is None:
        return None
    rho_led = base.reflectance if leds.led_reflectance is None else leds.led_reflectance
    rho = max(_max_reflectance(wall), _max_reflectance(base), rho_led, rho_top)
    if rho >= 1.0:
        return float(trace.max_events)
    if rho <= 0.0:
        return 1.0
    level = trace.threshold if trace.termination == "threshold" else trace.roulette_threshold
    n = math.log(level) / math.log(rho) + 1.0
    if trace.termination != "threshold":
        n += 1.0 / (1.0 - rho)
    return float(min(n, trace.max_events))


def check_work(scene: "Scene", rays: int) -> None:
    """Refuse a trace whose surface events would exceed :data:`MAX_TRACE_EVENTS` (see :func:`events_per_ray`).

    Parameters
    ----------
    scene : Scene
        The scene to trace.
    rays : int
        Rays to trace.

    Raises
    ------
    ValidationError
        If rays × events per ray exceeds :data:`MAX_TRACE_EVENTS`.
    """
    n = events_per_ray(scene.wall, scene.base, scene.leds, scene.top, scene.trace)
    if n is not None and rays * n > MAX_TRACE_EVENTS:
        raise ValidationError("the trace would cost too many surface events (a closed cavity that absorbs very "
                              "little)", file=scene.path, field="rays",
                              expected=f"rays x events per ray <= MAX_TRACE_EVENTS ({MAX_TRACE_EVENTS:.0e}): fewer "
                                       "rays, a lower reflectance, a smaller max_events or a higher threshold",
                              got=f"{rays} x {n:.3g}")


def check_termination(wall: Surface, base: Surface, leds: Leds, top: Top, trace: TraceOptions, file) -> None:
    """Refuse a closed lossless cavity with many events per ray, which would trace for ever.

    A ray ends when it leaves through the top, when a surface absorbs it (its weight drops by the
    reflectance at every bounce until the roulette or the flux threshold ends it) or after ``max_events``.
    With wall, base and LEDs of reflectance 1 and a top that sends everything back (a Lambertian top of
    reflectance 1, or a phosphor plate whose reflection-side TIS is 1 at every incidence: it neither
    transmits nor absorbs, :func:`top_reflectance`), rays need not ever leave or lose weight: they run to
    ``max_events`` whatever the termination, their power is "truncated", and the run costs rays x max_events
    events (2e6 rays under a lossless plate: 2e10 events, hours). Such a scene is accepted only as a test of
    the truncation ledger, with ``max_events`` <= :data:`LOSSLESS_MAX_EVENTS`.

    Parameters
    ----------
    wall, base : Surface
        The cavity's wall and base.
    leds : Leds
        The LEDs (their reflectance).
    top : Top
        The top.
    trace : TraceOptions
        Mode and ``max_events``.
    file : str or Path or None
        The scene file, named in the error.

    Raises
    ------
    ValidationError
        For a closed lossless cavity with ``max_events`` above :data:`LOSSLESS_MAX_EVENTS`.
    """
    rho_led = base.reflectance if leds.led_reflectance is None else leds.led_reflectance
    rho_top = top_reflectance(top, trace.mode, least=True)
    closed = rho_top is not None and rho_top >= 1.0
    lossless = min(_max_reflectance(wall), _max_reflectance(base), rho_led) >= 1.0
    if closed and lossless and trace.max_events > LOSSLESS_MAX_EVENTS:
        what = "closed top" if top.kind == "lambertian" else "a plate that reflects everything"
        raise ValidationError(f"no ray can ever leave or be absorbed (reflectance 1 everywhere, {what}): every "
                              "ray would run to max_events", file=file, field="trace.max_events",
                              expected=f"an exit, a transmitting top or a reflectance < 1, or max_events <= "
                                       f"LOSSLESS_MAX_EVENTS ({LOSSLESS_MAX_EVENTS})", got=trace.max_events)
