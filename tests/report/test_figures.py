"""Figure code: readable ticks, distinguishable coinciding curves, legends beside the data, the consistency band."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from pursuit.engine import monte_carlo
from pursuit.report.figures import consistency_over_time, figure_problems, rmse_over_time
from pursuit.report.sweep_figures import metric_against_value

from ..engine.helpers import SMALL, small_filters


@pytest.fixture(scope="module")
def twins():
    """Three filters, the last a copy of the first under another name: their curves coincide exactly."""
    filters = small_filters()
    twin = dataclasses.replace(filters[0], name=f"{filters[0].name}-twin")
    return monte_carlo(SMALL, [*filters, twin], 6, 3)


def _series(ax):
    return [ln for ln in ax.lines if not ln.get_label().startswith("_") and ln.get_transform() == ax.transData]


def test_coinciding_curves_are_drawn_distinguishably_and_named(twins):
    fig = rmse_over_time(twins, "position", log=True)
    assert figure_problems(fig) == []
    ax = fig.get_axes()[0]
    lines = _series(ax)
    styles = {(ln.get_linestyle(), ln.get_marker()) for ln in lines}
    assert len(styles) == len(lines)  # no two series drawn alike
    first = twins.filter_names[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert f"{first}-twin (= {first})" in labels


def test_figure_problems_flags_curves_drawn_alike_on_top_of_each_other():
    fig = Figure(layout="constrained")
    ax = fig.add_subplot()
    ax.plot([0, 1, 2], [1, 2, 3], label="STF", color="k")
    ax.plot([0, 1, 2], [1, 2, 3], label="EWFMKF", color="k")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position RMSE (m)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1))
    assert any("coincide and are drawn alike" in p for p in figure_problems(fig))


def test_log_axes_have_plain_tick_labels(twins):
    fig = rmse_over_time(twins, "position", log=True)
    fig.draw_without_rendering()
    ax = fig.get_axes()[0]
    texts = [t.get_text() for t in (*ax.get_yticklabels(), *ax.get_yticklabels(minor=True)) if t.get_text()]
    assert texts and not any("times" in t or "^" in t for t in texts)
    # the check that keeps it so: matplotlib's default log labels are flagged
    bare = Figure(layout="constrained")
    bx = bare.add_subplot()
    bx.plot([1, 2, 3], [2.0, 3.0, 5.0])
    bx.set_yscale("log")
    bx.set_xlabel("time (s)")
    bx.set_ylabel("RMSE (m)")
    assert any("scientific notation" in p for p in figure_problems(bare))


def test_a_legend_over_the_data_is_a_problem():
    fig = Figure(layout="constrained")
    ax = fig.add_subplot()
    t = np.linspace(0.0, 1.0, 50)
    ax.plot(t, np.full_like(t, 0.5), label="EKF")
    ax.plot(t, t, label="UKF")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("x (m)")
    ax.legend(loc="center")
    assert any("legend covers" in p for p in figure_problems(fig))


def test_bare_symbol_x_label_is_a_problem():
    fig = Figure(layout="constrained")
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1])
    ax.set_xlabel("l")
    ax.set_ylabel("wall time (s)")
    assert any("names no quantity" in p for p in figure_problems(fig))


def test_consistency_figure_draws_the_chi_square_band(twins):
    fig = consistency_over_time(twins)
    assert figure_problems(fig) == []
    axes = fig.get_axes()
    assert [ax.get_ylabel() for ax in axes] == ["ANEES (average over runs)", "ANIS (average over runs)"]
    name = twins.filter_names[0]
    for ax, what in zip(axes, ("nees", "nis")):
        assert ax.get_yscale() == "log"
        bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert [b.get_label() for b in bands] == ["χ² 95 % band"]
        lo, hi = twins.consistency_bounds(name, what)
        ys = bands[0].get_paths()[0].vertices[:, 1]
        assert np.isclose(ys.min(), np.nanmin(lo)) and np.isclose(ys.max(), np.nanmax(hi))
        values = {ln.get_label().split(" (")[0]: ln.get_ydata() for ln in _series(ax)}
        assert np.array_equal(values[name], getattr(twins, f"a{what}")(name), equal_nan=True)
        assert "χ² 95 % band" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_sweep_baselines_are_named_in_the_legend_not_overprinted():
    rows = [
        {"filter": f, "variant": v, "l": l, "wall_time_s": w, "ci95": 0.1}
        for v, scale in (("1 node (P1)", 1.0), ("4 corner nodes", 4.0))
        for f in ("UPF", "UPF-local")
        for l, w in ((0.0, scale), (0.5, 3 * scale), (1.0, 9 * scale))
    ]
    rows += [{"filter": "UKF", "variant": "1 node (P1)", "l": None, "wall_time_s": 0.9},
             {"filter": "UKF", "variant": "4 corner nodes", "l": None, "wall_time_s": 1.0}]
    fig = metric_against_value(rows, "l", "wall_time_s", error_key="ci95", xlabel="UKF fraction l", ylabel="wall time (s)")
    assert figure_problems(fig) == []
    ax = fig.get_axes()[0]
    assert len(ax.texts) == 0  # no labels written into the plot, where two close baselines overprint
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "UKF, 1 node (P1) (baseline)" in labels and "UKF, 4 corner nodes (baseline)" in labels
    base = [ln for ln in _series(ax) if "baseline" in ln.get_label()]
    assert len({(str(ln.get_linestyle()), ln.get_color()) for ln in base}) == 2
    swept = {ln.get_color() for ln in _series(ax) if "baseline" not in ln.get_label()}
    assert not swept & {ln.get_color() for ln in base}  # baseline colours differ from every swept series'
    assert ax.get_xlabel() == "UKF fraction l"


@pytest.mark.parametrize("low, high, expected", [(2.1e-3, 2.7e-3, "0.0025"), (0.5, 3e4, "10000"), (1.2, 6.5, "3")])
def test_log_tick_labels_are_plain_numbers(low, high, expected):
    from pursuit.report.figures import plain_log_ticks

    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([0, 1], [low, high])
    ax.set_yscale("log")
    plain_log_ticks(ax)
    fig.draw_without_rendering()
    texts = [t.get_text() for t in (*ax.get_yticklabels(), *ax.get_yticklabels(minor=True)) if t.get_text()]
    assert expected in texts and not any("e+" in t or "times" in t for t in texts), texts


def test_consistency_figure_of_a_diverged_filter_draws_and_says_where_it_clipped(twins):
    import copy

    broken = copy.deepcopy(twins)
    name = broken.filter_names[0]
    fr = broken.filters[name]
    fr.estimates[5:] = 1e100  # diverged: NEES ~1e200
    broken.statistics = None  # recompute from the arrays
    assert np.nanmax(broken.anees(name)) > 1e150
    fig = consistency_over_time(broken)
    fig.canvas.print_figure(__import__("io").BytesIO(), format="png")
    ax = fig.get_axes()[0]
    assert name in ax.get_title() and "1e+12" in ax.get_title(), ax.get_title()
    drawn = next(ln for ln in _series(ax) if ln.get_label().split(" (")[0] == name).get_ydata()
    assert np.nanmax(drawn) == 1e12


def test_log_tick_at_infinity_gets_no_label():
    """An axis stretched to the float limit asks for a label at inf (p1-wsn's ICS-PF): '' rather than OverflowError."""
    from pursuit.report.figures import _PlainLogFormatter

    fmt = _PlainLogFormatter()
    fmt.set_axis(Figure().add_subplot().yaxis)
    assert fmt(np.inf) == "" and fmt(0.0) == ""


def test_sweep_figure_marks_the_papers_values_and_the_limit():
    rows = [
        {"N": n, "filter": f, "rmse": r, "ci95": 0.1}
        for n, f, r in [(30, "PF", 5.8), (100, "PF", 4.75), (30, "ICS-PF", 6.0), (100, "ICS-PF", 5.9)]
    ]
    paper = [("PF", 30.0, 6.0, "PF, paper (Table 1)"), ("PF", 100.0, 4.7, "PF, paper (Table 1)"), ("ICS-PF", 100.0, 3.11, "ICS-PF, paper (Table 1)")]
    fig = metric_against_value(rows, "N", "rmse", error_key="ci95", paper=paper, references=[("MMSE limit (PF)", 4.4)])
    ax = fig.axes[0]
    by = {ln.get_label(): ln for ln in ax.lines}
    pf_paper = by["PF, paper (Table 1)"]
    assert pf_paper.get_marker() == "H" and pf_paper.get_linestyle() == "None"  # markers only, a shape no series uses
    assert list(pf_paper.get_ydata()) == [6.0, 4.7]
    assert np.allclose(pf_paper.get_xdata(), [30, 100], atol=2.0)  # beside our points, not on them
    assert pf_paper.get_color() == by["PF"].get_color()  # in the filter's colour
    assert list(by["ICS-PF, paper (Table 1)"].get_ydata()) == [3.11]
    assert list(by["MMSE limit (PF)"].get_ydata()) == [4.4, 4.4]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert {"PF, paper (Table 1)", "ICS-PF, paper (Table 1)", "MMSE limit (PF)"} <= set(legend)
    assert "H" not in (by["PF"].get_marker(), by["ICS-PF"].get_marker())


def test_trajectory_keeps_the_truths_axes_and_marks_a_runaway_estimate():
    from pursuit.report.figures import LEAVES_LABEL, VIEW_MARGIN, trajectory, view_limits

    from ..engine.test_divergence_flags import SCENARIO, Runaway, _kfs

    good, _ = _kfs()
    result = monte_carlo(SCENARIO, [good, Runaway()], 3, 2)
    assert np.abs(result.filters["runaway"].estimates[:, 0, 0]).max() > 1e6
    anchors = np.array([[-5.0, -5.0]])
    fig = trajectory(result, 0, landmarks=anchors)
    assert figure_problems(fig) == []
    ax = fig.get_axes()[0]
    truth = result.truth[:, 0][:, [0, 2]]
    lo, hi = np.vstack([truth, anchors]).min(axis=0), np.vstack([truth, anchors]).max(axis=0)
    margin = VIEW_MARGIN * float(np.max(hi - lo))
    assert ax.get_xlim() == pytest.approx((lo[0] - margin, hi[0] + margin))
    assert ax.get_ylim() == pytest.approx((lo[1] - margin, hi[1] + margin))
    np.testing.assert_allclose(view_limits(truth, anchors), [lo - margin, hi + margin])
    marks = [c for c in ax.collections if c.get_label() == LEAVES_LABEL]
    assert len(marks) == 1
    (x, y), = marks[0].get_offsets()
    assert x == pytest.approx(hi[0] + margin)  # on the right edge, where the estimate runs out
    assert lo[1] - margin <= y <= hi[1] + margin
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert LEAVES_LABEL in labels
    step = int(result.diverged_step("runaway")[0])
    assert f"runaway (diverged at step {step})" in labels and good.name in labels


def test_trajectory_against_time_keeps_the_truths_axes():
    from pursuit.report.figures import LEAVES_LABEL, trajectory

    from ..engine.test_divergence_flags import Runaway

    result = monte_carlo(SMALL, [Runaway(start=5)], 2, 1)
    result = dataclasses.replace(result, position_indices=(0,))  # one position component: drawn against time
    fig = trajectory(result, 1)
    ax = fig.get_axes()[0]
    x = result.truth[:, 1, 0]
    assert ax.get_ylim()[1] < x.max() + 0.3 * (x.max() - x.min())
    assert [c for c in ax.collections if c.get_label() == LEAVES_LABEL]


def test_leaving_point_is_on_the_edge_where_the_path_crosses_it():
    from pursuit.report.figures import leaving_point

    view = np.array([[0.0, 0.0], [10.0, 10.0]])
    assert leaving_point(np.array([[1.0, 1.0], [9.0, 9.0]]), view) is None
    np.testing.assert_allclose(leaving_point(np.array([[5.0, 5.0], [25.0, 15.0]]), view), [10.0, 7.5])
    np.testing.assert_allclose(leaving_point(np.array([[5.0, 5.0], [np.nan, np.nan]]), view), [5.0, 5.0])
    np.testing.assert_allclose(leaving_point(np.array([[-5.0, 50.0], [1.0, 1.0]]), view), [0.0, 10.0])


def test_rmse_figure_names_diverged_runs_and_stays_readable():
    from ..engine.test_divergence_flags import SCENARIO, Runaway, _kfs

    good, _ = _kfs()
    result = monte_carlo(SCENARIO, [good, Runaway()], 3, 2)
    fig = rmse_over_time(result, "position", log=False)
    assert figure_problems(fig) == []
    ax = fig.get_axes()[0]
    assert ax.get_yscale() == "log"  # the runaway's 1e14 m would flatten the KF's curve on a linear axis
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == [good.name, "runaway (diverged in 3 of 3 runs)"]
    alone = rmse_over_time(result, "position", log=False, filters=[good.name])
    assert alone.get_axes()[0].get_yscale() == "linear"
