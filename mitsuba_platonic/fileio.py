"""Atomic file writes: a file is either its old self or completely written, never torn."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable

__all__ = ["atomic_write", "temporary_name"]


def temporary_name(path: Path) -> Path:
    """The hidden sibling ``path`` is written through: ``.<stem>.tmp<pid><suffix>`` (the suffix
    kept, so writers that pick a format by it still do)."""
    return path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")


def atomic_write(path: Path, write: Callable[[Path], Any], durable: bool = False) -> None:
    """Write ``path`` by calling ``write(tmp)`` on a temporary sibling, then renaming it into place.

    ``durable``: fsync the temporary file before the rename (for files a crash must not lose).
    The temporary file is removed if ``write`` fails (or is interrupted).
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
    finally:
        if tmp.exists():
            tmp.unlink()
