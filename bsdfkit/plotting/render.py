"""PNG bytes of finished figures, drawn in this process or in one helper process while this one goes on.

Drawing a figure to PNG (tick layout, text, rasterising) is Python holding the interpreter lock. In the main job
it came after the traces, when one core worked through 14 figures and the exports while the other idled.
:class:`PngRenderer` pickles each figure (matplotlib figures pickle with their data), a spawned helper process
draws it and sends the bytes back, and the caller writes them itself (atomically, with the bookkeeping of
unfinished outputs in one process). The helper imports matplotlib and :mod:`bsdfkit.plotting.ticks` only, not
JAX. A figure that does not pickle, or a helper that dies, is drawn in this process instead: the same bytes.
"""
from __future__ import annotations

import contextlib
import io
import multiprocessing
import pickle
from collections.abc import Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from bsdfkit.core.children import child_initializer
from bsdfkit.io.atomic import write_bytes

#: resolution of the PNG files a run writes [dots per inch]
FIGURE_DPI = 120


def png_bytes(fig: Figure, dpi: int = FIGURE_DPI) -> bytes:
    """The PNG file of ``fig`` as bytes.

    Parameters
    ----------
    fig : Figure
        The figure.
    dpi : int
        Resolution [dots per inch].

    Returns
    -------
    bytes
        The PNG file.
    """
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _draw_pickled(blob: bytes, dpi: int) -> bytes:
    return png_bytes(pickle.loads(blob), dpi)


def _ready() -> None:
    """Load what drawing needs (matplotlib's Agg backend and its fonts) while the caller still computes."""
    from matplotlib import font_manager

    font_manager.findfont("DejaVu Sans")


@dataclass(frozen=True, eq=False)
class FigureFile:
    """A figure to write as a PNG output; calling it writes the file in this process.

    Parameters
    ----------
    figure : Figure
        The figure.
    dpi : int
        Resolution [dots per inch].
    """

    figure: Figure
    dpi: int = FIGURE_DPI

    def __call__(self, path: str | Path, force: bool = False) -> Path:
        """Write the PNG file atomically; return its path.

        Parameters
        ----------
        path : str or Path
            The PNG file to write.
        force : bool
            Replace an existing file.

        Returns
        -------
        Path
            The file written.
        """
        return write_bytes(path, png_bytes(self.figure, self.dpi), force)


@dataclass(frozen=True, eq=False)
class PendingPng:
    """A figure being drawn; :meth:`result` gives its PNG bytes (drawn here if the helper has not begun it, or
    failed)."""

    figure: Figure
    dpi: int
    future: Future | None = None

    def result(self) -> bytes:
        """The PNG file as bytes.

        Returns
        -------
        bytes
            The PNG file, the same bytes as :func:`png_bytes` of the figure.
        """
        if self.future is not None and not self.future.cancel():  # one the helper has not begun is drawn here
            try:
                return self.future.result()
            except (BrokenProcessPool, pickle.UnpicklingError, EOFError, OSError):
                pass  # the helper is gone: draw here
        return png_bytes(self.figure, self.dpi)


def png_results(pending: Sequence[PendingPng]) -> list[bytes]:
    """The PNG bytes of every figure of ``pending``, in order.

    The helper draws from the first figure on; this process takes the others from the last backwards (those the
    helper has not begun: :meth:`PendingPng.result`), so both processes draw until the two meet. After the
    traces this halved the wait for the main job's figures.

    Parameters
    ----------
    pending : sequence of PendingPng
        Figures submitted to a :class:`PngRenderer`.

    Returns
    -------
    list of bytes
        The PNG files, the same bytes wherever each was drawn.
    """
    out: list[bytes] = [b""] * len(pending)
    for k in reversed(range(len(pending))):
        out[k] = pending[k].result()
    return out


class PngRenderer:
    """Draws figures to PNG bytes in one spawned helper process (a context manager).

    Parameters
    ----------
    helper : bool
        Use a helper process; False draws every figure in this process when its result is asked for.
    pool : ProcessPoolExecutor, optional
        A spawned helper the caller already runs (and shuts down itself), used instead of starting one: a process
        that has imported matplotlib already saves the start-up.

    Notes
    -----
    The helper starts on entering (loading matplotlib while the caller computes) and is shut down on exit;
    a command ended by a signal terminates it with its other child processes.
    """

    def __init__(self, helper: bool = True, pool: ProcessPoolExecutor | None = None) -> None:
        self._helper = helper
        self._given = pool
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> PngRenderer:
        if self._helper:
            if self._given is None:  # its own helper ends with this process, however this process ends
                initializer, initargs = child_initializer()
                self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=initializer, initargs=initargs)
            else:
                self._pool = self._given
            with contextlib.suppress(BrokenProcessPool, RuntimeError):  # a dead helper: figures drawn here
                self._pool.submit(_ready)
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None and self._pool is not self._given:
            self._pool.shutdown(wait=exc[0] is None, cancel_futures=True)
        self._pool = None

    def submit(self, fig: Figure, dpi: int = FIGURE_DPI) -> PendingPng:
        """Start drawing ``fig``; the figure must not change afterwards.

        Parameters
        ----------
        fig : Figure
            The figure.
        dpi : int
            Resolution [dots per inch].

        Returns
        -------
        PendingPng
            Its PNG bytes when asked for.
        """
        if self._pool is None:
            return PendingPng(fig, dpi)
        try:
            blob = pickle.dumps(fig, protocol=pickle.HIGHEST_PROTOCOL)
            return PendingPng(fig, dpi, self._pool.submit(_draw_pickled, blob, dpi))
        except (pickle.PicklingError, TypeError, AttributeError, BrokenProcessPool, RuntimeError):
            return PendingPng(fig, dpi)  # not picklable, or the helper is gone: drawn here
