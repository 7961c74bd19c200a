"""A script that starts worker processes outside its ``__main__`` guard gets an error naming the guard."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import pursuit
from pursuit.engine.main_guard import guarded_lines, unguarded_main_call

SRC = Path(pursuit.__file__).resolve().parents[1]

BODY = """\
import pursuit as pu
from pursuit.scenarios import LinearCV

scenario = LinearCV(ndim=1, steps=3)
filters = [pu.KalmanFilter(scenario.motion, scenario.measurement)]
"""
CALL = "result = pu.monte_carlo(scenario, filters, runs=4, seed=1, backend=2, chunk_size=2)\nprint('rmse', result.rmse('KF'))\n"


def run_script(tmp_path, source):
    script = tmp_path / "user_script.py"
    script.write_text(source)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


def test_unguarded_script_is_told_about_the_guard(tmp_path):
    proc = run_script(tmp_path, BODY + CALL)
    assert proc.returncode != 0
    # the parent's error (the workers print Python's own message before it)
    [last] = [line for line in proc.stderr.splitlines() if line.startswith("pursuit.engine.backends.MissingMainGuard: ")]
    assert "WorkerLost" not in proc.stderr  # said at the first broken pool, not after the restarts
    assert 'if __name__ == "__main__":' in last
    assert f"import {tmp_path / 'user_script.py'} again" in last
    assert "its line 6 starts" in last  # the monte_carlo call


def test_guarded_script_runs(tmp_path):
    proc = run_script(tmp_path, BODY + 'if __name__ == "__main__":\n' + textwrap.indent(CALL, "    "))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("rmse ")


def test_guarded_lines_finds_the_guard_either_way_round():
    source = "a = 1\nif __name__ == '__main__':\n    b = 2\n    c = 3\nif '__main__' == __name__:\n    d = 4\nif x == '__main__':\n    e = 5\n"
    assert guarded_lines(source) == [range(2, 5), range(5, 7)]


def test_guarded_lines_ignores_nested_and_other_tests():
    source = "def f():\n    if __name__ == '__main__':\n        pass\nif __name__ != '__main__':\n    pass\n"
    assert guarded_lines(source) == []


def test_no_unguarded_call_from_the_test_runner():
    # pytest's own __main__ is guarded (or absent): the check must not fire outside user scripts.
    assert unguarded_main_call() is None


@pytest.mark.parametrize("guard", [False, True])
def test_unguarded_main_call_reads_the_calling_line(tmp_path, monkeypatch, guard):
    # A stand-in __main__ module whose top level calls the check on its line 3.
    path = tmp_path / "fake_main.py"
    lines = ["from pursuit.engine.main_guard import unguarded_main_call", "found = None"]
    lines += ["if __name__ == '__main__':", "    found = unguarded_main_call()"] if guard else ["found = unguarded_main_call()"]
    path.write_text("\n".join(lines) + "\n")
    module = type(sys)("__main__")
    module.__file__ = str(path)
    monkeypatch.setitem(sys.modules, "__main__", module)
    module.__dict__["__name__"] = "__main__"
    exec(compile(path.read_text(), str(path), "exec"), module.__dict__)
    assert module.found == (None if guard else (str(path), 3))
