"""GNN tracker: spec 05 §7 checks, the assignment against brute force, any Gaussian filter and the IMM."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import InteractingMultipleModel
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.multitarget import GNNTracker, track_scans
from pursuit.multitarget.gnn import gnn_assign

from . import _checks


def test_single_target_equals_the_kalman_filter():
    _checks.check_single_target_equals_kf(GNNTracker)


def test_separated_targets_equal_independent_kalman_filters():
    _checks.check_separated_targets_equal_independent_kfs(GNNTracker)


def test_crossing_targets_in_clutter_from_nothing():
    _checks.check_tracks_crossing_targets_in_clutter(GNNTracker)


def test_order_of_detections_within_a_scan_does_not_matter():
    _checks.check_order_of_detections_does_not_matter(GNNTracker)


def test_batch_equals_one_run_at_a_time():
    _checks.check_batch_equals_one_run_at_a_time(GNNTracker)


def test_same_seed_same_bits():
    _checks.check_same_seed_same_bits(GNNTracker)


def test_ekf_with_range_bearing():
    _checks.check_ekf_range_bearing(GNNTracker)


def brute_best(log_g: np.ndarray) -> float:
    """The largest Σ log g over one-to-one partial assignments (exhaustive)."""
    L, D = log_g.shape
    best = 0.0
    options = [[-1] + [r for r in range(D) if np.isfinite(log_g[t, r])] for t in range(L)]
    for choice in itertools.product(*options):
        used = [r for r in choice if r >= 0]
        if len(used) == len(set(used)):
            best = max(best, sum(log_g[t, r] for t, r in enumerate(choice) if r >= 0))
    return best


@pytest.mark.parametrize("seed", range(30))
def test_assignment_is_the_brute_force_optimum(seed):
    rng = np.random.default_rng(seed)
    M, L, D = 4, int(rng.integers(1, 6)), int(rng.integers(1, 6))
    log_g = np.where(rng.random((M, L, D)) < rng.uniform(0.1, 0.9), rng.normal(0.0, 2.0, (M, L, D)), -np.inf)
    index = gnn_assign(log_g)
    for m in range(M):
        taken = [(t, r - 1) for t, r in enumerate(index[m]) if r > 0]
        assert len({r for _, r in taken}) == len(taken)  # one detection per track at most
        value = sum(log_g[m, t, r] for t, r in taken)
        assert np.isfinite(value)
        assert value == pytest.approx(brute_best(log_g[m]), rel=1e-12, abs=1e-12)


def test_sigma_point_filters_on_a_linear_model_equal_the_kalman_filter():
    truth, z = _checks.cluttered_scene(runs=3, K=25)
    kf = _checks.kf()
    want = track_scans(GNNTracker(kf, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    for filt in (pu.CubatureKalmanFilter(kf.motion, kf.measurement), pu.UnscentedKalmanFilter(kf.motion, kf.measurement)):
        got = track_scans(GNNTracker(filt, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
        np.testing.assert_array_equal(got.label, want.label)
        np.testing.assert_allclose(got.mean, want.mean, rtol=1e-7, atol=1e-7)


def test_imm_with_one_mode_equals_its_filter():
    truth, z = _checks.cluttered_scene(runs=3, K=25)
    kf = _checks.kf()
    want = track_scans(GNNTracker(kf, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    got = track_scans(GNNTracker(InteractingMultipleModel([kf]), 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    np.testing.assert_array_equal(got.label, want.label)
    np.testing.assert_allclose(got.mean, want.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.cov, want.cov, rtol=1e-9, atol=1e-9)


def test_imm_tracks_in_clutter():
    cv_quiet = ConstantVelocity(ndim=2, dt=1.0, q=0.001)
    cv_loud = ConstantVelocity(ndim=2, dt=1.0, q=0.5)
    meas = LinearGaussian.position(4, cv_quiet.position_indices, 1.0)
    imm = InteractingMultipleModel([pu.KalmanFilter(cv_quiet, meas), pu.KalmanFilter(cv_loud, meas)], 0.95)
    _checks.check_tracks_crossing_targets_in_clutter(GNNTracker, imm)


def test_a_compiled_per_track_filter_gives_the_numpy_tracks():
    pytest.importorskip("numba")
    truth, z = _checks.cluttered_scene(runs=3, K=25)
    kf = _checks.kf()
    compiled = pu.KalmanFilter(kf.motion, kf.measurement, backend="numba")
    assert compiled.compiled
    want = track_scans(GNNTracker(kf, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    got = track_scans(GNNTracker(compiled, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    np.testing.assert_array_equal(got.label, want.label)
    np.testing.assert_allclose(got.mean, want.mean, rtol=1e-9, atol=1e-9)
