"""Effects: the static configuration a scene compiles to, and the numeric parameters of the kernel.

The kernel (:mod:`bsdfkit.raytrace.kernel`) is specialised on an :class:`Effects` record passed as a static
argument to ``jax.jit``: code for a feature the scene does not use is never traced, so a diffuse-only
cavity with an exit top carries no specular, conversion, plate, map, histogram or budget code. Everything
that is a number (reflectances, geometry, plate tables) goes into :func:`kernel_params`, a pytree of arrays,
so sweeping a number reuses the compiled kernel.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from bsdfkit.raytrace.plate import PhosphorPlate, PlateTables, plate_tables
from bsdfkit.raytrace.scene import Scene, scene_spectral_tables, surface_reflectance_table


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


def kernel_params(scene: Scene, effects: Effects) -> dict:
    """Numeric kernel inputs (a pytree of NumPy arrays): geometry, surfaces, source, plate tables.

    Parameters
    ----------
    scene : Scene
        The parsed scene.
    effects : Effects
        The static configuration from :func:`scene_effects`; selects which entries are built and their dtype.

    Returns
    -------
    dict
        Name → array (nested dicts for ``spectral`` and ``plate``); lengths in [mm], reflectances [-].
    """
    dt = np.float32 if effects.precision == "float32" else np.float64
    leds, led = scene.leds, scene.led_surface
    p: dict = {
        "radius": np.asarray(scene.cavity.radius_mm, dt),
        "height": np.asarray(scene.cavity.height_mm, dt),
        "rho": np.asarray([scene.wall.reflectance, scene.base.reflectance, led.reflectance], np.float64),
        "spec": np.asarray([scene.wall.specular_fraction, scene.base.specular_fraction, led.specular_fraction],
                           np.float64),
        "led_grid": np.asarray(leds.grid, np.int32),
        "pitch": np.asarray(leds.pitch_mm, dt),
        "emitter_radius": np.asarray(leds.emitter_radius_mm, dt),
        "cos_exponent": np.asarray(leds.cos_exponent, dt),
        "roulette_threshold": np.asarray(scene.trace.roulette_threshold, np.float64),
        "threshold": np.asarray(scene.trace.threshold, np.float64),
        "max_events": np.asarray(scene.trace.max_events, np.int32),
    }
    if effects.source == "rayfile":
        rays = leds.rays
        cdf = np.cumsum(rays.power) / np.sum(rays.power)
        cdf[-1] = 1.0
        p["ray_origin"] = rays.origin.astype(dt)
        p["ray_direction"] = rays.direction.astype(dt)
        p["ray_cdf"] = cdf
    if effects.surface_spectra:
        p["rho_table"] = surface_reflectance_table(scene)
    if effects.spectral:
        sp = scene_spectral_tables(scene)
        p["spectral"] = {"lam": sp.lam, "photon_scale": sp.photon_scale, "band": sp.band,
                         "elastic_shape": sp.elastic_shape, "led_cdf": sp.led_cdf}
        if sp.plate is not None:
            p["spectral"].update(tis=sp.tis, alias_prob=sp.alias_prob, alias_index=sp.alias_index)
    if effects.top == "plate":
        tab: PlateTables = sp.plate if effects.spectral else plate_tables(top_plate(scene))
        p["plate"] = {
            "grid": tab.grid.astype(dt),
            "range": np.asarray(tab.theta_range, dt),
            "tis": tab.tis,
            "kind": tab.kind,
            "lobe_share": tab.lobe_share,
            "sigma": tab.sigma.astype(dt),
            "s_nodes": tab.s_nodes,
            "f_nodes": tab.f_nodes,
            "cdf": tab.cdf,
        }
    return p
