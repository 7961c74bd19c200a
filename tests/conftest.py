"""Shared test settings, and one compiled-kernel cache for the whole test session."""

import hashlib
import os
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]


def _kernel_cache_dirs() -> dict[str, str]:
    """``NUMBA_CACHE_DIR`` and ``PURSUIT_KERNEL_DIR`` for a test session, keyed by the compiled sources.

    Set here, before anything imports numba, they reach every xdist worker and every subprocess a
    test starts (through the environment): a kernel one process compiled is loaded by the others
    (unless two compile it at the same moment), and ``make test-slow`` and ``make test-avx2-paths``
    start warm.  numba keys a cached kernel on its own file's path and time stamp only, not on the
    functions it calls from other files (a generated linear-KF module calls ``common.fma``, the
    kernels inline ``model_math``): after an edit to one ``pursuit/_compiled`` module, a kernel
    whose own file did not change would load stale machine code.  The folder's name therefore
    carries a hash of every file there, and an edit starts a fresh folder (``make clean`` removes
    them).  A value already in the environment is kept: the caller chose it.
    """
    digest = hashlib.sha256()
    for path in sorted((ROOT / "src" / "pursuit" / "_compiled").glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    base = ROOT / ".test-cache" / digest.hexdigest()[:16]
    return {"NUMBA_CACHE_DIR": str(base / "numba"), "PURSUIT_KERNEL_DIR": str(base / "kernels")}


for _name, _value in _kernel_cache_dirs().items():
    os.environ.setdefault(_name, _value)

settings.register_profile("ci", deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
settings.register_profile("dev", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def rng():
    """A fixed generator so that statistical tests are reproducible."""
    return np.random.default_rng(12345)
