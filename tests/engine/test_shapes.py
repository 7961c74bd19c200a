"""Wrong sizes given to ``pursuit.run`` or ``step`` are refused by name, for every kind of filter and backend."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import CurrentStatisticalFilter, InteractingMultipleModel
from pursuit.models import ConstantVelocity, LinearGaussian, RangeSensors

MOTION = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
LINEAR = LinearGaussian.position(4, (0, 2), 1.0)
RANGES = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 1.0, (0, 2))
PRIOR = pu.Gaussian(np.array([10.0, 0.5, 40.0, 0.8]), np.eye(4))


def _filters():
    kf = pu.KalmanFilter(MOTION, LINEAR)
    out = {
        "kf": (kf, 2),
        "ekf": (pu.ExtendedKalmanFilter(MOTION, RANGES), 3),
        "ukf": (pu.UnscentedKalmanFilter(MOTION, RANGES), 3),
        "ckf": (pu.CubatureKalmanFilter(MOTION, RANGES), 3),
        "pf": (pu.BootstrapParticleFilter(MOTION, RANGES, particles=20), 3),
        "ics-pf": (pu.ICSPF(MOTION, RANGES, particles=20), 3),
        "upf": (pu.PartialUPF(MOTION, RANGES, particles=20), 3),
        "imm": (InteractingMultipleModel([kf, kf], np.array([[0.9, 0.1], [0.1, 0.9]])), 2),
    }
    try:
        import numba  # noqa: F401
    except ImportError:  # the NumPy cases still run
        return out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pu.compute.CompiledBackendWarning)
        out["ekf-numba"] = (pu.ExtendedKalmanFilter(MOTION, RANGES, backend="numba"), 3)
        out["ukf-numba"] = (pu.UnscentedKalmanFilter(MOTION, RANGES, backend="numba"), 3)
        out["pf-numba"] = (pu.BootstrapParticleFilter(MOTION, RANGES, particles=20, backend="numba"), 3)
    return out


FILTERS = _filters()


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_measurements_with_the_wrong_number_of_components_name_z_and_both_shapes(name):
    filt, m = FILTERS[name]
    zs = np.zeros((4, 5, m + 1))
    with pytest.raises(ValueError, match=rf"^step 1: z: expected shape \(5, {m}\) \(m = {m} components per measurement\), got \(5, {m + 1}\)$"):
        pu.run(filt, zs, PRIOR, rng=1)


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_a_batch_that_does_not_match_the_state_names_both_shapes(name):
    filt, m = FILTERS[name]
    state = filt.init(PRIOR, (5,), rng=1)
    with pytest.raises(ValueError, match=rf"^step 1: z: expected shape \(5, {m}\) for a batch of \(5,\), got \(4, {m}\)$"):
        filt.step(state, np.zeros((4, m)))


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_a_prior_of_the_wrong_size_names_the_motion_model(name):
    filt, m = FILTERS[name]
    with pytest.raises(ValueError, match=r"^prior: expected 4 state components for the ConstantVelocity motion model"):
        pu.run(filt, np.zeros((4, 5, m)), pu.Gaussian(np.zeros(3), np.eye(3)), rng=1)


def test_the_cs_filter_names_its_axes():
    cs = CurrentStatisticalFilter(LinearGaussian.position(6, (0, 3), 1.0))  # 2 axes of [p, v, a]
    state = cs.init(pu.Gaussian(np.zeros(6), np.eye(6)), (5,))
    with pytest.raises(ValueError, match=r"^step 1: z: expected shape \(5, 2\) \(m = 2 components per measurement\), got \(5, 3\)$"):
        cs.step(state, np.zeros((5, 3)))


@pytest.mark.parametrize("dt", [-1.0, 0.0, float("nan")])
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_step_refuses_a_time_step_that_is_not_positive_and_finite(name, dt):
    filt, m = FILTERS[name]
    state = filt.init(PRIOR, (5,), rng=1)
    with pytest.raises(ValueError, match=r"^step 1: dt: must be a finite time step > 0 s"):
        filt.step(state, np.zeros((5, m)), dt=dt)
