"""The run folder: what one is, so that ``train`` writes only into its own; one run at a time in
it; and the resolved config it records.

A run folder is one ``train`` created: it writes :data:`RUN_MARKER` (``run.json``) first, into a
folder that did not exist or was empty. A folder written before the marker existed is recognised
by its own records: a checkpoint in ``checkpoints/``. Any other folder that holds something is a
user's, and :func:`claim_run_folder` refuses it before anything in it is touched (no temporary
removed, no ``run.lock`` taken).

One run per folder: :func:`run_lock` holds ``run.lock``, an exclusive lock (``flock``) that the
kernel releases when its process ends, so a lock file left by a killed run is simply taken over,
while a second run in the folder of a live one is refused. :func:`prepare_run_folder` then checks
that the folder's checkpoints agree with ``--resume``, removes what a killed run was writing and
records the resolved config (``config.yaml``), which :func:`read_run_config` reads back.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional

import yaml

from .. import __version__
from ..config import Config, ConfigError, config_from_dict, load_yaml, yaml_problem
from ..config.loading import config_difference
from ..config.retired import without_retired
from ..files.checkpoint import RunError, checkpoint_files
from ..files.fileio import InputFileRefused, atomic_write, make_folder, open_file, read_input_text, remove_temporaries
from ..files.locks import exclusive_lock

__all__ = ["RUN_MARKER", "RUN_PARTS", "is_run_folder", "claim_run_folder", "run_lock", "prepare_run_folder", "read_run_config"]

#: The file ``train`` writes first into a folder it makes a run folder.
RUN_MARKER = "run.json"

#: What ``train`` writes, locks and deletes in a run folder: none of them may be a symbolic link
#: (:func:`~mitsuba_platonic.files.fileio.confined`; a folder copied from a colleague may hold links).
RUN_PARTS = (RUN_MARKER, "run.lock", "config.yaml", "scalars.csv", "checkpoints", "samples", "tb")


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
    make_folder(folder)
    _write_marker(folder)


def _write_marker(folder: Path) -> None:
    """Write :data:`RUN_MARKER` directly (not through a temporary: a torn marker still marks the folder)."""
    text = json.dumps({"written_by": "platonic train", "mitsuba_platonic": __version__, "pid": os.getpid()})
    with os.fdopen(open_file(folder / RUN_MARKER, os.O_WRONLY | os.O_CREAT | os.O_TRUNC), "w") as f:
        f.write(text + "\n")


@contextmanager
def run_lock(run_dir: Path) -> Iterator[Path]:
    """Hold ``run_dir/run.lock`` (an exclusive ``flock`` holding this process's pid) while inside.

    A lock file whose process is gone is free (the kernel dropped its lock) and is taken over; a
    live holder makes this raise :class:`RunError`. The file is removed on exit
    (:func:`~mitsuba_platonic.files.locks.exclusive_lock`).
    """
    make_folder(run_dir)
    path = run_dir / "run.lock"

    def refused(holder: str) -> RunError:
        return RunError(f"{run_dir} is in use by another training run (pid {holder if holder.isdigit() else '?'}, "
                        f"lock {path}); wait for it to end or choose another run.name")

    with exclusive_lock(path, str(os.getpid()), refused):
        yield path


def prepare_run_folder(run_dir: Path, cfg: Config, resume: bool, config_file: Optional[Path] = None) -> None:
    """Ready the claimed and locked ``run_dir`` for ``cfg``: :class:`RunError` unless it holds a
    checkpoint exactly when ``resume`` asks to continue one, and on ``resume`` unless its
    ``config.yaml`` has the same data, model, render and train settings; then remove the temporaries
    a killed run left and write ``cfg`` as ``config.yaml`` (atomically: ``--resume`` reads it), unless
    that file is ``config_file``, the user's ``--config``, which is never written."""
    existing = checkpoint_files(run_dir / "checkpoints")
    if resume and not existing:
        raise RunError(f"--resume: {run_dir} has no checkpoint to continue from")
    if not resume and existing:
        raise RunError(f"{run_dir} already holds a run; pass --resume to continue it, or choose "
                       f"another run.name")
    make_folder(run_dir)
    for folder in (run_dir, run_dir / "checkpoints"):   # what a killed run was writing (we hold the lock)
        remove_temporaries(folder)
    if resume:
        try:
            saved = read_run_config(run_dir / "config.yaml")
        except RunError as e:
            raise RunError(f"--resume: {e}") from None
        diff = config_difference(saved, cfg, there="there")
        if diff is not None:
            raise RunError(f"--resume: the {diff.split('.')[0]} settings differ from {run_dir}/config.yaml "
                           f"({diff}); an exact continuation needs the same config (only run.* may change)")
    if not _same_file(config_file, run_dir / "config.yaml"):
        text = yaml.safe_dump(cfg.to_dict(), sort_keys=False)
        atomic_write(run_dir / "config.yaml", lambda p: p.write_text(text))


def _same_file(a: Optional[Path], b: Path) -> bool:
    try:
        return a is not None and os.path.samefile(a, b)
    except OSError:
        return False


def read_run_config(path: Path) -> Config:
    """The resolved config a run wrote (``RUN/config.yaml``), validated; :class:`RunError` naming
    ``path`` if it is missing, not valid YAML, not a mapping, or has a bad key or value."""
    expected = "expected the run's resolved config as `platonic train` wrote it"
    try:
        text = read_input_text(path)                         # a regular file, at most 16 MiB
    except InputFileRefused as e:
        raise RunError(f"{e}; {expected}") from None
    except FileNotFoundError:
        raise RunError(f"{path} is missing; {expected}") from None
    except OSError as e:
        raise RunError(f"{path} cannot be read: {e}") from None
    except UnicodeDecodeError:
        raise RunError(f"{path} is not a text file (not UTF-8); {expected}") from None
    try:
        data = load_yaml(text)
    except yaml.YAMLError as e:
        raise RunError(f"{path} is not valid YAML ({yaml_problem(e)}); {expected}") from None
    if not isinstance(data, dict):
        got = "an empty file" if data is None else f"a {type(data).__name__}"
        raise RunError(f"{path}: expected a mapping of sections (run, data, model, render, train), got {got}; "
                       f"{expected}")
    try:
        return config_from_dict(without_retired(data))
    except ConfigError as e:
        raise RunError(f"{path}: {e}; {expected}") from None
