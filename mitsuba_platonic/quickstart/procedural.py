"""``platonic quickstart``: the whole pipeline in minutes on a CPU.

1. render a small procedural collection (``configs/quickstart.yaml``: 32³, EA);
2. train single-image reconstruction through the batched Mitsuba ray marcher (EA);
3. reconstruct held-out images (shapes the run never saw), write volumes, turntable GIFs and
   meshes, and a report comparing each reconstruction with the ground truth at the input view
   *and at novel views* (where a model that learnt only the input view fails).

Novel-view scoring (:func:`mitsuba_platonic.evaluate.protocol.held_out_scores`). A reconstruction lives in its input camera's frame (the input view is ω₀).
The ground-truth volume is resampled into that frame (the closed form's rotation T(ω_in)), and
both are rendered from the same novel views (a ring around the object at 30° elevation, plus the
back view). A *billboard* baseline — the input image extruded through the depth of the cube,
which matches the input view exactly and knows nothing about depth — shows what "learning only
the input view" scores.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

import torch

from ..config import load_config
from ..errors import Interrupted
from ..evaluate.protocol import held_out_scores
from ..export import export_held_out
from ..files.fileio import confined, write_text
from ..files.outputs import MARKER, claim_output_folder, output_lock
from ..files.resources import config_path
from ..model import Model
from ..train import data as training_data
from ..train import run as training_run
from ..train.memory_fit import check_model_fits
from ..train.folder import is_run_folder

__all__ = ["quickstart", "stopped", "claim_quickstart_folder"]

#: The quickstart's config, carried inside the package (configs/quickstart.yaml).
CONFIG = config_path("quickstart")

_BACKEND_NAMES = {"closed_form": "closed-form layer", "mitsuba": "Mitsuba ray marcher",
                  "physical": "Mitsuba path tracer"}


def quickstart(out: Path = Path("quickstart"), steps: Optional[int] = None, progress: bool = True,
               overrides: Sequence[str] = (), overwrite: bool = False) -> Path:
    """Run the quickstart into ``out``; return the path of its report.

    overrides: ``section.key=value`` changes to ``configs/quickstart.yaml`` (``--set``), applied
    after ``out`` and ``steps``. ``out`` must be new, empty or an earlier quickstart's (which it
    continues), else it is refused before any work unless ``overwrite``
    (:func:`claim_quickstart_folder`). Ctrl-C stops it at any stage (a half-trained model is never
    evaluated): raises :class:`~mitsuba_platonic.errors.Interrupted` saying what is kept (the cached
    data, the checkpoint training saved) and that running it again continues from there.
    """
    stage = {"now": "preparing the data"}
    try:
        return _quickstart(Path(out), steps, progress, stage, overrides, overwrite)
    except KeyboardInterrupt as e:
        raise stopped(e, stage, f"platonic quickstart --out {out}", steps, overrides) from None


def stopped(e: KeyboardInterrupt, stage: Dict[str, str], command: str, steps: Optional[int],
            overrides: Sequence[str]) -> Interrupted:
    """The :class:`~mitsuba_platonic.errors.Interrupted` of a quickstart stopped by Ctrl-C in
    ``stage["now"]``: what was kept (the checkpoint training saved) and the ``command`` (with its
    ``--steps`` and ``--set`` flags) that continues it."""
    saved = getattr(e, "saved", None)
    kept = f"{saved}; " if saved else ""
    again = command + (f" --steps {steps}" if steps is not None else "") + "".join(f" --set {o}" for o in overrides)
    return Interrupted(f"while {stage['now']}: {kept}no report was written; run `{again}` again to continue "
                       f"(the data stays cached and training resumes from its last checkpoint)", saved=saved)


def claim_quickstart_folder(out: Path, run_dir: Path, overwrite: bool) -> None:
    """Make ``out`` the quickstart's output folder (:func:`~mitsuba_platonic.files.outputs.claim_output_folder`):
    new, empty or an earlier quickstart's (marked, or from before the mark: ``run_dir`` is a run
    folder), else refused unless ``overwrite``."""
    claim_output_folder(out, "quickstart", overwrite, earlier=lambda _: is_run_folder(run_dir))


#: What the quickstarts write into ``--out`` (:func:`~mitsuba_platonic.files.fileio.confined`: none may be a link).
QUICKSTART_PARTS = (MARKER, "report.md", "run", "data", "reconstructions", "evaluation")


def _quickstart(out: Path, steps: Optional[int], progress: bool, stage: Dict[str, str],
                overrides: Sequence[str] = (), overwrite: bool = False) -> Path:
    """:func:`quickstart`, telling ``stage["now"]`` what it is doing."""

    t0 = time.perf_counter()
    extra, overrides = list(overrides), [f"run.out_dir={out}", f"data.cache={out / 'data'}"]
    if steps is not None:
        overrides.append(f"run.steps={steps}")
    cfg = load_config(CONFIG, overrides + extra)
    check_model_fits(cfg)                               # before rendering the data
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    with confined(out, QUICKSTART_PARTS), output_lock(out, "quickstart"):   # no link, one quickstart at a time
        claim_quickstart_folder(out, run_dir, overwrite)
        return _run_quickstart(out, cfg, run_dir, progress, stage, t0)


def _run_quickstart(out: Path, cfg: Any, run_dir: Path, progress: bool, stage: Dict[str, str], t0: float) -> Path:
    """:func:`quickstart` in its claimed, confined folder ``out``."""
    resume = (run_dir / "checkpoints" / "last.pt").exists()
    data = training_data.load_training_data(cfg, progress=progress)   # looked up when called (tests replace it)
    t_data = time.perf_counter() - t0
    stage["now"] = "scoring the untrained model"
    torch.manual_seed(cfg.run.seed)
    untrained = held_out_scores(Model.from_config(cfg), data)          # a fresh model, drawn from the run's seed
    stage["now"] = "training"
    training_run.train(cfg, resume=resume, progress=progress)          # looked up when called (tests replace it)
    stage["now"] = "scoring and exporting the trained model"
    t_train = time.perf_counter() - t0 - t_data
    model = Model.from_checkpoint(run_dir)
    step = model.step
    trained = held_out_scores(model, data)

    recon_dir = out / "reconstructions"
    written = [str(p) for p in export_held_out(model, data.held_out, recon_dir)]

    with open(run_dir / "scalars.csv") as f:
        rows = list(csv.DictReader(f))
    first, last = rows[0], rows[-1]
    total = time.perf_counter() - t0
    lines = [
        "# mitsuba-platonic quickstart report", "",
        f"- data: {cfg.data.n_shapes} procedural '{cfg.data.shape_class}' shapes × {cfg.data.views_per_shape} "
        f"random views at {cfg.model.resolution}³ ({len(data.images)} training images, {len(data.held_out)} "
        f"held-out images of unseen shapes), {t_data:.0f} s",
        f"- training: {step} steps, batch {cfg.train.batch_size}, {cfg.render.model.upper()} through the "
        f"{_BACKEND_NAMES[cfg.render.backend]}, "
        f"{t_train:.0f} s; total {total:.0f} s",
        f"- losses (step {first['step']} → {last['step']}): reconstruction {float(first['loss_rec']):.4f} → "
        f"{float(last['loss_rec']):.4f}, D {float(first['loss_d']):.3f} → {float(last['loss_d']):.3f}, "
        f"G {float(first['loss_g']):.3f} → {float(last['loss_g']):.3f}", "",
        "## Held-out reconstructions against the ground truth", "",
        "Mean absolute error (MAE) of premultiplied RGBA renders, and intersection-over-union (IoU) of",
        "their silhouettes (alpha > ½); higher IoU and lower MAE are better.", "",
        "| | input view MAE | input view IoU | novel views MAE | novel views IoU |", "|---|---|---|---|---|",
        *[f"| {name} | {m['input_view_mae']:.4f} | {m['input_view_iou']:.3f} | {m['novel_view_mae']:.4f} | "
          f"{m['novel_view_iou']:.3f} |" for name, m in (("untrained", untrained), ("trained", trained))],
    ]
    if "billboard_novel_view_mae" in trained:
        lines.append(f"| billboard (input view only) | {trained['billboard_input_view_mae']:.4f} | "
                     f"{trained['billboard_input_view_iou']:.3f} | {trained['billboard_novel_view_mae']:.4f} | "
                     f"{trained['billboard_novel_view_iou']:.3f} |")
    lines += ["", "Novel views: a ring at 30° elevation and the back view, in each input's camera frame, "
              "against the ground-truth volume resampled into that frame.", "",
              "## Files", "", f"- run folder: {run_dir} (samples/, scalars.csv, tb/, checkpoints/)",
              f"- reconstructions of held-out images: {recon_dir}"] + [f"  - {w}" for w in written]
    return write_text(out / "report.md", "\n".join(lines) + "\n")
