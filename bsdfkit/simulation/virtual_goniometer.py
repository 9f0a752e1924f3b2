"""The virtual goniometer: simulate the raw export of a spectral goniometer scan from a truth BSDF.

Users plan measurements with it (how fine a scan, how long an exposure, what uncertainty to expect); the test
suite uses it as ground truth. It models the set-up of §2 of the power-budget paper ([Power-budget]): a
collimated Xe beam through an interference or cut-on filter (or a monochromator stepped through a series of narrow
bands, :class:`BandSeries`), a circular detector aperture at distance d feeding a CCD spectrometer, and a reference
(direct-beam) spectrum taken by the same detector through an ND filter.

Signal chain per spectral pixel (counts):
    raw = clip(round(N_e/G + bias + N(0, σ_read)), 0, full scale),  N_e ~ Poisson(G·t·(rate + dark_rate))
with rate = R(λ)·P(λ) (R: relative responsivity, P: spectral power reaching the detector). The scattered
power is the aperture integral P_s(λ) = P_i(λ)·∫_ap f(ω, λ) cos θ dΩ (elastic) plus
Φ_exc·e(λ)·∫_ap f_conv(ω) cos θ dΩ (converted), evaluated with
:func:`bsdfkit.measurement.instrument.aperture_quadrature`,
so finite-aperture averaging of sharp lobes is part of the simulation. Everything is deterministic per seed:
each file draws from its own ``numpy.random.SeedSequence`` stream.
"""
from __future__ import annotations

import csv
import gzip
import io
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import jax
import jaxlib
import numpy as np
from numpy.typing import NDArray

from bsdfkit.core.conventions import CONVERSION_BAND_NM, EXCITATION_BAND_NM, band_label
from bsdfkit.core.errors import ValidationError
from bsdfkit.io import atomic
from bsdfkit.io.toml_write import dumps as toml_dumps
from bsdfkit.measurement.instrument import Instrument, aperture_quadrature
from bsdfkit.measurement.manifest import MAX_BAND_SERIES, MAX_WAVELENGTHS
from bsdfkit.simulation import truth as synthetic

#: Most detector positions per incidence and side of a simulated scan plan.
MAX_POSITIONS_PER_ARC = 100_000
EXPOSURE_LADDER_S: tuple[float, ...] = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)


@dataclass(frozen=True)
class Spectrometer:
    """CCD spectrometer: wavelength grid (nm), conversion gain, noise and range."""

    wavelength_min_nm: float = 380.0
    wavelength_max_nm: float = 780.0
    wavelength_step_nm: float = 0.5
    gain_e_per_count: float = 2.0
    read_noise_counts: float = 8.0
    bias_counts: float = 1000.0
    dark_rate_counts_per_s: float = 20.0
    full_scale_counts: int = 65535

    def __post_init__(self) -> None:
        lo, hi, step = self.wavelength_min_nm, self.wavelength_max_nm, self.wavelength_step_nm
        if not (np.isfinite([lo, hi, step]).all() and step > 0 and hi > lo):
            raise ValidationError("spectrometer grid must be finite and increasing", field="wavelength_step_nm",
                                  expected="min < max and step > 0", got=(lo, hi, step))
        n = (hi - lo) / step + 1
        if n > MAX_WAVELENGTHS:  # bounded before anything is allocated
            raise ValidationError("spectrometer grid too fine", field="wavelength_step_nm",
                                  expected=f"at most {MAX_WAVELENGTHS} wavelengths (limit MAX_WAVELENGTHS)",
                                  got=f"{step:g} nm ({n:.3g} wavelengths)")
        if not (self.gain_e_per_count > 0 and self.full_scale_counts > 0):
            raise ValidationError("gain and full scale must be positive", field="gain_e_per_count/full_scale_counts",
                                  got=(self.gain_e_per_count, self.full_scale_counts))

    @property
    def wavelength(self) -> NDArray[np.float64]:
        n = int(round((self.wavelength_max_nm - self.wavelength_min_nm) / self.wavelength_step_nm)) + 1
        return self.wavelength_min_nm + self.wavelength_step_nm * np.arange(n)

    def responsivity(self, wavelength_nm: NDArray[np.float64]) -> NDArray[np.float64]:
        """Relative spectral responsivity (counts per unit spectral power), peak 1: a smooth CCD-like curve.

        Parameters
        ----------
        wavelength_nm : ndarray
            Wavelength [nm].

        Returns
        -------
        ndarray
            Relative responsivity [-], 1 at 600 nm.
        """
        lam = np.asarray(wavelength_nm, dtype=np.float64)
        return 0.35 + 0.65 * np.exp(-(((lam - 600.0) / 230.0) ** 2))


@dataclass(frozen=True)
class Configuration:
    """An incident configuration: the lamp through a filter. ``filter`` is ("bandpass", lo, hi),
    ("longpass", cut_on) or ("monochromator", centre, fwhm) (:func:`~bsdfkit.simulation.truth.monochromator_slit`)."""

    name: str
    description: str
    filter: tuple
    incident_band_nm: tuple[float, float]
    reference_attenuation: float = 1e-3

    def incident_power(self, wavelength_nm: NDArray[np.float64], beam_scale: float) -> NDArray[np.float64]:
        """Spectral power of the beam at the sample (counts/s at unit responsivity per pixel).

        Parameters
        ----------
        wavelength_nm : ndarray
            Wavelength [nm].
        beam_scale : float
            The lamp's spectral power at 560 nm before the filter, in the unit of the result (e.g. [counts/s] per
            pixel; 1 for a relative spectrum).

        Returns
        -------
        ndarray
            The lamp spectrum times the filter's transmittance, in the unit of ``beam_scale``.
        """
        kind = self.filter[0]
        if kind == "bandpass":
            filt = synthetic.bandpass_filter(wavelength_nm, self.filter[1], self.filter[2])
        elif kind == "longpass":
            filt = synthetic.longpass_filter(wavelength_nm, self.filter[1])
        elif kind == "monochromator":
            filt = synthetic.monochromator_slit(wavelength_nm, self.filter[1], self.filter[2])
        else:
            raise ValidationError("unknown filter kind", field="filter", expected="bandpass, longpass or monochromator",
                                  got=kind)
        return beam_scale * synthetic.xenon_lamp(wavelength_nm) * filt


BLUE = Configuration("blue", f"blue interference filter {band_label(EXCITATION_BAND_NM)}",
                     ("bandpass", *EXCITATION_BAND_NM), EXCITATION_BAND_NM)
YELLOW = Configuration("yellow", "yellow cut-on filter 475 nm", ("longpass", 475.0), (475.0, 780.0))


@dataclass(frozen=True)
class BandSeries:
    """A monochromator scan: narrow incident bands centred at first, first + step, …, last (nm), each a
    triangular slit of FWHM ``bandwidth_nm`` (nominal band centre ± bandwidth/2). Written to the manifest
    as one ``[[band_series]]`` entry (docs/raw-format.md); its configurations are named ``{name}-{centre:g}``."""

    name: str = "mono"
    description: str = "grating monochromator, triangular slit 10 nm FWHM"
    first_nm: float = 390.0
    last_nm: float = 520.0
    step_nm: float = 10.0
    bandwidth_nm: float = 10.0
    reference_attenuation: float = 0.1

    def __post_init__(self) -> None:
        n = (self.last_nm - self.first_nm) / self.step_nm if self.step_nm > 0 else np.nan
        if not (np.isfinite(n) and n >= 0 and abs(n - round(n)) < 1e-9 and self.bandwidth_nm > 0
                and round(n) + 1 <= MAX_BAND_SERIES):
            raise ValidationError("bad band series", field="band_series",
                                  expected=f"first ≤ last, a whole number of steps > 0, at most {MAX_BAND_SERIES} "
                                           "bands and bandwidth > 0",
                                  got=(self.first_nm, self.last_nm, self.step_nm, self.bandwidth_nm))

    @property
    def centers_nm(self) -> NDArray[np.float64]:
        n = int(round((self.last_nm - self.first_nm) / self.step_nm)) + 1
        return self.first_nm + self.step_nm * np.arange(n)

    def configurations(self) -> tuple[Configuration, ...]:
        """One monochromator configuration per band, named ``{name}-{centre:g}``.

        Returns
        -------
        tuple of Configuration
            The bands in order of their centres; each nominal band is centre ± bandwidth/2 [nm].
        """
        half = self.bandwidth_nm / 2
        return tuple(Configuration(f"{self.name}-{c:g}", f"{self.description}, centre {c:g} nm",
                                   ("monochromator", float(c), self.bandwidth_nm), (float(c) - half, float(c) + half),
                                   self.reference_attenuation) for c in self.centers_nm)

    def manifest_entry(self) -> dict:
        """The series' ``[[band_series]]`` manifest entry (docs/raw-format.md).

        Returns
        -------
        dict
            Name, description, first and last centre, centre step and bandwidth [nm], the scan and reference file
            patterns (``{center}`` for the centre) and the reference attenuation [-].
        """
        return {"name": self.name, "description": self.description, "first_center_nm": self.first_nm,
                "last_center_nm": self.last_nm, "center_step_nm": self.step_nm, "bandwidth_nm": self.bandwidth_nm,
                "scan_file": f"scans/{self.name}-{{center}}.csv.gz",
                "reference_file": f"reference/{self.name}-{{center}}.csv.gz",
                "reference_attenuation": self.reference_attenuation}


@dataclass(frozen=True)
class ScanPlan:
    """Detector positions per incidence: the in-plane arc (signed θs; + = specular side) in each listed side,
    and the perpendicular arc through the specular direction (elevation ε), degrees."""

    theta_i_deg: tuple[float, ...] = (5.0, 45.0, 56.0)
    in_plane_deg: tuple[float, ...] = ()
    perpendicular_deg: tuple[float, ...] = ()
    sides: tuple[str, ...] = synthetic.SIDES
    retro_block_deg: float = 3.0
    fine_step_deg: float = 1.0
    fine_halfwidth_deg: float = 10.0

    def __post_init__(self) -> None:
        if self.fine_halfwidth_deg > 0 and not (np.isfinite(self.fine_step_deg) and self.fine_step_deg > 0):
            raise ValidationError("fine scan step must be positive", field="fine_step_deg", expected="> 0 deg",
                                  got=self.fine_step_deg)
        n = (2 * self.fine_halfwidth_deg / self.fine_step_deg if self.fine_halfwidth_deg > 0 else 0) + len(
            self.in_plane_deg) + len(self.perpendicular_deg)
        if not n <= MAX_POSITIONS_PER_ARC:  # bounded before anything is allocated
            raise ValidationError("too many detector positions per incidence", field="fine_step_deg",
                                  expected=f"at most {MAX_POSITIONS_PER_ARC} (limit MAX_POSITIONS_PER_ARC)",
                                  got=f"{n:.3g}")

    def positions(self, theta_i_deg: float, side: str) -> list[tuple[float, float, str]]:
        """(θs, φs, arc) in degrees in the sample frame for one incidence and side.

        In-plane positions beyond 90° are dropped, and in reflection those within ``retro_block_deg`` of the
        incident beam's direction; the perpendicular arc's ε = 0 is on the in-plane arc already.

        Parameters
        ----------
        theta_i_deg : float
            Angle of incidence [deg].
        side : str
            ``reflection`` or ``transmission``.

        Returns
        -------
        list of tuple
            ``(theta_s [deg], phi_s [deg], arc)`` per detector position, ``arc`` ``in_plane`` or
            ``perpendicular``.
        """
        th = theta_i_deg
        signed = set(np.round(self.in_plane_deg, 6))
        if self.fine_halfwidth_deg > 0:
            fine = np.arange(-self.fine_halfwidth_deg, self.fine_halfwidth_deg + 1e-9, self.fine_step_deg)
            signed |= set(np.round(th + fine, 6))
        out = []
        for s in sorted(signed):
            if abs(s) > 90.0 or (side == "reflection" and abs(s + th) < self.retro_block_deg):
                continue
            out.append((abs(s), 0.0 if s >= 0 else 180.0, "in_plane"))
        for eps in self.perpendicular_deg:
            if abs(eps) < 1e-9:
                continue  # the specular point is on the in-plane arc already
            e, t = np.radians(eps), np.radians(th)
            ts = np.degrees(np.arccos(np.clip(np.cos(e) * np.cos(t), -1, 1)))
            ps = np.degrees(np.arctan2(np.sin(e), np.cos(e) * np.sin(t)))
            out.append((float(ts), float(ps), "perpendicular"))
        return out


def default_plan() -> ScanPlan:
    """The cl830-synthetic plan: in-plane −88…88° every 4° plus 1° steps within ±10° of specular; the
    perpendicular arc −60…60° every 5° plus 1° steps within ±8°."""
    coarse = tuple(float(x) for x in np.arange(-88.0, 88.0 + 1e-9, 4.0))
    perp = sorted(set(np.round(np.arange(-60.0, 60.0 + 1e-9, 5.0), 6))
                  | set(np.round(np.arange(-8.0, 8.0 + 1e-9, 1.0), 6)))
    return ScanPlan(in_plane_deg=coarse, perpendicular_deg=tuple(float(x) for x in perp))


@dataclass(frozen=True)
class VirtualGoniometer:
    """Instrument + spectrometer + lamp of the power-budget paper's set-up (§2)."""

    instrument: Instrument = Instrument(886.0, 25.4, 14.0)
    spectrometer: Spectrometer = Spectrometer()
    beam_peak_counts_per_s: float = 2.0e8
    target_fill: float = 0.6
    max_exposure_s: float = 20.0
    dark_frames: int = 8
    reference_frames: int = 8
    exposure_ladder_s: tuple[float, ...] = EXPOSURE_LADDER_S

    # -- signal model ------------------------------------------------------------------------------
    def scattered_rate(self, truth: synthetic.TruthModel, config: Configuration, theta_i_deg: float,
                       side: str, theta_s_deg: NDArray, phi_s_deg: NDArray) -> NDArray[np.float64]:
        """Mean signal (counts/s per pixel, no dark) for detector centres (θs, φs); shape (n_pos, n_wavelength).

        Parameters
        ----------
        truth : bsdfkit.simulation.truth.TruthModel
            The sample's truth BSDF.
        config : Configuration
            The incident configuration (lamp and filter).
        theta_i_deg : float
            Angle of incidence [deg].
        side : str
            ``reflection`` or ``transmission``.
        theta_s_deg : ndarray
            Polar angles of the detector centres [deg].
        phi_s_deg : ndarray
            Azimuths of the detector centres [deg].

        Returns
        -------
        ndarray
            Mean signal rate [counts/s] per spectral pixel, shape ``(n_pos, n_wavelength)``: the scattered power
            integrated over each detector aperture (:func:`bsdfkit.measurement.instrument.aperture_quadrature`).
        """
        lam = self.spectrometer.wavelength
        resp = self.spectrometer.responsivity(lam)
        p_i = config.incident_power(lam, self.beam_peak_counts_per_s)
        th = np.radians(theta_i_deg)
        quad = aperture_quadrature(np.radians(theta_s_deg), np.radians(phi_s_deg), self.instrument)
        cos = np.clip(quad.directions[..., 2], 0.0, None)  # nodes past the horizon see nothing
        w = quad.weights * cos
        return resp * truth.scattered_power(side, th, quad.directions, w, lam, p_i)

    def expected_bsdf(self, truth: synthetic.TruthModel, config: Configuration, theta_i_deg: float,
                      side: str, theta_s_deg: NDArray, phi_s_deg: NDArray) -> dict[str, NDArray[np.float64]]:
        """What an ideal (noise-free) instrument reports: aperture-averaged BSDF and bi-spectral BSDF.

        ``bsdf`` = P_s(λ)/(P_i(λ) Ω cos θs) where P_i(λ) > 0; ``bsdf_bispectral`` = P_s(λ)/(Φ_i Ω cos θs).

        Parameters
        ----------
        truth : bsdfkit.simulation.truth.TruthModel
            The sample's truth BSDF.
        config : Configuration
            The incident configuration (lamp and filter).
        theta_i_deg : float
            Angle of incidence [deg].
        side : str
            ``reflection`` or ``transmission``.
        theta_s_deg : ndarray
            Polar angles of the detector centres [deg].
        phi_s_deg : ndarray
            Azimuths of the detector centres [deg].

        Returns
        -------
        dict
            ``bsdf`` [1/sr] (NaN where no incident power) and ``bsdf_bispectral`` [1/(sr nm)], each of shape
            ``(n_pos, n_wavelength)``.
        """
        lam = self.spectrometer.wavelength
        resp = self.spectrometer.responsivity(lam)
        p_i = config.incident_power(lam, self.beam_peak_counts_per_s)
        rate = self.scattered_rate(truth, config, theta_i_deg, side, theta_s_deg, phi_s_deg)
        geom = self.instrument.solid_angle_sr * np.cos(np.radians(np.asarray(theta_s_deg)))[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            bsdf = np.where(p_i > 0, rate / (resp * np.where(p_i > 0, p_i, 1.0)) / geom, np.nan)
        phi_i = np.trapezoid(p_i, lam)
        return {"bsdf": bsdf, "bsdf_bispectral": rate / resp / phi_i / geom}

    # -- noise -------------------------------------------------------------------------------------
    def choose_exposure(self, peak_rate: float) -> float:
        """The longest exposure of the ladder, up to ``max_exposure_s``, that keeps the peak pixel's mean counts
        (bias + signal + dark) within ``target_fill`` × full scale (the shortest step when none does).

        Parameters
        ----------
        peak_rate : float
            Mean signal rate of the brightest pixel, dark excluded [counts/s].

        Returns
        -------
        float
            Exposure time [s].
        """
        sp = self.spectrometer
        budget = self.target_fill * sp.full_scale_counts - sp.bias_counts
        best = self.exposure_ladder_s[0]
        for t in self.exposure_ladder_s:
            if t <= self.max_exposure_s and (peak_rate + sp.dark_rate_counts_per_s) * t <= budget:
                best = t
        return best

    def read_counts(self, rate: NDArray[np.float64], exposure_s: NDArray[np.float64] | float,
                    rng: np.random.Generator) -> NDArray[np.int64]:
        """Raw counts for mean signal ``rate`` (counts/s) integrated for ``exposure_s``, with dark, shot and read
        noise.

        Parameters
        ----------
        rate : ndarray
            Mean signal rate per spectral pixel, dark excluded [counts/s], shape ``(n, n_wavelength)``.
        exposure_s : float or ndarray
            Exposure time, one for all or one per row [s].
        rng : numpy.random.Generator
            The random stream of the draws.

        Returns
        -------
        ndarray
            Raw counts (bias included, rounded and clipped to 0 … full scale) [counts], shape of ``rate``.
        """
        sp = self.spectrometer
        t = np.asarray(exposure_s, dtype=np.float64)
        if t.ndim == 1:
            t = t[:, None]
        electrons = rng.poisson(sp.gain_e_per_count * t * (np.clip(rate, 0, None) + sp.dark_rate_counts_per_s))
        counts = (electrons / sp.gain_e_per_count + sp.bias_counts
                  + rng.normal(0.0, sp.read_noise_counts, electrons.shape))
        return np.clip(np.rint(counts), 0, sp.full_scale_counts).astype(np.int64)


# ------------------------------------------------------------------------------------------- export
@dataclass
class RawExport:
    """An in-memory raw export; :func:`write_raw_export` writes it in the documented format (docs/raw-format.md)."""

    manifest: dict
    scans: dict[str, dict]            # config name -> {"columns": {...}, "counts": (n, n_wl)}
    references: dict[str, dict]       # config name -> {"exposure_s": t, "counts": (frames, n_wl)}
    dark: dict                        # {"exposure_s": (n,), "frame": (n,), "counts": (n, n_wl)}
    responsivity: NDArray[np.float64]
    wavelength: NDArray[np.float64]


def _stream(seed: int, *words: str) -> np.random.Generator:
    key = [int(seed)] + [int.from_bytes(w.encode()[:8].ljust(8, b"\0"), "little") for w in words]
    return np.random.default_rng(np.random.SeedSequence(key))


def simulate_scan(truth: synthetic.TruthModel, plan: ScanPlan | None = None,
                  goniometer: VirtualGoniometer | None = None,
                  configurations: tuple[Configuration, ...] = (BLUE, YELLOW), seed: int = 0,
                  sample_name: str | None = None, extra_manifest: dict | None = None,
                  band_series: tuple[BandSeries, ...] = ()) -> RawExport:
    """Simulate a complete raw export (scans, reference beams, darks) of ``truth`` measured with ``plan``:
    the ``configurations`` and then every band of each ``band_series`` (a monochromator scan).

    Parameters
    ----------
    truth : bsdfkit.simulation.truth.TruthModel
        The sample's truth BSDF.
    plan : ScanPlan, optional
        Incidences and detector positions; None for :func:`default_plan`.
    goniometer : VirtualGoniometer, optional
        Instrument, spectrometer and lamp; None for the default set-up.
    configurations : tuple of Configuration, optional
        Incident configurations measured (default: the blue and yellow filters).
    seed : int, optional
        Seed of every file's random stream.
    sample_name : str, optional
        The manifest's sample name; None for the truth's name.
    extra_manifest : dict, optional
        Top-level manifest tables added to (or replacing) the generated ones.
    band_series : tuple of BandSeries, optional
        Monochromator scans measured after the configurations.

    Returns
    -------
    RawExport
        The export in memory (:func:`write_raw_export` writes it).
    """
    plan = plan or default_plan()
    gonio = goniometer or VirtualGoniometer()
    sp = gonio.spectrometer
    lam = sp.wavelength
    used_exposures: set[float] = set()
    scans: dict[str, dict] = {}
    references: dict[str, dict] = {}
    for config in configurations + tuple(c for series in band_series for c in series.configurations()):
        cols: dict[str, list] = {k: [] for k in ("theta_i_deg", "phi_i_deg", "theta_s_deg", "phi_s_deg", "side",
                                                 "arc", "exposure_s")}
        blocks = []
        for th in plan.theta_i_deg:
            for side in plan.sides:
                pos = plan.positions(th, side)
                ts = np.array([p[0] for p in pos])
                ps = np.array([p[1] for p in pos])
                rate = gonio.scattered_rate(truth, config, th, side, ts, ps)
                exposure = np.array([gonio.choose_exposure(r.max()) for r in rate])
                used_exposures.update(exposure.tolist())
                rng = _stream(seed, "scan", config.name, f"{th:g}", side)
                blocks.append(gonio.read_counts(rate, exposure, rng))
                cols["theta_i_deg"] += [th] * len(pos)
                cols["phi_i_deg"] += [180.0] * len(pos)
                cols["theta_s_deg"] += ts.tolist()
                cols["phi_s_deg"] += ps.tolist()
                cols["side"] += [side] * len(pos)
                cols["arc"] += [p[2] for p in pos]
                cols["exposure_s"] += exposure.tolist()
        scans[config.name] = {"columns": cols, "counts": np.concatenate(blocks, axis=0)}
        ref_rate = (sp.responsivity(lam) * config.incident_power(lam, gonio.beam_peak_counts_per_s)
                    * config.reference_attenuation)
        t_ref = gonio.choose_exposure(ref_rate.max())
        used_exposures.add(t_ref)
        rng = _stream(seed, "reference", config.name)
        references[config.name] = {
            "exposure_s": t_ref,
            "counts": gonio.read_counts(np.broadcast_to(ref_rate, (gonio.reference_frames, lam.size)),
                                        np.full(gonio.reference_frames, t_ref), rng),
        }
    exposures = sorted(used_exposures)
    dark_t = np.repeat(exposures, gonio.dark_frames)
    rng = _stream(seed, "dark")
    dark_counts = gonio.read_counts(np.zeros((dark_t.size, lam.size)), dark_t, rng)
    dark = {"exposure_s": dark_t, "frame": np.tile(np.arange(gonio.dark_frames), len(exposures)), "counts": dark_counts}

    manifest = {
        "format": "bsdfkit-raw-scan",
        "format_version": 1,
        "sample": {"name": sample_name or truth.name, "synthetic": True,
                   "description": f"SYNTHETIC data made by bsdfkit's virtual goniometer from the truth '{truth.name}'"},
        "instrument": asdict(gonio.instrument),
        "spectrometer": {
            "wavelength_min_nm": sp.wavelength_min_nm, "wavelength_max_nm": sp.wavelength_max_nm,
            "wavelength_step_nm": sp.wavelength_step_nm, "gain_e_per_count": sp.gain_e_per_count,
            "full_scale_counts": sp.full_scale_counts, "responsivity_file": "responsivity.csv",
        },
        "dark": {"file": "dark.csv.gz"},
        "configuration": [
            {"name": c.name, "description": c.description, "incident_band_nm": list(c.incident_band_nm),
             "scan_file": f"scans/{c.name}.csv.gz", "reference_file": f"reference/{c.name}.csv.gz",
             "reference_attenuation": c.reference_attenuation}
            for c in configurations
        ],
        **({"band_series": [series.manifest_entry() for series in band_series]} if band_series else {}),
        "provenance": {"generator": "bsdfkit.simulation.virtual_goniometer.simulate_scan", "seed": int(seed),
                       "versions": generator_versions(),
                       "plan": asdict(plan), "goniometer": json.loads(json.dumps(asdict(gonio)))},
    }
    if extra_manifest:
        manifest.update(extra_manifest)
    return RawExport(manifest=manifest, scans=scans, references=references, dark=dark,
                     responsivity=sp.responsivity(lam), wavelength=lam)


def generator_versions() -> dict[str, str]:
    """Versions of the numerical libraries that made a simulated export: the files regenerate bit for bit under
    these (the locked ones); other versions may round differently in the last place."""
    return {"numpy": np.__version__, "jax": jax.__version__, "jaxlib": jaxlib.__version__}


# --------------------------------------------------------------------------------------------- writing
def _csv_gz(header: list[str], rows: list[list]) -> bytes:
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    # mtime=0 keeps the bytes identical for identical content.
    return gzip.compress(text.getvalue().encode("utf-8"), compresslevel=9, mtime=0)


def _wl_header(lam: NDArray[np.float64]) -> list[str]:
    return [f"{x:.1f}" if abs(x * 10 - round(x * 10)) < 1e-9 else repr(float(x)) for x in lam]


def raw_export_names(export: RawExport) -> list[str]:
    """The files of a raw export folder, manifest last.

    Parameters
    ----------
    export : RawExport
        The export.

    Returns
    -------
    list of str
        Paths relative to the export folder.
    """
    return ([f"scans/{n}.csv.gz" for n in export.scans] + [f"reference/{n}.csv.gz" for n in export.references]
            + ["dark.csv.gz", "responsivity.csv", "manifest.toml"])


def write_raw_export(export: RawExport, folder: str | Path, force: bool = False) -> Path:
    """Write ``export`` as manifest.toml + gzip CSV files (docs/raw-format.md) as one atomic output set.

    ``folder`` is the export as a whole: an existing folder that is not empty is refused without ``force`` and
    replaced with it (:class:`bsdfkit.io.atomic.OutputSet`, ``whole_folder``).

    Parameters
    ----------
    export : RawExport
        The export to write.
    folder : str or Path
        The export folder.
    force : bool, optional
        Replace an existing, non-empty folder.

    Returns
    -------
    Path
        The folder written.
    """
    folder = Path(folder)
    wl = _wl_header(export.wavelength)
    with atomic.OutputSet(folder, raw_export_names(export), force, whole_folder=True) as out:
        for name, scan in export.scans.items():
            c = scan["columns"]
            rows = [[f"{c['theta_i_deg'][k]:.6g}", f"{c['phi_i_deg'][k]:.6g}", f"{c['theta_s_deg'][k]:.6f}",
                     f"{c['phi_s_deg'][k]:.6f}", c["side"][k], c["arc"][k], f"{c['exposure_s'][k]:g}"]
                    + scan["counts"][k].tolist() for k in range(len(c["side"]))]
            atomic.write_bytes(out.path(f"scans/{name}.csv.gz"),
                               _csv_gz(["theta_i_deg", "phi_i_deg", "theta_s_deg", "phi_s_deg", "side", "arc",
                                        "exposure_s"] + wl, rows), True)
        for name, ref in export.references.items():
            rows = [[k, f"{ref['exposure_s']:g}"] + ref["counts"][k].tolist() for k in range(ref["counts"].shape[0])]
            atomic.write_bytes(out.path(f"reference/{name}.csv.gz"), _csv_gz(["frame", "exposure_s"] + wl, rows),
                               True)
        d = export.dark
        rows = [[int(d["frame"][k]), f"{d['exposure_s'][k]:g}"] + d["counts"][k].tolist()
                for k in range(d["counts"].shape[0])]
        atomic.write_bytes(out.path("dark.csv.gz"), _csv_gz(["frame", "exposure_s"] + wl, rows), True)
        resp_rows = "wavelength_nm,relative_responsivity\n" + "".join(
            f"{x:.1f},{r:.8f}\n" for x, r in zip(export.wavelength, export.responsivity))
        atomic.write_text(out.path("responsivity.csv"), resp_rows, True)
        atomic.write_text(out.path("manifest.toml"), toml_dumps(export.manifest), True)
    return folder


# ------------------------------------------------------------------------------ the cl830 stand-in
#: TIS targets (percent of incident power) of the synthetic CL830 stand-in. 45° is Table 2 of the
#: power-budget paper; 5° and 56° are plausible values with the specular share growing with incidence.
CL830_TIS_TARGETS: dict[float, dict[str, float]] = {
    5.0: {"B_bibs": 10.2, "F_bibs": 6.4, "B_biys": 26.0, "F_biys": 26.6, "B_yiys": 45.0, "F_yiys": 48.3},
    45.0: {"B_bibs": 10.9, "F_bibs": 5.4, "B_biys": 26.3, "F_biys": 25.7, "B_yiys": 45.7, "F_yiys": 47.1},
    56.0: {"B_bibs": 11.8, "F_bibs": 4.7, "B_biys": 26.6, "F_biys": 25.0, "B_yiys": 46.6, "F_yiys": 45.9},
}
#: Lobe shapes: (A, σ) per interaction, side and incidence. Reflection lobes are specular peaks whose TIS
#: share grows with incidence (Figs. 6-8); transmission lobes are broad forward bodies centred on the direct
#: transmission direction ("decreasing with scattering angle", Fig. 4 of the cylindrical-module paper).
_CL830_LOBES = {
    ("bibs", "reflection"): {5.0: (0.6, 0.045), 45.0: (2.0, 0.05), 56.0: (3.2, 0.055)},
    ("yiys", "reflection"): {5.0: (1.0, 0.045), 45.0: (3.0, 0.05), 56.0: (4.5, 0.055)},
    ("bibs", "transmission"): {5.0: (0.016, 0.42), 45.0: (0.014, 0.40), 56.0: (0.012, 0.40)},
    ("yiys", "transmission"): {5.0: (0.09, 0.45), 45.0: (0.085, 0.43), 56.0: (0.08, 0.42)},
}
_CL830_KAPPA = {"bibs": (-5.0, 460.0), "yiys": (3.0, 600.0)}
_CL830_EPSILON = {"reflection": 0.10, "transmission": 0.05}


def cl830_truth(goniometer: VirtualGoniometer | None = None) -> synthetic.PhosphorPlateTruth:
    """Truth of the cl830-synthetic plate, with ρ and T solved so that the exact TIS equals the targets.

    The exact TIS depends on the measurement's incident spectra (the weighted means of eqs. 5 and 8), so the
    lamp and filters of ``goniometer`` enter: ρ = TIS/⟨m⟩ − TIS_lobe.

    Parameters
    ----------
    goniometer : VirtualGoniometer, optional
        The set-up whose spectrometer grid and incident spectra enter; None for the default set-up.

    Returns
    -------
    bsdfkit.simulation.truth.PhosphorPlateTruth
        The truth at the incidences of :data:`CL830_TIS_TARGETS`.
    """
    gonio = goniometer or VirtualGoniometer()
    lam = gonio.spectrometer.wavelength
    blue = BLUE.incident_power(lam, 1.0)
    yellow = YELLOW.incident_power(lam, 1.0)
    angles = tuple(sorted(CL830_TIS_TARGETS))
    tables: dict[str, dict[str, list]] = {"bibs": {}, "yiys": {}, "biys": {}}
    for side, tag in (("reflection", "B"), ("transmission", "F")):
        for inter, band, spec in (("bibs", EXCITATION_BAND_NM, blue), ("yiys", CONVERSION_BAND_NM, yellow)):
            kappa, lref = _CL830_KAPPA[inter]
            rows = []
            for th in angles:
                a, sigma = _CL830_LOBES[(inter, side)][th]
                m = synthetic.weighted_mean(lam, 1.0 + kappa / 100.0 * (lam - lref) / 100.0, spec, band)
                rho = (CL830_TIS_TARGETS[th][f"{tag}_{inter}"] / 100.0 / m
                       - synthetic.clipped_gaussian_lobe_tis(a, sigma, np.radians(th)))
                if rho <= 0:
                    raise ValidationError("lobe carries more than the target TIS", field=f"{inter}.{side}.{th}")
                rows.append(synthetic.LobeParams(rho=rho, A=a, sigma=sigma, kappa=kappa / 100.0, lambda_ref=lref))
            tables[inter][side] = rows
        tables["biys"][side] = [synthetic.ConversionParams(T=CL830_TIS_TARGETS[th][f"{tag}_biys"] / 100.0,
                                                           epsilon=_CL830_EPSILON[side]) for th in angles]
    return synthetic.PhosphorPlateTruth(
        name="cl830-synthetic", theta_i_deg=angles,
        bibs={s: tuple(v) for s, v in tables["bibs"].items()},
        yiys={s: tuple(v) for s, v in tables["yiys"].items()},
        biys={s: tuple(v) for s, v in tables["biys"].items()},
    )


def truth_manifest_section(truth: synthetic.PhosphorPlateTruth, goniometer: VirtualGoniometer | None = None) -> dict:
    """The ``[truth]`` manifest table: parameters and the exact TIS per incidence (percent).

    Parameters
    ----------
    truth : bsdfkit.simulation.truth.PhosphorPlateTruth
        The truth of the simulated scan.
    goniometer : VirtualGoniometer, optional
        The set-up whose spectrometer grid and incident spectra enter the exact TIS; None for the default set-up.

    Returns
    -------
    dict
        ``{"truth": {...}}``: the model's name, its parameters as JSON and ``tis_percent`` [%] per incidence.
    """
    gonio = goniometer or VirtualGoniometer()
    lam = gonio.spectrometer.wavelength
    blue = BLUE.incident_power(lam, 1.0)
    yellow = YELLOW.incident_power(lam, 1.0)
    tis = {f"{th:g}": synthetic.exact_tis_table(truth, th, lam, blue, yellow) for th in truth.theta_i_deg}
    return {"truth": {"model": "bsdfkit.simulation.truth.PhosphorPlateTruth", "parameters_json": truth.to_json(),
                      "tis_percent": tis}}


def cl830_synthetic(seed: int = 830, plan: ScanPlan | None = None,
                    goniometer: VirtualGoniometer | None = None) -> RawExport:
    """The bundled measurement: the cl830 truth measured with the default plan (``measurements/cl830-synthetic``).

    Parameters
    ----------
    seed : int, optional
        Seed of every file's random stream (830 for the bundled set).
    plan : ScanPlan, optional
        Incidences and detector positions; None for :func:`default_plan`.
    goniometer : VirtualGoniometer, optional
        Instrument, spectrometer and lamp; None for the default set-up.

    Returns
    -------
    RawExport
        The export in memory, with the ``[truth]`` table and the command that regenerates it in its manifest.
    """
    gonio = goniometer or VirtualGoniometer()
    truth = cl830_truth(gonio)
    extra = truth_manifest_section(truth, gonio)
    extra["provenance_command"] = (f"bsdfkit simulate --preset cl830-synthetic --seed {seed} "
                                   "-o measurements/cl830-synthetic")
    return simulate_scan(truth, plan, gonio, seed=seed, sample_name="cl830-synthetic", extra_manifest=extra)


# ------------------------------------------------------------------ the excitation-emission stand-in
#: The monochromator scan of ``measurements/eem-synthetic``: 390-520 nm every 10 nm, 10 nm FWHM (a band at
#: 380 nm would reach below the 380 nm spectrometer grid), over the absorption edge and the emission onset.
EEM_BAND_SERIES = BandSeries()
#: Its continuation through the converted light's wavelengths every 20 nm (the same series name: one scan), so
#: that the plate model holds the elastic scattering, and the vanishing absorption, of every emitted wavelength.
EEM_LONG_SERIES = BandSeries(first_nm=540.0, last_nm=760.0, step_nm=20.0)
#: Its spectrometer: the power-budget paper's range at 1 nm (the 0.5 nm pixels of the bundled set would double
#: the files and add nothing to 10 nm bands and a 150 nm wide emission).
EEM_SPECTROMETER = Spectrometer(wavelength_step_nm=1.0)
EEM_SEED = 17


def eem_plan() -> ScanPlan:
    """A sparse plan that keeps the set small: in-plane −84…84° every 6° plus 1° steps within ±6° of specular;
    the perpendicular arc −60…60° every 10° plus 1° steps within ±5°; 5°, 45°, 56° incidence."""
    coarse = tuple(float(x) for x in np.arange(-84.0, 84.0 + 1e-9, 6.0))
    perp = sorted(set(np.round(np.arange(-60.0, 60.0 + 1e-9, 10.0), 6))
                  | set(np.round(np.arange(-5.0, 5.0 + 1e-9, 1.0), 6)))
    return ScanPlan(in_plane_deg=coarse, perpendicular_deg=tuple(float(x) for x in perp), fine_halfwidth_deg=6.0)


def eem_truth() -> synthetic.ExcitationEmissionTruth:
    """Truth of the eem-synthetic plate (:class:`~bsdfkit.simulation.truth.ExcitationEmissionTruth`).

    At zero absorption the elastic lobes are the cl830 stand-in's yellow (yiys) lobes with ρ solved so that
    their exact TIS is the yiys targets (Table 2 of the power-budget paper at 45°); the converted photons split
    between the sides as the cl830 biys targets do, with the same shape factors ε. Absorption, quantum yield
    and emission are the class defaults (documented there).
    """
    angles = tuple(sorted(CL830_TIS_TARGETS))
    elastic, conversion = {}, {}
    for side, tag in (("reflection", "B"), ("transmission", "F")):
        rows = []
        for th in angles:
            a, sigma = _CL830_LOBES[("yiys", side)][th]
            rho = CL830_TIS_TARGETS[th][f"{tag}_yiys"] / 100.0 - synthetic.clipped_gaussian_lobe_tis(
                a, sigma, np.radians(th))
            rows.append(synthetic.LobeParams(rho=rho, A=a, sigma=sigma))
        elastic[side] = tuple(rows)
    for th in angles:
        t = CL830_TIS_TARGETS[th]
        share = t["B_biys"] / (t["B_biys"] + t["F_biys"])
        for side, value in (("reflection", share), ("transmission", 1.0 - share)):
            conversion.setdefault(side, []).append(synthetic.ConversionParams(T=value, epsilon=_CL830_EPSILON[side]))
    return synthetic.ExcitationEmissionTruth(
        name="eem-synthetic", theta_i_deg=angles, elastic=elastic,
        conversion={s: tuple(v) for s, v in conversion.items()},
        emission_range_nm=(EEM_SPECTROMETER.wavelength_min_nm, EEM_SPECTROMETER.wavelength_max_nm))


def eem_command(seed: int = EEM_SEED, folder: str = "measurements/eem-synthetic") -> str:
    """The command that regenerates the eem-synthetic set bit for bit.

    Parameters
    ----------
    seed : int, optional
        Seed of every file's random stream.
    folder : str, optional
        The export folder the command writes.

    Returns
    -------
    str
        A shell command line.
    """
    return (f"python -c \"from bsdfkit.simulation.virtual_goniometer import eem_synthetic, write_raw_export; "
            f"write_raw_export(eem_synthetic(seed={seed}), '{folder}')\"")


def eem_synthetic(seed: int = EEM_SEED) -> RawExport:
    """The bundled excitation-emission set (``measurements/eem-synthetic``): the eem truth measured with the
    blue and yellow filters of the two-wavelength approach and the monochromator scan :data:`EEM_BAND_SERIES` +
    :data:`EEM_LONG_SERIES`, on the sparse :func:`eem_plan`, with a 1 nm spectrometer.

    Parameters
    ----------
    seed : int, optional
        Seed of every file's random stream.

    Returns
    -------
    RawExport
        The export in memory, with the ``[truth]`` table and the command that regenerates it in its manifest.
    """
    gonio = VirtualGoniometer(spectrometer=EEM_SPECTROMETER)
    truth = eem_truth()
    lam = EEM_SPECTROMETER.wavelength
    blue, yellow = BLUE.incident_power(lam, 1.0), YELLOW.incident_power(lam, 1.0)
    tis = {f"{th:g}": truth.two_colour_tis_percent(th, lam, blue, yellow) for th in truth.theta_i_deg}
    extra = {"provenance_command": eem_command(seed),
             "truth": {"model": "bsdfkit.simulation.truth.ExcitationEmissionTruth",
                       "parameters_json": truth.to_json(), "tis_percent": tis}}
    return simulate_scan(truth, eem_plan(), gonio, seed=seed, sample_name="eem-synthetic", extra_manifest=extra,
                         band_series=(EEM_BAND_SERIES, EEM_LONG_SERIES))
