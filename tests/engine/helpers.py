"""Picklable test doubles for the backend tests (imported by worker processes too)."""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pursuit.scenarios import WSNRange

SMALL = WSNRange(steps=20)
"""A cheap scenario: 20 steps of WSN range tracking."""


def small_filters():
    """EKF and CKF on :data:`SMALL` (one Jacobian-based, one sigma-point filter)."""
    import pursuit as pu

    return [pu.ExtendedKalmanFilter(SMALL.motion, SMALL.measurement), pu.CubatureKalmanFilter(SMALL.motion, SMALL.measurement)]


class _WrappedScenario:
    """A test scenario around ``inner`` (a dataclass field of the subclass): everything it does not define is ``inner``'s.

    Its own fields and dunder names are never looked up on ``inner``: unpickling in a worker
    asks for them before they are set, and must get AttributeError, not a recursion.
    """

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in {f.name for f in dataclasses.fields(self)}:
            raise AttributeError(name)
        return getattr(self.inner, name)

    @property
    def name(self) -> str:
        return self.inner.name


@dataclass(frozen=True)
class PauseOnce(_WrappedScenario):
    """A scenario that, the first time any process simulates with it, writes its pid and waits.

    The first caller (chosen atomically through ``O_EXCL`` on ``marker``)
    writes its process id to ``marker`` and sleeps, so that a test can kill
    that worker in the middle of a chunk.  Every later call, including the
    recomputation of the killed chunk, simulates normally.
    """

    inner: Any
    marker: str
    pause_s: float = 120.0

    def simulate(self, rng, runs=None):
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return self.inner.simulate(rng, runs)
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        time.sleep(self.pause_s)  # the test kills this process meanwhile
        raise RuntimeError("PauseOnce: the test did not kill the paused worker")


@dataclass(frozen=True)
class Slow(_WrappedScenario):
    """A scenario that sleeps before simulating, so chunks finish one by one."""

    inner: Any
    delay_s: float

    def simulate(self, rng, runs=None):
        time.sleep(self.delay_s)
        return self.inner.simulate(rng, runs)


@dataclass(frozen=True)
class Failing(_WrappedScenario):
    """A scenario whose simulation raises (a bug in user code), to check it is not retried."""

    inner: Any

    def simulate(self, rng, runs=None):
        raise ValueError("deliberate failure in simulate")


class Killer(threading.Thread):
    """Waits for a :class:`PauseOnce` marker and SIGKILLs the process whose pid it holds."""

    def __init__(self, marker: str | Path, timeout: float = 120.0):
        super().__init__(daemon=True)
        self.marker = Path(marker)
        self.timeout = timeout
        self.killed: int | None = None
        self.error: str | None = None

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            try:
                text = self.marker.read_text()
            except FileNotFoundError:
                text = ""
            if text:
                pid = int(text)
                os.kill(pid, signal.SIGKILL)
                self.killed = pid
                return
            time.sleep(0.02)
        self.error = f"no worker paused within {self.timeout} s"


def assert_same_result(a, b) -> None:
    """Two MonteCarloResults hold the same bits (everything but wall times)."""
    import numpy as np

    assert a.runs == b.runs and a.store == b.store
    if a.store == "full":
        assert np.array_equal(a.truth, b.truth)
        assert np.array_equal(a.measurements, b.measurements, equal_nan=True)
    for name in a.filters:
        fa, fb = a.filters[name], b.filters[name]
        if a.store == "full":
            assert np.array_equal(fa.estimates, fb.estimates), name
            assert np.array_equal(fa.covariances, fb.covariances), name
            assert fa.info.keys() == fb.info.keys()
            for key in fa.info:
                assert np.array_equal(fa.info[key], fb.info[key], equal_nan=True), (name, key)
        sa, sb = a.filter_statistics(name), b.filter_statistics(name)
        for key in sa.sums:
            assert np.array_equal(sa.sums[key], sb.sums[key], equal_nan=True), (name, key)
        for key in sa.per_run:
            assert np.array_equal(sa.per_run[key], sb.per_run[key], equal_nan=True), (name, key)
    assert_same_summary(a, b)


def assert_same_summary(a, b) -> None:
    """Summary tables equal bit for bit, wall times aside."""
    import math

    for ra, rb in zip(a.summary(), b.summary(), strict=True):
        assert ra.keys() == rb.keys()
        for key in ra:
            if key == "wall_time_s":
                continue
            x, y = ra[key], rb[key]
            same = x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
            assert same, (ra["filter"], key, x, y)


@dataclass(frozen=True)
class KillsItsWorker(_WrappedScenario):
    """A scenario that SIGKILLs the worker process simulating with it, every time (a worker that keeps dying).

    In a process not started by :mod:`multiprocessing` (the test runner
    itself) it raises instead, so a mistake cannot kill the test session.
    """

    inner: Any

    def simulate(self, rng, runs=None):
        import multiprocessing

        if multiprocessing.parent_process() is None:
            raise RuntimeError("KillsItsWorker: simulate called outside a worker process")
        os.kill(os.getpid(), signal.SIGKILL)


def session_pids(sid: int) -> list[int]:
    """Ids of the live processes in session ``sid`` (Linux ``/proc``), zombies excluded."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # ended meanwhile
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) "
        if fields[0] != "Z" and int(fields[3]) == sid:
            pids.append(int(entry.name))
    return sorted(pids)


def end_session(proc) -> None:
    """Kill whatever is left of ``proc``'s session (started with ``start_new_session=True``) and reap ``proc``."""
    for pid in session_pids(proc.pid):
        os.kill(pid, signal.SIGKILL)
    if proc.poll() is None:
        proc.kill()
        proc.wait(30)


def wait_until(condition, timeout: float, interval: float = 0.05) -> bool:
    """Poll ``condition()`` until it is true or ``timeout`` seconds have passed; returns its last value."""
    deadline = time.monotonic() + timeout
    while True:
        if condition():
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(interval)


@dataclass(frozen=True)
class SlowButOnce(_WrappedScenario):
    """A scenario whose first simulation (in any process, chosen through ``O_EXCL`` on ``marker``) is
    immediate and every later one sleeps ``delay_s`` first: one chunk finishes while others still run."""

    inner: Any
    marker: str
    delay_s: float = 60.0

    def simulate(self, rng, runs=None):
        try:
            os.close(os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            time.sleep(self.delay_s)
        return self.inner.simulate(rng, runs)


def half_sent_result(seconds: float = 600.0) -> None:
    """A pool task that writes the first bytes of a result message to the pool's result pipe, then sleeps.

    It stands for a worker stopped while it sends a large result: the pool's
    thread in the parent reads the message's length and waits for the rest.
    """
    import struct
    import sys

    frame = sys._getframe()
    while frame.f_code.co_name != "_process_worker":  # concurrent.futures' worker loop holds the result queue
        frame = frame.f_back
    queue = frame.f_locals["result_queue"]
    os.write(queue._writer.fileno(), struct.pack("!i", 1000) + b"x" * 10)  # multiprocessing's framing: length, then bytes
    time.sleep(seconds)
