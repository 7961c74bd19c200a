"""Kinematic motion models: matrices, layouts, sampling statistics, bad parameters."""

import numpy as np
import pytest

from pursuit.models import ConstantAcceleration, ConstantVelocity


def test_cv_matrices_one_axis():
    m = ConstantVelocity(ndim=1, dt=2.0, q=3.0)
    np.testing.assert_array_equal(m.transition_matrix(), [[1.0, 2.0], [0.0, 1.0]])
    # discrete white-noise acceleration: q * [dt^2/2, dt][dt^2/2, dt]^T
    np.testing.assert_allclose(m.cov(), 3.0 * np.array([[4.0, 4.0], [4.0, 4.0]]))
    c = ConstantVelocity(ndim=1, dt=2.0, q=3.0, noise="continuous")
    np.testing.assert_allclose(c.cov(), 3.0 * np.array([[8.0 / 3.0, 2.0], [2.0, 2.0]]))


def test_ca_matrices_one_axis():
    m = ConstantAcceleration(ndim=1, dt=0.5, q=2.0, noise="continuous")
    dt = 0.5
    np.testing.assert_allclose(m.transition_matrix(), [[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
    Q = m.cov()
    assert Q[0, 0] == pytest.approx(2.0 * dt**5 / 20)
    assert Q[2, 2] == pytest.approx(2.0 * dt)
    assert m.acceleration_indices == (2,)


def test_layouts_are_permutations_of_each_other():
    a = ConstantVelocity(ndim=3, dt=0.3, q=0.7, layout="axis")
    d = ConstantVelocity(ndim=3, dt=0.3, q=0.7, layout="derivative")
    assert a.position_indices == (0, 2, 4) and a.velocity_indices == (1, 3, 5)
    assert d.position_indices == (0, 1, 2) and d.velocity_indices == (3, 4, 5)
    perm = [0, 2, 4, 1, 3, 5]  # derivative-layout state i is axis-layout state perm[i]
    np.testing.assert_allclose(d.transition_matrix(), a.transition_matrix()[np.ix_(perm, perm)])
    np.testing.assert_allclose(d.cov(), a.cov()[np.ix_(perm, perm)])


def test_dt_override_matches_a_model_with_that_dt():
    m = ConstantVelocity(ndim=2, dt=1.0, q=0.5)
    other = ConstantVelocity(ndim=2, dt=0.25, q=0.5)
    np.testing.assert_array_equal(m.transition_matrix(dt=0.25), other.transition_matrix())
    np.testing.assert_array_equal(m.cov(dt=0.25), other.cov())
    x = np.arange(8.0).reshape(2, 4)
    np.testing.assert_array_equal(m.f(x, 1, dt=0.25), other.f(x, 1))


@pytest.mark.parametrize("model", [ConstantVelocity(ndim=2, q=0.5), ConstantAcceleration(ndim=1, q=0.2, noise="continuous")])
def test_samples_have_the_model_covariance(model, rng):
    x = np.zeros((200_000, model.dim))
    d = model.sample(x, 1, rng) - model.f(x, 1)
    cov = d.T @ d / d.shape[0]
    Q = model.cov()
    # each entry of a sample covariance has standard error about sqrt((Q_ii Q_jj + Q_ij^2) / N)
    se = np.sqrt((np.outer(np.diag(Q), np.diag(Q)) + Q**2) / d.shape[0])
    assert np.all(np.abs(cov - Q) < 5 * se + 1e-15)


def test_matrices_are_read_only():
    F = ConstantVelocity().transition_matrix()
    with pytest.raises(ValueError):
        F[0, 0] = 2.0


@pytest.mark.parametrize(
    "kwargs,field",
    [({"dt": 0.0}, "dt"), ({"q": -1.0}, "q"), ({"ndim": 4}, "ndim"), ({"noise": "pink"}, "noise"), ({"layout": "x"}, "layout")],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        ConstantVelocity(**kwargs)
