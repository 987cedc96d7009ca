"""The rendering layer R(ω, v) a run trains through, chosen by ``config.render``, and the schedule
that can start a lit run through emission–absorption (``train.light_warmup``, ``train.light_fade``).

A lit renderer (single scattering, the path tracer) can be entered from an emissive start, as
Nimier-David et al. (2022) start dense scattering volumes, and ShadeGAN fades its shading in: at
step s the image G's volume is judged by is

    I(s) = (1 − λ_s) I_EA + λ_s I_lit,     λ_s = clamp((s − W) / F, 0, 1)      (F = 0: a switch at W)

with W = ``light_warmup`` steps through the EA marcher alone and F = ``light_fade`` steps of the
blend (both renderers run only while 0 < λ_s < 1). What it does to shape: docs/training.md,
"Training through light".
"""

from __future__ import annotations

from typing import Callable

import torch

from ..render import RenderSettings, render_with

__all__ = ["make_renderer", "light_share", "blend", "RenderFn", "EA_WARMUP"]

#: ``fn(volume, views, seed) → images`` (:func:`make_renderer`)
RenderFn = Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]

#: The emission–absorption renderer of a warm-up: the batched marcher, one ray per pixel.
EA_WARMUP = RenderSettings(backend="mitsuba", model="ea")


def make_renderer(settings: RenderSettings) -> RenderFn:
    """``fn(volume, views, seed) → images``, differentiable w.r.t. ``volume``: the config's
    ``render`` section (a :class:`~mitsuba_platonic.render.RenderSettings`) with a per-step seed."""
    settings = settings.validate()
    return lambda v, w, seed: render_with(v, w, settings, seed)


def light_share(step: int, warmup: int, fade: int) -> float:
    """λ_s of the module docstring: 0 during the warm-up, 1 once the fade is over."""
    if warmup < 0 or fade < 0:
        raise ValueError(f"warmup, fade: expected numbers of steps ≥ 0, got {warmup!r}, {fade!r}")
    if step < warmup:
        return 0.0
    return 1.0 if fade == 0 else min(1.0, (step - warmup) / fade)


def blend(ea: RenderFn, lit: RenderFn, λ: float) -> RenderFn:
    """The renderer of a step with light share λ (module docstring): ``lit`` itself at 1, ``ea`` at
    0, else both, blended."""
    if λ == 1.0:
        return lit
    if λ == 0.0:
        return ea
    return lambda v, w, seed: (1.0 - λ) * ea(v, w, seed) + λ * lit(v, w, seed)
