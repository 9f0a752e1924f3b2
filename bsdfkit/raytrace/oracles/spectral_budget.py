"""The spectral module budget with re-absorption: a deterministic oracle of the tracer's spectral mode.

The power-budget paper's iterative module budget ([Power-budget] §5, Figs. 9-10) followed per wavelength bin
instead of for two colours: light of bin k meeting the plate is scattered back or forward at λ_k (elastic TIS),
converted back or forward (converted TIS, power) into the bins of the emission row of k, or absorbed; converted
light returning to the plate is absorbed and converted again (re-absorption). The cavity is that of
:mod:`bsdfkit.raytrace.oracles.radiosity` (exact view factors between base annuli, wall rings and top annuli), so
for a diffuse cavity, Lambertian LEDs and an angle-independent, Lambertian plate the answer is exact (up to the
patch discretisation, < 1e-6): with G_k the power incident on each patch in bin k,

    G_k = D·e_k + Fᵀ (ρ_k ∘ G_k) + Fᵀ s_k,     s_k = top ∘ Σ_k' C_R(k') f(k'→k) G_k',

where e_k is the LED power fraction of bin k, ρ_k the patches' reflectance in bin k (the plate's: elastic
reflection TIS), C_R the backward converted TIS and f(k'→k) = (p_k'k / λ_k) / Σ_j (p_k'j / λ_j) the share of
converted power landing in bin k (p the conditional photon pdf of the kernel's tables, the thermal tail below
the excitation included, with the data's photon yield: photons spread by p carry power ∝ p/λ). The system is solved
by block Gauss–Seidel over the bins (each bin a dense solve), which converges geometrically because every pass
through the plate loses power. Extracted power in bin k = elastic_T(k)·ΣG_k(top) + Σ_k' C_T(k') f(k'→k) ΣG_k'(top).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from bsdfkit.core.errors import NumericalError, ValidationError
from bsdfkit.raytrace.oracles.radiosity import TOP, WALL, cylinder_patches, led_direct, view_factors
from bsdfkit.raytrace.scene import Scene, scene_spectral_tables, surface_reflectance_table
from bsdfkit.raytrace.spectral import model_on_bins


@dataclass(frozen=True)
class SpectralBudget:
    """Fractions of the emitted power: extracted per bin, and the plate's loss (absorption + Stokes loss)."""

    wavelength_nm: np.ndarray
    extracted: np.ndarray
    plate_loss: float
    sweeps: int


def spectral_module_budget(scene: Scene, n_base: int = 48, n_wall: int = 96, n_top: int = 48,
                           tol: float = 1e-14, max_sweeps: int = 2000) -> SpectralBudget:
    """The exact spectral budget of a diffuse spectral scene (see module docstring).

    Parameters
    ----------
    scene : Scene
        A diffuse spectral scene with Lambertian LED disks and an angle-independent Lambertian top.
    n_base, n_wall, n_top : int
        Number of base annuli, wall rings and top annuli.
    tol : float
        Convergence limit on the largest change of a patch's power per sweep [-].
    max_sweeps : int
        Sweeps over the wavelength bins before giving up.

    Returns
    -------
    SpectralBudget
        Fractions of the emitted power [-] per wavelength bin, the plate's loss and the sweeps used.

    Raises
    ------
    NumericalError
        If the sweeps do not converge within ``max_sweeps``.
    """
    led = scene.led_surface
    if any(s.specular_fraction > 0 for s in (scene.wall, scene.base, led)) or scene.leds.ray_file is not None \
            or (scene.leds.fwhm is not None and abs(scene.leds.cos_exponent - 1.0) > 1e-12):
        raise ValidationError("the spectral budget needs a diffuse cavity and Lambertian LED disks", file=scene.path,
                              field="wall.specular_fraction", expected="0 specular, Lambertian LEDs, no ray file")
    tab = scene_spectral_tables(scene)
    lam = tab.lam
    K = lam.size
    model = scene.top.spectral_model
    if model is None:
        eR, eT, cR, cT = np.zeros(K), np.ones(K), np.zeros(K), np.zeros(K)
        share = np.zeros((K, K))
    else:
        plate = scene.top.plate
        if (plate is not None and not plate.lambertian) or np.ptp(model.elastic_tis, axis=1).max() > 0 \
                or np.ptp(model.converted_tis, axis=1).max() > 0:
            raise ValidationError("the spectral budget needs an angle-independent, Lambertian plate",
                                  file=scene.path, field="top.spectral", expected="TIS constant over incidence")
        elastic, converted, pdf = model_on_bins(model, plate)
        eR, eT = elastic[0, 0], elastic[1, 0]
        # the conditional emission (thermal tail below the excitation) keeps the data's photon yield: the
        # converted power scales by Σ p'/λ / Σ p/λ (photons × their energies)
        w = tab.emission_pdf / lam[None, :]
        norm = w.sum(axis=1)
        data = (pdf / lam[None, :]).sum(axis=1)
        power = np.where(data > 0, norm / np.where(data > 0, data, 1.0), 0.0)
        cR, cT = converted[0, 0] * power, converted[1, 0] * power
        share = np.where(norm[:, None] > 0, w / np.where(norm > 0, norm, 1.0)[:, None], 0.0)  # f(k' → k)
    p = cylinder_patches(scene.cavity.radius_mm, scene.cavity.height_mm, n_base, n_wall, n_top)
    F = view_factors(p)
    D = led_direct(p, scene.leds.centres(), scene.leds.emitter_radius_mm)
    top = p.kind == TOP
    rho_table = surface_reflectance_table(scene).reshape(3, K)  # wall, base, leds (the oracle: LEDs = base)
    if not np.array_equal(rho_table[1], rho_table[2]):
        raise ValidationError("the spectral budget needs LEDs that reflect like the base", file=scene.path,
                              field="leds.led_reflectance", expected="the base's reflectance")
    n = p.kind.size
    lus = []
    for k in range(K):
        rho = np.where(top, eR[k], np.where(p.kind == WALL, rho_table[0, k], rho_table[1, k]))
        lus.append(lu_factor(np.eye(n) - F.T * rho[None, :]))
    G = np.zeros((K, n))
    sweeps = 0
    while sweeps < max_sweeps:
        sweeps += 1
        change = 0.0
        for k in range(K):
            src = np.where(top, (cR * share[:, k]) @ G, 0.0)
            new = lu_solve(lus[k], D * tab.led_power[k] + F.T @ src)
            change = max(change, float(np.max(np.abs(new - G[k]))))
            G[k] = new
        if change <= tol:
            break
    if change > tol:
        raise NumericalError(f"spectral budget did not converge in {max_sweeps} sweeps (change {change:.2e})")
    on_top = G[:, top].sum(axis=1)
    extracted = eT * on_top + (cT * on_top) @ share
    # power the plate takes out of the light (absorbed + Stokes loss of the conversions)
    plate_loss = float(((1.0 - eR - eT - cR - cT) * on_top).sum())
    return SpectralBudget(wavelength_nm=lam, extracted=extracted, plate_loss=plate_loss, sweeps=sweeps)
