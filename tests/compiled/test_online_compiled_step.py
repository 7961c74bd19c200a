"""One run stepped from Python with ``backend="numba"`` (the online lane) gives the batched compiled step's bits.

The lane (:mod:`pursuit._compiled.online`) takes ``filt.step`` for a batch
``()`` or ``(1,)``; the batched compiled step (a batch of several runs, where
the lane does not apply) is the exact reference, the NumPy filter the
cross-check (1e-9 relative).
"""

from __future__ import annotations

import copy
import gc
import inspect
import pickle
import weakref

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled.online import INFO_KEYS, StepInfo  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors  # noqa: E402

MOTION = ConstantVelocity(ndim=2, dt=1.0, q=0.05)
LINEAR = LinearGaussian.position(4, (0, 2), 1.0)
RB = RangeBearing(np.array([0.0, -50.0]), 1.0, 0.02)
X0 = np.array([10.0, 1.0, 40.0, 0.5])
COV0 = np.diag([4.0, 0.5, 4.0, 0.5])
T = 30
DTS = [None, 0.5, None, 2.0, 1.0] * (T // 5)  # dt given on some steps (irregular sampling)

CASES = [
    ("KF", pu.KalmanFilter, LINEAR),
    ("EKF-linear", pu.ExtendedKalmanFilter, LINEAR),
    ("EKF-rb", pu.ExtendedKalmanFilter, RB),
    ("UKF-rb", pu.UnscentedKalmanFilter, RB),
    ("CKF-rb", pu.CubatureKalmanFilter, RB),
]


def _measurements(meas, seed=3):
    rng = np.random.default_rng(seed)
    x = X0.copy()
    zs = np.empty((T, meas.dim))
    for k in range(T):
        x = MOTION.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    zs[3, 0] = np.nan  # one missing component
    zs[5] = np.nan  # nothing measured: predict only
    zs[8, 0] += 40.0  # an outlier for the gate
    return zs


def _filters(cls, meas, **kw):
    return cls(MOTION, meas, backend="numba", **kw), cls(MOTION, meas, backend="numpy", **kw)


OPTIONS = [dict(), dict(fading=1.05), dict(gate=0.99)]


def _steps(filt, zs, batch, dts):
    """States and infos of one run stepped from Python (batch () or (1,))."""
    s = filt.init(pu.Gaussian(X0, COV0), batch=batch)
    out = []
    for k in range(T):
        z = zs[k] if batch == () else zs[k][None]
        s, info = filt.step(s, z, dt=dts[k])
        out.append((s, info))
    return out


@pytest.mark.parametrize("name, cls, meas", CASES)
@pytest.mark.parametrize("opts", OPTIONS, ids=["plain", "fading", "gate"])
@pytest.mark.parametrize("batch", [(), (1,)])
def test_online_equals_batched_compiled_bit_for_bit(name, cls, meas, opts, batch):
    zs = _measurements(meas)
    filt, _ = _filters(cls, meas, **opts)
    online = _steps(filt, zs, batch, DTS)
    # the reference: a batch of three runs (the lane does not apply), run 0 the same as the online run
    other = zs + np.random.default_rng(9).normal(0.0, 0.01, zs.shape)
    zb = np.stack([zs, other, other[::-1]], axis=1)
    sb = filt.init(pu.Gaussian(np.stack([X0, X0 + 0.1, X0 - 0.1]), np.broadcast_to(COV0, (3, 4, 4))), batch=(3,))
    assert isinstance(online[0][1], StepInfo)  # the lane was taken
    gated_somewhere = False
    for k in range(T):
        sb, ib = filt.step(sb, zb[k], dt=DTS[k])
        assert not isinstance(ib, StepInfo)
        s, info = online[k]
        assert s.k == k + 1 and s.memory is None
        assert np.array_equal(s.mean.reshape(4), sb.mean[0], equal_nan=True), k
        assert np.array_equal(s.cov.reshape(4, 4), sb.cov[0], equal_nan=True), k
        assert set(info) == set(ib)
        for key in ib:
            assert info[key].shape == batch + ib[key].shape[1:], key
            assert info[key].dtype == ib[key].dtype, key
            assert np.array_equal(info[key].reshape(ib[key][0].shape), ib[key][0], equal_nan=True), (key, k)
        gated_somewhere |= bool(info["gated"].any())
    assert gated_somewhere == ("gate" in opts)


@pytest.mark.parametrize("name, cls, meas", CASES)
@pytest.mark.parametrize("opts", OPTIONS, ids=["plain", "fading", "gate"])
def test_online_equals_numpy(name, cls, meas, opts):
    zs = _measurements(meas)
    filt, ref = _filters(cls, meas, **opts)
    for batch in [(), (1,)]:
        online = _steps(filt, zs, batch, DTS)
        numpy = _steps(ref, zs, batch, DTS)
        for (s, info), (r, rinfo) in zip(online, numpy):
            assert s.mean.shape == r.mean.shape and s.cov.shape == r.cov.shape
            np.testing.assert_allclose(s.mean, r.mean, rtol=1e-9, atol=1e-9 * np.abs(r.mean).max())
            np.testing.assert_allclose(s.cov, r.cov, rtol=1e-9, atol=1e-9 * np.abs(r.cov).max())
            assert sorted(info) == sorted(rinfo) == sorted(INFO_KEYS)
            for key in rinfo:
                a, b = np.asarray(info[key]), np.asarray(rinfo[key])
                if key in ("pred_cov", "cross_cov"):
                    # NumPy keeps one (n, n) matrix where every run shares it; the compiled steps give (*batch, n, n)
                    assert a.shape == batch + (4, 4) and b.shape in (a.shape, (4, 4)), key
                    b = np.broadcast_to(b, a.shape)
                assert a.shape == b.shape, key
                assert a.dtype == b.dtype, key
                if a.dtype == bool or a.dtype.kind == "i":
                    assert np.array_equal(a, b), key
                else:
                    scale = max(float(np.abs(np.nan_to_num(b)).max(initial=0.0)), 1e-300)
                    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * scale, equal_nan=True, err_msg=key)


@pytest.mark.parametrize("name, cls, meas", CASES)
def test_states_are_independent(name, cls, meas):
    """A later step never writes into an earlier state or info, and mutating a returned array only changes what it should."""
    zs = _measurements(meas)
    filt, _ = _filters(cls, meas)
    s0 = filt.init(pu.Gaussian(X0, COV0))
    s1, i1 = filt.step(s0, zs[0])
    keep = (s1.mean.copy(), s1.cov.copy(), {k: np.array(v, copy=True) for k, v in i1.items()})
    s2, i2 = filt.step(s1, zs[1])
    s2.mean[:] = 1e6  # the caller scribbles on the newest state and info
    i2["innovation"][...] = -1.0
    s3, _ = filt.step(s2, zs[2])  # the lane reuses s2's arrays as they are now
    assert np.array_equal(s1.mean, keep[0]) and np.array_equal(s1.cov, keep[1])
    for key, value in keep[2].items():
        assert np.array_equal(i1[key], value, equal_nan=True), key
    # branching: stepping again from s1 gives the first result, and s3 is what the mutated s2 gives
    again, _ = filt.step(s1, zs[1])
    fresh = pu.filters.GaussianState(mean=np.full(4, 1e6), cov=s2.cov.copy(), k=2)
    s3_ref, _ = filt.step(fresh, zs[2])
    assert not np.shares_memory(again.mean, s2.mean)
    assert np.array_equal(s3.mean, s3_ref.mean) and np.array_equal(s3.cov, s3_ref.cov)
    s2b, _ = filt.step(s1, zs[1])
    assert np.array_equal(s2b.cov, again.cov)


def test_info_mapping():
    filt, _ = _filters(pu.KalmanFilter, LINEAR)
    s, info = filt.step(filt.init(pu.Gaussian(X0, COV0)), np.array([10.0, 40.0]))
    assert isinstance(info, StepInfo)
    assert list(info) == list(INFO_KEYS) and len(info) == len(INFO_KEYS)
    assert "nis" in info and "nope" not in info and info.get("nope") is None
    with pytest.raises(KeyError):
        info["nope"]
    assert info["nis"] is info["nis"]  # made once
    assert info["dof"].dtype == np.int64 and info["dof"] == 2
    info["extra"] = np.ones(1)  # a caller may add keys, as to the batched step's dict
    del info["cross_cov"]
    assert "extra" in info and "cross_cov" not in info and len(info) == len(INFO_KEYS)
    assert set(dict(info)) == (set(INFO_KEYS) - {"cross_cov"}) | {"extra"}


@pytest.mark.parametrize("name, cls, meas", [CASES[0], CASES[3]])
def test_bad_input_raises_as_numpy(name, cls, meas):
    filt, ref = _filters(cls, meas)
    s, r = filt.init(pu.Gaussian(X0, COV0)), ref.init(pu.Gaussian(X0, COV0))
    for z, kw in [(np.array([np.inf, 1.0]), {}), (np.array([1e200, 1.0]), {}), (np.ones(3), {}), (np.ones((1, 2)), {}),
                  (np.ones(2), {"dt": -1.0}), (np.ones(2), {"dt": float("nan")})]:
        with pytest.raises(ValueError) as got:
            filt.step(s, z, **kw)
        with pytest.raises(ValueError) as want:
            ref.step(r, z, **kw)
        assert str(got.value) == str(want.value)
    # a list or an int array is converted as by the NumPy step
    a, _ = filt.step(s, [60.0, 1.0])
    b, _ = filt.step(s, np.array([60.0, 1.0]))
    assert np.array_equal(a.mean, b.mean)


def test_filter_pickles_after_stepping():
    filt, _ = _filters(pu.UnscentedKalmanFilter, RB)
    s, _ = filt.step(filt.init(pu.Gaussian(X0, COV0)), np.array([60.0, 1.0]))
    copy = pickle.loads(pickle.dumps(filt))
    assert "_online_lane" not in vars(copy)
    a, _ = filt.step(s, np.array([61.0, 1.01]))
    b, info = copy.step(s, np.array([61.0, 1.01]))
    assert isinstance(info, StepInfo)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)


def test_the_step_info_pickles_as_the_numpy_steps_dict():
    """Info sent to another process (multiprocessing, Dask) pickles like the NumPy step's plain dict."""
    filt, ref = _filters(pu.UnscentedKalmanFilter, RB)
    z = np.array([60.0, 1.0])
    _, info = filt.step(filt.init(pu.Gaussian(X0, COV0)), z)
    _, want = ref.step(ref.init(pu.Gaussian(X0, COV0)), z)
    info["extra"] = 1.0  # a caller's own key travels too
    got = pickle.loads(pickle.dumps(info))
    assert type(got) is dict and list(got) == list(want) + ["extra"]
    for key in want:
        np.testing.assert_allclose(np.broadcast_to(got[key], np.shape(want[key])), want[key], rtol=1e-9, atol=1e-12)


# -- the scalar one-run EKF and UKF/CKF kernels (pursuit._compiled.one_run_kernels) -----------------------
def _lane_of(filt, z):
    """The online lane of a compiled filter, made by one step."""
    filt.step(filt.init(pu.Gaussian(X0, COV0)), z)
    return vars(filt)["_online_lane"]


SCALAR_SENSORS = [
    ("range-bearing, bearings wrap", RangeBearing(np.array([0.0, 0.0]), 1.0, 0.02), np.array([-50.0, 1.0, 0.3, 0.5])),
    ("one range (m = 1)", RangeSensors(np.array([[0.0, 0.0]]), 2.0), X0),
    ("three ranges (m = 3, S inverted through its Cholesky factor)", RangeSensors(np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]), 2.0), X0),
]


@pytest.mark.parametrize("cls", [pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter])
@pytest.mark.parametrize("label, meas, centre", SCALAR_SENSORS, ids=[s[0] for s in SCALAR_SENSORS])
@pytest.mark.parametrize("fading", [1.0, 1.05])
def test_scalar_kernels_give_the_block_kernels_bits(cls, label, meas, centre, fading):
    """The lane's scalar kernel against the serial block kernel on one lane, the same arguments: the same bits."""
    from pursuit._compiled import gauss_kernels as GK
    from pursuit._compiled import one_run_kernels as OS

    filt = cls(MOTION, meas, backend="numba", fading=fading)
    m = meas.dim
    rng = np.random.default_rng(11)
    lane = _lane_of(filt, meas.sample(centre, 1, rng))
    packed = lane.model(None)
    sigma = cls is not pu.ExtendedKalmanFilter
    scalar, block = (OS.sigma_one_scalar, GK.sigma_one) if sigma else (OS.ekf_one_scalar, GK.ekf_one)
    assert lane.kernel is scalar
    missing = [np.zeros(m, bool), np.ones(m, bool)] + ([np.arange(m) == 0] if m > 1 else [])
    for trial in range(60):
        x = centre + rng.normal(0.0, 2.0, 4)
        A = rng.normal(0.0, 1.0, (4, 4))
        P = A @ A.T + np.diag(rng.uniform(0.1, 3.0, 4))
        z = meas.sample(x, 1, rng)
        z[missing[trial % len(missing)]] = np.nan
        a, b = np.empty(lane.size), np.empty(lane.size)
        assert scalar(x, P, z, *packed, a) == block(x, P, z, *packed, b) == 0
        assert np.array_equal(a, b, equal_nan=True), (trial, np.flatnonzero(~((a == b) | (np.isnan(a) & np.isnan(b)))))
    # a covariance that does not factor is flagged alike (the lane then hands the step to the batched path)
    a, b = np.empty(lane.size), np.empty(lane.size)
    bad_P = -np.eye(4)
    # and said by the return code (the lane's fast path reads no row for it)
    assert scalar(centre, bad_P, z, *packed, a) == block(centre, bad_P, z, *packed, b) == 2
    ok_row = lane.rows["ok"][0]
    assert a[ok_row] == b[ok_row] == 0.0
    # an infinite measurement is refused by both
    z_inf = np.full(m, np.inf)
    assert scalar(centre, COV0, z_inf, *packed, a) == block(centre, COV0, z_inf, *packed, b) == 1


@pytest.mark.parametrize("name, cls, meas", [CASES[0], CASES[3]])
@pytest.mark.parametrize("batch", [(), (1,)])
def test_read_only_measurements_take_the_lane(name, cls, meas, batch):
    """A read-only z (np.broadcast_to's view, as benchmarks/bench_online.py passes it) steps as a writable copy does."""
    zs = _measurements(meas)
    filt, _ = _filters(cls, meas)
    writable = _steps(filt, zs, batch, [None] * T)
    s = filt.init(pu.Gaussian(X0, COV0), batch=batch)
    for k in range(T):
        z = np.broadcast_to(zs[k], batch + zs[k].shape)
        assert not z.flags.writeable
        s, info = filt.step(s, z)
        assert isinstance(info, StepInfo)
        w, winfo = writable[k]
        assert np.array_equal(s.mean, w.mean) and np.array_equal(s.cov, w.cov)
        for key in INFO_KEYS:
            assert np.array_equal(info[key], winfo[key], equal_nan=True), key


def test_the_fast_path_equals_the_general_path():
    """The chained step (the lane's fast path) and a step through its general path (``k`` given) agree bit for bit."""
    zs = _measurements(LINEAR)
    filt, _ = _filters(pu.KalmanFilter, LINEAR)
    fast = _steps(filt, zs, (), [None] * T)
    s = filt.init(pu.Gaussian(X0, COV0))
    for k in range(T):
        s, info = filt.step(s, zs[k], k=k + 1)
        assert np.array_equal(s.mean, fast[k][0].mean) and np.array_equal(s.cov, fast[k][0].cov)
        assert s.k == fast[k][0].k == k + 1
        for key in INFO_KEYS:
            assert np.array_equal(info[key], fast[k][1][key], equal_nan=True), key


@pytest.mark.parametrize("cls", [pu.KalmanFilter, pu.UnscentedKalmanFilter])
@pytest.mark.parametrize("batch", [(), (1,)])
@pytest.mark.parametrize("gate", [None, 0.99])
def test_a_covariance_that_does_not_factor_on_the_fast_path_goes_to_the_batched_step(cls, batch, gate):
    """A chained state whose covariance was overwritten in place (not positive definite): the kernel says so by its
    return code and the batched step takes the step (the UKF's repair), as on the general path and as the NumPy step."""
    bad = np.diag([1.0, -2.0, 1.0, 1.0])  # the predicted covariance does not factor either
    filt, ref = _filters(cls, LINEAR, gate=gate)
    z1, z2 = np.array([10.0, 40.0]).reshape(batch + (2,)), np.array([11.0, 40.5]).reshape(batch + (2,))
    if cls is pu.KalmanFilter:  # the generated kernel: a covariance whose innovation covariance does not factor
        bad = np.diag([-5.0, 0.5, 1.0, 0.5])
    s, _ = filt.step(filt.init(pu.Gaussian(X0, COV0), batch=batch), z1)
    s.cov[...] = bad
    fast, fast_info = filt.step(s, z2)  # s is the lane's last state: the fast path
    general, general_info = filt.step(s, z2, k=2)
    mean, cov = s.mean.copy(), np.broadcast_to(bad, s.cov.shape).copy()
    want, want_info = ref.step(pu.filters.GaussianState(mean=mean, cov=cov, k=1), z2)
    assert not isinstance(fast_info, StepInfo)  # the batched step's info: the lane handed the step over
    assert bool(np.all(fast_info["repaired"])) == bool(np.all(want_info["repaired"])) == (cls is pu.UnscentedKalmanFilter)
    assert np.array_equal(fast_info["gated"], want_info["gated"])
    assert np.array_equal(fast.mean, general.mean) and np.array_equal(fast.cov, general.cov)
    np.testing.assert_allclose(fast.mean, want.mean, rtol=1e-9)
    np.testing.assert_allclose(fast.cov, want.cov, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name, cls, meas", [CASES[0], CASES[3]])
def test_the_lanes_step_becomes_the_filters_own(name, cls, meas):
    """After the first step, ``filt.step`` is the lane's step (one frame per call) with the class step's name,
    docstring and signature; copies and pickles leave it out and make their own; a subclass's step is untouched."""
    filt, ref = _filters(cls, meas)
    z = _measurements(meas)[0]
    assert "step" not in vars(filt)
    s, _ = filt.step(filt.init(pu.Gaussian(X0, COV0)), z)
    assert "step" in vars(filt)
    assert filt.step.__doc__ == cls.step.__doc__ and filt.step.__name__ == "step"
    assert inspect.signature(filt.step) == inspect.signature(ref.step)
    a, _ = filt.step(s, z, 2, None)  # positional k and dt, as the class step takes them
    b, _ = ref.step(s, z, k=2)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-9)
    assert inspect.ismethod(filt.step) and filt.step.__self__ is filt
    for other in (copy.copy(filt), copy.deepcopy(filt), pickle.loads(pickle.dumps(filt))):
        assert "step" not in vars(other) and "_online_lane" not in vars(other)
        c, _ = other.step(s, z, k=2)
        assert np.array_equal(c.mean, a.mean) and "step" in vars(other)
    # the bound step pickles as a method does, by name: the class step of the unpickled filter
    unpickled = pickle.loads(pickle.dumps(filt.step))
    assert "step" not in vars(unpickled.__self__)
    c, _ = unpickled(s, z, k=2)
    assert np.array_equal(c.mean, a.mean)
    # no cycle through the lane: a dropped filter is freed by the cyclic collector
    gone = weakref.ref(filt)
    del filt, other, unpickled
    gc.collect()
    assert gone() is None

    class Own(cls):
        def step(self, state, z, k=None, dt=None):
            return super().step(state, z, k, dt)

    own = Own(MOTION, meas, backend="numba")
    c, _ = own.step(own.init(pu.Gaussian(X0, COV0)), z)
    assert "step" not in vars(own) and np.array_equal(c.mean, s.mean)


@pytest.mark.parametrize("batch", [(), (1,)])
def test_a_bad_measurement_on_the_fast_path_raises_as_on_the_general_path(batch):
    """An infinite or huge z in a chained step (the fast path) raises the general path's error, naming the step."""
    filt, _ = _filters(pu.UnscentedKalmanFilter, RB)
    s, _ = filt.step(filt.init(pu.Gaussian(X0, COV0), batch=batch), np.array([60.0, 1.0]).reshape(batch + (2,)))
    for bad in (np.array([np.inf, 1.0]), np.array([60.0, 1e200])):
        z = bad.reshape(batch + (2,))
        with pytest.raises(ValueError) as fast:
            filt.step(s, z)
        with pytest.raises(ValueError) as general:
            filt.step(s, z, k=2)
        assert str(fast.value) == str(general.value) and "step 2" in str(fast.value)
    s2, info = filt.step(s, np.array([61.0, 1.01]).reshape(batch + (2,)))  # the lane goes on from s
    assert isinstance(info, StepInfo) and s2.k == 2


@pytest.mark.parametrize("name, cls, meas", [CASES[0], CASES[3]])
@pytest.mark.parametrize("batch", [(), (1,)])
def test_the_lanes_states_are_ordinary_states(name, cls, meas, batch):
    """The lane builds its states without the constructor (trusted arrays): they behave as constructed ones.

    Same type and fields in the same order, the general path's array flags,
    equal repr and fields to a state made by ``GaussianState(...)``, frozen,
    and a pickle round trip that gives the same arrays.
    """
    import dataclasses

    zs = _measurements(meas)
    filt, _ = _filters(cls, meas)
    s = filt.init(pu.Gaussian(X0, COV0), batch=batch)
    for k in range(4):
        s_fast, _ = filt.step(s, zs[k].reshape(batch + zs[k].shape))  # chained from the second step: the fast path
        s_general, _ = filt.step(s, zs[k].reshape(batch + zs[k].shape), k=s.k + 1)  # k given: the general path
        s = s_fast
    built = pu.filters.GaussianState(mean=s.mean, cov=s.cov, k=s.k, memory=None)
    for got in (s, s_general):
        assert type(got) is pu.filters.GaussianState
        assert list(vars(got)) == [f.name for f in dataclasses.fields(built)]
        assert repr(got) == repr(pu.filters.GaussianState(mean=got.mean, cov=got.cov, k=got.k, memory=None))
        assert got.k == 4 and got.memory is None and got.batch == batch
        assert got.mean.shape == batch + (4,) and got.cov.shape == batch + (4, 4)
        assert got.mean.dtype == got.cov.dtype == np.float64
        with pytest.raises(dataclasses.FrozenInstanceError):
            got.k = 5
        back = pickle.loads(pickle.dumps(got))
        assert type(back) is type(got) and back.k == got.k and back.memory is None
        assert np.array_equal(back.mean, got.mean) and np.array_equal(back.cov, got.cov)
    assert np.array_equal(s.mean, s_general.mean) and np.array_equal(s.cov, s_general.cov)
    for a, b in [(s.mean, s_general.mean), (s.cov, s_general.cov)]:
        assert a.flags.writeable == b.flags.writeable and a.flags.c_contiguous == b.flags.c_contiguous
        assert a.strides == b.strides
    assert repr(s) == repr(s_general) and repr(s) == repr(built)


@pytest.mark.parametrize("name, cls, meas", [CASES[0], CASES[3]])
@pytest.mark.parametrize("batch", [(), (1,), (3,)])
def test_a_state_of_the_wrong_size_is_refused(name, cls, meas, batch):
    """A state whose size is not the model's raises a clear error (the compiled kernels would read past its arrays)."""
    filt, ref = _filters(cls, meas)
    z = np.array([60.0, 1.0])
    for n in (3, 5):
        state = pu.filters.GaussianState(mean=np.zeros(batch + (n,)), cov=np.broadcast_to(np.eye(n), batch + (n, n)))
        with pytest.raises(ValueError, match=rf"state: the filter's model has 4 states, got mean \({', '.join(map(str, batch + (n,)))},?\)"):
            filt.step(state, z)
        with pytest.raises(ValueError):  # NumPy's own matrix product refuses it too
            ref.step(state, z)
    state = pu.filters.GaussianState(mean=np.zeros(batch + (4,)), cov=np.broadcast_to(np.eye(3), batch + (3, 3)))
    with pytest.raises(ValueError, match="state: the filter's model has 4 states"):
        filt.step(state, z)
    good, _ = filt.step(filt.init(pu.Gaussian(X0, COV0), batch=batch), z)  # and the lane goes on as before
    assert good.mean.shape == batch + (4,)


def test_two_threads_stepping_one_filter_each_get_their_own_runs():
    """One filter stepped from two threads, a run each: every step equals the run stepped alone (the lane reads what
    it keeps of the last step as one tuple, never one run's state with the other's arrays)."""
    import sys
    import threading

    filt, _ = _filters(pu.KalmanFilter, LINEAR)
    steps = 400
    rng = np.random.default_rng(4)
    zs = [rng.normal([10.0, 40.0], 5.0, (steps, 2)), rng.normal([-300.0, 900.0], 5.0, (steps, 2))]
    alone = []
    for run in range(2):
        ref, _ = _filters(pu.KalmanFilter, LINEAR)
        s = ref.init(pu.Gaussian(X0, COV0))
        means = []
        for z in zs[run]:
            s, _ = ref.step(s, z)
            means.append(s.mean)
        alone.append(np.array(means))
    got = [None, None]
    start = threading.Barrier(2)

    def track(run):
        s = filt.init(pu.Gaussian(X0, COV0))
        means = []
        start.wait()
        for z in zs[run]:
            s, _ = filt.step(s, z)
            means.append(s.mean)
        got[run] = np.array(means)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as the interpreter can
    try:
        for _ in range(5):
            threads = [threading.Thread(target=track, args=(run,)) for run in range(2)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            for run in range(2):
                assert np.array_equal(got[run], alone[run]), run
    finally:
        sys.setswitchinterval(interval)
