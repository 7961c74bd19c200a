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
    ObserverBearings,
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
    # a moving observer (packed per step: its position of step K_STEP), azimuth and elevation
    ObserverBearings: (ObserverBearings([[5.0, -3.0, 1.0], [-40.0, 10.0, 30.0], [7.0, 8.0, -9.0]], [1e-3, 2e-3]), 9),
}
K_STEP = 2  # the step a moving sensor is packed for
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
    k = K_STEP if spec.moving else None
    sensor = spec.kernel_args(k)
    assert isinstance(sensor, Sensor)
    X = np.random.default_rng(0).normal(20.0, 15.0, (64, n))
    out = np.full((64, model.dim), np.nan)
    _h_all(sensor, X, out)
    np.testing.assert_allclose(out, model.h(X, k), rtol=1e-13, atol=0.0)
    H = np.full((64, model.dim, n), np.nan)
    _jac_all(sensor, X, H)
    np.testing.assert_allclose(H, np.broadcast_to(model.jacobian(X, k), H.shape), rtol=1e-13, atol=1e-300)


def test_the_moving_observer_is_packed_per_step():
    """Each step's sensor carries that step's observer position, 2-D and 3-D; without a step it refuses."""
    track = np.array([[0.0, 0.0], [100.0, -50.0]])
    spec = specs.measurement_spec(ObserverBearings(track, 1e-3, position_indices=(0, 2)))
    assert spec.moving and spec.dim == 1
    X = np.array([[300.0, 1.0, 400.0, 2.0]])
    for k in (1, 2):
        out = np.zeros((1, 1))
        _h_all(spec.kernel_args(k), X, out)
        np.testing.assert_allclose(out[0, 0], np.arctan2(400.0 - track[k - 1, 1], 300.0 - track[k - 1, 0]), rtol=1e-14)
    with pytest.raises(ValueError, match="^k:"):
        spec.kernel_args()
    model, n = SENSORS[ObserverBearings]
    X = np.zeros((1, n))
    X[0, 0], X[0, 3], X[0, 6] = 5.0, -3.0, 10.0  # above the observer of step 1: the azimuth is undefined
    H = np.full((1, 2, n), np.nan)
    _jac_all(specs.measurement_spec(model).kernel_args(1), X, H)
    np.testing.assert_array_equal(H, model.jacobian(X, 1))
    assert not H.any()  # zero rows, as the NumPy model
