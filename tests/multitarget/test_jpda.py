"""JPDA tracker: spec 05 §7 checks, the combined update against the spread-of-means formula."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import InteractingMultipleModel
from pursuit.gaussian import Gaussian
from pursuit.multitarget import JPDATracker, track_scans
from pursuit.models import ConstantVelocity
from pursuit.multitarget.association import evaluate_hypotheses, jpda_marginals, log_weights
from pursuit.multitarget.jpda import combine

from . import _checks


def test_single_target_equals_the_kalman_filter():
    _checks.check_single_target_equals_kf(JPDATracker)


def test_separated_targets_equal_independent_kalman_filters():
    _checks.check_separated_targets_equal_independent_kfs(JPDATracker)


def test_crossing_targets_in_clutter_from_nothing():
    _checks.check_tracks_crossing_targets_in_clutter(JPDATracker)


def test_order_of_detections_within_a_scan_does_not_matter():
    _checks.check_order_of_detections_does_not_matter(JPDATracker)


def test_batch_equals_one_run_at_a_time():
    _checks.check_batch_equals_one_run_at_a_time(JPDATracker)


def test_same_seed_same_bits():
    _checks.check_same_seed_same_bits(JPDATracker)


def test_ekf_with_range_bearing():
    _checks.check_ekf_range_bearing(JPDATracker)


@pytest.mark.parametrize("seed", range(5))
def test_moment_matching_equals_the_spread_of_means_formula(seed):
    """For the KF: x = x̄ + K ν, P = β₀ P̄ + (1 − β₀) P_c + K (Σ β_r ν_r ν_rᵀ − ν νᵀ) Kᵀ (Bar-Shalom, Fortmann)."""
    kf = _checks.kf()
    rng = np.random.default_rng(seed)
    M, L, D = 2, 3, 4
    mean = rng.normal(0.0, 2.0, (M, L, 4))
    P0 = np.diag([3.0, 0.5, 2.0, 0.7])
    state = kf.init(Gaussian(mean, P0), batch=(M, L))
    z = rng.normal(0.0, 3.0, (M, D, 2))
    hyp = evaluate_hypotheses(kf, state, z, np.ones((M, L), dtype=bool), 0.99, k=1)
    w = rng.random((M, L, D + 1))
    w /= w.sum(axis=-1, keepdims=True)
    beta0, beta = w[..., 0], w[..., 1:]
    assert (hyp.pair >= 0).all()
    pb = beta[hyp.runs, hyp.tracks, hyp.dets]
    x, P = combine(hyp.missed.mean, hyp.missed.cov, hyp.states.mean, hyp.states.cov, hyp.runs, hyp.tracks, pb, beta0)

    F, Q, H, R = kf.motion.transition_matrix(), kf.motion.cov(), kf.measurement.matrix(), kf.measurement.cov()
    xb = mean @ F.T
    Pb = F @ P0 @ F.T + Q
    S = H @ Pb @ H.T + R
    K = Pb @ H.T @ np.linalg.inv(S)
    nus = z[:, None, :, :] - (xb @ H.T)[:, :, None, :]  # (M, L, D, 2)
    nu = np.einsum("mlr,mlri->mli", beta, nus)
    Pc = Pb - K @ S @ K.T
    spread = np.einsum("mlr,mlri,mlrj->mlij", beta, nus, nus) - nu[..., :, None] * nu[..., None, :]
    want_x = xb + nu @ K.T
    want_P = beta0[..., None, None] * Pb + (1.0 - beta0)[..., None, None] * Pc + K @ spread @ K.T
    np.testing.assert_allclose(x, want_x, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P, want_P, rtol=1e-9, atol=1e-10)


def test_a_capped_cluster_still_tracks():
    truth, z = _checks.cluttered_scene(runs=3, K=30)
    exact = track_scans(JPDATracker(_checks.kf(), 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    capped = track_scans(JPDATracker(_checks.kf(), 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0, max_events=1), z)
    e1 = _checks.nearest_errors(exact, truth)[8:]
    e2 = _checks.nearest_errors(capped, truth)[8:]
    assert (e2 < 4.0).mean() > 0.95 and (e1 < 4.0).mean() > 0.95


def test_sigma_point_filter_works():
    kf = _checks.kf()
    _checks.check_tracks_crossing_targets_in_clutter(JPDATracker, pu.CubatureKalmanFilter(kf.motion, kf.measurement))


def test_imm_with_one_mode_equals_its_filter():
    truth, z = _checks.cluttered_scene(runs=3, K=25)
    kf = _checks.kf()
    want = track_scans(JPDATracker(kf, 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    got = track_scans(JPDATracker(InteractingMultipleModel([kf]), 0.9, _checks.CLUTTER_DENSITY, max_speed=3.0), z)
    np.testing.assert_array_equal(got.label, want.label)
    np.testing.assert_allclose(got.mean, want.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got.cov, want.cov, rtol=1e-9, atol=1e-9)


def test_imm_jpda_moments_match_the_mixture_over_hypotheses_and_modes():
    """The combined IMM state has the mean and covariance of the mixture over (hypothesis r, mode j), weights β_r μ_jr."""
    kf = _checks.kf()
    quiet, loud = kf, pu.KalmanFilter(ConstantVelocity(ndim=2, dt=1.0, q=0.5), kf.measurement)
    imm = InteractingMultipleModel([quiet, loud], 0.9)
    rng = np.random.default_rng(3)
    M, L, D = 2, 2, 3
    state = imm.init(Gaussian(rng.normal(0.0, 2.0, (M, L, 4)), np.eye(4)), batch=(M, L))
    z = rng.normal(0.0, 2.0, (M, D, 2))
    hyp = evaluate_hypotheses(imm, state, z, np.ones((M, L), dtype=bool), 1.0 - 1e-9, k=1)
    log_g = log_weights(hyp, 0.9, 1e-2, 1.0 - 1e-9)
    tracker = JPDATracker(imm, 0.9, 1e-2, gate=1.0 - 1e-9)
    got, _ = tracker.associate(hyp, log_g)
    beta, beta0 = jpda_marginals(log_g)
    for m in range(M):
        for t in range(L):
            parts = [(beta0[m, t], hyp.missed, (m, t))] + [(beta[m, t, r], hyp.states, hyp.pair[m, t, r]) for r in range(D)]
            ws, xs, Ps = [], [], []
            for b, s, i in parts:
                for j in range(2):
                    ws.append(b * s.probs[i][j])
                    xs.append(s.modes[j].mean[i])
                    Ps.append(s.modes[j].cov[i])
            ws, xs, Ps = np.array(ws), np.array(xs), np.array(Ps)
            mean = ws @ xs
            d = xs - mean
            cov = np.einsum("a,aij->ij", ws, Ps) + np.einsum("a,ai,aj->ij", ws, d, d)
            np.testing.assert_allclose(got.mean[m, t], mean, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(got.cov[m, t], cov, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(got.probs[m, t], ws.reshape(-1, 2).sum(axis=0), rtol=1e-12)
            for j in range(2):
                wj = ws[j::2] / ws[j::2].sum()
                np.testing.assert_allclose(got.modes[j].mean[m, t], wj @ xs[j::2], rtol=1e-9, atol=1e-9)


def test_imm_tracks_in_clutter():
    kf = _checks.kf()
    imm = InteractingMultipleModel([kf, pu.KalmanFilter(ConstantVelocity(ndim=2, dt=1.0, q=0.5), kf.measurement)], 0.95)
    _checks.check_tracks_crossing_targets_in_clutter(JPDATracker, imm)
