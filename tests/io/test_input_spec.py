"""The ``[input]`` section of a model file: columns, time origin, and the derived largest gap."""

from __future__ import annotations

import math
import tomllib
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from pursuit.experiment import ConfigError
from pursuit.io import build_track_model, load_track_model
from pursuit.io.input_spec import EPOCH, POSITION_SCALE, InputSpec, build_input_spec, default_max_gap
from pursuit.io.model import Sensor
from pursuit.models.motion import ConstantAcceleration, ConstantVelocity

from .conftest import EXAMPLES

SENSORS = {"A1": Sensor("A1", "range", 1, 0, (-1e9, 1e9)), "gps": Sensor("gps", "position", 2, 1, (-1e9, 1e9))}
CV = ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="discrete")


@pytest.mark.parametrize(
    "motion",
    [
        CV,
        ConstantVelocity(ndim=2, dt=1.0, q=1e-4, noise="continuous"),
        ConstantVelocity(ndim=3, dt=0.1, q=5.0, noise="discrete"),
        ConstantAcceleration(ndim=1, dt=1.0, q=0.01, noise="continuous"),
    ],
)
def test_the_default_max_gap_is_where_the_process_noise_spreads_a_position_over_the_scale(motion):
    gap = default_max_gap(motion)
    pos = list(motion.position_indices)
    assert np.sqrt(np.diagonal(motion.cov(dt=gap))[pos]).max() > POSITION_SCALE
    assert np.sqrt(np.diagonal(motion.cov(dt=gap * (1 - 1e-5)))[pos]).max() <= POSITION_SCALE


def test_maneuvering_motion_models_get_the_same_rule():
    from pursuit.models.maneuver import CoordinatedTurn, Singer

    for motion in (Singer(alpha=0.1, sigma=1.0, ndim=2), CoordinatedTurn()):
        gap = default_max_gap(motion)
        pos = list(motion.position_indices)
        assert math.isfinite(gap)
        assert np.sqrt(np.diagonal(motion.cov(dt=gap))[pos]).max() > POSITION_SCALE
        assert np.sqrt(np.diagonal(motion.cov(dt=gap * (1 - 1e-5)))[pos]).max() <= POSITION_SCALE


def test_a_motion_model_without_a_process_noise_covariance_gets_no_limit():
    class NoQ:
        dt = 1.0
        position_indices = (0,)

    assert default_max_gap(NoQ()) == math.inf
    assert default_max_gap(ConstantVelocity(ndim=1, dt=1.0, q=0.0 + 1e-300)) < math.inf


def test_the_default_max_gap_of_the_wsn_example_by_hand():
    # discrete white-noise acceleration: Q_xx = q dt^4 / 4, so dt = (4 * 1e18 / q) ** (1/4)
    assert default_max_gap(CV) == pytest.approx((4e18 / 0.01) ** 0.25, rel=2e-6)
    assert load_track_model(EXAMPLES / "wsn-range.toml").input.max_gap == pytest.approx(141421.356, rel=2e-6)


def test_defaults_without_an_input_section():
    spec = build_input_spec({}, CV, SENSORS)
    assert (spec.time_column, spec.sensor_column, spec.columns, spec.time_origin) == ("time", "sensor", None, EPOCH)
    assert spec.max_gap == default_max_gap(CV)
    assert InputSpec().max_gap == math.inf  # built directly: no limit


def test_a_full_input_section():
    doc = tomllib.loads(
        'time_column = "t"\ncolumns = {gps = ["East", "north"], A1 = "r1"}\n'
        "time_origin = 2026-07-01T02:00:00+02:00\nmax_gap = inf\n"
    )
    spec = build_input_spec(doc, CV, SENSORS)
    assert spec.columns == {"gps": ("East", "north"), "A1": ("r1",)}
    assert spec.time_origin == datetime(2026, 7, 1, tzinfo=timezone.utc)
    assert spec.max_gap == math.inf


@pytest.mark.parametrize(
    "origin,expected",
    [
        ("2026-07-01", datetime(2026, 7, 1, tzinfo=timezone.utc)),  # a TOML date: midnight UTC
        ("2026-07-01T12:00:00", datetime(2026, 7, 1, 12, tzinfo=timezone.utc)),  # naive: UTC
        ('"2026-07-01T12:00:00-01:00"', datetime(2026, 7, 1, 13, tzinfo=timezone.utc)),  # a string
    ],
)
def test_time_origin_forms(origin, expected):
    spec = build_input_spec(tomllib.loads(f"time_origin = {origin}\n"), CV, SENSORS)
    assert spec.time_origin == expected and spec.time_origin.utcoffset() == timedelta(0)


@pytest.mark.parametrize(
    "text,message",
    [
        ('columns = {gps = ["x"]}', "input.columns.gps: sensor 'gps' has 2 component(s), got 1 column(s)"),
        ('columns = {B = "r"}', "input.columns.B: unknown sensor 'B' (known: A1, gps)"),
        ('columns = {gps = ["x", "Time"]}', "input.columns.gps: column 'Time' is already used by input.time_column"),
        ('time_column = "T"\ncolumns = {A1 = "t"}', "input.columns.A1: column 't' is already used by input.time_column"),
        ('columns = {gps = ["x", "y"]}\nsensor_column = "id"', "input.sensor_column: a wide file"),
        ("columns = {}", "input.columns: expected a table"),
        ('columns = {gps = []}', "input.columns.gps: expected one column name per component"),
        ('columns = {gps = ["x", "a,b"]}', "input.columns.gps: expected a column name"),
        ('sensor_column = "Time"', "input.sensor_column: the same column as input.time_column"),
        ('time_column = ""', "input.time_column: expected a column name"),
        ("max_gap = -1.0", "input.max_gap: expected a positive number of seconds"),
        ("max_gap = nan", "input.max_gap: expected a positive number"),
        ('max_gap = "1 day"', "input.max_gap: expected a positive number"),
        ('time_origin = "yesterday"', "input.time_origin: not an ISO 8601 time: 'yesterday'"),
        ("time_origin = 12:00:00", "input.time_origin: expected a date and time"),
        ("time_origin = 0", "input.time_origin: expected a date and time"),
        ("rows = 3", "input.rows: unknown key"),
    ],
)
def test_bad_input_sections_name_the_field(text, message):
    with pytest.raises(ValueError) as e:
        build_input_spec(tomllib.loads(text), CV, SENSORS)
    assert str(e.value).startswith(message)


def test_a_bad_input_section_in_a_model_file_names_its_line(tmp_path):
    text = (EXAMPLES / "wsn-range.toml").read_text() + '\n[input]\ncolumns = {A9 = "r"}\n'
    path = tmp_path / "model.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_track_model(path)
    assert e.value.line == text.count("\n")  # the columns line
    assert "input.columns.A9: unknown sensor 'A9'" in str(e.value)


def test_the_model_carries_the_input_section():
    doc = tomllib.loads((EXAMPLES / "wsn-range.toml").read_text() + "\n[input]\nmax_gap = 60.0\n")
    assert build_track_model(doc).input.max_gap == 60.0
