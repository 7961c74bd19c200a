"""The one-run step of the Gaussian filters (batch ``()``) against the general NumPy step.

``step`` on one run without a batch axis takes a lean path (plain 2-D arrays,
closed forms, no broadcasts); ``numpy_step`` is the general step every batch
takes, ``(1,)`` included, so that a run gives the same bits alone in a batch
of one as inside a larger batch (tested here too).  From the
same state and measurement both must give the same estimate and the same info
(keys, shapes, dtypes) to 1e-12 relative, in every situation the step meets:
angles wrapping, missing components, all-NaN steps, a gate, constant fading
above 1, a given dt.
"""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit._validation import measurement_for_step
from pursuit.filters.fading import Constant
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors

RTOL = 1e-12
SENSOR = np.array([0.0, 0.0])
X0 = np.array([-120.0, 4.0, 0.5, 0.1])  # left of the sensor: the bearing crosses ±π as y changes sign
STEPS = 60


def _motion():
    return ConstantVelocity(ndim=2, dt=1.0, q=0.5, noise="continuous")


def _filter(kind: str, **kw):
    mot = _motion()
    if kind == "KF":
        return pu.KalmanFilter(mot, LinearGaussian.position(4, mot.position_indices, 1.0), backend="numpy", **kw)
    if kind == "EKF3":  # three range anchors: m = 3 closed forms
        meas = RangeSensors(np.array([[0.0, 0.0], [-200.0, 50.0], [-100.0, -80.0]]), 2.0)
        return pu.ExtendedKalmanFilter(mot, meas, backend="numpy", **kw)
    meas = RangeBearing(SENSOR, 1.0, 0.01)
    cls = {"EKF": pu.ExtendedKalmanFilter, "UKF": pu.UnscentedKalmanFilter, "CKF": pu.CubatureKalmanFilter}[kind]
    return cls(mot, meas, backend="numpy", **kw)


def _measurements(filt, seed: int = 0) -> np.ndarray:
    """(STEPS, m) measurements of a CV track near the sensor's ±π cut, with gaps, partly missing ones and an outlier."""
    rng = np.random.default_rng(seed)
    x, out = X0.copy(), []
    for k in range(1, STEPS + 1):
        x = filt.motion.sample(x, k, rng)
        out.append(filt.measurement.sample(x, k, rng))
    zs = np.array(out)
    zs[7] = np.nan  # all missing
    zs[8] = np.nan
    zs[15, 0] = np.nan  # one component missing
    zs[30] += 500.0  # an outlier (the gate rejects it)
    return zs


def _assert_close(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype, f"{what}: dtype {a.dtype} != {b.dtype}"
    if a.dtype == bool or np.issubdtype(a.dtype, np.integer):
        np.testing.assert_array_equal(a, b, err_msg=what)
        return
    scale = np.nanmax(np.abs(b)) if np.isfinite(b).any() else 0.0
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * scale, equal_nan=True, err_msg=what)


def _compare(filt, state, z, dt, batch):
    k = state.k + 1
    fast_state, fast = filt.step(state, z, dt=dt)
    zb = measurement_for_step(z, batch, filt._measurement_dim(), k)
    ref_state, ref = filt.numpy_step(state, zb, k, dt)
    assert fast_state.k == ref_state.k == k
    assert fast_state.mean.shape == ref_state.mean.shape and fast_state.cov.shape == ref_state.cov.shape
    _assert_close(fast_state.mean, ref_state.mean, f"step {k}: mean")
    _assert_close(fast_state.cov, ref_state.cov, f"step {k}: cov")
    assert set(fast) == set(ref), f"step {k}: info keys"
    for key in ref:
        want = np.asarray(ref[key])
        got = np.asarray(fast[key])
        if key in ("pred_cov", "cross_cov"):  # (n, n) or (*batch, n, n): either broadcasts, as today
            got, want = np.broadcast_arrays(got, want)
        else:
            assert got.shape == want.shape, f"step {k}: info[{key!r}] shape {got.shape} != {want.shape}"
        _assert_close(got, want, f"step {k}: info[{key!r}]")
    return fast_state, fast


CASES = [
    ("KF", {}),
    ("KF", {"gate": 0.99}),
    ("KF", {"fading": Constant(1.3)}),
    ("EKF", {}),
    ("EKF", {"gate": 0.99, "fading": 1.2}),
    ("EKF3", {}),
    ("UKF", {}),
    ("UKF", {"gate": 0.99}),
    ("UKF", {"fading": Constant(1.15)}),
    ("CKF", {}),
    ("CKF", {"gate": 0.995, "fading": 1.1}),
]


@pytest.mark.parametrize("batch", [(), (1,)], ids=["batch()", "batch(1,)"])
@pytest.mark.parametrize("kind,kw", CASES, ids=[f"{k}-{'-'.join(map(str, kw)) or 'plain'}" for k, kw in CASES])
@pytest.mark.parametrize("irregular", [False, True], ids=["dt-model", "dt-given"])
def test_one_run_step_equals_the_general_step(kind, kw, batch, irregular):
    filt = _filter(kind, **kw)
    zs = _measurements(filt)
    dts = np.random.default_rng(3).uniform(0.2, 3.0, STEPS) if irregular else [None] * STEPS
    state = filt.init(pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0])), batch=batch)
    gated = wrapped = 0
    for z, dt in zip(zs, dts):
        z = np.broadcast_to(z, (*batch, z.shape[-1])) if batch else z
        state, info = _compare(filt, state, z, dt, batch)
        gated += int(np.sum(info["gated"]))
        wrapped += kind in ("EKF", "UKF", "CKF") and bool(np.any(np.abs(info["pred_mean"][..., 2]) < 1.0))
    if "gate" in kw:
        assert gated >= 1  # the outlier was rejected
    if kind in ("EKF", "UKF", "CKF"):
        assert wrapped  # the track passed the bearing's cut during the test


@pytest.mark.parametrize("kind", ["KF", "EKF", "UKF", "CKF"])
def test_a_batch_of_three_equals_three_one_run_steps(kind):
    """The general (batched) step on three runs against the one-run step of each, along a whole sequence."""
    filt = _filter(kind, gate=0.99)
    zs = np.stack([_measurements(filt, seed) for seed in range(3)], axis=1)  # (STEPS, 3, m)
    prior = pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0]))
    batched = filt.init(prior, batch=(3,))
    singles = [filt.init(prior) for _ in range(3)]
    for z in zs:
        batched, info = filt.step(batched, z)
        for i in range(3):
            singles[i], one = filt.step(singles[i], z[i])
            np.testing.assert_allclose(singles[i].mean, batched.mean[i], rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(singles[i].cov, batched.cov[i], rtol=1e-9, atol=1e-9)
            for key in ("nis", "loglik", "dof", "gated"):
                np.testing.assert_allclose(one[key], info[key][i], rtol=1e-9, atol=1e-9, equal_nan=True, err_msg=key)


@pytest.mark.parametrize("kind", ["KF", "EKF", "UKF", "CKF"])
def test_a_batch_of_one_equals_the_same_run_in_a_batch_of_three_bit_for_bit(kind):
    """A Monte Carlo chunk of one run must not change a bit (results do not depend on the chunk size)."""
    filt = _filter(kind, gate=0.99)
    zs = np.stack([_measurements(filt, seed) for seed in range(3)], axis=1)  # (STEPS, 3, m)
    prior = pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0]))
    three, one = filt.init(prior, batch=(3,)), filt.init(prior, batch=(1,))
    for z in zs:
        three, info3 = filt.step(three, z)
        one, info1 = filt.step(one, z[2:3])
        assert np.array_equal(one.mean[0], three.mean[2]) and np.array_equal(one.cov[0], three.cov[2])
        for key in ("innovation", "S", "nis", "loglik"):  # reductions over a batch may round differently: states are what must agree
            np.testing.assert_allclose(np.asarray(info1[key])[0], np.asarray(info3[key])[2], rtol=1e-12, equal_nan=True, err_msg=key)


def test_the_one_run_path_runs(monkeypatch):
    """A fully measured step of one run does not go through the general step (the lean path is taken)."""
    filt = _filter("UKF")
    state = filt.init(pu.Gaussian(X0, np.eye(4)))

    def boom(*a, **k):
        raise AssertionError("general step called")

    monkeypatch.setattr(type(filt), "numpy_step", boom)
    filt.step(state, np.array([120.0, 3.1]))
    filt.step(state, np.array([np.nan, np.nan]))
    with pytest.raises(AssertionError, match="general step"):
        filt.step(state, np.array([np.nan, 3.1]))  # partly missing: the general step


def test_a_covariance_that_needs_a_repair_takes_the_general_step():
    filt = _filter("UKF")
    state = filt.init(pu.Gaussian(X0, np.eye(4)))
    bad = np.diag([1.0, -1e-9, 1.0, 1.0])  # not positive definite: the sigma points need the repair
    state = pu.filters.GaussianState(mean=state.mean, cov=bad, k=0)
    new, info = filt.step(state, np.array([120.0, 3.1]))
    assert bool(info["repaired"])
    ref, ref_info = filt.numpy_step(state, np.array([120.0, 3.1]), 1, None)
    np.testing.assert_allclose(new.mean, ref.mean, rtol=RTOL)


@pytest.mark.parametrize("batch", [(), (1,)])
def test_measurement_checks_stay(batch):
    filt = _filter("KF")
    state = filt.init(pu.Gaussian(np.zeros(4), np.eye(4)), batch=batch)
    with pytest.raises(ValueError, match="z: expected shape"):
        filt.step(state, np.zeros((*batch, 3)))
    with pytest.raises(ValueError, match="infinity"):
        filt.step(state, np.array([np.inf, 0.0]))
    with pytest.raises(ValueError, match="beyond"):
        filt.step(state, np.array([1e200, 0.0]))
    # lists and integers are still accepted and broadcast
    new, _ = filt.step(state, [1, 2])
    assert new.mean.shape == (*batch, 4)


def test_one_run_state_is_shared_and_read_only():
    filt = _filter("KF")
    state = filt.init(pu.Gaussian(np.zeros(4), np.eye(4)), batch=(1,))
    new, _ = filt.step(state, np.array([[1.0, 2.0]]))
    assert new.cov.shape == (1, 4, 4) and new.cov.strides[0] == 0 and not new.cov.flags.writeable


@pytest.mark.parametrize("batch", [(), (1,)], ids=["batch()", "batch(1,)"])
@pytest.mark.parametrize("kind", ["KF", "EKF", "UKF", "CKF"])
def test_a_kept_prediction_does_not_share_memory_with_the_info(kind, batch):
    """Gated or unmeasured, the new mean is the prediction's value in an array of its own (as in the general step)."""
    filt = _filter(kind, gate=0.99)
    state = filt.init(pu.Gaussian(X0, np.diag([25.0, 1.0, 25.0, 1.0])), batch=batch)
    z_far = filt.measurement.h(X0, 1) + np.array([500.0, 0.0])[: filt._measurement_dim()]
    for z in (np.broadcast_to(z_far, (*batch, z_far.size)), np.full((*batch, z_far.size), np.nan)):
        new, info = filt.step(state, z)
        assert bool(np.all(info["gated"])) or np.isnan(z).all()
        np.testing.assert_array_equal(new.mean, info["pred_mean"])
        assert not np.shares_memory(new.mean, info["pred_mean"]) and not np.shares_memory(new.mean, state.mean)
