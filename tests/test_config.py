"""Experiment files: a good one loads; every kind of bad one gets one clear line."""

import textwrap

import pytest

from pursuit.experiment import ConfigError, find_experiment, list_experiments, load_experiment, locate

GOOD = """\
[experiment]
title = "test"
runs = 3
seed = 1

[scenario]
type = "wsn-range"
sigma = 1.0
steps = 5
P0 = [4.0, 0.25, 4.0, 0.25]

[[filters]]
type = "ekf"

[[filters]]
type = "ukf"
alpha = 0.5
"""


def write(tmp_path, text, name="exp.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_good_file_loads(tmp_path):
    exp = load_experiment(write(tmp_path, GOOD))
    assert exp.name == "exp" and exp.runs == 3 and exp.seed == 1 and exp.kind == "montecarlo"
    assert [f.name for f in exp.plan.filters] == ["EKF", "UKF"]
    assert exp.plan.filters[1].alpha == 0.5


def test_bundled_experiments_load():
    names = list_experiments()
    assert "wsn-gaussian" in names
    for name in names:
        load_experiment(find_experiment(name))


def test_cpu_s_defaults_to_zero_and_is_read(tmp_path):
    assert load_experiment(write(tmp_path, GOOD)).cpu_s == 0.0
    assert load_experiment(write(tmp_path, GOOD.replace("seed = 1", "seed = 1\ncpu_s = 12.5"))).cpu_s == 12.5
    # every bundled experiment says what it costs, so that reproduce --workers starts the costliest first
    assert all(load_experiment(find_experiment(n)).cpu_s > 0 for n in list_experiments())


@pytest.mark.parametrize(
    "old,new,field,line",
    [
        ('sigma = 1.0', 'sigma = 1.0\ncolour = "red"', "scenario.colour: unknown key", 9),
        ('sigma = 1.0', 'sigma = "big"', "scenario.sigma: expected a number", 8),
        ('sigma = 1.0', 'sigma = -1.0', "scenario.sigma: must be positive", 8),
        ('P0 = [4.0, 0.25, 4.0, 0.25]', 'P0 = [[1.0, 2.0, 0.0, 0.0], [2.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]', "scenario.P0: covariance is not positive definite", 10),
        ('P0 = [4.0, 0.25, 4.0, 0.25]', 'P0 = [4.0, 0.25, 4.0]', "scenario.P0: expected a 4x4 matrix", 10),
        ("runs = 3", "runs = 0", "experiment.runs: must be at least 1", 3),
        ("runs = 3", "runs = 2.5", "experiment.runs: expected an integer", 3),
        ("seed = 1", "seed = -4", "experiment.seed: must be a non-negative integer", 4),
        ("seed = 1", "seed = 1\ncpu_s = -2.0", "experiment.cpu_s: must be a number of seconds >= 0", 5),
        ("seed = 1", "seed = 1\ncpu_s = nan", "experiment.cpu_s: must be finite", 5),
        ('type = "ukf"', 'type = "xkf"', "filters[1].type: unknown filter 'xkf'", 16),
        ("alpha = 0.5", "alpha = -0.5", "filters[1].alpha: must lie in", 17),
        ("alpha = 0.5", "fading = 0.5", "filters[1].fading.lam: must lie in", 17),
        ("alpha = 0.5", "kappa = -4.0", "filters[1].kappa: must exceed -n = -4", 17),  # n + κ = 0: no sigma points
        ("alpha = 0.5", "kappa = -7.5", "filters[1].kappa: must exceed -n = -4", 17),
        ("alpha = 0.5", 'name = "EKF"', "filters: names must be unique", None),
        ('type = "wsn-range"', 'type = "moon"', "scenario.type: unknown scenario 'moon'", 7),
        ("[experiment]", "[experimant]\n[experiment]", "experimant: unknown section", None),
    ],
)
def test_bad_values_name_file_line_and_field(tmp_path, old, new, field, line):
    assert old in GOOD
    p = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_experiment(p)
    msg = str(info.value)
    assert field in msg
    assert msg.startswith(str(p))
    if line is not None:
        assert info.value.line == line, msg
        assert msg.startswith(f"{p}:{line}: ")
    assert "\n" not in msg


def test_paper_values_are_checked(tmp_path):
    ok = GOOD + '\n[[paper]]\nfilter = "EKF"\nmetric = "rmse_position"\nvalue = 1.5\n'
    load_experiment(write(tmp_path, ok))
    bad = ok.replace('filter = "EKF"', 'filter = "PF"')
    with pytest.raises(ConfigError, match=r"paper\[0\]\.filter: no filter named 'PF'"):
        load_experiment(write(tmp_path, bad, "bad.toml"))
    # a metric that is no summary column gave an empty "measured" cell, silently
    typo = ok.replace('metric = "rmse_position"', 'metric = "rmse_postion"')
    with pytest.raises(ConfigError, match=r"bad2.toml:\d+: paper\[0\]\.metric: no summary column 'rmse_postion' \(have rmse_position, "):
        load_experiment(write(tmp_path, typo, "bad2.toml"))


def test_missing_sections_and_files(tmp_path):
    with pytest.raises(ConfigError, match="filters: required section"):
        load_experiment(write(tmp_path, GOOD.split("[[filters]]")[0]))
    with pytest.raises(ConfigError, match="file not found"):
        load_experiment(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="invalid TOML") as info:
        load_experiment(write(tmp_path, GOOD + "\nthis is not toml\n", "broken.toml"))
    assert info.value.line == 19
    with pytest.raises(ConfigError, match="no experiment named"):
        find_experiment("no-such-experiment")


def test_locate():
    text = GOOD
    assert locate(text, "scenario.sigma") == 8
    assert locate(text, "filters[1].alpha") == 17
    assert locate(text, "filters[1]") == 15
    assert locate(text, "filters[1].fading.lam") == 15
    assert locate(text, "nothing.here") is None


@pytest.mark.parametrize(
    "fading,lam",
    [
        ('{ type = "tfmkf" }', 1.23),  # paper P2's TFMKF
        ('{ type = "tfmkf", lam = 1.5 }', 1.5),
        ('{ type = "constant" }', 1.0),  # the plain filter unless told
        ("1.23", 1.23),
    ],
)
def test_constant_fading_types_and_their_defaults(tmp_path, fading, lam):
    exp = load_experiment(write(tmp_path, GOOD.replace("alpha = 0.5", f"fading = {fading}")))
    strategy = exp.plan.filters[1].fading
    assert type(strategy).__name__ == "Constant"
    assert strategy.lam == lam


def test_tfmkf_refuses_an_impossible_factor_naming_the_field(tmp_path):
    p = write(tmp_path, GOOD.replace("alpha = 0.5", 'fading = { type = "tfmkf", lam = 0.5 }'))
    with pytest.raises(ConfigError, match=r"filters\[1\]\.fading\.lam: must lie in") as info:
        load_experiment(p)
    assert info.value.line == 17


def test_kappa_just_above_minus_n_is_accepted(tmp_path):
    exp = load_experiment(write(tmp_path, GOOD.replace("alpha = 0.5", "kappa = -3.5")))
    assert exp.plan.filters[1].kappa == -3.5


def test_cli_refuses_a_kappa_without_sigma_points_with_exit_2_and_writes_nothing(tmp_path, capsys):
    # Before the check in UnscentedKalmanFilter.__post_init__ this ran, wrote
    # the output folder and died at the first step with a traceback (exit 1).
    from pursuit.cli import main

    p = write(tmp_path, GOOD.replace("alpha = 0.5", "kappa = -4.0"))
    out = tmp_path / "out"
    assert main(["run", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith(f"pursuit: error: {p}:17: filters[1].kappa: must exceed -n = -4")
    assert list(tmp_path.iterdir()) == [p]


@pytest.mark.parametrize(
    "fading, field",
    [("1e5", "filters[0].fading: 100000 is beyond 2^13"), ('{type = "constant", lam = 1e300}', "filters[0].fading.lam: 1e+300 is beyond 2^13")],
)
def test_a_constant_fading_factor_beyond_the_model_files_limit_is_refused(tmp_path, fading, field):
    # the limit of model files (docs/track.md), for experiment files too: λ = 1e300 overflowed the EKF's covariance
    from pursuit.experiment import ConfigError, load_experiment

    path = tmp_path / "e.toml"
    path.write_text(f'[experiment]\nruns = 2\n[scenario]\ntype = "cv-position"\n[[filters]]\ntype = "kf"\nfading = {fading}\n')
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert field in str(info.value)
    path.write_text('[experiment]\nruns = 2\n[scenario]\ntype = "cv-position"\n[[filters]]\ntype = "kf"\nfading = 8192\n')
    load_experiment(path)  # 2^13 itself is accepted
