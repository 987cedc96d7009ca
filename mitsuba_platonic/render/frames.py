"""Turntable frames of a volume and looping GIFs of them: what training's samples and the exports show.

:func:`display_frames` renders a ``(C, N, N, N)`` volume in closed form from given views and
composites it over a background as sRGB images; :func:`turntable_frames` does so around +y;
:func:`save_gif` writes frames as a GIF. The renderer's own pictures of a volume, below both training
(its sample turntables) and :mod:`mitsuba_platonic.export` (which names them too).
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Sequence, Union

import numpy as np
import torch
from PIL import Image

from ..files.fileio import atomic_write, make_folder
from ..images import composite, linear_to_srgb, to_hwc
from ..views import turntable
from . import render

__all__ = ["display_frames", "turntable_frames", "save_gif"]

PathLike = Union[str, Path]


def display_frames(volume: torch.Tensor, model: str, views: torch.Tensor, filter: str = "trilinear",
                   background: float = 1.0) -> List[np.ndarray]:
    """Closed-form renders of ``(C, N, N, N)`` from ``views`` → sRGB ``(H, W, 3)`` images over ``background``."""
    n = len(views)
    with torch.no_grad():
        images = render(volume.detach().float().cpu()[None].expand(n, -1, -1, -1, -1).contiguous(),
                        views, model, "closed_form", filter=filter)
    return [linear_to_srgb(composite(to_hwc(i), background=background)) for i in images]


def turntable_frames(volume: torch.Tensor, model: str, frames: int = 36, elevation: float = 20.0,
                     background: float = 1.0) -> List[np.ndarray]:
    """:func:`display_frames` from ``frames`` azimuths around +y at ``elevation`` degrees."""
    return display_frames(volume, model, turntable(frames, elevation=elevation), background=background)


def save_gif(frames: Sequence[np.ndarray], path: PathLike, scale: int = 4, duration_ms: int = 60) -> Path:
    """Frames (float sRGB in [0, 1]) → an endlessly looping GIF, upscaled ``scale``× (nearest)."""
    path = Path(path)
    make_folder(path.parent)
    pil = [Image.fromarray((np.clip(f, 0, 1) * 255 + 0.5).astype(np.uint8)) for f in frames]
    pil = [p.resize((p.width * scale, p.height * scale), Image.NEAREST) for p in pil]
    atomic_write(path, lambda tmp: pil[0].save(tmp, format="GIF", save_all=True, append_images=pil[1:],
                                               duration=duration_ms, loop=0))
    return path
