"""Scratch buffers that particle filters reuse from step to step.

A fresh multi-megabyte NumPy array is a fresh ``mmap`` (or heap pages that
glibc trimmed back to the system), and touching it costs a page fault per
4 KiB page: on this machine kind that doubled the cost of a bootstrap PF
step.  Temporaries of a step therefore live in a :class:`Workspace` kept in
the filter state and are overwritten by the next step.  Arrays that outlive
the step (particles, estimates, info) are fresh, except the large
per-particle outputs, which :func:`recycled` takes from the step before last
when nothing but the workspace holds them any more.
"""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["Workspace", "scratch", "memo", "recycled"]


class Workspace:
    """Named scratch arrays, reallocated only when the shape or dtype changes."""

    __slots__ = ("_bufs",)

    def __init__(self) -> None:
        self._bufs: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype=float) -> np.ndarray:
        """The scratch array called ``name`` with this shape and dtype (contents undefined)."""
        buf = self._bufs.get(name)
        if buf is None or buf.shape != tuple(shape) or buf.dtype != np.dtype(dtype):
            buf = np.empty(shape, dtype=dtype)
            self._bufs[name] = buf
        return buf

    def __repr__(self) -> str:
        return f"Workspace({len(self._bufs)} buffers)"


def scratch(work: Workspace | None, name: str, shape: tuple[int, ...], dtype=float) -> np.ndarray:
    """A scratch array from ``work``, or a fresh one when there is no workspace."""
    if work is None:
        return np.empty(shape, dtype=dtype)
    return work.get(name, shape, dtype)


def memo(work: Workspace | None, name: str, key: object, make):
    """A cached object for ``key`` (compared by identity), rebuilt by ``make()`` when the key changes."""
    if work is None:
        return make()
    held = work._bufs.get(name)
    if held is None or held[0] is not key:
        held = (key, make())
        work._bufs[name] = held
    return held[1]


# CPython only: elsewhere every recycled() array is fresh
_REFCOUNTS = hasattr(sys, "getrefcount")


def recycled(work: Workspace | None, name: str, shape: tuple[int, ...], dtype=float) -> np.ndarray:
    """An output array a step hands out, reusing the one it handed out two steps ago when that one is free.

    The workspace keeps the last two arrays handed out under ``name``.  One
    is reused only when the workspace holds the last reference to it (the
    state that returned it, and every view of it, are gone), so a state the
    caller still holds never changes.  Otherwise, and without a workspace or
    outside CPython, the array is fresh.  Contents are undefined.
    """
    shape = tuple(shape)
    if work is None or not _REFCOUNTS:
        return np.empty(shape, dtype=dtype)
    pool = work._bufs.get(name)
    if pool is None:
        pool = work._bufs[name] = []
    dtype = np.dtype(dtype)
    for i in range(len(pool)):
        # references: the pool's list and getrefcount's argument, nothing else
        if sys.getrefcount(pool[i]) == 2 and pool[i].shape == shape and pool[i].dtype == dtype:
            pool.append(pool.pop(i))  # most recently handed out last
            return pool[-1]
    buf = np.empty(shape, dtype=dtype)
    pool.append(buf)
    if len(pool) > 2:
        del pool[0]
    return buf
