"""Benchmark: where a training step's CPU time goes, by operator (torch.profiler), for a packaged config.

    .venv/bin/python benchmarks/train_step_profile.py [--config quickstart] [--steps 10] [--warmup 3] [--set KEY=VALUE ...]

Trains ``--warmup`` steps, then profiles ``--steps`` steps of the config's trainer on random
images (the speed of a step does not depend on what the images show) with the run's thread
settings, and prints:

- the seconds per step without the profiler (timed over the same number of steps first) and the
  renderer / networks / optimiser split of :class:`mitsuba_platonic.bench.train.StepClock`;
- the operators with the largest self CPU time, as a share of all self CPU time (the table of
  lab/step-time.md).

Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import time

import torch
from torch.profiler import ProfilerActivity, profile

from mitsuba_platonic.bench.train import StepClock, image_channels, random_training_data
from mitsuba_platonic.config import load_config
from mitsuba_platonic.files.resources import config_path
from mitsuba_platonic.train.run import training_threads
from mitsuba_platonic.train.trainer import Trainer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="quickstart", help="a packaged config's name (default: %(default)s)")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    # data.path: a photo config's folder, never read (the images are random)
    cfg = load_config(config_path(args.config), ["data.path=unused", *args.overrides])
    r = cfg.model.resolution
    trainer = Trainer(cfg, random_training_data(r, image_channels(cfg)), torch.device("cpu"))
    with training_threads(cfg):
        for step in range(args.warmup):
            trainer.step(step)
        clock = StepClock(trainer)
        t0 = time.perf_counter()
        for step in range(args.warmup, args.warmup + args.steps):
            trainer.step(step)
        wall = time.perf_counter() - t0
        parts = clock.totals()
        clock.detach()
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            for step in range(args.warmup + args.steps, args.warmup + 2 * args.steps):
                trainer.step(step)
        threads = torch.get_num_threads()
    renderer = parts["renderer_forward"] + parts["renderer_backward"]
    print(f"config {args.config} {' '.join(args.overrides)}: N {r}, width {cfg.model.width}, batch "
          f"{cfg.train.batch_size}, renderer {cfg.render.backend}, torch threads {threads}")
    print(f"{wall / args.steps:.4f} s/step over {args.steps} steps; renderer {renderer / wall:.1%} "
          f"(backward {parts['renderer_backward'] / wall:.1%}), optimiser {parts['optimiser'] / wall:.1%}, "
          f"networks {(wall - renderer - parts['optimiser']) / wall:.1%}")
    events = [e for e in prof.key_averages() if e.self_cpu_time_total > 0]
    total = sum(e.self_cpu_time_total for e in events)
    print(f"\n| operator | self CPU share | self CPU ms per step | calls per step |\n|---|---:|---:|---:|")
    for e in sorted(events, key=lambda e: -e.self_cpu_time_total)[:args.top]:
        print(f"| `{e.key}` | {e.self_cpu_time_total / total:.1%} | {e.self_cpu_time_total / 1e3 / args.steps:.2f} | "
              f"{e.count / args.steps:.0f} |")


if __name__ == "__main__":
    main()
