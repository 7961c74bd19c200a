"""MODEL.toml: what it builds, and one clear line naming file, line and field for every mistake."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.experiment import ConfigError
from pursuit.io import load_track_model
from pursuit.models import LinearGaussian, RangeSensors, TimeOfArrival
from pursuit.models.sensors import BearingSensors, StackedMeasurement

BASE = """\
[motion]
type = "cv"
ndim = 2
q = 0.01

[[sensors]]
id = "A"
type = "range"
position = [0.0, 0.0]
sigma = 1.0

[[sensors]]
id = "B"
type = "range"
position = [100.0, 0.0]
sigma = 2.0

[prior]
mean = [10.0, 0.5, 40.0, 0.8]
cov = [4.0, 0.25, 4.0, 0.25]

[filter]
type = "ekf"
"""


def _load(tmp_path, text: str):
    path = tmp_path / "model.toml"
    path.write_text(text)
    return load_track_model(path)


def test_the_base_model(tmp_path):
    model = _load(tmp_path, BASE)
    assert isinstance(model.filter, pu.ExtendedKalmanFilter)
    assert isinstance(model.measurement, RangeSensors)
    np.testing.assert_array_equal(model.measurement.anchors, [[0.0, 0.0], [100.0, 0.0]])
    np.testing.assert_array_equal(np.diag(model.measurement.R), [1.0, 4.0])
    assert model.state_labels == ("x", "vx", "y", "vy")
    assert [s.block for s in model.sensors.values()] == [slice(0, 1), slice(1, 2)]
    assert model.prior_time is None and model.dt == 1.0 and model.name == "model"
    np.testing.assert_array_equal(model.prior.cov, np.diag([4.0, 0.25, 4.0, 0.25]))


def test_mixed_sensors_are_stacked_one_block_per_type(tmp_path):
    text = BASE + """
[[sensors]]
id = "H"
type = "toa"
position = [0.0, 50.0]
sigma = 1e-5

[[sensors]]
id = "gps"
type = "position"
sigma = [3.0, 4.0]

[[sensors]]
id = "cam"
type = "bearing"
position = [50.0, -10.0]
sigma = 0.01
"""
    model = _load(tmp_path, text)
    meas = model.measurement
    assert isinstance(meas, StackedMeasurement)
    assert [type(p) for p in meas.parts] == [RangeSensors, TimeOfArrival, LinearGaussian, BearingSensors]
    blocks = {k: (s.block.start, s.block.stop) for k, s in model.sensors.items()}
    assert blocks == {"A": (0, 1), "B": (1, 2), "H": (2, 3), "gps": (3, 5), "cam": (5, 6)}
    assert meas.dim == 6
    np.testing.assert_allclose(np.diag(meas.R), [1.0, 4.0, 1e-10, 9.0, 16.0, 1e-4])
    x = np.array([[30.0, 1.0, 20.0, -1.0]])
    z = meas.h(x, 1)[0]
    np.testing.assert_allclose(z[:2], [np.hypot(30, 20), np.hypot(70, 20)])
    np.testing.assert_allclose(z[2], np.hypot(30, 30) / 1500.0)
    np.testing.assert_allclose(z[3:5], [30.0, 20.0])
    np.testing.assert_allclose(z[5], np.arctan2(30.0, -20.0))


def test_any_registered_filter_and_its_parameters(tmp_path):
    model = _load(tmp_path, BASE.replace('type = "ekf"', 'type = "ukf"\nalpha = 0.5\ngate = 0.99\nname = "mine"'))
    assert isinstance(model.filter, pu.UnscentedKalmanFilter)
    assert (model.filter.alpha, model.filter.gate, model.filter.name) == (0.5, 0.99, "mine")


def test_an_all_position_model_is_linear_so_the_kf_can_run_it(tmp_path):
    text = BASE.split("[[sensors]]")[0] + """
[[sensors]]
id = "gps"
type = "position"
sigma = 2.0

[[sensors]]
id = "radar"
type = "position"
sigma = 5.0

[prior]
mean = [0.0, 0.0, 0.0, 0.0]
cov = 10.0

[filter]
type = "kf"
"""
    model = _load(tmp_path, text)
    assert isinstance(model.filter, pu.KalmanFilter)
    np.testing.assert_array_equal(model.measurement.H, [[1, 0, 0, 0], [0, 0, 1, 0], [1, 0, 0, 0], [0, 0, 1, 0]])


@pytest.mark.parametrize(
    "old,new,line,message",
    [
        ('type = "cv"', 'type = "cj"', 2, "motion.type: must be one of 'cv', 'ca'"),
        ("q = 0.01", "q = -1.0", 4, "motion.q: must be positive"),
        ("q = 0.01", "", 1, "motion.q: required"),  # a missing key: the line of its table
        ("ndim = 2", "ndim = 5", 3, "motion.ndim: must be 1, 2 or 3"),
        ("ndim = 2", 'ndim = "2"', 3, "motion.ndim: expected an integer"),
        ('id = "B"', 'id = "A"', 13, "sensors[1].id: 'A' is already used by sensors[0]"),
        ('id = "B"', 'id = "a,b"', 13, "sensors[1].id"),
        ("position = [100.0, 0.0]", "position = [100.0]", 15, "sensors[1].position: expected 2 coordinates"),
        ("sigma = 2.0", "sigma = 0.0", 16, "sensors[1].sigma: noise standard deviations must be positive"),
        ("sigma = 2.0", "sigma = 2.0\nc = 1500.0", 17, "sensors[1].c: only a 'toa' sensor"),
        ("sigma = 2.0", "sigma = 2.0\nvalid = [5.0, 1.0]", 17, "sensors[1].valid: expected [low, high]"),
        ("sigma = 2.0", "sigma = 2.0\ncolour = 1", 17, "sensors[1].colour: unknown key"),
        ('type = "range"\nposition = [100.0, 0.0]', 'type = "sonar"\nposition = [100.0, 0.0]', 14, "sensors[1].type: must be one of"),
        ("mean = [10.0, 0.5, 40.0, 0.8]", "mean = [10.0, 0.5]", 19, "prior.mean: expected 4 values"),
        ("cov = [4.0, 0.25, 4.0, 0.25]", "cov = [4.0, -0.25, 4.0, 0.25]", 20, "prior.cov: covariance is not positive definite"),
        ('type = "ekf"', 'type = "magic"', 23, "filter.type: unknown filter 'magic'"),
        ('type = "ekf"', 'type = "ekf"\ngate = 1.5', 24, "filter.gate: must lie in (0, 1)"),
        ('type = "ekf"', 'type = "kf"', 23, "filter.type: KalmanFilter needs a linear measurement model"),
        ("[filter]", "[filters]", 22, "filters: unknown section"),
        ('type = "ekf"', 'type = "ekf"\n[track]\nseed = -1', 25, "track.seed: must be a non-negative integer"),
    ],
)
def test_mistakes_name_file_line_and_field(tmp_path, old, new, line, message):
    assert old in BASE
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, BASE.replace(old, new, 1))
    e = err.value
    assert message in e.message
    assert e.line == line, str(e)
    assert str(e).startswith(f"{tmp_path / 'model.toml'}:{line}:" if line else f"{tmp_path / 'model.toml'}: ")


def test_missing_sections_file_and_syntax(tmp_path):
    with pytest.raises(ConfigError, match="sensors: required section is missing"):
        _load(tmp_path, BASE.split("[[sensors]]")[0] + "[prior]\nmean=[0,0,0,0]\ncov=1.0\n[filter]\ntype='ekf'\n")
    with pytest.raises(ConfigError, match="invalid TOML") as err:
        _load(tmp_path, BASE + "\n[broken\n")
    assert err.value.line == 25
    with pytest.raises(ConfigError, match="file not found"):
        load_track_model(tmp_path / "nope.toml")


def test_bearing_needs_two_dimensions(tmp_path):
    text = BASE.replace("ndim = 2", "ndim = 3").replace("[0.0, 0.0]", "[0.0, 0.0, 0.0]").replace("[100.0, 0.0]", "[100.0, 0.0, 0.0]")
    text = text.replace("mean = [10.0, 0.5, 40.0, 0.8]", "mean = [10.0, 0.5, 40.0, 0.8, 0.0, 0.0]").replace(
        "cov = [4.0, 0.25, 4.0, 0.25]", "cov = [4.0, 0.25, 4.0, 0.25, 1.0, 1.0]"
    )
    model = _load(tmp_path, text)
    assert model.state_labels == ("x", "vx", "y", "vy", "z", "vz")
    with pytest.raises(ConfigError, match="bearing sensors need a 2-D motion model"):
        _load(tmp_path, text.replace('type = "range"', 'type = "bearing"', 1))


# -- magnitudes float64 can square, invert and update with (each used to surface as "199 bad records"
#    or as "sensors[0].Matrix is not positive definite") ------------------------------------------------
@pytest.mark.parametrize(
    "old,new,where",
    [
        ("sigma = 1.0\n", "sigma = 1e200\n", r"model\.toml:10: sensors\[0\]\.sigma: 1e\+200 is outside \[2\^-537, 2\^500\]"),
        ("sigma = 1.0\n", "sigma = 1e-300\n", r"model\.toml:10: sensors\[0\]\.sigma: 1e-300 is outside \[2\^-537, 2\^500\]"),
        ("q = 0.01\n", "q = 1e308\n", r"model\.toml:4: motion\.q: the process noise of one 1 s step is too large for the measurement noise: sensor '[AB]'"),
        ("mean = [10.0,", "mean = [1e308,", r"model\.toml:\d+: prior\.mean: 1e\+308 is beyond ±2\^500"),
        ("position = [100.0, 0.0]", "position = [1e300, 0.0]", r"model\.toml:15: sensors\[1\]\.position: 1e\+300 is beyond ±2\^500"),
        ("cov = [4.0, 0.25, 4.0, 0.25]", "cov = 1e20", r"model\.toml:\d+: prior\.cov: too large for the measurement noise: sensor '[AB]' \(sensors\[\d\]\) would have a predicted variance"),
        ('type = "ekf"\n', 'type = "ekf"\nfading = 1e300\n', r"model\.toml:\d+: filter\.fading: 1e\+300 is beyond 2\^13"),
    ],
    ids=["sigma-1e200", "sigma-1e-300", "q-1e308", "mean-1e308", "position-1e300", "cov-1e20", "fading-1e300"],
)
def test_a_magnitude_float64_cannot_update_with_is_a_bad_model_file_naming_line_and_field(tmp_path, old, new, where):
    assert old in BASE
    with pytest.raises(ConfigError, match=where):
        _load(tmp_path, BASE.replace(old, new, 1))


def test_the_magnitude_limits_are_where_the_rules_put_them(tmp_path):
    # σ at the ends of [2^-537, 2^500] and a prior whose H P Hᵀ / R is just under 2^48 load
    _load(tmp_path, BASE.replace("sigma = 1.0\n", "sigma = 3.0e150\n", 1))
    # a particle filter takes any σ whose square is positive (its weights underflow and it recovers) ...
    pf = BASE.replace('type = "ekf"\n', 'type = "pf"\nparticles = 10\n', 1)
    _load(tmp_path, pf.replace("sigma = 1.0\n", "sigma = 2.3e-162\n", 1))
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.sigma: 2\.1e-162 is outside"):
        _load(tmp_path, pf.replace("sigma = 1.0\n", "sigma = 2.1e-162\n", 1))
    # ... while the EKF holds a tiny R to the prior rule
    with pytest.raises(ConfigError, match=r"prior\.cov: too large for the measurement noise: sensor 'A' \(sensors\[0\]\)"):
        _load(tmp_path, BASE.replace("sigma = 1.0\n", "sigma = 1e-160\n", 1))
    _load(tmp_path, BASE.replace("cov = [4.0, 0.25, 4.0, 0.25]", "cov = [2.8e14, 0.25, 2.8e14, 0.25]", 1))
    with pytest.raises(ConfigError, match=r"prior\.cov: .* scale prior\.cov by at most 0\.9"):
        _load(tmp_path, BASE.replace("cov = [4.0, 0.25, 4.0, 0.25]", "cov = [3.0e14, 0.25, 3.0e14, 0.25]", 1))
    _load(tmp_path, BASE.replace('type = "ekf"\n', 'type = "ekf"\nfading = 8000.0\n', 1))
