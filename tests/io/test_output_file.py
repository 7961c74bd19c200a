"""``pursuit.io.output_file``: the output is never the input, and writing it destroys nothing else."""

from __future__ import annotations

import os
import stat

import pytest

from pursuit.io.output_file import same_file, same_file_as_stream, write_whole


def test_same_file_sees_through_symbolic_and_hard_links(tmp_path):
    data = tmp_path / "data.csv"
    data.write_text("x")
    (tmp_path / "soft.csv").symlink_to(data)
    os.link(data, tmp_path / "hard.csv")
    assert same_file(data, tmp_path / "soft.csv") and same_file(data, tmp_path / "hard.csv")
    assert not same_file(data, tmp_path / "other.csv")  # does not exist
    (tmp_path / "other.csv").write_text("x")
    assert not same_file(data, tmp_path / "other.csv")
    with open(data, "rb") as f:
        assert same_file_as_stream(f, tmp_path / "soft.csv")
        assert not same_file_as_stream(f, tmp_path / "other.csv")


def test_a_symbolic_link_is_written_through_to_its_target_and_stays_a_link(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    write_whole(link, "new")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text() == "new"


def test_a_dangling_link_creates_its_target(tmp_path):
    link = tmp_path / "link.csv"
    link.symlink_to(tmp_path / "later.csv")
    write_whole(link, "new")
    assert link.is_symlink() and (tmp_path / "later.csv").read_text() == "new"


def test_an_existing_file_keeps_its_mode_and_a_new_one_gets_the_umasks(tmp_path):
    old = tmp_path / "old.csv"
    old.write_text("old")
    old.chmod(0o640)
    write_whole(old, "new")
    assert stat.S_IMODE(old.stat().st_mode) == 0o640 and old.read_text() == "new"
    mask = os.umask(0o027)
    try:
        write_whole(tmp_path / "fresh.csv", "new")
    finally:
        os.umask(mask)
    assert stat.S_IMODE((tmp_path / "fresh.csv").stat().st_mode) == 0o640  # 0o666 less 0o027
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_a_fifo_is_written_directly_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # a reader, so that opening for writing does not block
    try:
        write_whole(fifo, "through the pipe")
        assert os.read(reader, 100) == b"through the pipe"
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(fifo.stat().st_mode)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_a_device_is_written_directly_and_a_full_one_is_an_oserror(tmp_path):
    with pytest.raises(OSError):
        write_whole("/dev/full", "x" * 10000)
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)  # still the device node
