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
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import bsdfkit.raytrace.plate_from_scan as plate_source
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.io import toml_write
from bsdfkit.io.atomic import write_text
from bsdfkit.raytrace.plate import PhosphorPlate, load_plate
from bsdfkit.raytrace.rayfile import RaySet, read_ray_file

TOP_KINDS = ("exit", "lambertian", "phosphor")
TERMINATIONS = ("roulette", "threshold")
PRECISIONS = ("float32", "float64")


@dataclass(frozen=True)
class Cavity:
    """Cylinder of ``radius_mm`` and ``height_mm`` (base at z = 0, top at z = height)."""

    radius_mm: float
    height_mm: float


@dataclass(frozen=True)
class Surface:
    """A reflector: total ``reflectance``; ``specular_fraction`` of it is mirror-like, the rest Lambertian."""

    reflectance: float
    specular_fraction: float = 0.0


@dataclass(frozen=True)
class Leds:
    """Pump LEDs: Lambertian disks (or a cos^m intensity of given FWHM) in the base plane.

    ``fwhm`` (radians) is None for a Lambertian source; otherwise I(θ) ∝ cos^m θ with
    m = ln ½ / ln cos(FWHM/2) (m = 1 at FWHM = 120°, the Lambertian case). ``led_reflectance`` and
    ``led_specular_fraction`` default to the base's. ``ray_file`` replaces the emission model by rays
    read from a file (the disks still reflect); ``rays`` holds them once loaded.
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

    @property
    def grid(self) -> int:
        """k for a k × k grid of LEDs."""
        return math.isqrt(self.count)

    @property
    def cos_exponent(self) -> float:
        """m of the cos^m intensity (1 for Lambertian)."""
        if self.fwhm is None:
            return 1.0
        return math.log(0.5) / math.log(math.cos(self.fwhm / 2.0))

    def centres(self) -> list[tuple[float, float]]:
        """LED centres (x, y) in mm, row-major over the k × k grid."""
        k = self.grid
        off = [(i - (k - 1) / 2.0) * self.pitch_mm for i in range(k)]
        return [(x, y) for x in off for y in off]


@dataclass(frozen=True)
class Top:
    """The top of the cavity.

    ``exit``: all light reaching it leaves the module. ``lambertian``: a non-converting diffuser with
    ``reflectance`` and ``transmittance`` (both Lambertian). ``phosphor``: the plate of
    :mod:`bsdfkit.raytrace.plate`, from ``plate_file`` (JSON), ``plate_recipe`` (a fitting recipe resolved
    by :func:`bsdfkit.raytrace.plate_from_scan.plate_from_recipe`) or given inline.
    """

    kind: str = "exit"
    reflectance: float = 0.0
    transmittance: float = 0.0
    plate: PhosphorPlate | None = None
    plate_file: str | None = None
    plate_recipe: str | None = None


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
    kernel (memory ∝ lanes + chunk; progress granularity). Neither changes results.
    """

    termination: str = "roulette"
    roulette_threshold: float = 0.1
    threshold: float = 0.01
    max_events: int = 10000
    precision: str = "float32"
    lanes: int = 16384
    chunk: int = 1048576


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
        rho = self.base.reflectance if self.leds.led_reflectance is None else self.leds.led_reflectance
        spec = (self.base.specular_fraction if self.leds.led_specular_fraction is None
                else self.leds.led_specular_fraction)
        return Surface(rho, spec)

    def tally_enabled(self, name: str) -> bool:
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


def parse_scene(data: Mapping[str, Any], file: str | Path | None = None, *,
                preloaded: Mapping[str, Any] | None = None) -> Scene:
    """Build a :class:`Scene` from a TOML mapping; relative paths resolve against ``file``'s folder.

    ``preloaded`` may hold ``{"ray_file": (text, RaySet), "plate": (key, PhosphorPlate)}`` to skip
    re-reading unchanged files (used by sweeps).
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

    def surface(name: str) -> Surface:
        s = _Reader(data[name], name, file, {"reflectance", "specular_fraction"})
        return Surface(s.number("reflectance", lo=0, hi=1, required=True),
                       s.number("specular_fraction", 0.0, lo=0, hi=1))

    wall, base = surface("wall"), surface("base")

    r = _Reader(data["leds"], "leds", file, {"count", "pitch_mm", "emitter_radius_mm", "distribution", "fwhm_deg",
                                             "power_W", "led_reflectance", "led_specular_fraction", "ray_file"})
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

    r = _Reader(data["top"], "top", file, {"kind", "reflectance", "transmittance", "plate", "from"})
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
        for key in ("reflectance", "transmittance"):
            if r.has(key):
                raise InputError("a phosphor top takes its TIS from the plate", file=file, field=f"top.{key}",
                                 expected="plate = 'file.json', from = 'recipe.toml' or [top.plate]",
                                 got=r.table[key])
        given = [k for k in ("plate", "from") if r.has(k)]
        if len(given) != 1:
            raise InputError("a phosphor top needs exactly one plate source", file=file, field="top.plate",
                             expected="one of plate = 'file.json' | from = 'fitting/<recipe>.toml' | [top.plate]",
                             got=given or None)
        key = given[0]
        value = r.table[key]
        pre = preloaded.get("plate")
        if isinstance(value, Mapping):
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
        else:
            top = Top("phosphor", plate=plate_from_recipe(_resolve(value, base_dir), file), plate_recipe=value)

    trace = TraceOptions()
    if "trace" in data:
        r = _Reader(data["trace"], "trace", file, {"termination", "roulette_threshold", "threshold", "max_events",
                                                   "precision", "lanes", "chunk"})
        trace = TraceOptions(
            termination=r.string("termination", trace.termination, choices=TERMINATIONS),
            roulette_threshold=r.number("roulette_threshold", trace.roulette_threshold, lo=0, hi=1, lo_open=True),
            threshold=r.number("threshold", trace.threshold, lo=0, hi=1, lo_open=True, hi_open=True),
            max_events=r.integer("max_events", trace.max_events, lo=1),
            precision=r.string("precision", trace.precision, choices=PRECISIONS),
            lanes=r.integer("lanes", trace.lanes, lo=1),
            chunk=r.integer("chunk", trace.chunk, lo=1),
        )
        if trace.max_events >= 2 ** 29:
            raise ValidationError("too many events per ray for the random-number counter", file=file,
                                  field="trace.max_events", expected="< 2**29", got=trace.max_events)
    tallies = Tallies()
    if "tallies" in data:
        r = _Reader(data["tallies"], "tallies", file, {"irradiance_map", "map_bins", "incidence_histogram",
                                                       "histogram_bins", "interaction_budget", "budget_bins"})
        tallies = Tallies(
            irradiance_map=r.boolean("irradiance_map"),
            map_bins=r.integer("map_bins", tallies.map_bins, lo=2),
            incidence_histogram=r.boolean("incidence_histogram"),
            histogram_bins=r.integer("histogram_bins", tallies.histogram_bins, lo=1),
            interaction_budget=r.boolean("interaction_budget"),
            budget_bins=r.integer("budget_bins", tallies.budget_bins, lo=1),
        )
    sweep = None
    if "sweep" in data:
        r = _Reader(data["sweep"], "sweep", file, {"params", "rays", "seed"})
        params = r.table.get("params", [])
        if not isinstance(params, list) or not all(isinstance(p, str) for p in params):
            raise InputError("wrong type", file=file, field="sweep.params",
                             expected="a list of strings like 'wall.reflectance=0.80:0.98:5'", got=params)
        sweep = SweepDefaults(tuple(params), r.integer("rays", None, lo=1), r.integer("seed", None, lo=0))
    _check_sizes(cavity, leds, trace, tallies, file)
    check_termination(wall, base, leds, top, trace, file)
    return Scene(cavity, wall, base, leds, top, trace, tallies, sweep, Path(file) if file is not None else None)


#: Largest irradiance-map side (bins): the map is an int64 array of side², and bin indices must stay in int32.
MAX_MAP_BINS = 2048
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


def plate_from_recipe(recipe: Path, scene_file: str | Path | None) -> PhosphorPlate:
    """The plate of a fitting recipe (:func:`bsdfkit.raytrace.plate_from_scan.plate_from_recipe`)."""
    return plate_source.plate_from_recipe(recipe)


def loads_scene(text: str, file: str | Path | None = None) -> Scene:
    """Parse scene TOML text (``file`` is used for messages and relative paths)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"not valid TOML ({exc})", file=file) from None
    return parse_scene(data, file)


def load_scene(path: str | Path) -> Scene:
    """Read a scene TOML file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("scene file not found", file=path) from None
    except UnicodeDecodeError as exc:
        raise InputError("scene file is not UTF-8 text", file=path, expected="a TOML text file",
                         got=f"byte 0x{exc.object[exc.start]:02x} at offset {exc.start}") from None
    except OSError as exc:
        raise InputError(f"cannot read scene file ({exc.strerror})", file=path) from None
    return loads_scene(text, path)


# ---- writing ----------------------------------------------------------------------------------------------
def scene_to_mapping(scene: Scene) -> dict[str, Any]:
    """The TOML mapping of ``scene`` (inverse of :func:`parse_scene`)."""
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
    top = scene.top
    top_map: dict[str, Any] = {"kind": top.kind}
    if top.kind == "lambertian":
        top_map.update(reflectance=top.reflectance, transmittance=top.transmittance)
    elif top.kind == "phosphor":
        if top.plate_file is not None:
            top_map["plate"] = top.plate_file
        elif top.plate_recipe is not None:
            top_map["from"] = top.plate_recipe
        else:
            top_map["plate"] = top.plate.to_mapping()
    t = scene.trace
    doc: dict[str, Any] = {
        "cavity": {"radius_mm": scene.cavity.radius_mm, "height_mm": scene.cavity.height_mm},
        "wall": {"reflectance": scene.wall.reflectance, "specular_fraction": scene.wall.specular_fraction},
        "base": {"reflectance": scene.base.reflectance, "specular_fraction": scene.base.specular_fraction},
        "leds": led_map,
        "top": top_map,
        "trace": {"termination": t.termination, "roulette_threshold": t.roulette_threshold,
                  "threshold": t.threshold, "max_events": t.max_events, "precision": t.precision,
                  "lanes": t.lanes, "chunk": t.chunk},
        "tallies": {k: getattr(scene.tallies, k) for k in ("irradiance_map", "map_bins", "incidence_histogram",
                                                           "histogram_bins", "interaction_budget", "budget_bins")},
    }
    if scene.sweep is not None:
        doc["sweep"] = {"params": list(scene.sweep.params), "rays": scene.sweep.rays, "seed": scene.sweep.seed}
    return doc


def dumps_scene(scene: Scene) -> str:
    """The scene as TOML text."""
    return toml_write.dumps(scene_to_mapping(scene))


def save_scene(scene: Scene, path: str | Path, force: bool = False) -> Path:
    """Write the scene as TOML, atomically; an existing file is kept unless ``force``."""
    return write_text(path, dumps_scene(scene), force)


def with_values(scene: Scene, values: Mapping[str, Any]) -> Scene:
    """A copy of ``scene`` with ``{"section.key": value}`` set, re-validated like a file.

    Setting ``leds.fwhm_deg`` also sets ``leds.distribution = "fwhm"``; setting ``leds.distribution`` to
    ``"lambertian"`` drops ``fwhm_deg``.
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
    return replace(parse_scene(doc, scene.path, preloaded=preloaded), path=scene.path)


def _drop_none(node: Any) -> Any:
    if isinstance(node, dict):
        return {k: _drop_none(v) for k, v in node.items() if v is not None}
    return node


def check_termination(wall: Surface, base: Surface, leds: Leds, top: Top, trace: TraceOptions, file) -> None:
    """Refuse a closed lossless cavity with many events per ray, which would trace for ever.

    A ray ends when it leaves through the top, when a surface absorbs it (its weight drops by the
    reflectance at every bounce until the roulette or the flux threshold ends it) or after ``max_events``.
    With wall, base and LEDs of reflectance 1 and a top that neither transmits nor absorbs (a Lambertian top
    of reflectance 1), nothing can leave or absorb: every ray runs to ``max_events`` whatever the
    termination, all its power is "truncated", and the run costs rays x max_events events. Such a scene is
    accepted only as a test of the truncation ledger, with ``max_events`` <= :data:`LOSSLESS_MAX_EVENTS`.
    """
    rho_led = base.reflectance if leds.led_reflectance is None else leds.led_reflectance
    closed = top.kind == "lambertian" and top.reflectance >= 1.0
    if closed and min(wall.reflectance, base.reflectance, rho_led) >= 1.0 and trace.max_events > LOSSLESS_MAX_EVENTS:
        raise ValidationError("no ray can ever leave or be absorbed (reflectance 1 everywhere, closed top): every "
                              "ray would run to max_events", file=file, field="trace.max_events",
                              expected=f"an exit, a transmitting top or a reflectance < 1, or max_events <= "
                                       f"LOSSLESS_MAX_EVENTS ({LOSSLESS_MAX_EVENTS})", got=trace.max_events)
