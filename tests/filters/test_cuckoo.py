"""Cuckoo-search particle filters: building blocks and reductions."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import logsumexp

import pursuit as pu
from pursuit.filters.cuckoo import CSPF, ICSPF, CuckooSearch, levy_steps, mantegna_sigma
from pursuit.rng import run_streams
from pursuit.scenarios.ungm import UNGM


def test_mantegna_sigma_test_vector():
    assert mantegna_sigma(1.5) == pytest.approx(0.6965745, abs=1e-7)
    assert mantegna_sigma(1.0) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="beta"):
        mantegna_sigma(2.5)


def test_levy_steps_are_heavy_tailed_and_symmetric(rng):
    L = levy_steps(rng, (200000,), 1.5)
    assert abs(np.median(L)) < 0.02
    # Mantegna's steps have tails P(|L| > x) ~ x^(-beta): far heavier than a normal's
    q = np.quantile(np.abs(L), [0.99, 0.999])
    assert q[1] / q[0] > 3.0  # a normal would give about 1.27
    # the ratio of tail probabilities at x and 4x approaches 4^beta = 8 for beta = 1.5
    p1, p4 = np.mean(np.abs(L) > 5), np.mean(np.abs(L) > 20)
    assert 5.0 < p1 / p4 < 11.0


def test_schedules_run_from_max_to_min():
    s = CuckooSearch(n_iter=10)
    assert s.alpha(0) == 0.5 and s.alpha(9) == pytest.approx(0.01)
    assert s.pa(0) == pytest.approx(0.3) and s.pa(9) == pytest.approx(0.01)
    a = [s.alpha(t) for t in range(10)]
    p = [s.pa(t) for t in range(10)]
    assert np.all(np.diff(a) < 0) and np.all(np.diff(p) < 0)
    for shape in ("linear", "cosine"):
        q = CuckooSearch(n_iter=5, pa_schedule=shape)
        assert q.pa(0) == pytest.approx(0.3) and q.pa(4) == pytest.approx(0.01)
    assert CuckooSearch(n_iter=1).alpha(0) == 0.5  # n = 1: t/(n-1) := 0


@settings(max_examples=40)
@given(
    seed=st.integers(0, 2**31 - 1),
    N=st.integers(2, 40),
    n=st.integers(1, 4),
    scaling=st.sampled_from(["relative", "absolute", "std"]),
    trend=st.sampled_from(["exp", "linear", "off"]),
    discovery=st.sampled_from(["yang", "literal_pa"]),
)
def test_greedy_moves_never_lower_a_fitness(seed, N, n, scaling, trend, discovery):
    g = np.random.default_rng(seed)
    target = g.standard_normal(n) * 3
    scale = np.exp(g.standard_normal(n))

    def fitness(X):  # a rugged, multimodal fitness
        d = (X - target) / scale
        return -0.5 * np.sum(d * d, axis=-1) + np.sum(np.cos(3 * X), axis=-1)

    search = CuckooSearch(n_iter=6, step_scaling=scaling, trend=trend, discovery=discovery)
    X0 = g.standard_normal((3, N, n)) * 5
    trace = []
    X, F, stats_ = search.run(X0, fitness, g, trace=trace)
    assert len(trace) == 12
    for before, after in trace:
        assert np.all(after >= before)
    np.testing.assert_allclose(F, fitness(X))
    assert np.all(F >= fitness(X0))
    assert np.all(stats_["iterations"] == 6)


def test_bounds_are_respected(rng):
    search = CuckooSearch(n_iter=5, lower=[-1.0, 0.0], upper=[1.0, 2.0])
    X0 = rng.uniform([-1, 0], [1, 2], size=(2, 30, 2))
    X, F, _ = search.run(X0, lambda X: -np.sum((X - 5.0) ** 2, axis=-1), rng)
    assert np.all(X >= [-1.0, 0.0]) and np.all(X <= [1.0, 2.0])
    assert np.all(F >= -np.sum((X0 - 5.0) ** 2, axis=-1))


def test_early_stop_halts_a_run_without_touching_the_others():
    search = CuckooSearch(n_iter=8, f_stop=np.exp(-0.5))
    X0 = np.stack([np.full((20, 1), 0.1), np.linspace(5, 9, 20)[:, None]])  # run 0 is already at the optimum

    def fitness(X):
        return -0.5 * X[..., 0] ** 2

    X, F, s = search.run(X0, fitness, run_streams(3, [0, 1], 1))
    assert s["iterations"][0] == 0 and s["iterations"][1] > 0
    np.testing.assert_array_equal(X[0], X0[0])
    alone, _, s1 = search.run(X0[1:], fitness, run_streams(3, [1], 1))
    np.testing.assert_array_equal(alone[0], X[1])
    assert s1["iterations"][0] == s["iterations"][1]


def test_zero_iterations_is_propagate_and_weight():
    sc = UNGM(steps=3)
    filt = ICSPF(sc.motion, sc.measurement, particles=64, search=CuckooSearch(n_iter=0))
    g = np.random.default_rng(11)
    state = filt.init(pu.Gaussian([0.1], [[2.0]]), batch=(2,), rng=g)
    X0 = state.particles.copy()
    g_copy = copy.deepcopy(g)
    z = np.array([[1.0], [3.0]])
    state, info = filt.step(state, z)
    X1 = sc.motion.sample(X0, 1, g_copy)
    ll = sc.measurement.loglik(z[:, None, :], X1)
    np.testing.assert_array_equal(state.particles, X1)
    np.testing.assert_allclose(state.logw, ll - logsumexp(ll, axis=-1, keepdims=True), atol=1e-12)
    w = np.exp(state.logw)
    np.testing.assert_allclose(state.mean, np.einsum("mp,mpi->mi", w, X1), rtol=1e-12)
    assert not info["resampled"].any()
    # reset mode: the next step ignores these weights (equal predictive weights)
    g_copy2 = copy.deepcopy(state.rng)
    X2 = sc.motion.sample(state.particles, 2, g_copy2)
    state2, info2 = filt.step(state, z)
    np.testing.assert_allclose(info2["innovation"][:, 0], z[:, 0] - (X2[..., 0] ** 2 / 20).mean(axis=-1), rtol=1e-12)


def test_cs_pf_is_the_fixed_parameter_search():
    sc = UNGM()
    cs = CSPF(sc.motion, sc.measurement)
    assert cs.name == "CS-PF" and cs.search.alpha(0) == cs.search.alpha(9) == 0.01
    assert cs.search.pa(3) == 0.25 and cs.search.trend == "off"
    assert ICSPF(sc.motion, sc.measurement).name == "ICS-PF"
    with pytest.raises(ValueError, match="weight_mode"):
        ICSPF(sc.motion, sc.measurement, weight_mode="magic")
    with pytest.raises(ValueError, match="alpha_min"):
        CuckooSearch(alpha_max=0.1, alpha_min=0.2)
    with pytest.raises(ValueError, match="n_iter"):
        CuckooSearch(n_iter=-1)


def test_the_moves_raise_the_likelihood_of_the_particles():
    # what the cuckoo step is for: after the moves the particles sit where the
    # measurement is likely, so the likelihood weights are far more even (ESS up),
    # paired run by run against the same filter without moves
    sc = UNGM(steps=20)
    runs = 30
    sim = sc.simulate(run_streams(6, range(runs), 0), runs)
    base = ICSPF(sc.motion, sc.measurement, particles=100, search=CuckooSearch(n_iter=0))
    moved = ICSPF(sc.motion, sc.measurement, particles=100)
    a = pu.run(base, sim.measurements, sim.prior, rng=run_streams(6, range(runs), 1))
    b = pu.run(moved, sim.measurements, sim.prior, rng=run_streams(6, range(runs), 1))
    d = b.info["ess"].mean(axis=0) - a.info["ess"].mean(axis=0)  # per run
    t = stats.ttest_1samp(d, 0.0)
    assert d.mean() > 0 and t.pvalue < 1e-3
