"""Where a run computes: its device, its place among data-parallel processes, and the threads
torch and Dr.Jit use while it trains.

Data parallel: launch with ``torchrun --nproc-per-node N -m mitsuba_platonic.cli train ...``
(CUDA + NCCL, or CPU + gloo); :func:`distributed` initialises the process group and says which
rank this process is. Threads: :func:`training_threads` sets ``run.threads`` and
:func:`drjit_threads` for the run and restores both afterwards (docs/training.md, "The measurements").
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator, Optional, Tuple

import torch
import torch.distributed as dist

from ..config import Config
from ..files.checkpoint import RunError
from ..render.variant import ensure_variant

__all__ = ["run_device", "distributed", "drjit_threads", "training_threads", "SERIAL_MARCHER_MAX_RESOLUTION"]


def run_device(cfg: Config, local_rank: int) -> torch.device:
    """The device ``run.device`` names ('auto': CUDA where available), CUDA's ``local_rank``-th GPU;
    :class:`RunError` if CUDA is asked for and missing."""
    if cfg.run.device == "cuda" or (cfg.run.device == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise RunError("run.device: 'cuda' requested but CUDA is not available")
        return torch.device("cuda", local_rank)
    return torch.device("cpu")


def distributed() -> Tuple[int, int, int]:
    """(rank, world size, local rank), initialising torch.distributed under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, 0
    if not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", "0"))


#: 'auto' runs the marcher's launches on the training thread up to this resolution (docs/training.md, "The measurements").
SERIAL_MARCHER_MAX_RESOLUTION = 32


def drjit_threads(cfg: Config) -> Optional[int]:
    """Dr.Jit's worker threads for a training run, or None to leave them as they are.

    ``run.drjit_threads`` if it is a count. 'auto': 1 (each launch runs on the training thread)
    when the marcher trains at N ≤ :data:`SERIAL_MARCHER_MAX_RESOLUTION` on the LLVM backend,
    because Dr.Jit's idle workers keep spinning for 20 ms after every launch and take the cores
    from torch's convolutions, while a 32³ launch only takes a few ms (measured in
    docs/training.md, "The measurements"; at 64³ the workers pay for themselves); otherwise
    ``run.threads`` (all cores when 0). The closed form uses no Dr.Jit.
    """
    if cfg.render.backend == "closed_form":
        return None
    if cfg.run.drjit_threads != "auto":
        return int(cfg.run.drjit_threads)
    if (cfg.render.backend == "mitsuba" and ensure_variant().variant().startswith("llvm")
            and cfg.model.resolution <= SERIAL_MARCHER_MAX_RESOLUTION):
        return 1
    return cfg.run.threads or None


@contextmanager
def training_threads(cfg: Config) -> Iterator[None]:
    """torch's threads (``run.threads``) and Dr.Jit's (:func:`drjit_threads`) while a run trains,
    restored afterwards (a quickstart evaluates in the same process, with every core)."""
    torch_before = torch.get_num_threads()
    if cfg.run.threads:
        torch.set_num_threads(cfg.run.threads)
    n, dr, before = drjit_threads(cfg), None, None
    if n is not None:
        import drjit as dr  # lazy: Dr.Jit only where a run renders with Mitsuba
        before = dr.thread_count()
        if n != before:
            dr.set_thread_count(n)
    try:
        yield
    finally:
        torch.set_num_threads(torch_before)
        if dr is not None and dr.thread_count() != before:
            dr.set_thread_count(before)
