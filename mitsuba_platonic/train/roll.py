"""In-plane rotation of the images D judges (``train.d_roll``).

Why. For reconstruction, G's volume lives in the input camera's frame, and the random views ω
are drawn in that frame, with cameras upright in it (up = the frame's +y). The input camera
itself was upright in the *world* (docs/conventions.md, "Views"), but looked along ω₀ at some
elevation θ₀, so the frame's +y is the world's up tilted by θ₀. A random view's camera is
therefore rolled against the world's upright camera at the same direction: from ω = (±1, 0, 0)
(beside the input) by exactly ±θ₀, from the front and the back by 0. The photos D compares with
were all taken upright, so wherever θ₀ ≠ 0 (the 'sphere' and 'band' collections) D can tell a
fake by its tilt alone, however right its shape, and G cannot undo a tilt it does not control.

The fix: D sees every real and every fake image turned about the image centre by its own
angle ψ ~ U[0, 2π). A fake from direction d with roll ψ_f then looks like a real from d with roll
ψ_f + ψ, which is uniform again: turned this way, fakes and reals have the same distribution of
rolls (uniform, independent of the view), so the tilt tells D nothing and the shape is all that is
left to judge. D then cannot use which way is up either: that is the price.

The rotation, for image coordinates (x, y) ∈ [−1, 1]² (x right, y up; docs/conventions.md, "Images"):
the output pixel at (x, y) reads the input at R(−ψ) (x, y) with bilinear interpolation and
zeros outside (a rotation by ψ counter-clockwise). Corners that turn out of the square are lost
for reals and fakes alike; a centred object within the inscribed circle keeps every pixel.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["roll", "ROLLS"]

#: train.d_roll: 'none' (D sees the images as rendered) | 'uniform' (module docstring).
ROLLS = ("none", "uniform")


def roll(images: torch.Tensor, angles: torch.Tensor) -> torch.Tensor:
    """``(B, C, H, W)`` images turned counter-clockwise by ``angles`` (B,) radians about their
    centres (bilinear, zeros outside); differentiable w.r.t. ``images``."""
    if images.dim() != 4 or angles.shape != images.shape[:1]:
        raise ValueError(f"roll expects images (B, C, H, W) and angles (B,), got {tuple(images.shape)} "
                         f"and {tuple(angles.shape)}")
    c, s = torch.cos(angles), torch.sin(angles)
    # affine_grid's y points down the rows (y_down = −y): R(−ψ) (x, y) in those coordinates is
    # (x cos ψ − y_down sin ψ, x sin ψ + y_down cos ψ)
    zero = torch.zeros_like(c)
    theta = torch.stack([torch.stack([c, -s, zero], dim=1), torch.stack([s, c, zero], dim=1)], dim=1)
    grid = F.affine_grid(theta.to(images), list(images.shape), align_corners=False)
    return F.grid_sample(images, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
