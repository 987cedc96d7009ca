"""What a run shows while it trains: scalar logs (``scalars.csv`` and TensorBoard) and samples
(renders of fixed held-out inputs from fixed views, and a turntable GIF).

A run folder's ``scalars.csv`` and ``tb/`` come from :class:`ScalarLog`, its ``samples/`` from
:func:`write_samples`; rank 0 writes both.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Dict, List, Tuple

import torch

from ..files.fileio import atomic_write, make_folder
from ..images import composite, linear_to_srgb, save_grid, to_hwc
from ..model import Model
from ..render.frames import display_frames, save_gif, turntable_frames
from ..views import front_view, turntable

__all__ = ["ScalarLog", "write_samples", "SAMPLE_VIEWS"]


#: Fixed views of the periodic samples: the input view and three turntable views.
SAMPLE_VIEWS = torch.cat([front_view(1), turntable(3, elevation=25.0, start=60.0)])


def write_samples(model: Model, inputs: torch.Tensor, folder: Path, step: int, seed: int) -> Tuple[Path, Path]:
    """PNG grid (input | reconstruction from the sample views; for generation, samples of a
    generator seeded with ``seed``) and a turntable GIF of the first volume."""
    if model.task == "reconstruction":
        vols = model.reconstruct(inputs).cpu()
        first = [[linear_to_srgb(composite(to_hwc(x), background=1.0))] for x in inputs]
    else:
        vols = model.generate(len(inputs), seed).cpu()
        first = [[] for _ in vols]
    rows = [first[i] + display_frames(vol, model.formation, SAMPLE_VIEWS, filter=model.render.filter)
            for i, vol in enumerate(vols)]
    scale = max(1, 256 // model.resolution)
    png = save_grid(folder / f"step_{step:07d}.png", rows, scale=scale)
    gif = save_gif(turntable_frames(vols[0], model.formation, frames=24), folder / f"turntable_{step:07d}.gif",
                   scale=scale, duration_ms=80)
    return png, gif


class ScalarLog:
    """scalars.csv (rows after a resumed step are dropped) and TensorBoard."""

    def __init__(self, folder: Path, start_step: int):
        self.path = folder / "scalars.csv"
        self.rows: List[Dict[str, Any]] = []
        if self.path.exists():
            with open(self.path) as f:
                self.rows = [r for r in csv.DictReader(f) if int(r["step"]) <= start_step]
        try:
            from torch.utils.tensorboard import SummaryWriter  # lazy: TensorBoard is slow to import, and may be broken
            self.tb = SummaryWriter(str(make_folder(folder / "tb")), purge_step=start_step + 1)
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

        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=keys)
                w.writeheader()
                w.writerows(self.rows)

        atomic_write(self.path, write)
        if self.tb is not None:
            self.tb.flush()

    def close(self) -> None:
        self.flush()
        if self.tb is not None:
            self.tb.close()
