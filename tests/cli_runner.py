"""Running ``platonic`` in the test process, and the one-line check of a user error."""

from __future__ import annotations

import contextlib
import io
from typing import List, Optional, Sequence, Tuple

from mitsuba_platonic.cli import main


def run_cli(argv: Sequence[str]) -> Tuple[int, str, str]:
    """``main(argv)`` in this process → (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def one_line(stderr: str, command: str, kind: Optional[str] = None) -> str:
    """The single line a user error prints, checked: one line, no traceback, ``platonic <command>: ``
    (followed by ``<kind>: `` when ``kind`` is given, e.g. 'error')."""
    err = stderr.strip()
    assert "\n" not in err and "Traceback" not in err, err
    prefix = f"platonic {command}: " + (f"{kind}: " if kind else "")
    assert err.startswith(prefix), err
    return err


def set_flags(overrides: Sequence[str]) -> List[str]:
    """``--set KEY=VALUE`` for each override, as the command line takes them."""
    return [arg for o in overrides for arg in ("--set", o)]
