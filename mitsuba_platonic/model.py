"""The model: encoder E and generator G with what using them needs, for inference and training.

:class:`Model` holds E (image → z) and G (z → volume) of :mod:`mitsuba_platonic.networks.nets` and
the settings inference needs: the network shapes (resolution, channels, latent size), the
render settings a run trained through (image formation, backend, filter) and the task E/G
learnt. It is built from a config (a fresh model, which the trainer trains) or read from a
checkpoint (:meth:`Model.from_checkpoint`, no training code involved), and it turns images into
volumes (:meth:`Model.reconstruct`) or draws volumes from the prior (:meth:`Model.generate`).

This module sits above the config and the checkpoint reader (:mod:`mitsuba_platonic.config.loading`,
which it imports and which never imports it): a ``cfg`` argument is a
:class:`~mitsuba_platonic.config.Config`, read by its sections' attributes; reading a checkpoint
is :mod:`mitsuba_platonic.config.loading`'s, and whether a config's networks fit in memory
:mod:`mitsuba_platonic.train.memory_fit`'.

A PrGAN-style model (``train.mode: prgan``) takes the view as part of its latent: G's input is
z followed by a one-hot code of one of :data:`RING_VIEWS` views on a ring (:meth:`Model.code`).
Its volumes are in the frame of ring view 0, which is the input view ω₀ for reconstruction, so
:meth:`Model.reconstruct` and :meth:`Model.generate` append the code of view 0.

A model trained with ``train.pose: elevation`` also has a pose head P (z → the input camera's
elevation θ̂, :class:`~mitsuba_platonic.networks.nets.PoseHead`): its G builds the object upright, in
an object frame, and :meth:`Model.reconstruct` turns that volume into the input camera's frame by
θ̂ (:func:`~mitsuba_platonic.render.pytorch.closed_form.tilt`), so every model's reconstructions live in
the frame of their input view (docs/training.md, "The measurements").

A model trained with ``train.light: head`` has a light head L (z → the photo's sun direction
and sky share, :class:`~mitsuba_platonic.networks.nets.LightHead`; docs/training.md, "The measurements",
"A light read from the photo").

Its state dict keys are the checkpoint's (``E.*``, ``G.*``, ``P.*``, ``L.*``): a checkpoint's ``nets``
holds E, G (and P, L) under the same names, next to the critics D and D3 that only training needs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional, Tuple, Union

import torch
import torch.nn.functional as F
from torch import nn

from .config.loading import load_model
from .data.photos import decode_image, prepare_image
from .errors import UserError
from .runtime import budget
from .networks.nets import Encoder, Generator, LightHead, NetConfig, PoseHead, init_weights
from .networks.photo_colours import photo_volume
from .render.pytorch.closed_form import tilt
from .render.settings import RenderSettings
from .volume import CHANNELS

__all__ = ["Model", "net_config", "critic_config", "RING_VIEWS", "view_codes", "check_weights_fit", "BYTES_PER_WEIGHT"]

#: Views of the PrGAN-style baseline: azimuths k · 360°/8 on one elevation ring (Gadelha et al.).
RING_VIEWS = 8


def view_codes(cfg: Any) -> int:
    """Length of the view code G gets next to z: :data:`RING_VIEWS` for ``train.mode: prgan``, else 0."""
    return RING_VIEWS if cfg.train.mode == "prgan" else 0


def net_config(cfg: Any) -> NetConfig:
    """The networks' shapes for a config: its model section's
    (:meth:`~mitsuba_platonic.networks.settings.ModelConfig.net_config`), with the channels of its
    image formation, the PrGAN view code and the pose and light heads its train section asks for."""
    return cfg.model.net_config(CHANNELS[cfg.render.model], view_codes=view_codes(cfg),
                                pose=cfg.train.pose == "elevation", light=cfg.train.light == "head")


def critic_config(cfg: Any) -> NetConfig:
    """The critics' (D's, D3's) shapes: :func:`net_config` at ``model.critic_width`` when it is set."""
    return cfg.model.critic_config(net_config(cfg))


#: Bytes a weight takes at least where a model is only used (float32), not trained.
BYTES_PER_WEIGHT = 4


def check_weights_fit(cls: type, net: NetConfig, cfg: Any) -> None:
    """:class:`~mitsuba_platonic.errors.UserError` (one line naming the model's size keys) where the
    weights of ``cls(net, ...)``, counted on PyTorch's meta device (nothing allocated), take more than
    the memory free at :data:`BYTES_PER_WEIGHT` bytes each (a lower bound: ``generate`` and ``view``
    of a run whose config says ``model.width: 100000``). Nothing is counted where the default device
    is the meta device already (the count of :func:`~mitsuba_platonic.train.memory_fit.parameter_count`)."""
    if torch.empty(0).device.type == "meta":
        return
    with torch.device("meta"):
        count = sum(p.numel() for p in cls(net, cfg.render, cfg.train.task, init=False).parameters())
    sizes = ", ".join(f"model.{k}: {getattr(cfg.model, k)}" for k in ("resolution", "width", "latent")
                      if hasattr(cfg.model, k))
    budget.check_fits(count * BYTES_PER_WEIGHT, budget.available_memory(),
                      f"the networks of this config ({sizes}; {count:.3g} weights)",
                      "lower model.width (a run folder whose config asks for this cannot be opened here)")


class Model(nn.Module):
    """E and G, with ``net`` (their :class:`~mitsuba_platonic.networks.nets.NetConfig`), ``render`` (the
    run's :class:`~mitsuba_platonic.render.RenderSettings`), ``task`` ('reconstruction' or
    'generation': only a reconstruction model's E was trained), ``step`` (training steps behind
    the weights; None for a fresh model) and ``origin`` (the checkpoint file it came from).

    ``init=False`` leaves PyTorch's default initialisation for a caller that initialises E and G
    together with other networks (the trainer: one seeded draw for all of them).
    """

    def __init__(self, net: NetConfig, render: RenderSettings, task: str = "reconstruction", init: bool = True):
        super().__init__()
        self.net, self.render, self.task = net.validate(), render.validate(), task
        self.step: Optional[int] = None
        self.origin: Optional[Path] = None
        self.E = Encoder(net)
        self.G = Generator(net)
        #: the pose head (``train.pose: elevation``), else None
        self.P: Optional[PoseHead] = PoseHead(net.latent) if net.pose else None
        #: the light head (``train.light: head``), else None
        self.L: Optional[LightHead] = LightHead(net.latent) if net.light else None
        if init:
            self.apply(init_weights)

    # -- building ---------------------------------------------------------------------------

    @classmethod
    def from_config(cls, cfg: Any, init: bool = True) -> "Model":
        """A fresh model for ``cfg`` (initialised from torch's global generator unless ``init=False``).

        The sizes come from a config someone may have written by hand (a run folder's): where E's
        and G's float32 weights cannot fit in the memory free, :class:`~mitsuba_platonic.errors.UserError`
        before anything is allocated (:func:`check_weights_fit`)."""
        net = net_config(cfg)
        check_weights_fit(cls, net, cfg)
        return cls(net, cfg.render, cfg.train.task, init=init)

    @classmethod
    def from_checkpoint(cls, source: Union[str, Path], device: Union[str, torch.device] = "cpu") -> "Model":
        """The model of a run folder (its newest loadable checkpoint) or of one checkpoint file.

        The file is loaded safely (no code runs, :func:`~mitsuba_platonic.files.checkpoint.load_checkpoint`).
        Raises :class:`~mitsuba_platonic.files.checkpoint.RunError` (one line naming the file) if there
        is no loadable checkpoint, the safe loader refused one (``UnsafeCheckpoint``), its saved
        config is not valid or its weights do not fit that config's networks.

        The moving average of E's and G's weights is loaded when the run kept one (``train.ema``).
        Reading is :func:`mitsuba_platonic.config.loading.load_model`'s (it validates the saved config and
        is handed this class); this is its entry point on the class.
        """
        return load_model(cls, source, device)

    # -- what inference needs ---------------------------------------------------------------

    @property
    def resolution(self) -> int:
        return self.net.resolution

    @property
    def channels(self) -> int:
        """Image and volume channels: 4 (premultiplied RGBA / RGB + density) or 1 (opacity / density)."""
        return self.net.image_channels

    @property
    def formation(self) -> str:
        """The image formation model ('vh', 'ao', 'ea') the volumes are rendered with."""
        return self.render.model

    @property
    def latent(self) -> int:
        return self.net.latent

    @property
    def views(self) -> int:
        """Length of G's view code (:data:`RING_VIEWS` for a PrGAN-style model, else 0: G sees z only)."""
        return self.net.view_codes

    def code(self, z: torch.Tensor, view: Union[int, torch.Tensor] = 0) -> torch.Tensor:
        """G's input for latent codes ``z`` ``(B, latent)`` seen from ring view(s) ``view`` (an index or
        ``(B,)`` indices): z followed by the one-hot of the view, or z itself for a model without
        view codes (then ``view`` must be 0)."""
        if not self.views:
            if not (isinstance(view, int) and view == 0):
                raise ValueError("this model's G takes no view code (train.mode is not 'prgan')")
            return z
        index = torch.as_tensor(view, device=z.device, dtype=torch.long).expand(z.shape[0])
        return torch.cat([z, F.one_hot(index, self.views).to(z.dtype)], dim=1)

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    def load_image(self, path: Union[str, Path], background: Optional[str] = None, crop: str = "image") -> torch.Tensor:
        """An image file → ``(1, C, R, R)`` input for :meth:`reconstruct` (the photo loader's
        preparation at this model's resolution; alpha only for a one-channel model)."""

        path = Path(path)
        x = prepare_image(decode_image(path), self.resolution, background=background, crop=crop, name=str(path))
        return torch.from_numpy(x[3:] if self.channels == 1 else x)[None]

    # -- using the networks -----------------------------------------------------------------

    @torch.no_grad()
    def reconstruct(self, images: torch.Tensor) -> torch.Tensor:
        """G(E(x)): ``(B, C, R, R)`` images → ``(B, C, R, R, R)`` volumes in the input cameras'
        frames, on the model's device (eval mode: BatchNorm uses running statistics; the previous
        mode is restored). A PrGAN-style model's G gets the code of ring view 0, the input view.
        With a pose head, G's upright volume is tilted by the estimated elevation θ̂ = P(z),
        ``tilt(G(z), θ̂)`` clamped to [0, 1] (trilinear round-off). With ``photo_colour``, G also
        gets each image's mean colour (:func:`~mitsuba_platonic.networks.photo_colours.photo_colour`), or with
        ``photo_texture`` its colours along the rays of a camera at θ̂
        (:func:`~mitsuba_platonic.networks.photo_colours.photo_texture`)."""
        def run() -> torch.Tensor:
            v, θ = self._upright(images)
            return v if θ is None else tilt(v, θ).clamp(0.0, 1.0)

        return self._eval(run)

    @torch.no_grad()
    def reconstruct_upright(self, images: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """(volumes, θ̂): G(E(x)) in the object's own frame, ``(B, C, R, R, R)``, and the elevation
        θ̂ ``(B,)`` in degrees at which the input camera sees it there. For a model with a pose head
        these are G's upright volumes and P's estimates (:meth:`reconstruct` is them tilted by θ̂);
        for one without, the input camera's frame is the only frame it knows, so the volumes are
        :meth:`reconstruct`'s and θ̂ = 0. A turntable about the object's vertical axis at the input
        camera's elevation, ω(φ, θ̂), is what the judge renders (:mod:`~mitsuba_platonic.evaluate.judge`):
        at φ = 0 it is the input view, and a tree stays upright from every side."""
        def run() -> Tuple[torch.Tensor, torch.Tensor]:
            v, θ = self._upright(images)
            return v, (torch.zeros(len(v), device=v.device) if θ is None else torch.rad2deg(θ))

        return self._eval(run)

    def _upright(self, images: torch.Tensor) -> Tuple[torch.Tensor, Optional[torch.Tensor]]:
        """G's volumes for ``images`` in its own frame and P's elevations in radians (None without P)."""
        self._needs_encoder()
        x = images.to(self.device)
        z = self.E(x)
        θ = self.P(z) if self.P is not None else None
        if self.net.photo_colour:                            # the colour G offsets from, read from x
            v, _ = photo_volume(self.G, self.code(z), x, self.net, θ if self.net.photo_texture else None)
        else:
            v = self.G(self.code(z))
        return v, θ

    @torch.no_grad()
    def estimate_elevation(self, images: torch.Tensor) -> torch.Tensor:
        """The input cameras' elevations θ̂ in degrees, ``(B,)``, that a model trained with
        ``train.pose: elevation`` reads from ``(B, C, R, R)`` images; a
        :class:`~mitsuba_platonic.errors.UserError` for a model without a pose head."""
        self._needs_encoder()
        if self.P is None:
            raise UserError("this model estimates no elevation: it was trained with train.pose: input "
                            "(its reconstructions are in the input camera's frame as they come)")
        return self._eval(lambda: torch.rad2deg(self.P(self.E(images.to(self.device)))))

    @torch.no_grad()
    def estimate_light(self, images: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """The light a model trained with ``train.light: head`` reads from ``(B, C, R, R)`` images:
        the sun's direction in each input camera's frame (right, up, ω) ``(B, 3)`` and the sky's
        share of the mean luminance ``(B,)`` (:class:`~mitsuba_platonic.networks.nets.LightHead`); a
        :class:`~mitsuba_platonic.errors.UserError` for a model without a light head."""
        self._needs_encoder()
        if self.L is None:
            raise UserError("this model estimates no light: it was trained with train.light: prior")
        return self._eval(lambda: self.L(self.E(images.to(self.device))))

    def _needs_encoder(self) -> None:
        if self.task != "reconstruction":
            where = self.origin.parent.parent if self.origin is not None else "this model"
            raise UserError(f"{where} was trained for {self.task!r}; reconstruction needs an encoder "
                            f"(train.task: reconstruction)")

    @torch.no_grad()
    def generate(self, n: int, seed: int = 0) -> torch.Tensor:
        """G(z), z ~ N(0, I) drawn by a generator seeded with ``seed`` → ``(n, C, R, R, R)`` (a
        PrGAN-style model's G gets the code of ring view 0; a model with a pose head gives its
        upright volumes, in their own frame: no input view to tilt them into; a model with
        ``photo_colour`` has no photo to read a colour from and offsets from grey)."""
        return self.decode(self.latents(n, seed).to(self.device))

    def latents(self, n: int, seed: int = 0) -> torch.Tensor:
        """The latents :meth:`generate` decodes: z ~ N(0, I) ``(n, latent)`` on the CPU, drawn by a
        generator seeded with ``seed`` (z[i] is the latent of sample i of ``generate(n, seed)``)."""
        return torch.randn(n, self.latent, generator=torch.Generator().manual_seed(seed))

    @torch.no_grad()
    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """G of given latents ``z`` ``(n, latent)`` as :meth:`generate` decodes its draws → ``(n, C, R, R, R)``
        (the viewer's walk between two latents decodes the points between them)."""
        n = z.shape[0]
        grey = torch.full((n, 3), 0.5, device=self.device) if self.net.photo_colour else None   # no photo: logit 0
        return self._eval(lambda: self.G(self.code(z)) if grey is None else self.G(self.code(z), grey))

    def _eval(self, fn):
        was = self.training
        self.eval()
        try:
            return fn()
        finally:
            self.train(was)
