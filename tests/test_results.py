"""MonteCarloResult: turning a full-mode result into the summary mode written by light output folders."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.engine import monte_carlo

from .engine.helpers import SMALL, assert_same_result, small_filters

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
