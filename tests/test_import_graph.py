"""The import graph of src/pursuit has no cycles, and only the compute seam reaches the compiled side.

The graph is built from the source with :mod:`ast`, not by importing:
module-level and function-level imports alike (a lazy import inside a
function is still a dependency), relative imports resolved, and
``from package import submodule`` counted as an edge to the submodule.
Loading by name with :mod:`importlib` (the seam, :mod:`pursuit.compute`) is
not an import statement and is not an edge: that is what keeps the compiled
side a leaf.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "pursuit"
COMPILED = "pursuit._compiled"
SEAM = "pursuit.compute"
"""The one module allowed to name the compiled side (it loads it with importlib)."""


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(node: ast.AST, module: str, is_package: bool, modules: dict[str, Path]) -> list[tuple[str, str]]:
    """``(package module, imported name)`` for each name one import statement imports."""
    if isinstance(node, ast.Import):
        pairs = [(alias.name, alias.name) for alias in node.names]
    elif isinstance(node, ast.ImportFrom):
        if node.level:
            base = module.split(".") if is_package else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            origin = ".".join(base + ([node.module] if node.module else []))
        else:
            origin = node.module or ""
        # ``from pkg import sub`` depends on pkg.sub when that is a module, else on pkg itself
        pairs = [(f"{origin}.{a.name}" if f"{origin}.{a.name}" in modules else origin, a.name) for a in node.names]
    else:
        return []
    out = []
    for target, name in pairs:
        while target and target not in modules:  # ``import pkg.sub.attr``, or a module outside the package
            target = target.rpartition(".")[0]
        if target:
            out.append((target, name))
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports (anywhere in its body)."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            for target, _ in _imports(node, module, is_package, modules):
                if target != module:
                    graph[module].add(target)
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_graph_sees_lazy_and_relative_imports():
    """The builder itself: a function-level relative import and ``from pkg import submodule`` are edges."""
    graph = import_graph()
    assert "pursuit.filters.gaussian" in graph["pursuit.filters"]  # from .gaussian import ...
    assert "pursuit._compiled.specs" in graph["pursuit._compiled.particle"]  # from .specs import ...
    assert "pursuit._compiled.gauss_kernels" in graph["pursuit._compiled.gaussian"]  # from . import gauss_kernels


def test_no_import_cycles():
    cycles = strongly_connected(import_graph())
    assert not cycles, "import cycles in src/pursuit:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_only_the_seam_imports_the_compiled_side():
    """Outside pursuit._compiled nothing imports it, except the seam (pursuit.compute), which loads it by name."""
    graph = import_graph()
    offenders = sorted(
        f"{module} imports {target}"
        for module, targets in graph.items()
        if not (module == COMPILED or module.startswith(COMPILED + ".")) and module != SEAM
        for target in targets
        if target == COMPILED or target.startswith(COMPILED + ".")
    )
    assert not offenders, "\n".join(offenders)


def test_compiled_side_uses_public_filter_api():
    """pursuit._compiled imports no underscore name from the filter layer and does not run the engine."""
    modules = _modules()
    offenders = []
    for module, path in modules.items():
        if not module.startswith(COMPILED + "."):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            for target, name in _imports(node, module, False, modules):
                if target.startswith(f"{PACKAGE}.filters") and (name.startswith("_") or "._" in target):
                    offenders.append(f"{module}: from {target} import {name}")
                if target.startswith(f"{PACKAGE}.engine"):
                    offenders.append(f"{module}: imports {target}")
    assert not offenders, "\n".join(offenders)


def test_compiled_glue_reads_no_private_filter_attribute():
    """The glue gets a filter as ``filt``: it reads only its public attributes (no ``filt._weights``)."""
    offenders = []
    for module, path in _modules().items():
        if not module.startswith(COMPILED + "."):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "filt":
                if node.attr.startswith("_"):
                    offenders.append(f"{module}:{node.lineno}: filt.{node.attr}")
    assert not offenders, "\n".join(offenders)
