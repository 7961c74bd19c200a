"""Whole tasks side by side in local processes (pursuit.engine.tasks), and --workers auto."""

from __future__ import annotations

import os

import pytest

from pursuit.engine.tasks import cpu_count, parse_workers, run_tasks


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def _fail(x: int) -> int:
    raise ValueError(f"deliberate failure {x}")


def test_cpu_count_is_this_process_cores():
    n = cpu_count()
    assert n >= 1
    if hasattr(os, "sched_getaffinity"):
        assert n == len(os.sched_getaffinity(0))


@pytest.mark.parametrize("text, expected", [("1", 1), ("3", 3), (" 2 ", 2), ("0", 0), ("-1", -1)])
def test_parse_workers_numbers_as_given(text, expected):
    # 0 and negatives pass through: the command refuses them naming --workers (test_cli_report.py)
    assert parse_workers(text) == expected


@pytest.mark.parametrize("text", ["auto", "AUTO", "Auto"])
def test_parse_workers_auto_is_the_core_count(text):
    assert parse_workers(text) == cpu_count()


@pytest.mark.parametrize("text", ["", "many", "2.5", "auto2"])
def test_parse_workers_refuses_other_words_naming_the_flag(text):
    with pytest.raises(ValueError, match=r"--workers: expected a whole number or 'auto', got"):
        parse_workers(text)


@pytest.mark.parametrize("workers", [1, 2])
def test_run_tasks_computes_every_task_once(workers):
    got = {}

    def keep(i, result):
        assert i not in got
        got[i] = result

    run_tasks(_square_and_pid, [(x,) for x in range(5)], workers, keep, first=[4, 3, 2, 1, 0])
    assert {i: r[0] for i, r in got.items()} == {x: x * x for x in range(5)}
    pids = {r[1] for r in got.values()}
    assert (pids == {os.getpid()}) if workers == 1 else (os.getpid() not in pids)


def test_run_tasks_in_process_follows_first():
    seen = []
    run_tasks(_square_and_pid, [(x,) for x in range(3)], 1, lambda i, r: seen.append(i), first=[2, 0, 1])
    assert seen == [2, 0, 1]


def test_run_tasks_checks_its_arguments():
    with pytest.raises(ValueError, match="workers: must be a positive integer"):
        run_tasks(_square_and_pid, [(1,)], 0, lambda i, r: None)
    with pytest.raises(ValueError, match="first: expected an order of the task indices 0 .. 1"):
        run_tasks(_square_and_pid, [(1,), (2,)], 2, lambda i, r: None, first=[0, 0])


def test_run_tasks_raises_a_task_error():
    with pytest.raises(ValueError, match="deliberate failure"):
        run_tasks(_fail, [(1,), (2,)], 2, lambda i, r: None)
