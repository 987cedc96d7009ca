"""Contact sheets: a shape class at a glance (a few shapes, each from a ring of views)."""

from __future__ import annotations

from pathlib import Path
from typing import Union

import torch

from .. import views as V
from ..files.fileio import atomic_write, make_folder
from ..images import composite, linear_to_srgb, to_hwc
from ..render import render
from . import shapes
from .collection_spec import CollectionSpec

__all__ = ["contact_sheet"]


def contact_sheet(shape_class: str, path: Union[str, Path], n_shapes: int = 4, n_views: int = 8,
                  resolution: int = 64, elevation: float = 20.0, seed: int = 0,
                  shape_seed=None) -> Path:
    """Render ``n_shapes`` members of ``shape_class`` from ``n_views`` azimuths and save a PNG grid.

    Rows are shapes, columns views (a turntable at ``elevation`` degrees); EA closed form,
    composited over white and sRGB-encoded for display. ``shape_seed(i)`` picks the seeds (the
    default matches :class:`~mitsuba_platonic.data.collection_spec.CollectionSpec` with ``seed``).
    """
    from matplotlib.figure import Figure  # lazy: matplotlib is slow to import, only for figures

    if shape_seed is None:
        spec = CollectionSpec(shape_class, seed=seed)
        shape_seed = spec.shape_seed
    views = V.turntable(n_views, elevation=elevation, start=30.0)
    azimuths, _ = V.to_angles(views)
    fig = Figure(figsize=(1.3 * n_views + 0.6, 1.3 * n_shapes + 0.7), dpi=110)
    axes = fig.subplots(n_shapes, n_views, squeeze=False)
    for i in range(n_shapes):
        s = shape_seed(i)
        vol = shapes.generate(shape_class, s, resolution)
        with torch.no_grad():
            images = render(vol[None].expand(n_views, -1, -1, -1, -1).contiguous(), views, "ea")
        for j in range(n_views):
            rgb = linear_to_srgb(composite(to_hwc(images[j]), background=1.0))
            ax = axes[i, j]
            ax.imshow(rgb, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if j == 0:
                ax.set_ylabel(f"seed {s}", fontsize=7)
            if i == 0:
                ax.set_title(f"az {float(azimuths[j]) % 360:.0f}°", fontsize=8)
    fig.suptitle(f"{shape_class}: {n_shapes} shapes × {n_views} views (EA, closed form, {resolution}³, "
                 f"elevation {elevation:g}°)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    make_folder(path.parent)
    atomic_write(path, lambda tmp: fig.savefig(tmp))          # whole, and never through a link
    return path
