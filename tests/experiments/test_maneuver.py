"""The p4-maneuver experiment, the maneuver experiment kind and the maneuvering registrations."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from pursuit import registry
from pursuit.cli import main
from pursuit.engine.montecarlo import monte_carlo
from pursuit.experiment import ConfigError, find_experiment, load_experiment

P4 = find_experiment("p4-maneuver")


@pytest.mark.slow
def test_p4_maneuver_reproduces_with_tables_and_figures(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["reproduce", "p4-maneuver", "--runs", "6", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "Table 2" in printed and "APCS" in printed and "IMM-Singer" in printed
    folder = out / "p4-maneuver"
    for name in ("rmse", "segments", "detections", "claims"):
        assert (folder / f"{name}.csv").exists(), name
    for fig in ("rmse_x", "rmse_y", "rmse_z", "rmse_zoom", "mode_probabilities", "detections"):
        assert (folder / "figures" / f"{fig}.png").exists(), fig
    with (folder / "rmse.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {r["filter"] for r in rows} == {"CS", "APCS", "Singer", "IMM-Singer", "MS"}
    assert {r["axis"] for r in rows} == {"x", "y", "z"}
    assert all(float(r["position_m"]) > 0 for r in rows)
    # each filter's count of diverged runs, beside its RMSE (the same on every axis row)
    counts = {(r["filter"], int(r["diverged"])) for r in rows}
    assert len(counts) == 5 and all(0 <= n <= 6 for _, n in counts)
    meta = json.loads((folder / "run.json").read_text())
    assert meta["strongest_maneuver"] == {"axis": "y", "time_s": 67.0, "jump_m_s2": 90.0}
    assert meta["runs"] == 6


def test_results_do_not_depend_on_the_chunk_size():
    exp = load_experiment(P4)
    plan = exp.plan
    a = monte_carlo(plan.scenario, plan.filters, 7, 11, chunk_size=7)
    b = monte_carlo(plan.scenario, plan.filters, 7, 11, chunk_size=3)
    for name in a.filter_names:
        assert np.array_equal(a.filters[name].estimates, b.filters[name].estimates), name
        assert np.array_equal(a.filters[name].covariances, b.filters[name].covariances), name


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return p


BASE = """
[experiment]
kind = "maneuver"
runs = 2

[scenario]
type = "maneuver-3d"
horizon = 30

[[scenario.maneuvers]]
axis = "y"
start = 10
stop = 15
accel = 20.0

[[filters]]
type = "cs"

[[filters]]
type = "apcs"
"""


@pytest.mark.parametrize(
    "change,field,line",
    [
        (("accel = 20.0", "accel = 20.0\nspeed = 3"), "scenario.maneuvers[0].speed", 15),
        (('type = "apcs"', 'type = "apcs"\nalpha_max = 2.0'), "filters[1].alpha_max", 21),
        (('type = "apcs"', 'type = "apcs"\nvariance = "cubic"'), "filters[1].variance", 21),
        (('type = "cs"', 'type = "cs"\nalpha = -1.0'), "filters[0].alpha", 18),
        (("horizon = 30", "horizon = 2"), "scenario.horizon", 8),
        (('type = "apcs"', 'type = "apcs"\n\n[claims]\nbaseline = "KF"'), "claims.baseline", 23),
    ],
)
def test_config_errors_name_file_line_and_field(tmp_path, change, field, line):
    p = _write(tmp_path, BASE.replace(*change, 1))
    with pytest.raises(ConfigError) as err:
        load_experiment(p)
    assert field in str(err.value)
    assert err.value.line == line, str(err.value)


def test_cs_family_filters_refuse_other_state_layouts(tmp_path):
    text = """
[experiment]
kind = "montecarlo"
[scenario]
type = "cv-position"
[[filters]]
type = "apcs"
"""
    with pytest.raises(ConfigError, match=r"filters\[0\]\.type: needs a scenario with a \[p, v, a\] state"):
        load_experiment(_write(tmp_path, text))


def test_generic_imm_builds_its_models_from_filter_tables(tmp_path):
    text = BASE + """
[[filters]]
type = "imm"
name = "IMM-CS"
transition = [[0.9, 0.1], [0.2, 0.8]]
models = [{type = "cs", alpha = 0.01}, {type = "singer", alpha = 0.1, sigma = 30.0}]
"""
    exp = load_experiment(_write(tmp_path, text))
    imm = exp.plan.filters[-1]
    assert imm.name == "IMM-CS" and imm.modes == 2
    np.testing.assert_allclose(imm.transition, [[0.9, 0.1], [0.2, 0.8]])
    out = exp.run(runs=2, seed=1)
    assert np.allclose(out.results["result"].filters["IMM-CS"].info["mode_probs"].sum(axis=-1), 1.0)
    bad = text.replace("alpha = 0.01}", "alpha = 0.01, bogus = 1}")
    with pytest.raises(ConfigError, match=r"filters\[2\]\.models\[0\]\.bogus"):
        load_experiment(_write(tmp_path, bad))


def test_registrations_are_listed():
    names = {c.name for c in registry.components("filter")}
    assert {"cs", "apcs", "ms", "singer", "imm-singer", "imm"} <= names
    assert {"singer", "cs", "jerk", "ct", "coordinated-turn"} <= {c.name for c in registry.components("model")}
    assert "maneuver-3d" in {c.name for c in registry.components("scenario")}
    assert "maneuver" in {c.name for c in registry.components("experiment")}
