"""Fixed figure margins in inches: the cheap alternative to a layout engine.

``tight_layout`` and constrained layout measure every text of a figure (tick labels included) before it is drawn,
and drawing measures them again: for the run's tick-heavy figures the layout pass was about half of their drawing
time. Figures whose panels form a regular grid with known labels get fixed margins instead, sized for their
widest labels (tests check that every panel's ticks, labels and title lie inside the figure and apart).
"""
from __future__ import annotations

from matplotlib.figure import Figure


def fixed_margins(fig: Figure, nrows: int, ncols: int, *, left: float, right: float, bottom: float, top: float,
                  wspace: float = 0.0, hspace: float = 0.0) -> None:
    """Place a ``nrows`` × ``ncols`` subplot grid of ``fig`` with margins and gaps in inches [in].

    ``left``/``right``/``bottom``/``top`` are the distances from the figure's edges to the grid, ``wspace`` and
    ``hspace`` the gaps between columns and between rows. Call it before ``fig.subplots``.
    """
    width, height = fig.get_size_inches()
    panel_w = (width - left - right - (ncols - 1) * wspace) / ncols
    panel_h = (height - top - bottom - (nrows - 1) * hspace) / nrows
    if panel_w <= 0 or panel_h <= 0:
        raise ValueError(f"margins leave no room for the panels ({width:g} x {height:g} in)")
    fig.subplots_adjust(left=left / width, right=1.0 - right / width, bottom=bottom / height, top=1.0 - top / height,
                        wspace=wspace / panel_w if ncols > 1 else 0.0, hspace=hspace / panel_h if nrows > 1 else 0.0)
