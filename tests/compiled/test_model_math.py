"""The compiled model maths (pursuit._compiled.model_math) against the NumPy models, for every registered model.

Every measurement model registered in ``specs.MEASUREMENTS`` must have an
example here (the first test fails otherwise), so a new compiled sensor is
checked against its NumPy ``h`` and ``jacobian`` as soon as it is registered.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

from numba import njit  # noqa: E402

from pursuit._compiled import specs  # noqa: E402
from pursuit._compiled.kernel_args import Motion, Sensor  # noqa: E402
from pursuit._compiled.model_math import h_row, jac_row, propagate_row  # noqa: E402
from pursuit.models import (  # noqa: E402
    ConstantAcceleration,
    ConstantVelocity,
    LinearGaussian,
    LinearMotion,
    RangeBearing,
    RangeSensors,
    TimeOfArrival,
)
from pursuit.models.ungm import UNGMMeasurement, UNGMMotion  # noqa: E402

SENSORS = {
    LinearGaussian: (LinearGaussian.position(4, (0, 2), 1.0), 4),
    RangeSensors: (RangeSensors([[0.0, 0.0], [100.0, 0.0], [50.0, 80.0]], 2.0, (0, 2)), 4),
    TimeOfArrival: (TimeOfArrival([[0.0, 0.0], [100.0, 0.0]], 0.01, (0, 2), c=3.0), 4),
    RangeBearing: (RangeBearing([0.0, -50.0], 1.0, 0.02), 4),
    UNGMMeasurement: (UNGMMeasurement(r=1.0, scale=20.0), 1),
}
MOTIONS = {
    ConstantVelocity: ConstantVelocity(ndim=2, dt=1.0, q=0.01),
    ConstantAcceleration: ConstantAcceleration(ndim=1, dt=0.5, q=0.1),
    LinearMotion: LinearMotion(np.array([[1.0, 0.5], [0.0, 0.9]]), 0.2 * np.eye(2)),
    UNGMMotion: UNGMMotion(),
}


@njit(cache=True)
def _h_all(sensor, X, out):
    for i in range(X.shape[0]):
        h_row(sensor, X, i, out, i)


@njit(cache=True)
def _jac_all(sensor, X, H):
    for i in range(X.shape[0]):
        jac_row(sensor, X, i, H, i)


@njit(cache=True)
def _propagate_all(motion, X, noise, out):
    for i in range(X.shape[0]):
        propagate_row(motion, X, i, noise, out, i)


def test_every_registered_model_has_an_example_here():
    assert set(SENSORS) == set(specs.MEASUREMENTS)
    assert set(MOTIONS) == set(specs.MOTIONS)


@pytest.mark.parametrize("cls", sorted(SENSORS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
def test_h_and_jacobian_match_the_numpy_model(cls):
    model, n = SENSORS[cls]
    spec = specs.measurement_spec(model)
    assert not isinstance(spec, str), spec
    sensor = spec.kernel_args()
    assert isinstance(sensor, Sensor)
    X = np.random.default_rng(0).normal(20.0, 15.0, (64, n))
    out = np.full((64, model.dim), np.nan)
    _h_all(sensor, X, out)
    np.testing.assert_allclose(out, model.h(X), rtol=1e-13, atol=0.0)
    H = np.full((64, model.dim, n), np.nan)
    _jac_all(sensor, X, H)
    np.testing.assert_allclose(H, np.broadcast_to(model.jacobian(X), H.shape), rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize("cls", sorted(MOTIONS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
def test_propagation_matches_the_numpy_model(cls):
    model = MOTIONS[cls]
    spec = specs.motion_spec(model)
    assert not isinstance(spec, str), spec
    motion = spec.kernel_args(3, None)
    assert isinstance(motion, Motion)
    n = model.dim
    X = np.random.default_rng(1).normal(0.0, 3.0, (32, n))
    out = np.empty_like(X)
    _propagate_all(motion, X, np.zeros(32 * motion.G.shape[1]), out)  # noise-free: the transition itself
    np.testing.assert_allclose(out, model.f(X, 3), rtol=1e-13, atol=1e-12)


def test_a_sensor_code_without_its_branch_gives_nan_not_another_sensors_formula():
    from pursuit._compiled.model_math import h_point, jac_point

    unknown = max(specs.M_LINEAR, specs.M_RANGE, specs.M_RANGE_BEARING, specs.M_UNGM) + 1
    A = np.array([[0.0, 0.0], [10.0, 0.0]])
    idx = np.array([0, 1])
    X = np.array([[3.0, 4.0]])
    out = np.zeros((1, 2))
    H = np.zeros((1, 2, 2))
    h_point(unknown, A, idx, 1.0, X, 0, out, 0)
    jac_point(unknown, A, idx, 1.0, X, 0, H, 0)
    assert np.isnan(out).all() and np.isnan(H).all()
    h_point(specs.M_RANGE, A, idx, 1.0, X, 0, out, 0)  # the same arguments do reach a real branch
    assert np.allclose(out, [[5.0, np.hypot(7.0, 4.0)]])
