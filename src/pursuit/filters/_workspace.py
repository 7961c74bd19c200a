"""Scratch buffers that particle filters reuse from step to step.

A fresh multi-megabyte NumPy array is a fresh ``mmap`` (or heap pages that
glibc trimmed back to the system), and touching it costs a page fault per
4 KiB page: on this machine kind that doubled the cost of a bootstrap PF
step.  Temporaries of a step therefore live in a :class:`Workspace` kept in
the filter state and are overwritten by the next step; arrays that outlive
the step (particles, estimates, info) are always fresh.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Workspace", "scratch"]


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
