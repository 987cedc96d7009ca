"""Torch volumes as Mitsuba grids: the layout, the path tracer's extinction and ``.vol`` files.

The lowest module of the Mitsuba side: the ray marcher, the path tracer, the scene files'
grids (:func:`~mitsuba_platonic.render.scenes.write_scene_grids`), the exports and the
collections all convert volumes here, and it imports nothing of theirs.

Grid layout (docs/rendering.md, "The Mitsuba side"): a torch ``(C, D, H, W)`` volume becomes a
Mitsuba ``[Z, Y, X, C]`` grid by a permute and two flips (Z = N−1−d, Y = N−1−h, X = w).
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

import torch

from ..volume import voxel_size
from .variant import ensure_variant

__all__ = ["to_mitsuba_grid", "extinction", "V_MAX_PHYSICAL", "write_vol"]

PathLike = Union[str, Path]

#: Density cap of the physically based medium (σ_t Δ ≤ ln 1000).
V_MAX_PHYSICAL = 1.0 - 1e-3


def to_mitsuba_grid(v: torch.Tensor) -> torch.Tensor:
    """``(C, D, H, W)`` torch volume → ``(N, N, N, C)`` Mitsuba grid ``[Z, Y, X, C]`` (one copy)."""
    return v.permute(1, 2, 3, 0).flip(0, 1)                   # [d, h, w, c] → [Z, Y, X, C]


def extinction(density: torch.Tensor) -> torch.Tensor:
    """σ_t = −ln(1 − min(v, v_max)) / Δ of a density volume ``(…, N, N, N)`` (differentiable)."""
    return -torch.log1p(-density.clamp(0.0, V_MAX_PHYSICAL)) / voxel_size(density.shape[-1])


def write_vol(volume: torch.Tensor, path: PathLike) -> Path:
    """Write a ``(C, N, N, N)`` volume in Mitsuba's ``.vol`` format (grid layout ``[Z, Y, X, C]``)."""
    mi = ensure_variant()
    grid = to_mitsuba_grid(volume.detach().float().cpu()).contiguous().numpy()
    mi.VolumeGrid(grid).write(str(path))
    return Path(path)
