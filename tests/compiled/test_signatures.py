"""One compiled signature per kernel, whatever the caller: each extra one is another cold compile.

numba compiles a kernel once per distinct argument *type*, and the type of
an array includes its read-only flag (a model's own arrays are read-only, a
freshly built one is not), and the type of a constant passed from inside a
kernel is a ``Literal`` (``0``, ``True``) rather than ``int64``/``bool``.
The test suite's cache once held 2 to 10 signatures of the same kernels
for these reasons (docs/testing.md, "One signature per kernel").  These tests
pin the normalisations that make it one: the packed sensor is read-only
and the packed motion writable whatever the model holds, the Gaussian
filters' lane-major state is writable, and a kernel passes ``int64``/``bool`` values, not
literals, to the kernels it calls.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from pursuit._compiled import cuckoo_kernels as CK  # noqa: E402
from pursuit._compiled import specs  # noqa: E402

from .test_model_math import K_STEP, SENSORS  # noqa: E402


def _packed(spec: specs.MeasurementSpec):
    return spec.kernel_args(K_STEP if spec.moving else None)


def _writable(spec: specs.MeasurementSpec) -> specs.MeasurementSpec:
    """The same spec with writable copies of its arrays (a model whose arrays are not read-only)."""
    return dataclasses.replace(spec, A=spec.A.copy(), idx=spec.idx.astype(np.int32), R=np.asfortranarray(spec.R.copy()))


@pytest.mark.parametrize("cls", sorted(SENSORS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
def test_the_packed_sensor_has_one_numba_type_whatever_the_arrays(cls):
    model, _ = SENSORS[cls]
    spec = specs.measurement_spec(model)
    w = _writable(spec)
    a, b = _packed(spec), _packed(w)
    assert numba.typeof(a) == numba.typeof(b)
    for name in ("A", "idx", "R"):
        arr = getattr(a, name)
        assert not arr.flags.writeable and arr.flags.c_contiguous, name
        assert np.array_equal(arr, getattr(b, name)), name
    assert w.A.flags.writeable and w.R.flags.writeable, "packing leaves the spec's own arrays as they were"


def test_the_packed_motion_has_one_numba_type_whatever_the_model_holds():
    """F and G writable and C-contiguous, as the sequence kernels' slices of their stacks are."""
    from pursuit._compiled.kernel_args import Motion
    from pursuit.models import ConstantVelocity, LinearMotion

    F = np.array([[1.0, 0.5], [0.0, 0.9]])
    models = [ConstantVelocity(ndim=2, dt=1.0, q=0.01), LinearMotion(np.asfortranarray(F), 0.2 * np.eye(2))]
    types = set()
    for model in models:
        packed = specs.motion_spec(model).kernel_args(1, None)
        assert packed.F.flags.writeable and packed.G.flags.writeable and packed.F.flags.c_contiguous
        types.add(numba.typeof(packed))
    seq = specs.motion_spec(models[0]).sequence_args(3)
    types.add(numba.typeof(Motion(seq.kind, seq.F[0], seq.G[0], seq.par[0])))  # what _pf_sequence hands _step_body
    assert len(types) == 1, types


def test_lanes_are_writable_whatever_the_state_holds():
    from pursuit._compiled.gaussian import lanes

    cov = np.broadcast_to(np.eye(3), (1, 3, 3))  # a shared covariance: a read-only view
    P = lanes(cov, 2)
    assert P.flags.writeable and P.flags.c_contiguous and np.array_equal(P[..., 0], np.eye(3))


def test_frozen_copies_only_where_it_must():
    a = np.arange(6.0).reshape(2, 3)
    v = specs.frozen(a, np.float64)
    assert np.shares_memory(v, a) and not v.flags.writeable and a.flags.writeable
    t = specs.frozen(a.T, np.float64)
    assert t.flags.c_contiguous and np.array_equal(t, a.T) and not t.flags.writeable


def test_a_kernel_passes_no_literal_to_the_fitness_kernel():
    """``_greedy`` calls ``_fitness_rows`` with the types a Python caller gives it (int64 ``i0``, not ``Literal[int](0)``).

    ``_fitness_rows`` is called from Python, then a fresh, uncached copy of
    ``_greedy`` is typed here, so numba resolves its call to ``_fitness_rows``
    again (loading or compiling that kernel for the types it meets): one
    signature serves both.
    """
    model, n = SENSORS[next(iter(SENSORS))]
    sensor = _packed(specs.measurement_spec(model))
    rng = np.random.default_rng(5)
    N, m = 8, model.dim
    X, C = rng.normal(size=(N, n)), rng.normal(size=(N, n))
    z, valid = rng.normal(size=m), np.ones(m, dtype=bool)
    cst = CK._fit_consts(sensor.R, False)
    F = np.full(N, -np.inf)
    CK._fitness_rows(sensor, X, 0, N, z, valid, True, False, cst, np.empty((N, m)), F)
    lower, upper = np.full(n, -10.0), np.full(n, 10.0)
    greedy = numba.njit(error_model="numpy")(CK._greedy.py_func)
    greedy(X, F, C, sensor, z, valid, True, False, lower, upper, cst, np.empty((N, m)), np.empty(N))
    assert len(CK._fitness_rows.signatures) == 1, CK._fitness_rows.signatures
