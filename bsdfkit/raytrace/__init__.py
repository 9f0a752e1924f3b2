"""JAX Monte Carlo tracer for cylindrical remote-phosphor LED modules (docs/tracer.md).

Data flow: scene TOML → :class:`Scene` (frozen dataclasses) → :class:`Effects` (static kernel
configuration) + kernel parameters → chunked, compiled kernel → exact tallies → :class:`TraceResult`.

>>> from bsdfkit.raytrace import load_scene, trace
>>> result = trace(load_scene("scene.toml"), rays=100_000, seed=1)   # doctest: +SKIP
>>> result.LER, result.std_err["LER"], result.ledger_error            # doctest: +SKIP
"""
from bsdfkit.raytrace.effects import Effects, scene_effects
from bsdfkit.raytrace.plate import LambertGaussian, Lambertian, PhosphorPlate, PlateChannel, Tabulated, load_plate
from bsdfkit.raytrace.rayfile import RaySet, read_ray_file
from bsdfkit.raytrace.scene import (
                                 Cavity,
                                 Leds,
                                 Scene,
                                 Surface,
                                 Tallies,
                                 Top,
                                 TraceOptions,
                                 dumps_scene,
                                 load_scene,
                                 loads_scene,
                                 save_scene,
                                 with_values,
)
from bsdfkit.raytrace.spectral import (
                                    SpectralPlateModel,
                                    load_spectral_model,
                                    spectral_model_from_dataset,
                                    spectral_plate_from_two_colour,
)
from bsdfkit.raytrace.tallies import SpectralResult, TraceResult
from bsdfkit.raytrace.tracer import threshold_bias, trace

__all__ = [
    "Cavity", "Effects", "LambertGaussian", "Lambertian", "Leds", "PhosphorPlate", "PlateChannel", "RaySet",
    "Scene", "SpectralPlateModel", "SpectralResult", "Surface", "Tabulated", "Tallies", "Top", "TraceOptions",
    "TraceResult", "dumps_scene", "load_plate", "load_scene", "load_spectral_model", "loads_scene", "read_ray_file",
    "save_scene", "scene_effects", "spectral_model_from_dataset", "spectral_plate_from_two_colour",
    "threshold_bias", "trace", "with_values",
]
