"""Live runs: ``platonic view RUN`` on a run still training follows its newest checkpoint.

:class:`RunWatcher` polls, every :data:`POLL_S` seconds in a thread of its own, the run folder's
``checkpoints/last.pt`` (its modification time and size, :func:`stamp`) and ``scalars.csv``. A
new ``last.pt`` is read there (:func:`~.scene.model_of`, off the page's request threads) and
handed to a callback (the app swaps the scene's volume for the new model's, under its scene lock,
and every page renders again); a ``scalars.csv`` that changed is read for its last row. A
checkpoint that cannot be read (torn by a copy, corrupt, another run's) is one line in the
server's log and nothing else: the model shown stays the previous one, and the same file is not
tried again until its stamp changes (the rest of a write, the next checkpoint).

Training saves ``last.pt`` by an atomic rename (:func:`~mitsuba_platonic.files.checkpoint.save_checkpoint`),
so a run this watches is never read half written; the one-line refusal is for files put there by
other means. :func:`status_line` is what the page shows: the model's step and the latest losses.
"""

from __future__ import annotations

import csv
import sys
import threading
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple

from ..errors import UserError

__all__ = ["POLL_S", "stamp", "last_scalars", "status_line", "RunWatcher"]

#: How often the watcher looks at the run folder (seconds).
POLL_S = 2.0
#: At most this many losses on the page's run line (the ``loss_*`` columns, in the file's order).
MAX_LOSSES = 6

Stamp = Optional[Tuple[int, int]]


def stamp(path: Path) -> Stamp:
    """``(modification time in ns, size in bytes)`` of ``path``, None where there is no such file."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size)


def last_scalars(folder: Path) -> Dict[str, str]:
    """The last row of ``folder/scalars.csv`` as written (column → text), {} where there is none or it
    cannot be read."""
    try:
        with open(Path(folder) / "scalars.csv", newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, csv.Error, UnicodeDecodeError):
        return {}
    return {k: v for k, v in rows[-1].items() if k is not None and v not in (None, "")} if rows else {}


def status_line(step: int, scalars: Dict[str, str]) -> str:
    """The page's run line: the step of the model shown, and the ``loss_*`` columns of ``scalars.csv``'s
    last row (its step named where it is another)."""
    line = f"run: model of step {step} (checkpoints/last.pt, followed every {POLL_S:g} s)"
    losses = [(k, v) for k, v in scalars.items() if k.startswith("loss_")][:MAX_LOSSES]
    if losses:
        line += f"; scalars.csv, step {scalars.get('step', '?')}: " + ", ".join(f"{k} {v}" for k, v in losses)
    return line


class RunWatcher:
    """Follow ``folder`` (a run): ``load(path)`` → a model for each new ``checkpoints/last.pt``, handed to
    ``on_model(model)``; ``on_status()`` after either changed. ``seen``: the checkpoint's stamp the
    shown model was read from (None: read it at the first poll); ``step``: that model's step."""

    def __init__(self, folder: Path, step: int, seen: Stamp, load: Callable[[Path], object],
                 on_model: Callable[[object], None], on_status: Callable[[], None] = lambda: None,
                 poll_s: float = POLL_S):
        self.folder = Path(folder)
        self.path = self.folder / "checkpoints" / "last.pt"
        self.step, self.seen = int(step), seen
        self.scalars_seen: Stamp = stamp(self.folder / "scalars.csv")
        self.scalars = last_scalars(self.folder)
        self.load, self.on_model, self.on_status = load, on_model, on_status
        self.poll_s = float(poll_s)
        self.polls = 0                                     # polls done (the tests wait on it)
        self.failed: Optional[str] = None                  # why the last new checkpoint was not taken
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="run-watcher", daemon=True)
        self._thread.start()

    def line(self) -> str:
        return status_line(self.step, self.scalars)

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            try:
                self.poll()
            except Exception as e:                         # the watcher outlives anything a poll meets
                print(f"platonic view: following the run: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
            self.polls += 1

    def poll(self) -> bool:
        """Look once: take a new checkpoint (True where one was taken) and a changed ``scalars.csv``."""
        changed = False
        now = stamp(self.folder / "scalars.csv")
        if now != self.scalars_seen:
            self.scalars_seen, self.scalars, changed = now, last_scalars(self.folder), True
        took = False
        now = stamp(self.path)
        if now is not None and now != self.seen:
            self.seen = now                                # tried once per stamp: a bad file is one line
            try:
                model = self.load(self.path)
                self.on_model(model)                       # refuses a model of another kind of run
            except Exception as e:                         # torn, corrupt, not a checkpoint: keep the model shown
                self.failed = (f"{e}" if isinstance(e, UserError) else f"{type(e).__name__}: {e}").splitlines()[0]
                print(f"platonic view: the run's new checkpoints/last.pt was not taken ({self.failed}); still "
                      f"showing step {self.step}", file=sys.stderr, flush=True)
            else:
                self.step, self.failed, took, changed = int(getattr(model, "step", self.step)), None, True, True
        if changed:
            self.on_status()
        return took

    def stop(self) -> None:
        self._stop.set()

    def join(self, timeout: float) -> None:
        """Wait up to ``timeout`` seconds for the thread to end (after :meth:`stop`)."""
        self._thread.join(timeout=timeout)
