"""Writing mutated TOML documents: a small writer and dotted-path edits.

The fuzzers read a shipped file with :mod:`tomllib`, edit one field by its path
(``("sensors", 0, "sigma")``) and write the document back with :func:`dumps`, which also
returns the line each key landed on, so the oracle knows which line an error must name.
"""

from __future__ import annotations

import copy
import json
import math
from typing import Any

DELETE = object()  # a mutation value that removes the key


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, RawValue):
        return v.text
    raise TypeError(f"cannot write {type(v).__name__}")


class RawValue:
    """A value written as given (for text TOML cannot make from a Python value, e.g. ``1e400``)."""

    def __init__(self, text: str) -> None:
        self.text = text


def _key(k: str) -> str:
    return k if k and all(c.isalnum() or c in "-_" for c in k) else json.dumps(k)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(doc: dict) -> tuple[str, dict[tuple, int]]:
    """TOML text of ``doc`` and the 1-based line of each key path written."""
    lines: list[str] = []
    where: dict[tuple, int] = {}

    def table(prefix: tuple, header: str | None, t: dict) -> None:
        if header is not None:
            lines.append(header)
            where[prefix] = len(lines)
        subs = []
        for k, v in t.items():
            if isinstance(v, dict) or _is_table_array(v):  # a section or [[tables]] (an inline table reads back the same)
                subs.append((k, v))
            else:
                lines.append(f"{_key(k)} = {_value(v)}")
                where[(*prefix, k)] = len(lines)
        for k, v in subs:
            name = ".".join(_key(str(p)) for p in (*_names(prefix), k))
            if isinstance(v, dict):
                lines.append("")
                table((*prefix, k), f"[{name}]", v)
            else:
                for i, item in enumerate(v):
                    lines.append("")
                    table((*prefix, k, i), f"[[{name}]]", item)

    table((), None, doc)
    return "\n".join(lines) + "\n", where


def _names(prefix: tuple) -> list[str]:
    return [p for p in prefix if isinstance(p, str)]


def edit(doc: dict, path: tuple, value: Any) -> dict:
    """A copy of ``doc`` with ``path`` set to ``value`` (or removed, for DELETE)."""
    new = copy.deepcopy(doc)
    node = new
    for p in path[:-1]:
        if isinstance(node, dict) and p not in node:
            node[p] = {}
        node = node[p]
    if value is DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return new


def get(doc: dict, path: tuple, default: Any = None) -> Any:
    """The value at ``path`` in ``doc``, or ``default`` when there is none."""
    node = doc
    for p in path:
        try:
            node = node[p]
        except (KeyError, IndexError, TypeError):
            return default
    return node
