"""PlatonicGAN's update, Algorithm 1 of the paper, for every task and mode of the trainer.

:meth:`Trainer.step` is the loop's body, one stage a method:

1. **sample** (:meth:`Trainer._sample`), from one generator seeded by (run seed, step), so a resumed
   run draws exactly what an uninterrupted one would, in a fixed order: the batch of real images x,
   z ~ N(0, I), per volume ``random_views`` views ω ~ p_view, WGAN-GP's ε, D's roll angles, D3's
   real volumes (the photos' and D's augmentations, the turn prior's angles and the renderer's seed
   draw from side streams of their own, :mod:`.step_state`);
2. **generate** (:meth:`Trainer._generate`): z = E(x) (reconstruction) or the prior's z; v = G(z)
   (with ``model.photo_colour``: G(z, m(x)), colour offsets ℓ from the photo's);
3. **render** (:meth:`Trainer._render`): I_view = R(ω, v); for reconstruction also I_front = R(ω₀, v),
   the input view by convention;
4. **update D** (:meth:`Trainer._update_critics`): ``d_steps`` updates on x vs I_view (each skipped,
   and the rest with it, while D's soft accuracy on this batch, ½(mean σ(l_real) + 1 − mean σ(l_fake)),
   is above ``d_gate``); with ``d_roll: uniform`` D sees each of them turned in-plane by its own
   random angle (the images of G's adversarial term too), with ``matched`` the reals turned by the
   tilt of a right volume's view (:mod:`.image_roll`); with ``d_augment`` both sides augmented alike
   (:mod:`.augment`); Platonic3D's D3 then on ground-truth volumes vs v;
5. **update G and E** (:meth:`Trainer._update_generator`) on the sum of the named terms of
   :data:`.terms.G_TERMS` that the config sets, each λ · value:

       L_G = adv(D(I_view))                                  'adv2d'
           + w₃ adv(D3(v))                                   'adv3d'         (platonic3d)
           + λ_rec mean (I_front − x)²                       'rec'           (reconstruction; l1: |·|;
                                                                              rec_channels alpha: opacity)
           + λ_rec mean (v_input − v*)²                      'rec3d'         (rec_target: volume)
           + λ_tv L_tv(v) + λ_off L_off(v, ℓ)               'colour_tv', 'colour_offset'
           + λ_ds L_ds(v_input) + λ_turn L_turn(v, φ)        'depth_spread', 'turn'
           + λ_solid L_solid(v_input)                        'solidity'
           + λ_cm mean |c̄(I_view) − c̄(x)|                   'colour_match'
           + λ_pose L_pose + L_light                         'pose', 'light' (the heads, below)

   (the priors' formulas: :mod:`.losses`; one place sees every term, :meth:`Trainer._g_objective`).
   With ``train.ema`` a moving average of E's and G's weights follows.

D is updated before G, and G's adversarial term uses the updated D (the usual alternating scheme;
the paper's listing computes c_Gen before the update, which autograd cannot do once D's weights
changed in place). The baselines' modes ('prgan', 'platonic3d', 'gan3d', :mod:`.baselines`) change
stages of this loop: PrGAN's views and G's input, Platonic3D's second critic, and the 3D-GAN's
step without images.

Where the volume stands (``train.pose``). With 'input' (the paper's view-space reconstruction)
v lives in the input camera's frame: I_front renders it from ω₀ and the random views ω are drawn
around that frame. A camera above the object sees its up axis tilted, so a right volume is tilted
by the input's elevation θ₀ in that frame, its views from random ω are rolled, and D, whose photos
were all taken by upright cameras, pushes G to build the object upright in every input frame
instead (docs/training.md, "The measurements"). With 'elevation' G builds the object
upright, in its own frame; a pose head P reads the input camera's elevation θ̂ = P(z) from E's
code, and

    I_front = R(ω₀, tilt(v, θ̂))       (v seen from elevation θ̂, differentiable in θ̂)
    I_view  = R(ω, v),  ω ~ p_view     (around the upright object, as the photos' cameras were)

The input-view term alone does not teach P the elevation (it stays uncorrelated with θ₀,
docs/training.md, "The measurements"), so P also learns from G's own renders, whose elevations are known:

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
(docs/training.md, "The measurements").

The reconstruction term compares images by default (``train.rec_target: image``, as above). With
``rec_target: volume`` (the 3D modes) it compares volumes instead: λ_rec ‖v − v*‖², where v* is
the input image's ground-truth volume resampled into its camera's frame (:mod:`.baselines`).

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
from torch import nn
from torch.nn.parallel import DistributedDataParallel as DDP

from ..config import Config, ConfigError
from ..config.train_settings import MODES, MODES_3D, POSES, REC_TARGETS, TASKS  # noqa: F401  (the choice lists, also named here)
from ..model import Model, critic_config
from ..networks.nets import Discriminator, VolumeDiscriminator, init_critic_he, init_he, init_weights
from ..networks.photo_colours import photo_volume
from ..render.pytorch.closed_form import tilt
from ..render.pytorch.single_scatter import daylights
from ..views import DEFAULT_ELEVATION, front_view, sample_views, to_angles
from .augment import augment, augment_photos
from .baselines import BaselineModes, ring_views
from .data import TrainingData
from .losses import d_loss, gradient_penalty, hard_accuracy_counts, r1_penalty, soft_accuracy_counts
from .renderer import make_lit_renderer, make_renderer
from .image_roll import input_frame_roll, roll
from .step_state import D_AUGMENT, PHOTO_AUGMENT, RENDER, StepState, side_generator, side_seed
from .terms import active_terms, g_terms

__all__ = ["Trainer", "TASKS", "MODES", "MODES_3D", "REC_TARGETS", "POSES", "ring_views"]


class Trainer(BaselineModes):
    """The :class:`~mitsuba_platonic.model.Model` being trained (``model``: E and G), the critics,
    optimisers and :meth:`step`; ``nets`` holds E, G, D (and D3) under one state dict;
    ``rank``/``world`` for data-parallel runs; ``terms`` the config's terms of G's objective
    (:func:`~mitsuba_platonic.train.terms.active_terms`). The baselines' stages are inherited from
    :class:`~mitsuba_platonic.train.baselines.BaselineModes`."""

    def __init__(self, cfg: Config, data: TrainingData, device: torch.device, rank: int = 0, world: int = 1):
        if cfg.train.batch_size % world:
            raise ConfigError(f"train.batch_size: {cfg.train.batch_size} must be divisible by the "
                              f"number of processes ({world})")
        needs_3d = cfg.train.mode in MODES_3D
        if needs_3d and data.volumes is None:
            raise ValueError(f"train.mode {cfg.train.mode!r} needs ground-truth volumes")
        self.cfg, self.data, self.device, self.rank, self.world = cfg, data, device, rank, world
        self.nets = self._networks(needs_3d)
        self.nets.to(device)
        #: train.ema: the moving average of E's and G's weights (a copy of ``model``, never trained)
        self.ema: Optional[Model] = (copy.deepcopy(self.model).requires_grad_(False)
                                     if cfg.train.ema is not None else None)
        self.modules: Dict[str, nn.Module] = dict(self.nets.items())
        if world > 1:
            self.modules = {k: DDP(m, device_ids=[device.index] if device.type == "cuda" else None)
                            for k, m in self.nets.items()}
        self._optimisers()
        self.render = make_renderer(cfg.render)
        #: train.light: head: single scattering under a given light, for the input view; else None
        self.render_lit = make_lit_renderer(cfg.render) if cfg.train.light == "head" else None
        self.images = data.images.to(device)
        self.volumes = data.volumes.to(device) if needs_3d else None
        #: 'prgan': the 8 ring views (train.elevation, default 0°)
        self.ring = ring_views(cfg.train.elevation if cfg.train.elevation is not None else 0.0) \
            if cfg.train.mode == "prgan" else None
        self.terms = active_terms(cfg.train)

    def _networks(self, needs_3d: bool) -> nn.ModuleDict:
        """E, G (``model``), D, the heads and D3, initialised from the run's seed: one draw for all,
        then ``model.init`` / ``model.critic_init`` 'he' re-draw E and G / the critics from it."""
        cfg = self.cfg
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
        nets = nn.ModuleDict(nets)
        nets.apply(init_weights)
        if cfg.model.init == "he":                           # E and G re-drawn, from the run's seed
            torch.manual_seed(cfg.run.seed)
            init_he(self.model.E)
            init_he(self.model.G)
        if cfg.model.critic_init == "he":                    # the critics re-drawn, from the run's seed
            torch.manual_seed(cfg.run.seed)
            for name in ("D", "D3"):
                if name in nets:
                    nets[name].apply(init_critic_he)
        return nets

    def _optimisers(self) -> None:
        """Adam for G (with E for reconstruction, and the pose and light heads at E's rate), D and D3."""
        t = self.cfg.train
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

    def global_mean(self, loss: torch.Tensor) -> float:
        """``loss``, a mean over this process's rows, averaged over the processes: what a step logs."""
        return float(self._all_sum(loss.detach().cpu()) / self.world)

    def step(self, step: int) -> Dict[str, float]:
        """One update of Algorithm 1 (module docstring); returns the step's scalars (means over the
        whole batch)."""
        if self.cfg.train.mode == "gan3d":                   # the 3D-GAN renders nothing (train/baselines.py)
            return self._step_gan3d(step)
        s = self._sample(step)                               # 1. x, ω ~ p_view, z ~ N(0, I), ε
        self._generate(s)                                    # 2. z = E(x) or the prior's; v = G(z)
        self._render(s)                                      # 3. I_view = R(ω, v), I_front = R(ω₀, v)
        self._update_critics(s)                              # 4. D on x vs I_view (and D3 on volumes)
        self._update_generator(s)                            # 5. G and E on the sum of the named terms
        return s.out

    # -- 1. sample --------------------------------------------------------------------------

    def _sample(self, step: int) -> StepState:
        """The step's draws from its generator, in this order: the batch's indices, z ~ N(0, I), the
        random views (PrGAN: ring views), WGAN-GP's ε, D's roll angles, D3's real volumes; and the
        photos x of the batch (``train.photo_augment``: transformed, from their own stream)."""
        t, g = self.cfg.train, self.generator(step)
        B, K = t.batch_size, t.random_views
        s = StepState(step, g, idx=torch.randint(len(self.images), (B,), generator=g))
        s.x = self._shard(self.images[s.idx.to(self.device)])
        if t.photo_augment:                                  # train/augment.py: new photos for E, the target and D
            s.x = augment_photos(s.x, t.photo_augment, side_generator(self.cfg.run.seed, step, PHOTO_AUGMENT, self.rank))
        s.z_prior = torch.randn(B, self.cfg.model.latent, generator=g)
        if self.ring is not None:                            # 'prgan': one of the 8 ring views per random view
            s.views, s.ring_k = self._ring_draw(g)
        else:
            s.views = self._shard(self._views(B * K, g).view(B, K, 3)).reshape(-1, 3)
        s.eps = self._shard(torch.rand(B * K, generator=g))
        s.roll_real, s.roll_fake = self._roll_angles(g, s.views)
        if "D3" in self.nets:                                # 'platonic3d'
            s.real_volumes = self._real_volumes(g)
        return s

    def _roll_angles(self, g: torch.Generator, views: torch.Tensor) -> Tuple[Optional[torch.Tensor], Optional[torch.Tensor]]:
        """``train.d_roll``: the angles D's reals and fakes are turned by (train/image_roll.py); None: as they are.
        'uniform': an angle per real and per fake image; 'matched': the reals turned as a right
        volume's views are, for input elevations drawn from the collection's views (photos: p_view)."""
        cfg, t = self.cfg, self.cfg.train
        n = t.batch_size * t.random_views
        if t.d_roll == "uniform":
            ψ_real, ψ_fake = self._shard(torch.rand(2, n, generator=g).mul(2 * math.pi).T).T
            return ψ_real, ψ_fake
        if t.d_roll == "matched":
            photos = cfg.data if cfg.data.source == "procedural" else None
            return input_frame_roll(views, self._shard(to_angles(self._views(n, g, photos))[1])), None
        return None, None

    # -- 2. generate ------------------------------------------------------------------------

    def _generate(self, s: StepState) -> None:
        """z = E(x) (reconstruction) or the prior's z; G's volumes (PrGAN: G(z, onehot(k)), train/baselines.py)."""
        self.nets.train()
        rec = self.cfg.train.task == "reconstruction"
        s.z = self.modules["E"](s.x) if rec else self._shard(s.z_prior).to(self.device)
        if s.ring_k is not None:
            self._ring_generate(s)
        else:
            self._volumes(s)

    def _volumes(self, s: StepState) -> None:
        """v = G(z) (``model.photo_colour``: with colour offsets ℓ from the photo's), each volume once
        per random view, and the input view's: with ``train.pose: elevation`` v tilted by θ̂ = P(z)."""
        cfg, G = self.cfg, self.modules["G"]
        if cfg.model.photo_colour:                           # G's colour offsets from x's (photo_colours.photo_volume)
            θ = None
            if "P" in self.nets and cfg.model.photo_texture:     # the head's θ̂, held constant: the
                with torch.no_grad():                            # plain module, so DDP sees one use of P
                    θ = self.nets["P"](s.z.detach())
            s.v, s.offsets = photo_volume(G, s.z, s.x, cfg.model, θ)
        else:
            s.v = G(s.z)
        K = cfg.train.random_views
        s.v_view, s.v_input = (s.v.repeat_interleave(K, 0) if K > 1 else s.v), s.v    # K = 1: no copy
        if "P" in self.modules:                              # train.pose: elevation: upright v, seen from θ̂
            s.v_input = self._input_volume(s)

    def _input_volume(self, s: StepState) -> torch.Tensor:
        """``train.pose: elevation``: the input view's volume, v tilted to the pose head's elevation θ̂ = P(z)."""
        return tilt(s.v, self.modules["P"](s.z))

    # -- 3. render --------------------------------------------------------------------------

    def _render(self, s: StepState) -> None:
        """I_view = R(ω, v_view) with the step's render seed; for an image reconstruction term also
        the input view I_front = R(ω₀, v_input) (``train.light: head``: under the light L(z) reads)."""
        t = self.cfg.train
        s.seed = side_seed(self.cfg.run.seed, s.step, RENDER, self.rank) >> 2
        s.i_view = self.render(s.v_view, s.views.to(self.device), s.seed)
        if t.task != "reconstruction" or t.rec_target != "image":
            return
        front = front_view(s.x.shape[0]).to(self.device)
        if self.render_lit is None:
            s.i_front = self.render(s.v_input, front, s.seed + 1)
            return
        with torch.no_grad():                                # the photo's light as L reads it, held constant
            ω_s, share = self.nets["L"](s.z.detach())        # (the plain module: DDP sees one use of L)
        s.i_front = self.render_lit(s.v_input, front, daylights(ω_s, share))

    # -- 4. update D ------------------------------------------------------------------------

    def _update_critics(self, s: StepState) -> None:
        """D on the photos (one copy per random view) vs the rendered views, both as D sees them:
        rolled (``train.d_roll``) and augmented alike (``train.d_augment``); then, in 'platonic3d',
        D3 on ground-truth volumes vs v, whose verdict on v under its new weights is G's 3D term."""
        t, K = self.cfg.train, self.cfg.train.random_views
        real_d = s.x.repeat_interleave(K, 0) if K > 1 else s.x
        fake_d = s.i_view
        if s.roll_real is not None:
            real_d = roll(real_d, s.roll_real.to(self.device))
        if s.roll_fake is not None:
            fake_d = roll(s.i_view, s.roll_fake.to(self.device))
        if t.d_augment:                                      # train/augment.py: the same kind of T on both sides
            g_aug = side_generator(self.cfg.run.seed, s.step, D_AUGMENT, self.rank)
            real_d, fake_d = augment(real_d, t.d_augment, g_aug), augment(fake_d, t.d_augment, g_aug)
        s.fake_d = fake_d
        self._critic_update("D", self.opt_d, real_d, fake_d.detach(), s.eps, t.d_gate, s.out)
        if t.mode == "platonic3d":
            s.d3_verdict = self._update_d3(s)

    # -- 5. update G and E ------------------------------------------------------------------

    def _update_generator(self, s: StepState) -> None:
        """G (and E, and the heads) on the sum of the config's terms of G_TERMS (train/terms.py);
        logs ``loss_g``, the 2D adversarial term."""
        terms = g_terms(self, s, self.terms)
        self._update_g(self._g_objective(terms), s.step)
        s.out["loss_g"] = self.global_mean(terms["adv2d"])

    def _g_objective(self, terms: Dict[str, torch.Tensor]) -> torch.Tensor:
        """G's (and E's) loss: the sum of its weighted terms, named as :data:`.terms.G_TERMS` names
        them ('adv2d', 'adv3d', 'rec', 'rec3d', the priors, 'pose', 'light'), in that order. One
        place that sees every term, so the tests can check which of them reach G."""
        return sum(terms.values())

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
