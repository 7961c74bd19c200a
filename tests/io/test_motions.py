"""MODEL.toml motions: ct and singer in [motion], and [imm] over mixed motions, each mistake named."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

from pursuit.experiment import ConfigError
from pursuit.filters.imm import InteractingMultipleModel
from pursuit.io import load_track_model, read_records, track_records
from pursuit.models import ConstantAcceleration, ConstantTurn, ConstantVelocity, Singer

from .conftest import csv_text

SENSORS = """
[[sensors]]
id = "gps"
type = "position"
sigma = 5.0

[prior]
from = "measurements"
"""


def _load(tmp_path, text):
    p = tmp_path / "model.toml"
    p.write_text(text)
    return load_track_model(p)


def _motion(body: str, filt: str = "kf") -> str:
    return "[motion]\n" + body + "\n" + SENSORS + f'\n[filter]\ntype = "{filt}"\n'


def test_ct_and_singer_motions(tmp_path):
    ct = _load(tmp_path, _motion('type = "ct"\nomega = 0.05\nq = 0.1\nndim = 3'))
    assert isinstance(ct.motion, ConstantTurn) and ct.motion.omega == 0.05 and ct.motion.ndim == 3
    assert ct.state_labels == ("x", "vx", "y", "vy", "z", "vz")
    singer = _load(tmp_path, _motion('type = "singer"\nalpha = 0.1\nsigma = 2.0\ndt = 0.5'))
    assert isinstance(singer.motion, Singer) and (singer.motion.alpha, singer.motion.sigma, singer.motion.dt) == (0.1, 2.0, 0.5)
    assert singer.state_labels == ("x", "vx", "ax", "y", "vy", "ay")


@pytest.mark.parametrize(
    "body, message",
    [
        ('type = "ct"\nq = 0.1', "motion.omega: required for a 'ct' motion"),
        ('type = "ct"\nomega = 0.1\nq = 0.1\nndim = 1', "motion.type: a 'ct' motion turns in the x-y plane: it needs ndim = 2 or 3, got 1"),
        ('type = "ct"\nomega = inf\nq = 0.1', "motion.omega: must be finite, got inf"),
        ('type = "ct"\nomega = 0.1\nq = 0.1\nnoise = "continuous"', "motion.noise: a 'ct' motion has its own process noise"),
        ('type = "cv"\nq = 0.1\nomega = 0.1', "motion.omega: a 'cv' motion has no turn rate (only ct)"),
        ('type = "cv"', "motion.q: required for a 'cv' motion"),
        ('type = "singer"\nalpha = 0.1', "motion.sigma: required for a 'singer' motion"),
        ('type = "singer"\nalpha = -1.0\nsigma = 1.0', "motion.alpha: must be a positive number"),
        ('type = "singer"\nalpha = 0.1\nsigma = 1.0\nq = 1.0', "motion.q: a 'singer' motion has no noise intensity"),
        ('type = "jerk"\nq = 1.0', "motion.type"),
    ],
)
def test_motion_mistakes_name_the_field_and_line(tmp_path, body, message):
    with pytest.raises(ConfigError, match=re.escape(message)) as e:
        _load(tmp_path, _motion(body))
    field = message.split(":", 1)[0].split(".")[1]
    line = (tmp_path / "model.toml").read_text().splitlines()[e.value.line - 1]
    # the line of the field itself, or of its table when the field is missing
    assert line == "[motion]" if "required" in message else line.startswith(field), line


IMM = """
[imm]
transition = 0.95
[[imm.modes]]
type = "cv"
q = 0.01
[[imm.modes]]
type = "ct"
omega = 0.1
q = 0.01
[[imm.modes]]
type = "ca"
q = 0.1
"""


def test_imm_over_mixed_motions(tmp_path):
    model = _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "kf"\ngate = 0.999\n')
    f = model.filter
    assert isinstance(f, InteractingMultipleModel) and f.gate == 0.999
    assert [type(m.motion) for m in f.filters] == [ConstantVelocity, ConstantTurn, ConstantAcceleration]
    assert isinstance(model.motion, ConstantAcceleration)  # the largest state is the common one
    assert model.state_labels == ("x", "vx", "ax", "y", "vy", "ay")
    assert f.maps[0].indices == (0, 1, 3, 4) and f.maps[1].indices == (0, 1, 3, 4) and f.maps[2] is None
    np.testing.assert_allclose(np.diag(f.transition), 0.95)


@pytest.mark.parametrize(
    "text, message",
    [
        (IMM.replace("q = 0.1\n", ""), "imm.modes[2].q: required for a 'ca' motion"),
        (IMM.replace("omega = 0.1\n", "omega = 0.1\nsigma = 2.0\n"), "imm.modes[1].sigma: a 'ct' motion has no"),
        (IMM.replace("transition = 0.95", "transition = [[0.9, 0.1], [0.1, 0.9]]"), "imm.transition: expected a 3x3 matrix"),
        (IMM.replace("transition = 0.95", "initial_probs = [0.5, 0.5]"), "imm.initial_probs: expected 3"),
        ("[imm]\n[[imm.modes]]\ntype = \"cv\"\nq = 1.0\n", "imm.modes: expected two or more"),
        (IMM + '[motion]\ntype = "cv"\nq = 1.0\n', "imm: give either [motion]"),
    ],
)
def test_imm_mistakes_name_the_field(tmp_path, text, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        _load(tmp_path, text + SENSORS + '\n[filter]\ntype = "kf"\n')


def test_imm_needs_a_filter_that_runs_each_mode(tmp_path):
    with pytest.raises(ConfigError, match="filter.type: with \\[imm\\] the filter runs each mode"):
        _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "pf"\n')
    with pytest.raises(ConfigError, match="filter.gate: .* got 2"):
        _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "kf"\ngate = 2\n')
    with pytest.raises(ConfigError, match="filter.name: expected a string, got 3"):
        _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "kf"\nname = 3\n')
    named = _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "ekf"\nname = "mixed"\n')
    assert named.filter.name == "mixed" and [f.name for f in named.filter.filters] == ["EKF cv", "EKF ct", "EKF ca"]


def _turning_target(rng):
    """60 s straight at 10 m/s, then 40 s of a 0.15 rad/s turn, fixes with 5 m noise each second."""
    x = np.array([0.0, 10.0, 0.0, 0.0])
    states = []
    for k in range(100):
        omega = 0.0 if k < 60 else 0.15
        x = ConstantTurn(omega=omega, q=1e-4, ndim=2).sample(x, k, rng)
        states.append(x)
    truth = np.array(states)
    z = truth[:, [0, 2]] + rng.normal(0.0, 5.0, size=(100, 2))
    return truth, z


def test_an_imm_with_a_turn_mode_follows_a_turn_a_cv_filter_loses(tmp_path):
    rng = np.random.default_rng(7)
    truth, z = _turning_target(rng)
    rows = [(float(k + 1), "gps", *z[k]) for k in range(100)]
    imm_text = IMM.replace("omega = 0.1", "omega = 0.15") + SENSORS + '\n[filter]\ntype = "kf"\n'
    cv_text = _motion('type = "cv"\nq = 0.01')

    def turn_rmse(text):
        model = _load(tmp_path, text)
        est = track_records(read_records(io.BytesIO(csv_text(rows).encode()), "csv"), model).estimates
        assert len(est) == 100
        pos = np.array([[e.mean[i] for i in model.position_indices] for e in est])
        err = pos[65:] - truth[65:, [0, 2]]
        return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))

    imm, cv = turn_rmse(imm_text), turn_rmse(cv_text)
    print(f"position RMSE in the turn: IMM {imm:.2f} m, CV {cv:.2f} m")
    assert imm < 0.5 * cv, (imm, cv)


def test_pursuit_run_on_an_imm_model_says_it_is_a_track_model(tmp_path, capsys):
    from pursuit.cli import main

    path = tmp_path / "imm.toml"
    path.write_text(IMM + SENSORS + '\n[filter]\ntype = "kf"\n')
    assert main(["run", str(path)]) == 2
    assert "this is a `pursuit track` model file, not an experiment" in capsys.readouterr().err


# --------------------------------------------------------------------------
# magnitude checks reach every mode of an [imm] (found in review: they read [motion] and the IMM only)
# --------------------------------------------------------------------------
PRIOR6 = """
[[sensors]]
id = "gps"
type = "position"
sigma = 5.0

[prior]
mean = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]
cov = [100.0, 10.0, 1.0, 100.0, 10.0, 1.0]
"""


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("type = \"ct\"\nomega = 0.1\nq = 0.01", "type = \"ct\"\nomega = 0.1\nq = 1e20", "imm.modes[1].q: the process noise of one 1 s step is"),
        ("type = \"cv\"\nq = 0.01", "type = \"singer\"\nalpha = 0.1\nsigma = 1e12", "imm.modes[0].sigma: the process noise"),
    ],
)
def test_every_imm_modes_process_noise_is_checked_and_named(tmp_path, old, new, message):
    assert old in IMM
    with pytest.raises(ConfigError, match=re.escape(message)) as e:
        _load(tmp_path, IMM.replace(old, new) + PRIOR6 + '\n[filter]\ntype = "kf"\n')
    assert e.value.line is not None  # the mode's own line, not "199 bad records" after loading
    _load(tmp_path, IMM + PRIOR6 + '\n[filter]\ntype = "kf"\n')  # the same file with sane values loads


def test_a_singer_models_noise_is_named_by_its_sigma(tmp_path):
    with pytest.raises(ConfigError, match=re.escape("motion.sigma: the process noise of one 1 s step is")):
        _load(tmp_path, "[motion]\ntype = \"singer\"\nalpha = 0.1\nsigma = 1e12\nndim = 2\n" + PRIOR6 + '\n[filter]\ntype = "kf"\n')


def test_the_fading_limit_holds_for_every_imm_mode(tmp_path):
    with pytest.raises(ConfigError, match=re.escape("filter.fading: 1e+06 is beyond 2^13")):
        _load(tmp_path, IMM + SENSORS + '\n[filter]\ntype = "ekf"\nfading = 1.0e6\n')
