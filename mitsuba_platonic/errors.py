"""The two exceptions that tell a user's mistake and a Ctrl-C apart from a bug.

- :class:`UserError` (a ``ValueError``): bad input from the user (a file, a flag, a setting, a
  value, an environment variable). Its message names what was wrong and says what was
  expected. The ``platonic`` command line prints it as one line and exits with code 2; every
  other exception is a bug and keeps its traceback. Library code raises it where it checks
  its inputs (``ConfigError``, ``RunError``, the CLI's ``CLIError`` and the photo loader's
  ``ImageRejected`` are user errors too).
- :class:`Interrupted` (a ``KeyboardInterrupt``): Ctrl-C, with a message saying what was saved
  and how to continue. The command line prints it as one line and exits with code 130.
"""

from __future__ import annotations

from typing import Optional

__all__ = ["UserError", "Interrupted"]


class UserError(ValueError):
    """Bad input from the user; the message names the file, flag or value and what was expected."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) while work was saved step by step; the message says what was saved and how to
    go on, ``saved`` (if given) what was saved alone, for a caller that words its own message."""

    def __init__(self, message: str, saved: Optional[str] = None):
        super().__init__(message)
        self.saved = saved
