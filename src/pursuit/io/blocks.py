"""Columnar blocks of records, steps and estimates: the fast lane of ``pursuit track --stream``.

A live stream's chunk of lines (what :class:`pursuit.io.lines.ChunkedLines`
has at hand) is parsed at once when every line in it is plain (one sensor's
finite numbers, times in seconds); the readers then yield one
:class:`RecordBlock` in place of its records, :func:`pursuit.io.steps.assemble_steps`
turns a block of strictly increasing times into a :class:`StepBlock`, the
tracker filters it in one compiled call into an :class:`EstimateBlock`, and
the writers format that in one string operation.  The modules that own
:class:`~pursuit.io.records.Record`, :class:`~pursuit.io.steps.Step` and
:class:`~pursuit.io.tracker.Estimate` turn a block back into those objects
(``block_records``, ``block_steps``, ``block_estimates``); this module
imports none of them.  Any chunk or block that is
not plain goes through the record-by-record path, whose messages and
recovery rules are the reference: the blocks are a faster way to the same
bytes, never a different result (``tests/io/test_stream_blocks.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RecordBlock", "StepBlock", "EstimateBlock"]


@dataclass(frozen=True)
class RecordBlock:
    """Good records of consecutive input lines, one per line, as columns.

    Attributes
    ----------
    lines
        ``(n,)`` input line numbers (consecutive).
    times
        ``(n,)`` times, s (finite).
    sensors
        ``n`` sensor ids (stripped, non-empty).
    values
        ``(n, k)`` components (finite: no record of the block misses one).
    """

    lines: np.ndarray
    times: np.ndarray
    sensors: list[str]
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.times)



@dataclass(frozen=True)
class StepBlock:
    """Consecutive complete steps of one record each, as columns.

    Attributes
    ----------
    times
        ``(n,)`` strictly increasing step times, s.
    z
        ``(n, m)`` measurement vectors (NaN where the sensor has no block).
    lines
        ``(n,)`` the input line of each step's record.
    sensors
        The sensor id of each step.
    """

    times: np.ndarray
    z: np.ndarray
    lines: np.ndarray
    sensors: list[str]

    def __len__(self) -> int:
        return len(self.times)

    def part(self, start: int, stop: int) -> "StepBlock":
        """Steps ``start`` to ``stop`` (views)."""
        return StepBlock(self.times[start:stop], self.z[start:stop], self.lines[start:stop], self.sensors[start:stop])



@dataclass(frozen=True)
class EstimateBlock:
    """Consecutive estimates as columns (see :class:`pursuit.io.tracker.Estimate` for the fields).

    ``covs`` is ``(n, d, d)``; ``flags`` holds one tuple of names per row.
    """

    times: np.ndarray
    means: np.ndarray
    var: np.ndarray
    nis: np.ndarray
    dof: list[int]
    flags: list[tuple[str, ...]]
    lines: np.ndarray
    covs: np.ndarray

    def __len__(self) -> int:
        return len(self.times)

