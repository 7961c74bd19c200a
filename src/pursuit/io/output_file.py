"""Writing ``pursuit track``'s output file without losing anything that was there.

Two rules:

* the output must not be the input: :func:`same_file` tells, through links
  (symbolic and hard) and for an input that is standard input redirected
  from a file;
* :func:`write_whole` replaces a regular file atomically, keeping its
  permission bits, writes through a symbolic link to its target (the link
  stays a link), and writes a FIFO, a device or a socket directly (they have
  no earlier content to keep whole, and renaming over ``/dev/full`` would
  replace the device node with a regular file).
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable

__all__ = ["same_file", "same_file_as_stream", "write_whole"]


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether the paths name one file (after following links); False if either does not exist."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def same_file_as_stream(stream: BinaryIO, path: str | os.PathLike) -> bool:
    """Whether an open stream (standard input redirected from a file, say) reads the file at ``path``."""
    try:
        mine = os.fstat(stream.fileno())
        theirs = os.stat(path)
    except (AttributeError, OSError, ValueError):
        return False
    return stat.S_ISREG(mine.st_mode) and (mine.st_dev, mine.st_ino) == (theirs.st_dev, theirs.st_ino)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def replace_with(path: str | os.PathLike, produce: Callable[[str], None]) -> None:
    """Have ``produce`` write a temporary file beside ``path``, then rename it into place.

    For writers that want a file name rather than text (``Figure.savefig``
    picks the format from the suffix, which the temporary file keeps).  The
    file gets the mode of the regular file it replaces, or the default mode
    less the umask; a symbolic link is followed to its target.  On any
    failure (or interruption) the temporary file is removed and ``path`` is
    unchanged.
    """
    target = Path(os.path.realpath(path))
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    mode = stat.S_IMODE(st.st_mode) if st is not None and stat.S_ISREG(st.st_mode) else 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    try:
        os.chmod(tmp, mode)
        produce(tmp)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_whole(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` so that a reader sees the old content or the new one, never part of either.

    A regular file (or a new one) is written to a temporary file beside it,
    flushed to disk and renamed into place; it keeps the mode of the file it
    replaces, or gets the default mode less the umask.  A symbolic link is
    followed to its target (a dangling link creates its target).  A path
    that is neither a regular file nor missing (a FIFO, a character device)
    is opened and written directly.

    Raises
    ------
    OSError
        When the file cannot be written; nothing at ``path`` has changed then
        (except for a FIFO or device, which was written as far as it took).
    """
    target = Path(os.path.realpath(path))
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        with open(target, "w", encoding="utf-8", newline="") as f:
            f.write(text)
        return
    mode = stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
