"""Scans, MultiTargetTruth and pad_scans: shapes, counts, selections and every validation error."""

import numpy as np
import pytest

from pursuit.multitarget import CLUTTER, PADDING, MultiTargetTruth, Scans, pad_scans


def _ragged(rng, K=4, M=3, m=2, most=5):
    dets = [[rng.normal(size=(int(rng.integers(0, most + 1)), m)) for _ in range(M)] for _ in range(K)]
    origins = [[rng.integers(-1, 3, size=len(d)) for d in scan] for scan in dets]
    return dets, origins


def test_pad_scans_packs_each_run_first_and_counts(rng):
    dets, origins = _ragged(rng)
    s = pad_scans(dets, [1.0, 2.0, 3.5, 4.0], origins)
    K, M = 4, 3
    D = max(len(d) for scan in dets for d in scan)
    assert s.z.shape == (K, M, D, 2) and s.origin.shape == (K, M, D)
    assert (s.steps, s.runs, s.dim, s.capacity) == (K, M, 2, D)
    for k in range(K):
        for i in range(M):
            n = len(dets[k][i])
            assert s.count[k, i] == n
            np.testing.assert_array_equal(s.z[k, i, :n], dets[k][i])
            np.testing.assert_array_equal(s.per_run(k, i), dets[k][i])
            assert np.isnan(s.z[k, i, n:]).all()
            np.testing.assert_array_equal(s.origin[k, i, :n], origins[k][i])
            assert (s.origin[k, i, n:] == PADDING).all()
    np.testing.assert_array_equal(s.present, ~np.isnan(s.z[..., 0]))


def test_pad_scans_all_empty_needs_dim():
    with pytest.raises(ValueError, match="^dim"):
        pad_scans([[[], []]], [0.0])
    s = pad_scans([[[], []]], [0.0], dim=3)
    assert s.z.shape == (1, 2, 0, 3) and (s.count == 0).all()


@pytest.mark.parametrize(
    "dets,times,field",
    [
        ([[np.ones((1, 2))], [np.ones((1, 2)), np.ones((1, 2))]], [0, 1], r"detections\[1\]"),
        ([[np.ones((1, 2))], [np.ones((1, 3))]], [0, 1], "detections"),
        ([[np.array([[1.0, np.nan]])]], [0], r"detections\[0\]\[0\]"),
        ([[np.ones(3)]], [0], r"detections\[0\]\[0\]"),
        ([], [], "detections"),
        ([[np.ones((1, 2))], [np.ones((1, 2))]], [1, 1], "times"),
        ([[np.ones((1, 2))]], [0, 1], "times"),
    ],
)
def test_pad_scans_rejects_bad_input(dets, times, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        pad_scans(dets, times)


def test_pad_scans_origin_count_must_match():
    with pytest.raises(ValueError, match=r"^origins\[0\]\[0\]"):
        pad_scans([[np.ones((2, 2))]], [0.0], [[[0]]])


def _scans(**kw):
    z = np.full((2, 2, 3, 2), np.nan)
    z[:, :, 0] = 1.0
    z[0, 1, 1] = 2.0
    origin = np.full((2, 2, 3), PADDING)
    origin[:, :, 0] = 0
    origin[0, 1, 1] = CLUTTER
    args = {"z": z, "times": [0.0, 1.0], "origin": origin}
    args.update(kw)
    return Scans(**args)


def test_scans_count_and_read_only():
    s = _scans()
    np.testing.assert_array_equal(s.count, [[1, 2], [1, 1]])
    with pytest.raises(ValueError):
        s.z[0, 0, 0, 0] = 5.0


@pytest.mark.parametrize(
    "change,field",
    [
        (lambda z, o: (z[0], o), "z"),
        (lambda z, o: (z.__setitem__((0, 0, 2, 0), 3.0) or z, o), "z"),
        (lambda z, o: (z.__setitem__((1, 1, 0, 1), np.inf) or z, o), "z"),
        (lambda z, o: (z, o[..., :2]), "origin"),
        (lambda z, o: (z, o.__setitem__((0, 0, 0), PADDING) or o), "origin"),
        (lambda z, o: (z, o.__setitem__((0, 0, 2), 1) or o), "origin"),
        (lambda z, o: (z, o.__setitem__((0, 0, 0), -3) or o), "origin"),
        (lambda z, o: (z, o + 0.5), "origin"),
    ],
    ids=[
        "not-4d", "half-nan-row", "inf", "origin-shape", "detection-marked-padding", "padding-with-origin", "origin-below-2",
        "origin-float",
    ],
)
def test_scans_validation_names_the_field(change, field):
    base = _scans()
    z, o = change(np.array(base.z), np.array(base.origin))
    with pytest.raises(ValueError, match=f"^{field}"):
        Scans(z, base.times, o)


def test_scans_times_must_increase():
    with pytest.raises(ValueError, match="^times"):
        _scans(times=[1.0, 1.0])
    with pytest.raises(ValueError, match="^times"):
        _scans(times=[0.0, np.nan])
    with pytest.raises(ValueError, match="^times"):
        _scans(times=[0.0])


def test_select_runs_keeps_runs_and_trims_padding():
    s = _scans()
    one = s.select_runs([0])
    assert one.z.shape == (2, 1, 1, 2)  # run 0 never uses more than one row
    np.testing.assert_array_equal(one.count, s.count[:, :1])
    np.testing.assert_array_equal(one.origin, s.origin[:, :1, :1])
    both = s.select_runs(slice(None))
    assert both.z.shape == (2, 2, 2, 2)
    mask = s.select_runs(np.array([False, True]))
    np.testing.assert_array_equal(mask.count, s.count[:, 1:])
    with pytest.raises(ValueError, match="^idx"):
        s.select_runs(0)
    assert Scans(s.z, s.times).select_runs([1]).origin is None


def _truth():
    states = np.full((3, 2, 2, 4), np.nan)
    states[:, :, 0] = 1.0
    states[1:, :, 1] = 2.0
    return states, ~np.isnan(states[..., 0]), np.array([7, 9])


def test_truth_positions_count_select():
    states, exists, labels = _truth()
    t = MultiTargetTruth(states, exists, labels)
    assert (t.steps, t.runs, t.targets) == (3, 2, 2)
    np.testing.assert_array_equal(t.count, [[1, 1], [2, 2], [2, 2]])
    pos = t.positions((0, 2))
    assert pos.shape == (3, 2, 2, 2)
    np.testing.assert_array_equal(np.isnan(pos[..., 0]), ~t.exists)
    sel = t.select_runs([1])
    assert sel.states.shape == (3, 1, 2, 4)
    np.testing.assert_array_equal(sel.labels, labels)
    with pytest.raises(ValueError, match="^indices"):
        t.positions((0, 4))


@pytest.mark.parametrize(
    "change,field",
    [
        (lambda s, e, l: (s[..., 0], e, l), "states"),
        (lambda s, e, l: (s, e[:, :1], l), "exists"),
        (lambda s, e, l: (s, e.astype(int), l), "exists"),
        (lambda s, e, l: (s, ~e, l), "exists"),
        (lambda s, e, l: (s.__setitem__((0, 0, 0, 1), np.nan) or s, e, l), "states"),
        (lambda s, e, l: (s.__setitem__((0, 0, 0, 1), np.inf) or s, e, l), "states"),
        (lambda s, e, l: (s, e, np.array([1, 1])), "labels"),
        (lambda s, e, l: (s, e, np.array([1])), "labels"),
        (lambda s, e, l: (s, e, np.array([1.0, 2.0])), "labels"),
    ],
)
def test_truth_validation_names_the_field(change, field):
    states, exists, labels = _truth()
    with pytest.raises(ValueError, match=f"^{field}"):
        MultiTargetTruth(*change(states, exists, labels))
