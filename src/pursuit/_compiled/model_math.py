"""The model maths of every compiled kernel, written once: motion f, measurement h and its Jacobian.

The compiled counterparts of :mod:`pursuit.models` for the built-in models
that :mod:`pursuit._compiled.specs` registers.  Every kernel (bootstrap PF,
cuckoo PF, the Kalman block kernels) evaluates its models through the three
dispatchers here, which branch on the packed spec's ``kind`` code:

* :func:`propagate_row` — ``Xout[o] = f(Xin[i]) + noise`` (:class:`~.kernel_args.Motion`),
* :func:`h_row` — ``out[o] = h(X[i])`` (:class:`~.kernel_args.Sensor`),
* :func:`jac_row` — ``H[o] = ∂h/∂x (X[i])``.

They work on one point, a row of a 2-D array: a particle of ``(N, n)``
particles as it is stored, or a run of the Kalman kernels' lane-major
``(n, B)`` block through its transpose ``X.T`` (a view).  Row indices
rather than row views keep the particle loops free of per-particle array
objects.  Each formula is written with the operations in the order of the
NumPy model, so a kernel that moved here from its own copy gives the same
bits.  Everything is ``inline="always"``: the hot particle loops see plain
code, as before.  :func:`propagate_point` and :func:`h_point` are the same
dispatchers on the tuples' fields, for a particle loop that reads the
fields once before the loop (reading them from the tuple for every particle
cost the compiled CV-range PF about a third of its speed).

Adding a compiled sensor (docs/compiled-backend.md has the checklist): a
code in :mod:`.specs` with its spec builder in ``specs.MEASUREMENTS``, a
``h_<sensor>`` and ``jac_<sensor>`` pair below (arguments ``A, idx, scale``:
the spec's fields), and one branch in each of :func:`h_point` and
:func:`jac_point`.
"""

from __future__ import annotations

import math

from numba import njit

from .common import atan2_lanes, hypot_lanes
# frozen into the compiled code as constants
from .specs import M_LINEAR, M_OBSERVER_BEARINGS, M_RANGE, M_RANGE_BEARING, M_UNGM, UNGM

__all__ = ["propagate_row", "propagate_point", "h_row", "h_point", "h_sigma_row", "range_bearing_lanes", "jac_row", "jac_point",
           "wraps", "ungm_mean", "ungm_h"]

_NJ = dict(cache=True, inline="always", error_model="numpy")


# --------------------------------------------------------------------------
# motion
# --------------------------------------------------------------------------
@njit(**_NJ)
def ungm_mean(x, a, b, forcing):
    """UNGM's noise-free transition a x + b x / (1 + x²) + forcing, as ``x (a + b / (x² + 1)) + forcing``."""
    return x * (a + b / (x * x + 1.0)) + forcing


@njit(**_NJ)
def _linear_motion(F, G, Xin, i, noise, Xout, o):
    """x = F x + G ξ with ξ the q normals ``noise[i q : (i + 1) q]``."""
    n = Xin.shape[1]
    q = G.shape[1]
    for a_ in range(n):
        acc = 0.0
        for j in range(n):
            acc += F[a_, j] * Xin[i, j]
        acc2 = 0.0
        for j in range(q):
            acc2 += G[a_, j] * noise[i * q + j]
        Xout[o, a_] = acc + acc2


@njit(**_NJ)
def propagate_point(kind, F, G, par, Xin, i, noise, Xout, o):
    """:func:`propagate_row` on the motion's fields (a particle loop reads them from the tuple once, outside)."""
    if kind == UNGM:
        Xout[o, 0] = noise[i] * par[3] + ungm_mean(Xin[i, 0], par[0], par[1], par[2])
    else:
        _linear_motion(F, G, Xin, i, noise, Xout, o)


@njit(**_NJ)
def propagate_row(motion, Xin, i, noise, Xout, o):
    """``Xout[o] = f(Xin[i]) + G noise`` for point i; ``noise`` is flat, q normals per point (1 for UNGM)."""
    propagate_point(motion.kind, motion.F, motion.G, motion.par, Xin, i, noise, Xout, o)


# --------------------------------------------------------------------------
# measurement: one h and one Jacobian per sensor
# --------------------------------------------------------------------------
@njit(**_NJ)
def ungm_h(x, inv_scale):
    """UNGM's h = x² / s, as ``x x (1 / s)``."""
    return x * x * inv_scale


@njit(**_NJ)
def h_ungm(A, idx, scale, X, i, out, o):
    out[o, 0] = ungm_h(X[i, 0], 1.0 / scale)


@njit(**_NJ)
def jac_ungm(A, idx, scale, X, i, H, o):
    H[o, 0, 0] = (2.0 / scale) * X[i, 0]


@njit(**_NJ)
def h_linear(A, idx, scale, X, i, out, o):
    m, n = A.shape
    for a in range(m):
        acc = 0.0
        for j in range(n):
            acc += A[a, j] * X[i, j]
        out[o, a] = acc


@njit(**_NJ)
def jac_linear(A, idx, scale, X, i, H, o):
    m, n = A.shape
    for a in range(m):
        for j in range(n):
            H[o, a, j] = A[a, j]


@njit(**_NJ)
def h_range(A, idx, scale, X, i, out, o):
    """Distances to the anchors (rows of A) from the position ``X[i, idx]``, divided by ``scale`` (c for TOA)."""
    s, d = A.shape
    for a in range(s):
        acc = 0.0
        for j in range(d):
            t = X[i, idx[j]] - A[a, j]
            acc += t * t
        out[o, a] = math.sqrt(acc) / scale


@njit(**_NJ)
def jac_range(A, idx, scale, X, i, H, o):
    s, d = A.shape
    for a in range(s):
        acc = 0.0
        for j in range(d):
            t = X[i, idx[j]] - A[a, j]
            acc += t * t
        r = math.sqrt(acc)
        if r > 0:
            for j in range(d):
                H[o, a, idx[j]] = (X[i, idx[j]] - A[a, j]) / r / scale


@njit(**_NJ)
def h_range_bearing(A, idx, scale, X, i, out, o):
    """Range and bearing from the sensor position ``A[0]``."""
    dx = X[i, idx[0]] - A[0, 0]
    dy = X[i, idx[1]] - A[0, 1]
    out[o, 0] = math.hypot(dx, dy)
    out[o, 1] = math.atan2(dy, dx)


@njit(**_NJ)
def jac_range_bearing(A, idx, scale, X, i, H, o):
    dx = X[i, idx[0]] - A[0, 0]
    dy = X[i, idx[1]] - A[0, 1]
    r2 = dx * dx + dy * dy
    r = math.sqrt(r2)
    if r > 0:
        H[o, 0, idx[0]] = dx / r
        H[o, 0, idx[1]] = dy / r
    if r2 > 0:
        H[o, 1, idx[0]] = -dy / r2
        H[o, 1, idx[1]] = dx / r2


@njit(**_NJ)
def h_observer_bearings(A, idx, scale, X, i, out, o):
    """Azimuth (and elevation) from the observer's position of the step ``A[0]`` (:class:`~pursuit.models.ObserverBearings`)."""
    dx = X[i, idx[0]] - A[0, 0]
    dy = X[i, idx[1]] - A[0, 1]
    out[o, 0] = math.atan2(dy, dx)
    if idx.shape[0] == 3:
        dz = X[i, idx[2]] - A[0, 2]
        out[o, 1] = math.atan2(dz, math.hypot(dx, dy))


@njit(**_NJ)
def jac_observer_bearings(A, idx, scale, X, i, H, o):
    """Zero rows on the observer's vertical (azimuth undefined), as the NumPy model."""
    dx = X[i, idx[0]] - A[0, 0]
    dy = X[i, idx[1]] - A[0, 1]
    r2 = dx * dx + dy * dy
    if r2 > 0:
        H[o, 0, idx[0]] = -dy / r2
        H[o, 0, idx[1]] = dx / r2
        if idx.shape[0] == 3:
            dz = X[i, idx[2]] - A[0, 2]
            rho = math.sqrt(r2)
            R2 = r2 + dz * dz
            H[o, 1, idx[0]] = -dz * dx / (rho * R2)
            H[o, 1, idx[1]] = -dz * dy / (rho * R2)
            H[o, 1, idx[2]] = rho / R2


@njit(**_NJ)
def wraps(kind, angle, a):
    """Whether innovation component ``a`` is an angle, wrapped to [−π, π) as the NumPy model's ``residual`` does.

    RangeBearing's bearing (``angle`` and a = 1); every component of
    ObserverBearings (its residual wraps the elevation too, which leaves it
    unchanged).
    """
    return kind == M_OBSERVER_BEARINGS or (angle and a == 1)


# the dispatch table: one branch per sensor code of specs.py
@njit(**_NJ)
def h_point(kind, A, idx, scale, X, i, out, o):
    """:func:`h_row` on the sensor's fields (a particle loop reads them from the tuple once, outside)."""
    if kind == M_UNGM:
        h_ungm(A, idx, scale, X, i, out, o)
    elif kind == M_LINEAR:
        h_linear(A, idx, scale, X, i, out, o)
    elif kind == M_RANGE:
        h_range(A, idx, scale, X, i, out, o)
    elif kind == M_RANGE_BEARING:
        h_range_bearing(A, idx, scale, X, i, out, o)
    elif kind == M_OBSERVER_BEARINGS:
        h_observer_bearings(A, idx, scale, X, i, out, o)
    else:  # a sensor code without its branch here: NaN, never another sensor's formula
        for a in range(out.shape[1]):
            out[o, a] = math.nan


@njit(**_NJ)
def jac_point(kind, A, idx, scale, X, i, H, o):
    """:func:`jac_row` on the sensor's fields."""
    m, n = H.shape[1], H.shape[2]
    for a in range(m):
        for j in range(n):
            H[o, a, j] = 0.0
    if kind == M_UNGM:
        jac_ungm(A, idx, scale, X, i, H, o)
    elif kind == M_LINEAR:
        jac_linear(A, idx, scale, X, i, H, o)
    elif kind == M_RANGE:
        jac_range(A, idx, scale, X, i, H, o)
    elif kind == M_RANGE_BEARING:
        jac_range_bearing(A, idx, scale, X, i, H, o)
    elif kind == M_OBSERVER_BEARINGS:
        jac_observer_bearings(A, idx, scale, X, i, H, o)
    else:  # a sensor code without its branch here: NaN, never another sensor's Jacobian
        for a in range(m):
            for j in range(n):
                H[o, a, j] = math.nan


@njit(**_NJ)
def h_row(sensor, X, i, out, o):
    """``out[o] = h(X[i])``: the noise-free measurement of point i."""
    h_point(sensor.kind, sensor.A, sensor.idx, sensor.scale, X, i, out, o)


@njit(**_NJ)
def range_bearing_lanes(dx, dy):
    """``(range, bearing, exact)`` of the offset ``(dx, dy)`` without libm calls, so a loop over lanes vectorises.

    Within 1 ulp of ``math.hypot`` / ``math.atan2`` where ``exact``; where
    not the caller takes libm's values: dx = 0 exactly (a point due north or
    south), |dx| or a non-zero |dy| outside [2^−500, 2^500], dx² + dy²
    outside [2^−1000, 2^1000], an infinite or NaN offset.
    """
    r, r_exact = hypot_lanes(dx, dy)
    b, b_exact = atan2_lanes(dy, dx)
    return r, b, r_exact & b_exact


@njit(**_NJ)
def h_sigma_row(sensor, X, i, out, o):
    """:func:`h_row` for the UKF/CKF's sigma points: RangeBearing through :func:`range_bearing_lanes`.

    The compiled UKF/CKF kernels (block, whole-sequence and one-run) all
    evaluate their points through this (or its vectorised loop,
    ``gauss_kernels._h_sigma_block``), so they give the same bits; the
    values are within 1 ulp of the libm ones the other kernels use.
    """
    if sensor.kind == M_RANGE_BEARING:
        A, idx = sensor.A, sensor.idx
        r, b, exact = range_bearing_lanes(X[i, idx[0]] - A[0, 0], X[i, idx[1]] - A[0, 1])
        if exact:
            out[o, 0] = r
            out[o, 1] = b
            return
    h_row(sensor, X, i, out, o)  # other sensors, and a point the lanes' functions do not take (libm's values)


@njit(**_NJ)
def jac_row(sensor, X, i, H, o):
    """``H[o] = ∂h/∂x`` at point i, into ``H[o]`` (m, n); entries a model leaves out are zero."""
    jac_point(sensor.kind, sensor.A, sensor.idx, sensor.scale, X, i, H, o)
