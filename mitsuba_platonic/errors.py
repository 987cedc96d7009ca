"""The two exceptions that tell a user's mistake and a Ctrl-C apart from a bug.

- :class:`UserError` (a ``ValueError``): bad input from the user (a file, a flag, a setting, a
  value, an environment variable). Its message names what was wrong and says what was
  expected. The ``platonic`` command line prints it as one line and exits with code 2; every
  other exception is a bug and keeps its traceback. Library code raises it where it checks
  its inputs (``ConfigError``, ``RunError``, the CLI's ``CLIError`` and the photo loader's
  ``ImageRejected`` are user errors too).
- :class:`Interrupted` (a ``KeyboardInterrupt``): Ctrl-C, with a message saying what was saved
  and how to continue. The command line prints it as one line and exits with code 130.

A Ctrl-C is not lost where a C extension swallows it: Python raises ``KeyboardInterrupt`` in
whatever Python code runs when the signal arrives, and that can be code a compiled library
calls and whose exception it then clears (an overload resolution trying the next candidate).
The command line therefore runs in :func:`remembering_ctrl_c`, which notes every Ctrl-C before
raising, and long loops call :func:`raise_if_ctrl_c` between units of work (one shape of a
collection), which raises the interrupt again if it was noted but swallowed.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator, Optional

__all__ = ["UserError", "Interrupted", "remembering_ctrl_c", "raise_if_ctrl_c"]

_ctrl_c = {"pressed": False}


class UserError(ValueError):
    """Bad input from the user; the message names the file, flag or value and what was expected."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) while work was saved step by step; the message says what was saved and how to
    go on, ``saved`` (if given) what was saved alone, for a caller that words its own message."""

    def __init__(self, message: str, saved: Optional[str] = None):
        super().__init__(message)
        self.saved = saved


def _note_and_raise(signum: int, frame: object) -> None:
    _ctrl_c["pressed"] = True
    raise KeyboardInterrupt


@contextmanager
def remembering_ctrl_c() -> Iterator[None]:
    """Within the block, Ctrl-C (SIGINT) notes itself before it raises ``KeyboardInterrupt`` as
    usual, so that :func:`raise_if_ctrl_c` can raise it again where a compiled library swallowed
    it; the handler before is restored afterwards. Only where SIGINT has Python's default
    handler (not where it is ignored, or where someone installed their own) and in the main
    thread (the only one Python runs signal handlers in). SIGINT is also unblocked there: a
    process inherits its parent's signal mask, and a blocked Ctrl-C would wait unseen until the
    command had finished."""
    _ctrl_c["pressed"] = False
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.default_int_handler or threading.current_thread() is not threading.main_thread():
        yield
        return
    if hasattr(signal, "pthread_sigmask"):                   # a parent's blocked SIGINT is inherited: unblock it
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, _note_and_raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def raise_if_ctrl_c() -> None:
    """Raise ``KeyboardInterrupt`` if a Ctrl-C was noted within :func:`remembering_ctrl_c`; the
    interrupt's own exception is on its way already unless something swallowed it."""
    if _ctrl_c["pressed"]:
        raise KeyboardInterrupt
