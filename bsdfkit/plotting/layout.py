"""Fixed figure margins in inches: the cheap alternative to a layout engine.

``tight_layout`` and constrained layout measure every text of a figure (tick labels included) before it is drawn,
and drawing measures them again: for the run's tick-heavy figures the layout pass was about half of their drawing
time. Figures whose panels form a regular grid with known labels get fixed margins instead, sized for their
widest labels (tests check that every panel's ticks, labels and title lie inside the figure and apart).
"""
from __future__ import annotations

from dataclasses import dataclass

from matplotlib.figure import Figure


@dataclass(frozen=True)
class Margins:
    """Distances [in] from the figure's edges to a subplot grid, and the gaps between its columns and rows."""

    left: float
    right: float
    bottom: float
    top: float
    wspace: float = 0.0
    hspace: float = 0.0


def fixed_margins(fig: Figure, nrows: int, ncols: int, margins: Margins) -> None:
    """Place a ``nrows`` × ``ncols`` subplot grid of ``fig`` with margins and gaps in inches.

    Call it before ``fig.subplots``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure; its size [in] is read.
    nrows, ncols : int
        Rows and columns of the subplot grid.
    margins : Margins
        Edges to grid and gaps between panels [in].

    Raises
    ------
    ValueError
        When the margins leave no room for the panels.
    """
    m = margins
    width, height = fig.get_size_inches()
    panel_w = (width - m.left - m.right - (ncols - 1) * m.wspace) / ncols
    panel_h = (height - m.top - m.bottom - (nrows - 1) * m.hspace) / nrows
    if panel_w <= 0 or panel_h <= 0:
        raise ValueError(f"margins leave no room for the panels ({width:g} x {height:g} in)")
    fig.subplots_adjust(left=m.left / width, right=1.0 - m.right / width, bottom=m.bottom / height,
                        top=1.0 - m.top / height, wspace=m.wspace / panel_w if ncols > 1 else 0.0,
                        hspace=m.hspace / panel_h if nrows > 1 else 0.0)
