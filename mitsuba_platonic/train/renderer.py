"""The rendering layer R(ω, v) a run trains through, chosen by ``config.render``, and single
scattering under a given light (``train.light: head``).

A light read from the photo (``train.light: head``, docs/training.md, "The measurements"): the random
views are rendered under lights drawn from the prior, pair i's from the step's
seed as :func:`~mitsuba_platonic.render.render_with` draws them
(:func:`~mitsuba_platonic.render.pytorch.single_scatter.sample_lights`), so the
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
from ..render.pytorch.single_scatter import LightBatch
from ..views import camera_frames

__all__ = ["make_renderer", "RenderFn", "LitRenderFn", "make_lit_renderer", "in_camera"]

#: ``fn(volume, views, seed) → images`` (:func:`make_renderer`)
RenderFn = Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]
#: ``fn(volume, views, lights) → images`` (:func:`make_lit_renderer`)
LitRenderFn = Callable[[torch.Tensor, torch.Tensor, LightBatch], torch.Tensor]

def make_renderer(settings: RenderSettings) -> RenderFn:
    """``fn(volume, views, seed) → images``, differentiable w.r.t. ``volume``: the config's
    ``render`` section (a :class:`~mitsuba_platonic.render.RenderSettings`) with a per-step seed."""
    settings = settings.validate()
    return lambda v, w, seed: render_with(v, w, settings, seed)


def make_lit_renderer(settings: RenderSettings) -> LitRenderFn:
    """``fn(volume, views, lights) → images``, differentiable w.r.t. ``volume``: single scattering
    (``settings.backend`` 'single_scatter' or 'scatter_march', with its steps and samples) under the
    given :class:`~mitsuba_platonic.render.pytorch.single_scatter.LightBatch`, one light per pair, in place
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
