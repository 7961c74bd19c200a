"""Closed-form TOA positioning, the position-fix model and the linear motion model."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pursuit.models import LinearMotion, PositionFix, l_array, toa_position, trilaterate, trilateration_jacobian

coords = st.floats(-500.0, 500.0, allow_nan=False)


def _ranges(anchors, p):
    return np.linalg.norm(np.asarray(p)[..., None, :] - anchors, axis=-1)


@given(x=coords, y=coords, d=st.floats(1.0, 500.0))
def test_closed_form_position_from_noise_free_travel_times_is_the_truth(x, y, d):
    c = 1500.0
    anchors = l_array(d)
    times = _ranges(anchors, [x, y]) / c
    scale = max(abs(x), abs(y), d)
    np.testing.assert_allclose(toa_position(c * times, d), [x, y], atol=1e-13 * scale**2 / d)
    np.testing.assert_allclose(trilaterate(anchors, c * times), [x, y], atol=1e-13 * scale**2 / d)


@given(x=coords, y=coords, z=coords)
def test_least_squares_trilateration_is_exact_without_noise(x, y, z):
    anchors = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 5.0], [0.0, 80.0, -5.0], [30.0, 40.0, 60.0], [-50.0, 10.0, 20.0]])
    p = np.array([x, y, z])
    np.testing.assert_allclose(trilaterate(anchors, _ranges(anchors, p)), p, atol=1e-7 * max(1.0, np.abs(p).max()))


def test_trilateration_is_vectorised_over_batches(rng):
    anchors = l_array(50.0)
    p = rng.uniform(-100, 100, size=(4, 7, 2))
    np.testing.assert_allclose(trilaterate(anchors, _ranges(anchors, p)), p, atol=1e-9)


def test_trilateration_jacobian_matches_finite_differences(rng):
    anchors = l_array(50.0)
    r = _ranges(anchors, rng.uniform(-80, 80, size=(5, 2)))
    J = trilateration_jacobian(anchors, r)
    h = 1e-6
    for j in range(3):
        dr = np.zeros(3)
        dr[j] = h
        fd = (trilaterate(anchors, r + dr) - trilaterate(anchors, r - dr)) / (2 * h)
        np.testing.assert_allclose(J[..., j], fd, rtol=1e-6, atol=1e-8)
    # paper P2's layout: dx/dr1 = r1/d, dx/dr3 = -r3/d, dy/dr1 = r1/d, dy/dr2 = -r2/d
    np.testing.assert_allclose(J[:, 0, 0], r[:, 0] / 50.0)
    np.testing.assert_allclose(J[:, 0, 2], -r[:, 2] / 50.0)
    np.testing.assert_allclose(J[:, 1, 1], -r[:, 1] / 50.0)


def test_degenerate_anchor_layouts_are_refused():
    with pytest.raises(ValueError, match="anchors: are collinear"):
        trilaterate(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]), np.ones(3))
    with pytest.raises(ValueError, match="at least 3 anchors"):
        trilaterate(np.array([[0.0, 0.0], [1.0, 0.0]]), np.ones(2))
    with pytest.raises(ValueError, match="d: must be positive"):
        l_array(0.0)


def test_position_fix_uses_the_step_covariance():
    R = np.array([np.eye(2) * (k + 1) for k in range(3)])
    fix = PositionFix(4, (0, 1), R)
    assert np.array_equal(fix.cov(1), R[0]) and np.array_equal(fix.cov(3), R[2])
    assert np.array_equal(fix.cov(10), R[2]) and np.array_equal(fix.cov(0), R[0])
    x = np.array([[1.0, 2.0, 3.0, 4.0]])
    assert np.array_equal(fix.h(x), [[1.0, 2.0]])
    assert np.array_equal(fix.matrix(), [[1, 0, 0, 0], [0, 1, 0, 0]])
    expected = -0.5 * (np.sum(np.array([0.5, -1.0]) ** 2) / 2 + 2 * np.log(2) + 2 * np.log(2 * np.pi))
    assert fix.loglik(np.array([1.5, 1.0]), x[0], 2) == pytest.approx(expected)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        (dict(state_dim=4, position_indices=(0, 5), R=np.eye(2)), "position_indices"),
        (dict(state_dim=4, position_indices=(0, 1), R=np.eye(3)), "R: expected"),
        (dict(state_dim=4, position_indices=(0, 1), R=-np.eye(2)), "positive definite"),
    ],
)
def test_position_fix_refuses_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PositionFix(**kwargs)


def test_linear_motion_samples_with_its_covariance(rng):
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    Q = np.array([[0.5, 0.1], [0.1, 0.2]])
    model = LinearMotion(F, Q)
    x = np.tile([1.0, 2.0], (40000, 1))
    draws = model.sample(x, 1, rng) - model.f(x)
    np.testing.assert_allclose(model.f(x[:1]), [[3.0, 2.0]])
    # sample covariance of 40000 draws: standard error about 0.5 * sqrt(2/40000) = 0.0035
    np.testing.assert_allclose(np.cov(draws.T), Q, atol=0.02)
    assert model.transition_matrix() is model.F and model.jacobian() is model.F


def test_linear_motion_refuses_bad_matrices():
    with pytest.raises(ValueError, match="F: expected a square matrix"):
        LinearMotion(np.ones((2, 3)), np.eye(2))
    with pytest.raises(ValueError, match="Q: covariance is not positive semidefinite"):
        LinearMotion(np.eye(2), np.diag([1.0, -1.0]))
