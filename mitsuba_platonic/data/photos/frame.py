"""Framing and resampling: premultiplied linear RGBA at the photo's size → ``(4, R, R)``.

**Framing.** ``crop="image"`` (default) keeps the photo's framing; ``crop="bbox"`` first crops
to the bounding box of ``α > 0``. The result is padded with transparent pixels to a centred
square of side ``S = ceil(max(h, w) / (1 − 2·margin))``, so the longer side maps to
``R·(1 − 2·margin)`` output pixels and the shorter side is padded: never stretched. (An odd
padding puts the extra source pixel at the bottom/right, a shift of ``R/(2S)`` output pixels.)

A photo (with ``crop="bbox"``: its object's bounding box) whose longer side is more than
:data:`MAX_ASPECT` (8) times its shorter side is rejected as ``extreme_aspect``: padded to a
square it would fill less than 1/8 of the training image (an 8 × 2000 photo becomes a 2-pixel
strip in a 16² image).

**Resampling** ``S × S → R × R`` of the premultiplied linear image, all four channels alike,
with a separable tent (triangle) filter whose support is scaled by the reduction factor
(Pillow's float-image ``BILINEAR`` resampler). All its weights are ≥ 0, so each output pixel
is a convex combination of input pixels: values stay in [0, 1], ``rgb ≤ alpha`` holds exactly
and no ringing or halo can appear at silhouette edges. Resampling *premultiplied linear*
values is what keeps edges free of dark or bright halos: transparent pixels contribute
nothing whatever colour their RGB holds in the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

import numpy as np
from PIL import Image

from .rejections import ImageRejected

__all__ = ["frame_and_resample", "framing", "Framing", "check_aspect", "CROPS", "MAX_ASPECT"]

#: ``crop`` choices: keep the photo's framing, or crop to the object's bounding box.
CROPS = ("image", "bbox")

#: The largest aspect ratio (longer side / shorter side) of what is framed: the photo, or with
#: ``crop="bbox"`` its object's bounding box. Framing pads the shorter side to a square, so the
#: content covers only 1 / ratio of the training image: beyond 8:1 that is under 12.5 %, a strip
#: at most R/8 pixels across (2 pixels at R = 16), which would teach the networks a near-empty image.
MAX_ASPECT = 8.0


def check_aspect(w: int, h: int, name: str, what: str = "the image") -> None:
    """Raise ``ImageRejected('extreme_aspect')`` if ``max(w, h) / min(w, h)`` exceeds :data:`MAX_ASPECT`."""
    ratio = max(w, h) / max(1, min(w, h))
    if ratio > MAX_ASPECT:
        raise ImageRejected("extreme_aspect",
                            f"{name}: {what} is {w} × {h} pixels, an aspect ratio of {ratio:.3g}:1; at most "
                            f"{MAX_ASPECT:g}:1 is accepted, since padded to a square it would fill only "
                            f"{100.0 / ratio:.2g} % of the training image; crop it to the object first")


@dataclass(frozen=True)
class Framing:
    """Where :func:`frame_and_resample` puts a photo: the kept part is rows ``row … row + height − 1``
    and columns ``col … col + width − 1`` of the photo, placed at (``top``, ``left``) in a transparent
    square of ``side`` source pixels, which is then resampled to R × R."""

    row: int
    col: int
    height: int
    width: int
    side: int
    top: int
    left: int

    def square(self) -> Tuple[float, float, float]:
        """The square's centre (row, column) and side in the photo's pixel units (edges at integers):
        the photo's pixel (i, j) lands at ((i + ½ − row_c) / side, (j + ½ − col_c) / side) of the
        framed image's width, measured from its centre."""
        return (self.row - self.top + self.side / 2.0, self.col - self.left + self.side / 2.0, float(self.side))


def framing(alpha: np.ndarray, crop: str = "image", margin: float = 0.0, name: str = "<image>") -> Framing:
    """The framing rule of :func:`frame_and_resample` for a photo of alpha ``(H, W)``: crop to the
    bounding box of ``α > 0`` (``crop="bbox"``; the whole photo where no pixel is covered), pad to a
    centred square of side ``S = ceil(max(h, w) / (1 − 2·margin))``.

    Raises:
        ImageRejected: ``extreme_aspect`` (see :func:`check_aspect`).
    """
    row, col, (h, w) = 0, 0, alpha.shape[:2]
    if crop == "bbox":
        rows = np.flatnonzero(alpha.any(axis=1))
        cols = np.flatnonzero(alpha.any(axis=0))
        if rows.size:
            row, col = int(rows[0]), int(cols[0])
            h, w = int(rows[-1]) + 1 - row, int(cols[-1]) + 1 - col
    check_aspect(w, h, name, "its object's bounding box" if crop == "bbox" else "the image")
    side = max(h, w, math.ceil(max(h, w) / (1.0 - 2.0 * margin) - 1e-9))
    return Framing(row, col, h, w, side, (side - h) // 2, (side - w) // 2)


def _resample(planes: np.ndarray, resolution: int) -> np.ndarray:
    """``(C, S, S)`` float32 → ``(C, R, R)`` with Pillow's antialiasing triangle filter."""
    out = np.empty((planes.shape[0], resolution, resolution), np.float32)
    for c, plane in enumerate(planes):
        image = Image.fromarray(np.ascontiguousarray(plane, dtype=np.float32))
        out[c] = np.asarray(image.resize((resolution, resolution),
                                         resample=Image.Resampling.BILINEAR))
    return out


def frame_and_resample(image: np.ndarray, resolution: int = 64, *, crop: str = "image",
                       margin: float = 0.0, name: str = "<image>") -> np.ndarray:
    """``(H, W, 4)`` premultiplied linear RGBA → ``(4, R, R)`` float32.

    ``crop="bbox"`` crops to the bounding box of ``α > 0`` first; the image is then padded
    with transparent pixels to a centred square of side ``S = ceil(max(h, w) / (1 − 2·margin))``
    and resampled to ``R × R`` with the triangle filter. The result is clipped to
    ``0 ≤ alpha ≤ 1``, ``0 ≤ rgb ≤ alpha`` (a no-op up to float rounding).

    Raises:
        ImageRejected: ``extreme_aspect`` if what is framed (the image, or with ``crop="bbox"``
            the bounding box) is more than :data:`MAX_ASPECT` times longer than wide or wider than long.
    """
    f = framing(image[..., 3], crop, margin, name)
    image = image[f.row:f.row + f.height, f.col:f.col + f.width]
    planes = np.zeros((4, f.side, f.side), np.float32)
    planes[:, f.top:f.top + f.height, f.left:f.left + f.width] = np.moveaxis(image, 2, 0)
    out = _resample(planes, resolution)
    np.clip(out[3], 0.0, 1.0, out=out[3])
    np.clip(out[:3], 0.0, out[3:4], out=out[:3])
    return out
