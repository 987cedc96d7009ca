"""The rendering layer R(ω, v) a run trains through, chosen by ``config.render``."""

from __future__ import annotations

from typing import Callable

import torch

from ..render import RenderSettings, render_with

__all__ = ["make_renderer", "RenderFn"]

RenderFn = Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]


def make_renderer(settings: RenderSettings) -> RenderFn:
    """``fn(volume, views, seed) → images``, differentiable w.r.t. ``volume``: the config's
    ``render`` section (a :class:`~mitsuba_platonic.render.RenderSettings`) with a per-step seed."""
    settings = settings.validate()
    return lambda v, w, seed: render_with(v, w, settings, seed)
