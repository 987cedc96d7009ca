"""The baselines' modes of the trainer (docs/paper.md, Table 2), beside its main path 'platonic'
(:mod:`mitsuba_platonic.train.trainer`); ``tests/test_baselines.py`` checks the gradient flow of each.

- 'prgan': the PrGAN-style baseline (Gadelha et al.): visual hull images only, random views
  drawn from the :data:`~mitsuba_platonic.model.RING_VIEWS` = 8 azimuths k · 45° on one ring
  (``train.elevation``, 0° by default: in view space the input view ω₀ is ring view 0), and the
  view as part of the latent: G(z, onehot(k)) is rendered from ring view k; the reconstruction
  term renders G(E(x), onehot(0)) from ω₀. Same D, renderer and gate as 'platonic'.
- 'platonic3d': also a 3D discriminator D3 on ground-truth volumes vs v, where 3D data exists.
  G's objective holds *both* adversarial terms (the authors' public Platonic3D code never lets
  its generator see the 2D term; here it does, as the paper describes the method). For
  reconstruction, G's volumes live in the input camera's frame, so D3's real volumes are
  resampled into the frames of views drawn from the data's view distribution (else D3 could tell
  fakes from their orientation alone).
- 'gan3d': the 3D-GAN baseline: WGAN-GP (or the config's loss) between G(z) and ground-truth
  volumes; no rendering, no 2D discriminator: G's only gradients are D3's and, for
  reconstruction (z = E(x)), the volume reconstruction term (``rec_target: volume``):

      L_rec3d = λ_rec · mean (v − v*)²,   v* the input image's truth resampled into its camera's frame

  (where v lives, the frame :func:`~mitsuba_platonic.evaluate.protocol.truth_in_input_frame` scores
  against): 3D supervision, as the 3D-GAN's reconstruction variant (3D-VAE-GAN, Wu et al. 2016) and
  the paper's Platonic3D ("the 3DGAN framework plus the PlatonicGAN adversarial term") use it; with
  ``rec_target: volume`` 'platonic3d' compares volumes the same way.
"""

from __future__ import annotations

from typing import Dict, Tuple

import torch
import torch.nn.functional as F

from ..model import RING_VIEWS
from ..render.pytorch.closed_form import rotate
from ..views import from_angles
from .losses import g_loss
from .step_state import StepState
from .terms import g_terms

__all__ = ["ring_views", "in_frames", "BaselineModes"]


def ring_views(elevation: float = 0.0) -> torch.Tensor:
    """The PrGAN-style baseline's views: ``(8, 3)``, azimuths k · 45° (k = 0 … 7) at ``elevation``
    degrees; at 0° view 0 is the input view ω₀."""
    return from_angles(torch.arange(RING_VIEWS, dtype=torch.float64) * (360.0 / RING_VIEWS), float(elevation))


def in_frames(volumes: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """Ground-truth ``(B, C, N, N, N)`` volumes resampled into the frames of cameras at ``views``
    (the closed form's rotation, as :func:`~mitsuba_platonic.evaluate.protocol.truth_in_input_frame`),
    clamped to [0, 1] (trilinear round-off)."""
    return rotate(volumes, views).clamp(0.0, 1.0)


class BaselineModes:
    """The baselines' stages of :class:`~mitsuba_platonic.train.trainer.Trainer`, which inherits them:
    PrGAN's ring draw and view codes, the 3D critic's real volumes and update, the volume
    reconstruction term and the 3D-GAN's whole step. They use the trainer's networks, optimisers,
    critic update and objective."""

    # -- 'prgan' ----------------------------------------------------------------------------

    def _ring_draw(self, g: torch.Generator) -> Tuple[torch.Tensor, torch.Tensor]:
        """(views, k): one of the 8 ring views per random view (this process's rows), drawn with ``g``."""
        t = self.cfg.train
        ring_k = self._shard(torch.randint(RING_VIEWS, (t.batch_size, t.random_views), generator=g)).reshape(-1)
        return self.ring[ring_k], ring_k

    def _ring_generate(self, s: StepState) -> None:
        """The view is part of G's input: one volume per (z, ring view k), rendered from view k; the
        input view is ring view 0 (one forward pass, so DDP sees each weight used once)."""
        K, b = self.cfg.train.random_views, s.x.shape[0]
        codes = self.model.code(s.z.repeat_interleave(K, 0), s.ring_k.to(self.device))
        if self.cfg.train.task == "reconstruction":
            codes = torch.cat([codes, self.model.code(s.z, 0)])
        s.v = self.modules["G"](codes)
        s.v_view, s.v_input = s.v[:b * K], s.v[b * K:]

    # -- the 3D critic ('platonic3d', 'gan3d') -----------------------------------------------

    def _real_volumes(self, g: torch.Generator) -> torch.Tensor:
        """D3's real batch: this process's rows of B ground-truth volumes drawn with ``g``. For
        reconstruction, G's volumes are in input cameras' frames, so these are shown in the frames
        of cameras drawn from the data's views, not in object space (else D3 could tell fakes from
        their orientation alone)."""
        B = self.cfg.train.batch_size
        real = self._shard(self.volumes[torch.randint(len(self.volumes), (B,), generator=g).to(self.device)])
        if self.cfg.train.task != "reconstruction":
            return real
        return in_frames(real, self._shard(self._views(B, g, self.cfg.data)).to(self.device))

    def _update_d3(self, s: StepState) -> torch.Tensor:
        """D3's updates (the truth ``s.real_volumes`` vs v.detach()); returns G's 3D adversarial
        loss on v under D3's new weights (the 'adv3d' term's value)."""
        self._critic_update("D3", self.opt_d3, s.real_volumes, s.v.detach(), s.eps, None, s.out)
        return g_loss(self.cfg.train.loss, self.modules["D3"](s.v))

    def volume_rec(self, v: torch.Tensor, idx: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
        """‖v − v*‖² (mean over voxels) for this process's rows of the batch ``idx`` of training
        images: v* is each image's ground-truth volume resampled into its camera's frame. Logs
        ``loss_rec3d``."""
        rows = self._shard(idx)
        truth = in_frames(self.volumes[self.data.image_shapes[rows].to(self.device)],
                          self.data.image_views[rows].to(self.device))
        loss = F.mse_loss(v, truth)
        out["loss_rec3d"] = self.global_mean(loss)
        return loss

    # -- 'gan3d' ----------------------------------------------------------------------------

    def _step_gan3d(self, step: int) -> Dict[str, float]:
        """The 3D-GAN baseline's Algorithm 1: sample ground-truth volumes, (the batch,) z ~ N(0, I) and
        ε; v = G(z) (reconstruction: z = E(x)); update D3 on the truth vs v; update G (and E) on
        'adv3d' (+ 'rec3d'). Logs ``loss_g``, the whole objective."""
        t = self.cfg.train
        B, rec = t.batch_size, t.task == "reconstruction"
        s = StepState(step, self.generator(step))
        s.real_volumes = self._real_volumes(s.g)
        s.idx = torch.randint(len(self.images), (B,), generator=s.g) if rec else None
        s.z_prior = torch.randn(B, self.cfg.model.latent, generator=s.g)
        s.eps = self._shard(torch.rand(B, generator=s.g)).to(self.device)
        self.nets.train()
        s.z = self.modules["E"](self._shard(self.images[s.idx.to(self.device)])) if rec else \
            self._shard(s.z_prior).to(self.device)
        s.v = s.v_input = self.modules["G"](s.z)
        s.d3_verdict = self._update_d3(s)
        loss_g = self._g_objective(g_terms(self, s, self.terms))
        self._update_g(loss_g, step)
        s.out["loss_g"] = self.global_mean(loss_g)
        return s.out
