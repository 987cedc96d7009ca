"""What a run folder is, so that ``train`` writes only into its own.

A run folder is one ``train`` created: it writes :data:`RUN_MARKER` (``run.json``) first, into a
folder that did not exist or was empty. A folder written before the marker existed is recognised
by its own records: a checkpoint in ``checkpoints/``. Any other folder that holds something is a
user's, and :func:`claim_run_folder` refuses it before anything in it is touched (no temporary
removed, no ``run.lock`` taken).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .. import __version__
from ..checkpoint import RunError, checkpoint_files

__all__ = ["RUN_MARKER", "is_run_folder", "claim_run_folder"]

#: The file ``train`` writes first into a folder it makes a run folder.
RUN_MARKER = "run.json"


def is_run_folder(folder: Path) -> bool:
    """Whether ``folder`` is a run folder: it holds :data:`RUN_MARKER` or a checkpoint."""
    folder = Path(folder)
    return (folder / RUN_MARKER).is_file() or bool(checkpoint_files(folder / "checkpoints"))


def claim_run_folder(folder: Path) -> None:
    """Make ``folder`` a run folder (create it and write :data:`RUN_MARKER`) unless it is one.

    Raises :class:`RunError` (naming ``run.name`` and ``run.out_dir``, the settings that choose the
    folder) when ``folder`` is a file, or a folder that holds something and is not a run folder;
    nothing in it is changed then.
    """
    folder = Path(folder)
    change = "choose another run.name (or run.out_dir)"
    if folder.exists() and not folder.is_dir():
        raise RunError(f"{folder} is a file, not a run folder; {change}")
    if folder.is_dir():
        if is_run_folder(folder):
            if not (folder / RUN_MARKER).exists():           # a run from before the marker: mark it
                _write_marker(folder)
            return
        held = sorted(p.name for p in folder.iterdir())
        if held:
            shown = ", ".join(held[:3]) + (", …" if len(held) > 3 else "")
            raise RunError(f"{folder} is not a run folder (no {RUN_MARKER}, no checkpoints) and holds "
                           f"{len(held)} item(s) ({shown}); train writes only into a new or empty folder or "
                           f"one of its own runs, and changed nothing there; {change}")
    folder.mkdir(parents=True, exist_ok=True)
    _write_marker(folder)


def _write_marker(folder: Path) -> None:
    """Write :data:`RUN_MARKER` directly (not through a temporary: a torn marker still marks the folder)."""
    text = json.dumps({"written_by": "platonic train", "mitsuba_platonic": __version__, "pid": os.getpid()})
    with open(folder / RUN_MARKER, "w") as f:
        f.write(text + "\n")
