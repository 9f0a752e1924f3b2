"""The figures of a run drawn by a helper process: the same PNG bytes as drawn here, a figure that does not pickle
drawn here instead, and a helper that loads matplotlib, not JAX."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from bsdfkit.plotting.render import FigureFile, PngRenderer, png_bytes, png_results
from bsdfkit.plotting.ticks import decade_label, log_y

PNG = b"\x89PNG\r\n\x1a\n"


def _log_figure() -> Figure:
    fig = Figure(figsize=(3, 2))
    ax = fig.add_subplot()
    x = np.linspace(-80.0, 80.0, 33)
    ax.plot(x, 0.3 / np.pi + 2.0 * np.exp(-0.5 * (x / 4.0) ** 2), marker="o")
    log_y(ax)
    ax.set_title("BSDF [1/sr]")
    return fig


def test_helper_process_draws_the_same_png_as_this_process_and_a_figure_that_does_not_pickle_here(tmp_path):
    figs = [_log_figure(), _log_figure(), _log_figure()]
    figs[2].axes[0].xaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}°"))  # a lambda does not pickle
    expected = [png_bytes(f, 120) for f in figs]
    with PngRenderer() as renderer:  # one helper for the three (each start loads matplotlib again)
        pending = [renderer.submit(f, 120) for f in figs]
        assert [p.future is not None for p in pending] == [True, True, False]  # pickled and sent, or drawn here
        got = [p.result() for p in pending]
        # both processes draw: this one takes from the last backwards those the helper has not begun (the pool
        # hands the helper at most two at a time, the first two at once: those are never drawn here)
        many = [renderer.submit(figs[k % 2], 120) for k in range(6)]
        both = png_results(many)
        assert both == [expected[k % 2] for k in range(6)]
        assert many[-1].future.cancelled() and not many[0].future.cancelled()
    assert got == expected and got[0].startswith(PNG)
    with PngRenderer(helper=False) as serial:
        assert serial.submit(figs[0], 120).result() == expected[0]
    path = FigureFile(figs[0])(tmp_path / "a.png")
    assert path.read_bytes() == expected[0]


def test_the_helper_loads_no_jax():
    # what the spawned helper imports: this module, the entry point it re-imports as __mp_main__, and the tick
    # formatters a run's pickled figures refer to
    code = ("import sys, bsdfkit.plotting.render, bsdfkit.plotting.ticks, bsdfkit.cli.main; "
            "print(sorted(m for m in ('jax', 'colour', 'scipy', 'bsdfkit.plotting.figures') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"
    assert decade_label(1e-2) == "10⁻²" and decade_label(3e-2) == ""
