"""A dependency-free progress bar on standard error, silent when that is not a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress"]

LABEL_WIDTH = 36
"""Characters of the label shown (experiment, swept value and filter: ``p1-ungm N=100 ICS-PF``)."""


class Progress:
    """Count units of work and redraw one status line.

    Parameters
    ----------
    total
        Number of units expected.
    label
        Text shown before the bar.
    enabled
        Draw at all; even when True, nothing is drawn unless ``stream`` is a
        terminal, so logs and pipes stay clean.
    stream
        Where to draw (default ``sys.stderr``).
    """

    def __init__(self, total: int, label: str = "", enabled: bool = True, stream: TextIO | None = None):
        self.total = max(int(total), 1)
        self.done = 0
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", lambda: False)
        self.active = bool(enabled) and bool(isatty())
        self._start = time.monotonic()
        self._last = 0.0
        if self.active:
            self._draw()

    def advance(self, n: int = 1) -> None:
        """Record ``n`` finished units and redraw (at most ten times a second)."""
        self.done = min(self.done + n, self.total)
        now = time.monotonic()
        if self.active and (now - self._last > 0.1 or self.done == self.total):
            self._last = now
            self._draw()

    def _draw(self) -> None:
        width = 30
        frac = self.done / self.total
        filled = int(round(frac * width))
        elapsed = time.monotonic() - self._start
        eta = elapsed / frac - elapsed if frac > 0 else float("nan")
        eta_s = f"{eta:5.0f}s left" if frac > 0 and frac < 1 else f"{elapsed:5.1f}s"
        line = f"\r{self.label[:LABEL_WIDTH]:<{LABEL_WIDTH}} [{'#' * filled}{'.' * (width - filled)}] {100 * frac:5.1f}% {eta_s}"
        self.stream.write(line)
        self.stream.flush()

    def close(self) -> None:
        """End the status line."""
        if self.active:
            self._draw()
            self.stream.write("\n")
            self.stream.flush()
            self.active = False
