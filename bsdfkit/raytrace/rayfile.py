"""Source ray files: the "septuples" of §2 of [Cylindrical-module] (position, direction, flux).

Format (text, UTF-8): one ray per line, seven whitespace- or comma-separated numbers

    x  y  z  dx  dy  dz  power

with x, y, z in mm in the scene frame (cavity axis z, base at z = 0), (dx, dy, dz) any non-zero vector
(normalised on reading) and power in W (> 0). Blank lines and lines starting with ``#`` are ignored.
The tracer samples file rays with probability proportional to their power, so every traced ray carries the
same weight (total power / number of traced rays) and the estimate is unbiased for any ray count.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bsdfkit.core.errors import FormatError, ValidationError
from bsdfkit.io.text import read_text, refuse_cut_last_line


@dataclass(frozen=True, eq=False)
class RaySet:
    """Rays as arrays: ``origin`` (N, 3) mm, ``direction`` (N, 3) unit vectors, ``power`` (N,) W."""

    origin: np.ndarray
    direction: np.ndarray
    power: np.ndarray
    source: str = ""

    @property
    def total_power(self) -> float:
        return float(np.sum(self.power))

    def __len__(self) -> int:
        return int(self.power.size)

    def check_inside(self, radius: float, height: float, file=None, field: str = "ray_file") -> None:
        """Raise unless every ray starts inside the cavity and does not leave through the base at once.

        Parameters
        ----------
        radius : float
            Cavity radius [mm].
        height : float
            Cavity height [mm].
        file : str or Path, optional
            File named in the error.
        field : str
            Field named in the error.

        Raises
        ------
        ValidationError
            Naming the first ray that starts outside or points into the base.
        """
        r = np.hypot(self.origin[:, 0], self.origin[:, 1])
        z = self.origin[:, 2]
        tol = 1e-9 * max(radius, height)
        bad = (r > radius + tol) | (z < -tol) | (z > height + tol) | ((z <= tol) & (self.direction[:, 2] <= 0))
        if np.any(bad):
            k = int(np.argmax(bad))
            raise ValidationError(f"ray {k + 1} of {self.source or 'the ray file'} starts outside the cavity or "
                                  "points into the base", file=file, field=field,
                                  expected=f"r <= {radius:g} mm, 0 <= z <= {height:g} mm, dz > 0 on the base",
                                  got=tuple(float(v) for v in self.origin[k]))


def read_ray_file(path: str | Path) -> RaySet:
    """Read a ray file (see module docstring); errors name the file and line.

    Parameters
    ----------
    path : str or Path
        The ray file.

    Returns
    -------
    RaySet
        Origins [mm], unit directions [-] and powers [W].
    """
    path = Path(path)
    text = read_text(path, expected="a ray file (lines of x y z dx dy dz power)")
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 7:
            raise FormatError("a ray is seven numbers", file=path, line=lineno,
                              expected="x y z dx dy dz power", got=s)
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise FormatError("not a number", file=path, line=lineno, expected="x y z dx dy dz power",
                              got=s) from None
        if not all(np.isfinite(vals)):
            raise FormatError("non-finite value", file=path, line=lineno, expected="finite numbers", got=s)
        if vals[6] <= 0:
            raise ValidationError("ray power must be positive", file=path, line=lineno, expected="power > 0",
                                  got=vals[6])
        n = np.hypot(np.hypot(vals[3], vals[4]), vals[5])
        if n == 0:
            raise ValidationError("zero direction", file=path, line=lineno, expected="a non-zero (dx, dy, dz)",
                                  got=s)
        rows.append(vals)
    refuse_cut_last_line(text.replace(",", " "), path, None, expected="x y z dx dy dz power")
    if not rows:
        raise FormatError("no rays in file", file=path, expected="lines of x y z dx dy dz power")
    a = np.asarray(rows, dtype=float)
    d = a[:, 3:6] / np.linalg.norm(a[:, 3:6], axis=1, keepdims=True)
    return RaySet(origin=a[:, :3].copy(), direction=d, power=a[:, 6].copy(), source=str(path))


def format_rays(rays: RaySet) -> str:
    """Ray-file text for ``rays`` (inverse of :func:`read_ray_file`).

    Parameters
    ----------
    rays : RaySet
        The rays.

    Returns
    -------
    str
        One line ``x y z dx dy dz power`` per ray after a header line.
    """
    lines = ["# x_mm y_mm z_mm dx dy dz power_W"]
    for o, d, p in zip(rays.origin, rays.direction, rays.power):
        lines.append(" ".join(repr(float(v)) for v in (*o, *d, p)))
    return "\n".join(lines) + "\n"
