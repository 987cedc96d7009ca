"""Benchmark: a photo config judged on a suite of collections, 3 seeds each, where the truth exists too.

    .venv/bin/python benchmarks/photo_suite.py [--config photos] [--set KEY=VALUE ...] [--label NAME]
        [--quick | --seeds 0 1 2] [--collections tree pt-mushroom pt-tree pt-chair pt-airplane pt-animal
        pt-animal-sides] [--out photo-suite]

A photo config adopted on one collection can fail on the next (docs/evaluation.md, "The photo
suite"). This trains ``--config`` (with ``--set`` changes) on every collection of the suite with
every seed, judges each run as ``platonic evaluate`` does (the two-sample critics per band of
turntable angle, roughness, ΔE, the input view, the front-card check), and prints one table per
collection: a row per seed and the mean with the spread (max − min) over the seeds.

The collections:

- ``tree``: the tree photos (``--tree DIR``, by default ``../shared/data/tree`` beside the
  repository; left out with a note where absent);
- ``pt-mushroom``, ``pt-tree``: procedural classes path-traced under random skies
  (``platonic make-dataset --formation physical``: 62 shapes, one view each, uniform in azimuth, in
  the elevation band −10°…40°, 64² pixels at 32 spp, seed 0; made once under ``OUT/collections``) and
  handed to the photo path as cut-out photo folders (``data.path: COLLECTION/images``), so the same
  loader, crop and split apply: round classes.
- ``pt-chair``, ``pt-airplane``, ``pt-animal``: classes that are not round, made the same way but at
  48² pixels and 16 spp (below). The animal (``data/shapes/animal.py``) is a body on four legs whose
  length lies along z: seen end-on it is a third to a half as wide as from the side.
- ``pt-animal-sides``: the animals photographed mostly from the sides, as people photograph animals:
  azimuths within ±30° of the side views ±90° (``make-dataset --view-dist sides``), the same band.

For the path-traced collections the table also has the truth at the views the photo never showed
(:mod:`mitsuba_platonic.evaluate.photo_truth`): silhouette IoU and MAE of EA renders at ±90°
(side), ±45° (oblique: a four-pointed star passes at ±90° but not here) and 180° (back) about the
object's true axis, the IoU at the photo's own view (how well the truth was framed as the photo
was), the 3D IoU, the thickness: the matter behind the photo's surface along its rays, as a share
of the object's (1: as solid as the truth), and the silhouette width at ±90° over the width at 0°
(:func:`~mitsuba_platonic.evaluate.photo_truth.width_ratio`): the reconstruction's, the truth's and
the mean over the photos of their difference's size (a lathe-turned animal shows at ±90° the broad
profile it shows at 0°: about 1, where the truth end-on is about 0.4).

Everything resumes: a finished run, evaluation or truth file is read, not redone, so a re-run
prints the table at once, and an interrupted suite continues where it stopped (a truth file without
the width columns is scored again from the run's checkpoint). Runs of a config live under
``OUT/runs/LABEL``; ``--label`` names them (default: the config's name, then the ``--set``
changes). Budget on 2 cores: ~6 minutes a run and ~1 minute its judge at 32³: 21 runs, about two and
a half hours; ``--quick`` runs seed 0 only, 7 runs, under an hour. Rendering, once: pt-mushroom and
pt-tree ~30 minutes each at 64² and 32 spp. The four new collections at those settings would take
about 2 hours 10 minutes (measured: 31.8 s of CPU a chair), so they are rendered at 48² and 16 spp,
7.9, 8.0 and 9.6 s of CPU a shape (animal, airplane, chair; measured on 2 shapes each and
extrapolated, where a wall-clock second of the path tracer is about one of CPU), about 10 minutes a
collection and 40 minutes for the four; the loader crops each photo to its object and
resamples it to the 32² the runs train at, so the 48² photos still hold more pixels than training
reads. ``--resolution`` renders every collection at one size instead (a new folder's worth: a
collection made at another size is refused, not overwritten). Figures only: the test of a change is
the spread.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Dict, List, NamedTuple, Optional, Sequence

import numpy as np

from mitsuba_platonic.config import load_config
from mitsuba_platonic.data.render_collection import CollectionSpec, make_collection
from mitsuba_platonic.evaluate.judge import CRITIC_STEPS
from mitsuba_platonic.evaluate.photo_truth import score_against_truth
from mitsuba_platonic.errors import Interrupted, UserError
from mitsuba_platonic.evaluate.report import evaluate_runs
from mitsuba_platonic.model import Model
from mitsuba_platonic.train import run as training_run

sys.path.insert(0, str(Path(__file__).resolve().parent))
from photo_seeds import figures  # noqa: E402  (the judge's row of one evaluation, as photo_seeds reads it)

ROOT = Path(__file__).resolve().parents[1]
TREE = ROOT.parent / "shared" / "data" / "tree"

class PathTraced(NamedTuple):
    """A path-traced collection of the suite: its class, views ('band': uniform azimuths; 'sides': within
    ±30° of the side views), pixels and samples per pixel."""

    shape_class: str
    views: str = "band"
    resolution: int = 64
    spp: int = 32


#: The path-traced collections (the module docstring says why the new four are smaller).
PATH_TRACED = {"pt-mushroom": PathTraced("mushroom"), "pt-tree": PathTraced("tree"),
               "pt-chair": PathTraced("chair", resolution=48, spp=16),
               "pt-airplane": PathTraced("airplane", resolution=48, spp=16),
               "pt-animal": PathTraced("animal", resolution=48, spp=16),
               "pt-animal-sides": PathTraced("animal", views="sides", resolution=48, spp=16)}
COLLECTIONS = ("tree", *PATH_TRACED)

#: The columns of the table: (key, heading, digits).
JUDGE = [("c2st_near", "acc. near", 3), ("c2st_side", "acc. side", 3), ("c2st_back", "acc. back", 3),
         ("roughness_side", "rough. side", 2), ("delta_e_side", "ΔE side", 1), ("delta_e_back", "ΔE back", 1),
         ("input_view_mae", "input MAE", 4), ("not_cards", "not cards", 0)]
TRUTH = [("truth_front_iou", "IoU 0°", 3), ("truth_oblique_iou", "IoU ±45°", 3), ("truth_side_iou", "IoU ±90°", 3),
         ("truth_back_iou", "IoU 180°", 3),
         ("truth_side_mae", "MAE ±90°", 4), ("truth_volume_iou", "3D IoU", 3), ("truth_thickness", "thickness", 2),
         ("truth_width_ratio", "width ±90°/0°", 2), ("truth_width_ratio_truth", "truth's", 2),
         ("truth_width_ratio_error", "abs. Δ width", 2)]


def collection_spec(shape_class: str, shapes: int = 62, resolution: int = 64, views: str = "band",
                    spp: int = 32) -> CollectionSpec:
    """The suite's path-traced collection of ``shape_class``: one photo per object, as a photo collection has,
    from the elevation band −10°…40° at uniform azimuths (``views='band'``) or within ±30° of the side views
    (``'sides'``)."""
    return CollectionSpec(shape_class, n_shapes=shapes, views_per_shape=1, resolution=resolution,
                          formation="physical", views=views, elevation=(-10.0, 40.0),
                          side_width=30.0 if views == "sides" else None, spp=spp, seed=0)


def suite_spec(name: str, shapes: int = 62, resolution: Optional[int] = None) -> CollectionSpec:
    """The spec of the suite's path-traced collection ``name`` (:data:`PATH_TRACED`); ``resolution``
    replaces its own pixels."""
    c = PATH_TRACED[name]
    return collection_spec(c.shape_class, shapes, c.resolution if resolution is None else resolution, c.views, c.spp)


def photo_folder(name: str, out: Path, tree: Path, shapes: int, resolution: Optional[int], quiet: bool) -> Optional[Path]:
    """The photo folder of collection ``name`` (rendering a path-traced one first), or None where absent."""
    if name == "tree":
        return tree if tree.is_dir() else None
    folder = out / "collections" / name
    make_collection(folder, suite_spec(name, shapes, resolution), progress=not quiet)
    return folder / "images"


def run_one(config: str, sets: Sequence[str], photos: Path, run_dir: Path, eval_dir: Path, seed: int,
            truth: bool, judge_steps: int, quiet: bool) -> Dict[str, Optional[float]]:
    """Train (or resume), judge and score one (collection, seed); returns its figures (also kept in
    ``eval_dir``: ``results.json`` from the evaluation, ``truth.json`` from the truth)."""
    cfg = load_config(config, [f"data.path={photos.resolve()}", f"run.out_dir={run_dir.parent}",
                               f"run.name={run_dir.name}", f"run.seed={seed}", *sets])
    t0 = time.perf_counter()
    training_run.train(cfg, resume=(run_dir / "checkpoints" / "last.pt").exists(), progress=not quiet)
    if not (eval_dir / "results.json").exists():
        evaluate_runs([run_dir], eval_dir, baselines=False, progress=not quiet, judge_steps=judge_steps)
    row = figures(eval_dir)
    if truth:
        truth_file = eval_dir / "truth.json"
        if not truth_file.exists() or set(k for k, _, _ in TRUTH) - set(json.loads(truth_file.read_text())["means"]):
            scores = score_against_truth(Model.from_checkpoint(run_dir), cfg)
            truth_file.write_text(json.dumps({"means": scores.means(), "per_photo": scores.__dict__}, indent=1))
        row.update(json.loads(truth_file.read_text())["means"])
    print(f"  {run_dir}: {time.perf_counter() - t0:.0f} s", flush=True)
    return row


def _cell(value: Optional[float], digits: int) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def table(name: str, label: str, rows: Dict[int, Dict[str, Optional[float]]], truth: bool) -> List[str]:
    """One collection's Markdown table: a row per seed, then the mean (spread)."""
    columns = JUDGE + (TRUTH if truth else [])
    lines = [f"### {name}: {label}", "", "| seed | " + " | ".join(h for _, h, _ in columns) + " |",
             "|---|" + "---|" * len(columns)]
    for seed, row in rows.items():
        lines.append(f"| {seed} | " + " | ".join(_cell(row.get(k), d) for k, _, d in columns) + " |")
    cells = []
    for k, _, d in columns:
        vals = [r[k] for r in rows.values() if r.get(k) is not None]
        cells.append("—" if not vals else f"{np.mean(vals):.{d}f} ({np.max(vals) - np.min(vals):.{d}f})")
    lines.append(f"| **mean (spread) of {len(rows)}** | " + " | ".join(cells) + " |")
    return lines


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="photos", help="the config under test (default: %(default)s)")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                    help="a change to the config (repeatable)")
    ap.add_argument("--label", help="the runs' folder name under OUT/runs (default: config and changes)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--quick", action="store_true", help="seed 0 only")
    ap.add_argument("--collections", nargs="+", default=list(COLLECTIONS), choices=COLLECTIONS)
    ap.add_argument("--out", type=Path, default=Path("photo-suite"))
    ap.add_argument("--tree", type=Path, default=TREE, help="the tree photos (default: %(default)s)")
    ap.add_argument("--shapes", type=int, default=62, help="objects per path-traced collection (default: 62)")
    ap.add_argument("--resolution", type=int, default=None,
                    help="path-traced photos' pixels (default: each collection's own, 64 for pt-mushroom and "
                         "pt-tree, 48 for the others)")
    ap.add_argument("--judge-steps", type=int, default=CRITIC_STEPS, help="the judge's critic steps")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    seeds = [0] if args.quick else args.seeds
    label = args.label or "_".join([Path(args.config).stem, *(s.replace("/", "_") for s in args.sets)])
    out: Path = args.out
    report: List[str] = [f"Config `{args.config}`" + (f" with {', '.join(args.sets)}" if args.sets else "") +
                         f", seeds {seeds}.", ""]
    t0 = time.perf_counter()
    for name in args.collections:
        print(f"{name}: preparing the photos", flush=True)
        photos = photo_folder(name, out, args.tree, args.shapes, args.resolution, args.quiet)
        if photos is None:
            report += [f"### {name}: left out ({args.tree} is absent)", ""]
            continue
        rows = {}
        for seed in seeds:
            print(f"{name}, seed {seed}: training and judging", flush=True)
            rows[seed] = run_one(args.config, args.sets, photos, out / "runs" / label / name / f"seed{seed}",
                                 out / "eval" / label / name / f"seed{seed}", seed, name in PATH_TRACED,
                                 args.judge_steps, args.quiet)
        report += table(name, label, rows, name in PATH_TRACED) + [""]
    report.append(f"({time.perf_counter() - t0:.0f} s)")
    text = "\n".join(report)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{label}.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Interrupted as e:                           # training saved a checkpoint: a re-run resumes
        sys.exit(f"photo_suite: interrupted {e}")
    except UserError as e:
        sys.exit(f"photo_suite: {e}")
