"""mitsuba-platonic: PlatonicGAN with closed-form and Mitsuba 3 rendering layers.

Data flow: ``views`` → ``volume`` → ``render`` (closed form | Mitsuba) → images →
networks → training → evaluation/export.

Importing the package is cheap and needs no Dr.Jit: ``render``, ``render_with``,
``RenderSettings``, ``views`` and ``volume`` are imported on first use, so that ``platonic
--help`` answers at once and a Ctrl-C while torch loads reaches the command line's handler.
Where Dr.Jit is needed (a Mitsuba render, the first read of ``BACKEND``) its backend is checked
(:func:`~mitsuba_platonic.runtime.backend.check_backend`), raising
:class:`~mitsuba_platonic.runtime.backend.BackendError` with install instructions if it has none; the
closed-form layers, photo loading and ``--help`` work without a usable LLVM.

Where the package is imported by the ``platonic`` command itself (its console script, or ``python -m
mitsuba_platonic.cli``), a Ctrl-C that comes while it imports, before the command line catches the
signals (:mod:`mitsuba_platonic.console`), is one line too, ``platonic: interrupted: while starting;
nothing was written``, not a traceback (:func:`_one_line_interrupt`, Python's hook for an uncaught
exception; the process still ends by SIGINT: exit status 130 to a shell). Imported by anyone else,
the package changes nothing of the kind.
"""

from __future__ import annotations

import sys


def _launched_as_the_command() -> bool:
    """Whether this process is the ``platonic`` command: its console script, or ``-m mitsuba_platonic.cli``."""
    script = sys.argv[0].replace("\\", "/").rsplit("/", 1)[-1] if sys.argv else ""
    line = list(getattr(sys, "orig_argv", ()))
    module = line[line.index("-m") + 1] if "-m" in line[:-1] else ""
    return script in ("platonic", "platonic.exe", "platonic-script.py") or module.startswith("mitsuba_platonic.cli")


def _one_line_interrupt(kind, value, traceback, _before=sys.excepthook) -> None:
    """A Ctrl-C before the command line caught it: one line; anything else as Python shows it."""
    if issubclass(kind, KeyboardInterrupt):
        print("platonic: interrupted: while starting; nothing was written", file=sys.stderr)
        return
    _before(kind, value, traceback)


if _launched_as_the_command():  # first, before the imports that take the first ~100 ms (LLVM's search, typing)
    sys.excepthook = _one_line_interrupt

import importlib  # noqa: E402
import types  # noqa: E402
from typing import Any  # noqa: E402

from .runtime.backend import BackendError, check_backend, preselect_libllvm  # noqa: E402

__version__ = "0.1.0"
__all__ = ["render", "render_with", "RenderSettings", "views", "volume", "BackendError", "BACKEND", "__version__"]

preselect_libllvm()              # before anything imports drjit: the newest LLVM >= 16, where none is chosen

#: Names imported on first use: (the module that holds each, its name there; None: the module itself).
_LAZY = {"render": (".render", "render"), "render_with": (".render", "render_with"),
         "RenderSettings": (".render", "RenderSettings"), "views": (".views", None), "volume": (".volume", None)}


def __getattr__(name: str) -> Any:
    """``BACKEND`` (checked once, on first read) and the lazily imported names of :data:`_LAZY`."""
    if name == "BACKEND":
        backend = check_backend()                # raises BackendError; a failure is not remembered
        globals()["BACKEND"] = backend
        return backend
    if name in _LAZY:
        where, attribute = _LAZY[name]
        module = importlib.import_module(where, __name__)
        value = module if attribute is None else getattr(module, attribute)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _Package(types.ModuleType):
    """The package module: its ``render`` stays the function (as it always was), also after the
    import system binds the just-loaded ``render`` subpackage to that name."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "render" and isinstance(value, types.ModuleType):
            value = value.render
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
