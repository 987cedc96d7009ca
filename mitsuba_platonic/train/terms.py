"""The named terms of G's (and E's) objective, registered in one place: :data:`G_TERMS`.

    L_G = Σ over the active terms of  w_term · value_term(inputs)

Each :class:`Term` declares its ``name`` (the key G's objective sees), the ``weight`` key of
:class:`~mitsuba_platonic.config.train_settings.TrainConfig` that scales it (None: unweighted),
``active``, when a config uses it, and ``reads``, the fields of the step's
:class:`~mitsuba_platonic.train.step_state.StepState` its value is computed from (the value sees those
alone). A new prior is a new unit in :data:`G_TERMS`; the trainer computes the active ones in the
registry's order (which is also their order in the sum) and hands them to its one objective.

The terms, with x the input photos, v = G(z), I_view = R(ω, v), I_front = R(ω₀, v_input):

========================  ===============  ====================================================================
name                      weight           value
========================  ===============  ====================================================================
adv2d                     (none)           adv(D(I_view)): softplus(−l) (non-saturating) or −l (WGAN), mean
adv3d (platonic3d)        ``weight_3d``    adv(D3(v)), D3 after its update
adv3d (gan3d)             (none)           adv(D3(v)): the 3D-GAN's only critic
colour_tv                 ``colour_tv``    Σ w_ij ‖c_i − c_j‖₁ / (3 Σ w_ij) over v (:func:`.losses.colour_tv`)
colour_offset             ``colour_offset`` Σ ρ ‖ℓ‖₁ / (3 Σ ρ) (:func:`.losses.colour_offset`)
depth_spread              ``depth_spread`` the rays' weight distortion of v_input (:func:`.losses.depth_spread`)
turn                      ``turn``         Σ |α − T_φ α| / Σ (α + T_φ α), φ ~ U[0, 2π) per volume (:func:`.losses.turn`)
solidity                  ``solidity``     Σ relu(h − α) / Σ h along v_input's rays (:func:`.losses.solidity`)
colour_match              ``colour_match`` mean |c̄(I_view) − c̄(x)| (:func:`.losses.colour_match`)
rec3d                     ``rec_weight``   mean (v_input − v*)², v* the image's truth in its camera's frame
rec                       ``rec_weight``   mean (I_front − x)² (``rec_loss: l1``: mean |I_front − x|;
                                           ``rec_channels: alpha``: the opacity channel alone)
pose                      ``pose_weight``  mean (P(E(I_view)) − asin ω_y)², I_view detached
light                     (none)           mean (1 − L_ω(E(I_view)) · ω_s^cam) + mean ((L_s(E(I_view)) − s)/(s₁ − s₀))²
========================  ===============  ====================================================================

A prior (colour_tv … colour_match, pose) is active where its weight is above 0, in every mode with
images (not 'gan3d', whose G learns from volumes alone); rec where the reconstruction compares
images, rec3d where it compares volumes; light with ``train.light: head``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, Mapping, Optional, Protocol, Tuple

import torch
import torch.nn.functional as F
from torch import nn

from ..config import Config
from ..config.train_settings import TrainConfig
from ..render.pytorch.single_scatter import SKY_SHARE, sample_lights, sky_share
from ..views import to_angles
from .losses import colour_match, colour_offset, colour_tv, depth_spread, g_loss, solidity, turn
from .renderer import in_camera
from .step_state import TURN, StepState, side_generator

__all__ = ["Term", "StepContext", "G_TERMS", "active_terms", "g_terms"]


class StepContext(Protocol):
    """What a term's value may use besides the step's tensors (the trainer provides it)."""

    cfg: Config
    modules: Mapping[str, nn.Module]
    device: torch.device
    rank: int

    def global_mean(self, loss: torch.Tensor) -> float:
        """A per-process mean, averaged over the processes (what a step logs)."""

    def volume_rec(self, v: torch.Tensor, idx: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
        """mean (v − v*)² against the batch ``idx``'s ground truth in its cameras' frames."""


@dataclass(frozen=True)
class Term:
    """One weighted term of G's objective: ``name``; ``weight``, the TrainConfig key of its weight
    (None: unweighted); ``active(train)``, whether a config uses it; ``reads``, the StepState fields
    ``value(ctx, **inputs)`` is computed from. Calling it gives the weighted value."""

    name: str
    weight: Optional[str]
    active: Callable[[TrainConfig], bool]
    reads: Tuple[str, ...]
    value: Callable[..., torch.Tensor]

    def __call__(self, ctx: StepContext, s: StepState) -> torch.Tensor:
        loss = self.value(ctx, **{k: getattr(s, k) for k in self.reads})
        return loss if self.weight is None else getattr(ctx.cfg.train, self.weight) * loss


def _with_images(t: TrainConfig) -> bool:
    return t.mode != "gan3d"


def _prior(key: str) -> Callable[[TrainConfig], bool]:
    """Active where weight ``key`` is set, in the modes that render images."""
    return lambda t: _with_images(t) and getattr(t, key) > 0


# -- the values ----------------------------------------------------------------------------

def _adv2d(ctx: StepContext, fake_d: torch.Tensor) -> torch.Tensor:
    """adv(D(I_view)) on the rendered views as D sees them (rolled, augmented), D just updated."""
    return g_loss(ctx.cfg.train.loss, ctx.modules["D"](fake_d))


def _adv3d(ctx: StepContext, d3_verdict: torch.Tensor) -> torch.Tensor:
    """adv(D3(v)), evaluated right after D3's update (the critics' stage)."""
    return d3_verdict


def _colour_tv(ctx: StepContext, v: torch.Tensor) -> torch.Tensor:
    return colour_tv(v)


def _colour_offset(ctx: StepContext, v: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    return colour_offset(v, offsets)


def _depth_spread(ctx: StepContext, v_input: torch.Tensor) -> torch.Tensor:
    return depth_spread(v_input)


def _turn(ctx: StepContext, v: torch.Tensor, step: int) -> torch.Tensor:
    """L_turn with one angle φ = 2π u per volume, u ~ U[0, 1) from the step's turn stream."""
    g = side_generator(ctx.cfg.run.seed, step, TURN, ctx.rank)
    φ = 2.0 * math.pi * torch.rand(v.shape[0], generator=g, dtype=torch.float64)
    return turn(v, φ.to(v.device))


def _solidity(ctx: StepContext, v_input: torch.Tensor) -> torch.Tensor:
    return solidity(v_input)


def _colour_match(ctx: StepContext, i_view: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    return colour_match(i_view, x)


def _rec3d(ctx: StepContext, v_input: torch.Tensor, idx: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
    """mean (v − v*)² (the trainer's ``volume_rec``, which logs ``loss_rec3d``)."""
    return ctx.volume_rec(v_input, idx, out)


def _rec(ctx: StepContext, i_front: torch.Tensor, x: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
    """The input-view term, mean (I_front − x)² or mean |I_front − x| over all channels or the
    opacity alone. Logs ``loss_rec``."""
    t = ctx.cfg.train
    a, y = (i_front, x) if t.rec_channels == "all" else (i_front[:, -1:], x[:, -1:])   # 'alpha': the opacity
    loss = F.mse_loss(a, y) if t.rec_loss == "l2" else F.l1_loss(a, y)
    out["loss_rec"] = ctx.global_mean(loss)
    return loss


def _pose(ctx: StepContext, i_view: torch.Tensor, views: torch.Tensor, out: Dict[str, float]) -> torch.Tensor:
    """mean (P(E(I)) − θ)² over G's renders ``i_view`` (detached) from ``views``, θ = asin ω_y their
    elevations in radians: the pose head learns to read the elevation of an upright object's view,
    and carries it over to the photos. Logs ``loss_pose``."""
    θ = to_angles(views, degrees=False)[1].to(ctx.device, i_view.dtype)
    loss = F.mse_loss(ctx.modules["P"](ctx.modules["E"](i_view.detach())), θ)
    out["loss_pose"] = ctx.global_mean(loss)
    return loss


def _light(ctx: StepContext, i_view: torch.Tensor, views: torch.Tensor, seed: int,
           out: Dict[str, float]) -> torch.Tensor:
    """L_light over G's renders ``i_view`` (detached) from ``views``, lit by the prior's lights for
    ``seed`` (the renderer's own draw, :func:`~mitsuba_platonic.render.pytorch.single_scatter.sample_lights`):
    the light head learns the sun's direction in each view's camera frame and the sky's share.
    Logs ``loss_light``."""
    lights = sample_lights(len(i_view), seed)
    ω_cam = in_camera(lights.direction, views).to(ctx.device, i_view.dtype)
    share = sky_share(lights)
    ω_hat, s_hat = ctx.modules["L"](ctx.modules["E"](i_view.detach()))
    lo, hi = SKY_SHARE
    loss = (1.0 - (ω_hat * ω_cam).sum(1)).mean() + \
        (((s_hat - share.to(ctx.device, s_hat.dtype)) / (hi - lo)) ** 2).mean()
    out["loss_light"] = ctx.global_mean(loss)
    return loss


# -- the registry --------------------------------------------------------------------------

#: Every term of G's objective, in the order they are computed and summed.
G_TERMS: Tuple[Term, ...] = (
    Term("adv2d", None, _with_images, ("fake_d",), _adv2d),
    Term("adv3d", "weight_3d", lambda t: t.mode == "platonic3d", ("d3_verdict",), _adv3d),
    Term("adv3d", None, lambda t: t.mode == "gan3d", ("d3_verdict",), _adv3d),
    Term("colour_tv", "colour_tv", _prior("colour_tv"), ("v",), _colour_tv),
    Term("colour_offset", "colour_offset", _prior("colour_offset"), ("v", "offsets"), _colour_offset),
    Term("depth_spread", "depth_spread", _prior("depth_spread"), ("v_input",), _depth_spread),
    Term("turn", "turn", _prior("turn"), ("v", "step"), _turn),
    Term("solidity", "solidity", _prior("solidity"), ("v_input",), _solidity),
    Term("colour_match", "colour_match", _prior("colour_match"), ("i_view", "x"), _colour_match),
    Term("rec3d", "rec_weight", lambda t: t.task == "reconstruction" and t.rec_target == "volume",
         ("v_input", "idx", "out"), _rec3d),
    Term("rec", "rec_weight", lambda t: _with_images(t) and t.task == "reconstruction" and t.rec_target == "image",
         ("i_front", "x", "out"), _rec),
    Term("pose", "pose_weight", _prior("pose_weight"), ("i_view", "views", "out"), _pose),
    Term("light", None, lambda t: _with_images(t) and t.light == "head", ("i_view", "views", "seed", "out"), _light),
)

def active_terms(train: TrainConfig) -> Tuple[Term, ...]:
    """The terms of :data:`G_TERMS` that ``train`` uses, in the registry's order; two with one name
    are an error (each name is one key of G's objective)."""
    terms = tuple(term for term in G_TERMS if term.active(train))
    names = [term.name for term in terms]
    if len(set(names)) != len(names):
        raise ValueError(f"active_terms: two active terms share a name: {names}")
    return terms


def g_terms(ctx: StepContext, s: StepState, terms: Tuple[Term, ...]) -> Dict[str, torch.Tensor]:
    """``{name: weighted value}`` of ``terms`` on the step ``s``, computed in their order."""
    return {term.name: term(ctx, s) for term in terms}
