"""Radiosity of a fully diffuse cylindrical cavity with exact view factors (a deterministic oracle).

The cavity (radius R, height H) is discretised into base annuli, wall rings and top annuli. View factors
between these axisymmetric patches follow from two closed forms (Howell, *A Catalog of Radiation Heat
Transfer Configuration Factors*, cases C-41 and B-13; Modest, *Radiative Heat Transfer*, App. D;
[Howell-catalog], [Modest] in docs/references.md):

* coaxial parallel disks of radii r₁, r₂ at distance h, with Rᵢ = rᵢ/h and S = 1 + (1 + R₂²)/R₁²:
  F₁₂ = ½ [S − √(S² − 4 (r₂/r₁)²)]  (:func:`disk_to_disk`);
* a differential element parallel to a disk of radius a at height h, offset r from the disk's axis:
  F = ½ [1 − (h² + r² − a²) / √((h² + r² + a²)² − 4 a² r²)]  (:func:`element_to_disk`),

combined by view-factor algebra: an annulus is the difference of two disks; what leaves a base disk and
crosses the cap z = z₁ but not the cap z = z₂ lands on the wall band z₁ < z < z₂; ring-to-ring and
ring-to-annulus factors follow by reciprocity A_i F_ij = A_j F_ji. Every row of the matrix sums to one
(closed enclosure), which the tests assert together with reciprocity.

For an axisymmetric target patch the fraction of power leaving a point of ring i that reaches patch j does
not depend on the point's azimuth, so the LEDs' off-axis, non-axisymmetric first-bounce irradiance is
treated exactly; the only approximation is uniform radiosity along z within a ring and along r within an
annulus, which vanishes as the patches are refined (the error is checked by refinement).

LED emitters are Lambertian disks in the base plane; their first-hit distribution is the emitter-area
average of :func:`element_to_disk` differences, integrated by Gauss–Legendre quadrature (polar, over each
emitter disk) — smooth integrands, quadrature error ≪ 10⁻¹⁰.

The top is an exit (nothing returns), a Lambertian diffuser (ρ, τ) or a phosphor plate reduced to
angle-independent TIS with Lambertian angular distributions. In the two-wavelength radiosity blue power
reaching the top is split into bibs (back, forward), biys (back, forward) and absorption, yellow into yiys
(back, forward) and absorption; back-scattered power re-enters the cavity as a Lambertian source. With
G the power incident on each patch and ρ its reflectance (for the top: the backward TIS),

    G_blue = D + Fᵀ (ρ_blue ∘ G_blue),     G_yellow = Fᵀ (s_yellow + ρ_yellow ∘ G_yellow),

where D is the LEDs' direct power and s_yellow = biys_B · G_blue on the top patches. Extracted blue =
Σ bibs_F G_blue(top), yellow = Σ (biys_F G_blue + yiys_F G_yellow)(top). This is the closed form of the
iterative module budget of §5 of the power-budget paper with an exact cavity instead of a constant η_MC.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bsdfkit.core.errors import ValidationError
from bsdfkit.core.quadrature import gauss_legendre
from bsdfkit.raytrace.plate import PhosphorPlate
from bsdfkit.raytrace.scene import Scene

BASE, WALL, TOP = 0, 1, 2


def disk_to_disk(r1, r2, h):
    """View factor from a disk of radius r1 to a coaxial parallel disk of radius r2 at distance h.

    Howell C-41, ½[S − √(S² − 4(r₂/r₁)²)], rewritten without cancellation or division by r₁ as
    F = 2R₂² / (X + √(X² − 4R₁²R₂²)) with Rᵢ = rᵢ/h and X = 1 + R₁² + R₂² (r₁ → 0 gives the element
    factor R₂²/(1 + R₂²)). At h = 0 the disks coincide: F = min(1, (r₂/r₁)²).

    Parameters
    ----------
    r1 : float or array_like
        Radius of the emitting disk [mm].
    r2 : float or array_like
        Radius of the receiving disk [mm].
    h : float or array_like
        Distance between the disks [mm].

    Returns
    -------
    float or ndarray
        View factor [-].
    """
    r1, r2, h = np.broadcast_arrays(np.asarray(r1, float), np.asarray(r2, float), np.asarray(h, float))
    out = np.zeros(r1.shape)
    touching = h <= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        out[touching] = np.where(r1[touching] > 0, np.minimum(1.0, (r2[touching] / r1[touching]) ** 2), 1.0)
    m = ~touching
    R1 = r1[m] / h[m]
    R2 = r2[m] / h[m]
    X = 1.0 + R1 * R1 + R2 * R2
    out[m] = 2.0 * R2 * R2 / (X + np.sqrt(np.maximum(X * X - 4.0 * R1 * R1 * R2 * R2, 0.0)))
    return out if out.ndim else float(out)


def element_to_disk(offset, a, h):
    """View factor from a differential element (normal towards the disk) to a parallel disk of radius a.

    ``offset`` is the element's distance from the disk axis, ``h`` the plane separation (h = 0: 1 inside the
    disk, 0 outside).

    Parameters
    ----------
    offset : float or array_like
        Distance of the element from the disk axis [mm].
    a : float or array_like
        Disk radius [mm].
    h : float or array_like
        Plane separation [mm].

    Returns
    -------
    float or ndarray
        View factor [-].
    """
    r, a, h = np.broadcast_arrays(np.asarray(offset, float), np.asarray(a, float), np.asarray(h, float))
    num = h * h + r * r - a * a
    den = np.sqrt(np.maximum((h * h + r * r + a * a) ** 2 - 4.0 * a * a * r * r, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        f = 0.5 * (1.0 - num / den)
    f = np.where(den > 0, f, np.where(r < a, 1.0, 0.0))
    return f if f.ndim else float(f)


@dataclass(frozen=True)
class Patches:
    """Axisymmetric patches: ``kind`` (BASE, WALL, TOP), ``lo``/``hi`` radii (annuli) or heights (rings)."""

    radius: float
    height: float
    kind: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @property
    def area(self) -> np.ndarray:
        ann = math.pi * (self.hi ** 2 - self.lo ** 2)
        ring = 2.0 * math.pi * self.radius * (self.hi - self.lo)
        return np.where(self.kind == WALL, ring, ann)


def cylinder_patches(radius: float, height: float, n_base: int, n_wall: int, n_top: int) -> Patches:
    """Base annuli (equal area), wall rings (equal height) and top annuli (equal area).

    Parameters
    ----------
    radius : float
        Cavity radius [mm].
    height : float
        Cavity height [mm].
    n_base, n_wall, n_top : int
        Number of base annuli, wall rings and top annuli.

    Returns
    -------
    Patches
        The patches, base first, then wall, then top.
    """
    rb = radius * np.sqrt(np.linspace(0.0, 1.0, n_base + 1))
    rt = radius * np.sqrt(np.linspace(0.0, 1.0, n_top + 1))
    zw = np.linspace(0.0, height, n_wall + 1)
    kind = np.r_[np.full(n_base, BASE), np.full(n_wall, WALL), np.full(n_top, TOP)]
    lo = np.r_[rb[:-1], zw[:-1], rt[:-1]]
    hi = np.r_[rb[1:], zw[1:], rt[1:]]
    return Patches(radius, height, kind, lo, hi)


def _annulus_to_disk(a, b, R, h):
    """F from the annulus a < r < b to a coaxial parallel disk of radius R at distance h (vectorised)."""
    Ab, Aa = b * b, a * a
    return (Ab * disk_to_disk(b, R, h) - Aa * disk_to_disk(a, R, h)) / (Ab - Aa)


def view_factors(p: Patches) -> np.ndarray:
    """The exact view-factor matrix F[i, j] (fraction of power leaving patch i that reaches patch j).

    Parameters
    ----------
    p : Patches
        The cavity's patches.

    Returns
    -------
    ndarray
        (n, n) view factors [-].
    """
    n = p.kind.size
    R, H = p.radius, p.height
    A = p.area
    F = np.zeros((n, n))
    base = np.flatnonzero(p.kind == BASE)
    wall = np.flatnonzero(p.kind == WALL)
    top = np.flatnonzero(p.kind == TOP)

    def ann_to_ann(i_idx, j_idx, h):
        a1, b1 = p.lo[i_idx][:, None], p.hi[i_idx][:, None]
        a2, b2 = p.lo[j_idx][None, :], p.hi[j_idx][None, :]
        # A1 F(ann1→ann2) = Σ ± A(disk) F(disk→disk)
        def AF(r1, r2):
            return math.pi * r1 * r1 * disk_to_disk(r1, r2, h)
        af = AF(b1, b2) - AF(b1, a2) - AF(a1, b2) + AF(a1, a2)
        return af / (math.pi * (b1 * b1 - a1 * a1))

    def ann_to_ring(i_idx, dist_lo, dist_hi):
        # annulus → wall band between caps at distances dist_lo < dist_hi from the annulus plane
        a, b = p.lo[i_idx][:, None], p.hi[i_idx][:, None]
        return _annulus_to_disk(a, b, R, dist_lo[None, :]) - _annulus_to_disk(a, b, R, dist_hi[None, :])

    F[np.ix_(base, top)] = ann_to_ann(base, top, H)
    F[np.ix_(top, base)] = ann_to_ann(top, base, H)
    F[np.ix_(base, wall)] = ann_to_ring(base, p.lo[wall], p.hi[wall])
    F[np.ix_(top, wall)] = ann_to_ring(top, H - p.hi[wall], H - p.lo[wall])
    F[np.ix_(wall, base)] = (A[base][:, None] * F[np.ix_(base, wall)]).T / A[wall][:, None]
    F[np.ix_(wall, top)] = (A[top][:, None] * F[np.ix_(top, wall)]).T / A[wall][:, None]
    # ring k → ring l above it: F(ring_k → cap z_l) − F(ring_k → cap z_{l+1}), with
    # A_k F(ring_k → cap z) = A_cap [F_dd(R, R, z − z_k,hi) − F_dd(R, R, z − z_k,lo)]
    cap = math.pi * R * R
    zlo, zhi = p.lo[wall], p.hi[wall]

    def ring_to_cap(z):  # (n_wall, n_z): rings below the cap at heights z
        return cap * (disk_to_disk(R, R, z[None, :] - zhi[:, None]) - disk_to_disk(R, R, z[None, :] - zlo[:, None])) \
            / A[wall][:, None]

    up = ring_to_cap(zlo) - ring_to_cap(zhi)  # [k, l] valid for l > k
    k_idx, l_idx = np.meshgrid(np.arange(wall.size), np.arange(wall.size), indexing="ij")
    above = l_idx > k_idx
    Fww = np.where(above, up, 0.0)
    Fww = Fww + (A[wall][:, None] * Fww).T / A[wall][:, None]  # below, by reciprocity (equal-height rings)
    self_f = 1.0 - 2.0 * cap * (1.0 - disk_to_disk(R, R, zhi - zlo)) / A[wall]
    Fww[np.arange(wall.size), np.arange(wall.size)] = self_f
    F[np.ix_(wall, wall)] = Fww
    return F


def _gauss_disk(n: int = 24):
    """Nodes (ρ, φ) and weights of a polar Gauss–Legendre rule on the unit disk (weights sum to 1)."""
    x, wx = gauss_legendre(n)
    rho = 0.5 * (x + 1.0)
    wr = 0.5 * wx * rho * 2.0  # ∫_0^1 2ρ dρ = 1
    phi = (np.arange(2 * n) + 0.5) * (2.0 * math.pi / (2 * n))
    wp = np.full(2 * n, 1.0 / (2 * n))
    R, P = np.meshgrid(rho, phi, indexing="ij")
    W = wr[:, None] * wp[None, :]
    return R.ravel(), P.ravel(), W.ravel()


def led_direct(p: Patches, centres, emitter_radius: float, quad: int = 24) -> np.ndarray:
    """Fraction of the LEDs' power (Lambertian disks, equal power each) first reaching each patch.

    Parameters
    ----------
    p : Patches
        The cavity's patches.
    centres : iterable of (float, float)
        LED centres (x, y) on the base [mm].
    emitter_radius : float
        Radius of each LED disk [mm].
    quad : int
        Gauss–Legendre order of the quadrature over each LED disk.

    Returns
    -------
    ndarray
        Fraction of the emitted power first reaching each patch [-].
    """
    rho, phi, wq = _gauss_disk(quad)
    out = np.zeros(p.kind.size)
    R, H = p.radius, p.height
    wall = p.kind == WALL
    top = p.kind == TOP
    for cx, cy in centres:
        x = cx + emitter_radius * rho * np.cos(phi)
        y = cy + emitter_radius * rho * np.sin(phi)
        r = np.hypot(x, y)[:, None]
        f_top = element_to_disk(r, p.hi[top][None, :], H) - element_to_disk(r, p.lo[top][None, :], H)
        f_wall = element_to_disk(r, R, p.lo[wall][None, :]) - element_to_disk(r, R, p.hi[wall][None, :])
        out[top] += wq @ f_top
        out[wall] += wq @ f_wall
    return out / len(centres)


@dataclass(frozen=True)
class RadiosityResult:
    """Fractions of the emitted power: extracted blue/yellow, absorbed per surface; LER and YBR."""

    extracted_blue: float
    extracted_yellow: float
    absorbed_base: float
    absorbed_wall: float
    absorbed_plate: float
    n_patches: int

    @property
    def LER(self) -> float:
        return self.extracted_blue + self.extracted_yellow

    @property
    def YBR(self) -> float:
        return self.extracted_yellow / self.extracted_blue if self.extracted_blue > 0 else float("nan")


def _plate_tis(scene: Scene) -> dict[str, float]:
    top = scene.top
    if top.kind == "exit":
        return {"bibs_reflection": 0.0, "bibs_transmission": 1.0, "biys_reflection": 0.0, "biys_transmission": 0.0,
                "yiys_reflection": 0.0, "yiys_transmission": 1.0}
    if top.kind == "lambertian":
        return {"bibs_reflection": top.reflectance, "bibs_transmission": top.transmittance,
                "biys_reflection": 0.0, "biys_transmission": 0.0,
                "yiys_reflection": top.reflectance, "yiys_transmission": top.transmittance}
    plate: PhosphorPlate = top.plate
    if not (plate.angle_independent and plate.lambertian):
        raise ValidationError("the radiosity oracle needs an angle-independent, Lambertian plate",
                              file=scene.path, field="top.plate", expected="constant TIS, Lambertian distributions",
                              got=plate.name or "angle-dependent plate")
    return {c: plate.channel(c).tis[0] for c in
            ("bibs_reflection", "bibs_transmission", "biys_reflection", "biys_transmission", "yiys_reflection",
             "yiys_transmission")}


def require_two_colours(scene: Scene, who: str) -> None:
    """Refuse a spectral scene (spectral mode or a reflectance spectrum) in a two-colour oracle.

    Parameters
    ----------
    scene : Scene
        The scene to check.
    who : str
        The oracle's name, used in the error message.

    Raises
    ------
    ValidationError
        If the scene is spectral.
    """
    if scene.trace.mode != "two-wavelength" or any(x.spectrum is not None for x in (scene.wall, scene.base)):
        raise ValidationError(f"{who} traces two colours with constant reflectances", file=scene.path,
                              field="trace.mode", expected="two-wavelength, no reflectance_spectrum "
                              "(bsdfkit.raytrace.oracles.spectral_budget handles spectral scenes)",
                              got=scene.trace.mode)


def module_radiosity(scene: Scene, n_base: int = 48, n_wall: int = 96, n_top: int = 48) -> RadiosityResult:
    """Two-wavelength radiosity of ``scene`` (diffuse cavity, Lambertian LEDs; see module docstring).

    Parameters
    ----------
    scene : Scene
        A diffuse two-colour scene with Lambertian LED disks and an angle-independent Lambertian top.
    n_base, n_wall, n_top : int
        Number of base annuli, wall rings and top annuli.

    Returns
    -------
    RadiosityResult
        Fractions of the emitted power [-].
    """
    led = scene.led_surface
    require_two_colours(scene, "the radiosity oracle")
    if any(s.specular_fraction > 0 for s in (scene.wall, scene.base, led)):
        raise ValidationError("the radiosity oracle needs a fully diffuse cavity", file=scene.path,
                              field="wall.specular_fraction", expected="0 on wall, base and LEDs",
                              got=scene.wall.specular_fraction)
    if scene.leds.fwhm is not None and abs(scene.leds.cos_exponent - 1.0) > 1e-12:
        raise ValidationError("the radiosity oracle needs Lambertian LEDs", file=scene.path, field="leds.fwhm_deg",
                              expected="distribution = 'lambertian'", got=math.degrees(scene.leds.fwhm))
    if scene.leds.ray_file is not None:
        raise ValidationError("the radiosity oracle needs LED disks, not a ray file", file=scene.path,
                              field="leds.ray_file", expected="no ray file", got=scene.leds.ray_file)
    if led.reflectance != scene.base.reflectance:
        raise ValidationError("the radiosity oracle needs LEDs that reflect like the base", file=scene.path,
                              field="leds.led_reflectance", expected=f"{scene.base.reflectance}",
                              got=led.reflectance)
    tis = _plate_tis(scene)
    p = cylinder_patches(scene.cavity.radius_mm, scene.cavity.height_mm, n_base, n_wall, n_top)
    F = view_factors(p)
    D = led_direct(p, scene.leds.centres(), scene.leds.emitter_radius_mm)
    top = p.kind == TOP
    rho_cav = np.where(p.kind == WALL, scene.wall.reflectance, scene.base.reflectance)
    rho_b = np.where(top, tis["bibs_reflection"], rho_cav)
    rho_y = np.where(top, tis["yiys_reflection"], rho_cav)
    n = p.kind.size
    eye = np.eye(n)
    Gb = np.linalg.solve(eye - F.T * rho_b[None, :], D)
    sy = np.where(top, tis["biys_reflection"] * Gb, 0.0)
    Gy = np.linalg.solve(eye - F.T * rho_y[None, :], F.T @ sy)
    ext_b = tis["bibs_transmission"] * Gb[top].sum()
    ext_y = tis["biys_transmission"] * Gb[top].sum() + tis["yiys_transmission"] * Gy[top].sum()
    cav_abs = (1.0 - rho_cav) * (Gb + Gy)
    a_plate = ((1.0 - tis["bibs_reflection"] - tis["bibs_transmission"] - tis["biys_reflection"]
                - tis["biys_transmission"]) * Gb[top].sum()
               + (1.0 - tis["yiys_reflection"] - tis["yiys_transmission"]) * Gy[top].sum())
    return RadiosityResult(
        extracted_blue=float(ext_b), extracted_yellow=float(ext_y),
        absorbed_base=float(cav_abs[p.kind == BASE].sum()), absorbed_wall=float(cav_abs[p.kind == WALL].sum()),
        absorbed_plate=float(a_plate), n_patches=n,
    )
