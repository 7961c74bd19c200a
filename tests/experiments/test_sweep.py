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


@pytest.mark.slow
def test_reproduce_prints_the_paper_table_and_writes_figures(tmp_path, capsys):
    code = main(["reproduce", "p1-ungm", "--runs", "3", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "Paper's values (source: paper) beside ours (source: measured)" in text
    assert "6.0001" in text  # the paper's PF value at N = 30
    figs = {p.name for p in (tmp_path / "p1-ungm" / "figures").iterdir()}
    for q in ("q-1", "q-10"):  # both readings of Q
        assert {f"N30_estimates_{q}.png", f"N100_abs_error_{q}.png", f"N100_rmse_{q}.png", f"N100_particles_{q}.png", f"rmse_vs_N_{q}.png"} <= figs
    assert "MMSE limit (PF, N = 20 000, 6 runs)" in text  # its own row, twice the runs
    assert "ICS-PF's 3.1075 at N = 100 (Table 1, printed as Q = 1)" in text  # a claim with its verdict
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


# -- variants, the MMSE limit and the claims ------------------------------------------

VARIANTS = (
    SMALL.replace("[sweep]", '[[variants]]\nlabel = "Q = 1"\nq = 1.0\n\n[[variants]]\nlabel = "Q = 10"\nq = 10.0\n\n[sweep]')
    .replace('note = "made up"', 'variant = "Q = 1"\nnote = "made up"')
    .replace("snapshot_steps = [2, 12]", 'snapshot_steps = [2, 12]\nvariants = ["Q = 1", "Q = 10"]\npaper_label = "paper (Table 1)"')
    + """
[limit]
filter = { type = "pf", particles = 300 }
runs_factor = 2
backend = "numpy"

[[claim]]
variant = "Q = 1"
order = ["ICS-PF", "PF"]

[[claim]]
variant = "Q = 1"
filter = "PF"
at = 40

[[claim]]
variant = "Q = 10"
filter = "ICS-PF"
at = 20
value = 0.5
source = "made up, far below any filter"
"""
)


def test_variants_limit_and_claims(tmp_path):
    from pursuit.experiments.sweep import order_verdict, value_verdict

    out = load_experiment(_write(tmp_path, VARIANTS)).run(runs=5, seed=2)
    summary, paper, claims, pairs = out.tables
    col = {c: i for i, c in enumerate(summary.columns)}
    limit = [r for r in summary.rows if r[col["filter"]].startswith("MMSE limit")]
    # its own row per variant, labelled with what it is; twice the runs; same truths as the filters' runs
    assert [(r[col["variant"]], r[col["filter"]], r[col["N"]], r[col["runs"]]) for r in limit] == [
        ("Q = 1", "MMSE limit (PF, N = 300, 10 runs)", None, 10),
        ("Q = 10", "MMSE limit (PF, N = 300, 10 runs)", None, 10),
    ]
    assert {r[col["variant"]] for r in summary.rows} == {"Q = 1", "Q = 10"}
    # the limit is in the paper table too, one row per variant
    assert [(r[0], r[2]) for r in paper.rows if str(r[2]).startswith("MMSE")] == [(v, limit[0][col["filter"]]) for v in ("Q = 1", "Q = 10")]
    # the verdicts follow the measured numbers
    assert claims.kind == "paper" and claims.columns == ["variant", "claim", "verdict", "because"]
    assert claims.rows[0][1] == "ICS-PF < PF in state RMSE at every N"
    diffs = [(f"N = {r[1]}", r[2], r[3], r[6], r[7]) for r in pairs.rows if r[0] == "Q = 1" and (r[2], r[3]) == ("ICS-PF", "PF")]
    assert len(diffs) == 2 and (claims.rows[0][2], claims.rows[0][3]) == order_verdict(diffs)
    pf_rows = {r[col["N"]]: r for r in summary.rows if r[col["variant"]] == "Q = 1" and r[col["filter"]] == "PF"}
    assert claims.rows[1][1] == "PF's 4.7 at N = 40 (made up)"
    assert claims.rows[1][2] == value_verdict(4.7, pf_rows[40][col["rmse"]], pf_rows[40][col["ci95"]])[0]
    assert claims.rows[2][2] == "not reachable" and "below the MMSE limit" in claims.rows[2][3]
    # one-run figures for both variants, named by variant; one RMSE figure per variant with the paper marked on Q = 1's
    assert {"N40_estimates_q-1", "N40_estimates_q-10", "N40_particles_q-10", "rmse_vs_N_q-1", "rmse_vs_N_q-10"} <= set(out.figures)
    legend = [t.get_text() for t in out.figures["rmse_vs_N_q-1"].axes[0].get_legend().get_texts()]
    assert "PF, paper (Table 1)" in legend and limit[0][col["filter"]] in legend
    legend10 = [t.get_text() for t in out.figures["rmse_vs_N_q-10"].axes[0].get_legend().get_texts()]
    assert not any("paper" in t for t in legend10)  # the paper's values belong to Q = 1 (no paper_on_every_variant)
    assert len(pairs.rows) == 8


def test_the_limit_shares_the_filters_truths(tmp_path):
    # the limit's first runs are the filters' runs (same root seed): its per-run errors pair with theirs
    out = load_experiment(_write(tmp_path, VARIANTS)).run(runs=4, seed=9)
    lim, pf = out.results["Q = 10|limit"], out.results["Q = 10|N=20"]
    np.testing.assert_array_equal(lim.truth[:, :4], pf.truth)


def test_order_verdict_follows_the_intervals():
    from pursuit.experiments.sweep import order_verdict

    holds = [("N = 30", "ICS-PF", "CS-PF", -0.5, 0.2), ("N = 30", "CS-PF", "PF", -0.3, 0.25)]
    # a diverged filter's non-finite differences fail every comparison: never "reproduced"
    for bad in ((-1.0, float("nan")), (float("nan"), float("nan")), (float("-inf"), 0.1)):
        assert order_verdict(holds + [("N = 60", "ICS-PF", "CS-PF", *bad)])[0] == "not shown"
    assert order_verdict(holds) == ("reproduced", "weakest: CS-PF \u2212 PF = \u22120.3 [\u22120.55, \u22120.05] at N = 30")
    fails = holds + [("N = 100", "CS-PF", "PF", 0.4, 0.2), ("N = 60", "CS-PF", "PF", 0.3, 0.1)]
    assert order_verdict(fails) == ("not reproduced", "CS-PF \u2212 PF = +0.4 [0.2, 0.6] at N = 100")
    unclear = holds + [("N = 60", "ICS-PF", "CS-PF", -0.1, 0.3)]
    verdict, because = order_verdict(unclear)
    assert verdict == "not shown" and because.startswith("ICS-PF \u2212 CS-PF = \u22120.1 [\u22120.4, 0.2] at N = 60")
    with pytest.raises(ValueError, match="diffs"):
        order_verdict([])


def test_value_verdict_follows_the_numbers():
    from pursuit.experiments.sweep import value_verdict

    assert value_verdict(4.7, 4.75, 0.2) == ("reproduced", "measured 4.75 \u00b1 0.2")
    assert value_verdict(4.0, 4.75, 0.2)[0] == "not reproduced"  # 0.75 > sqrt(2)*0.2
    assert value_verdict(4.0, 4.75, 0.2)[1].endswith("(the paper's is lower)")
    assert value_verdict(4.5, 4.75, 0.2)[0] == "reproduced"  # 0.25 <= 0.283
    assert value_verdict(3.11, 6.3, 0.2, limit=4.4, limit_half=0.3) == ("not reachable", "below the MMSE limit 4.4 [4.1, 4.7]")
    assert value_verdict(4.2, 4.3, 0.2, limit=4.4, limit_half=0.3)[0] == "reproduced"  # within the limit's interval: reachable


@pytest.mark.parametrize(
    "edit, field",
    [
        (('order = ["ICS-PF", "PF"]', 'order = ["ICS-PF", "XX"]'), "claim[0]: no filter named 'XX'"),
        (('order = ["ICS-PF", "PF"]', 'order = ["ICS-PF"]'), "claim[0].order: name at least two filters"),
        (('order = ["ICS-PF", "PF"]', 'order = ["ICS-PF", "PF"]\nfilter = "PF"'), "claim[0]: give either order"),
        (('variant = "Q = 1"\norder', 'variant = "Q = 3"\norder'), "claim[0].variant: expected one of the variants"),
        (("at = 40\n\n[[claim]]", "at = 30\n\n[[claim]]"), "claim[1].at: 30 is not a swept value"),
        (("at = 40\n\n[[claim]]", "\n[[claim]]"), "claim[1].at: required, PF is run at every swept value"),
        (("filter = \"PF\"\nat = 40", "filter = \"PF\"\nat = 20"), "claim[1].value: required (no [[paper]] entry"),
        (('at = 40\n\n[[claim]]', 'at = 40\nmetric = "nis_mean"\n\n[[claim]]'), "claim[1].metric: no error column 'nis_mean'"),
        (("runs_factor = 2", "runs_factor = 0"), "limit.runs_factor: must be at least 1"),
        (('backend = "numpy"', 'backend = "gpu"'), "limit.backend"),
        (('filter = { type = "pf", particles = 300 }', 'filter = { type = "pf", particles = 300, backend = "numpy" }'), "limit.filter.backend"),
        (('filter = { type = "pf", particles = 300 }', 'filter = { type = "pf", particles = -3 }'), "limit.filter"),
        (('filter = { type = "pf", particles = 300 }', 'filter = "pf"'), "limit.filter: expected a filter table"),
        (('variants = ["Q = 1", "Q = 10"]', 'variants = ["Q = 2"]'), "figures.variants[0]: no variant labelled 'Q = 2'"),
    ],
)
def test_bad_limit_and_claims_name_the_field(tmp_path, edit, field):
    old, new = edit
    assert old in VARIANTS
    with pytest.raises(ConfigError) as err:
        load_experiment(_write(tmp_path, VARIANTS.replace(old, new, 1)))
    assert field in str(err.value)


def test_a_value_is_not_judged_from_an_interval_that_reaches_zero():
    from pursuit.experiments.sweep import value_verdict

    # a diverging filter: its mean error is huge and so is its interval; it says nothing about 0.03
    assert value_verdict(0.0306, 2.2e19, 2.1e19)[0] == "not shown"
    assert value_verdict(0.0306, 0.5, float("nan"))[0] == "not shown"
