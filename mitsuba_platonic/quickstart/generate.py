"""``platonic quickstart --photos DIR --generate``: new objects of the class a photo folder shows, in one command.

1. load the folder as training would (``configs/photos_generate.yaml``: 32³, EA through the batched
   marcher, ``train.task: generation``; de-duplicated, split train / held-out by content hash), so a
   folder that cannot train is refused before anything is written;
2. train the generator G(z), z ~ N(0, I), against a critic of the training photos (resumes a finished
   or interrupted run);
3. judge the run on the held-out photos (:func:`mitsuba_platonic.evaluate.report.evaluate_runs`, its
   generation section, :mod:`mitsuba_platonic.evaluate.generation`): a fresh two-sample critic at random
   views and per band of azimuth, the samples' diversity, their renders' roughness against the photos';
4. export :data:`SAMPLES` samples (volumes, turntable GIFs, the sample grid, turntables, an
   interpolation: :func:`mitsuba_platonic.export.export_samples`) and write ``report.md``.

The recipe and what it was measured to give: docs/training.md, "Generating new objects of a class from photos".
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from ..config import load_config
from ..errors import UserError
from ..evaluate import report as evaluation_report
from ..evaluate.generation import GENERATION_BANDS
from ..evaluate.photos import photo_splits
from ..export import export_samples
from ..files.fileio import confined, write_text
from ..files.resources import config_path
from ..model import Model
from ..train import run as training_run
from ..train.memory_fit import check_model_fits
from .procedural import QUICKSTART_PARTS, claim_quickstart_folder, stopped

__all__ = ["generation_quickstart", "GENERATE_CONFIG", "SAMPLES", "GENERATE_PARTS"]

#: The generation recipe, carried inside the package (configs/photos_generate.yaml).
GENERATE_CONFIG = config_path("photos_generate")
#: Samples exported into ``out/samples``.
SAMPLES = 16
#: What this quickstart writes into ``--out`` (none may be a link).
GENERATE_PARTS = (*QUICKSTART_PARTS, "samples")

_BAND_HEADS = {"random": "random views", "front": "front (0°)", "near": "near (15–45°)", "side": "side (60–120°)",
               "back": "back (135–180°)"}


def _figure_lines(means: Dict[str, Any]) -> List[str]:
    """The report's two tables: the critic's accuracy per band, and diversity and roughness."""
    cell = lambda k, d=3: "—" if means.get(k) is None else f"{means[k]:.{d}f}"      # noqa: E731
    lines = []
    if "c2st_random" in means:
        lines += ["| " + " | ".join(f"two-sample accuracy, {_BAND_HEADS[b]}" for b in GENERATION_BANDS) + " |",
                  "|" + "---|" * len(GENERATION_BANDS),
                  "| " + " | ".join(cell(f"c2st_{b}") for b in GENERATION_BANDS) + " |", ""]
    lines += ["| volume diversity | render diversity | held-out photos' diversity | roughness, renders / photos |",
              "|---|---|---|---|",
              f"| {cell('diversity_volumes')} | {cell('diversity_renders')} | {cell('diversity_photos')} | "
              f"{cell('roughness_ratio', 2)} |"]
    return lines


def generation_quickstart(photos: Path, out: Path = Path("quickstart-generate"), steps: Optional[int] = None,
                          progress: bool = True, overrides: Sequence[str] = (), overwrite: bool = False) -> Path:
    """Train a generator on the photo folder ``photos`` into ``out``, judge it and export samples; return
    ``out/report.md``. ``overrides``: ``KEY=VALUE`` changes to ``configs/photos_generate.yaml``. Ctrl-C
    stops it at any stage (a half-trained model is never judged) with an
    :class:`~mitsuba_platonic.errors.Interrupted` that says what was kept and how to continue. ``out`` must
    be new, empty or an earlier quickstart's (which it continues), else it is refused before any work
    unless ``overwrite``."""
    stage = {"now": "loading the photos"}
    try:
        return _generation_quickstart(Path(photos), Path(out), steps, progress, overrides, stage, overwrite)
    except KeyboardInterrupt as e:
        raise stopped(e, stage, f"platonic quickstart --photos {photos} --generate --out {out}", steps,
                      overrides) from None


def _generation_quickstart(photos: Path, out: Path, steps: Optional[int], progress: bool, overrides: Sequence[str],
                           stage: Dict[str, str], overwrite: bool) -> Path:
    """:func:`generation_quickstart`, telling ``stage["now"]`` what it is doing."""
    if not photos.is_dir():
        raise UserError(f"--photos {str(photos)!r} is not a folder")
    t0 = time.perf_counter()
    fixed = [f"data.path={photos.resolve()}", f"run.out_dir={out}", "run.name=run"]
    if steps is not None:
        fixed.append(f"run.steps={steps}")
    cfg = load_config(GENERATE_CONFIG, [*fixed, *overrides])
    if cfg.train.task != "generation" or cfg.data.source != "folder":
        raise UserError(f"--generate trains train.task 'generation' on data.source 'folder'; the overrides made them "
                        f"{cfg.train.task!r} and {cfg.data.source!r}")
    check_model_fits(cfg)
    train_photos, held, _ = photo_splits(cfg)                      # a folder that cannot train fails here
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    with confined(out, GENERATE_PARTS):                 # a link in the folder is refused before any work
        claim_quickstart_folder(out, run_dir, overwrite)
        return _run(photos, out, cfg, run_dir, len(train_photos), len(held), progress, stage, t0)


def _run(photos: Path, out: Path, cfg: Any, run_dir: Path, n_train: int, n_held: int, progress: bool,
         stage: Dict[str, str], t0: float) -> Path:
    """:func:`generation_quickstart` in its claimed, confined folder ``out``."""
    resume = (run_dir / "checkpoints" / "last.pt").exists()
    stage["now"] = "training"
    training_run.train(cfg, resume=resume, progress=progress)          # looked up when called (tests replace it)
    t_train = time.perf_counter() - t0
    stage["now"] = "judging the samples"
    evaluation = evaluation_report.evaluate_runs([run_dir], out / "evaluation", progress=progress)
    results = json.loads((evaluation.parent / "results.json").read_text())
    entry = next(r for r in results if r.get("section") == "generation")
    stage["now"] = "exporting samples"
    model = Model.from_checkpoint(run_dir)
    samples = out / "samples"
    export_samples(model, SAMPLES, samples, seed=0, overwrite=True)
    lines = ["# mitsuba-platonic quickstart: generating from photos", "",
             f"- photos: `{photos}`: {n_train} for training, {n_held} held out (never trained on)",
             f"- training: {model.step} steps at {cfg.model.resolution}³, {cfg.render.model.upper()} through "
             f"{cfg.render.backend}, z ~ N(0, I) of size {cfg.model.latent}, {t_train:.0f} s",
             "", "## Judged against the held-out photos", "",
             "Accuracy of fresh critics telling the held-out photos from renders of random samples, at random "
             "views in the training band of elevation and on a turntable by band of azimuth: 0.5, the renders "
             "pass for photos; 1, they never do. Diversity: mean pairwise 1 − IoU of the samples' occupancies and "
             "of their silhouettes (below 0.1: collapsed). Roughness: the renders' mean |Laplacian| over the "
             "photos' (above 1: speckle the photos do not have). docs/evaluation.md, \"Generation runs\".", "",
             *_figure_lines(entry["means"]), ""]
    lines += [f"**{w}.**" for w in entry.get("warnings", [])]
    lines += ["", f"The full evaluation (sample grid, turntables, interpolation, photos beside samples): {evaluation}",
              "", "## Files", "",
              f"- run folder: {run_dir} (samples/, scalars.csv, tb/, checkpoints/); more samples: "
              f"`platonic generate --run {run_dir} -n 32 --seed 1`",
              f"- {SAMPLES} samples (seed 0): {samples} (sample_NNN.npz/.vol/.gif, samples.png, turntables.png, "
              f"interpolation.png)"]
    return write_text(out / "report.md", "\n".join(lines) + "\n")
