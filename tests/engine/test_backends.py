"""Backends: local processes give the serial bits, survive a killed worker, report progress."""

import multiprocessing
import pickle
import sys
import warnings

import numpy as np
import pytest

from pursuit.config.scenarios import _cv_position, _wsn
from pursuit.engine import monte_carlo
from pursuit.engine.backends import LocalProcesses, Serial, WorkerLost, WorkerRestart, engine_options, make_backend
from pursuit.scenarios import LinearCV, WSNRange

from ..filters.cases import CASES, NONLINEAR_CASES
from .helpers import (
    SMALL,
    Failing,
    Killer,
    KillsItsWorker,
    PauseOnce,
    Slow,
    SlowButOnce,
    assert_same_result,
    end_session,
    session_pids,
    small_filters,
    wait_until,
)

RUNS, SEED = 30, 3


@pytest.fixture(scope="module")
def serial():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=RUNS)


@pytest.fixture(scope="module")
def pool():
    with LocalProcesses(2) as backend:
        yield backend


PAIRS = (
    [(c, LinearCV(ndim=2, steps=5)) for c in CASES if c.scenario is None]
    + [(c, WSNRange(steps=5)) for c in NONLINEAR_CASES]
    + [(c, c.scenario) for c in CASES if c.scenario is not None]
)


@pytest.mark.parametrize("case, scenario", PAIRS, ids=[f"{c.id}-{type(s).__name__}" for c, s in PAIRS])
def test_filters_and_scenarios_pickle(case, scenario):
    """Backends ship scenarios and filters to other processes: they must pickle and behave the same."""
    filt = case.build(scenario)
    s2, f2 = pickle.loads(pickle.dumps((scenario, filt)))
    a = monte_carlo(scenario, [filt], 3, 1)
    b = monte_carlo(s2, [f2], 3, 1)
    assert_same_result(a, b)


def test_registered_scenarios_pickle():
    for s in (_wsn(anchors=[[0.0, 0.0], [50.0, 0.0], [0.0, 50.0]], sigma=1.0, steps=5, dt=1.0, q=0.01, noise="discrete",
                   x0=[1.0, 0.1, 2.0, 0.1], P0=[1.0, 0.1, 1.0, 0.1], prior_mean="sampled"),
              _cv_position(ndim=1, dt=1.0, q=0.1, sigma=1.0, steps=5, x0=None, P0=None, prior_mean="truth")):
        s2 = pickle.loads(pickle.dumps(s))
        assert np.array_equal(s.simulate(np.random.default_rng(0), 2).truth, s2.simulate(np.random.default_rng(0), 2).truth)


@pytest.mark.parametrize("chunk", [1, 7, 30])
def test_processes_equal_serial(serial, pool, chunk):
    got = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=chunk, backend=pool)
    assert_same_result(serial, got)


def test_processes_summary_equals_serial_full(serial, pool):
    got = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=4, backend=pool, store="summary")
    assert got.store == "summary"
    from .helpers import assert_same_summary

    assert_same_summary(serial, got)


def test_engine_options_reach_monte_carlo(serial, pool):
    with engine_options(backend=pool, store="summary", keep_runs=3):
        got = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=8)
    assert got.store == "summary" and got.stored().runs == 3
    assert monte_carlo(SMALL, small_filters(), 2, SEED).store == "full"  # the options ended with the block


def test_progress_advances_as_chunks_finish(pool):
    seen = []
    scenario = Slow(SMALL, 0.15)
    monte_carlo(scenario, small_filters(), 12, SEED, chunk_size=3, backend=pool, progress=lambda d, t: seen.append((d, t)))
    assert [d for d, _ in seen] == [2, 4, 6, 8]  # one advance of len(filters) per chunk
    assert all(t == 8 for _, t in seen)


def test_serial_progress_counts_filters():
    seen = []
    monte_carlo(SMALL, small_filters(), 6, SEED, chunk_size=3, progress=lambda d, t: seen.append(d))
    assert seen == [1, 2, 3, 4]


def test_killed_worker_chunk_is_recomputed(serial, tmp_path):
    """SIGKILL a worker in the middle of a chunk: the pool restarts and nothing is lost or doubled."""
    marker = tmp_path / "paused.pid"
    scenario = PauseOnce(SMALL, str(marker))
    killer = Killer(marker, timeout=60)
    killer.start()
    with LocalProcesses(2) as backend, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = monte_carlo(scenario, small_filters(), RUNS, SEED, chunk_size=5, backend=backend)
        restarts = backend.restarts
    killer.join(5)
    assert killer.error is None and killer.killed is not None
    assert restarts == 1
    assert any(issubclass(w.category, WorkerRestart) and "worker process died" in str(w.message) for w in caught)
    assert_same_result(serial, got)


def test_task_errors_are_raised_not_retried(pool):
    with pytest.raises(ValueError, match="deliberate failure"):
        monte_carlo(Failing(SMALL), small_filters(), 4, SEED, chunk_size=2, backend=pool)
    assert pool.restarts == 0


def test_make_backend_checks_its_arguments():
    assert isinstance(make_backend(), Serial)
    assert isinstance(make_backend(workers=1), Serial)
    with pytest.raises(ValueError, match="not both"):
        make_backend(workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ValueError, match="--workers"):
        make_backend(workers=0)
    with pytest.raises(ValueError, match="tcp://HOST:PORT"):
        make_backend(scheduler="127.0.0.1:8786")
    with pytest.raises(ValueError, match="workers"):
        LocalProcesses(0)
    with pytest.raises(ValueError, match="--worker-timeout applies to --scheduler only"):
        make_backend(workers=2, worker_timeout=5)
    for bad in (0, -1, float("nan")):
        with pytest.raises(ValueError, match=r"--worker-timeout: must be a number of seconds > 0"):
            make_backend(scheduler="tcp://127.0.0.1:1", worker_timeout=bad)


def test_progress_bar_draws_as_chunks_finish(pool, monkeypatch):
    import io
    import re
    import sys

    class FakeTerminal(io.StringIO):
        def isatty(self):
            return True

    term = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", term)
    monte_carlo(Slow(SMALL, 0.3), small_filters(), 8, SEED, chunk_size=2, backend=pool, progress=True)
    shown = [float(p) for p in re.findall(r"(\d+\.\d)%", term.getvalue())]
    assert shown[0] == 0.0 and shown[-1] == 100.0
    assert shown == sorted(shown) and len({p for p in shown if 0 < p < 100}) >= 2  # it moved in between


def _worker_thread_env(start, stop):
    import os

    from pursuit.engine.backends import WORKER_THREAD_ENV

    return {name: os.environ.get(name) for name in WORKER_THREAD_ENV}


def test_workers_compute_on_one_thread_each():
    """Worker processes get one BLAS/OpenMP/numba thread each (values the user set are kept), and the
    parent's environment is left as it was."""
    import os

    from pursuit.engine.backends import WORKER_THREAD_ENV

    before = {name: os.environ.get(name) for name in WORKER_THREAD_ENV}
    seen = []
    with LocalProcesses(1) as backend:
        backend.map_chunks(_worker_thread_env, [(0, 1)], lambda span, result: seen.append(result))
    assert seen == [{name: before[name] or "1" for name in WORKER_THREAD_ENV}]
    assert {name: os.environ.get(name) for name in WORKER_THREAD_ENV} == before


def _report_sigint_handler(queue) -> None:
    """In a child: what SIGINT does there, before any initializer of pursuit's has run."""
    import signal

    handler = signal.getsignal(signal.SIGINT)
    queue.put("ignored" if handler is signal.SIG_IGN else "default" if handler is signal.default_int_handler else repr(handler))


def _sigint_handler_of_child(ctx, make) -> str:
    queue = ctx.SimpleQueue()
    proc = make(target=_report_sigint_handler, args=(queue,))
    proc.start()
    try:
        return queue.get()
    finally:
        proc.join(30)


def test_workers_ignore_ctrl_c_from_their_first_instruction_and_other_processes_keep_it():
    """A Ctrl-C that reaches a worker still in multiprocessing's bootstrap (before ``_worker_init``) must not
    print a KeyboardInterrupt traceback (a flaky CLI test caught one): pursuit's workers ignore SIGINT from
    the first line of their bootstrap.  A process of the user's from the same start method, started after
    pursuit's, keeps Python's default handler (Ctrl-C still stops it)."""
    from pursuit.engine.backends import _mp_context, _RecordingContext

    ctx = _mp_context()
    ours = _RecordingContext(ctx)
    assert _sigint_handler_of_child(ctx, ours.Process) == "ignored"
    assert _sigint_handler_of_child(ctx, multiprocessing.get_context(ctx.get_start_method()).Process) == "default"


def test_interrupt_stops_the_workers_without_waiting_for_their_chunks(tmp_path):
    """Ctrl-C while chunks run (raised here from the progress hook, in the main thread as a signal would be):
    the workers are stopped at once, not after the 60 s their chunks still need."""
    import os
    import time

    scenario = SlowButOnce(SMALL, str(tmp_path / "first"), delay_s=60.0)
    workers: list[int] = []
    raised: list[float] = []

    def progress(done, total):
        workers.extend(backend._pool._processes)
        raised.append(time.monotonic())
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with LocalProcesses(2) as backend:
            monte_carlo(scenario, small_filters(), 8, SEED, chunk_size=2, backend=backend, progress=progress)
    assert time.monotonic() - raised[0] < 15
    assert len(workers) == 2
    for pid in workers:
        with pytest.raises(ProcessLookupError):  # ended and reaped
            os.kill(pid, 0)
    assert backend._pool is None


def test_a_signal_while_a_worker_starts_stops_that_worker_too(monkeypatch):
    """A signal between a worker's start and its entry in the pool's table (a flaky CLI test caught it):
    the unlisted worker is stopped too, else exiting would join it for ever (multiprocessing's atexit);
    a process of the user's, started while the pool lives, is left alone."""
    import multiprocessing
    import time
    from concurrent.futures.process import ProcessPoolExecutor

    before = {p.pid for p in multiprocessing.active_children()}
    spawn = ProcessPoolExecutor._spawn_process
    users = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(60,))

    def spawn_then_signal(pool):
        if not pool._processes:
            spawn(pool)
            users.start()  # the user's own process, started while the pool lives
            return
        table, pool._processes = pool._processes, {}
        try:
            spawn(pool)  # the real start, entered in a throwaway table: unlisted, as after the signal
        finally:
            pool._processes = table
        raise KeyboardInterrupt

    monkeypatch.setattr(ProcessPoolExecutor, "_spawn_process", spawn_then_signal)
    started = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            with LocalProcesses(2) as backend:
                backend.map_chunks(_worker_thread_env, [(0, 1), (1, 2)], lambda span, result: None)
        assert time.monotonic() - started < 30
        assert {p.pid for p in multiprocessing.active_children()} - before == {users.pid}
    finally:
        users.terminate()
        users.join(10)


def test_workers_that_keep_dying_end_in_worker_lost(tmp_path):
    with LocalProcesses(2, max_restarts=1) as backend, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(WorkerLost, match=r"died 2 times \(at most 1 restarts\); 2 chunk\(s\) left uncomputed"):
            monte_carlo(KillsItsWorker(SMALL), small_filters(), 4, SEED, chunk_size=2, backend=backend)
    restarts = [str(w.message) for w in caught if issubclass(w.category, WorkerRestart)]
    assert restarts == ["a worker process died; computing 2 chunk(s) again (restart 1 of at most 1)"]


_ORPHAN_PARENT = r"""
import sys
from pursuit.engine import monte_carlo
from pursuit.engine.backends import LocalProcesses
from tests.engine.helpers import SMALL, Slow, small_filters

if __name__ == "__main__":
    with LocalProcesses(2) as backend:
        monte_carlo(Slow(SMALL, 60.0), small_filters(), 8, 1, chunk_size=2, backend=backend)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="lists processes through /proc")
def test_workers_end_when_their_parent_is_killed(tmp_path):
    """SIGKILL the process that owns a pool (it cannot clean up): its workers, the forkserver and the
    resource tracker end within seconds, not when their 60 s chunks are done."""
    import os
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    script = tmp_path / "parent.py"
    script.write_text(_ORPHAN_PARENT)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(root / "src"), str(root), os.environ.get("PYTHONPATH")])))
    proc = subprocess.Popen([sys.executable, str(script)], env=env, start_new_session=True, cwd=root)
    try:
        # main, resource tracker, forkserver and 2 workers
        assert wait_until(lambda: len(session_pids(proc.pid)) >= 5, 120), session_pids(proc.pid)
        proc.kill()
        proc.wait(30)
        assert wait_until(lambda: not session_pids(proc.pid), 20), f"still alive: {session_pids(proc.pid)}"
    finally:
        end_session(proc)


_HALF_SENT = """
import sys, time
from pursuit.engine.backends import LocalProcesses
from tests.engine.helpers import half_sent_result

def reading():  # the pool's thread is inside a recv of the result pipe (not of its wake-up pipe)
    for frame in sys._current_frames().values():
        while frame is not None:
            if frame.f_code.co_name == "_recv_bytes" and frame.f_locals.get("self") is results:
                return True
            frame = frame.f_back
    return False

backend = LocalProcesses(1)
pool = backend._executor()
results = pool._result_queue._reader
pool.submit(half_sent_result)
deadline = time.monotonic() + 60
while not reading():
    assert time.monotonic() < deadline, "the pool's thread never started reading the result"
    time.sleep(0.05)
started = time.monotonic()
backend.terminate()
print(f"terminated in {time.monotonic() - started:.1f} s")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the result pipe's framing and forkserver are POSIX")
def test_terminate_returns_when_a_worker_was_stopped_halfway_through_sending_a_result(tmp_path):
    """A worker stopped while it sends a result left the pool's thread waiting for the rest for ever, and
    ``terminate`` (Ctrl-C, SIGTERM, SIGHUP with --workers) waiting for that thread: the CLI hung (CI caught
    it, about 1 run in 40-150).  In a subprocess, so that a hang fails this test instead of the test run."""
    import subprocess
    from pathlib import Path

    from .helpers import end_session

    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-c", _HALF_SENT], cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=90)
    except subprocess.TimeoutExpired:
        end_session(proc)
        pytest.fail("terminate() did not return: the pool's thread still waits for the half-sent result")
    finally:
        end_session(proc)
    assert proc.returncode == 0, out
    assert out.startswith("terminated in"), out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver")
def test_a_signal_while_the_forkserver_makes_a_worker_waits_for_its_pid(monkeypatch):
    """Ctrl-C after the forkserver was asked for a worker but before its pid was read: the signal acts when
    the pid is known, and that worker is stopped with the others (before, no one knew its pid: it went on
    starting, and after the parent had ended it printed a traceback of its own)."""
    import os
    import signal
    import threading
    from multiprocessing import forkserver

    real = forkserver.read_signed
    sent = []

    def read_after_a_signal(fd):
        if not sent and threading.current_thread() is threading.main_thread():  # the first worker's pid
            sent.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        return real(fd)

    monkeypatch.setattr(forkserver, "read_signed", read_after_a_signal)
    with pytest.raises(KeyboardInterrupt):
        with LocalProcesses(2) as backend:
            backend.map_chunks(_worker_thread_env, [(0, 1), (1, 2)], lambda span, result: None)
    assert sent
    made = backend._context.made
    assert made and all(p.pid is not None for p in made), "a worker was asked for but its pid was never read"
    assert all(p.exitcode is not None for p in made), "a worker whose start was interrupted is still running"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler is put back


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver")
def test_a_signal_held_back_while_a_worker_fails_to_start_still_reaches_its_handler(monkeypatch):
    """Ctrl-C that also ends the forkserver (the same process group) while a worker starts: the caller gets
    the KeyboardInterrupt, with the failed start as its context, not the start's own error."""
    import os
    import signal
    import threading
    from multiprocessing import forkserver

    def signal_then_fail(fd):
        if threading.current_thread() is threading.main_thread():
            os.kill(os.getpid(), signal.SIGINT)
            raise EOFError("unexpected EOF")  # what reading the pid from a dead forkserver raises
        return real(fd)

    real = forkserver.read_signed
    monkeypatch.setattr(forkserver, "read_signed", signal_then_fail)
    with pytest.raises(KeyboardInterrupt) as caught:
        with LocalProcesses(2) as backend:
            backend.map_chunks(_worker_thread_env, [(0, 1), (1, 2)], lambda span, result: None)
    assert isinstance(caught.value.__context__, EOFError)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
