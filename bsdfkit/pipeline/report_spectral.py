"""The report section of the spectral comparison (issue 17): both tracer modes on one plate beside §4.2 of
[Cylindrical-module]. Called by :mod:`bsdfkit.pipeline.report` with its report object (summary ``rep.s``,
``rep.run_png``, ``rep.v``)."""
from __future__ import annotations

from typing import Any

from bsdfkit.pipeline.report import _esc, _f, _num, _pair, _pm_sig, _section, _table

ANCHOR = "spectral-modes"
TITLE = "Spectral mode vs two-wavelength mode (§4.2 of [Cylindrical-module])"


def _rel(row: dict) -> str:
    r, s = _num(row.get("relative_difference")), _num(row.get("relative_difference_std"))
    if r is None:
        return "—"
    return f"{100 * r:+.2f} ± {100 * (s or 0):.2f} % (z {r / s:+.1f})" if s else f"{100 * r:+.2f} %"


def spectral_comparison_section(rep: Any) -> str:
    """HTML section: the figure, band powers with relative differences, the direction check, LER/YBR/efficacy,
    the spectral trace's ledgers, and the stage's seconds and share of the run. Empty without the stage."""
    sc = rep.s.get("spectral_comparison")
    if not sc:
        return ""
    b, chk = sc.get("bands") or {}, sc.get("direction_check") or {}
    tw, sp = sc.get("two_wavelength") or {}, sc.get("spectral") or {}
    holds = chk.get("holds")
    below = "below" if chk.get("yellow_underestimated") else "NOT below"
    verdict = (f'<span class="{"agree" if holds else "differs"}">'
               f'{"the direction holds" if holds else "the direction does NOT hold"}</span>: near 470 nm '
               f'the two-wavelength spectrum is {"above" if chk.get("near_pump_overestimated") else "NOT above"} the '
               f'spectral one, in the yellow band it is {below}.')
    if not holds:
        rep.v.disagreements.append("spectral vs two-wavelength mode: the direction of §4.2 of [Cylindrical-module] "
                                   "does not hold on this plate (see its section)")
    rows = []
    for key, what in (("near_pump", "power near 470 nm"), ("yellow", "yellow power (module yellow band)")):
        row = b.get(key) or {}
        rows.append([f"{_esc(what)}, {_esc(row.get('label', '?'))} (W)",
                     _pm_sig(row.get("two_wavelength_W"), row.get("two_wavelength_std_W")),
                     _pm_sig(row.get("spectral_W"), row.get("spectral_std_W")), _rel(row)])
    rows += [["LER: extracted / emitted power (1)", _pm_sig(tw.get("LER"), tw.get("LER_std")),
              _pm_sig(sp.get("LER"), sp.get("LER_std")), "—"],
             ["YBR (1), " + _esc(sp.get("YBR_definition", "")), _pm_sig(tw.get("YBR_spectrum"),
                                                                     tw.get("YBR_spectrum_std")),
              _pm_sig(sp.get("YBR"), sp.get("YBR_std")), "—"],
             ["luminous efficacy of radiation (lm/W)", _f(tw.get("luminous_efficacy_lm_per_W"), 1),
              _f(sp.get("luminous_efficacy_lm_per_W"), 1), "—"]]
    tab = _table(["quantity", "two-wavelength", "spectral", "two-wavelength / spectral − 1"], rows,
                 "Module spectra of the two modes on the same plate (± standard errors of the traces)")
    ledger = sp.get("ledger") or {}
    power, photons = ledger.get("power_W") or {}, ledger.get("photons_per_s") or {}
    lines = [k for k in power if k != "error"] + [k for k in photons if k not in power and k != "error"]
    tab += _table(["ledger line (spectral trace)", "power (W)", "photons (1/s)"],
                  [[_esc(k), _f(power.get(k), 6) if k in power else "—",
                    f"{photons[k]:.5e}" if _num(photons.get(k)) is not None else "—"] for k in lines]
                  + [["relative error", f"{power.get('error', float('nan')):.1e}",
                      f"{photons.get('error', float('nan')):.1e}"]],
                  "Spectral trace: power and photon ledgers (the Stokes loss is a power line only)")
    seconds = rep.s.get("stage_seconds") or {}
    own = _num(seconds.get("spectral comparison"))
    total = sum(v for v in (_num(x) for x in seconds.values()) if v is not None)
    parts = ", ".join(f"{_esc(k)} {v:g} s" for k, v in (sc.get("stage_seconds") or {}).items())
    time_note = (f"<p class=\"note\">Stage time {own:.1f} s of {total:.1f} s of stages "
                 f"({100 * own / total:.0f} %): {parts}.</p>" if own is not None and total > 0 else "")
    text = (f"<p>One plate, two descriptions, both from <code>{_esc(sc.get('measurement', '?'))}</code>: the "
            "two-wavelength plate (blue and yellow configurations) and the plate spectral model (monochromator "
            f"scan); the device scene traced in both modes with {_esc(sc.get('rays'))} rays each and the same LED "
            "spectrum. The two-wavelength spectrum is built as the paper builds it: extracted blue power × the LED "
            f"spectrum shape + extracted yellow power × the emission shape ({_esc(sc.get('emission_shape', '?'))})."
            f"</p><p><b>[Cylindrical-module] §4.2</b>: the two-wavelength model overestimates the power near 470 nm "
            f"and underestimates the yellow emission. This run: {verdict}</p>")
    return _section(ANCHOR, TITLE, text + _pair(rep.run_png("spectral_comparison.png"), tab) + time_note)
