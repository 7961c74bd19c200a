"""OSPA / GOSPA against brute force, their closed forms and properties, track switches and counts.

References: ``docs/spec/05-multi-target-pmht.md §5`` (the definitions) and §7 (the brute-force check).
"""

from itertools import combinations, permutations

import numpy as np
import pytest
from scipy import stats

from pursuit.multitarget import metrics as mt
from pursuit.multitarget import gospa, gospa_assignment, gospa_summary, ospa, run_average, track_counts, track_switches


# --------------------------------------------------------------------------
# brute-force references, written from the definitions
# --------------------------------------------------------------------------
def _dist(a, b):
    return float(np.sqrt(np.sum((np.asarray(a) - np.asarray(b)) ** 2)))


def brute_matching(X, Y, c, p):
    """min over matchings of min(n_x, n_y) pairs of Σ min(d, c)^p (every permutation)."""
    small, big = (X, Y) if len(X) <= len(Y) else (Y, X)
    best = np.inf
    for perm in permutations(range(len(big)), len(small)):
        best = min(best, sum(min(_dist(small[i], big[j]), c) ** p for i, j in enumerate(perm)))
    return best


def brute_ospa(X, Y, c, p):
    n = max(len(X), len(Y))
    if n == 0:
        return 0.0
    return ((brute_matching(X, Y, c, p) + c**p * abs(len(X) - len(Y))) / n) ** (1 / p)


def brute_gospa(X, Y, c, p, alpha):
    """The α-form of the definition: min over full matchings, cut distance, c^p/α per unmatched point."""
    return (brute_matching(X, Y, c, p) + c**p / alpha * abs(len(X) - len(Y))) ** (1 / p)


def brute_gospa2(X, Y, c, p):
    """α = 2 as the spec writes it: min over partial assignments γ of pairs with d ≤ c; returns (d^p, loc, k)."""
    best = (np.inf, None, None)
    for k in range(min(len(X), len(Y)) + 1):
        for rows in combinations(range(len(X)), k):
            for cols in permutations(range(len(Y)), k):
                ds = [_dist(X[i], Y[j]) for i, j in zip(rows, cols)]
                if any(d > c for d in ds):
                    continue
                loc = sum(d**p for d in ds)
                total = loc + c**p / 2 * (len(X) + len(Y) - 2 * k)
                if total < best[0]:
                    best = (total, loc, k)
    return best


def random_padded(rng, batch, rows, d, scale):
    """Random sets with random (not prefix) masks; NaN in every padding row."""
    pts = rng.uniform(0, scale, (*batch, rows, d))
    mask = rng.random((*batch, rows)) < 0.6
    pts[~mask] = np.nan
    return pts, mask


# --------------------------------------------------------------------------
# brute force, all sizes 0..4 each side
# --------------------------------------------------------------------------
@pytest.mark.parametrize("p", [1.0, 2.0, 3.5])
def test_ospa_and_gospa_equal_brute_force_on_every_size(p):
    rng = np.random.default_rng(20)
    c = 1.5
    sizes = [(a, b) for a in range(5) for b in range(5)]
    reps = 6
    X = np.full((len(sizes), reps, 4, 2), np.nan)
    Y = np.full((len(sizes), reps, 4, 2), np.nan)
    mx = np.zeros((len(sizes), reps, 4), bool)
    my = np.zeros((len(sizes), reps, 4), bool)
    for s, (a, b) in enumerate(sizes):
        for r in range(reps):
            ix = rng.choice(4, a, replace=False)  # present rows anywhere among the slots
            iy = rng.choice(4, b, replace=False)
            X[s, r, ix] = rng.uniform(0, 3, (a, 2))  # on [0, 3]²: some pairs beyond c = 1.5, some within
            Y[s, r, iy] = rng.uniform(0, 3, (b, 2))
            mx[s, r, ix] = True
            my[s, r, iy] = True
    got_ospa = ospa(X, mx, Y, my, c, p)
    got = {alpha: gospa(X, mx, Y, my, c, p, alpha) for alpha in (2.0, 1.0, 0.5)}
    for s in range(len(sizes)):
        for r in range(reps):
            A, B = X[s, r][mx[s, r]], Y[s, r][my[s, r]]
            assert got_ospa[s, r] == pytest.approx(brute_ospa(A, B, c, p), rel=1e-12, abs=1e-12)
            for alpha, g in got.items():
                assert g.total[s, r] == pytest.approx(brute_gospa(A, B, c, p, alpha), rel=1e-12, abs=1e-12)
            total_p, loc, k = brute_gospa2(A, B, c, p)
            g = got[2.0]
            assert g.total[s, r] ** p == pytest.approx(total_p, rel=1e-12, abs=1e-12)
            # random continuous points: the optimal partial assignment is unique, so are its parts
            assert g.localisation[s, r] == pytest.approx(loc, rel=1e-12, abs=1e-12)
            assert g.assigned[s, r] == k
            assert g.n_missed[s, r] == len(A) - k and g.n_false[s, r] == len(B) - k


@pytest.mark.parametrize("alpha", [2.0, 1.0, 0.3])
def test_gospa_parts_add_up_to_total_p(alpha):
    rng = np.random.default_rng(21)
    X, mx = random_padded(rng, (7, 9), 6, 2, 4.0)
    Y, my = random_padded(rng, (7, 9), 8, 2, 4.0)
    g = gospa(X, mx, Y, my, 1.2, 2.5, alpha)
    np.testing.assert_allclose(g.localisation + g.missed + g.false, g.total**2.5, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(g.missed, 1.2**2.5 / alpha * g.n_missed, rtol=1e-15)
    np.testing.assert_allclose(g.false, 1.2**2.5 / alpha * g.n_false, rtol=1e-15)
    np.testing.assert_array_equal(g.assigned + g.n_missed, mx.sum(-1))
    np.testing.assert_array_equal(g.assigned + g.n_false, my.sum(-1))
    assert (g.localisation >= 0).all()


def test_ospa_is_gospa_with_alpha_one_normalised():
    # GOSPA(α = 1)^p = max(n_x, n_y) · OSPA^p, an identity of the two definitions
    rng = np.random.default_rng(22)
    X, mx = random_padded(rng, (50,), 5, 3, 5.0)
    Y, my = random_padded(rng, (50,), 5, 3, 5.0)
    n = np.maximum(mx.sum(-1), my.sum(-1))
    np.testing.assert_allclose(gospa(X, mx, Y, my, 2.0, 3.0, 1.0).total ** 3, n * ospa(X, mx, Y, my, 2.0, 3.0) ** 3, rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------
# closed forms
# --------------------------------------------------------------------------
@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_closed_forms(p):
    c = 4.0
    one = np.array([[1.0, 2.0]])
    none = np.full((1, 2), np.nan)
    T, F = np.array([True]), np.array([False])
    # one missed target: GOSPA^p = c^p / 2, so GOSPA = c / 2^(1/p); OSPA = c (all cardinality error)
    g = gospa(one, T, none, F, c, p)
    assert g.total == pytest.approx(c / 2 ** (1 / p))
    assert (g.missed, g.false, g.localisation, g.n_missed, g.n_false, g.assigned) == (pytest.approx(c**p / 2), 0.0, 0.0, 1, 0, 0)
    assert ospa(one, T, none, F, c, p) == pytest.approx(c)
    # one false estimate: the mirror image
    g = gospa(none, F, one, T, c, p)
    assert g.total == pytest.approx(c / 2 ** (1 / p)) and g.false == pytest.approx(c**p / 2) and g.missed == 0
    # with α: c / α^(1/p)
    assert gospa(one, T, none, F, c, p, alpha=1.0).total == pytest.approx(c)
    assert gospa(one, T, none, F, c, p, alpha=0.5).total == pytest.approx(c * 2 ** (1 / p))
    # one pair 3 apart (< c): both are 3, all localisation
    near = one + [3.0, 0.0]
    g = gospa(one, T, near, T, c, p)
    assert g.total == pytest.approx(3.0) and g.localisation == pytest.approx(3.0**p) and g.assigned == 1
    assert ospa(one, T, near, T, c, p) == pytest.approx(3.0)
    # one pair 5 apart (> c): GOSPA^p = c^p (one missed + one false); OSPA = c
    far = one + [3.0, 4.0]
    g = gospa(one, T, far, T, c, p)
    assert g.total == pytest.approx(c) and g.assigned == 0 and g.n_missed == 1 and g.n_false == 1
    assert g.missed == pytest.approx(c**p / 2) and g.false == pytest.approx(c**p / 2)
    assert ospa(one, T, far, T, c, p) == pytest.approx(c)
    # α = 1 cuts the pair at c and calls it localisation
    g1 = gospa(one, T, far, T, c, p, alpha=1.0)
    assert g1.total == pytest.approx(c) and g1.localisation == pytest.approx(c**p) and g1.assigned == 1
    # two empty sets
    assert ospa(none, F, none, F, c, p) == 0.0 and gospa(none, F, none, F, c, p).total == 0.0
    # two truths, one exact estimate: GOSPA = (c^p / 2)^(1/p), OSPA = (c^p / 2)^(1/p) too
    two = np.array([[0.0, 0.0], [100.0, 0.0]])
    TT = np.array([True, True])
    assert gospa(two, TT, two[:1], T, c, p).total == pytest.approx((c**p / 2) ** (1 / p))
    assert ospa(two, TT, two[:1], T, c, p) == pytest.approx((c**p / 2) ** (1 / p))


# --------------------------------------------------------------------------
# properties
# --------------------------------------------------------------------------
def test_symmetric_and_order_free():
    rng = np.random.default_rng(23)
    X, mx = random_padded(rng, (40,), 5, 2, 3.0)
    Y, my = random_padded(rng, (40,), 4, 2, 3.0)
    g, h = gospa(X, mx, Y, my, 1.0), gospa(Y, my, X, mx, 1.0)
    np.testing.assert_allclose(g.total, h.total, rtol=1e-12)
    np.testing.assert_allclose(g.missed, h.false, rtol=1e-12)
    np.testing.assert_allclose(g.localisation, h.localisation, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ospa(X, mx, Y, my, 1.0), ospa(Y, my, X, mx, 1.0), rtol=1e-12)
    # the order of rows within a set carries no meaning
    px, py = rng.permutation(5), rng.permutation(4)
    np.testing.assert_allclose(gospa(X[:, px], mx[:, px], Y[:, py], my[:, py], 1.0).total, g.total, rtol=1e-12)
    # a set against itself is at distance 0
    assert np.all(ospa(X, mx, X, mx, 1.0) == 0.0) and np.all(gospa(X, mx, X, mx, 1.0).total == 0.0)


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_triangle_inequality(p):
    rng = np.random.default_rng(24)
    sets = [random_padded(rng, (300,), 4, 2, 3.0) for _ in range(3)]
    (X, mx), (Y, my), (Z, mz) = sets
    for metric in (lambda a, ma, b, mb: ospa(a, ma, b, mb, 1.5, p), lambda a, ma, b, mb: gospa(a, ma, b, mb, 1.5, p).total):
        xz, xy, yz = metric(X, mx, Z, mz), metric(X, mx, Y, my), metric(Y, my, Z, mz)
        assert np.all(xz <= xy + yz + 1e-12)


def test_batch_equals_one_set_at_a_time_and_broadcasts(monkeypatch):
    rng = np.random.default_rng(25)
    X, mx = random_padded(rng, (3, 5), 6, 2, 5.0)
    Y, my = random_padded(rng, (3, 5), 7, 2, 5.0)
    g = gospa(X, mx, Y, my, 2.0)
    o = ospa(X, mx, Y, my, 2.0)
    to_est, to_truth = gospa_assignment(X, mx, Y, my, 2.0)
    for k in range(3):
        for m in range(5):
            one = gospa(X[k, m], mx[k, m], Y[k, m], my[k, m], 2.0)
            for field in ("total", "localisation", "missed", "false"):
                assert getattr(one, field) == pytest.approx(getattr(g, field)[k, m], rel=1e-14, abs=0)
            assert (one.assigned, one.n_missed, one.n_false) == (g.assigned[k, m], g.n_missed[k, m], g.n_false[k, m])
            assert ospa(X[k, m], mx[k, m], Y[k, m], my[k, m], 2.0) == pytest.approx(o[k, m], rel=1e-14, abs=0)
            a, b = gospa_assignment(X[k, m], mx[k, m], Y[k, m], my[k, m], 2.0)
            np.testing.assert_array_equal(a, to_est[k, m])
            np.testing.assert_array_equal(b, to_truth[k, m])
    # the assignment is consistent both ways and pairs only present rows within c
    for (k, m, i) in zip(*np.nonzero(to_est >= 0)):
        j = to_est[k, m, i]
        assert to_truth[k, m, j] == i and mx[k, m, i] and my[k, m, j]
        assert np.linalg.norm(X[k, m, i] - Y[k, m, j]) < 2.0
    assert (to_est >= 0).sum() == g.assigned.sum()
    # a truth shared by all runs broadcasts against the runs' estimates
    shared = gospa(X[:, :1], mx[:, :1], Y, my, 2.0)
    np.testing.assert_allclose(shared.total, gospa(np.repeat(X[:, :1], 5, 1), np.repeat(mx[:, :1], 5, 1), Y, my, 2.0).total, rtol=1e-14)
    # small chunks of sets give the same result as one chunk
    monkeypatch.setattr(mt, "_CHUNK_ELEMENTS", 100)
    np.testing.assert_allclose(gospa(X, mx, Y, my, 2.0).total, g.total, rtol=1e-14, atol=0)


# --------------------------------------------------------------------------
# track switches and counts on hand-made sequences
# --------------------------------------------------------------------------
def test_track_switches_on_hand_made_labels():
    # one truth at the origin, one estimate slot per scan; each run is one label story
    stories = {  # label per scan; None = no estimate (gap), "far" = an estimate beyond c (also a gap)
        "steady": [1, 1, 1, 1],
        "one switch": [1, 1, 2, 2],
        "there and back": [1, 2, 1, 1],
        "gap then same": [1, None, None, 1],
        "gap then other": [1, None, 2, 2],
        "far estimate is a gap": [1, ("far", 2), 1, 1],
        "starts late": [None, 3, 3, 4],
    }
    expected = [0, 1, 2, 0, 1, 0, 1]
    K, M = 4, len(stories)
    truth = np.zeros((K, M, 1, 2))
    tmask = np.ones((K, M, 1), bool)
    est = np.full((K, M, 1, 2), np.nan)
    lab = np.full((K, M, 1), -1)
    emask = np.zeros((K, M, 1), bool)
    for m, story in enumerate(stories.values()):
        for k, s in enumerate(story):
            if s is None:
                continue
            far = isinstance(s, tuple)
            est[k, m, 0] = [50.0, 0.0] if far else [0.1, -0.2]
            lab[k, m, 0] = s[1] if far else s
            emask[k, m, 0] = True
    got = track_switches(truth, tmask, est, lab, emask, c=5.0)
    assert got.shape == (M, 1)
    np.testing.assert_array_equal(got[:, 0], expected)


def test_track_switches_when_two_tracks_swap_targets():
    # two truths side by side; the tracks' labels swap at scan 2 (a crossing tracked wrongly): one switch each
    K = 4
    truth = np.array([[[0.0, 0.0], [10.0, 0.0]]] * K)  # (K, N, d): no run axis at all
    est = truth + 0.1
    lab = np.array([[1, 2], [1, 2], [2, 1], [2, 1]])
    mask = np.ones((K, 2), bool)
    np.testing.assert_array_equal(track_switches(truth, mask, est, lab, mask, c=3.0), [1, 1])
    counts = track_counts(truth, mask, est, lab, mask, c=3.0)  # swapped, but every scan assigned
    assert (counts.confirmed, counts.false, counts.lost, counts.truths) == (2, 0, 0, 2)
    # the truth rows absent at a scan do not count either
    tm = mask.copy()
    tm[1:3, 0] = False
    truth2 = truth.copy()
    truth2[1:3, 0] = np.nan
    np.testing.assert_array_equal(track_switches(truth2, tm, est, lab, mask, c=3.0), [1, 1])


def test_track_counts_on_hand_made_tracks():
    K = 4
    far = [50.0, 50.0]
    truth = np.full((K, 2, 3, 2), np.nan)  # (K, M = 2 runs, N = 3, d)
    tmask = np.zeros((K, 2, 3), bool)
    truth[:, :, 0] = [0.0, 0.0]  # truth 0: every scan, always tracked
    truth[:, :, 1] = [100.0, 0.0]  # truth 1: every scan, tracked at scans 0 and 2 (half: not lost)
    truth[1:, :, 2] = [0.0, 100.0]  # truth 2: scans 1..3, never tracked: lost
    tmask[:, :, :2] = True
    tmask[1:, :, 2] = True
    est = np.full((K, 2, 3, 2), np.nan)
    lab = np.full((K, 2, 3), -1)
    emask = np.zeros((K, 2, 3), bool)
    est[:, :, 0] = [0.2, 0.0]  # label 7 on truth 0 all its life
    lab[:, :, 0] = 7
    est[0, :, 1] = [100.0, 0.5]  # label 8: on truth 1 at scan 0, then far for 3 scans -> false
    est[1:, :, 1] = far
    lab[:, :, 1] = 8
    est[2, :, 2] = [100.0, -0.5]  # slot 2: on truth 1 at scan 2, far at scan 3
    est[3, :, 2] = far
    lab[2:, 0, 2] = 9  # run 0: its own label 9, assigned half its life: not false
    lab[2:, 1, 2] = 8  # run 1: the same track as label 8, now 2 of 6 scans assigned: still false
    emask[:, :, :2] = True
    emask[2:, :, 2] = True
    counts = track_counts(truth, tmask, est, lab, emask, c=2.0)
    np.testing.assert_array_equal(counts.confirmed, [3, 2])
    np.testing.assert_array_equal(counts.false, [1, 1])
    np.testing.assert_array_equal(counts.lost, [1, 1])
    np.testing.assert_array_equal(counts.truths, [3, 3])
    # no estimates at all: nothing confirmed, every truth lost
    none = track_counts(truth, tmask, est, lab, np.zeros_like(emask), c=2.0)
    np.testing.assert_array_equal(none.confirmed, [0, 0])
    np.testing.assert_array_equal(none.lost, [3, 3])


# --------------------------------------------------------------------------
# averages over runs
# --------------------------------------------------------------------------
def test_run_average_matches_student_t_and_covers():
    rng = np.random.default_rng(26)
    v = rng.normal(3.0, 2.0, (2000, 10))  # 2000 scans, 10 runs
    avg = run_average(v)
    np.testing.assert_allclose(avg.per_scan, v.mean(1))
    np.testing.assert_allclose(avg.per_scan_half_width, stats.t.ppf(0.975, 9) * v.std(1, ddof=1) / np.sqrt(10), rtol=1e-10)
    np.testing.assert_allclose(avg.per_run, v.mean(0))
    assert avg.mean == pytest.approx(v.mean())
    assert avg.half_width == pytest.approx(stats.t.ppf(0.975, 9) * v.mean(0).std(ddof=1) / np.sqrt(10), rel=1e-10)
    # coverage of the per-scan intervals ~ Binomial(2000, 0.95): sd 0.5 %, accept ±2 % (4 sd)
    covered = np.abs(avg.per_scan - 3.0) <= avg.per_scan_half_width
    assert 0.93 <= covered.mean() <= 0.97
    assert np.isnan(run_average(v[:, :1]).half_width)


def test_gospa_summary_parts_add_up():
    rng = np.random.default_rng(27)
    X, mx = random_padded(rng, (12, 30), 4, 2, 6.0)
    Y, my = random_padded(rng, (12, 30), 6, 2, 6.0)
    s = gospa_summary(gospa(X, mx, Y, my, 3.0))
    assert set(s) == {"total", "total_p", "localisation", "missed", "false"}
    parts = s["localisation"].per_scan + s["missed"].per_scan + s["false"].per_scan
    np.testing.assert_allclose(parts, s["total_p"].per_scan, rtol=1e-12)
    assert s["localisation"].mean + s["missed"].mean + s["false"].mean == pytest.approx(s["total_p"].mean, rel=1e-12)
    assert s["total"].per_scan.shape == (12,) and s["total"].per_run.shape == (30,)


# --------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------
X1 = np.zeros((2, 2))
M1 = np.ones(2, bool)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(truth=np.zeros(2)), "truth"),
        (dict(truth=[["a", "b"]], truth_mask=np.ones(1, bool)), "truth"),
        (dict(truth_mask=np.ones(2)), "truth_mask"),
        (dict(truth_mask=np.ones(3, bool)), "truth_mask"),
        (dict(truth=np.array([[0.0, np.nan], [1.0, 1.0]])), "truth"),
        (dict(est=np.array([[np.inf, 0.0], [1.0, 1.0]])), "est"),
        (dict(est=np.zeros((2, 3)), est_mask=M1), "est"),
        (dict(est=np.zeros((4, 2, 2)), est_mask=np.ones((4, 2), bool), truth=np.zeros((3, 2, 2)), truth_mask=np.ones((3, 2), bool)), "est"),
        (dict(est_mask=np.ones((1, 2), bool)), "est_mask"),
        (dict(c=0.0), "c"),
        (dict(c=np.nan), "c"),
        (dict(p=0.5), "p"),
        (dict(p=np.inf), "p"),
        (dict(alpha=0.0), "alpha"),
        (dict(alpha=2.5), "alpha"),
    ],
)
def test_bad_input_names_the_argument(kwargs, field):
    args = dict(truth=X1, truth_mask=M1, est=X1, est_mask=M1, c=1.0, p=2.0, alpha=2.0) | kwargs
    with pytest.raises(ValueError, match=rf"^{field}:"):
        gospa(**args)
    if "alpha" not in kwargs:
        args.pop("alpha")
        with pytest.raises(ValueError, match=rf"^{field}:"):
            ospa(**args)


def test_bad_track_input_names_the_argument():
    truth = np.zeros((3, 1, 2))
    tm = np.ones((3, 1), bool)
    lab = np.ones((3, 1), int)
    with pytest.raises(ValueError, match="^est_labels:"):
        track_switches(truth, tm, truth, lab.astype(float), tm, 1.0)
    with pytest.raises(ValueError, match="^est_labels:"):
        track_counts(truth, tm, truth, -lab, tm, 1.0)
    with pytest.raises(ValueError, match="^est_labels:"):
        track_counts(truth, tm, truth, np.ones((3, 2), int), tm, 1.0)
    with pytest.raises(ValueError, match="^truth_positions:"):
        track_switches(truth[0], tm[0], truth[0], lab[0], tm[0], 1.0)
    with pytest.raises(ValueError, match="^level:"):
        run_average(np.ones((2, 2)), level=1.0)
    with pytest.raises(ValueError, match="^values:"):
        run_average(np.ones(3))
    with pytest.raises(ValueError, match="^result:"):
        gospa_summary(gospa(X1, M1, X1, M1, 1.0))
