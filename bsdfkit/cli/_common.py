"""Helpers shared by the CLI verbs: JSON output, option ranges and progress reporting."""
from __future__ import annotations

import math
import sys
from typing import Any

from bsdfkit.core.errors import InputError


def check_options(args: Any, ranges: dict[str, tuple[float, float, str]]) -> None:
    """Refuse a numeric option that is not finite or outside its range (never ignored or replaced).

    ``ranges`` maps an attribute of ``args`` to (lo, hi, text of the expected range); None values are skipped.
    """
    for name, (lo, hi, expected) in ranges.items():
        value = getattr(args, name, None)
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise InputError("option out of range", field="--" + name.replace("_", "-"), expected=expected,
                             got=value)


def emit_json(obj: Any) -> None:
    from bsdfkit.io.jsonout import dumps  # numpy: not for `bsdfkit --help`

    sys.stdout.write(dumps(obj) + "\n")


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
