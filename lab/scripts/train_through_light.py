"""Benchmark: the cost of a training step through each renderer on a path-traced collection.

    .venv/bin/python lab/scripts/train_through_light.py [--steps 10] [--shapes 60] [--cache data] [--width 32]
        [--device cuda|cpu] [--rows marcher,m = 2]

One process, one collection (``configs/procedural_physical.yaml``: mushrooms at 32³ path-traced
under random skies, metered exposure, ``--shapes`` × 4 views), the same seed and batch (8) for
every row; each row builds a fresh :class:`~mitsuba_platonic.train.trainer.Trainer`, runs one
warm-up step (kernel compilation, scene loading) and then times ``--steps`` steps:

- EA through the Mitsuba ray marcher (``render.backend: mitsuba``), the project's fast path;
- EA through the closed-form layer (``render.backend: closed_form``), the reference;
- single scattering of the same kind of sky in Dr.Jit (``render.backend: scatter_march``, a
  random sun and sky per pair from the backend's light prior) at 2 and 4 camera samples per voxel;
- the differentiable path tracer (``render.backend: physical``, prbvolpath under a random sun per
  pair) at spp 1 / max depth 2 (the setting ``docs/training.md``, "Training through light",
  trained with) and at the config's spp 4 / max depth 4.

Prints a Markdown table of seconds per step and images per second (the batch's input-view and
random-view renders: 16 images a step), and the Dr.Jit kernels' own time per step, measured in
``--steps`` further steps with Dr.Jit's kernel history on (it makes each launch wait for its
timing, so it is kept out of the wall-time steps): what is left of a step once the kernels are
subtracted (launches, bindings, torch and the networks) is all that batching renders into fewer
launches could save; and how many launches (every kind in the history: kernels, copies,
clears, reductions) a step makes. Figures only, nothing asserted.
"""

from __future__ import annotations

import argparse
import time
from typing import Tuple

import torch

from mitsuba_platonic.bench.timing import kernel_time
from mitsuba_platonic.config import load_config
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer

from common import config_path

CONFIG = config_path("procedural_physical")

ROWS = {
    "EA, Mitsuba ray marcher": ["render.backend=mitsuba"],
    "EA, closed form": ["render.backend=closed_form"],
    "single scattering, Dr.Jit, m = 2": ["render.backend=scatter_march", "render.steps_per_voxel=2"],
    "single scattering, Dr.Jit, m = 4": ["render.backend=scatter_march", "render.steps_per_voxel=4"],
    "path tracer, spp 1, depth 2": ["render.physical_spp=1", "render.max_depth=2"],
    "path tracer, spp 4, depth 4": [],
}


def seconds_per_step(overrides, shapes: int, cache: str, steps: int, width: int,
                     device: str = "cpu") -> Tuple[float, float, float]:
    """(wall seconds, Dr.Jit kernel seconds, Dr.Jit launches) per step of a fresh trainer on ``device``
    (each step reads its losses back, so a GPU's queued work is inside the timing)."""
    cfg = load_config(CONFIG, [f"data.n_shapes={shapes}", f"data.cache={cache}", f"model.width={width}", *overrides])
    trainer = Trainer(cfg, load_training_data(cfg, progress=True), torch.device(device))
    trainer.step(1)                                                  # warm-up: compilation, scene loading
    t0 = time.perf_counter()
    for s in range(2, steps + 2):
        trainer.step(s)
    wall = (time.perf_counter() - t0) / steps
    kernels, launches = kernel_time(lambda: [trainer.step(s) for s in range(steps + 2, 2 * steps + 2)])
    return wall, kernels / 1e3 / steps, launches / steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, default=10, help="timed steps per row (default: %(default)s)")
    p.add_argument("--shapes", type=int, default=60, help="shapes in the collection (default: %(default)s)")
    p.add_argument("--cache", default="data", help="collection cache folder (default: %(default)s)")
    p.add_argument("--width", type=int, default=32, help="the networks' width (default: %(default)s, the config's)")
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu",
                   help="where the networks train (default: %(default)s; the renderers follow the Mitsuba variant)")
    p.add_argument("--rows", default=None,
                   help="only the rows whose names contain one of these comma-separated parts (default: all)")
    args = p.parse_args()
    rows = {k: v for k, v in ROWS.items() if args.rows is None or any(part in k for part in args.rows.split(","))}
    print(f"(networks on {args.device})\n")
    print("| training step through | s / step | images / s | × the marcher's time | Dr.Jit kernels, s / step | "
          "the rest of the step | Dr.Jit launches / step |\n|---|---|---|---|---|---|---|")
    base = None
    for name, overrides in rows.items():
        t, k, n = seconds_per_step(overrides, args.shapes, args.cache, args.steps, args.width, args.device)
        base = base or t
        print(f"| {name} | {t:.3f} | {16 / t:.1f} | {t / base:.1f} | {k:.3f} | {max(t - k, 0.0):.3f} | {n:.0f} |",
              flush=True)


if __name__ == "__main__":
    main()
