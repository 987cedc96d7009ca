"""The two exceptions that tell a user's mistake and a Ctrl-C apart from a bug, and the signals
that stop a command.

- :class:`UserError` (a ``ValueError``): bad input from the user (a file, a flag, a setting, a
  value, an environment variable). Its message names what was wrong and says what was
  expected. The ``platonic`` command line prints it as one line and exits with code 2; every
  other exception is a bug and keeps its traceback. Library code raises it where it checks
  its inputs (``ConfigError``, ``RunError``, the CLI's ``CLIError`` and the photo loader's
  ``ImageRejected`` are user errors too).
- :class:`Interrupted` (a ``KeyboardInterrupt``): Ctrl-C, with a message saying what was saved
  and how to continue. The command line prints it as one line and exits with code 130 (143 for SIGTERM).

The stop signals (:data:`STOP_SIGNALS`): SIGINT (Ctrl-C), SIGTERM (what ``kill``, ``timeout``,
Slurm, systemd and container runtimes send) and SIGHUP (a closed terminal or SSH session) stop a
command alike: each raises
``KeyboardInterrupt`` (:func:`remembering_ctrl_c`), or, inside a training loop, asks it to stop
after the current step (:class:`StopBetweenSteps`), so that what is done is saved and one line
says so. The first signal is remembered (:func:`stopped_by`): the ``platonic`` console script
then ends by that signal (:func:`end_by_signal`: exit status 130, 143 or 129 as a shell sees it, so
that a script running ``platonic train; platonic evaluate`` stops as well). A signal that is
ignored when the command starts stays ignored: under ``nohup`` a hang-up does not stop a training.

A Ctrl-C is not lost where a C extension swallows it: Python raises ``KeyboardInterrupt`` in
whatever Python code runs when the signal arrives, and that can be code a compiled library
calls and whose exception it then clears (an overload resolution trying the next candidate).
The command line therefore runs in :func:`remembering_ctrl_c`, which notes every Ctrl-C before
raising, and long loops call :func:`raise_if_ctrl_c` between units of work (one shape of a
collection), which raises the interrupt again if it was noted but swallowed.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from contextlib import contextmanager
from typing import Dict, Iterator, List, Optional

__all__ = ["UserError", "Interrupted", "STOP_SIGNALS", "remembering_ctrl_c", "catch_stop_signals", "raise_if_ctrl_c",
           "stopped_by", "stop_words", "interrupt_exit_code", "interrupt_caught", "StopBetweenSteps", "end_by_signal"]

#: The signals that stop a command as Ctrl-C does, by name (those the platform has).
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")

#: How a command's one line names the signal that stopped it (SIGINT, or none: "interrupted").
_STOP_WORDS = {"SIGTERM": "terminated (SIGTERM)", "SIGHUP": "hung up (SIGHUP)"}

#: ``pressed``: a stop signal raised (or was swallowed); ``signal``: the first stop signal that came;
#: ``caught``: the command line has caught the interrupt (:func:`interrupt_caught`): later signals only note.
_ctrl_c: Dict[str, Optional[object]] = {"pressed": False, "signal": None, "caught": False}


def _stop_signals() -> List[int]:
    return [getattr(signal, name) for name in STOP_SIGNALS if hasattr(signal, name)]


def _note(signum: int) -> None:
    if _ctrl_c["signal"] is None:
        _ctrl_c["signal"] = signum


class UserError(ValueError):
    """Bad input from the user; the message names the file, flag or value and what was expected."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) while work was saved step by step; the message says what was saved and how to
    go on, ``saved`` (if given) what was saved alone, for a caller that words its own message."""

    def __init__(self, message: str, saved: Optional[str] = None):
        super().__init__(message)
        self.saved = saved


def _note_and_raise(signum: int, frame: object) -> None:
    _note(signum)
    if _ctrl_c["caught"]:                                    # a second Ctrl-C while the first's line is printed
        return
    _ctrl_c["pressed"] = True
    raise KeyboardInterrupt


def _is_default(signum: int, handler: object) -> bool:
    """Whether ``handler`` is Python's own for ``signum`` (or already this module's)."""
    return handler in (signal.default_int_handler, _note_and_raise) or (
        signum != signal.SIGINT and handler == signal.SIG_DFL)


@contextmanager
def remembering_ctrl_c() -> Iterator[None]:
    """Within the block, each stop signal (Ctrl-C, SIGTERM) notes itself before it raises
    ``KeyboardInterrupt``, so that :func:`raise_if_ctrl_c` can raise it again where a compiled
    library swallowed it and :func:`stopped_by` names it; the handlers before are restored
    afterwards. Only for a signal that has Python's default handler (not one that is ignored, or
    where someone installed their own) and in the main thread (the only one Python runs signal
    handlers in). The signals are also unblocked there: a process inherits its parent's signal
    mask, and a blocked Ctrl-C would wait unseen until the command had finished."""
    _ctrl_c.update(pressed=False, signal=None, caught=False)
    replaced = catch_stop_signals()
    try:
        yield
    finally:
        for s, handler in replaced.items():
            signal.signal(s, handler)


def catch_stop_signals() -> Dict[int, object]:
    """Make each stop signal that has Python's default handler note itself and raise
    ``KeyboardInterrupt`` (in the main thread; elsewhere nothing); return the handlers replaced.
    The console script calls it first thing, so that a Ctrl-C while the package loads is one line."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    replaced = {s: signal.getsignal(s) for s in _stop_signals() if _is_default(s, signal.getsignal(s))}
    if replaced and hasattr(signal, "pthread_sigmask"):     # a parent's blocked signal is inherited: unblock it
        signal.pthread_sigmask(signal.SIG_UNBLOCK, set(replaced))
    for s in replaced:
        signal.signal(s, _note_and_raise)
    return replaced


def raise_if_ctrl_c() -> None:
    """Raise ``KeyboardInterrupt`` if a Ctrl-C was noted within :func:`remembering_ctrl_c`; the
    interrupt's own exception is on its way already unless something swallowed it."""
    if _ctrl_c["pressed"]:
        raise KeyboardInterrupt


def stopped_by() -> Optional[int]:
    """The first stop signal (``signal.SIGINT``, ``SIGTERM``, ``SIGHUP``) that came in the command, else None."""
    return _ctrl_c["signal"]  # type: ignore[return-value]


def stop_words() -> str:
    """What stopped the command, for its one line: 'terminated (SIGTERM)', 'hung up (SIGHUP)', else
    'interrupted' (Ctrl-C, or a ``KeyboardInterrupt`` raised by code)."""
    sig = stopped_by()
    return _STOP_WORDS.get(signal.Signals(sig).name, "interrupted") if sig is not None else "interrupted"


def interrupt_exit_code() -> int:
    """The exit code of a command stopped by an interrupt: 128 + the signal (130 for Ctrl-C, 143
    for SIGTERM, 129 for SIGHUP), 130 where no signal came (a ``KeyboardInterrupt`` raised by code)."""
    sig = stopped_by()
    return 128 + int(sig) if sig is not None else 130


def interrupt_caught() -> None:
    """Say that the command line has caught the interrupt: until the next command, a stop signal
    only notes itself and raises nothing, so that a second Ctrl-C (``timeout --foreground`` sends
    more than one) cannot raise again while the command prints its one line and ends."""
    _ctrl_c["caught"] = True


class StopBetweenSteps:
    """While it is active (until :meth:`restore`), the stop signals do not raise: the first is
    noted (:attr:`signal`, and :func:`stopped_by`) for a loop that checks it between steps, saves
    and stops. A signal ignored before (``nohup`` ignores SIGHUP) stays ignored. In the main thread
    only (elsewhere it does nothing)."""

    def __init__(self) -> None:
        self.signal: Optional[int] = None
        self._previous: Dict[int, object] = {}
        if threading.current_thread() is threading.main_thread():
            for s in _stop_signals():
                if signal.getsignal(s) is not signal.SIG_IGN:
                    self._previous[s] = signal.signal(s, self._stop)

    def _stop(self, signum: int, frame: object) -> None:
        if self.signal is None:
            self.signal = signum
        _note(signum)

    def restore(self) -> None:
        """Put back the handlers there were before."""
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous.clear()


def end_by_signal(code: int) -> None:
    """End the process with exit code ``code``; where that is :func:`interrupt_exit_code` of a stop
    signal that came, end by that signal instead (its default action, after flushing stdout and
    stderr), so that a calling shell sees the signal and stops its script too (a process that
    merely exits 130 on Ctrl-C lets ``bash`` run the next line). Otherwise a stop signal from here
    on ends the process at once, quietly (none raises into Python's own shutdown)."""
    sig = stopped_by()
    if sig is not None and code == 128 + int(sig):
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        signal.signal(sig, signal.SIG_DFL)
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {sig})
        os.kill(os.getpid(), sig)
    if threading.current_thread() is threading.main_thread():
        for s in _stop_signals():
            if signal.getsignal(s) is _note_and_raise:
                signal.signal(s, signal.SIG_DFL)
    sys.exit(code)
