"""Score trained runs as in the paper's Table 2 and write a Markdown report with figures.

``evaluate_runs(run_dirs, out_dir)``: for each run folder (``platonic train``), reconstruct every
held-out image of its procedural collection (the shapes the run never saw; ``train/data.py``),
resample the collection's ground-truth volume (``manifest.json`` → ``volumes/SSSSS.npz``) into
the input camera's frame, and score each (reconstruction, truth) pair with
:func:`~.protocol.evaluate_pair`. The same is done for two baselines per run: the run's
networks untrained (initialised with the run's seed) and, for EA, the billboard (the input image
extruded through the depth of the cube). Written to ``out_dir``:

- ``report.md``: a table laid out like Table 2 — rows: method × image formation (IF); columns:
  DSSIM of the VOL, ISO, VOX and IF re-renders, then RMSE, IoU and CD of the volumes (VGG per
  re-render and FID only when a weights file is given);
- ``figures/<row>.png``: per row, examples of input | reconstruction from 3 novel views |
  ground truth from the same views;
- ``results.json``: every pair's metrics and each row's means.

A run trained on a photo folder (``data.source: folder``) has no ground truth; it gets a "Real
photos" section instead (:mod:`.photos`): its held-out photos reconstructed and rendered with the
run's renderer, MAE / silhouette IoU / DSSIM at the input view, coverage and depth at views 10–30°
above and beside it (no ground truth there: reported, not scored), the front-card check, and a
figure ``figures/<run>_photos.png`` (photo | input view | novel views).

``main_evaluate(argv)`` is the ``platonic evaluate`` command (``add_arguments`` + ``run``).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch

from ..config.loading import checkpoint_config, model_from_checkpoint
from ..errors import UserError, raise_if_ctrl_c
from ..files.checkpoint import read_checkpoint
from ..files.names import readable_stem
from ..files.fileio import confined, make_folder, write_text
from ..files.outputs import MARKER, check_output_folder, claim_output_folder, output_lock
from ..model import Model
from ..render import render
from ..runtime.progress import progress_bar
from ..train.data import collection_folder, load_training_data
from ..views import turntable
from . import metrics as M
from .figures import save_image_grid
from .generation_report import GenerationSection, evaluate_generation_run, section_lines, section_results as generation_results
from .judge import CRITIC_STEPS
from .photos import (PhotoSection, evaluate_photo_run, section_markdown, section_results, write_judge_figure,
                     write_photo_figure)
from .protocol import METHODS, N_VIEWS, billboard, evaluate_pair, held_out_truths

__all__ = ["Row", "score_pairs", "write_table", "write_class_table", "write_figure", "write_report", "evaluate_runs",
           "add_arguments", "run", "main_evaluate", "FIGURE_VIEWS", "SCALE"]

#: What evaluate writes into ``--out`` (:func:`~mitsuba_platonic.files.fileio.confined`: none may be a link).
REPORT_PARTS = (MARKER, "report.md", "results.json", "figures")

#: The paper's display scales (Table 2): DSSIM and VGG × 10, RMSE × 10².
SCALE = {"dssim": 10.0, "vgg": 10.0, "rmse": 100.0, "iou": 1.0, "cd": 1.0, "fid": 1.0}
#: The novel views of the figures: azimuths 60°, 180°, 300° at 30° elevation, in the input's frame.
FIGURE_VIEWS = turntable(3, elevation=30.0, start=60.0)

PathLike = Union[str, Path]


@dataclass
class Row:
    """One table row: ``method`` (e.g. the run's name or a baseline), ``formation`` (VH/AO/EA),
    per-pair metrics, and up to a few (input image, reconstruction, truth) examples for a figure.
    A trained run's row also names its ``shape_class`` and training ``mode`` (empty for baselines)."""

    method: str
    formation: str
    shape_class: str = ""
    mode: str = ""
    pairs: List[Dict[str, float]] = field(default_factory=list)
    examples: List[Tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = field(default_factory=list)
    extra: Dict[str, float] = field(default_factory=dict)        # set-level metrics (FID)

    def mean(self, key: str) -> Optional[float]:
        vals = [p[key] for p in self.pairs if key in p]
        return float(np.mean(vals)) if vals else None

    def means(self) -> Dict[str, float]:
        keys = sorted({k for p in self.pairs for k in p})
        out = {k: self.mean(k) for k in keys}
        out.update(self.extra)
        return out


def score_pairs(method: str, model: str, triples: Sequence[Tuple[torch.Tensor, torch.Tensor, torch.Tensor]],
                n_views: int = N_VIEWS, seed: int = 0, spp: int = 16, max_depth: int = 8,
                methods: Sequence[str] = METHODS, backend: str = "closed_form",
                vgg_network: Optional[torch.nn.Module] = None, fid_network: Optional[torch.nn.Module] = None,
                n_examples: int = 3, progress: bool = False, if_max_depth: Optional[int] = None) -> Row:
    """Score (input image, reconstruction, truth-in-input-frame) triples into one :class:`Row`.

    Pair k uses the views and skies of seed ``seed + k`` (the same for every row, so rows see the
    same views). FID (with ``fid_network``) compares the IF re-renders of all references with
    those of all reconstructions.
    """

    row = Row(method, model.upper())
    if_recon, if_ref = [], []
    bar = progress_bar(len(triples), unit="pair", desc=f"  {method}", disable=not progress)
    for k, (image, recon, truth) in enumerate(triples):
        raise_if_ctrl_c()                                    # a Ctrl-C Mitsuba's render took (it cancels, winds down)
        res = evaluate_pair(recon, truth, model, n_views=n_views, seed=seed + k, methods=methods, spp=spp,
                            max_depth=max_depth, backend=backend, vgg_network=vgg_network, if_max_depth=if_max_depth)
        row.pairs.append(res.metrics)
        if "IF" in res.images:
            if_recon.append(res.images["IF"][0])
            if_ref.append(res.images["IF"][1])
        if len(row.examples) < n_examples:
            row.examples.append((image.detach().cpu(), recon.detach().cpu(), truth.detach().cpu()))
        bar.update(1)
    bar.close()
    if fid_network is not None and if_recon:
        row.extra["fid"] = M.fid(torch.cat(if_ref), torch.cat(if_recon), network=fid_network)
    return row


# -- writing ---------------------------------------------------------------------------------

def _fmt(value: Optional[float], key: str) -> str:
    if value is None:
        return "—"                                          # not computed: never a made-up number
    scale = SCALE[key.split("_")[0]]
    # CD: three significant digits (a good reconstruction's is ~1e-4: fixed decimals would print 0.000)
    return f"{value * scale:.3g}" if key.startswith("cd") else f"{value * scale:.2f}"


def write_table(rows: Sequence[Row], methods: Sequence[str] = METHODS) -> str:
    """The Markdown table (Table 2 layout) of ``rows``: DSSIM (and VGG where computed) per re-render
    method, RMSE, IoU, CD (and FID where computed)."""
    vgg = any(r.mean(f"vgg_{m}") is not None for r in rows for m in methods)
    fid = any("fid" in r.extra for r in rows)
    head = ["Method", "IF"] + [f"DSSIM {m}" for m in methods]
    if vgg:
        head += [f"VGG {m}" for m in methods]
    head += ["RMSE", "IoU", "CD"] + (["FID"] if fid else []) + ["pairs"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r.method, r.formation] + [_fmt(r.mean(f"dssim_{m}"), "dssim") for m in methods]
        if vgg:
            cells += [_fmt(r.mean(f"vgg_{m}"), "vgg") for m in methods]
        cells += [_fmt(r.mean("rmse"), "rmse"), _fmt(r.mean("iou"), "iou"), _fmt(r.mean("cd"), "cd")]
        if fid:
            cells.append(_fmt(r.extra.get("fid"), "fid"))
        cells.append(str(len(r.pairs)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: The re-render methods of the per-class table (the paper's Table 3 leaves out IF).
CLASS_METHODS = ("VOL", "ISO", "VOX")


def write_class_table(rows: Sequence[Row], methods: Sequence[str] = CLASS_METHODS) -> Optional[str]:
    """The Markdown table (Table 3 layout) of the PlatonicGAN rows (``mode`` 'platonic'): one line
    per class, SSIM = 1 − 2 DSSIM (higher is better) per image formation × re-render method, the
    mean over the runs of that class and formation (their count in the last column); — where no
    run was scored. None when ``rows`` hold no PlatonicGAN run."""
    ours = [r for r in rows if r.mode == "platonic" and r.shape_class]
    if not ours:
        return None
    formations = [f for f in ("VH", "AO", "EA") if any(r.formation == f for r in ours)]
    classes = list(dict.fromkeys(r.shape_class for r in ours))            # in the order of the runs
    head = ["Class"] + [f"{f} {m}" for f in formations for m in methods] + ["runs"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in classes:
        cells = [c]
        for f in formations:
            chosen = [r for r in ours if r.shape_class == c and r.formation == f]
            for m in methods:
                vals = [v for v in (r.mean(f"dssim_{m}") for r in chosen) if v is not None]
                cells.append(f"{1.0 - 2.0 * float(np.mean(vals)):.2f}" if vals else "—")
        cells.append(str(sum(r.shape_class == c for r in ours)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_figure(row: Row, path: PathLike, views: torch.Tensor = FIGURE_VIEWS) -> Path:
    """A PNG: one line per example of ``row``: input | reconstruction from ``views`` | ground truth
    from the same views (the training image formation, closed form, over white)."""
    if not row.examples:
        raise UserError(f"row {row.method!r} has no examples to draw")
    model = row.formation.lower()
    k = len(views)
    lines = []
    for image, recon, truth in row.examples:
        with torch.no_grad():
            a = render(recon[None].expand(k, -1, -1, -1, -1).contiguous(), views, model)
            b = render(truth[None].expand(k, -1, -1, -1, -1).contiguous(), views, model)
        lines.append([image] + list(a) + list(b))
    titles = ["input"] + [f"recon {j + 1}" for j in range(k)] + [f"truth {j + 1}" for j in range(k)]
    return save_image_grid(lines, titles, path, f"{row.method} ({row.formation})", cell=(1.3, 1.4))


def write_report(rows: Sequence[Row], out_dir: PathLike, notes: Sequence[str] = (),
                 methods: Sequence[str] = METHODS, photo_sections: Sequence[PhotoSection] = (),
                 generation_sections: Sequence[GenerationSection] = ()) -> Path:
    """Write ``report.md``, ``figures/*.png`` and ``results.json`` for ``rows`` (runs with ground
    truth, the Table 2 layout) and ``photo_sections`` (folder runs, :mod:`.photos`) into ``out_dir``."""
    if not rows and not photo_sections and not generation_sections:
        raise UserError("nothing to report: expected at least one scored row or photo section")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {str(out)!r} exists and is not a folder")
    make_folder(out)
    figures = []
    for r in rows:
        if r.examples:
            stem = f"{readable_stem(r.method, 'row')}_{r.formation.lower()}"
            figures.append((r, write_figure(r, out / "figures" / f"{stem}.png")))
    lines = ["# Evaluation", ""]
    if rows:
        lines += ["Held-out reconstructions against the ground truth, laid out like Table 2 of the paper. "
                 "DSSIM = (1 − SSIM)/2 of re-renders from the same random views under the same random skies "
                 "(VOL: volumetric path tracing, ISO: iso-surface at density 0.1, VOX: voxels, IF: the training "
                 "image formation); RMSE, IoU (density ≥ ½) and CD (density-weighted chamfer distance, world "
                 "units²) of the volumes in the input camera's frame. As in the paper, DSSIM and VGG are "
                 "multiplied by 10 and RMSE by 10². Lower is better except IoU. — marks a value that was not "
                 "computed. Definitions: docs/evaluation.md.", "",
                 write_table(rows, methods), ""]
        classes = write_class_table(rows)
        if classes is not None:
            lines += ["## Per class (Table 3 layout)", "",
                      "SSIM (higher is better) of the PlatonicGAN runs' re-renders per class, image formation "
                      "and re-render method, averaged over the runs of each cell (runs: how many entered the "
                      "line). SSIM = 1 − 2 DSSIM of the table above, without the × 10.", "", classes, ""]
    for section in photo_sections:
        link, stem = None, readable_stem(section.run, "row")
        if section.rows and section.rows[0].examples:
            section.figure = write_photo_figure(section.rows[0], out / "figures" / f"{stem}_photos.png",
                                                section.folder)
            link = f"figures/{section.figure.name}"
        write_judge_figure(section, out / "figures" / f"{stem}_turntable.png")
        lines += section_markdown(section, link)
    for generation in generation_sections:                       # generation runs (.generation_report)
        lines += section_lines(generation, out)
    lines += [f"- {n}" for n in notes]
    if figures:
        lines += ["", "## Figures", "", "Input | reconstruction from 3 novel views | ground truth from the same views.", ""]
        lines += [f"![{r.method} ({r.formation})](figures/{p.name})" for r, p in figures]
    report = out / "report.md"
    write_text(report, "\n".join(lines) + "\n")
    results = [{"method": r.method, "formation": r.formation, "shape_class": r.shape_class, "mode": r.mode,
                "means": r.means(), "pairs": r.pairs} for r in rows]
    results += [entry for section in photo_sections for entry in section_results(section)]
    results += [generation_results(generation) for generation in generation_sections]
    write_text(out / "results.json", json.dumps(results, indent=1))
    return report


# -- runs ------------------------------------------------------------------------------------

def _load(run_dir: Path) -> Tuple[Any, Model, Callable[[], Model], int, str]:
    """A trained run folder or one of its checkpoint files: (config, its
    :class:`~mitsuba_platonic.model.Model`, a factory of the untrained model, step, label). The
    label names the rows: the run folder's name, and for a checkpoint file ``RUN/step_0004000``
    (the run and the file), so that two checkpoints of one run get rows and figures of their own."""
    ckpt = read_checkpoint(run_dir)
    cfg = checkpoint_config(ckpt)
    model = model_from_checkpoint(Model, ckpt, cfg)

    def untrained_model() -> Model:
        torch.manual_seed(cfg.run.seed)                    # the run's seed, fresh initialisation
        return Model.from_config(cfg)

    label = f"{cfg.run.name}/{run_dir.stem}" if run_dir.is_file() else cfg.run.name
    return cfg, model, untrained_model, ckpt.step, label


def _held_out(cfg, run_dir: Path, data_cache: Optional[PathLike], progress: bool):
    if cfg.data.source != "procedural":
        raise UserError(f"{run_dir} was trained on data.source {cfg.data.source!r}: the ground-truth evaluation "
                        f"needs a procedural collection ('folder' runs get the real-photo section)")
    if data_cache is not None:
        cfg.data.cache = str(data_cache)
    folder = collection_folder(cfg)
    if not (folder / "manifest.json").is_file():
        raise UserError(f"{run_dir}: its collection {folder} has no manifest.json (not rendered here, or "
                        f"unfinished); pass --data-cache DIR where the run's data.cache folder is, or run "
                        f"make-dataset with the run's settings")
    data = load_training_data(cfg, progress=progress)
    if not len(data.held_out):
        raise UserError(f"{run_dir}: its collection has no held-out shapes (data.split leaves none)")
    return data


def evaluate_runs(run_dirs: Sequence[PathLike], out_dir: PathLike, n_views: int = N_VIEWS,
                  limit: Optional[int] = None, spp: int = 16, max_depth: int = 8, seed: int = 0,
                  baselines: bool = True, vgg_weights: Optional[PathLike] = None,
                  fid_weights: Optional[PathLike] = None, data_cache: Optional[PathLike] = None,
                  progress: bool = True, data_path: Optional[PathLike] = None,
                  judge_steps: int = CRITIC_STEPS, overwrite: bool = False) -> Path:
    """Score each trained run (and its baselines) on its held-out shapes; write the report. Returns
    the path of ``report.md``. ``limit``: at most this many held-out images per run (all by default).

    A folder run (``data.source: folder``) is scored on its held-out photos instead
    (:func:`~.photos.evaluate_photo_run`, its renderer seeded by ``seed``) and gets a "Real
    photos" section, judged away from the input view by critics of ``judge_steps`` steps
    (:mod:`.judge`; 0 skips the judge); ``data_path`` replaces such runs' ``data.path``. ``n_views``, ``spp``,
    ``max_depth`` and the VGG/FID networks apply to the ground-truth protocol only.

    ``out_dir`` must be new, empty or an earlier evaluation's; any other folder that holds something
    is refused before any work (:class:`UserError`) unless ``overwrite``
    (:func:`~mitsuba_platonic.files.outputs.claim_output_folder`), and nothing is written through a link
    it holds."""
    if not run_dirs:
        raise UserError("no run to evaluate: pass at least one --run DIR")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
        raise UserError(f"limit must be a positive int, got {limit!r}")
    with confined(out_dir, REPORT_PARTS), output_lock(out_dir, "evaluate"):   # one evaluate at a time in --out
        check_output_folder(out_dir, "evaluate", overwrite, earlier=_earlier_evaluation)   # before any work
        rows, notes, sections, generations = _evaluate_runs(run_dirs, n_views, limit, spp, max_depth, seed, baselines,
                                                            vgg_weights, fid_weights, data_cache, progress, data_path,
                                                            judge_steps)
        claim_output_folder(out_dir, "evaluate", overwrite, earlier=_earlier_evaluation)
        return write_report(rows, out_dir, notes, photo_sections=sections, generation_sections=generations)


def _earlier_evaluation(out: Path) -> bool:
    """Whether ``out`` holds an evaluation written before :data:`~mitsuba_platonic.files.outputs.MARKER`
    existed: a ``results.json`` beside a ``report.md`` that starts as evaluate's do."""
    try:
        return (out / "results.json").is_file() and (out / "report.md").read_text().startswith("# Evaluation\n")
    except (OSError, UnicodeDecodeError):
        return False


def _evaluate_runs(run_dirs: Sequence[PathLike], n_views: int, limit: Optional[int], spp: int, max_depth: int,
                   seed: int, baselines: bool, vgg_weights: Optional[PathLike], fid_weights: Optional[PathLike],
                   data_cache: Optional[PathLike], progress: bool, data_path: Optional[PathLike],
                   judge_steps: int) -> Tuple[List[Row], List[str], List[PhotoSection], List[GenerationSection]]:
    """The scoring of :func:`evaluate_runs`: its rows, notes, photo sections and generation sections."""
    vgg = M.load_feature_network(vgg_weights, "VGG16") if vgg_weights is not None else None
    fidnet = M.load_feature_network(fid_weights, "Inception-v3") if fid_weights is not None else None
    rows: List[Row] = []
    sections: List[PhotoSection] = []
    generations: List[GenerationSection] = []
    notes: List[str] = []
    t0 = time.perf_counter()
    kw = dict(n_views=n_views, seed=seed, spp=spp, max_depth=max_depth, vgg_network=vgg, fid_network=fidnet,
              progress=progress)
    for run_dir in map(Path, run_dirs):
        cfg, trained, untrained, step, label = _load(run_dir)
        if cfg.train.task == "generation":                       # samples judged (.generation_report)
            generations.append(evaluate_generation_run(f"{label} (generation, step {step})", cfg, trained, limit, seed,
                                                       data_path, data_cache, progress, judge_steps))
            continue
        if cfg.train.task != "reconstruction":
            raise UserError(f"{run_dir} was trained for {cfg.train.task!r}; evaluation reconstructs held-out "
                            f"images and needs an encoder (train.task: reconstruction)")
        model = cfg.render.model
        if cfg.data.source == "folder":
            name = f"{label} ({cfg.train.mode}, step {step})"
            sections.append(evaluate_photo_run(name, label, cfg, trained, untrained if baselines else None,
                                               limit=limit, seed=seed, data_path=data_path, progress=progress,
                                               judge_steps=judge_steps))
            notes.append(f"{name}: {len(sections[-1].rows[0].photos)} held-out photos, {cfg.model.resolution}³, "
                         f"rendered with the run's renderer (seed {seed}); no VOL/ISO/VOX re-renders, 3D scores, VGG "
                         f"or FID: there is no ground truth")
            continue
        data = _held_out(cfg, run_dir, data_cache, progress)
        m = len(data.held_out) if limit is None else min(limit, len(data.held_out))
        images, records = data.held_out[:m], data.held_out_records[:m]
        truths = held_out_truths(records, model)
        name = f"{label} ({cfg.train.mode}, step {step})"
        recon = trained.reconstruct(images).cpu()
        # IF is the run's own image formation: path traced (at its max_depth) for a run trained through light
        physical = cfg.render.backend == "physical"
        kw_run = dict(kw, backend="physical", if_max_depth=cfg.render.max_depth) if physical else kw
        rows.append(score_pairs(name, model, list(zip(images, recon, truths)), **kw_run))
        rows[-1].shape_class, rows[-1].mode = cfg.data.shape_class, cfg.train.mode
        notes.append(f"{name}: {m} held-out images of '{cfg.data.shape_class}' ({cfg.data.formation} collection, "
                     f"{cfg.model.resolution}³), {n_views} views per pair, {spp} spp"
                     + (f"; IF path traced (max depth {cfg.render.max_depth}), as it trained" if physical else ""))
        if baselines:
            fresh = untrained().reconstruct(images).cpu()
            rows.append(score_pairs(f"{label}: untrained", model, list(zip(images, fresh, truths)), **kw_run))
            if model == "ea":
                boards = [billboard(x) for x in images]
                rows.append(score_pairs(f"{label}: billboard", model, list(zip(images, boards, truths)),
                                        **kw_run))
    notes.append(f"evaluated in {time.perf_counter() - t0:.0f} s" + (
        f"; held-out pair k of every row is re-rendered with views and skies of seed {seed} + k" if rows else ""))
    return rows, notes, sections, generations


# -- the command -----------------------------------------------------------------------------

def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``platonic evaluate`` flags."""
    p.add_argument("--run", action="append", required=True, metavar="DIR",
                   help="a trained run folder, or one of its checkpoint files (RUN/checkpoints/step_….pt; "
                        "repeatable: one table row per run, plus its baselines)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for report.md, figures/ and results.json")
    p.add_argument("--views", type=int, default=N_VIEWS, help="random re-render views per pair (default 10)")
    p.add_argument("--limit", type=int, default=None, help="at most this many held-out images per run (default all)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of the VOL/ISO/VOX path tracing (default 16)")
    p.add_argument("--seed", type=int, default=0, help="seed of the re-render views and skies (default 0)")
    p.add_argument("--no-baselines", action="store_true", help="skip the untrained and billboard rows")
    p.add_argument("--vgg-weights", default=None, metavar="FILE",
                   help="VGG16 weights (torchvision's vgg16-397923af.pth) for VGG columns; none ships here")
    p.add_argument("--fid-weights", default=None, metavar="FILE",
                   help="a TorchScript Inception-v3 feature extractor for an FID column")
    p.add_argument("--data-cache", default=None, metavar="DIR",
                   help="where the runs' procedural collections are cached (default: each run's data.cache)")
    p.add_argument("--data-path", default=None, metavar="DIR",
                   help="the photo folder of folder runs (data.source: folder) when their data.path, relative to "
                        "where training ran, does not resolve from here")
    p.add_argument("--judge-steps", type=int, default=CRITIC_STEPS, metavar="N",
                   help=f"training steps of each two-sample critic that judges photo runs away from the input view "
                        f"(default {CRITIC_STEPS}; 0 skips the judge)")
    p.add_argument("--overwrite", action="store_true",
                   help="write into an --out that holds files evaluate did not write, replacing report.md, "
                        "results.json and figures/ of the same names there (nothing else is deleted)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``platonic evaluate`` with parsed ``args``; print the report's path."""
    for flag, value in (("--views", args.views), ("--spp", args.spp)):
        if value < 1:
            raise UserError(f"{flag} must be a positive int, got {value}")
    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative int, got {args.seed}")
    if args.judge_steps < 0:
        raise UserError(f"--judge-steps must be a non-negative int, got {args.judge_steps}")
    report = evaluate_runs(args.run, args.out, n_views=args.views, limit=args.limit, spp=args.spp, seed=args.seed,
                           baselines=not args.no_baselines, vgg_weights=args.vgg_weights,
                           fid_weights=args.fid_weights, data_cache=args.data_cache, progress=not args.quiet,
                           data_path=args.data_path, judge_steps=args.judge_steps, overwrite=args.overwrite)
    print(f"report: {report}")
    return 0


def main_evaluate(argv: Optional[Sequence[str]] = None) -> int:
    """``platonic evaluate --run DIR [--run DIR ...] --out DIR [...]`` as a function of its arguments."""
    parser = add_arguments(argparse.ArgumentParser(prog="platonic evaluate",
                                                   description="Score trained runs as in the paper's Table 2."))
    return run(parser.parse_args(argv))
