"""Differentiable augmentation of D's images (``train.d_augment``), for small photo collections.

A critic that sees the same few dozen photos for thousands of steps memorises them: it tells
reals from fakes by the photos' exact pixels, not by what an object of the class looks like, and
the gradient it hands G through the renderer is then noise (speckle, drifted colour). Zhao et
al. ("Differentiable Augmentation for Data-Efficient GAN Training", NeurIPS 2020) showed the cure:
every image D sees, real or fake, in D's update and in G's, goes through the same random
transform T, differentiable for the fakes, so D learns the distribution of T(x) and G still
learns to match x itself (T is applied to both sides, so nothing of T leaks into G's images).

Transforms, each drawn per image from the step's generator (a resumed run draws the same), for
``(B, C, H, W)`` premultiplied RGBA or opacity images, in which 0 is empty space:

- ``flip``: mirrored left–right with probability ½ (a mirrored photo is still a photo);
- ``translation``: shifted by (Δx, Δy), each uniform in {−s, …, s} with s = round(H / 8), the
  uncovered border filled with 0 (empty space, not a wrapped-around object);
- ``cutout``: a square of side H / 2 at a uniformly random centre set to 0 (D must judge the
  object from its parts).

Every transform is an index gather or a mask product, so ∂T(x)/∂x is exact.
"""

from __future__ import annotations

from typing import Sequence

import torch
import torch.nn.functional as F

__all__ = ["AUGMENTS", "augment"]

#: The transforms ``train.d_augment`` may list, applied in this order.
AUGMENTS = ("flip", "translation", "cutout")


def _flip(x: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    mirror = (torch.rand(len(x), generator=g) < 0.5).to(x.device)
    return torch.where(mirror[:, None, None, None], x.flip(-1), x)


def _translation(x: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    b, _, h, w = x.shape
    s = max(1, round(h / 8))
    dy, dx = (torch.randint(-s, s + 1, (2, b), generator=g)).to(x.device)
    padded = F.pad(x, (s, s, s, s))                               # zeros: empty space around the image
    rows = torch.arange(h, device=x.device)[None] + s - dy[:, None]        # (B, H): source row of each row
    cols = torch.arange(w, device=x.device)[None] + s - dx[:, None]        # (B, W)
    out = padded[torch.arange(b, device=x.device)[:, None, None], :, rows[:, :, None], cols[:, None, :]]
    return out.permute(0, 3, 1, 2)                                # advanced indexing put C last


def _cutout(x: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    b, _, h, w = x.shape
    cy = torch.randint(h, (b,), generator=g).to(x.device)
    cx = torch.randint(w, (b,), generator=g).to(x.device)
    ys = torch.arange(h, device=x.device)[None]
    xs = torch.arange(w, device=x.device)[None]
    inside_y = (ys - cy[:, None]).abs() < h // 4                  # a square of side H/2 (|Δ| < H/4)
    inside_x = (xs - cx[:, None]).abs() < w // 4
    keep = ~(inside_y[:, :, None] & inside_x[:, None, :])
    return x * keep[:, None].to(x.dtype)


_TRANSFORMS = {"flip": _flip, "translation": _translation, "cutout": _cutout}


def augment(x: torch.Tensor, transforms: Sequence[str], g: torch.Generator) -> torch.Tensor:
    """``x`` ``(B, C, H, W)`` through ``transforms`` (names from :data:`AUGMENTS`, applied in that
    order), each image with its own random draw from ``g``; differentiable in ``x``."""
    if x.dim() != 4:
        raise ValueError(f"augment needs (B, C, H, W) images, got shape {tuple(x.shape)}")
    unknown = [t for t in transforms if t not in _TRANSFORMS]
    if unknown:
        raise ValueError(f"unknown augmentation(s) {unknown}; expected some of {list(AUGMENTS)}")
    for name in AUGMENTS:
        if name in transforms:
            x = _TRANSFORMS[name](x, g)
    return x
