"""Result objects: brief displays (text and notebook HTML), a pandas DataFrame, and the summary form
that light output folders save."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import pursuit as pu
from pursuit.engine import monte_carlo
from pursuit.rng import run_streams
from pursuit.scenarios import WSNRange

from .engine.helpers import SMALL, assert_same_result, small_filters

SCENARIO = WSNRange(steps=20)
FILTERS = [pu.ExtendedKalmanFilter(SCENARIO.motion, SCENARIO.measurement, name="EKF<1>"),
           pu.UnscentedKalmanFilter(SCENARIO.motion, SCENARIO.measurement)]


@pytest.fixture(scope="module", params=["full", "summary"])
def result(request):
    return pu.monte_carlo(SCENARIO, FILTERS, runs=40, seed=1, store=request.param, keep_runs=3)


def test_repr_is_short_and_names_every_filter(result):
    text = repr(result)
    # was 68 137 characters over 1591 lines for this result (the arrays printed)
    assert len(text) < 800 and text.count("\n") <= 6
    assert "runs=40, steps=20" in text and f"store={result.store!r}" in text
    for name in result.filter_names:
        assert repr(name) in text
    assert "[" not in text.replace("state=[", "")  # no array values
    if result.store == "full":
        assert "estimates=float64(20, 40, 4), covariances=float64(20, 40, 4, 4)" in text
    else:
        assert "example_runs=3" in text and "estimates=None" in text


def test_repr_lists_at_most_eight_filters():
    from pursuit.scenarios import LinearCV

    sc = LinearCV(ndim=2, steps=3)
    many = [pu.KalmanFilter(sc.motion, sc.measurement, name=f"KF{i}") for i in range(11)]
    text = repr(pu.monte_carlo(sc, many, runs=2, seed=0))
    assert "'KF7'" in text and "'KF8'" not in text and "... +3 more" in text


def test_html_is_the_summary_table_escaped(result):
    page = result._repr_html_()
    assert page.count("<tr>") == 1 + len(FILTERS)  # header + one row per filter
    assert "<td>EKF&lt;1&gt;</td>" in page  # names are escaped
    rmse = result.rmse("UKF")
    assert f"<td>{rmse:.4g}</td>" in page
    assert "<th>anees</th>" in page


def test_to_dataframe_is_the_summary(result):
    pd = pytest.importorskip("pandas", reason="to_dataframe needs pandas (the `pandas` and `test` extras)")
    df = result.to_dataframe()
    assert isinstance(df, pd.DataFrame)
    assert list(df.index) == result.filter_names
    for row in result.summary():
        for key, value in row.items():
            if key != "filter":
                assert df.loc[row["filter"], key] == value


def test_to_dataframe_without_pandas_names_the_extra(result, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    with pytest.raises(ImportError, match=r"pip install 'pursuit\[pandas\]'"):
        result.to_dataframe()


def test_track_and_filter_result_reprs_show_shapes_not_values():
    sim = SCENARIO.simulate(run_streams(1, range(30), 0))
    track = pu.run(FILTERS[1], sim.measurements, sim.prior)
    text = repr(track)
    # was 66 328 characters over 1297 lines
    assert text.startswith("Track('UKF', mean=float64(20, 30, 4), cov=float64(20, 30, 4, 4), info={")
    assert len(text) < 300
    fr = pu.FilterResult("X", np.zeros((2, 3, 4)), None, {"nis": np.zeros((2, 3))}, 1.5)
    assert repr(fr) == "FilterResult('X', estimates=float64(2, 3, 4), covariances=None, info={nis}, wall_time=1.5)"


# --------------------------------------------------------------------------
# the summary form of light output folders
# --------------------------------------------------------------------------
RUNS, SEED = 7, 11


@pytest.fixture(scope="module")
def full():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED)


def test_summarised_equals_what_summary_mode_computes(full):
    direct = monte_carlo(SMALL, small_filters(), RUNS, SEED, store="summary", keep_runs=2, chunk_size=3)
    light = full.summarised(2)
    assert light.store == "summary" and light.runs == RUNS and full.store == "full"
    assert light.summary() == full.summary()
    no_wall = lambda rows: [{k: v for k, v in r.items() if k != "wall_time_s"} for r in rows]  # noqa: E731
    assert no_wall(light.summary()) == no_wall(direct.summary())
    for name in full.filter_names:
        assert np.array_equal(light.rmse_per_step(name), full.rmse_per_step(name))
        assert np.array_equal(light.anees(name), full.anees(name), equal_nan=True)
        assert np.array_equal(light.consistency_bounds(name)[1], full.consistency_bounds(name)[1], equal_nan=True)
    assert_same_result(direct.stored(), light.stored())


def test_summarised_keeps_small_results_whole_and_refuses_bad_counts(full):
    assert full.summarised(RUNS) is full
    assert full.summarised(0).examples is None
    with pytest.raises(ValueError, match="keep_runs"):
        full.summarised(-1)
