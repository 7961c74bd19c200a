"""Building a config's sections through the registry: ``[scenario]``, ``[[filters]]``, plain tables, ``[[paper]]``.

Experiment kinds (:mod:`pursuit.experiments`) and registrations that nest
filter tables (the ``imm`` filter) call these; each error names the field.
"""

from __future__ import annotations

from typing import Any

from .. import registry
from ..engine.montecarlo import validate_filters
from ..registry import Param

__all__ = ["PAPER_PARAMS", "build_scenario", "build_filter", "build_filters", "resolve_section", "resolve_paper"]

PAPER_PARAMS = (
    Param("filter", "str", doc="filter name as in [[filters]]"),
    Param("metric", "str", doc="a summary column, e.g. rmse_position, rms_x, wall_time_s"),
    Param("value", "float", doc="the paper's number"),
    Param("note", "str", "", "where the number comes from, caveats"),
)


def build_scenario(sections: dict[str, Any], *, multi_target: bool = False) -> Any:
    """Build the ``[scenario]`` table through the registry.

    A multi-target scenario (``mt-*``) is refused unless ``multi_target``
    (the ``multitarget`` kind), and the other way round, naming the field.
    """
    table = sections.get("scenario")
    if table is None:
        raise ValueError("scenario: required section is missing")
    if not isinstance(table, dict):
        raise ValueError("scenario: expected a table")
    values = dict(table)
    kind = values.pop("type", None)
    if kind is None:
        raise ValueError("scenario.type: required (see `pursuit list`)")
    comp = registry.get("scenario", kind, "scenario.type")
    is_multi = comp.target is not None and comp.target.__name__ == "MultiTargetScenario"
    if is_multi and not multi_target:
        raise ValueError(f"scenario.type: {kind!r} is a multi-target scenario; use it with kind = \"multitarget\"")
    if multi_target and not is_multi:
        raise ValueError(
            f"scenario.type: the multitarget kind needs a multi-target scenario (mt-crossing, mt-williams, mt-maneuvering), got {kind!r}"
        )
    return comp.build(where="scenario", **comp.resolve(values, "scenario"))


def build_filter(entry: dict[str, Any], scenario: Any, where: str) -> Any:
    """Build one filter table ``{type = ..., ...}`` against the scenario; errors are prefixed with ``where``."""
    values = dict(entry)
    kind = values.pop("type", None)
    if kind is None:
        raise ValueError(f"{where}.type: required (see `pursuit list`)")
    comp = registry.get("filter", kind, f"{where}.type")
    return comp.build(scenario=scenario, where=where, **comp.resolve(values, where))


def build_filters(sections: dict[str, Any], scenario: Any) -> list[Any]:
    """Build every ``[[filters]]`` entry against the scenario."""
    entries = sections.get("filters")
    if entries is None:
        raise ValueError("filters: required section is missing (add [[filters]] tables)")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError("filters: expected one or more [[filters]] tables")
    out = [build_filter(entry, scenario, f"filters[{i}]") for i, entry in enumerate(entries)]
    try:
        return validate_filters(out)
    except ValueError as e:
        raise ValueError(str(e)) from None


def resolve_section(sections: dict[str, Any], name: str, params: tuple[Param, ...]) -> dict[str, Any]:
    """Check an optional plain table against a parameter list."""
    table = sections.get(name, {})
    if not isinstance(table, dict):
        raise ValueError(f"{name}: expected a table")
    return registry.Component("section", name, "", params, dict).resolve(table, name)


def resolve_section_list(sections: dict[str, Any], name: str, params: tuple[Param, ...]) -> list[tuple[str, dict[str, Any]]]:
    """Check an array of tables ``[[name]]`` entry by entry against a parameter list.

    Returns ``(where, values)`` per entry, ``where`` = ``"name[i]"`` for the
    caller's own cross-checks (a known filter, a scan in range).
    """
    entries = sections.get(name, [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ValueError(f"{name}: expected [[{name}]] tables")
    component = registry.Component("section", name, "", params, dict)
    return [(f"{name}[{i}]", component.resolve(entry, f"{name}[{i}]")) for i, entry in enumerate(entries)]


def resolve_paper(
    sections: dict[str, Any], filter_names: list[str] | set[str], params: tuple[Param, ...] = PAPER_PARAMS
) -> list[dict[str, Any]]:
    """Check the ``[[paper]]`` reference values against ``params``; each must name a known filter.

    Kinds with extra keys (a condition, a swept value) pass their own
    ``params`` and check those keys on the returned entries.
    """
    out = []
    for where, vals in resolve_section_list(sections, "paper", params):
        if vals["filter"] not in filter_names:
            have = ", ".join(sorted(filter_names) if isinstance(filter_names, set) else filter_names)
            raise ValueError(f"{where}.filter: no filter named {vals['filter']!r} (have {have})")
        out.append(vals)
    return out
