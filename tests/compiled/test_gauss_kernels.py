"""The UKF/CKF block kernels' measurement loops (pursuit._compiled.gauss_kernels) without libm calls.

The sigma points' range and bearing go through ``range_bearing_lanes`` in
one vectorised loop, and an angle's differences are wrapped without the
remainder where they are already in [−π, π).  Each has a slow path (libm's
values, ``wrap``) for what the fast one does not take; these tests reach
both and check the fast path gives the slow path's bits where it applies.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from numba import njit  # noqa: E402

import pursuit as pu  # noqa: E402
from pursuit._compiled import gauss_kernels as GK  # noqa: E402
from pursuit._compiled import specs  # noqa: E402
from pursuit._compiled.model_math import h_row, h_sigma_row  # noqa: E402
from pursuit.models import ConstantVelocity, RangeBearing  # noqa: E402

SENSOR_AT = (10.0, -50.0)


def _sensor():
    return specs.measurement_spec(RangeBearing(list(SENSOR_AT), 1.0, 0.02)).kernel_args(None)


@njit(cache=True, error_model="numpy")  # as the kernels: 0/0 is NaN, not an exception
def _rows(sensor, XT, out, sigma):
    for i in range(XT.shape[0]):
        if sigma:
            h_sigma_row(sensor, XT, i, out, i)
        else:
            h_row(sensor, XT, i, out, i)


def test_sigma_block_gives_the_row_functions_bits_and_libm_where_it_must():
    rng = np.random.default_rng(0)
    X = rng.uniform(-300.0, 300.0, (4, 37))
    X[0, 5], X[2, 5] = SENSOR_AT  # a point on the sensor: zero offset, libm's hypot and atan2
    X[0, 9] = 1e300  # an offset beyond the range the lanes take
    X[0, 12] = SENSOR_AT[0]  # due north or south of the sensor: dx = 0, libm's atan2
    sensor = _sensor()
    block = np.empty((2, 37))
    GK._h_sigma_block(sensor, X, block)
    rows, libm = np.empty((37, 2)), np.empty((37, 2))
    _rows(sensor, np.ascontiguousarray(X.T), rows, True)
    _rows(sensor, np.ascontiguousarray(X.T), libm, False)
    assert np.array_equal(block, rows.T)  # the vectorised loop and the one-run kernels' row function agree
    assert np.array_equal(block[:, [5, 9, 12]], libm.T[:, [5, 9, 12]])  # the slow path is libm's, for those runs only
    ulps = np.abs(block - libm.T) / np.spacing(np.abs(libm.T))
    assert ulps.max() <= 1.0 and (ulps > 0).any()  # within 1 ulp, and not libm's bits everywhere


def _angles(straddle: bool):
    """Sigma-point measurements Z (npts=5, m=2, B=3); with ``straddle`` lane 1's bearings lie on both sides of ±π."""
    rng = np.random.default_rng(1)
    Z = np.empty((5, 2, 3))
    Z[:, 0] = rng.uniform(50.0, 60.0, (5, 3))
    Z[:, 1] = rng.uniform(-0.1, 0.1, (5, 3)) + np.array([0.3, 3.1 if straddle else 2.9, -2.0])
    if straddle:
        Z[2, 1, 1] = -3.1  # across the cut from the others
    return Z


@pytest.mark.parametrize("straddle", [False, True])
def test_wrapped_means_and_residuals_equal_the_remainder_loops(straddle):
    Z = _angles(straddle)
    wm = np.array([0.2, 0.3, 0.1, 0.25, 0.15])
    kind = specs.M_RANGE_BEARING
    fast, slow = np.empty((2, 3)), np.empty((2, 3))
    outside = GK._mean_angles_inside(Z, wm, kind, True, fast)
    GK._mean_angles(Z, wm, kind, True, slow)
    assert outside == straddle
    if not straddle:
        assert np.array_equal(fast, slow)
    else:  # the lanes that stayed inside still have the remainder loop's bits
        assert np.array_equal(fast[:, [0, 2]], slow[:, [0, 2]])
    zp = slow + Z[0]
    fast_res, slow_res = np.empty_like(Z), np.empty_like(Z)
    outside = GK._residuals_inside(Z, zp, kind, True, fast_res)
    GK._residuals(Z, zp, kind, True, slow_res)
    assert outside == straddle
    if not straddle:
        assert np.array_equal(fast_res, slow_res)
    assert np.all(np.abs(slow_res[:, 1]) <= math.pi)


@pytest.mark.parametrize("name", ["ukf", "ckf"])
def test_a_target_crossing_the_bearing_cut_agrees_with_numpy(name):
    """A target passing behind the sensor: its sigma points' bearings straddle ±π (the slow paths) for several steps."""
    cls = {"ukf": pu.UnscentedKalmanFilter, "ckf": pu.CubatureKalmanFilter}[name]
    motion, meas = ConstantVelocity(ndim=2, dt=1.0, q=0.01), RangeBearing(list(SENSOR_AT), 1.0, 0.02)
    rng = np.random.default_rng(2)
    T, M = 30, 4
    x = np.tile([SENSOR_AT[0] - 100.0, 0.0, SENSOR_AT[1] - 15.0, 1.0], (M, 1))  # crosses y = sensor's y at step 15, behind it
    zs = np.empty((T, M, 2))
    for k in range(T):
        x = motion.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    assert (np.abs(zs[:, :, 1]) > 3.0).sum() > 10  # bearings near ±π
    prior = pu.Gaussian([SENSOR_AT[0] - 100.0, 0.0, SENSOR_AT[1] - 15.0, 1.0], np.diag([4.0, 0.5, 4.0, 0.5]))
    compiled = pu.run(cls(motion, meas, backend="numba"), zs, prior)
    steps = pu.run(cls(motion, meas, backend="numba"), zs, prior, sequence=False)
    numpy_run = pu.run(cls(motion, meas), zs, prior, store_predictions=True)
    # the update's points, drawn as the kernels draw them from the (NumPy) predictions: the kernel's
    # fast wrap declines them on several step-runs, so its slow path is what this test checks
    cscale, wm, _ = cls(motion, meas).sigma_weights(4)
    centre = wm.shape[0] % 2 == 1
    xp, Pp = numpy_run.info["pred_mean"].reshape(-1, 4), numpy_run.info["pred_cov"].reshape(-1, 4, 4)
    cols = cscale * np.linalg.cholesky(Pp).transpose(0, 2, 1)  # (runs, j, i): column j of the factor
    pts = np.concatenate(([xp[:, None]] if centre else []) + [xp[:, None] + cols, xp[:, None] - cols], axis=1)
    Z = np.ascontiguousarray(meas.h(pts, None).transpose(1, 2, 0))  # (points, m, step-runs)
    declined = 0
    for r in range(Z.shape[2]):
        declined += GK._mean_angles_inside(np.ascontiguousarray(Z[:, :, r:r + 1]), np.ascontiguousarray(wm), specs.M_RANGE_BEARING,
                                           True, np.empty((2, 1)))
    assert declined >= 5
    assert np.array_equal(compiled.mean, steps.mean) and np.array_equal(compiled.cov, steps.cov)
    np.testing.assert_allclose(compiled.mean, numpy_run.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(compiled.info["nis"], numpy_run.info["nis"], rtol=1e-9)
