"""The UNGM scenario."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.rng import run_streams
from pursuit.scenarios.ungm import UNGM


def test_shapes_prior_and_run_independence():
    sc = UNGM(steps=20)
    sim = sc.simulate(run_streams(4, range(5), 0), 5)
    assert sim.truth.shape == (20, 5, 1) and sim.measurements.shape == (20, 5, 1)
    np.testing.assert_array_equal(sim.prior.mean, np.full((5, 1), 0.1))
    assert sim.prior.cov[0, 0] == 2.0
    one = sc.simulate(run_streams(4, [3], 0), 1)
    np.testing.assert_array_equal(one.truth[:, 0], sim.truth[:, 3])
    sampled = UNGM(steps=20, prior_mean="sampled").simulate(run_streams(4, range(5), 0), 5)
    np.testing.assert_array_equal(sampled.truth, sim.truth)  # same truth, different prior means
    assert not np.allclose(sampled.prior.mean, 0.1)


def test_measurements_follow_the_model():
    sc = UNGM(steps=50, r=1.0)
    sim = sc.simulate(run_streams(5, range(400), 0), 400)
    resid = sim.measurements - sim.truth**2 / 20
    assert resid.mean() == pytest.approx(0.0, abs=0.03) and resid.var() == pytest.approx(1.0, rel=0.05)


def test_bad_parameters():
    with pytest.raises(ValueError, match="P0"):
        UNGM(P0=-1.0)
    with pytest.raises(ValueError, match="prior_mean"):
        UNGM(prior_mean="guess")
    with pytest.raises(ValueError, match="steps"):
        UNGM(steps=0)
