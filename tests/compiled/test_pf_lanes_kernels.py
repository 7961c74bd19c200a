"""The compiled bootstrap PF's component-by-component path (linear motion, range or linear sensor): NumPy's numbers.

``pf_kernels._lanes_run`` computes a step one state component at a time over
all particles, so every pass vectorises; its weights, running sums and
resampling decisions are those of the general path, its moments are summed in
another order. Checked here against the NumPy filter with the same draws (the
exact reference: same resampling decisions, estimates to rounding), for every
resampler, with and without an ESS threshold, and for batch invariance.
"""

from __future__ import annotations

import numpy as np
import pytest

numba = pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeSensors  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402

CV = ConstantVelocity(ndim=2, dt=1.0, q=0.05)
RANGES = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 2.0, (0, 2))
POSITION = LinearGaussian.position(4, CV.position_indices, 1.5)


def _work(meas, M=5, T=15):
    rng = np.random.default_rng(11)
    x0 = np.array([10.0, 0.5, 40.0, 0.8])
    x = np.tile(x0, (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = CV.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    return zs, pu.Gaussian(x0, np.diag([4.0, 0.5, 4.0, 0.5]))


@pytest.mark.parametrize("meas", [RANGES, POSITION], ids=["ranges", "position"])
@pytest.mark.parametrize(
    "options",
    [{}, {"ess_threshold": 0.5}, {"resampler": "stratified"}, {"resampler": "residual", "ess_threshold": 0.7}],
    ids=["systematic", "systematic-ess", "stratified", "residual-ess"],
)
def test_agrees_with_numpy(meas, options):
    zs, prior = _work(meas)
    M = zs.shape[1]
    tracks = [
        pu.run(pu.BootstrapParticleFilter(CV, meas, particles=400, backend=b, **options), zs, prior, rng=run_streams(4, range(M), 1))
        for b in ("numpy", "numba")
    ]
    a, b = tracks
    # the same draws and the same resampling decisions: estimates agree to rounding
    assert np.array_equal(b.info["resampled"], a.info["resampled"])
    np.testing.assert_allclose(b.mean, a.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.cov, a.cov, rtol=1e-9, atol=1e-9)
    for key in ("loglik", "ess", "nis"):
        np.testing.assert_allclose(b.info[key], a.info[key], rtol=1e-9, atol=1e-9, err_msg=key)
    np.testing.assert_allclose(b.info["innovation"], a.info["innovation"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.info["S"], a.info["S"], rtol=1e-9, atol=1e-9)


def test_a_run_alone_equals_the_run_in_a_batch():
    zs, prior = _work(RANGES, M=6)
    filt = pu.BootstrapParticleFilter(CV, RANGES, particles=300, backend="numba", ess_threshold=0.5)
    batch = pu.run(filt, zs, prior, rng=run_streams(3, range(6), 1))
    alone = pu.run(filt, zs[:, 4:5], prior, rng=run_streams(3, [4], 1))
    assert np.array_equal(alone.mean[:, 0], batch.mean[:, 4])
    assert np.array_equal(alone.cov[:, 0], batch.cov[:, 4])
    assert np.array_equal(alone.info["loglik"][:, 0], batch.info["loglik"][:, 4])


def test_a_particle_count_that_is_not_a_multiple_of_the_vector_width():
    """The vectorised passes' remainder loops give the same numbers as NumPy (N = 203)."""
    zs, prior = _work(RANGES, M=2, T=8)
    a, b = (
        pu.run(pu.BootstrapParticleFilter(CV, RANGES, particles=203, backend=bk), zs, prior, rng=run_streams(9, range(2), 1))
        for bk in ("numpy", "numba")
    )
    np.testing.assert_allclose(b.mean, a.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.info["loglik"], a.info["loglik"], rtol=1e-9, atol=1e-9)


def test_weights_that_underflow_to_zero():
    """A likelihood so narrow that most particles weigh exactly 0, the last ones included (systematic resampling's edge)."""
    narrow = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 0.01, (0, 2))
    zs, prior = _work(narrow, M=3, T=4)
    wide = pu.Gaussian(prior.mean, np.diag([25.0, 0.5, 25.0, 0.5]))
    a, b = (
        pu.run(pu.BootstrapParticleFilter(CV, narrow, particles=500, backend=bk), zs, wide, rng=run_streams(6, range(3), 1))
        for bk in ("numpy", "numba")
    )
    assert np.all(b.info["ess"] < 50)  # the regime tested: few particles carry weight
    np.testing.assert_allclose(b.mean, a.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b.info["loglik"], a.info["loglik"], rtol=1e-9, atol=1e-9)
