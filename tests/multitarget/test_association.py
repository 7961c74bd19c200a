"""Hypothesis evaluation, gating, state trees and JPDA marginals against brute force (spec 05 §7)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import InteractingMultipleModel as IMM
from pursuit.filters.gating import chi2_gate_thresholds
from pursuit.gaussian import Gaussian
from pursuit.multitarget.association import (
    evaluate_hypotheses,
    jpda_marginals,
    jpda_marginals_lbp,
    log_weights,
    select_state,
    where_state,
)

from ._scenes import cv_models


def events(L: int, D: int, gated: np.ndarray):
    """Every joint event: a tuple giving each track a detection or −1, detections used at most once."""
    options = [[-1] + [r for r in range(D) if gated[t, r]] for t in range(L)]
    for choice in itertools.product(*options):
        used = [r for r in choice if r >= 0]
        if len(used) == len(set(used)):
            yield choice


def brute_marginals(log_g: np.ndarray) -> np.ndarray:
    """β (L, D) of one run by enumerating every joint event of the whole run."""
    L, D = log_g.shape
    gated = np.isfinite(log_g)
    beta = np.zeros((L, D))
    total = 0.0
    for choice in events(L, D, gated):
        w = np.exp(sum(log_g[t, r] for t, r in enumerate(choice) if r >= 0))
        total += w
        for t, r in enumerate(choice):
            if r >= 0:
                beta[t, r] += w
    return beta / total


def random_log_g(rng, M: int, L: int, D: int, density: float) -> np.ndarray:
    log_g = rng.normal(0.0, 2.0, (M, L, D))
    return np.where(rng.random((M, L, D)) < density, log_g, -np.inf)


@pytest.mark.parametrize("seed", range(40))
def test_jpda_marginals_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    M, L, D = 3, int(rng.integers(1, 6)), int(rng.integers(1, 6))
    log_g = random_log_g(rng, M, L, D, density=rng.uniform(0.2, 0.9))
    beta, beta0 = jpda_marginals(log_g)
    for m in range(M):
        want = brute_marginals(log_g[m])
        np.testing.assert_allclose(beta[m], want, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(beta0[m], 1.0 - want.sum(axis=1), rtol=1e-12, atol=1e-14)


def test_jpda_marginals_permute_with_tracks_and_detections():
    rng = np.random.default_rng(7)
    log_g = random_log_g(rng, 4, 5, 6, 0.6)
    beta, beta0 = jpda_marginals(log_g)
    pt, pr = rng.permutation(5), rng.permutation(6)
    beta_p, beta0_p = jpda_marginals(log_g[:, pt][:, :, pr])
    np.testing.assert_allclose(beta_p, beta[:, pt][:, :, pr], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(beta0_p, beta0[:, pt], rtol=1e-12, atol=1e-15)


def test_cap_falls_back_to_loopy_belief_propagation():
    rng = np.random.default_rng(3)
    log_g = np.zeros((1, 4, 4))  # every track gates every detection: one cluster, 209 events
    log_g += rng.normal(0.0, 1.0, log_g.shape)
    exact, _ = jpda_marginals(log_g)
    capped, capped0 = jpda_marginals(log_g, max_events=50)
    lbp, lbp0 = jpda_marginals_lbp(log_g)
    np.testing.assert_allclose(capped, lbp, rtol=1e-12)
    np.testing.assert_allclose(capped0, np.clip(lbp0, 0, 1), rtol=1e-12)
    assert not np.allclose(capped, exact, rtol=1e-6)  # an approximation on a loopy graph...
    np.testing.assert_allclose(capped, exact, atol=0.1)  # ...and a close one


def test_loopy_belief_propagation_is_exact_on_a_tree():
    # Chain t0–r0–t1–r1–t2: no cycle.
    log_g = np.full((1, 3, 2), -np.inf)
    log_g[0, 0, 0], log_g[0, 1, 0], log_g[0, 1, 1], log_g[0, 2, 1] = 0.3, 1.2, -0.4, 0.8
    beta, _ = jpda_marginals_lbp(log_g)
    np.testing.assert_allclose(beta[0], brute_marginals(log_g[0]), rtol=1e-10)


def test_hypotheses_are_single_kalman_steps_and_gate_by_chi_square():
    cv, meas = cv_models()
    kf = pu.KalmanFilter(cv, meas)
    rng = np.random.default_rng(11)
    M, L, D = 2, 3, 4
    mean = rng.normal(0.0, 3.0, (M, L, 4))
    state = kf.init(Gaussian(mean, np.eye(4) * 2.0), batch=(M, L))
    z = rng.normal(0.0, 4.0, (M, D, 2))
    z[1, 3] = np.nan  # padding
    alive = np.array([[True, True, False], [True, False, True]])
    hyp = evaluate_hypotheses(kf, state, z, alive, 0.99, k=1)
    thr = chi2_gate_thresholds(0.99, 2)[2]
    for m, t, r in itertools.product(range(M), range(L), range(D)):
        if not alive[m, t] or np.isnan(z[m, r, 0]):
            assert not hyp.gated[m, t, r] and hyp.pair[m, t, r] == -1
            continue
        one = kf.init(Gaussian(mean[m, t], np.eye(4) * 2.0))
        s, info = kf.step(one, z[m, r], k=1)
        i = hyp.pair[m, t, r]
        assert (hyp.runs[i], hyp.tracks[i], hyp.dets[i]) == (m, t, r)
        np.testing.assert_allclose(hyp.states.mean[i], s.mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(hyp.states.cov[i], s.cov, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(hyp.loglik[m, t, r], info["loglik"], rtol=1e-12)
        assert hyp.gated[m, t, r] == (info["nis"] <= thr)
    pred, _ = kf.step(kf.init(Gaussian(mean[0, 0], np.eye(4) * 2.0)), [np.nan, np.nan], k=1)
    np.testing.assert_allclose(hyp.missed.mean[0, 0], pred.mean, rtol=1e-12)
    lg = log_weights(hyp, 0.9, 1e-3, 0.99)
    assert np.all(np.isneginf(lg[~hyp.gated]))
    base = np.log(0.9) - np.log(1 - 0.9 * 0.99) - np.log(1e-3)
    np.testing.assert_allclose(lg[hyp.gated], base + hyp.loglik[hyp.gated], rtol=1e-12)


def test_state_tree_operations_on_an_imm_state():
    cv, meas = cv_models()
    imm = IMM([pu.KalmanFilter(cv, meas), pu.KalmanFilter(cv, meas)], 0.9)
    rng = np.random.default_rng(2)
    a = imm.init(Gaussian(rng.normal(size=(2, 3, 4)), np.eye(4)), batch=(2, 3))
    b = imm.init(Gaussian(rng.normal(size=(2, 3, 4)), np.eye(4) * 2), batch=(2, 3))
    flat = imm.init(Gaussian(rng.normal(size=(5, 4)), np.eye(4) * 3), batch=(5,))  # five pair states
    mask = np.array([[True, False, True], [False, False, True]])
    w = where_state(mask, a, b)
    np.testing.assert_array_equal(w.modes[0].mean[mask], a.modes[0].mean[mask])
    np.testing.assert_array_equal(w.modes[0].mean[~mask], b.modes[0].mean[~mask])
    np.testing.assert_array_equal(w.probs[~mask], b.probs[~mask])
    position = np.array([[-1, 0, 4], [2, -1, 3]])
    s = select_state(b, flat, position)
    np.testing.assert_array_equal(s.mean[position < 0], b.mean[position < 0])
    np.testing.assert_array_equal(s.modes[1].cov[0, 2], flat.modes[1].cov[4])
    np.testing.assert_array_equal(s.modes[0].mean[1, 0], flat.modes[0].mean[2])
    assert s.k == b.k
