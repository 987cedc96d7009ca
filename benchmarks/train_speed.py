"""Benchmark: training images/s per renderer for one training configuration. Prints figures only.

    .venv/bin/python benchmarks/train_speed.py [--resolution 32] [--batch 8] [--steps 10]

One configuration (reconstruction, EA, width 16, batch 8, one random view per volume), rendered
by each backend in turn in the same run; images/s counts every rendered image of a step
(the random views and the input views), after two warm-up steps.
"""

from __future__ import annotations

import argparse
import time

import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.train.data import TrainingData
from mitsuba_platonic.train.trainer import Trainer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--width", type=int, default=16)
    args = ap.parse_args()
    r = args.resolution
    data = TrainingData(torch.rand(64, 4, r, r) * 0.5, torch.zeros(0, 4, r, r))
    backends = [("closed_form", []), ("mitsuba", []), ("mitsuba", ["render.spp=4"]),
                ("physical", ["render.physical_spp=1", "render.max_depth=2"]),
                ("physical", ["render.physical_spp=4", "render.max_depth=4"])]
    print(f"# training speed: reconstruction, EA, {r}³, width {args.width}, batch {args.batch}, "
          f"{torch.get_num_threads()} threads; {args.steps} steps after 2 warm-up steps")
    print(f"{'renderer':<44} {'s/step':>8} {'images/s':>9} {'vs closed form':>15}")
    base = None
    for backend, extra in backends:
        cfg = load_config(None, [f"model.resolution={r}", f"model.width={args.width}", f"train.batch_size={args.batch}",
                                 f"render.backend={backend}", "data.formation=ea", *extra])
        trainer = Trainer(cfg, data, torch.device("cpu"))
        for s in range(2):
            trainer.step(s)
        t = time.perf_counter()
        for s in range(2, 2 + args.steps):
            trainer.step(s)
        per_step = (time.perf_counter() - t) / args.steps
        rate = args.batch * 2 / per_step
        base = base or rate
        name = backend + (" (" + ", ".join(e.split(".")[1] for e in extra) + ")" if extra else "")
        print(f"{name:<44} {per_step:>8.3f} {rate:>9.1f} {rate / base:>14.2f}×")


if __name__ == "__main__":
    main()
