"""The p4-bearings experiment: the maneuver kind's [[variants]] and paired [[claim]] verdicts, bearings registrations."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.experiment import ConfigError, load_experiment
from pursuit.experiments.maneuver import log_ratio_interval


@pytest.mark.slow
def test_p4_bearings_reproduces_with_a_verdict_per_claim(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["reproduce", "p4-bearings", "--runs", "4", "--out", str(out), "--no-progress", "--no-pdf"]) == 0
    folder = out / "p4-bearings"
    with (folder / "claims.csv").open() as fh:
        claims = list(csv.DictReader(fh))
    assert len(claims) == 7
    assert {c["variant"] for c in claims} == {"weak 2-D", "strong 2-D", "weak 3-D", "strong 3-D"}
    assert all(c["verdict"] in ("holds", "reversed", "not significant") for c in claims)
    for c in claims:
        assert float(c["ratio_lo95"]) <= float(c["ratio"]) <= float(c["ratio_hi95"])
    for slug in ("weak-2-D", "strong-2-D", "weak-3-D", "strong-3-D"):
        assert (folder / f"rmse-{slug}.csv").exists(), slug
        assert (folder / "figures" / f"rmse_y-{slug}.png").exists(), slug
    assert (folder / "figures" / "rmse_z-strong-3-D.png").exists()
    with (folder / "rmse-strong-3-D.csv").open() as fh:
        names = {r["filter"] for r in csv.DictReader(fh)}
    assert names == {"CS-EKF", "CS-EKF-2", "ACS-EKF", "ACS-UKF", "IMM-Singer"}


def test_paired_log_ratio_interval_against_a_hand_computation():
    rb = np.array([2.0, 4.0, 3.0, 5.0])
    rf = np.array([1.0, 2.0, 2.0, 2.0])
    d = np.log(rf / rb)
    half = 3.182446305284263 * d.std(ddof=1) / 2.0  # t_{0.975, 3}
    m, lo, hi = log_ratio_interval(rb, rf)
    assert m == pytest.approx(d.mean()) and lo == pytest.approx(d.mean() - half) and hi == pytest.approx(d.mean() + half)


BASE = """
[experiment]
kind = "maneuver"
runs = 2

[scenario]
type = "bearings"
horizon = 20

[[variants]]
label = "weak"
strength = "weak"

[[filters]]
type = "cs-nonlinear"
name = "CS"
adaptation = "none"

[[filters]]
type = "cs-nonlinear"
name = "ACS"

[[claim]]
variant = "weak"
baseline = "CS"
filter = "ACS"
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return p


def test_small_config_runs_every_variant(tmp_path):
    plan = load_experiment(_write(tmp_path, BASE)).plan
    out = plan.run(runs=3, seed=1)
    assert [t.name for t in out.tables][0] == "claims"
    assert {"rmse-weak", "segments-weak"} <= {t.name for t in out.tables}
    assert set(out.results) == {"result-weak"}


@pytest.mark.parametrize(
    "change,field",
    [
        (('variant = "weak"', 'variant = "strong"'), "claim[0].variant"),
        (('filter = "ACS"', 'filter = "UKF"'), "claim[0].filter"),
        (('label = "weak"', 'name = "weak"'), "variants[0].label"),
        (('strength = "weak"', 'strength = "mild"'), "strength"),
        (('adaptation = "none"', 'adaptation = "fixed"'), "filters[0].adaptation"),
        (('filter = "ACS"', 'filter = "ACS"\nsteps = "onsets"'), "claim[0].steps"),
    ],
)
def test_config_errors_name_the_field(tmp_path, change, field):
    with pytest.raises(ConfigError) as err:
        load_experiment(_write(tmp_path, BASE.replace(*change, 1)))
    assert field in str(err.value)


def test_singer_and_imm_singer_take_bearings_with_ekf_modes(tmp_path):
    text = BASE + """
[[filters]]
type = "singer"
alpha = 0.05
sigma = 2.0

[[filters]]
type = "imm-singer"
models = [[0.05, 1.0], [0.2, 10.0]]
"""
    plan = load_experiment(_write(tmp_path, text)).plan
    singer, imm = plan.filters[2], plan.filters[3]
    assert type(singer).__name__ == "ExtendedKalmanFilter"
    assert all(type(f).__name__ == "ExtendedKalmanFilter" for f in imm.filters)
