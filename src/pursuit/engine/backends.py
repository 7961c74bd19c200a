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
  restarted and every chunk without a result is computed again.  Workers
  end when this process ends, however it ends (even by SIGKILL), and are
  stopped at once when the computation is interrupted.
* :class:`Dask`: a ``dask.distributed`` cluster at ``tcp://HOST:PORT`` (or a
  ``Client`` you already have).  Needs the optional extra
  ``pursuit[distributed]``.  When a worker dies, the scheduler gives its
  chunks to another worker; when the cluster has had no worker at all for
  ``worker_timeout`` seconds, :class:`WorkerLost`.

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
import multiprocessing.connection
import os
import signal
import threading
import time
import uuid
import warnings
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
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


def _worker_init() -> None:
    """Worker initializer: leave Ctrl-C to the parent; end as soon as the parent has ended.

    Ctrl-C in a terminal sends SIGINT to the whole process group: the parent
    stops the workers itself (:meth:`LocalProcesses.terminate`), so a worker
    ignores it rather than print a ``KeyboardInterrupt`` traceback of its own.

    A parent that is killed (SIGKILL, or any signal it cannot clean up after)
    cannot stop its workers, and a worker blocked on the pool's queue would
    wait forever (it holds both ends of the queue's pipe).  The sentinel
    ``multiprocessing`` gives each child becomes readable when the parent's
    end closes, which happens however the parent ends.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = multiprocessing.parent_process()
    if parent is None or parent.sentinel is None:  # pragma: no cover - not started by multiprocessing
        return

    def watch() -> None:
        multiprocessing.connection.wait([parent.sentinel])
        os._exit(1)

    threading.Thread(target=watch, name="pursuit-exit-with-parent", daemon=True).start()


# How long a worker asked to stop (SIGTERM) may take before it is killed.
_TERMINATE_GRACE_S = 2.0


_HELD_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


@contextlib.contextmanager
def _signals_held_back():
    """Hold SIGINT, SIGTERM and SIGHUP back while a worker starts, then hand them to their handlers.

    ``start`` sends the forkserver the request and the pickled process, then
    reads the new pid.  A signal handler that raises in between (Ctrl-C, the
    CLI's SIGTERM and SIGHUP handlers) left a child whose pid no one knew: it
    went on starting after the parent had removed its queues' semaphores and
    printed a ``FileNotFoundError`` traceback under ``pursuit: stopped by
    SIGTERM`` (CI caught it once).  Here such a signal is only recorded; when
    ``start`` has returned (the pid known, so :meth:`LocalProcesses.terminate`
    stops that worker too), the handlers are put back and each recorded
    signal goes, once, to its handler, which raises where it would have; so
    also when ``start`` fails (the forkserver, in the same process group,
    may have died of the same Ctrl-C), with that failure as the context.
    Python handlers run in the main thread only, so elsewhere nothing is
    changed.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    saved = {s: signal.getsignal(s) for s in _HELD_SIGNALS}
    swapped: list[int] = []
    try:
        for s, h in saved.items():
            if callable(h):  # Python handlers; SIG_DFL, SIG_IGN and C handlers are left alone
                signal.signal(s, lambda signum, frame: caught.append(signum))
                swapped.append(s)
        yield
    except BaseException:
        # start failed (the forkserver, in the same process group, may have died of the same Ctrl-C): the
        # signal still goes to its handler, which raises as it would have, the failure as its context
        _put_back(saved, swapped)
        _replay(saved, caught)
        raise
    _put_back(saved, swapped)
    _replay(saved, caught)


def _put_back(saved: dict[int, Any], swapped: list[int]) -> None:
    for s in swapped:
        signal.signal(s, saved[s])


def _replay(saved: dict[int, Any], caught: list[int]) -> None:
    """Hand each recorded signal, once and in order, to the handler it was held back from."""
    for s in dict.fromkeys(caught):
        saved[s](s, None)


class _IgnoresCtrlC:
    """A worker process that ignores SIGINT from the first line of its bootstrap.

    Ctrl-C in a terminal reaches every process of the group.  A worker
    ignores it from its initializer on (:func:`_worker_init`), but one still
    in ``multiprocessing``'s bootstrap would print a ``KeyboardInterrupt``
    traceback of its own.  Set first thing in ``_bootstrap``, no such window
    is left with ``forkserver``: a SIGINT before it ends the child before the
    bootstrap's traceback printer is entered, and the forkserver's own code
    exits on it silently.  With ``spawn`` (where there is no forkserver, e.g.
    Windows), a SIGINT during the new interpreter's start-up can still print
    one.  Only pursuit's workers are this class; other processes of the same
    forkserver (the user's) keep Python's default.
    """

    def _bootstrap(self, *args: Any, **kwargs: Any) -> int:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        return super()._bootstrap(*args, **kwargs)  # type: ignore[misc]


class _SpawnWorker(_IgnoresCtrlC, multiprocessing.context.SpawnProcess):
    pass


_WORKER_CLASSES: dict[type, type] = {multiprocessing.context.SpawnProcess: _SpawnWorker}
if hasattr(multiprocessing.context, "ForkServerProcess"):  # POSIX

    class _ForkServerWorker(_IgnoresCtrlC, multiprocessing.context.ForkServerProcess):
        def start(self) -> None:
            with _signals_held_back():
                super().start()

    _WORKER_CLASSES[multiprocessing.context.ForkServerProcess] = _ForkServerWorker


class _RecordingContext:
    """A multiprocessing context that remembers every process it makes, before it starts.

    ``concurrent.futures`` starts a worker and only then enters it in its
    table; a signal in between leaves a running child that the table misses,
    and exiting would wait for it for ever (multiprocessing joins its
    children).  The pool makes its workers through this context, so they
    are all known, and no other child of this process (another pool's, the
    user's) is ever taken for one.
    """

    def __init__(self, ctx: multiprocessing.context.BaseContext):
        self._ctx = ctx
        self.made: list = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ctx, name)

    def Process(self, *args: Any, **kwargs: Any) -> Any:  # noqa: N802 - the context's own name
        cls = _WORKER_CLASSES.get(self._ctx.Process, self._ctx.Process)  # pursuit's workers ignore Ctrl-C at once
        proc = cls(*args, **kwargs)
        self.made.append(proc)
        return proc

    def started(self) -> list:
        """The processes made here that were started (a pid) and are not yet reaped."""
        return [p for p in self.made if p.pid is not None and p.exitcode is None]


def _close_result_writer(pool: ProcessPoolExecutor) -> None:
    """Close this process's write end of the pool's result pipe, after the workers were stopped.

    A worker stopped while it was sending a result (a chunk's arrays are
    megabytes, written in pieces) leaves the pool's own thread reading the
    rest of that message for ever: this process holds the pipe's write end
    too, so no end of file comes, and ``shutdown(wait=True)`` then waits for
    that thread for ever (seen as a SIGHUP that never ended ``pursuit run
    --workers 2``, about 1 time in 40-150).  The parent never writes to it,
    and no worker is started again, so closing it turns the wait into an end
    of file once the workers' copies are closed (they exit): the thread
    marks the pool broken and exits.  A private attribute of
    ``concurrent.futures`` (CPython 3.11-3.13); a no-op where it is absent.
    """
    writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
    if writer is not None:
        writer.close()


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
        self._context: _RecordingContext | None = None

    def _executor(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._context = _RecordingContext(_mp_context())
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers, mp_context=self._context, initializer=_worker_init
            )
        return self._pool

    def _discard(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def terminate(self) -> None:
        """Stop the worker processes now, without waiting for the chunks they compute.

        Used when the computation is abandoned (Ctrl-C, SIGTERM, an error):
        a graceful shutdown would wait for every running chunk.
        """
        pool, self._pool = self._pool, None
        if pool is None:
            return
        # Every worker the pool made, listed in its table or not (a signal between a start and the listing)
        procs = self._context.started() if self._context is not None else []
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.join(_TERMINATE_GRACE_S)
            if proc.is_alive():
                proc.kill()
                proc.join(_TERMINATE_GRACE_S)
        # Unconditionally: a worker the forkserver has not yet reported dead still reads as alive here, and
        # any worker that is alive keeps its own copy of the write end (the parent never writes to it).
        _close_result_writer(pool)
        pool.shutdown(wait=True, cancel_futures=True)

    def map_chunks(self, task, spans, on_result, **serial_kwargs) -> None:
        finished: set[Span] = set()
        todo = [tuple(s) for s in spans]
        breaks = 0

        def deliver(fut: Future, span: Span) -> None:
            if span not in finished:  # once per chunk, whatever happened to the pool
                finished.add(span)
                on_result(span, fut.result())

        while todo:
            futures: dict[Future, Span] = {}
            broken = False
            try:
                pool = self._executor()
                # Inside the try: a signal while the workers start must stop the ones already started.
                with _one_thread_per_worker():  # processes (and the forkserver) start inside submit
                    futures.update((pool.submit(task, *span), span) for span in todo)
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
                # An error in a chunk, Ctrl-C, SIGTERM: the other chunks are of no use, so stop the workers
                # instead of waiting for them.  (Not fut.cancel(): Python 3.11's pool then fails in its own
                # thread with InvalidStateError when the workers are stopped.)
                self.terminate()
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
                raise WorkerLost(
                    f"local worker processes died {breaks} times (at most {self.max_restarts} restarts); "
                    f"{len(todo)} chunk(s) left uncomputed"
                )
            warnings.warn(
                f"a worker process died; computing {len(todo)} chunk(s) again (restart {breaks} of at most {self.max_restarts})",
                WorkerRestart,
                stacklevel=2,
            )

    def describe(self) -> dict[str, Any]:
        return {"backend": "processes", "workers": self.workers}

    def close(self) -> None:
        self._discard()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        else:  # the work is abandoned: chunks still running are of no use
            self.terminate()


def _import_distributed():
    try:
        import distributed
    except ImportError:  # pragma: no cover - exercised only without the extra
        raise ImportError(
            "a Dask scheduler needs dask.distributed: pip install 'pursuit[distributed]'"
        ) from None
    return distributed


# How often the Dask backend looks at the cluster while it waits for chunks, and how long one look may take.
_DASK_POLL_S = 1.0
_DASK_ASK_TIMEOUT_S = 10.0


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
    worker_timeout
        Seconds the cluster may have no worker (all died, none started, or
        the scheduler cannot be reached) while chunks are left, before
        :class:`WorkerLost` is raised (default 60; None: wait for workers
        forever).  Workers that join within it pick the chunks up.

    Notes
    -----
    Each chunk is one task.  The reduction of a chunk (in summary mode) runs
    inside the task, so only the small reduced result travels back.  When a
    worker dies, the scheduler reschedules its tasks on the remaining workers
    (up to ``distributed.scheduler.allowed-failures`` times per task, 3 by
    default; past that, :class:`WorkerLost`).  The workers need pursuit
    installed (same version), and any user-defined model must be importable
    there.
    """

    def __init__(
        self,
        address: str | None = None,
        *,
        client: Any = None,
        timeout: float = 30.0,
        wait_timeout: float | None = None,
        worker_timeout: float | None = 60.0,
    ):
        distributed = _import_distributed()
        if (address is None) == (client is None):
            raise ValueError("give either a scheduler address or a client")
        if worker_timeout is not None and not worker_timeout > 0:
            raise ValueError(f"worker_timeout: must be a number of seconds > 0, got {worker_timeout!r}")
        self.address = address
        self.wait_timeout = wait_timeout
        self.worker_timeout = worker_timeout
        self._own = client is None
        if client is None:
            try:
                client = distributed.Client(address, timeout=timeout, set_as_default=False)
            except OSError as e:
                raise ConnectionError(f"--scheduler {address}: cannot connect ({e})") from None
        self.client = client

    def _where(self) -> str:
        return self.address or getattr(self.client.scheduler, "address", None) or "the scheduler"

    def _workers_now(self) -> int:
        """How many workers the scheduler has now (0 when it cannot be asked within a few seconds)."""
        try:
            info = self.client.sync(self.client.scheduler.identity, n_workers=0, callback_timeout=_DASK_ASK_TIMEOUT_S)
        except Exception:  # connection closed, refused, timed out: no worker can deliver either
            return 0
        return int(info.get("n_workers", len(info.get("workers", ()))))

    def map_chunks(self, task, spans, on_result, **serial_kwargs) -> None:
        distributed = _import_distributed()
        token = uuid.uuid4().hex[:12]
        futures = {
            self.client.submit(task, s, e, key=f"pursuit-chunk-{token}-{s}-{e}", pure=False): (s, e) for s, e in spans
        }
        finished: set[Span] = set()
        start = time.monotonic()
        no_workers_since: float | None = None
        try:
            while futures:
                # Wait a short while at a time: a cluster whose workers are all gone never completes
                # or fails a task, so the wait itself has to look at the cluster (below).
                try:
                    with self.client.as_current():  # distributed.wait uses the current client
                        done, _ = distributed.wait(list(futures), timeout=_DASK_POLL_S, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done = set()
                for fut in done:
                    span = futures.pop(fut)
                    result = fut.result()
                    fut.release()
                    if span not in finished:
                        finished.add(span)
                        on_result(span, result)
                    del result
                if done or not futures:
                    continue
                now = time.monotonic()
                if self.wait_timeout is not None and now - start > self.wait_timeout:
                    raise TimeoutError(
                        f"Dask cluster at {self._where()}: {len(futures)} chunk(s) not finished within {self.wait_timeout:g} s"
                    )
                if self.worker_timeout is None:
                    continue
                if self._workers_now() > 0:
                    no_workers_since = None
                elif no_workers_since is None:
                    no_workers_since = now
                elif now - no_workers_since >= self.worker_timeout:
                    raise WorkerLost(
                        f"the Dask cluster at {self._where()} has had no worker for {self.worker_timeout:g} s "
                        f"(all died, none started, or the scheduler is unreachable); {len(futures)} chunk(s) left "
                        "uncomputed (wait longer with --worker-timeout)"
                    )
        except distributed.KilledWorker as e:
            raise WorkerLost(f"Dask workers died while computing a chunk too often: {e}") from None
        except CancelledError:  # the scheduler dropped the task (it restarted, or the client reconnected)
            raise WorkerLost(
                f"the Dask cluster at {self._where()} lost a chunk (the scheduler restarted or the connection dropped); "
                f"{len(futures) + 1} chunk(s) left uncomputed"
            ) from None
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


def make_backend(workers: int | None = None, scheduler: str | None = None, worker_timeout: float | None = None) -> Backend:
    """The backend for ``--workers`` / ``--scheduler`` (neither: :class:`Serial`).

    ``worker_timeout`` (``--worker-timeout``) is :class:`Dask`'s; None keeps its default.
    """
    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    if worker_timeout is not None and scheduler is None:
        raise ValueError("--worker-timeout applies to --scheduler only")
    if scheduler is not None:
        if "://" not in scheduler:
            raise ValueError(f"--scheduler: expected an address like tcp://HOST:PORT, got {scheduler!r}")
        if worker_timeout is None:
            return Dask(scheduler)
        if not worker_timeout > 0:  # also nan
            raise ValueError(f"--worker-timeout: must be a number of seconds > 0, got {worker_timeout}")
        return Dask(scheduler, worker_timeout=worker_timeout)
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

