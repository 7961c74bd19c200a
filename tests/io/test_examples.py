"""The worked examples: the shipped data are pursuit's simulator output, and every documented command runs as shown."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from .conftest import EXAMPLES, ROOT

DOC = ROOT / "docs" / "track.md"


def test_the_shipped_data_are_what_the_simulator_makes(tmp_path):
    subprocess.run([sys.executable, str(EXAMPLES / "make_data.py"), str(tmp_path)], check=True, capture_output=True)
    shipped = sorted(p.name for p in (EXAMPLES / "data").iterdir())
    assert shipped == sorted(p.name for p in tmp_path.iterdir())
    for name in shipped:
        new, old = (tmp_path / name).read_text(), (EXAMPLES / "data" / name).read_text()
        if new == old:
            continue
        # another platform may differ in the last bits; the numbers must still agree closely
        _same_text(new.splitlines(), old.splitlines(), name)


def _tokens(line: str) -> list[str]:
    return [t for t in re.split(r"([,\s:{}\[\]\"])", line) if t and not t.isspace()]


def _same_text(actual: list[str], expected: list[str], what: str) -> None:
    assert len(actual) == len(expected), f"{what}: {len(actual)} lines, expected {len(expected)}\n" + "\n".join(actual)
    for a, e in zip(actual, expected):
        ta, te = _tokens(a), _tokens(e)
        assert len(ta) == len(te), f"{what}:\n  got      {a}\n  expected {e}"
        for x, y in zip(ta, te):
            if x == y:
                continue
            try:
                fx, fy = float(x), float(y)
            except ValueError:
                raise AssertionError(f"{what}:\n  got      {a}\n  expected {e}") from None
            assert np.isclose(fx, fy, rtol=1e-9, atol=1e-12), f"{what}:\n  got      {a}\n  expected {e}"


def documented_commands() -> list[tuple[str, list[str]]]:
    """(command, expected output lines) for every ``$ `` line of the console blocks in docs/track.md."""
    out = []
    in_block = False
    current = None
    for line in DOC.read_text().splitlines():
        if line.startswith("```"):
            if in_block and current is not None:
                out.append(current)
                current = None
            in_block = line.strip() == "```console"
            continue
        if not in_block:
            continue
        if line.startswith("$ "):
            if current is not None:
                out.append(current)
            current = (line[2:], [])
        elif current is not None:
            current[1].append(line)
    return out


COMMANDS = documented_commands()


def test_the_docs_show_the_four_examples_and_the_bad_input_one():
    text = " ".join(cmd for cmd, _ in COMMANDS)
    for needle in ("wsn-range.csv", "wsn-range.jsonl", "underwater-toa.csv", "underwater-toa.jsonl", "wsn-range-damaged.csv"):
        assert needle in text
    assert sum(cmd.startswith("pursuit track - ") for cmd, _ in COMMANDS) == 2  # two from a stream


@pytest.mark.parametrize("command,expected", COMMANDS, ids=[c[:60] for c, _ in COMMANDS])
def test_documented_command(command, expected):
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    proc = subprocess.run(["bash", "-c", f"set -o pipefail; {command}"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no warnings, no broken-pipe noise
    _same_text(proc.stdout.splitlines(), expected, command)


def test_the_python_example_reads_the_shipped_examples(tmp_path, monkeypatch):
    # tests/test_docs.py runs the block too; here its result is checked, from a folder that is not
    # the repository root (examples_dir() finds the files, not the working directory).
    blocks = [b for b in re.findall(r"^```python\n(.*?)^```", DOC.read_text(), re.S | re.M) if "track_records" in b]
    assert len(blocks) == 1
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(blocks[0], "track.md", "exec"), namespace)
    result = namespace["result"]
    assert result.problems == [] and len(result.estimates) == 59


def test_make_data_has_a_help_and_writes_nothing_for_it(tmp_path):
    res = subprocess.run(
        [sys.executable, str(EXAMPLES / "make_data.py"), "--help"], capture_output=True, text=True, cwd=tmp_path, timeout=120
    )
    assert res.returncode == 0 and res.stdout.startswith("usage: make_data.py [-h] [outdir]")
    assert list(tmp_path.iterdir()) == []  # --help is not taken for the output folder
    res = subprocess.run(
        [sys.executable, str(EXAMPLES / "make_data.py"), "a", "b"], capture_output=True, text=True, cwd=tmp_path, timeout=120
    )
    assert res.returncode == 2 and "unrecognized arguments: b" in res.stderr
