"""Short text and HTML renderings of result objects (for ``repr`` and notebooks)."""

from __future__ import annotations

import html
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

__all__ = ["array_text", "keys_text", "number_text", "html_table"]


def array_text(a: Any) -> str:
    """``float64(30, 50, 4)`` for an array, ``None`` for None: the shape, never the values."""
    if a is None:
        return "None"
    a = np.asarray(a)
    return f"{a.dtype}{tuple(a.shape)}"


def keys_text(keys: Iterable[str], limit: int = 6) -> str:
    """``{a, b, c, ... +4}``: at most ``limit`` names of a mapping's keys."""
    keys = list(keys)
    shown = ", ".join(keys[:limit])
    more = f", ... +{len(keys) - limit}" if len(keys) > limit else ""
    return "{" + shown + more + "}"


def number_text(v: Any) -> str:
    """Four significant figures for floats, ``str`` otherwise."""
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.4g}"
    return str(v)


def html_table(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    """A plain HTML table of ``rows`` (missing cells empty), every text escaped."""
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(number_text(r[c])) if c in r else ''}</td>" for c in columns) + "</tr>"
        for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
