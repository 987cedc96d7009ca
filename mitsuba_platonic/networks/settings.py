"""The model section of a config (``model:``): the networks' sizes, arithmetic and how they start.

:class:`ModelConfig` is the section's dataclass, beside the networks it configures
(:mod:`mitsuba_platonic.networks.nets`). Ten of its keys (:data:`NET_KEYS`) are the networks' own settings
(their shapes and arithmetic), :class:`~mitsuba_platonic.networks.nets.NetConfig`'s fields of the same names;
:meth:`ModelConfig.net_config` hands them over, with what the other sections decide (the
image formation's channels, the PrGAN view code, the pose head), so the two never disagree.
The other three (``init``, ``critic_init``, ``critic_width``) are training's: how the networks
start, and the critics' width. Imports no config: the config composes it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional

from ..settings_checks import ConfigError, choice, non_negative, positive
from .nets import INITS, NORMS, PRECISIONS, RESOLUTIONS, UPSAMPLES, NetConfig

__all__ = ["ModelConfig", "NET_KEYS"]

#: The model keys that :class:`~mitsuba_platonic.networks.nets.NetConfig` takes as they are.
NET_KEYS = ("resolution", "latent", "width", "norm", "encoder_hidden", "upsample", "precision", "photo_colour",
            "photo_texture", "texture_conv", "texture_turns", "offsets_behind")


@dataclass
class ModelConfig:
    """The model section, one line per key (why each default: docs/training.md, as named).

    resolution: volume and image size R (16 | 32 | 64 | 128).
    latent: the size of z.
    width: channels at the highest resolution (the paper: 64).
    norm: 'batch' (the paper's) | 'instance' | 'none' (the default: "What the numbers say").
    encoder_hidden: width of E's last layer before its Linear to z; 0: none (the authors': 1024, docs/paper.md).
    upsample: how G doubles its resolution, 'transposed' (the paper's k4 s2) | 'resize' (nearest ×2, k3).
    critic_init: how D and D3 start, 'dcgan' (N(0, 0.02)) | 'he' ("A discriminator that never learns").
    init: how E and G start, 'dcgan' (the paper's) | 'he' (scaled by fan-in: "E and G that start blind").
    critic_width: channels of D's and D3's first layer, doubling per stage; null: ``width`` (same section).
    precision: the networks' arithmetic, 'fp32' | 'bf16' (convolutions in bfloat16: "Where a step's time goes").
    photo_colour: G's colour as an offset from the input photo's mean colour (reconstruction, EA:
    "A colour read from the photo").
    photo_texture: with photo_colour, the offset is from the photo's own colour at each voxel's pixel,
    carried along the input camera's rays, not from its mean (:func:`~mitsuba_platonic.networks.photo_colours.photo_texture`).
    texture_conv: with photo_texture, G's last logits corrected by a 3³ convolution that sees the photo's
    colour, G's own logits and how much of each voxel the input camera sees
    (:func:`~mitsuba_platonic.networks.photo_colours.texture_corrected`; "G's colour seeing the photo").
    texture_turns: with texture_conv, 1: the photo carried along the input camera's rays; 4: behind what the
    input camera sees, the photo projected from four cameras a quarter turn apart about the vertical,
    blended by each voxel's azimuth (docs/training.md, "The photo config's choices").
    offsets_behind: with texture_turns 4, whether G's colour offsets apply behind what the input camera sees
    (false: the colour there is the turned cameras' texture as read; docs/training.md).
    """

    resolution: int = 32
    latent: int = 64
    width: int = 16
    norm: str = "none"
    encoder_hidden: int = 0
    upsample: str = "transposed"
    critic_init: str = "dcgan"
    init: str = "dcgan"
    critic_width: Optional[int] = None
    precision: str = "fp32"
    photo_colour: bool = False
    photo_texture: bool = False
    texture_conv: bool = False
    texture_turns: int = 1
    offsets_behind: bool = True

    def validate(self) -> "ModelConfig":
        """Check this section's values; raise :class:`~mitsuba_platonic.settings_checks.ConfigError`
        naming the key (``model.width: ...``)."""
        choice("model.resolution", self.resolution, RESOLUTIONS)
        positive("model.latent", self.latent)
        positive("model.width", self.width)
        choice("model.norm", self.norm, NORMS)
        choice("model.upsample", self.upsample, UPSAMPLES)
        choice("model.critic_init", self.critic_init, INITS)
        choice("model.init", self.init, INITS)
        choice("model.precision", self.precision, PRECISIONS)
        if self.critic_width is not None:
            positive("model.critic_width", self.critic_width)
        non_negative("model.encoder_hidden", self.encoder_hidden)
        if self.photo_texture and not self.photo_colour:
            raise ConfigError("model.photo_texture: the offset per voxel is G's photo colour read per pixel, so it "
                              "needs model.photo_colour: true")
        choice("model.texture_turns", self.texture_turns, (1, 4))
        if self.texture_turns != 1 and not self.texture_conv:
            raise ConfigError("model.texture_turns: the turned cameras' texture goes where the input camera does not "
                              "see, which texture_conv weighs, so it needs model.texture_conv: true")
        if not isinstance(self.offsets_behind, bool):
            raise ConfigError(f"model.offsets_behind must be true or false, got {self.offsets_behind!r}")
        if not self.offsets_behind and self.texture_turns != 4:
            raise ConfigError("model.offsets_behind: false keeps the turned cameras' texture behind the seen surface, "
                              "so it needs model.texture_turns: 4")
        if self.texture_conv and not self.photo_texture:
            raise ConfigError("model.texture_conv: the convolution reads the photo's texture, so it needs "
                              "model.photo_texture: true")
        return self

    def net_config(self, channels: int, view_codes: int = 0, pose: bool = False, light: bool = False) -> NetConfig:
        """E's and G's shapes and arithmetic: this section's :data:`NET_KEYS`, with ``channels`` for the volumes
        and images (1 or 4: the image formation's), ``view_codes`` (the length of the view code
        appended to z, 0: none), ``pose`` (a pose head) and ``light`` (a light head), which the
        config's other sections decide."""
        return NetConfig(**{key: getattr(self, key) for key in NET_KEYS}, volume_channels=channels,
                         image_channels=channels, view_codes=view_codes, pose=pose, light=light).validate()

    def critic_config(self, net: NetConfig) -> NetConfig:
        """The critics' (D's, D3's) shapes: ``net`` (:meth:`net_config`'s) at ``critic_width`` when it is set."""
        return dataclasses.replace(net, width=self.critic_width or self.width)
