"""Benchmark: does a photo run get colour wrong because of the unseen side, or already in front?

    .venv/bin/python lab/scripts/photo_colour_fit.py RUN [RUN ...] [--data-path DIR]

For each run folder trained on photos, its inference model (the newest checkpoint) reconstructs
the run's training photos and its held-out photos, and renders each at its input view. Printed
per run and split: the mean CIE76 ΔE between the render's and the photo's mean foreground
colour (``evaluate.image_stats.colour_distance``, as the judge's) and the input-view MAE. A run
whose training photos come back with a small ΔE and its held-out ones with a large one has
memorised the training photos' colours: the judge's side-view ΔE cannot fall below the held-out
input view's. Figures only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.evaluate import image_stats as S
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.model import Model
from mitsuba_platonic.render import render_with
from mitsuba_platonic.views import front_view


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--data-path", default=None)
    args = ap.parse_args()
    print("| run | step | training photos: ΔE input view | MAE | held-out photos: ΔE input view | MAE |\n"
          "|---|---|---|---|---|---|")
    for run in args.runs:
        ckpt = read_checkpoint(run)
        cfg = checkpoint_config(ckpt)
        train, held, _ = photo_splits(cfg, args.data_path)
        model = model_from_checkpoint(Model, ckpt, cfg)
        cells = []
        for photos in (train, held):
            with torch.no_grad():
                images = render_with(model.reconstruct(photos).clamp(0, 1), front_view(len(photos)), cfg.render)
            de = [S.colour_distance(images[i], photos[i])["delta_e"] for i in range(len(photos))]
            cells += [f"{np.mean([d for d in de if d is not None]):.1f}", f"{float((images - photos).abs().mean()):.4f}"]
        print(f"| {run.name} | {ckpt.step} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
