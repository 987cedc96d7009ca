"""Colour helpers for the shape classes: pick colours in sRGB (perceptual), store linear RGB."""

from __future__ import annotations

import colorsys
from typing import Sequence, Tuple

import numpy as np

from ...images import srgb_to_linear

__all__ = ["hsv", "jitter", "mix"]

RGB = Tuple[float, float, float]


def hsv(h: float, s: float, v: float) -> RGB:
    """Linear RGB of the sRGB colour with hue ``h`` (turns, wraps), saturation ``s`` and value ``v``."""
    rgb = colorsys.hsv_to_rgb(h % 1.0, float(np.clip(s, 0, 1)), float(np.clip(v, 0, 1)))
    return tuple(float(x) for x in srgb_to_linear(rgb))


def jitter(rng: np.random.Generator, h: float, s: float, v: float,
           dh: float = 0.02, ds: float = 0.08, dv: float = 0.08) -> RGB:
    """:func:`hsv` of a colour randomly perturbed by up to ``(dh, ds, dv)``."""
    return hsv(h + rng.uniform(-dh, dh), s + rng.uniform(-ds, ds), v + rng.uniform(-dv, dv))


def mix(a: Sequence[float], b: Sequence[float], t: float) -> RGB:
    """Linear interpolation ``(1 − t) a + t b``."""
    return tuple(float((1 - t) * x + t * y) for x, y in zip(a, b))
