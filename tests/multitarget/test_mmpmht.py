"""The multiple-model PMHT (process-noise modes as missing data): PMHT with one mode, brute-force mode posteriors, EM."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pursuit as pu
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.multitarget import MMPMHTTracker, PMHTTracker
from pursuit.multitarget.mmpmht import noise_mode_posteriors
from pursuit.multitarget.pmht import em_window

from .test_pmht import CLUTTER_DENSITY, PRIOR_COV, cluttered_scene, kf, simulate, tracker, window_inputs


def test_one_mode_of_scale_one_is_pmht():
    truth, z = cluttered_scene(runs=3, K=25)
    a = tracker().track(z)
    b = tracker(MMPMHTTracker, noise_scales=(1.0,)).track(z)
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.iterations, b.iterations)
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.objective, a.objective, rtol=1e-12, atol=0)
    assert b.name.startswith("MMPMHT")


def _log_gauss(r: np.ndarray, S: np.ndarray) -> float:
    """log N(r; 0, S) on S's range (pseudo-inverse and pseudo-determinant), as PMHT's process term."""
    vals, vecs = np.linalg.eigh(S)
    keep = vals > vals.max() * 1e-12
    inv = (vecs[:, keep] / vals[keep]) @ vecs[:, keep].T
    return float(-0.5 * (r @ inv @ r + np.sum(np.log(2 * np.pi * vals[keep]))))


def test_mode_posteriors_equal_brute_force_enumeration():
    """Every mode sequence of a short window enumerated: log Σ p(X | modes) P(modes) and the marginals γ (1e-10)."""
    B, J, runs, L = 4, 3, 2, 2
    rng = np.random.default_rng(7)
    pm = rng.normal(0, 3, (runs, L, 4))
    pc = np.broadcast_to(PRIOR_COV, (runs, L, 4, 4)).copy()
    model, _, start = window_inputs(pm, np.full((B, runs, 1, 2), np.nan), B)
    first = np.array([[0, 1], [2, 0]])  # tracks starting mid-window too
    active = np.arange(B) >= first[..., None]
    # states in Q's range after the first step (as the smoother's are), off it at the first step
    X = start.copy()
    for b in range(1, B):
        w = rng.normal(0, 2.0, (runs, L, 2))
        X[:, :, b] = np.einsum("ij,mlj->mli", model.F[b], X[:, :, b - 1]) + np.stack([w[..., 0] / 2, w[..., 0], w[..., 1] / 2, w[..., 1]], -1)
    X[:, :, 0] += rng.normal(0, 1, (runs, L, 4))
    X = np.where(active[..., None], X, 0.0)
    for b in range(B):  # before its first step a track holds its prior mean (the smoother does the same)
        X[:, :, b] = np.where((b < first)[..., None], pm, X[:, :, b])
    tr = tracker(MMPMHTTracker, noise_scales=(0.5, 1.0, 40.0), stay=0.8, mode_prior=(0.2, 0.5, 0.3))
    # an asymmetric Π (the tracker's is symmetric) so that a transposed Π in the backward pass shows
    modes = replace(tr._maneuver(runs, L), transition=np.array([[0.8, 0.15, 0.05], [0.3, 0.6, 0.1], [0.05, 0.25, 0.7]]))
    gamma, alpha, loglik = noise_mode_posteriors(model, modes, X, pm, pc, first, active)
    Pi, s = modes.transition, modes.scales
    for m in range(runs):
        total = 0.0
        for l in range(L):
            steps = [b for b in range(B) if active[m, l, b]]
            logp = []
            seqs = list(itertools.product(range(J), repeat=len(steps)))
            for seq in seqs:
                lp, prev_mode, x_prev = 0.0, None, pm[m, l]
                for b, j in zip(steps, seq):
                    lp += np.log(modes.prior[m, l, 0] @ Pi[:, j]) if prev_mode is None else np.log(Pi[prev_mode, j])
                    F, Q = model.F[b], model.Q[b]
                    S = F @ pc[m, l] @ F.T + s[j] * Q if prev_mode is None else s[j] * Q
                    lp += _log_gauss(X[m, l, b] - F @ x_prev, S)
                    prev_mode, x_prev = j, X[m, l, b]
                logp.append(lp)
            logp = np.array(logp)
            top = logp.max()
            total += top + np.log(np.exp(logp - top).sum())
            post = np.exp(logp - top) / np.exp(logp - top).sum()
            for i, b in enumerate(steps):
                marg = np.array([post[[k for k, q in enumerate(seqs) if q[i] == j]].sum() for j in range(J)])
                np.testing.assert_allclose(gamma[m, l, b, 0], marg, rtol=0, atol=1e-10)
        assert loglik[m] == pytest.approx(total, rel=1e-10)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 10_000),
    targets=st.integers(1, 4),
    clutter=st.floats(0.0, 15.0),
    p_detect=st.floats(0.5, 1.0),
    B=st.integers(1, 6),
    late=st.booleans(),
)
def test_em_objective_never_decreases(seed, targets, clutter, p_detect, B, late):
    """Random small scenes, three noise modes, tracks starting mid-window: L_i ≥ L_{i−1} at every M-step (exact EM)."""
    rng = np.random.default_rng(seed)
    pos, vel = rng.uniform(-8, 8, (2, targets)), rng.normal(0, 1, (2, targets))
    starts = np.column_stack([pos[0], vel[0], pos[1], vel[1]])
    region = ((-20.0, 20.0), (-20.0, 20.0))
    _, z = simulate(starts, B, 3, seed, p_detect=p_detect, clutter_rate=clutter, region=region)
    runs = z.shape[1]
    pm = np.broadcast_to(starts + rng.normal(0, 2.0, starts.shape), (runs, targets, 4))
    pc = np.broadcast_to(PRIOR_COV, (runs, targets, 4, 4))
    model, first, start = window_inputs(pm, z, B)
    if late:
        first = rng.integers(0, B, (runs, targets))
    modes = tracker(MMPMHTTracker, noise_scales=(0.3, 1.0, 50.0))._maneuver(runs, targets)
    volume = 40.0**2
    fit = em_window(
        model, pm, pc, first, z, start, p_detect=min(p_detect, 0.999), clutter_density=max(clutter, 0.5) / volume,
        volume=volume, max_iter=40, tol=0.0, maneuver=modes,
    )  # fmt: skip
    h = fit.history
    steps = np.diff(h, axis=0)
    ok = np.isnan(steps) | (steps >= -1e-9 * np.abs(h[:-1]))
    assert ok.all(), steps
    assert fit.mode_probs.shape == (runs, targets, B, 1, 3)
    np.testing.assert_allclose(fit.mode_probs.sum(axis=-1), 1.0, rtol=1e-12)


def test_batch_equals_one_run_at_a_time():
    truth, z = cluttered_scene(runs=3, K=25)
    tr = tracker(MMPMHTTracker, noise_scales=(1.0, 50.0))
    whole = tr.track(z)
    for m in range(z.shape[1]):
        one = tr.track(z[:, m : m + 1])
        np.testing.assert_array_equal(one.label[:, 0], whole.label[:, m])
        np.testing.assert_array_equal(one.iterations[:, 0], whole.iterations[:, m])
        np.testing.assert_allclose(one.mean[:, 0], whole.mean[:, m], rtol=1e-12, atol=1e-10)


def test_a_high_noise_mode_follows_an_acceleration_that_pmht_lags():
    """One target accelerating at 1 m/s² for 10 scans (σ = 0.1 m, no clutter): MM-PMHT beats PMHT.

    20 runs; the paired per-run gain in mean position error over the maneuver must exceed 5 standard
    errors (a one-sided z-test far beyond any reasonable significance level).
    """
    cv = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
    meas = LinearGaussian.position(4, cv.position_indices, 0.1)
    K, runs = 25, 20
    rng = np.random.default_rng(21)
    x = np.tile([0.0, 5.0, 0.0, 0.0], (runs, 1))
    truth, zs = [], []
    for k in range(1, K + 1):
        x = cv.sample(x, k, rng)
        if 11 <= k <= 20:
            x = x + np.array([0.0, 0.0, 0.5, 1.0])
        truth.append(x.copy())
        zs.append(meas.sample(x, k, rng))
    truth = np.array(truth)
    z = np.array(zs)[:, :, None]
    prior = Gaussian(np.array([[0.0, 5.0, 0.0, 0.0]]), np.diag([0.01, 0.01, 0.01, 0.01]))
    common = dict(capacity=2, max_misses=30)
    res_p = PMHTTracker(pu.KalmanFilter(cv, meas), 1.0, 1e-300, **common).track(z, initial=prior)
    res_m = MMPMHTTracker(pu.KalmanFilter(cv, meas), 1.0, 1e-300, noise_scales=(1.0, 100.0), **common).track(z, initial=prior)
    seg = slice(11, 22)
    err_p = np.linalg.norm(res_p.mean[seg, :, 0][..., [0, 2]] - truth[seg][..., [0, 2]], axis=-1).mean(axis=0)
    err_m = np.linalg.norm(res_m.mean[seg, :, 0][..., [0, 2]] - truth[seg][..., [0, 2]], axis=-1).mean(axis=0)
    gain = err_p - err_m
    assert gain.mean() > 5 * gain.std(ddof=1) / np.sqrt(runs)


@pytest.mark.parametrize(
    ("kw", "field"),
    [({"noise_scales": ()}, "noise_scales"), ({"noise_scales": (1.0, -2.0)}, "noise_scales"), ({"noise_scales": (1.0, np.inf)}, "noise_scales"),
     ({"stay": 0.0}, "stay"), ({"mode_prior": (0.5, 0.6)}, "mode_prior"), ({"mode_prior": (1.0,)}, "mode_prior")],
)  # fmt: skip
def test_bad_parameters_name_the_field(kw, field):
    with pytest.raises(ValueError, match=field):
        MMPMHTTracker(kf(), 0.9, CLUTTER_DENSITY, **kw)
