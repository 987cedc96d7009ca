"""Benchmark: seconds per training step of packaged configs, this checkout against an older commit, in one run.

    .venv/bin/python benchmarks/train_step_speed.py --against 6e1fc08 [--config quickstart --config paper]
                                                    [--steps 30] [--warmup 5] [--rounds 2] [--set KEY=VALUE ...]
                                                    [--this-set KEY=VALUE ...]

The older commit's package is unpacked (``git archive``) into a temporary folder and put first on
``PYTHONPATH`` of a child process; this checkout's package runs the same way, so both time the
same script, with the same virtual environment, on the same machine, in alternating rounds (the
best round counts). Each child runs in its package's folder (``python -c`` puts the working
directory first on ``sys.path``) and prints the package it imported, which the table names. Each measurement: the config's trainer on random images (the speed of a step
does not depend on what the images show), ``--warmup`` steps, then ``--steps`` timed steps, with
the run's thread settings. Prints s/step per commit and config and the ratio. Figures only.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import sys, time, torch
from mitsuba_platonic.config import load_config
from mitsuba_platonic.files.resources import config_path
from mitsuba_platonic.train.data import TrainingData
from mitsuba_platonic.train.run import training_threads
from mitsuba_platonic.train.trainer import Trainer
name, steps, warm, overrides = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
cfg = load_config(config_path(name), overrides)
r, c = cfg.model.resolution, 1 if cfg.render.model in ("vh", "ao") else 4
data = TrainingData(torch.rand(64, c, r, r, generator=torch.Generator().manual_seed(0)) * 0.5, torch.zeros(0, c, r, r))
trainer = Trainer(cfg, data, torch.device("cpu"))
with training_threads(cfg):
    for s in range(warm):
        trainer.step(s)
    t0 = time.perf_counter()
    for s in range(warm, warm + steps):
        trainer.step(s)
import mitsuba_platonic
print(mitsuba_platonic.__file__)
print((time.perf_counter() - t0) / steps)
"""


def _time(package_root: Path, config: str, steps: int, warmup: int, overrides) -> float:
    env = {**os.environ, "PYTHONPATH": str(package_root)}
    out = subprocess.run([sys.executable, "-c", CHILD, config, str(steps), str(warmup), *overrides], env=env,
                         cwd=package_root, capture_output=True, text=True, check=True)   # cwd: first on sys.path
    *_, imported, seconds = out.stdout.strip().splitlines()
    if not Path(imported).resolve().is_relative_to(package_root.resolve()):
        raise RuntimeError(f"the child imported {imported}, not the package under {package_root}")
    return float(seconds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", required=True, help="the older commit (anything git rev-parse takes)")
    ap.add_argument("--config", action="append", default=None, help="packaged config names (default: quickstart)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--this-set", dest="this_overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="an override for this checkout only (a setting the older commit lacks, e.g. "
                         "model.precision=bf16)")
    args = ap.parse_args()
    configs = args.config or ["quickstart"]
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.against], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive.stdout, check=True)
        print(f"| config | {args.against}: s/step | this checkout: s/step | speed-up |\n|---|---:|---:|---:|")
        for config in configs:
            best = {"old": float("inf"), "new": float("inf")}
            for _ in range(args.rounds):
                best["old"] = min(best["old"], _time(old, config, args.steps, args.warmup, args.overrides))
                best["new"] = min(best["new"], _time(ROOT, config, args.steps, args.warmup,
                                                     args.overrides + args.this_overrides))
            label = " ".join([config, *args.overrides] + [f"(this checkout: {o})" for o in args.this_overrides])
            print(f"| {label} | {best['old']:.4f} | {best['new']:.4f} | {best['old'] / best['new']:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
