"""Small compiled helpers shared by the particle and Gaussian kernels: elementary functions, resampling, linear algebra.

Everything here is ``@njit(cache=True, error_model="numpy")``.  The models themselves are
evaluated in :mod:`pursuit._compiled.model_math`.
"""

from __future__ import annotations

import math
import types as pytypes
from typing import Callable

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

R_SYSTEMATIC = 0
R_STRATIFIED = 1
R_MULTINOMIAL = 2
R_RESIDUAL = 3

LOG_2PI = math.log(2.0 * math.pi)
TWO_PI = 2.0 * math.pi
# exp() of a log-weight below this is a denormal or zero (and slow): use 0
EXP_FLOOR = -708.0


def serial_and_parallel(func: Callable, **options) -> tuple[Callable, Callable]:
    """``(serial, parallel)`` ``njit`` builds of ``func`` that numba caches apart.

    numba's on-disk cache files a build under the function's qualified
    name and first line, and tells entries apart by signature and bytecode,
    not by ``parallel=``: two builds of one function share one cache entry,
    and once it is warm the second loads the first one's machine code (a
    "parallel" kernel that runs on one thread, or a serial one that runs
    ``prange`` from a worker thread).  The parallel build is therefore made
    from a copy of ``func`` under its own name.

    Parameters
    ----------
    func : callable
        The Python function (not yet jitted).
    **options
        ``njit`` options for both builds (``cache``, ``error_model``, ...).
    """
    name = func.__name__ + "__parallel"
    twin = pytypes.FunctionType(func.__code__.replace(co_name=name), func.__globals__, name, func.__defaults__, func.__closure__)
    twin.__qualname__ = func.__qualname__ + "__parallel"
    twin.__module__ = func.__module__
    twin.__doc__ = func.__doc__
    return njit(**options)(func), njit(parallel=True, **options)(twin)


# --------------------------------------------------------------------------
# exp that the compiler can vectorise (libm's exp is one call per value)
# --------------------------------------------------------------------------
@intrinsic
def _bits(typingctx, x):
    """The IEEE bits of a float64 as an int64."""
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return sig, codegen


@intrinsic
def _from_bits(typingctx, i):
    """The float64 whose IEEE bits are the int64 ``i``."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


@intrinsic
def fma(typingctx, a, b, c):
    """a·b + c rounded once (llvm.fma: one instruction on CPUs with FMA)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


_ROUND = 6755399441055744.0  # 1.5·2^52: x + _ROUND rounds x to an integer kept in the low mantissa bits
_ROUND_BITS = np.int64(0x4338000000000000)
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k·_LN2_HI is exact (Cody and Waite)
_LN2_LO = 1.90821492927058770002e-10
_C = [1.0 / math.factorial(i) for i in range(14)]
_C2, _C3, _C4, _C5, _C6, _C7, _C8, _C9, _C10, _C11, _C12, _C13 = _C[2:14]


@njit(cache=True, inline="always", error_model="numpy")
def exp_weight(x):
    """exp(x) for a log-weight x < 709, 0 for x <= EXP_FLOOR (also −inf and NaN).

    Branch-free, so loops over particles vectorise: x = k ln 2 + r with
    |r| <= ln 2 / 2, exp(r) by its Taylor polynomial of degree 13 (truncation
    below 1e-17 relative), 2^k from the exponent bits.  Within 1 ulp of libm's
    exp (tested), which is what the NumPy filters use.
    """
    t = fma(x, _LOG2E, _ROUND)
    kf = t - _ROUND
    r = fma(-kf, _LN2_LO, fma(-kf, _LN2_HI, x))
    p = fma(_C13, r, _C12)
    p = fma(p, r, _C11)
    p = fma(p, r, _C10)
    p = fma(p, r, _C9)
    p = fma(p, r, _C8)
    p = fma(p, r, _C7)
    p = fma(p, r, _C6)
    p = fma(p, r, _C5)
    p = fma(p, r, _C4)
    p = fma(p, r, _C3)
    p = fma(p, r, _C2)
    p = fma(p, r, 1.0)
    p = fma(p, r, 1.0)
    k = _bits(t) - _ROUND_BITS
    v = p * _from_bits((k + np.int64(1023)) << np.int64(52))
    return v if x > EXP_FLOOR else 0.0


# log, as exp above: branch-free so that loops over lanes vectorise (the Kalman kernels' log det S)
_TINY = 2.2250738585072014e-308  # smallest normal float64
_TWO54 = 18014398509481984.0
_SQRT2 = 1.4142135623730951
_MANT = np.int64(0x000FFFFFFFFFFFFF)
_ONE_BITS = np.int64(0x3FF0000000000000)
# minimax coefficients of (log(1+f) − f + f²/2) / s expanded in s² = (f / (2 + f))² (Sun's fdlibm e_log.c)
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01


@njit(cache=True, inline="always", error_model="numpy")
def log_positive(x):
    """log(x) for a positive finite x (subnormals included), within 1 ulp of libm's log (tested).

    x = 2^k m with m in (√2/2, √2]; with f = m − 1 and s = f / (2 + f),
    log m = f − f²/2 + s (f²/2 + R(s²)), R a degree-7 polynomial in s², and
    k ln 2 is added in two parts (Cody and Waite).  No branches and no call,
    so a loop over lanes vectorises; zero, negative, infinite or NaN input
    gives an unspecified finite value, so callers pass only positive finite x.
    """
    sub = x < _TINY
    y = x * _TWO54 if sub else x
    hx = _bits(y)
    k = (hx >> np.int64(52)) - np.int64(1023) - (np.int64(54) if sub else np.int64(0))
    m = _from_bits((hx & _MANT) | _ONE_BITS)
    big = m > _SQRT2
    m = m * 0.5 if big else m
    k = k + (np.int64(1) if big else np.int64(0))
    dk = _from_bits(k + _ROUND_BITS) - _ROUND  # exact for |k| < 2^51, and vectorises (no int64 → float conversion in AVX2)
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * fma(w, fma(w, _LG6, _LG4), _LG2)
    t2 = z * fma(w, fma(w, fma(w, _LG7, _LG5), _LG3), _LG1)
    r = t2 + t1
    hfsq = 0.5 * f * f
    return dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f)


# atan2 and hypot, as exp and log above: no libm call, so that loops over lanes vectorise (the
# compiled UKF/CKF's range-bearing sigma points); a lane outside the ranges below says so and the
# caller takes libm's value there instead
# minimax coefficients of (atan(t) − t) / t in t² on |t| ≤ 7/16 and the breakpoints' atan split in two
# (Sun's fdlibm s_atan.c)
_AT0, _AT1, _AT2, _AT3, _AT4, _AT5 = (3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01,
                                      -1.11111104054623557880e-01, 9.09088713343650656196e-02, -7.69187620504482999495e-02)
_AT6, _AT7, _AT8, _AT9, _AT10 = (6.66107313738753120669e-02, -5.83357013379057348645e-02, 4.97687799461593236017e-02,
                                 -3.65315727442169155270e-02, 1.62858201153657823623e-02)
_ATAN_HALF = (4.63647609000806093515e-01, 2.26987774529616870924e-17)  # atan(1/2), hi and lo
_ATAN_ONE = (7.85398163397448278999e-01, 3.06161699786838301793e-17)
_ATAN_3_2 = (9.82793723247329054082e-01, 1.39033110312309984516e-17)
_ATAN_INF = (1.57079632679489655800e+00, 6.12323399573676603587e-17)
_PI_LO = 1.2246467991473531772e-16  # π − fl(π)
_LANE_MIN = 2.0 ** -500  # atan2_lanes / hypot_lanes: arguments inside these bounds neither overflow nor lose bits
_LANE_MAX = 2.0 ** 500


@njit(cache=True, inline="always", error_model="numpy")
def atan2_lanes(y, x):
    """``(atan2(y, x), exact)``: within 1 ulp of libm's atan2 where ``exact`` (tested), else libm's value is needed.

    Branch-free, so a loop over lanes vectorises.  ``exact`` is False for
    a zero, subnormal, huge (beyond 2^±500), infinite or NaN argument (y = ±0
    excepted): the caller recomputes those lanes with ``math.atan2``.
    With q = |y| / |x| reduced to |t| ≤ 7/16 around 0, 1/2, 1, 3/2 or ∞
    (t = q, (2q − 1)/(2 + q), (q − 1)/(q + 1), (q − 1.5)/(1 + 1.5q), −1/q),
    atan q = atan(c) + atan t by fdlibm's polynomial; the quadrant from the
    signs of x and y (their sign bits, so atan2(−0, x) = −0 as in libm).
    """
    ax = abs(x)
    ay = abs(y)
    exact = (ax >= _LANE_MIN) & (ax <= _LANE_MAX) & (((ay >= _LANE_MIN) & (ay <= _LANE_MAX)) | (ay == 0.0))
    q = ay / ax
    near_inf = q >= 2.4375
    near_3_2 = q >= 1.1875
    near_one = q >= 0.6875
    near_half = q >= 0.4375
    num = -1.0 if near_inf else (q - 1.5 if near_3_2 else (q - 1.0 if near_one else (fma(2.0, q, -1.0) if near_half else q)))
    den = q if near_inf else (fma(1.5, q, 1.0) if near_3_2 else (q + 1.0 if near_one else (2.0 + q if near_half else 1.0)))
    hi = _ATAN_INF[0] if near_inf else (_ATAN_3_2[0] if near_3_2 else (_ATAN_ONE[0] if near_one else (_ATAN_HALF[0] if near_half else 0.0)))
    lo = _ATAN_INF[1] if near_inf else (_ATAN_3_2[1] if near_3_2 else (_ATAN_ONE[1] if near_one else (_ATAN_HALF[1] if near_half else 0.0)))
    t = num / den
    z = t * t
    w = z * z
    s1 = z * fma(w, fma(w, fma(w, fma(w, fma(w, _AT10, _AT8), _AT6), _AT4), _AT2), _AT0)
    s2 = w * fma(w, fma(w, fma(w, fma(w, _AT9, _AT7), _AT5), _AT3), _AT1)
    a = hi - (fma(t, s1 + s2, -lo) - t)
    v = math.pi - (a - _PI_LO) if math.copysign(1.0, x) < 0.0 else a
    return math.copysign(v, y), exact


@njit(cache=True, inline="always", error_model="numpy")
def hypot_lanes(x, y):
    """``(√(x² + y²), exact)``: within 1 ulp of libm's hypot where ``exact`` (tested), else libm's value is needed.

    Branch-free (one ``fma`` and a square root); ``exact`` is False where
    x² + y² is zero, below 2^−1000, above 2^1000, infinite or NaN.
    """
    s = fma(x, x, y * y)
    return math.sqrt(s), (s >= _LANE_MIN * _LANE_MIN) & (s <= _LANE_MAX * _LANE_MAX)


@njit(cache=True, inline="always", error_model="numpy")
def wrap(a):
    """Angle wrapped to [-π, π), as :func:`pursuit.models.measurement.wrap_angle`."""
    return (a + math.pi) % TWO_PI - math.pi


@njit(cache=True, inline="always", error_model="numpy")
def wrap_inside(a):
    """``(wrap(a), inside)`` where ``a + π`` is already in [0, 2π) (``inside``), the same bits as :func:`wrap` there.

    No remainder is taken (``%`` is a libm ``fmod`` call, one per value),
    so a loop over lanes vectorises; where ``inside`` is False the value is
    not the wrapped angle and the caller wraps that value with :func:`wrap`.
    """
    t = a + math.pi
    return t - math.pi, (t >= 0.0) & (t < TWO_PI)


@njit(cache=True, error_model="numpy")
def cholesky_inplace(S, L):
    """Lower Cholesky factor of ``S`` (m, m) into ``L``; False if S is not finite and positive definite."""
    m = S.shape[0]
    for i in range(m):
        for j in range(m):
            L[i, j] = 0.0
    for j in range(m):
        acc = S[j, j]
        for p in range(j):
            acc -= L[j, p] * L[j, p]
        if not (acc > 0.0) or not math.isfinite(acc):
            return False
        d = math.sqrt(acc)
        L[j, j] = d
        for i in range(j + 1, m):
            acc = S[i, j]
            for p in range(j):
                acc -= L[i, p] * L[j, p]
            L[i, j] = acc / d
    return True


@njit(cache=True, error_model="numpy")
def chol_quad(L, v, tmp):
    """vᵀ (L Lᵀ)⁻¹ v by forward substitution."""
    m = L.shape[0]
    tot = 0.0
    for i in range(m):
        acc = v[i]
        for p in range(i):
            acc -= L[i, p] * tmp[p]
        tmp[i] = acc / L[i, i]
        tot += tmp[i] * tmp[i]
    return tot


# --------------------------------------------------------------------------
# resampling: copy counts of one run from its weights (unnormalised) and uniforms
# --------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _cdf(e, c):
    N = e.shape[0]
    acc = 0.0
    for i in range(N):
        acc += e[i]
        c[i] = acc
    last = c[N - 1]
    for i in range(N):
        c[i] /= last
    c[N - 1] = 1.0


@njit(cache=True, error_model="numpy")
def n_uniforms(kind, N):
    """Uniforms a run draws to resample (as the NumPy resamplers)."""
    if kind == R_SYSTEMATIC:
        return 1
    if kind == R_STRATIFIED:
        return N
    return N + 1


@njit(cache=True, error_model="numpy")
def _sorted_uniforms(U, count, out):
    """``count`` sorted uniforms from N + 1 exponential spacings (as resample._sorted_uniforms), padded with 2."""
    N = out.shape[0]
    acc = 0.0
    total = 1.0
    for i in range(N + 1):
        acc += -math.log1p(-U[i])
        if i < N:
            out[i] = acc
        if i == count:
            total = acc
    for i in range(N):
        out[i] = out[i] / total if i < count else 2.0


@njit(cache=True, error_model="numpy")
def _locate_counts(c, u, counts):
    """counts[bin] += 1 for each u <= 1, bin = #{j: c_j <= u} capped at N − 1 (u sorted)."""
    N = c.shape[0]
    j = 0
    for t in range(u.shape[0]):
        x = u[t]
        if x > 1.0:
            break
        while j < N and c[j] <= x:
            j += 1
        counts[min(j, N - 1)] += 1


@njit(cache=True, error_model="numpy")
def resample_counts(kind, e, U, c, tmp, counts):
    """Copy counts (N,) of one run: weights ``e`` (unnormalised), uniforms ``U``, scratch ``c``, ``tmp``."""
    N = e.shape[0]
    if kind == R_SYSTEMATIC:
        _cdf(e, c)
        u0 = U[0]
        prev = 0.0
        for i in range(N):
            below = math.ceil(c[i] * N - u0)
            counts[i] = np.int64(below - prev)
            prev = below
    elif kind == R_STRATIFIED:
        _cdf(e, c)
        prev = 0
        for i in range(N):
            x = N * c[i]
            J = min(int(math.floor(x)), N - 1)
            below = J + (1 if U[J] < x - J else 0)
            counts[i] = below - prev
            prev = below
    elif kind == R_MULTINOMIAL:
        _cdf(e, c)
        _sorted_uniforms(U, N, tmp)
        for i in range(N):
            counts[i] = 0
        _locate_counts(c, tmp, counts)
    else:
        s = 0.0
        for i in range(N):
            s += e[i]
        rest = N
        for i in range(N):
            Nw = N * (e[i] / s)
            d = math.floor(Nw + 1e-9)
            counts[i] = np.int64(d)
            rest -= np.int64(d)
            c[i] = max(Nw - d, 0.0)
        if rest < 0:
            rest = 0
        tot = 0.0
        for i in range(N):
            tot += c[i]
        if not (tot > 0):
            for i in range(N):
                c[i] = 1.0
        _cdf(c.copy(), c)
        _sorted_uniforms(U, rest, tmp)
        _locate_counts(c, tmp, counts)


@njit(cache=True, error_model="numpy")
def copy_by_counts(src, counts, dst):
    """dst = src with particle i repeated counts[i] times (rows in order)."""
    N, n = src.shape
    pos = 0
    for i in range(N):
        for _ in range(counts[i]):
            for j in range(n):
                dst[pos, j] = src[i, j]
            pos += 1
