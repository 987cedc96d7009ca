"""The bench's accuracy yardsticks: two extra EA layers (the PlatonicGAN authors' and a plain one)
and the measures of an image's and a gradient's error against a reference."""

from __future__ import annotations

from typing import Dict, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F

from ..views import camera_frames

__all__ = ["authors_ea", "plain_ea", "loss_weights", "image_error", "gradient_error", "AUTHORS_DEPTH_SAMPLES",
           "AUTHORS_DENSITY_FACTOR"]

#: The authors' EA layer: depth samples per ray and density factor (see :func:`authors_ea`).
AUTHORS_DEPTH_SAMPLES = 1024
AUTHORS_DENSITY_FACTOR = 100.0


# --------------------------------------------------------------------------- the two extra EA layers


def authors_ea(volume: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """The PlatonicGAN authors' EA layer (github.com/henzler/platonicgan, ``scripts/renderer``),
    re-implemented from its description, for speed and image comparisons only.

    This is *their* image formation, not this package's (docs/paper.md, "Differences"):

    1. Rotation by resampling: the camera-space grid (``linspace(−1, 1, N)`` per axis, z from the
       front +1 to −1, y from the top +1 to −1) is rotated into the world by the view matrix
       [right, up, ω] (the same camera frame as ours) and the volume is read there by
       ``grid_sample`` (trilinear, zero padding) with ``align_corners=True``: the behaviour of
       ``grid_sample`` before PyTorch 1.3, for which their code was written.
    2. The rotated volume is padded by one empty voxel on every side and resampled again at
       1,024 depth samples × N × N pixels (``linspace(−1, 1)`` grids over the padded cube, so the
       pixels frame the object slightly smaller than ours).
    3. Densities are multiplied by 100 / 1,024: a ray across the cube has an optical depth of
       about 100 v whatever N.
    4. Inclusive transmittance T_i = Π_{j≤i}(1 − a_j) (``cumprod``), weights a_i T_i, colour
       renormalised by the weight sum (+1e-8) and multiplied by α = 1 − Π(1 − a_i).

    ``volume`` ``(B, 4, N, N, N)``, ``views`` ``(B, 3)`` → ``(B, 4, N, N)`` premultiplied RGB + alpha.
    """
    b, n = volume.shape[0], volume.shape[-1]
    dtype, dev = volume.dtype, volume.device
    # 1. rotation into camera space
    right, up, w = camera_frames(views.detach().cpu())
    rot = torch.stack([right, up, w], dim=2).to(dtype=dtype, device=dev)          # (B, 3, 3), columns
    ax = torch.linspace(-1.0, 1.0, n, dtype=dtype, device=dev)
    cz, cy, cx = torch.meshgrid(ax.flip(0), ax.flip(0), ax, indexing="ij")       # graphics coordinates
    cam = torch.stack([cx, cy, cz]).reshape(1, 3, -1).expand(b, -1, -1)
    world = torch.bmm(rot, cam).transpose(1, 2).reshape(b, n, n, n, 3)
    grid = world * world.new_tensor([1.0, -1.0, -1.0])                           # grid_sample: y down, z back
    camera_volume = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=True)
    # 2. pad and resample at 1,024 depth samples per pixel
    padded = F.pad(camera_volume, (1, 1, 1, 1, 1, 1))
    zs = torch.linspace(-1.0, 1.0, AUTHORS_DEPTH_SAMPLES, dtype=dtype, device=dev)
    sz, sy, sx = torch.meshgrid(zs, ax, ax, indexing="ij")
    samples = torch.stack([sx, sy, sz], dim=-1).expand(b, -1, -1, -1, -1)
    # 3. density scale
    density = padded[:, 3:] * (AUTHORS_DENSITY_FACTOR / AUTHORS_DEPTH_SAMPLES)
    a = F.grid_sample(density, samples, mode="bilinear", padding_mode="zeros", align_corners=True)
    colour = F.grid_sample(padded[:, :3], samples, mode="bilinear", padding_mode="zeros", align_corners=True)
    # 4. inclusive transmittance, renormalised colour
    weight = a * torch.cumprod(1.0 - a, dim=2)
    rgb = (weight * colour).sum(dim=2) / (weight.sum(dim=2) + 1e-8)
    alpha = 1.0 - torch.prod(1.0 - a, dim=2)
    return torch.cat([rgb * alpha, alpha], dim=1)


def plain_ea(volume: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """A plain EA layer: ``affine_grid`` + ``grid_sample`` + ``cumprod``, no tricks (a speed yardstick).

    Our image formation and sample positions (docs/rendering.md): the affine map sends the output
    grid's normalised coordinates g to F M F g, M = [right, up, ω] (columns), F = diag(1, −1, −1)
    (grid_sample's y and z point down and back); exclusive transmittance, no renormalisation.
    """
    b = volume.shape[0]
    right, up, w = camera_frames(views.detach().cpu())
    m = torch.stack([right, up, w], dim=2)                                       # (B, 3, 3), float64
    flip = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64))
    theta = torch.cat([flip @ m @ flip, torch.zeros(b, 3, 1, dtype=torch.float64)], dim=2)
    grid = F.affine_grid(theta.to(volume.dtype).to(volume.device), list(volume.shape), align_corners=False)
    rotated = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    colour, a = rotated[:, :3], rotated[:, 3:]
    t_incl = torch.cumprod(1.0 - a, dim=2)
    t_excl = torch.cat([torch.ones_like(t_incl[:, :, :1]), t_incl[:, :, :-1]], dim=2)
    return torch.cat([(t_excl * a * colour).sum(dim=2), 1.0 - t_incl[:, :, -1]], dim=1)


# --------------------------------------------------------------------------- measuring


def loss_weights(shape: Sequence[int], seed: int) -> torch.Tensor:
    """The fixed random weights W of the loss L = Σ W ⊙ image (standard normal, seeded)."""
    g = torch.Generator().manual_seed(int(seed) + 12345)
    return torch.randn(*shape, generator=g)


def image_error(image: torch.Tensor, reference: torch.Tensor) -> Tuple[float, float]:
    """(RMSE, max |difference|) over every pixel, channel and view."""
    d = (image.detach().double() - reference.detach().double())
    return float(d.pow(2).mean().sqrt()), float(d.abs().max())


def gradient_error(grad: torch.Tensor, reference: torch.Tensor) -> Dict[str, Optional[float]]:
    """Cosine, norm ratio ‖g‖/‖g_ref‖ and relative error ‖g − g_ref‖/‖g_ref‖ of a volume gradient."""
    g, r = grad.detach().double().flatten(), reference.detach().double().flatten()
    nr, ng = float(r.norm()), float(g.norm())
    if nr == 0.0:
        return {"grad_cosine": None, "grad_norm_ratio": None, "grad_rel_err": None}
    cos = float(g @ r) / (ng * nr) if ng > 0 else 0.0
    return {"grad_cosine": cos, "grad_norm_ratio": ng / nr, "grad_rel_err": float((g - r).norm()) / nr}
