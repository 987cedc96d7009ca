"""The evaluation's PNG figures: a grid of display images (over white), one line per example."""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Tuple, Union

import torch

from ..files.fileio import atomic_write, make_folder
from . import metrics as M

__all__ = ["save_image_grid"]


def save_image_grid(lines: Sequence[Sequence[torch.Tensor]], titles: Sequence[str], path: Union[str, Path],
                    suptitle: str, cell: Tuple[float, float], extra_height: float = 0.0,
                    labels: Optional[Sequence[str]] = None) -> Path:
    """Write a PNG with one line of images per entry of ``lines`` (``(C, R, R)`` images, shown as
    :func:`~.metrics.display_image`: RGBA over white, opacity in grey), ``titles`` above the first
    line, an optional label left of each line, ``suptitle`` on top. ``cell``: inches per image
    (width, height); ``extra_height``: inches added for the title. Returns ``path``."""
    import matplotlib  # lazy: matplotlib is slow to import, only for figures; Agg before pyplot
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: as matplotlib above

    cols = len(titles)
    fig, axes = plt.subplots(len(lines), cols, figsize=(cell[0] * cols, cell[1] * len(lines) + extra_height),
                             squeeze=False)
    for i, images in enumerate(lines):
        for ax, img, title in zip(axes[i], images, titles):
            d = M.display_image(img)
            ax.imshow(d[..., 0] if d.shape[-1] == 1 else d, cmap="gray", vmin=0.0, vmax=1.0,
                      interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(title, fontsize=7)
        if labels is not None:
            axes[i][0].set_ylabel(labels[i], fontsize=6)
    fig.suptitle(suptitle, fontsize=8)
    fig.tight_layout()
    path = Path(path)
    make_folder(path.parent)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=100))     # whole, and never through a link
    plt.close(fig)
    return path
