"""The ``sweep`` experiment kind and the particle-filter registrations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pursuit import registry
from pursuit.cli import main
from pursuit.experiments.sweep import paired_difference
from pursuit.experiment import ConfigError, find_experiment, load_experiment

SMALL = """
[experiment]
kind = "sweep"
runs = 6
seed = 3

[scenario]
type = "ungm"
steps = 12

[[filters]]
type = "pf"
name = "PF"

[[filters]]
type = "ics-pf"
name = "ICS-PF"
n_iter = 2

[[filters]]
type = "ekf"

[sweep]
parameter = "particles"
label = "N"
values = [20, 40]
pairs = [["ICS-PF", "PF"], ["PF", "EKF"]]

[figures]
values = [40]
snapshot_steps = [2, 12]

[[paper]]
filter = "PF"
metric = "rmse"
at = 40
value = 4.7
note = "made up"
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return p


def test_a_sweep_runs_every_value_and_reports_paper_beside_measured(tmp_path):
    exp = load_experiment(_write(tmp_path, SMALL))
    out = exp.run()
    summary, paper, pairs = out.tables
    assert summary.columns[:4] == ["N", "filter", "rmse", "ci95"]
    rows = {(r[0], r[1]) for r in summary.rows}
    assert rows == {(20, "PF"), (20, "ICS-PF"), (None, "EKF"), (40, "PF"), (40, "ICS-PF")}
    assert paper.kind == "paper" and paper.columns[3:5] == ["paper", "measured"]
    pf40 = next(r for r in summary.rows if r[0] == 40 and r[1] == "PF")
    assert paper.rows[0][3] == 4.7 and paper.rows[0][4] == pf40[2]
    assert {r[1] for r in pairs.rows} == {"ICS-PF", "PF"} and len(pairs.rows) == 4
    # each row counts its filter's diverged runs at that value, beside the RMSE
    col = summary.columns.index("diverged")
    for row in summary.rows:
        at = 20 if row[0] is None else row[0]  # a baseline runs once, with the first value
        assert row[col] == out.results[f"N={at}"].divergence(row[1])["diverged"]
    assert {"rmse_vs_N", "time_vs_N", "N40_estimates", "N40_abs_error", "N40_rmse", "N40_particles"} <= set(out.figures)


def test_the_same_seed_gives_the_same_tables(tmp_path):
    a = load_experiment(_write(tmp_path, SMALL)).run()
    b = load_experiment(_write(tmp_path, SMALL)).run()
    for ta, tb in zip(a.tables, b.tables):
        cols = [i for i, c in enumerate(ta.columns) if c != "wall_time_s"]
        assert [[r[i] for i in cols] for r in ta.rows] == [[r[i] for i in cols] for r in tb.rows]


@pytest.mark.parametrize(
    "edit, field",
    [
        (("values = [20, 40]", "values = []"), "sweep.values"),
        (('parameter = "particles"', 'parameter = "nonsense"'), "sweep.parameter"),
        (("values = [20, 40]", "values = [20, -1]"), "particles"),
        (('pairs = [["ICS-PF", "PF"], ["PF", "EKF"]]', 'pairs = [["ICS-PF", "XX"]]'), "sweep.pairs"),
        (('filter = "PF"\nmetric', 'filter = "XX"\nmetric'), "paper[0].filter"),
        (("n_iter = 2", "n_iter = -3"), "n_iter"),
        (('type = "ics-pf"', 'type = "ics-pff"'), "filters[1].type"),
        (("snapshot_steps = [2, 12]", "snapshot_steps = [0]"), "figures.snapshot_steps"),
        # impossible values that were accepted silently
        (('metric = "rmse"', 'metric = "rsme"'), "paper[0].metric: no summary column 'rsme' (have rmse, ci95, rms_x, "),
        (("at = 40", "at = 30"), "paper[0].at: 30 is not a swept value (sweep.values = [20, 40])"),
        (('name = "PF"\n', 'name = "PF"\nparticles = 500\n'), "filters[0].particles: set here but swept by [sweep]"),
        (("[figures]\nvalues = [40]", "[figures]\nvalues = [nan]"), "figures.values: expected finite numbers, got nan"),
        (("[figures]\nvalues = [40]", "[figures]\nvalues = [30]"), "figures.values[0]: 30 is not a swept value"),
        (("snapshot_steps = [2, 12]", "snapshot_steps = [2, 12]\nsnapshot_value = 25"), "figures.snapshot_value: 25 is"),
        (("values = [20, 40]", "values = [20, inf]"), "sweep.values: expected finite numbers, got inf"),
    ],
)
def test_bad_sweep_files_name_the_field(tmp_path, edit, field):
    old, new = edit
    assert old in SMALL
    with pytest.raises(ConfigError) as err:
        load_experiment(_write(tmp_path, SMALL.replace(old, new, 1)))
    assert field in str(err.value)


def test_paired_difference_verdicts():
    rng = np.random.default_rng(0)
    a = rng.normal(1.0, 0.1, 200)
    assert paired_difference(a, a + 0.5)[2] == "A < B"
    assert paired_difference(a + 0.5, a)[2] == "A > B"
    assert paired_difference(a, a + rng.normal(0, 0.1, 200))[2] == "no difference shown"


@pytest.mark.parametrize("name", ["p1-ungm", "p1-wsn", "p3-upf"])
def test_the_bundled_experiments_load(name):
    exp = load_experiment(find_experiment(name))
    assert exp.kind == "sweep" and exp.runs == 100


def test_reproduce_prints_the_paper_table_and_writes_figures(tmp_path, capsys):
    code = main(["reproduce", "p1-ungm", "--runs", "3", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "Paper's values (source: paper) beside ours (source: measured)" in text
    assert "6.0001" in text  # the paper's PF value at N = 30
    figs = {p.name for p in (tmp_path / "p1-ungm" / "figures").iterdir()}
    assert {"N30_estimates.png", "N100_abs_error.png", "N100_rmse.png", "N100_particles.png", "rmse_vs_N.png"} <= figs
    assert (tmp_path / "p1-ungm" / "paper_vs_measured.csv").exists()


def test_particle_filters_and_ungm_are_registered():
    names = {c.name for c in registry.components("filter")}
    assert {"pf", "upf", "cs-pf", "ics-pf"} <= names
    assert registry.get("filter", "sir").name == "pf"
    assert "ungm" in {c.name for c in registry.components("scenario")}


WSN_SMALL = (
    SMALL.replace('type = "ungm"\nsteps = 12', 'type = "wsn-range"\nsteps = 8\nanchors = [[0.0, 0.0], [100.0, 0.0]]')
    .replace("[sweep]", '[sweep]\ncomponent = "position"')
    .replace("snapshot_steps = [2, 12]", "snapshot_steps = [2, 8]")
)


def _labels(figures):
    return {
        name: [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.get_axes() if ax.get_visible()]
        for name, fig in figures.items()
    }


def test_sweep_figures_carry_the_scenarios_units(tmp_path):
    # every axis of a physical quantity carries the unit the scenario declares (metres here), and the
    # one-run error plot's x axis is time in seconds (it plots result.times)
    out = load_experiment(_write(tmp_path, WSN_SMALL)).run(runs=3, seed=1)
    labels = _labels(out.figures)
    assert labels["rmse_vs_N"] == [("particles N", "position RMSE (m)")]  # the quantity's name, not only its symbol
    assert labels["time_vs_N"] == [("particles N", "filter wall time, all runs (s)")]
    assert labels["N40_rmse"] == [("time (s)", "position RMSE (m)")]
    assert labels["N40_estimates"] == [("x (m)", "y (m)")]
    assert set(labels["N40_particles"]) == {("particle index", "x (m)")}


def test_sweep_figures_of_a_dimensionless_state_show_no_made_up_unit(tmp_path):
    out = load_experiment(_write(tmp_path, SMALL)).run(runs=3, seed=1)
    labels = _labels(out.figures)
    assert labels["N40_abs_error"] == [("time (s)", "|x error|")]  # UNGM's x is dimensionless
    assert labels["N40_rmse"] == [("time (s)", "state RMSE")]
    assert labels["rmse_vs_N"] == [("particles N", "state RMSE")]
