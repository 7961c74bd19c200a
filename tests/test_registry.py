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
