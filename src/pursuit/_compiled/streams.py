"""NumPy's PCG64 normal and uniform streams, drawn inside compiled code at full speed.

A run's draws must be NumPy's own (``Generator.standard_normal`` and
``Generator.random`` on the run's ``PCG64``): that is what keeps the compiled
and NumPy backends on the same numbers.  numba can call a ``Generator``
directly, but every draw then goes through the bit generator's C function
pointer (about 11 ns a normal on the development machine).  This module
advances the same PCG64 state itself: it reads the generator's 128-bit state
and increment from the bit generator's C struct (``ctypes.state_address``),
runs the PCG64 step (128-bit LCG with the XSL-RR output) and NumPy's ziggurat
on local variables, and writes the state back, so the ``Generator`` continues
exactly where NumPy would (about 3.5 ns a normal).

The draws are bit-for-bit NumPy's (tested on millions of draws, including the
ziggurat's rare tail and wedge branches).  Whether the memory layout is the
one expected (``pcg64_random_t`` as two little-endian ``__uint128_t``: state,
increment) is checked once per process by :func:`fast_streams_available`
against the generator's own ``state`` and draws; where it is not, or a
generator is not a ``PCG64``, the callers draw with NumPy instead.

The ziggurat tables are NumPy's (numba ships copies of them).
"""

from __future__ import annotations

import ctypes
import math
from functools import lru_cache
from typing import Sequence

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r

__all__ = ["fast_streams_available", "stream_addresses", "fill_normal", "fill_random", "next_random"]

_NJ = dict(cache=True, error_model="numpy")

_MUL_HI = np.uint64(2549297995355413924)  # PCG_DEFAULT_MULTIPLIER_128, high and low words
_MUL_LO = np.uint64(4865540595714422341)
_U1 = np.uint64(1)
_MANT = np.uint64(0x000FFFFFFFFFFFFF)


@intrinsic
def _load(typingctx, addr, i):
    """The i-th uint64 at address ``addr``."""
    sig = types.uint64(types.uint64, types.intp)

    def codegen(context, builder, signature, args):
        ptr = builder.inttoptr(args[0], ir.IntType(64).as_pointer())
        return builder.load(builder.gep(ptr, [args[1]]))

    return sig, codegen


@intrinsic
def _store(typingctx, addr, i, value):
    """Write ``value`` as the i-th uint64 at address ``addr``."""
    sig = types.void(types.uint64, types.intp, types.uint64)

    def codegen(context, builder, signature, args):
        ptr = builder.inttoptr(args[0], ir.IntType(64).as_pointer())
        builder.store(args[2], builder.gep(ptr, [args[1]]))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _umulh(typingctx, a, b):
    """High 64 bits of the 128-bit product of two uint64 (one ``mul`` instruction)."""
    sig = types.uint64(types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        i128 = ir.IntType(128)
        p = builder.mul(builder.zext(args[0], i128), builder.zext(args[1], i128))
        return builder.trunc(builder.lshr(p, ir.Constant(i128, 64)), ir.IntType(64))

    return sig, codegen


@njit(inline="always", **_NJ)
def _next64(lo, hi, ilo, ihi):
    """PCG64 step (state = state·MULT + inc mod 2^128) and XSL-RR output: ``(value, lo, hi)``."""
    plo = lo * _MUL_LO
    phi = _umulh(lo, _MUL_LO) + lo * _MUL_HI + hi * _MUL_LO
    nlo = plo + ilo
    nhi = phi + ihi + (_U1 if nlo < plo else np.uint64(0))
    x = nhi ^ nlo
    rot = nhi >> np.uint64(58)
    return (x >> rot) | (x << ((np.uint64(64) - rot) & np.uint64(63))), nlo, nhi


@njit(inline="always", **_NJ)
def _next_double(lo, hi, ilo, ihi):
    """NumPy's ``next_double``: the top 53 bits of a draw, scaled to [0, 1)."""
    r, lo, hi = _next64(lo, hi, ilo, ihi)
    return np.float64(np.int64(r >> np.uint64(11))) * (1.0 / 9007199254740992.0), lo, hi


@njit(inline="never", **_NJ)
def _normal_rejected(x, idx, rabs, lo, hi, ilo, ihi):
    """The rest of NumPy's ``random_standard_normal`` after a first draw outside the ziggurat's core."""
    while True:
        if idx == 0:  # the tail beyond r
            while True:
                u, lo, hi = _next_double(lo, hi, ilo, ihi)
                xx = -ziggurat_nor_inv_r * math.log1p(-u)
                u, lo, hi = _next_double(lo, hi, ilo, ihi)
                yy = -math.log1p(-u)
                if yy + yy > xx * xx:
                    if (rabs >> np.uint64(8)) & _U1:
                        return -(ziggurat_nor_r + xx), lo, hi
                    return ziggurat_nor_r + xx, lo, hi
        else:  # a wedge
            u, lo, hi = _next_double(lo, hi, ilo, ihi)
            if (fi_double[idx - 1] - fi_double[idx]) * u + fi_double[idx] < math.exp(-0.5 * x * x):
                return x, lo, hi
        r, lo, hi = _next64(lo, hi, ilo, ihi)
        idx = np.intp(r & np.uint64(0xFF))
        r >>= np.uint64(8)
        rabs = (r >> _U1) & _MANT
        x = np.float64(np.int64(rabs)) * wi_double[idx]
        if r & _U1:
            x = -x
        if rabs < ki_double[idx]:
            return x, lo, hi


@njit(inline="always", **_NJ)
def _normal(lo, hi, ilo, ihi):
    """NumPy's ``random_standard_normal`` (ziggurat), the common case without a branch on the sign."""
    r, lo, hi = _next64(lo, hi, ilo, ihi)
    idx = np.intp(r & np.uint64(0xFF))
    r >>= np.uint64(8)
    rabs = np.int64((r >> _U1) & _MANT)  # < 2^52: signed arithmetic is exact and cheaper
    sign = 1.0 - 2.0 * np.float64(np.int64(r & _U1))  # ±1 exactly: x·sign is NumPy's −x
    x = (np.float64(rabs) * wi_double[idx]) * sign
    if rabs < np.int64(ki_double[idx]):
        return x, lo, hi
    return _normal_rejected(x, idx, np.uint64(rabs), lo, hi, ilo, ihi)


@njit(**_NJ)
def fill_normal(addr, out):
    """``out[:] = Generator.standard_normal(out.size)`` for the PCG64 state at ``addr``, advancing it."""
    lo, hi, ilo, ihi = _load(addr, 0), _load(addr, 1), _load(addr, 2), _load(addr, 3)
    for i in range(out.shape[0]):
        v, lo, hi = _normal(lo, hi, ilo, ihi)
        out[i] = v
    _store(addr, 0, lo)
    _store(addr, 1, hi)


@njit(**_NJ)
def fill_random(addr, out):
    """``out[:] = Generator.random(out.size)`` for the PCG64 state at ``addr``, advancing it."""
    lo, hi, ilo, ihi = _load(addr, 0), _load(addr, 1), _load(addr, 2), _load(addr, 3)
    for i in range(out.shape[0]):
        v, lo, hi = _next_double(lo, hi, ilo, ihi)
        out[i] = v
    _store(addr, 0, lo)
    _store(addr, 1, hi)


@njit(**_NJ)
def next_random(addr):
    """One ``Generator.random()`` draw from the PCG64 state at ``addr``."""
    lo, hi, ilo, ihi = _load(addr, 0), _load(addr, 1), _load(addr, 2), _load(addr, 3)
    v, lo, hi = _next_double(lo, hi, ilo, ihi)
    _store(addr, 0, lo)
    _store(addr, 1, hi)
    return v


def _state_address(g: np.random.Generator) -> int:
    """Address of the ``pcg64_random_t`` (state, increment) behind a PCG64 Generator."""
    # the bit generator's struct starts with a pointer to the pcg64_random_t
    return ctypes.cast(g.bit_generator.ctypes.state_address, ctypes.POINTER(ctypes.c_uint64))[0]


@lru_cache(maxsize=1)
def fast_streams_available() -> bool:
    """Whether this process's NumPy PCG64 has the layout these kernels expect (checked against NumPy itself)."""
    try:
        g = np.random.Generator(np.random.PCG64(20261201))
        ref = np.random.Generator(np.random.PCG64(20261201))
        addr = _state_address(g)
        words = ctypes.cast(addr, ctypes.POINTER(ctypes.c_uint64))
        st = g.bit_generator.state["state"]
        mask = (1 << 64) - 1
        expected = [st["state"] & mask, st["state"] >> 64, st["inc"] & mask, st["inc"] >> 64]
        if [int(words[i]) for i in range(4)] != expected:
            return False
        a = np.empty(4096)
        fill_normal(np.uint64(addr), a)
        if not np.array_equal(a, ref.standard_normal(4096)):
            return False
        fill_random(np.uint64(addr), a)
        if not np.array_equal(a, ref.random(4096)):
            return False
        return bool(next_random(np.uint64(addr)) == ref.random() and g.standard_normal() == ref.standard_normal())
    except Exception:  # any surprise in the struct: draw with NumPy instead
        return False


def stream_addresses(generators: Sequence[np.random.Generator]) -> np.ndarray | None:
    """``(len(generators),)`` uint64 state addresses, or None where the fast streams cannot be used.

    None when the layout check fails, a generator is not a PCG64, or two runs
    share one generator (parallel runs would then race on its state).
    """
    if not fast_streams_available():
        return None
    if any(type(g.bit_generator) is not np.random.PCG64 for g in generators):
        return None
    if len({id(g) for g in generators}) != len(generators):
        return None
    return np.array([_state_address(g) for g in generators], dtype=np.uint64)
