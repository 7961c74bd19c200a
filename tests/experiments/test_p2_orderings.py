"""Orderings measured on paper P2's experiment (100 runs), tested only where a paired comparison is decisive.

Paper P2 claims IFMKF beats TFMKF and EWFMKF in the ideal and actual
conditions and does not jump at the outlier of the abnormal condition.  With
the reconstruction of spec 03 we measure (docs/papers.md):

* ideal: all five filters within about 0.1 % of each other; IFMKF never
  fades, so it *is* the EKF;
* actual: IFMKF beats the EKF and TFMKF, but EWFMKF and STF beat IFMKF
  (contrary to the paper);
* abnormal: IFMKF beats every other filter, because it rejects the outlier.

Each ordering is asserted with a two-sided paired t-test on the per-run
cumulative RMSE at p < 1e-4; the paper's percentages are never thresholds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from pursuit import metrics
from pursuit.experiment import load_experiment

pytestmark = pytest.mark.slow

P2 = Path(__file__).resolve().parents[2] / "experiments" / "p2-toa.toml"
ALPHA = 1e-4


@pytest.fixture(scope="module")
def results():
    exp = load_experiment(P2)
    return exp.run().results  # the file's 100 runs and seed


def _per_run(result, name):
    return metrics.rmse_per_run(result.squared_error(name, "position"))


def _decisively_better(result, better, worse):
    a, b = _per_run(result, better), _per_run(result, worse)
    test = stats.ttest_rel(a, b)
    return np.mean(a) < np.mean(b) and test.pvalue < ALPHA


def test_runs_match_the_papers_count(results):
    assert all(r.runs == 100 for r in results.values())


def test_ideal_ifmkf_never_fades_and_equals_the_ekf(results):
    r = results["ideal"]
    info = r.filters["IFMKF"].info
    assert not info["faded"].any() and not info["gated"].any()
    assert np.array_equal(r.filters["IFMKF"].estimates, r.filters["EKF"].estimates)


@pytest.mark.parametrize("worse", ["EKF", "TFMKF"])
def test_actual_ifmkf_beats_ekf_and_tfmkf(results, worse):
    assert _decisively_better(results["actual"], "IFMKF", worse)


@pytest.mark.parametrize("better", ["EWFMKF", "STF"])
def test_actual_innovation_based_fading_beats_ifmkf(results, better):
    # measured, and contrary to the paper's 48.8 % (see docs/papers.md)
    assert _decisively_better(results["actual"], better, "IFMKF")


@pytest.mark.parametrize("worse", ["EKF", "TFMKF", "EWFMKF", "STF"])
def test_abnormal_ifmkf_beats_every_other_filter(results, worse):
    assert _decisively_better(results["abnormal"], "IFMKF", worse)


@pytest.mark.parametrize("other", ["EKF", "TFMKF", "EWFMKF", "STF"])
def test_abnormal_outlier_moves_ifmkf_less_than_the_others(results, other):
    r = results["abnormal"]
    k = int(np.flatnonzero(np.isclose(r.times, 15.0))[0])
    err = lambda name: np.sqrt(r.squared_error(name, "position")[k])  # noqa: E731
    smaller = int(np.sum(err("IFMKF") < err(other)))
    assert stats.binomtest(smaller, r.runs, 0.5, alternative="greater").pvalue < ALPHA
