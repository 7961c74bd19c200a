"""The compiled bootstrap PF over the whole sequence (``pursuit.run``'s ``sequence``) gives the step-by-step bits."""

from __future__ import annotations

import numpy as np
import pytest

numba = pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import particle  # noqa: E402
from pursuit.models import ConstantVelocity, RangeBearing, RangeSensors  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.ungm import UNGM  # noqa: E402

from .test_sequence import _assert_same_bits  # noqa: E402 (tracks equal bit for bit: means, covariances, every info key)

CV = ConstantVelocity(ndim=2, dt=1.0, q=0.05)
RANGES = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 2.0, (0, 2))
BEARING = RangeBearing([-20.0, 10.0], 2.0, 0.02)


def _ungm(M=12, T=25):
    sc = UNGM(steps=T)
    sim = sc.simulate(run_streams(1, range(M), 0), M)
    return sc.motion, sc.measurement, sim.measurements.copy(), sim.prior


def _cv(meas, M=9, T=20):
    rng = np.random.default_rng(3)
    x0 = np.array([10.0, 0.5, 40.0, 0.8])
    x = np.tile(x0, (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = CV.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    return CV, meas, zs, pu.Gaussian(x0, np.diag([4.0, 0.5, 4.0, 0.5]))


def _states(rs):
    return [g.bit_generator.state["state"] for g in rs.generators]


CASES = {
    "ungm-systematic": (_ungm, {}),
    "ungm-ess": (_ungm, {"ess_threshold": 0.5}),
    "ungm-stratified": (_ungm, {"resampler": "stratified"}),
    "ungm-residual-ess": (_ungm, {"resampler": "residual", "ess_threshold": 0.6}),
    "ungm-multinomial": (_ungm, {"resampler": "multinomial"}),
    "cv-ranges": (lambda: _cv(RANGES), {}),
    "cv-range-bearing": (lambda: _cv(BEARING), {"ess_threshold": 0.5}),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("missing", [False, True])
@pytest.mark.parametrize("keep_cov", [True, False])
def test_sequence_equals_step_by_step(case, missing, keep_cov):
    make, options = CASES[case]
    motion, meas, zs, prior = make()
    if missing:
        zs[3, 1] = np.nan  # nothing measured: predict only
        zs[7, :4, 0] = np.nan  # one component (all of it for UNGM)
    M = zs.shape[1]
    filt = pu.BootstrapParticleFilter(motion, meas, particles=300, backend="numba", **options)
    rs_whole, rs_steps = run_streams(5, range(M), 1), run_streams(5, range(M), 1)
    assert filt.run_sequence(filt.init(prior, batch=(M,), rng=run_streams(5, range(M), 1)), zs) is not None
    whole = pu.run(filt, zs, prior, rng=rs_whole, keep_cov=keep_cov)
    steps = pu.run(filt, zs, prior, rng=rs_steps, keep_cov=keep_cov, sequence=False)
    _assert_same_bits(whole, steps)
    assert _states(rs_whole) == _states(rs_steps)  # each stream is left where the steps leave it


def test_sequence_agrees_with_numpy():
    """Through the sequence path the compiled PF still gives NumPy's numbers (same draws)."""
    motion, meas, zs, prior = _ungm(M=6, T=30)
    a = pu.run(pu.BootstrapParticleFilter(motion, meas, particles=500), zs, prior, rng=run_streams(2, range(6), 1))
    b = pu.run(pu.BootstrapParticleFilter(motion, meas, particles=500, backend="numba"), zs, prior, rng=run_streams(2, range(6), 1))
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.info["loglik"], a.info["loglik"], rtol=0, atol=1e-9)
    assert np.array_equal(b.info["resampled"], a.info["resampled"])


@pytest.mark.slow  # the parallel build: make test runs the serial builds only (PURSUIT_NUMBA_PARALLEL=0)
def test_one_and_two_threads_give_the_same_bits(monkeypatch):
    monkeypatch.setattr(particle, "PARALLEL", True)
    motion, meas, zs, prior = _ungm(M=10, T=15)
    filt = pu.BootstrapParticleFilter(motion, meas, particles=400, backend="numba", ess_threshold=0.5)
    before = numba.get_num_threads()
    try:
        tracks = []
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            tracks.append(pu.run(filt, zs, prior, rng=run_streams(7, range(10), 1)))
    finally:
        numba.set_num_threads(before)
    _assert_same_bits(*tracks)


def test_a_run_alone_equals_the_run_in_a_batch():
    motion, meas, zs, prior = _ungm(M=8, T=15)
    filt = pu.BootstrapParticleFilter(motion, meas, particles=200, backend="numba")
    batch = pu.run(filt, zs, prior, rng=run_streams(3, range(8), 1))
    alone = pu.run(filt, zs[:, 5:6], pu.Gaussian(prior.mean[5:6], prior.cov), rng=run_streams(3, [5], 1))
    assert np.array_equal(alone.mean[:, 0], batch.mean[:, 5])
    assert np.array_equal(alone.info["loglik"][:, 0], batch.info["loglik"][:, 5])


def test_not_used_where_the_runs_cannot_draw_themselves():
    """One shared Generator (the NumPy draw order over the batch), a started state, or a shape the step broadcasts."""
    motion, meas, zs, prior = _ungm(M=4, T=6)
    filt = pu.BootstrapParticleFilter(motion, meas, particles=100, backend="numba")
    assert filt.run_sequence(filt.init(prior, batch=(4,), rng=np.random.default_rng(1)), zs) is None
    state = filt.init(prior, batch=(4,), rng=run_streams(1, range(4), 1))
    started, _ = filt.step(state, zs[0])
    assert filt.run_sequence(started, zs[1:]) is None
    assert filt.run_sequence(state, zs[:, :1]) is None  # (K, 1, m) broadcast over 4 runs: the step path does it
    shared = pu.run(filt, zs, prior, rng=np.random.default_rng(1))
    stepped = pu.run(filt, zs, prior, rng=np.random.default_rng(1), sequence=False)
    _assert_same_bits(shared, stepped)
    numpy = pu.BootstrapParticleFilter(motion, meas, particles=100)
    assert numpy.run_sequence(numpy.init(prior, batch=(4,), rng=run_streams(1, range(4), 1)), zs) is None


def test_infinite_measurement_names_the_step():
    motion, meas, zs, prior = _ungm(M=3, T=6)
    zs[4, 2, 0] = np.inf
    filt = pu.BootstrapParticleFilter(motion, meas, particles=50, backend="numba")
    with pytest.raises(ValueError, match="step 5: measurement contains infinity"):
        pu.run(filt, zs, prior, rng=run_streams(1, range(3), 1))


def test_a_measurement_too_large_to_square_names_the_step():
    motion, meas, zs, prior = _ungm(M=3, T=6)
    zs[4, 2, 0] = 1e300
    filt = pu.BootstrapParticleFilter(motion, meas, particles=50, backend="numba")
    with pytest.raises(ValueError, match=r"step 5: measurement z\[2, 0\] = 1e\+300 is beyond ±2\^500"):
        pu.run(filt, zs, prior, rng=run_streams(1, range(3), 1))


def test_branch_free_systematic_resampling_matches_the_two_pointer_rule():
    """systematic_fill_cdf picks, for each position (u0 + j)/N, the first particle whose normalised cumulative weight exceeds it."""
    from pursuit._compiled.pf_kernels import systematic_fill_cdf

    rng = np.random.default_rng(11)
    for trial in range(300):
        N = int(rng.integers(1, 400))
        e = rng.random(N) ** rng.choice([1.0, 8.0, 60.0])
        e[rng.random(N) < 0.3] = 0.0  # runs of zero weights: equal b_i
        e[-1] = max(e[-1], 1e-3)
        c = np.cumsum(e)
        u0 = 0.0 if trial == 0 else rng.random()
        src = rng.standard_normal(N)
        dst = np.empty(N)
        systematic_fill_cdf(c, u0, src, dst)
        positions = (u0 + np.arange(N)) / N
        cdf = c / c[-1]
        cdf[-1] = 1.0
        expected = src[np.minimum(np.searchsorted(cdf, positions, side="right"), N - 1)]
        assert np.array_equal(dst, expected), trial


def test_a_subclass_that_overrides_step_is_stepped_from_python():
    motion, meas, zs, prior = _ungm(M=3, T=5)
    calls = []

    class Counting(pu.BootstrapParticleFilter):
        def step(self, state, z, k=None, dt=None):
            calls.append(k)
            return super().step(state, z, k, dt)

    filt = Counting(motion, meas, particles=50, backend="numba")
    assert filt.run_sequence(filt.init(prior, batch=(3,), rng=run_streams(1, range(3), 1)), zs) is None
    pu.run(filt, zs, prior, rng=run_streams(1, range(3), 1))
    assert calls == [1, 2, 3, 4, 5]
