"""The tracker on recorded data equals the library driver on the same numbers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import pursuit as pu
from pursuit.io import Dropped, load_track_model, read_records, stream_records, track_records
from pursuit.io.input_spec import InputSpec
from pursuit.rng import run_streams
from pursuit.scenarios import WSNRange

from .conftest import EXAMPLES, csv_text, read_truth


def _records(text: str, fmt: str = "csv"):
    return list(read_records(text.encode().splitlines(keepends=True), fmt))


def _from_file(path, fmt):
    with open(path, "rb") as f:
        return list(read_records(f, fmt))


def _measurement_matrix(records, sensors):
    """(K, 1, m) measurements and (K,) times from records, by hand."""
    times = sorted({r.time for r in records})
    zs = np.full((len(times), 1, sum(s.dim for s in sensors.values())), np.nan)
    for r in records:
        zs[times.index(r.time), 0, sensors[r.sensor].block] = r.values
    return np.array(times), zs


@pytest.mark.parametrize("example,fmt", [("wsn-range", "csv"), ("wsn-range", "jsonl"), ("underwater-toa", "csv"), ("underwater-toa", "jsonl")])
def test_examples_equal_the_run_driver_with_irregular_steps_and_missing_sensors(example, fmt):
    model = load_track_model(EXAMPLES / f"{example}.toml")
    records = _from_file(EXAMPLES / "data" / f"{example}.{fmt}", fmt)
    result = track_records(records, model)
    assert result.problems == [] and result.dropped == []
    times, zs = _measurement_matrix(records, model.sensors)
    dts = np.diff(np.concatenate([[model.prior_time], times]))
    ref = pu.run(model.filter, zs, model.prior, dts=dts)
    assert [e.time for e in result.estimates] == times.tolist()
    np.testing.assert_array_equal(np.array([e.mean for e in result.estimates]), ref.mean[:, 0])
    np.testing.assert_array_equal(np.array([e.var for e in result.estimates]), np.diagonal(ref.cov[:, 0], axis1=-2, axis2=-1))
    np.testing.assert_array_equal(np.array([e.nis for e in result.estimates]), ref.info["nis"][:, 0])
    assert [e.dof for e in result.estimates] == ref.info["dof"][:, 0].tolist()
    assert np.any(np.isnan(zs)) if example == "wsn-range" else len(set(np.round(dts, 9))) > 10


@pytest.mark.parametrize("example", ["wsn-range", "underwater-toa"])
def test_examples_track_the_truth_consistently(example):
    # The estimates are close to the simulated truth by the filter's own account: the
    # time-averaged position NEES (diagonal form) stays below 3x its expected value 2;
    # a diverged or overconfident filter gives tens to thousands.
    model = load_track_model(EXAMPLES / f"{example}.toml")
    result = track_records(_from_file(EXAMPLES / "data" / f"{example}.csv", "csv"), model)
    times, truth = read_truth(EXAMPLES / "data" / f"{example}-truth.csv")
    # (a time at which every WSN report was lost has no estimate)
    at = np.searchsorted(times, [e.time for e in result.estimates])
    np.testing.assert_array_equal(times[at], [e.time for e in result.estimates])
    err = np.array([e.mean for e in result.estimates]) - truth[at]
    pos = list(model.position_indices)
    var = np.array([e.var for e in result.estimates])[:, pos]
    nees = np.mean(np.sum(err[:, pos] ** 2 / var, axis=1))  # diagonal NEES, a conservative proxy
    assert nees < 2 * 3.0  # mean of chi2(2) is 2; a diverged filter gives hundreds


def test_the_toa_outlier_is_gated_and_only_it():
    model = load_track_model(EXAMPLES / "underwater-toa.toml")
    result = track_records(_from_file(EXAMPLES / "data" / "underwater-toa.csv", "csv"), model)
    gated = [e.time for e in result.estimates if "gated" in e.flags]
    assert len(gated) == 1 and abs(gated[0] - 15.0) < 1.0


def test_the_wsn_scenario_through_a_csv_equals_the_run_driver_bit_for_bit(tmp_path, wsn_model_path):
    # pursuit's own WSN simulator -> CSV text -> pursuit track == pu.run on the arrays
    sc = WSNRange(steps=30, prior_mean="truth")
    sim = sc.simulate(run_streams(4, range(1), 0), 1)
    names = ["A1", "A2", "A3", "A4"]
    rows = [(t, names[j], sim.measurements[k, 0, j]) for k, t in enumerate(sim.times) for j in range(4)]
    model = load_track_model(wsn_model_path)
    result = track_records(_records(csv_text(rows)), model)
    ref = pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement), sim.measurements, pu.Gaussian(sc.x0, sc.P0))
    np.testing.assert_array_equal(np.array([e.mean for e in result.estimates]), ref.mean[:, 0])


def test_out_of_order_records_are_sorted_in_by_default(wsn_model_path):
    model = load_track_model(wsn_model_path)
    rows = [(1.0, "A1", 40.0), (1.0, "A2", 98.0), (2.0, "A1", 41.0), (3.0, "A3", 60.0), (2.0, "A2", 97.5)]
    shuffled = track_records(_records(csv_text(rows)), model)
    ordered = track_records(_records(csv_text(sorted(rows, key=lambda r: r[0]))), model)
    assert shuffled.problems == []
    np.testing.assert_array_equal([e.mean for e in shuffled.estimates], [e.mean for e in ordered.estimates])
    # the step at t = 2 has both sensors, whatever the file order
    assert shuffled.estimates[1].dof == 2


def test_out_of_order_error_and_drop_policies(wsn_model_path):
    model = load_track_model(wsn_model_path)
    rows = [(1.0, "A1", 40.0), (2.0, "A1", 41.0), (1.5, "A2", 98.0), (3.0, "A1", 42.0)]
    errs = track_records(_records(csv_text(rows)), model, out_of_order="error")
    assert [(p.line, p.field) for p in errs.problems] == [(4, "time")]
    assert "out of order: 1.5 is earlier than time 2.0" in errs.problems[0].message
    drop = track_records(_records(csv_text(rows)), model, out_of_order="drop")
    assert drop.problems == [] and [d.line for d in drop.dropped] == [4]
    without = track_records(_records(csv_text([rows[0], rows[1], rows[3]])), model)
    np.testing.assert_array_equal([e.mean for e in drop.estimates], [e.mean for e in without.estimates])


def test_records_at_or_before_the_prior_time_and_duplicates_are_bad(wsn_model_path):
    model = load_track_model(wsn_model_path)
    rows = [(0.0, "A1", 40.0), (-1.0, "A2", 40.0), (1.0, "A1", 40.0), (1.0, "A1", 41.0), (1.0, "A2", 98.0)]
    res = track_records(_records(csv_text(rows)), model)
    assert [(p.line, p.field) for p in res.problems] == [(2, "time"), (3, "time"), (5, "sensor")]
    assert "not after the prior's time 0.0" in res.problems[0].message
    assert "'A1' already has a measurement at time 1.0 (line 4)" in res.problems[2].message
    assert len(res.estimates) == 1 and res.estimates[0].dof == 2


def test_without_a_prior_time_the_first_step_is_one_nominal_dt_after_the_prior(tmp_path, wsn_model_path):
    text = wsn_model_path.read_text().replace("time = 0.0\n", "")
    path = tmp_path / "m.toml"
    path.write_text(text)
    model = load_track_model(path)
    assert model.prior_time is None
    rows = [(100.0, "A1", 40.0), (101.0, "A1", 41.0)]
    res = track_records(_records(csv_text(rows)), model)
    shifted = track_records(_records(csv_text([(1.0, "A1", 40.0), (2.0, "A1", 41.0)])), load_track_model(wsn_model_path))
    np.testing.assert_array_equal([e.mean for e in res.estimates], [e.mean for e in shifted.estimates])


def test_a_time_only_record_asks_for_a_prediction(wsn_model_path):
    model = load_track_model(wsn_model_path)
    text = '{"time": 1, "sensor": "A1", "value": 40}\n{"time": 2.5}\n{"time": 3, "sensor": "A1", "value": 41}\n'
    res = track_records(_records(text, "jsonl"), model)
    assert [e.time for e in res.estimates] == [1.0, 2.5, 3.0]
    assert res.estimates[1].flags == ("predict",) and math.isnan(res.estimates[1].nis) and res.estimates[1].dof == 0


def test_a_step_that_would_overflow_the_filter_is_refused_and_the_filter_goes_on(wsn_model_path):
    # no max_gap, so that the gap reaches the filter (by default it is a bad record first: test_steps.py)
    model = dataclasses.replace(load_track_model(wsn_model_path), input=InputSpec())
    rows = [(1.0, "A1", 40.0), (1e300, "A1", 41.0)]
    res = track_records(_records(csv_text(rows)), model)
    # the gap is to blame (a prediction alone over it overflows): the time field is named
    assert [(p.line, p.field) for p in res.problems] == [(3, "time")]
    assert res.problems[0].message == (
        "rejected at time 1e+300: 1e+300 s after the previous step at 1.0 is a gap the filter cannot "
        "predict across (the filter failed: ValueError: step 2: dt: 1e+300 s is beyond 2^200 ≈ 1.61e+60 s, "
        "the longest step whose fifth power (the motion models' process noise) float64 holds)"
    )
    assert len(res.estimates) == 1
    # streaming: the same refusal, then the next record is filtered from the last good state
    rows = [(1.0, "A1", 40.0), (1e300, "A1", 41.0), (2e300, "A1", 41.0)]
    events = list(stream_records(_records(csv_text(rows)), model))
    assert [type(e).__name__ for e in events] == ["Estimate", "BadRecord", "BadRecord"]


def test_stream_stop_at_bad_filters_everything_before_the_bad_record(wsn_model_path):
    model = load_track_model(wsn_model_path)
    text = '{"time": 1, "sensor": "A1", "value": 40}\n{"time": 2, "sensor": "A1", "value": 41}\n{"time": 2, "sensor": "A9", "value": 1}\n{"time": 3, "sensor": "A1", "value": 42}\n'
    events = list(stream_records(_records(text, "jsonl"), model, stop_at_bad=True))
    assert [type(e).__name__ for e in events] == ["Estimate", "Estimate", "BadRecord"]
    assert [e.time for e in events[:2]] == [1.0, 2.0]
    events = list(stream_records(_records(text, "jsonl"), model))
    assert [type(e).__name__ for e in events] == ["Estimate", "BadRecord", "Estimate", "Estimate"]


def test_late_stream_records_are_dropped_by_default(wsn_model_path):
    model = load_track_model(wsn_model_path)
    text = '{"time": 1, "sensor": "A1", "value": 40}\n{"time": 2, "sensor": "A1", "value": 41}\n{"time": 1.5, "sensor": "A2", "value": 98}\n'
    events = list(stream_records(_records(text, "jsonl"), model))
    assert [type(e).__name__ for e in events] == ["Estimate", "Dropped", "Estimate"]
    assert isinstance(events[1], Dropped) and events[1].line == 3


def test_position_and_bearing_sensors_in_one_model(tmp_path):
    # A mixed model: the stacked measurement equals a hand-built EKF on the same blocks.
    text = """
[motion]
type = "cv"
q = 0.1
[[sensors]]
id = "gps"
type = "position"
sigma = 3.0
[[sensors]]
id = "cam"
type = "bearing"
position = [0.0, -50.0]
sigma = 0.01
[prior]
time = 0.0
mean = [0.0, 1.0, 0.0, 1.0]
cov = [25.0, 1.0, 25.0, 1.0]
[filter]
type = "ekf"
"""
    path = tmp_path / "m.toml"
    path.write_text(text)
    model = load_track_model(path)
    rows = []
    rng = np.random.default_rng(0)
    for k in range(1, 21):
        t = float(k)
        p = np.array([t, t])
        if k % 3:
            rows.append((t, "gps", *(p + 3 * rng.standard_normal(2))))
        rows.append((t, "cam", float(np.arctan2(p[1] + 50, p[0]) + 0.01 * rng.standard_normal())))
    res = track_records(_records(csv_text(rows)), model)
    assert res.problems == []
    final = res.estimates[-1]
    assert abs(final.mean[0] - 20.0) < 5 * math.sqrt(final.var[0]) and abs(final.mean[2] - 20.0) < 5 * math.sqrt(final.var[2])
    assert [e.dof for e in res.estimates[:3]] == [3, 3, 1]


@pytest.mark.parametrize("policy", ["drop", "error"])
def test_a_late_record_at_or_before_the_prior_time_is_bad_whatever_the_policy(wsn_model_path, policy):
    # docs/track.md: "Whatever the policy, a record at or before [prior] time ... [is a] bad record";
    # found by tests/fuzz: in a stream it was dropped (drop) or called out of order (error) once a step was pending.
    model = load_track_model(wsn_model_path)
    rows = [(1.0, "A1", 40.0), (0.0, "A2", 40.0), (2.0, "A1", 41.0), (-3.0, "A3", 40.0)]
    events = list(stream_records(_records(csv_text(rows)), model, out_of_order=policy))
    bad = [e for e in events if not isinstance(e, (Dropped,)) and hasattr(e, "field")]
    assert [(b.line, b.field) for b in bad] == [(3, "time"), (5, "time")]
    assert all("not after the prior's time 0.0" in b.message for b in bad)
    assert not any(isinstance(e, Dropped) for e in events)


def test_a_step_whose_nis_comes_out_negative_is_refused_not_written(wsn_model_path):
    # A prior covariance of 1e20 used to reach the output as a negative NIS; the loader refuses that
    # prior now, and the tracker refuses any step whose NIS round-off made negative.
    import dataclasses

    model = load_track_model(wsn_model_path)

    class NegativeNIS:  # the model's EKF, with the round-off of an update that lost R
        def init(self, *args, **kwargs):
            return model.filter.init(*args, **kwargs)

        def step(self, *args, **kwargs):
            state, info = model.filter.step(*args, **kwargs)
            return state, {**info, "nis": np.where(np.isnan(info["nis"]), np.nan, -1e-5)}  # NaN: nothing measured

    bad = dataclasses.replace(model, filter=NegativeNIS())
    res = track_records(_records(csv_text([(1.0, "A1", 40.0), (2.0, "A1", 41.0)])), bad)
    assert res.estimates == []
    assert [(p.line, p.field) for p in res.problems] == [(2, "record"), (3, "record")]
    assert "round-off made its NIS negative" in res.problems[0].message


def test_a_track_that_turns_inconsistent_is_flagged_diverged_and_stays_flagged():
    model = load_track_model(EXAMPLES / "wsn-range.toml")
    records = _from_file(EXAMPLES / "data" / "wsn-range.csv", "csv")
    clean = track_records(records, model).estimates
    assert not any("diverged" in e.flags for e in clean)
    # from t = 20 s on, sensor A1 reads 300 m too long: the EKF cannot explain it with any state
    bad = [dataclasses.replace(r, values=tuple(v + 300.0 for v in r.values)) if r.sensor == "A1" and r.time >= 20.0 else r for r in records]
    est = track_records(bad, model).estimates
    flagged = ["diverged" in e.flags for e in est]
    first = flagged.index(True)
    assert est[first].time > 20.0 and all(flagged[first:])
    # a stream cannot look back: the flag starts at the step that completes the streak, after `streak` inconsistent steps
    from pursuit.divergence import DivergenceTest

    over = [e.dof > 0 and e.nis > DivergenceTest().threshold(e.dof) for e in est[: first + 1]]
    assert over[-DivergenceTest().streak :] == [True] * DivergenceTest().streak
