"""JSON text of results: numpy scalars and arrays as plain JSON, non-finite floats as ``null``."""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays (and nested containers of them) to plain JSON types.

    Non-finite floats become ``None`` so the JSON stays valid; callers that can produce them should say so.

    Parameters
    ----------
    obj : object
        A value, possibly a dict, list or tuple nesting numpy scalars and arrays.

    Returns
    -------
    object
        The same structure in plain Python types (dict keys as str, tuples as lists).
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
    """JSON text of ``obj`` (:func:`to_jsonable`), indented by two spaces, keys in their order.

    Parameters
    ----------
    obj : object
        A value :func:`to_jsonable` converts.

    Returns
    -------
    str
        JSON text.
    """
    return json.dumps(to_jsonable(obj), indent=2, sort_keys=False)
