"""The divergence tests (pursuit.divergence) on synthetic NIS sequences and estimates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from pursuit.divergence import (
    DivergenceMonitor,
    DivergenceTest,
    detect_divergence,
    onset_step,
    outside_region,
    possible_region,
)

TEST = DivergenceTest()
BIG = 1e3  # far beyond the χ²(1) quantile at 1e-6 (28.4)


def _flags(nis, dof=1.0, mean=None, test=TEST):
    nis = np.asarray(nis, dtype=float)
    if nis.ndim == 1:
        nis = nis[:, None]
    mean = np.zeros((*nis.shape, 2)) if mean is None else mean
    return detect_divergence(nis, np.broadcast_to(dof, nis.shape), mean, test=test)


def test_threshold_is_the_chi2_quantile():
    for d in (1, 2, 3, 7):
        assert TEST.threshold(d) == pytest.approx(stats.chi2.isf(1e-6, d), rel=1e-10)
    np.testing.assert_allclose(TEST.thresholds(np.array([1, 2, 3, 3])), stats.chi2.isf(1e-6, [1, 2, 3, 3]), rtol=1e-10)


def test_flags_after_exactly_streak_exceedances_not_one_fewer():
    k = TEST.streak
    short = [1.0] * 3 + [BIG] * (k - 1) + [1.0] * 5
    assert not _flags(short).any()
    exact = [1.0] * 3 + [BIG] * k + [1.0] * 5
    f = _flags(exact)[:, 0]
    # flagged from the first step of the streak, and sticky: the consistent steps after it stay flagged
    np.testing.assert_array_equal(f, [False] * 3 + [True] * (k + 5))


def test_a_consistent_step_breaks_the_streak_and_a_missing_one_does_not():
    k = TEST.streak
    broken = [BIG] * (k - 1) + [1.0] + [BIG] * (k - 1)
    assert not _flags(broken).any()
    gapped = [BIG] * (k - 1) + [np.nan, np.nan] + [BIG]  # two steps with no measurement inside the streak
    f = _flags(gapped)[:, 0]
    assert f.all()  # onset at the first exceedance
    # dof = 0 also means "nothing measured"
    dof = np.array([1.0] * (k - 1) + [0.0] + [1.0])
    nis = np.array([BIG] * (k - 1) + [0.0] + [BIG])
    assert _flags(nis, dof[:, None]).all()


def test_threshold_depends_on_dof():
    nis = np.full(TEST.streak + 1, 30.0)  # above the χ²(1) quantile (28.4), below the χ²(3) one (33.4)
    assert _flags(nis, 1.0).all()
    assert not _flags(nis, 3.0).any()


def test_infinite_nis_and_non_finite_estimates_are_inconsistent():
    k = TEST.streak
    assert _flags([np.inf] * k).all()
    mean = np.zeros((k + 2, 1, 2))
    mean[2:, 0, 1] = np.nan  # the estimate breaks at step 3 and no measurement is taken after it
    f = detect_divergence(np.full((k + 2, 1), np.nan), np.ones((k + 2, 1)), mean)
    np.testing.assert_array_equal(f[:, 0], [False, False] + [True] * k)
    cov = np.tile(np.eye(2), (k + 2, 1, 1, 1))
    cov[1:, 0, 0, 0] = np.inf
    f = detect_divergence(np.full((k + 2, 1), 1.0), np.ones((k + 2, 1)), np.zeros((k + 2, 1, 2)), cov)
    np.testing.assert_array_equal(f[:, 0], [False] + [True] * (k + 1))


def test_no_nis_means_only_the_finiteness_test():
    k = TEST.streak
    mean = np.zeros((k + 3, 3, 2))
    mean[3:, 1] = np.inf
    f = detect_divergence(None, None, mean)
    assert f[:, [0, 2]].sum() == 0
    np.testing.assert_array_equal(f[:, 1], [False] * 3 + [True] * k)
    mean[4, 1] = 0.0  # one finite step in between: k - 1 in a row is not enough
    assert not detect_divergence(None, None, mean)[:, 1].any()


def test_options_are_checked_and_change_the_result():
    for bad in (dict(tail=0.0), dict(tail=1.0), dict(streak=0), dict(streak=2.5), dict(region=0.0), dict(region=np.inf)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            DivergenceTest(**bad)
    nis = [BIG] * 2
    assert not _flags(nis).any()
    assert _flags(nis, test=DivergenceTest(streak=2)).all()
    assert _flags([20.0] * 20, test=DivergenceTest(tail=1e-3)).all()  # χ²(1) isf(1e-3) = 10.8
    assert not _flags([20.0] * 20).any()


def test_batched_equals_one_run_at_a_time_and_the_monitor():
    rng = np.random.default_rng(3)
    K, M = 90, 40
    dof = rng.integers(0, 4, size=(K, M)).astype(float)
    nis = np.where(dof > 0, stats.chi2.rvs(np.maximum(dof, 1), random_state=rng), np.nan)
    # runs with streaks of huge NIS of random length and place
    for m in range(0, M, 2):
        start, length = rng.integers(0, K - 30), rng.integers(TEST.streak - 4, TEST.streak + 8)
        nis[start : start + length, m] = np.where(dof[start : start + length, m] > 0, BIG, np.nan)
    mean = rng.normal(size=(K, M, 4))
    mean[rng.integers(0, K), 5, 0] = np.nan
    batched = detect_divergence(nis, dof, mean)
    assert 0 < batched[-1].sum() < M  # both outcomes occur
    for m in range(M):
        alone = detect_divergence(nis[:, m : m + 1], dof[:, m : m + 1], mean[:, m : m + 1])
        np.testing.assert_array_equal(alone[:, 0], batched[:, m])
    mon = DivergenceMonitor((M,))
    seen = np.zeros(M, dtype=bool)
    for k in range(K):
        now = mon.update(nis[k], dof[k], mean[k])
        assert np.all(now >= seen)  # sticky
        seen = now
    np.testing.assert_array_equal(mon.flags(), batched)
    np.testing.assert_array_equal(onset_step(batched), np.where(mon.onset >= 0, mon.onset + 1.0, np.nan))


def _monitor_flags(nis, dof, mean, cov, test):
    """The reference: :class:`DivergenceMonitor` fed one step at a time (what detect_divergence did)."""
    mon = DivergenceMonitor(mean.shape[1:-1], test)
    for k in range(mean.shape[0]):
        mon.update(None if nis is None else nis[k], None if dof is None else (dof[k] if np.ndim(dof) else dof),
                   mean[k], None if cov is None else cov[k])
    return mon.flags()


def test_whole_run_detection_equals_the_monitor_step_by_step():
    """detect_divergence works on all steps at once: it must flag exactly what the monitor flags.

    400 random cases: batch shapes (), (M,), (M1, M2); dof per step and run, per step, scalar or None;
    NIS with streaks of all lengths, missing steps, infinities; non-finite estimates and covariances
    (and finite ones so large that their sum overflows); streak lengths 1 to 7 and the default 20.
    """
    rng = np.random.default_rng(11)
    flagged = 0
    for case in range(400):
        K = int(rng.integers(1, 80))
        batch = tuple(int(b) for b in rng.integers(1, 6, size=rng.integers(0, 3)))
        mean = rng.standard_normal((K, *batch, 3))
        if rng.random() < 0.5:
            hit = rng.random(mean.shape) < 0.02
            mean[hit] = rng.choice([np.nan, np.inf, -np.inf, 1e308], size=hit.sum())
        cov = None
        if rng.random() < 0.3:
            cov = rng.standard_normal((K, *batch, 3, 3))
            cov[rng.random(cov.shape) < 0.005] = np.nan
        p_bad = rng.random()
        nis = np.where(rng.random((K, *batch)) < p_bad, BIG, rng.chisquare(2, (K, *batch)))
        nis[rng.random(nis.shape) < 0.1] = np.nan
        nis[rng.random(nis.shape) < 0.01] = np.inf
        kind = case % 4
        dof = [rng.integers(0, 3, size=(K, *batch)), 2, None, rng.integers(0, 3, size=(K,))][kind]
        if kind == 3:  # one NIS per step, broadcast to the runs
            nis = nis.reshape(K, -1)[:, 0]
        if rng.random() < 0.1:
            nis = None
        test = DivergenceTest(streak=20 if case % 5 == 0 else int(rng.integers(1, 8)))
        got = detect_divergence(nis, dof, mean, cov, test=test)
        want = _monitor_flags(nis, dof, mean, cov, test)
        assert got.shape == want.shape and got.dtype == bool
        np.testing.assert_array_equal(got, want, err_msg=f"case {case}")
        flagged += bool(want.any())
    assert 100 < flagged < 380  # both outcomes occur often


def test_float_uniform_and_mixed_dof_and_a_long_consistent_run_with_one_late_streak():
    rng = np.random.default_rng(12)
    K, M = 600, 50
    nis = rng.chisquare(2, (K, M))
    nis[500:500 + TEST.streak, 7] = BIG  # exactly a streak, late
    nis[100:100 + TEST.streak - 1, 8] = BIG  # one short
    mean = np.zeros((K, M, 4))
    for dof in (np.full((K, M), 2.0), np.full((K, M), 2), np.where(rng.random((K, M)) < 0.5, 2, 1)):
        got = detect_divergence(nis, dof, mean)
        np.testing.assert_array_equal(got, _monitor_flags(nis, dof, mean, None, TEST))
        assert got[:, 7].sum() == K - 500 and not got[:, 8].any() and got.sum() == K - 500

def test_monitor_flags_at_the_step_that_completes_the_streak():
    mon = DivergenceMonitor((1,), DivergenceTest(streak=5))
    out = [bool(mon.update(v, 1, np.zeros((1, 2)))[0]) for v in [1.0, BIG, BIG, BIG, BIG, BIG, 1.0]]
    assert out == [False, False, False, False, False, True, True]
    assert mon.onset[0] == 1


def test_region_is_the_truth_and_sensor_box_grown_by_its_scale():
    truth = np.zeros((3, 2, 4))
    truth[:, 0, 0] = [0.0, 10.0, 20.0]  # run 0 moves 20 m along x
    truth[:, 0, 2] = [0.0, 5.0, 10.0]
    low, high = possible_region(truth, (0, 2))
    np.testing.assert_allclose(low[0], [-200.0, -200.0])
    np.testing.assert_allclose(high[0], [220.0, 210.0])
    np.testing.assert_allclose(low[1], [0.0, 0.0])  # run 1 does not move: no scale, no margin...
    low, _ = possible_region(truth, (0, 2), scale=np.array([1.0, 3.0]))
    np.testing.assert_allclose(low[1], [-30.0, -30.0])  # ...unless given one (the prior's σ)
    low, high = possible_region(truth, (0, 2), sensors=np.array([[-40.0, 0.0]]), test=DivergenceTest(region=1.0))
    np.testing.assert_allclose(low[0], [-100.0, -60.0])  # box [-40, 20] x [0, 10], scale 60
    np.testing.assert_allclose(high[0], [80.0, 70.0])
    est = np.zeros((3, 2, 4))
    est[2, 0, 0] = 221.0
    est[1, 1, 2] = np.nan
    out = outside_region(est, truth, (0, 2), scale=1.0)
    np.testing.assert_array_equal(out, [[False, False], [False, True], [True, False]])
    assert not outside_region(est, truth, ()).any()  # no position: the test does not apply


def test_region_onset_is_immediate_and_sticky():
    K = 10
    outside = np.zeros((K, 2), dtype=bool)
    outside[4, 1] = True  # one step out, then back in
    f = detect_divergence(np.ones((K, 2)), np.ones((K, 2)), np.zeros((K, 2, 2)), outside=outside)
    assert not f[:, 0].any()
    np.testing.assert_array_equal(f[:, 1], np.arange(K) >= 4)
    np.testing.assert_array_equal(onset_step(f), [np.nan, 5.0])


def test_whole_run_detection_edge_shapes():
    assert detect_divergence(np.zeros((0, 3)), 2, np.zeros((0, 3, 4))).shape == (0, 3)
    K = 3 * TEST.streak
    mean = np.zeros((K, 3, 4))
    cov = np.ones((K, 4, 4))  # one covariance per step, shared by the runs
    cov[10:, 0, 0] = np.nan
    got = detect_divergence(np.ones((K, 3)), 2, mean, cov)
    np.testing.assert_array_equal(got, _monitor_flags(np.ones((K, 3)), 2, mean, cov, TEST))
    assert got[10:].all() and not got[:10].any()


def test_whole_run_detection_with_no_step_or_no_run_and_covariances():
    for K, batch in ((0, (3,)), (4, (0,)), (0, (5, 0)), (4, (2, 0))):
        got = detect_divergence(np.zeros((K, *batch)), 2, np.zeros((K, *batch, 3)), np.zeros((K, *batch, 3, 3)))
        assert got.shape == (K, *batch) and got.dtype == bool and not got.any()


def test_not_finite_rows_when_the_whole_sum_is_not_finite():
    """The one-sum shortcut of _not_finite_steps: a finite total clears every row; a total that overflows (every
    entry finite) or holds NaN/±inf falls back to the row check, which flags exactly the rows with a bad entry."""
    from pursuit.divergence import _not_finite_steps

    values = np.ones((4, 3, 2))
    assert not _not_finite_steps(values).any() and _not_finite_steps(values).shape == (4, 3)
    values[:, :, 0] = 1e308  # every entry finite, the total overflows
    assert not _not_finite_steps(values).any()
    values[1, 2, 1] = np.inf
    values[3, 0, 0] = -np.inf  # +inf and -inf make the total NaN
    values[2, 1, 1] = np.nan
    want = np.zeros((4, 3), dtype=bool)
    want[1, 2] = want[3, 0] = want[2, 1] = True
    assert np.array_equal(_not_finite_steps(values), want)
    assert _not_finite_steps(np.zeros((0, 3, 2))).shape == (0, 3)
