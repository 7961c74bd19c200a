"""The shared-moments path of evaluate_hypotheses against one filter step per pair (the generic path).

A Gaussian filter without a gate and with a constant fading factor updates every (track, detection)
pair from moments computed once per track (:meth:`update_moments`); the generic path steps the filter
on the flat batch of pairs.  Both must give the same hypotheses to round-off (1e-12 relative).
"""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import StrongTracking
from pursuit.filters.gaussian import GaussianState
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantVelocity, RangeBearing
from pursuit.multitarget.association import evaluate_hypotheses

from ._scenes import cv_models


class _StepOnly:
    """The filter seen through its ``step`` alone: evaluate_hypotheses takes the generic path."""

    def __init__(self, filt):
        self.step = filt.step


def _close(actual, expected, what):
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, what
    finite = np.isfinite(expected)
    np.testing.assert_array_equal(np.isfinite(actual), finite, err_msg=what)
    scale = np.max(np.abs(expected[finite]), initial=1.0)
    np.testing.assert_allclose(actual[finite], expected[finite], rtol=1e-12, atol=1e-12 * scale, err_msg=what)


def _random_spd(rng, shape, n, scale):
    A = rng.normal(0.0, 1.0, (*shape, n, n))
    return scale * (A @ np.swapaxes(A, -1, -2) / n + 0.5 * np.eye(n))


def _scene(rng, M, L, D, measurement_kind):
    """Track means, detections with NaN padding and dead slots; bearings straddle ±π for range-bearing."""
    mean = rng.normal(0.0, 5.0, (M, L, 4))
    if measurement_kind == "range-bearing":
        mean[..., 0] = rng.uniform(-60.0, -40.0, (M, L))  # behind the sensor: bearings near ±π
        mean[..., 2] = rng.normal(0.0, 2.0, (M, L))
        r = rng.uniform(40.0, 60.0, (M, D))
        b = np.pi + rng.normal(0.0, 0.05, (M, D))
        z = np.stack([r, np.angle(np.exp(1j * b))], axis=-1)  # wrapped to (−π, π]
    else:
        z = rng.normal(0.0, 6.0, (M, D, 2))
    z[rng.random((M, D)) < 0.25] = np.nan  # padding rows
    alive = rng.random((M, L)) < 0.7
    alive[0, 0] = True
    return mean, z, alive


def _filters():
    cv, lin = cv_models(q=0.1, sigma=1.5)
    rb = RangeBearing(np.zeros(2), 1.0, 0.02)
    cv2 = ConstantVelocity(ndim=2, dt=1.0, q=0.5)
    return {
        "KF": (pu.KalmanFilter(cv, lin), "linear"),
        "KF faded": (pu.KalmanFilter(cv, lin, 1.2), "linear"),
        "EKF range-bearing": (pu.ExtendedKalmanFilter(cv2, rb), "range-bearing"),
        "UKF range-bearing": (pu.UnscentedKalmanFilter(cv2, rb, alpha=0.5, kappa=1.0), "range-bearing"),
        "CKF range-bearing": (pu.CubatureKalmanFilter(cv2, rb), "range-bearing"),
    }


def _compare(filt, state, z, alive, k=3, dt=None):
    fast = evaluate_hypotheses(filt, state, z, alive, 0.99, k=k, dt=dt)
    slow = evaluate_hypotheses(_StepOnly(filt), state, z, alive, 0.99, k=k, dt=dt)
    for field in ("pair", "runs", "tracks", "dets", "detected", "gated"):
        np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field), err_msg=field)
    _close(fast.nis, slow.nis, "nis")
    _close(fast.loglik, slow.loglik, "loglik")
    _close(fast.missed.mean, slow.missed.mean, "missed mean")
    n = state.mean.shape[-1]
    _close(np.broadcast_to(fast.missed.cov, (*alive.shape, n, n)), np.broadcast_to(slow.missed.cov, (*alive.shape, n, n)), "missed cov")
    assert fast.missed.k == slow.missed.k
    if slow.states is None:
        assert fast.states is None
        return fast
    P = slow.runs.size
    assert isinstance(fast.states, GaussianState) and fast.states.k == slow.states.k
    _close(fast.states.mean, slow.states.mean, "pair means")
    _close(np.broadcast_to(fast.states.cov, (P, n, n)), np.broadcast_to(slow.states.cov, (P, n, n)), "pair covariances")
    return fast


@pytest.mark.parametrize("name", list(_filters()))
@pytest.mark.parametrize("seed", range(4))
def test_shared_moments_equal_one_step_per_pair(name, seed):
    filt, kind = _filters()[name]
    rng = np.random.default_rng(seed)
    M, L, D = 3, 5, 6
    mean, z, alive = _scene(rng, M, L, D, kind)
    state = filt.init(Gaussian(mean, _random_spd(rng, (M, L), 4, 4.0)), batch=(M, L))
    assert filt.update_moments(state, 3) is not None  # the fast path is taken
    hyp = _compare(filt, state, z, alive, dt=1.5 if seed % 2 else None)
    assert hyp.gated.any() and not hyp.gated.all()  # the scene exercises the gate both ways
    free = ~alive
    np.testing.assert_array_equal(hyp.missed.mean[free], state.mean[free])  # a free slot keeps its state


@pytest.mark.parametrize("name", ["KF", "EKF range-bearing", "UKF range-bearing"])
def test_every_slot_alive_and_a_shared_covariance(name):
    filt, kind = _filters()[name]
    rng = np.random.default_rng(7)
    M, L, D = 4, 3, 5
    mean, z, _ = _scene(rng, M, L, D, kind)
    alive = np.ones((M, L), dtype=bool)
    state = filt.init(Gaussian(mean, np.diag([9.0, 1.0, 9.0, 1.0])), batch=(M, L))  # one covariance, broadcast
    hyp = _compare(filt, state, z, alive)
    if name == "KF":
        # A KF keeps one covariance for all tracks: the pairs' covariance is a broadcast view, not P copies.
        assert hyp.states.cov.strides[0] == 0


def test_no_pair_and_no_alive_track():
    filt, _ = _filters()["EKF range-bearing"]
    rng = np.random.default_rng(3)
    M, L, D = 2, 3, 4
    state = filt.init(Gaussian(rng.normal(10.0, 5.0, (M, L, 4)), np.eye(4)), batch=(M, L))
    _compare(filt, state, np.full((M, D, 2), np.nan), rng.random((M, L)) < 0.5)  # padding only
    hyp = _compare(filt, state, rng.normal(20.0, 1.0, (M, D, 2)), np.zeros((M, L), dtype=bool))
    assert hyp.states is None


def test_filters_whose_update_reads_the_measurement_take_the_generic_path():
    cv, lin = cv_models()
    assert pu.KalmanFilter(cv, lin, gate=0.99).update_moments(pu.KalmanFilter(cv, lin).init(Gaussian(np.zeros(4), np.eye(4))), 1) is None
    stf = pu.ExtendedKalmanFilter(cv, lin, StrongTracking())
    assert stf.update_moments(stf.init(Gaussian(np.zeros(4), np.eye(4))), 1) is None
    # and evaluate_hypotheses still serves them (through step): the same as the generic path, trivially
    rng = np.random.default_rng(5)
    M, L, D = 2, 3, 4
    mean, z, alive = _scene(rng, M, L, D, "linear")
    for filt in (pu.KalmanFilter(cv, lin, gate=0.99), stf):
        _compare(filt, filt.init(Gaussian(mean, np.eye(4) * 3.0), batch=(M, L)), z, alive)
