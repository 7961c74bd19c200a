"""The bearings-only scenario: geometry, schedule variants and seeded simulation."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.rng import run_streams
from pursuit.scenarios.bearings import STRONG_SCHEDULE, WEAK_SCHEDULE, BearingsOnlyTarget


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("strength", ["weak", "strong"])
def test_range_stays_in_10_to_20_km_and_the_observer_maneuvers(dims, strength):
    sc = BearingsOnlyTarget(dims=dims, strength=strength)
    r = sc.ranges()
    assert 10e3 < r.min() and r.max() < 20e3
    obs = sc.observer_track()
    accel = np.diff(obs, 2, axis=0) / sc.dt**2
    assert np.abs(accel[:, 0]).max() > 20.0  # the weave: about 32 m/s² at its turns
    assert sc.measurement.dim == dims - 1


def test_weak_is_a_tenth_of_strong_and_2d_drops_the_z_segments():
    assert [m.accel for m in WEAK_SCHEDULE] == pytest.approx([m.accel / 10 for m in STRONG_SCHEDULE])
    sc2 = BearingsOnlyTarget(dims=2)
    assert all(m.axis in "xy" for m in sc2.maneuvers)
    assert max(abs(m.accel) for m in BearingsOnlyTarget(dims=3).maneuvers) == 20.0
    assert sc2.maneuvering().shape == (sc2.steps, 2)


def test_simulation_is_seeded_per_run_and_wraps_the_azimuth():
    sc = BearingsOnlyTarget(dims=3, strength="weak", horizon=30)
    a = sc.simulate(run_streams(3, range(4), 0))
    b = sc.simulate(run_streams(3, range(2, 4), 0))
    np.testing.assert_array_equal(a.measurements[:, 2:], b.measurements)  # run i only uses stream i
    np.testing.assert_array_equal(a.prior.mean[2:], b.prior.mean)
    assert a.measurements.shape == (28, 4, 2) and a.truth.shape == (28, 4, 9)
    assert np.all(np.abs(a.measurements[..., 0]) <= np.pi)
    clean = sc.measurement.h(a.truth[:, 0], 1)  # step 1 geometry only for the first row
    assert abs(a.measurements[0, 0, 0] - clean[0, 0]) < 5e-3


def test_bad_parameters_name_the_field():
    for kw, field in [(dict(dims=4), "dims"), (dict(strength="mild"), "strength"), (dict(weave_amplitude=-1.0), "weave_amplitude")]:
        with pytest.raises(ValueError, match=f"^{field}:"):
            BearingsOnlyTarget(**kw)


def test_the_measurement_uses_the_observer_track_in_closed_form():
    sc = BearingsOnlyTarget(dims=3)
    track = sc.observer_track()
    for k in (1, 50, sc.steps):
        np.testing.assert_allclose(sc.measurement.observer_at(k), track[k - 1], rtol=1e-14, atol=1e-9)
    # a huge horizon stores nothing at construction (the engine's memory check refuses it later)
    huge = BearingsOnlyTarget(horizon=10**15)
    assert huge.measurement.steps is None
