"""Renderers: one entry point, two backends (closed form | Mitsuba) that agree.

``render(volume, views, model, backend, **options)`` → ``(B, C, H, W)``, differentiable
w.r.t. ``volume``. See :mod:`.closed_form` and :mod:`.marcher` (the batched Mitsuba/Dr.Jit ray
marcher: one launch per call) for the maths.
"""

from __future__ import annotations

from typing import Any

import torch

from ..views import validate_views
from ..volume import CHANNELS, validate_volume
from .closed_form import FILTERS, render_closed_form

__all__ = ["render", "BACKENDS", "MODELS"]

BACKENDS = ("closed_form", "mitsuba")
MODELS = tuple(CHANNELS)
_CLOSED_FORM_OPTIONS = {"filter"}
_MITSUBA_OPTIONS = {"step", "spp", "jitter", "filter", "termination", "seed"}


def render(volume: torch.Tensor, views: torch.Tensor, model: str = "ea",
           backend: str = "closed_form", **options: Any) -> torch.Tensor:
    """Render a batch of (volume, view) pairs.

    Args:
        volume: ``(B, C, N, N, N)`` in [0, 1]; C = 1 ``[density]`` for 'vh'/'ao',
            C = 4 ``[r, g, b, density]`` for 'ea' (layout: docs/conventions.md, :mod:`mitsuba_platonic.volume`).
        views: ``(B, 3)`` unit vectors from the object towards the camera.
        model: image formation, 'vh' | 'ao' | 'ea'.
        backend: 'closed_form' (the paper's layers, reference mode) or 'mitsuba' (ray marcher).
        options: ``filter`` ('nearest' | 'trilinear', both backends; default 'trilinear');
            Mitsuba only: ``step`` (voxels, default 1), ``spp`` (default 1), ``jitter``
            (default False), ``termination`` (default 0), ``seed`` (default 0).

    Returns:
        ``(B, 1, N, N)`` opacity for VH/AO, ``(B, 4, N, N)`` premultiplied RGB + alpha for EA.

    Raises:
        ValueError: on a wrong rank or channel count, values outside [0, 1], NaN, non-unit
            views, mismatched batch, an unknown model/backend or option.
    """
    if model not in CHANNELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    validate_volume(volume, model)
    validate_views(views, batch=volume.shape[0])
    allowed = _CLOSED_FORM_OPTIONS if backend == "closed_form" else _MITSUBA_OPTIONS
    unknown = set(options) - allowed
    if unknown:
        raise ValueError(f"unknown option(s) {sorted(unknown)} for backend {backend!r}; "
                         f"expected some of {sorted(allowed)}")
    filter = options.get("filter", "trilinear")
    if filter not in FILTERS:
        raise ValueError(f"filter must be one of {tuple(FILTERS)}, got {filter!r}")
    if backend == "closed_form":
        return render_closed_form(volume, views.to(volume.device), model, filter)
    from .marcher import MarchOptions, march
    return march(volume, views, model, MarchOptions(**options))
