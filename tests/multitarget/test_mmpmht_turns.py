"""The multiple-model PMHT with turn modes (an IMM smoother in the M-step): PMHT with one CV mode, exact cases, a turn."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters.imm_smoother import imm_smooth
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantAcceleration, ConstantTurn, ConstantVelocity, LinearGaussian
from pursuit.multitarget import MMPMHTTracker, PMHTTracker
from pursuit.multitarget.mmpmht import mode_transitions
from pursuit.multitarget.pmht import _smooth, em_window, linear_model

from ._scenes import cv_models
from .test_pmht import CLUTTER_DENSITY, PRIOR_COV, cluttered_scene, kf, simulate, tracker, window_inputs

TURNS = (0.0, 0.1, -0.1)


def test_one_cv_mode_is_pmht():
    """turn_rates = (0,): the IMM smoother is the RTS smoother, so the tracker is PMHT (labels, iterations, 1e-9)."""
    truth, z = cluttered_scene(runs=3, K=25)
    a = tracker().track(z)
    b = tracker(MMPMHTTracker, turn_rates=(0.0,)).track(z)
    assert b.iterations.sum() > 0
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.iterations, b.iterations)
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.objective, a.objective, rtol=1e-10, atol=0)


def _m_step_inputs(seed, runs=2, L=3, B=5):
    """Random synthetic measurements of one window: prior, active (late starts), measured, z̃, W."""
    rng = np.random.default_rng(seed)
    pm = rng.normal(0, 3, (runs, L, 4))
    pc = np.broadcast_to(PRIOR_COV, (runs, L, 4, 4)).copy()
    model, _, _ = window_inputs(pm, np.full((B, runs, 1, 2), np.nan), B)
    first = rng.integers(0, 3, (runs, L))
    active = np.arange(B) >= first[..., None]
    W = rng.uniform(0.0, 1.2, (runs, L, B))
    W[W < 0.2] = 0.0  # some misses
    zs = rng.normal(0, 4, (runs, L, B, 2))
    return model, pm, pc, active, active & (W > 0), zs, W


def test_the_m_step_with_one_cv_mode_is_pmhts_smoother():
    """The IMM M-step with the single rate 0 = PMHT's KF/RTS on the synthetic measurements (1e-9), late starts and misses too."""
    model, pm, pc, active, measured, zs, W = _m_step_inputs(1)
    modes = tracker(MMPMHTTracker, turn_rates=(0.0,))._maneuver(*pm.shape[:2])
    got = modes.smoother(model, modes, pm, pc, active, measured, zs, W, model.H)
    want = _smooth(model, pm, pc, active, measured, zs, W, np.zeros((*W.shape, 0)), model.H)
    for g, w in zip(got[:4], want):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-9)


def test_pinned_turn_mode_is_that_turns_smoother():
    """Π = I and a known prior mode: the M-step is the KF/RTS of that turn's F alone (1e-9)."""
    model, pm, pc, active, measured, zs, W = _m_step_inputs(2)
    for j, w in enumerate(TURNS):
        prior = tuple(np.eye(3)[j])
        modes = tracker(MMPMHTTracker, turn_rates=TURNS, transition=tuple(map(tuple, np.eye(3))), mode_prior=prior)._maneuver(*pm.shape[:2])
        got = modes.smoother(model, modes, pm, pc, active, measured, zs, W, model.H)
        ct, meas = ConstantTurn(omega=w, q=0.01), cv_models()[1]
        want = _smooth(linear_model(ct, meas, [None] * 5), pm, pc, active, measured, zs, W, np.zeros((*W.shape, 0)), model.H)
        for g, x in zip(got[:4], want):
            np.testing.assert_allclose(g, x, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(got[4][..., 0, j], 1.0)


def test_identical_turn_modes_are_the_rts_smoother_of_that_turn():
    """Three modes all turning at 0.1 rad/s under a non-trivial Π: that turn's RTS smoother (1e-9)."""
    model, pm, pc, active, measured, zs, W = _m_step_inputs(3)
    modes = tracker(MMPMHTTracker, turn_rates=(0.1, 0.1, 0.1), stay=0.7)._maneuver(*pm.shape[:2])
    got = modes.smoother(model, modes, pm, pc, active, measured, zs, W, model.H)
    want = _smooth(linear_model(ConstantTurn(omega=0.1, q=0.01), cv_models()[1], [None] * 5), pm, pc, active, measured, zs, W,
                   np.zeros((*W.shape, 0)), model.H)  # fmt: skip
    for g, x in zip(got[:4], want):
        np.testing.assert_allclose(g, x, rtol=0, atol=1e-9)


def test_mode_transitions_follow_the_step_times_and_the_state_layout():
    """F_j per step is ConstantTurn(ω_j, dt) placed on the (x, vx, y, vy) indices, in either CV layout."""
    for layout in ("axis", "derivative"):
        cv = ConstantVelocity(ndim=3, dt=1.0, q=0.5, layout=layout)
        meas = LinearGaussian.position(6, cv.position_indices, 1.0)
        model = linear_model(cv, meas, [None, 0.5, 2.0])
        tr = MMPMHTTracker(pu.KalmanFilter(cv, meas), 0.9, 1e-3, turn_rates=(0.0, 0.2), noise_scales=(1.0, 3.0))
        plane = tr._plane()
        F, Q = mode_transitions(model, np.array(tr.turn_rates), np.array(tr.noise_scales), plane)
        for b, dt in enumerate([1.0, 0.5, 2.0]):
            np.testing.assert_array_equal(F[b, 0], model.F[b])
            want = ConstantTurn(omega=0.2, dt=dt).transition_matrix()
            np.testing.assert_allclose(F[b, 1][np.ix_(plane, plane)], want, rtol=0, atol=1e-15)
            rest = [i for i in range(6) if i not in plane]
            np.testing.assert_array_equal(F[b, 1][np.ix_(rest, rest)], model.F[b][np.ix_(rest, rest)])
            np.testing.assert_array_equal(Q[b, 1], 3.0 * model.Q[b])


def test_batch_equals_one_run_at_a_time():
    truth, z = cluttered_scene(runs=3, K=20)
    tr = tracker(MMPMHTTracker, turn_rates=TURNS)
    whole = tr.track(z)
    for m in range(z.shape[1]):
        one = tr.track(z[:, m : m + 1])
        np.testing.assert_array_equal(one.label[:, 0], whole.label[:, m])
        np.testing.assert_array_equal(one.iterations[:, 0], whole.iterations[:, m])
        np.testing.assert_allclose(one.mean[:, 0], whole.mean[:, m], rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(one.objective[:, 0], whole.objective[:, m], rtol=1e-12)


def test_detection_order_within_a_scan_does_not_matter():
    truth, z = cluttered_scene(runs=2, K=20)
    rng = np.random.default_rng(9)
    perm = rng.permutation(z.shape[2])
    tr = tracker(MMPMHTTracker, turn_rates=TURNS)
    a, b = tr.track(z), tr.track(z[:, :, perm])
    np.testing.assert_array_equal(a.label, b.label)
    np.testing.assert_array_equal(a.iterations, b.iterations)
    np.testing.assert_allclose(a.mean, b.mean, rtol=0, atol=1e-9)


def test_em_reports_objective_and_stops_on_pmhts_rule():
    """Per window: the objective after each M-step, NaN after the stop; stopped runs met the tolerance or the cap."""
    B, runs = 5, 4
    starts = [[0.0, 1.0, 0.0, 1.0], [10.0, -1.0, 0.0, 0.5]]
    _, z = simulate(starts, B, runs, 3, p_detect=0.9, clutter_rate=3.0, region=((-20.0, 20.0), (-20.0, 20.0)))
    pm = np.broadcast_to(np.asarray(starts), (runs, 2, 4))
    pc = np.broadcast_to(PRIOR_COV, (runs, 2, 4, 4))
    model, first, start = window_inputs(pm, z, B)
    modes = tracker(MMPMHTTracker, turn_rates=TURNS)._maneuver(runs, 2)
    fit = em_window(model, pm, pc, first, z, start, p_detect=0.9, clutter_density=3.0 / 40.0**2, max_iter=8, tol=1e-6, maneuver=modes)
    h = fit.history
    for m in range(runs):
        it = fit.iterations[m]
        assert np.isfinite(h[: it + 1, m]).all() and np.isnan(h[it + 1 :, m]).all()
        assert fit.objective[m] == h[it, m]
        if it < 8:  # stopped by the tolerance
            assert abs(h[it, m] - h[it - 1, m]) <= 1e-6 * abs(h[it - 1, m])
    assert fit.mode_probs.shape == (runs, 2, B, 1, 3)
    np.testing.assert_allclose(fit.mode_probs.sum(axis=-1), 1.0, rtol=1e-12)


def _turning_target(runs: int, seed: int):
    """One target, 30 scans: straight at 10 m/s, a 0.1 rad/s left turn at scans 11-25 (≈ 86°), straight again; σ = 1 m."""
    cv, meas = ConstantVelocity(ndim=2, dt=1.0, q=0.01), LinearGaussian.position(4, (0, 2), 1.0)
    ct = ConstantTurn(omega=0.1, q=0.01)
    rng = np.random.default_rng(seed)
    x = np.tile([0.0, 10.0, 0.0, 0.0], (runs, 1))
    truth, zs = [], []
    for k in range(1, 31):
        x = (ct if 11 <= k <= 25 else cv).sample(x, k, rng)
        truth.append(x.copy())
        zs.append(meas.sample(x, k, rng))
    return cv, meas, np.array(truth), np.array(zs)[:, :, None]


def test_turn_modes_beat_pmht_during_a_turn():
    """A clutter-free coordinated turn: MM-PMHT with modes (0, ±0.1 rad/s) beats PMHT (CV) in position RMSE over the turn.

    30 runs (seed 31); the paired per-run gain in RMS position error over scans 11..27 must exceed 5
    standard errors of its mean (a one-sided z-test at a level far below 1e-6).
    """
    runs = 30
    cv, meas, truth, z = _turning_target(runs, 31)
    prior = Gaussian(np.array([[0.0, 10.0, 0.0, 0.0]]), np.diag([1.0, 0.1, 1.0, 0.1]))
    common = dict(capacity=2, max_misses=30)
    res_p = PMHTTracker(pu.KalmanFilter(cv, meas), 1.0, 1e-300, **common).track(z, initial=prior)
    res_m = MMPMHTTracker(pu.KalmanFilter(cv, meas), 1.0, 1e-300, turn_rates=TURNS, **common).track(z, initial=prior)
    seg = slice(10, 27)
    rms = lambda r: np.sqrt((np.sum((r.mean[seg, :, 0][..., [0, 2]] - truth[seg][..., [0, 2]]) ** 2, axis=-1)).mean(axis=0))  # noqa: E731
    gain = rms(res_p) - rms(res_m)
    assert gain.mean() > 5 * gain.std(ddof=1) / np.sqrt(runs)


@pytest.mark.parametrize(
    ("kw", "field"),
    [({"turn_rates": ()}, "turn_rates"), ({"turn_rates": (0.0, np.nan)}, "turn_rates"),
     ({"turn_rates": (0.0, 0.1), "noise_scales": (1.0, 1.0, 1.0)}, "noise_scales"),
     ({"turn_rates": (0.0, 0.1), "transition": ((0.9, 0.2), (0.1, 0.9))}, "transition"),
     ({"turn_rates": (0.0, 0.1), "transition": ((1.0,),)}, "transition"),
     ({"turn_rates": (0.0, 0.1), "mode_prior": (1.0,)}, "mode_prior")],
)  # fmt: skip
def test_bad_parameters_name_the_field(kw, field):
    with pytest.raises(ValueError, match=field):
        MMPMHTTracker(kf(), 0.9, CLUTTER_DENSITY, **kw)


def test_turn_modes_need_a_constant_velocity_model():
    ca = ConstantAcceleration(ndim=2)
    meas = LinearGaussian.position(6, ca.position_indices, 1.0)
    with pytest.raises(ValueError, match="turn_rates"):  # positions and velocities only
        MMPMHTTracker(pu.KalmanFilter(ca, meas), 0.9, 1e-3, turn_rates=(0.0, 0.1))
    # a linear model whose (x, vx, y, vy) block is not constant velocity is refused when it is used
    F = np.eye(4)
    F[0, 1] = F[2, 3] = 1.0
    F[1, 3] = 0.1
    lin = pu.models.LinearMotion(F, 0.01 * np.eye(4))
    lin_meas = LinearGaussian.position(4, (0, 2), 1.0)
    with pytest.raises(ValueError, match="turn_rates"):
        mode_transitions(linear_model(lin, lin_meas, [None]), np.array([0.0]), np.ones(1), (0, 1, 2, 3))
    one_d = ConstantVelocity(ndim=1)
    with pytest.raises(ValueError, match="turn_rates"):
        MMPMHTTracker(pu.KalmanFilter(one_d, LinearGaussian.position(2, one_d.position_indices, 1.0)), 0.9, 1e-3, turn_rates=(0.0,))


def test_imm_smoother_is_the_m_step():
    """The M-step hands the synthetic measurements to imm_smooth unchanged (a guard on the wiring)."""
    model, pm, pc, active, measured, zs, W = _m_step_inputs(4)
    modes = tracker(MMPMHTTracker, turn_rates=TURNS, stay=0.8)._maneuver(*pm.shape[:2])
    got = modes.smoother(model, modes, pm, pc, active, measured, zs, W, model.H)
    F, Q = mode_transitions(model, np.array(TURNS), np.ones(3), (0, 1, 2, 3))
    out = imm_smooth(pm, pc, modes.prior[:, :, 0], modes.transition, F, Q, zs, model.H, model.R, weight=W, measured=measured, active=active)
    np.testing.assert_array_equal(got[0], out.mean)
    np.testing.assert_array_equal(got[5][..., 0, :], out.filt_mode_probs)


# --------------------------------------------------------------------------
# from a config
# --------------------------------------------------------------------------
TOML = """
[experiment]
kind = "multitarget"
runs = 2
seed = 3

[scenario]
type = "mt-crossing"
steps = 8

[[trackers]]
name = "MM"
type = "mmpmht"
turn_rates = [0.0, 0.05, -0.05]
transition = [[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]]
"""


def test_turn_modes_from_a_config(tmp_path):
    from pursuit.experiment import load_experiment

    path = tmp_path / "mt.toml"
    path.write_text(TOML)
    tr = load_experiment(path).plan.trackers[0]
    assert tr.turn_rates == (0.0, 0.05, -0.05) and tr.noise_scales == (1.0, 1.0, 1.0)
    assert tr.transition[0] == (0.9, 0.05, 0.05)
    path.write_text(TOML.replace("transition = [[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]]\n", "noise_scales = [1.0, 1.0, 100.0]\n"))
    tr = load_experiment(path).plan.trackers[0]
    assert tr.noise_scales == (1.0, 1.0, 100.0) and tr.transition is None and tr.stay == 0.95


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("turn_rates = [0.0, 0.05, -0.05]", "turn_rates = []"), "trackers[0].turn_rates"),
        (("turn_rates = [0.0, 0.05, -0.05]", 'turn_rates = "left"'), "trackers[0].turn_rates: expected a list of numbers"),
        (("turn_rates = [0.0, 0.05, -0.05]", "turn_rates = [0.0, 0.05]"), "trackers[0].transition: expected a (2, 2) Markov matrix"),
        (("[0.05, 0.05, 0.9]]", "[0.05, 0.05, 0.8]]"), "trackers[0].transition"),
        (("turn_rates = [0.0, 0.05, -0.05]", "turn_rates = [0.0, 0.05, -0.05]\nnoise_scales = [1.0, 2.0]"), "trackers[0].noise_scales: expected one scale per turn rate"),
    ],
)  # fmt: skip
def test_turn_modes_config_refusals_name_the_field(tmp_path, edit, message):
    from pursuit.experiment import ConfigError, load_experiment

    path = tmp_path / "mt.toml"
    path.write_text(TOML.replace(*edit, 1))
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert message in str(info.value)


def test_motion_mode_posteriors_with_zero_rates_are_the_noise_modes():
    """Rates all 0: the per-mode-F emissions are the noise modes' (γ, α and the process term to 1e-10), late starts too."""
    from pursuit.multitarget.mmpmht import motion_mode_posteriors, noise_mode_posteriors

    B, runs, L = 5, 2, 3
    rng = np.random.default_rng(8)
    pm = rng.normal(0, 3, (runs, L, 4))
    pc = np.broadcast_to(PRIOR_COV, (runs, L, 4, 4)).copy()
    model, _, start = window_inputs(pm, np.full((B, runs, 1, 2), np.nan), B)
    first = rng.integers(0, B, (runs, L))
    active = np.arange(B) >= first[..., None]
    X = start + rng.normal(0, 0.5, start.shape)
    tr = tracker(MMPMHTTracker, turn_rates=(0.0, 0.0, 0.0), noise_scales=(0.5, 1.0, 30.0), transition=((0.8, 0.15, 0.05), (0.3, 0.6, 0.1), (0.05, 0.25, 0.7)))
    modes = tr._maneuver(runs, L)
    got = motion_mode_posteriors(model, modes, X, pm, pc, first, active, rates=np.zeros(3), plane=(0, 1, 2, 3))
    want = noise_mode_posteriors(model, modes, X, pm, pc, first, active)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-10, atol=1e-12)
