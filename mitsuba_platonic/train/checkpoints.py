"""Checkpoint-keeping: which checkpoints a run writes, when a state is good enough to write, and
what a failure leaves on disk.

A run keeps ``checkpoints/last.pt`` (the newest, atomically replaced) and the last
``run.keep_checkpoints`` numbered ``step_NNNNNNN.pt``. A state is written only if every tensor
of it is finite (:func:`non_finite`), so a diverged run never replaces, or rotates out, a good
checkpoint. :class:`Checkpoints` remembers the newest good checkpoint on disk, so that every
error and interrupt can say which step it holds (:meth:`Checkpoints.kept`). ``--resume`` loads
the newest loadable one into the trainer and refuses one saved with other data, model, render or
train settings, naming the first key (:meth:`Checkpoints.resume`). The file format itself is
:mod:`mitsuba_platonic.files.checkpoint`'s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Optional

import torch

from ..config import Config
from ..config.loading import config_difference, saved_config
from ..files.checkpoint import CHECKPOINT_VERSION, RunError, load_latest_checkpoint, load_weights, save_checkpoint
from ..files.fileio import remove
from ..runtime.no_room import no_room, what_to_free

__all__ = ["Checkpoints", "non_finite", "same_settings"]


def non_finite(state: Any, name: str = "") -> Optional[str]:
    """The name of the first floating tensor of ``state`` holding NaN or Inf, else None."""
    if isinstance(state, torch.Tensor):
        return name if state.is_floating_point() and not bool(torch.isfinite(state).all()) else None
    if isinstance(state, dict):
        items = state.items()
    elif isinstance(state, (list, tuple)):
        items = enumerate(state)
    else:
        return None
    for k, v in items:
        bad = non_finite(v, f"{name}.{k}" if name else str(k))
        if bad is not None:
            return bad
    return None


def same_settings(state: Dict[str, Any], path: Path, cfg: Config) -> None:
    """:class:`RunError` naming the checkpoint and the first key unless the config saved in it has
    the same data, model, render and train settings as ``cfg`` (config.yaml may have been edited,
    or the checkpoint come from another run: its weights would not fit, or not continue exactly)."""
    diff = config_difference(saved_config(state, path, run_name=cfg.run.name), cfg, there=f"in {path.name}")
    if diff is not None:
        raise RunError(f"{path} was saved with other settings ({diff}); an exact continuation needs the "
                       f"config it was trained with (only run.* may change)")


class Checkpoints:
    """The checkpoints of the run in ``run_dir`` with config ``cfg``, and the newest good one on
    disk: ``path`` and the ``step`` it holds (None before the first is written or loaded)."""

    def __init__(self, run_dir: Path, cfg: Config):
        self.folder = Path(run_dir) / "checkpoints"
        self.last = self.folder / "last.pt"
        self.cfg = cfg
        self.path: Optional[Path] = None
        self.step: Optional[int] = None

    def resume(self, trainer: Any, device: torch.device, warn: bool = True) -> int:
        """Load the newest loadable checkpoint into ``trainer`` and return its step; :class:`RunError`
        (``--resume: …``) if none loads, or it was saved with other settings or does not fit."""
        try:
            state, path = load_latest_checkpoint(self.folder, device, warn=warn)
            same_settings(state, path, self.cfg)
            load_weights(trainer, state["trainer"], path, "this run's networks and optimisers")
        except RunError as e:
            raise RunError(f"--resume: {e}") from None
        self.path, self.step = path, int(state["step"])
        return self.step

    def kept(self) -> str:
        """What a failure now leaves: nothing saved, and which checkpoint still holds which step."""
        if self.path is None:
            return "nothing was saved (no checkpoint had been written yet)"
        return f"nothing was saved: {self.path} still holds step {self.step}"

    def go_on(self) -> str:
        """How to continue once the cause is mended: ``--resume`` from the step kept, or start again."""
        if self.step is None:
            return "run the same command again"
        return f"run the same command with --resume to go on from step {self.step}"

    def no_room(self, e: BaseException) -> str:
        """For a full disk behind ``e`` (:func:`~mitsuba_platonic.runtime.no_room.no_room`): ``; <which disk,
        what to free, how to go on>``; else ''."""
        full = no_room(e)
        if full is None:
            return ""
        keep = self.cfg.run.keep_checkpoints
        fewer = f"run.keep_checkpoints={keep - 1} keeps fewer step_*.pt" if keep > 1 else "older runs"
        return f"; {what_to_free(full, free=f'other runs and collections; {fewer}', then=self.go_on())}"

    def held(self) -> str:
        """``<the newest good checkpoint> holds step <its step>``."""
        return f"{self.path} holds step {self.step}"

    def save(self, step: int, state: Dict[str, Any]) -> None:
        """Write the trainer's ``state`` after ``step`` as ``last.pt`` and ``step_NNNNNNN.pt``, then
        delete the numbered ones beyond ``run.keep_checkpoints``. :class:`RunError` if ``state`` is
        not finite (nothing is written) or a file cannot be written (a full disk: the old files are
        whole, and the message says which step they hold)."""
        bad = non_finite(state)
        if bad is not None:                                  # never over (or rotating out) a good one
            raise RunError(f"step {step}: the training state is not finite (NaN or Inf in {bad}); {self.kept()}")
        payload = {"version": CHECKPOINT_VERSION, "step": step, "config": self.cfg.to_dict(), "trainer": state}
        numbered = self.folder / f"step_{step:07d}.pt"
        try:
            save_checkpoint(self.last, payload)
            self.path, self.step = self.last, step
            save_checkpoint(numbered, payload)
        except OSError as e:                                 # a full disk: the old files are whole (atomic)
            held = self.held() if self.step == step else self.kept()
            raise RunError(f"step {step}: the checkpoint could not be written ({e}); {held}{self.no_room(e)}") from None
        for old in sorted(self.folder.glob("step_*.pt"))[:-self.cfg.run.keep_checkpoints]:
            remove(old)
