"""The maneuvering-target scenario: exact kinematics, schedule parsing, two-point prior, seeding."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.rng import run_streams
from pursuit.scenarios import Maneuver, ManeuveringTarget
from pursuit.scenarios.maneuver import DEFAULT_SCHEDULE, parse_schedule


def test_default_scenario_follows_the_spec_schedule_with_exact_kinematics():
    sc = ManeuveringTarget()
    X = sc.true_states()  # t = 1 .. 100
    t = np.arange(1, 101)
    ay = np.select([(t >= 21) & (t <= 35), (t >= 51) & (t <= 66), (t >= 67) & (t <= 80)], [40.0, -30.0, 60.0], 0.0)
    ax = np.where((t >= 31) & (t <= 45), 15.0, 0.0)
    az = np.where((t >= 51) & (t <= 70), -5.0, 0.0)
    np.testing.assert_array_equal(X[:, 2], ax)
    np.testing.assert_array_equal(X[:, 5], ay)
    np.testing.assert_array_equal(X[:, 8], az)
    # velocity integrates the acceleration, position the constant-acceleration step
    prev = np.concatenate([[[200e3, 0.0, 0.0, 200e3, 400.0, 0.0, 200e3, 10.0, 0.0]], X[:-1]])
    for axis in range(3):
        p, v, a = (slice(None), 3 * axis), (slice(None), 3 * axis + 1), (slice(None), 3 * axis + 2)
        np.testing.assert_allclose(X[v], prev[v] + X[a], rtol=1e-15)
        np.testing.assert_allclose(X[p], prev[p] + prev[v] + X[a] / 2, rtol=1e-15)
    assert X[34, 4] == 400.0 + 40.0 * 15
    assert sc.steps == 98 and sc.times[0] == 3.0 and sc.times[-1] == 100.0
    assert sc.state_labels == ("x", "vx", "ax", "y", "vy", "ay", "z", "vz", "az")


def test_turn_segments_rotate_the_velocity_at_constant_speed():
    sc = ManeuveringTarget(horizon=40, velocity=(200.0, 0.0, 5.0), maneuvers=[{"plane": "xy", "start": 11, "stop": 30, "rate": 3.0}])
    X = sc.true_states()
    speed = np.hypot(X[:, 1], X[:, 4])
    np.testing.assert_allclose(speed, 200.0, rtol=1e-13)
    heading = np.degrees(np.arctan2(X[:, 4], X[:, 1]))
    assert heading[9] == 0.0 and heading[29] == pytest.approx(60.0, rel=1e-12)
    turning = slice(10, 30)
    np.testing.assert_allclose(np.hypot(X[turning, 2], X[turning, 5]), np.radians(3.0) * 200.0, rtol=1e-12)
    # the position follows the exact arc: radius v/ω about the turn centre
    r = 200.0 / np.radians(3.0)
    centre = np.array([X[9, 0], X[9, 3] + r])
    np.testing.assert_allclose(np.hypot(X[turning, 0] - centre[0], X[turning, 3] - centre[1]), r, rtol=1e-12)
    np.testing.assert_array_equal(X[:, 8], 0.0)  # z untouched
    assert sc.maneuvering()[:, 0].sum() == 20 and sc.maneuvering()[:, 1].sum() == 20


def test_two_point_initialisation_and_its_covariance():
    sc = ManeuveringTarget()
    runs = 4000
    sim = sc.simulate(run_streams(3, range(runs), 0), runs)
    X = sc.true_states()
    err = sim.prior.mean - X[1]  # prior is at t_2
    P = sim.prior.cov
    assert np.all(err[:, 2::3] == 0.0)  # â = 0 and the truth has no acceleration before t = 21
    for axis in range(3):
        i = [3 * axis, 3 * axis + 1]
        emp = np.cov(err[:, i].T)
        # sampling error of a covariance estimate with n = 4000: a few percent; allow 5 standard errors
        se = np.sqrt((P[np.ix_(i, i)] ** 2 + np.outer(np.diag(P)[i], np.diag(P)[i])) / runs)
        assert np.all(np.abs(emp - P[np.ix_(i, i)]) < 5 * se)


def test_runs_are_independent_of_the_batch_they_are_simulated_in():
    sc = ManeuveringTarget(init="sampled")
    all_ = sc.simulate(run_streams(8, range(10), 0), 10)
    part = sc.simulate(run_streams(8, range(4, 7), 0), 3)
    np.testing.assert_array_equal(part.measurements, all_.measurements[:, 4:7])
    np.testing.assert_array_equal(part.prior.mean, all_.prior.mean[4:7])


@pytest.mark.parametrize(
    "entries,match",
    [
        ([{"axis": "y", "start": 1, "stop": 5}, {"axis": "y", "start": 5, "stop": 9, "accel": 1.0}], r"maneuvers\[1\]: overlaps"),
        ([{"axis": "w", "start": 1, "stop": 5}], r"maneuvers\[0\]\.axis"),
        ([{"axis": "x", "start": 1}], r"maneuvers\[0\]\.stop: required"),
        ([{"axis": "x", "start": 5, "stop": 1}], r"maneuvers\[0\]\.stop"),
        ([{"axis": "x", "start": 1, "stop": 2, "speed": 3}], r"maneuvers\[0\]\.speed: unknown key"),
        ([{"start": 1, "stop": 2}], r"maneuvers\[0\]: a maneuver needs exactly one"),
        ([{"plane": "xy", "start": 1, "stop": 5, "rate": 1.0}, {"axis": "y", "start": 3, "stop": 4}], "overlaps"),
        ("fast", "list of maneuver tables"),
        ([{"axis": "x", "start": -5, "stop": 2}], r"maneuvers\[0\]\.start: must be at least 0 s \(the truth starts at t = 0\), got -5"),
    ],
)
def test_bad_schedules_name_the_entry(entries, match):
    with pytest.raises(ValueError, match=match):
        ManeuveringTarget(maneuvers=entries)


def test_schedule_axes_must_exist():
    with pytest.raises(ValueError, match="does not exist"):
        ManeuveringTarget(position=(0.0, 0.0), velocity=(1.0, 1.0), maneuvers=[{"axis": "z", "start": 1, "stop": 2}])


def test_default_schedule_parses_from_tables():
    tables = [{"axis": m.axis, "start": m.start, "stop": m.stop, "accel": m.accel} for m in DEFAULT_SCHEDULE]
    assert parse_schedule(tables) == DEFAULT_SCHEDULE
    assert Maneuver(67, 80, axis="y", accel=60.0).label() == "y +60 m/s² 67-80 s"


@pytest.mark.parametrize("kwargs,field", [({"horizon": 2}, "horizon"), ({"R": 0.0}, "R"), ({"velocity": (1.0, 2.0)}, "velocity"), ({"init": "three-point"}, "init")])
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        ManeuveringTarget(**kwargs)
