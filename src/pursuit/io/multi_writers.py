"""Writers for ``pursuit track --multi``: one row per confirmed track per scan, CSV or JSON Lines.

CSV columns: ``time``, ``label``, the state components (``x, vx, y, vy``
...) and, unless left out, the covariance diagonal (``var_x, var_vx, ...``).
JSON Lines: one object per row, ``{"time": ..., "label": ..., "state": {"x":
...}, "var": {"x": ...}}``.  Within a scan the rows come in label order.
Numbers are written with ``repr``: the shortest text that reads back to the
same float.
"""

from __future__ import annotations

import json
from typing import Sequence, TextIO

import numpy as np

__all__ = ["TrackRowWriter", "make_track_writer", "scan_rows"]


def scan_rows(mean: np.ndarray, cov: np.ndarray, label: np.ndarray, confirmed: np.ndarray) -> list[tuple[int, list[float], list[float]]]:
    """The confirmed tracks of one scan of one run as ``(label, state, variances)``, in label order.

    Parameters
    ----------
    mean, cov, label, confirmed
        ``(L, n)``, ``(L, n, n)``, ``(L,)``, ``(L,)``: one run's slots after a scan.
    """
    slots = np.nonzero(confirmed)[0]
    slots = slots[np.argsort(label[slots], kind="stable")]
    var = np.diagonal(cov[slots], axis1=-2, axis2=-1)
    return [(int(label[s]), mean[s].tolist(), v.tolist()) for s, v in zip(slots, var)]


class TrackRowWriter:
    """Writes track rows to a text stream; ``flush_each`` flushes after every scan."""

    def __init__(self, fmt: str, stream: TextIO, labels: Sequence[str], *, variances: bool = True, flush_each: bool = False):
        if fmt not in ("csv", "jsonl"):
            raise ValueError(f"format: must be csv or jsonl, got {fmt!r}")
        self.fmt, self.stream, self.labels = fmt, stream, tuple(labels)
        self.variances, self.flush_each = variances, flush_each
        self._started = False

    def start(self) -> None:
        """Write the header (CSV only); called by the first :meth:`write_scan` if not before."""
        if self.fmt == "csv":
            var = [f"var_{lbl}" for lbl in self.labels] if self.variances else []
            self.stream.write(",".join(["time", "label", *self.labels, *var]) + "\n")
        self._started = True

    def write_scan(self, time: float, rows: list[tuple[int, list[float], list[float]]]) -> None:
        """Write the rows of one scan (:func:`scan_rows`)."""
        if not self._started:
            self.start()
        self.stream.write("".join(self._format(time, *row) for row in rows))
        if self.flush_each:
            self.stream.flush()

    def _format(self, time: float, label: int, state: list[float], var: list[float]) -> str:
        if self.fmt == "csv":
            nums = [time, *state, *(var if self.variances else ())]
            return ",".join([repr(float(time)), str(label), *(repr(float(v)) for v in nums[1:])]) + "\n"
        obj: dict = {"time": float(time), "label": label, "state": dict(zip(self.labels, state))}
        if self.variances:
            obj["var"] = dict(zip(self.labels, var))
        return json.dumps(obj, allow_nan=False) + "\n"


def make_track_writer(fmt: str, stream: TextIO, labels: Sequence[str], *, variances: bool = True, flush_each: bool = False) -> TrackRowWriter:
    """A track-row writer for ``fmt`` (``"csv"`` or ``"jsonl"``)."""
    return TrackRowWriter(fmt, stream, labels, variances=variances, flush_each=flush_each)
