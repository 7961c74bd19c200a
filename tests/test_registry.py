"""The registry's catalog, which `pursuit list` prints without importing the components."""

import re
import subprocess
import sys

from pursuit import registry
from pursuit._catalog import CATALOG


def test_the_catalog_is_the_registry():
    # After adding or describing a component: python -m pursuit.registry > src/pursuit/_catalog.py
    assert CATALOG == registry.catalog()


def test_the_catalog_source_round_trips():
    namespace: dict = {}
    exec(registry.catalog_source(), namespace)
    assert namespace["CATALOG"] == registry.catalog()


def test_summaries_speak_to_a_user_not_of_internal_document_numbers():
    # "paper P4", "patent P3", "spec 04" mean nothing to a user of `pursuit list`
    internal = re.compile(r"\b(paper|patent|spec)\s+(P\d|\d)|\bP\d['’]s\b|\(P\d\)")
    for kind, entries in registry.catalog().items():
        for name, summary in entries:
            assert not internal.search(summary), (kind, name, summary)
        for comp in registry.components(kind):
            for p in comp.params:
                assert not internal.search(p.doc), (kind, comp.name, p.name, p.doc)


def test_importing_pursuit_and_listing_load_no_numerical_library():
    code = (
        "import sys, pursuit; from pursuit.cli import main; main(['list']); "
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'scipy', 'matplotlib', 'numba', 'dask'}))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "[]"  # every import of these took 3.3 s of `pursuit list`
    assert "ics-pf" in done.stdout and "wsn-gaussian" in done.stdout


def test_import_pursuit_still_reaches_every_public_name_and_subpackage():
    code = (
        "import pursuit as pu; "
        "names = [getattr(pu, n) for n in pu.__all__]; "
        "print(pu.scenarios.WSNRange.__name__, pu.filters.GaussianState.__name__, pu.KalmanFilter.__module__); "
        "print(hasattr(pu, 'no_such_name'))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["WSNRange", "GaussianState", "pursuit.filters.gaussian", "False"]


# --------------------------------------------------------------------------
# every registered component against its class: a default is written once
# --------------------------------------------------------------------------
import dataclasses  # noqa: E402
import inspect  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

_COMPATIBLE = {  # TOML type of a Param -> TOML types of the annotations it may set
    "float": {"float"},
    "int": {"int"},
    "bool": {"bool"},
    "str": {"str"},
    "vector": {"vector"},
    "matrix": {"vector"},
    "table": {"table"},
    "any": set(),
}


def _same(a, b) -> bool:
    """Equal defaults: arrays, lists and tuples by value (a TOML list stands for a tuple or an array)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b if isinstance(a, (bool, int, float)) and isinstance(b, (bool, int, float)) else a == b


def _where(p: registry.Param, comp: registry.Component) -> tuple[type, str] | None:
    """The class field a parameter sets: its derived source, else the target's field of that name."""
    if p.source is not None:
        return p.source
    if p.own or comp.target is None:
        return None
    return comp.target, p.name


def _all_components():
    return [c for kind in registry.KINDS if kind != "experiment" for c in registry.components(kind)]


def test_every_component_but_the_experiment_kinds_names_its_class():
    for comp in _all_components():
        assert isinstance(comp.target, type), (comp.kind, comp.name)


@pytest.mark.parametrize("comp", _all_components(), ids=lambda c: f"{c.kind}:{c.name}")
def test_each_parameter_agrees_with_the_class_field_it_sets(comp):
    for p in comp.params:
        where = _where(p, comp)
        if where is None:
            continue
        cls, path = where
        # nothing is registered that the class would refuse: a parameter that is no field is marked own=True
        try:
            default = registry.field_default(cls, path)
        except TypeError as e:
            pytest.fail(f"{comp.kind} {comp.name}: parameter {p.name!r} is no field of {cls.__name__} ({e}); mark it own=True")
        # the Param's default is the class's (converted as a TOML value would be: 1.0 -> Constant(1.0))
        value = p.default
        if value is not None and value is not registry.REQUIRED and p.check is not None:
            value = p.convert(f"{comp.name}.{p.name}", value)
        assert _same(value, default), f"{comp.kind} {comp.name}: {p.name} = {p.default!r} but {cls.__name__}.{path} = {default!r}"
        # the TOML type fits the annotation, and the choices are ones the annotation allows
        ann_type, ann_choices = registry.toml_type(registry.field_annotation(cls, path))
        if ann_type != "any" and p.type != "any":
            assert ann_type in _COMPATIBLE[p.type], f"{comp.kind} {comp.name}: {p.name} is {p.type}, {cls.__name__}.{path} is {ann_type}"
        if ann_choices is not None:
            assert p.choices is not None and set(p.choices) <= set(ann_choices), (comp.name, p.name, p.choices, ann_choices)
        if p.choices is not None and p.default not in (None, registry.REQUIRED):
            assert p.default in p.choices, (comp.name, p.name)


@pytest.mark.parametrize("comp", [c for c in _all_components() if c.params], ids=lambda c: f"{c.kind}:{c.name}")
def test_every_parameter_is_documented_for_pursuit_list(comp):
    for p in comp.params:
        assert p.doc.strip(), (comp.kind, comp.name, p.name)


@dataclasses.dataclass
class _Search:
    """A nested part.

    Parameters
    ----------
    step : float
        The step size. Longer text follows.
    """

    step: float = 0.5
    mode: "Literal['a', 'b'] | None" = "a"  # noqa: F821


@dataclasses.dataclass
class _Filter:
    particles: int = 100
    grid: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2), metadata={"doc": "the grid"})
    search: _Search = dataclasses.field(default_factory=lambda: _Search(step=0.25))


def test_params_from_reads_defaults_types_choices_and_docs_from_the_fields():
    particles, grid, step, mode = registry.params_from(
        _Filter, ["particles", "grid", "search.step", "search.mode"], rename={"search.step": "alpha"}
    )
    assert (particles.name, particles.type, particles.default, particles.source) == ("particles", "int", 100, (_Filter, "particles"))
    assert (grid.type, grid.default, grid.doc) == ("vector", [0.0, 0.0], "the grid")
    # a nested field's default is the one of the parent's default instance, not of its class
    assert (step.name, step.type, step.default, step.doc) == ("alpha", "float", 0.25, "The step size")
    assert (mode.type, mode.choices, mode.default) == ("str", ("a", "b"), "a")
    with pytest.raises(TypeError, match="no init field"):
        registry.field_param(_Filter, "nope")


def test_registry_finds_its_modules_without_a_list():
    assert not hasattr(registry, "_COMPONENT_MODULES")
    mods = {m for pkg in registry.REGISTERING_PACKAGES for m in registry._modules(pkg)}
    assert {"pursuit.config.filters", "pursuit.experiments.montecarlo"} <= mods
    assert inspect.ismodule(__import__("pursuit.config.build"))
