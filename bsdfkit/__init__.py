"""bsdfkit: goniophotometer spectral scans in, validated BSDF models and ray-tracer tables out.

Modules follow the data flow (see docs/architecture.md):
``io.goniometer`` → ``calibrate`` → ``spectral`` / ``angular`` → ``budget``; ``models`` / ``fit``;
``frames`` / ``export``; ``trace``. Importing the package is cheap: submodules are imported on use.
"""
__version__ = "0.1.0"
