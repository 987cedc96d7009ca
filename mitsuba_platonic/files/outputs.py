"""Output folders: which ``--out`` folder a command may write into, and which it made itself.

``evaluate``, ``quickstart`` and ``compare`` write fixed names (``report.md``, ``results.json``,
``compare.json``, …) into their ``--out`` folder. A folder they write into is one that did not
exist or was empty, or one they made before: :func:`claim_output_folder` writes the marker
:data:`MARKER` (``platonic.json``, naming the command) first, as ``train`` marks a run folder with
``run.json``, so that the command's own earlier output is recognised (a quickstart resumes, an
evaluation is redone in place). Any other folder that holds something is the user's: it is refused,
with nothing in it changed, unless ``--overwrite`` (as ``reconstruct`` and ``generate`` take it),
which replaces the files of the command's names there and nothing else.

One command at a time in an output folder: :func:`output_lock` holds :data:`LOCK`
(``platonic.lock``, an exclusive lock naming its holder, :func:`~mitsuba_platonic.files.locks.exclusive_lock`)
while a command writes there, so that a second command into the same ``--out`` is refused at
once, in one line naming the holder, instead of mixing its files with the first's.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Optional, Union

from ..errors import UserError
from .fileio import check_path, make_folder, write_text
from .locks import exclusive_lock

__all__ = ["MARKER", "LOCK", "made_by", "check_output_folder", "claim_output_folder", "output_lock"]

#: The file a command writes first into an output folder it makes: ``{"written_by": "platonic <command>"}``.
MARKER = "platonic.json"
#: The lock file a command holds in its output folder while it writes there (:func:`output_lock`).
LOCK = "platonic.lock"


def made_by(folder: Union[str, Path]) -> Optional[str]:
    """The command (``platonic evaluate``) whose :data:`MARKER` ``folder`` holds, else None."""
    try:
        data = json.loads((Path(folder) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    written_by = data.get("written_by") if isinstance(data, dict) else None
    return written_by if isinstance(written_by, str) else None


def check_output_folder(out: Union[str, Path], command: str, overwrite: bool = False,
                        earlier: Optional[Callable[[Path], bool]] = None) -> Path:
    """Refuse ``out`` as the output folder of ``platonic <command>`` unless it may write there; change nothing.

    ``out`` may be new, empty, marked by ``command``, or recognised by ``earlier(out)`` as the
    command's own output from before the marker existed. Any other ``out`` that holds something is
    refused (:class:`~mitsuba_platonic.errors.UserError`, one line naming ``--out`` and
    ``--overwrite``) unless ``overwrite``; a file is refused always.
    """
    out = Path(out)
    name = f"platonic {command}"
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file, not a folder; choose another --out")
    if out.is_dir() and made_by(out) != name and not (earlier is not None and earlier(out)):
        held = sorted(p.name for p in out.iterdir() if p.name != LOCK)     # a lock is no one's output
        if held and not overwrite:
            shown = ", ".join(held[:3]) + (f" and {len(held) - 3} more" if len(held) > 3 else "")
            raise UserError(f"--out {out} holds {len(held)} item(s) {command} did not write ({shown}); nothing was "
                            f"changed: choose another (or an empty) --out, or pass --overwrite to write there, "
                            f"replacing the files of {command}'s names")
    return out


def claim_output_folder(out: Union[str, Path], command: str, overwrite: bool = False,
                        earlier: Optional[Callable[[Path], bool]] = None) -> Path:
    """:func:`check_output_folder`, then make ``out`` the output folder of ``platonic <command>``
    (create it and write :data:`MARKER`) unless it is one already; return it. Call it inside
    :func:`~mitsuba_platonic.files.fileio.confined` ``(out)``, so a link named :data:`MARKER` is refused too."""
    out = check_output_folder(out, command, overwrite, earlier)
    name = f"platonic {command}"
    check_path(out / MARKER)
    if made_by(out) != name:
        make_folder(out)
        write_text(out / MARKER, json.dumps({"written_by": name, "pid": os.getpid()}) + "\n")
    return out


@contextmanager
def output_lock(out: Union[str, Path], command: str) -> Iterator[Path]:
    """Hold ``out/``:data:`LOCK` while inside: ``platonic <command>`` is the one command writing into
    ``out`` (created if missing; removed again on exit if it was created here and is still empty).
    Where a live command holds it, :class:`~mitsuba_platonic.errors.UserError`, one line naming the
    holder (its pid and command) and ``--out``, before anything is written. Call it inside
    :func:`~mitsuba_platonic.files.fileio.confined` ``(out)``, so a link named :data:`LOCK` is refused too."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file, not a folder; choose another --out")
    created = not out.exists()
    make_folder(out)
    path = out / LOCK

    def refused(holder: str) -> UserError:
        pid, _, who = holder.partition(" ")
        held_by = f"pid {pid}, {who}" if pid.isdigit() and who else f"pid {pid}" if pid.isdigit() else "?"
        return UserError(f"--out {out} is in use by another command ({held_by}; lock {path}); nothing was "
                         f"written: wait for it to end, or choose another --out")

    try:
        with exclusive_lock(path, f"{os.getpid()} platonic {command}", refused):
            yield out
    finally:
        if created:
            try:
                out.rmdir()                                   # nothing was written: leave no new folder
            except OSError:
                pass
