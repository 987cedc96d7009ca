"""The run section of a config (``run:``): where a run's folder is, its seed, device, length and cadence.

:class:`RunConfig` is the section's dataclass and :data:`DEVICES` its choice of device, read by
the runs (:mod:`mitsuba_platonic.train.run` and the modules beside it). In the config, not beside
them: the runs read the whole config (:mod:`mitsuba_platonic.config.train_settings` says why).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Literal, Union

from ..settings_checks import ConfigError, choice, non_negative, positive, quoted

__all__ = ["RunConfig", "DEVICES"]

#: run.device: 'auto' picks CUDA when available.
DEVICES = ("auto", "cpu", "cuda")


@dataclass
class RunConfig:
    """The run section, one line per key (its table in docs/training.md is made from these lines).

    name, out_dir: the run folder is ``out_dir/name`` (``name``: one folder name, no '/', no '..');
    ``train`` writes only into a new or empty folder or one of its own runs.
    seed: the master seed: every draw of a run (batches, views, initialisation) follows from it; a resumed
    run draws what an uninterrupted one would.
    device: 'cpu', 'cuda', or 'auto' (CUDA when present).
    steps: training steps; the photo configs gain nothing from more (docs/training.md, "The measurements").
    log_every, sample_every, checkpoint_every: the cadence in steps of ``scalars.csv``, sample grids and checkpoints.
    threads: torch's and Dr.Jit's CPU threads (0: all cores).
    drjit_threads: Dr.Jit's worker threads while training, 'auto' or a count (1: its launches run on the
    training thread alone); 'auto' picks 1 for the marcher at N ≤ 32 on a CPU, where idle workers would
    spin against torch, and uses them at 64³ (docs/training.md, "The measurements").
    keep_checkpoints: how many numbered checkpoints are kept besides ``last.pt``.
    """

    name: str = "run"
    out_dir: str = "runs"
    seed: int = 0
    device: str = "auto"
    steps: int = 2000
    log_every: int = 10
    sample_every: int = 250
    checkpoint_every: int = 250
    threads: int = 0
    drjit_threads: Union[Literal["auto"], int] = "auto"
    keep_checkpoints: int = 3

    def validate(self) -> "RunConfig":
        """Check this section's values; raise :class:`~mitsuba_platonic.settings_checks.ConfigError`
        naming the key (``run.steps: ...``)."""
        _folder_name("run.name", self.name)
        choice("run.device", self.device, DEVICES)
        for key in ("steps", "log_every", "sample_every", "checkpoint_every", "keep_checkpoints"):
            positive(f"run.{key}", getattr(self, key))
        non_negative("run.threads", self.threads)
        if self.drjit_threads != "auto":
            positive("run.drjit_threads", self.drjit_threads)
        non_negative("run.seed", self.seed)
        return self


#: The longest folder name in bytes (UTF-8) that Linux's, macOS's and Windows' file systems all take (NAME_MAX).
MAX_NAME_BYTES = 255


def _folder_name(key: str, value: str) -> None:
    """One path component: no separator, not '.' or '..', not empty (so the run stays in out_dir), and
    at most :data:`MAX_NAME_BYTES` bytes in UTF-8 (a longer one was the file system's ``File name too
    long`` when the run folder was made, quoting the whole name)."""
    seps = {"/", "\\"} | ({os.sep, os.altsep} - {None})
    if not value or value in (".", "..") or any(sep in value for sep in seps) or "\0" in value:
        raise ConfigError(f"{key}: expected a single folder name (no '/', '..' or absolute path), got {quoted(value)}")
    size = len(value.encode("utf-8", "surrogatepass")) if isinstance(value, str) else 0
    if size > MAX_NAME_BYTES:
        raise ConfigError(f"{key}: expected a folder name of at most {MAX_NAME_BYTES} bytes (UTF-8), got one of "
                          f"{size:,} bytes: {quoted(value, 60)}")
