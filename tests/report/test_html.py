"""The HTML report and index, built from output folders; figure quality checks."""

from __future__ import annotations

import base64
import re

import pytest
from matplotlib.figure import Figure

from pursuit.engine import monte_carlo
from pursuit.experiment import find_experiment, list_experiments, load_experiment
from pursuit.experiments.montecarlo import standard_figures, summary_table
from pursuit.report.figures import figure_problems
from pursuit.report.html import render_report, write_index, write_report
from pursuit.report.output import write_output
from pursuit.tables import ExperimentOutput, Table

from ..engine.helpers import SMALL, small_filters


@pytest.fixture(scope="module")
def result():
    return monte_carlo(SMALL, small_filters(), 5, 2)


def _folder(result, tmp_path, title="Demo <b>&</b>", **kw):
    tables = [summary_table(result), Table("paper_vs_measured", "Paper", ["filter", "paper", "measured"], [["EKF", 1.0, 0.5]], kind="paper")]
    out = ExperimentOutput("demo", title, "desc", tables, standard_figures(result, SMALL, {}), {"result": result},
                           sidecar={"seed": 2, "runs": 5, "config": {"scenario": {"type": "wsn-range"}}, **kw})
    return write_output(out, tmp_path / "demo", engine={"backend": {"backend": "processes", "workers": 2}, "chunk_size": 3, "store": "full"})


def test_report_is_self_contained(result, tmp_path):
    folder = _folder(result, tmp_path)
    page = (folder / "report.html").read_text()
    pngs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(pngs) == 4  # position and velocity RMSE, consistency, trajectory
    for data in pngs:
        assert base64.b64decode(data).startswith(b"\x89PNG")
    assert "<script" not in page and "http://" not in page and "https://" not in page
    assert "Demo &lt;b&gt;&amp;&lt;/b&gt;" in page  # escaped, not markup
    assert 'class="paper"' in page and "Paper against measured" in page
    assert "processes (2 workers)" in page and ">2<" in page  # backend and root seed
    for pkg in ("numpy", "scipy", "matplotlib", "pursuit"):
        assert f"<th>{pkg}</th>" in page
    assert 'href="figures/trajectory.pdf"' in page


def test_rebuild_equals_original_and_reports_missing_figures(result, tmp_path, capsys):
    folder = _folder(result, tmp_path)
    original = (folder / "report.html").read_text()
    (folder / "report.html").unlink()
    write_report(folder)
    assert (folder / "report.html").read_text() == original
    (folder / "figures" / "trajectory.png").unlink()
    write_report(folder)
    assert "trajectory.png is missing" in (folder / "report.html").read_text()
    assert "trajectory.png is missing" in capsys.readouterr().err


def test_render_needs_an_output_folder(tmp_path):
    with pytest.raises(ValueError, match="no run.json"):
        render_report(tmp_path)


def test_index_links_reports(result, tmp_path):
    folder = _folder(result, tmp_path)
    page = write_index(tmp_path, [folder]).read_text()
    assert 'href="demo/report.html"' in page and "yes" in page  # has paper values


def test_standard_figures_are_publication_ready(result):
    figs = standard_figures(result, SMALL, {})
    for name, fig in figs.items():
        assert figure_problems(fig) == [], name
        for ax in fig.get_axes():
            assert re.search(r"\(.+\)", ax.get_ylabel()), (name, ax.get_ylabel())  # a unit
            if ax.get_xlabel() or not ax.get_shared_x_axes().get_siblings(ax)[1:]:  # stacked panels share the bottom label
                assert re.search(r"\(.+\)", ax.get_xlabel()), (name, ax.get_xlabel())


def _labels(figs):
    return {name: [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.get_axes()] for name, fig in figs.items()}


def test_standard_figures_carry_the_scenarios_units(result):
    assert _labels(standard_figures(result, SMALL, {})) == {
        "rmse_position": [("time (s)", "position RMSE (m)")],
        "rmse_velocity": [("time (s)", "velocity RMSE (m/s)")],
        "consistency": [("", "ANEES (average over runs)"), ("time (s)", "ANIS (average over runs)")],
        "trajectory": [("x (m)", "y (m)")],
    }


class _Feet:
    """SMALL with its positions declared in feet (a unit the library cannot guess)."""

    def __init__(self, units):
        self.state_units = units

    def __getattr__(self, key):
        return getattr(SMALL, key)


def test_figure_units_come_from_the_scenario_never_guessed():
    feet = monte_carlo(_Feet(("ft", "ft/s", "ft", "ft/s")), small_filters(), 2, 2)
    assert _labels(standard_figures(feet, SMALL, {})) == {
        "rmse_position": [("time (s)", "position RMSE (ft)")],
        "rmse_velocity": [("time (s)", "velocity RMSE (ft/s)")],
        "consistency": [("", "ANEES (average over runs)"), ("time (s)", "ANIS (average over runs)")],
        "trajectory": [("x (ft)", "y (ft)")],
    }
    # a scenario that declares no units gets none, not metres
    unknown = monte_carlo(_Feet(None), small_filters(), 2, 2)
    assert unknown.unit(0) is None
    labels = _labels(standard_figures(unknown, SMALL, {}))
    assert labels["rmse_position"] == [("time (s)", "position RMSE")]
    assert labels["trajectory"] == [("x", "y")]


def test_summary_mode_figures_use_the_kept_runs():
    summ = monte_carlo(SMALL, small_filters(), 12, 2, store="summary", keep_runs=2, chunk_size=5)
    figs = standard_figures(summ, SMALL, {"trajectory_run": 7})
    assert "run 1" in figs["trajectory"].get_axes()[0].get_title()  # clamped to a kept run
    assert "12 runs" in figs["rmse_position"].get_axes()[0].get_title()


def test_figure_problems_finds_unlabelled_axes():
    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([0, 1], label="a")
    ax.plot([1, 0], label="b")
    problems = figure_problems(fig)
    assert any("no x label" in p for p in problems) and any("in no legend" in p for p in problems)
    ax.legend()
    ax.set_xlabel("time (s)")
    ax.set_ylabel("x (m)")
    assert figure_problems(fig) == []


def test_figure_problems_accepts_stacked_panels_with_one_legend():
    fig = Figure()
    top, bottom = fig.subplots(2, 1, sharex=True)
    for ax, unit in ((top, "m"), (bottom, "m/s")):
        ax.plot([0, 1], label="EKF")
        ax.plot([1, 0], label="UKF")
        ax.set_ylabel(f"RMSE ({unit})")
    bottom.set_xlabel("time (s)")
    problems = figure_problems(fig)
    assert len(problems) == 2 and all("in no legend" in p for p in problems)
    top.legend()
    assert figure_problems(fig) == []


@pytest.mark.slow
@pytest.mark.parametrize("name", list_experiments())
def test_every_bundled_experiment_has_publication_ready_figures(name):
    """Labelled axes (with units where the quantity has one) and legends, for every kind's figures."""
    output = load_experiment(find_experiment(name)).run(runs=2)
    assert output.figures
    for fig_name, fig in output.figures.items():
        assert figure_problems(fig) == [], (name, fig_name)
