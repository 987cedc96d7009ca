"""Checkpoints: the file format, atomic saves, and reading the newest loadable one.

A checkpoint (``RUN/checkpoints/last.pt``, ``RUN/checkpoints/step_NNNNNNN.pt``) is a
``torch.save``d dict::

    version   CHECKPOINT_VERSION (a file of another version is refused with one line)
    step      training steps done
    config    the run's resolved config (``Config.to_dict()``)
    trainer   the trainer's state: ``nets`` (E, G, D and D3 in one state dict, keys ``E.*``,
              ``G.*``, ...) and the optimisers' states

Training writes checkpoints (:mod:`mitsuba_platonic.train.run`); inference reads them
(:meth:`mitsuba_platonic.model.Model.from_checkpoint`) without the training code.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Tuple, Union

import torch

from .config import Config, ConfigError, config_from_dict
from .errors import UserError
from .fileio import atomic_write

__all__ = ["RunError", "CHECKPOINT_VERSION", "Checkpoint", "save_checkpoint", "load_checkpoint",
           "checkpoint_files", "load_latest_checkpoint", "read_checkpoint"]

CHECKPOINT_VERSION = 1

_NUMBERED = re.compile(r"step_(\d+)\.pt")


class RunError(UserError):
    """A run folder or checkpoint that cannot be used as asked (exists, missing, incompatible)."""


def save_checkpoint(path: Path, payload: Dict[str, Any]) -> None:
    """``torch.save`` to a temporary sibling, fsync, then rename over ``path`` (atomic).

    A failed write (a full disk) is the ``OSError`` the file raised, naming ``path``: ``torch.save``
    itself reports it as a ``RuntimeError`` about stream positions.
    """
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            out = _Recorded(f)
            try:
                torch.save(payload, out)
            except RuntimeError:
                if out.error is not None:
                    raise out.error from None
                raise

    atomic_write(path, write, durable=True)


class _Recorded:
    """A binary file for ``torch.save`` that remembers the ``OSError`` a write raised."""

    def __init__(self, f):
        self.f, self.error = f, None

    def write(self, data) -> int:
        try:
            return self.f.write(data)
        except OSError as e:
            self.error = e
            raise

    def flush(self) -> None:
        self.f.flush()


def load_checkpoint(path: Path, device: torch.device = torch.device("cpu")) -> Dict[str, Any]:
    """The raw contents of one checkpoint file (not checked; see :func:`load_latest_checkpoint`)."""
    if not path.is_file():
        raise RunError(f"no checkpoint at {path}")
    return torch.load(path, map_location=device, weights_only=False)


def _checked(path: Path, device: torch.device) -> Dict[str, Any]:
    """:func:`load_checkpoint`, then ``ValueError`` unless it is a training checkpoint of this version."""
    state = load_checkpoint(path, device)
    if not isinstance(state, dict) or not {"step", "trainer", "config"} <= set(state):
        raise ValueError("not a training checkpoint")
    if state.get("version") != CHECKPOINT_VERSION:
        raise ValueError(f"checkpoint format {state.get('version')!r}, this version reads {CHECKPOINT_VERSION}")
    return state


def checkpoint_files(folder: Path) -> List[Path]:
    """``last.pt`` (if present), then the numbered checkpoints, newest first."""
    numbered = sorted((p for p in folder.glob("step_*.pt") if _NUMBERED.fullmatch(p.name)),
                      key=lambda p: int(_NUMBERED.fullmatch(p.name).group(1)), reverse=True)
    last = folder / "last.pt"
    return ([last] if last.exists() or last.is_symlink() else []) + numbered   # a dangling link: named, not skipped


def load_latest_checkpoint(folder: Path, device: torch.device = torch.device("cpu"),
                           warn: bool = True) -> Tuple[Dict[str, Any], Path]:
    """The newest loadable checkpoint of ``folder`` (``RUN/checkpoints``): ``last.pt``, else the
    newest ``step_*.pt`` that loads, with a warning on stderr naming the files that did not.

    Raises :class:`RunError` (one line, naming every file tried) if none loads.
    """
    failed: List[Tuple[Path, str]] = []
    for path in checkpoint_files(folder):
        try:
            state = _checked(path, device)
        except Exception as e:  # torch.load raises RuntimeError, EOFError, UnpicklingError, ... for torn files
            failed.append((path, _one_line(e)))
            continue
        if failed and warn:
            print(f"warning: could not load {_by_reason(failed, str)}; using {path} (step {int(state['step'])})",
                  file=sys.stderr, flush=True)
        return state, path
    if not failed:
        raise RunError(f"no checkpoint in {folder}")
    raise RunError(f"no loadable checkpoint in {folder}: {_by_reason(failed, lambda p: p.name)}")


@dataclass
class Checkpoint:
    """A read checkpoint: its validated config, its raw state, the file and the step."""

    config: Config
    state: Dict[str, Any]
    path: Path
    step: int


def read_checkpoint(source: Union[str, Path], device: Union[str, torch.device] = "cpu") -> Checkpoint:
    """A run folder (its newest loadable checkpoint) or one checkpoint file → :class:`Checkpoint`.

    The config is the one saved in the checkpoint (``config.yaml`` is not read), with
    ``run.name`` set to the run folder's name; a bad one is a :class:`RunError` naming the file.
    """
    source, device = Path(source), torch.device(device)
    if source.is_file():
        try:
            state = _checked(source, device)
        except Exception as e:
            raise RunError(f"{source} cannot be loaded: {_one_line(e)}") from None
        path, run_dir = source, source.parent.parent
    else:
        if not checkpoint_files(source / "checkpoints"):
            raise RunError(f"{source} has no checkpoints/last.pt: not a training run, or not started")
        state, path = load_latest_checkpoint(source / "checkpoints", device)
        run_dir = source
    if not isinstance(state["config"], dict) or not isinstance(state["config"].get("run") or {}, dict):
        raise RunError(f"{path}: the config saved in this checkpoint is not a mapping of sections")
    saved = dict(state["config"])
    saved["run"] = {**(saved.get("run") or {}), "name": run_dir.resolve().name}   # the folder is the run
    try:
        cfg = config_from_dict(saved)
    except ConfigError as e:
        raise RunError(f"{path}: the config saved in this checkpoint is not valid: {e}") from None
    return Checkpoint(cfg, state, path, int(state["step"]))


def _by_reason(failed: List[Tuple[Path, str]], name) -> str:
    """``a.pt, b.pt (reason 1); c.pt (reason 2)``: files grouped by why they did not load."""
    groups: Dict[str, List[str]] = {}
    for path, why in failed:
        groups.setdefault(why, []).append(name(path))
    return "; ".join(f"{', '.join(names)} ({why})" for why, names in groups.items())


def _one_line(e: BaseException, limit: int = 100) -> str:
    """The first sentence of an error, on one line, at most ``limit`` characters."""
    text = " ".join(str(e).split()).split(". ")[0] or type(e).__name__
    return text if len(text) <= limit else text[:limit - 1] + "…"
