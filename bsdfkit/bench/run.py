"""Run the accuracy studies and write the report (``bsdfkit bench``)."""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from bsdfkit.bench import fitting, measurement, tracing
from bsdfkit.bench.core import Study, write_report
from bsdfkit.io.atomic import check_writable


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
    """Run every study (or ``only`` those named) and write accuracy.md + figures into ``folder``."""

    folder = Path(folder)
    check_writable(folder / "accuracy.md", force)
    start = time.perf_counter()
    studies = []
    for name, fn in study_functions():
        if only and name not in only:
            continue
        t0 = time.perf_counter()
        log(f"study {name} ...")
        studies.append(fn(quick))
        log(f"study {name}: {time.perf_counter() - t0:.1f} s")
    write_report(studies, folder, command, quick, time.perf_counter() - start, force=True)
    return studies
