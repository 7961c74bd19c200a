"""Checks shared by the GNN and JPDA tests (spec 05 §7), written once for both trackers."""

from __future__ import annotations

import numpy as np

import pursuit as pu
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantVelocity, RangeBearing
from pursuit.multitarget import track_scans

from ._scenes import cv_models, simulate

CLUTTER_REGION = ((-60.0, 60.0), (-60.0, 60.0))
CLUTTER_RATE = 10.0
CLUTTER_DENSITY = CLUTTER_RATE / 120.0**2
CROSSING = [[-40.0, 1.0, -40.0, 1.0], [-40.0, 1.0, 40.0, -1.0], [40.0, -1.0, 0.0, 0.1]]


def kf():
    cv, meas = cv_models()
    return pu.KalmanFilter(cv, meas)


def cluttered_scene(runs: int = 6, K: int = 40, seed: int = 5):
    return simulate(CROSSING, K, runs, seed, p_detect=0.9, clutter_rate=CLUTTER_RATE, region=CLUTTER_REGION)


def check_single_target_equals_kf(make):
    """One target, no clutter, P_D = 1, a given prior: the tracker is the KF (1e-9)."""
    filt = kf()
    truth, z = simulate([[0.0, 1.0, 0.0, 0.5]], 30, 4, 1, shuffle=False)
    prior = Gaussian(np.array([0.5, 0.8, -0.3, 0.4]), np.diag([4.0, 1.0, 4.0, 1.0]))
    want = pu.run(filt, z[:, :, 0], prior)
    res = track_scans(make(filt, 1.0, 1e-12, gate=1.0 - 1e-9), z, initial=Gaussian(prior.mean[None], prior.cov[None]))
    np.testing.assert_allclose(res.mean[:, :, 0], want.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.cov[:, :, 0], want.cov, rtol=1e-9, atol=1e-12)
    assert (res.label[:, :, 0] == 0).all() and res.confirmed[:, :, 0].all()
    assert (res.label[:, :, 1:] == -1).all()


def check_separated_targets_equal_independent_kfs(make):
    """Well-separated targets, no clutter, P_D = 1, detections shuffled: one KF per target."""
    filt = kf()
    starts = [[-1000.0, 1.0, 0.0, 0.0], [1000.0, -1.0, 0.0, 0.0], [0.0, 0.0, 1000.0, 1.0]]
    truth, _ = simulate(starts, 25, 3, 2, shuffle=False)
    rng = np.random.default_rng(9)
    z_true = truth[..., [0, 2]] + rng.normal(0.0, 1.0, truth[..., [0, 2]].shape)  # (K, M, N, 2)
    z = np.stack([zk[:, rng.permutation(3)] for zk in z_true])  # shuffled within each scan
    priors = Gaussian(np.array(starts), np.diag([4.0, 1.0, 4.0, 1.0]))
    res = track_scans(make(filt, 1.0, 1e-12, gate=1.0 - 1e-9), z, initial=priors)
    for i in range(3):
        want = pu.run(filt, z_true[:, :, i], Gaussian(priors.mean[i], priors.cov))
        np.testing.assert_allclose(res.mean[:, :, i], want.mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(res.cov[:, :, i], want.cov, rtol=1e-9, atol=1e-12)


def nearest_errors(res, truth, indices=(0, 2)):
    """Distance from each true target to the nearest confirmed track: ``(K, M, N)``."""
    pos, mask = res.positions(indices)
    d = np.linalg.norm(pos[:, :, :, None] - truth[..., list(indices)][:, :, None], axis=-1)
    return np.where(mask[..., None], d, np.inf).min(axis=2)


def check_tracks_crossing_targets_in_clutter(make, filt=None):
    """Initiation from nothing in clutter: every target held by a confirmed track after a few scans."""
    truth, z = cluttered_scene()
    res = track_scans(make(filt or kf(), 0.9, CLUTTER_DENSITY, max_speed=3.0), z)
    err = nearest_errors(res, truth)[8:]
    assert (err < 4.0).mean() > 0.97
    n_conf = res.confirmed[8:].sum(axis=-1)
    assert n_conf.mean() < 3.3  # few false tracks
    return res


def check_order_of_detections_does_not_matter(make):
    truth, z = cluttered_scene(runs=4, K=30)
    tracker = make(kf(), 0.9, CLUTTER_DENSITY, max_speed=3.0)
    a = track_scans(tracker, z)
    rng = np.random.default_rng(4)
    zp = z.copy()
    for k in range(z.shape[0]):
        for m in range(z.shape[1]):
            zp[k, m] = z[k, m][rng.permutation(z.shape[2])]
    b = track_scans(tracker, zp)
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.confirmed, b.confirmed)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-12, atol=1e-10)


def check_batch_equals_one_run_at_a_time(make):
    truth, z = cluttered_scene(runs=4, K=30)
    tracker = make(kf(), 0.9, CLUTTER_DENSITY, max_speed=3.0)
    whole = track_scans(tracker, z)
    for m in range(z.shape[1]):
        one = track_scans(tracker, z[:, m : m + 1])
        np.testing.assert_array_equal(one.label[:, 0], whole.label[:, m])
        np.testing.assert_array_equal(one.confirmed[:, 0], whole.confirmed[:, m])
        np.testing.assert_allclose(one.mean[:, 0], whole.mean[:, m], rtol=1e-12, atol=1e-10)


def check_same_seed_same_bits(make):
    tracker = make(kf(), 0.9, CLUTTER_DENSITY, max_speed=3.0)
    a = track_scans(tracker, cluttered_scene(runs=3, K=25, seed=8)[1])
    b = track_scans(tracker, cluttered_scene(runs=3, K=25, seed=8)[1])
    for name in ("mean", "cov", "label", "confirmed", "dropped"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def range_bearing_scene(runs: int = 6, K: int = 40, seed: int = 12):
    """Two targets seen by one range-bearing sensor at the origin, clutter uniform in range and bearing."""
    cv = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
    rb = RangeBearing(np.zeros(2), 1.0, 0.005)
    r_lo, r_hi, b_lo, b_hi = 50.0, 400.0, 0.0, np.pi / 2
    rate = 5.0

    def clutter(rng, count):
        return np.column_stack([rng.uniform(r_lo, r_hi, count), rng.uniform(b_lo, b_hi, count)])

    starts = [[150.0, 1.0, 100.0, 0.5], [100.0, -0.5, 250.0, 1.0]]
    truth, z = simulate(starts, K, runs, seed, motion=cv, measurement=rb, p_detect=0.9, clutter_rate=rate, clutter_sampler=clutter)
    return cv, rb, truth, z, rate / ((r_hi - r_lo) * (b_hi - b_lo))


def check_ekf_range_bearing(make):
    cv, rb, truth, z, density = range_bearing_scene()
    res = track_scans(make(pu.ExtendedKalmanFilter(cv, rb), 0.9, density, max_speed=4.0), z)
    err = nearest_errors(res, truth)[10:]
    assert (err < 5.0).mean() > 0.95
    assert res.confirmed[10:].sum(axis=-1).mean() < 2.5
