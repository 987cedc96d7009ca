"""GAN losses: non-saturating (the paper) and WGAN-GP, plus the discriminator accuracy gate.

Non-saturating (logits l):  L_D = softplus(−l_real) + softplus(l_fake)   (= −log D(x) − log(1 − D(G)))
                            L_G = softplus(−l_fake)                      (= −log D(G))
R1 (optional, non-saturating): L_D += γ/2 · mean over reals of ‖∇_x l(x)‖²  (Mescheder et al. 2018)
Colour TV (optional prior on G, EA volumes [r, g, b, ρ]): over every pair (i, j) of face-neighbouring
voxels, w_ij = min(ρ_i, ρ_j) (held constant) and
                            L_tv = Σ w_ij ‖c_i − c_j‖₁ / (3 Σ w_ij)
Colour offset (optional prior on G with model.photo_colour, offsets ℓ of its colour logits from the
photo's): with w = ρ held constant,
                            L_off = Σ w ‖ℓ‖₁ / (3 Σ w)
Colour match (optional prior on G, premultiplied RGBA images): the mean colour of an image's
object, c̄(I) = Σ_p rgb_p / Σ_p α_p, is the same from every side, so each random view I of the
reconstruction of photo x answers to
                            L_cm = mean over views and channels of |c̄(I) − c̄(x)|
Depth spread (optional prior on G's input view, EA volumes in the input camera's frame, depth along
dim 2 front to back): per ray, the weights w_k = T_k a_k of its N samples at depths s_k = (k + ½)/N
(T exclusive, as the EA layer), and the distortion loss of Barron et al. 2022 (Mip-NeRF 360)
                            L_ds = mean over rays of Σ_{k,l} w_k w_l |s_k − s_l| + (1/3N) Σ_k w_k²
small where a ray's colour comes from one thin surface, large where it is gathered over a thick haze
Turn (optional prior on G, upright volumes of ``train.pose: elevation``, dim 2 the depth along the input
view, dim 3 the vertical): the object is probably round about its vertical axis, so α and α turned by a random angle φ about the vertical
through the volume's centre, T_φ α (resampled trilinearly; φ uniform in [0, 2π), one per volume and
step), agree:
                            L_turn = Σ |α − T_φ α| / Σ (α + T_φ α)
0 for a volume that every turn leaves alone (a ball, a cylinder, a cone; up to the resampling's blur),
1 at most; it asks the object to be as deep as it is wide, where the photo alone leaves any depth
behind its surface free. A quarter turn alone is satisfied by a four-pointed star as well as by a disc
Solidity (optional prior on G, volumes in the input camera's frame as for the depth spread): along
each input ray the object is solid between its first and its last surface. With a ray's surfaces
m_l = α_l where α_l ≥ ½, else 0, and their hull h_k = min(max_{l≤k} m_l, max_{l≥k} m_l) (held
constant),
                            L_solid = Σ relu(h − α) / Σ h
0 where every ray's surfaces rise to one peak and fall (a solid body, a single shell, an empty
ray, a haze below ½), 1 at most; it fills the gap between a front shell and a back one and never
asks for matter beyond a ray's outermost surface. A haze is not a surface: filled, a haze of G's first steps would turn every ray into an opaque block, whose
saturated opacity no longer passes the input view's gradient back (a run that did so collapsed)
WGAN-GP:                    L_D = l_fake − l_real + λ (‖∇_x̂ D(x̂)‖ − 1)²,  x̂ = ε x + (1 − ε) G
                            L_G = −l_fake
Soft accuracy of D on a batch (the authors' gate: D is updated only while it is ≤ 0.6, so D
never runs away from G):

    acc = ½ (mean σ(l_real) + 1 − mean σ(l_fake))

It stays near ½ for an untrained D whose logits barely differ, and moves smoothly as D learns.
The *hard* share of correct signs, ½(mean[l_real > 0] + mean[l_fake < 0]), jumps to 0.75–1.0
on logits that differ by 1e-3, so a gate on it would block a D that has learnt nothing.
"""

from __future__ import annotations

from typing import Callable, Optional, Tuple

import torch
import torch.nn.functional as F

from ..render.pytorch.closed_form import transmittance_before

__all__ = ["d_loss", "g_loss", "gradient_penalty", "r1_penalty", "colour_tv", "colour_offset", "depth_spread", "turned", "turn", "solidity", "mean_colour", "colour_match", "soft_accuracy_counts", "hard_accuracy_counts"]


def d_loss(kind: str, real: torch.Tensor, fake: torch.Tensor) -> torch.Tensor:
    if kind == "nonsaturating":
        return F.softplus(-real).mean() + F.softplus(fake).mean()
    return fake.mean() - real.mean()


def g_loss(kind: str, fake: torch.Tensor) -> torch.Tensor:
    if kind == "nonsaturating":
        return F.softplus(-fake).mean()
    return -fake.mean()


def gradient_penalty(D: Callable[[torch.Tensor], torch.Tensor], real: torch.Tensor, fake: torch.Tensor,
                     eps: torch.Tensor) -> torch.Tensor:
    """(‖∇ D(x̂)‖₂ − 1)² averaged over the batch, x̂ = ε real + (1 − ε) fake, ε ∈ U[0, 1] per sample."""
    shape = (-1,) + (1,) * (real.dim() - 1)
    x = (eps.view(shape) * real + (1.0 - eps.view(shape)) * fake).requires_grad_(True)
    (grad,) = torch.autograd.grad(D(x).sum(), x, create_graph=True)
    return ((grad.flatten(1).norm(dim=1) - 1.0) ** 2).mean()


def r1_penalty(D: Callable[[torch.Tensor], torch.Tensor], real: torch.Tensor,
               fake: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, Optional[torch.Tensor], torch.Tensor]:
    """(logits D(x) at the reals x, logits D(fake) or None, mean over the reals of ‖∇ₓ D(x)‖₂²),
    differentiable in D's weights: the R1 penalty (times γ/2), which keeps D flat on the data so
    that a D that learns cannot sharpen into the steep boundary that makes G's gradients explode.

    One forward pass serves the logits of the loss and the penalty; with ``fake`` it runs over
    reals and fakes together (for a critic whose samples do not interact: no BatchNorm), and
    the penalty still differentiates the reals' logits alone."""
    x = real.detach().requires_grad_(True)
    if fake is None:
        logits, l_fake = D(x), None
    else:
        logits, l_fake = D(torch.cat([x, fake])).split([len(x), len(fake)])
    (grad,) = torch.autograd.grad(logits.sum(), x, create_graph=True)
    return logits, l_fake, grad.flatten(1).pow(2).sum(1).mean()


def colour_tv(volume: torch.Tensor) -> torch.Tensor:
    """The density-weighted total variation of an EA volume's colour (formula above): the mean
    absolute colour step between neighbouring voxels where *both* hold matter.

    Where the input view cannot see (behind the visible surface, T ≈ 0) nothing else constrains
    colour but the critic; this prior carries the visible colour into the body instead of leaving
    it to G's noise. The weights are detached: the term moves colour, never density (it cannot
    be lowered by emptying the volume). Empty regions (w = 0) cost nothing; a volume without
    matter gives 0."""
    if volume.dim() != 5 or volume.shape[1] != 4:
        raise ValueError(f"colour_tv: expected an EA volume (B, 4, D, H, W), got {tuple(volume.shape)}")
    c, ρ = volume[:, :3], volume[:, 3:].detach()
    num = volume.new_zeros(())
    den = volume.new_zeros(())
    for axis in (2, 3, 4):
        n = volume.shape[axis]
        w = torch.minimum(ρ.narrow(axis, 0, n - 1), ρ.narrow(axis, 1, n - 1))       # both voxels dense
        step = (c.narrow(axis, 0, n - 1) - c.narrow(axis, 1, n - 1)).abs().sum(1, keepdim=True)
        num = num + (w * step).sum()
        den = den + w.sum()
    return num / (3.0 * den).clamp_min(1e-12)


def colour_offset(volume: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """L_off (module docstring): the density-weighted mean |ℓ| of G's colour offsets ``offsets``
    ``(B, 3, D, H, W)`` from the photo's colour, over an EA volume ``(B, 4, D, H, W)`` whose density
    weighs each voxel (held constant: the term moves colour, never density). The colour of matter
    stays the photo's unless the views need otherwise; a saturated fleck (|ℓ| large) costs most.
    A volume without matter gives 0."""
    if volume.dim() != 5 or volume.shape[1] != 4 or offsets.shape != (volume.shape[0], 3, *volume.shape[2:]):
        raise ValueError(f"colour_offset: expected an EA volume (B, 4, D, H, W) and offsets (B, 3, D, H, W), got "
                         f"{tuple(volume.shape)} and {tuple(offsets.shape)}")
    w = volume[:, 3:].detach()
    return (w * offsets.abs()).sum() / (3.0 * w.sum()).clamp_min(1e-12)


def depth_spread(camera_volume: torch.Tensor) -> torch.Tensor:
    """L_ds (module docstring) of volumes ``(B, C, N, H, W)`` in a camera's frame (the opacity the last
    channel, dim 2 the depth from the front): the mean over the H·W rays of the distortion of their
    EA weights. Zero for empty rays; for a ray stopped by one opaque voxel 1/(3N); for weights spread
    over depth it grows with their spread. The pairwise sum in O(N) per ray, with W_k = Σ_{l<k} w_l
    and S_k = Σ_{l<k} w_l s_l: Σ_{k,l} w_k w_l |s_k − s_l| = 2 Σ_k w_k (s_k W_k − S_k)."""
    if camera_volume.dim() != 5:
        raise ValueError(f"depth_spread: expected volumes (B, C, N, H, W), got {tuple(camera_volume.shape)}")
    a = camera_volume[:, -1]
    n = a.shape[1]
    τ = 1.0 - a
    T = transmittance_before(τ, 1)                      # exclusive: Π_{l<k}, as the EA layer
    w = T * a
    s = ((torch.arange(n, dtype=a.dtype, device=a.device) + 0.5) / n)[None, :, None, None]
    W = torch.cumsum(w, dim=1) - w                      # Σ_{l<k} w_l
    S = torch.cumsum(w * s, dim=1) - w * s              # Σ_{l<k} w_l s_l
    pairs = 2.0 * (w * (s * W - S)).sum(dim=1)
    return (pairs + (w * w).sum(dim=1) / (3.0 * n)).mean()


def turned(volume: torch.Tensor, φ: torch.Tensor) -> torch.Tensor:
    """``volume`` ``(B, C, N, H, N)`` turned by φ ``(B,)`` radians about the vertical through its
    centre, resampled trilinearly (nothing from beyond the cube): the value at p is the volume's at
    p' in grid coordinates (x, y, z) ↔ (w, h, d), each in [−1, 1]:

        x' = cos φ x − sin φ z,   z' = sin φ x + cos φ z,   y' = y

    so a positive quarter turn takes the front (d = 0, nearest the camera) to the left (w = 0).

    A quarter turn maps voxel centres onto voxel centres: exact, as :func:`torch.rot90`."""
    b = volume.shape[0]
    c, s = torch.cos(φ).to(volume), torch.sin(φ).to(volume)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    # grid_sample's coordinates are (x, y, z) ↔ (w, h, d); the affine grid maps output to input
    rows = torch.stack([torch.stack([c, zero, -s, zero], -1),
                        torch.stack([zero, one, zero, zero], -1),
                        torch.stack([s, zero, c, zero], -1)], 1)          # (B, 3, 4)
    grid = F.affine_grid(rows, list(volume.shape), align_corners=False)
    return F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def turn(volume: torch.Tensor, φ: torch.Tensor) -> torch.Tensor:
    """L_turn (module docstring) of upright volumes ``(B, C, N, N, N)`` (the opacity the last channel,
    dims 2, 3, 4 depth, height, width) turned by φ ``(B,)`` radians about the vertical through the
    volume's centre (:func:`turned`): over the whole batch, Σ |α − T_φ α| / Σ (α + T_φ α); in [0, 1],
    0 where the volume is empty."""
    if volume.dim() != 5 or volume.shape[2] != volume.shape[4]:
        raise ValueError(f"turn: expected upright volumes (B, C, N, H, N), got {tuple(volume.shape)}")
    if φ.shape != (volume.shape[0],):
        raise ValueError(f"turn: expected one angle per volume, shape ({volume.shape[0]},), got {tuple(φ.shape)}")
    a = volume[:, -1:]
    t = turned(a, φ)
    return (a - t).abs().sum() / (a + t).sum().clamp_min(1e-12)


#: The opacity from which a voxel counts as a surface for :func:`solidity`.
SURFACE = 0.5


def solidity(camera_volume: torch.Tensor) -> torch.Tensor:
    """L_solid (module docstring) of volumes ``(B, C, N, H, W)`` in a camera's frame (the opacity the
    last channel, dim 2 the depth from the front): over the whole batch, the opacity missing below
    the hull of each ray's surfaces (α ≥ :data:`SURFACE`), Σ relu(h − α) / Σ h; in [0, 1], 0 for a
    volume without surfaces. The hull is held constant: the term raises the gaps, never lowers the
    walls."""
    if camera_volume.dim() != 5:
        raise ValueError(f"solidity: expected volumes (B, C, N, H, W), got {tuple(camera_volume.shape)}")
    a = camera_volume[:, -1]
    with torch.no_grad():
        m = torch.where(a >= SURFACE, a, torch.zeros_like(a))         # the surfaces: a haze is none
        front = torch.cummax(m, dim=1).values                         # max_{l≤k} m_l
        back = torch.cummax(m.flip(1), dim=1).values.flip(1)          # max_{l≥k} m_l
        hull = torch.minimum(front, back)
    return torch.relu(hull - a).sum() / hull.sum().clamp_min(1e-12)


def mean_colour(images: torch.Tensor) -> torch.Tensor:
    """c̄(I) = Σ_p rgb_p / Σ_p α_p ``(B, 3)`` of premultiplied RGBA images ``(B, 4, H, W)``: the mean
    colour of the object, each pixel weighted by its coverage (0 for an empty image)."""
    if images.dim() != 4 or images.shape[1] != 4:
        raise ValueError(f"mean_colour: expected RGBA images (B, 4, H, W), got {tuple(images.shape)}")
    return images[:, :3].sum((2, 3)) / images[:, 3:].sum((2, 3)).clamp_min(1e-6)


def colour_match(views: torch.Tensor, photos: torch.Tensor) -> torch.Tensor:
    """L_cm = mean |c̄(I) − c̄(x)| (module docstring) of ``views`` ``(B K, 4, H, W)``, K renders per
    photo of ``photos`` ``(B, 4, H, W)`` in order; the photos' colours are targets (detached).

    An object seen from its other side is no darker and no other hue on average: this carries the
    photo's colour to the sides the input view does not see, where otherwise only the critic,
    which accepts any plausible colour, constrains it."""
    k = len(views) // max(len(photos), 1)
    if len(photos) == 0 or k * len(photos) != len(views):
        raise ValueError(f"colour_match: expected K renders per photo, got {len(views)} for {len(photos)}")
    target = mean_colour(photos.detach()).repeat_interleave(k, 0)
    return (mean_colour(views) - target).abs().mean()


def soft_accuracy_counts(real: torch.Tensor, fake: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """(Σ σ(l_real) + Σ (1 − σ(l_fake)), count) as float tensors, summable across processes.

    Their ratio is the soft accuracy ½(mean σ(l_real) + 1 − mean σ(l_fake)) when both halves have
    the same size (they do in the trainer); otherwise it weighs each logit equally.
    """
    score = torch.sigmoid(real).sum() + (1.0 - torch.sigmoid(fake)).sum()
    return score.detach().float(), torch.tensor(float(real.numel() + fake.numel()))


def hard_accuracy_counts(real: torch.Tensor, fake: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """(correct signs, count): the share of real logits > 0 and fake logits < 0 (reported, not gated on)."""
    correct = (real > 0).float().sum() + (fake < 0).float().sum()
    return correct, torch.tensor(float(real.numel() + fake.numel()))
