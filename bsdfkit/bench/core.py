"""Study records and the markdown/figure report of ``bsdfkit bench``."""
from __future__ import annotations

import datetime as _dt
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from bsdfkit.io.atomic import OutputSet, write_text
from bsdfkit.plotting.render import FigureFile


@dataclass(frozen=True)
class Row:
    """One setting of a study: its label, cost and error (relative, a fraction)."""

    setting: str
    error: float
    wall_s: float
    cost: float            # the cost axis used to pick "cheapest" (samples, rays, instrument seconds, ...)
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Study:
    name: str
    title: str
    truth: str             # what the error is measured against
    cost_label: str
    rows: tuple[Row, ...]
    notes: str = ""
    groups: tuple[str, ...] = ()  # optional: rows are tagged by extra["group"] (e.g. two methods compared)

    def cheapest(self, target: float, group: str | None = None) -> Row | None:
        """The lowest-cost row whose error is ≤ ``target``, among the rows of ``group`` if given.

        Parameters
        ----------
        target : float
            Largest relative error accepted [-].
        group : str, optional
            Consider only rows tagged with this group.

        Returns
        -------
        Row or None
        """
        return cheapest(self.rows if group is None else tuple(r for r in self.rows if r.extra.get("group") == group),
                        target)


def cheapest(rows: tuple[Row, ...], target: float) -> Row | None:
    """The lowest-cost row whose error is ≤ target (None if no setting reaches it).

    Parameters
    ----------
    rows : tuple of Row
        Settings of a study.
    target : float
        Largest relative error accepted [-].

    Returns
    -------
    Row or None
    """
    ok = [r for r in rows if np.isfinite(r.error) and r.error <= target]
    return min(ok, key=lambda r: (r.cost, r.wall_s)) if ok else None


def _fmt(x: float) -> str:
    if not np.isfinite(x):
        return "n/a"
    return f"{x:.3g}"


def study_markdown(study: Study, figure_name: str | None) -> str:
    """The markdown section of one study: its table and the cheapest settings reaching 1 % and 0.1 %.

    Parameters
    ----------
    study : Study
        The study.
    figure_name : str or None
        File name of its figure, linked below the table; None links none.

    Returns
    -------
    str
    """
    lines = [f"## {study.title}", "", f"Error: {study.truth}. Cost: {study.cost_label}.", ""]
    if study.notes:
        lines += [study.notes, ""]
    extra_keys = sorted({k for r in study.rows for k in r.extra if k != "group"})
    head = (["setting"] + (["method"] if study.groups else []) + ["error", "wall time (s)", study.cost_label]
            + extra_keys)
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for r in study.rows:
        cells = [r.setting] + ([str(r.extra.get("group", ""))] if study.groups else [])
        cells += [f"{100 * r.error:.3g} %" if np.isfinite(r.error) else "n/a", f"{r.wall_s:.3g}", _fmt(r.cost)]
        cells += [_fmt(r.extra[k]) if isinstance(r.extra.get(k), (int, float)) else str(r.extra.get(k, ""))
                  for k in extra_keys]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for group in (study.groups or (None,)):
        label = f" ({group})" if group else ""
        for target in (0.01, 0.001):
            best = study.cheapest(target, group)
            text = (f"**{best.setting}** (error {100 * best.error:.3g} %, {study.cost_label} {_fmt(best.cost)}, "
                    f"{best.wall_s:.3g} s)" if best else "not reached by any setting tried")
            lines.append(f"- cheapest setting reaching {100 * target:g} %{label}: {text}")
    lines.append("")
    if figure_name:
        lines += [f"![{study.title}]({figure_name})", ""]
    return "\n".join(lines)


def study_figure(study: Study) -> Figure:
    """Log-log plot of a study's error against its cost, with the 1 % and 0.1 % lines.

    Parameters
    ----------
    study : Study
        The study.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(6, 3.6))
    ax = fig.subplots()
    groups = study.groups or ("",)
    for g in groups:
        rows = [r for r in study.rows if (not study.groups or r.extra.get("group") == g) and np.isfinite(r.error)]
        if not rows:
            continue
        ax.loglog([max(r.cost, 1e-12) for r in rows], [max(r.error, 1e-9) for r in rows], "o-", label=g or None)
    ax.axhline(0.01, color="grey", ls="--", lw=0.8)
    ax.axhline(0.001, color="grey", ls=":", lw=0.8)
    ax.set_xlabel(study.cost_label)
    ax.set_ylabel("relative error")
    ax.set_title(study.title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    if study.groups:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def report_header(command: str, quick: bool, elapsed_s: float) -> str:
    """The title and preamble of accuracy.md: command, date, machine and mode.

    Parameters
    ----------
    command : str
        Command line that made the report.
    quick : bool
        Whether the studies ran in quick mode.
    elapsed_s : float
        Wall time of all studies [s].

    Returns
    -------
    str
    """
    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cpu = platform.processor() or platform.machine()
    return "\n".join([
        "# What accuracy costs in time",
        "",
        f"Made by `{command}` on {now}: {os.cpu_count()} cores ({cpu}), Python {platform.python_version()}, "
        f"{'quick' if quick else 'full'} mode, {elapsed_s:.0f} s in all. Regenerate with the same command; "
        "numbers are from this machine and vary with load (times are wall-clock of one run).",
        "",
        "Every study measures error against a known truth (the virtual goniometer's exact TIS, closed forms, the "
        "radiosity oracle, or a fine reference) and lists the cheapest setting that reaches 1 % and 0.1 %.",
        "",
    ])


def figure_name(study_name: str) -> str:
    """File name of a study's figure.

    Parameters
    ----------
    study_name : str
        ``Study.name``.

    Returns
    -------
    str
    """
    return f"accuracy_{study_name}.png"


def write_report(studies: list[Study], folder: Path, command: str, quick: bool, elapsed_s: float,
                 force: bool = False, out: OutputSet | None = None) -> Path:
    """Write accuracy.md and one figure per study into ``folder`` as one atomic output set (or into ``out``).

    Parameters
    ----------
    studies : list of Study
        Studies in report order.
    folder : Path
        Output folder.
    command : str
        Command line named in the report.
    quick : bool
        Whether the studies ran in quick mode.
    elapsed_s : float
        Wall time of all studies [s].
    force : bool, optional
        Replace an existing, non-empty folder.
    out : OutputSet, optional
        An open output set to write into (the caller commits it); a new one on ``folder`` by default.

    Returns
    -------
    Path
        The written ``accuracy.md``.
    """
    names = [figure_name(s.name) for s in studies] + ["accuracy.md"]
    own = out is None
    out = out if out is not None else OutputSet(folder, names, force)
    try:
        parts = [report_header(command, quick, elapsed_s)]
        for study in studies:
            name = figure_name(study.name)
            FigureFile(study_figure(study))(out.path(name), True)
            parts.append(study_markdown(study, name))
        write_text(out.path("accuracy.md"), "\n".join(parts), True)
    except BaseException:
        if own:
            out.abort()
        raise
    if own:
        out.commit()
    return Path(folder) / "accuracy.md"
