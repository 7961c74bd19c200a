"""Every run through the engine is tested for divergence, and the summary counts the diverged runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import pursuit as pu
from pursuit.divergence import DivergenceTest
from pursuit.engine import monte_carlo
from pursuit.models.measurement import LinearGaussian
from pursuit.scenarios import LinearCV

SCENARIO = LinearCV(ndim=2, steps=30)


def _kfs():
    sc = SCENARIO
    good = pu.KalmanFilter(sc.motion, sc.measurement, name="KF")
    # a badly wrong model: the filter believes the sensor 1000 times more precise than it is
    wrong = LinearGaussian.position(4, sc.motion.position_indices, sc.sigma / 1000.0)
    bad = pu.KalmanFilter(sc.motion, wrong, name="KF-wrong-R")
    return good, bad


@dataclass
class _State:
    mean: np.ndarray
    cov: np.ndarray


@dataclass(frozen=True)
class Runaway:
    """A stub filter whose estimate runs away (×3 each step) and that reports no NIS: only the truth can tell."""

    start: int = 10
    name: str = "runaway"

    def init(self, prior, batch=(), rng=None):
        mean = np.broadcast_to(np.asarray(prior.mean, dtype=float), (*batch, 4)).copy()
        return _State(mean, np.broadcast_to(np.eye(4), (*batch, 4, 4)).copy())

    def step(self, state, z, k, dt=None):
        mean = state.mean.copy()
        mean[..., 0] = np.where(k >= self.start, 1.0 + np.abs(mean[..., 0]) * 3.0, z[..., 0])
        mean[..., 2] = z[..., 1]
        nan = np.full(mean.shape[:-1], np.nan)
        return _State(mean, state.cov), {"nis": nan, "dof": np.zeros(mean.shape[:-1])}


def test_run_flags_a_wrong_model_in_the_step_info_and_not_a_matched_one():
    sim = SCENARIO.simulate(np.random.default_rng(0), 8)
    good, bad = _kfs()
    a = pu.run(good, sim.measurements, sim.prior, keep_info=["nis"])
    b = pu.run(bad, sim.measurements, sim.prior)
    assert a.info["diverged"].shape == (30, 8) and a.info["diverged"].dtype == bool
    assert not a.info["diverged"].any()
    # once the prior's variance is gone the NIS is ~1e4 at every step: every run flagged, from the streak's start
    flags = b.info["diverged"]
    assert flags[-1].all() and not flags[0].any()
    assert np.all(flags[10:]) and np.all(flags == np.logical_or.accumulate(flags, axis=0))
    c = pu.run(bad, sim.measurements, sim.prior, divergence=None)
    assert "diverged" not in c.info
    d = pu.run(bad, sim.measurements, sim.prior, divergence=DivergenceTest(tail=1e-300, streak=30))
    assert not d.info["diverged"].any()  # documented options change the verdict


def test_the_summary_counts_diverged_runs_in_every_storage_mode():
    good, bad = _kfs()
    filters = [good, bad, Runaway()]
    full = monte_carlo(SCENARIO, filters, 12, 4, store="full")
    rows = {r["filter"]: r for r in full.summary()}
    assert rows["KF"]["diverged"] == 0 and rows["KF"]["diverged_from_step"] is None
    assert rows["KF-wrong-R"]["diverged"] == 12 and 2 <= rows["KF-wrong-R"]["diverged_from_step"] <= 10
    # the runaway estimate reports no NIS; the region test against the truth flags it once it leaves
    assert rows["runaway"]["diverged"] == 12
    assert rows["runaway"]["diverged_from_step"] > Runaway.start
    # the RMSE still includes the diverged runs, and the count stands beside it
    keys = list(rows["runaway"])
    assert keys.index("diverged") == keys.index("rmse_velocity") + 1
    assert rows["runaway"]["rmse_position"] > 1e6
    np.testing.assert_array_equal(full.diverged_step("KF"), np.full(12, np.nan))
    summary = monte_carlo(SCENARIO, filters, 12, 4, store="summary", chunk_size=5, keep_runs=2)
    for name in rows:
        np.testing.assert_array_equal(summary.diverged_step(name), full.diverged_step(name))
        assert summary.divergence(name) == full.divergence(name)
    np.testing.assert_array_equal(summary.info_mean("runaway", "diverged")[-1], 1.0)  # share of runs flagged per step
    none = monte_carlo(SCENARIO, [good], 3, 4, divergence=None)
    assert "diverged" not in none.summary()[0] and none.divergence("KF") is None


def test_a_matched_kf_is_never_flagged():
    """200 runs × 100 steps of a KF on its own model: no false alarm.

    Expected false-alarm probability: the NIS of a matched KF are independent
    χ²(2) draws, so a streak of 20 exceedances at tail 1e-6 starts at a given
    step with probability 1e-120; over 2·10⁴ steps the chance of any flag is
    below 2·10⁻¹¹⁶.  The region test needs an estimate 10 path lengths from the
    truth, about 10⁴ σ here.  A single exceedance (probability 2 % over all
    steps) must not flag.
    """
    sc = LinearCV(ndim=2, steps=100)
    kf = pu.KalmanFilter(sc.motion, sc.measurement, name="KF")
    result = monte_carlo(sc, [kf], 200, 11)
    assert result.divergence("KF") == {"diverged": 0, "diverged_from_step": None}
    nis = result.filters["KF"].info["nis"]
    assert np.isfinite(nis).all() and nis.shape == (100, 200)


def test_experiment_tables_carry_the_count(tmp_path):
    from pursuit.experiments.montecarlo import summary_table

    good, bad = _kfs()
    result = monte_carlo(SCENARIO, [good, bad], 5, 1)
    table = summary_table(result)
    col = table.columns.index("diverged")
    assert col == table.columns.index("rmse_velocity") + 1
    assert [row[col] for row in table.rows] == [0, 5]


@pytest.mark.parametrize("sequence", [True, False])
def test_flag_is_the_same_step_by_step_and_batched(sequence):
    sim = SCENARIO.simulate(np.random.default_rng(5), 6)
    _, bad = _kfs()
    tr = pu.run(bad, sim.measurements, sim.prior, sequence=sequence)
    from pursuit.divergence import detect_divergence

    np.testing.assert_array_equal(tr.info["diverged"], detect_divergence(tr.info["nis"], tr.info["dof"], tr.mean, tr.cov))
