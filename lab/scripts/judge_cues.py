"""Benchmark: what tells the judge's critic a photo run's side views from photos? Shape or texture?

    .venv/bin/python lab/scripts/judge_cues.py RUN [RUN ...] [--axis object|camera] [--figure F.png] [--data-path DIR]

For each photo run (a ``platonic train`` folder on a photo collection) the judge's critics
(``evaluate/judge.py``: its number of critics, seeds 0, 1, …, its budget) are trained as ``platonic
evaluate`` trains them, on the run's training photos against renders of their reconstructions at
random turntable azimuths (each critic its own), and then shown probes made from the held-out photos' reconstructions:

- the held-out photos, their input-view renders, their side renders (φ = ±90°), 45° and 180°;
- each with a flat colour (every pixel the image's mean colour, its own alpha): is it the texture?
- each with a hard silhouette (alpha thresholded at ½, colour unpremultiplied on it);
- the input view's texture (colour / α) on the side view's silhouette, and the side view's
  texture on the input view's silhouette: which of the two carries the verdict?

It prints, per probe, the share the critics call photos (f > 0) and their mean logit, and with
``--figure`` saves the side renders beside the critics' mean |∂f/∂α| and |∂f/∂rgb| over them
(where the critic looks). ``--axis camera`` turns the turntable about the input camera's vertical
axis (the judge before it turned about the object's: docs/evaluation.md, "The turntable's axis"),
``object`` (the default) about the object's, as the judge does now. Figures only.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Dict

import numpy as np
import torch

from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.evaluate import judge as J
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.model import Model


def flat(x: torch.Tensor) -> torch.Tensor:
    """Premultiplied RGBA images with every pixel's colour the image's mean colour (own alpha kept)."""
    a = x[:, 3:]
    m = x[:, :3].sum((2, 3)) / a.sum((2, 3)).clamp_min(1e-6)
    return torch.cat([a * m[:, :, None, None], a], 1)


def own_colour(x: torch.Tensor) -> torch.Tensor:
    """Each pixel's own colour rgb / α where α > 0.05, the image's mean colour elsewhere."""
    a = x[:, 3:]
    m = x[:, :3].sum((2, 3), keepdim=True) / a.sum((2, 3), keepdim=True).clamp_min(1e-6)
    return torch.where(a > 0.05, x[:, :3] / a.clamp_min(0.05), m)


def texture_on(texture: torch.Tensor, silhouette: torch.Tensor) -> torch.Tensor:
    """``texture``'s own colours on ``silhouette``'s alpha."""
    return torch.cat([own_colour(texture) * silhouette[:, 3:], silhouette[:, 3:]], 1)


def hard(x: torch.Tensor) -> torch.Tensor:
    """The silhouette made binary (α > ½), the pixels' own colours on it."""
    a = (x[:, 3:] > 0.5).float()
    return torch.cat([own_colour(x) * a, a], 1)


def probes(model: Model, train: torch.Tensor, test: torch.Tensor, settings, axis: str):
    """(the critics' training renders, {probe name: images}, the side renders)."""
    def answer(x: torch.Tensor):
        return model.reconstruct_upright(x) if axis == "object" else model.reconstruct(x)

    vt, θt = J.volumes_and_elevations(answer(train), len(train), "train")
    vs, θs = J.volumes_and_elevations(answer(test), len(test), "test")
    renders = [J.random_renders(vt, θt, J.TRAIN_VIEWS, settings, r) for r in range(J.CRITIC_REPEATS)]
    tt = J.turntable_renders(vs, θs, [0.0, 45.0, 90.0, -90.0, 180.0], settings, 0)
    front, side = tt[0], torch.cat([tt[2], tt[3]])
    fronts = torch.cat([front, front])
    out = {"held-out photos": test, "photos, flat colour": flat(test), "photos, hard silhouette": hard(test),
           "input view": front, "input view, flat colour": flat(front), "input view, hard silhouette": hard(front),
           "side (±90°)": side, "side, flat colour": flat(side), "side, hard silhouette": hard(side),
           "input view's texture on the side's silhouette": texture_on(fronts, side),
           "side's texture on the input view's silhouette": texture_on(side, fronts),
           "45°": tt[1], "180°": tt[4]}
    return renders, out, side


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--axis", choices=("object", "camera"), default="object")
    ap.add_argument("--figure", type=Path, default=None, help="a PNG of the side renders and the critics' gradients")
    ap.add_argument("--data-path", default=None)
    args = ap.parse_args()
    for run in args.runs:
        ckpt = read_checkpoint(run)
        cfg = checkpoint_config(ckpt)
        model = model_from_checkpoint(Model, ckpt, cfg)
        train, test, _ = photo_splits(cfg, args.data_path)
        renders, shown, side = probes(model, train, test, cfg.render, args.axis)
        rows: Dict[str, list] = {k: [] for k in shown}
        grad = torch.zeros(side.shape[1:])
        for seed in range(J.CRITIC_REPEATS):
            critic = J.train_critic(train, renders[seed], seed, J.CRITIC_STEPS, 32)   # its own views, as the judge
            with torch.no_grad():
                for k, x in shown.items():
                    f = critic(x)
                    rows[k].append((float((f > 0).float().mean()), float(f.mean())))
            x = side.clone().requires_grad_(True)
            critic(x).sum().backward()
            grad += x.grad.abs().mean(0) / J.CRITIC_REPEATS
        print(f"\n{run.name} (step {ckpt.step}), turntable about the {args.axis}'s vertical axis, "
              f"{J.CRITIC_REPEATS} critics\n\n| probe | called photos | mean logit |\n|---|---|---|")
        for k, v in rows.items():
            v = np.array(v)
            print(f"| {k} | {v[:, 0].mean():.2f} | {v[:, 1].mean():+.2f} |")
        if args.figure is not None:
            save_figure(args.figure.with_name(f"{args.figure.stem}_{run.name}{args.figure.suffix}"), side, grad, test)


def save_figure(path: Path, side: torch.Tensor, grad: torch.Tensor, photos: torch.Tensor) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    over_white = (lambda x: (x[:3] + (1 - x[3:])).permute(1, 2, 0).clamp(0, 1).numpy())
    n = min(6, len(side))
    fig, ax = plt.subplots(2, n, figsize=(2 * n, 4.3), squeeze=False)
    for i in range(n):
        ax[0, i].imshow(over_white(side[i]))
    ax[1, 0].imshow(grad[3].numpy()); ax[1, 0].set_title("mean |∂f/∂α|", fontsize=8)
    ax[1, 1].imshow(grad[:3].sum(0).numpy()); ax[1, 1].set_title("mean |∂f/∂rgb|", fontsize=8)
    for i in range(2, n):
        ax[1, i].imshow(over_white(photos[(i - 2) % len(photos)]))
    for a in ax.flat:
        a.set_xticks([]); a.set_yticks([])
    ax[0, 0].set_title("side renders (±90°)", fontsize=8, loc="left")
    ax[1, 2].set_title("held-out photos", fontsize=8, loc="left")
    plt.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    plt.savefig(path, dpi=80)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
