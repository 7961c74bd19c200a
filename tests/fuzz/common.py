"""What every fuzz case shares: its outcome classes, the in-process CLI call and its bounds.

A case is run by calling :func:`pursuit.cli.main` in this process (no interpreter start per
case), with standard input, output and error captured.  Any exception that escapes ``main``
is what a user would see as a Python traceback.  Each call is bounded in time (SIGALRM) and in
address space (RLIMIT_AS), so an input that asks for 10^12 runs cannot take the machine with it.
"""

from __future__ import annotations

import io
import resource
import signal
import sys
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

# The outcome classes of a case, in table order.  The last four are failures.
CLEAN_ERROR = "clean error"
ACCEPTED = "accepted, correct"
TRACEBACK = "traceback"
WRONG = "silent wrong answer"
PARTIAL = "partial output"
OVER_TIME = "over time"
OUTCOMES = (CLEAN_ERROR, ACCEPTED, TRACEBACK, WRONG, PARTIAL, OVER_TIME)
FAILURES = (TRACEBACK, WRONG, PARTIAL, OVER_TIME)

TIME_LIMIT_S = 20.0  # one case; an accepted tiny case takes about a second (the first one compiles)
MEMORY_HEADROOM = 3 << 30  # bytes of address space a case may add to the process's current size


@dataclass
class Outcome:
    """How one case ended, and why the oracle put it there."""

    kind: str  # "track", "model" or "config"
    name: str  # the mutation or generator that made the case
    outcome: str  # one of OUTCOMES
    why: str = ""  # for a failure: what the docs promise and what happened
    reproducer: dict = field(default_factory=dict)  # files (name -> text) and argv to replay the case


@dataclass
class CliResult:
    """The exit code, captured streams and escaped exception of one in-process ``pursuit`` call."""

    code: int | None
    out: str
    err: str
    exc: str | None = None  # the traceback text, when an exception escaped ``main``
    timed_out: bool = False


class _OverTime(BaseException):
    """Raised by the alarm; a BaseException so that ``except Exception`` in the code cannot swallow it."""


def _on_alarm(signum, frame):
    raise _OverTime()


def _vm_size() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def bounded(fn: Callable[[], object], time_limit: float = TIME_LIMIT_S) -> tuple[object, str | None, bool]:
    """Call ``fn()`` under a time and memory bound: ``(value, traceback text or None, timed out)``."""
    old_handler = signal.signal(signal.SIGALRM, _on_alarm)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    vm = _vm_size()
    limit = vm + MEMORY_HEADROOM if vm else resource.RLIM_INFINITY
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    signal.setitimer(signal.ITIMER_REAL, time_limit)
    try:
        with warnings.catch_warnings():  # numerical RuntimeWarnings of extreme inputs: the outcome is judged, not the noise
            warnings.simplefilter("ignore", RuntimeWarning)
            return fn(), None, False
    except _OverTime:
        return None, None, True
    except SystemExit as e:  # argparse's usage errors: a clean exit with its code
        return SystemExit(e.code), None, False
    except BaseException:  # noqa: BLE001 - anything escaping is a traceback for the user
        return None, traceback.format_exc(), False
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
        signal.signal(signal.SIGALRM, old_handler)


def run_cli(argv: list[str], stdin: bytes = b"", time_limit: float = TIME_LIMIT_S) -> CliResult:
    """Run ``pursuit ARGV`` in this process with ``stdin`` as standard input."""
    from pursuit.cli import main

    old = sys.stdin, sys.stdout, sys.stderr
    sys.stdin = io.TextIOWrapper(io.BytesIO(stdin), encoding="utf-8")
    sys.stdout, sys.stderr = io.StringIO(), io.StringIO()
    try:
        value, exc, timed_out = bounded(lambda: main(argv), time_limit)
        out, err = sys.stdout.getvalue(), sys.stderr.getvalue()
    finally:
        sys.stdin, sys.stdout, sys.stderr = old
    code = value.code if isinstance(value, SystemExit) else value
    if isinstance(code, str):  # SystemExit("message"): printed, exit code 1
        code = 1
    return CliResult(code=code, out=out, err=err, exc=exc, timed_out=timed_out)


def classify_cli(res: CliResult) -> str | None:
    """The failure class a call shows by itself (an escaped exception, over time), else None."""
    if res.timed_out:
        return OVER_TIME
    if res.exc is not None or "Traceback (most recent call last)" in res.err:
        return TRACEBACK
    if res.code not in (0, 2):  # 1 is "an unexpected failure (a bug)" in docs/cli.md
        return TRACEBACK
    return None


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes), to check that an error left it as it was."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
