"""The WSN network: sensing radius and missed detections (NaN ranges), and how the filters treat them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pursuit.compute import numba_available
from pursuit.filters import BootstrapParticleFilter, ExtendedKalmanFilter, UnscentedKalmanFilter
from pursuit.gaussian import Gaussian
from pursuit.models import RangeSensors
from pursuit.rng import run_streams
from pursuit.scenarios import WSNRange

# the p1-wsn grid: 4 x 4 nodes at 50 m spacing, centred on the Fig. 8 track's midpoint (35, 80) m
GRID = np.array([[x, y] for y in (5.0, 55.0, 105.0, 155.0) for x in (-40.0, 10.0, 60.0, 110.0)])


def _sim(runs: int = 20, **kw):
    return WSNRange(anchors=GRID, sigma=0.85, steps=60, **kw).simulate(run_streams(7, range(runs), 0))


def test_defaults_equal_the_scenario_without_the_options_bit_for_bit():
    plain = _sim()
    explicit = _sim(sensing_radius=math.inf, p_detect=1.0)
    for a, b in ((plain.truth, explicit.truth), (plain.measurements, explicit.measurements), (plain.prior.mean, explicit.prior.mean)):
        np.testing.assert_array_equal(a, b)
    assert not np.isnan(plain.measurements).any()


def test_the_radius_blanks_exactly_the_nodes_out_of_range():
    plain, limited = _sim(), _sim(sensing_radius=60.0)
    np.testing.assert_array_equal(limited.truth, plain.truth)  # the options draw nothing before the ranges
    true_range = WSNRange(anchors=GRID).measurement.h(plain.truth)
    far = true_range > 60.0
    assert 0.2 < far.mean() < 0.95  # both cases occur
    np.testing.assert_array_equal(np.isnan(limited.measurements), far)
    np.testing.assert_array_equal(limited.measurements[~far], plain.measurements[~far])


def test_missed_detections_follow_p_detect_and_the_documented_stream_order():
    runs, steps, s, pd = 20, 60, GRID.shape[0], 0.9
    plain, missed = _sim(runs), _sim(runs, p_detect=pd)
    np.testing.assert_array_equal(missed.truth, plain.truth)
    # the uniforms come after everything else of a run, step-major: replay run 3's stream by hand
    g = run_streams(7, [3], 0).generators[0]
    g.standard_normal(4)  # the prior offset
    for _ in range(steps):
        g.standard_normal(2)  # process noise (discrete: through Gamma)
        g.standard_normal(s)  # range noise
    u = g.random(steps * s).reshape(steps, s)
    np.testing.assert_array_equal(np.isnan(missed.measurements[:, 3]), u >= pd)
    # the miss rate: 1 - P_D within 4 standard errors (binomial, runs*steps*s trials)
    n = runs * steps * s
    rate = np.isnan(missed.measurements).mean()
    assert abs(rate - (1 - pd)) < 4 * math.sqrt(pd * (1 - pd) / n)


def test_radius_and_p_detect_combine():
    both = _sim(sensing_radius=60.0, p_detect=0.9)
    radius, pd = _sim(sensing_radius=60.0), _sim(p_detect=0.9)
    np.testing.assert_array_equal(np.isnan(both.measurements), np.isnan(radius.measurements) | np.isnan(pd.measurements))


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"sensing_radius": 0.0}, "sensing_radius: must be positive"),
        ({"sensing_radius": -5.0}, "sensing_radius: must be positive"),
        ({"sensing_radius": float("nan")}, "sensing_radius: must be positive"),
        ({"sensing_radius": "far"}, "sensing_radius: expected a number"),
        ({"p_detect": 0.0}, r"p_detect: must lie in \(0, 1\]"),
        ({"p_detect": 1.5}, r"p_detect: must lie in \(0, 1\]"),
        ({"p_detect": True}, "p_detect: expected a number"),
    ],
)
def test_bad_options_name_the_field(kwargs, message):
    with pytest.raises(ValueError, match=f"^{message}"):
        WSNRange(**kwargs)


def _one_step(filt, z):
    g = Gaussian(np.broadcast_to(WSNRange().x0, (3, 4)).copy(), np.diag([4.0, 0.25, 4.0, 0.25]))
    state = filt.init(g, (3,), run_streams(1, range(3), 1))
    state, info = filt.step(state, z, 1)
    return state, info


BACKENDS = ["numpy"] + (["numba"] if numba_available() else [])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", ["pf", "ekf", "ukf"])
def test_a_nan_range_is_treated_as_that_node_missing(kind, backend):
    # exact reference: the same filter on the model without the missing nodes
    sc = WSNRange(anchors=GRID, sigma=0.85)
    keep = np.array([0, 1, 4, 5, 6, 9])
    sub = RangeSensors(GRID[keep], 0.85)
    truth = np.array([[12.0, 0.5, 41.0, 0.8]] * 3)
    z_full = sc.measurement.h(truth) + 0.3
    z_nan = np.full_like(z_full, np.nan)
    z_nan[:, keep] = z_full[:, keep]

    def make(meas):
        if kind == "pf":
            return BootstrapParticleFilter(sc.motion, meas, 500, backend=backend)
        cls = ExtendedKalmanFilter if kind == "ekf" else UnscentedKalmanFilter
        return cls(sc.motion, meas, backend=backend)

    a, _ = _one_step(make(sc.measurement), z_nan)
    b, _ = _one_step(make(sub), z_full[:, keep])
    if kind == "pf":  # resampled by the weights: a wrong weight moves the particles
        np.testing.assert_allclose(a.particles, b.particles, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.weights, b.weights, rtol=1e-10, atol=1e-14)
    else:
        np.testing.assert_allclose(a.mean, b.mean, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(a.cov, b.cov, rtol=1e-10, atol=1e-10)
