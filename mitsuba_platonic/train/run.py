"""Training runs: a run folder, checkpoints, exact resume, logs, samples, Ctrl-C, data parallel.

A run folder (``run.out_dir/run.name``) holds::

    config.yaml              the resolved config (every key, defaults included)
    checkpoints/last.pt      the newest checkpoint (atomically replaced)
    checkpoints/step_NNNNNNN.pt   the last ``keep_checkpoints`` periodic checkpoints
    scalars.csv, tb/         scalar logs (CSV and TensorBoard)
    samples/step_NNNNNNN.png renders of fixed held-out inputs from fixed views
    samples/turntable_NNNNNNN.gif

Checkpoints are written to a temporary file and renamed over the old one, so a kill at any
moment leaves the previous checkpoint loadable. ``resume=True`` continues from ``last.pt``;
because every random draw of a step derives from (seed, step), the continued run matches an
uninterrupted one step for step (on CPU). Ctrl-C (SIGINT) finishes the current step, saves a
checkpoint and returns cleanly.

Data parallel: launch with ``torchrun --nproc-per-node N -m mitsuba_platonic.cli train ...``
(CUDA + NCCL, or CPU + gloo). Each process renders its share of the batch with the configured
renderer; rank 0 writes checkpoints, logs and samples.
"""

from __future__ import annotations

import csv
import os
import signal
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import torch
import torch.distributed as dist
import yaml

from ..config import Config
from ..images import composite, linear_to_srgb, to_hwc
from ..views import front_view, turntable
from .data import load_training_data
from .trainer import Trainer

__all__ = ["train", "load_run", "RunError", "save_checkpoint", "load_checkpoint", "SAMPLE_VIEWS"]

CHECKPOINT_VERSION = 1


class RunError(ValueError):
    """A run folder that cannot be used as asked (exists, missing, incompatible)."""


def _device(cfg: Config, local_rank: int) -> torch.device:
    if cfg.run.device == "cuda" or (cfg.run.device == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise RunError("run.device: 'cuda' requested but CUDA is not available")
        return torch.device("cuda", local_rank)
    return torch.device("cpu")


def save_checkpoint(path: Path, payload: Dict[str, Any]) -> None:
    """``torch.save`` to a temporary sibling, fsync, then rename over ``path`` (atomic)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            torch.save(payload, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def load_checkpoint(path: Path, device: torch.device = torch.device("cpu")) -> Dict[str, Any]:
    if not path.is_file():
        raise RunError(f"no checkpoint at {path}")
    return torch.load(path, map_location=device, weights_only=False)


#: Fixed views of the periodic samples: the input view and three turntable views.
SAMPLE_VIEWS = torch.cat([front_view(1), turntable(3, elevation=25.0, start=60.0)])


def write_samples(trainer: Trainer, inputs: torch.Tensor, folder: Path, step: int) -> Tuple[Path, Path]:
    """PNG grid (input | reconstruction from the sample views) and a turntable GIF of input 0."""
    from PIL import Image
    from ..export import display_frames, save_gif, turntable_frames

    folder.mkdir(parents=True, exist_ok=True)
    cfg = trainer.cfg
    if cfg.train.task == "reconstruction":
        vols = trainer.reconstruct(inputs).cpu()
        first = [linear_to_srgb(composite(to_hwc(x), background=1.0)) for x in inputs]
    else:
        g = torch.Generator().manual_seed(cfg.run.seed + 12345)
        vols = trainer.generate(torch.randn(len(inputs), cfg.model.latent, generator=g)).cpu()
        first = None
    rows = []
    for i, vol in enumerate(vols):
        tiles = ([first[i]] if first is not None else []) + display_frames(vol, cfg.render.model, SAMPLE_VIEWS,
                                                                           filter=cfg.render.filter)
        rows.append(np.concatenate(tiles, axis=1))
    grid = np.concatenate(rows, axis=0)
    scale = max(1, 256 // cfg.model.resolution)
    png = folder / f"step_{step:07d}.png"
    Image.fromarray((grid * 255 + 0.5).astype(np.uint8)).resize(
        (grid.shape[1] * scale, grid.shape[0] * scale), Image.NEAREST).save(png)
    gif = save_gif(turntable_frames(vols[0], cfg.render.model, frames=24), folder / f"turntable_{step:07d}.gif",
                   scale=scale, duration_ms=80)
    return png, gif


class _ScalarLog:
    """scalars.csv (rows after a resumed step are dropped) and TensorBoard."""

    def __init__(self, folder: Path, start_step: int):
        self.path = folder / "scalars.csv"
        self.rows: List[Dict[str, Any]] = []
        if self.path.exists():
            with open(self.path) as f:
                self.rows = [r for r in csv.DictReader(f) if int(r["step"]) <= start_step]
        try:
            from torch.utils.tensorboard import SummaryWriter
            self.tb = SummaryWriter(str(folder / "tb"), purge_step=start_step + 1)
        except ImportError:  # tensorboard is a dependency; keep training if it is broken
            self.tb = None

    def add(self, step: int, scalars: Dict[str, float]) -> None:
        self.rows.append({"step": step, **{k: f"{v:.6g}" for k, v in scalars.items()}})
        if self.tb is not None:
            for k, v in scalars.items():
                self.tb.add_scalar(k, v, step)

    def flush(self) -> None:
        keys: List[str] = []
        for r in self.rows:
            keys += [k for k in r if k not in keys]
        tmp = self.path.with_suffix(".tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(self.rows)
        os.replace(tmp, self.path)
        if self.tb is not None:
            self.tb.flush()

    def close(self) -> None:
        self.flush()
        if self.tb is not None:
            self.tb.close()


def _distributed() -> Tuple[int, int, int]:
    """(rank, world size, local rank), initialising torch.distributed under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, 0
    if not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", "0"))


def train(cfg: Config, resume: bool = False, progress: bool = True,
          stop_at: Optional[int] = None) -> Path:
    """Run (or continue) training; return the run folder.

    ``stop_at`` ends the loop after that step as if interrupted (a checkpoint is saved): used to
    test exact resume.
    """
    from tqdm.auto import tqdm
    import drjit as dr  # noqa: F401  (the backend check ran at import)

    rank, world, local_rank = _distributed()
    device = _device(cfg, local_rank)
    if cfg.run.threads:
        torch.set_num_threads(cfg.run.threads)
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    last = run_dir / "checkpoints" / "last.pt"
    if rank == 0:
        if resume and not last.exists():
            raise RunError(f"--resume: {run_dir} has no checkpoint to continue from")
        if not resume and last.exists():
            raise RunError(f"{run_dir} already holds a run; pass --resume to continue it, or choose "
                           f"another run.name")
        run_dir.mkdir(parents=True, exist_ok=True)
        if resume:
            saved = yaml.safe_load((run_dir / "config.yaml").read_text())
            for section in ("data", "model", "render", "train"):
                if saved.get(section) != cfg.to_dict()[section]:
                    raise RunError(f"--resume: the {section} settings differ from {run_dir}/config.yaml; "
                                   f"an exact continuation needs the same config (only run.* may change)")
        (run_dir / "config.yaml").write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
    if world > 1:
        dist.barrier()                                       # rank 0 checked the folder first
    if rank == 0:
        data = load_training_data(cfg, progress=progress)
    if world > 1:
        dist.barrier()                                       # the procedural cache is complete
    if rank != 0:
        data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, device, rank, world)
    start = 0
    if resume:
        state = load_checkpoint(last, device)
        trainer.load_state_dict(state["trainer"])
        start = int(state["step"])
    pool = data.held_out if len(data.held_out) else data.images
    sample_inputs = pool[torch.linspace(0, len(pool) - 1, min(4, len(pool))).long()]   # spread: different shapes

    def checkpoint(step: int) -> None:
        if rank != 0:
            return
        payload = {"version": CHECKPOINT_VERSION, "step": step, "config": cfg.to_dict(),
                   "trainer": trainer.state_dict()}
        save_checkpoint(last, payload)
        numbered = run_dir / "checkpoints" / f"step_{step:07d}.pt"
        save_checkpoint(numbered, payload)
        for old in sorted((run_dir / "checkpoints").glob("step_*.pt"))[:-cfg.run.keep_checkpoints]:
            old.unlink()

    stop = {"now": False}
    previous = None
    if rank == 0 and hasattr(signal, "SIGINT"):
        previous = signal.signal(signal.SIGINT, lambda *_: stop.update(now=True))
    log = _ScalarLog(run_dir, start) if rank == 0 else None
    end = cfg.run.steps if stop_at is None else min(stop_at, cfg.run.steps)
    bar = tqdm(total=cfg.run.steps, initial=start, disable=not progress or rank != 0, unit="step",
               dynamic_ncols=True)
    images_per_step = cfg.train.batch_size * (cfg.train.random_views + (cfg.train.task == "reconstruction"))
    step, t_last, n_last = start, time.perf_counter(), start
    try:
        while step < end:
            scalars = trainer.step(step)
            step += 1
            if rank == 0 and (step % cfg.run.log_every == 0 or step == end):
                rate = (step - n_last) * images_per_step / max(time.perf_counter() - t_last, 1e-9)
                t_last, n_last = time.perf_counter(), step
                log.add(step, {**scalars, "images_per_s": rate})
                bar.set_postfix({k: f"{v:.3g}" for k, v in scalars.items()
                                 if not k.endswith(("_updated", "_hard"))}
                                | {"img/s": f"{rate:.1f}"})
            bar.update(1)
            if rank == 0 and step % cfg.run.sample_every == 0:
                write_samples(trainer, sample_inputs, run_dir / "samples", step)
            if step % cfg.run.checkpoint_every == 0:
                checkpoint(step)
                if log:
                    log.flush()
            flag = torch.tensor(float(stop["now"]))
            if world > 1:
                dist.all_reduce(flag)                       # stop together
            if flag.item() > 0:
                print(f"\ninterrupted: saving a checkpoint at step {step} (resume with --resume)")
                break
    finally:
        bar.close()
        if rank == 0:
            checkpoint(step)
            if step == cfg.run.steps:
                write_samples(trainer, sample_inputs, run_dir / "samples", step)
            log.close()
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        if world > 1:
            dist.barrier()                                   # rank 0 has written the last checkpoint
            dist.destroy_process_group()
    return run_dir


def load_run(run_dir: Path, device: str = "cpu") -> Tuple[Config, Trainer, int]:
    """A trained run's config and networks (no training data is loaded)."""
    from ..config import _build
    from .data import TrainingData

    run_dir = Path(run_dir)
    ckpt = run_dir / "checkpoints" / "last.pt"
    if not ckpt.exists():
        raise RunError(f"{run_dir} has no checkpoints/last.pt: not a training run, or not started")
    state = load_checkpoint(ckpt, torch.device(device))
    cfg = _build(Config, state["config"], "").validate()
    c = 1 if cfg.render.model in ("vh", "ao") else 4
    r = cfg.model.resolution
    dummy = TrainingData(torch.zeros(1, c, r, r), torch.zeros(0, c, r, r),
                         torch.zeros(1, c, r, r, r) if cfg.train.mode != "platonic" else None)
    trainer = Trainer(cfg, dummy, torch.device(device))
    trainer.load_state_dict(state["trainer"])
    return cfg, trainer, int(state["step"])
