"""``platonic quickstart --photos DIR``: a user's photo folder, trained, judged and exported in one command.

1. load the folder as training would (``configs/photos.yaml``: 32³, EA through the batched
   marcher; de-duplicated, split train / held-out by content hash), so a folder that cannot train
   is refused before anything is written;
2. train single-image reconstruction on the training split (resumes a finished or interrupted run);
3. evaluate the run on the held-out photos (:func:`mitsuba_platonic.evaluate.report.evaluate_runs`):
   input-view scores, the front-card check, and the judge from every side (:mod:`.evaluate.judge`);
4. export up to four held-out reconstructions (volumes, turntable GIFs, meshes) beside their photos
   and write ``report.md`` with the judge's verdict, the shape priors the run used and, where its
   photos' silhouettes contradict a round prior, a warning (:mod:`mitsuba_platonic.evaluate.priors`),
   which the command also prints last.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import torch

from ..config import load_config
from ..errors import UserError
from ..evaluate import report as evaluation_report
from ..evaluate.judge import BANDS
from ..evaluate.photos import photo_splits
from ..evaluate.priors import priors_markdown, priors_used, round_evidence
from ..export import export_held_out
from ..files.fileio import confined, write_text
from ..files.outputs import output_lock
from ..files.resources import config_path
from ..model import Model
from ..train import run as training_run
from ..train.memory_fit import check_model_fits
from .procedural import QUICKSTART_PARTS, claim_quickstart_folder, stopped

__all__ = ["photo_quickstart", "PHOTO_CONFIG"]

PHOTO_CONFIG = config_path("photos")


def _judge_lines(results: List[Dict]) -> List[str]:
    """The report's table of the judge's figures, one line per evaluated row (trained, baselines)."""
    names = [b[0] for b in BANDS]
    lines = ["| | " + " | ".join(f"two-sample accuracy, {n}" for n in names) +
             " | side roughness / input's | side ΔE | back ΔE |", "|---|" + "---|" * (len(names) + 3)]
    for r in results:
        j = r.get("judge")
        if j is None:
            continue
        cell = lambda k, d=3: "—" if j.get(k) is None else f"{j[k]:.{d}f}"      # noqa: E731
        lines.append(f"| {r['method']} | " + " | ".join(cell(f"c2st_{n}") for n in names) +
                     f" | {cell('roughness_side', 2)} | {cell('delta_e_side', 1)} | {cell('delta_e_back', 1)} |")
    return lines


def photo_quickstart(photos: Path, out: Path = Path("quickstart-photos"), steps: Optional[int] = None,
                     progress: bool = True, overrides: Sequence[str] = (), overwrite: bool = False) -> Path:
    """Train on the photo folder ``photos`` into ``out``, judge and export; return ``out/report.md``.
    ``overrides``: ``KEY=VALUE`` changes to ``configs/photos.yaml`` (e.g. ``model.resolution=16``).
    Ctrl-C stops it at any stage (a half-trained model is never evaluated) with an
    :class:`~mitsuba_platonic.errors.Interrupted` that says what was kept and how to continue. ``out``
    must be new, empty or an earlier quickstart's (which it continues), else it is refused before any
    work unless ``overwrite``."""
    stage = {"now": "loading the photos"}
    try:
        return _photo_quickstart(Path(photos), Path(out), steps, progress, overrides, stage, overwrite)
    except KeyboardInterrupt as e:
        raise stopped(e, stage, f"platonic quickstart --photos {photos} --out {out}", steps, overrides) from None


def _photo_quickstart(photos: Path, out: Path, steps: Optional[int], progress: bool, overrides: Sequence[str],
                      stage: Dict[str, str], overwrite: bool = False) -> Path:
    """:func:`photo_quickstart`, telling ``stage["now"]`` what it is doing."""

    if not photos.is_dir():
        raise UserError(f"--photos {str(photos)!r} is not a folder")
    t0 = time.perf_counter()
    extra = list(overrides)
    overrides = [f"data.path={photos.resolve()}", f"run.out_dir={out}", "run.name=run"]
    if steps is not None:
        overrides.append(f"run.steps={steps}")
    cfg = load_config(PHOTO_CONFIG, [*overrides, *extra])
    check_model_fits(cfg)
    train_photos, held, files = photo_splits(cfg)                 # a folder that cannot train fails here
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    with confined(out, QUICKSTART_PARTS), output_lock(out, "quickstart"):   # no link, one quickstart at a time
        claim_quickstart_folder(out, run_dir, overwrite)
        return _run_photo_quickstart(photos, out, cfg, run_dir, train_photos, held, progress, stage, t0)


def _run_photo_quickstart(photos: Path, out: Path, cfg: Any, run_dir: Path, train_photos: Any, held: Any,
                          progress: bool, stage: Dict[str, str], t0: float) -> Path:
    """:func:`photo_quickstart` in its claimed, confined folder ``out``."""
    resume = (run_dir / "checkpoints" / "last.pt").exists()
    stage["now"] = "training"
    training_run.train(cfg, resume=resume, progress=progress)          # looked up when called (tests replace it)
    t_train = time.perf_counter() - t0
    stage["now"] = "judging and exporting the trained model"
    # looked up when called (tests replace it)
    evaluation = evaluation_report.evaluate_runs([run_dir], out / "evaluation", progress=progress)
    results = json.loads((evaluation.parent / "results.json").read_text())
    model = Model.from_checkpoint(run_dir)

    recon_dir = out / "reconstructions"
    written = [str(p) for p in export_held_out(model, held, recon_dir)]
    trained = results[0]
    means = trained["means"]
    cards = trained["card_check"]
    lines = ["# mitsuba-platonic quickstart on photos", "",
             f"- photos: `{photos}`: {len(train_photos)} for training, {len(held)} held out (never trained on)",
             f"- training: {model.step} steps at {cfg.model.resolution}³, {cfg.render.model.upper()} through "
             f"{cfg.render.backend}, {t_train:.0f} s",
             f"- input view (the photo is the truth there): MAE {means['input_view_mae']:.4f}, silhouette IoU "
             f"{means['input_view_iou']:.3f}; {cards['not_cards']} of {cards['n']} reconstructions are not front cards",
             "", *priors_markdown(priors_used(cfg), round_evidence(torch.cat([train_photos, held]))),
             "## Judged from every side", "",
             "Accuracy of a fresh critic telling the held-out photos from renders of their reconstructions, per "
             "band of turntable angle from the input view: 0.5, the renders pass for photos; 1, they never do. "
             "The billboard (the photo extruded through the cube) shows what a reconstruction that learnt only "
             "the input view scores. Roughness and ΔE (CIE76) of the side (±90°) and back (180°) views: "
             "docs/evaluation.md.", "", *_judge_lines(results), "",
             f"The full evaluation: {evaluation}", "", "## Files", "",
             f"- run folder: {run_dir} (samples/, scalars.csv, tb/, checkpoints/)",
             f"- held-out reconstructions: {recon_dir}"] + [f"  - {w}" for w in written]
    return write_text(out / "report.md", "\n".join(lines) + "\n")
