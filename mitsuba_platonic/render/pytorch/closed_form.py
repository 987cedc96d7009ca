"""Closed-form rendering layers (the paper's reference mode), in PyTorch.

``R(ω, v) = ρ(T(ω) v)``: the volume is first *rotated into camera space by resampling*
(``grid_sample``, trilinear as in the paper, or nearest), then each pixel reduces the N
camera-space samples along depth, front (i = 1) to back (i = N):

    VH:  ρ = 1 − exp(−Σ_i v_i)
    AO:  ρ = 1 − Π_i (1 − v_i)
    EA:  C = Σ_i T_i a_i c_i,   T_i = Π_{j<i} (1 − a_j),   α = 1 − Π_i (1 − a_i)

with a = density channel, c = RGB channels. EA uses the *exclusive* transmittance T_i; the
paper's equation writes the inclusive opacity 1 − Π_{j≤i}(1 − a_j), a typo (docs/conventions.md,
"Emission–absorption: exclusive transmittance"). The authors' code also renormalises the
colour and supersamples depth 1024× (docs/paper.md); this layer does neither: it is exactly
the discrete emission–absorption sum at the N resampled planes, which is what a ray marcher
with step Δ and pixel-centre rays integrates.

Numerical extremes. AO and EA work in the *product domain* with no log and no clamp:
Π(1 − v) is exact at v = 0 and v = 1, and so is its gradient −Π_{j≠i}(1 − v_j), because
``torch.prod``/``torch.cumprod`` back-propagate through zero factors without dividing by
them. Values stay in [0, 1] and gradients finite for every v in [0, 1].

Camera-space sample positions (shared with the Mitsuba renderer): for an N³ volume and
Δ = 2/N, output pixel (row i, column j) and depth plane k sample the world point

    p = S(z_k) (x_j · right + y_i · up) + z_k · ω,
    x_j = −1 + (j + ½)Δ,  y_i = 1 − (i + ½)Δ,  z_k = 1 − (k + ½)Δ

with (right, up, ω) from :func:`mitsuba_platonic.views.camera_frames` and S ≡ 1 for the
orthographic camera (the paper's). At the front view these are the voxel centres themselves, so
the rotation is the identity. A :class:`~.window.Window` (zoom m, centre (c_x, c_y); orthographic
only) moves the lateral positions into it, h = 1/m:

    p = x_j (h right) + y_i (h up) + (c_x right + c_y up) + z_k ω

the same N depth planes; the full window is the formula above, computed as before.

Perspective (:func:`mitsuba_platonic.views.lens`): S(z) = (D − z) tan(F/2), and a pixel's ray
crosses each plane's slab along a path ℓ = √(1 + tan²(F/2)(x² + y²)) times its depth, so the
per-plane factors become exp(−ℓ v) (VH) and (1 − v)^ℓ (AO, EA: still exact at v = 0 and 1).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

import math
from typing import Optional, Tuple

from ...views import camera_frames
from ...volume import voxel_size, world_to_grid
from ..window import Window, check_orthographic, window_or_none

__all__ = ["FILTERS", "ORTHOGRAPHIC", "camera_space_points", "path_factor", "rotate", "tilt", "transmittance_before", "reduce_depth",
           "render_closed_form"]

#: Lookup filters both renderers accept, mapped to ``grid_sample`` modes.
FILTERS = {"nearest": "nearest", "trilinear": "bilinear"}


#: The orthographic camera's ``(tan(F/2), D)`` (:func:`mitsuba_platonic.views.lens`).
ORTHOGRAPHIC = (0.0, math.inf)


def camera_space_points(views: torch.Tensor, n: int, dtype: torch.dtype = torch.float32,
                        lens: Tuple[float, float] = ORTHOGRAPHIC, window: Optional[Window] = None) -> torch.Tensor:
    """World positions of the camera-space samples: ``(B, N, N, N, 3)`` indexed [b, k, i, j].

    ``p = S(z_k) (x_j · right + y_i · up) + z_k · ω`` (see the module docstring); float64 maths.
    ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`; None: the full one).
    """
    return _frame_points(*camera_frames(views), n, lens, window).to(dtype)


def _frame_points(right: torch.Tensor, up: torch.Tensor, w: torch.Tensor, n: int,
                  lens: Tuple[float, float] = ORTHOGRAPHIC, window: Optional[Window] = None) -> torch.Tensor:
    """``p = S(z_k) (x_j · right + y_i · up) + z_k · ω`` for frames ``(B, 3)`` each: ``(B, N, N, N, 3)``
    in the frames' dtype (differentiable in the frames); with a ``window`` (orthographic),
    ``p = x_j (h right) + y_i (h up) + o + z_k ω`` (:meth:`~.window.Window.frames`)."""
    window = window_or_none(window)
    check_orthographic(window, lens)
    origin = None
    if window is not None:
        right, up, origin = window.frames(right, up)
    c = -1.0 + (torch.arange(n, dtype=w.dtype, device=w.device) + 0.5) * voxel_size(n)
    xs, ys, zs = c, -c, -c
    t, d = lens
    scale = torch.ones_like(zs) if t == 0.0 else (d - zs) * t          # S(z_k)
    p = (zs[None, :, None, None, None] * w[:, None, None, None, :]
         + scale[None, :, None, None, None] * (ys[None, None, :, None, None] * up[:, None, None, None, :]
                                                + xs[None, None, None, :, None] * right[:, None, None, None, :]))
    if origin is not None:
        p = p + origin[:, None, None, None, :]
    return p


def path_factor(n: int, lens: Tuple[float, float], dtype: torch.dtype = torch.float32) -> Optional[torch.Tensor]:
    """ℓ(x_j, y_i) = √(1 + tan²(F/2)(x² + y²)) per pixel, ``(N, N)``; None for the orthographic camera."""
    t = lens[0]
    if t == 0.0:
        return None
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * voxel_size(n)
    r2 = c[:, None] ** 2 + c[None, :] ** 2
    return torch.sqrt(1.0 + t * t * r2).to(dtype)


def rotate(volume: torch.Tensor, views: torch.Tensor, filter: str = "trilinear",
           lens: Tuple[float, float] = ORTHOGRAPHIC, window: Optional[Window] = None) -> torch.Tensor:
    """Resample ``volume`` ``(B, C, N, N, N)`` into the camera space of ``views`` ``(B, 3)``.

    Output ``(B, C, N, N, N)`` indexed [b, c, k, i, j]: depth plane k (k = 0 nearest the
    camera), image row i, column j. Outside [−1, 1]³ the volume is empty (zero padding), so
    trilinear lookups within half a voxel of the boundary blend towards 0. ``window``: the
    orthographic camera's zoom and pan (:class:`~.window.Window`), None for the full one.
    """
    if filter not in FILTERS:
        raise ValueError(f"filter must be one of {tuple(FILTERS)}, got {filter!r}")
    n = volume.shape[-1]
    grid = world_to_grid(camera_space_points(views, n, torch.float64, lens, window)).to(volume.dtype)
    return F.grid_sample(volume, grid.to(volume.device), mode=FILTERS[filter],
                         padding_mode="zeros", align_corners=False)


def tilt(volume: torch.Tensor, elevation: torch.Tensor) -> torch.Tensor:
    """Resample ``volume`` ``(B, C, N, N, N)`` into the frame of a camera at azimuth 0 and
    ``elevation`` θ ``(B,)`` (radians), differentiably in θ as well as in the volume.

    The same resampling as :func:`rotate` at the view ω(0, θ) = (0, sin θ, cos θ) (trilinear, zero
    outside the cube, orthographic), with the frame written in θ rather than taken from
    :func:`~mitsuba_platonic.views.camera_frames` (which holds views constant):

        right = (1, 0, 0),   up = ω × right = (0, cos θ, −sin θ),   ω = (0, sin θ, cos θ)

    so at θ = ±90° it is the pole's frame of :func:`rotate` (right = +x) without a special case.
    As right = +x, a sample's x is its voxel's own, and the trilinear read is a bilinear one in
    each x column's (depth, height) plane: one 2D ``grid_sample`` with the columns as channels.
    Rendering the result from the front view ω₀ renders ``volume`` from ω(0, θ): a volume in an
    upright object frame, seen by the input camera at an elevation E estimated
    (``train.pose: elevation``, :mod:`mitsuba_platonic.train.trainer`).
    """
    if elevation.shape != volume.shape[:1]:
        raise ValueError(f"elevation must have shape ({volume.shape[0]},), one angle per volume, "
                         f"got {tuple(elevation.shape)}")
    θ = elevation.to(torch.float64)
    s, c = torch.sin(θ), torch.cos(θ)
    b, ch, n = volume.shape[0], volume.shape[1], volume.shape[-1]
    centres = -1.0 + (torch.arange(n, dtype=torch.float64, device=θ.device) + 0.5) * voxel_size(n)
    z, y = centres.flip(0)[:, None], centres.flip(0)[None, :]          # plane k's depth, row i's height
    # p = z ω + y up + x right: x stays x_j (a voxel centre, so no blend along x), and p's height and
    # depth depend on (k, i) alone: one bilinear read per (k, i) of every x column's (d, h) plane
    p_y = z * s[:, None, None] + y * c[:, None, None]
    p_z = z * c[:, None, None] - y * s[:, None, None]
    grid = torch.stack([-p_y, -p_z], dim=-1).to(device=volume.device, dtype=volume.dtype)   # (x, y) → (h, d)
    columns = volume.permute(0, 1, 4, 2, 3).reshape(b, ch * n, n, n)   # (B, C·W, D, H)
    out = F.grid_sample(columns, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return out.reshape(b, ch, n, n, n).permute(0, 1, 3, 4, 2)


def transmittance_before(tau: torch.Tensor, dim: int) -> torch.Tensor:
    """EA's exclusive transmittance T_i = Π_{j<i} τ_j along ``dim`` of per-sample transmittances τ
    (1 at the first sample), in the product domain: exact, with its gradient, at τ = 0 and 1."""
    ones = torch.ones_like(tau.narrow(dim, 0, 1))
    return torch.cumprod(torch.cat([ones, tau.narrow(dim, 0, tau.shape[dim] - 1)], dim=dim), dim=dim)


def reduce_depth(camera_volume: torch.Tensor, model: str, path: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Apply the image formation ρ along depth (dim 2) of a camera-space volume → ``(B, C', H, W)``.

    VH and AO give one channel (opacity); EA gives premultiplied RGB plus alpha. ``path``: the
    perspective camera's per-pixel path factor ℓ ``(H, W)`` (:func:`path_factor`), None for 1.
    """
    if model == "vh":
        depth = camera_volume.sum(dim=2)
        return 1.0 - torch.exp(-(depth if path is None else path * depth))
    if model == "ao":
        tau = 1.0 - camera_volume if path is None else torch.pow((1.0 - camera_volume).clamp_min(0.0), path)
        return 1.0 - torch.prod(tau, dim=2)
    if model == "ea":
        colour, a = camera_volume[:, :3], camera_volume[:, 3:]
        # per-sample transmittance (the clamp: trilinear round-off may lift a density 1 ulp above 1)
        tau = 1.0 - a if path is None else torch.pow((1.0 - a).clamp_min(0.0), path)
        T = transmittance_before(tau, 2)                                    # exclusive: Π_{j<i}
        rgb = (T * (a if path is None else 1.0 - tau) * colour).sum(dim=2)
        alpha = 1.0 - torch.prod(tau, dim=2)
        return torch.cat([rgb, alpha], dim=1)
    raise ValueError(f"model must be 'vh', 'ao' or 'ea', got {model!r}")


def render_closed_form(volume: torch.Tensor, views: torch.Tensor, model: str,
                       filter: str = "trilinear", lens: Tuple[float, float] = ORTHOGRAPHIC,
                       window: Optional[Window] = None) -> torch.Tensor:
    """The closed-form layer R(ω, v) = ρ(T(ω) v) for a batch of (volume, view) pairs.

    ``lens``: ``(tan(F/2), D)`` of a perspective camera (:func:`mitsuba_platonic.views.lens`).
    ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`; None or the full
    window: the whole cross-section, as before). Inputs are assumed valid (see
    :func:`mitsuba_platonic.render`, which checks them).
    """
    n = volume.shape[-1]
    path = path_factor(n, lens, volume.dtype)
    return reduce_depth(rotate(volume, views, filter, lens, window), model,
                        None if path is None else path.to(volume.device))
