"""The settings E and G share with the config's model section, declared once: :class:`NetSettings`.

The networks' own configuration (:class:`~mitsuba_platonic.networks.nets.NetConfig`) and the config's
``model:`` section (:class:`~mitsuba_platonic.networks.settings.ModelConfig`) both inherit these fields,
so each has one type, one default and one line of documentation, here. Each adds its own: NetConfig
what the config's other sections decide (the channels, the view code, the heads), ModelConfig how the
networks start and the critics' width. Each checks the values its own way (NetConfig raises
``ValueError``, the config a ``ConfigError`` naming ``model.<key>``). Imports nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Tuple

__all__ = ["NetSettings", "net_keys"]


@dataclass
class NetSettings:
    """The networks' shapes and arithmetic, one line per key (why each default: docs/training.md, as named).

    resolution: volume and image size R (16 | 32 | 64 | 128).
    latent: the size of z (the paper: 200).
    width: channels at the highest resolution (the paper: 64).
    norm: 'batch' (the paper's) | 'instance' | 'none' (the default: with BatchNorm the reconstruction loss
    stays at 0.21 and the gate blocks D on 96 % of steps, docs/training.md, "The measurements").
    encoder_hidden: width of E's last layer before its Linear to z; 0: none, E's trunk feeds the Linear
    directly (the authors': 1024, docs/paper.md).
    upsample: how G doubles its resolution, 'transposed' (the paper's k4 s2) | 'resize' (nearest ×2, k3, in
    every stage) | 'resize_last' (in the last stage only: the quickstart's, "The quickstart's choices").
    precision: the networks' arithmetic, 'fp32' | 'bf16' (convolutions in bfloat16: the paper's set-up on a
    CPU then takes 1.07 s a step; at the quickstart's size it is not faster, docs/training.md, "Speed").
    photo_colour: G's colour as an offset from the input photo's mean colour (reconstruction, EA,
    orthographic: "The photo config's choices").
    photo_texture: with photo_colour, the offset is from the photo's own colour at each voxel's pixel,
    carried along the input camera's rays, not from its mean (:func:`~mitsuba_platonic.networks.photo_colours.photo_texture`).
    texture_conv: with photo_texture, G's last logits corrected by a 3³ convolution that sees the photo's
    colour, G's own logits and how much of each voxel the input camera sees
    (:func:`~mitsuba_platonic.networks.photo_colours.texture_corrected`; "G's colour seeing the photo").
    texture_turns: with texture_conv, 1: the photo carried along the input camera's rays; 4: behind what the
    input camera sees, the photo projected from four cameras a quarter turn apart about the vertical,
    blended by each voxel's azimuth (the photo configs'; a class round about its vertical, "The photo
    config's choices").
    offsets_behind: with texture_turns 4, whether G's colour offsets apply behind what the input camera sees
    (false, the photo configs': the colour there is the turned cameras' texture as read).
    """

    resolution: int = 32
    latent: int = 64
    width: int = 16
    norm: str = "none"
    encoder_hidden: int = 0
    upsample: str = "transposed"
    precision: str = "fp32"
    photo_colour: bool = False
    photo_texture: bool = False
    texture_conv: bool = False
    texture_turns: int = 1
    offsets_behind: bool = True


def net_keys() -> Tuple[str, ...]:
    """The names of :class:`NetSettings`' fields, in order (``('resolution', 'latent', …)``)."""
    return tuple(f.name for f in fields(NetSettings))
