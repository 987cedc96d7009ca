"""A generation run's part of ``platonic evaluate``'s report: its data, its judgement, its tables and figures.

:func:`generation_data` reads what judging a generation run (:mod:`.generation`) needs: the run's
training and held-out images (a photo folder's train and val + test splits,
:func:`~.photos.photo_splits`; a procedural collection's training and held-out shapes'
images, :func:`~mitsuba_platonic.train.data.load_training_data`) and, where the collection has
them, the ground-truth volumes behind the held-out images (a procedural collection's, or a rendered
collection's ``manifest.json`` beside or above a photo folder, as ``platonic make-dataset`` writes
it: the suite's path-traced collections). :func:`evaluate_generation_run` judges the run;
:func:`section_lines` writes its figures and returns its Markdown (the style of the photo
section: tables, then figures); :func:`section_results` its ``results.json`` entry.
docs/evaluation.md, "Generation runs", explains every figure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch

from ..data.render_collection import load_manifest
from ..errors import UserError
from ..files.names import readable_stem
from ..render.frames import display_frames
from ..sheets import GRID_VIEW, save_interpolation, save_sample_grid, save_sheet, save_turntables
from ..views import from_angles
from . import metrics as M
from .generation import (COLLAPSE, EVAL_RESOLUTION, FILL, GENERATION_BANDS, SAMPLES, TURNS, GenerationJudgement,
                         judge_generation)
from .judge import CRITIC_REPEATS, CRITIC_STEPS, TRAIN_VIEWS
from .photos import photo_splits

__all__ = ["GenerationData", "generation_data", "GenerationSection", "evaluate_generation_run", "section_lines",
           "section_results", "FIGURE_SAMPLES"]

PathLike = Union[str, Path]

#: Samples shown on the turntables and beside their nearest truth.
FIGURE_SAMPLES = 8


@dataclass
class GenerationData:
    """A generation run's images: ``train`` ``(N, C, R, R)`` and ``held_out`` ``(M, C, R, R)``, a
    description of where they came from (``source``), and the ground-truth volumes behind the held-out
    images (``truths``, ``(4, N, N, N)`` each, distinct; empty without truth) with ``truth_source``."""

    train: torch.Tensor
    held_out: torch.Tensor
    source: str
    truths: List[torch.Tensor] = field(default_factory=list)
    truth_source: str = ""


def _volume(path: Path) -> torch.Tensor:
    try:
        return torch.from_numpy(np.load(path)["volume"]).float()
    except (OSError, KeyError, ValueError) as e:
        raise UserError(f"cannot read the ground-truth volume {path}: {e}") from None


def _folder_truths(folder: Path, files: Sequence[PathLike]) -> Tuple[List[torch.Tensor], str]:
    """The distinct ground-truth volumes of held-out photos ``files`` when ``folder`` is a rendered
    collection's images (``manifest.json`` in it or in its parent), else ([], "")."""
    for root in (folder, folder.parent):
        if (root / "manifest.json").is_file():
            records = {str((root / r["image"]).resolve()): r for r in load_manifest(root)["images"]}
            paths = []
            for f in files:
                rec = records.get(str(Path(f).resolve()))
                if rec is None:
                    raise UserError(f"{f} is not in {root / 'manifest.json'}")
                if rec["volume"] not in paths:
                    paths.append(rec["volume"])
            return [_volume(root / p) for p in paths], f"{root / 'manifest.json'}"
    return [], ""


def generation_data(cfg: Any, data_path: Optional[PathLike] = None, data_cache: Optional[PathLike] = None,
                    limit: Optional[int] = None, progress: bool = False) -> GenerationData:
    """The images and truth of a generation run (module docstring); ``limit``: at most this many held-out
    images (and the truths behind them); ``data_path`` replaces a folder run's ``data.path``,
    ``data_cache`` a procedural run's ``data.cache``."""
    if cfg.data.source == "folder":
        folder = Path(data_path if data_path is not None else cfg.data.path)
        train, held, files = photo_splits(cfg, folder)
        if limit is not None:
            held, files = held[:limit], files[:limit]
        truths, where = _folder_truths(folder, files)
        return GenerationData(train, held, f"`{folder}` (photo folder)", truths, where)
    from ..train.data import collection_folder, load_training_data  # lazy: the trainer's data, for these runs only

    if data_cache is not None:
        cfg.data.cache = str(data_cache)
    folder = collection_folder(cfg)
    if not (folder / "manifest.json").is_file():
        raise UserError(f"the run's collection {folder} has no manifest.json (not rendered here, or unfinished); "
                        f"pass --data-cache DIR where the run's data.cache folder is")
    data = load_training_data(cfg, progress=progress)
    records = data.held_out_records if limit is None else data.held_out_records[:limit]
    held = data.held_out if limit is None else data.held_out[:limit]
    if not len(held):
        raise UserError(f"the run's collection {folder} has no held-out shapes (data.split leaves none)")
    paths = list(dict.fromkeys(str(Path(r["folder"]) / r["volume"]) for r in records))
    return GenerationData(data.images, held, f"`{folder}` (procedural '{cfg.data.shape_class}')",
                          [_volume(Path(p)) for p in paths], str(folder / "manifest.json"))


@dataclass
class GenerationSection:
    """A generation run's part of the report: its name, data, model, renderer and judgement; the figures'
    paths once :func:`section_lines` wrote them."""

    run: str
    data: GenerationData
    model: Any
    settings: Any
    judgement: GenerationJudgement
    seed: int = 0
    judge_steps: int = CRITIC_STEPS
    repeats: int = CRITIC_REPEATS
    figures: Dict[str, Path] = field(default_factory=dict)


def evaluate_generation_run(name: str, cfg: Any, model: Any, limit: Optional[int] = None, seed: int = 0,
                            data_path: Optional[PathLike] = None, data_cache: Optional[PathLike] = None,
                            progress: bool = False, judge_steps: int = CRITIC_STEPS,
                            n_samples: int = SAMPLES, repeats: int = CRITIC_REPEATS) -> GenerationSection:
    """Judge a generation run (:func:`~.generation.judge_generation`: ``n_samples`` samples, ``repeats``
    critics of ``judge_steps`` steps, 0: none) on its data (:func:`generation_data`), its renderer
    ``cfg.render`` seeded by ``seed``."""
    data = generation_data(cfg, data_path, data_cache, limit, progress)
    if progress:
        print(f"  {name}: {n_samples} samples against {len(data.held_out)} held-out image(s), {len(data.train)} "
              f"training image(s) for the critics" + (f", {len(data.truths)} truth volumes" if data.truths else ""),
              flush=True)
    judgement = judge_generation(model, data.train, data.held_out, cfg.render, cfg.train, data.truths or None,
                                 n_samples=n_samples, seed=seed, steps=judge_steps, repeats=repeats)
    return GenerationSection(name, data, model, cfg.render, judgement, seed, judge_steps, repeats)


def _num(value: Optional[float], digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _critic_table(j: GenerationJudgement) -> str:
    heads = {"random": "random p_view views", "front": "front (0°)", "near": "near (15–45°)",
             "side": "side (60–120°)", "back": "back (135–180°)"}
    c = j.c2st
    lines = ["| " + " | ".join(heads[b] for b in GENERATION_BANDS) + " | critic on its training sets | "
             "held-out photos called photos | held-out photos |", "|" + "---|" * (len(GENERATION_BANDS) + 3)]
    cells = " | ".join(f"{_num(c['accuracy'][b])} ({_num(c['auc'][b], 2)})" for b in GENERATION_BANDS)
    lines.append(f"| {cells} | {_num(c['train_accuracy'])} | {_num(c['photo_pass'], 2)} | {c['photos']} |")
    return "\n".join(lines)


def _variety_table(j: GenerationJudgement) -> str:
    d, r = j.diversity, j.roughness
    return "\n".join([
        "| samples | volume diversity | render diversity (shared views) | held-out photos' diversity | "
        "roughness of the renders | of the photos | renders / photos |", "|---|---|---|---|---|---|---|",
        f"| {j.samples} | {_num(d['volumes'])} | {_num(d['renders'])} | {_num(d['photos'])} | "
        f"{_num(r['renders'], 4)} | {_num(r['photos'], 4)} | {_num(r['ratio'], 2)} |"])


def _truth_table(j: GenerationJudgement) -> str:
    t = j.truth
    return "\n".join([
        "| samples | truth volumes | nearest-truth IoU (mean over samples) | nearest-sample IoU (mean over truths, "
        "MMD-style) | coverage (COV) |", "|---|---|---|---|---|",
        f"| {t['samples']} | {t['truths']} | {_num(t['sample_iou'])} | {_num(t['truth_iou'])} | "
        f"{_num(t['coverage'], 2)} ({len(set(t['nearest']))} of {t['truths']}) |"])


def _figures(section: GenerationSection, out: Path) -> Dict[str, Path]:
    """Write the section's figures into ``out/figures``; name → path."""
    j, model = section.judgement, section.model
    base = out / "figures" / readable_stem(section.run, "run")
    names = [f"sample_{i:03d}" for i in range(j.samples)]
    k = min(FIGURE_SAMPLES, j.samples)
    figs = {"samples": save_sample_grid(j.volumes, model.formation, f"{base}_samples.png", columns=8, labels=names,
                                        title=f"{section.run}: {j.samples} samples (seed {section.seed})"),
            "turntables": save_turntables(j.volumes[:k], model.formation, f"{base}_turntables.png",
                                          labels=names[:k], title=f"{section.run}: turntables"),
            "interpolation": save_interpolation(model, j.latents[0], j.latents[1], f"{base}_interpolation.png",
                                                title=f"{section.run}: sample_000 to sample_001, "
                                                      f"G(slerp(z0, z1; t))")[0]}
    photos = [M.display_image(x) for x in section.data.held_out[:k]]
    renders = [M.display_image(x) for x in j.views[:k]]
    width = max(len(photos), len(renders))
    blank = np.ones_like(renders[0])
    figs["photos"] = save_sheet(f"{base}_photos_and_samples.png",
                                [photos + [blank] * (width - len(photos)), renders + [blank] * (width - len(renders))],
                                row_labels=["held-out images", "samples at random p_view views (the run's renderer)"],
                                title=f"{section.run}: what the critic compares")
    if j.truth is not None:
        view = from_angles(GRID_VIEW[0], GRID_VIEW[1])[None]
        formation = model.formation
        rows, tags = [], []
        for i in range(k):
            t = section.data.truths[j.truth["nearest"][i]]
            truth = t if formation == "ea" else t[3:]
            rows.append([display_frames(j.volumes[i], formation, view)[0], display_frames(truth, formation, view)[0]])
            tags.append([names[i], f"nearest truth #{j.truth['nearest'][i]}, IoU {j.truth['nearest_iou'][i]:.2f}"])
        figs["nearest"] = save_sheet(f"{base}_nearest_truth.png", rows, tile_labels=tags,
                                     title=f"{section.run}: samples beside their nearest truth (in its own frame and scale)")
    return figs


def section_lines(section: GenerationSection, out: PathLike) -> List[str]:
    """Write the section's figures under ``out/figures`` and return its Markdown lines."""
    j = section.judgement
    section.figures = _figures(section, Path(out))
    st = section.settings
    lines = [f"## Generation: {section.run}", "",
             f"{j.samples} samples G(z), z ~ N(0, I) drawn with seed {section.seed} (`platonic generate --seed "
             f"{section.seed}` draws the same), rendered with the run's renderer ({st.backend}, {st.model.upper()}) "
             f"in G's frame, against the {len(section.data.held_out)} held-out images of {section.data.source}.", ""]
    if j.warnings:
        lines += [f"**{w}.**" for w in j.warnings] + [""]
    if j.c2st is not None:
        lines += [f"Two-sample critic: fresh critics (seeded, {section.judge_steps} steps, {section.repeats} critics "
                  f"averaged; the judge's budget is {CRITIC_STEPS} and {CRITIC_REPEATS}) learn to tell the run's "
                  f"training images from renders of other samples at {TRAIN_VIEWS} random views each, drawn from the "
                  "run's p_view; then tell the held-out images from these samples' renders: at random p_view views, "
                  "and on a turntable at each sample's own p_view elevation, by band of azimuth from G's +z axis (no "
                  "input view in a generation run). Accuracy 0.5: the renders pass for photos; 1: they never do. AUC "
                  "in brackets.", "", _critic_table(j), ""]
        if j.c2st["photo_pass"] < 0.5:
            lines += [f"- The critic calls {100 * j.c2st['photo_pass']:.0f} % of the held-out images photos: it has "
                      "learnt its training images rather than the class (docs/evaluation.md, \"When the critic "
                      "memorises\").", ""]
    lines += [f"Diversity: mean pairwise 1 − IoU of the samples' occupancies (density ≥ ½, G's frame) and of their "
              f"renders' silhouettes from 4 shared views; the held-out images' own for reference. Below {COLLAPSE:g} "
              f"the samples are named collapsed. Roughness: mean |Laplacian| of the display image on the object, "
              f"the renders at random views against the held-out images (> 1: speckle or stripes the photos do "
              f"not have).", "", _variety_table(j), ""]
    if j.truth is not None:
        lines += [f"Against the ground truth of {len(section.data.truths)} held-out object(s) ({section.data.truth_source}): "
                  f"each volume's occupancy centred on its vertical axis, scaled to fill {FILL:g} of the cube by its "
                  f"half-height or horizontal radius, on a {EVAL_RESOLUTION}³ grid; a sample and a truth are as "
                  f"similar as their best IoU over {TURNS} turns about the vertical. Coverage: the share of truth "
                  f"volumes that are some sample's nearest (GET3D, PointFlow; it grows with the samples' count).", "",
                  _truth_table(j), ""]
    f = section.figures
    lines += [f"![{section.run}: samples](figures/{f['samples'].name})", "",
              f"![{section.run}: turntables](figures/{f['turntables'].name})", "",
              f"![{section.run}: interpolation](figures/{f['interpolation'].name})", "",
              f"![{section.run}: held-out images and samples](figures/{f['photos'].name})", ""]
    if "nearest" in f:
        lines += [f"![{section.run}: nearest truth](figures/{f['nearest'].name})", ""]
    return lines


def section_results(section: GenerationSection) -> Dict[str, Any]:
    """The ``results.json`` entry of a generation run (``section: "generation"``)."""
    j = section.judgement
    entry: Dict[str, Any] = {"method": section.run, "formation": section.settings.model.upper(),
                             "section": "generation", "means": j.summary(), "warnings": j.warnings,
                             "c2st": j.c2st, "diversity": j.diversity, "roughness": j.roughness}
    if j.truth is not None:
        entry["truth"] = j.truth
    return json.loads(json.dumps(entry))                          # plain JSON types only
