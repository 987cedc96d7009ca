"""Experiment script: how mirror-symmetric are a photo run's silhouettes, against its photos' and the truth's?

    .venv/bin/python lab/scripts/silhouette_symmetry.py RUN [RUN ...]

For each photo run (a ``platonic train`` folder on a photo collection) it renders the held-out photos'
reconstructions on the judge's turntable about the object's vertical (``evaluate/judge.py``, at each
photo's estimated elevation) and prints, per azimuth, the mean over the photos of

- the silhouette's left-right asymmetry, |S − flip(S)| / |S| with S = [α > ½] and flip the image's
  mirror about its vertical centre line: 0 for a silhouette that is its own mirror image, 2 at most;
- the silhouette's width and coverage as shares of the image.

The held-out photos' own figures come first. On the photo suite's path-traced collections
(``benchmarks/photo_suite.py``; the collection's ``manifest.json`` has each photo's truth) the truth is
rendered on the same turntable, framed and stood upright as in ``judge_truth.py``. A volume round about
its vertical through the image's centre shows a mirror-symmetric silhouette from every side, so a prior
of roundness shows here first. Figures only; lab/photo-sides.md reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Dict

import torch

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import judge as J
from mitsuba_platonic.evaluate.photos import photo_splits
from common import upright_run, upright_truth

AZIMUTHS = (0.0, 45.0, 90.0, -90.0, 180.0)


def silhouette_figures(alpha: torch.Tensor) -> Dict[str, float]:
    """Means over images ``(M, R, R)`` of the asymmetry, the width and the coverage of S = [α > ½]."""
    s = (alpha > 0.5).double()
    area = s.sum((-2, -1))
    asym = (s - s.flip(-1)).abs().sum((-2, -1)) / area.clamp_min(1.0)
    width = s.amax(-2).sum(-1) / s.shape[-1]
    return {"asym": float(asym.mean()), "width": float(width.mean()), "cover": float(s.mean((-2, -1)).mean())}


def row(name: str, figures: Dict[str, float]) -> str:
    return f"| {name} | {figures['asym']:.3f} | {figures['width']:.3f} | {figures['cover']:.3f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", type=Path, nargs="+")
    args = ap.parse_args()
    torch.set_num_threads(1)
    for run in args.runs:
        model, cfg = upright_run(run)
        _, held, _ = photo_splits(cfg)
        print(f"\n{run}\n\n| silhouettes of | asymmetry | width | coverage |\n|---|---|---|---|")
        print(row("held-out photos", silhouette_figures(held[:, -1])))
        answers = {"model": model.reconstruct_upright(held)}
        try:
            _, upright, elevations = upright_truth(model, cfg)
            answers["truth"] = (upright.float(), elevations)
        except UserError as e:                               # the tree photos and other real folders: no truth
            print(f"(no truth: {e})")
        for name, (v, el) in answers.items():
            turntable = J.turntable_renders(v.detach().float().cpu().clamp(0.0, 1.0), el.double(), AZIMUTHS, cfg.render, 0)
            for i, φ in enumerate(AZIMUTHS):
                print(row(f"{name}, {φ:+.0f}°", silhouette_figures(turntable[i, :, -1])))


if __name__ == "__main__":
    main()
