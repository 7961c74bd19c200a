"""Bearing sensors and stacked measurement models."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit._linalg import numerical_jacobian
from pursuit.models import ConstantVelocity, LinearGaussian, RangeSensors, TimeOfArrival
from pursuit.models.sensors import BearingSensors, StackedMeasurement, stack


def test_bearings_and_their_jacobian(rng):
    b = BearingSensors(np.array([[0.0, 0.0], [10.0, -5.0]]), [0.01, 0.02])
    x = rng.normal(0, 20, (7, 4))
    z = b.h(x)
    np.testing.assert_allclose(z[:, 0], np.arctan2(x[:, 2], x[:, 0]))
    np.testing.assert_allclose(z[:, 1], np.arctan2(x[:, 2] + 5.0, x[:, 0] - 10.0))
    np.testing.assert_allclose(b.jacobian(x), numerical_jacobian(b.h, x), rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(np.diag(b.R), [1e-4, 4e-4])
    # on top of a sensor: a zero Jacobian row, not NaN
    assert np.all(np.isfinite(b.jacobian(np.zeros((1, 4)))))


def test_bearing_residuals_wrap():
    b = BearingSensors([0.0, 0.0], 0.01)
    np.testing.assert_allclose(b.residual(np.array([3.1]), np.array([-3.1])), [3.1 + 3.1 - 2 * np.pi])
    s = b.sample(np.array([[-10.0, 0.0, 1e-9, 0.0]]), 1, np.random.default_rng(0))
    assert -np.pi <= s[0, 0] < np.pi


def test_bearing_rejects_bad_parameters():
    with pytest.raises(ValueError, match="sigma"):
        BearingSensors([0.0, 0.0], -1.0)
    with pytest.raises(ValueError, match="sensors"):
        BearingSensors([[0.0, 0.0, 0.0]], 0.1)


def _parts():
    return (
        RangeSensors(np.array([[0.0, 0.0], [100.0, 0.0]]), 1.0),
        BearingSensors([50.0, -20.0], 0.01),
        LinearGaussian.position(4, (0, 2), 2.0),
    )


def test_stacked_model_concatenates_its_parts(rng):
    parts = _parts()
    s = StackedMeasurement(parts)
    x = rng.normal(30, 10, (5, 4))
    assert s.dim == 5 and s.slices == (slice(0, 2), slice(2, 3), slice(3, 5))
    np.testing.assert_allclose(s.h(x), np.concatenate([p.h(x) for p in parts], axis=-1))
    J = s.jacobian(x)
    assert J.shape == (5, 5, 4)
    np.testing.assert_allclose(J, numerical_jacobian(s.h, x), rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(np.diag(s.cov(3)), [1.0, 1.0, 1e-4, 4.0, 4.0])
    a, b = np.array([0.0, 0.0, 3.1, 0.0, 0.0]), np.array([0.0, 0.0, -3.1, 0.0, 0.0])
    np.testing.assert_allclose(s.residual(a, b)[2], 6.2 - 2 * np.pi)
    z = s.sample(x, 1, np.random.default_rng(0))
    assert z.shape == (5, 5)
    # the log-likelihood is the sum over parts, and skips missing blocks
    z[0, 3:] = np.nan
    ll = s.loglik(z, x)
    ref = sum(p.loglik(z[:, sl], x) for p, sl in zip(parts, s.slices))
    np.testing.assert_allclose(ll, ref)


def test_stack_of_one_part_is_the_part_itself():
    p = RangeSensors([[0.0, 0.0]], 1.0)
    assert stack([p]) is p
    assert isinstance(stack(_parts()), StackedMeasurement)
    with pytest.raises(ValueError, match="parts"):
        StackedMeasurement(())
    with pytest.raises(TypeError, match="h\\(\\)"):
        StackedMeasurement((p, object()))


def test_an_ekf_on_stacked_parts_equals_one_on_the_merged_model(rng):
    # Two range parts stacked are the same model as one RangeSensors with both anchors.
    motion = ConstantVelocity(ndim=2, q=0.01)
    a = TimeOfArrival([[0.0, 0.0]], 1e-4)
    b = TimeOfArrival([[0.0, 50.0], [50.0, 0.0]], 1e-4)
    merged = TimeOfArrival(np.array([[0.0, 0.0], [0.0, 50.0], [50.0, 0.0]]), 1e-4)
    x = np.broadcast_to([10.0, 0.5, 20.0, 0.4], (3, 4))
    zs = []
    for k in range(1, 30):
        x = motion.sample(x, k, rng)
        zs.append(merged.sample(x, k, rng))
    zs = np.array(zs)
    zs[5, 1, 2] = np.nan
    prior = pu.Gaussian([10.0, 0.5, 20.0, 0.4], np.eye(4))
    for cls in (pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter):
        one = pu.run(cls(motion, merged), zs, prior)
        two = pu.run(cls(motion, StackedMeasurement((a, b))), zs, prior)
        np.testing.assert_allclose(two.mean, one.mean, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(two.cov, one.cov, rtol=1e-8, atol=1e-14)


# --------------------------------------------------------------------------
# angles from a moving observer
# --------------------------------------------------------------------------
def _observer(K: int, d: int) -> np.ndarray:
    t = np.arange(1, K + 1, dtype=float)
    return np.stack([100.0 * np.sin(t), 50.0 * t, 10.0 * t][:d], axis=1)


@pytest.mark.parametrize("d", [2, 3])
def test_observer_angles_and_their_jacobian(rng, d):
    from pursuit.models import ObserverBearings

    s = ObserverBearings(_observer(5, d), 0.002)
    x = rng.normal(0, 3000, (7, 3 * d))
    for k in (1, 4):
        z = s.h(x, k)
        dp = x[:, [0, 3, 6][:d]] - s.observer[k - 1]
        np.testing.assert_allclose(z[:, 0], np.arctan2(dp[:, 1], dp[:, 0]))
        if d == 3:
            np.testing.assert_allclose(z[:, 1], np.arctan2(dp[:, 2], np.hypot(dp[:, 0], dp[:, 1])))
        np.testing.assert_allclose(s.jacobian(x, k), numerical_jacobian(lambda xs: s.h(xs, k), x), rtol=1e-6, atol=1e-10)
    assert s.dim == d - 1
    np.testing.assert_array_equal(np.diag(s.R), np.full(d - 1, 4e-6))


def test_observer_angles_sample_with_their_noise_and_wrap():
    from pursuit.models import ObserverBearings

    s = ObserverBearings(np.zeros((1, 3)), [0.01, 0.02])
    x = np.array([[-1000.0, 0, 0, 1e-6, 0, 0, 500.0, 0, 0]])
    draws = s.sample(np.repeat(x, 20000, axis=0), 1, np.random.default_rng(4))
    assert np.all((draws[:, 0] >= -np.pi) & (draws[:, 0] < np.pi))  # azimuth near ±π stays wrapped
    res = s.residual(draws, s.h(x, 1))
    # 20000 draws: the standard errors of the standard deviations are 0.5 %; 4 % is far outside chance
    np.testing.assert_allclose(res.std(axis=0), [0.01, 0.02], rtol=0.04)
    np.testing.assert_allclose(res.mean(axis=0), [0.0, 0.0], atol=1e-3)


def test_observer_angles_need_a_step_on_the_track():
    from pursuit.models import ObserverBearings

    s = ObserverBearings(_observer(3, 2), 0.001)
    with pytest.raises(ValueError, match="^k:"):
        s.h(np.zeros(6), None)
    with pytest.raises(ValueError, match="^k:"):
        s.h(np.zeros(6), 4)
    with pytest.raises(ValueError, match="^observer:"):
        ObserverBearings(np.zeros((3, 4)), 0.001)
    with pytest.raises(ValueError, match="^sigma:"):
        ObserverBearings(np.zeros((3, 3)), [0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="^position_indices:"):
        ObserverBearings(np.zeros((3, 3)), 0.1, position_indices=(0, 3))
    with pytest.raises(ValueError, match="position_indices: expected distinct non-negative"):
        ObserverBearings(np.zeros((3, 3)), 0.1, position_indices=(0, 0, 6))
    with pytest.raises(ValueError, match="position_indices: expected distinct non-negative"):
        ObserverBearings(np.zeros((3, 2)), 0.1, position_indices=(-1, 3))


def test_an_ekf_with_observer_angles_and_numba_compiles_and_agrees_with_numpy():
    # The moving observer is packed into the kernels' sensor per step: no fallback, the NumPy answer.
    import warnings

    pytest.importorskip("numba")
    from pursuit.compute import CompiledBackendWarning
    from pursuit.models import ConstantAcceleration, ObserverBearings

    sensor = ObserverBearings(_observer(4, 2), 0.001)
    motion = ConstantAcceleration(ndim=2, q=1.0, layout="axis")  # a motion model that compiles
    with warnings.catch_warnings():
        warnings.simplefilter("error", CompiledBackendWarning)
        ekf = pu.ExtendedKalmanFilter(motion, sensor, backend="numba")
    assert ekf.compiled
    ref = pu.ExtendedKalmanFilter(motion, sensor, backend="numpy")
    prior = pu.Gaussian(np.array([5000.0, 0, 0, 5000.0, 0, 0]), np.eye(6) * 100.0)
    zs = np.array([[0.78], [0.77], [0.79], [0.78]])
    # atan2 and the trigonometry differ in the last bit between NumPy's SIMD paths and the kernels' libm
    np.testing.assert_allclose(pu.run(ekf, zs, prior).mean, pu.run(ref, zs, prior).mean, rtol=1e-9, atol=1e-6)
