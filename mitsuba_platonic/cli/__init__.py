"""The ``platonic`` command line: its parser and :func:`main`.

Subcommands (one ``argparse`` subparser each), one module per group, each command a thin handler
that checks its flags, calls the library function that does the work and prints what it wrote:

- :mod:`.training`: ``quickstart``, ``train``, ``evaluate``.
- :mod:`.export`: ``reconstruct`` / ``generate``, a trained run's volumes, turntables and meshes.
- :mod:`.dataset`: ``make-dataset``, procedural shape classes rendered to image collections.
- :mod:`.renderers`: ``compare`` (closed form vs Mitsuba on one volume) and ``bench`` (the
  renderers' speed/accuracy trade).
- :mod:`.viewer`: ``view``, an interactive web viewer on the renderers (the ``viewer`` extra).
- :mod:`.checkpoints`: ``convert-checkpoint``, for a trusted checkpoint the safe loader refuses
  (the only command that unpickles with ``weights_only=False``).

Shared: :mod:`.args` (``CLIError``, the argparse number types, ``--models``), :mod:`.exits`
(the one-line messages of errors, Ctrl-C and warnings). To add a command, write an
``add_<command>(sub)`` that adds its subparser with ``handler`` (parsed arguments → exit code) and
``interrupted`` (what a Ctrl-C leaves) defaults, and list it in :data:`SUBCOMMANDS`.

Every module here imports only argparse and the package's light modules at the top, so importing
the package loads no numpy or torch; building the parser loads torch (the choice lists it offers
live beside the torch code that owns them) but never Mitsuba or Dr.Jit: each handler imports
what it runs when it runs, so ``--help`` and a wrong flag answer without starting LLVM. A command
line that starts with ``view`` is parsed by the parser of that command alone (:data:`ALONE`:
``build_parser("view")``, the same usage, help and errors), which loads no torch: ``platonic view``
prints its page's address while torch loads (:mod:`.viewer`).

Exit codes: 0 on success; 2 on a user error (usage errors, unreadable or invalid files, invalid
options: :class:`~mitsuba_platonic.errors.UserError`, which ``ConfigError``, ``RunError`` and
``CLIError`` are, ``BackendError``, and ``OSError`` from files and disks), printed as one line on
stderr without a traceback; 130 on Ctrl-C, 143 on SIGTERM and 129 on SIGHUP, one line saying what was saved (the
console script, :mod:`mitsuba_platonic.console`, then ends by the signal itself, so that a calling
shell stops too). Any other exception is a bug and keeps its traceback (exit code 1).
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Optional, Sequence

from .. import __version__
from ..errors import UserError, interrupt_caught, interrupt_exit_code, remembering_ctrl_c
from ..runtime.backend import BackendError
from .args import PROG, CLIError, parse_models
from .checkpoints import add_convert_checkpoint
from .dataset import add_make_dataset
from .exits import error_message, interrupt_behind, interrupt_message, printable_streams, run_handler
from .export import add_generate, add_reconstruct
from .renderers import add_bench, add_compare
from .training import add_evaluate, add_quickstart, add_train
from .viewer import add_view

__all__ = ["main", "build_parser", "parse_models", "CLIError", "SUBCOMMANDS", "ALONE"]

#: Subcommand registrars, in help order. Add ``add_<command>`` functions here.
SUBCOMMANDS: Sequence[Callable[["argparse._SubParsersAction"], None]] = (
    add_quickstart, add_train, add_reconstruct, add_generate, add_evaluate, add_make_dataset, add_compare,
    add_bench, add_convert_checkpoint, add_view)
#: Commands whose subparser loads nothing heavy: a command line starting with one of them is parsed
#: by a parser of it alone (its subparser the same, and the top level's usage: ``COMMAND``).
ALONE = {"view": add_view}


def build_parser(alone: Optional[str] = None) -> argparse.ArgumentParser:
    """The ``platonic`` parser with one subparser per subcommand (``alone``: a command of
    :data:`ALONE`, the only subparser)."""
    parser = argparse.ArgumentParser(
        prog=PROG, description="PlatonicGAN with closed-form and Mitsuba 3 rendering layers.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in (ALONE[alone],) if alone else SUBCOMMANDS:
        add(sub)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run ``platonic`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Usage errors (argparse) and user errors (:class:`~mitsuba_platonic.errors.UserError`,
    ``BackendError``, and ``OSError``: a missing file, no permission, a full disk) print a
    one-line message on stderr and return 2; Ctrl-C, at any moment (numpy and torch load in
    here, where it is caught), prints one line on stderr saying what was saved and how to go on
    and returns 130 (SIGTERM likewise, returning 143); ``--help`` and ``--version`` return 0. Any other exception is a bug: it
    propagates with its traceback. A warning (a skipped photo, a checkpoint fallen back from) is
    one line, ``platonic <command>: warning: …``, not Python's file-and-source-line format.
    """
    printable_streams()
    with remembering_ctrl_c():                               # a Ctrl-C a library swallows is raised again
        return _run(argv)


def _run(argv: Optional[Sequence[str]]) -> int:
    args: Optional[argparse.Namespace] = None
    try:
        words = sys.argv[1:] if argv is None else list(argv)
        parser = build_parser(words[0]) if words and words[0] in ALONE else build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # argparse has printed usage / help already
            return int(e.code) if isinstance(e.code, int) else 2
        return run_handler(args)
    except KeyboardInterrupt as e:
        interrupt_caught()                                   # a second Ctrl-C now raises nothing
        print(interrupt_message(args, e), file=sys.stderr)
        return interrupt_exit_code()
    except (UserError, BackendError, OSError) as e:
        print(error_message(args, e), file=sys.stderr)
        return 2
    except Exception as e:
        interrupt = interrupt_behind(e)
        if interrupt is None:
            raise
        interrupt_caught()
        print(interrupt_message(args, interrupt), file=sys.stderr)
        return interrupt_exit_code()
