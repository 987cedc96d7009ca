"""The orthographic camera's window: zoom and pan on its image plane, the same for every renderer.

At view ω the orthographic camera has the frame (right, up, ω) of
:func:`~mitsuba_platonic.views.camera_frames`, and pixel (row i, column j) of an R×R image, at the
image coordinates x_j = −1 + (j + ½)·2/R and y_i = 1 − (i + ½)·2/R, sees the world line
p = x_j·right + y_i·up + z·ω: the image spans the cube's cross-section [−1, 1]². A
:class:`Window` of ``zoom`` m and ``centre`` (c_x, c_y) (world units on the camera plane, along
right and up) shows the square of half-width h = 1/m about that centre instead:

    p = (c_x + h x_j) right + (c_y + h y_i) up + z ω  =  x_j (h right) + y_i (h up) + o + z ω,
    o = c_x right + c_y up

so a world point at lateral coordinates (X, Y) = (p·right, p·up) lands at image coordinates
((X − c_x) m, (Y − c_y) m): zoom m magnifies m times about the centre, and moving the centre by
(δ_x, δ_y) moves the picture by −(δ_x, δ_y) m image units, −(δ_x, δ_y) m R/2 pixels (a camera that
pans right sees the volume move left). The depth z still runs through the whole cube [−1, 1].

Each renderer takes the window where its orthographic camera is made:

- the closed form (:mod:`.closed_form`): its camera-space sample positions, p above, so the
  resampling T(ω) reads the volume inside the window;
- the ray marcher (:mod:`.marcher`) and single scattering at the marcher's speed
  (:mod:`.scatter_march`): the per-pair frame (h right, h up, ω) and the origin o, one Dr.Jit array
  read by the same kernels (the window's values are data: a new zoom or pan replays the recorded
  kernel);
- the path tracer (:mod:`.physical`): the orthographic sensor's
  to_world = look_at(o + 2ω → o, up) · scale(h, h, 1) (Mitsuba's orthographic film covers the
  sensor's local [−1, 1]², which the scale widens to [−h, h]²), and its alpha pass, the marcher's.

The full window (m = 1, centre 0) is no window: :func:`window_or_none` turns it into None, and
every renderer then runs the code it ran before windows existed, bit for bit. Windows are for the
orthographic camera only (the lit renderers have no other; a pinhole's window is refused).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

import torch

from ..errors import UserError

__all__ = ["Window", "window_or_none", "check_orthographic"]


def _number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{name}: expected a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Window:
    """The part of the orthographic image plane a render shows (module docstring).

    zoom: the magnification m > 0 (finite): the image shows the square of half-width h = 1/m
        (m = 1: the cube's cross-section [−1, 1]²; m = 2: its central half, twice as large).
    centre: (c_x, c_y), the window's centre on the camera plane in world units along (right, up).

    Raises :class:`~mitsuba_platonic.errors.UserError` (a ``ValueError``) naming the field when
    the zoom is not a finite number > 0 or the centre not two finite numbers.
    """

    zoom: float = 1.0
    centre: Tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if isinstance(self.zoom, bool) or not isinstance(self.zoom, (int, float)) \
                or not math.isfinite(self.zoom) or not self.zoom > 0.0:
            raise UserError(f"zoom: expected a finite magnification > 0, got {self.zoom!r}")
        if not isinstance(self.centre, (tuple, list)) or len(self.centre) != 2:
            raise UserError(f"centre: expected two numbers (c_x, c_y), got {self.centre!r}")
        centre = tuple(_number(f"centre[{k}]", c) for k, c in enumerate(self.centre))
        object.__setattr__(self, "zoom", float(self.zoom))
        object.__setattr__(self, "centre", centre)

    @property
    def half_width(self) -> float:
        """h = 1/m, the window's half-width in world units."""
        return 1.0 / self.zoom

    @property
    def full(self) -> bool:
        """Whether this is the full window [−1, 1]² (m = 1, centre 0): no window at all."""
        return self.zoom == 1.0 and self.centre == (0.0, 0.0)

    def frames(self, right: torch.Tensor, up: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(h right, h up, o = c_x right + c_y up) of camera frames ``(B, 3)`` each (their dtype and
        device; differentiable in the frames): p = x (h right) + y (h up) + o + z ω."""
        h, (cx, cy) = self.half_width, self.centre
        return h * right, h * up, cx * right + cy * up

    def image_point(self, lateral: Tuple[float, float]) -> Tuple[float, float]:
        """Image coordinates ((X − c_x) m, (Y − c_y) m) ∈ [−1, 1]² where the window shows the world
        point of lateral coordinates (X, Y) = (p·right, p·up)."""
        return ((lateral[0] - self.centre[0]) * self.zoom, (lateral[1] - self.centre[1]) * self.zoom)


def window_or_none(window: Optional[Window]) -> Optional[Window]:
    """``window``, or None for no window or the full one (the renderers' unwindowed code); anything
    but a :class:`Window` or None is a ``ValueError``."""
    if window is None:
        return None
    if not isinstance(window, Window):
        raise UserError(f"window: expected a Window or None, got {type(window).__name__}")
    return None if window.full else window


def check_orthographic(window: Optional[Window], lens: Tuple[float, float]) -> None:
    """Refuse a window for a pinhole camera (``lens`` ``(tan(F/2), D)`` with tan(F/2) > 0)."""
    if window is not None and lens[0] != 0.0:
        raise UserError("window: zoom and pan are the orthographic camera's; render the perspective camera "
                        "without a window")
