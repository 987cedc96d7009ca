"""How a command ends, as the user sees it: one line on stderr for a user error (exit code 2),
a Ctrl-C (130) or a warning, never a traceback for those.

A Ctrl-C's line says what was saved and how to go on: the command's own account where it
raised :class:`~mitsuba_platonic.errors.Interrupted`, else the ``interrupted`` text its subparser
set (``p.set_defaults(interrupted=...)``), else :data:`STARTING`.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from typing import Optional

from ..errors import Interrupted, stop_words
from ..files.fileio import interrupt_behind
from ..runtime.no_room import full_disk_line, no_room
from ..settings_checks import quoted
from .args import PROG

__all__ = ["STARTING", "one_line", "interrupt_message", "error_message", "interrupt_behind", "printable_streams",
           "run_handler"]

#: What a Ctrl-C leaves before a command runs, or in a command that says nothing more precise.
STARTING = "while starting; nothing was written"


def one_line(text: object) -> str:
    """``text`` (a message or an exception) as one line: its lines stripped and joined by spaces."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def interrupt_message(args: Optional[argparse.Namespace], e: BaseException) -> str:
    """The one line of a Ctrl-C in the command of ``args`` (None: before the arguments were parsed)."""
    command = getattr(args, "command", None)
    where = f"{PROG} {command}" if command else PROG
    detail = str(e) if isinstance(e, Interrupted) and str(e) else getattr(args, "interrupted", STARTING)
    what = stop_words()
    return f"{where}: {what}: {one_line(detail)}"


def error_message(args: Optional[argparse.Namespace], e: BaseException) -> str:
    """The one line of a user error: ``platonic <command>: error: <message>``; for a full disk (an
    ``OSError`` no command explained) also what was kept and what to free where."""
    full = no_room(e) if isinstance(e, OSError) else None
    more = f"; {full_disk_line(full)}" if full is not None else ""
    return f"{PROG} {getattr(args, 'command', None)}: error: {one_line(os_error_text(e))}{more}"


def os_error_text(e: BaseException) -> object:
    """An ``OSError`` from a file or disk as Python words it (``[Errno 36] File name too long: 'PATH'``)
    but with each path quoted at most a few hundred characters (:func:`~mitsuba_platonic.settings_checks.quoted`):
    a path made of a user's 10 MB name was a 10 MB line. Anything else as it is."""
    if not isinstance(e, OSError) or e.errno is None or e.strerror is None or e.filename is None:
        return e
    paths = " -> ".join(quoted(p) for p in (e.filename, e.filename2) if p is not None)
    return f"[Errno {e.errno}] {e.strerror}: {paths}"


def printable_streams() -> None:
    """Make stdout and stderr print any text (help and messages hold ³, →, …): characters the
    terminal's encoding lacks (PYTHONIOENCODING=ascii) are escaped instead of raising."""
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):
                pass


def run_handler(args: argparse.Namespace) -> int:
    """Call ``args.handler`` with warnings shown as one line each, ``platonic <command>: warning: …``."""
    def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"{PROG} {args.command}: warning: {message}", file=sys.stderr if file is None else file)

    with warnings.catch_warnings():                          # restores Python's own display afterwards
        warnings.showwarning = one_line_warning
        return int(args.handler(args))
