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

    def _format_block(self, block: EstimateBlock) -> str:
        """The block's rows: one ``%`` per run of rows alike in everything but their floats (usually the whole block).

        The floats of a row (time, mean, variances, NIS) come from one array's
        ``tolist()``, so ``%r`` writes each as ``repr`` of a Python float, the
        text :meth:`_format` writes; what else a row holds (dof, flags, and in
        JSON Lines whether the NIS is ``null``) is written into the run's row
        format as text.  A column that mostly repeats its value from row to row
        (the variances of a filter whose covariance has converged) is written
        as text made once per run of equal bits (:func:`_repeated_as_text`).
        """
        n = len(block)
        if n == 0:
            return ""
        floats = np.column_stack([block.times, block.means, block.var, block.nis]).astype(float, copy=False)
        per_row = floats.shape[1]
        flat = floats.ravel().tolist()
        codes = tuple(_repeated_as_text(floats, j, flat) for j in range(per_row))
        keys = self._row_keys(block)
        rows: dict = {}
        parts = []
        for start, stop in _runs(keys):
            key = keys[start]
            row = rows.get(key)
            if row is None:
                row = rows[key] = self._row_format(codes, *key)
            parts.append((row * (stop - start)) % tuple(flat[start * per_row : stop * per_row]))
        return "".join(parts)

    def _row_keys(self, block: EstimateBlock) -> list[tuple]:
        """Per row, what :meth:`_row_format` needs: ``(dof, flags)``."""
        return list(zip(block.dof, block.flags))

    def _row_format(self, codes: tuple[str, ...], dof: int, flags: tuple[str, ...], *rest) -> str:  # pragma: no cover - abstract
        """A ``%`` format of one row that takes its floats (time, mean, variances, NIS) in that order.

        ``codes`` holds the conversion of each float: ``"%r"``, or ``"%s"`` where the block gives it as its text.
        """
        raise NotImplementedError


def _runs(keys: list) -> list[tuple[int, int]]:
    """``(start, stop)`` of each run of equal consecutive keys."""
    if not keys:
        return []
    if keys.count(keys[0]) == len(keys):  # the usual block: one run (count compares in C)
        return [(0, len(keys))]
    cuts = [i for i in range(1, len(keys)) if keys[i] != keys[i - 1]]
    return list(zip([0, *cuts], [*cuts, len(keys)]))


def _repeated_as_text(floats: np.ndarray, j: int, flat: list) -> str:
    """Column ``j``'s conversion code: ``"%s"`` after putting its text into ``flat`` when it mostly repeats, else ``"%r"``.

    ``repr`` of a float is most of a block's time; a column whose value stays
    the same over runs of rows (compared by bits, so -0.0 and 0.0 are not
    merged) gets ``repr`` once per run instead of once per row, the same text.
    """
    n, per_row = floats.shape
    col = floats[:, j]
    bits = col.view(np.int64)
    starts = np.flatnonzero(bits[1:] != bits[:-1]) + 1
    if 4 * len(starts) >= n:  # mostly changing: %r of each
        return "%r"
    starts = np.concatenate([[0], starts])
    words = np.array([repr(v) for v in col[starts].tolist()], dtype=object)
    flat[j::per_row] = np.repeat(words, np.diff(np.append(starts, n))).tolist()
    return "%s"


def _literal(text: str) -> str:
    """``text`` as it must stand in a ``%`` format to come out unchanged."""
    return text.replace("%", "%%")


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

    def _row_format(self, codes: tuple[str, ...], dof: int, flags: tuple[str, ...], *rest) -> str:
        # %r of a Python float is its repr, as in _format; dof and flags as _format writes them
        return "".join(code + "," for code in codes) + _literal(f"{dof},{';'.join(flags)}\n")


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

    def _row_keys(self, block: EstimateBlock) -> list[tuple]:
        """Per row ``(dof, flags, whether the NIS is finite)``: a NaN NIS is written ``null``."""
        return list(zip(block.dof, block.flags, np.isfinite(block.nis).tolist()))

    def _row_format(self, codes: tuple[str, ...], dof: int, flags: tuple[str, ...], *rest) -> str:
        # json.dumps writes a float with float.__repr__ and a key with its escapes: the same text as _format;
        # "%.0s" takes a NaN NIS and writes nothing of it
        (finite_nis,) = rest
        d = len(self.labels)
        keys = [_literal(json.dumps(lbl)) for lbl in self.labels]
        state = ", ".join(f"{k}: {c}" for k, c in zip(keys, codes[1 : d + 1]))
        var = ", ".join(f"{k}: {c}" for k, c in zip(keys, codes[d + 1 : 2 * d + 1]))
        nis = codes[-1] if finite_nis else "null%.0s"
        tail = _literal(f', "dof": {dof}, "flags": {json.dumps(list(flags))}}}\n')
        return '{"time": ' + codes[0] + ', "state": {' + state + '}, "var": {' + var + '}, "nis": ' + nis + tail


def make_writer(fmt: str, stream: TextIO, labels: Sequence[str], flush_each: bool = False) -> EstimateWriter:
    """A writer for ``fmt`` (``"csv"`` or ``"jsonl"``)."""
    if fmt == "csv":
        return CsvEstimateWriter(stream, labels, flush_each)
    if fmt == "jsonl":
        return JsonlEstimateWriter(stream, labels, flush_each)
    raise ValueError(f"format: must be one of {', '.join(OUTPUT_FORMATS)}, got {fmt!r}")
