"""Experiment script: where the far side's colour of a ``model.texture_turns: 4`` photo run comes from.

    .venv/bin/python docs/experiments/scripts/behind_colour.py RUN [--step N]

``RUN`` is a folder photo run trained with ``model.texture_turns: 4`` (``benchmarks/photo_suite.py``
makes them under ``OUT/runs``). Its held-out photos are reconstructed with the trained weights and
the density G made, coloured three ways, and each judged as the suite judges a run
(``evaluate/judge.judge``, seed 0):

- ``model``: the run's own colour, σ(ℓ' + logit t), ℓ' G's offsets with the convolution's;
- ``texture``: the texture as read, t = T_front t_carried + (1 − T_front) t_turned, no offsets;
- ``seen offsets``: σ(T_front ℓ' + logit t), G's offsets only where the input camera sees.

Prints one row per colouring: the critic's accuracy by band, the side roughness and ΔE at the side
and the back. Figures only; docs/experiments/photo-sides.md reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable, Tuple

import torch
from torch import nn

from mitsuba_platonic.config import load_config
from mitsuba_platonic.evaluate.judge import judge
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.model import Model
from mitsuba_platonic.networks.photo_colours import photo_texture, texture_corrected

KEYS = [("c2st_near", "acc. near", 3), ("c2st_side", "acc. side", 3), ("c2st_back", "acc. back", 3),
        ("roughness_side", "rough. side", 2), ("delta_e_side", "ΔE side", 1), ("delta_e_back", "ΔE back", 1)]


def coloured(model: Model, kind: str) -> Callable[[torch.Tensor], Tuple[torch.Tensor, torch.Tensor]]:
    """A reconstruct function for the judge: upright volumes of ``model`` coloured by ``kind``, and θ̂ in
    degrees. Both kinds go through the recipe's own :func:`texture_corrected`: ``seen offsets`` with
    ``offsets_behind=False``, ``texture`` with zero offsets and a zero convolution (colour σ(logit t) = t);
    the density is the model's in every kind."""
    conv = model.G.texture_conv
    if kind == "texture":
        conv = nn.Conv3d(conv.in_channels, conv.out_channels, 3, padding=1)
        nn.init.zeros_(conv.weight)
        nn.init.zeros_(conv.bias)

    def reconstruct(x: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        with torch.no_grad():
            z = model.E(x)
            θ = model.P(z)
            t = photo_texture(x, model.net.resolution, θ)
            behind = photo_texture(x, model.net.resolution, θ, 4)
            v, ℓ = model.G(model.code(z), t, offsets=True)
            density = texture_corrected(model.G.texture_conv, v, ℓ, t, θ, behind)[0][:, 3:]
            if kind == "texture":
                colour = texture_corrected(conv.to(v), v, torch.zeros_like(ℓ), t, θ, behind)[0][:, :3]
            else:
                colour = texture_corrected(conv, v, ℓ, t, θ, behind, offsets_behind=False)[0][:, :3]
        return torch.cat([colour, density], 1), torch.rad2deg(θ)
    return reconstruct


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--step", type=int, default=None, help="the checkpoint's step (default: the latest)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    steps = sorted((args.run / "checkpoints").glob("step_*.pt"))
    ckpt = args.run / "checkpoints" / f"step_{args.step:07d}.pt" if args.step else (steps[-1] if steps else None)
    if ckpt is None or not ckpt.is_file():
        raise SystemExit(f"{args.run}: no checkpoint {ckpt or 'step_*.pt'}")
    model = Model.from_checkpoint(ckpt)
    if model.net.texture_turns != 4 or model.P is None:
        raise SystemExit(f"{args.run}: expected a run with model.texture_turns 4 and train.pose elevation")
    cfg = load_config(args.run / "config.yaml")
    train, held, files = photo_splits(cfg)
    print("| colour of the body | " + " | ".join(h for _, h, _ in KEYS) + " |")
    print("|---" * (len(KEYS) + 1) + "|")
    for kind in ("model", "texture", "seen offsets"):
        reconstruct = model.reconstruct_upright if kind == "model" else coloured(model, kind)
        s = judge(reconstruct, train, held, cfg.render, [str(f) for f in files], seed=0).summary()
        print(f"| {kind} | " + " | ".join(f"{s[k]:.{d}f}" for k, _, d in KEYS) + " |", flush=True)


if __name__ == "__main__":
    main()
