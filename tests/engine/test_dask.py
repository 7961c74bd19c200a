"""The Dask backend against real clusters on loopback: a LocalCluster, and
``dask scheduler`` / ``dask worker`` started as subprocesses."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed", reason="the Dask backend needs pursuit[distributed]")

from pursuit.engine import monte_carlo  # noqa: E402
from pursuit.engine.backends import Dask, WorkerLost  # noqa: E402

from .helpers import SMALL, Killer, PauseOnce, assert_same_result, assert_same_summary, small_filters  # noqa: E402

RUNS, SEED = 24, 5
ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).with_name("dask")
START_TIMEOUT = 60


@pytest.fixture(scope="module")
def serial():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED)


def test_local_cluster_equals_serial(serial):
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
        silence_logs=logging.ERROR,
    ) as cluster, distributed.Client(cluster, set_as_default=False) as client:
        backend = Dask(client=client)
        assert backend.describe()["workers"] == 2
        full = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=5, backend=backend)
        summ = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=7, backend=backend, store="summary")
        backend.close()  # does not close a client it did not open
        assert client.status == "running"
    assert_same_result(serial, full)
    assert_same_summary(serial, summ)


def _start(args: list[str], log: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    fh = log.open("wb")
    # A new session per process, so teardown can kill exactly what the test started.
    return subprocess.Popen([str(DASK), *args], cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(10)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait(10)


@pytest.fixture(scope="module")
def subprocess_cluster(tmp_path_factory):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1 (free ports, no dashboard)."""
    if not DASK.exists():
        pytest.skip(f"no dask command beside {sys.executable}")
    tmp = tmp_path_factory.mktemp("dask")
    sched_file = tmp / "scheduler.json"
    procs: list[subprocess.Popen] = []
    try:
        procs.append(_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                             "--scheduler-file", str(sched_file)], tmp / "scheduler.log"))
        deadline = time.monotonic() + START_TIMEOUT
        while not sched_file.exists():
            if time.monotonic() > deadline or procs[0].poll() is not None:
                pytest.fail(f"dask scheduler did not start:\n{(tmp / 'scheduler.log').read_text()}")
            time.sleep(0.1)
        time.sleep(0.2)  # the file is written in one go, but give the writer a moment
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for i in range(2):
            procs.append(_start(["worker", address, "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1",
                                 "--no-dashboard", "--death-timeout", "60", "--memory-limit", "0"], tmp / f"worker{i}.log"))
        with distributed.Client(address, timeout=START_TIMEOUT, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT)
        yield address
    finally:
        for p in reversed(procs):
            _stop(p)


def test_subprocess_cluster_equals_serial(serial, subprocess_cluster):
    with Dask(subprocess_cluster) as backend:
        got = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=4, backend=backend)
    assert_same_result(serial, got)
    # The address form that the CLI's --scheduler passes.
    got = monte_carlo(SMALL, small_filters(), RUNS, SEED, chunk_size=6, backend=subprocess_cluster, store="summary")
    assert_same_summary(serial, got)


def test_worker_killed_mid_run(serial, subprocess_cluster, tmp_path):
    """SIGKILL the worker process computing a chunk: the chunk is computed again elsewhere;
    the result is complete and identical to the serial run."""
    marker = tmp_path / "paused.pid"
    killer = Killer(marker, timeout=START_TIMEOUT)
    killer.start()
    done = []
    with Dask(subprocess_cluster, wait_timeout=240) as backend:
        got = monte_carlo(PauseOnce(SMALL, str(marker)), small_filters(), RUNS, SEED, chunk_size=4, backend=backend,
                          progress=lambda d, t: done.append(d))
    killer.join(5)
    assert killer.error is None and killer.killed is not None
    with pytest.raises(ProcessLookupError):
        os.kill(killer.killed, 0)  # that worker process is gone
    assert done[-1] == len(done) * 2 == RUNS // 4 * 2  # each chunk counted once
    assert_same_result(serial, got)


@pytest.fixture(scope="module")
def lonely_scheduler(tmp_path_factory):
    """A ``dask scheduler`` on 127.0.0.1 with no worker of its own (tests add and kill workers)."""
    if not DASK.exists():
        pytest.skip(f"no dask command beside {sys.executable}")
    tmp = tmp_path_factory.mktemp("lonely")
    sched_file = tmp / "scheduler.json"
    proc = _start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file", str(sched_file)],
                  tmp / "scheduler.log")
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not (sched_file.exists() and sched_file.read_text().strip().endswith("}")):
            if time.monotonic() > deadline or proc.poll() is not None:
                pytest.fail(f"dask scheduler did not start:\n{(tmp / 'scheduler.log').read_text()}")
            time.sleep(0.1)
        yield json.loads(sched_file.read_text())["address"], tmp
    finally:
        _stop(proc)


def _run_bounded(fn, limit: float):
    """Run ``fn()`` in a thread; returns (exception or None, seconds), or fails the test if it is still waiting after ``limit``."""
    import threading

    box: dict = {}

    def target():
        try:
            fn()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            box["error"] = e

    start = time.monotonic()
    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(limit)
    assert not thread.is_alive(), f"still waiting after {limit} s"
    return box.get("error"), time.monotonic() - start


def test_a_cluster_without_workers_is_an_error_after_worker_timeout(lonely_scheduler):
    address, _ = lonely_scheduler
    with Dask(address, worker_timeout=2) as backend:
        error, took = _run_bounded(lambda: monte_carlo(SMALL, small_filters(), 8, SEED, chunk_size=4, backend=backend), 60)
    assert isinstance(error, WorkerLost), error
    assert str(error) == (
        f"the Dask cluster at {address} has had no worker for 2 s (all died, none started, or the scheduler is "
        "unreachable); 2 chunk(s) left uncomputed (wait longer with --worker-timeout)"
    )
    assert 2 <= took < 30


def test_when_every_worker_dies_the_run_ends_with_an_error(lonely_scheduler, tmp_path):
    """The only worker (no nanny to restart it) is SIGKILLed in the middle of a chunk: no hang, WorkerLost."""
    address, logs = lonely_scheduler
    worker = _start(["worker", address, "--no-nanny", "--host", "127.0.0.1", "--nthreads", "1", "--no-dashboard",
                     "--memory-limit", "0", "--death-timeout", "60"], logs / "worker.log")
    try:
        with Dask(address, worker_timeout=3) as backend:
            backend.client.wait_for_workers(1, timeout=START_TIMEOUT)
            marker = tmp_path / "paused.pid"
            killer = Killer(marker, timeout=START_TIMEOUT)
            killer.start()
            error, took = _run_bounded(
                lambda: monte_carlo(PauseOnce(SMALL, str(marker)), small_filters(), 8, SEED, chunk_size=4, backend=backend), 120
            )
            killer.join(5)
    finally:
        _stop(worker)
    assert killer.error is None and killer.killed == worker.pid
    assert isinstance(error, WorkerLost), error
    assert "has had no worker for 3 s" in str(error)


def test_cli_without_workers_exits_3_with_one_line(lonely_scheduler, tmp_path, capsys):
    from pursuit.cli import main

    from ..test_config import GOOD

    address, _ = lonely_scheduler
    config = tmp_path / "exp.toml"
    config.write_text(GOOD)
    out = tmp_path / "out"
    code = main(["run", str(config), "--out", str(out), "--scheduler", address, "--worker-timeout", "1.5", "--no-progress"])
    assert code == 3
    assert capsys.readouterr().err.splitlines() == [
        f"pursuit: error: the Dask cluster at {address} has had no worker for 1.5 s (all died, none started, or the "
        "scheduler is unreachable); 1 chunk(s) left uncomputed (wait longer with --worker-timeout)"
    ]
    assert not out.exists()
