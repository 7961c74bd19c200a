"""IMM: reduction to one filter, mode probabilities, state maps between models of different sizes."""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import AdaptiveCSFilter, InteractingMultipleModel, StateMap, kinematic_map
from pursuit.models import ConstantAcceleration, ConstantVelocity, LinearGaussian, Singer
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, ManeuveringTarget

SCENARIO = ManeuveringTarget()


def _sim(scenario, runs, seed=9):
    return scenario.simulate(run_streams(seed, range(runs), 0), runs)


def _singer_kf(alpha, sigma):
    return pu.KalmanFilter(Singer(alpha=alpha, sigma=sigma, ndim=3), SCENARIO.measurement)


def _singer_imm():
    return InteractingMultipleModel([_singer_kf(a, s) for a, s in ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))], 0.95)


@pytest.mark.parametrize(
    "make",
    [lambda: _singer_kf(0.05, 20.0), lambda: AdaptiveCSFilter(SCENARIO.measurement)],
    ids=["kf-singer", "apcs"],
)
@pytest.mark.parametrize("transition", [0.95, [[0.5, 0.3, 0.2], [0.1, 0.8, 0.1], [0.3, 0.3, 0.4]]], ids=["sym", "asym"])
def test_an_imm_of_identical_models_is_the_single_filter(make, transition):
    sim = _sim(SCENARIO, 5)
    single = pu.run(make(), sim.measurements, sim.prior)
    imm = pu.run(InteractingMultipleModel([make(), make(), make()], transition, [0.2, 0.5, 0.3]), sim.measurements, sim.prior)
    np.testing.assert_allclose(imm.mean, single.mean, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose(imm.cov, single.cov, rtol=1e-8, atol=1e-9)
    for key in ("nis", "loglik"):
        np.testing.assert_allclose(imm.info[key], single.info[key], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(imm.info["loglik_mixture"], single.info["loglik"], rtol=1e-6, atol=1e-9)
    # equal likelihoods: μ only follows the Markov chain
    mu = np.array([0.2, 0.5, 0.3])
    Pi = InteractingMultipleModel([make()] * 3, transition).transition
    for k in range(SCENARIO.steps):
        mu = mu @ Pi
        np.testing.assert_allclose(imm.info["mode_probs"][k], np.broadcast_to(mu, (5, 3)), rtol=1e-9)


def test_mode_probabilities_sum_to_one_and_move_towards_the_maneuvering_models():
    runs = 60
    sim = _sim(SCENARIO, runs)
    mu = pu.run(_singer_imm(), sim.measurements, sim.prior).info["mode_probs"]  # (K, M, 3)
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, rtol=0, atol=1e-12)
    assert np.all((mu >= 0) & (mu <= 1))
    maneuver = SCENARIO.maneuvering().any(axis=1)
    quiet = ~maneuver & (SCENARIO.times > 10)  # after the start-up transient
    # probability of the two maneuvering (larger-σ) models, per run, during maneuvers and in quiet flight
    p_man = 1.0 - mu[..., 0]
    d = p_man[maneuver].mean(axis=0) - p_man[quiet].mean(axis=0)
    z = d.mean() / (d.std(ddof=1) / np.sqrt(runs))
    assert z > 5, z


def test_cv_ca_imm_with_a_state_map_switches_to_ca_during_maneuvers():
    runs = 40
    sim = _sim(SCENARIO, runs)
    cv = ConstantVelocity(ndim=3, dt=1.0, q=0.01)
    ca = ConstantAcceleration(ndim=3, dt=1.0, q=100.0)
    meas_cv = LinearGaussian.position(cv.dim, cv.position_indices, np.sqrt(SCENARIO.R))
    imm = InteractingMultipleModel(
        [pu.KalmanFilter(cv, meas_cv), pu.KalmanFilter(ca, SCENARIO.measurement)], 0.95, maps=[kinematic_map(cv, ca), None]
    )
    track = pu.run(imm, sim.measurements, sim.prior)
    assert track.mean.shape == sim.truth.shape
    mu_ca = track.info["mode_probs"][..., 1]
    maneuver = SCENARIO.maneuvering().any(axis=1)
    quiet = ~maneuver & (SCENARIO.times > 10)
    d = mu_ca[maneuver].mean(axis=0) - mu_ca[quiet].mean(axis=0)
    assert d.mean() / (d.std(ddof=1) / np.sqrt(runs)) > 5


def test_a_mode_with_zero_probability_leaves_the_other_filter_alone():
    sim = _sim(SCENARIO, 4)
    cv = ConstantVelocity(ndim=3, dt=1.0, q=0.01)
    ca = ConstantAcceleration(ndim=3, dt=1.0, q=5.0)
    meas_cv = LinearGaussian.position(cv.dim, cv.position_indices, np.sqrt(SCENARIO.R))
    imm = InteractingMultipleModel(
        [pu.KalmanFilter(cv, meas_cv), pu.KalmanFilter(ca, SCENARIO.measurement)],
        np.eye(2),
        initial_probs=[0.0, 1.0],
        maps=[kinematic_map(cv, ca, fill_var=3.0), None],
    )
    track = pu.run(imm, sim.measurements, sim.prior)
    ca_only = pu.run(pu.KalmanFilter(ca, SCENARIO.measurement), sim.measurements, sim.prior)
    np.testing.assert_allclose(track.mean, ca_only.mean, rtol=1e-13, atol=1e-9)
    np.testing.assert_allclose(track.cov, ca_only.cov, rtol=1e-12, atol=1e-9)
    assert np.all(track.info["mode_probs"][..., 0] == 0.0)


def test_state_map_round_trip_and_fill(rng):
    cv = ConstantVelocity(ndim=3)
    ca = ConstantAcceleration(ndim=3)
    m = kinematic_map(cv, ca, fill_var=2.5)
    assert m.indices == (0, 1, 3, 4, 6, 7)
    x = rng.normal(size=(5, 9))
    A = rng.normal(size=(5, 9, 9))
    P = A @ np.swapaxes(A, -1, -2)
    xm, Pm = m.to_mode(x, P)
    np.testing.assert_array_equal(xm, x[:, [0, 1, 3, 4, 6, 7]])
    xc, Pc = m.to_common(xm, Pm)
    np.testing.assert_array_equal(xc[:, [0, 1, 3, 4, 6, 7]], xm)
    assert np.all(xc[:, [2, 5, 8]] == 0.0)
    np.testing.assert_array_equal(Pc[:, [2, 5, 8], [2, 5, 8]], 2.5)
    assert np.all(Pc[:, 2, [0, 1, 3, 4, 5, 6, 7, 8]] == 0.0)
    with pytest.raises(ValueError, match="indices"):
        StateMap((0, 0), 3)
    with pytest.raises(ValueError, match="acceleration_indices"):
        kinematic_map(ca, cv)


def test_mixture_info_is_the_moment_matched_predicted_measurement():
    sc = LinearCV(ndim=2, steps=5)
    sim = sc.simulate(run_streams(1, range(3), 0), 3)
    modes = [pu.KalmanFilter(ConstantVelocity(ndim=2, q=q), sc.measurement) for q in (0.01, 1.0)]
    imm = InteractingMultipleModel(modes, [[0.9, 0.1], [0.2, 0.8]], [0.7, 0.3])
    state = imm.init(sim.prior, (3,))
    state, info = imm.step(state, sim.measurements[0])
    c_bar = np.array([0.7, 0.3]) @ imm.transition
    # recompute each mode's step from the mixed priors
    infos = []
    mu = np.array([0.7, 0.3])
    for j, f in enumerate(modes):
        w = imm.transition[:, j] * mu / c_bar[j]
        mean0 = sum(w[i] * np.broadcast_to(sim.prior.mean, (3, 4)) for i in range(2))
        s0 = f.init(pu.Gaussian(mean0, sim.prior.cov), (3,))
        infos.append(f.step(s0, sim.measurements[0])[1])
    nu = sum(c_bar[j] * infos[j]["innovation"] for j in range(2))
    S = sum(c_bar[j] * (infos[j]["S"] + np.einsum("...a,...b->...ab", infos[j]["innovation"] - nu, infos[j]["innovation"] - nu)) for j in range(2))
    np.testing.assert_allclose(info["innovation"], nu, rtol=1e-12)
    np.testing.assert_allclose(info["S"], S, rtol=1e-12, atol=1e-15)
    ll = np.logaddexp(*[np.log(c_bar[j]) + infos[j]["loglik"] for j in range(2)])
    np.testing.assert_allclose(info["loglik_mixture"], ll, rtol=1e-12)
    post = np.stack([c_bar[j] * np.exp(infos[j]["loglik"]) for j in range(2)], axis=-1)
    np.testing.assert_allclose(info["mode_probs"], post / post.sum(axis=-1, keepdims=True), rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"transition": [[0.9, 0.2], [0.1, 0.9]]}, "rows must sum to 1"),
        ({"transition": [[1.0]]}, "2x2"),
        ({"transition": 1.5}, "staying probability"),
        ({"initial_probs": [0.5, 0.6]}, "initial_probs"),
        ({"maps": [None]}, "maps"),
    ],
)
def test_bad_imm_configurations_are_refused(kwargs, match):
    modes = [_singer_kf(0.05, 1.0), _singer_kf(0.1, 2.0)]
    with pytest.raises(ValueError, match=match):
        InteractingMultipleModel(modes, **kwargs)
