"""The rendering layer R(ω, v) a run trains through, chosen by ``config.render``."""

from __future__ import annotations

from typing import Callable

import torch

from ..config import RenderConfig
from ..render import render

__all__ = ["make_renderer", "RenderFn"]

RenderFn = Callable[[torch.Tensor, torch.Tensor, int], torch.Tensor]


def make_renderer(cfg: RenderConfig) -> RenderFn:
    """``fn(volume, views, seed) → images``, differentiable w.r.t. ``volume``.

    closed_form / mitsuba: :func:`mitsuba_platonic.render` with the config's model and options.
    physical: the differentiable path tracer (:func:`mitsuba_platonic.render.physical.render_physical_ad`)
    under random sky light drawn from ``seed``.
    """
    if cfg.backend == "closed_form":
        return lambda v, w, seed: render(v, w, cfg.model, "closed_form", filter=cfg.filter)
    if cfg.backend == "mitsuba":
        return lambda v, w, seed: render(v, w, cfg.model, "mitsuba", filter=cfg.filter, step=cfg.step,
                                         spp=cfg.spp, jitter=cfg.jitter, seed=seed)
    from ..render.physical import render_physical_ad
    return lambda v, w, seed: render_physical_ad(v, w, lighting=cfg.lighting, spp=cfg.physical_spp,
                                                 max_depth=cfg.max_depth, seed=seed, filter=cfg.filter)
