"""Imported first by the ``forkserver`` that starts pursuit's worker processes: it ignores SIGINT.

Ctrl-C in a terminal sends SIGINT to the whole process group, workers
included.  A worker ignores it from its initializer on
(:func:`pursuit.engine.backends._worker_init`), but a worker forked a moment
before is still in ``multiprocessing``'s bootstrap with Python's default
handler and prints a ``KeyboardInterrupt`` traceback of its own.  The
forkserver hands each forked child the SIGINT handler it had when it started
serving, which is this module's ``SIG_IGN``: workers ignore Ctrl-C from their
first instruction, and the parent alone stops them.

This module is light on purpose (``pursuit/__init__`` imports nothing
eagerly): it is listed first in the forkserver's preload list, so the window
before SIGINT is ignored is the interpreter's own start-up.  It acts only in
the forkserver process (started as ``python -c 'from multiprocessing.forkserver
import main; ...'``), never in a process that imports it by mistake.
"""

from __future__ import annotations

import signal
import sys


def _in_forkserver() -> bool:
    """Whether this process is a ``multiprocessing`` forkserver (its command is ``-c``, its server imported)."""
    return sys.argv[:1] == ["-c"] and "multiprocessing.forkserver" in sys.modules


if _in_forkserver():
    signal.signal(signal.SIGINT, signal.SIG_IGN)
