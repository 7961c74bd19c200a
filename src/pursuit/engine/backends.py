"""Where the chunks of a Monte Carlo comparison are computed.

A backend maps a *chunk task* (a picklable callable ``task(start, stop)``
that computes runs ``[start, stop)``) over the chunks and hands each result
to the engine (``on_result(span, result)``) as soon as it is finished, once
per chunk; the engine folds it in and drops it, so the backend holds no
results.  Because a chunk's result is a pure function
of the scenario, the filters, the root seed and the run range, where it is
computed does not change a bit of it.

* :class:`Serial`: in this process, one chunk after the other (the default;
  needs nothing beyond NumPy).
* :class:`LocalProcesses`: ``workers`` local processes
  (:mod:`concurrent.futures`).  If a worker process dies, the pool is
  restarted and every chunk without a result is computed again.
* :class:`Dask`: a ``dask.distributed`` cluster at ``tcp://HOST:PORT`` (or a
  ``Client`` you already have).  Needs the optional extra
  ``pursuit[distributed]``.  When a worker dies, the scheduler gives its
  chunks to another worker.

In every case a chunk's result is kept once: the engine checks that the
returned chunks tile the runs exactly, so no run is lost or counted twice.

The command line picks a backend with ``--workers N`` or ``--scheduler
ADDRESS``; in Python, pass ``backend=`` to
:func:`pursuit.engine.monte_carlo` or set it for a block of code (for
example around an experiment's ``run``) with :func:`engine_options`.
"""

from __future__ import annotations

import contextlib
import contextvars
import multiprocessing
import os
import uuid
import warnings
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Protocol, Sequence

from .main_guard import unguarded_main_call

__all__ = [
    "Backend",
    "Serial",
    "LocalProcesses",
    "Dask",
    "make_backend",
    "engine_options",
    "current_options",
    "EngineOptions",
    "WorkerLost",
    "MissingMainGuard",
    "WorkerRestart",
]

Span = tuple[int, int]
OnResult = Callable[[Span, Any], None]


class WorkerLost(RuntimeError):
    """Workers kept dying: a chunk could not be computed within the allowed restarts."""


class MissingMainGuard(WorkerLost):
    """The workers died starting because the ``__main__`` script starts them outside its guard."""


class WorkerRestart(UserWarning):
    """A local worker process died; its chunks are being computed again."""


class Backend(Protocol):
    """What the engine needs from a backend."""

    def map_chunks(self, task: Callable[..., Any], spans: Sequence[Span], on_result: OnResult, **serial_kwargs: Any) -> None:
        """Compute ``task(start, stop)`` for every span; call ``on_result(span, result)`` once per span as each finishes."""

    def describe(self) -> dict[str, Any]:
        """A JSON-able description for the output's sidecar."""

    def close(self) -> None:
        """Release processes or connections."""


class Serial:
    """Every chunk in this process, in order.

    Keyword arguments to :meth:`map_chunks` beyond ``on_done`` are passed to
    the task (the engine passes a per-filter progress hook this way; other
    backends cannot call back into this process mid-chunk).
    """

    def map_chunks(self, task, spans, on_result, **serial_kwargs) -> None:
        for span in spans:
            on_result(span, task(*span, **serial_kwargs))

    def describe(self) -> dict[str, Any]:
        return {"backend": "serial", "workers": 1}

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _mp_context() -> multiprocessing.context.BaseContext:
    """``forkserver`` where it exists (safe with threads in the parent, cheap to start), else ``spawn``."""
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    if ctx.get_start_method() == "forkserver":
        # Workers fork from a server that has imported pursuit (and NumPy) once.
        ctx.set_forkserver_preload(["pursuit.engine.montecarlo"])
    return ctx


# Each local worker computes on one core: without these, every worker's OpenBLAS (or MKL, OpenMP,
# numba) starts a thread per core, N workers oversubscribe N cores, and two workers on two cores
# measured 1.05x the in-process speed instead of 1.77x (docs/scale-out.md).  Values the user has
# set are kept.  Dask's nanny does the same for its workers.
WORKER_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


@contextlib.contextmanager
def _one_thread_per_worker():
    """Set the thread-count variables (where unset) while worker processes are started."""
    added = [name for name in WORKER_THREAD_ENV if name not in os.environ]
    for name in added:
        os.environ[name] = "1"
    try:
        yield
    finally:
        for name in added:
            os.environ.pop(name, None)


class LocalProcesses:
    """Chunks across ``workers`` local processes.

    Worker processes run their numerical libraries on one thread each
    (``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` and
    ``NUMBA_NUM_THREADS`` set to 1 unless already set in the environment),
    so ``workers`` processes use ``workers`` cores.

    Parameters
    ----------
    workers
        Number of processes (at least 1).
    max_restarts
        How many times the pool may break (a worker killed by the operating
        system, out of memory, ...) before giving up with :class:`WorkerLost`.
        After each break the chunks without a result are computed again.

    Raises
    ------
    MissingMainGuard
        From :meth:`map_chunks`, when the pool broke because the workers
        import the ``__main__`` script again and its top level, outside
        ``if __name__ == "__main__":``, starts workers itself.
    """

    def __init__(self, workers: int, *, max_restarts: int = 3):
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers: must be a positive integer, got {workers!r}")
        self.workers = workers
        self.max_restarts = int(max_restarts)
        self.restarts = 0
        self._pool: ProcessPoolExecutor | None = None

    def _executor(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=_mp_context())
        return self._pool

    def _discard(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def map_chunks(self, task, spans, on_result, **serial_kwargs) -> None:
        finished: set[Span] = set()
        todo = [tuple(s) for s in spans]
        breaks = 0

        def deliver(fut: Future, span: Span) -> None:
            if span not in finished:  # once per chunk, whatever happened to the pool
                finished.add(span)
                on_result(span, fut.result())

        while todo:
            pool = self._executor()
            with _one_thread_per_worker():  # processes (and the forkserver) start inside submit
                futures: dict[Future, Span] = {pool.submit(task, *span): span for span in todo}
            broken = False
            try:
                pending = set(futures)
                while pending and not broken:
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in done:
                        exc = fut.exception()
                        if isinstance(exc, BrokenProcessPool):
                            broken = True
                        elif exc is not None:
                            raise exc
                        else:
                            deliver(fut, futures.pop(fut))  # drop our reference: the result is the engine's now
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
            if not broken:
                return
            # Keep what finished before the break; compute the rest again on a new pool.
            for fut, span in futures.items():
                if fut.done() and not fut.cancelled() and fut.exception() is None:
                    deliver(fut, span)
            self._discard()
            unguarded = unguarded_main_call()
            if unguarded is not None:  # every new pool would break the same way: say why, now
                path, line = unguarded
                raise MissingMainGuard(
                    f"local worker processes import {path} again when they start, and its line {line} starts "
                    f"worker processes outside `if __name__ == \"__main__\":`, so every worker died starting; "
                    "put the script's top-level code under that guard (docs/scale-out.md)"
                )
            breaks += 1
            self.restarts += 1
            todo = [s for s in todo if s not in finished]
            if breaks > self.max_restarts:
                raise WorkerLost(f"local worker processes died {breaks} times; {len(todo)} chunk(s) left uncomputed")
            warnings.warn(f"a worker process died; computing {len(todo)} chunk(s) again", WorkerRestart, stacklevel=2)

    def describe(self) -> dict[str, Any]:
        return {"backend": "processes", "workers": self.workers}

    def close(self) -> None:
        self._discard()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _import_distributed():
    try:
        import distributed
    except ImportError:  # pragma: no cover - exercised only without the extra
        raise ImportError(
            "a Dask scheduler needs dask.distributed: pip install 'pursuit[distributed]'"
        ) from None
    return distributed


class Dask:
    """Chunks on a ``dask.distributed`` cluster.

    Parameters
    ----------
    address
        Scheduler address, e.g. ``tcp://10.0.0.5:8786``; or None with
        ``client``.
    client
        An existing ``distributed.Client`` (not closed by :meth:`close`).
    timeout
        Seconds to wait for the scheduler when connecting.
    wait_timeout
        Seconds to wait for all chunks of one comparison (None: no limit);
        past it, :class:`TimeoutError`.

    Notes
    -----
    Each chunk is one task.  The reduction of a chunk (in summary mode) runs
    inside the task, so only the small reduced result travels back.  When a
    worker dies, the scheduler reschedules its tasks on the remaining workers
    (up to ``distributed.scheduler.allowed-failures`` times per task, 3 by
    default).  The workers need pursuit installed (same version), and any
    user-defined model must be importable there.
    """

    def __init__(
        self, address: str | None = None, *, client: Any = None, timeout: float = 30.0, wait_timeout: float | None = None
    ):
        distributed = _import_distributed()
        if (address is None) == (client is None):
            raise ValueError("give either a scheduler address or a client")
        self.address = address
        self.wait_timeout = wait_timeout
        self._own = client is None
        if client is None:
            try:
                client = distributed.Client(address, timeout=timeout, set_as_default=False)
            except OSError as e:
                raise ConnectionError(f"--scheduler {address}: cannot connect ({e})") from None
        self.client = client

    def map_chunks(self, task, spans, on_result, **serial_kwargs) -> None:
        distributed = _import_distributed()
        token = uuid.uuid4().hex[:12]
        futures = {
            self.client.submit(task, s, e, key=f"pursuit-chunk-{token}-{s}-{e}", pure=False): (s, e) for s, e in spans
        }
        finished: set[Span] = set()
        try:
            for fut in distributed.as_completed(list(futures), loop=self.client.loop, timeout=self.wait_timeout):
                span = futures[fut]
                result = fut.result()
                fut.release()
                del futures[fut]
                if span not in finished:
                    finished.add(span)
                    on_result(span, result)
                del result
        except distributed.KilledWorker as e:
            raise WorkerLost(f"Dask workers died while computing a chunk too often: {e}") from None
        finally:
            for fut in list(futures):
                if not fut.done():
                    fut.cancel()

    def describe(self) -> dict[str, Any]:
        try:
            info = self.client.scheduler_info(n_workers=-1)  # newer clients list only 5 workers by default
        except TypeError:
            info = self.client.scheduler_info()
        workers = info.get("workers", {})
        return {
            "backend": "dask",
            "scheduler": self.address or info.get("address"),
            "workers": len(workers),
            "threads": int(sum(w.get("nthreads", 0) for w in workers.values())),
        }

    def close(self) -> None:
        if self._own:
            self.client.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def make_backend(workers: int | None = None, scheduler: str | None = None) -> Backend:
    """The backend for ``--workers`` / ``--scheduler`` (neither: :class:`Serial`)."""
    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    if scheduler is not None:
        if "://" not in scheduler:
            raise ValueError(f"--scheduler: expected an address like tcp://HOST:PORT, got {scheduler!r}")
        return Dask(scheduler)
    if workers is not None:
        if workers < 1:
            raise ValueError(f"--workers: must be at least 1, got {workers}")
        return Serial() if workers == 1 else LocalProcesses(workers)
    return Serial()


# --------------------------------------------------------------------------
# options for a block of code
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class EngineOptions:
    """Defaults that :func:`pursuit.engine.monte_carlo` uses when its caller gives none.

    Attributes
    ----------
    backend
        Where chunks are computed (None: in this process).
    store
        ``"auto"``, ``"full"`` or ``"summary"`` (see :func:`pursuit.engine.monte_carlo`).
    keep_runs
        Example runs kept whole in summary mode.
    """

    backend: Any = None
    store: str | None = None
    keep_runs: int | None = None


_OPTIONS: contextvars.ContextVar[EngineOptions] = contextvars.ContextVar("pursuit_engine_options", default=EngineOptions())


def current_options() -> EngineOptions:
    """The options in force (set by :func:`engine_options`)."""
    return _OPTIONS.get()


@contextlib.contextmanager
def engine_options(*, backend: Any = None, store: str | None = None, keep_runs: int | None = None) -> Iterator[EngineOptions]:
    """Set the engine's backend and storage mode for every Monte Carlo run inside the block.

    Experiment kinds call :func:`pursuit.engine.monte_carlo` without knowing
    about backends; the CLI wraps ``Experiment.run`` in this context so that
    ``--workers`` and ``--scheduler`` reach every comparison the kind makes.
    """
    base = _OPTIONS.get()
    opts = EngineOptions(
        backend=base.backend if backend is None else backend,
        store=base.store if store is None else store,
        keep_runs=base.keep_runs if keep_runs is None else keep_runs,
    )
    token = _OPTIONS.set(opts)
    try:
        yield opts
    finally:
        _OPTIONS.reset(token)

