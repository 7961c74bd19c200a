"""Full and summary storage: the summaries are the same bits whatever the mode and chunking."""

import numpy as np
import pytest

import pursuit.engine.montecarlo as mc
from pursuit.engine import monte_carlo

from .helpers import SMALL, assert_same_result, assert_same_summary, small_filters

RUNS, SEED = 45, 11


@pytest.fixture(scope="module")
def full():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED, store="full")


@pytest.mark.parametrize("chunk", [1, 7, 16, RUNS])
def test_summary_equals_full_bitwise(full, chunk):
    summ = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=chunk, store="summary", keep_runs=5)
    assert summ.store == "summary" and summ.runs == RUNS and summ.truth is None
    assert_same_summary(full, summ)
    for name in full.filter_names:
        for comp in ("position", "velocity", "state", "x", "vy"):
            assert np.array_equal(full.rmse_per_step(name, comp), summ.rmse_per_step(name, comp))
            assert np.array_equal(full.rmse_per_run(name, comp), summ.rmse_per_run(name, comp))
            assert full.rmse(name, comp, "per-run") == summ.rmse(name, comp, "per-run")
        assert np.array_equal(full.anees(name), summ.anees(name))
        assert np.array_equal(full.anis(name), summ.anis(name))
        assert full.info_keys(name) == summ.info_keys(name)
        for key in full.info_keys(name):
            assert np.array_equal(full.info_mean(name, key), summ.info_mean(name, key), equal_nan=True)
    # The first keep_runs runs are kept whole and equal the full arrays.
    ex = summ.stored()
    assert ex.runs == 5
    assert np.array_equal(ex.truth, full.truth[:, :5])
    for name in full.filter_names:
        assert np.array_equal(ex.filters[name].estimates, full.filters[name].estimates[:, :5])


def test_full_mode_is_chunk_invariant(full):
    other = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=4, store="full")
    assert_same_result(full, other)


def test_summaries_agree_with_plain_numpy(full):
    """The canonical sums are ordinary sums up to rounding: check against numpy on the arrays."""
    for name in full.filter_names:
        sq = full.squared_error(name, "position")
        assert np.allclose(full.rmse_per_step(name), np.sqrt(sq.mean(axis=1)), rtol=1e-13)
        assert np.isclose(full.rmse(name), np.sqrt(sq.mean()), rtol=1e-13)
        assert np.allclose(full.anees(name), full.nees(name).mean(axis=1), rtol=1e-13)


def test_summary_mode_refuses_per_run_arrays():
    summ = monte_carlo(SMALL, small_filters(), 6, SEED, store="summary", keep_runs=2)
    with pytest.raises(ValueError, match="stored as a summary"):
        summ.squared_error("EKF")
    with pytest.raises(ValueError, match="stored as a summary"):
        summ.nees("EKF")
    with pytest.raises(ValueError, match="stored as a summary"):
        summ.rmse_per_step("EKF", (0, 1))  # a group that was not reduced


def test_auto_switches_to_summary_above_the_limit(monkeypatch):
    assert monte_carlo(SMALL, small_filters(), 4, SEED).store == "full"
    monkeypatch.setattr(mc, "AUTO_FULL_LIMIT", 1000)
    assert monte_carlo(SMALL, small_filters(), 4, SEED).store == "summary"


def test_bad_store_and_keep_runs():
    with pytest.raises(ValueError, match="store"):
        monte_carlo(SMALL, small_filters(), 4, SEED, store="some")
    with pytest.raises(ValueError, match="keep_runs"):
        monte_carlo(SMALL, small_filters(), 4, SEED, store="summary", keep_runs=-1)


def test_summary_memory_does_not_grow_with_runs():
    """Reduced chunks are small: their size grows with runs only through per-run scalars."""
    task = mc.ChunkTask(SMALL, tuple(small_filters()), SEED, store="summary", keep_runs=0)
    part = task(0, 64)
    per_step = sum(v.nbytes for s in part.stats.values() for blocks in s.sums.values() for v in blocks.values())
    per_run = sum(v.nbytes for s in part.stats.values() for v in s.per_run.values())
    full = task.__class__(SMALL, tuple(small_filters()), SEED, store="full")(0, 64)
    full_bytes = full.truth.nbytes + sum(t.estimates.nbytes + t.covariances.nbytes for t in full.tracks.values())
    assert per_step + per_run < full_bytes / 20
    # Per run, only a handful of floats per filter and component group remain.
    assert per_run / 64 <= 8 * len(small_filters()) * 8
