"""The model section of a config (``model:``): the networks' sizes and how they start.

:class:`ModelConfig` is the section's dataclass, beside the networks it configures
(:mod:`mitsuba_platonic.models`). Imports no config: the config composes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from .models import INITS, NORMS, RESOLUTIONS, UPSAMPLES
from .settings_checks import choice, non_negative, positive

__all__ = ["ModelConfig"]


@dataclass
class ModelConfig:
    """resolution: volume and image size R (16 | 32 | 64 | 128); latent: size of z;
    width: channels at the highest resolution (the paper: 64); norm: 'batch' (the paper) |
    'instance' | 'none'. The default is 'none': with BatchNorm the quickstart's reconstruction
    loss stays at 0.21 and novel-view IoU at 0.18 (0.007 and 0.63 without; docs/training.md);
    'none' also makes data-parallel training identical to single-process training.
    encoder_hidden: width of the encoder's last layer before its Linear to z (0, the default:
    none; the authors' encoder: 1024, see docs/paper.md). upsample: how G doubles its
    resolution, 'transposed' (the paper's k4 s2 transposed convolutions) | 'resize' (nearest ×2
    and a k3 convolution; mitsuba_platonic.models.UPSAMPLES). critic_init: how the critics D and
    D3 start, 'dcgan' (N(0, 0.02), as every network and the paper) | 'he' (He's initialisation
    for LeakyReLU, drawn from the run's seed after the others): without normalisation a DCGAN
    critic's logits are ~5e-4 and it does not learn in the quickstart's 2,000 steps
    (docs/training.md, "A discriminator that never learns"). init: how E and G start, 'dcgan'
    (the paper's) | 'he' (He's, scaled by each layer's fan-in; G's output layer keeps the start
    at density 1/R: mitsuba_platonic.models.init_he): without normalisation the DCGAN
    initialisation gives every input image the same first volume (docs/training.md).
    critic_width: channels of the critics' (D's, D3's) first layer, doubling per stage as E's;
    null: ``width``. D is a 2D network: at 32 it costs little next to G's 3D convolutions
    (docs/training.md, "E and G that start blind, and a wider D")."""

    resolution: int = 32
    latent: int = 64
    width: int = 16
    norm: str = "none"
    encoder_hidden: int = 0
    upsample: str = "transposed"
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
        if self.critic_width is not None:
            positive("model.critic_width", self.critic_width)
        non_negative("model.encoder_hidden", self.encoder_hidden)
        return self
