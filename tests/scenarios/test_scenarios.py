"""Scenario simulators: shapes, statistics, seeding, parameter checks."""

import numpy as np
import pytest

from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, WSNRange


@pytest.mark.parametrize("scenario", [WSNRange(steps=12), LinearCV(ndim=3, steps=12)], ids=["wsn", "cv"])
def test_shapes_and_labels(scenario):
    sim = scenario.simulate(run_streams(0, range(5), 0))
    n = len(scenario.state_labels)
    assert sim.truth.shape == (12, 5, n)
    assert sim.measurements.shape == (12, 5, scenario.measurement.dim)
    assert sim.prior.mean.shape == (5, n)
    np.testing.assert_allclose(sim.times, scenario.dt * np.arange(1, 13))
    assert scenario.motion.dim == n


def test_wsn_measurements_are_ranges_plus_noise(rng):
    sc = WSNRange(sigma=0.5, steps=200)
    sim = sc.simulate(rng, 50)
    resid = sim.measurements - sc.measurement.h(sim.truth)
    assert resid.std() == pytest.approx(0.5, rel=0.03)
    assert abs(resid.mean()) < 0.02


def test_prior_mean_modes(rng):
    sampled = WSNRange(steps=2).simulate(np.random.default_rng(1), 4000)
    off = sampled.prior.mean - WSNRange().x0
    np.testing.assert_allclose(np.cov(off.T), WSNRange().P0, atol=0.2)
    truth = WSNRange(steps=2, prior_mean="truth").simulate(np.random.default_rng(1), 3)
    np.testing.assert_array_equal(truth.prior.mean, np.broadcast_to(WSNRange().x0, (3, 4)))
    # the truth does not depend on the prior mode (same draws)
    np.testing.assert_array_equal(truth.truth, WSNRange(steps=2).simulate(np.random.default_rng(1), 3).truth)


def test_single_generator_needs_runs():
    with pytest.raises(ValueError, match="runs"):
        WSNRange().simulate(np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"sigma": 0.0}, "sigma"),
        ({"steps": 0}, "steps"),
        ({"x0": [1.0, 2.0]}, "x0"),
        ({"P0": [[1.0, 2.0], [2.0, 1.0]]}, "P0"),
        ({"P0": [1.0, 1.0, -1.0, 1.0]}, "P0"),
        ({"anchors": [[0.0, 0.0, 0.0]]}, "anchors"),
        ({"prior_mean": "zero"}, "prior_mean"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        WSNRange(**kwargs)
