"""Compare mode's arithmetic: two renderers' frames at one camera, side by side or as |A − B|.

The page's compare mode renders one camera through two renderers A and B (:data:`PAIRS`: the closed
form against the marcher, the marcher against the path tracer) and shows them in one of
:data:`LAYOUTS`:

- ``side by side``: A's frame, a :data:`GAP`-pixel divider, B's frame; each rendered at half the
  canvas' aspect (:func:`half_aspect`), so that the two fill the canvas together.
- ``difference``: both frames at the canvas' aspect, and of their displayed 8-bit sRGB pixels

      D = |A − B|                       (per channel, in 8-bit levels, 0 … 255)
      d = max(D_R, D_G, D_B)            (per pixel: the magnitude the colour scale maps)
      [lo, hi] = [min d, max d]         (the scale's range, printed on the page)
      t = (d − lo) / (hi − lo)          (0 everywhere where hi = lo)
      colour = the piecewise-linear ramp through :data:`STOPS` at t = 0, 1/(K−1), …, 1

  so the darkest colour is the least difference in the frame and the brightest the largest.

The difference and its range are worked out in both layouts (the halves have one size); only the
difference layout draws it.

The input beside the frame (:func:`input_beside`, a reconstruction's input or photo against the
frame) is the same side-by-side composition: the input, scaled to the frame's height H by the
nearest pixel (source row ⌊(i + ½) R / H⌋ of an R-pixel input, columns alike: each input pixel a
block, nothing blurred), the divider, the frame. :func:`beside_aspect` gives the frame's aspect
a − 1 on a canvas of aspect a, so that the square input and the frame fill the canvas together.

Nothing here renders: :mod:`.app` hands in the frames. numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Tuple

import numpy as np

__all__ = ["PAIRS", "LAYOUTS", "GAP", "STOPS", "pairs_for", "half_aspect", "difference", "ColourScale", "colour_bar",
           "side_by_side", "Comparison", "compare", "beside_aspect", "nearest", "input_beside"]

#: The pairs the page offers: label → (renderer A, renderer B), labels of :data:`~.scene.RENDERERS`.
PAIRS: Dict[str, Tuple[str, str]] = {"closed form vs marcher": ("closed form", "marcher"),
                                     "marcher vs path tracer": ("marcher", "path tracer")}
#: How a comparison is drawn.
LAYOUTS = ("side by side", "difference")
#: The divider's width in pixels between the halves of a side-by-side frame, and its grey (8-bit).
GAP, GAP_GREY = 2, 200
#: The colour scale's ramp, low to high (8-bit sRGB): viridis at t = 0, ¼, ½, ¾, 1.
STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], np.float64)


def pairs_for(channels: int) -> List[str]:
    """The pair labels for a volume of ``channels`` channels (the path tracer renders colour only)."""
    return list(PAIRS) if channels == 4 else ["closed form vs marcher"]


def half_aspect(layout: str, aspect: float) -> float:
    """The aspect (width/height) each of the two frames is rendered at on a canvas of ``aspect``:
    half of it side by side, all of it for the difference."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout: expected one of {list(LAYOUTS)}, got {layout!r}")
    return float(aspect) / 2.0 if layout == "side by side" else float(aspect)


def _image(image: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8:
        raise ValueError(f"{what}: expected an (H, W, 3) uint8 image, got {a.dtype} {a.shape}")
    return a


def difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """D = |A − B| of two ``(H, W, 3)`` uint8 frames of one size, per channel, as float32 8-bit levels."""
    a, b = _image(a, "frame A"), _image(b, "frame B")
    if a.shape != b.shape:
        raise ValueError(f"frames A and B: expected one size, got {a.shape[1]}×{a.shape[0]} and "
                         f"{b.shape[1]}×{b.shape[0]}")
    return np.abs(a.astype(np.float32) - b.astype(np.float32))


@dataclass(frozen=True)
class ColourScale:
    """The ramp of :data:`STOPS` over [``lo``, ``hi``] (8-bit levels of the magnitude d)."""

    lo: float
    hi: float

    @classmethod
    def of(cls, magnitude: np.ndarray) -> "ColourScale":
        """The scale over the range of ``magnitude``: [min d, max d]."""
        m = np.asarray(magnitude)
        return cls(float(m.min()), float(m.max()))

    def apply(self, magnitude: np.ndarray) -> np.ndarray:
        """``(H, W)`` magnitudes → ``(H, W, 3)`` uint8 colours (module docstring)."""
        m = np.asarray(magnitude, np.float64)
        t = np.zeros_like(m) if self.hi <= self.lo else np.clip((m - self.lo) / (self.hi - self.lo), 0.0, 1.0)
        x = t * (len(STOPS) - 1)
        i = np.minimum(x.astype(np.int64), len(STOPS) - 2)
        f = (x - i)[..., None]
        rgb = STOPS[i] * (1.0 - f) + STOPS[i + 1] * f
        return (rgb + 0.5).astype(np.uint8)

    def line(self) -> str:
        """The page's words for the scale: its range in numbers."""
        return (f"|A − B| colour scale: {self.lo:g} (dark) … {self.hi:g} (bright), max over RGB, in 8-bit sRGB "
                f"levels")


def colour_bar(width: int = 256, height: int = 12) -> np.ndarray:
    """The ramp itself, low (left) to high (right), as a ``(height, width, 3)`` uint8 bar."""
    row = ColourScale(0.0, 1.0).apply(np.linspace(0.0, 1.0, int(width)))
    return np.repeat(row[None], int(height), axis=0)


def side_by_side(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A | divider | B: two ``(H, W, 3)`` uint8 frames of one height joined along the width, a
    :data:`GAP`-pixel column of grey :data:`GAP_GREY` between them (each half's pixels as they are)."""
    a, b = _image(a, "frame A"), _image(b, "frame B")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"frames A and B: expected one height, got {a.shape[0]} and {b.shape[0]}")
    gap = np.full((a.shape[0], GAP, 3), GAP_GREY, np.uint8)
    return np.concatenate([a, gap, b], axis=1)


def beside_aspect(aspect: float, least: float) -> float:
    """The aspect (width/height) a frame is rendered at with the square input beside it on a canvas
    of ``aspect``: a − 1 (the input takes a square of the frame's height), at least ``least`` (the
    renderers' narrowest; on a canvas narrower than 1 + ``least`` the two are stretched over it)."""
    if not (math.isfinite(aspect) and aspect > 0):
        raise ValueError(f"aspect: expected a positive number, got {aspect!r}")
    return max(float(least), float(aspect) - 1.0)


def nearest(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """``(h, w, 3)`` uint8 → ``(height, width, 3)`` by the nearest pixel: output row i takes source row
    ⌊(i + ½) h / height⌋ (columns alike)."""
    a = _image(image, "image")
    rows = ((np.arange(int(height)) + 0.5) * a.shape[0] / int(height)).astype(np.int64)
    cols = ((np.arange(int(width)) + 0.5) * a.shape[1] / int(width)).astype(np.int64)
    return a[rows][:, cols]


def input_beside(input_image: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """The input (``(R, R', 3)`` uint8) at the frame's height H | divider | the frame (:func:`side_by_side`):
    the input scaled by :func:`nearest` to H rows and R'·H/R columns (rounded; H × H for a square input)."""
    a, f = _image(input_image, "input"), _image(frame, "frame")
    h = f.shape[0]
    return side_by_side(nearest(a, h, max(1, round(a.shape[1] * h / a.shape[0]))), f)


@dataclass
class Comparison:
    """Two frames compared: the ``image`` drawn (the layout's), the ``difference`` D ``(H, W, 3)``,
    its per-pixel ``magnitude`` d ``(H, W)``, the ``scale`` over d's range, and the ``layout``."""

    image: np.ndarray
    difference: np.ndarray
    magnitude: np.ndarray
    scale: ColourScale
    layout: str

    def line(self) -> str:
        """One line of numbers: the scale's range and d's mean."""
        return f"{self.scale.line()}; mean {float(self.magnitude.mean()):.3g}"


def compare(a: np.ndarray, b: np.ndarray, layout: str) -> Comparison:
    """Frames A and B (one size) in ``layout`` (:data:`LAYOUTS`), with their difference (module docstring)."""
    half_aspect(layout, 1.0)                                   # the layout's check
    d = difference(a, b)
    magnitude = d.max(axis=2)
    scale = ColourScale.of(magnitude)
    image = side_by_side(a, b) if layout == "side by side" else scale.apply(magnitude)
    return Comparison(image, d, magnitude, scale, layout)
