"""Torch volumes as Mitsuba grids: the layout and the path tracer's extinction.

The lowest module of the Mitsuba side: the ray marcher, the path tracer and the scene files'
grids (:func:`~mitsuba_platonic.render.mitsuba.scenes.write_scene_grids`) convert volumes here, and it
imports nothing of theirs.

Grid layout (docs/rendering.md, "The Mitsuba side"): a torch ``(C, D, H, W)`` volume becomes a
Mitsuba ``[Z, Y, X, C]`` grid by a permute and two flips (Z = N−1−d, Y = N−1−h, X = w):
:func:`~mitsuba_platonic.files.volume_io.to_mitsuba_grid`, defined with the ``.vol`` files that store
it (:mod:`mitsuba_platonic.files.volume_io`, which writes them) and named here for the renderers.
"""

from __future__ import annotations

import torch

from ..files.volume_io import to_mitsuba_grid
from ..volume import voxel_size

__all__ = ["to_mitsuba_grid", "extinction", "V_MAX_PHYSICAL"]

#: Density cap of the physically based medium (σ_t Δ ≤ ln 1000).
V_MAX_PHYSICAL = 1.0 - 1e-3


def extinction(density: torch.Tensor) -> torch.Tensor:
    """σ_t = −ln(1 − min(v, v_max)) / Δ of a density volume ``(…, N, N, N)`` (differentiable)."""
    return -torch.log1p(-density.clamp(0.0, V_MAX_PHYSICAL)) / voxel_size(density.shape[-1])
