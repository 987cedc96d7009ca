"""Benchmark: the collection's evidence about roundness, measured on round and non-round collections.

    .venv/bin/python benchmarks/shape_evidence.py [--photos 40] [--seeds 0 1 2] [--tree DIR]

The photo report warns where a run's round priors (``train.turn``, ``model.texture_turns: 4``)
meet a collection whose silhouettes say it is not round (:mod:`mitsuba_platonic.evaluate.priors`:
the mean mirror asymmetry A over the photos, against ``ASYMMETRY_THRESHOLD``). This prints the
figure, and the spread of ln(width / height) beside it, on collections whose answer is known:

- the procedural classes at uniform random azimuths: ``mushroom`` and ``tree`` (round about their
  vertical), ``chair`` and ``airplane`` (not);
- ``chair`` and ``airplane`` seen from the side only (azimuths within ±30° of the two side views,
  ±90°), as people photograph animals and vehicles;
- the tree photos (``--tree``, by default ``../shared/data/tree`` beside the repository; left out
  with a note where absent).

Each procedural photo is one shape (seed = the collection's seed × 1000 + its index) rendered in
closed form (EA) at 64² from its azimuth and an elevation uniform in −10°…40° (the photo config's
band), written as an RGBA PNG and loaded with every other through the photo loader as
``configs/photos.yaml`` frames photos (32², ``crop: bbox``), so the figures are those a quickstart
on such a folder computes. One row per collection: the figure per seed, their mean, and the
verdict at the threshold. About 4 minutes on 2 shared cores at the defaults. Figures only; the table is in
docs/evaluation.md, "Shape priors and the collection's evidence".
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Callable, Dict, List

import numpy as np
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.data import shapes
from mitsuba_platonic.data.photos import PhotoCollection
from mitsuba_platonic.evaluate.priors import ASYMMETRY_THRESHOLD, RoundEvidence, round_evidence
from mitsuba_platonic.files.resources import config_path
from mitsuba_platonic.images import save_png, to_hwc, to_png_rgba
from mitsuba_platonic.render import render
from mitsuba_platonic.views import from_angles

ROOT = Path(__file__).resolve().parents[1]
TREE = ROOT.parent / "shared" / "data" / "tree"
#: (row name, class, round?, azimuth sampler)
Sampler = Callable[[np.random.Generator], float]
UNIFORM: Sampler = lambda rng: float(rng.uniform(-180.0, 180.0))                               # noqa: E731
SIDES: Sampler = lambda rng: float(rng.choice([-90.0, 90.0]) + rng.uniform(-30.0, 30.0))       # noqa: E731
COLLECTIONS = [("mushroom, every side", "mushroom", True, UNIFORM), ("tree, every side", "tree", True, UNIFORM),
               ("chair, every side", "chair", False, UNIFORM), ("airplane, every side", "airplane", False, UNIFORM),
               ("chair, sides only (±30°)", "chair", False, SIDES),
               ("airplane, sides only (±30°)", "airplane", False, SIDES)]


def photo_options(resolution: int) -> Dict:
    """The photo loader's options of ``configs/photos.yaml`` (crop, margin, cleaning) at ``resolution``."""
    cfg = load_config(config_path("photos"), ["data.path=unused"])
    return dict(resolution=resolution, split="all", splits=(1.0, 0.0, 0.0), **cfg.data.image_kwargs())


def rendered_collection(folder: Path, name: str, n: int, seed: int, azimuth: Sampler) -> None:
    """``n`` photos of class ``name`` into ``folder`` (module docstring)."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        volume = shapes.generate(name, seed=seed * 1000 + i, n=64)[None]
        view = from_angles(torch.tensor([azimuth(rng)]), torch.tensor([float(rng.uniform(-10.0, 40.0))]))
        with torch.no_grad():
            image = render(volume, view, "ea")[0]
        save_png(folder / f"{i:03d}.png", to_png_rgba(to_hwc(image)))


def evidence(folder: Path, options: Dict) -> RoundEvidence:
    return round_evidence(PhotoCollection(folder, **options).images())


def verdict(mean: float) -> str:
    return "not round" if mean > ASYMMETRY_THRESHOLD else "round"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=40, help="photos per procedural collection (default 40)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--resolution", type=int, default=32, help="the loader's resolution (default 32, the photo config's)")
    ap.add_argument("--tree", type=Path, default=TREE)
    args = ap.parse_args()
    torch.set_num_threads(1)
    options = photo_options(args.resolution)
    seeds = " | ".join(f"A, seed {s}" for s in args.seeds)
    print(f"threshold {ASYMMETRY_THRESHOLD:.2f}; {args.photos} photos per collection, {args.resolution}² masks\n")
    print(f"| collection | round? | {seeds} | A, mean | spread of ln(w/h), mean | verdict |")
    print("|---|---|" + "---|" * len(args.seeds) + "---|---|---|")
    for label, name, is_round, azimuth in COLLECTIONS:
        figures: List[RoundEvidence] = []
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as tmp:
                rendered_collection(Path(tmp), name, args.photos, seed, azimuth)
                figures.append(evidence(Path(tmp), options))
        mean = float(np.mean([f.asymmetry for f in figures]))
        spread = float(np.mean([f.aspect_spread for f in figures]))
        print(f"| {label} | {'yes' if is_round else 'no'} | " + " | ".join(f"{f.asymmetry:.3f}" for f in figures)
              + f" | {mean:.3f} | {spread:.3f} | {verdict(mean)} |", flush=True)
    if args.tree.is_dir():
        f = evidence(args.tree, options)
        print(f"| tree photos ({f.photos} photos) | yes | {f.asymmetry:.3f}" + " | —" * (len(args.seeds) - 1)
              + f" | {f.asymmetry:.3f} | {f.aspect_spread:.3f} | {verdict(f.asymmetry)} |")
    else:
        print(f"(the tree photos are not at {args.tree}: left out)")


if __name__ == "__main__":
    main()
