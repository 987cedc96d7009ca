"""The model section of a config (``model:``): the networks' sizes, arithmetic and how they start.

:class:`ModelConfig` is the section's dataclass, beside the networks it configures
(:mod:`mitsuba_platonic.networks.nets`). Twelve of its keys (:data:`NET_KEYS`) are the networks' own settings
(their shapes and arithmetic): both it and :class:`~mitsuba_platonic.networks.nets.NetConfig` inherit them
from :class:`~mitsuba_platonic.networks.net_settings.NetSettings`, where each is declared and documented
once; :meth:`ModelConfig.net_config` hands them over, with what the other sections decide (the
image formation's channels, the PrGAN view code, the pose head), so the two never disagree.
The other three (``init``, ``critic_init``, ``critic_width``) are training's: how the networks
start, and the critics' width. Imports no config: the config composes it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional

from ..settings_checks import ConfigError, choice, non_negative, positive
from .net_settings import NetSettings, net_keys
from .nets import INITS, NORMS, PRECISIONS, RESOLUTIONS, UPSAMPLES, NetConfig

__all__ = ["ModelConfig", "NET_KEYS"]

#: The model keys that :class:`~mitsuba_platonic.networks.nets.NetConfig` takes as they are: the
#: fields of :class:`~mitsuba_platonic.networks.net_settings.NetSettings`, which both inherit.
NET_KEYS = net_keys()


@dataclass
class ModelConfig(NetSettings):
    """The model section: the networks' shapes and arithmetic (:class:`~mitsuba_platonic.networks.net_settings.NetSettings`,
    whose fields it inherits), and how training starts them, one line per key (why each default:
    docs/training.md, as named).

    critic_init: how D and D3 start, 'dcgan' (N(0, 0.02)) | 'he' (for networks without normalisation:
    "A discriminator that never learns").
    init: how E and G start, 'dcgan' (the paper's) | 'he' (scaled by fan-in: "E and G that start blind").
    critic_width: channels of D's and D3's first layer, doubling per stage; null: ``width`` (same section).
    """

    critic_init: str = "dcgan"
    init: str = "dcgan"
    critic_width: Optional[int] = None

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
