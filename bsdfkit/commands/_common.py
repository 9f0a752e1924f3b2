"""Helpers shared by the CLI verbs: JSON output and progress reporting."""
from __future__ import annotations

import json
import math
import sys
from typing import Any

import numpy as np


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays (and nested containers of them) to plain JSON types.

    Non-finite floats become ``None`` so the JSON stays valid; callers that can produce them should say so.
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        return value if math.isfinite(value) else None
    return obj


def dumps(obj: Any) -> str:
    return json.dumps(to_jsonable(obj), indent=2, sort_keys=False)


def emit_json(obj: Any) -> None:
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
