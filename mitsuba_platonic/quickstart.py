"""``platonic quickstart``: the whole pipeline in minutes on a CPU.

1. render a small procedural collection (``configs/quickstart.yaml``: 32³, EA);
2. train single-image reconstruction through the batched Mitsuba ray marcher (EA);
3. reconstruct held-out images (shapes the run never saw), write volumes, turntable GIFs and
   meshes, and a report comparing each reconstruction with the ground truth at the input view
   *and at novel views* (where a model that learnt only the input view fails).

Novel-view scoring. A reconstruction lives in its input camera's frame (the input view is ω₀).
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
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch

from .config import load_config
from .export import export_volume
from .images import composite, linear_to_srgb, save_png, to_hwc
from .model import Model
from .render import render
from .render.closed_form import rotate
from .views import from_angles, front_view, turntable
from .volume import CHANNELS

__all__ = ["quickstart", "novel_view_errors", "billboard", "NOVEL_VIEWS"]

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "quickstart.yaml"

_BACKEND_NAMES = {"closed_form": "closed-form layer", "mitsuba": "Mitsuba ray marcher",
                  "physical": "Mitsuba path tracer"}

#: Novel views in the reconstruction's frame: a ring at 30° elevation (the input view excluded) and the back.
NOVEL_VIEWS = torch.cat([turntable(6, elevation=30.0, start=60.0), from_angles(180.0, 0.0)[None]])


def billboard(image: torch.Tensor) -> torch.Tensor:
    """The input image extruded through the cube: ``(4, R, R)`` → ``(4, R, R, R)`` (EA).

    Each of the R depth samples gets opacity a = 1 − (1 − α)^{1/R} and colour rgb/α, so the
    front view reproduces the image exactly (Π(1 − a) = 1 − α, Σ T a c = rgb).
    """
    r = image.shape[-1]
    alpha = image[3:].clamp(0.0, 1.0)
    a = 1.0 - (1.0 - alpha.clamp(max=1.0 - 1e-6)) ** (1.0 / r)
    colour = torch.where(alpha > 1e-6, image[:3] / alpha.clamp_min(1e-6), torch.zeros_like(image[:3]))
    return torch.cat([colour, a]).clamp(0, 1)[:, None].expand(-1, r, -1, -1).contiguous()


def silhouette_iou(a: torch.Tensor, b: torch.Tensor) -> float:
    """Mean IoU of the silhouettes (alpha > ½, the last channel) of two image batches ``(B, C, H, W)``.

    An image pair where both silhouettes are empty counts as 1.
    """
    sa, sb = a[:, -1] > 0.5, b[:, -1] > 0.5
    inter = (sa & sb).flatten(1).sum(1).float()
    union = (sa | sb).flatten(1).sum(1).float()
    return float(torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union)).mean())


def novel_view_errors(recon: torch.Tensor, truth_in_frame: torch.Tensor, model: str) -> Tuple[float, float]:
    """(MAE, silhouette IoU) between renders of two ``(C, N, N, N)`` volumes over :data:`NOVEL_VIEWS`."""
    n = len(NOVEL_VIEWS)
    with torch.no_grad():
        a = render(recon[None].expand(n, -1, -1, -1, -1).contiguous(), NOVEL_VIEWS, model)
        b = render(truth_in_frame[None].expand(n, -1, -1, -1, -1).contiguous(), NOVEL_VIEWS, model)
    return float((a - b).abs().mean()), silhouette_iou(a, b)


def _evaluate(net: Model, data, model: Optional[str] = None, limit: int = 64) -> Dict[str, float]:
    """Input-view and novel-view errors of a :class:`~mitsuba_platonic.model.Model` on held-out
    images (and of the billboard), rendered with image formation ``model`` (default: the model's).

    ``net`` may also be a trainer, whose ``model`` is scored (benchmarks/train_defaults.py passes one).
    """
    net = getattr(net, "model", net)
    model = model or net.formation
    records = data.held_out_records[:limit]
    images = data.held_out[:limit]
    recon = net.reconstruct(images).cpu()
    front = front_view(len(images))
    with torch.no_grad():
        rendered = render(recon, front, model)
    truths = []
    for r in records:
        vol = torch.from_numpy(np.load(Path(r["folder"]) / r["volume"])["volume"]).float()
        if CHANNELS[model] == 1:
            vol = vol[3:]
        # the ground truth resampled into the input camera frame (clamped: trilinear round-off exceeds 1)
        truths.append(rotate(vol[None], torch.tensor([r["view"]]))[0].clamp(0.0, 1.0))
    novel = np.array([novel_view_errors(v, t, model) for v, t in zip(recon, truths)])
    out = {"input_view_mae": float((rendered - images).abs().mean()), "input_view_iou": silhouette_iou(rendered, images),
           "novel_view_mae": float(novel[:, 0].mean()), "novel_view_iou": float(novel[:, 1].mean())}
    if model == "ea":
        boards = torch.stack([billboard(x) for x in images])
        with torch.no_grad():
            board_front = render(boards, front, model)
        out["billboard_input_view_mae"] = float((board_front - images).abs().mean())
        out["billboard_input_view_iou"] = silhouette_iou(board_front, images)
        bb = np.array([novel_view_errors(b, t, model) for b, t in zip(boards, truths)])
        out["billboard_novel_view_mae"], out["billboard_novel_view_iou"] = float(bb[:, 0].mean()), float(bb[:, 1].mean())
    return out


def quickstart(out: Path = Path("quickstart"), steps: Optional[int] = None, progress: bool = True) -> Path:
    """Run the quickstart into ``out``; return the path of its report."""
    from .train.data import load_training_data
    from .train.run import train

    t0 = time.perf_counter()
    overrides = [f"run.out_dir={out}", f"data.cache={out / 'data'}"]
    if steps is not None:
        overrides.append(f"run.steps={steps}")
    cfg = load_config(CONFIG, overrides)
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    resume = (run_dir / "checkpoints" / "last.pt").exists()
    data = load_training_data(cfg, progress=progress)
    t_data = time.perf_counter() - t0
    torch.manual_seed(cfg.run.seed)
    untrained = _evaluate(Model.from_config(cfg), data)          # a fresh model, drawn from the run's seed
    train(cfg, resume=resume, progress=progress)
    t_train = time.perf_counter() - t0 - t_data
    model = Model.from_checkpoint(run_dir)
    step = model.step
    trained = _evaluate(model, data)

    recon_dir = out / "reconstructions"
    written: List[str] = []
    picks = torch.linspace(0, len(data.held_out) - 1, min(4, len(data.held_out))).long().tolist()
    for i, j in enumerate(picks):                       # spread over the held-out set: different shapes
        stem = recon_dir / f"heldout_{i}"
        done = export_volume(model.reconstruct(data.held_out[j:j + 1])[0], stem, model.formation)
        written += [str(p) for p in done.paths if p.suffix in (".gif", ".ply")]
        save_png(stem.with_name(stem.name + "_input.png"), linear_to_srgb(composite(to_hwc(data.held_out[j]), 1.0)))

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
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report
