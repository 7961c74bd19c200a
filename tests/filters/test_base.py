"""The common filter base: keyword-only name and backend, one backend selection, batch from the prior."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import pursuit as pu
from pursuit import compute
from pursuit.filters import (
    CSPF,
    AdaptiveCSFilter,
    CurrentStatisticalFilter,
    FilterBase,
    InteractingMultipleModel,
    ModifiedSingerFilter,
    PartialUPF,
)
from pursuit.filters.base import prior_batch
from pursuit.models import ConstantVelocity, LinearGaussian

CV = ConstantVelocity(ndim=2, dt=1.0, q=0.1)
POS = LinearGaussian(np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]), np.eye(2))
AXES = LinearGaussian(np.array([[1.0, 0, 0, 0, 0, 0], [0, 0, 0, 1.0, 0, 0]]), np.eye(2))


def _families():
    """One filter of every family, built with models only."""
    return [
        pu.KalmanFilter(CV, POS),
        pu.ExtendedKalmanFilter(CV, POS),
        pu.UnscentedKalmanFilter(CV, POS),
        pu.CubatureKalmanFilter(CV, POS),
        pu.BootstrapParticleFilter(CV, POS, particles=10),
        CSPF(CV, POS, particles=10),
        PartialUPF(CV, POS, particles=10),
        CurrentStatisticalFilter(AXES),
        AdaptiveCSFilter(AXES),
        ModifiedSingerFilter(AXES),
        InteractingMultipleModel([pu.KalmanFilter(CV, POS)]),
    ]


@pytest.mark.parametrize("filt", _families(), ids=lambda f: type(f).__name__)
def test_every_family_derives_from_the_base_with_keyword_only_name_and_backend(filt):
    assert isinstance(filt, FilterBase)
    assert filt.name  # the family's default label
    assert filt.backend == "numpy" and not filt.compiled
    params = filt.__dataclass_fields__
    assert params["name"].kw_only and params["backend"].kw_only


def test_a_positional_name_is_refused():
    with pytest.raises(TypeError):
        pu.ExtendedKalmanFilter(CV, POS, 1.0, "mine")
    assert CurrentStatisticalFilter(AXES, 1.0, 0.01).alpha == 0.01  # the filter's parameters follow the models
    assert pu.ExtendedKalmanFilter(CV, POS, name="mine").name == "mine"


def test_filters_without_a_compiled_path_warn_only_when_numba_is_asked_for(monkeypatch):
    pytest.importorskip("numba")
    monkeypatch.delenv(compute.ENV_VAR, raising=False)
    with pytest.warns(compute.CompiledBackendWarning, match="CurrentStatisticalFilter"):
        assert not CurrentStatisticalFilter(AXES, backend="numba").compiled
    compute.set_default_backend("numba")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            CurrentStatisticalFilter(AXES)
            InteractingMultipleModel([pu.KalmanFilter(CV, POS, backend="numpy")])
    finally:
        compute.set_default_backend(None)


def test_filters_without_a_compiled_path_ignore_a_numba_default_without_numba(monkeypatch):
    """The CS filters and the IMM had no backend before the common base: a process default of numba
    (even with numba missing, or a bad name in the environment) must not stop them being built."""
    monkeypatch.setattr(compute, "numba_available", lambda: False)
    monkeypatch.setenv(compute.ENV_VAR, "numba")
    assert CurrentStatisticalFilter(AXES).backend == "numpy"
    assert InteractingMultipleModel([pu.KalmanFilter(CV, POS, backend="numpy")]).backend == "numpy"
    with pytest.raises(ImportError, match=r"pursuit\[fast\]"):
        CurrentStatisticalFilter(AXES, backend="numba")  # asked for explicitly: the clear error


def test_batch_from_the_prior():
    prior = pu.Gaussian(np.zeros((3, 4)), np.eye(4))
    assert prior_batch(prior) == (3,)
    assert prior_batch(prior, (5,)) == (5,)
    assert prior_batch(pu.Gaussian(np.zeros(4), np.eye(4))) == ()
    for filt in (pu.KalmanFilter(CV, POS), pu.BootstrapParticleFilter(CV, POS, particles=10)):
        assert filt.init(prior, rng=1).batch == (3,)


def test_run_sequence_is_none_without_a_compiled_path():
    filt = pu.KalmanFilter(CV, POS)
    state = filt.init(pu.Gaussian(np.zeros(4), np.eye(4)), batch=(2,))
    assert filt.run_sequence(state, np.zeros((3, 2, 2))) is None
