"""The colour G offsets from, read from the input photo (``model.photo_colour`` and the keys after it).

A reconstruction's colour is hardest where the photo says most: E's 64-number code cannot carry a
tree's leaves. So with ``model.photo_colour`` G's colour logits ℓ are offsets from a colour read
from the photo itself, c = σ(ℓ + logit base) (:meth:`~mitsuba_platonic.networks.nets.Generator.forward`):

- :func:`photo_colour`: base = the photo's mean colour (``model.photo_colour``);
- :func:`photo_texture`: base = the photo's pixel, carried along the input camera's rays
  (``model.photo_texture``);
- :func:`texture_corrected`: G's logits corrected by a convolution that sees the texture, G's
  logits and what the input camera sees (``model.texture_conv``);

with :func:`front_transmittance` (a deep shadow map of G's density towards the input camera) for
the last, and :func:`photo_volume` the one recipe that training and
:meth:`~mitsuba_platonic.model.Model.reconstruct` share. docs/training.md, "The measurements" has the
measurements behind each.
"""

from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..render.pytorch.closed_form import tilt, transmittance_before

__all__ = ["COLOUR_MIN", "photo_colour", "photo_texture", "front_transmittance", "texture_corrected", "photo_volume",
           "in_g_frame"]


#: Where :func:`photo_colour` clamps a mean colour, so that its logit stays finite (≈ ±5.5).
COLOUR_MIN = 1.0 / 255.0


def photo_colour(images: torch.Tensor) -> torch.Tensor:
    """The mean colour of the covered pixels of premultiplied RGBA images ``(B, 4, R, R)``:
    m = Σ_pixels (r, g, b) / Σ_pixels α, ``(B, 3)``; ½ (grey) for an image with nothing in it."""
    if images.dim() != 4 or images.shape[1] != 4:
        raise ValueError(f"photo_colour expects premultiplied RGBA images (B, 4, R, R), got {tuple(images.shape)}")
    coverage = images[:, 3].sum(dim=(1, 2))
    total = images[:, :3].sum(dim=(2, 3))
    m = total / coverage.clamp_min(1e-8)[:, None]
    return torch.where(coverage[:, None] > 1e-8, m, torch.full_like(m, 0.5)).clamp(0.0, 1.0)


def _camera_coordinates(resolution: int, θ: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(X, Y, Z) of G's voxel centres ``[B, d, h, w]`` (broadcastable) in the frame of an orthographic
    camera at azimuth 0 and elevation θ ``(B,)``: X right, Y up, Z towards the camera,

        X = x,   Y = y cos θ − z sin θ,   Z = y sin θ + z cos θ

    for a centre p = (x, y, z) of G's frame (docs/conventions.md: w along +x, h along −y, d along −z)."""
    centres = -1.0 + (torch.arange(resolution, dtype=torch.float64) + 0.5) * (2.0 / resolution)
    x = centres[None, None, None, :]                                                       # w: along +x
    y = centres.flip(0)[None, None, :, None]                                               # h: along −y
    z = centres.flip(0)[None, :, None, None]                                               # d: along −z
    s, c = torch.sin(θ)[:, None, None, None], torch.cos(θ)[:, None, None, None]
    return x.expand(θ.shape[0], 1, 1, resolution), y * c - z * s, y * s + z * c


def _read(colour: torch.Tensor, column: torch.Tensor, up: torch.Tensor, r: int) -> torch.Tensor:
    """``colour`` ``(B, 3, H, W)`` read bilinearly at image coordinates (column, −up) in [−1, 1]
    (beyond the image, its edge), one read per voxel: ``(B, 3, r, r, r)`` for coordinates
    broadcastable to ``[B, r, r, r]``."""
    b = colour.shape[0]
    grid = torch.stack(torch.broadcast_tensors(column, -up), dim=-1).expand(b, r, r, r, 2)
    grid = grid.reshape(b, r, r * r, 2).to(device=colour.device, dtype=colour.dtype)
    out = F.grid_sample(colour, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return out.reshape(b, 3, r, r, r)


def _over_mean(images: torch.Tensor, what: str) -> torch.Tensor:
    """Premultiplied RGBA photos ``(B, 4, H, W)`` laid over their own mean colour m
    (:func:`photo_colour`): c = rgb + (1 − α) m, ``(B, 3, H, W)``."""
    if images.dim() != 4 or images.shape[1] != 4:
        raise ValueError(f"{what} expects premultiplied RGBA images (B, 4, H, W), got {tuple(images.shape)}")
    return images[:, :3] + (1.0 - images[:, 3:]) * photo_colour(images)[:, :, None, None]


def _elevations(elevation: Optional[torch.Tensor], b: int, what: str) -> torch.Tensor:
    """One elevation per photo, float64 on the CPU (None: 0)."""
    θ = torch.zeros(b, dtype=torch.float64) if elevation is None else elevation.detach().to("cpu", torch.float64)
    if θ.shape != (b,):
        raise ValueError(f"{what}: one elevation per photo expected, shape ({b},), got {tuple(θ.shape)}")
    return θ


#: The power p of the four turned cameras' blend weights, w_k ∝ max(0, cos(φ − φ_k))^p.
TURN_BLEND = 8


def photo_texture(images: torch.Tensor, resolution: int, elevation: Optional[torch.Tensor] = None,
                  turns: int = 1) -> torch.Tensor:
    """The photo's colour carried along the input camera's rays: ``(B, 3, R, R, R)``, a colour per
    voxel of G's frame for premultiplied RGBA photos ``(B, 4, H, W)``.

    The photo is first laid over its own mean colour m (:func:`photo_colour`), c = rgb + (1 − α) m,
    so the background adds no colour of its own. A voxel centre p = (x, y, z) of G's frame
    (docs/conventions.md: w along +x, h along −y, d along −z) is seen by an orthographic camera at
    azimuth 0 and elevation θ (``elevation`` ``(B,)`` radians; None: 0, the volume in the input
    camera's frame) at image coordinates

        X = x,   Y = y cos θ − z sin θ        (right = +x, up = (0, cos θ, −sin θ))

    and takes the colour there, read bilinearly (column X, row −Y; beyond the photo, its edge).
    Every voxel along a ray gets that ray's pixel: the front of the object starts with the photo's
    detail, the back with its mirror image, and G's offsets change what the views disagree with.

    ``turns`` 4: the photo as seen by four cameras at the input's elevation, turned by φ_k = k·90°
    about the vertical. Camera k sees p at X_k = x cos φ_k − z sin φ_k, Y_k = y cos θ − z_k sin θ
    with z_k = x sin φ_k + z cos φ_k, and the voxel at azimuth φ = atan2(x, z) about the vertical
    takes Σ_k w_k c(X_k, Y_k), w_k ∝ max(0, cos(φ − φ_k))^p (p = :data:`TURN_BLEND`): each side of
    a body round about its vertical shows a photo's worth of texture, where the carried photo shows
    its rim's columns stretched across the side."""
    c = _over_mean(images, "photo_texture")
    θ = _elevations(elevation, images.shape[0], "photo_texture")
    X, Y, _ = _camera_coordinates(resolution, θ)
    if turns == 1:
        return _read(c, X, Y, resolution)
    if turns != 4:
        raise ValueError(f"photo_texture: turns must be 1 or 4, got {turns!r}")
    centres = -1.0 + (torch.arange(resolution, dtype=torch.float64) + 0.5) * (2.0 / resolution)
    x = centres[None, None, None, :]                                                   # G's frame, as above
    y = centres.flip(0)[None, None, :, None]
    z = centres.flip(0)[None, :, None, None]
    φ = torch.atan2(x, z)                                                               # azimuth about the vertical
    s, co = torch.sin(θ)[:, None, None, None], torch.cos(θ)[:, None, None, None]
    out, total = 0.0, 0.0
    for k in range(4):
        φ_k = k * math.pi / 2.0
        x_k = x * math.cos(φ_k) - z * math.sin(φ_k)                                     # camera k's right
        z_k = x * math.sin(φ_k) + z * math.cos(φ_k)                                     # towards camera k
        w = torch.cos(φ - φ_k).clamp_min(0.0) ** TURN_BLEND
        out = out + w.to(c) * _read(c, x_k, y * co - z_k * s, resolution)
        total = total + w
    return out / total.to(c).clamp_min(1e-12)


def front_transmittance(density: torch.Tensor, elevation: Optional[torch.Tensor] = None) -> torch.Tensor:
    """T_front ``(B, 1, R, R, R)`` in [0, 1] and in the input camera's frame: the transmittance from
    each voxel out of the volume towards the input camera, for a density ``(B, 1, R, R, R)`` in G's
    frame (held constant) and the input camera at ``elevation`` θ (None: the volume in the camera's
    frame).

    In the camera's frame (:func:`~mitsuba_platonic.render.pytorch.closed_form.tilt` by θ: planes k = 0
    nearest the camera), with τ = 1 − v each voxel's transmittance (EA at one sample per voxel),

        T_front,k = Π_{k'<k} τ_k'

    It goes back into G's frame with :func:`in_g_frame`."""
    v = density.detach().clamp(0.0, 1.0)
    if elevation is not None:
        v = tilt(v, elevation.detach())
    return transmittance_before(1.0 - v, 2)


def in_g_frame(weight: torch.Tensor, elevation: Optional[torch.Tensor]) -> torch.Tensor:
    """A weight in [0, 1] of the input camera's frame (:func:`front_transmittance`) back in G's frame:
    tilted back by the input's ``elevation`` (None: the frames are one), clamped to [0, 1]."""
    return weight if elevation is None else tilt(weight, -elevation.detach()).clamp(0.0, 1.0)


def texture_corrected(conv: nn.Module, volume: torch.Tensor, offsets: torch.Tensor, texture: torch.Tensor,
                      elevation: Optional[torch.Tensor] = None,
                      behind: Optional[torch.Tensor] = None,
                      offsets_behind: bool = True) -> Tuple[torch.Tensor, torch.Tensor]:
    """``model.texture_conv``: (volume, ℓ') of the volume G made with offsets ℓ from the photos'
    ``texture`` t (:func:`photo_texture`, ``(B, 3, R, R, R)``), its logits corrected by ``conv``
    (G's :attr:`~mitsuba_platonic.networks.nets.Generator.texture_conv`, a 3³ convolution, 8 channels
    to 4):

        x = [ℓ, logit ρ, logit t, T_front]                      (3 + 1 + 3 + 1 channels per voxel)
        [δ_c, δ_ρ] = conv(x)
        colour = σ(ℓ + δ_c + logit t),   ρ' = σ(logit ρ + δ_ρ),   ℓ' = ℓ + δ_c

    with ρ G's density and T_front the transmittance from each voxel towards the input camera
    (:func:`front_transmittance` of ρ, held constant, in G's frame). G's own offsets see only the
    code, so they cannot tell where the texture carried along the input camera's rays runs
    through the body as streaks seen from the side; the convolution sees the texture, its
    neighbours and how deep behind what the camera sees each voxel lies. ℓ' is the whole offset
    from the photo's colour (``train.colour_offset`` penalises it).

    ``behind`` (``model.texture_turns`` 4: the photo from four turned cameras, :func:`photo_texture`):
    the texture where the input camera does not see, t ← T_front t + (1 − T_front) t_behind, so the
    surface the photo shows keeps the photo's own pixels. ``offsets_behind`` False
    (``model.offsets_behind``): G's colour offsets act only where the input camera sees,
    ℓ' ← T_front (ℓ + δ_c), so the body behind that surface keeps the turned cameras' texture as read."""
    ρ = volume[:, 3:]
    front = in_g_frame(front_transmittance(ρ, elevation), elevation)
    if behind is not None:
        texture = front * texture.to(volume) + (1.0 - front) * behind.to(volume)
    t = torch.logit(texture.to(volume).clamp(COLOUR_MIN, 1.0 - COLOUR_MIN))
    logit_ρ = torch.logit(ρ.clamp(1e-6, 1.0 - 1e-6))            # G's own density logit (ρ is its sigmoid)
    x = torch.cat([offsets, logit_ρ, t, front], dim=1).contiguous(memory_format=torch.channels_last_3d)
    δ = conv(x).float()
    ℓ = offsets + δ[:, :3]
    if behind is not None and not offsets_behind:
        ℓ = front * ℓ                                          # T_front held constant: offsets where seen
    logits = torch.cat([ℓ + t, logit_ρ + δ[:, 3:]], dim=1)
    return torch.sigmoid(logits).contiguous(), ℓ


def photo_volume(G: nn.Module, code: torch.Tensor, images: torch.Tensor, recipe: Any,
                 elevation: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, torch.Tensor]:
    """(volume, ℓ) of a ``photo_colour`` G (or its data-parallel wrapper) for ``code`` and the
    ``images`` it encodes, by ``recipe`` (the model section of a config, or a
    :class:`~mitsuba_platonic.networks.nets.NetConfig`: its ``photo_texture``, ``texture_conv`` and
    ``resolution``): G's colour offset from the photos' mean colour (:func:`photo_colour`) or, with
    ``photo_texture``, from their texture seen from ``elevation`` (:func:`photo_texture`), corrected by
    :func:`texture_corrected` with ``texture_conv``; ℓ the offsets. The one
    recipe of training and of :meth:`~mitsuba_platonic.model.Model.reconstruct`."""
    mean = photo_colour(images)
    r = recipe.resolution
    t = photo_texture(images, r, elevation) if recipe.photo_texture else None
    behind = photo_texture(images, r, elevation, 4) if recipe.texture_turns == 4 else None
    v, ℓ = G(code, mean if t is None else t, offsets=True)
    if recipe.texture_conv:
        conv = getattr(G, "module", G).texture_conv                # G, or the G inside a data-parallel wrapper
        v, ℓ = texture_corrected(conv, v, ℓ, t, elevation, behind, recipe.offsets_behind)
    return v, ℓ
