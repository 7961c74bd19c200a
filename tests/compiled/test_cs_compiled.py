"""The compiled path of the CS-model filter for nonlinear measurements and of the moving observer's angles.

``NonlinearCSFilter(backend="numba")`` runs its two measurement updates (the
nominal one of the residual test, the final one) in the compiled EKF/UKF
update kernels, with :class:`~pursuit.models.sensors.ObserverBearings` packed
for each step; the Kalman-family filters run the moving observer too.  The
two backends differ in the order of summation and in atan2/hypot (libm in
the kernels, NumPy's own SIMD code on AVX-512), so they are compared step by
step from the same state to a relative ``RTOL`` of each array's largest
entry per run (observed: about 1e-10 at most, on the innovations of the
UKF, which are differences of nearly equal angles).  Over whole bearings-only
runs the tiny differences grow (the range is weakly observable), so runs are
compared only backend against itself: batch against one run at a time and
``pursuit.run`` against stepping, bit for bit.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit.compute import CompiledBackendWarning  # noqa: E402
from pursuit.filters import NonlinearCSFilter  # noqa: E402
from pursuit.models import ConstantVelocity  # noqa: E402
from pursuit.models.sensors import ObserverBearings  # noqa: E402
from pursuit.scenarios.bearings import BearingsOnlyTarget  # noqa: E402

RTOL = 1e-8
RUNS = 6
ADAPTATIONS = {  # the options the adaptation reads, each once
    "none": dict(adaptation="none"),
    "apcs": dict(adaptation="apcs", fading="stf", alpha_rule="fading"),
    "limit": dict(adaptation="limit", fading="ratio", gate=0.999),
}


def _data(dims: int, runs: int = RUNS, horizon: int = 60):
    sc = BearingsOnlyTarget(dims=dims, horizon=horizon)
    sim = sc.simulate(np.random.default_rng(7 + dims), runs=runs)
    zs = np.array(sim.measurements)
    zs[5, 1, 0] = np.nan  # one missing angle
    zs[9] = np.nan  # a step with nothing measured
    return sc, zs, sim.prior


def _make(sc, update: str, adaptation: str, backend: str) -> NonlinearCSFilter:
    # a_max and alpha0 small enough that the strong maneuvers fire the residual test
    return NonlinearCSFilter(sc.measurement, dt=sc.dt, update=update, alpha0=0.05, a_max=2.0, backend=backend, **ADAPTATIONS[adaptation])


def _close(a, b, what: str) -> None:
    """|a − b| ≤ RTOL · (largest |a| of the run), NaN where NaN (a NumPy KF's shared covariance broadcast)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.ndim < b.ndim:
        a = np.broadcast_to(a, b.shape)
    assert a.shape == b.shape, what
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{what}: NaN pattern differs"
    a0, b0 = np.nan_to_num(a), np.nan_to_num(b)
    axes = tuple(range(1, a.ndim))
    scale = np.max(np.abs(a0), axis=axes, keepdims=True) if axes else np.abs(a0)
    err = np.max(np.abs(a0 - b0) / np.where(scale > 0, scale, 1.0))
    assert err <= RTOL, f"{what}: relative difference {err:.3g}"


def _compare_steps(make, zs, prior, batch):
    """Step both backends from the NumPy filter's state at every step; returns how many steps detected a maneuver."""
    fn, fc = make("numpy"), make("numba")
    assert fc.compiled and not fn.compiled
    state = fn.init(prior, batch=batch)
    detected = 0
    for k in range(zs.shape[0]):
        a, ia = fn.step(state, zs[k], k + 1)
        b, ib = fc.step(state, zs[k], k + 1)
        _close(a.mean, b.mean, f"mean, step {k + 1}")
        _close(a.cov, b.cov, f"cov, step {k + 1}")
        assert sorted(ia) == sorted(ib)
        for key in ia:
            _close(ia[key], ib[key], f"{key}, step {k + 1}")
        detected += int(np.any(ia.get("maneuver", False)))
        state = a
    return detected


@pytest.mark.parametrize("adaptation", sorted(ADAPTATIONS))
@pytest.mark.parametrize("update", ["ekf", "ukf"])
@pytest.mark.parametrize("dims", [2, 3])
def test_compiled_step_equals_numpy_step(dims, update, adaptation):
    sc, zs, prior = _data(dims)
    detected = _compare_steps(lambda be: _make(sc, update, adaptation, be), zs, prior, (RUNS,))
    if adaptation != "none":
        assert detected > 0  # the adapted branch (λ, α, a_max) was compared too


def test_moving_observer_in_the_kalman_filters_equals_numpy():
    """EKF and UKF with ObserverBearings (a CV state, 2-D) compile, and agree with NumPy step by step."""
    T = 30
    t = np.arange(1, T + 1)
    track = np.column_stack([200.0 * np.sin(t / 5.0), 30.0 * t])
    sensor = ObserverBearings(track, 2e-3, position_indices=(0, 2))
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.5)
    rng = np.random.default_rng(3)
    x = np.tile([3000.0, -5.0, 4000.0, 20.0], (RUNS, 1))
    zs = np.empty((T, RUNS, 1))
    for k in range(T):
        x = motion.sample(x, k + 1, rng)
        zs[k] = sensor.sample(x, k + 1, rng)
    zs[4, 2] = np.nan
    prior = pu.Gaussian(np.array([2900.0, 0.0, 4100.0, 15.0]), np.diag([1e4, 25.0, 1e4, 25.0]))
    for cls in (pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter):
        _compare_steps(lambda be: cls(motion, sensor, backend=be), zs, prior, (RUNS,))


@pytest.mark.parametrize("update", ["ekf", "ukf"])
@pytest.mark.parametrize("dims", [2, 3])
def test_batch_equals_one_run_at_a_time_bit_for_bit(dims, update):
    sc, zs, prior = _data(dims, horizon=40)
    filt = _make(sc, update, "limit", "numba")
    batch = pu.run(filt, zs, prior)
    for r in range(RUNS):
        alone = pu.run(filt, zs[:, r], pu.Gaussian(prior.mean[r], prior.cov))
        np.testing.assert_array_equal(alone.mean, batch.mean[:, r])
        np.testing.assert_array_equal(alone.cov, batch.cov[:, r])
        for key in batch.info:
            np.testing.assert_array_equal(alone.info[key], batch.info[key][:, r], err_msg=key)


def test_run_equals_stepping():
    sc, zs, prior = _data(3, horizon=40)
    filt = _make(sc, "ukf", "apcs", "numba")
    track = pu.run(filt, zs, prior)
    state = filt.init(prior, batch=(RUNS,))
    for k in range(zs.shape[0]):
        state, info = filt.step(state, zs[k])
        np.testing.assert_array_equal(track.mean[k], state.mean)
        np.testing.assert_array_equal(track.cov[k], state.cov)
        for key in set(track.info) & set(info):  # the track adds its own (diverged); the smoother's are not kept
            np.testing.assert_array_equal(track.info[key][k], info[key], err_msg=key)


def test_compiled_without_a_warning_and_the_others_still_warn():
    sc = BearingsOnlyTarget(dims=2, horizon=20)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for update in ("ekf", "ukf"):
            assert NonlinearCSFilter(sc.measurement, update=update, backend="numba").compiled
        cv, angles = ConstantVelocity(ndim=2, dt=1.0, q=0.1), ObserverBearings(np.zeros((5, 2)), 1e-3, position_indices=(0, 2))
        assert pu.UnscentedKalmanFilter(cv, angles, backend="numba").compiled
    # the particle filters' glue packs the sensor once, not per step: they refuse a moving observer by name
    with pytest.warns(CompiledBackendWarning, match="ObserverBearings.*moving observer"):
        pf = pu.BootstrapParticleFilter(cv, angles, particles=10, backend="numba")
    assert not pf.compiled


@pytest.mark.parametrize("update", ["ekf", "ukf"])
def test_the_compiled_step_checks_the_state_size_against_the_axes(update):
    """The nonlinear CS filter has no motion model: its state is 3 x axes (6 for bearings in 2-D), which a
    compiled step accepts and a 5-component state is refused with a clear error (the kernels trust shapes)."""
    import dataclasses

    sc = BearingsOnlyTarget(dims=2)
    filt = NonlinearCSFilter(sc.measurement, update=update, backend="numba")
    assert filt.compiled and filt.axes == 2
    state = filt.init(pu.Gaussian(np.array([1000.0, 5.0, 0.0, 2000.0, -3.0, 0.0]), np.eye(6) * 100.0), batch=(2,))
    z = np.full((2, 1), 0.5)
    good, _ = filt.step(state, z)
    assert good.mean.shape == (2, 6)
    cut = dataclasses.replace(state, mean=state.mean[..., :5], cov=state.cov[..., :5, :5])
    with pytest.raises(ValueError, match=r"state: the filter's model has 6 states, got mean \(2, 5\), cov \(2, 5, 5\)"):
        filt.step(cut, z)
