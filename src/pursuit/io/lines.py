"""Lines of a live input, read in chunks: what has arrived, without a system call per line.

``iter(fh.readline, b"")`` costs a buffered read per line; :class:`ChunkedLines`
reads whatever the input has at hand (``read1``: it waits only when nothing
has arrived), splits it at ``\\n`` exactly as ``readline`` does, and keeps
the unfinished last line for the next chunk.  :meth:`ChunkedLines.ready`
tells a consumer whether a line is at hand without waiting (so
:func:`pursuit.io.tracker.stream_records` can end a block of steps there),
and ``before_wait`` runs each time the reader is about to wait for more
input (``pursuit track --stream`` flushes its output there: every estimate
written is flushed before the process could block).  :meth:`ChunkedLines.chunks`
gives the same lines as lists of what one read brought, for readers that parse
a chunk at once (:func:`pursuit.io.records.read_record_chunks`).
"""

from __future__ import annotations

from collections import deque
from typing import BinaryIO, Callable, Iterator

__all__ = ["ChunkedLines", "CHUNK_BYTES", "INPUT_WAITS"]


class _InputWaits:
    """The type of :data:`INPUT_WAITS`."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "INPUT_WAITS"


INPUT_WAITS = _InputWaits()
"""Marks the place in a live input where taking the next record would wait for more input (also :data:`pursuit.io.steps.INPUT_WAITS`)."""

CHUNK_BYTES = 1 << 16


class ChunkedLines:
    """The lines (bytes, each with its ``\\n``; the last may lack one) of a binary input.

    Parameters
    ----------
    fh
        A binary file object (standard input, a pipe, a file).
    before_wait
        Called before each read that may wait for input (an attribute: it may
        be set later).
    chunk
        The most bytes one read takes (default :data:`CHUNK_BYTES`).
    """

    def __init__(self, fh: BinaryIO, before_wait: Callable[[], None] | None = None, chunk: int | None = None):
        chunk = CHUNK_BYTES if chunk is None else chunk
        if chunk < 1:
            raise ValueError(f"chunk: must be a positive number of bytes, got {chunk!r}")
        self._fh = fh
        self._read = getattr(fh, "read1", None) or fh.read
        self.before_wait = before_wait
        self._chunk = chunk
        self._lines: deque[bytes] = deque()
        self._tail: list[bytes] = []  # the unfinished line, in pieces (a long one is not copied per chunk)
        self._ended = False

    def ready(self) -> bool:
        """Whether the next line is at hand (or the input has ended): taking it does not wait."""
        return bool(self._lines) or self._ended

    def _fill(self) -> None:
        while not self._lines and not self._ended:
            if self.before_wait is not None:
                self.before_wait()
            data = self._read(self._chunk)
            if not data:
                self._ended = True
                if self._tail:
                    self._lines.append(b"".join(self._tail))  # the last line, without its newline
                    self._tail = []
                return
            if b"\n" not in data:
                self._tail.append(data)
                continue
            parts = data.split(b"\n")
            if self._tail:
                parts[0] = b"".join([*self._tail, parts[0]])
            tail = parts.pop()
            self._tail = [tail] if tail else []
            self._lines.extend(p + b"\n" for p in parts)

    def chunks(self) -> Iterator[list[bytes]]:
        """The lines in lists: each list is every line at hand (one read's worth), waiting only when none is."""
        lines = self._lines
        while True:
            if not lines:
                self._fill()
                if not lines:
                    return
            batch = list(lines)
            lines.clear()
            yield batch

    def __iter__(self) -> Iterator[bytes]:
        lines = self._lines
        while True:
            if not lines:
                self._fill()
                if not lines:
                    return
            yield lines.popleft()
