"""Volumes: the generator's output and the one scene representation both renderers share.

Convention (docs/conventions.md, "Volumes"): ``v[b, c, d, h, w]``, float32 in [0, 1], sampling the cube
[−1, 1]³ at voxel centres with voxel size Δ = 2 / N:

    x = −1 + (w + ½) Δ      (w grows with +x)
    y =  1 − (h + ½) Δ      (h grows with −y, row 0 at the top)
    z =  1 − (d + ½) Δ      (d grows with −z, d = 0 nearest the front camera at +z)

Channels: ``[density]`` for VH and AO, ``[r, g, b, density]`` for EA.
"""

from __future__ import annotations

import math
from typing import Dict

import torch

from .errors import UserError

__all__ = [
    "MODELS",
    "CHANNELS",
    "voxel_size",
    "world_to_grid",
    "voxel_centres",
    "validate_volume",
    "test_volume",
    "TEST_VOLUMES",
]

#: Image formation models and the number of volume channels each needs.
CHANNELS: Dict[str, int] = {"vh": 1, "ao": 1, "ea": 4}
MODELS = tuple(CHANNELS)


def voxel_size(n: int) -> float:
    """Δ = 2 / N: the edge of one voxel of an N³ volume covering [−1, 1]³."""
    return 2.0 / n


def world_to_grid(p: torch.Tensor) -> torch.Tensor:
    """World points ``(..., 3)`` → ``grid_sample`` coordinates ``(gx, gy, gz) = (x, −y, −z)``.

    With ``align_corners=False`` the coordinate −1 is the outer face of the first voxel,
    so voxel centres land exactly where the convention above puts them.
    """
    return p * p.new_tensor([1.0, -1.0, -1.0])


def validate_volume(volume: torch.Tensor, model: str) -> None:
    """Raise ``ValueError`` (a :class:`~mitsuba_platonic.errors.UserError`) unless ``volume`` is a
    valid ``(B, C, N, N, N)`` volume for ``model``: B ≥ 1, real values (not the 'meta' device)."""
    if model not in CHANNELS:
        raise UserError(f"model must be one of {MODELS}, got {model!r}")
    if not isinstance(volume, torch.Tensor):
        raise UserError(f"volume must be a torch.Tensor of shape (B, C, D, H, W), "
                        f"got {type(volume).__name__}")
    if volume.dim() != 5:
        raise UserError(f"volume must have rank 5 (B, C, D, H, W), got shape {tuple(volume.shape)}")
    if volume.shape[0] == 0:
        raise UserError(f"volume has batch size 0 (shape {tuple(volume.shape)}): there is nothing to "
                        f"render; pass at least one volume")
    c = CHANNELS[model]
    if volume.shape[1] != c:
        layout = "[density]" if c == 1 else "[r, g, b, density]"
        raise UserError(f"model {model!r} needs {c} channel(s) {layout}, "
                        f"got {volume.shape[1]} in shape {tuple(volume.shape)}")
    d, h, w = volume.shape[2:]
    if not d == h == w:
        raise UserError(f"volume must be cubic (D = H = W), got {tuple(volume.shape[2:])}")
    if d < 2:
        raise UserError(f"volume resolution must be at least 2, got {d}")
    if not volume.is_floating_point():
        raise UserError(f"volume must be a floating-point tensor, got {volume.dtype}")
    if volume.is_meta:
        raise UserError("volume is on the 'meta' device (a shape without values); rendering needs "
                        "values: create it on 'cpu' or 'cuda'")
    lo, hi = (float(x) for x in torch.aminmax(volume.detach()))  # one pass; NaN and ±Inf propagate
    if math.isnan(lo) or math.isnan(hi):
        raise UserError("volume contains NaN")
    if lo < 0.0 or hi > 1.0:
        raise UserError(f"volume values must lie in [0, 1], got range [{lo:.9g}, {hi:.9g}]")


def voxel_centres(n: int) -> torch.Tensor:
    """World coordinates ``(x, y, z)`` of the voxel centres: ``(N, N, N, 3)`` float64 indexed [d, h, w]."""
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * voxel_size(n)
    z, y, x = torch.meshgrid(-c, -c, c, indexing="ij")
    return torch.stack([x, y, z], dim=-1)


def _soft(sdf: torch.Tensor, n: int, width: float = 1.0) -> torch.Tensor:
    """Anti-aliased occupancy from a signed distance: a logistic ramp ``width`` voxels wide."""
    return torch.sigmoid(-sdf / (width * voxel_size(n) / 4.0))


def _figure(n: int) -> torch.Tensor:
    """An asymmetric coloured figure: a sphere, an offset box and a torus, each with its own colour.

    Asymmetric in x, y and z, so a flipped axis in either renderer shows at once.
    """
    p = voxel_centres(n)
    x, y, z = p.unbind(-1)
    sphere = (p - p.new_tensor([-0.25, 0.2, 0.1])).norm(dim=-1) - 0.45
    q = (p - p.new_tensor([0.35, -0.35, -0.2])).abs() - p.new_tensor([0.25, 0.3, 0.35])
    box = q.clamp_min(0).norm(dim=-1) + q.max(dim=-1).values.clamp_max(0)
    ring_r = torch.sqrt((x - 0.1) ** 2 + (z - 0.3) ** 2) - 0.5
    torus = torch.sqrt(ring_r ** 2 + (y + 0.55) ** 2) - 0.12
    occ = torch.stack([_soft(sphere, n), _soft(box, n), _soft(torus, n)])
    colours = p.new_tensor([[0.9, 0.3, 0.2], [0.2, 0.6, 0.9], [0.3, 0.85, 0.3]])
    density = 1.0 - torch.prod(1.0 - occ, dim=0)
    weight = occ / occ.sum(0).clamp_min(1e-6)
    rgb = torch.einsum("k...,kc->c...", weight, colours)
    rgb = rgb * (0.75 + 0.25 * (y + 1.0) / 2.0)  # a vertical shading gradient: colour varies in-part
    return torch.cat([rgb, density[None]]).clamp(0.0, 1.0)


def _cloud(n: int) -> torch.Tensor:
    """A smooth, semi-transparent cloud: densities spread over (0, 1), the AO/x-ray regime."""
    p = voxel_centres(n)
    x, y, z = p.unbind(-1)
    r2 = (x * x + 1.5 * y * y + z * z)
    density = 0.35 * torch.exp(-3.0 * r2) * (1.0 + 0.5 * torch.sin(4.0 * x + 2.0 * z) * torch.cos(3.0 * y))
    rgb = torch.stack([0.5 + 0.4 * x.clamp(-1, 1), 0.5 + 0.4 * y.clamp(-1, 1), 0.5 - 0.4 * z.clamp(-1, 1)])
    return torch.cat([rgb, density[None]]).clamp(0.0, 1.0)


TEST_VOLUMES = {"figure": _figure, "cloud": _cloud}


def test_volume(n: int = 32, kind: str = "figure", model: str = "ea",
                dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """A built-in analytic test volume ``(1, C, N, N, N)`` for ``model`` ('vh'/'ao' keep density only).

    ``kind``: ``"figure"`` (opaque, coloured, asymmetric solids with anti-aliased boundaries)
    or ``"cloud"`` (smooth semi-transparent density).
    """
    if kind not in TEST_VOLUMES:
        raise ValueError(f"kind must be one of {tuple(TEST_VOLUMES)}, got {kind!r}")
    if model not in CHANNELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"n must be an int >= 2, got {n!r}")
    v = TEST_VOLUMES[kind](n).to(dtype)
    if CHANNELS[model] == 1:
        v = v[3:]
    return v[None].contiguous()


test_volume.__test__ = False  # not a pytest test despite its name
