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

``matched``: turn the *reals* only, by the tilt a right reconstruction's view would have, and keep
"up". In the input frame the world's up is u = (0, cos θ₀, sin θ₀) (the input camera's right is
horizontal). A camera at ω, upright in that frame, with right r and up t (``views.camera_frames``),
sees u at the angle α = atan2(u·r, u·t) from its image's up towards its right, so its image is the
world's upright photo from the same direction turned counter-clockwise by

    ψ(θ₀, ω) = −atan2(u·r, u·t)          (beside the input, ω = ±x: ψ = ±θ₀; front and back: 0)

(:func:`input_frame_roll`). With θ₀ drawn from the photos' view distribution (the collection's,
``data.view_distribution`` and ``data.elevation``, for a procedural one; for photo folders, whose
poses nobody knows, the assumed p_view, ``train.view_distribution`` and ``train.elevation``) and ω
the slot's random view, each real is turned by ψ(θ₀, ω): the reals' tilts are then distributed as
the fakes' are when G's volume is the right one, tilted by the input's elevation in its frame; a
volume kept upright in the frame, whose fakes are never tilted, is what D can now tell apart.
Unlike 'uniform', the turns are those a right volume's views have, not arbitrary ones, so D keeps
"which way is up" where that tells anything: 0 in front and behind, ±θ₀ beside, atan(0.6 tan θ₀)
at ω = (0.6, 0, 0.8); views above or below the input turn further, up to ±π at the frame's
poles, where a right volume's view is upside down too.
What it cannot match: a fake's tilt also goes with the elevation it shows the object from, a real's
is drawn independently of its (unknown) pose; and only the reals are resampled, so they are
slightly smoother than the fakes (bilinear) and lose the corners that turn out of the square.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..views import camera_frames, validate_views

__all__ = ["roll", "input_frame_roll"]


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


def input_frame_roll(views: torch.Tensor, elevation: torch.Tensor) -> torch.Tensor:
    """ψ(θ₀, ω) (module docstring), radians ``(B,)``: the counter-clockwise turn that takes the
    world's upright photo from the world direction that ω names to the image of a camera at ω
    upright in the frame of an input camera at elevation θ₀ (``elevation``, degrees, ``(B,)``);
    ``views`` ``(B, 3)``, given in that frame."""
    if not (isinstance(views, torch.Tensor) and isinstance(elevation, torch.Tensor)) or views.dim() != 2 \
            or views.shape[1] != 3 or elevation.shape != views.shape[:1]:
        raise ValueError(f"input_frame_roll expects tensors: views (B, 3) and elevations (B,), got "
                         f"{tuple(getattr(views, 'shape', ()))} and {tuple(getattr(elevation, 'shape', ()))}")
    validate_views(views)                                    # finite, non-zero directions
    right, up, _ = camera_frames(views)
    θ0 = torch.deg2rad(elevation.to(views.device, torch.float64))
    u = torch.stack([torch.zeros_like(θ0), torch.cos(θ0), torch.sin(θ0)], dim=-1)   # world up, input frame
    return -torch.atan2((u * right).sum(-1), (u * up).sum(-1)).to(torch.float32)
