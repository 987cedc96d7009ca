"""Single scattering's reference: Mitsuba's ``volpath`` at ``max_depth`` 2 on the same medium and light.

:func:`~mitsuba_platonic.render.pytorch.single_scatter.render_single_scatter` (torch) and
:func:`~mitsuba_platonic.render.drjit.scatter_march.render_scatter_march` (Dr.Jit) are checked
against it: the path tracer's scene (:mod:`.physical`, ``scenes/physical.xml``) lit by
``scenes/emitters/sun_and_sky.xml`` (a ``directional`` sun and a uniform sky), paths of at most
one scattering event, forward only and Monte Carlo. With the ``metered`` exposure the radiance is
divided by the light's mean luminance, as single scattering's own (docs/rendering.md, "Single
scattering").
"""

from __future__ import annotations

from typing import Sequence

import torch

from ..pytorch.single_scatter import SunAndSky, checked_lights, mean_luminance
from .physical import render_physical

__all__ = ["reference_render"]


def reference_render(volume: torch.Tensor, views: torch.Tensor, lights: Sequence[SunAndSky], spp: int = 1024,
                     seed: int = 0, exposure: str = "metered") -> torch.Tensor:
    """Mitsuba's ``volpath`` at ``max_depth`` 2 (single scattering) on the same medium and light:
    the reference :func:`~mitsuba_platonic.render.pytorch.single_scatter.render_single_scatter` is
    checked against, ``(B, 4, N, N)``, forward only."""
    batch = checked_lights(volume, views, lights, exposure)
    images, _ = render_physical(volume, views, list(lights), spp=spp, max_depth=2, seed=seed, exposure="none")
    if exposure == "metered":
        images[:, :3] /= mean_luminance(batch).to(images)[:, None, None, None]
    return images
