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


class _UsersCV:
    """The constant-velocity model as a user's class: not a built-in linear model, so the UKF/CKF predict through points."""

    def __init__(self):
        self._cv = _motion()
        self.dim = 4

    def f(self, x, k=None, dt=None):
        return self._cv.f(x, k, dt=dt)

    def cov(self, k=None, dt=None):
        return self._cv.cov(k, dt=dt)

    def sample(self, x, k, rng):  # for simulating the test's measurements only
        return self._cv.sample(x, k, rng)


def _filter(kind: str, **kw):
    mot = _motion()
    if kind.endswith("-users-motion"):  # the sigma-point prediction through points
        kind, mot = kind.removesuffix("-users-motion"), _UsersCV()
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
    ("UKF-users-motion", {}),
    ("CKF-users-motion", {"gate": 0.995}),
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
        wrapped += kind.split("-")[0] in ("EKF", "UKF", "CKF") and bool(np.any(np.abs(info["pred_mean"][..., 2]) < 1.0))
    if "gate" in kw:
        assert gated >= 1  # the outlier was rejected
    if kind.split("-")[0] in ("EKF", "UKF", "CKF"):
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
    # not positive definite, nor is its prediction F P Fᵀ + Q (the linear motion is predicted without
    # points): the update's sigma points need the repair
    bad = np.diag([1.0, -2.0, 1.0, 1.0])
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


# -- the lazy info ------------------------------------------------------------------------------------
def _steps(filt, count=12, batch=()):
    """(state, info) of ``count`` one-run steps along :func:`_measurements` (gaps and a partly missing step included)."""
    zs = _measurements(filt)
    state = filt.init(pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0])), batch=batch)
    out = []
    for z in zs[:count]:
        state, info = filt.step(state, z)
        out.append((state, info))
    return out


def _eager(info):
    """The values of ``info`` as a plain dict, each made now (np.array copies: no view of the lazy mapping's arrays)."""
    return {key: np.array(value) for key, value in dict(info).items()}


@pytest.mark.parametrize("kind", ["KF", "EKF", "EKF3", "UKF", "CKF"])
def test_the_lazy_info_is_a_mapping_with_the_keys_and_order_of_the_general_step(kind):
    from collections.abc import Mapping

    filt = _filter(kind, gate=0.99)
    state = filt.init(pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0])))
    z = _measurements(filt)[0]
    _, info = filt.step(state, z)
    _, ref = filt.numpy_step(state, z, 1, None)
    assert isinstance(info, Mapping) and type(info) is not dict  # the lazy mapping: the test below is about it
    assert list(info) == list(ref) == list(pu.filters.gaussian.INFO_KEYS)
    assert len(info) == len(ref) and all(key in info for key in ref) and "nope" not in info
    assert info.get("nope") is None
    with pytest.raises(KeyError):
        info["nope"]
    got = dict(info)
    assert list(got) == list(ref)
    for key in ref:
        _assert_close(got[key], ref[key], key)


@pytest.mark.parametrize("kind", ["KF", "EKF", "UKF"])
def test_each_lazy_value_is_made_once_and_equals_the_eager_one(kind):
    """Read in any order, each value is one array (the same object on every read), equal to the one-run step's eager values."""
    filt = _filter(kind)
    steps = _steps(filt)
    for order in (list(pu.filters.gaussian.INFO_KEYS), list(reversed(pu.filters.gaussian.INFO_KEYS))):
        for state, info in _steps(filt):
            first = {key: info[key] for key in order}
            assert all(info[key] is first[key] for key in order)
    # values read after later steps are those of their own step (no buffer shared between steps)
    late = [_eager(info) for _, info in steps]
    again = [_eager(info) for _, info in _steps(filt)]
    for a, b in zip(late, again):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_the_lazy_values_have_the_dtypes_and_shapes_of_the_general_step():
    filt = _filter("EKF")
    state, info = _steps(filt, 3)[-1]
    assert info["S"].shape == (2, 2) and info["S"].dtype == np.float64 and info["S"].flags.writeable
    for key in ("nis", "loglik"):
        assert info[key].shape == () and info[key].dtype == np.float64
    nu, S = info["innovation"], info["S"]
    np.testing.assert_allclose(info["nis"], nu @ np.linalg.solve(S, nu), rtol=1e-12)
    want = -0.5 * (nu @ np.linalg.solve(S, nu) + np.linalg.slogdet(S)[1] + 2 * np.log(2 * np.pi))
    np.testing.assert_allclose(info["loglik"], want, rtol=1e-12)


@pytest.mark.parametrize("kind", ["KF", "UKF"])
def test_the_lazy_info_pickles_copies_and_prints_as_the_plain_dict(kind):
    import copy
    import pickle

    filt = _filter(kind)
    for _, info in _steps(filt, 10):  # includes the all-missing steps 8 and 9
        back = pickle.loads(pickle.dumps(info))
        assert type(back) is dict and list(back) == list(info)
        for key in info:
            np.testing.assert_array_equal(back[key], info[key], err_msg=key)
        assert type(copy.copy(info)) is dict
        assert repr(info) == repr(dict(info)) and repr(info).startswith("{'innovation': array(")


def test_setting_or_deleting_a_key_keeps_every_value_and_the_order():
    filt = _filter("EKF")
    (_, a), (_, b) = _steps(filt, 2)
    want = _eager(a)
    a["diverged"] = np.array(False)  # what pursuit.run adds
    assert list(a) == [*pu.filters.gaussian.INFO_KEYS, "diverged"]
    for key in want:
        np.testing.assert_array_equal(a[key], want[key], err_msg=key)
    want_b = _eager(b)
    del b["cross_cov"]
    assert list(b) == list(pu.filters.gaussian.INFO_KEYS)[:-1] and len(b) == 11 and "cross_cov" not in b
    for key in b:
        np.testing.assert_array_equal(b[key], want_b[key], err_msg=key)
    b.update(x=1)
    assert b["x"] == 1 and {**b}["x"] == 1


def test_one_run_update_gives_the_values_of_the_lazy_info():
    """The eager helper that other filters' one-run paths call agrees with the step's info to the bit."""
    from pursuit.filters.gaussian import _one_run_update

    filt = _filter("EKF")
    state = _steps(filt, 3)[-1][0]
    z = _measurements(filt)[3]
    pred = filt._predict_one(state.mean, state.cov, 4, None)
    P_pred = pred.propagated + pred.Q
    meas = filt._measure_one(pred.mean, P_pred, 4)
    mean, cov, nu, S, nis, loglik = _one_run_update(pred.mean, P_pred, z, meas, filt.measurement, 4)
    new, info = filt.step(state, z)
    np.testing.assert_array_equal(mean, new.mean)
    np.testing.assert_array_equal(cov, new.cov)
    np.testing.assert_array_equal(S, info["S"])
    assert nis == float(info["nis"]) and loglik == float(info["loglik"]) and isinstance(nis, float)


# -- the covariance: the Joseph form as Gram matrices --------------------------------------------------
@pytest.mark.parametrize("kind", ["KF", "EKF", "EKF3", "UKF", "CKF"])
def test_the_one_run_covariance_is_symmetric_to_the_bit(kind):
    for state, _ in _steps(_filter(kind), 40):
        assert np.array_equal(state.cov, state.cov.T)


_SLOW = pytest.mark.slow  # several seconds each: the sigma-point and range cases run with make test-slow


@pytest.mark.parametrize(
    "kind,sensor",
    [("KF", "position"), ("EKF", "range-bearing"), pytest.param("EKF", "range", marks=_SLOW),
     pytest.param("UKF", "toa", marks=_SLOW), pytest.param("CKF", "range", marks=_SLOW)],
)
def test_one_run_steps_after_long_gaps_stay_positive_definite_under_last_bit_perturbations(kind, sensor):
    """test_perturbation's gaps scenario (500 s gaps, 1 mm sensors, 20 % missing) stepped one run at a time (batch ())."""
    from .test_perturbation import perturbed_batch, scenario

    motion, meas, z, dts, prior = scenario(sensor, gaps=True, runs=2, steps=700, seed=4)[:5]
    zs, batch_prior = perturbed_batch(z, prior)
    cls = {"KF": pu.KalmanFilter, "EKF": pu.ExtendedKalmanFilter, "UKF": pu.UnscentedKalmanFilter, "CKF": pu.CubatureKalmanFilter}[kind]
    filt = cls(motion, meas, backend="numpy")
    gaps = int(np.sum(dts >= 500.0))
    assert gaps >= 1
    for run in range(zs.shape[1]):
        state = filt.init(pu.Gaussian(batch_prior.mean[run], batch_prior.cov[run]))
        for i in range(zs.shape[0]):
            state, info = filt.step(state, zs[i, run], dt=float(dts[i]))
            assert not bool(info["repaired"]), f"run {run}, step {i + 1}: repaired"
            assert np.all(np.isfinite(state.mean)) and np.array_equal(state.cov, state.cov.T)
            np.linalg.cholesky(state.cov)  # LinAlgError where not positive definite


# -- cached model matrices -----------------------------------------------------------------------------
class _Growing(pu.models.ConstantVelocity):
    """A user's model: Q grows with the step (an override: the one-run step must not cache its matrices)."""

    def cov(self, k=None, dt=None):
        return super().cov(k, dt) * (1.0 + 0.1 * (k or 0))


class _Drifting(LinearGaussian):
    """A user's sensor whose noise grows with the step, without ``residual`` override and without ``dim``."""

    def cov(self, k=None):
        return self.R * (1.0 + 0.05 * (k or 0))


def test_a_model_whose_matrices_change_with_the_step_is_not_cached():
    base = LinearGaussian.position(4, (0, 2), 1.0)
    meas = _Drifting(base.H, base.R)
    filt = pu.KalmanFilter(_Growing(ndim=2, dt=1.0, q=0.5, noise="continuous"), meas, backend="numpy")
    zs = _measurements(_filter("KF"))
    state = filt.init(pu.Gaussian(X0, np.diag([20.0, 2.0, 20.0, 2.0])))
    for z in zs[:20]:
        state, _ = _compare(filt, state, z, None, ())
    assert filt.__dict__.get("_one_run_motion") is False and "_one_run_noise" not in filt.__dict__


def test_built_in_models_are_read_once_per_dt():
    filt = _filter("KF")
    state = filt.init(pu.Gaussian(X0, np.eye(4)))
    for dt in (None, 0.5, None, 0.5, 2.0):
        state, _ = _compare(filt, state, np.array([-120.0, 4.0]), dt, ())
    assert set(filt.__dict__["_one_run_motion"]) == {None, 0.5, 2.0}
    R, C, r = filt.__dict__["_one_run_noise"]
    assert R is filt.measurement.R and r == R.ravel().tolist()
    np.testing.assert_allclose(C @ C.T, R, rtol=1e-15)


def test_a_sensor_without_dim_or_residual_takes_the_one_run_path():
    class Plain:
        """A bare user sensor: h, jacobian, cov only."""

        H = LinearGaussian.position(4, (0, 2), 1.0).H

        def h(self, x, k=None):
            return x[..., [0, 2]]

        def jacobian(self, x, k=None):
            return self.H

        def cov(self, k=None):
            return np.diag([1.0, 2.0])

    filt = pu.ExtendedKalmanFilter(_motion(), Plain(), backend="numpy")
    state = filt.init(pu.Gaussian(X0, np.eye(4)))
    for z in _measurements(_filter("KF"))[:12]:
        state, info = _compare(filt, state, z, None, ())
    assert type(info) is not dict  # the lazy info of the one-run step


def test_changing_the_innovation_in_place_does_not_change_the_lazy_nis_or_loglik():
    filt = _filter("KF")
    state = filt.init(pu.Gaussian(X0 + 1.0, np.diag([20.0, 2.0, 20.0, 2.0])))
    z = _measurements(filt)[0]
    _, want = filt.numpy_step(state, z, 1, None)
    _, info = filt.step(state, z)
    info["innovation"][:] = 0.0  # a caller's own use of the array it was given
    _assert_close(info["nis"], want["nis"], "nis")
    _assert_close(info["loglik"], want["loglik"], "loglik")


def test_the_lazy_info_copies_and_merges_as_a_dict():
    filt = _filter("EKF")
    (_, info), = _steps(filt, 1)
    want = _eager(info)
    for got in (info.copy(), info | {}, {} | info):
        assert type(got) is dict and list(got) == list(want)
        for key in want:
            np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    merged = {"nis": None, "extra": 1} | info
    assert merged["extra"] == 1 and merged["nis"] is not None and list(merged)[:2] == ["nis", "extra"]
    assert (info | {"extra": 2})["extra"] == 2


def test_pickling_a_filter_drops_its_model_caches_and_the_unpickled_models_stay_read_only():
    import pickle

    filt = _filter("KF")
    state = filt.init(pu.Gaussian(X0, np.eye(4)))
    for dt in (None, 0.5, 2.0):
        state, _ = filt.step(state, np.array([-120.0, 4.0]), dt=dt)
    assert "_one_run_motion" in filt.__dict__ and "_one_run_noise" in filt.__dict__
    back = pickle.loads(pickle.dumps(filt))
    assert not any(name.startswith("_one_run_") for name in back.__dict__)
    for arr in (back.measurement.R, back.motion.transition_matrix(), back.motion.cov()):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[0, 0] = 1.0
    np.testing.assert_array_equal(back.measurement.H, filt.measurement.H)
    assert back.measurement.H.dtype == filt.measurement.H.dtype
    lin = pu.models.LinearMotion(np.eye(2), 0.1 * np.eye(2))
    for arr in (pickle.loads(pickle.dumps(lin)).F, pickle.loads(pickle.dumps(lin)).Q):
        assert not arr.flags.writeable


def test_a_writable_noise_matrix_is_read_every_step():
    """R made writable behind the model's back (e.g. by an old pickle) is not cached: an in-place change is seen."""
    filt = _filter("KF")
    R = np.array(filt.measurement.R)  # writable
    object.__setattr__(filt.measurement, "R", R)
    state = filt.init(pu.Gaussian(X0, np.eye(4)))
    state, _ = filt.step(state, np.array([-120.0, 4.0]))
    assert "_one_run_noise" not in filt.__dict__
    R *= 4.0
    z = np.array([-119.0, 4.5])
    _, want = filt.numpy_step(state, z, 2, None)
    _, got = filt.step(state, z)
    _assert_close(got["nis"], want["nis"], "nis")
