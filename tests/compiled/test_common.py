"""Shared compiled helpers (pursuit._compiled.common): the vectorisable exp and log, and the serial/parallel builds."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from pursuit._compiled import cuckoo_kernels, gauss_kernels, pf_kernels  # noqa: E402
from pursuit._compiled.common import exp_weight, log_positive, serial_and_parallel  # noqa: E402


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
