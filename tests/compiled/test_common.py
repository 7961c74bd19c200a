"""Shared compiled helpers (pursuit._compiled.common): the vectorisable exp, log, atan2, hypot and wrap, and the serial/parallel builds."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from pursuit._compiled import cuckoo_kernels, gauss_kernels, pf_kernels  # noqa: E402
from pursuit._compiled.common import (  # noqa: E402
    atan2_lanes, exp_weight, hypot_lanes, log_positive, serial_and_parallel, wrap, wrap_inside)


def _elementwise(scalar):
    """A compiled loop ``out[i] = scalar(a[i])`` (the vectorised context the kernels call these functions in)."""
    from numba import njit

    @njit
    def apply(a, out):
        for i in range(a.shape[0]):
            out[i] = scalar(a[i])

    return apply


def test_log_positive_within_one_ulp_of_libm():
    rng = np.random.default_rng(0)
    random_bits = rng.integers(1, 0x7FEFFFFFFFFFFFFF, 500_000, dtype=np.int64).view(np.float64)  # every exponent, subnormals too
    a = np.concatenate([random_bits, np.exp(rng.uniform(-700, 700, 200_000)), 1.0 + rng.uniform(-1e-3, 1e-3, 100_000),
                        [5e-324, 1e-310, 2.2250738585072014e-308, 0.5, 1.0, 2.0, math.sqrt(2.0),
                         np.nextafter(math.sqrt(2.0), 2.0), 1.7976931348623157e308]])
    out = np.empty_like(a)
    _elementwise(log_positive)(a, out)
    ref = np.log(a)
    assert out[np.flatnonzero(a == 1.0)[0]] == 0.0
    ulps = np.abs(out - ref) / np.spacing(np.abs(ref)).clip(min=5e-324)
    assert ulps.max() <= 1.0


def test_exp_weight_within_one_ulp_of_libm():
    rng = np.random.default_rng(0)
    a = np.concatenate([-rng.exponential(5, 200_000), -rng.uniform(0, 708, 200_000), rng.uniform(-1e-3, 12, 10_000),
                        [0.0, -1e-300, -707.9, -708.0, -708.1, -np.inf, np.nan]])
    out = np.empty_like(a)
    _elementwise(exp_weight)(a, out)
    with np.errstate(all="ignore"):
        ref = np.where(a > -708.0, np.exp(a), 0.0)
    pos = ref > 0
    assert np.array_equal(out > 0, pos)  # the floor at -708 (and -inf, NaN) gives exactly 0
    assert np.max(np.abs(out[pos] - ref[pos]) / np.spacing(ref[pos])) <= 1.0


def _elementwise_pair(scalar):
    """A compiled loop ``out[i], flag[i] = scalar(a[i], b[i])`` (numpy error model, as the kernels)."""
    from numba import njit

    @njit(error_model="numpy")
    def apply(a, b, out, flag):
        for i in range(a.shape[0]):
            out[i], flag[i] = scalar(a[i], b[i])

    return apply


def _ulps(got, ref):
    return np.abs(got - ref) / np.spacing(np.abs(ref)).clip(min=5e-324)


def _offsets(rng, N):
    """Offsets of every sign at scales from 1e-13 to 1e13, and of the size a tracking sensor sees."""
    wide = rng.standard_normal((2, N)) * np.exp(rng.uniform(-30, 30, (2, N)))
    local = rng.uniform(-300.0, 300.0, (2, N))
    axes = np.array([[0.0, 1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 3.0, -2.5],
                     [1.0, 0.0, 0.0, -1.0, 1.0, 1.0, -1.0, 7.5, 1e-200]])  # (first, second) = (y, x): axes, diagonals, a tiny x
    return np.concatenate([wide, local, axes], axis=1)


def test_atan2_lanes_within_one_ulp_of_libm():
    y, x = _offsets(np.random.default_rng(3), 400_000)
    out, exact = np.empty_like(x), np.empty(x.shape, dtype=bool)
    _elementwise_pair(atan2_lanes)(y, x, out, exact)
    ref = np.array([math.atan2(b, a) for a, b in zip(x, y)])
    assert exact[:-9].all()
    # x = 0 and an x of 1e-200 are outside the range it takes (libm's values then)
    assert exact[-9:].tolist() == [True, False, False, True, True, True, True, True, False]
    assert _ulps(out[exact], ref[exact]).max() <= 1.0
    assert out[exact][np.flatnonzero(ref[exact] == 0.0)].size > 0  # y = 0 on the positive x axis
    assert np.array_equal(np.signbit(out[exact]), np.signbit(ref[exact]))


def test_atan2_lanes_hands_special_arguments_to_libm_and_keeps_signed_zeros():
    values = [0.0, -0.0, 1.0, -1.0, 5e-324, 1e-160, 2.0 ** 501, np.inf, -np.inf, np.nan]
    y, x = (a.ravel() for a in np.meshgrid(values, values))
    out, exact = np.empty_like(x), np.empty(x.shape, dtype=bool)
    _elementwise_pair(atan2_lanes)(y, x, out, exact)
    for a, b, got, ok in zip(x, y, out, exact):
        finite_normal = 2.0 ** -500 <= abs(a) <= 2.0 ** 500 and (b == 0.0 or 2.0 ** -500 <= abs(b) <= 2.0 ** 500)
        assert ok == finite_normal, (b, a)
        if ok:  # ±0 against ±1: ±0 or ±π, with libm's signs
            ref = math.atan2(b, a)
            assert got == ref and math.copysign(1.0, got) == math.copysign(1.0, ref), (b, a)


def test_hypot_lanes_within_one_ulp_of_libm():
    y, x = _offsets(np.random.default_rng(4), 400_000)
    out, exact = np.empty_like(x), np.empty(x.shape, dtype=bool)
    _elementwise_pair(hypot_lanes)(x, y, out, exact)
    ref = np.hypot(x, y)
    assert exact.all()
    assert _ulps(out, ref).max() <= 1.0
    specials = np.array([0.0, 1e-160, 1e160, np.inf, np.nan])
    _elementwise_pair(hypot_lanes)(specials, np.zeros(5), out[:5], exact[:5])
    assert not exact[:5].any()  # zero, underflow, overflow, inf, NaN: libm's hypot then


def test_wrap_inside_is_wrap_where_it_says_inside():
    a = np.concatenate([np.random.default_rng(5).uniform(-12.0, 12.0, 100_000),
                        [-math.pi, math.pi, np.nextafter(math.pi, 0.0), np.nextafter(-math.pi, 0.0), 0.0, -0.0, np.inf, np.nan]])
    out, inside = np.empty_like(a), np.empty(a.shape, dtype=bool)
    from numba import njit

    @njit(error_model="numpy")
    def apply(v, o, f, exact):
        for i in range(v.shape[0]):
            o[i], f[i] = wrap_inside(v[i])
            exact[i] = wrap(v[i])

    ref = np.empty_like(a)
    apply(a, out, inside, ref)
    expect_inside = (a + math.pi >= 0.0) & (a + math.pi < 2.0 * math.pi)
    assert np.array_equal(inside, expect_inside)
    assert 0 < inside.sum() < a.size
    assert np.array_equal(out[inside], ref[inside])
    assert not inside[a == math.pi].any()  # π itself wraps to −π: outside


@pytest.mark.parametrize("serial, parallel", [
    (gauss_kernels.ekf_step_serial, gauss_kernels.ekf_step_parallel),
    (gauss_kernels.ekf_sequence_serial, gauss_kernels.ekf_sequence_parallel),
    (gauss_kernels.sigma_step_serial, gauss_kernels.sigma_step_parallel),
    (pf_kernels.pf_step_serial, pf_kernels.pf_step_parallel),
    (pf_kernels.pf_sequence_serial, pf_kernels.pf_sequence_parallel),
    (cuckoo_kernels.cuckoo_step_serial, cuckoo_kernels.cuckoo_step_parallel),
], ids=["ekf_step", "ekf_sequence", "sigma_step", "pf_step", "pf_sequence", "cuckoo_step"])
def test_serial_and_parallel_builds_have_their_own_cache_entries(serial, parallel):
    """numba files cached code by function name and line, not by ``parallel=``: one shared entry would
    make a warm cache hand the parallel kernel the serial machine code (or the reverse)."""
    assert serial.targetoptions.get("parallel") in (None, False)
    assert parallel.targetoptions.get("parallel")
    assert serial._cache._cache_file._index_name != parallel._cache._cache_file._index_name  # numba internals: the .nbi files


def test_serial_and_parallel_compute_the_same():
    def total(a):
        s = 0.0
        for i in range(a.shape[0]):
            s += a[i] * a[i]
        return s

    ser, par = serial_and_parallel(total, cache=False)
    a = np.arange(10.0)
    assert ser(a) == par(a) == 285.0
    assert par.py_func.__qualname__.endswith("__parallel")
