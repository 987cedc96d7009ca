"""Renderers: one entry point, two backends (closed form | Mitsuba) that agree, and the one dispatcher.

``render(volume, views, model, backend, **options)`` → ``(B, C, H, W)``, differentiable
w.r.t. ``volume``. See :mod:`.pytorch.closed_form` and :mod:`.drjit.marcher` (the batched
Mitsuba/Dr.Jit ray marcher: one launch per call) for the maths. :func:`render_with` (settings
already checked) is the one place that dispatches to a backend; the backends import nothing of
this module. Its ``window`` (:class:`~.window.Window`) zooms and pans the orthographic camera of
every backend but the torch single scattering (``platonic view``'s camera).

By backend: :mod:`.pytorch` (the closed form, single scattering in torch), :mod:`.drjit` (the
marcher, single scattering at its speed, the sky's occlusion, and what their launches share) and
:mod:`.mitsuba` (the scene files, the per-pair integrator, the path tracer, baked skies), on a
floor of :mod:`.settings`, :mod:`.window`, :mod:`.grids` and :mod:`.variant`. Above them:
:mod:`.frames`, a volume's turntable, and ``platonic compare``'s tools
(:mod:`mitsuba_platonic.bench.compare`, :mod:`mitsuba_platonic.bench.compare_light`).
"""

from __future__ import annotations

from typing import Any, Optional

import torch

from ..errors import UserError
from ..views import validate_views
from ..volume import validate_volume
from .pytorch.closed_form import render_closed_form
from .settings import BACKENDS, MODELS, RenderSettings, check_lanes
from .window import Window, window_or_none

__all__ = ["render", "render_with", "render_under", "RenderSettings", "BACKENDS", "MODELS", "Window"]


def render(volume: torch.Tensor, views: torch.Tensor, model: str = "ea",
           backend: str = "closed_form", seed: int = 0, **options: Any) -> torch.Tensor:
    """Render a batch of (volume, view) pairs.

    Args:
        volume: ``(B, C, N, N, N)`` in [0, 1]; C = 1 ``[density]`` for 'vh'/'ao',
            C = 4 ``[r, g, b, density]`` for 'ea' (layout: docs/conventions.md, :mod:`mitsuba_platonic.volume`).
        views: ``(B, 3)`` unit vectors from the object towards the camera.
        model: image formation, 'vh' | 'ao' | 'ea'.
        backend: 'closed_form' (the paper's layers, reference mode), 'mitsuba' (the batched ray
            marcher), 'physical' (the differentiable path tracer under a random sky; 'ea' only),
            'single_scatter' (single scattering of a random sun and sky; 'ea' only) or
            'scatter_march' (the same light at the marcher's speed; 'ea' only).
        seed: random numbers of this call (the marcher's jitter, the path tracer's and single
            scattering's skies).
        options: the :class:`RenderSettings` the backend reads: ``filter`` ('nearest' |
            'trilinear'; default 'trilinear'; every backend but 'single_scatter', which reads
            trilinearly); 'mitsuba': ``step`` (voxels, default 1), ``spp`` (default 1), ``jitter``
            (default False), ``termination`` (default 0); 'physical': ``lighting``,
            ``physical_spp``, ``max_depth``; 'single_scatter': ``spp`` (default 1),
            ``steps_per_voxel`` (4), ``shadow_planes`` (2); 'scatter_march': ``spp`` (1),
            ``steps_per_voxel`` (4).

    Returns:
        ``(B, 1, N, N)`` opacity for VH/AO, ``(B, 4, N, N)`` premultiplied RGB + alpha for EA.

    Raises:
        ValueError (:class:`~mitsuba_platonic.errors.UserError`): on a wrong rank or channel
            count, an empty batch, a tensor on the 'meta' device, values outside [0, 1], NaN,
            non-unit views, mismatched batch, an unknown model/backend, or an option the backend
            does not read (``OPTIONS_OF``).
    """
    try:
        settings = RenderSettings.for_call(backend, model, **options)
    except UserError:
        raise
    except ValueError as e:                              # the settings' own check: the caller's values
        raise UserError(str(e)) from None
    validate_volume(volume, model)
    validate_views(views, batch=volume.shape[0])
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise UserError(f"seed: expected a non-negative int, got {seed!r}")
    return render_with(volume, views, settings, seed)


def render_with(volume: torch.Tensor, views: torch.Tensor, settings: RenderSettings, seed: int = 0,
                window: Optional[Window] = None) -> torch.Tensor:
    """Render ``(B, C, N, N, N)`` volumes from ``(B, 3)`` views with ``settings`` (inputs assumed valid).

    ``seed`` drives the marcher's jitter and the path tracer's skies and samples. ``window``: the
    orthographic camera's zoom and pan (:class:`~.window.Window`, the same for every pair; None or
    the full window: the whole cross-section, each backend's code as without one).
    """
    window = window_or_none(window)
    if settings.backend == "closed_form":
        return render_closed_form(volume, views.to(volume.device), settings.model, settings.filter, settings.lens,
                                  window)
    if settings.backend == "mitsuba":
        check_lanes(volume.shape[0], volume.shape[-1], settings.spp)   # before Dr.Jit: say why, up front
        from .drjit.marcher import march       # imports Dr.Jit and sets Mitsuba's variant: on the first Mitsuba render
        return march(volume, views, settings, seed, window)
    if settings.backend in ("single_scatter", "scatter_march"):
        from .pytorch.single_scatter import sample_lights             # torch only; kept off the import path
        return render_under(volume, views, settings, sample_lights(volume.shape[0], seed), window)
    from .mitsuba.physical import render_physical_ad    # the path tracer (its scene files, Mitsuba): on first use
    return render_physical_ad(volume, views, lighting=settings.lighting, spp=settings.physical_spp,
                              max_depth=settings.max_depth, seed=seed, filter=settings.filter, window=window)


def render_under(volume: torch.Tensor, views: torch.Tensor, settings: RenderSettings, lights: Any,
                 window: Optional[Window] = None) -> torch.Tensor:
    """Single scattering (``settings.backend`` 'single_scatter' or 'scatter_march', with its steps
    and samples) of ``(B, 4, N, N, N)`` volumes from ``(B, 3)`` views under given ``lights`` (a
    :class:`~.single_scatter.LightBatch`, one light per pair; inputs assumed valid).
    :func:`render_with` draws them from the prior for its seed; a light read from a photo passes its own.
    ``window``: the orthographic camera's zoom and pan, 'scatter_march' only (:class:`~.window.Window`)."""
    window = window_or_none(window)
    if settings.backend == "single_scatter":
        if window is not None:
            raise UserError("window: the single_scatter backend renders the whole cross-section only; zoom and "
                            "pan with 'scatter_march' (the same light at the marcher's speed)")
        from .pytorch.single_scatter import render_single_scatter     # torch only; kept off the import path
        return render_single_scatter(volume, views.to(volume.device), lights, steps_per_voxel=settings.steps_per_voxel,
                                     shadow_planes=settings.shadow_planes, spp=settings.spp)
    if settings.backend == "scatter_march":
        from .drjit.scatter_march import render_scatter_march       # imports Dr.Jit: on first use
        return render_scatter_march(volume, views, lights, steps_per_voxel=settings.steps_per_voxel, spp=settings.spp,
                                    window=window)
    raise ValueError(f"render_under: expected backend 'single_scatter' or 'scatter_march', got {settings.backend!r}")
