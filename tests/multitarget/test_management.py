"""Track management: two-point initiation, M of N confirmation, deletion, labels, capacity, bad input."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.gaussian import Gaussian
from pursuit.initiation import polar_to_cartesian, two_point
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors
from pursuit.multitarget import GNNTracker, JPDATracker, track_scans
from pursuit.multitarget.management import detection_positions

CV = ConstantVelocity(ndim=2, dt=1.0, q=1e-6)
POS = LinearGaussian.position(4, CV.position_indices, 0.01)


def tracker(kind=GNNTracker, **kw):
    kw.setdefault("max_speed", 2.0)
    return kind(pu.KalmanFilter(CV, POS), 0.9, 1e-4, **kw)


def scans(pattern: str, velocity=(1.0, 0.5), start=(0.0, 0.0)):
    """One target in straight flight, detected at the scans marked 'x' of ``pattern`` ('.' = missed); ``(K, 1, 1, 2)``."""
    k = np.arange(1, len(pattern) + 1)[:, None]
    p = np.asarray(start) + k * np.asarray(velocity)
    z = np.where(np.array([c == "x" for c in pattern])[:, None], p, np.nan)
    return z[:, None, None, :]


@pytest.mark.parametrize("kind", [GNNTracker, JPDATracker])
def test_two_point_start_then_two_of_three_confirms(kind):
    res = track_scans(tracker(kind), scans("xxxx"))
    alive = res.label[:, 0] >= 0
    assert not alive[0].any()  # one scan: nothing to pair yet
    assert alive[1].sum() == 1 and not res.confirmed[1].any()  # tentative from scans 1 and 2
    assert not res.confirmed[2].any()  # one hit after initiation
    assert res.confirmed[3, 0].sum() == 1  # two hits of three: confirmed
    slot = np.nonzero(alive[1])[0][0]
    first = two_point([1.0, 0.5], POS.cov(), [2.0, 1.0], POS.cov(), 1.0, CV)
    np.testing.assert_allclose(res.mean[1, 0, slot], first.mean, atol=1e-12)
    np.testing.assert_allclose(res.cov[1, 0, slot], first.cov, atol=1e-15)


@pytest.mark.parametrize(
    "pattern, confirmed_at, deleted_at",
    [
        ("xxx.x", 5, None),  # hit, miss, hit: 2 of 3 at the third scan after initiation
        ("xx..", None, 4),  # two misses: 2 of 3 is out of reach
        ("xxxx...", 4, 7),  # confirmed, then deleted at the third consecutive miss
        ("xxxx..x...", 4, 10),  # a hit resets the run of misses
    ],
)
def test_m_of_n_confirmation_and_deletion(pattern, confirmed_at, deleted_at):
    res = track_scans(tracker(), scans(pattern))
    conf = res.confirmed[:, 0].any(axis=-1)
    alive = (res.label[:, 0] >= 0).any(axis=-1)
    first_conf = int(np.argmax(conf)) + 1 if conf.any() else None
    assert first_conf == confirmed_at
    if deleted_at is None:
        assert alive[-1]
    else:
        assert alive[deleted_at - 2] and not alive[deleted_at - 1:].any()


def test_labels_persist_and_are_never_reused():
    # The target is lost (deleted after 3 misses) and found again: the new track gets a new label.
    res = track_scans(tracker(), scans("xxxx...xxxx"))
    labels = [set(res.label[k, 0][res.label[k, 0] >= 0].tolist()) for k in range(res.steps)]
    assert labels[1:6] == [{0}] * 5
    assert labels[6] == set() and labels[7] == set()
    assert labels[8:] == [{1}] * 3


def test_pairs_beyond_the_maximum_speed_start_nothing():
    fast = scans("xxxx", velocity=(3.0, 0.0))
    assert (track_scans(tracker(max_speed=2.9), fast).label == -1).all()
    assert (track_scans(tracker(max_speed=3.1), fast).label >= 0).any()


def test_given_tracks_are_confirmed_and_need_no_initiation():
    t = GNNTracker(pu.KalmanFilter(CV, POS), 0.9, 1e-4)  # no max_speed: no initiation
    res = track_scans(t, scans("xxxx"), initial=Gaussian(np.array([[0.0, 1.0, 0.0, 0.5]]), np.eye(4)))
    assert (res.label[:, 0, 0] == 0).all() and res.confirmed[:, 0, 0].all()
    assert (res.label[:, 0, 1:] == -1).all()


def test_capacity_drops_the_excess_and_counts_it():
    # Three targets, two slots: the lexicographically last candidate is dropped.
    z = np.concatenate([scans("xxxx", start=s) for s in [(0.0, 0.0), (50.0, 0.0), (100.0, 0.0)]], axis=2)
    res = track_scans(tracker(capacity=2), z)
    assert res.dropped[1, 0] == 1
    assert (res.label[1:, 0] >= 0).all()
    np.testing.assert_allclose(np.sort(res.mean[1, 0, :, 0]), [2.0, 52.0], atol=1e-6)
    assert res.label[1, 0].tolist() == [0, 1]


def test_detection_positions_of_the_built_in_sensors():
    to_p = detection_positions(POS, CV)
    z = np.array([[3.0, 4.0], [1.0, -2.0]])
    p, C = to_p(z)
    np.testing.assert_array_equal(p, z)
    np.testing.assert_array_equal(C, np.broadcast_to(POS.cov(), (2, 2, 2)))
    rb = RangeBearing(np.array([10.0, 5.0]), 2.0, 0.01)
    p, C = detection_positions(rb, CV)(np.array([[100.0, 0.3]]))
    want_p, want_C = polar_to_cartesian(100.0, 0.3, 2.0, 0.01, (10.0, 5.0))
    np.testing.assert_allclose(p[0], want_p)
    np.testing.assert_allclose(C[0], want_C)
    ranges = RangeSensors(np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]), 1.0)
    assert detection_positions(ranges, CV) is None
    with pytest.raises(ValueError, match="^position: "):
        GNNTracker(pu.ExtendedKalmanFilter(CV, ranges), 0.9, 1e-4, max_speed=2.0)
    custom = GNNTracker(pu.ExtendedKalmanFilter(CV, ranges), 0.9, 1e-4, max_speed=2.0, position=to_p)
    assert custom.position is to_p


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"p_detect": 0.0}, "p_detect"),
        ({"p_detect": 1.5}, "p_detect"),
        ({"clutter_density": 0.0}, "clutter_density"),
        ({"gate": 1.0}, "gate"),
        ({"capacity": 0}, "capacity"),
        ({"confirm": (3, 2)}, "confirm"),
        ({"max_misses": 0}, "max_misses"),
        ({"max_speed": -1.0}, "max_speed"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    args = {"p_detect": 0.9, "clutter_density": 1e-4, **kwargs}
    with pytest.raises(ValueError, match=f"^{field}: "):
        GNNTracker(pu.KalmanFilter(CV, POS), args.pop("p_detect"), args.pop("clutter_density"), **args)


def test_bad_detections_and_initial_tracks_name_the_field():
    t = tracker()
    with pytest.raises(ValueError, match="^z: "):
        track_scans(t, np.zeros((3, 1, 2)))
    z = scans("xxx").copy()
    z[1, 0, 0, 1] = np.nan
    with pytest.raises(ValueError, match="^z: a detection row"):
        track_scans(t, z)
    with pytest.raises(ValueError, match="^initial: 3 tracks exceed"):
        track_scans(tracker(capacity=2), scans("xxx"), initial=Gaussian(np.zeros((3, 4)), np.eye(4)))
    with pytest.raises(TypeError, match="^filter: "):
        GNNTracker(object(), 0.9, 1e-4)


@pytest.mark.parametrize("kind", [GNNTracker, JPDATracker])
def test_scans_without_detections(kind):
    given = Gaussian(np.array([[0.0, 1.0, 0.0, 0.5]]), np.eye(4))
    for z in (np.zeros((4, 2, 0, 2)), np.full((4, 2, 3, 2), np.nan)):
        res = track_scans(tracker(kind), z, initial=given)
        assert (res.label[:2, :, 0] == 0).all() and (res.label[2:, :, 0] == -1).all()  # the third miss deletes it
        assert (res.label[:, :, 1:] == -1).all()
        pred = pu.run(pu.KalmanFilter(CV, POS), np.full((4, 2), np.nan), Gaussian(given.mean[0], given.cov))
        np.testing.assert_allclose(res.mean[:2, 0, 0], pred.mean[:2], rtol=1e-12)


def test_irregular_scan_times_step_with_their_differences():
    times = np.array([0.0, 1.0, 3.0, 3.5, 6.0])
    k = times[:, None]
    z = (np.array([1.0, 0.5]) * k)[:, None, None, :]
    res = track_scans(tracker(max_speed=2.0), z, times=times)
    assert (res.label[1:, 0] >= 0).sum(axis=-1).tolist() == [1, 1, 1, 1]
    slot = int(np.nonzero(res.label[-1, 0] >= 0)[0][0])
    np.testing.assert_allclose(res.mean[-1, 0, slot], [6.0, 1.0, 3.0, 0.5], atol=1e-4)


def test_a_particle_filter_is_refused_as_per_track_filter():
    from pursuit.filters import BootstrapParticleFilter
    from pursuit.models import ConstantVelocity, LinearGaussian
    from pursuit.multitarget import GNNTracker, JPDATracker

    pf = BootstrapParticleFilter(ConstantVelocity(ndim=2), LinearGaussian.position(4, (0, 2), 1.0), particles=10)
    for cls in (GNNTracker, JPDATracker):
        with pytest.raises(ValueError, match="filter: BootstrapParticleFilter cannot be a per-track filter"):
            cls(pf, 0.9, 1e-3)


def test_track_method_is_track_scans():
    from pursuit.filters import KalmanFilter
    from pursuit.multitarget import GNNTracker, track_scans
    from pursuit.rng import run_streams
    from pursuit.scenarios.multitarget import crossing

    sc = crossing(steps=6)
    _, scans = sc.simulate(run_streams(1, range(3), 0), 3)
    tracker = GNNTracker(KalmanFilter(sc.motion, sc.measurement), sc.p_detect, sc.clutter_density, max_speed=sc.max_speed)
    a = tracker.track(scans.z, times=scans.times)
    b = track_scans(tracker, scans.z, times=scans.times)
    assert np.array_equal(a.mean, b.mean, equal_nan=True) and np.array_equal(a.label, b.label)


def test_checked_scans_names_the_argument():
    from types import SimpleNamespace

    from pursuit.multitarget.tracking import checked_scans

    filt = SimpleNamespace(motion=SimpleNamespace(dt=None))
    z = np.zeros((3, 1, 2, 2))
    with pytest.raises(ValueError, match="times: the first scan is one motion-model dt after the start"):
        checked_scans(z, [1.0, 2.0, 3.0], filt)
    assert checked_scans(z, None, filt)[1] is None  # untimed scans need no dt
    with pytest.raises(ValueError, match="times: expected 3 increasing scan times"):
        checked_scans(z, [1.0, 1.0, 2.0], SimpleNamespace(motion=SimpleNamespace(dt=1.0)))
    z[0, 0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="z: detections must be finite or NaN"):
        checked_scans(z, None, filt)
