"""Networks of PlatonicGAN: encoder E (image → z), generator G (z → volume), discriminators.

Shapes follow the authors' code (docs/paper.md, "Networks"), parameterised so that a CPU run
can use 16³ or 32³ and narrow widths while a GPU run uses the paper's 64³ (``configs/paper.yaml``):

- G (3D-GAN style): z (with ``view_codes`` > 0: z and a view code, the PrGAN-style baseline's
  input) → ConvTranspose3d(k4, s1) to 4³ → (k4, s2, p1) stages doubling the
  resolution and halving the width, the last one to C channels at R³ → sigmoid.
  At R = 64 and width 64: 512 → 256 → 128 → 64 → C, as in the paper. With ``upsample:
  resize`` each (k4, s2, p1) transposed convolution becomes a nearest ×2 upsampling and a k3
  convolution (no period-2 checkerboard); with ``resize_last`` only the last one does.
- D (2D): Conv2d(k4, s2, p1) stages from R² down to 4², doubling the width (64 → 128 → 256 → 512
  at R = 64), LeakyReLU 0.2, then Conv2d(k4) to one logit.
- E: D's trunk, then Linear → z; or, with ``encoder_hidden`` = H > 0, the authors' head:
  Conv2d(k4) from 4² to an H-wide 1² layer, norm, LeakyReLU 0.2, then Linear(H → z)
  (their encoder: H = 1024, Linear(1024 → 200)).
- D3 (3D, for Platonic3D and the 3D-GAN baseline): D's trunk in 3D.

``norm`` = 'batch' (the paper), 'instance' or 'none' (no batch statistics: then data-parallel
training with half the batch per process makes exactly the single-process update).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import ContextManager, List, Optional, Tuple, Union

import torch
import torch.nn.functional as F
from torch import nn

from ..render.pytorch.single_scatter import SKY_SHARE
from .net_settings import NetSettings
from .photo_colours import COLOUR_MIN

__all__ = ["NORMS", "UPSAMPLES", "INITS", "PRECISIONS", "NetConfig", "Encoder", "Generator", "Discriminator",
           "VolumeDiscriminator", "PoseHead", "LightHead", "ResizeConv3d", "init_weights", "init_critic_he", "init_he"]

NORMS = ("batch", "instance", "none")
#: How G doubles its resolution: the paper's transposed convolution (k4, s2, p1), or a nearest
#: upsampling followed by a k3 convolution, which cannot make a transposed convolution's
#: period-2 checkerboard (Odena, Dumoulin and Olah 2016), in every stage ('resize') or only in
#: the last one ('resize_last': the checkerboard at R³ comes from it, and the k3 convolutions
#: at full resolution are what makes 'resize' slow).
UPSAMPLES = ("transposed", "resize", "resize_last")
RESOLUTIONS = (16, 32, 64, 128)
#: How a network starts (``model.critic_init`` for D and D3, ``model.init`` for E and G): the
#: DCGAN initialisation of every network (:func:`init_weights`), or He's (:func:`init_critic_he`
#: for the critics, :func:`init_he` for E and G).
INITS = ("dcgan", "he")
#: The networks' arithmetic (``model.precision``): float32 throughout, or their convolutions and
#: matrix products in bfloat16 under :func:`torch.autocast` (weights, optimiser state and every
#: network's output stay float32; the renderers never see bfloat16). bfloat16 keeps float32's range
#: with an 8-bit mantissa: on a CPU with AVX-512 BF16 (or a GPU) the paper-scale step is 1.5×
#: faster; what it does to training is measured in docs/training.md, "Speed".
PRECISIONS = ("fp32", "bf16")


def arithmetic(precision: str, x: torch.Tensor) -> ContextManager:
    """The context a network computes in (:data:`PRECISIONS`): autocast to bfloat16 on ``x``'s
    device for 'bf16', nothing for 'fp32'."""
    if precision == "bf16":
        return torch.autocast(x.device.type, dtype=torch.bfloat16)
    return contextlib.nullcontext()


@dataclass
class NetConfig(NetSettings):
    """E's, G's and the critics' configuration: the shapes and arithmetic of :class:`~.net_settings.NetSettings`
    (its fields, defaults and their documentation, which the config's model section shares), and what
    the config's other sections decide, one line per key:

    volume_channels: the channels of G's volumes, 1 (density) or 4 (colour and density).
    image_channels: the channels of the images E and D read, 1 or 4.
    view_codes: the length of a view code appended to z as G's input (the PrGAN-style baseline,
    ``train.mode: prgan``: a one-hot of one of 8 ring views); 0: none, G sees z only.
    pose: whether a :class:`PoseHead` reads the input camera's elevation from z (``train.pose: elevation``).
    light: whether a :class:`LightHead` reads the photo's light from z (``train.light: head``).

    A config's model section builds it (:meth:`~mitsuba_platonic.networks.settings.ModelConfig.net_config`)."""

    volume_channels: int = 4
    image_channels: int = 4
    view_codes: int = 0
    pose: bool = False
    light: bool = False

    def validate(self) -> "NetConfig":
        if self.resolution not in RESOLUTIONS:
            raise ValueError(f"resolution must be one of {RESOLUTIONS}, got {self.resolution!r}")
        if self.volume_channels not in (1, 4) or self.image_channels not in (1, 4):
            raise ValueError(f"volume/image channels must be 1 or 4, got "
                             f"{self.volume_channels!r}/{self.image_channels!r}")
        if not isinstance(self.latent, int) or self.latent < 1:
            raise ValueError(f"latent must be a positive int, got {self.latent!r}")
        if not isinstance(self.width, int) or self.width < 1:
            raise ValueError(f"width must be a positive int, got {self.width!r}")
        if self.norm not in NORMS:
            raise ValueError(f"norm must be one of {NORMS}, got {self.norm!r}")
        if self.upsample not in UPSAMPLES:
            raise ValueError(f"upsample must be one of {UPSAMPLES}, got {self.upsample!r}")
        if not isinstance(self.encoder_hidden, int) or self.encoder_hidden < 0:
            raise ValueError(f"encoder_hidden must be a non-negative int, got {self.encoder_hidden!r}")
        if not isinstance(self.view_codes, int) or self.view_codes < 0:
            raise ValueError(f"view_codes must be a non-negative int, got {self.view_codes!r}")
        if not isinstance(self.pose, bool):
            raise ValueError(f"pose must be True or False, got {self.pose!r}")
        if not isinstance(self.light, bool):
            raise ValueError(f"light must be True or False, got {self.light!r}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")
        if not isinstance(self.photo_colour, bool):
            raise ValueError(f"photo_colour must be True or False, got {self.photo_colour!r}")
        if self.photo_colour and self.volume_channels != 4:
            raise ValueError("photo_colour needs colour: volume_channels 4")
        if not isinstance(self.photo_texture, bool) or (self.photo_texture and not self.photo_colour):
            raise ValueError(f"photo_texture must be True or False, and True only with photo_colour; got "
                             f"{self.photo_texture!r} (photo_colour {self.photo_colour!r})")
        if not isinstance(self.texture_conv, bool) or (self.texture_conv and not self.photo_texture):
            raise ValueError(f"texture_conv must be True or False, and True only with photo_texture; got "
                             f"{self.texture_conv!r} (photo_texture {self.photo_texture!r})")
        if self.texture_turns not in (1, 4):
            raise ValueError(f"texture_turns must be 1 or 4, got {self.texture_turns!r}")
        if not isinstance(self.offsets_behind, bool) or (not self.offsets_behind and self.texture_turns != 4):
            raise ValueError(f"offsets_behind must be True or False, and False only with texture_turns 4; got "
                             f"{self.offsets_behind!r} (texture_turns {self.texture_turns!r})")
        return self

    @property
    def stages(self) -> int:
        """Number of ×2 resolution steps between 4 and R."""
        return int(math.log2(self.resolution)) - 2


def _norm(kind: str, channels: int, dims: int) -> nn.Module:
    if kind == "batch":
        return (nn.BatchNorm2d if dims == 2 else nn.BatchNorm3d)(channels)
    if kind == "instance":
        return (nn.InstanceNorm2d if dims == 2 else nn.InstanceNorm3d)(channels, affine=True)
    return nn.Identity()


def _trunk(cfg: NetConfig, in_channels: int, dims: int) -> nn.Sequential:
    """Strided k4 s2 p1 convolutions R → 4, widths width·2^i; no norm on the first layer."""
    conv = nn.Conv2d if dims == 2 else nn.Conv3d
    layers: List[nn.Module] = []
    c_in = in_channels
    for i in range(cfg.stages):
        c_out = cfg.width * 2 ** i
        layers += [conv(c_in, c_out, 4, 2, 1, bias=(i == 0 or cfg.norm == "none"))]
        if i > 0:
            layers += [_norm(cfg.norm, c_out, dims)]
        layers += [nn.LeakyReLU(0.2, inplace=True)]
        c_in = c_out
    return nn.Sequential(*layers)


class ResizeConv3d(nn.Conv3d):
    """A nearest ×2 upsampling followed by this k3, s1, p1 convolution (G's ``resize`` stage),
    computed as the one k4, s2, p1 transposed convolution that equals it.

    Along one axis the upsampled input is u[j] = x[⌊j/2⌋], so with the k3 taps (w₀, w₁, w₂)

        out[2i]     = w₀ x[i−1] + (w₁ + w₂) x[i]
        out[2i + 1] = (w₀ + w₁) x[i] + w₂ x[i+1],

    which is the transposed convolution out[o] = Σᵢ x[i] k[o + 1 − 2i] with the k4 kernel
    k = (w₂, w₁ + w₂, w₀ + w₁, w₀) = T w. In 3D, k = T ⊗ T ⊗ T applied to the k3 weight, and zero
    padding of the upsampled grid is zero padding of x. The parameters (so initialisation,
    :func:`fan_in`, checkpoints and their gradients) stay the k3 convolution's; the work is a
    transposed convolution's at the input's resolution instead of 27 taps per output at twice it:
    4× faster forward and backward for G's last stage at 32³ (docs/training.md, "Speed"). The
    sums of taps keep the k3 form's smoothness: no period-2 checkerboard.
    """

    def __init__(self, c_in: int, c_out: int, bias: bool):
        super().__init__(c_in, c_out, 3, 1, 1, bias=bias)
        # T: rows are the k4 taps, columns the k3 ones they sum (not saved: a constant of the layer)
        self.register_buffer("taps", torch.tensor([[0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
                             persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        T = self.taps.to(self.weight.dtype)
        k = torch.einsum("ak,bl,cm,oiklm->ioabc", T, T, T, self.weight)   # (c_in, c_out, 4, 4, 4), transposed layout
        if x.is_contiguous(memory_format=torch.channels_last_3d):
            k = k.contiguous(memory_format=torch.channels_last_3d)          # oneDNN's fast layout, as the input's
        return nn.functional.conv_transpose3d(x, k, self.bias, stride=2, padding=1)


def _up(kind: str, c_in: int, c_out: int, bias: bool) -> List[nn.Module]:
    """One ×2 stage of G (:data:`UPSAMPLES`). A resize stage keeps two slots (the first, empty,
    was its upsampling), so the indices of G's layers, and of checkpoints' keys, stay as they were."""
    if kind == "transposed":
        return [nn.ConvTranspose3d(c_in, c_out, 4, 2, 1, bias=bias)]
    return [nn.Identity(), ResizeConv3d(c_in, c_out, bias=bias)]


class Generator(nn.Module):
    """G: ``(B, latent + view_codes)`` → ``(B, C, R, R, R)`` volume in (0, 1) (sigmoid), contiguous.
    Its weights and activations are channels-last (N, D, H, W, C in memory)."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg.validate()
        top = cfg.width * 2 ** (cfg.stages - 1)
        layers: List[nn.Module] = [nn.ConvTranspose3d(cfg.latent + cfg.view_codes, top, 4, 1, 0, bias=cfg.norm == "none"),
                                   _norm(cfg.norm, top, 3), nn.ReLU(inplace=True)]
        c = top
        inner = "transposed" if cfg.upsample == "resize_last" else cfg.upsample
        for _ in range(cfg.stages - 1):
            layers += [*_up(inner, c, c // 2, bias=cfg.norm == "none"),
                       _norm(cfg.norm, c // 2, 3), nn.ReLU(inplace=True)]
            c //= 2
        last = "resize" if cfg.upsample == "resize_last" else cfg.upsample
        layers += [*_up(last, c, cfg.volume_channels, bias=True), nn.Sigmoid()]
        self.net = nn.Sequential(*layers)
        #: ``texture_conv``: the correction of G's logits that sees the photo's texture, 8 channels in,
        #: the 4 logits out; applied by :func:`~mitsuba_platonic.networks.photo_colours.photo_volume`
        #: (:func:`~mitsuba_platonic.networks.photo_colours.texture_corrected`), not by :meth:`forward`, since it
        #: needs the input camera's elevation
        self.texture_conv: Optional[nn.Conv3d] = nn.Conv3d(8, 4, 3, padding=1) if cfg.texture_conv else None
        # channels-last 3D weights and activations: oneDNN's 3D convolutions on a CPU run about twice
        # as fast in this layout (docs/training.md, "Speed"); the maths is the same
        self.to(memory_format=torch.channels_last_3d)

    def init_density(self) -> None:
        """Start from a uniform, half-transparent volume: the density output's bias is logit(v₀)
        with v₀ = 1/R (colour biases 0: colour ½), so a ray through the cube has optical depth
        ≈ 1 in every image formation: VH 1 − e⁻¹, AO/EA 1 − (1 − 1/R)^R ≈ 0.63.

        With a zero bias (v₀ = ½) every ray starts opaque (VH 1 − e^(−R/2), AO/EA 1 − 2^(−R)), the
        opacity's gradient w.r.t. a voxel is ≈ e^(−R/2) or 2^(−R), and once Adam's first large
        steps come the generator can overshoot to an empty volume with its sigmoid saturated,
        where it stays: the VH baseline (reconstruction loss 0.136 after 200 steps, empty images;
        0.031 from v₀ = 1/R) and EA on path-traced images (0.049 after 400 steps, empty; 0.0077).
        Measured in docs/training.md, "The measurements".
        """
        out = self.convolutions()[-1]
        v0 = 1.0 / self.cfg.resolution
        with torch.no_grad():
            out.bias[-1] = math.log(v0 / (1.0 - v0))

    def convolutions(self) -> List[nn.Module]:
        """G's (transposed) convolutions, input first; the last one gives the volume."""
        return [m for m in self.net if isinstance(m, (nn.Conv3d, nn.ConvTranspose3d))]

    def forward(self, z: torch.Tensor, colour: Optional[torch.Tensor] = None,
                offsets: bool = False) -> Union[torch.Tensor, Tuple[torch.Tensor, torch.Tensor]]:
        """The volume for codes ``z``. With ``photo_colour`` (and only then) ``colour`` is the input
        photos' mean colour m ``(B, 3)`` (:func:`~mitsuba_platonic.networks.photo_colours.photo_colour`) or a
        colour per voxel m ``(B, 3, R, R, R)`` (:func:`~mitsuba_platonic.networks.photo_colours.photo_texture`),
        and G's colour logits are offsets from it:
        c = σ(ℓ + logit m) per channel, the density's σ(ℓ) as always. A colour the encoder has not
        learnt (an orange tree among green ones) is then still the photo's, and an untrained G's
        colour (ℓ ≈ 0) starts at m instead of grey. With ``offsets`` it returns (volume, ℓ), the
        colour offsets ``(B, 3, R, R, R)`` float32 (``train.colour_offset`` penalises them)."""
        n = self.cfg.latent + self.cfg.view_codes
        if z.dim() != 2 or z.shape[1] != n:
            what = f"z and a view code, (B, {self.cfg.latent} + {self.cfg.view_codes})" if self.cfg.view_codes \
                else f"z of shape (B, {n})"
            raise ValueError(f"G expects {what}, got {tuple(z.shape)}")
        if self.cfg.photo_colour != (colour is not None):
            raise ValueError("G was built with photo_colour and needs the photos' mean colour (B, 3)"
                             if self.cfg.photo_colour else "G was built without photo_colour: it takes no colour")
        r = self.cfg.resolution
        if colour is not None and colour.shape not in ((z.shape[0], 3), (z.shape[0], 3, r, r, r)):
            raise ValueError(f"G expects the photos' mean colour of shape ({z.shape[0]}, 3), or a colour per voxel "
                             f"({z.shape[0]}, 3, {r}, {r}, {r}), got {tuple(colour.shape)}")
        x = z[:, :, None, None, None].contiguous(memory_format=torch.channels_last_3d)
        with arithmetic(self.cfg.precision, z):
            logits = self.net[:-1](x)                       # everything but the final sigmoid
        logits = logits.float()
        ℓ = logits[:, :3]                                   # the colour offsets (models without colour: unused)
        if colour is not None:
            m = colour.to(logits).clamp(COLOUR_MIN, 1.0 - COLOUR_MIN)
            m = m[:, :, None, None, None] if m.dim() == 2 else m
            offset = torch.cat([torch.logit(m), m.new_zeros(m.shape[0], 1, *m.shape[2:])], dim=1)   # density: none
            logits = logits + offset
        v = torch.sigmoid(logits).contiguous()              # float32, in the usual layout for the renderers
        return (v, ℓ) if offsets else v


class Discriminator(nn.Module):
    """D: ``(B, C, R, R)`` image → ``(B,)`` logit."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg.validate()
        self.trunk = _trunk(cfg, cfg.image_channels, 2)
        self.head = nn.Conv2d(cfg.width * 2 ** (cfg.stages - 1), 1, 4)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r, c = self.cfg.resolution, self.cfg.image_channels
        if x.dim() != 4 or x.shape[1:] != (c, r, r):
            raise ValueError(f"D expects images (B, {c}, {r}, {r}), got {tuple(x.shape)}")
        with arithmetic(self.cfg.precision, x):
            return self.head(self.trunk(x)).flatten().float()


class VolumeDiscriminator(nn.Module):
    """D3: ``(B, C, R, R, R)`` volume → ``(B,)`` logit (Platonic3D, 3D-GAN baseline)."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg.validate()
        self.trunk = _trunk(cfg, cfg.volume_channels, 3)
        self.head = nn.Conv3d(cfg.width * 2 ** (cfg.stages - 1), 1, 4)

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        r, c = self.cfg.resolution, self.cfg.volume_channels
        if v.dim() != 5 or v.shape[1:] != (c, r, r, r):
            raise ValueError(f"D3 expects volumes (B, {c}, {r}, {r}, {r}), got {tuple(v.shape)}")
        with arithmetic(self.cfg.precision, v):
            return self.head(self.trunk(v)).flatten().float()


class Encoder(nn.Module):
    """E: ``(B, C, R, R)`` image → ``(B, latent)`` code.

    With ``encoder_hidden`` = H > 0 a k4 convolution maps the trunk's 4² output to H channels
    at 1² (norm, LeakyReLU) before the Linear(H → latent). With BatchNorm that layer normalises
    one value per channel and sample, so a training-mode forward needs at least 2 images.
    """

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg.validate()
        self.trunk = _trunk(cfg, cfg.image_channels, 2)
        top = cfg.width * 2 ** (cfg.stages - 1)
        if cfg.encoder_hidden:
            h = cfg.encoder_hidden
            self.hidden = nn.Sequential(nn.Conv2d(top, h, 4, 1, 0, bias=cfg.norm == "none"),
                                        _norm(cfg.norm, h, 2), nn.LeakyReLU(0.2, inplace=True))
            self.head = nn.Linear(h, cfg.latent)
        else:
            self.hidden = nn.Identity()
            self.head = nn.Linear(top * 16, cfg.latent)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r, c = self.cfg.resolution, self.cfg.image_channels
        if x.dim() != 4 or x.shape[1:] != (c, r, r):
            raise ValueError(f"E expects images (B, {c}, {r}, {r}), got {tuple(x.shape)}")
        with arithmetic(self.cfg.precision, x):
            return self.head(self.hidden(self.trunk(x)).flatten(1)).float()


class PoseHead(nn.Module):
    """P: E's code z ``(B, latent)`` → the input camera's elevation θ̂ ``(B,)`` in radians,

        θ̂ = (π/2) · tanh(w · z + b)

    so θ̂ ∈ (−90°, 90°), the range of an upright camera's elevation. w and b start at 0 (every
    estimate 0°: the reconstruction starts as a view-space model's) and are plain parameters, not
    a Linear layer, so no network initialisation (:func:`init_weights`, :func:`init_he`) redraws
    them. ``train.pose: elevation`` (:mod:`mitsuba_platonic.train.trainer`) trains it.
    """

    def __init__(self, latent: int):
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(latent))
        self.bias = nn.Parameter(torch.zeros(()))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        if z.dim() != 2 or z.shape[1] != self.weight.shape[0]:
            raise ValueError(f"P expects codes (B, {self.weight.shape[0]}), got {tuple(z.shape)}")
        return (math.pi / 2) * torch.tanh(z @ self.weight + self.bias)



class LightHead(nn.Module):
    """L: E's code z ``(B, latent)`` → the light of the photo it encodes, as the single-scattering
    formation's grey daylight (:func:`~mitsuba_platonic.render.pytorch.single_scatter.daylights`): the sun's
    direction in the *camera's* frame (right, up, ω: the input camera's frame is the world's) and the
    sky's share of the mean luminance,

        ω̂_s = u / |u|,   u = W_d z + b_d;        ŝ = s₀ + (s₁ − s₀) · sigmoid(w_s · z + b_s)

    with [s₀, s₁] the prior's range of shares (:data:`~mitsuba_platonic.render.pytorch.single_scatter.SKY_SHARE`).
    W and w start at 0 and b_d at (0, 1, 0), b_s at 0: every estimate starts as a sun straight
    above the camera and the prior's middle share. Plain parameters, as :class:`PoseHead`'s, so no
    network initialisation redraws them. ``train.light: head`` (:mod:`mitsuba_platonic.train.trainer`)
    teaches it the lights of G's own renders, whose lights are drawn from the prior and known.
    """

    def __init__(self, latent: int):
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(latent, 4))
        self.bias = nn.Parameter(torch.tensor([0.0, 1.0, 0.0, 0.0]))

    def forward(self, z: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """(ω̂_s ``(B, 3)`` unit vectors in the camera's frame, ŝ ``(B,)``)."""
        if z.dim() != 2 or z.shape[1] != self.weight.shape[0]:
            raise ValueError(f"L expects codes (B, {self.weight.shape[0]}), got {tuple(z.shape)}")
        u = z @ self.weight + self.bias
        d = u[:, :3] / u[:, :3].norm(dim=1, keepdim=True).clamp_min(1e-6)
        lo, hi = SKY_SHARE
        return d, lo + (hi - lo) * torch.sigmoid(u[:, 3])

def init_weights(m: nn.Module) -> None:
    """DCGAN initialisation: N(0, 0.02) weights, norm scales N(1, 0.02); G's output starts from
    the density 1/R (:meth:`Generator.init_density`)."""
    if isinstance(m, Generator):                   # ``apply`` reaches G after its layers
        m.init_density()
    elif isinstance(m, (nn.Conv2d, nn.Conv3d, nn.ConvTranspose3d, nn.Linear)):
        nn.init.normal_(m.weight, 0.0, 0.02)
        if m.bias is not None:
            nn.init.zeros_(m.bias)
    elif isinstance(m, (nn.BatchNorm2d, nn.BatchNorm3d, nn.InstanceNorm2d, nn.InstanceNorm3d)) and m.affine:
        nn.init.normal_(m.weight, 1.0, 0.02)
        nn.init.zeros_(m.bias)


def init_critic_he(m: nn.Module) -> None:
    """He (Kaiming) normal weights for LeakyReLU(0.2), zero biases, on a critic's convolutions
    (and E's, whose trunk is a critic's: :func:`init_he`).

    Without normalisation the DCGAN initialisation N(0, 0.02) shrinks activations by about
    0.02 √fan-in ≈ 0.3 a layer: an untrained D's logits have a standard deviation of 5e-4, and at
    lr_D 2e-5 it does not learn in thousands of steps (docs/training.md, "The measurements"). He's
    variance 2 / ((1 + 0.2²) fan-in) keeps them O(0.1).
    """
    if isinstance(m, (nn.Conv2d, nn.Conv3d, nn.Linear)):
        nn.init.kaiming_normal_(m.weight, a=0.2, nonlinearity="leaky_relu")
        if m.bias is not None:
            nn.init.zeros_(m.bias)


def fan_in(m: nn.Module) -> int:
    """How many inputs one output of layer ``m`` sums: in_features (Linear), c_in · k^d (a
    convolution, any stride), c_in · ⌈k/s⌉^d (a transposed convolution: of its k^d taps, every
    s-th along each axis meets an input), for an input larger than the kernel."""
    if isinstance(m, nn.Linear):
        return m.in_features
    taps = 1
    for k, s in zip(m.kernel_size, m.stride):
        taps *= -(-k // s) if isinstance(m, (nn.ConvTranspose2d, nn.ConvTranspose3d)) else k
    return m.in_channels * taps // m.groups


def init_he(net: nn.Module) -> None:
    """He's initialisation of E or G (``model.init: he``): weights N(0, g² / fan_in), zero biases,
    with the gain g of the next activation; then a layer's outputs keep their inputs' scale. E is
    built like a critic's trunk (strided convolutions, LeakyReLU(0.2)) and gets
    :func:`init_critic_he`; G gets g = √2 (ReLU) and fan_in from :func:`fan_in`.

    G's output layer keeps the DCGAN N(0, 0.02) and :meth:`Generator.init_density`: the first
    volume is still the fog of density 1/R, now varying with the input image. Without
    normalisation the DCGAN initialisation shrinks the signal by ≈ 0.02 √fan_in a layer: in the
    quickstart's E and G (width 16), the spread of G's last hidden layer over 16 images is 3e-6
    (0.08 with this initialisation), so every image starts with the same volume
    (docs/training.md, "The measurements").
    """
    if not isinstance(net, Generator):                       # E: strided convolutions and LeakyReLU(0.2),
        net.apply(init_critic_he)                            # a critic's trunk: the critics' He initialisation
        return
    layers = net.convolutions()[:-1]
    fans = [layers[0].in_channels] + [fan_in(m) for m in layers[1:]]   # the first maps z at 1³ to 4³: one tap
    with torch.no_grad():
        for m, fan in zip(layers, fans):
            m.weight.normal_(0.0, math.sqrt(2.0 / fan))       # gain √2 of the ReLU that follows
            if m.bias is not None:
                m.bias.zero_()
