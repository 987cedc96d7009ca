"""Will it fit: the memory and disk this process has, and the one-line refusal where a command's
estimate exceeds them, before any work.

The one owner of "available memory" and "will it fit": ``compare`` (:func:`mitsuba_platonic.bench.compare.check_memory`),
the networks and the batch of a training (:mod:`mitsuba_platonic.train.memory_fit`), ``generate``
(:mod:`mitsuba_platonic.export`) and ``make-dataset`` (:mod:`mitsuba_platonic.data.render_collection`) read
:func:`available_memory` and :func:`free_disk` here and refuse through :func:`check_fits`. Estimates
are lower bounds where a command's true need is not known exactly (what is written and held alone):
a refusal is certain, a pass is not a promise.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable, List, Optional, Tuple, Union

from ..errors import UserError

__all__ = ["available_memory", "existing_folder", "free_disk", "check_fits", "gigabytes", "memory_check"]


def available_memory() -> Tuple[Optional[int], str]:
    """(bytes this process can still allocate, where the number comes from): ``MemAvailable`` of
    ``/proc/meminfo`` (else the free pages of ``os.sysconf``), or a cgroup v2 limit if that is
    smaller; ``(None, 'unknown')`` where neither can be read."""
    found: List[Tuple[int, str]] = []
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append((int(line.split()[1]) * 1024, "MemAvailable in /proc/meminfo"))
                    break
    except (OSError, ValueError, IndexError):
        pass
    if not found:
        try:
            found.append((os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "free pages, os.sysconf"))
        except (ValueError, OSError, AttributeError):
            pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            used = int(Path("/sys/fs/cgroup/memory.current").read_text())
            found.append((int(limit) - used, "the cgroup limit /sys/fs/cgroup/memory.max"))
    except (OSError, ValueError):
        pass
    return min(found) if found else (None, "unknown")


def existing_folder(path: Union[str, Path]) -> Path:
    """``path`` (absolute) or its nearest existing parent: where a file to be written there would live."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def free_disk(path: Union[str, Path]) -> Tuple[Optional[int], str]:
    """(bytes free on the file system ``path`` is or would be on, where the number comes from): its
    nearest existing folder's ``shutil.disk_usage``; ``(None, 'unknown')`` where it cannot be read."""
    p = existing_folder(path)
    try:
        return shutil.disk_usage(p).free, f"free on the disk of {p}"
    except OSError:
        return None, "unknown"


def gigabytes(n: float) -> str:
    """``n`` bytes for a message: '3.1 GB', '0.012 GB', '5.2e+05 GB'."""
    return f"{n / 1e9:.3g} GB"


def check_fits(need: int, have: Tuple[Optional[int], str], what: str, fix: str, resource: str = "memory") -> None:
    """Raise :class:`~mitsuba_platonic.errors.UserError`, one line, if ``need`` bytes exceed ``have``
    (``(bytes, source)`` of :func:`available_memory` or :func:`free_disk`; None: unknown, passes):
    ``<what> needs at least <need> of <resource>, more than the <have> available (<source>); <fix>``.
    ``what`` names the input in the command line's words (``--views 100000000``), ``fix`` what to change."""
    bytes_, source = have
    if bytes_ is None or need <= bytes_:
        return
    raise UserError(f"{what} needs at least {gigabytes(need)} of {resource} (an estimate), more than the "
                    f"{max(bytes_, 0) / 1e9:.1f} GB available ({source}); {fix}")


def memory_check(fix: str) -> Callable[[int, str], None]:
    """``fits(need, what)``: :func:`check_fits` of ``need`` bytes against :func:`available_memory`
    (read at each call), ``fix`` what to change; for readers below this layer that learn a size from
    a file (a volume's header, :mod:`mitsuba_platonic.files.volume_io`)."""
    return lambda need, what: check_fits(need, available_memory(), what, fix)
