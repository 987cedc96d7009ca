"""A full disk (or a used-up quota) in the one line a command ends with: which disk, how much is
free on it now, and what to do.

Every write of the project is atomic (:func:`~mitsuba_platonic.files.fileio.atomic_write`): the
file that could not be written is as it was before (or absent), the files written before it are
whole. :func:`no_room` finds the full-disk ``OSError`` behind an exception; :func:`what_to_free`
words the advice (the disk of the file, its free bytes, what to free); :func:`full_disk_line` is
the command line's text for a full disk nothing else has explained.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Optional

from .budget import existing_folder, free_disk, gigabytes

__all__ = ["NO_ROOM", "no_room", "what_to_free", "full_disk_line"]

#: The ``errno``s of a write that found no room: a full disk, a used-up disk quota.
NO_ROOM = (errno.ENOSPC, errno.EDQUOT)


def no_room(e: Optional[BaseException]) -> Optional[OSError]:
    """The ``OSError`` of a full disk or quota that ``e`` is or was raised from (its cause and
    context chain), else None."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, OSError) and e.errno in NO_ROOM:
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def _folder(e: OSError) -> Path:
    """The nearest existing folder of the file ``e`` names (the working folder if it names none)."""
    return existing_folder(Path(os.path.abspath(e.filename)).parent if e.filename else Path.cwd())


def what_to_free(e: OSError, free: str = "", then: str = "run the same command again") -> str:
    """``the disk holding <folder> is full (<n> free now): free space on it (<free>), or write
    elsewhere; then <then>``: the advice for the full-disk ``e`` (:func:`no_room`); ``free`` names
    what the command's own files there are that could go."""
    folder = _folder(e)
    free_bytes, _ = free_disk(folder)
    left = "free space unknown" if free_bytes is None else f"{gigabytes(free_bytes)} free now"
    quota = "its disk quota is used up" if e.errno == errno.EDQUOT else "is full"
    holding = f"the disk holding {folder} {quota}" if e.errno != errno.EDQUOT else f"{folder}: {quota}"
    return f"{holding} ({left}): free space on it{f' ({free})' if free else ''}, or write elsewhere; then {then}"


def full_disk_line(e: OSError) -> str:
    """The command line's words after the message of a full-disk ``OSError`` no command explained:
    what the atomic writes kept, and :func:`what_to_free`."""
    what = f"{e.filename!s}" if e.filename else "the file"
    return (f"{what} was not written (files are written whole or not at all: a copy there before is as it was, "
            f"and the files written before it are complete); {what_to_free(e)}")
