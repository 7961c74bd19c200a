"""The ``conditions`` experiment kind and the bundled ``p2-toa`` experiment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pursuit import metrics
from pursuit.cli import main
from pursuit.experiments.conditions import improvement
from pursuit.experiment import ConfigError, load_experiment

ROOT = Path(__file__).resolve().parents[2]
P2 = ROOT / "experiments" / "p2-toa.toml"


@pytest.fixture(scope="module")
def p2_output():
    return load_experiment(P2).run(runs=6, seed=11)


def _table(output, name):
    return next(t for t in output.tables if t.name == name)


def test_p2_experiment_produces_its_tables_and_figures(p2_output):
    names = [t.name for t in p2_output.tables]
    assert names == ["cumulative_rmse", "improvement", "paper_vs_measured", "fading", "details"]
    rmse = _table(p2_output, "cumulative_rmse")
    assert rmse.columns == ["filter", "ideal_m", "actual_m", "abnormal_m", "ideal_diverged", "actual_diverged", "abnormal_diverged"]
    assert [r[0] for r in rmse.rows] == ["EKF", "TFMKF", "EWFMKF", "STF", "IFMKF"]
    assert all(np.isfinite(v) and v > 0 for r in rmse.rows for v in r[1:4])
    # each condition's count of diverged runs, beside its RMSE
    for r in rmse.rows:
        assert r[4:] == [p2_output.results[c].divergence(r[0])["diverged"] for c in ("ideal", "actual", "abnormal")]
    assert sorted(p2_output.figures) == [
        "consistency_abnormal", "consistency_actual", "consistency_ideal",
        "fading_factor", "rmse_position_abnormal", "rmse_position_actual", "rmse_position_ideal",
    ]


def test_paper_table_puts_the_papers_numbers_beside_measured_ones(p2_output):
    paper = _table(p2_output, "paper_vs_measured")
    assert paper.kind == "paper"
    assert "paper" in paper.columns and "measured" in paper.columns
    assert [r[4] for r in paper.rows] == [19.4, 21.4, 78.4, 48.8]
    for cond, filt, base, metric, _, measured, _ in paper.rows:
        result = p2_output.results[cond]
        assert measured == improvement(result, filt, base)["improvement_pct"]


def test_cumulative_rmse_is_the_mean_of_per_run_rmse(p2_output):
    rmse = _table(p2_output, "cumulative_rmse")
    result = p2_output.results["actual"]
    for row in rmse.rows:
        per_run = metrics.rmse_per_run(result.squared_error(row[0], "position"))
        assert row[2] == pytest.approx(per_run.mean(), rel=1e-12)


def test_fading_table_reports_ifmkf_flags(p2_output):
    rows = {(r[0], r[1]): r for r in _table(p2_output, "fading").rows}
    assert rows[("ideal", "EKF")][2:5] == [1.0, 1.0, 0.0]
    assert rows[("ideal", "TFMKF")][2] == pytest.approx(1.23)
    assert rows[("abnormal", "IFMKF")][6] == 6  # the outlier is gated in every run
    assert rows[("actual", "IFMKF")][5] > 50  # diverging most of the time under the unknown drift


def test_results_do_not_depend_on_the_chunk_size(p2_output):
    again = load_experiment(P2).run(runs=6, seed=11, chunk_size=4)
    for a, b in zip(p2_output.tables, again.tables):
        if a.name == "details":  # holds wall times
            continue
        assert repr(a.rows) == repr(b.rows), a.name  # repr: NaN equals NaN


def test_improvement_by_hand():
    class Fake:
        def squared_error(self, name, component):
            return {"a": np.array([[1.0, 4.0], [1.0, 4.0]]), "b": np.array([[4.0, 16.0], [4.0, 16.0]])}[name]

        def rmse(self, name, component, average):
            return float(metrics.rmse_per_run(self.squared_error(name, component)).mean())

    imp = improvement(Fake(), "a", "b")
    # per-run RMSE: a = (1, 2), b = (2, 4); E_a = 1.5, E_b = 3
    assert imp["improvement_pct"] == pytest.approx(50.0)
    assert imp["runs_better"] == 1.0


BASE = """
[experiment]
kind = "conditions"
runs = 2

[scenario]
type = "underwater-toa"
steps = 8

[[conditions]]
name = "ideal"
condition = "ideal"

[[conditions]]
name = "abnormal"
condition = "abnormal"

[[filters]]
type = "ekf"
name = "EKF"

[[filters]]
type = "ekf"
name = "IFMKF"
fading = { type = "ifmkf" }
"""


def _load(tmp_path, text):
    path = tmp_path / "exp.toml"
    path.write_text(text)
    return load_experiment(path)


def test_a_small_conditions_experiment_runs(tmp_path):
    out = _load(tmp_path, BASE).run()
    assert list(out.results) == ["ideal", "abnormal"]
    assert _table(out, "improvement").rows[0][:3] == ["ideal", "IFMKF", "EKF"]


@pytest.mark.parametrize(
    "extra,replace,message,line",
    [
        ("", ('condition = "abnormal"', 'condition = "worse"'), "conditions[1].condition: must be one of", 16),
        ("", ('condition = "abnormal"', "sigma_r = -1.0"), "conditions[1].sigma_r: must be positive", 16),
        ("", ('name = "abnormal"', 'name = "ideal"'), "conditions[1].name: repeated condition", 15),
        ("", ('name = "abnormal"\n', 'type = "wsn-range"\nname = "abnormal"\n'), "conditions[1].type: a condition overrides", 15),
        ("[compare]\nfilter = \"UKF\"\n", None, "compare.filter: no filter named 'UKF'", None),
        ("[bogus]\nx = 1\n", None, "bogus: unknown section", None),
        (
            '[[paper]]\ncondition = "ideal"\nfilter = "IFMKF"\nmetric = "improvement_pct"\nvalue = 19.4\n',
            None,
            "paper[0].baseline: metric improvement_pct needs a baseline",
            None,
        ),
        (
            '[[paper]]\ncondition = "actual"\nfilter = "IFMKF"\nbaseline = "EKF"\nmetric = "improvement_pct"\nvalue = 19.4\n',
            None,
            "paper[0].condition: no condition named 'actual'",
            None,
        ),
        ("", ('fading = { type = "ifmkf" }', 'fading = { type = "ifmkf", window = 0 }'), "filters[1].fading.window: must be at least 1", None),
        ("", ('fading = { type = "ifmkf" }', 'fading = { type = "ifmkf", search = "newton" }'), "filters[1].fading.search: must be one of", None),
    ],
)
def test_config_errors_name_the_field(tmp_path, extra, replace, message, line):
    text = BASE + extra
    if replace:
        text = text.replace(*replace)
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, text)
    assert message in str(err.value)
    if line is not None:
        assert err.value.line == line


@pytest.mark.slow
def test_cli_reproduces_p2_and_writes_the_output(tmp_path, capsys):
    code = main(["run", str(P2), "--runs", "3", "--out", str(tmp_path / "p2"), "--no-progress"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "Paper's values (source: paper) beside ours (source: measured)" in printed
    assert "19.4" in printed and "48.8" in printed
    for name in ("cumulative_rmse.csv", "improvement.csv", "paper_vs_measured.csv", "fading.csv", "run.json"):
        assert (tmp_path / "p2" / name).exists()
    assert (tmp_path / "p2" / "figures" / "fading_factor.png").exists()


def test_fading_figure_shows_the_median_and_the_share_of_faded_runs(p2_output):
    # The mean λ of IFMKF is dominated by the few runs at λ_max; the figure shows
    # the median over runs and, beside it, the share of runs with λ > 1.
    fig = p2_output.figures["fading_factor"]
    axes = fig.get_axes()
    assert len(axes) == 6  # three conditions, two columns
    left, right = axes[0::2], axes[1::2]
    assert all(ax.get_ylabel() == "median λ" for ax in left)
    assert all(ax.get_ylabel() == "runs faded (%)" for ax in right)
    result = p2_output.results["actual"]
    names = [line.get_label() for line in left[1].get_lines() if not line.get_label().startswith("_")]
    i = names.index("IFMKF")
    lam = result.filters["IFMKF"].info["fading"]
    np.testing.assert_array_equal(left[1].get_lines()[i].get_ydata(), np.median(lam, axis=1))
    np.testing.assert_allclose(right[1].get_lines()[i].get_ydata(), 100.0 * np.mean(lam > 1.0, axis=1))
