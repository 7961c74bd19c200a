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

    def _format(self, est: Estimate) -> str:  # pragma: no cover - abstract
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


def make_writer(fmt: str, stream: TextIO, labels: Sequence[str], flush_each: bool = False) -> EstimateWriter:
    """A writer for ``fmt`` (``"csv"`` or ``"jsonl"``)."""
    if fmt == "csv":
        return CsvEstimateWriter(stream, labels, flush_each)
    if fmt == "jsonl":
        return JsonlEstimateWriter(stream, labels, flush_each)
    raise ValueError(f"format: must be one of {', '.join(OUTPUT_FORMATS)}, got {fmt!r}")
