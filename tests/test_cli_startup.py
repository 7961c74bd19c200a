"""Start-up of ``pursuit track``: the registry imports only the modules of the components a model names.

The index of which module registers which name is a static table
(:data:`pursuit._catalog.MODULES`, generated with the catalog); these tests
keep it in step with the modules, and check in fresh interpreters that a
look-up imports no more than it needs while an unknown name still lists
every known one.
"""

from __future__ import annotations

import subprocess
import sys

from pursuit import registry
from pursuit._catalog import CATALOG, MODULES


def test_the_module_index_is_the_registry():
    # After adding a component: python -m pursuit.registry > src/pursuit/_catalog.py
    assert MODULES == registry.index()
    assert set(MODULES) == set(registry.KINDS)


def test_the_module_index_source_round_trips():
    namespace: dict = {}
    exec(registry.catalog_source(), namespace)
    assert namespace["MODULES"] == registry.index()


def _fresh(code: str) -> list[str]:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def test_a_known_filter_imports_its_module_only():
    out = _fresh(
        "import sys; from pursuit import registry\n"
        "comp = registry.get('filter', 'kf', 'filter.type')\n"
        "print(comp.name)\n"
        "print(sorted(m for m in sys.modules if m.startswith(('pursuit.config.', 'pursuit.experiments.'))))\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'matplotlib', 'numba'}))\n"
    )
    assert out[0] == "kf"
    assert out[1] == str([MODULES["filter"]["kf"]])
    assert out[2] == "[]"


def test_an_unknown_name_still_lists_every_known_one():
    out = _fresh(
        "from pursuit import registry\n"
        "try:\n"
        "    registry.get('filter', 'kalman', 'filter.type')\n"
        "except ValueError as e:\n"
        "    print(e)\n"
    )
    names = ", ".join(sorted(n for n, _ in CATALOG["filter"]))
    assert out == [f"filter.type: unknown filter 'kalman' (known: {names})"]


def test_every_indexed_name_is_registered_by_its_module():
    # each module on its own, in a fresh interpreter per module: importing it registers every name it is given for
    by_module: dict[str, list[tuple[str, str]]] = {}
    for kind, entries in MODULES.items():
        for name, module in entries.items():
            by_module.setdefault(module, []).append((kind, name))
    code = (
        "import importlib, sys\nfrom pursuit import registry\n"
        "importlib.import_module(sys.argv[1])\n"
        "pairs = [p.split(':', 1) for p in sys.argv[2:]]\n"
        "print(all(n in registry._REGISTRY[k] for k, n in pairs))\n"
    )
    for module, pairs in sorted(by_module.items()):
        done = subprocess.run(
            [sys.executable, "-c", code, module, *(f"{k}:{n}" for k, n in pairs)], capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "True", module
