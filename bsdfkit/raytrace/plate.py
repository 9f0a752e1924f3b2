"""The remote phosphor converter (RPC) plate in the two-wavelength approach.

The plate is the "one virtual surface to which three BSDFs are attributed" of §3 of the cylindrical-module
paper ([Cylindrical-module] in docs/references.md, "Impact of the geometrical and optical parameters on the
performance of a cylindrical remote phosphor LED"): blue-incident blue-scattered (``bibs``), blue-incident
yellow-scattered (``biys``) and yellow-incident yellow-scattered (``yiys``), each on the reflection
(backward, into the cavity) and the transmission (forward, out of the module) side. For each of these six
channels the plate holds, on a grid of incidence angles θi (degrees, measured from the plate normal):

* the TIS, the fraction of the incident power scattered into the channel (Eqs. (7) and (13) of the
  power-budget paper [Power-budget], Table 2 at 45°), and
* the normalised angular distribution of the scattered power, one of

  - :class:`Lambertian` (radiance independent of direction),
  - :class:`LambertGaussian`, in Harvey–Shack direction cosines β = (sin θs cos φs, sin θs sin φs)
    (0 < σ ≤ 2):
    ``f(β) = ρ/π + A·exp(−|β − β0|² / (2σ²))`` with β0 = (sin θi, 0) in the plane of incidence (the same
    β0 is used on the transmission side), f = BSDF·cos θs, so that ∫_{|β|<1} f dβ is the channel's
    scatter, or
  - :class:`Tabulated`, a BSDF tabulated in θs and independent of the scattering azimuth.

A blue ray meeting the plate is scattered back/forward blue (bibs), converted back/forward yellow (biys) or
absorbed with probabilities given by the TIS at its incidence; a yellow ray follows yiys. How the tracer
samples these (linear interpolation in θi, clamping outside the measured grid, mixture sampling of the
Lambert and lobe parts, rejection of lobe samples outside the unit disk) is described in
:mod:`bsdfkit.raytrace.kernel` and docs/tracer.md.

Plates are stored as JSON (:meth:`PhosphorPlate.save` / :func:`load_plate`); a scene can also hold the same
mapping inline under ``[top.plate]``.
"""
from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import jax
import numpy as np

from bsdfkit.core.conventions import INTERACTIONS, SIDES
from bsdfkit.core.errors import FormatError, InputError, ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.io.atomic import write_text
from bsdfkit.io.text import read_text
from bsdfkit.models.functions import tis_gaussian_lobe

FORMAT = "bsdfkit-phosphor-plate"
VERSION = 1
#: Order of the six channels in the kernel tables.
CHANNELS = tuple(f"{i}_{s}" for i in INTERACTIONS for s in SIDES)
#: The three backward (reflection) channels whose directions the tracer samples, in kernel order.
BACKWARD = ("bibs_reflection", "biys_reflection", "yiys_reflection")
#: Column of each channel in :attr:`PlateTables.tis`.
BIBS_R, BIBS_T, BIYS_R, BIYS_T, YIYS_R, YIYS_T = (CHANNELS.index(c) for c in (
    "bibs_reflection", "bibs_transmission", "biys_reflection", "biys_transmission", "yiys_reflection",
    "yiys_transmission"))
#: Index of each backward channel in the (G, 3) tables of :class:`PlateTables`.
BACK_BIBS, BACK_BIYS, BACK_YIYS = (BACKWARD.index(c) for c in BACKWARD)
#: The kinds of backward distribution in :attr:`PlateTables.kind`.
LAMBERTIAN, LAMBERT_GAUSSIAN, TABULATED = 0, 1, 2
#: Tolerance on "TIS sums may not exceed one".
_SUM_TOL = 1e-9


@dataclass(frozen=True)
class Lambertian:
    """Radiance independent of direction: pdf of the projected solid angle = 1/π on the unit disk."""

    kind = "lambertian"

    def to_mapping(self) -> dict[str, Any]:
        """The JSON/TOML mapping of the distribution."""
        return {"kind": self.kind}


@dataclass(frozen=True)
class LambertGaussian:
    """Lambert plus a Gaussian lobe in Harvey–Shack direction cosines.

    ``f(β) = ρ/π + A·exp(−|β−β0|²/(2σ²))`` where ``ρ/π`` is ``rho_per_sr`` (the Lambertian BSDF level,
    1/sr), ``A`` is ``a_per_sr`` (1/sr) and ``sigma`` is the lobe width in direction-cosine units
    (0 < σ ≤ 2). Only the shape matters to the tracer; the channel's TIS sets the scattered power.
    """

    rho_per_sr: float
    a_per_sr: float
    sigma: float
    kind = "lambert_gaussian"

    def to_mapping(self) -> dict[str, Any]:
        """The JSON/TOML mapping of the distribution (BSDF levels in 1/sr)."""
        return {"kind": self.kind, "rho_per_sr": self.rho_per_sr, "a_per_sr": self.a_per_sr, "sigma": self.sigma}


@dataclass(frozen=True)
class Tabulated:
    """BSDF (1/sr) tabulated at polar scattering angles θs (degrees), azimuthally symmetric.

    Between nodes the BSDF is taken linear in s = sin²θs, which makes the sampling below exact: the
    projected solid angle is cos θs dΩ = ½ ds dφ, so the pdf of s is proportional to the BSDF itself.
    """

    theta_s_deg: tuple[float, ...]
    bsdf_per_sr: tuple[float, ...]
    kind = "tabulated"

    def to_mapping(self) -> dict[str, Any]:
        """The JSON/TOML mapping of the distribution (angles in degrees, BSDF in 1/sr)."""
        return {"kind": self.kind, "theta_s_deg": list(self.theta_s_deg), "bsdf_per_sr": list(self.bsdf_per_sr)}


AngularDistribution = Union[Lambertian, LambertGaussian, Tabulated]


@dataclass(frozen=True)
class PlateChannel:
    """One (interaction, side) channel: TIS and angular distribution per incidence of the plate grid."""

    tis: tuple[float, ...]
    distributions: tuple[AngularDistribution, ...]

    def to_mapping(self) -> dict[str, Any]:
        """The JSON/TOML mapping of the channel; one distribution when it is the same at every incidence."""
        dists = [d.to_mapping() for d in self.distributions]
        if all(d == dists[0] for d in dists):
            return {"tis": list(self.tis), "distribution": dists[0]}
        return {"tis": list(self.tis), "distribution": dists}


@dataclass(frozen=True)
class PhosphorPlate:
    """A remote phosphor converter plate: TIS and angular distributions of bibs, biys, yiys (B and F)."""

    theta_i_deg: tuple[float, ...]
    bibs_reflection: PlateChannel
    bibs_transmission: PlateChannel
    biys_reflection: PlateChannel
    biys_transmission: PlateChannel
    yiys_reflection: PlateChannel
    yiys_transmission: PlateChannel
    name: str = ""
    notes: str = ""

    # ---- construction -------------------------------------------------------------------------------
    @classmethod
    def constant(
        cls,
        tis: Mapping[str, float],
        name: str = "",
        notes: str = "",
        distribution: AngularDistribution | None = None,
    ) -> "PhosphorPlate":
        """An angle-independent plate: the same TIS at every incidence (grid 0° and 90°).

        ``tis`` maps the six channel names (``bibs_reflection`` ... ``yiys_transmission``) to fractions of
        the incident power; missing channels are zero. ``distribution`` (default Lambertian) is used for
        every channel.

        Parameters
        ----------
        tis : mapping of str to float
            Channel name → TIS [-].
        name : str
            Plate name.
        notes : str
            Free text.
        distribution : Lambertian, LambertGaussian or Tabulated, optional
            Angular distribution of every channel.

        Returns
        -------
        PhosphorPlate
            The validated plate.
        """
        unknown = set(tis) - set(CHANNELS)
        if unknown:
            raise ValidationError("unknown plate channel", field=sorted(unknown)[0],
                                  expected="one of " + ", ".join(CHANNELS), got=sorted(unknown)[0])
        dist = distribution if distribution is not None else Lambertian()
        channels = {c: PlateChannel((float(tis.get(c, 0.0)),) * 2, (dist, dist)) for c in CHANNELS}
        plate = cls(theta_i_deg=(0.0, 90.0), name=name, notes=notes, **channels)
        plate.validate()
        return plate

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], file: str | Path | None = None, prefix: str = "") -> "PhosphorPlate":
        """Parse the JSON/TOML mapping of a plate (see module docstring); errors name ``file`` and key.

        Parameters
        ----------
        data : mapping
            The parsed JSON object or TOML table.
        file : str or Path, optional
            File named in errors.
        prefix : str
            Prefix of the key names in errors (e.g. the enclosing TOML table).

        Returns
        -------
        PhosphorPlate
            The parsed, validated plate.
        """
        return _parse_plate(data, file, prefix)

    @classmethod
    def from_json(cls, text: str, file: str | Path | None = None) -> "PhosphorPlate":
        """Parse a plate from JSON text (see module docstring).

        Parameters
        ----------
        text : str
            The JSON document.
        file : str or Path, optional
            File named in errors.

        Returns
        -------
        PhosphorPlate
            The parsed, validated plate.
        """
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise FormatError(f"not valid JSON ({exc.msg})", file=file, line=exc.lineno) from None
        if not isinstance(data, dict):
            raise FormatError("a phosphor plate file holds one JSON object", file=file,
                              expected="object", got=type(data).__name__)
        return cls.from_mapping(data, file)

    # ---- output ---------------------------------------------------------------------------------------
    def channel(self, name: str) -> PlateChannel:
        """One channel by name.

        Parameters
        ----------
        name : str
            One of :data:`CHANNELS`, e.g. ``bibs_reflection``.

        Returns
        -------
        PlateChannel
            The channel.
        """
        return getattr(self, name)

    def to_mapping(self) -> dict[str, Any]:
        """The JSON mapping of the plate (the layout :meth:`from_mapping` reads)."""
        out: dict[str, Any] = {"format": FORMAT, "version": VERSION, "name": self.name, "notes": self.notes,
                               "theta_i_deg": list(self.theta_i_deg)}
        for inter in INTERACTIONS:
            out[inter] = {side: self.channel(f"{inter}_{side}").to_mapping() for side in SIDES}
        return out

    def to_json(self) -> str:
        """The plate as indented JSON text."""
        return json.dumps(self.to_mapping(), indent=2) + "\n"

    def save(self, path: str | Path, force: bool = False) -> Path:
        """Write the plate as JSON, atomically; an existing file is kept unless ``force``.

        Parameters
        ----------
        path : str or Path
            The JSON file to write.
        force : bool
            Replace an existing file.

        Returns
        -------
        Path
            The file written.
        """
        return write_text(path, self.to_json(), force)

    # ---- checks ---------------------------------------------------------------------------------------
    def validate(self, file: str | Path | None = None, prefix: str = "") -> None:
        """Raise :class:`ValidationError` unless the plate conserves energy at every incidence.

        Parameters
        ----------
        file : str or Path, optional
            File named in errors.
        prefix : str
            Prefix of the key names in errors (e.g. the enclosing TOML table).
        """
        g = np.asarray(self.theta_i_deg, dtype=float)
        if g.size < 1 or np.any(~np.isfinite(g)) or np.any(g < 0) or np.any(g > 90) or np.any(np.diff(g) <= 0):
            raise ValidationError("incidence grid must be strictly increasing within [0, 90] deg", file=file,
                                  field=prefix + "theta_i_deg", expected="increasing degrees in [0, 90]",
                                  got=list(self.theta_i_deg))
        for name in CHANNELS:
            ch = self.channel(name)
            if len(ch.tis) != g.size or len(ch.distributions) != g.size:
                raise ValidationError("one TIS and one distribution per incidence", file=file,
                                      field=prefix + name.replace("_", ".", 1) + ".tis",
                                      expected=f"{g.size} values", got=len(ch.tis))
            if any(not (0.0 <= t <= 1.0) for t in ch.tis):
                raise ValidationError("TIS is a fraction of the incident power", file=file,
                                      field=prefix + name.replace("_", ".", 1) + ".tis",
                                      expected="values in [0, 1]", got=list(ch.tis))
            for k, dist in enumerate(ch.distributions):
                _check_distribution(dist, file, prefix + name.replace("_", ".", 1) + f".distribution[{k}]")
        blue = sum(np.asarray(self.channel(c).tis) for c in CHANNELS[:4])
        yellow = sum(np.asarray(self.channel(c).tis) for c in CHANNELS[4:])
        for label, total in (("bibs + biys", blue), ("yiys", yellow)):
            if np.any(total > 1.0 + _SUM_TOL):
                k = int(np.argmax(total))
                raise ValidationError(f"{label} TIS (reflection + transmission) exceeds 1", file=file,
                                      field=prefix + f"theta_i_deg[{k}]", expected="a sum <= 1",
                                      got=float(total[k]))

    @property
    def angle_independent(self) -> bool:
        """True when every channel has the same TIS and distribution at every incidence."""
        return all(len(set(self.channel(c).tis)) == 1 and len(set(self.channel(c).distributions)) == 1
                   for c in CHANNELS)

    @property
    def lambertian(self) -> bool:
        """True when every channel's angular distribution is Lambertian."""
        return all(isinstance(d, Lambertian) for c in CHANNELS for d in self.channel(c).distributions)


def load_plate(path: str | Path) -> PhosphorPlate:
    """Read a plate JSON file written by :meth:`PhosphorPlate.save` (or by hand, same layout).

    Parameters
    ----------
    path : str or Path
        The plate JSON file.

    Returns
    -------
    PhosphorPlate
        The parsed, validated plate.
    """
    path = Path(path)
    return PhosphorPlate.from_json(read_text(path, expected="a phosphor plate JSON file"), path)


# ---- parsing --------------------------------------------------------------------------------------------
def _numbers(value: Any, file, field: str, n: int | None = None) -> tuple[float, ...]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, (list, tuple)) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError("wrong type", file=file, field=field, expected="a list of numbers", got=value)
    out = tuple(float(v) for v in value)
    if any(not math.isfinite(v) for v in out):
        raise ValidationError("non-finite value", file=file, field=field, expected="finite numbers", got=list(out))
    if n is not None and len(out) != n:
        raise ValidationError("wrong length", file=file, field=field, expected=f"{n} values", got=len(out))
    return out


def _check_keys(data: Mapping[str, Any], allowed: set[str], file, prefix: str) -> None:
    for key in data:
        if key not in allowed:
            raise InputError("unknown key", file=file, field=prefix + key,
                             expected="one of " + ", ".join(sorted(allowed)), got=key)


#: widest Gaussian lobe (direction-cosine units): keeps the rejection sampler's acceptance above ~0.1
MAX_SIGMA = 2.0


def _check_distribution(dist: AngularDistribution, file, field: str) -> None:
    """Raise :class:`ValidationError` unless ``dist`` is a usable angular distribution."""
    if isinstance(dist, LambertGaussian):
        vals = (dist.rho_per_sr, dist.a_per_sr, dist.sigma)
        if not all(math.isfinite(v) for v in vals) or dist.rho_per_sr < 0 or dist.a_per_sr < 0 \
                or dist.rho_per_sr + dist.a_per_sr <= 0:
            raise ValidationError("lobe and Lambert levels must be >= 0 and not both 0", file=file, field=field,
                                  expected="rho_per_sr >= 0, a_per_sr >= 0, sum > 0",
                                  got=(dist.rho_per_sr, dist.a_per_sr))
        if not (0.0 < dist.sigma <= MAX_SIGMA):
            raise ValidationError("lobe width out of range", file=file, field=field + ".sigma",
                                  expected=f"0 < sigma <= {MAX_SIGMA:g} (direction-cosine units)", got=dist.sigma)
    elif isinstance(dist, Tabulated):
        th = np.asarray(dist.theta_s_deg, dtype=float)
        f = np.asarray(dist.bsdf_per_sr, dtype=float)
        if th.size < 2 or th.size != f.size or np.any(np.diff(th) <= 0) or th[0] < 0 or th[-1] > 90:
            raise ValidationError("scattering angles must increase within [0, 90] deg", file=file,
                                  field=field + ".theta_s_deg", expected=">= 2 increasing values in [0, 90], one "
                                  "BSDF value each", got=list(dist.theta_s_deg))
        if not np.all(np.isfinite(f)) or f.min() < 0 or f.max() <= 0:
            raise ValidationError("tabulated BSDF must be >= 0 and not all zero", file=file,
                                  field=field + ".bsdf_per_sr", expected="values >= 0", got=list(dist.bsdf_per_sr))


def _parse_distribution(data: Any, file, field: str) -> AngularDistribution:
    if isinstance(data, str):
        data = {"kind": data}
    if not isinstance(data, Mapping) or "kind" not in data:
        raise InputError("angular distribution must name its kind", file=file, field=field,
                         expected="'lambertian' or a table with kind = lambertian | lambert_gaussian | tabulated",
                         got=data)
    kind = data["kind"]
    if kind == "lambertian":
        _check_keys(data, {"kind"}, file, field + ".")
        return Lambertian()
    if kind == "lambert_gaussian":
        _check_keys(data, {"kind", "rho_per_sr", "a_per_sr", "sigma"}, file, field + ".")
        vals = {}
        for key in ("rho_per_sr", "a_per_sr", "sigma"):
            if key not in data:
                raise InputError("missing key", file=file, field=f"{field}.{key}", expected="a number")
            vals[key] = _numbers(data[key], file, f"{field}.{key}", 1)[0]
        dist = LambertGaussian(**vals)
        _check_distribution(dist, file, field)
        return dist
    if kind == "tabulated":
        _check_keys(data, {"kind", "theta_s_deg", "bsdf_per_sr"}, file, field + ".")
        for key in ("theta_s_deg", "bsdf_per_sr"):
            if key not in data:
                raise InputError("missing key", file=file, field=f"{field}.{key}", expected="a list of numbers")
        th = _numbers(data["theta_s_deg"], file, field + ".theta_s_deg")
        f = _numbers(data["bsdf_per_sr"], file, field + ".bsdf_per_sr", len(th))
        dist = Tabulated(th, f)
        _check_distribution(dist, file, field)
        return dist
    raise InputError("unknown angular distribution", file=file, field=field + ".kind",
                     expected="lambertian, lambert_gaussian or tabulated", got=kind)


def _parse_plate(data: Mapping[str, Any], file, prefix: str) -> PhosphorPlate:
    allowed = {"format", "version", "name", "notes", "theta_i_deg", *INTERACTIONS}
    _check_keys(data, allowed, file, prefix)
    if "format" in data and data["format"] != FORMAT:
        raise FormatError("not a phosphor plate", file=file, field=prefix + "format", expected=FORMAT,
                          got=data["format"])
    if "version" in data and data["version"] != VERSION:
        raise FormatError("unsupported plate format version", file=file, field=prefix + "version",
                          expected=str(VERSION), got=data["version"])
    if "theta_i_deg" not in data:
        raise InputError("missing key", file=file, field=prefix + "theta_i_deg", expected="a list of degrees")
    grid = _numbers(data["theta_i_deg"], file, prefix + "theta_i_deg")
    n = len(grid)
    channels: dict[str, PlateChannel] = {}
    for inter in INTERACTIONS:
        block = data.get(inter)
        if not isinstance(block, Mapping):
            raise InputError("missing interaction table", file=file, field=prefix + inter,
                             expected="a table with reflection and transmission", got=block)
        _check_keys(block, set(SIDES), file, f"{prefix}{inter}.")
        for side in SIDES:
            field = f"{prefix}{inter}.{side}"
            ch = block.get(side)
            if not isinstance(ch, Mapping):
                raise InputError("missing channel", file=file, field=field,
                                 expected="a table with tis and distribution", got=ch)
            _check_keys(ch, {"tis", "distribution"}, file, field + ".")
            if "tis" not in ch:
                raise InputError("missing key", file=file, field=field + ".tis", expected=f"{n} fractions")
            tis = _numbers(ch["tis"], file, field + ".tis", n)
            raw = ch.get("distribution", "lambertian")
            if isinstance(raw, list):
                if len(raw) != n:
                    raise ValidationError("one distribution per incidence", file=file,
                                          field=field + ".distribution", expected=f"{n} entries", got=len(raw))
                dists = tuple(_parse_distribution(d, file, f"{field}.distribution[{k}]") for k, d in enumerate(raw))
            else:
                dists = (_parse_distribution(raw, file, field + ".distribution"),) * n
            channels[f"{inter}_{side}"] = PlateChannel(tis, dists)
    name = data.get("name", "")
    notes = data.get("notes", "")
    for key, val in (("name", name), ("notes", notes)):
        if not isinstance(val, str):
            raise InputError("wrong type", file=file, field=prefix + key, expected="a string", got=val)
    plate = PhosphorPlate(theta_i_deg=grid, name=name, notes=notes, **channels)
    plate.validate(file, prefix)
    return plate


# ---- kernel tables --------------------------------------------------------------------------------------
#: The clipped-lobe TIS at A = 1 as one compiled call: run eagerly, its dozen JAX operations were dispatched one
#: by one (5 ms per call; a plate extrapolated over 19 incidences asks for hundreds).
_unit_lobe_tis = jax.jit(lambda theta_i, sigma: tis_gaussian_lobe(theta_i, 1.0, sigma, n_psi=4096))


@functools.lru_cache(maxsize=4096)
def lobe_disk_integral(beta0: float, sigma: float) -> float:
    """∫_{|β|<1} exp(−|β−β0|²/(2σ²)) dβ, the lobe's scatter per unit A (truncated to the unit disk).

    The registry's clipped-lobe TIS (:func:`bsdfkit.models.functions.tis_gaussian_lobe`) at A = 1 and
    sin θi = |β0|, with 4096 azimuth nodes so that lobes of σ ≳ 1e-3 stay exact up to grazing incidence.

    Parameters
    ----------
    beta0 : float
        Lobe centre in direction cosines, sin θi [-].
    sigma : float
        Lobe width in direction-cosine units [-].

    Returns
    -------
    float
        The integral over the unit disk [-].
    """
    with x64():
        return float(_unit_lobe_tis(math.asin(min(abs(float(beta0)), 1.0)), float(sigma)))


def lobe_share(dist: AngularDistribution, theta_i_deg: float) -> float:
    """Share of the lobe in a channel's scatter at incidence θi: A·L/(ρ + A·L) (0 for non-lobe kinds).

    The Lambert part scatters ∫ ρ/π dβ = ρ over the unit disk (ρ = π·rho_per_sr); the lobe scatters A·L with
    L from :func:`lobe_disk_integral` at β0 = sin θi.

    Parameters
    ----------
    dist : Lambertian, LambertGaussian or Tabulated
        The channel's angular distribution.
    theta_i_deg : float
        Incidence angle [deg].

    Returns
    -------
    float
        The lobe's share of the scattered power [-].
    """
    if not isinstance(dist, LambertGaussian):
        return 0.0
    lam = math.pi * dist.rho_per_sr
    lobe = dist.a_per_sr * lobe_disk_integral(math.sin(math.radians(theta_i_deg)), dist.sigma)
    return lobe / (lam + lobe)


@dataclass(frozen=True)
class PlateTables:
    """Numeric tables the kernel reads (NumPy; converted to JAX arrays by the tracer).

    ``grid`` (G,) incidence in radians (G ≥ 2; a one-angle plate is duplicated), ``tis`` (G, 6) in
    :data:`CHANNELS` order, and for the three :data:`BACKWARD` channels: ``kind`` (G, 3) :data:`LAMBERTIAN`,
    :data:`LAMBERT_GAUSSIAN` or :data:`TABULATED`, ``lobe_share`` and ``sigma`` (G, 3), tabulated sampling tables
    ``s_nodes``, ``f_nodes``, ``cdf`` (G, 3, T) in s = sin²θs. ``theta_range`` is the measured range in
    radians used by the clamping rule.
    """

    grid: np.ndarray
    tis: np.ndarray
    kind: np.ndarray
    lobe_share: np.ndarray
    sigma: np.ndarray
    s_nodes: np.ndarray
    f_nodes: np.ndarray
    cdf: np.ndarray
    theta_range: tuple[float, float]
    has_lobe: bool
    has_table: bool
    conversion: bool
    covers_hemisphere: bool


def plate_tables(plate: PhosphorPlate) -> PlateTables:
    """Tables for the kernel: TIS per channel and sampling data of the backward distributions.

    Parameters
    ----------
    plate : PhosphorPlate
        The plate.

    Returns
    -------
    PlateTables
        The kernel's tables (incidence grid in radians).
    """
    grid_deg = np.asarray(plate.theta_i_deg, dtype=float)
    tis = np.stack([np.asarray(plate.channel(c).tis, dtype=float) for c in CHANNELS], axis=1)
    dists = [[plate.channel(c).distributions[g] for c in BACKWARD] for g in range(grid_deg.size)]
    if grid_deg.size == 1:  # one incidence: constant in θi
        grid_deg = np.array([grid_deg[0], grid_deg[0] + 1.0])
        tis = np.concatenate([tis, tis])
        dists = dists * 2
    G = grid_deg.size
    kinds = {Lambertian: LAMBERTIAN, LambertGaussian: LAMBERT_GAUSSIAN, Tabulated: TABULATED}
    kind = np.array([[kinds[type(d)] for d in row] for row in dists], dtype=np.int32)
    share = np.array([[lobe_share(d, min(grid_deg[g], 90.0)) for d in row] for g, row in enumerate(dists)])
    sigma = np.array([[d.sigma if isinstance(d, LambertGaussian) else 1.0 for d in row] for row in dists])
    tabs = [d for row in dists for d in row if isinstance(d, Tabulated)]
    T = max([len(d.theta_s_deg) for d in tabs], default=2)
    s_nodes = np.zeros((G, 3, T))
    f_nodes = np.zeros((G, 3, T))
    cdf = np.zeros((G, 3, T))
    for g in range(G):
        for c in range(3):
            d = dists[g][c]
            if isinstance(d, Tabulated):
                s = np.sin(np.radians(np.asarray(d.theta_s_deg))) ** 2
                f = np.asarray(d.bsdf_per_sr, dtype=float)
                # pad with zero-width cells at the last node
                s = np.concatenate([s, np.full(T - s.size, s[-1])])
                f = np.concatenate([f, np.full(T - f.size, f[-1])])
                mass = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(s))])
                s_nodes[g, c], f_nodes[g, c], cdf[g, c] = s, f / mass[-1], mass / mass[-1]
            else:
                s_nodes[g, c] = np.linspace(0.0, 1.0, T)
                f_nodes[g, c] = 1.0
                cdf[g, c] = np.linspace(0.0, 1.0, T)
    lo, hi = float(plate.theta_i_deg[0]), float(plate.theta_i_deg[-1])
    conversion = bool(np.any(tis[:, [BIYS_R, BIYS_T]] > 0))
    return PlateTables(
        grid=np.radians(grid_deg), tis=tis, kind=kind, lobe_share=share, sigma=sigma, s_nodes=s_nodes,
        f_nodes=f_nodes, cdf=cdf, theta_range=(math.radians(lo), math.radians(hi)),
        has_lobe=bool(np.any(share > 0)), has_table=bool(np.any(kind == TABULATED)), conversion=conversion,
        covers_hemisphere=(lo <= 0.0 and hi >= 90.0),
    )
