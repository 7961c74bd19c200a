"""The batched fitness and the Metropolis test of the compiled cuckoo kernels (pursuit._compiled.cuckoo_kernels).

The MH kernel measures a half's proposals as one batch (``_fitness_rows``,
one loop per sensor kind in ``_h_rows``) instead of one ``h_row`` call per
particle; it must give the same bits as the per-particle dispatcher for every
registered sensor, including a code without its loop (through ``h_point``).
Both backends write the Metropolis test ``log u < Δ`` as
``u − 1 < Δ or log u < Δ``; that is the same decision for NumPy's log on
this CPU.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from numba import njit  # noqa: E402

from pursuit._compiled import cuckoo_kernels as CK  # noqa: E402
from pursuit._compiled import specs  # noqa: E402
from pursuit._compiled.common import LOG_2PI, wrap  # noqa: E402
from pursuit._compiled.model_math import h_row  # noqa: E402

from .test_model_math import SENSORS  # noqa: E402


@njit(cache=True)
def _h_each(sensor, X, out):
    for i in range(X.shape[0]):
        h_row(sensor, X, i, out, i)


def _reference_fitness(sensor, H, z, valid, full):
    """The per-particle fitness as the kernel formed it before the batching: −½/R_jj and the log-constant in the loop."""
    F = np.zeros(H.shape[0])
    R = sensor.R
    for i in range(H.shape[0]):
        acc = 0.0
        for j in range(z.size):
            if valid[j]:
                r = z[j] - H[i, j]
                if sensor.angle and j == 1:
                    r = wrap(r)
                acc += r * r / R[j, j] + (math.log(R[j, j]) + LOG_2PI) if full else r * r * (-0.5 / R[j, j])
        F[i] = -0.5 * acc if full else acc
    return F


def _packed(model):
    """The sensor as the kernels get it (a moving observer's at step 1)."""
    spec = specs.measurement_spec(model)
    return spec.kernel_args(1 if spec.moving else None)


@pytest.mark.parametrize("cls", sorted(SENSORS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@pytest.mark.parametrize("full", [False, True], ids=["fast", "full"])
def test_batched_fitness_is_the_per_particle_dispatcher_bit_for_bit(cls, full):
    model, n = SENSORS[cls]
    sensor = _packed(model)
    rng = np.random.default_rng(3)
    X = rng.normal(20.0, 15.0, (40, n))
    H_ref = np.empty((40, model.dim))
    _h_each(sensor, X, H_ref)
    H = np.full((40, model.dim), np.nan)
    CK._h_rows(sensor, X, 5, 40, H)
    assert np.isnan(H[:5]).all(), "rows outside [i0, i1) are left alone"
    assert np.array_equal(H[5:], H_ref[5:])
    z = H_ref[0] + rng.normal(0.0, 1.0, model.dim)
    valid = np.ones(model.dim, dtype=bool)
    if model.dim > 1:
        valid[0] = False  # a missing component
    F = np.full(40, np.nan)
    CK._fitness_rows(sensor, X, 0, 40, z, valid, True, full, CK._fit_consts(sensor.R, full), np.empty((40, model.dim)), F)
    assert np.array_equal(F, _reference_fitness(sensor, H_ref, z, valid, full))
    CK._fitness_rows(sensor, X, 0, 40, z, valid, False, full, CK._fit_consts(sensor.R, full), np.empty((40, model.dim)), F)
    assert np.array_equal(F, np.zeros(40)), "nothing measured: fitness 0"


def test_a_sensor_code_without_its_loop_goes_through_the_dispatcher():
    model, n = next(iter(SENSORS.values()))
    sensor = _packed(model)
    codes = [v for name, v in vars(specs).items() if name.startswith("M_") and isinstance(v, int)]
    unknown = sensor._replace(kind=max(codes) + 1)  # a code no sensor has: the dispatcher's NaN
    H = np.zeros((3, model.dim))
    CK._h_rows(unknown, np.ones((3, n)), 0, 3, H)
    assert np.isnan(H).all()


def test_the_metropolis_bound_takes_the_log_tests_decision():
    """``u − 1 < Δ or log u < Δ`` equals ``log u < Δ`` with NumPy's log, on the edges where the bound could matter."""
    rng = np.random.default_rng(11)
    k = rng.integers(0, 2**53, 200_000, dtype=np.int64)
    k[:6] = [0, 1, 2**52, 2**53 - 1, 2**53 - 2, 2**52 + 1]
    u = k * 2.0**-53  # NumPy's uniforms: multiples of 2^-53 in [0, 1)
    with np.errstate(divide="ignore"):
        lu = np.log(u)
    # Δ just around u − 1 and log u, where a log above the bound would flip a decision; and spread
    d = np.concatenate([u - 1.0, np.nextafter(u - 1.0, 1.0), np.nextafter(u - 1.0, -1.0), lu,
                        np.nextafter(lu, np.inf), rng.normal(0.0, 2.0, u.size), [np.nan, np.inf, -np.inf] * (u.size // 3)
                        + [0.0] * (u.size % 3)])
    uu = np.tile(u, 7)
    with np.errstate(divide="ignore"):
        exact = np.log(uu) < d
        bounded = (uu - 1.0 < d) | (np.log(uu) < d)
    assert np.array_equal(exact, bounded)
    assert np.all(lu[1:] <= u[1:] - 1.0), "NumPy's log stays below u − 1 (faithful rounding)"
