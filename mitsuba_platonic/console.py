"""The ``platonic`` console script (and ``python -m mitsuba_platonic.cli``): :func:`main`.

It catches the stop signals first thing, before the command line's modules load, so that a
Ctrl-C (or SIGTERM, or SIGHUP) at any moment is one line and no traceback; it runs
:func:`mitsuba_platonic.cli.main`; and a command that a signal stopped ends by that signal
(:func:`~mitsuba_platonic.errors.end_by_signal`: a shell sees exit status 130, 143 or 129 and stops its
script), once it has saved what it had and said so.
"""

from __future__ import annotations

import sys
from typing import Optional, Sequence

from .errors import catch_stop_signals, end_by_signal, interrupt_caught, interrupt_exit_code, stop_words

__all__ = ["main"]


def main(argv: Optional[Sequence[str]] = None) -> None:
    """Run ``platonic`` with ``argv`` (default ``sys.argv[1:]``) and end the process: by the exit
    code of :func:`mitsuba_platonic.cli.main`, or by the stop signal that interrupted it."""
    catch_stop_signals()
    started = False
    try:
        from .cli import main as run  # here, after the signals are caught: it loads the command line's modules

        started = True
        code = run(argv)
    except KeyboardInterrupt:                                # while the command line loaded, or as it returned
        interrupt_caught()
        if not started:
            what = stop_words()
            print(f"platonic: {what}: while starting; nothing was written", file=sys.stderr)
        code = interrupt_exit_code()
    end_by_signal(code)
