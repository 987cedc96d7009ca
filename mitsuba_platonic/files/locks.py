"""One writer per folder: an exclusive lock file, held while a command writes there.

:func:`exclusive_lock` holds a lock file (``flock``, exclusive, not waiting) that names its holder
(its first line: the pid, and for an output folder the command: ``1234 platonic evaluate``). The
kernel releases the lock when its process ends, so a lock file a killed command left is simply
taken over, while a second command on the folder of a live one is refused at once, in one line
naming the holder. The file is opened never through a link
(:func:`~mitsuba_platonic.files.fileio.open_file`) and removed on release, while still held (no
one can hold a stale copy of it). ``train``'s ``run.lock`` (:func:`mitsuba_platonic.train.folder.run_lock`)
and every output folder's ``platonic.lock`` (:func:`mitsuba_platonic.files.outputs.output_lock`) are such locks.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from .fileio import open_file

__all__ = ["exclusive_lock", "lock_holder"]


def lock_holder(fd: int) -> str:
    """The holder a lock file names (its first line, printable, at most 80 characters), else ``'?'``."""
    try:
        text = os.pread(fd, 80, 0).decode(errors="replace").splitlines()
    except OSError:
        return "?"
    first = text[0].strip() if text else ""
    return first if first and first.isprintable() else "?"


@contextmanager
def exclusive_lock(path: Path, holder: str, refused: Callable[[str], Exception]) -> Iterator[Path]:
    """Hold the lock file ``path`` (created if missing; its folder must exist) while inside, writing
    ``holder`` as its first line; where a live process holds it, raise ``refused(its holder line)``
    (nothing written). The file is removed on exit."""
    import fcntl  # lazy: POSIX only, where folders are locked

    path = Path(path)
    while True:
        fd = open_file(path, os.O_RDWR | os.O_CREAT)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            held_by = lock_holder(fd)
            os.close(fd)
            raise refused(held_by) from None
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)                                 # its holder removed it as we opened it: again
    try:
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{holder}\n".encode(), 0)
        except OSError as e:                         # a full disk: say where
            raise OSError(e.errno, e.strerror, str(path)) from None
        yield path
    finally:
        try:
            os.unlink(path)                          # while still holding it: no one can hold a stale copy
        finally:
            os.close(fd)
