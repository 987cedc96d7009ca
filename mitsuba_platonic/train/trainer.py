"""One PlatonicGAN update (Algorithm 1 of the paper), for every task and mode of the trainer.

Per step, with a generator seeded by (run seed, step) so a resumed run draws exactly what an
uninterrupted one would:

1. sample a batch of real images x and, per volume, ``random_views`` views ω ~ p_view;
2. z = E(x) (reconstruction) or z ~ N(0, I) (generation); v = G(z) (with ``model.photo_colour``: G(z, m(x)));
3. I_view = R(ω, v); for reconstruction also I_front = R(ω₀, v) (the input view by convention);
4. ``d_steps`` D updates on x vs I_view (each skipped, and the rest with it, while D's soft
   accuracy on this batch, ½(mean σ(l_real) + 1 − mean σ(l_fake)), is above ``d_gate``); with
   ``d_roll: uniform`` D sees each of them turned in-plane by its own random angle (the images
   of G's adversarial term too), with ``matched`` the reals turned by the tilt of a right
   volume's view (:mod:`.roll`);
5. G (and E) update on  L_G = adv(D(I_view)) + λ_rec ‖x − I_front‖² (+ w₃ adv₃(D3(v))), the mean
   squared difference; with ``rec_loss: l1`` the mean absolute one, λ_rec mean |x − I_front|;
   with ``rec_channels: alpha`` on the opacity channel alone.
   With ``colour_match`` = w > 0, L_G adds w · mean |c̄(I_view) − c̄(x)|, c̄ the mean colour of an
   image's object (:func:`.losses.colour_match`).

Where the volume stands (``train.pose``). With 'input' (the paper's view-space reconstruction)
v lives in the input camera's frame: I_front renders it from ω₀ and the random views ω are drawn
around that frame. A camera above the object sees its up axis tilted, so a right volume is tilted
by the input's elevation θ₀ in that frame, its views from random ω are rolled, and D, whose photos
were all taken by upright cameras, pushes G to build the object upright in every input frame
instead (docs/experiments/pose.md). With 'elevation' G builds the object
upright, in its own frame; a pose head P reads the input camera's elevation θ̂ = P(z) from E's
code, and

    I_front = R(ω₀, tilt(v, θ̂))       (v seen from elevation θ̂, differentiable in θ̂)
    I_view  = R(ω, v),  ω ~ p_view     (around the upright object, as the photos' cameras were)

The input-view term alone does not teach P the elevation (it stays uncorrelated with θ₀,
docs/experiments/pose-elevation.md), so P also learns from G's own renders, whose elevations are known:

    L_pose = λ_pose · mean (P(E(I_view)) − asin ω_y)²      (I_view detached: it trains E and P)

and a reconstruction is ``tilt(G(z), P(z))`` (:meth:`~mitsuba_platonic.model.Model.reconstruct`).
Only the elevation is estimated: an azimuth turns an upright object into an upright object, so G
is free to build it already turned to the input's azimuth.

A light read from the photo (``train.light: head``, single scattering): the random views are lit
by lights ℓ_i drawn from the prior (sun direction ω_s, sky share s), known to the trainer, and a
light head L learns to read them from those renders in each view's camera frame, as P learns
elevations:

    L_light = mean (1 − L_ω(E(I_view)) · ω_s^cam) + mean ((L_s(E(I_view)) − s) / (s₁ − s₀))²     (I_view detached)

((s₀, s₁) the prior's range of shares); the input view is then rendered under L(z), held constant,
so the input-view term compares colour and shading under the photo's light, not a random one
(docs/experiments/training-through-light.md, "A light read from the photo").

The reconstruction term compares images by default (``train.rec_target: image``, as above). With
``rec_target: volume`` (the 3D modes) it compares volumes instead: λ_rec ‖v − v*‖², where v* is
the input image's ground-truth volume resampled into its camera's frame (where v lives, the frame
:func:`~mitsuba_platonic.evaluate.protocol.truth_in_input_frame` scores against): 3D supervision,
as the 3D-GAN's reconstruction variant (3D-VAE-GAN, Wu et al. 2016) and the paper's Platonic3D
("the 3DGAN framework plus the PlatonicGAN adversarial term") use it.

Modes (which critics train G; ``tests/test_baselines.py`` checks the gradient flow of each):

- 'platonic': the above; G's gradient comes from D (2D adversarial) and, for reconstruction,
  the input-view term.
- 'platonic3d': also a 3D discriminator D3 on ground-truth volumes vs v, where 3D data exists.
  G's objective holds *both* adversarial terms (the authors' public Platonic3D code never lets
  its generator see the 2D term; here it does, as the paper describes the method). For
  reconstruction, G's volumes live in the input camera's frame, so D3's real volumes are
  resampled into the frames of views drawn from the data's view distribution (else D3 could tell
  fakes from their orientation alone).
- 'gan3d': the 3D-GAN baseline: WGAN-GP (or the config's loss) between G(z) and ground-truth
  volumes; no rendering, no 2D discriminator: G's only gradients are D3's and, for
  reconstruction (z = E(x)), the volume reconstruction term (``rec_target: volume``).
- 'prgan': the PrGAN-style baseline (Gadelha et al.): visual hull images only, random views
  drawn from the :data:`~mitsuba_platonic.model.RING_VIEWS` = 8 azimuths k · 45° on one ring
  (``train.elevation``, 0° by default: in view space the input view ω₀ is ring view 0), and the
  view as part of the latent: G(z, onehot(k)) is rendered from ring view k; the reconstruction
  term renders G(E(x), onehot(0)) from ω₀. Same D, renderer and gate as 'platonic'.
 D is updated before G, and G's
adversarial term uses the updated D (the usual alternating scheme; the paper's listing computes
c_Gen before the update, which autograd cannot do once D's weights changed in place).

Data parallel: the batch drawn from the step generator is the *global* batch; process r of W
takes rows [r·B/W, (r+1)·B/W). Losses are means over a process's rows and DDP averages the
gradients, so W processes make the single-process update (exactly, for networks without batch
statistics; with BatchNorm each process normalises its own rows). D's accuracy is summed over
processes, so the gate decides the same way everywhere.

Every critic (D on images, D3 on volumes, in every mode) is updated by one routine,
:meth:`Trainer._critic_update`: ``d_steps`` times, a fresh loss on the same real and (detached)
fake batch, gated by the soft accuracy when a gate is set.
"""

from __future__ import annotations

import copy
import math
from typing import Dict, Optional, Tuple

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch import nn
from torch.nn.parallel import DistributedDataParallel as DDP

from ..config import Config, ConfigError
from ..config.train_settings import MODES, MODES_3D, POSES, REC_TARGETS, TASKS  # noqa: F401  (the choice lists, also named here)
from ..model import RING_VIEWS, Model, critic_config
from ..networks.nets import Discriminator, VolumeDiscriminator, init_critic_he, init_he, init_weights
from ..networks.photo_colours import photo_volume
from ..render.pytorch.closed_form import rotate, tilt
from ..render.pytorch.single_scatter import SKY_SHARE, daylights, sample_lights, sky_share
from ..views import DEFAULT_ELEVATION, from_angles, front_view, sample_views, to_angles
from .augment import augment, augment_photos
from .data import TrainingData
from .losses import (colour_match, colour_offset, colour_tv, d_loss, depth_spread, g_loss, gradient_penalty,
                     hard_accuracy_counts, r1_penalty, soft_accuracy_counts, solidity, turn)
from .renderer import in_camera, make_lit_renderer, make_renderer
from .roll import input_frame_roll, roll

__all__ = ["Trainer", "TASKS", "MODES", "MODES_3D", "REC_TARGETS", "POSES", "ring_views"]


def _in_frames(volumes: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """Ground-truth ``(B, C, N, N, N)`` volumes resampled into the frames of cameras at ``views``
    (the closed form's rotation, as :func:`~mitsuba_platonic.evaluate.protocol.truth_in_input_frame`),
    clamped to [0, 1] (trilinear round-off)."""
    return rotate(volumes, views).clamp(0.0, 1.0)


def ring_views(elevation: float = 0.0) -> torch.Tensor:
    """The PrGAN-style baseline's views: ``(8, 3)``, azimuths k · 45° (k = 0 … 7) at ``elevation``
    degrees; at 0° view 0 is the input view ω₀."""
    return from_angles(torch.arange(RING_VIEWS, dtype=torch.float64) * (360.0 / RING_VIEWS), float(elevation))


class Trainer:
    """The :class:`~mitsuba_platonic.model.Model` being trained (``model``: E and G), the critics,
    optimisers and :meth:`step`; ``nets`` holds E, G, D (and D3) under one state dict;
    ``rank``/``world`` for data-parallel runs."""

    def __init__(self, cfg: Config, data: TrainingData, device: torch.device, rank: int = 0, world: int = 1):
        if cfg.train.batch_size % world:
            raise ConfigError(f"train.batch_size: {cfg.train.batch_size} must be divisible by the "
                              f"number of processes ({world})")
        needs_3d = cfg.train.mode in MODES_3D
        if needs_3d and data.volumes is None:
            raise ValueError(f"train.mode {cfg.train.mode!r} needs ground-truth volumes")
        self.cfg, self.data, self.device, self.rank, self.world = cfg, data, device, rank, world
        torch.manual_seed(cfg.run.seed)                      # network initialisation: one draw for all
        self.model = Model.from_config(cfg, init=False)
        critic = critic_config(cfg)
        nets = {"E": self.model.E, "G": self.model.G, "D": Discriminator(critic)}
        if self.model.P is not None:                         # train.pose: elevation (starts at 0°)
            nets["P"] = self.model.P
        if self.model.L is not None:                         # train.light: head (starts at a sun overhead)
            nets["L"] = self.model.L
        if needs_3d:
            nets["D3"] = VolumeDiscriminator(critic)
        self.nets = nn.ModuleDict(nets)
        self.nets.apply(init_weights)
        if cfg.model.init == "he":                           # E and G re-drawn, from the run's seed
            torch.manual_seed(cfg.run.seed)
            init_he(self.model.E)
            init_he(self.model.G)
        if cfg.model.critic_init == "he":                    # the critics re-drawn, from the run's seed
            torch.manual_seed(cfg.run.seed)
            for name in ("D", "D3"):
                if name in self.nets:
                    self.nets[name].apply(init_critic_he)
        self.nets.to(device)
        #: train.ema: the moving average of E's and G's weights (a copy of ``model``, never trained)
        self.ema: Optional[Model] = (copy.deepcopy(self.model).requires_grad_(False)
                                     if cfg.train.ema is not None else None)
        self.modules: Dict[str, nn.Module] = dict(self.nets.items())
        if world > 1:
            self.modules = {k: DDP(m, device_ids=[device.index] if device.type == "cuda" else None)
                            for k, m in self.nets.items()}
        t = cfg.train
        betas = tuple(t.betas)
        groups = [{"params": self.nets["G"].parameters(), "lr": t.lr_g}]
        if t.task == "reconstruction":
            groups.append({"params": self.nets["E"].parameters(), "lr": t.lr_e})
        for head in ("P", "L"):                              # the pose and light heads learn with E
            if head in self.nets:
                groups.append({"params": self.nets[head].parameters(), "lr": t.lr_e})
        self.opt_g = torch.optim.Adam(groups, betas=betas)
        self.opt_d = torch.optim.Adam(self.nets["D"].parameters(), lr=t.lr_d, betas=betas)
        self.opt_d3 = (torch.optim.Adam(self.nets["D3"].parameters(), lr=t.lr_d, betas=betas)
                       if "D3" in self.nets else None)
        self.render = make_renderer(cfg.render)
        #: train.light: head: single scattering under a given light, for the input view; else None
        self.render_lit = make_lit_renderer(cfg.render) if cfg.train.light == "head" else None
        self.images = data.images.to(device)
        self.volumes = data.volumes.to(device) if needs_3d else None
        #: 'prgan': the 8 ring views (train.elevation, default 0°)
        self.ring = ring_views(cfg.train.elevation if cfg.train.elevation is not None else 0.0) \
            if cfg.train.mode == "prgan" else None

    # -- state ------------------------------------------------------------------------------

    def state_dict(self) -> Dict[str, object]:
        state = {"nets": self.nets.state_dict(), "opt_g": self.opt_g.state_dict(), "opt_d": self.opt_d.state_dict()}
        if self.opt_d3 is not None:
            state["opt_d3"] = self.opt_d3.state_dict()
        if self.ema is not None:
            state["ema"] = self.ema.state_dict()
        return state

    def load_state_dict(self, state: Dict[str, object]) -> None:
        self.nets.load_state_dict(state["nets"])
        self.opt_g.load_state_dict(state["opt_g"])
        self.opt_d.load_state_dict(state["opt_d"])
        if self.opt_d3 is not None:
            self.opt_d3.load_state_dict(state["opt_d3"])
        if self.ema is not None:
            self.ema.load_state_dict(state["ema"])

    @property
    def inference_model(self) -> Model:
        """The model that samples, evaluation and exports use: the moving average ``ema`` when
        ``train.ema`` is set, else the trained ``model`` itself."""
        return self.ema if self.ema is not None else self.model

    def _update_ema(self, step: int) -> None:
        """θ_ema ← β_t θ_ema + (1 − β_t) θ for E's and G's weights, after G's update of ``step``
        (0-based), with β_t = min(β, (1 + t) / (10 + t)): early on, while the weights move fast, the
        average forgets quickly (β_0 = 0.1), and it reaches β after about 10 / (1 − β) steps.
        Buffers (BatchNorm's running statistics) are copied, not averaged."""
        β = min(self.cfg.train.ema, (1.0 + step) / (10.0 + step))
        with torch.no_grad():
            for θ_ema, θ in zip(self.ema.parameters(), self.model.parameters()):
                θ_ema.lerp_(θ, 1.0 - β)
            for b_ema, b in zip(self.ema.buffers(), self.model.buffers()):
                b_ema.copy_(b)

    # -- one step ---------------------------------------------------------------------------

    def generator(self, step: int) -> torch.Generator:
        """The step's generator: seeded by (run seed, step), so a resumed run draws the same batch."""
        g = torch.Generator()
        g.manual_seed(int(np.random.SeedSequence([self.cfg.run.seed, step, 0]).generate_state(1)[0]))
        return g

    def _shard(self, x: torch.Tensor) -> torch.Tensor:
        b = x.shape[0] // self.world
        return x[self.rank * b:(self.rank + 1) * b]

    def _views(self, n: int, g: torch.Generator, section=None) -> torch.Tensor:
        """``n`` views from the p_view of ``section`` (the train section, or the data's)."""
        t = self.cfg.train if section is None else section
        kwargs = {}
        if t.view_distribution != "sphere":
            e = t.elevation if t.elevation is not None else DEFAULT_ELEVATION[t.view_distribution]
            kwargs["elevation"] = tuple(e) if isinstance(e, list) else e
        return sample_views(n, t.view_distribution, seed=g, **kwargs)

    def _all_sum(self, x: torch.Tensor) -> torch.Tensor:
        if self.world > 1:
            x = x.to(self.device)
            dist.all_reduce(x)
        return x.cpu()

    def step(self, step: int) -> Dict[str, float]:
        """One update; returns the step's scalars (means over the whole batch)."""
        if self.cfg.train.mode == "gan3d":
            return self._step_gan3d(step)
        cfg, t = self.cfg, self.cfg.train
        E, G, D = self.modules["E"], self.modules["G"], self.modules["D"]
        g = self.generator(step)
        B, K = t.batch_size, t.random_views
        idx = torch.randint(len(self.images), (B,), generator=g)
        x = self._shard(self.images[idx.to(self.device)])
        if t.photo_augment:                                  # train/augment.py: new photos for E, the target and D
            g_photo = torch.Generator()
            g_photo.manual_seed(int(np.random.SeedSequence([cfg.run.seed, step, 13, self.rank]).generate_state(1)[0]))
            x = augment_photos(x, t.photo_augment, g_photo)
        z_prior = torch.randn(B, cfg.model.latent, generator=g)
        ring_k = None
        if t.mode == "prgan":                                # one of the 8 ring views per random view
            ring_k = self._shard(torch.randint(RING_VIEWS, (B, K), generator=g)).reshape(-1)
            views = self.ring[ring_k]
        else:
            views = self._shard(self._views(B * K, g).view(B, K, 3)).reshape(-1, 3)
        eps = self._shard(torch.rand(B * K, generator=g))
        # train.d_roll: the angles D's reals and fakes are turned by (train/roll.py); None: as they are
        ψ_real = ψ_fake = None
        if t.d_roll == "uniform":                            # an angle per real and per fake image
            ψ_real, ψ_fake = self._shard(torch.rand(2, B * K, generator=g).mul(2 * math.pi).T).T
        elif t.d_roll == "matched":                          # the reals turned as a right volume's views are
            photos = cfg.data if cfg.data.source == "procedural" else None   # their views; else p_view
            ψ_real = input_frame_roll(views, self._shard(to_angles(self._views(B * K, g, photos))[1]))
        b = x.shape[0]
        rec = t.task == "reconstruction"

        self.nets.train()
        z = E(x) if rec else self._shard(z_prior).to(self.device)
        if ring_k is None:
            if cfg.model.photo_colour:                       # G's colour offsets from x's (photo_colours.photo_volume)
                θ = None
                if "P" in self.nets and cfg.model.photo_texture:   # the head's θ̂, held constant: the
                    with torch.no_grad():                           # plain module, so DDP sees one use of P
                        θ = self.nets["P"](z.detach())
                v, ℓ = photo_volume(G, z, x, cfg.model, θ)
            else:
                v = G(z)
            v_view, v_input = (v.repeat_interleave(K, 0) if K > 1 else v), v   # K = 1: no copy
            if "P" in self.modules:                          # train.pose: elevation: upright v, seen from θ̂
                v_input = tilt(v, self.modules["P"](z))
        else:
            # the view is part of G's input: one volume per (z, ring view k), rendered from view k;
            # the input view is ring view 0 (one forward pass, so DDP sees each weight used once)
            codes = self.model.code(z.repeat_interleave(K, 0), ring_k.to(self.device))
            if rec:
                codes = torch.cat([codes, self.model.code(z, 0)])
            v = G(codes)
            v_view, v_input = v[:b * K], v[b * K:]
        seed = int(np.random.SeedSequence([cfg.run.seed, step, 7, self.rank]).generate_state(1)[0] >> 2)
        i_view = self.render(v_view, views.to(self.device), seed)
        i_front = None
        if rec and t.rec_target == "image" and self.render_lit is not None:
            with torch.no_grad():                            # the photo's light as L reads it, held constant
                ω_s, share = self.nets["L"](z.detach())      # (the plain module: DDP sees one use of L)
            i_front = self.render_lit(v_input, front_view(b).to(self.device), daylights(ω_s, share))
        elif rec and t.rec_target == "image":                # the input view
            i_front = self.render(v_input, front_view(b).to(self.device), seed + 1)
        out: Dict[str, float] = {}

        # -- D: real photos vs rendered views, gated by its soft accuracy -----------------------
        real_d = x.repeat_interleave(K, 0) if K > 1 else x
        fake_d = i_view
        if ψ_real is not None:
            real_d = roll(real_d, ψ_real.to(self.device))
        if ψ_fake is not None:
            fake_d = roll(i_view, ψ_fake.to(self.device))
        if t.d_augment:                                      # train/augment.py: the same kind of T on both sides
            g_aug = torch.Generator()
            g_aug.manual_seed(int(np.random.SeedSequence([cfg.run.seed, step, 11, self.rank]).generate_state(1)[0]))
            real_d, fake_d = augment(real_d, t.d_augment, g_aug), augment(fake_d, t.d_augment, g_aug)
        self._critic_update("D", self.opt_d, real_d, fake_d.detach(), eps, t.d_gate, out)

        # -- D3 (Platonic3D): ground-truth volumes vs generated ----------------------------------
        loss_g3 = torch.zeros((), device=self.device)
        if t.mode == "platonic3d":
            loss_g3 = self._update_d3(v, g, eps, out)

        # -- G and E: fool D from random views (and D3), reconstruct the input view --------------
        l_fake = D(fake_d)
        loss_adv = g_loss(t.loss, l_fake)
        terms = {"adv2d": loss_adv}
        if t.mode == "platonic3d":
            terms["adv3d"] = t.weight_3d * loss_g3
        if t.colour_tv > 0:                                  # colour carried into the unseen body
            terms["colour_tv"] = t.colour_tv * colour_tv(v)
        if t.colour_offset > 0:                              # the photo's colour unless the views need otherwise
            terms["colour_offset"] = t.colour_offset * colour_offset(v, ℓ)
        if t.depth_spread > 0:                               # the input view's colour from a thin surface
            terms["depth_spread"] = t.depth_spread * depth_spread(v_input)
        if t.turn > 0:                                       # as deep as wide: round about the vertical
            g_turn = torch.Generator()                       # one angle per volume, drawn from the run's seed and step
            g_turn.manual_seed(int(np.random.SeedSequence([cfg.run.seed, step, 17, self.rank]).generate_state(1)[0]))
            φ = 2.0 * math.pi * torch.rand(v.shape[0], generator=g_turn, dtype=torch.float64)
            terms["turn"] = t.turn * turn(v, φ.to(v.device))
        if t.solidity > 0:                                   # no gaps along the photo's rays
            terms["solidity"] = t.solidity * solidity(v_input)
        if t.colour_match > 0:                               # the photo's mean colour from every side
            terms["colour_match"] = t.colour_match * colour_match(i_view, x)
        if rec and t.rec_target == "volume":
            terms["rec3d"] = t.rec_weight * self._volume_rec(v_input, idx, out)
        elif rec:
            a, y = (i_front, x) if t.rec_channels == "all" else (i_front[:, -1:], x[:, -1:])   # 'alpha': the opacity
            loss_rec = F.mse_loss(a, y) if t.rec_loss == "l2" else F.l1_loss(a, y)
            terms["rec"] = t.rec_weight * loss_rec
            out["loss_rec"] = float(self._all_sum(loss_rec.detach().cpu()) / self.world)
        if t.pose_weight > 0:                                # P learns the elevations of G's renders
            terms["pose"] = t.pose_weight * self._pose_loss(i_view, views, out)
        if self.render_lit is not None:                      # L learns the lights of G's renders
            terms["light"] = self._light_loss(i_view, views, seed, out)
        self._update_g(self._g_objective(terms), step)
        out["loss_g"] = float(self._all_sum(loss_adv.detach().cpu()) / self.world)
        return out

    def _g_objective(self, terms: Dict[str, torch.Tensor]) -> torch.Tensor:
        """G's (and E's) loss: the sum of its weighted terms, named 'adv2d' (D on rendered views),
        'adv3d' (D3 on volumes), 'rec' (the input view), 'rec3d'
        (the input image's ground-truth volume), 'pose' (the elevations of G's renders), 'colour_tv',
        'colour_match', 'colour_offset', 'depth_spread', 'turn' and 'solidity' (priors, when their weights are set),
        'light' (the lights of G's renders). One place that sees
        every term, so the tests can check which of them reach G."""
        return sum(terms.values())

    def _pose_loss(self, i_view: torch.Tensor, views: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
        """mean (P(E(I)) − θ)² over G's renders ``i_view`` (detached) from ``views`` (this process's
        rows), θ = asin ω_y their elevations in radians: the pose head learns to read the elevation
        of an upright object's view, and carries it over to the photos. Logs ``loss_pose``."""
        θ = to_angles(views, degrees=False)[1].to(self.device, i_view.dtype)
        loss = F.mse_loss(self.modules["P"](self.modules["E"](i_view.detach())), θ)
        out["loss_pose"] = float(self._all_sum(loss.detach().cpu()) / self.world)
        return loss

    def _light_loss(self, i_view: torch.Tensor, views: torch.Tensor, seed: int,
                    out: Dict[str, float]) -> torch.Tensor:
        """L_light (module docstring) over G's renders ``i_view`` (detached) from ``views`` (this
        process's rows), lit by the prior's lights for ``seed`` (the renderer's own draw,
        :func:`~mitsuba_platonic.render.single_scatter.sample_lights`): the light head learns the sun's
        direction in each view's camera frame and the sky's share. Logs ``loss_light``."""
        lights = sample_lights(len(i_view), seed)
        ω_cam = in_camera(lights.direction, views).to(self.device, i_view.dtype)
        share = sky_share(lights)
        ω_hat, s_hat = self.modules["L"](self.modules["E"](i_view.detach()))
        lo, hi = SKY_SHARE
        loss = (1.0 - (ω_hat * ω_cam).sum(1)).mean() + \
            (((s_hat - share.to(self.device, s_hat.dtype)) / (hi - lo)) ** 2).mean()
        out["loss_light"] = float(self._all_sum(loss.detach().cpu()) / self.world)
        return loss

    def _update_g(self, loss: torch.Tensor, step: int) -> None:
        """One Adam step of G (and E) on ``loss``, then the moving average (``train.ema``) follows."""
        self.opt_g.zero_grad(set_to_none=True)
        loss.backward()
        self.opt_g.step()
        if self.ema is not None:
            self._update_ema(step)

    def _critic_update(self, name: str, opt: torch.optim.Optimizer, real: torch.Tensor, fake: torch.Tensor,
                       eps: torch.Tensor, gate: Optional[float], out: Dict[str, float]) -> None:
        """``d_steps`` updates of critic ``name`` ('D' or 'D3') on real vs (detached) fake.

        Each update evaluates a fresh loss with the critic's current weights (WGAN-GP adds its
        penalty at x̂ = ε real + (1 − ε) fake; ``r1_weight`` > 0 adds γ/2 ‖∇ₓD(x)‖² at the reals),
        reals and fakes in one forward pass unless the
        critic has BatchNorm (whose batch statistics would then mix them).
        With a ``gate``, an update happens only while the
        critic's soft accuracy on this batch is ≤ gate; the first refusal ends the loop. Logs
        ``loss_<name>`` and ``acc_<name>`` (soft) / ``acc_<name>_hard`` of the first evaluation,
        and ``<name>_updated``, the share of the ``d_steps`` updates that happened.
        """
        t, critic = self.cfg.train, self.modules[name]
        key = name.lower()
        updates = 0
        r1_now = t.r1_weight > 0
        # one forward pass over reals and fakes together where no BatchNorm mixes them
        together = not any(isinstance(m, nn.modules.batchnorm._BatchNorm) for m in critic.modules())
        for i in range(t.d_steps):
            if r1_now:                                       # γ/2 ‖∇ₓD(x)‖² at the reals
                l_real, l_fake, r1 = r1_penalty(critic, real, fake if together else None)
                if not together:
                    l_fake = critic(fake)
            elif together:
                l_real, l_fake = critic(torch.cat([real, fake])).split([len(real), len(fake)])
                r1 = None
            else:
                l_real, l_fake, r1 = critic(real), critic(fake), None
            loss = d_loss(t.loss, l_real, l_fake)
            if r1 is not None:
                loss = loss + 0.5 * t.r1_weight * r1
            if t.loss == "wgan-gp":
                loss = loss + t.gp_weight * gradient_penalty(critic, real, fake[: len(real)],
                                                                 eps[: len(real)].to(self.device))
            acc = self._ratio(soft_accuracy_counts(l_real, l_fake))
            if i == 0:
                out[f"loss_{key}"] = float(self._all_sum(loss.detach().cpu()) / self.world)
                out[f"acc_{key}"] = acc
                out[f"acc_{key}_hard"] = self._ratio(hard_accuracy_counts(l_real.detach(), l_fake.detach()))
            if gate is not None and acc > gate:
                break
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            updates += 1
        out[f"{key}_updated"] = updates / t.d_steps

    def _ratio(self, counts: Tuple[torch.Tensor, torch.Tensor]) -> float:
        """Σ numerator / Σ denominator over all processes."""
        return float(self._all_sum(counts[0].detach().cpu()) / self._all_sum(counts[1]))

    def _update_d3(self, v: torch.Tensor, g: torch.Generator, eps: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
        """D3 updates (ground truth vs v.detach()); returns G's 3D adversarial loss on v."""
        self._critic_update("D3", self.opt_d3, self._real_volumes(g), v.detach(), eps, None, out)
        return g_loss(self.cfg.train.loss, self.modules["D3"](v))

    def _real_volumes(self, g: torch.Generator) -> torch.Tensor:
        """D3's real batch: this process's rows of B ground-truth volumes drawn with ``g``. For
        reconstruction, G's volumes are in input cameras' frames, so these are shown in the frames
        of cameras drawn from the data's views, not in object space (else D3 could tell fakes from
        their orientation alone)."""
        B = self.cfg.train.batch_size
        real = self._shard(self.volumes[torch.randint(len(self.volumes), (B,), generator=g).to(self.device)])
        if self.cfg.train.task != "reconstruction":
            return real
        return _in_frames(real, self._shard(self._views(B, g, self.cfg.data)).to(self.device))

    def _volume_rec(self, v: torch.Tensor, idx: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
        """‖v − v*‖² (mean over voxels) for this process's rows of the batch ``idx`` of training
        images: v* is each image's ground-truth volume resampled into its camera's frame."""
        rows = self._shard(idx)
        truth = _in_frames(self.volumes[self.data.image_shapes[rows].to(self.device)],
                           self.data.image_views[rows].to(self.device))
        loss = F.mse_loss(v, truth)
        out["loss_rec3d"] = float(self._all_sum(loss.detach().cpu()) / self.world)
        return loss

    def _step_gan3d(self, step: int) -> Dict[str, float]:
        """The 3D-GAN baseline: WGAN-GP (or the config's loss) between G(z) and ground-truth
        volumes; for reconstruction z = E(x), D3's real volumes are in the frames of the data's
        views (as Platonic3D's), and G also learns from the volume reconstruction term."""
        t, G, D3 = self.cfg.train, self.modules["G"], self.modules["D3"]
        g = self.generator(step)
        B = t.batch_size
        rec = t.task == "reconstruction"
        real = self._real_volumes(g)
        idx = torch.randint(len(self.images), (B,), generator=g) if rec else None
        z_prior = self._shard(torch.randn(B, self.cfg.model.latent, generator=g)).to(self.device)
        eps = self._shard(torch.rand(B, generator=g)).to(self.device)
        self.nets.train()
        out: Dict[str, float] = {}
        z = self.modules["E"](self._shard(self.images[idx.to(self.device)])) if rec else z_prior
        v = G(z)
        self._critic_update("D3", self.opt_d3, real, v.detach(), eps, None, out)
        terms = {"adv3d": g_loss(t.loss, D3(v))}
        if rec:
            terms["rec3d"] = t.rec_weight * self._volume_rec(v, idx, out)
        loss_g = self._g_objective(terms)
        self._update_g(loss_g, step)
        out["loss_g"] = float(self._all_sum(loss_g.detach().cpu()) / self.world)
        return out
