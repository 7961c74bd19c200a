"""Replacing an output folder: stale helper folders, an interrupted swap, recovery."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pursuit import output_folder
from pursuit.output_folder import make_temp, recover, replace, stale_folders


def _dead_pid() -> int:
    """The id of a process that has ended (and been reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait(30)
    return proc.pid


def _folder(path: Path, text: str) -> Path:
    path.mkdir()
    (path / "run.json").write_text(text)
    return path


def _helper_name(out: Path, kind: str, pid: int, host: str | None = None) -> Path:
    return out.with_name(f".{out.name}.pursuit-{kind}-{host or output_folder._host()}-{pid}-0123abcd")


def test_only_our_dead_writers_folders_are_stale(tmp_path):
    out = tmp_path / "demo"
    dead = _dead_pid()
    ours = _folder(_helper_name(out, "tmp", dead), "half")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        kept = [
            _folder(_helper_name(out, "tmp", os.getpid()), "mine, being written"),
            _folder(_helper_name(out, "tmp", live.pid), "a live run's"),
            _folder(_helper_name(out, "tmp", dead, host="ffffffff"), "another machine's"),
            _folder(tmp_path / ".demo.abcd1234", "not named by pursuit"),
            _folder(tmp_path / f".demo2.pursuit-tmp-{output_folder._host()}-{dead}-0123abcd", "another output's"),
        ]
        assert stale_folders(out) == [("tmp", ours)]
        assert recover(out) == [ours]
        assert not ours.exists() and all(p.is_dir() for p in kept)
        assert not out.exists()  # nothing to restore: there was no old output
    finally:
        live.kill()
        live.wait(30)


def test_killed_between_the_renames_is_restored(tmp_path):
    """A writer killed after moving DIR away, before moving the new one in: the next recover puts DIR back."""
    out = tmp_path / "demo"
    dead = _dead_pid()
    old = _folder(_helper_name(out, "old", dead), "previous output")
    new = _folder(_helper_name(out, "tmp", dead), "new, never moved in")
    assert sorted(recover(out)) == [new]
    assert (out / "run.json").read_text() == "previous output"
    assert not old.exists() and not new.exists()


def test_killed_after_the_swap_leaves_only_garbage(tmp_path):
    out = _folder(tmp_path / "demo", "new output")
    old = _folder(_helper_name(out, "old", _dead_pid()), "previous output")
    assert recover(out) == [old]
    assert (out / "run.json").read_text() == "new output"


@pytest.mark.parametrize("atomic", [True, False], ids=["exchange", "two-renames"])
def test_replace_puts_the_new_folder_in_place_and_leaves_nothing(tmp_path, monkeypatch, atomic):
    if not atomic:
        monkeypatch.setattr(output_folder, "_exchange", lambda a, b: False)
    out = _folder(tmp_path / "demo", "old")
    tmp = make_temp(out)
    (tmp / "run.json").write_text("new")
    replace(tmp, out)
    assert (out / "run.json").read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["demo"]


def test_interrupted_between_the_renames_restores_the_old_folder(tmp_path, monkeypatch):
    """Without an atomic exchange: Ctrl-C between the two renames moves the old folder back at once."""
    monkeypatch.setattr(output_folder, "_exchange", lambda a, b: False)
    out = _folder(tmp_path / "demo", "old")
    tmp = make_temp(out)
    real = Path.rename

    def rename(self, target):
        if Path(target) == out and self == tmp:
            raise KeyboardInterrupt
        return real(self, target)

    monkeypatch.setattr(Path, "rename", rename)
    with pytest.raises(KeyboardInterrupt):
        replace(tmp, out)
    assert (out / "run.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["demo", tmp.name])  # the caller removes tmp


def test_temp_folder_is_named_for_recovery_and_not_private(tmp_path):
    out = tmp_path / "demo"
    tmp = make_temp(out)
    assert stale_folders(out) == []  # this process is alive
    mask = os.umask(0)
    os.umask(mask)
    assert tmp.stat().st_mode & 0o777 == 0o777 & ~mask
    assert tmp.name.startswith(".demo.pursuit-tmp-") and f"-{os.getpid()}-" in tmp.name
