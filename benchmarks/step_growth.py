"""Benchmark: how a photo training step's time grows with the resolution, part by part.

    .venv/bin/python benchmarks/step_growth.py [--resolutions 16 32 64] [--with-128] [--steps 10] [--warmup 3]
                                               [--config photos] [--set KEY=VALUE ...]

For each resolution R the packaged config (default ``photos``, configs/photos.yaml) at
``--set model.resolution=R``, which is what a user running ``platonic quickstart --photos DIR
--set model.resolution=R`` trains (images of R² follow the model's resolution; at 64 it is
configs/photos64.yaml but for the run's name), on random images with the run's thread settings:
``--warmup`` untimed steps, ``--steps`` timed ones (s/step), then ``--steps`` more under
:class:`mitsuba_platonic.bench.train.PartClock`, which splits each step into G, E, D, the renderer,
the priors' terms, the pose head, the optimisers and the rest, each forward and backward
(the parts: that class's module docstring). Prints a Markdown table of each part's milliseconds
per step and share, and how each grew from the resolution before.

``--with-128`` adds 128³ where the memory free allows it (a lower bound: the networks and G's last activations).
Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch

from mitsuba_platonic.bench.train import bench_parts, growth_table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[16, 32, 64])
    ap.add_argument("--with-128", action="store_true", help="add 128³ where the memory free allows it")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--config", default="photos", help="a packaged config's name (default: %(default)s)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    resolutions = args.resolutions + ([128] if args.with_128 and 128 not in args.resolutions else [])
    t0 = time.perf_counter()
    rows = bench_parts(args.config, resolutions, args.steps, args.warmup, args.overrides)
    threads = {(row.get("torch_threads"), row.get("drjit_threads")) for row in rows if not row["skipped"]}
    print(f"\nconfig {' '.join([args.config, *args.overrides])}, batch {rows[0]['batch']}; {platform.machine()}, "
          f"{os.cpu_count()} CPUs, torch {torch.__version__}; (torch, Dr.Jit) threads {sorted(threads, key=str)}; "
          f"{args.steps} steps per figure after {args.warmup}; {time.perf_counter() - t0:.0f} s in all\n")
    print(growth_table(rows))


if __name__ == "__main__":
    main()
