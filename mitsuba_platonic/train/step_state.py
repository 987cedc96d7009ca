"""What one training step holds: the sampled batch, views and noise, G's volumes, their renders and
the images the critic sees (:class:`StepState`), filled stage by stage by
:meth:`~mitsuba_platonic.train.trainer.Trainer.step` and read by the named terms of G's objective
(:mod:`mitsuba_platonic.train.terms`); and the step's side streams (:func:`side_seed`).

Randomness: the batch, the views, the noise and the roll angles come from one generator seeded by
(run seed, step), drawn in a fixed order; what is drawn elsewhere in the step (the photos'
augmentation, D's augmentation, the turn prior's angles, the renderer's seed) comes from a stream of
its own, seeded by (run seed, step, tag, rank), so adding a draw to one stream never moves another.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional

import numpy as np
import torch

__all__ = ["StepState", "side_seed", "side_generator", "RENDER", "D_AUGMENT", "PHOTO_AUGMENT", "TURN"]

#: The tags of the step's side streams (:func:`side_seed`).
RENDER, D_AUGMENT, PHOTO_AUGMENT, TURN = 7, 11, 13, 17


def side_seed(run_seed: int, step: int, tag: int, rank: int) -> int:
    """The seed of side stream ``tag`` of ``step`` on process ``rank``: the first 32-bit word of
    ``numpy.random.SeedSequence([run_seed, step, tag, rank])``."""
    return int(np.random.SeedSequence([run_seed, step, tag, rank]).generate_state(1)[0])


def side_generator(run_seed: int, step: int, tag: int, rank: int) -> torch.Generator:
    """A CPU generator seeded by :func:`side_seed`."""
    g = torch.Generator()
    g.manual_seed(side_seed(run_seed, step, tag, rank))
    return g


@dataclass
class StepState:
    """One step's tensors, this process's rows unless said otherwise (B the global batch, b = B / world
    this process's, K = ``train.random_views``):

    - sampled: ``idx`` (B,) the batch's image indices (global); ``x`` (b, C, H, W) its photos
      (augmented with ``train.photo_augment``); ``z_prior`` (B, latent) z ~ N(0, I) (global);
      ``views`` (b K, 3) the random views ω ~ p_view (PrGAN: ring views, ``ring_k`` their indices);
      ``eps`` (b K,) WGAN-GP's ε; ``roll_real``/``roll_fake`` D's in-plane angles (``train.d_roll``) or
      None; ``real_volumes`` D3's ground-truth batch (3D modes) or None;
    - generated: ``z`` = E(x) or z_prior; ``v`` G's volumes; ``offsets`` ℓ, G's colour offsets from the
      photo's (``model.photo_colour``) or None; ``v_view`` the volume of each random view (b K);
      ``v_input`` the input view's volume (b; with ``train.pose: elevation`` tilted by θ̂);
    - rendered: ``seed`` the renderer's; ``i_view`` = R(ω, v_view); ``i_front`` = R(ω₀, v_input) or None;
    - the critics': ``fake_d`` the rendered views as D sees them (rolled, augmented); ``d3_verdict``
      G's 3D adversarial loss under D3's updated weights (3D modes) or None;
    - ``out``: the step's scalars, in the order they are logged.
    """

    step: int
    g: torch.Generator
    idx: Optional[torch.Tensor] = None
    x: Optional[torch.Tensor] = None
    z_prior: Optional[torch.Tensor] = None
    views: Optional[torch.Tensor] = None
    ring_k: Optional[torch.Tensor] = None
    eps: Optional[torch.Tensor] = None
    roll_real: Optional[torch.Tensor] = None
    roll_fake: Optional[torch.Tensor] = None
    real_volumes: Optional[torch.Tensor] = None
    z: Optional[torch.Tensor] = None
    v: Optional[torch.Tensor] = None
    offsets: Optional[torch.Tensor] = None
    v_view: Optional[torch.Tensor] = None
    v_input: Optional[torch.Tensor] = None
    seed: Optional[int] = None
    i_view: Optional[torch.Tensor] = None
    i_front: Optional[torch.Tensor] = None
    fake_d: Optional[torch.Tensor] = None
    d3_verdict: Optional[torch.Tensor] = None
    out: Dict[str, float] = field(default_factory=dict)
