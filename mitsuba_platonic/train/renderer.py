"""The rendering layer R(ω, v) a run trains through, chosen by ``config.render``, the schedule
that can start a lit run through emission–absorption (``train.light_warmup``, ``train.light_fade``),
and single scattering under a given light (``train.light: head``).

A lit renderer (single scattering, the path tracer) can be entered from an emissive start, as
Nimier-David et al. (2022) start dense scattering volumes, and ShadeGAN fades its shading in: at
step s the image G's volume is judged by is

    I(s) = (1 − λ_s) I_EA + λ_s I_lit,     λ_s = clamp((s − W) / F, 0, 1)      (F = 0: a switch at W)

with W = ``light_warmup`` steps through the EA marcher alone and F = ``light_fade`` steps of the
blend (both renderers run only while 0 < λ_s < 1). What it does to shape: docs/training.md,
"Training through light".

A light read from the photo (``train.light: head``, docs/training.md, "A light read from the
photo"): the random views are rendered under lights drawn from the prior, pair i's from the step's
seed as :func:`~mitsuba_platonic.render.render_with` draws them
(:func:`~mitsuba_platonic.render.single_scatter.sample_lights`), so the
trainer knows them; a light head learns to read them from those renders, in each view's camera
frame (:func:`in_camera`: the sun direction's components along the camera's right, up and ω), and
the input view, whose camera frame is the world's, is rendered under the light it reads from the
photo (:func:`make_lit_renderer`).
"""

from __future__ import annotations

from typing import Callable

import torch

from ..render import RenderSettings, render_under, render_with
from ..render.settings import SINGLE_SCATTERING
from ..render.single_scatter import LightBatch
from ..views import camera_frames

__all__ = ["make_renderer", "light_share", "blend", "RenderFn", "LitRenderFn", "EA_WARMUP", "make_lit_renderer",
           "in_camera"]

#: ``fn(volume, views, seed) → images`` (:func:`make_renderer`)
RenderFn = Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]
#: ``fn(volume, views, lights) → images`` (:func:`make_lit_renderer`)
LitRenderFn = Callable[[torch.Tensor, torch.Tensor, LightBatch], torch.Tensor]

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


def make_lit_renderer(settings: RenderSettings) -> LitRenderFn:
    """``fn(volume, views, lights) → images``, differentiable w.r.t. ``volume``: single scattering
    (``settings.backend`` 'single_scatter' or 'scatter_march', with its steps and samples) under the
    given :class:`~mitsuba_platonic.render.single_scatter.LightBatch`, one light per pair, in place
    of the prior's."""
    settings = settings.validate()
    if settings.backend not in SINGLE_SCATTERING:
        raise ValueError(f"make_lit_renderer: expected a backend of {list(SINGLE_SCATTERING)}, got {settings.backend!r}")
    return lambda v, w, lights: render_under(v, w, settings, lights)


def in_camera(directions: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """World ``directions`` ``(B, 3)`` in the frames of the cameras of ``views`` ``(B, 3)``
    (:func:`~mitsuba_platonic.views.camera_frames`): ``(d · right, d · up, d · ω)``, float64. The input
    view ω₀ = (0, 0, 1) has right = +x and up = +y, so there camera and world coordinates agree."""
    right, up, ω = camera_frames(views)
    d = directions.to(right.device, torch.float64)
    return torch.stack([(d * right).sum(1), (d * up).sum(1), (d * ω).sum(1)], dim=1)
