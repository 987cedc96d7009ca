"""Benchmark: a training step through the marcher with Dr.Jit's default threads vs run.drjit_threads.

Prints figures only (no assertions); every ratio is measured within one run on one machine.

    .venv/bin/python benchmarks/train_thread_speed.py [--resolutions 32 64] [--steps 10] [--repeats 3]

Per resolution: seconds per training step (reconstruction, EA, width 16, batch 8, random images)
through the closed form, through the marcher with Dr.Jit's thread pool on every core, and through
the marcher with ``run.drjit_threads: auto`` (the default; lab/threads.md). Dr.Jit's
idle workers keep spinning for 20 ms after each launch; where a launch is short, that spinning
costs torch's convolutions more than the second thread gains the marcher.
"""

from __future__ import annotations

import argparse
import os
import platform

import torch

from mitsuba_platonic.bench.timing import best_of
from mitsuba_platonic.bench.train import random_training_data
from mitsuba_platonic.config import load_config
from mitsuba_platonic.train.run import drjit_threads, training_threads
from mitsuba_platonic.train.trainer import Trainer


def seconds_per_step(r: int, backend: str, threads: str, steps: int, repeats: int) -> float:
    """The best of ``repeats`` runs of ``steps`` training steps, after 5 warm-up steps."""
    data = random_training_data(r)
    cfg = load_config(None, [f"model.resolution={r}", "model.width=16", "train.batch_size=8",
                             f"render.backend={backend}", "render.model=ea", "data.formation=ea",
                             f"run.drjit_threads={threads}"])
    trainer = Trainer(cfg, data, torch.device("cpu"))
    with training_threads(cfg):
        for step in range(5):
            trainer.step(step)
        return best_of(lambda: [trainer.step(step) for step in range(steps)], repeats) / steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import drjit as dr
    from mitsuba_platonic.render.variant import ensure_variant
    mi = ensure_variant()
    cores = dr.thread_count()
    print(f"{platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__} with {torch.get_num_threads()} "
          f"threads, Mitsuba {mi.MI_VERSION} {mi.variant()} with {cores} Dr.Jit threads")
    print(f"\n{'N':>4} | {'closed form':>12} | {'marcher, ' + str(cores) + ' Dr.Jit threads':>28} | "
          f"{'marcher, auto':>22} | closed ÷ auto | {cores} threads ÷ auto")
    for r in args.resolutions:
        auto = drjit_threads(load_config(None, [f"model.resolution={r}", "render.backend=mitsuba"]))
        closed = seconds_per_step(r, "closed_form", "auto", args.steps, args.repeats)
        pool = seconds_per_step(r, "mitsuba", str(cores), args.steps, args.repeats)
        chosen = seconds_per_step(r, "mitsuba", "auto", args.steps, args.repeats)
        label = f"{chosen * 1e3:.1f} ms ({auto if auto is not None else cores} thr.)"
        print(f"{r:>4} | {closed * 1e3:>9.1f} ms | {pool * 1e3:>25.1f} ms | {label:>22} | "
              f"{closed / chosen:>13.2f} | {pool / chosen:>16.2f}", flush=True)


if __name__ == "__main__":
    main()
