"""Experiment script: what the judge's critic says of the truth itself, on a path-traced suite collection.

    .venv/bin/python lab/scripts/judge_truth.py RUN

``RUN`` is a photo run on one of the photo suite's path-traced collections (``benchmarks/photo_suite.py``
makes them under ``OUT/runs/LABEL/pt-*``; the collection's ``manifest.json`` has each photo's truth).
The judge (``evaluate/judge.judge``, seed 0, as the suite judges a run) trains its critics on the run's
training photos against renders of the run's reconstructions of them, then scores the held-out photos
against two sets of renders on the same turntables about the object's vertical:

- ``model``: the run's reconstructions (the suite's own figure, up to the judge's run-to-run noise);
- ``truth``: each held-out photo's ground truth, framed as the reconstruction is
  (``evaluate/photo_truth.framed_truth``) and stood upright at the photo's true elevation θ,
  ``tilt(truth, −θ)``, rendered by the same EA renderer.

The truth rendered by EA has the object's shape and albedo but none of the photo's shading, so where its
accuracy is as high as the model's, the critic's figure measures the renderer against path-traced photos,
not the shape. Figures only; lab/photo-sides.md reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from mitsuba_platonic.evaluate.judge import judge
from mitsuba_platonic.evaluate.photos import photo_splits
from common import upright_run, upright_truth

KEYS = [("c2st_input", "acc. input", 3), ("c2st_near", "acc. near", 3), ("c2st_side", "acc. side", 3),
        ("c2st_back", "acc. back", 3), ("roughness_side", "rough. side", 2), ("delta_e_side", "ΔE side", 1),
        ("delta_e_back", "ΔE back", 1)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model, cfg = upright_run(args.run)
    train, held, files = photo_splits(cfg)
    pairs, upright, elevations = upright_truth(model, cfg)
    if [p.file for p in pairs] != [str(f) for f in files]:
        raise SystemExit("the truth's photos are not the held-out photos in their order")
    answers = {"model": model.reconstruct_upright(held),
               "truth": (upright, elevations)}
    print("| renders of | " + " | ".join(h for _, h, _ in KEYS) + " |")
    print("|---" * (len(KEYS) + 1) + "|")
    for name, volumes in answers.items():
        s = judge(model.reconstruct_upright, train, held, cfg.render, [str(f) for f in files], seed=0,
                  test_volumes=volumes).summary()
        cells = ["–" if s.get(k) is None else f"{s[k]:.{d}f}" for k, _, d in KEYS]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
