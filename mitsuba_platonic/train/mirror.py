"""The mirror frame: each volume's vertical plane of mirror symmetry, and the random views drawn about it.

Most classes people photograph are mirror-symmetric about a vertical plane (animals, vehicles,
chairs, aeroplanes: the sagittal plane), and a round class is symmetric about every vertical plane,
so "probably mirror-symmetric about some vertical plane" is true of both kinds, where
``train.turn`` (probably round) is true of one. This module finds that plane in each of G's upright
volumes (``train.pose: elevation``), and uses it twice:

**The plane.** A vertical plane through the opacity's centroid c (in the horizontal plane) with
normal n(ψ) = (sin ψ, 0, cos ψ) (the view at azimuth ψ, :func:`~mitsuba_platonic.views.from_angles`,
so a camera at azimuth ψ looks along the normal: at an animal's side) maps p to

    M_ψ p = p − 2 ((p − c) · n) n

and the volume's asymmetry about it is

    A(ψ) = Σ |α − M_ψ α| / Σ (α + M_ψ α)      ∈ [0, 1], 0 for a mirror-symmetric volume

(M_ψ α the opacity resampled trilinearly at the mirrored points, nothing from beyond the cube). ψ and
ψ + 180° name one plane; :func:`mirror_planes` evaluates A at :data:`CANDIDATES` planes 180° / K apart and
refines the best by a parabola through it and its two neighbours.

**The views** (``train.view_frame: mirror``). The input camera sits at azimuth 0 of G's upright frame,
so its angle to volume i's plane normal, folded by the plane's symmetries (the normal's sign; the
mirror, which takes a camera at β to one at −β and the photo to its mirror image), is

    |β_i| = min(δ_i, 180° − δ_i),   δ_i = (−ψ_i) mod 180°      ∈ [0°, 90°]

(0°: the photo shows the plane's side, as a side view shows an animal's; 90°: it looks along the
plane, end-on). The |β_j| of the batch's photos are a sample of the collection's view distribution in
the objects' own frames. A random view of volume i keeps the elevation drawn from p_view and takes
the azimuth

    φ = ψ_i + s |β_j| + t · 180°,   j uniform over the batch, s ∈ {−1, 1}, t ∈ {0, 1} uniform

so that D sees each object from where the collection's cameras stood about such objects: a
collection of uniform azimuths gives uniform φ, as ``train.view_frame: camera`` draws; a collection
photographed from the sides gives side views only, and D, which has only seen side views, no longer
asks the end-on view to look like one. A round volume's plane is any plane, its ψ arbitrary, and its
views uniform. (docs/training.md, "What the photo recipe assumes".)

**The prior** (``train.mirror``, :func:`mirror_loss`): A at each volume's best plane, summed over the
batch as L_turn is: G is pulled towards the symmetry the volume nearly has, not towards one assumed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
import torch.nn.functional as F

from ..views import from_angles, to_angles

__all__ = ["CANDIDATES", "MirrorPlanes", "mirrored", "asymmetry", "mirror_planes", "fold_to_normal",
           "mirror_frame_views", "mirror_loss"]

#: The planes :func:`mirror_planes` tries, 180° / CANDIDATES apart.
CANDIDATES = 12


class MirrorPlanes(NamedTuple):
    """Each volume's plane: ψ ``(B,)`` radians in [0, π), the centroid ``(B, 2)`` (x, z) in world units
    of the cube [−1, 1]³, and A at ψ ``(B,)``."""

    ψ: torch.Tensor
    centre: torch.Tensor
    asymmetry: torch.Tensor


def _check(volume: torch.Tensor, name: str) -> None:
    if not isinstance(volume, torch.Tensor) or volume.dim() != 5 or volume.shape[2] != volume.shape[4]:
        raise ValueError(f"{name}: expected upright volumes (B, C, N, H, N), got "
                         f"{tuple(getattr(volume, 'shape', ()))}")


def centroid(opacity: torch.Tensor) -> torch.Tensor:
    """The opacity-weighted centre (x, z) ``(B, 2)`` of ``opacity`` ``(B, 1, D, H, W)`` in world units
    (x along W, z = +1 at the front plane d = 0); (0, 0) for an empty volume."""
    b, n = opacity.shape[0], opacity.shape[-1]
    centres = -1.0 + (torch.arange(n, dtype=opacity.dtype, device=opacity.device) + 0.5) * (2.0 / n)
    w = opacity[:, 0].sum(dim=2)                                        # (B, D, W): summed over height
    total = w.sum((1, 2)).clamp_min(1e-12)
    x = (w.sum(1) * centres).sum(1) / total
    z = (w.sum(2) * centres.flip(0)).sum(1) / total                    # depth plane d lies at z = centres[N − 1 − d]
    return torch.stack([x, z], 1)


def mirrored(volume: torch.Tensor, ψ: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """``volume`` ``(B, C, N, H, N)`` mirrored about the vertical plane through ``centre`` ``(B, 2)``
    (world x, z) with normal n(ψ) = (sin ψ, 0, cos ψ), ψ ``(B,)`` radians (module docstring), resampled
    trilinearly with zeros beyond the cube. In grid_sample's coordinates (x, y, z) ↔ (w, h, d), which are
    the world's (x, −y, −z), the normal is (sin ψ, 0, −cos ψ) and the map is the same reflection; being
    its own inverse, it maps output to input as affine_grid expects."""
    b = volume.shape[0]
    n = torch.stack([torch.sin(ψ), torch.zeros_like(ψ), -torch.cos(ψ)], 1).to(volume)          # (B, 3), grid coords
    c = torch.stack([centre[:, 0], torch.zeros_like(centre[:, 0]), -centre[:, 1]], 1).to(volume)
    R = torch.eye(3, dtype=volume.dtype, device=volume.device) - 2.0 * n[:, :, None] * n[:, None, :]
    t = 2.0 * (n * c).sum(1, keepdim=True) * n                          # M p = R p + 2 (n · c) n
    grid = F.affine_grid(torch.cat([R, t[:, :, None]], 2), list(volume.shape), align_corners=False)
    return F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def asymmetry(volume: torch.Tensor, ψ: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """A(ψ) ``(B,)`` of each volume's opacity (the last channel) about its plane (module docstring)."""
    _check(volume, "asymmetry")
    a = volume[:, -1:]
    m = mirrored(a, ψ, centre)
    return (a - m).abs().sum((1, 2, 3, 4)) / (a + m).sum((1, 2, 3, 4)).clamp_min(1e-12)


@torch.no_grad()
def mirror_planes(volume: torch.Tensor, candidates: int = CANDIDATES) -> MirrorPlanes:
    """Each volume's most nearly symmetric vertical plane through its centroid (module docstring): A at
    ``candidates`` planes ψ_k = k · 180° / K, the best refined by the parabola through it and its
    neighbours (the candidates are circular: ψ + 180° is ψ's plane). Held constant (no gradient)."""
    _check(volume, "mirror_planes")
    if not isinstance(candidates, int) or candidates < 3:
        raise ValueError(f"mirror_planes: expected at least 3 candidate planes, got {candidates!r}")
    b = volume.shape[0]
    a = volume[:, -1:].detach().float()
    centre = centroid(a)
    step = math.pi / candidates
    ψ_k = torch.arange(candidates, dtype=torch.float32, device=a.device) * step
    A = torch.stack([asymmetry(a, ψ_k[k].expand(b), centre) for k in range(candidates)], 1)     # (B, K)
    k = A.argmin(1)
    rows = torch.arange(b, device=a.device)
    lo, mid, hi = A[rows, (k - 1) % candidates], A[rows, k], A[rows, (k + 1) % candidates]
    curve = lo - 2.0 * mid + hi
    shift = torch.where(curve > 1e-12, 0.5 * (lo - hi) / curve.clamp_min(1e-12), torch.zeros_like(mid))
    ψ = torch.remainder(ψ_k[k] + shift.clamp(-0.5, 0.5) * step, math.pi)
    return MirrorPlanes(ψ, centre, asymmetry(a, ψ, centre))


def fold_to_normal(ψ: torch.Tensor) -> torch.Tensor:
    """|β| ``(B,)`` radians in [0, π/2]: the input camera's (azimuth 0) angle to each plane's normal,
    folded by the normal's sign and the mirror (module docstring)."""
    δ = torch.remainder(-ψ, math.pi)
    return torch.minimum(δ, math.pi - δ)


def mirror_frame_views(views: torch.Tensor, ψ: torch.Tensor, g: torch.Generator) -> torch.Tensor:
    """``views`` ``(B K, 3)`` (K per volume, in order) with each azimuth replaced by ψ_i + s |β_j| + t π
    (module docstring) and its elevation kept; ψ ``(B,)`` the volumes' planes; j, s and t drawn from ``g``."""
    b = ψ.shape[0]
    if views.dim() != 2 or views.shape[1] != 3 or views.shape[0] % b:
        raise ValueError(f"mirror_frame_views: expected views (B K, 3) for {b} planes, got {tuple(views.shape)}")
    n = views.shape[0]
    j = torch.randint(b, (n,), generator=g)
    s = torch.randint(2, (n,), generator=g) * 2 - 1
    t = torch.randint(2, (n,), generator=g)
    β = fold_to_normal(ψ.detach().double().cpu())
    i = torch.arange(n) // (n // b)
    φ = ψ.detach().double().cpu()[i] + s * β[j] + t * math.pi
    θ = to_angles(views, degrees=False)[1].cpu()
    return from_angles(φ, θ, degrees=False).to(views.device, views.dtype)


def mirror_loss(volume: torch.Tensor, planes: MirrorPlanes) -> torch.Tensor:
    """L_mirror (module docstring): Σ |α − M_ψ α| / Σ (α + M_ψ α) over the batch, each volume about its
    own plane ``planes`` (held constant; the gradient reaches G through α and M_ψ α)."""
    _check(volume, "mirror_loss")
    a = volume[:, -1:]
    m = mirrored(a, planes.ψ.to(a.device), planes.centre.to(a.device))
    return (a - m).abs().sum() / (a + m).sum().clamp_min(1e-12)
