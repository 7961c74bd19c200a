"""Compute-backend selection (no numba needed): defaults, bad names, the missing-numba error, imports without numba."""

import subprocess
import sys

import pytest

import pursuit as pu
from pursuit import compute
from pursuit.models import ConstantVelocity, LinearGaussian


@pytest.fixture(autouse=True)
def _clean_default(monkeypatch):
    monkeypatch.delenv(compute.ENV_VAR, raising=False)
    compute.set_default_backend(None)
    yield
    compute.set_default_backend(None)


def _models():
    mot = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
    return mot, LinearGaussian.position(4, (0, 2), 1.0)


def test_default_is_numpy_and_resolved_at_construction():
    f = pu.KalmanFilter(*_models())
    assert f.backend == "numpy" and not f.compiled
    pf = pu.BootstrapParticleFilter(*_models(), particles=10)
    assert pf.backend == "numpy" and not pf.compiled


def test_environment_and_process_default(monkeypatch):
    monkeypatch.setenv(compute.ENV_VAR, "numpy")
    assert compute.default_backend() == "numpy"
    monkeypatch.setenv(compute.ENV_VAR, "fortran")
    with pytest.raises(ValueError, match="PURSUIT_COMPUTE_BACKEND"):
        compute.default_backend()
    compute.set_default_backend("numpy")  # the process default wins over the environment
    assert compute.default_backend() == "numpy"


def test_unknown_backend_names_the_field():
    with pytest.raises(ValueError, match="backend: must be one of 'numpy', 'numba'"):
        pu.KalmanFilter(*_models(), backend="cuda")


def test_numba_without_numba_is_a_clear_import_error(monkeypatch):
    monkeypatch.setattr(compute, "numba_available", lambda: False)
    with pytest.raises(ImportError, match=r"pursuit\[fast\]"):
        pu.UnscentedKalmanFilter(*_models(), backend="numba")
    with pytest.raises(ImportError, match=r"pursuit\[fast\]"):
        pu.ICSPF(*_models(), particles=10, backend="numba")


def test_config_backend_parameter_is_checked():
    from pursuit import registry

    comp = registry.get("filter", "pf", "filters[0].type")
    with pytest.raises(ValueError, match="filters\\[0\\].backend: must be one of"):
        comp.resolve({"backend": "gpu"}, "filters[0]")
    assert comp.resolve({"backend": "numpy"}, "filters[0]")["backend"] == "numpy"


def test_pursuit_works_without_numba_installed():
    """A subprocess where importing numba fails runs filters with NumPy and refuses 'numba' clearly."""
    code = r"""
import sys, importlib.abc
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "numba" or name.startswith("numba."):
            raise ImportError("numba blocked for this test")
sys.meta_path.insert(0, Block())
import numpy as np, pursuit as pu
from pursuit.models import ConstantVelocity, LinearGaussian
mot = ConstantVelocity(ndim=2, dt=1.0, q=0.01); meas = LinearGaussian.position(4, (0, 2), 1.0)
zs = np.random.default_rng(0).standard_normal((5, 3, 2))
tr = pu.run(pu.BootstrapParticleFilter(mot, meas, particles=50), zs, pu.Gaussian(np.zeros(4), np.eye(4)), rng=1)
assert np.isfinite(tr.mean).all()
import pursuit.compute as c
c.numba_available = lambda: False
try:
    pu.KalmanFilter(mot, meas, backend="numba")
except ImportError as e:
    print("refused:", e)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "refused: backend: 'numba' needs numba" in proc.stdout
