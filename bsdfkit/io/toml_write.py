"""A small TOML writer for bsdfkit's own files (manifests, scenes, recipes).

Python's ``tomllib`` reads TOML but cannot write it. The subset written here (tables, arrays of tables,
strings, booleans, integers, floats, nested arrays) covers every file bsdfkit produces, and every output is
checked by reading it back with ``tomllib`` so a writer bug cannot produce a file that reads differently.
"""
from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from typing import Any

import numpy as np

from bsdfkit.core.errors import BsdfkitError

_BARE = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-")
_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped (TOML 1.0 §String)."""
    out = []
    for ch in text:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        elif 0xD800 <= ord(ch) <= 0xDFFF:
            raise BsdfkitError("cannot write a lone surrogate to TOML", expected="valid Unicode text", got=text)
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _key(k: str) -> str:
    return k if k and set(k) <= _BARE else _string(k)


def _value(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "nan"
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        return repr(f)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise BsdfkitError(f"cannot write a {type(v).__name__} to TOML", expected="str, number, bool, list or table")


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and all(isinstance(x, Mapping) for x in v)


def _emit(data: Mapping, prefix: list[str], out: list[str]) -> None:
    scalars = [(k, v) for k, v in data.items() if v is not None and not _is_table(v) and not _is_table_array(v)]
    for k, v in scalars:
        out.append(f"{_key(str(k))} = {_value(v)}")
    for k, v in data.items():
        path = prefix + [_key(str(k))]
        if _is_table(v):
            out.append("")
            out.append("[" + ".".join(path) + "]")
            _emit(v, path, out)
        elif _is_table_array(v):
            for item in v:
                out.append("")
                out.append("[[" + ".".join(path) + "]]")
                _emit(item, path, out)


def dumps(data: Mapping) -> str:
    """Serialise a mapping to TOML text; ``None`` values are omitted (TOML has no null).

    Parameters
    ----------
    data : Mapping
        Nested mapping of TOML values (str, int, float, bool, dates, lists, tables).

    Returns
    -------
    str
        TOML text, checked to parse.
    """
    out: list[str] = []
    _emit(data, [], out)
    text = "\n".join(out).lstrip("\n") + "\n"
    tomllib.loads(text)  # guard: what we write must parse
    return text
