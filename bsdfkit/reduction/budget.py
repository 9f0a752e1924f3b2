"""Power and photon budgets of the phosphor plate and of the module (power-budget paper, §§5-6).

Numbers refer to [Power-budget] (docs/references.md).

* :func:`interaction_table` — Table 2 of the power-budget paper at one incidence: back (B) and forward (F)
  TIS of bibs, biys and yiys, blue and yellow losses, in percent of incident power and of incident photons,
  with standard uncertainties, and the external quantum efficiency EQE = emitted yellow photons / absorbed
  blue photons (§6). Photon entries differ from power entries only for the converting interaction biys, by
  λ̄s/λ̄i, the ratio of the power-weighted mean wavelengths of scattered and incident spectra (eq. (16)).
* :func:`module_budget` — the iterative model of §5 / Fig. 9: the mixing chamber returns a fraction η_MC of
  the light it receives; η_MC is applied before every plate interaction (including the first, the LEDs'
  direct pass). Interaction k sends F·x_k out and B·x_k back, with x the (blue, yellow) power reaching the
  plate. Cumulative extracted blue/yellow and losses after each interaction (Fig. 10), and the converged
  limit in closed form: x = (I − η_MC B)⁻¹ η_MC e_blue, extracted = F x.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from bsdfkit.core.conventions import SIDES, InteractionBands
from bsdfkit.core.errors import InputError, NumericalError
from bsdfkit.reduction import spectral
from bsdfkit.reduction import tis as angular

KEYS = ("B_bibs", "F_bibs", "B_biys", "F_biys", "blue_losses", "B_yiys", "F_yiys", "yellow_losses")
TIS_KEYS = ("B_bibs", "F_bibs", "B_biys", "F_biys", "B_yiys", "F_yiys")


@dataclass(frozen=True)
class InteractionTable:
    """Plate interaction table in percent (power and photons) with standard uncertainties."""

    theta_i: float
    power: dict[str, float]
    power_std: dict[str, float]
    photons: dict[str, float]
    photons_std: dict[str, float]
    eqe: float
    eqe_std: float
    photon_ratio: dict[str, float]

    def as_dict(self) -> dict:
        """The table as a JSON-ready dict (incidence under ``theta_i_deg``).

        Returns
        -------
        dict
            ``theta_i_deg`` [deg]; ``power``, ``photons``, ``power_std``, ``photons_std`` (key → percent);
            ``eqe``, ``eqe_std`` [-]; ``photon_ratio_biys`` (B/F → λ̄s/λ̄i [-]).
        """
        return {"theta_i_deg": self.theta_i, "power": self.power, "photons": self.photons,
                "power_std": self.power_std, "photons_std": self.photons_std, "eqe": self.eqe,
                "eqe_std": self.eqe_std, "photon_ratio_biys": self.photon_ratio}


def complete_table(tis_percent: dict[str, float]) -> dict[str, float]:
    """Add blue and yellow losses (100 − the scattered parts) to six TIS entries in percent.

    Parameters
    ----------
    tis_percent : dict of str to float
        The six TIS entries (``B_bibs``, ``F_bibs``, ``B_biys``, ``F_biys``, ``B_yiys``, ``F_yiys``) [%]; other
        keys are ignored.

    Returns
    -------
    dict of str to float
        The eight entries of :data:`KEYS` [%], losses included.

    Raises
    ------
    InputError
        If a TIS entry is missing.
    """
    missing = [k for k in TIS_KEYS if k not in tis_percent]
    if missing:
        raise InputError("interaction table incomplete", field=missing[0], expected="keys " + ", ".join(TIS_KEYS))
    t = {k: float(tis_percent[k]) for k in TIS_KEYS}
    t["blue_losses"] = 100.0 - t["B_bibs"] - t["F_bibs"] - t["B_biys"] - t["F_biys"]
    t["yellow_losses"] = 100.0 - t["B_yiys"] - t["F_yiys"]
    return {k: t[k] for k in KEYS}


def _losses_std(std: dict[str, float]) -> dict[str, float]:
    out = dict(std)
    out["blue_losses"] = float(np.sqrt(sum(std[k] ** 2 for k in ("B_bibs", "F_bibs", "B_biys", "F_biys"))))
    out["yellow_losses"] = float(np.hypot(std["B_yiys"], std["F_yiys"]))
    return {k: out[k] for k in KEYS}


def require_phosphor_scan(ds: xr.Dataset) -> None:
    """Refuse, with one line saying why, a dataset the interaction table and the power/photon budget cannot use.

    They need a phosphor scan of the two-wavelength approach: configurations ``blue`` and ``yellow``, records
    on both sides and a bi-spectral BSDF (``bsdf_bispectral`` with finite values). Elastic data (any other
    sample) has directional-hemispherical values instead (``bsdfkit.tis`` / ``bsdfkit tis``).

    Parameters
    ----------
    ds : xarray.Dataset
        A calibrated scan.

    Raises
    ------
    InputError
        If ``ds`` lacks the ``blue`` and ``yellow`` configurations, a side, or finite bi-spectral values.
    """
    configs = sorted({str(c) for c in ds["config"].values}) if "config" in ds.coords else []
    sides = sorted({str(s) for s in ds["side"].values}) if "side" in ds.coords else []
    missing = []
    if not {"blue", "yellow"} <= set(configs):
        missing.append("configuration(s) " + (", ".join(repr(c) for c in configs) or "none"))
    if not set(SIDES) <= set(sides):
        missing.append((" and ".join(sides) or "no side") + " only")
    if not ("bsdf_bispectral" in ds and bool(np.isfinite(ds["bsdf_bispectral"].values).any())):
        missing.append("no bi-spectral BSDF")
    if missing:
        raise InputError("the power/photon budget does not apply to elastic data (" + ", ".join(missing)
                         + "): it needs a phosphor scan with configurations 'blue' and 'yellow', both sides and a "
                         "bi-spectral BSDF; use tis for the hemispherical values of elastic data",
                         file=ds.attrs.get("source") or None)


def interaction_table(ds: xr.Dataset, theta_i_deg: float, tis: xr.Dataset | None = None,
                      bands: InteractionBands | None = None) -> InteractionTable:
    """Table 2 of the power-budget paper at incidence ``theta_i_deg`` [deg] from a calibrated scan.

    ``bands`` (default: the power-budget filters) reach both the TIS and the photon ratios; a given ``tis``
    (:func:`bsdfkit.reduction.tis.tis_table`) must have been computed with the same bands. A dataset that is not a
    phosphor scan is refused with one line (:func:`require_phosphor_scan`).

    Parameters
    ----------
    ds : xarray.Dataset
        Calibrated phosphor scan.
    theta_i_deg : float
        Angle of incidence [deg]; must be in ``tis`` when given.
    tis : xarray.Dataset, optional
        A precomputed :func:`bsdfkit.reduction.tis.tis_table`; None computes it at ``theta_i_deg``.
    bands : InteractionBands, optional
        Excitation and conversion bands [nm]; None for the power-budget filters.

    Returns
    -------
    InteractionTable
        Power and photon entries with standard uncertainties [%], EQE [-] and photon ratios [-].

    Raises
    ------
    InputError
        If ``ds`` is not a phosphor scan, ``tis`` used other bands or lacks ``theta_i_deg``.
    NumericalError
        If no blue light is absorbed (EQE undefined).
    """
    require_phosphor_scan(ds)
    bands = bands or InteractionBands()
    if tis is None:
        tis = angular.tis_table(ds, theta_i_deg=[theta_i_deg], bands=bands)
    for name, band in (("blue_band_nm", bands.blue_nm), ("yellow_band_nm", bands.yellow_nm)):
        used = tuple(float(v) for v in tis.attrs.get(name, band))
        if used != tuple(band):
            raise InputError("the TIS table was computed with other bands", file=ds.attrs.get("source") or None,
                             field=f"tis.attrs['{name}']", expected=list(band), got=list(used))
    sel = tis.sel(theta_i=theta_i_deg, method="nearest")
    if abs(float(sel["theta_i"]) - theta_i_deg) > 1e-6:
        raise InputError("incidence not in the TIS table", field="theta_i", got=theta_i_deg)
    power, power_std = {}, {}
    for inter in ("bibs", "biys", "yiys"):
        for tag, side in zip("BF", SIDES):  # back (reflection), forward (transmission)
            power[f"{tag}_{inter}"] = 100 * float(sel["tis"].sel(interaction=inter, side=side))
            power_std[f"{tag}_{inter}"] = 100 * float(sel["tis_std"].sel(interaction=inter, side=side))
    # eq. (15): incident blue spectrum; eq. (14): hemispherically scattered yellow spectrum per side
    incident = spectral.incident_spectrum(ds, "blue")
    ratio = {}
    for tag, side in zip("BF", SIDES):  # back (reflection), forward (transmission)
        scattered = angular.hemispherical_spectrum(ds, "blue", theta_i_deg, side, "biys", bands.yellow_nm)
        ratio[tag] = spectral.photon_ratio(incident, bands.blue_nm, scattered, bands.yellow_nm)
    photons = dict(power)
    photons_std = dict(power_std)
    for tag in ("B", "F"):
        photons[f"{tag}_biys"] = power[f"{tag}_biys"] * ratio[tag]
        photons_std[f"{tag}_biys"] = power_std[f"{tag}_biys"] * ratio[tag]
    power = complete_table(power)
    photons = complete_table(photons)
    power_std = _losses_std(power_std)
    photons_std = _losses_std(photons_std)
    absorbed = 100.0 - photons["B_bibs"] - photons["F_bibs"]
    if not absorbed > 0:
        raise NumericalError("no blue light absorbed: EQE undefined", field="bibs", got=absorbed)
    emitted = photons["B_biys"] + photons["F_biys"]
    eqe = emitted / absorbed
    eqe_std = eqe * float(np.hypot(np.hypot(photons_std["B_biys"], photons_std["F_biys"]) / emitted,
                                   np.hypot(photons_std["B_bibs"], photons_std["F_bibs"]) / absorbed))
    return InteractionTable(theta_i=float(theta_i_deg), power=power, power_std=power_std, photons=photons,
                            photons_std=photons_std, eqe=eqe, eqe_std=eqe_std, photon_ratio=ratio)


@dataclass(frozen=True)
class ModuleBudget:
    """Cumulative extracted power (percent of the LEDs' emission) after each plate interaction, and the limit."""

    eta_mc: float
    iterations: list[dict[str, float]]
    converged: dict[str, float]
    first_iteration: dict[str, float]

    def as_dict(self) -> dict:
        """The budget as a JSON-ready dict.

        Returns
        -------
        dict
            ``eta_mc`` [-]; ``iterations`` (one dict per plate interaction), ``converged`` and
            ``first_iteration``, their values in percent of the LEDs' emission.
        """
        return {"eta_mc": self.eta_mc, "iterations": self.iterations, "converged": self.converged,
                "first_iteration": self.first_iteration}


def _matrices(table: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    t = {k: table[k] / 100.0 for k in TIS_KEYS}
    back = np.array([[t["B_bibs"], 0.0], [t["B_biys"], t["B_yiys"]]])
    forward = np.array([[t["F_bibs"], 0.0], [t["F_biys"], t["F_yiys"]]])
    return back, forward


#: Most plate interactions of an iterative budget (the series has converged long before).
MAX_ITERATIONS = 10_000


def module_budget(table: dict[str, float], eta_mc: float, iterations: int = 7) -> ModuleBudget:
    """The iterative module budget (§5, Figs. 9-10 of the power-budget paper) for an interaction table in percent.

    Iteration k is the k-th interaction with the plate (the first is the direct pass from the LEDs).
    ``table`` needs the six TIS keys (power or photons: the algebra is the same).

    Parameters
    ----------
    table : dict of str to float
        Interaction table [%] with at least the six TIS keys.
    eta_mc : float
        Mixing-chamber efficiency η_MC in [0, 1] [-].
    iterations : int, optional
        Number of plate interactions to list, in [1, :data:`MAX_ITERATIONS`].

    Returns
    -------
    ModuleBudget
        Cumulative extracted blue, yellow and total power, losses and backscattered power after each interaction
        and in the converged limit [% of the LEDs' emission].

    Raises
    ------
    InputError
        If η_MC or ``iterations`` is out of range, a TIS is negative or the table creates energy.
    NumericalError
        If the recycling is lossless and the series does not converge.
    """
    if not (0.0 <= eta_mc <= 1.0):
        raise InputError("mixing-chamber efficiency out of range", field="eta_mc", expected="0 ≤ η_MC ≤ 1", got=eta_mc)
    if not 1 <= iterations <= MAX_ITERATIONS:
        raise InputError("number of plate interactions out of range", field="iterations",
                         expected=f"an integer in [1, {MAX_ITERATIONS}] (limit MAX_ITERATIONS)", got=iterations)
    table = complete_table(table)
    for k in TIS_KEYS:
        if table[k] < 0:
            raise InputError("negative TIS in the interaction table", field=k, expected="≥ 0", got=table[k])
    if table["blue_losses"] < -1e-9 or table["yellow_losses"] < -1e-9:
        raise InputError("interaction table creates energy", field="losses",
                         expected="B + F ≤ 100 % for blue and for yellow",
                         got=(table["blue_losses"], table["yellow_losses"]))
    back, forward = _matrices(table)
    x = np.array([1.0, 0.0])
    extracted = np.zeros(2)
    rows = []
    first = {}
    for k in range(iterations):
        incident = eta_mc * x
        out = forward @ incident
        x = back @ incident
        extracted = extracted + out
        total = float(extracted.sum())
        in_flight = float(x.sum())
        rows.append({"blue": 100 * float(extracted[0]), "yellow": 100 * float(extracted[1]), "total": 100 * total,
                     "losses": 100 * (1.0 - total - in_flight), "backscattered": 100 * in_flight})
        if k == 0:
            first = {"forward": 100 * float(out.sum()), "backscattered": 100 * in_flight,
                     "lost": 100 * (1.0 - float(out.sum()) - in_flight)}
    system = np.eye(2) - eta_mc * back
    if np.linalg.cond(system) > 1e12:
        raise NumericalError("module budget does not converge (lossless recycling)", field="eta_mc",
                             expected="η_MC·B with spectral radius < 1", got=eta_mc)
    x_inf = np.linalg.solve(system, eta_mc * np.array([1.0, 0.0]))
    ext = forward @ x_inf
    converged = {"blue": 100 * float(ext[0]), "yellow": 100 * float(ext[1]), "total": 100 * float(ext.sum()),
                 "losses": 100 * (1.0 - float(ext.sum()))}
    return ModuleBudget(eta_mc=float(eta_mc), iterations=rows, converged=converged, first_iteration=first)


def table_from_json(data: dict, source: str = "<table>") -> dict[str, dict[str, float]]:
    """Validate ``{"power": {...}, "photons": {...}?}`` in percent (keys as in Table 2).

    Parameters
    ----------
    data : dict
        Parsed JSON with a ``power`` object and optionally a ``photons`` object, each holding the six TIS keys
        [%].
    source : str, optional
        Name of the source for error messages.

    Returns
    -------
    dict
        ``power`` (and ``photons`` when given): key → TIS [%], float.

    Raises
    ------
    InputError
        If an object or key is missing or a value is not a finite number in [0, 100].
    """
    if not isinstance(data, dict) or "power" not in data:
        raise InputError("interaction table JSON needs a 'power' object", file=source, field="power",
                         expected='{"power": {"B_bibs": 10.9, ...}}')
    out = {}
    for part in ("power", "photons"):
        if part not in data:
            continue
        table = data[part]
        if not isinstance(table, dict):
            raise InputError("table must be an object", file=source, field=part, got=table)
        for k in TIS_KEYS:
            if k not in table:
                raise InputError("interaction table key missing", file=source, field=f"{part}.{k}",
                                 expected="a number in percent")
            v = table[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise InputError("interaction table value not a finite number", file=source, field=f"{part}.{k}",
                                 expected="a number in percent", got=v)
            if not 0.0 <= v <= 100.0:
                raise InputError("interaction table value out of range (percent of the incident light)",
                                 file=source, field=f"{part}.{k}", expected="a percentage in [0, 100]", got=v)
        out[part] = {k: float(table[k]) for k in TIS_KEYS}
    return out
