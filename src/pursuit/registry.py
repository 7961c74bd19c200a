"""Named, documented, validated building blocks for configs and the CLI.

Every scenario, filter, fading strategy and experiment kind that a TOML file
can name is registered here with its parameters.  A parameter declares its
type, its default and a check, so the config loader can refuse an unknown
key, a wrong type or an impossible value with one line naming the field,
before anything runs or is written.

Modules register their own components with :func:`register`.  Every module
of the packages in :data:`REGISTERING_PACKAGES` (:mod:`pursuit.config`, the
registrations, and :mod:`pursuit.experiments`, the experiment kinds) is
imported on first use, so a new module there registers without a line here.
A look-up of a known name imports only the module that registers it (the
index :data:`pursuit._catalog.MODULES`, generated with the catalog and checked
against the registry by a test), so ``pursuit track`` does not pay for
matplotlib and every other component; an unknown name, :func:`components`
and the catalog still import every module.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import math
import pkgutil
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence, Type  # Type: `type` would be ambiguous with Param.type in the API docs

if TYPE_CHECKING:
    import numpy as np

__all__ = ["Param", "Component", "register", "get", "components", "REQUIRED", "KINDS", "REGISTERING_PACKAGES", "field_param", "params_from", "field_default", "field_annotation", "toml_type"]

KINDS = ("scenario", "filter", "fading", "experiment", "model", "tracker")

REGISTERING_PACKAGES = ("pursuit.config", "pursuit.experiments")
"""Packages whose every module is imported (and so registers its components) on first look-up."""


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()


@dataclass(frozen=True)
class Param:
    """One configurable parameter.

    Attributes
    ----------
    name
        Key in the TOML table.
    type
        ``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"vector"``,
        ``"matrix"``, ``"table"`` or ``"any"``.
    default
        Default value, or :data:`REQUIRED`.
    doc
        One line for ``pursuit list`` and the docs.
    check
        Optional ``check(field, value) -> value`` that converts and raises
        ``ValueError`` naming the field when the value is impossible.
    choices
        Allowed values for a ``"str"`` parameter.
    source
        ``(cls, "field")`` or ``(cls, "field.subfield")``: the dataclass
        field this parameter sets, whose default, type and choices it was
        derived from (:func:`field_param`, :func:`params_from`).
        ``tests/test_registry.py`` checks them against the class.
    own
        True for an option of the builder itself, not a field of the
        component's class (``resample`` of the ``pf`` filter, say); a
        parameter that is neither derived nor ``own`` must be a field of
        the component's :attr:`Component.target` with the same default.
    """

    name: str
    type: str
    default: Any = REQUIRED
    doc: str = ""
    check: Callable[[str, Any], Any] | None = None
    choices: tuple[Any, ...] | None = None
    source: tuple[Type[Any], str] | None = None
    own: bool = False

    def convert(self, field_name: str, value: Any) -> Any:
        """Type-check and convert a TOML value; raises ``ValueError``."""
        v = _TYPE_CHECKS[self.type](field_name, value)
        if self.choices is not None and v not in self.choices:
            opts = ", ".join(repr(c) for c in self.choices)
            raise ValueError(f"{field_name}: must be one of {opts}, got {value!r}")
        if self.check is not None:
            v = self.check(field_name, v)
        return v


@dataclass(frozen=True)
class Component:
    """A registered building block.

    ``build(**params, **context)`` makes the object; ``context`` holds what
    the kind needs beyond the TOML values (a filter gets the scenario).
    ``target`` is the class it builds (``build`` itself when that is a
    class): the class its parameters are checked against.
    """

    kind: str
    name: str
    summary: str
    params: tuple[Param, ...]
    build: Callable[..., Any]
    aliases: tuple[str, ...] = field(default_factory=tuple)
    target: Type[Any] | None = None

    def param(self, name: str) -> Param | None:
        """The parameter called ``name``, if any."""
        for p in self.params:
            if p.name == name:
                return p
        return None

    def resolve(self, values: dict[str, Any], where: str) -> dict[str, Any]:
        """Check a table of values against the parameters; returns converted values with defaults.

        ``where`` prefixes field names in errors (``"filters[2]"``).
        """
        known = {p.name for p in self.params}
        for key in values:
            if key not in known:
                hint = ", ".join(sorted(known)) or "none"
                raise ValueError(f"{where}.{key}: unknown key for {self.kind} '{self.name}' (known: {hint})")
        out: dict[str, Any] = {}
        for p in self.params:
            field_name = f"{where}.{p.name}"
            if p.name in values:
                out[p.name] = p.convert(field_name, values[p.name])
            elif p.default is REQUIRED:
                raise ValueError(f"{field_name}: required for {self.kind} '{self.name}'")
            else:
                out[p.name] = p.default
        return out


_REGISTRY: dict[str, dict[str, Component]] = {k: {} for k in KINDS}
_ORIGIN: dict[tuple[str, str], str] = {}  # (kind, name or alias) -> the module that registered it
_loaded = False


def register(
    kind: str,
    name: str,
    summary: str,
    params: Sequence[Param] = (),
    aliases: Sequence[str] = (),
    target: Type[Any] | None = None,
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator registering ``build`` as component ``name`` of ``kind``.

    ``target`` names the class that ``build`` makes when ``build`` is a
    function (a class registered directly is its own target).
    """
    if kind not in KINDS:
        raise ValueError(f"unknown component kind {kind!r}")
    module = sys._getframe(1).f_globals.get("__name__", "")  # the registering module, for the lazy index

    def deco(build: Callable[..., Any]) -> Callable[..., Any]:
        cls = target if target is not None else (build if isinstance(build, type) else None)
        comp = Component(kind, name, summary, tuple(params), build, tuple(aliases), cls)
        table = _REGISTRY[kind]
        for key in (name, *aliases):
            if key in table and table[key].build is not build:
                raise ValueError(f"{kind} {key!r} is registered twice")
            table[key] = comp
            _ORIGIN[(kind, key)] = module
        return build

    return deco


def _load() -> None:
    global _loaded
    if not _loaded:
        _loaded = True
        for package in REGISTERING_PACKAGES:
            for mod in _modules(package):
                importlib.import_module(mod)


def _modules(package: str) -> list[str]:
    """The modules of ``package``, sorted by name (the import order does not matter: names are unique)."""
    pkg = importlib.import_module(package)
    return sorted(f"{package}.{info.name}" for info in pkgutil.iter_modules(pkg.__path__) if not info.ispkg)


def _load_one(kind: str, name: str) -> bool:
    """Import only the module the index names for ``name``; whether ``name`` is registered now."""
    if name in _REGISTRY[kind]:
        return True
    if _loaded:
        return False
    from ._catalog import MODULES

    module = MODULES.get(kind, {}).get(name)
    if module is None:
        return False
    importlib.import_module(module)
    return name in _REGISTRY[kind]


def index() -> dict[str, dict[str, str]]:
    """The module that registers each component name (and alias), by kind: what :func:`get` imports."""
    _load()
    return {kind: {key: _ORIGIN[(kind, key)] for key in sorted(_REGISTRY[kind])} for kind in KINDS}


def get(kind: str, name: str, where: str = "") -> Component:
    """Look up a component; raises ``ValueError`` naming the field when unknown.

    A known name imports only its module (:data:`pursuit._catalog.MODULES`);
    an unknown one imports every module first, so the error lists every name.
    """
    if not (isinstance(name, str) and kind in _REGISTRY and _load_one(kind, name)):
        _load()
    table = _REGISTRY[kind]
    if not isinstance(name, str) or name not in table:
        prefix = f"{where}: " if where else ""
        known = ", ".join(sorted({c.name for c in table.values()}))
        raise ValueError(f"{prefix}unknown {kind} {name!r} (known: {known})")
    return table[name]


def components(kind: str) -> list[Component]:
    """Registered components of a kind, without alias duplicates, sorted by name."""
    _load()
    seen: dict[str, Component] = {}
    for comp in _REGISTRY[kind].values():
        seen[comp.name] = comp
    return [seen[k] for k in sorted(seen)]


LISTED_KINDS = ("model", "filter", "fading", "scenario", "tracker")
"""The kinds ``pursuit list`` prints from :mod:`pursuit._catalog`."""


def catalog() -> dict[str, list[tuple[str, str]]]:
    """Name and summary of every registered component of :data:`LISTED_KINDS`, sorted by name."""
    return {kind: [(c.name, c.summary) for c in components(kind)] for kind in LISTED_KINDS}


def catalog_source() -> str:
    """The text of ``pursuit/_catalog.py`` for the components registered now.

    ``pursuit list`` prints that file instead of importing every component
    module (NumPy, SciPy, matplotlib and every filter: seconds); a test
    checks it against the registry.  Regenerate it after adding or
    describing a component: ``python -m pursuit.registry > src/pursuit/_catalog.py``.
    """
    lines = [
        '"""Generated by ``python -m pursuit.registry > src/pursuit/_catalog.py``: do not edit.',
        "",
        "What ``pursuit list`` prints without importing the component modules, and the module",
        "that registers each name (:func:`pursuit.registry.get` imports only that one; see",
        ":func:`pursuit.registry.catalog_source`; ``tests/test_registry.py`` and",
        "``tests/test_cli_startup.py`` keep both in step).",
        '"""',
        "",
        "CATALOG: dict[str, list[tuple[str, str]]] = {",
    ]
    for kind, entries in catalog().items():
        lines.append(f"    {kind!r}: [")
        lines += [f"        ({name!r}, {summary!r})," for name, summary in entries]
        lines.append("    ],")
    lines.append("}")
    lines += ["", "MODULES: dict[str, dict[str, str]] = {"]
    for kind, entries in index().items():
        lines.append(f"    {kind!r}: {{")
        lines += [f"        {name!r}: {module!r}," for name, module in entries.items()]
        lines.append("    },")
    lines.append("}")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------
# parameters derived from dataclass fields: a default is written once, in the class
# --------------------------------------------------------------------------
def field_param(
    cls: Type[Any],
    path: str,
    *,
    name: str | None = None,
    doc: str | None = None,
    type: str | None = None,
    choices: Sequence[Any] | None = None,
    check: Callable[[str, Any], Any] | None = None,
) -> Param:
    """A :class:`Param` whose default, type, choices and doc come from a dataclass field.

    Parameters
    ----------
    cls
        The dataclass.
    path
        The field, or ``"field.subfield"`` for a field of the dataclass
        held in a field's default (``"search.alpha_max"`` of
        :class:`~pursuit.filters.cuckoo.ICSPF` is ``alpha_max`` of its
        default :class:`~pursuit.filters.cuckoo.CuckooSearch`).
    name
        The TOML key (default: the last part of ``path``).
    doc
        The line for ``pursuit list``; default: ``metadata["doc"]`` of the
        field, else the field's entry in the numpy docstring's Parameters or
        Attributes section of the class that declares it.
    type
        The TOML type when the annotation does not tell (``"matrix"`` for an
        array); default from the annotation (``float | None`` is
        ``"float"``, a ``Literal`` is ``"str"`` with its choices).
    choices, check
        As in :class:`Param`; ``choices`` default to ``metadata["choices"]``
        or the ``Literal``'s values.
    """
    owner, fld, default = _resolve_field(cls, path)
    derived_type, derived_choices = toml_type(fld.type)
    if hasattr(default, "tolist"):  # an array default reads (and prints) as the TOML list it stands for
        default = default.tolist()
    elif isinstance(default, tuple) and (type or derived_type) in ("vector", "matrix"):
        default = list(default)
    if choices is None:
        choices = fld.metadata.get("choices", derived_choices)
    if doc is None:
        doc = fld.metadata.get("doc") or _docstring_entries(owner).get(fld.name, "")
    return Param(
        name or fld.name,
        type or derived_type,
        default,
        doc,
        check,
        tuple(choices) if choices is not None else None,
        source=(cls, path),
    )


def params_from(
    cls: Type[Any],
    fields: Sequence[str] | None = None,
    *,
    exclude: Sequence[str] = (),
    rename: dict[str, str] | None = None,
    docs: dict[str, str] | None = None,
    types: dict[str, str] | None = None,
    choices: dict[str, Sequence[Any]] | None = None,
    checks: dict[str, Callable[[str, Any], Any]] | None = None,
) -> tuple[Param, ...]:
    """:func:`field_param` for several fields of ``cls``, in order.

    ``fields`` are field paths (default: every ``init`` field of ``cls`` in
    declaration order, less ``exclude``); ``rename`` maps a path to its TOML
    key; ``docs``, ``types``, ``choices`` and ``checks`` are keyed by TOML key.
    """
    rename, docs, types, choices, checks = rename or {}, docs or {}, types or {}, choices or {}, checks or {}
    if fields is None:
        fields = [f.name for f in dataclasses.fields(cls) if f.init]
    out = []
    for path in fields:
        if path in exclude:
            continue
        key = rename.get(path, path.rsplit(".", 1)[-1])
        out.append(
            field_param(cls, path, name=key, doc=docs.get(key), type=types.get(key), choices=choices.get(key), check=checks.get(key))
        )
    return tuple(out)


def field_default(cls: Type[Any], path: str) -> Any:
    """The default of a field path of a dataclass (:data:`REQUIRED` when it has none)."""
    return _resolve_field(cls, path)[2]


def field_annotation(cls: Type[Any], path: str) -> Any:
    """The annotation of a field path of a dataclass (a string under ``from __future__ import annotations``)."""
    return _resolve_field(cls, path)[1].type


def _resolve_field(cls: Type[Any], path: str) -> tuple[Type[Any], dataclasses.Field, Any]:
    """``(class declaring the last field, that field, its default)`` for a dotted field path."""
    owner: Any = cls
    holder: Any = None  # the default instance the current part is read from (after the first part)
    parts = path.split(".")
    for i, part in enumerate(parts):
        if not dataclasses.is_dataclass(owner):
            raise TypeError(f"{cls.__name__}.{'.'.join(parts[:i])} is not a dataclass")
        by_name = {f.name: f for f in dataclasses.fields(owner)}
        if part not in by_name or not by_name[part].init:
            raise TypeError(f"{cls.__name__} has no init field {'.'.join(parts[: i + 1])!r}")
        fld = by_name[part]
        if holder is not None:  # a field of the parent's default instance: its value is this path's default
            default = getattr(holder, part)
        elif fld.default is not dataclasses.MISSING:
            default = fld.default
        elif fld.default_factory is not dataclasses.MISSING:
            default = fld.default_factory()
        else:
            default = REQUIRED
        declaring = next((c for c in owner.__mro__ if part in c.__dict__.get("__annotations__", {})), owner)
        if i < len(parts) - 1:
            if default is REQUIRED or default is None:
                raise TypeError(f"{cls.__name__}.{'.'.join(parts[: i + 1])} has no default to read {path!r} from")
            owner, holder = type(default), default
    return declaring, fld, default


_SIMPLE = {"int": "int", "float": "float", "bool": "bool", "str": "str", "dict": "table"}
_ARRAYS = ("np.ndarray", "ndarray", "NDArray", "tuple[", "list[", "Sequence[")


def toml_type(annotation: Any) -> tuple[str, tuple[Any, ...] | None]:
    """The TOML type (and choices) an annotation stands for: ``float | None`` -> ``("float", None)``.

    A ``Literal`` of strings is ``"str"`` with its values as choices; an
    array, tuple or list is ``"vector"``; anything else ``"any"``.
    """
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", str(annotation))
    parts = [p.strip() for p in _split_union(text) if p.strip() not in ("None", "NoneType")]
    if len(parts) != 1:
        return "any", None
    a = parts[0]
    for prefix in ("Literal[", "typing.Literal["):
        if a.startswith(prefix) and a.endswith("]"):
            values = ast.literal_eval(f"({a[len(prefix):-1]},)")
            return ("str" if all(isinstance(v, str) for v in values) else "any"), tuple(values)
    if a in _SIMPLE:
        return _SIMPLE[a], None
    if a.startswith(_ARRAYS) or a in _ARRAYS:
        return "vector", None
    return "any", None


def _split_union(text: str) -> list[str]:
    """``a | b[c | d]`` -> ``["a ", " b[c | d]"]``: split on ``|`` outside brackets."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        depth += ch == "["
        depth -= ch == "]"
        if ch == "|" and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return [*parts, cur]


def _docstring_entries(cls: Type[Any]) -> dict[str, str]:
    """First sentence of each entry of the numpy docstring's Parameters / Attributes sections."""
    lines = (inspect.getdoc(cls) or "").splitlines()
    out: dict[str, str] = {}
    in_section = False
    names: list[str] = []
    text: list[str] = []

    def flush() -> None:
        sentence = " ".join(text).split(". ")[0].strip().rstrip(".")
        for n in names:
            out.setdefault(n, sentence)

    for i, line in enumerate(lines):
        if i + 1 < len(lines) and lines[i + 1].strip() and set(lines[i + 1].strip()) == {"-"}:
            flush()
            names, text = [], []
            in_section = line.strip() in ("Parameters", "Attributes", "Other Parameters")
            continue
        if not in_section or set(line.strip()) == {"-"}:
            continue
        if line and not line.startswith(" "):
            flush()
            names, text = [n.strip() for n in line.split(":")[0].split(",")], []
        elif line.strip():
            text.append(line.strip())
        elif text:  # a blank line ends the entry's first paragraph
            flush()
            names, text = [], []
    flush()
    return out


# --------------------------------------------------------------------------
# TOML type checks
# --------------------------------------------------------------------------
def _float(field_name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{field_name}: expected a number, got {_show(v)}")
    f = float(v)
    if not math.isfinite(f):
        raise ValueError(f"{field_name}: must be finite, got {v!r}")
    return f


def _int(field_name: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ValueError(f"{field_name}: expected an integer, got {_show(v)}")
    return int(v)


def _bool(field_name: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ValueError(f"{field_name}: expected true or false, got {_show(v)}")
    return v


def _str(field_name: str, v: Any) -> str:
    if not isinstance(v, str):
        raise ValueError(f"{field_name}: expected a string, got {_show(v)}")
    return v


def _vector(field_name: str, v: Any) -> np.ndarray:
    import numpy as np  # here, not at the top: `pursuit list` reads the registry module without NumPy

    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise ValueError(f"{field_name}: expected a list of numbers, got {_show(v)}")
    arr = np.array(v, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{field_name}: must be finite")
    return arr


def _matrix(field_name: str, v: Any) -> np.ndarray:
    import numpy as np

    """A matrix as a list of rows; a number or a flat list is accepted for diagonal covariances."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return np.array(float(v))
    if isinstance(v, list) and v and all(isinstance(r, list) for r in v):
        rows = [_vector(f"{field_name}[{i}]", r) for i, r in enumerate(v)]
        if len({len(r) for r in rows}) != 1:
            raise ValueError(f"{field_name}: rows have different lengths")
        return np.array(rows)
    return _vector(field_name, v)


def _table(field_name: str, v: Any) -> dict:
    if not isinstance(v, dict):
        raise ValueError(f"{field_name}: expected a table, got {_show(v)}")
    return v


def _any(field_name: str, v: Any) -> Any:
    return v


_TYPE_CHECKS: dict[str, Callable[[str, Any], Any]] = {
    "float": _float,
    "int": _int,
    "bool": _bool,
    "str": _str,
    "vector": _vector,
    "matrix": _matrix,
    "table": _table,
    "any": _any,
}


def _show(v: Any) -> str:
    kind = {str: "a string", bool: "a boolean", list: "a list", dict: "a table", int: "an integer", float: "a number"}
    return f"{kind.get(type(v), type(v).__name__)} ({v!r})" if not isinstance(v, (list, dict)) else kind[type(v)]


if __name__ == "__main__":  # pragma: no cover - the catalog's generator
    # components register in the imported module pursuit.registry, not in this __main__ copy
    from pursuit.registry import catalog_source as _source

    print(_source(), end="")
