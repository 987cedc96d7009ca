"""Benchmark: does a light head (``train.light: head``) read the sun from path-traced images it never saw?

    .venv/bin/python lab/scripts/light_head.py RUN [RUN ...]

Each RUN was trained with ``train.light: head`` on a procedural collection with ``data.formation:
physical`` (path-traced under random Mitsuba skies: a sun and a sky of some turbidity, multiple
scattering, metered exposure), whose manifest keeps every image's view and sun direction. The head
learnt only from G's own single-scattering renders under the prior's grey daylights. On the held-out
images it prints the angle between the head's sun direction and the true one, both in the image's
camera frame (right, up, ω: ``train/renderer.in_camera``), as median and mean in degrees, beside
two constant guesses: the head's starting answer (a sun straight above the camera) and the best
constant in hindsight (the normalised mean of the true directions of the same held-out images,
which no model could know); and the Pearson correlation of each component with the truth.
Figures only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.model import Model
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.renderer import in_camera


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between the rows of two ``(N, 3)`` arrays of unit vectors."""
    return np.degrees(np.arccos(np.clip((a * b).sum(1), -1.0, 1.0)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    args = ap.parse_args()
    print("| run | held-out images | head: median / mean ° | sun overhead: median / mean ° | "
          "best constant: median / mean ° | r (right, up, ω) |\n|---|---|---|---|---|---|")
    for run in args.runs:
        ckpt = read_checkpoint(run)
        cfg = checkpoint_config(ckpt)
        model = model_from_checkpoint(Model, ckpt, cfg)
        data = load_training_data(cfg, progress=False)
        records = data.held_out_records
        if not records or "lighting" not in records[0] or records[0]["lighting"].get("sun_direction") is None:
            raise SystemExit(f"{run}: its collection has no sun directions (data.formation: physical, lighting: sunsky)")
        views = torch.tensor([r["view"] for r in records], dtype=torch.float64)
        sun = torch.tensor([r["lighting"]["sun_direction"] for r in records], dtype=torch.float64)
        truth = in_camera(sun, views).numpy()
        truth /= np.linalg.norm(truth, axis=1, keepdims=True)
        estimate, _ = model.estimate_light(data.held_out)
        estimate = estimate.double().cpu().numpy()
        overhead = np.tile([0.0, 1.0, 0.0], (len(truth), 1))
        best = truth.mean(0) / np.linalg.norm(truth.mean(0))
        cells = []
        for guess in (estimate, overhead, np.tile(best, (len(truth), 1))):
            err = angles(guess, truth)
            cells.append(f"{np.median(err):.1f} / {err.mean():.1f}")
        r = [float(np.corrcoef(estimate[:, k], truth[:, k])[0, 1]) for k in range(3)]
        print(f"| {run.name} | {len(truth)} | " + " | ".join(cells) + " | " + ", ".join(f"{x:+.2f}" for x in r) + " |",
              flush=True)


if __name__ == "__main__":
    main()
