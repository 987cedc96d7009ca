"""Augmentations for small photo collections: D's images (``train.d_augment``) and the photos
themselves (``train.photo_augment``).

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

**The photos themselves** (:func:`augment_photos`, ``train.photo_augment``). D's augmentation
keeps D from memorising the photos; it does nothing for E, which reads every photo of a step as
it is. With a few dozen photos E memorises them too: each training photo is reconstructed with
its own colour (CIE76 ΔE ≈ 3 at the input view on the tree photos) while a held-out photo gets a
blend of the training photos' colours (ΔE ≈ 19; docs/training.md, "The measurements"). These
transforms change a step's photos *before* E reads them, so the reconstruction target, E's input
and D's reals are the same new photo; each is a photo the class could have produced:

- ``flip``: mirrored left–right with probability ½;
- ``colour``: c ↦ clamp(M c, 0, α) on each pixel's premultiplied RGB c (α unchanged), with
  M = b · S(s) · H(h): a hue rotation H by h ~ U[−30°, 30°] about the grey axis (1, 1, 1)/√3
  (Rodrigues' formula; greys stay grey), a saturation S(s) = s I + (1 − s) 𝟙𝟙ᵀ/3 with
  s ~ U[0.7, 1.3] and a brightness b ~ U[0.8, 1.2]. M is linear, so applying it to premultiplied
  colour is applying it to the colour and premultiplying; the clamp keeps c within [0, α]. E can
  then no longer name a photo by its colour, and has to read the colour from it.
"""

from __future__ import annotations

import math
from typing import Sequence

import torch
import torch.nn.functional as F

__all__ = ["augment", "augment_photos", "colour_matrices"]


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
    """``x`` ``(B, C, H, W)`` through ``transforms`` (names from ``train.d_augment``'s list, applied in
    that order), each image with its own random draw from ``g``; differentiable in ``x``."""
    return _apply(x, transforms, g, _TRANSFORMS, "augment", "augmentation")


def _apply(x: torch.Tensor, transforms: Sequence[str], g: torch.Generator, table, caller: str,
           what: str) -> torch.Tensor:
    """``x`` through the named ``transforms`` of ``table`` (name → transform), in the table's order."""
    if x.dim() != 4:
        raise ValueError(f"{caller} needs (B, C, H, W) images, got shape {tuple(x.shape)}")
    unknown = [t for t in transforms if t not in table]
    if unknown:
        raise ValueError(f"unknown {what}(s) {unknown}; expected some of {list(table)}")
    for name, transform in table.items():
        if name in transforms:
            x = transform(x, g)
    return x


#: The ranges of the ``colour`` transform: hue angle (degrees), saturation and brightness factors.
HUE_DEGREES, SATURATION, BRIGHTNESS = 30.0, (0.7, 1.3), (0.8, 1.2)


def colour_matrices(h: torch.Tensor, s: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(B, 3, 3)`` matrices M = b · S(s) · H(h) (module docstring) for hue angles ``h`` (radians),
    saturations ``s`` and brightnesses ``b``, each ``(B,)``."""
    k = torch.full((3,), 3.0 ** -0.5, dtype=h.dtype)                     # the grey axis
    K = torch.tensor([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]], dtype=h.dtype)
    eye, grey = torch.eye(3, dtype=h.dtype), torch.full((3, 3), 1.0 / 3.0, dtype=h.dtype)
    c, sn = h.cos()[:, None, None], h.sin()[:, None, None]
    H = eye + sn * K + (1.0 - c) * (K @ K)                                # Rodrigues: rotation about k
    S = s[:, None, None] * eye + (1.0 - s[:, None, None]) * grey
    return b[:, None, None] * (S @ H)


def _colour(x: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    n = len(x)
    h = (torch.rand(n, generator=g, dtype=torch.float64) * 2.0 - 1.0) * math.radians(HUE_DEGREES)
    s = SATURATION[0] + torch.rand(n, generator=g, dtype=torch.float64) * (SATURATION[1] - SATURATION[0])
    b = BRIGHTNESS[0] + torch.rand(n, generator=g, dtype=torch.float64) * (BRIGHTNESS[1] - BRIGHTNESS[0])
    M = colour_matrices(h, s, b).to(x.dtype).to(x.device)
    rgb, α = x[:, :3], x[:, 3:]
    rgb = torch.einsum("bij,bjhw->bihw", M, rgb)
    return torch.cat([torch.minimum(rgb.clamp_min(0.0), α), α], dim=1)  # premultiplied: 0 ≤ c ≤ α


_PHOTO_TRANSFORMS = {"flip": _flip, "colour": _colour}


def augment_photos(x: torch.Tensor, transforms: Sequence[str], g: torch.Generator) -> torch.Tensor:
    """A step's photos ``(B, C, H, W)`` (premultiplied RGBA for ``colour``) through ``transforms``
    (names from ``train.photo_augment``'s list, applied in that order), each photo with its own draw from ``g``."""
    if "colour" in transforms and x.dim() == 4 and x.shape[1] != 4:
        raise ValueError(f"the 'colour' photo augmentation needs RGBA photos, got {x.shape[1]} channel(s)")
    return _apply(x, transforms, g, _PHOTO_TRANSFORMS, "augment_photos", "photo augmentation")
