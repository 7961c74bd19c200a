"""Writers for estimates: CSV and JSON Lines.

CSV columns: ``time``, the state components (``x, vx, y, vy`` ...), the
covariance diagonal (``var_x, var_vx, ...``), ``nis``, ``dof`` and ``flags``
(``;``-separated).  JSON Lines: one object per step,
``{"time": ..., "state": {"x": ...}, "var": {"x": ...}, "nis": ..., "dof": ...,
"flags": [...]}`` with ``null`` for a NaN NIS.  Numbers are written with
``repr``: the shortest text that reads back to the same float.
"""

from __future__ import annotations

import json
import math
from typing import Sequence, TextIO

import numpy as np

from .blocks import EstimateBlock
from .tracker import Estimate

__all__ = ["EstimateWriter", "CsvEstimateWriter", "JsonlEstimateWriter", "make_writer", "OUTPUT_FORMATS"]

OUTPUT_FORMATS = ("csv", "jsonl")


class EstimateWriter:
    """Writes estimates to a text stream; ``flush_each`` flushes after every row."""

    def __init__(self, stream: TextIO, labels: Sequence[str], flush_each: bool = False):
        self.stream = stream
        self.labels = tuple(labels)
        self.flush_each = flush_each
        self._started = False

    def start(self) -> None:
        """Write the header (if the format has one)."""
        self._started = True

    def write(self, est: Estimate) -> None:
        """Write one estimate."""
        if not self._started:
            self.start()
        self.stream.write(self._format(est))
        if self.flush_each:
            self.stream.flush()

    def write_block(self, block: EstimateBlock) -> None:
        """Write a block of estimates: the same text as :meth:`write` on each, in one string operation."""
        if not self._started:
            self.start()
        self.stream.write(self._format_block(block))
        if self.flush_each:
            self.stream.flush()

    def _format(self, est: Estimate) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def _format_block(self, block: EstimateBlock) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def _cells(self, block: EstimateBlock, nis: list) -> list:
        """The block's row values in row order: time, mean, var, ``nis`` (given), dof, flags (Python objects)."""
        n, d = block.means.shape
        cells = np.empty((n, 2 * d + 4), dtype=object)
        cells[:, 0] = block.times.tolist()  # tolist(): Python floats, whose %r is repr (the shortest round-trip text)
        cells[:, 1 : d + 1] = block.means.tolist()
        cells[:, d + 1 : 2 * d + 1] = block.var.tolist()
        cells[:, 2 * d + 1] = nis
        cells[:, 2 * d + 2] = block.dof
        cells[:, 2 * d + 3] = self._flag_texts(block.flags)
        return cells.ravel().tolist()

    def _flag_texts(self, flags: list[tuple[str, ...]]) -> list[str]:  # pragma: no cover - abstract
        raise NotImplementedError


class CsvEstimateWriter(EstimateWriter):
    """CSV with a header line."""

    def start(self) -> None:
        cols = ["time", *self.labels, *(f"var_{lbl}" for lbl in self.labels), "nis", "dof", "flags"]
        self.stream.write(",".join(cols) + "\n")
        if self.flush_each:
            self.stream.flush()
        self._started = True

    def _format(self, est: Estimate) -> str:
        # tolist() gives Python floats, whose repr is the shortest round-trip text (NumPy scalars print otherwise)
        nums = [float(est.time), *est.mean.tolist(), *est.var.tolist(), float(est.nis)]
        return ",".join([*map(repr, nums), str(est.dof), ";".join(est.flags)]) + "\n"

    def _format_block(self, block: EstimateBlock) -> str:
        # one format string for the block: %r of a Python float is its repr, as in _format
        d = len(self.labels)
        row = "%r," * (2 * d + 2) + "%d,%s\n"
        return (row * len(block)) % tuple(self._cells(block, block.nis.tolist()))

    def _flag_texts(self, flags: list[tuple[str, ...]]) -> list[str]:
        return [";".join(f) for f in flags]


class JsonlEstimateWriter(EstimateWriter):
    """One JSON object per line."""

    def _format(self, est: Estimate) -> str:
        obj = {
            "time": est.time,
            "state": dict(zip(self.labels, est.mean.tolist())),
            "var": dict(zip(self.labels, est.var.tolist())),
            "nis": est.nis if math.isfinite(est.nis) else None,
            "dof": est.dof,
            "flags": list(est.flags),
        }
        return json.dumps(obj, allow_nan=False) + "\n"

    def _format_block(self, block: EstimateBlock) -> str:
        # json.dumps writes a float with float.__repr__ and a key with its escapes: the same text as _format
        keys = [json.dumps(lbl) for lbl in self.labels]
        state = ", ".join(f"{k}: %r" for k in keys)
        row = '{"time": %r, "state": {' + state + '}, "var": {' + state + '}, "nis": %s, "dof": %d, "flags": %s}\n'
        nis = [repr(v) if math.isfinite(v) else "null" for v in block.nis.tolist()]
        return (row * len(block)) % tuple(self._cells(block, nis))

    def _flag_texts(self, flags: list[tuple[str, ...]]) -> list[str]:
        return [json.dumps(list(f)) for f in flags]


def make_writer(fmt: str, stream: TextIO, labels: Sequence[str], flush_each: bool = False) -> EstimateWriter:
    """A writer for ``fmt`` (``"csv"`` or ``"jsonl"``)."""
    if fmt == "csv":
        return CsvEstimateWriter(stream, labels, flush_each)
    if fmt == "jsonl":
        return JsonlEstimateWriter(stream, labels, flush_each)
    raise ValueError(f"format: must be one of {', '.join(OUTPUT_FORMATS)}, got {fmt!r}")
