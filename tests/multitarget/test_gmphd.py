"""GM-PHD filter: spec 05 §7 checks, pruning/merging and extraction by hand, bad parameters."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import InteractingMultipleModel
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.multitarget.gmphd import GMPHDTracker, extract_estimates, prune_merge
from pursuit.scenarios import MultiTargetScenario, Target

from ._checks import CLUTTER_DENSITY, cluttered_scene, kf, nearest_errors, range_bearing_scene
from ._scenes import simulate

PRIOR = Gaussian(np.array([0.5, 0.8, -0.3, 0.4]), np.diag([4.0, 1.0, 4.0, 1.0]))


def phd(filt=None, p_detect=0.9, density=CLUTTER_DENSITY, **kw):
    kw.setdefault("max_speed", 3.0)
    return GMPHDTracker(filt or kf(), p_detect, density, **kw)


# ----------------------------------------------------------------------
# spec 05 §7
# ----------------------------------------------------------------------
def test_expected_count_tracks_the_truth_without_clutter():
    """P_D = 1, no clutter, targets born and dying: Σ w equals the true count once births have had two scans.

    Tolerance: |Σ w − N| ≤ 0.01 at every such scan of every run (seeded; the
    only slack is κ / (P_D q(z)) per target with κ = 1e-9, and p_S < 1 on a
    target that has just died, which P_D = 1 removes at once).
    """
    cv = ConstantVelocity(ndim=2, dt=1.0, q=0.05)
    scenario = MultiTargetScenario(
        targets=(
            Target([0.0, 1.0, 0.0, 0.5]),
            Target([200.0, -1.0, 0.0, 1.0], death=25),
            Target([0.0, 0.5, 200.0, -1.0], birth=10),
        ),
        motion=cv,
        measurement=LinearGaussian.position(4, cv.position_indices, 1.0),
        clutter_region=[[-50.0, 250.0], [-50.0, 250.0]],
        clutter_rate=0.0,
        p_detect=1.0,
        steps=35,
    )
    truth, scans = scenario.simulate(np.random.default_rng(3), runs=10)
    res = phd(pu.KalmanFilter(cv, scenario.measurement), p_detect=1.0, density=1e-9, max_speed=10.0).track(scans.z)
    count = truth.count
    steady = np.zeros_like(count, dtype=bool)
    steady[2:] = (count[2:] == count[1:-1]) & (count[1:-1] == count[:-2])  # no birth in the last two scans
    assert steady.sum() > 250
    np.testing.assert_allclose(res.expected_count[steady], count[steady], atol=0.01)
    # and the extracted estimates are that many, next to the targets
    assert ((res.label >= 0).sum(axis=-1)[steady] == count[steady]).all()


def test_single_target_given_birth_equals_the_kalman_filter():
    """One target, no clutter, P_D = 1, birth at the truth's prior: the estimate is the KF's (1e-9)."""
    filt = kf()
    truth, z = simulate([[0.0, 1.0, 0.0, 0.5]], 30, 4, 1, shuffle=False)
    want = pu.run(filt, z[:, :, 0], PRIOR)
    # a fixed birth at the prior: the first scan's estimate is the KF's
    res = phd(filt, 1.0, 1e-12, birth=Gaussian(PRIOR.mean[None], PRIOR.cov[None]), birth_rate=1.0).track(z)
    np.testing.assert_allclose(res.mean[0, :, 0], want.mean[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.cov[0, :, 0], want.cov[0], rtol=1e-9, atol=1e-12)
    assert (res.label[0, :, 0] == 0).all() and (res.label[0, :, 1:] == -1).all()
    # the prior as an initial component and no births: the KF at every scan, one label throughout
    res = phd(filt, 1.0, 1e-12, birth=None, p_survive=1.0).track(z, initial=Gaussian(PRIOR.mean[None], PRIOR.cov[None]))
    np.testing.assert_allclose(res.mean[:, :, 0], want.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.cov[:, :, 0], want.cov, rtol=1e-9, atol=1e-12)
    assert (res.label[:, :, 0] == 0).all() and (res.label[:, :, 1:] == -1).all()
    np.testing.assert_allclose(res.expected_count, 1.0, atol=1e-4)


def test_unscented_range_bearing_single_target_equals_the_ukf():
    """The update is the component filter's own step: with a UKF on a radar it is the UKF."""
    cv, rb, _, _, _ = range_bearing_scene()
    truth, z = simulate([[150.0, 1.0, 100.0, 0.5]], 20, 3, 4, motion=cv, measurement=rb, shuffle=False)
    prior = Gaussian(np.array([150.0, 1.0, 100.0, 0.5]), np.diag([25.0, 1.0, 25.0, 1.0]))
    ukf = pu.UnscentedKalmanFilter(cv, rb)
    want = pu.run(ukf, z[:, :, 0], prior)
    res = phd(ukf, 1.0, 1e-12, birth=None, p_survive=1.0).track(z, initial=Gaussian(prior.mean[None], prior.cov[None]))
    np.testing.assert_allclose(res.mean[:, :, 0], want.mean, rtol=1e-9, atol=1e-9)


def test_tracks_crossing_targets_in_clutter_from_nothing():
    truth, z = cluttered_scene()
    res = phd().track(z)
    err = nearest_errors(res, truth)[8:]
    # a missed detection drops a component's weight to about 1 − P_D, below 0.5 (the GM-PHD's known weakness)
    assert (err < 4.0).mean() > 0.85
    assert (res.label[8:] >= 0).sum(axis=-1).mean() < 3.3


def test_range_bearing_with_an_ekf_from_nothing():
    cv, rb, truth, z, density = range_bearing_scene()
    res = phd(pu.ExtendedKalmanFilter(cv, rb), 0.9, density, max_speed=4.0).track(z)
    err = nearest_errors(res, truth)[10:]
    assert (err < 5.0).mean() > 0.85
    assert (res.label[10:] >= 0).sum(axis=-1).mean() < 2.5


@pytest.mark.parametrize("birth", ["two-point", "one-point"])
def test_order_of_detections_within_a_scan_does_not_matter(birth):
    truth, z = cluttered_scene(runs=4, K=30)
    tracker = phd(birth=birth)
    a = tracker.track(z)
    rng = np.random.default_rng(4)
    zp = z.copy()
    for k in range(z.shape[0]):
        for m in range(z.shape[1]):
            zp[k, m] = z[k, m][rng.permutation(z.shape[2])]
    b = tracker.track(zp)
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(a.expected_count, b.expected_count, rtol=1e-12)


def test_batch_equals_one_run_at_a_time():
    truth, z = cluttered_scene(runs=4, K=30)
    tracker = phd()
    whole = tracker.track(z)
    for m in range(z.shape[1]):
        one = tracker.track(z[:, m : m + 1])
        np.testing.assert_array_equal(one.label[:, 0], whole.label[:, m])
        np.testing.assert_allclose(one.mean[:, 0], whole.mean[:, m], rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(one.expected_count[:, 0], whole.expected_count[:, m], rtol=1e-12)


def test_same_seed_same_bits():
    tracker = phd()
    a = tracker.track(cluttered_scene(runs=3, K=25, seed=8)[1])
    b = tracker.track(cluttered_scene(runs=3, K=25, seed=8)[1])
    for name in ("mean", "cov", "label", "confirmed", "dropped", "expected_count", "components"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_scan_times_equal_to_the_model_step_change_nothing():
    truth, z = cluttered_scene(runs=2, K=15)
    tracker = phd()
    a = tracker.track(z)
    b = tracker.track(z, times=10.0 + np.arange(15.0))
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-12, atol=1e-12)
    # a longer gap is a different prediction
    c = tracker.track(z, times=np.arange(15.0) * 1.5)
    assert not np.allclose(np.nan_to_num(a.mean), np.nan_to_num(c.mean))


def test_component_cap_and_estimate_slots_hold():
    truth, z = cluttered_scene(runs=3, K=20)
    res = phd(max_components=5, capacity=2).track(z)
    assert res.components.max() <= 5
    assert res.mean.shape[2] == 2
    assert ((res.label >= 0).sum(axis=-1) + res.dropped >= 3)[10:].mean() > 0.8  # three targets, two slots


# ----------------------------------------------------------------------
# pruning, merging, extraction by hand
# ----------------------------------------------------------------------
def test_prune_merge_by_hand():
    # run 0: two clusters and one component to prune; run 1: everything below T
    w = np.array([[0.5, 0.3, 0.2, 1e-6, 0.4], [1e-6, 2e-6, 0.0, 0.0, 0.0]])
    mean = np.array([[0.0, 1.0, 10.0, 0.5, 10.5], [0.0, 0.0, 0.0, 0.0, 0.0]])[..., None]
    cov = np.array([[1.0, 1.0, 1.0, 1.0, 4.0], [1.0] * 5])[..., None, None]
    label = np.array([[7, 8, 9, 10, 11], [1, 2, -1, -1, -1]])
    out_w, out_m, out_P, out_l = prune_merge(w, mean, cov, label, 1e-5, 4.0, 100)
    # heaviest 0.5 at 0: takes 1 (d² = 1); 10 (d² = 100) and 10.5 (d² = 110.25 / 4) stay; 0.5 is pruned
    m1 = (0.5 * 0.0 + 0.3 * 1.0) / 0.8
    P1 = (0.5 * (1.0 + m1**2) + 0.3 * (1.0 + (1.0 - m1) ** 2)) / 0.8
    # then 0.4 at 10.5: takes 10, measured with its own P = 1 (d² = 0.25)
    m2 = (0.2 * 10.0 + 0.4 * 10.5) / 0.6
    P2 = (0.2 * (1.0 + (10.0 - m2) ** 2) + 0.4 * (4.0 + (10.5 - m2) ** 2)) / 0.6
    np.testing.assert_allclose(out_w, [[0.8, 0.6], [0.0, 0.0]], rtol=1e-15)
    np.testing.assert_allclose(out_m[0, :, 0], [m1, m2], rtol=1e-14)
    np.testing.assert_allclose(out_P[0, :, 0, 0], [P1, P2], rtol=1e-14)
    np.testing.assert_array_equal(out_l, [[7, 11], [-1, -1]])
    # the cap keeps the heaviest
    out_w, out_m, _, out_l = prune_merge(w, mean, cov, label, 1e-5, 4.0, 1)
    np.testing.assert_allclose(out_w, [[0.8], [0.0]])
    np.testing.assert_array_equal(out_l, [[7], [-1]])
    # U = 0.2: nothing merges; sorted heaviest first
    out_w, out_m, _, out_l = prune_merge(w, mean, cov, label, 1e-5, 0.2, 100)
    np.testing.assert_allclose(out_w[0], [0.5, 0.4, 0.3, 0.2])
    np.testing.assert_array_equal(out_l[0], [7, 11, 8, 9])


def test_prune_merge_two_dimensional_matches_moments():
    rng = np.random.default_rng(2)
    n, C = 3, 6
    mean = rng.normal(0.0, 0.1, (1, C, n))  # all within U of the heaviest
    A = rng.normal(size=(1, C, n, n))
    cov = A @ np.swapaxes(A, -1, -2) + np.eye(n)
    w = rng.uniform(0.1, 1.0, (1, C))
    label = np.arange(C)[None]
    out_w, out_m, out_P, out_l = prune_merge(w, mean, cov, label, 1e-5, 1e6, 100)
    W = w.sum()
    m = (w[0, :, None] * mean[0]).sum(0) / W
    P = sum(w[0, i] * (cov[0, i] + np.outer(mean[0, i] - m, mean[0, i] - m)) for i in range(C)) / W
    np.testing.assert_allclose(out_w, [[W]])
    np.testing.assert_allclose(out_m[0, 0], m, rtol=1e-13)
    np.testing.assert_allclose(out_P[0, 0], P, rtol=1e-13)
    assert out_l[0, 0] == int(np.argmax(w))


def _merge_reference(w, mean, cov, threshold, merge):
    """Vo & Ma's pruning and merging written out directly, one run: (weights, means) heaviest first."""
    idx = [i for i in np.argsort(-w, kind="stable") if w[i] > threshold]
    out = []
    while idx:
        j = idx[0]
        group = [i for i in idx if (mean[i] - mean[j]) @ np.linalg.solve(cov[i], mean[i] - mean[j]) <= merge]
        W = w[group].sum()
        out.append((W, (w[group, None] * mean[group]).sum(0) / W))
        idx = [i for i in idx if i not in group]
    out.sort(key=lambda t: -t[0])
    return np.array([t[0] for t in out]), np.array([t[1] for t in out])


@pytest.mark.parametrize("scale", [1e2, 1e6, 1e8])
def test_prune_merge_equals_the_direct_formula_far_from_the_origin(scale):
    """The merge distances come from an expansion that cancels when |m| ≫ the spread (a review found
    components lost at |m|/σ ≈ 1e8): near the threshold they are computed again directly."""
    rng = np.random.default_rng(11)
    runs, C, n = 20, 8, 4
    centre = rng.uniform(1.0, 2.0, (runs, 1, n)) * scale
    mean = centre + rng.normal(0.0, 1.0, (runs, C, n)) * rng.choice([0.01, 3.0, 1e3], (runs, C, 1))
    cov = np.broadcast_to(np.eye(n) * 1e-4, (runs, C, n, n)).copy()
    cov[:, ::2] *= 1e4
    w = rng.uniform(0.05, 1.0, (runs, C))
    label = np.broadcast_to(np.arange(C), (runs, C))
    out_w, out_m, _, _ = prune_merge(w, mean, cov, label, 1e-5, 4.0, 100)
    for r in range(runs):
        ref_w, ref_m = _merge_reference(w[r], mean[r], cov[r], 1e-5, 4.0)
        got = out_w[r] > 0
        np.testing.assert_allclose(out_w[r, got], ref_w, rtol=1e-12)
        np.testing.assert_allclose(out_m[r, got], ref_m, rtol=1e-12, atol=1e-9 * scale)


def _vo_ma_reference(w, mean, cov, label, threshold, merge, cap):
    """Vo & Ma's pruning, merging and cap written out for one run: (w, mean, cov, label) heaviest first."""
    idx = [i for i in np.argsort(-w, kind="stable") if w[i] > threshold]
    out = []
    while idx:
        j = idx[0]
        group = [i for i in idx if (mean[i] - mean[j]) @ np.linalg.solve(cov[i], mean[i] - mean[j]) <= merge]
        W = w[group].sum()
        m = (w[group, None] * mean[group]).sum(0) / W
        P = sum(w[i] * (cov[i] + np.outer(mean[i] - m, mean[i] - m)) for i in group) / W
        out.append((W, m, P, label[j]))
        idx = [i for i in idx if i not in group]
    out.sort(key=lambda t: -t[0])  # stable: equal weights keep the order of the rounds
    return out[:cap]


def _random_mixtures(rng, runs, C, n):
    """Clustered components of random SPD covariance, unsorted, some below T, runs of 0..C components."""
    centres = rng.uniform(-50.0, 50.0, (runs, 4, n))
    mean = centres[np.arange(runs)[:, None], rng.integers(0, 4, (runs, C))] + rng.normal(0.0, 1.5, (runs, C, n))
    B = rng.normal(0.0, 0.7, (runs, C, n, n))
    cov = B @ np.swapaxes(B, -1, -2) + 0.3 * np.eye(n)
    w = rng.uniform(0.0, 1.0, (runs, C)) ** 3
    w[rng.uniform(size=(runs, C)) < 0.1] = 1e-7  # pruned
    size = rng.integers(0, C + 1, runs)  # runs of very different sizes (every size class of the pairs)
    w[np.arange(C)[None, :] >= size[:, None]] = 0.0
    label = rng.permutation(runs * C).reshape(runs, C)
    return w, mean, cov, label


@pytest.mark.parametrize("n", [1, 2, 4])
def test_prune_merge_equals_vo_ma_written_out(n):
    """All pairs' distances at once, greedy rounds on their adjacency, moments by segment sums: the same
    groups, labels and cap as the direct algorithm, weights and moments to 1e-12, over runs of every size."""
    rng = np.random.default_rng(21 + n)
    runs, C = 40, 60
    w, mean, cov, label = _random_mixtures(rng, runs, C, n)
    for cap in (100, 7):
        out_w, out_m, out_P, out_l = prune_merge(w, mean, cov, label, 1e-5, 4.0, cap)
        merged = 0
        for r in range(runs):
            ref = _vo_ma_reference(w[r], mean[r], cov[r], label[r], 1e-5, 4.0, cap)
            got = out_w[r] > 0
            assert got.sum() == len(ref)
            np.testing.assert_array_equal(out_l[r, got], [t[3] for t in ref])
            np.testing.assert_array_equal(out_l[r, ~got], -1)
            if ref:
                np.testing.assert_allclose(out_w[r, got], [t[0] for t in ref], rtol=1e-12)
                np.testing.assert_allclose(out_m[r, got], [t[1] for t in ref], rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(out_P[r, got], [t[2] for t in ref], rtol=1e-12, atol=1e-12)
            merged += (w[r] > 1e-5).sum() - len(ref)
        assert out_w.shape[1] == min(cap, max(len(_vo_ma_reference(w[r], mean[r], cov[r], label[r], 1e-5, 4.0, 1000)) for r in range(runs)))
    assert merged > 100  # the case merges a lot, not only singletons


def test_prune_merge_chunks_of_runs_change_no_bit(monkeypatch):
    """The (runs, C, C) pairs are computed in chunks of runs to bound memory: the chunking changes nothing."""
    import pursuit.multitarget.gmphd as gmphd

    rng = np.random.default_rng(5)
    w, mean, cov, label = _random_mixtures(rng, 30, 50, 4)
    whole = prune_merge(w, mean, cov, label, 1e-5, 4.0, 100)
    monkeypatch.setattr(gmphd, "_PAIR_BUDGET", 1)  # one run at a time
    for a, b in zip(whole, prune_merge(w, mean, cov, label, 1e-5, 4.0, 100)):
        np.testing.assert_array_equal(a, b)


def test_prune_merge_nothing_kept_and_sorted_input():
    # nothing above T: no slot
    out = prune_merge(np.full((2, 3), 1e-7), np.zeros((2, 3, 2)), np.broadcast_to(np.eye(2), (2, 3, 2, 2)), np.zeros((2, 3), int))
    assert [a.shape for a in out] == [(2, 0), (2, 0, 2), (2, 0, 2, 2), (2, 0)]
    # input already pruned and heaviest first (as the tracker's update hands it over) equals the same input shuffled
    rng = np.random.default_rng(8)
    w, mean, cov, label = _random_mixtures(rng, 10, 30, 2)
    order = np.argsort(np.where(w > 1e-5, -w, np.inf), axis=1, kind="stable")
    sw, sm, sc, sl = (np.take_along_axis(a, order.reshape(*order.shape, *(1,) * (a.ndim - 2)), axis=1) for a in (w, mean, cov, label))
    sw = np.where(sw > 1e-5, sw, 0.0)
    for a, b in zip(prune_merge(w, mean, cov, label), prune_merge(sw, sm, sc, sl)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6])
def test_spd_inverse_equals_lapack(n):
    """The entry-by-entry Cholesky inverse of the merge distances: LAPACK's inverse to round-off (scaled by the
    condition number), exactly symmetric; a matrix that is not positive definite goes to LAPACK."""
    from pursuit.multitarget.gmphd import _spd_inverse

    rng = np.random.default_rng(n)
    B = rng.normal(size=(500, n, n))
    P = B @ np.swapaxes(B, -1, -2) + 0.05 * np.eye(n)
    P[:50] *= 10.0 ** rng.uniform(-8, 8, (50, 1, 1))
    scale = np.sqrt(10.0 ** rng.uniform(-4, 4, (500, n)))
    P[50:100] *= scale[50:100, :, None] * scale[50:100, None, :]  # badly scaled axes
    A = _spd_inverse(P)
    np.testing.assert_array_equal(A, np.swapaxes(A, -1, -2))
    want = np.linalg.inv(P)
    cond = np.linalg.cond(P)
    err = np.abs(A - want).max(axis=(1, 2)) / np.abs(want).max(axis=(1, 2))
    assert (err <= 1e-13 * np.maximum(cond, 1.0)).all()
    indefinite = np.eye(n)
    indefinite[0, 0] = -2.0
    np.testing.assert_array_equal(_spd_inverse(indefinite[None])[0], np.linalg.inv(indefinite))
    with pytest.raises(np.linalg.LinAlgError):
        _spd_inverse(np.zeros((1, n, n)))


def test_extract_estimates_by_hand():
    w = np.array([[1.6, 0.5, 0.49, 2.2], [0.0, 0.0, 0.0, 0.0]])
    mean = np.arange(8.0).reshape(2, 4, 1)
    cov = np.ones((2, 4, 1, 1))
    label = np.array([[3, 4, 5, 6], [-1, -1, -1, -1]])
    m, P, lab, dropped = extract_estimates(w, mean, cov, label, 0.5, 4)
    # 1.6 → 2, 0.5 → 1, 0.49 → 0, 2.2 → 2: five estimates, one beyond the four slots
    np.testing.assert_array_equal(lab, [[3, 3, 4, 6], [-1, -1, -1, -1]])
    np.testing.assert_array_equal(m[0, :, 0], [0.0, 0.0, 1.0, 3.0])
    assert np.isnan(m[1]).all() and np.isnan(P[1]).all()
    np.testing.assert_array_equal(dropped, [1, 0])


# ----------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------
@pytest.mark.parametrize(
    "field, kwargs",
    [
        ("p_detect", {"p_detect": 0.0}),
        ("p_detect", {"p_detect": 1.5}),
        ("clutter_density", {"density": 0.0}),
        ("p_survive", {"p_survive": 0.0}),
        ("p_survive", {"p_survive": 1.2}),
        ("birth", {"birth": "three-point"}),
        ("birth", {"birth": Gaussian(np.zeros((2, 3)), np.eye(3))}),
        ("birth_rate", {"birth_rate": 0.0}),
        ("velocity_sigma", {"velocity_sigma": -1.0}),
        ("prune", {"prune": 1.0}),
        ("prune", {"prune": -1e-5}),
        ("merge", {"merge": 0.0}),
        ("max_components", {"max_components": 0}),
        ("max_components", {"max_components": 2.5}),
        ("extract", {"extract": 0.0}),
        ("capacity", {"capacity": 0}),
        ("max_speed", {"max_speed": None}),
        ("max_speed", {"max_speed": -3.0}),
        ("position", {"position": "x"}),
    ],
)
def test_bad_parameters_name_the_field(field, kwargs):
    with pytest.raises(ValueError, match=f"^{field}:"):
        phd(**kwargs)


def test_bad_filter_and_input_name_the_field():
    cv, meas = kf().motion, kf().measurement
    imm = InteractingMultipleModel([pu.KalmanFilter(cv, meas), pu.KalmanFilter(cv, meas)], np.array([[0.9, 0.1], [0.1, 0.9]]))
    with pytest.raises(ValueError, match="^filter:"):
        phd(imm)
    tracker = phd()
    with pytest.raises(ValueError, match="^z:"):
        tracker.track(np.zeros((3, 2, 2)))
    z = np.zeros((3, 1, 2, 2))
    z[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="^z:"):
        tracker.track(z)
    with pytest.raises(ValueError, match="^times:"):
        tracker.track(np.zeros((3, 1, 2, 2)), times=[0.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="^initial:"):
        phd(birth=None).track(np.zeros((3, 2, 2, 2)), initial=Gaussian(np.zeros((3, 2, 4)), np.eye(4)))
