"""Helpers shared by the CLI verbs: JSON output, option ranges, progress reporting and the rule that
``--force`` never replaces an input (:func:`refuse_replacing_inputs`, run by ``bsdfkit.cli.main`` before every
verb)."""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

from bsdfkit.core.errors import InputError
from bsdfkit.io.atomic import refuse_inputs


def check_options(args: Any, ranges: dict[str, tuple[float, float, str]]) -> None:
    """Refuse a numeric option that is not finite or outside its range (never ignored or replaced).

    ``ranges`` maps an attribute of ``args`` to (lo, hi, text of the expected range); None values are skipped.
    """
    for name, (lo, hi, expected) in ranges.items():
        value = getattr(args, name, None)
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise InputError("option out of range", field="--" + name.replace("_", "-"), expected=expected,
                             got=value)


#: argument names that hold a verb's input paths (positional arguments and ``--table``)
INPUT_ARGS = ("scan", "source", "path", "file", "files", "scene", "recipe", "table")


def _paths(value: Any) -> list[str]:
    if isinstance(value, str | Path):
        return [str(value)]
    if isinstance(value, list | tuple):
        return [str(v) for v in value if isinstance(v, str | Path)]
    return []


def io_paths(args: Any) -> tuple[list[str], list[str]]:
    """(inputs, outputs) of a parsed command line: the :data:`INPUT_ARGS` it holds, and ``--output`` with the
    files a verb writes beside or inside it (``args.extra_outputs(args)``, set by the verb, e.g. the plots of
    ``sweep``)."""
    inputs = [p for name in INPUT_ARGS for p in _paths(getattr(args, name, None))]
    outputs = _paths(getattr(args, "output", None))
    extra = getattr(args, "extra_outputs", None)
    if outputs and callable(extra):
        outputs += [str(p) for p in extra(args)]
    return inputs, outputs


def refuse_replacing_inputs(args: Any) -> None:
    """Refuse, before any work and whatever ``--force`` says, a command whose output is one of its inputs.

    Every output (and every file a verb writes beside or inside its output, :func:`io_paths`) is compared with
    every input by resolved path and, for existing files, ``os.path.samefile`` (a hard link or a second path to
    the same file); an input inside an output folder that a verb replaces as a whole is refused by
    :func:`bsdfkit.io.atomic.check_output_folder`. One shared check for every verb, so a new verb cannot forget it.
    """
    inputs, outputs = io_paths(args)
    for out in outputs:
        refuse_inputs(out, inputs)


def emit_json(obj: Any) -> None:
    from bsdfkit.io.jsonout import dumps  # numpy: not for `bsdfkit --help`

    sys.stdout.write(dumps(obj) + "\n")


def warn_dark(ds: Any, verb: str) -> None:
    """One warning line on stderr when the scan ``ds`` has records whose dark frames are above the signal.

    Said by ``ingest`` and by every verb that reduces such records (tis, budget, fit bsdf), not only recorded
    in the ``below_dark`` flag: the numbers they give are biased low.
    """
    from bsdfkit.measurement.calibrate import dark_above_signal  # xarray only once a scan is read

    line = dark_above_signal(ds)
    if line is not None:
        print(f"bsdfkit {verb}: warning: {line}", file=sys.stderr)


class Progress:
    """A minimal text progress bar on stderr (silent when stderr is not a terminal unless forced)."""

    def __init__(self, total: float, label: str = "", enabled: bool | None = None, width: int = 30):
        self.total = float(total) if total else 1.0
        self.label = label
        self.width = width
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._last = -1

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        frac = min(max(done / self.total, 0.0), 1.0)
        step = int(frac * 100)
        if step == self._last:
            return
        self._last = step
        filled = int(frac * self.width)
        sys.stderr.write(f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {step:3d}%")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


def add_table_arguments(p: Any) -> None:
    """The writers' options of ``export`` and ``convert``: ``--symmetry`` (Zemax), ``--xml-back``, ``--xml-basis``
    (BSDF XML) and ``--symmetry-tolerance``."""
    p.add_argument("--symmetry", default="PlaneSymmetrical", choices=("PlaneSymmetrical", "Asymmetrical", "auto"),
                   help="Zemax symmetry (PlaneSymmetrical is checked against the source; auto: PlaneSymmetrical "
                        "when the source is, else Asymmetrical; convert's default)")
    p.add_argument("--xml-back", default="none", choices=("none", "mirror"),
                   help="BSDF XML: Back blocks none (default) or mirror (= the Front blocks: a sample symmetric "
                        "between its faces)")
    p.add_argument("--xml-basis", default="auto", choices=("auto", "klems", "tree"),
                   help="BSDF XML basis: auto (default: a Radiance TensorTree3 when the source's specular lobe is "
                        "narrower than a Klems patch, FWHM < 10 deg, else Klems), klems (always; WINDOW reads only "
                        "Klems) or tree (always)")
    p.add_argument("--symmetry-tolerance", type=float, default=0.01, metavar="FRACTION",
                   help="PlaneSymmetrical: largest accepted mirror deviation of the source, as a fraction "
                        "of the block maximum (default 0.01); the mirror average is written")


def add_grid_arguments(p: Any, tis_tolerance_help: str) -> None:
    """The exported table's grid options of ``export`` and ``convert``: ``--grid``, ``--grid-tis-tolerance`` (its
    default differs by verb: ``tis_tolerance_help``), ``--grid-peak-tolerance`` and ``--node-values``."""
    p.add_argument("--grid", default="auto", choices=("auto", "fixed"),
                   help="table axes: auto (as fine as the source needs for the grid tolerances; default) or "
                        "fixed (the fine default grids; docs/exports.md, Grid resolution)")
    p.add_argument("--grid-tis-tolerance", type=float, default=None, metavar="FRACTION", help=tis_tolerance_help)
    p.add_argument("--grid-peak-tolerance", type=float, default=None, metavar="FRACTION",
                   help="auto grid: largest miss of the table at its cell midpoints, relative to the lobe peak "
                        "(default 0.01); also the limit of the peak re-check of the written file")
    # the choices are bsdfkit.tables.export.NODE_VALUES (not imported here: that module loads numpy)
    p.add_argument("--node-values", default="edge", choices=("point", "edge", "cell"),
                   help="TracePro, ASAP-style tables: edge (default: point samples, each row's last node inside the "
                        "disk the value that makes the strip up to the disk's edge integrate as the source does: "
                        "smaller auto grids), point samples of the source, or cell averages (the table's TIS by its "
                        "format's rule is the source's on any axes; --grid auto then refines by the lobe's peak only; "
                        "docs/exports.md, Grid resolution)")
