"""Run the accuracy studies and write the report (``bsdfkit bench``)."""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from bsdfkit.bench import fitting, measurement, tracing
from bsdfkit.bench.core import Study, figure_name, write_report
from bsdfkit.core.errors import InputError
from bsdfkit.io.atomic import OutputSet

#: Study keys whose Study.name (and figure) differ from the key.
FIGURE_STEMS = {"fit": "fit_tolerance"}


def study_functions() -> list[tuple[str, Callable[[bool], Study]]]:
    """The studies in report order (imported lazily: each pulls in its own part of the toolkit)."""

    studies: list[tuple[str, Callable[[bool], Study]]] = [
        ("tis_step", measurement.tis_vs_step),
        ("tis_exposure", measurement.tis_vs_exposure),
        ("quadrature", measurement.quadrature),
        ("spectral", measurement.spectral_resolution),
    ]

    studies += [("fit", fitting.fit_tolerance), ("fit_batch", fitting.batched_vs_loop),
                ("trace_rays", tracing.rays), ("trace_termination", tracing.termination),
                ("trace_precision", tracing.precision)]
    return studies


def run_bench(folder: str | Path, quick: bool = False, force: bool = False, command: str = "bsdfkit bench",
              only: list[str] | None = None, log: Callable[[str], None] = lambda m: None) -> list[Study]:
    """Run every study (or ``only`` those named) and write accuracy.md + figures into ``folder``.

    Parameters
    ----------
    folder : str or Path
        Output folder.
    quick : bool, optional
        Fewer, cheaper settings per study.
    force : bool, optional
        Replace an existing, non-empty folder.
    command : str, optional
        Command line named in the report.
    only : list of str, optional
        Keys of the studies to run (:func:`study_functions`); all by default.
    log : callable, optional
        ``log(message)`` receives a line before and after each study.

    Returns
    -------
    list of Study
    """

    folder = Path(folder)
    known = [name for name, _ in study_functions()]
    for name in only or ():
        if name not in known:
            raise InputError("unknown study", field="--only", expected="one of " + ", ".join(known), got=name)
    chosen = [(name, fn) for name, fn in study_functions() if not only or name in only]
    names = [figure_name(FIGURE_STEMS.get(name, name)) for name, _ in chosen] + ["accuracy.md"]
    # every output is checked before the studies run (minutes); they are written as one atomic set
    with OutputSet(folder, names, force) as out:
        start = time.perf_counter()
        studies = []
        for name, fn in chosen:
            t0 = time.perf_counter()
            log(f"study {name} ...")
            studies.append(fn(quick))
            log(f"study {name}: {time.perf_counter() - t0:.1f} s")
        write_report(studies, folder, command, quick, time.perf_counter() - start, force, out=out)
    return studies
