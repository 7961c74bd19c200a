"""Whole tasks (such as experiments) side by side in local worker processes.

:mod:`pursuit.engine.backends` spreads the *chunks of runs* of one Monte
Carlo comparison; this module spreads *independent tasks*, each computed
whole in one worker (``pursuit reproduce all --workers N`` runs one
experiment per worker).  A task computes exactly what it computes in the
parent: each experiment's runs are computed in that worker as they would be
serially, so its files are the same bits.

The tasks run on the chunk pool (:class:`~pursuit.engine.backends.LocalProcesses`:
``forkserver`` where it exists, one thread per worker, Ctrl-C left to the
parent, workers ending with the parent, a dead worker's task computed again).
"""

from __future__ import annotations

import os
from typing import Any, Callable, Sequence

from .backends import LocalProcesses

__all__ = ["cpu_count", "parse_workers", "run_tasks"]


def cpu_count() -> int:
    """The cores this process may run on (its CPU affinity where the system has one), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - no sched_getaffinity (macOS, Windows)
        return max(1, os.cpu_count() or 1)


def parse_workers(text: str) -> int:
    """``--workers``: a whole number, or ``auto`` for :func:`cpu_count`.

    The number is returned as given (the command checks that it is at least 1,
    naming the flag), so ``0`` reaches that check rather than failing here.

    Raises
    ------
    ValueError
        Naming ``--workers`` when ``text`` is neither an integer nor ``auto``.
    """
    word = str(text).strip()
    if word.lower() == "auto":
        return cpu_count()
    try:
        return int(word)
    except ValueError:
        raise ValueError(f"--workers: expected a whole number or 'auto', got {text!r}") from None


class _Task:
    """``task(start, stop)`` for :meth:`LocalProcesses.map_chunks`: the task ``start`` of a list (``stop`` is ``start + 1``)."""

    def __init__(self, fn: Callable[..., Any], args: Sequence[tuple]):
        self.fn, self.args = fn, [tuple(a) for a in args]

    def __call__(self, start: int, stop: int) -> Any:
        return self.fn(*self.args[start])


def run_tasks(
    fn: Callable[..., Any],
    args: Sequence[tuple],
    workers: int,
    on_result: Callable[[int, Any], None],
    *,
    first: Sequence[int] | None = None,
) -> None:
    """Compute ``fn(*args[i])`` for every i in ``workers`` processes; call ``on_result(i, result)`` as each ends.

    The tasks go through the chunk pool (:class:`~pursuit.engine.backends.LocalProcesses`),
    so they get its handling of Ctrl-C, SIGTERM and dead workers (a task whose
    worker died is computed again).

    Parameters
    ----------
    fn
        A picklable (module-level) function.
    args
        One argument tuple per task.
    workers
        Processes (at least 1; 1 computes in this process, in order).
    on_result
        Called in this process once per task, in the order the tasks end.
    first
        Task indices in the order they are started (default: as given).  On
        a few cores the costliest task should start first, or it ends alone
        after the others.

    Raises
    ------
    ValueError
        Naming ``workers`` or ``first`` when they are not what is described above.
    Exception
        A task's exception, re-raised here (the other workers are stopped).
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: must be a positive integer, got {workers!r}")
    order = list(range(len(args))) if first is None else [int(i) for i in first]
    if sorted(order) != list(range(len(args))):
        raise ValueError(f"first: expected an order of the task indices 0 .. {len(args) - 1}, got {order}")
    task = _Task(fn, args)
    if workers == 1 or len(args) <= 1:
        for i in order:
            on_result(i, task(i, i + 1))
        return
    pool = LocalProcesses(min(workers, len(args)))
    try:
        pool.map_chunks(task, [(i, i + 1) for i in order], lambda span, result: on_result(span[0], result))
    finally:
        pool.close()
