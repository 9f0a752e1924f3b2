"""Effects: the static configuration a scene compiles to, and the numeric parameters of the kernel.

The kernel (:mod:`bsdfkit.raytrace.kernel`) is specialised on an :class:`Effects` record passed as a static
argument to ``jax.jit``: code for a feature the scene does not use is never traced, so a diffuse-only
cavity with an exit top carries no specular, conversion, plate, map, histogram or budget code. Everything
that is a number (reflectances, geometry, plate tables) goes into :func:`kernel_params`, a :class:`KernelParams`
(named tuples: JAX pytrees of arrays), so sweeping a number reuses the compiled kernel. A part the effects do not
use (ray file, surface spectra, spectral tables, plate) is None: an empty pytree, so it adds no kernel input.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from bsdfkit.raytrace.plate import PhosphorPlate, PlateTables, plate_tables
from bsdfkit.raytrace.scene import CAVITY_SURFACES, Scene, scene_spectral_tables, surface_reflectance_table

#: rows of :attr:`KernelParams.rho` and :attr:`KernelParams.spec` (and blocks of ``rho_table``)
SURFACE_WALL, SURFACE_BASE, SURFACE_LEDS = (CAVITY_SURFACES.index(s) for s in ("wall", "base", "leds"))


@dataclass(frozen=True)
class Effects:
    """Hashable static configuration of the kernel (see module docstring)."""

    precision: str = "float32"
    source: str = "leds"  # "leds" | "rayfile"
    specular: bool = False  # any mirror-like reflection in the cavity
    top: str = "exit"  # "exit" | "plate" (diffuser and phosphor tops are both plates)
    conversion: bool = False  # blue → yellow (biys) possible
    plate_lobe: bool = False  # a Lambert+Gaussian backward distribution with a lobe
    plate_table: bool = False  # a tabulated backward distribution
    plate_clamp: bool = False  # the plate grid does not cover 0–90°: count clamped incidences
    termination: str = "roulette"  # "roulette" | "threshold"
    irradiance_map: bool = False
    map_bins: int = 32
    incidence_histogram: bool = False
    histogram_bins: int = 90
    interaction_budget: bool = False
    budget_bins: int = 16
    spectral: bool = False  # [trace] mode = "spectral": rays carry a wavelength bin (bsdfkit.raytrace.spectral)
    surface_spectra: bool = False  # a cavity surface's reflectance depends on the ray's colour or bin

    @property
    def dtype(self):
        return jnp.float32 if self.precision == "float32" else jnp.float64


def top_plate(scene: Scene) -> PhosphorPlate | None:
    """The top as a plate: the phosphor plate itself, or the equivalent non-converting plate.

    A Lambertian diffuser (ρ, τ) is the plate bibs = yiys = (ρ, τ) with Lambertian distributions; an exit
    top is the plate with bibs and yiys transmission 1 (used only when an exit top is forced through the
    full kernel).

    Parameters
    ----------
    scene : Scene
        The parsed scene; its ``top`` is read.

    Returns
    -------
    PhosphorPlate
        The plate standing for the top.
    """
    top = scene.top
    if top.kind == "phosphor":
        return top.plate
    if top.kind == "lambertian":
        return PhosphorPlate.constant({"bibs_reflection": top.reflectance, "bibs_transmission": top.transmittance,
                                       "yiys_reflection": top.reflectance, "yiys_transmission": top.transmittance},
                                      name="Lambertian diffuser top")
    return PhosphorPlate.constant({"bibs_transmission": 1.0, "yiys_transmission": 1.0}, name="exit top")


def scene_effects(scene: Scene, full: bool = False) -> Effects:
    """The effects a scene needs; ``full=True`` switches every optional branch on (benchmark/tests).

    Parameters
    ----------
    scene : Scene
        The parsed scene.
    full : bool
        Switch every optional branch on.

    Returns
    -------
    Effects
        The static kernel configuration.
    """
    t = scene.tallies
    common = dict(precision=scene.trace.precision, source="rayfile" if scene.leds.ray_file else "leds",
                  termination=scene.trace.termination, map_bins=t.map_bins, histogram_bins=t.histogram_bins,
                  budget_bins=t.budget_bins)
    spectral = scene.trace.mode == "spectral"
    surface_spectra = any(s.spectrum is not None for s in (scene.wall, scene.base, scene.led_surface))
    if full:
        top = "exit" if spectral and scene.top.spectral_model is None else "plate"
        return Effects(specular=True, top=top, conversion=not spectral, plate_lobe=True, plate_table=True,
                       plate_clamp=True, irradiance_map=True, incidence_histogram=True, interaction_budget=True,
                       spectral=spectral, surface_spectra=True, **common)
    specular = any(s.specular_fraction > 0 and s.reflectance > 0
                   for s in (scene.wall, scene.base, scene.led_surface))
    if spectral:  # the plate's angular tables on the spectral model's incidence grid (None: exit top)
        tables = scene_spectral_tables(scene).plate
    elif scene.top.kind == "exit":
        tables = None
    else:
        tables = plate_tables(top_plate(scene))
    if tables is not None:
        # with a plate the mirror branch costs a few per cent of an interaction: compile it in always, so
        # scenes (and sweeps) that differ only in their specular fractions share one kernel; a specular
        # fraction of 0 then never draws a mirror reflection (same random numbers, same result)
        specular = True
    return Effects(
        specular=specular,
        top="exit" if tables is None else "plate",
        conversion=bool(not spectral and tables is not None and tables.conversion),
        plate_lobe=bool(tables is not None and tables.has_lobe),
        plate_table=bool(tables is not None and tables.has_table),
        plate_clamp=bool(tables is not None and not tables.covers_hemisphere),
        irradiance_map=scene.tally_enabled("irradiance_map"),
        incidence_histogram=scene.tally_enabled("incidence_histogram"),
        interaction_budget=scene.tally_enabled("interaction_budget"),
        spectral=spectral,
        surface_spectra=surface_spectra,
        **common,
    )


class RayFileParams(NamedTuple):
    """The source as a ray file (``effects.source == "rayfile"``), N rays.

    Attributes
    ----------
    origin : array (N, 3)
        Start points [mm].
    direction : array (N, 3)
        Unit directions [-].
    cdf : array (N,)
        Cumulative ray powers normalised to 1 (last entry exactly 1) [-], float64.
    """

    origin: Any
    direction: Any
    cdf: Any


class SpectralParams(NamedTuple):
    """Tables of the spectral mode (``effects.spectral``) on K wavelength bins; see
    :class:`bsdfkit.raytrace.spectral.SpectralTables`.

    Attributes
    ----------
    lam : array (K,)
        Bin centres [nm].
    photon_scale : array (K,)
        λ_k / λ_K−1: photons per unit weight of a ray in bin k, in photons of the longest bin [-].
    band : array (K,) of int32
        :data:`~bsdfkit.raytrace.spectral.BAND_BLUE`, ``BAND_YELLOW`` or ``BAND_OTHER``.
    elastic_shape : array (K,) of int32
        Backward channel (:data:`~bsdfkit.raytrace.plate.BACK_BIBS` or ``BACK_YIYS``) whose angular
        distribution elastic light of bin k takes.
    led_cdf : array (K,)
        Cumulative LED bin powers (last entry exactly 1) [-].
    tis : array (G·K, 4) or None
        Photons out per incident photon in :data:`~bsdfkit.raytrace.spectral.PHOTON_CHANNELS` order at (incidence
        g, bin k) → row g·K + k [-]; None with an exit top.
    alias_prob, alias_index : array (K·K,) or None
        Alias tables of the conditional emission rows (probability [-], float64; bin index, int32); None with an
        exit top.
    """

    lam: Any
    photon_scale: Any
    band: Any
    elastic_shape: Any
    led_cdf: Any
    tis: Any = None
    alias_prob: Any = None
    alias_index: Any = None


class PlateParams(NamedTuple):
    """The plate's tables on its G incidence angles (``effects.top == "plate"``); see
    :class:`bsdfkit.raytrace.plate.PlateTables`.

    Attributes
    ----------
    grid : array (G,)
        Incidence angles θi [rad].
    range : array (2,)
        Measured θi range [rad] (the clamping rule).
    tis : array (G, 6)
        TIS per channel in :data:`~bsdfkit.raytrace.plate.CHANNELS` order [-], float64.
    kind : array (G, 3) of int
        Distribution of each :data:`~bsdfkit.raytrace.plate.BACKWARD` channel (``LAMBERTIAN``,
        ``LAMBERT_GAUSSIAN`` or ``TABULATED``).
    lobe_share : array (G, 3)
        TIS share of the Gaussian lobe [-].
    sigma : array (G, 3)
        Lobe width in projected direction cosines [-].
    s_nodes, f_nodes, cdf : array (G, 3, T)
        Tabulated distributions: nodes in s = sin²θs [-], density and cumulative distribution on them [-].
    """

    grid: Any
    range: Any
    tis: Any
    kind: Any
    lobe_share: Any
    sigma: Any
    s_nodes: Any
    f_nodes: Any
    cdf: Any


class KernelParams(NamedTuple):
    """Numeric inputs of the kernel (:func:`kernel_params`); float32 entries follow ``effects.precision``.

    Attributes
    ----------
    radius, height : array ()
        Cavity radius and height [mm].
    rho : array (3,)
        Total reflectance of wall, base and LED disks (:data:`SURFACE_WALL`, ``SURFACE_BASE``, ``SURFACE_LEDS``)
        [-], float64.
    spec : array (3,)
        Specular fraction of that reflectance, same rows [-], float64.
    led_grid : array () of int32
        LEDs per side of the square LED grid.
    pitch : array ()
        LED pitch [mm].
    emitter_radius : array ()
        Radius of an LED's emitting disk [mm].
    cos_exponent : array ()
        Exponent n of the LEDs' cosⁿ intensity [-].
    roulette_threshold, threshold : array ()
        Ray-weight thresholds of the roulette and of the flux threshold [-], float64.
    max_events : array () of int32
        Interactions after which a ray is retired as truncated.
    rays : RayFileParams or None
        The ray-file source; None for LEDs.
    rho_table : array (3·C,) or None
        Reflectance per surface and colour (C = 2) or bin (C = K), row surface·C + colour [-], float64; None
        without surface spectra.
    spectral : SpectralParams or None
        Spectral-mode tables; None in the two-wavelength mode.
    plate : PlateParams or None
        The plate on top; None for an exit top.
    """

    radius: Any
    height: Any
    rho: Any
    spec: Any
    led_grid: Any
    pitch: Any
    emitter_radius: Any
    cos_exponent: Any
    roulette_threshold: Any
    threshold: Any
    max_events: Any
    rays: RayFileParams | None = None
    rho_table: Any = None
    spectral: SpectralParams | None = None
    plate: PlateParams | None = None


def kernel_params(scene: Scene, effects: Effects) -> KernelParams:
    """Numeric kernel inputs (NumPy arrays): geometry, surfaces, source, plate tables.

    Parameters
    ----------
    scene : Scene
        The parsed scene.
    effects : Effects
        The static configuration from :func:`scene_effects`; selects which entries are built and their dtype.

    Returns
    -------
    KernelParams
        The arrays; the parts ``effects`` does not use are None.
    """
    dt = np.float32 if effects.precision == "float32" else np.float64
    leds, led = scene.leds, scene.led_surface
    surfaces = {"wall": scene.wall, "base": scene.base, "leds": led}
    rays = rho_table = spectral = plate = None
    if effects.source == "rayfile":
        cdf = np.cumsum(leds.rays.power) / np.sum(leds.rays.power)
        cdf[-1] = 1.0
        rays = RayFileParams(leds.rays.origin.astype(dt), leds.rays.direction.astype(dt), cdf)
    if effects.surface_spectra:
        rho_table = surface_reflectance_table(scene)
    if effects.spectral:
        sp = scene_spectral_tables(scene)
        spectral = SpectralParams(sp.lam, sp.photon_scale, sp.band, sp.elastic_shape, sp.led_cdf)
        if sp.plate is not None:
            spectral = spectral._replace(tis=sp.tis, alias_prob=sp.alias_prob, alias_index=sp.alias_index)
    if effects.top == "plate":
        tab: PlateTables = sp.plate if effects.spectral else plate_tables(top_plate(scene))
        plate = PlateParams(grid=tab.grid.astype(dt), range=np.asarray(tab.theta_range, dt), tis=tab.tis,
                            kind=tab.kind, lobe_share=tab.lobe_share, sigma=tab.sigma.astype(dt),
                            s_nodes=tab.s_nodes, f_nodes=tab.f_nodes, cdf=tab.cdf)
    return KernelParams(
        radius=np.asarray(scene.cavity.radius_mm, dt),
        height=np.asarray(scene.cavity.height_mm, dt),
        rho=np.asarray([surfaces[s].reflectance for s in CAVITY_SURFACES], np.float64),
        spec=np.asarray([surfaces[s].specular_fraction for s in CAVITY_SURFACES], np.float64),
        led_grid=np.asarray(leds.grid, np.int32),
        pitch=np.asarray(leds.pitch_mm, dt),
        emitter_radius=np.asarray(leds.emitter_radius_mm, dt),
        cos_exponent=np.asarray(leds.cos_exponent, dt),
        roulette_threshold=np.asarray(scene.trace.roulette_threshold, np.float64),
        threshold=np.asarray(scene.trace.threshold, np.float64),
        max_events=np.asarray(scene.trace.max_events, np.int32),
        rays=rays, rho_table=rho_table, spectral=spectral, plate=plate,
    )
