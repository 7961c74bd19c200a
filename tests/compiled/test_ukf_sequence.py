"""The compiled UKF/CKF over the whole sequence (``pursuit.run``'s ``sequence``).

The whole-sequence kernel (``gauss_kernels.sigma_sequence_*``) runs the
step kernel's own block functions (``_sigma_predict_ws``,
``_sigma_correct_ws``) step after step, so it must give the step path's
results **bit for bit** (not merely to 1e-12): every test below that
compares compiled paths uses ``np.array_equal``.  Against the NumPy filters
the tolerance is the backend's usual relative 1e-9.
"""

from __future__ import annotations

import numpy as np
import pytest

numba = pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import gauss_kernels  # noqa: E402
from pursuit._compiled import gaussian as glue  # noqa: E402
from pursuit._compiled import particle  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors  # noqa: E402

RTOL = 1e-9  # tests/compiled/test_numba_backend.py's agreement with NumPy
CV2 = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
CV3 = ConstantVelocity(ndim=3, dt=1.0, q=0.02)
SENSORS = {  # name: (motion, measurement)
    "range-bearing 2-D": (CV2, RangeBearing([0.0, -50.0], 1.0, 0.02)),
    "ranges 2-D": (CV2, RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 2.0, (0, 2))),
    "ranges 3-D": (CV3, RangeSensors([[0.0, 0.0, 0.0], [100.0, 0.0, 10.0], [0.0, 100.0, -10.0], [50.0, 50.0, 80.0]], 2.0, (0, 2, 4))),
    "linear 2-D": (CV2, LinearGaussian.position(4, (0, 2), 1.0)),
}
FILTERS = {"ukf": pu.UnscentedKalmanFilter, "ckf": pu.CubatureKalmanFilter}


def _data(motion, meas, M=5, T=30, seed=4):
    """Measurements ``(T, M, m)`` of targets near the sensors, with a missing component and steps with nothing measured."""
    rng = np.random.default_rng(seed)
    n = motion.transition_matrix().shape[0]
    x0 = np.zeros(n)
    x0[:4] = [20.0, 1.0, 30.0, 0.5]
    x = np.tile(x0, (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = motion.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    zs[3, min(2, M - 1), 0] = np.nan  # one missing component
    zs[5, : max(1, M // 2)] = np.nan  # a step with nothing measured for some runs
    return zs, x0


def _prior(x0, M, per_run):
    n = x0.shape[0]
    cov = np.diag(np.tile([2.0, 0.3], n // 2))
    if not per_run:
        return pu.Gaussian(x0, cov)
    return pu.Gaussian(np.tile(x0, (M, 1)) + np.random.default_rng(1).standard_normal((M, n)), np.broadcast_to(cov, (M, n, n)).copy())


def _assert_same_bits(a, b):
    assert np.array_equal(a.mean, b.mean, equal_nan=True)
    if b.cov is None:
        assert a.cov is None
    else:
        assert np.array_equal(a.cov, b.cov, equal_nan=True)
    assert sorted(a.info) == sorted(b.info)
    for key, value in b.info.items():
        assert a.info[key].dtype == value.dtype, key
        assert a.info[key].shape == value.shape, key
        assert np.array_equal(a.info[key], value, equal_nan=True), key


def _close(a, b, what):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, what
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{what}: NaN pattern differs"
    fin = np.isfinite(a)
    err = np.max(np.abs(a[fin] - b[fin]) / (1.0 + np.abs(a[fin])), initial=0.0)
    assert err <= RTOL, f"{what}: relative difference {err:.3g}"


@pytest.mark.parametrize("fading", [1.0, 1.05])
@pytest.mark.parametrize("sensor", sorted(SENSORS))
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_sequence_equals_step_by_step_bit_for_bit(name, sensor, fading):
    motion, meas = SENSORS[sensor]
    zs, x0 = _data(motion, meas)
    M = zs.shape[1]
    filt = FILTERS[name](motion, meas, backend="numba", fading=fading)
    for per_run in (False, True):
        prior = _prior(x0, M, per_run)
        assert filt.run_sequence(filt.init(prior, batch=(M,)), zs) is not None  # the path under test applies
        for keep_cov in (True, False):
            _assert_same_bits(pu.run(filt, zs, prior, keep_cov=keep_cov), pu.run(filt, zs, prior, keep_cov=keep_cov, sequence=False))


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_batches_of_one_and_unbatched(name):
    """Batch (1,) and () (one unbatched run, through the one-lane kernel) give the step path's bits: the online lane's."""
    motion, meas = SENSORS["range-bearing 2-D"]
    zs, x0 = _data(motion, meas, M=1)
    filt = FILTERS[name](motion, meas, backend="numba")
    prior = pu.Gaussian(x0, np.diag([2.0, 0.3, 2.0, 0.3]))
    assert filt.run_sequence(filt.init(prior, batch=()), zs[:, 0]) is not None
    one = pu.run(filt, zs, prior)
    _assert_same_bits(one, pu.run(filt, zs, prior, sequence=False))
    bare = pu.run(filt, zs[:, 0], prior)
    assert bare.mean.shape == (zs.shape[0], 4) and bare.info["nis"].shape == (zs.shape[0],)
    _assert_same_bits(bare, pu.run(filt, zs[:, 0], prior, sequence=False))
    # and the unbatched run is run 0 of the batch of one
    assert np.array_equal(bare.mean, one.mean[:, 0]) and np.array_equal(bare.cov, one.cov[:, 0])


@pytest.mark.parametrize("sensor", sorted(SENSORS))
@pytest.mark.parametrize("name", sorted(FILTERS))
def test_sequence_agrees_with_numpy(name, sensor):
    motion, meas = SENSORS[sensor]
    zs, x0 = _data(motion, meas, M=6, T=25)
    prior = _prior(x0, 6, True)
    a = pu.run(FILTERS[name](motion, meas, fading=1.05), zs, prior)
    b = pu.run(FILTERS[name](motion, meas, fading=1.05, backend="numba"), zs, prior)
    _close(a.mean, b.mean, "mean")
    _close(a.cov, b.cov, "cov")
    assert sorted(a.info) == sorted(b.info)
    for key in a.info:
        _close(a.info[key], b.info[key], key)


# 2 threads: the parallel build (make test runs the serial builds only, PURSUIT_NUMBA_PARALLEL=0)
@pytest.mark.parametrize("threads", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_a_runs_bits_do_not_depend_on_its_block(threads, monkeypatch):
    """Chunking invariance: a run gives the same bits alone, in a batch of 5 and at any place of a batch spanning several blocks."""
    if threads > 1:
        monkeypatch.setattr(particle, "PARALLEL", True)
    motion, meas = SENSORS["range-bearing 2-D"]
    M = 2 * gauss_kernels.SEQUENCE_BLOCK + 7  # three blocks, the last one short
    zs, x0 = _data(motion, meas, M=M, T=20)
    prior = _prior(x0, M, True)
    filt = pu.UnscentedKalmanFilter(motion, meas, backend="numba")
    old = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        whole = pu.run(filt, zs, prior)
        for lo in (0, gauss_kernels.SEQUENCE_BLOCK - 2, M - 5):  # the chunk straddles a block boundary, or ends the batch
            rows = slice(lo, lo + 5)
            part = pu.run(filt, zs[:, rows], pu.Gaussian(prior.mean[rows], prior.cov[rows]))
            assert np.array_equal(part.mean, whole.mean[:, rows]) and np.array_equal(part.cov, whole.cov[:, rows])
            for key in whole.info:
                assert np.array_equal(part.info[key], whole.info[key][:, rows], equal_nan=True), key
        for i in (0, gauss_kernels.SEQUENCE_BLOCK, M - 1):
            alone = pu.run(filt, zs[:, i], pu.Gaussian(prior.mean[i], prior.cov[i]))
            assert np.array_equal(alone.mean, whole.mean[:, i]) and np.array_equal(alone.cov, whole.cov[:, i])
    finally:
        numba.set_num_threads(old)


def test_runs_needing_repair_are_recomputed_step_by_step(monkeypatch):
    """A run the kernel flags (its covariance would need the NumPy repair) is recomputed alone, step by step."""
    motion, meas = SENSORS["range-bearing 2-D"]
    zs, x0 = _data(motion, meas, M=12, T=15)
    flagged = [3, 7]
    calls = []
    filt = pu.UnscentedKalmanFilter(motion, meas, backend="numba")
    prior = pu.Gaussian(x0, np.eye(4))
    steps = pu.run(filt, zs, prior, sequence=False)

    class Flagging:
        def __getattr__(self, name):
            real = getattr(gauss_kernels, name)
            if not name.startswith("sigma_sequence"):
                return real

            def call(*args):
                calls.append(name)
                real(*args)
                out = args[-1]
                out.ok[flagged] = False
                out.means[:, flagged] = -1.0  # what the kernel left there must not survive
            return call

    monkeypatch.setattr(glue, "GK", Flagging())
    whole = pu.run(filt, zs, prior)
    assert len(calls) == 1
    _assert_same_bits(whole, steps)


def test_not_used_where_a_step_needs_python():
    """A gate, irregular time steps and stored predictions take the step path, which still agrees with NumPy."""
    motion, meas = SENSORS["range-bearing 2-D"]
    zs, x0 = _data(motion, meas, M=4, T=10)
    prior = pu.Gaussian(x0, np.eye(4))
    gated = pu.UnscentedKalmanFilter(motion, meas, backend="numba", gate=0.999)
    assert gated.run_sequence(gated.init(prior, batch=(4,)), zs) is None
    _close(pu.run(gated, zs, prior).mean, pu.run(pu.UnscentedKalmanFilter(motion, meas, gate=0.999), zs, prior).mean, "gated mean")
    plain = pu.UnscentedKalmanFilter(motion, meas, backend="numba")
    a = pu.run(plain, zs, prior, dts=np.full(10, 0.5))
    b = pu.run(pu.UnscentedKalmanFilter(motion, meas), zs, prior, dts=np.full(10, 0.5))
    _close(a.mean, b.mean, "mean with dts")
    assert "pred_mean" in pu.run(plain, zs, prior, store_predictions=True).info
    assert plain.run_sequence(plain.init(prior, batch=(2, 2)), zs.reshape(10, 2, 2, 2)) is None  # two batch axes
