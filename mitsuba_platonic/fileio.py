"""Atomic file writes: a file is either its old self or completely written, never torn."""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path
from typing import Any, Callable, List, Optional

__all__ = ["atomic_write", "temporary_name", "remove_temporaries", "interrupt_behind"]

#: What :func:`temporary_name` names a temporary: ``.<stem>.tmp<pid><suffix>``.
_TEMPORARY = re.compile(r"\..+\.tmp\d+(\.[^.]+)?")

#: OS errors a writer that is not Python's own (Mitsuba's, OpenEXR's) may report in its message.
_WRITE_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS)


def temporary_name(path: Path) -> Path:
    """The hidden sibling ``path`` is written through: ``.<stem>.tmp<pid><suffix>`` (the suffix
    kept, so writers that pick a format by it still do)."""
    return path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")


def atomic_write(path: Path, write: Callable[[Path], Any], durable: bool = False) -> None:
    """Write ``path`` by calling ``write(tmp)`` on a temporary sibling, then renaming it into place.

    ``durable``: fsync the temporary file before the rename (for files a crash must not lose).
    The temporary file is removed if ``write`` fails (or is interrupted). A failed write (a full
    disk, no permission) raises ``OSError`` naming ``path``, also where the writer reported it
    as its own exception whose message names the OS error (Mitsuba and OpenEXR raise
    ``RuntimeError``), so that the command line shows it as one line. A Ctrl-C inside ``write``
    stays a ``KeyboardInterrupt`` even where the writer's own clean-up then fails on the torn file
    and raises something else (numpy's ``savez`` closing a zip whose entry is still open raises
    ``ValueError``), so the command line reports the interrupt, not the clean-up's error.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_name(path)
    try:
        write(tmp)
        if durable:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except Exception as e:
        interrupt = interrupt_behind(e)
        if interrupt is not None:                            # the clean-up of a write Ctrl-C tore
            raise interrupt from None
        failed = _as_os_error(e, path, tmp)
        if failed is None:
            raise
        raise failed from e
    finally:
        if tmp.exists():
            tmp.unlink()


def interrupt_behind(e: BaseException) -> Optional[KeyboardInterrupt]:
    """The ``KeyboardInterrupt`` that ``e`` is or was raised while handling (its context chain), if any:
    Dr.Jit re-raises a Ctrl-C in its callbacks as its own error, the interrupt only in the chain."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def _as_os_error(e: Exception, path: Path, tmp: Path) -> Optional[OSError]:
    """``e`` as an ``OSError`` naming ``path`` (not the temporary), if it is a failed write."""
    if isinstance(e, OSError):
        if e.errno is None or e.filename not in (None, str(tmp), tmp):
            return None
        return OSError(e.errno, e.strerror or os.strerror(e.errno), str(path))
    text = str(e)
    for code in _WRITE_ERRORS:
        if os.strerror(code) in text:
            return OSError(code, os.strerror(code), str(path))
    return None


def remove_temporaries(folder: Path) -> List[Path]:
    """Delete the temporaries :func:`atomic_write` left in ``folder`` when its process was killed
    (call it only while no other process writes there); return what was deleted."""
    removed = []
    if Path(folder).is_dir():
        for p in Path(folder).iterdir():
            if _TEMPORARY.fullmatch(p.name) and p.is_file():
                p.unlink()
                removed.append(p)
    return removed
