"""The compiled KF/EKF over the whole sequence (``pursuit.run``'s ``sequence``) gives the step-by-step bits."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import gaussian as glue  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeSensors  # noqa: E402

MOTION = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
LINEAR = LinearGaussian.position(4, (0, 2), 1.0)
RANGES = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], 2.0, (0, 2))


def _data(meas, M=300, T=40, seed=4):
    rng = np.random.default_rng(seed)
    x0 = np.array([10.0, 0.5, 40.0, 0.8])
    x = np.tile(x0, (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = MOTION.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    zs[3, min(7, M - 1), 0] = np.nan  # one missing component
    zs[5, :20] = np.nan  # steps with nothing measured for some runs
    return zs, x0


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


@pytest.mark.parametrize("cls, meas", [(pu.KalmanFilter, LINEAR), (pu.ExtendedKalmanFilter, RANGES), (pu.ExtendedKalmanFilter, LINEAR)])
@pytest.mark.parametrize("per_run_prior", [False, True])
@pytest.mark.parametrize("keep_cov", [True, False])
def test_sequence_equals_step_by_step(cls, meas, per_run_prior, keep_cov):
    zs, x0 = _data(meas)
    M = zs.shape[1]
    cov = np.diag([2.0, 0.3, 2.0, 0.3])
    prior = pu.Gaussian(np.tile(x0, (M, 1)) + np.random.default_rng(1).standard_normal((M, 4)), np.broadcast_to(cov, (M, 4, 4)).copy()) \
        if per_run_prior else pu.Gaussian(x0, cov)
    filt = cls(MOTION, meas, backend="numba", fading=1.05)
    assert filt.run_sequence(filt.init(prior, batch=(M,)), zs) is not None  # the path under test applies
    whole = pu.run(filt, zs, prior, keep_cov=keep_cov)
    steps = pu.run(filt, zs, prior, keep_cov=keep_cov, sequence=False)
    _assert_same_bits(whole, steps)


def test_keep_info_selects_keys():
    zs, x0 = _data(LINEAR, M=20, T=10)
    filt = pu.KalmanFilter(MOTION, LINEAR, backend="numba")
    track = pu.run(filt, zs, pu.Gaussian(x0, np.eye(4)), keep_info=["nis"])
    assert sorted(track.info) == ["diverged", "nis"]  # the divergence flag is kept whatever keep_info says
    assert not track.info["diverged"].any()


class _Flagging:
    """Wraps a kernel module: its sequence kernels flag some runs (and scribble on their means) after running."""

    def __init__(self, real, flagged, calls):
        self._real, self._flagged, self._calls = real, flagged, calls

    def __getattr__(self, name):
        return getattr(self._real, name)

    def _flag(self, kernel, generated_kernel):
        def call(*args):
            self._calls.append(kernel)
            kernel(*args)
            # the generated kernel takes a range of blocks after the outputs; the block kernel's outputs
            # are one GaussSequenceOutputs, its last argument
            means, ok = (args[-10], args[-3]) if generated_kernel else (args[-1].means, args[-1].ok)
            ok[self._flagged] = False
            # what the kernel left there must not survive (the generated kernel's means are flattened per step)
            means.reshape(means.shape[0], ok.shape[0], -1)[:, self._flagged] = -1.0
        return call

    def __getattribute__(self, name):
        if name in ("ekf_sequence_parallel", "ekf_sequence_serial", "sequence"):
            flag = object.__getattribute__(self, "_flag")
            return flag(getattr(object.__getattribute__(self, "_real"), name), name == "sequence")
        return object.__getattribute__(self, name)


@pytest.mark.parametrize("cls, meas", [(pu.KalmanFilter, LINEAR), (pu.ExtendedKalmanFilter, RANGES)], ids=["generated", "block"])
def test_runs_needing_repair_are_recomputed_step_by_step(monkeypatch, cls, meas):
    """A run the kernel flags (its covariance would need the NumPy repair) is recomputed alone, step by step.

    Both sequence kernels are covered: the generated one of a linear measurement and the block one.
    """
    zs, x0 = _data(meas, M=50, T=15)
    flagged = [3, 17, 40]
    calls = []
    filt = cls(MOTION, meas, backend="numba")
    prior = pu.Gaussian(x0, np.eye(4))
    steps = pu.run(filt, zs, prior, sequence=False)
    monkeypatch.setattr(glue, "GK", _Flagging(glue.GK, flagged, calls))
    real_linear = glue._linear_kernels

    def flagged_linear(*args):
        module = real_linear(*args)
        return None if module is None else _Flagging(module, flagged, calls)

    monkeypatch.setattr(glue, "_linear_kernels", flagged_linear)
    whole = pu.run(filt, zs, prior)
    assert len(calls) == 1
    assert whole.info["repaired"].sum() == 0  # flagged, not broken: the step path needed no repair
    _assert_same_bits(whole, steps)


def test_infinite_measurement_names_the_step():
    zs, x0 = _data(LINEAR, M=5, T=8)
    zs[4, 2, 1] = np.inf
    filt = pu.KalmanFilter(MOTION, LINEAR, backend="numba")
    with pytest.raises(ValueError, match="step 5: measurement contains infinity"):
        pu.run(filt, zs, pu.Gaussian(x0, np.eye(4)))


def test_a_measurement_too_large_to_square_names_the_step():
    zs, x0 = _data(LINEAR, M=5, T=8)
    zs[4, 2, 1] = -1e300  # used to run through the compiled sequence into NaN estimates
    filt = pu.KalmanFilter(MOTION, LINEAR, backend="numba")
    with pytest.raises(ValueError, match=r"step 5: measurement z\[2, 1\] = -1e\+300 is beyond ±2\^500"):
        pu.run(filt, zs, pu.Gaussian(x0, np.eye(4)))
    with pytest.raises(ValueError, match=r"step 5: measurement z\[2, 1\] = -1e\+300 is beyond ±2\^500"):
        pu.run(filt, zs, pu.Gaussian(x0, np.eye(4)), sequence=False)


def test_not_used_where_a_step_needs_python():
    """Gated filters, irregular time steps and stored predictions take the step path (and still agree with NumPy)."""
    zs, x0 = _data(LINEAR, M=10, T=8)
    prior = pu.Gaussian(x0, np.eye(4))
    gated = pu.KalmanFilter(MOTION, LINEAR, backend="numba", gate=0.999)
    state = gated.init(prior, batch=(10,))
    assert gated.run_sequence(state, zs) is None
    plain = pu.KalmanFilter(MOTION, LINEAR, backend="numba")
    a = pu.run(plain, zs, prior, dts=np.full(8, 0.5))
    b = pu.run(pu.KalmanFilter(MOTION, LINEAR), zs, prior, dts=np.full(8, 0.5))
    assert np.allclose(a.mean, b.mean, rtol=1e-9, atol=1e-9)
    track = pu.run(plain, zs, prior, store_predictions=True)
    assert "pred_mean" in track.info


def test_a_subclass_that_overrides_step_is_stepped_from_python():
    zs, x0 = _data(LINEAR, M=4, T=6)
    calls = []

    class Counting(pu.KalmanFilter):
        def step(self, state, z, k=None, dt=None):
            calls.append(k)
            return super().step(state, z, k, dt)

    filt = Counting(MOTION, LINEAR, backend="numba")
    prior = pu.Gaussian(x0, np.eye(4))
    assert filt.run_sequence(filt.init(prior, batch=(4,)), zs) is None
    pu.run(filt, zs, prior)
    assert calls == [1, 2, 3, 4, 5, 6]
