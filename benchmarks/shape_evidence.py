"""Benchmark: the collection's evidence about roundness, measured on round and non-round collections.

    .venv/bin/python benchmarks/shape_evidence.py [--photos 40] [--seeds 0 1 2] [--tree DIR]
        [--folder NAME=PATH ...] [--round NAME ...]

The photo report warns where a run's round priors (``train.turn``, ``model.texture_turns: 4``)
meet a collection whose silhouettes say it is not round (:mod:`mitsuba_platonic.evaluate.priors`:
the median over the photos of the upper asymmetry U, against ``UPPER_THRESHOLD``). This prints the
figure, and beside it the mean mirror asymmetry A and the spread of ln(width / height), on
collections whose answer is known:

- the procedural classes at uniform random azimuths: ``mushroom`` and ``tree`` (round about their
  vertical), ``chair``, ``airplane`` and ``animal`` (not);
- ``chair``, ``airplane`` and ``animal`` seen from the side only (azimuths within ±30° of the two
  side views, ±90°), as people photograph animals and vehicles;
- the tree photos (``--tree``, by default ``../shared/data/tree`` beside the repository; left out
  with a note where absent);
- any photo folder given as ``--folder NAME=PATH`` (not round unless ``--round NAME`` says so),
  e.g. the photo suite's path-traced collections (``<suite>/collections/pt-animal-sides/images``).

Each procedural photo is one shape (seed = the collection's seed × 1000 + its index) rendered in
closed form (EA) at 64² from its azimuth and an elevation uniform in −10°…40° (the photo config's
band), written as an RGBA PNG and loaded with every other through the photo loader as
``configs/photos.yaml`` frames photos (32², ``crop: bbox``), so the figures are those a quickstart
on such a folder computes; a folder is loaded the same way. One row per collection: U per seed
(a folder has one), their mean, the mean of A and of the spread, and the verdict at the threshold;
then the largest U of a round collection and the smallest of one that is not, seed by seed.
About 1 min 10 s on 2 shared cores at nice 19 at the defaults. Figures only; the table is in
docs/evaluation.md, "Shape priors and the collection's evidence".
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Callable, Dict, List, Tuple

import numpy as np
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.data import shapes
from mitsuba_platonic.data.photos import PhotoCollection
from mitsuba_platonic.evaluate.priors import UPPER_THRESHOLD, RoundEvidence, round_evidence
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
               ("animal, every side", "animal", False, UNIFORM),
               ("chair, sides only (±30°)", "chair", False, SIDES),
               ("airplane, sides only (±30°)", "airplane", False, SIDES),
               ("animal, sides only (±30°)", "animal", False, SIDES)]


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


def verdict(figure: float) -> str:
    return "not round" if figure > UPPER_THRESHOLD else "round"


def folder_arg(text: str) -> Tuple[str, Path]:
    """``NAME=PATH`` of ``--folder``."""
    name, sep, path = text.partition("=")
    if not sep or not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=PATH, got {text!r}")
    return name, Path(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=40, help="photos per procedural collection (default 40)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--resolution", type=int, default=32, help="the loader's resolution (default 32, the photo config's)")
    ap.add_argument("--tree", type=Path, default=TREE, help="the tree photos (a round collection)")
    ap.add_argument("--folder", type=folder_arg, action="append", default=[], metavar="NAME=PATH",
                    help="also measure this photo folder (repeatable); not round unless --round names it")
    ap.add_argument("--round", action="append", default=[], metavar="NAME", help="a --folder NAME that is round")
    args = ap.parse_args()
    names = [n for n, _ in args.folder]
    if len(set(names)) != len(names) or set(args.round) - set(names):
        ap.error("--folder names must differ, and each --round must name a --folder")
    torch.set_num_threads(1)
    options = photo_options(args.resolution)
    seeds = " | ".join(f"U, seed {s}" for s in args.seeds)
    print(f"threshold {UPPER_THRESHOLD:.2f} on U, the median over a collection's photos; {args.photos} photos per "
          f"procedural collection, {args.resolution}² masks\n")
    print(f"| collection | round? | {seeds} | U, mean | A, mean | spread of ln(w/h), mean | verdict |")
    print("|---|---|" + "---|" * len(args.seeds) + "---|---|---|---|")
    # (collection, round?, the collection's U per seed) for the summary
    measured: List[Tuple[str, bool, List[float]]] = []

    def row(label: str, is_round: bool, figures: List[RoundEvidence]) -> None:
        u = [f.upper_asymmetry for f in figures]
        mean = float(np.mean(u))
        cells = [f"{x:.3f}" for x in u] + ["—"] * (len(args.seeds) - len(u))
        print(f"| {label} | {'yes' if is_round else 'no'} | " + " | ".join(cells) + f" | {mean:.3f} | "
              f"{np.mean([f.asymmetry for f in figures]):.3f} | {np.mean([f.aspect_spread for f in figures]):.3f} | "
              f"{verdict(mean)} |", flush=True)
        measured.append((label, is_round, u))

    for label, name, is_round, azimuth in COLLECTIONS:
        figures: List[RoundEvidence] = []
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as tmp:
                rendered_collection(Path(tmp), name, args.photos, seed, azimuth)
                figures.append(evidence(Path(tmp), options))
        row(label, is_round, figures)
    folders = ([("tree photos", args.tree, True)] if args.tree.is_dir() else []) + \
        [(n, p, n in args.round) for n, p in args.folder]
    for label, path, is_round in folders:
        f = evidence(path, options)
        row(f"{label} ({f.photos} photos)", is_round, [f])
    if not args.tree.is_dir():
        print(f"(the tree photos are not at {args.tree}: left out)")
    rounds = [(max(u), n) for n, r, u in measured if r]
    others = [(min(u), n) for n, r, u in measured if not r]
    if rounds and others:
        (hi, hn), (lo, ln) = max(rounds), min(others)
        print(f"\nround collections: U at most {hi:.3f} ({hn}); not round: at least {lo:.3f} ({ln}); "
              f"threshold {UPPER_THRESHOLD:.2f}: " + ("separates them" if hi <= UPPER_THRESHOLD < lo else
                                                       "does NOT separate them"))


if __name__ == "__main__":
    main()
