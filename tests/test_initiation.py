"""Priors from the first measurements: consistent (NEES in its chi-square band) and clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.initiation import multilaterate, one_point, polar_to_cartesian, two_point
from pursuit.metrics import chi2_bounds, nees
from pursuit.models import ConstantAcceleration, ConstantTurn, ConstantVelocity, Singer

M = 4000  # simulated runs per consistency check


def _anees_in_band(est, cov, truth, dof):
    """Average NEES over the runs and its two-sided 99.9 % chi-square band."""
    e = nees(est[None], cov[None], truth[None])[0]
    lo, hi = chi2_bounds(dof, e.size, level=0.999)
    return float(e.mean()), float(lo), float(hi)


def test_two_point_differencing_is_consistent():
    rng = np.random.default_rng(1)
    motion = ConstantVelocity(ndim=2)
    dt = 0.7
    x1 = rng.normal([0, 1, 0, -2], [50, 3, 50, 3], size=(M, 4))
    x2 = motion.f(x1, dt=dt)  # no process noise between the fixes: the textbook assumption
    R1 = np.array([[4.0, 1.0], [1.0, 9.0]])
    R2 = np.diag([1.0, 2.0])
    z1 = x1[:, [0, 2]] + rng.multivariate_normal([0, 0], R1, size=M)
    z2 = x2[:, [0, 2]] + rng.multivariate_normal([0, 0], R2, size=M)
    prior = two_point(z1, R1, z2, R2, dt, motion)
    np.testing.assert_allclose(prior.mean[:, [1, 3]], (z2 - z1) / dt)
    np.testing.assert_array_equal(prior.mean[:, [0, 2]], z2)
    cov = np.broadcast_to(prior.cov, (M, 4, 4))
    avg, lo, hi = _anees_in_band(prior.mean, cov, x2, 4)
    assert lo < avg < hi, (avg, lo, hi)


def test_the_velocity_variance_needs_both_fixes():
    """The check above can fail: a P_vv below (C1 + C2)/dt² (here 1.2 instead of 2) is found too small."""
    rng = np.random.default_rng(2)
    motion = ConstantVelocity(ndim=1)
    x1 = rng.normal([0, 1], [10, 1], size=(M, 2))
    x2 = motion.f(x1, dt=1.0)
    R = np.array([[1.0]])
    z1 = x1[:, :1] + rng.normal(size=(M, 1))
    z2 = x2[:, :1] + rng.normal(size=(M, 1))
    good = two_point(z1, R, z2, R, 1.0, motion)
    bad_cov = good.cov.copy()
    bad_cov[:, 1, 1] = 1.2
    assert _anees_in_band(good.mean, np.broadcast_to(good.cov, (M, 2, 2)), x2, 2)[0] < 2.2
    avg, lo, hi = _anees_in_band(good.mean, np.broadcast_to(bad_cov, (M, 2, 2)), x2, 2)
    assert avg > hi


def test_one_point_is_consistent_for_a_velocity_within_its_sigma():
    rng = np.random.default_rng(3)
    motion = ConstantVelocity(ndim=3)
    truth = rng.normal(0.0, 1.0, size=(M, 6)) * [100, 5, 100, 5, 100, 5]
    R = np.diag([1.0, 4.0, 9.0])
    z = truth[:, [0, 2, 4]] + rng.multivariate_normal(np.zeros(3), R, size=M)
    prior = one_point(z, R, motion, velocity_sigma=5.0)
    np.testing.assert_array_equal(prior.mean[:, [1, 3, 5]], 0.0)
    avg, lo, hi = _anees_in_band(prior.mean, np.broadcast_to(prior.cov, (M, 6, 6)), truth, 6)
    assert lo < avg < hi, (avg, lo, hi)


def test_polar_conversion_is_consistent_for_small_bearing_noise():
    rng = np.random.default_rng(4)
    origin = np.array([10.0, -5.0])
    r = rng.uniform(50, 400, M)
    th = rng.uniform(-np.pi, np.pi, M)
    truth = origin + np.stack([r * np.cos(th), r * np.sin(th)], axis=-1)
    p, C = polar_to_cartesian(r + rng.normal(0, 2.0, M), th + rng.normal(0, 0.01, M), 2.0, 0.01, origin)
    avg, lo, hi = _anees_in_band(p, C, truth, 2)
    assert lo < avg < hi, (avg, lo, hi)
    # one known case: due east at 100 m, the cross-range variance is (r σθ)²
    p1, C1 = polar_to_cartesian(100.0, 0.0, 2.0, 0.01)
    np.testing.assert_allclose(p1, [100.0, 0.0])
    np.testing.assert_allclose(C1, np.diag([4.0, 1.0]), atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_multilateration_is_consistent(d):
    rng = np.random.default_rng(5 + d)
    anchors = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 0], [50, 50, 80]], dtype=float)[: d + 2, :d]
    truth = rng.uniform(10, 90, size=(M, d))
    sig = np.array([1.0, 1.0, 2.0, 1.0, 1.5])[: len(anchors)]
    dist = np.linalg.norm(truth[:, None, :] - anchors, axis=-1)
    p, C = multilaterate(anchors, dist + rng.normal(size=dist.shape) * sig, sig)
    avg, lo, hi = _anees_in_band(p, C, truth, d)
    assert lo < avg < hi, (avg, lo, hi)
    # noise-free ranges give the position itself
    p0, _ = multilaterate(anchors, dist[:3], sig)
    np.testing.assert_allclose(p0, truth[:3], atol=1e-8)


def test_multilateration_refuses_too_few_or_collinear_anchors():
    with pytest.raises(ValueError, match="at least 3 anchors, got 2"):
        multilaterate([[0, 0], [10, 0]], [5.0, 5.0], 1.0)
    with pytest.raises(ValueError, match="lie on a line"):
        multilaterate([[0, 0], [10, 0], [20, 0]], [5.0, 5.0, 15.0], 1.0)


@pytest.mark.parametrize(
    "motion, n",
    [(ConstantAcceleration(ndim=2), 6), (Singer(ndim=2), 6), (ConstantTurn(omega=0.1, ndim=2), 4)],
)
def test_other_state_layouts(motion, n):
    prior = two_point([0.0, 0.0], np.eye(2), [2.0, 4.0], np.eye(2), 2.0, motion, acceleration_sigma=3.0)
    assert prior.mean.shape == (n,)
    np.testing.assert_allclose(prior.mean[list(motion.velocity_indices)], [1.0, 2.0])
    for i in getattr(motion, "acceleration_indices", ()):
        assert prior.mean[i] == 0.0 and prior.cov[i, i] == 9.0


def test_two_point_refuses_a_non_increasing_time():
    with pytest.raises(ValueError, match="dt"):
        two_point([0.0], [[1.0]], [1.0], [[1.0]], 0.0, ConstantVelocity(ndim=1))
