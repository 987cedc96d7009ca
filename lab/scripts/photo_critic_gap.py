"""Benchmark: does a run's D memorise its training photos? (the diagnosis behind train.d_augment)

    .venv/bin/python lab/scripts/photo_critic_gap.py RUN [RUN ...] [--data-path DIR]

For each run folder trained on photos (``data.source: folder``), its trained D (from the newest
checkpoint) scores the run's training photos, its held-out photos (never trained on), and renders
of the held-out photos' reconstructions at random turntable views. A D that learnt what an object
of the class looks like scores the two kinds of photo alike; a D that memorised its few dozen
photos gives the training photos higher logits than the held-out ones. Printed per run: the mean
logits, the memorisation gap mean D(train) − mean D(held out), and the held-out gap
mean D(held out) − mean D(renders) (what G can still learn from). D sees the images as in
training, without augmentation. Figures only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.evaluate.judge import random_renders
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.model import Model, critic_config
from mitsuba_platonic.networks.nets import Discriminator


def critic_of(ckpt, cfg) -> Discriminator:
    """The run's trained D, from a read checkpoint and its config."""
    d = Discriminator(critic_config(cfg))
    nets = ckpt.state["trainer"]["nets"]
    d.load_state_dict({k[2:]: v for k, v in nets.items() if k.startswith("D.")})
    return d.eval()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--data-path", default=None)
    args = ap.parse_args()
    print("| run | step | D(train photos) | D(held-out photos) | D(renders, random views) | memorisation gap | "
          "held-out gap |\n|---|---|---|---|---|---|---|")
    for run in args.runs:
        ckpt = read_checkpoint(run)
        cfg = checkpoint_config(ckpt)
        train, held, _ = photo_splits(cfg, args.data_path)
        model = model_from_checkpoint(Model, ckpt, cfg)
        d = critic_of(ckpt, cfg)
        with torch.no_grad():
            volumes, elevations = model.reconstruct_upright(held)      # the turntable about the object's axis
            renders = random_renders(volumes.clamp(0, 1), elevations, 8, cfg.render, seed=0)
            lt, lh, lr = (float(d(x).mean()) for x in (train, held, renders))
        print(f"| {run.name} | {ckpt.step} | {lt:+.2f} | {lh:+.2f} | {lr:+.2f} | {lt - lh:+.2f} | {lh - lr:+.2f} |",
              flush=True)


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
