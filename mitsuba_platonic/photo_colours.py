"""The colour G offsets from, read from the input photo (``model.photo_colour`` and the keys after it).

A reconstruction's colour is hardest where the photo says most: E's 64-number code cannot carry a
tree's leaves. So with ``model.photo_colour`` G's colour logits ℓ are offsets from a colour read
from the photo itself, c = σ(ℓ + logit base) (:meth:`~mitsuba_platonic.models.Generator.forward`):

- :func:`photo_colour`: base = the photo's mean colour (``model.photo_colour``);
- :func:`photo_texture`: base = the photo's pixel, carried along the input camera's rays
  (``model.photo_texture``);
- :func:`texture_on_surface`: that pixel only where the input camera's line sees a voxel, the
  mean colour inside (``model.texture_surface``), or the photo blurred (``model.texture_blur``);
- :func:`texture_on_sides`: also the photo as seen from the input camera's left and right
  (:func:`photo_texture_sides`) where only those cameras see a voxel (``model.texture_sides``);
- :func:`texture_corrected`: G's logits corrected by a convolution that sees the texture, G's
  logits and what the input camera sees (``model.texture_conv``);

with :func:`transmittances` (deep shadow maps of G's density along the input camera's axes) for
the last three, and :func:`photo_volume` the one recipe that training and
:meth:`~mitsuba_platonic.model.Model.reconstruct` share. docs/training.md, "Real photos", has the
measurements behind each.
"""

from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from .render.closed_form import tilt, transmittance_before

__all__ = ["COLOUR_MIN", "photo_colour", "blurred", "photo_texture", "photo_texture_sides", "transmittances",
           "surface_weight", "texture_on_surface", "texture_on_sides", "texture_corrected", "photo_volume"]


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


def blurred(colour: torch.Tensor, sigma: float) -> torch.Tensor:
    """Images ``(B, 3, H, W)`` convolved with a normalised Gaussian of ``sigma`` pixels, separably
    (radius ⌈3σ⌉, edges replicated): G_σ * c."""
    r = max(1, math.ceil(3.0 * sigma))
    k = torch.exp(-torch.arange(-r, r + 1, dtype=colour.dtype, device=colour.device) ** 2 / (2.0 * sigma ** 2))
    k = (k / k.sum()).expand(colour.shape[1], 1, -1)
    x = F.conv2d(F.pad(colour, (r, r, 0, 0), mode="replicate"), k[:, :, None, :], groups=colour.shape[1])
    return F.conv2d(F.pad(x, (0, 0, r, r), mode="replicate"), k[:, :, :, None], groups=colour.shape[1])


def photo_texture(images: torch.Tensor, resolution: int, elevation: Optional[torch.Tensor] = None,
                  blur: float = 0.0) -> torch.Tensor:
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
    With ``blur`` σ > 0 the photo is first blurred by a Gaussian of σ of its pixels (:func:`blurred`)."""
    c = _over_mean(images, "photo_texture")
    if blur > 0:
        c = blurred(c, blur)
    X, Y, _ = _camera_coordinates(resolution, _elevations(elevation, images.shape[0], "photo_texture"))
    return _read(c, X, Y, resolution)


def photo_texture_sides(images: torch.Tensor, resolution: int,
                        elevation: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, torch.Tensor]:
    """The photo as if also taken from the input camera's left and right: (t_left, t_right), each
    ``(B, 3, R, R, R)``, for ``model.texture_sides``. In the input camera's frame (X right, Y up,
    Z towards it, :func:`photo_texture`), a camera turned 90° to the right (at +X, looking along
    −X) has −Z on its right, the one turned left +Z, so

        t_right(p) = c(−Z, Y),   t_left(p) = c(Z, Y)

    with c the photo over its mean colour, read as in :func:`photo_texture`: the photo carried
    along the side cameras' rays, so that each side of the object can start from a photo's
    detail rather than from the input rays' streaks."""
    c = _over_mean(images, "photo_texture_sides")
    _, Y, Z = _camera_coordinates(resolution, _elevations(elevation, images.shape[0], "photo_texture_sides"))
    return _read(c, Z, Y, resolution), _read(c, -Z, Y, resolution)


def transmittances(density: torch.Tensor,
                   elevation: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor,
                                                                      torch.Tensor]:
    """(T_front, T_back, T_left, T_right), each ``(B, 1, R, R, R)`` in [0, 1] and in the input
    camera's frame: the transmittance from each voxel out of the volume towards the input camera,
    away from it, and to its left and right, for a density ``(B, 1, R, R, R)`` in G's frame (held
    constant) and the input camera at ``elevation`` θ (None: the volume in the camera's frame).

    In the camera's frame (:func:`~mitsuba_platonic.render.closed_form.tilt` by θ: planes k = 0
    nearest the camera, columns j = 0 at its left), with τ = 1 − v each voxel's transmittance
    (EA at one sample per voxel),

        T_front,k = Π_{k'<k} τ_k',   T_back,k = Π_{k'>k} τ_k'        (along the camera's rays)
        T_left,j = Π_{j'<j} τ_j',    T_right,j = Π_{j'>j} τ_j'       (across them)

    A weight made of them goes back into G's frame with :func:`_in_g_frame`."""
    v = density.detach().clamp(0.0, 1.0)
    if elevation is not None:
        v = tilt(v, elevation.detach())
    τ = 1.0 - v
    before = transmittance_before                        # Π over the voxels before each one along a dim
    return before(τ, 2), before(τ.flip(2), 2).flip(2), before(τ, 4), before(τ.flip(4), 4).flip(4)


def _in_g_frame(weight: torch.Tensor, elevation: Optional[torch.Tensor]) -> torch.Tensor:
    """A weight in [0, 1] of the input camera's frame (:func:`transmittances`) back in G's frame."""
    return weight if elevation is None else tilt(weight, -elevation.detach()).clamp(0.0, 1.0)


def surface_weight(density: torch.Tensor, elevation: Optional[torch.Tensor] = None) -> torch.Tensor:
    """s ``(B, 1, R, R, R)`` in [0, 1]: how much of each voxel the input camera's rays see from either
    end, s = min(1, T_front + T_back) (:func:`transmittances`), for a density ``(B, 1, R, R, R)``
    in G's frame (held constant) and the input camera at ``elevation`` θ (None: the volume in the
    camera's frame). 1 on the surfaces the input view sees and on the ones a camera behind it
    would see, 0 deep inside."""
    front, back, _, _ = transmittances(density, elevation)
    return _in_g_frame((front + back).clamp(max=1.0), elevation)


def _coloured(volume: torch.Tensor, offsets: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
    """The volume with colour σ(ℓ + logit base) and its own density."""
    base = base.clamp(COLOUR_MIN, 1.0 - COLOUR_MIN)
    return torch.cat([torch.sigmoid(offsets + torch.logit(base)), volume[:, 3:]], dim=1).contiguous()


def texture_on_surface(volume: torch.Tensor, offsets: torch.Tensor, texture: torch.Tensor, inner: torch.Tensor,
                       elevation: Optional[torch.Tensor] = None) -> torch.Tensor:
    """``model.texture_surface``: the volume G made with offsets ℓ from the photos' ``texture``
    ``(B, 3, R, R, R)`` (:func:`photo_texture`), recoloured so that the texture lies only where the
    input camera's rays enter or leave the object: base = s t + (1 − s) m, s = :func:`surface_weight`
    of G's density, m the ``inner`` colour, and c = σ(ℓ + logit base). ``inner`` is the photos' mean
    colour ``(B, 3)`` or, with ``model.texture_blur``, a colour per voxel ``(B, 3, R, R, R)``: the
    photo blurred, carried along the same rays (:func:`photo_texture`). Inside, where no view of the
    input camera's line reaches, G offsets from it, so the photo's pixels do not run through the
    body as streaks seen from the side."""
    s = surface_weight(volume[:, 3:], elevation)
    m = inner.to(volume)
    m = m[:, :, None, None, None] if m.dim() == 2 else m                # one colour per photo, or per voxel
    return _coloured(volume, offsets, s * texture.to(volume) + (1.0 - s) * m)


def texture_on_sides(volume: torch.Tensor, offsets: torch.Tensor, texture: torch.Tensor,
                     sides: Tuple[torch.Tensor, torch.Tensor],
                     elevation: Optional[torch.Tensor] = None) -> torch.Tensor:
    """``model.texture_sides``: the volume G made with offsets ℓ from the photos' ``texture`` t
    (:func:`photo_texture`), recoloured so that the object's left and right sides carry the photo
    as seen from there, ``sides`` = (t_left, t_right) (:func:`photo_texture_sides`). With the
    transmittances of G's density out of each voxel (:func:`transmittances`),

        f = min(1, T_front + T_back)                     seen along the input camera's line
        u = min(1, T_left + T_right)                     seen from its left or right
        w_left = u (1 − f) T_left / max(T_left + T_right, 10⁻⁶),   w_right likewise
        base = (1 − w_left − w_right) t + w_left t_left + w_right t_right,    c = σ(ℓ + logit base)

    A voxel the input camera's line sees keeps the photo's pixel (w = 0 where f = 1), so the input
    view is :func:`photo_texture`'s; one that only a side camera sees takes that side's photo
    (w_left + w_right = 1 where f = 0 and u = 1); inside (u = 0) the input rays' colour stays.
    The weights are made in the input camera's frame and tilted back into G's (trilinear, so
    w_left + w_right ≤ 1 still). Why: seen from 90°, the input rays' colour runs across the object
    as horizontal streaks (docs/training.md, "The photo on the sides")."""
    front, back, left, right = transmittances(volume[:, 3:], elevation)
    f = (front + back).clamp(max=1.0)
    u = (left + right).clamp(max=1.0)
    w = u * (1.0 - f) / (left + right).clamp_min(1e-6)         # w T_left / (T_left + T_right) = w_left, …
    w_left, w_right = _in_g_frame(w * left, elevation), _in_g_frame(w * right, elevation)
    t_left, t_right = (t.to(volume) for t in sides)
    return _coloured(volume, offsets, (1.0 - w_left - w_right) * texture.to(volume) + w_left * t_left
                     + w_right * t_right)


def texture_corrected(conv: nn.Module, volume: torch.Tensor, offsets: torch.Tensor, texture: torch.Tensor,
                      elevation: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, torch.Tensor]:
    """``model.texture_conv``: (volume, ℓ') of the volume G made with offsets ℓ from the photos'
    ``texture`` t (:func:`photo_texture`, ``(B, 3, R, R, R)``), its logits corrected by ``conv``
    (G's :attr:`~mitsuba_platonic.models.Generator.texture_conv`, a 3³ convolution, 8 channels
    to 4):

        x = [ℓ, logit ρ, logit t, T_front]                      (3 + 1 + 3 + 1 channels per voxel)
        [δ_c, δ_ρ] = conv(x)
        colour = σ(ℓ + δ_c + logit t),   ρ' = σ(logit ρ + δ_ρ),   ℓ' = ℓ + δ_c

    with ρ G's density and T_front the transmittance from each voxel towards the input camera
    (:func:`transmittances` of ρ, held constant, in G's frame). G's own offsets see only the
    code, so they cannot tell where the texture carried along the input camera's rays runs
    through the body as streaks seen from the side; the convolution sees the texture, its
    neighbours and how deep behind what the camera sees each voxel lies. ℓ' is the whole offset
    from the photo's colour (``train.colour_offset`` penalises it)."""
    ρ = volume[:, 3:]
    front = _in_g_frame(transmittances(ρ, elevation)[0], elevation)
    t = torch.logit(texture.to(volume).clamp(COLOUR_MIN, 1.0 - COLOUR_MIN))
    logit_ρ = torch.logit(ρ.clamp(1e-6, 1.0 - 1e-6))            # G's own density logit (ρ is its sigmoid)
    x = torch.cat([offsets, logit_ρ, t, front], dim=1).contiguous(memory_format=torch.channels_last_3d)
    δ = conv(x).float()
    logits = torch.cat([offsets + t, logit_ρ], dim=1) + δ
    return torch.sigmoid(logits).contiguous(), offsets + δ[:, :3]


def photo_volume(G: nn.Module, code: torch.Tensor, images: torch.Tensor, recipe: Any,
                 elevation: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, torch.Tensor]:
    """(volume, ℓ) of a ``photo_colour`` G (or its data-parallel wrapper) for ``code`` and the
    ``images`` it encodes, by ``recipe`` (the model section of a config, or a
    :class:`~mitsuba_platonic.models.NetConfig`: its ``photo_texture``, ``texture_surface``,
    ``texture_blur``, ``texture_sides``, ``texture_conv`` and ``resolution``): G's colour offset from
    the photos' mean colour (:func:`photo_colour`) or, with ``photo_texture``, from their texture
    seen from ``elevation`` (:func:`photo_texture`), recoloured by :func:`texture_on_surface`
    (inside: the mean colour, or the photo blurred by ``texture_blur`` pixels) or by
    :func:`texture_on_sides`, or corrected by :func:`texture_corrected`; ℓ the offsets. The one
    recipe of training and of :meth:`~mitsuba_platonic.model.Model.reconstruct`."""
    mean = photo_colour(images)
    r = recipe.resolution
    t = photo_texture(images, r, elevation) if recipe.photo_texture else None
    v, ℓ = G(code, mean if t is None else t, offsets=True)
    if recipe.texture_surface:
        inner = photo_texture(images, r, elevation, blur=recipe.texture_blur) if recipe.texture_blur > 0 else mean
        v = texture_on_surface(v, ℓ, t, inner, elevation)
    elif recipe.texture_sides:
        v = texture_on_sides(v, ℓ, t, photo_texture_sides(images, r, elevation), elevation)
    elif recipe.texture_conv:
        conv = getattr(G, "module", G).texture_conv                # G, or the G inside a data-parallel wrapper
        v, ℓ = texture_corrected(conv, v, ℓ, t, elevation)
    return v, ℓ
