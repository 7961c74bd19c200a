"""The UNGM models against the paper's equations."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit._linalg import numerical_jacobian
from pursuit.models.ungm import UNGMMeasurement, UNGMMotion


def test_transition_and_measurement_follow_eq_15_16(rng):
    m, h = UNGMMotion(), UNGMMeasurement()
    x = rng.standard_normal((5, 1)) * 10
    for k in (1, 2, 7):
        expected = 0.5 * x + 25 * x / (1 + x**2) + 8 * np.cos(1.2 * (k - 1))
        np.testing.assert_allclose(m.f(x, k), expected, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(h.h(x), x**2 / 20, rtol=1e-15)
    assert h.cov()[0, 0] == 1.0 and m.cov()[0, 0] == 1.0


def test_jacobians_match_central_differences(rng):
    m, h = UNGMMotion(), UNGMMeasurement()
    x = rng.standard_normal((6, 1)) * 4
    np.testing.assert_allclose(m.jacobian(x, 3), numerical_jacobian(lambda v: m.f(v, 3), x), rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(h.jacobian(x), numerical_jacobian(h.h, x), rtol=1e-6, atol=1e-8)


def test_sampling_has_the_model_noise(rng):
    m = UNGMMotion(q=4.0)
    x = np.zeros((200000, 1))
    d = m.sample(x, 1, rng) - m.f(x, 1)
    assert d.mean() == pytest.approx(0.0, abs=0.02) and d.var() == pytest.approx(4.0, rel=0.02)
    h = UNGMMeasurement(r=0.5)
    z = h.sample(np.full((200000, 1), 3.0), 1, rng)
    assert z.mean() == pytest.approx(9 / 20, abs=0.01) and z.var() == pytest.approx(0.5, rel=0.02)
    np.testing.assert_allclose(h.loglik(np.array([1.0]), np.array([[2.0]])), -0.5 * ((1 - 0.2) ** 2 / 0.5 + np.log(2 * np.pi * 0.5)))


def test_bad_parameters_and_missing_step_index():
    with pytest.raises(ValueError, match="q"):
        UNGMMotion(q=0.0)
    with pytest.raises(ValueError, match="scale"):
        UNGMMeasurement(scale=-1.0)
    with pytest.raises(ValueError, match="k"):
        UNGMMotion().f(np.zeros((1, 1)))
