"""Hypothesis strategies that damage text files the way people and tools do."""
from __future__ import annotations

from hypothesis import strategies as st

TOKENS = ["nan", "NaN", "inf", "-inf", "1e309", "1e-400", "-1", "0", "", " ", "\t", ",", ";", "abc", "\ufeff",
          "999999", "-0", "1,5", "TIS", "DataBegin", "DataEnd", "Scatter", "=", "[", "]", '"', "#", "\r", "\x00"]


@st.composite
def damaged(draw, text: str) -> str:
    """Apply 1-3 random edits: replace/delete/insert spans, drop/duplicate/swap lines, truncate, inject tokens."""
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["replace", "delete", "insert", "drop_line", "dup_line", "swap_lines", "truncate",
                                   "token"]))
        n = len(text)
        if n == 0:
            text = draw(st.sampled_from(TOKENS))
            continue
        i = draw(st.integers(0, n - 1))
        if op == "replace":
            text = text[:i] + draw(st.text(max_size=3)) + text[i + 1:]
        elif op == "delete":
            j = draw(st.integers(i, min(n, i + 40)))
            text = text[:i] + text[j:]
        elif op == "insert":
            text = text[:i] + draw(st.text(max_size=8)) + text[i:]
        elif op == "token":
            j = i
            while j < n and text[j] not in ",\t \n":
                j += 1
            text = text[:i] + draw(st.sampled_from(TOKENS)) + text[j:]
        else:
            lines = text.split("\n")
            k = draw(st.integers(0, len(lines) - 1))
            if op == "drop_line":
                del lines[k]
            elif op == "dup_line":
                lines.insert(k, lines[k])
            elif op == "swap_lines" and len(lines) > 1:
                m = draw(st.integers(0, len(lines) - 1))
                lines[k], lines[m] = lines[m], lines[k]
            elif op == "truncate":
                lines = lines[:k]
            text = "\n".join(lines)
    return text
