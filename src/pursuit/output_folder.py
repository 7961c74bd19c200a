"""Replacing an output folder so that it can be recovered at every instant.

An output folder ``DIR`` is assembled in a temporary folder beside it and
then swapped in.  Both helper folders are named so that a later run can tell
they are pursuit's and whether the process that made them is still alive::

    .DIR.pursuit-tmp-HOST-PID-RANDOM    being written
    .DIR.pursuit-old-HOST-PID-RANDOM    the previous DIR, being replaced

``HOST`` is a short hash of the machine's name (several machines may share
a file system) and ``PID`` the writing process.  :func:`recover` (called by
every write of ``DIR``) removes such folders whose process has ended on this
machine and, if ``DIR`` itself is missing because a writer died between
moving the old folder away and moving the new one in, moves the old one back.

On Linux the swap is one atomic ``renameat2(RENAME_EXCHANGE)``, so ``DIR``
never disappears; elsewhere (or on a file system without it) it takes two
renames, and the gap between them is what :func:`recover` repairs.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import os
import re
import secrets
import shutil
import socket
import sys
from pathlib import Path

__all__ = ["make_temp", "replace", "recover", "stale_folders", "HELPER_PATTERN"]

HELPER_PATTERN = r"\.{name}\.pursuit-(tmp|old)-([0-9a-f]{{8}})-([0-9]+)-([0-9a-f]{{8}})"
"""The helper folders' names (``{name}`` is the escaped name of the output folder)."""

_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100


def _host() -> str:
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]


def _helper(out_dir: Path, kind: str) -> Path:
    return out_dir.with_name(f".{out_dir.name}.pursuit-{kind}-{_host()}-{os.getpid()}-{secrets.token_hex(4)}")


def make_temp(out_dir: Path) -> Path:
    """Create (empty, permissions as for an ordinary folder) the temporary folder for ``out_dir``."""
    tmp = _helper(out_dir, "tmp")
    tmp.mkdir()
    return tmp


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def stale_folders(out_dir: Path) -> list[tuple[str, Path]]:
    """``(kind, path)`` of ``out_dir``'s helper folders left by an ended process on this machine.

    Only folders whose whole name matches :data:`HELPER_PATTERN` for this
    ``out_dir``, made on this machine by a process that no longer runs,
    are listed: never a live run's folder, another machine's or anyone
    else's.
    """
    pattern = re.compile(HELPER_PATTERN.format(name=re.escape(out_dir.name)))
    host = _host()
    found = []
    try:
        entries = list(out_dir.parent.iterdir())
    except FileNotFoundError:
        return []
    for path in sorted(entries):
        m = pattern.fullmatch(path.name)
        if m is None or m.group(2) != host or path.is_symlink() or not path.is_dir():
            continue
        if not _alive(int(m.group(3))):
            found.append((m.group(1), path))
    return found


def recover(out_dir: str | Path) -> list[Path]:
    """Repair what an interrupted writer of ``out_dir`` left; returns the folders removed.

    If ``out_dir`` is missing and an ended writer's ``old`` folder exists,
    it is moved back to ``out_dir`` (the output as it was before the
    interrupted replacement).  Every other stale helper folder is removed.
    """
    out_dir = Path(out_dir)
    stale = stale_folders(out_dir)
    olds = [p for kind, p in stale if kind == "old"]
    if olds and not out_dir.exists():
        # One writer at a time owns the gap; if several died there, the newest old folder is the latest output.
        newest = max(olds, key=lambda p: p.stat().st_mtime)
        newest.rename(out_dir)
        stale = [(k, p) for k, p in stale if p != newest]
    removed = []
    for _, path in stale:
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2``); False where that is not available."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # file system or kernel without it
        return False
    raise OSError(err, os.strerror(err), str(a), None, str(b))


def replace(tmp: Path, out_dir: Path) -> None:
    """Put the complete folder ``tmp`` at ``out_dir``, replacing what is there.

    If ``out_dir`` exists, it and ``tmp`` are swapped atomically where the
    system allows, so ``out_dir`` is always either the old or the new
    output.  Otherwise the old folder is first renamed to an ``old`` helper
    folder; if this process is interrupted (any exception, including
    ``KeyboardInterrupt``) before the new one is in place, the old one is
    moved back; if it is killed, the next :func:`recover` moves it back.
    """
    if not out_dir.exists():
        tmp.rename(out_dir)
        return
    if _exchange(tmp, out_dir):
        shutil.rmtree(tmp, ignore_errors=True)  # it holds the previous output now
        return
    old = _helper(out_dir, "old")
    out_dir.rename(old)
    try:
        tmp.rename(out_dir)
    except BaseException:
        if not out_dir.exists():
            old.rename(out_dir)
        raise
    shutil.rmtree(old, ignore_errors=True)
