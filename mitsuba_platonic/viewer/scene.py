"""What ``platonic view`` shows, without the web library: the source's volumes, frames, exports.

- :func:`open_source`: SOURCE as a :class:`Scene`: a volume file (``.npz``, ``.vol``), a run folder
  (reconstruction: its held-out inputs, stepped through; generation: latents drawn by seed, or a
  walk between two), or a reconstruction run with ``photo`` (reconstructed, shown beside the view).
  Every problem is a :class:`~mitsuba_platonic.errors.UserError` (one line, exit 2 on the command line).
- :func:`render_frame`: the current volume from a view ω (from the object towards the camera; the
  orthographic camera, docs/conventions.md) through one of the project's renderers at an image
  resolution, as 8-bit sRGB over :data:`BACKGROUND`, with the seconds it took and the settings used.
  An image resolution R = kN above the volume's N: the marcher keeps its k² sub-pixel rays apart;
  the other renderers render the volume resampled trilinearly to R³ (cached). A
  :class:`~mitsuba_platonic.render.window.Window` zooms and pans the orthographic camera, in every
  renderer; :func:`camera_window` makes it from the browser's perspective camera (its distance from
  its look-at point and its field of view give the scale, the look-at point the centre), so that
  the frame moves and scales under the mouse as viser's own camera does.
- :class:`Exports`: the PNG of a frame (the view as drawn, or a still at a chosen size up to
  :data:`MAX_STILL`), a turntable (:func:`turntable_views`: an animated lossless WebP and its
  frames as PNGs) and the volume (``.npz`` + ``.vol``, a ``.ply`` mesh) written into one output
  folder, under names cleaned of path characters and never over an earlier file: nothing the page
  sends can name a file outside that folder.
"""

from __future__ import annotations

import math
import re
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image

from ..errors import UserError
from ..export import extract_mesh, save_ply
from ..files.fileio import atomic_write, confined
from ..files.names import readable_name
from ..files.outputs import output_lock
from ..files.volume_io import save_volume
from ..render import RenderSettings, render_with
from ..render.window import Window, window_or_none
from ..views import camera_frames, to_angles, turntable
from ..volume import CHANNELS
from .live import stamp
from .start import check_source, volume_title

__all__ = ["RENDERERS", "FORMATIONS", "BACKGROUND", "Frame", "Scene", "Exports", "open_source", "render_frame",
           "formations_for", "formations_of", "renderers_for", "resolutions_for", "to_display", "clean_name", "camera_window",
           "zoom_distance", "ZOOM_RANGE", "Window", "PASS_SPP", "Plan", "plan_frame", "path_pass",
           "passes_for", "DEFAULT_RESOLUTION", "ASPECT_RANGE", "default_resolution", "frame_size", "Tile", "tiles",
           "model_of", "prepare_volume", "MAX_STILL", "still_sizes", "checked_still", "TURNTABLE_FRAMES", "MAX_TURNTABLE_FRAMES",
           "FRAME_MS", "checked_frames", "turntable_views"]

#: The renderers the page offers: label → backend (mitsuba_platonic.render.BACKENDS).
RENDERERS: Dict[str, str] = {"closed form": "closed_form", "marcher": "mitsuba",
                             "single scattering": "scatter_march", "path tracer": "physical"}
#: Image formations: label → model.
FORMATIONS: Dict[str, str] = {"VH": "vh", "AO": "ao", "EA": "ea"}
#: The backends that light colour volumes (EA formation only).
_LIT = ("scatter_march", "physical")
#: The grey (linear) the frames are composited over.
BACKGROUND = 0.08
#: Largest image resolution the page offers (the marcher's 512² frame of a 64³ volume: 8×8 rays per voxel).
MAX_RESOLUTION = 512
#: Largest still the page exports (pixels along the frame's shorter side; the marcher's 2048 × 3641
#: frame of a 16:9 canvas: about 3 s on 2 cores). Only the marcher renders past :data:`MAX_RESAMPLED`.
MAX_STILL = 2048
#: A turntable's frames: the page's first choice, and the most it exports.
TURNTABLE_FRAMES, MAX_TURNTABLE_FRAMES = 48, 360
#: How long each frame of a turntable's animation is shown (milliseconds: 48 frames turn once in 3.84 s).
FRAME_MS = 80
#: The resolution a page opens with (the choice of :func:`resolutions_for` nearest to it): the
#: frame's shorter side in pixels.
DEFAULT_RESOLUTION = 128
#: The canvas aspects (width/height) frames are rendered at: a canvas past them gets the nearest one
#: (and its frame is stretched over it).
ASPECT_RANGE = (0.25, 4.0)
#: Largest image the renderers other than the marcher render (they render the volume resampled to
#: R³: the closed form takes about 13 s for 256² on 2 cores); a larger choice renders at this one.
MAX_RESAMPLED = 128
#: The zoom m the camera's distance can reach: from a quarter (the cube a quarter of the frame wide)
#: to 8× (an 8N² frame then shows about one voxel per pixel).
ZOOM_RANGE = (0.25, 8.0)
#: A camera this close to the initial one (|m − 1|, |c_x|, |c_y| at most this) has the full window:
#: the browser echoes positions in float32, and the unmoved camera's frames stay the renderers'
#: own, bit for bit (1e-5 world units: 0.02 pixel of a 512² frame at 8×).
WINDOW_SNAP = 1e-5

PathLike = Union[str, Path]


def formations_for(channels: int) -> List[str]:
    """The formation labels a volume of ``channels`` channels can be rendered with (EA needs colour)."""
    return ["VH", "AO", "EA"] if channels == 4 else ["VH", "AO"]


def formations_of(renderer: str, channels: int) -> List[str]:
    """The formation labels ``renderer`` renders a volume of ``channels`` channels with: the lit
    renderers (single scattering, the path tracer) form EA only; the others :func:`formations_for`."""
    if renderer not in RENDERERS:
        raise UserError(f"renderer: expected one of {list(RENDERERS)}, got {renderer!r}")
    return ["EA"] if RENDERERS[renderer] in _LIT else formations_for(channels)


def renderers_for(channels: int) -> List[str]:
    """The renderer labels for a volume of ``channels`` channels (the lit ones render colour only)."""
    return list(RENDERERS) if channels == 4 else ["closed form", "marcher"]


def to_display(image: torch.Tensor) -> np.ndarray:
    """A render ``(C, H, W)`` (premultiplied linear RGBA, or an opacity: a white object) → ``(H, W, 3)``
    uint8 sRGB over :data:`BACKGROUND` (the sRGB curve of :func:`~mitsuba_platonic.images.linear_to_srgb`,
    written out here in torch: colour-science costs a second to import and milliseconds a frame)."""
    x = image.detach().float().cpu()
    if x.shape[0] == 1:
        rgb, alpha = x.expand(3, -1, -1), x
    else:
        rgb, alpha = x[:3], x[3:4]
    lin = (rgb + (1.0 - alpha) * BACKGROUND).clamp(0.0, 1.0)
    srgb = torch.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin.clamp_min(1e-12) ** (1 / 2.4) - 0.055)
    return (srgb.clamp(0.0, 1.0) * 255.0 + 0.5).to(torch.uint8).permute(1, 2, 0).contiguous().numpy()


@dataclass
class Frame:
    """One rendered view: ``image`` ``(H, W, 3)`` uint8 sRGB (R×R on a square canvas; R the ``resolution``), ``seconds`` of rendering (from the call to
    the displayable image), ``settings`` (what the renderer was told, one line) and the ``view``."""

    image: np.ndarray
    seconds: float
    settings: str
    view: Tuple[float, float, float]
    renderer: str
    formation: str
    resolution: int
    window: Optional[Window] = None


#: The last resampled volume: (the source tensor itself, (R, whether VH's), the resampled one). The source is kept and
#: compared by identity, not by ``id()``, which a new volume may reuse once the old one is freed.
_resampled: List[Tuple[torch.Tensor, Tuple[int, bool], torch.Tensor]] = []


def _at_resolution(volume: torch.Tensor, r: int, model: str) -> torch.Tensor:
    """``(C, N, N, N)`` → ``(1, C, R, R, R)``: itself for R = N, else resampled trilinearly (cell-centred,
    the renderers' ``align_corners=False`` convention), clamped to [0, 1], its density made per fine
    voxel; the last one is cached.

    Every renderer reads a voxel's density as what one voxel step of the volume holds: the opacity
    a of a step (AO, EA; the lit renderers' σ = −ln(1 − a) / Δ with Δ the grid's voxel size) or its
    optical depth v (VH, 1 − exp(−Σ v)). A grid k = R / N times finer has k steps where the volume
    had one, so the resampled density ā is made that of one fine step:

        a′ = 1 − (1 − ā)^(1/k)  (AO, EA, lit; exact at ā = 0 and 1),    v′ = v̄ / k  (VH)

    so that k fine steps of a constant run hold what its one voxel did, (1 − a′)^k = 1 − ā, and σ,
    per unit length, is the volume's own. Without it a 16³ volume's closed form at 128² was as
    opaque as eight voxels per voxel (12 levels brighter on average than its 16² frame, up to 93
    from the marcher's at one camera), while the marcher's sub-pixel rays keep the volume's steps."""
    n = volume.shape[-1]
    if r == n:
        return volume[None]
    key = (r, model == "vh")
    if not (_resampled and _resampled[0][0] is volume and _resampled[0][1] == key):
        _resampled.clear()                                   # one resampled volume at a time (memory)
        fine = F.interpolate(volume[None], size=(r, r, r), mode="trilinear", align_corners=False).clamp_(0.0, 1.0)
        k, d = r / n, fine[:, -1]                            # the density: the last channel (C = 1 or 4)
        if model == "vh":
            d.div_(k)                                        # v′ = v̄ / k
        else:
            d.copy_(-torch.expm1(torch.log1p(-d) / k))       # a′ = 1 − exp(ln(1 − ā) / k): 1 at ā = 1
        _resampled.append((volume, key, fine))
    return _resampled[0][2]


def resolutions_for(n: int) -> List[int]:
    """The image resolutions offered for an N³ volume: kN for k = 1, 2, 4, 8 up to :data:`MAX_RESOLUTION`."""
    return [k * n for k in (1, 2, 4, 8) if k * n <= MAX_RESOLUTION] or [n]


def still_sizes(n: int) -> List[int]:
    """The still sizes offered for an N³ volume (pixels along the shorter side): kN for k = 1, 2, 4, …
    up to :data:`MAX_STILL` (a multiple of N: the marcher's k × k rays per voxel-sized pixel)."""
    return [n << j for j in range(32) if n << j <= MAX_STILL] or [n]


def checked_still(size: object, n: int) -> int:
    """A still's ``size`` for an N³ volume as an int kN (k ≥ 1) up to :data:`MAX_STILL`, else a
    :class:`UserError` saying what is expected."""
    try:
        number = float(size)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(size, bool) or not number.is_integer() or number % n or not n <= number <= max(n, MAX_STILL):
        raise UserError(f"still size: expected a multiple of the volume's {n} from {n} to {max(n, MAX_STILL)} "
                        f"pixels (the frame's shorter side), got {size!r}")
    return int(number)


def checked_frames(frames: object) -> int:
    """A turntable's frame count as an int from 2 to :data:`MAX_TURNTABLE_FRAMES`, else a :class:`UserError`."""
    try:
        number = float(frames)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(frames, bool) or not number.is_integer() or not 2 <= number <= MAX_TURNTABLE_FRAMES:
        raise UserError(f"turntable frames: expected a whole number from 2 to {MAX_TURNTABLE_FRAMES}, got {frames!r}")
    return int(number)


def turntable_views(view: Tuple[float, float, float], frames: int) -> List[Tuple[float, float, float]]:
    """The views of a turntable of ``frames`` frames from ``view`` ω (azimuth φ₀, elevation θ,
    :func:`~mitsuba_platonic.views.to_angles`) around the vertical (+y):

        ω_k = ω(φ₀ + k · 360°/F, θ),   k = 0 … F − 1      (:func:`~mitsuba_platonic.views.turntable`)

    the first the view itself (to float32). A frame's window (zoom m, centre (c_x, c_y) on the camera
    plane) is kept: the camera and its look-at point turn together about the cube's vertical axis."""
    frames = checked_frames(frames)
    phi, theta = (float(a) for a in to_angles(torch.tensor(view, dtype=torch.float64)))
    return [tuple(float(x) for x in w) for w in turntable(frames, elevation=theta, start=phi)]


def default_resolution(n: int) -> int:
    """The resolution an N³ volume's page opens with: the choice nearest :data:`DEFAULT_RESOLUTION`."""
    return min(resolutions_for(n), key=lambda r: (abs(r - DEFAULT_RESOLUTION), r))


def _checked_aspect(aspect: float) -> float:
    if isinstance(aspect, bool) or not isinstance(aspect, (int, float)) or not 0.0 < aspect < math.inf:
        raise UserError(f"aspect: expected a finite width/height > 0, got {aspect!r}")
    return min(max(float(aspect), ASPECT_RANGE[0]), ASPECT_RANGE[1])


def frame_size(resolution: int, aspect: float = 1.0) -> Tuple[int, int]:
    """(width, height) in pixels of the frame of ``resolution`` R on a canvas of width/height
    ``aspect`` (held to :data:`ASPECT_RANGE`): R along the shorter side, the longer one
    R + 2 round((R·a′ − R)/2), a′ = max(a, 1/a), the nearest size to the aspect with the same parity
    as R, so that the frame's central R×R square lies on whole pixels (it is the square frame)."""
    a = _checked_aspect(aspect)
    r = int(resolution)
    longer = r + 2 * int(round((r * max(a, 1.0 / a) - r) / 2.0))
    return (longer, r) if a >= 1.0 else (r, longer)


@dataclass(frozen=True)
class Tile:
    """One square R×R render of a frame: its ``window`` (None: the full one) and where its pixels go
    in the frame (``row``, ``column`` of its top-left pixel)."""

    window: Optional[Window]
    row: int
    column: int


def tiles(resolution: int, aspect: float = 1.0, window: Optional[Window] = None) -> List[Tile]:
    """The square renders that make the frame of ``resolution`` R on a canvas of ``aspect``
    (:func:`frame_size` W×H): the orthographic window widened along the longer side, as ⌈W/R⌉ (or
    ⌈H/R⌉) R×R renders side by side, overlapping where they must, each through ``window`` (zoom m,
    centre c) moved by whole pixels along the longer side. Pixel j of the frame's row sees
    x = c_x + p (j + ½ − W/2), p = 2/(m R) (the square frame's pitch), so the frame's central R×R
    square is the square frame and nothing is stretched; a square canvas has the one tile
    ``window`` itself."""
    w, h = frame_size(resolution, aspect)
    r = int(resolution)
    base = window_or_none(window) or Window()
    pitch = 2.0 * base.half_width / r
    longer = max(w, h)
    count = -(-longer // r)
    starts = [0] if count == 1 else [int(round(t * (longer - r) / (count - 1))) for t in range(count)]
    out = []
    for s in starts:
        shift = pitch * (s + r / 2.0 - longer / 2.0)             # the tile's centre from the frame's, world units
        cx, cy = base.centre
        if w >= h:
            centre, row, column = (cx + shift, cy), 0, s
        else:
            centre, row, column = (cx, cy - shift), s, 0          # rows run down, up runs up
        out.append(Tile(window_or_none(Window(base.zoom, centre)), row, column))
    return out


def _lens_scale(fov: float, aspect: float) -> float:
    """tan(fov/2)·min(1, aspect): the frame's half-width per unit of distance (:func:`camera_window`);
    ``fov`` the vertical field of view in radians, ``aspect`` the canvas' width/height."""
    if isinstance(fov, bool) or not isinstance(fov, (int, float)) or not 0.0 < fov < math.pi:
        raise UserError(f"fov: expected a vertical field of view in (0, π) radians, got {fov!r}")
    if isinstance(aspect, bool) or not isinstance(aspect, (int, float)) or not 0.0 < aspect < math.inf:
        raise UserError(f"aspect: expected a finite width/height > 0, got {aspect!r}")
    return math.tan(fov / 2.0) * min(1.0, float(aspect))


def camera_window(position: Sequence[float], look_at: Sequence[float], fov: float,
                  aspect: float = 1.0) -> Optional[Window]:
    """The orthographic window of the browser's perspective camera at ``position`` looking at
    ``look_at`` (world units), vertical field of view ``fov`` (radians) on a canvas of width/height
    ``aspect``, or None for the full one (:mod:`mitsuba_platonic.render.window`).

    The perspective camera shows the plane through its look-at point, at distance d, 2 d tan(fov/2)
    world units over the canvas' height; the page draws the frame as a square the canvas' shorter
    side wide (padded to the canvas' aspect). The window gives the frame that scale, so a point of
    that plane sits where the browser's camera projects it, and stays under the mouse while viser
    pans (it moves the camera and look_at by the world length the mouse travelled at that scale)
    or zooms.
    With ω = (position − look_at)/d and (right, up) ω's camera frame:

        half-width h = d tan(fov/2) min(1, aspect)              (zoom m = 1/h, clamped to :data:`ZOOM_RANGE`)
        centre (c_x, c_y) = (look_at · right, look_at · up)     (look_at's offset on the camera plane)

    so a camera that pans sees the volume move the other way, and one that orbits about a look-at
    point keeps that point at the frame's centre. Values within :data:`WINDOW_SNAP` of the full
    window's (m = 1, centre 0) are taken as them. Raises ``ValueError`` for non-finite coordinates,
    a camera at its look-at point, a ``fov`` outside (0, π) or an ``aspect`` that is not finite > 0.
    """
    p, a = np.asarray(position, np.float64).reshape(-1), np.asarray(look_at, np.float64).reshape(-1)
    if p.shape != (3,) or a.shape != (3,) or not (np.isfinite(p).all() and np.isfinite(a).all()):
        raise UserError(f"camera: expected finite 3-vectors, got position {tuple(p)} and look_at {tuple(a)}")
    scale = _lens_scale(fov, aspect)
    d = float(np.linalg.norm(p - a))
    if not d > 1e-9:
        raise UserError("camera: its position is its look-at point (no view direction)")
    right, up, _ = camera_frames(torch.from_numpy((p - a) / d)[None])
    zoom = min(max(1.0 / (d * scale), ZOOM_RANGE[0]), ZOOM_RANGE[1])
    centre = [float(torch.from_numpy(a) @ right[0]), float(torch.from_numpy(a) @ up[0])]
    if abs(zoom - 1.0) <= WINDOW_SNAP:
        zoom = 1.0
    centre = tuple(0.0 if abs(c) <= WINDOW_SNAP else c for c in centre)
    return window_or_none(Window(zoom, centre))


def zoom_distance(zoom: float, fov: float, aspect: float = 1.0) -> float:
    """The distance from the look-at point at which the camera of ``fov`` and ``aspect`` has the
    zoom ``zoom`` (:func:`camera_window`): d = 1 / (m tan(fov/2) min(1, aspect))."""
    return 1.0 / (float(zoom) * _lens_scale(fov, aspect))


#: The path tracer's samples per pixel in one pass: its frames are the average of passes of this many
#: spp under one sky (:func:`path_pass`), each shown as it arrives (the viewer's progressive frames).
PASS_SPP = 1


@dataclass(frozen=True)
class Plan:
    """What :func:`render_frame` renders: the ``backend`` and ``model``, the image's ``resolution``
    R and its ``k`` = R/N, the renderer's :class:`RenderSettings` and the settings line."""

    backend: str
    model: str
    resolution: int
    k: int
    settings: RenderSettings
    line: str
    width: int = 0
    height: int = 0
    tiles: Tuple[Tile, ...] = ()


def plan_frame(volume: torch.Tensor, renderer: str, formation: str, resolution: Optional[int], spp: int,
               window: Optional[Window], aspect: float = 1.0, most: int = MAX_RESOLUTION) -> Plan:
    """Check a frame's request (:func:`render_frame`'s arguments; ``most``: the largest resolution
    taken, :data:`MAX_RESOLUTION` for the page's frames, :data:`MAX_STILL` for a still) and say how
    it is rendered: the square renders (:func:`tiles`) of the frame's W×H pixels (:func:`frame_size`
    of the resolution rendered, R×R on a square canvas)."""
    aspect = _checked_aspect(aspect)
    if renderer not in RENDERERS:
        raise UserError(f"renderer: expected one of {list(RENDERERS)}, got {renderer!r}")
    if formation not in FORMATIONS:
        raise UserError(f"formation: expected one of {list(FORMATIONS)}, got {formation!r}")
    backend = RENDERERS[renderer]
    c, n = volume.shape[0], volume.shape[-1]
    model = "ea" if backend in _LIT else FORMATIONS[formation]
    if CHANNELS[model] == 4 and c != 4:
        raise UserError(f"{renderer} {model.upper()}: the volume has no colour (C = {c}); use VH or AO")
    r = n if resolution is None else int(resolution)
    if r % n or not n <= r <= max(n, most):
        raise UserError(f"resolution: expected a multiple of the volume's {n} up to {most} pixels, got {r}")
    k = r // n
    capped = ""
    if backend != "mitsuba" and r > max(n, MAX_RESAMPLED):
        k = max(1, MAX_RESAMPLED // n)
        capped, r = f" (asked {r}², the {renderer} renders at most {max(n, k * n)}² here)", k * n
    options: Dict[str, object] = {}
    width, height = frame_size(r, aspect)
    shown = [f"{renderer} ({backend})", model.upper(), f"{width}×{height} px{capped}"]
    if backend == "mitsuba":
        shown.append(f"volume {n}³, step 1 voxel" + (f", {k}×{k} rays per voxel-sized pixel" if k > 1 else ""))
    else:
        shown.append(f"volume {n}³" + ("" if k == 1 else f" resampled to {r}³"))
    if backend == "physical":
        if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
            raise UserError(f"spp: expected a positive int, got {spp!r}")
        options["physical_spp"] = PASS_SPP
        shown.append(f"spp {spp} in passes of {PASS_SPP}, max depth {RenderSettings().max_depth}, "
                     f"sun and sky of seed 0")
    elif backend == "scatter_march":
        shown.append(f"{RenderSettings().steps_per_voxel} samples per voxel, sun and sky of seed 0")
    window = window_or_none(window)
    if window is not None:
        shown.append(f"zoom {window.zoom:.3g}×, centre ({window.centre[0]:+.3f}, {window.centre[1]:+.3f})")
    if width != height:
        shown.append(f"{len(tiles(r, aspect, window))} renders of {r}×{r} side by side")
    return Plan(backend, model, r, k, RenderSettings.for_call(backend, model, **options), ", ".join(shown),
                width, height, tuple(tiles(r, aspect, window)))


def _unit(view: Tuple[float, float, float]) -> torch.Tensor:
    w = torch.tensor([view], dtype=torch.float64)
    return (w / w.norm()).to(torch.float32)


def prepare_volume(volume: torch.Tensor, plan: Plan) -> torch.Tensor:
    """The volume as the plan's renderer takes it: ``(1, C', R', R', R')`` (a resampled one cached:
    the viewer's warm-up calls it for the first full frame's plan)."""
    v = volume[None] if plan.backend == "mitsuba" else _at_resolution(volume, plan.resolution, plan.model)
    if CHANNELS[plan.model] == 1 and volume.shape[0] == 4:
        v = v[:, 3:]
    return v.contiguous()


def _assemble(plan: Plan, render) -> torch.Tensor:
    """The frame ``(C, H, W)`` of ``plan`` from ``render(window)`` → ``(C, R, R)``, one call per tile."""
    out = None
    r = plan.resolution
    for tile in plan.tiles:
        image = render(tile.window)
        if len(plan.tiles) == 1:
            return image
        if out is None:
            out = image.new_zeros((image.shape[0], plan.height, plan.width))
        out[:, tile.row:tile.row + r, tile.column:tile.column + r] = image
    return out


def path_pass(volume: torch.Tensor, view: Tuple[float, float, float], resolution: Optional[int] = None,
              index: int = 0, window: Optional[Window] = None, aspect: float = 1.0) -> torch.Tensor:
    """Pass ``index`` of the path tracer's frame: :data:`PASS_SPP` spp under the sky of seed 0, the
    samples of seed ``index`` (:func:`~mitsuba_platonic.render.mitsuba.physical.render_physical_ad`'s
    ``sample_seed``), as the linear premultiplied RGBA ``(4, H, W)`` (:func:`frame_size` on a canvas
    of ``aspect``). The frame of S spp is the mean of passes 0 … S/PASS_SPP − 1, summed in that
    order (:func:`render_frame`)."""
    from ..render.mitsuba.physical import render_physical_ad           # lazy: Mitsuba, on the path tracer's first pass

    plan = plan_frame(volume, "path tracer", "EA", resolution, PASS_SPP, window, aspect)
    s = plan.settings
    prepared = prepare_volume(volume, plan)
    with torch.no_grad():
        return _assemble(plan, lambda tile: render_physical_ad(
            prepared, _unit(view), lighting=s.lighting, spp=PASS_SPP, max_depth=s.max_depth, seed=0,
            filter=s.filter, window=tile, sample_seed=int(index))[0])


def passes_for(spp: int) -> int:
    """How many passes the path tracer's frame of ``spp`` samples per pixel takes."""
    return max(1, -(-int(spp) // PASS_SPP))


def render_frame(volume: torch.Tensor, view: Tuple[float, float, float], renderer: str = "closed form",
                 formation: str = "EA", resolution: Optional[int] = None, spp: int = 4,
                 window: Optional[Window] = None, aspect: float = 1.0, most: int = MAX_RESOLUTION) -> Frame:
    """Render the ``(C, N, N, N)`` ``volume`` (checked when it was opened) from the unit ``view`` ω.

    ``renderer``: a label of :data:`RENDERERS`; ``formation``: one of :data:`FORMATIONS` (a lit
    renderer always forms EA); ``resolution``: the image's R = kN, k a positive int (default N);
    ``spp``: the path tracer's samples per pixel; ``window``: the orthographic camera's zoom and pan
    (:class:`~mitsuba_platonic.render.window.Window`, every renderer; None: the whole cube's
    cross-section, the frame as without a window, bit for bit); ``aspect``: the canvas' width/height,
    the frame W×H of :func:`frame_size` (R along the shorter side) made of the square renders of
    :func:`tiles` (1: the one square frame); ``most``: the largest resolution taken (:func:`plan_frame`:
    a still's is :data:`MAX_STILL`). The random sky of the lit renderers is the one of seed 0
    (the same in every frame).

    At k > 1 the marcher keeps its k² regular sub-pixel rays per pixel apart
    (:func:`~mitsuba_platonic.render.drjit.marcher.march_pixels`: the same kernel, k² times the rays); the
    other renderers render the volume resampled trilinearly to (kN)³ (their images are the volume's
    resolution), which costs them about k³ times the work. The path tracer's frame is the mean of
    its passes (:func:`path_pass`): P passes of :data:`PASS_SPP` spp, P = ⌈spp / PASS_SPP⌉,

        image = (pass₀ + pass₁ + … + pass_{P−1}) / P      (summed in that order, float32)

    what the page shows once its last pass has arrived.
    """
    plan = plan_frame(volume, renderer, formation, resolution, spp, window, aspect, most)
    window = window_or_none(window)
    w = _unit(view)
    start = time.perf_counter()
    with torch.no_grad():
        if plan.backend == "physical":
            total = None
            for i in range(passes_for(spp)):
                image = path_pass(volume, view, plan.resolution, i, window, aspect)
                total = image if total is None else total + image
            image = total / passes_for(spp)
        elif plan.backend == "mitsuba" and plan.k > 1:
            from ..render.drjit.marcher import march_pixels          # lazy: imports Dr.Jit, on the marcher's first frame
            prepared = prepare_volume(volume, plan)
            image = _assemble(plan, lambda tile: march_pixels(prepared, w, plan.settings, plan.k, tile)[0])
        else:
            prepared = prepare_volume(volume, plan)
            image = _assemble(plan, lambda tile: render_with(prepared, w, plan.settings, 0, tile)[0])
        image = to_display(image)
    seconds = time.perf_counter() - start
    return Frame(image, seconds, plan.line, tuple(float(x) for x in w[0]), renderer, formation, plan.resolution,
                 window)


# --------------------------------------------------------------------------- sources


@dataclass
class Scene:
    """What the viewer shows: ``volume`` ``(C, N, N, N)`` (the current one), ``kind`` ('volume',
    'reconstruction', 'generation'), ``title``, and for a run its ``model``, held-out ``inputs``
    ``(M, C, R, R)`` with their ``input_names`` (reconstruction), the displayed ``input`` image
    (an input or the photo, ``(R, R, 3)`` uint8), the elevation θ̂ in degrees at which that input's
    camera sees the volume shown (``input_elevation``: the volume is G's upright one,
    :meth:`~mitsuba_platonic.model.Model.reconstruct_upright`, so the input camera is ω(0°, θ̂), θ̂
    what the pose head P reads from the input for ``train.pose: elevation``, 0 for ``train.pose:
    input``) and a note on what was found (``notes``)."""

    volume: torch.Tensor
    kind: str
    title: str
    model: Optional[object] = None
    inputs: Optional[torch.Tensor] = None
    input_names: List[str] = field(default_factory=list)
    input: Optional[np.ndarray] = None
    input_index: int = 0
    input_elevation: float = 0.0
    seeds: Tuple[int, int] = (0, 1)
    walk: float = 0.0
    notes: List[str] = field(default_factory=list)
    folder: Optional[Path] = None
    stamp: Optional[Tuple[int, int]] = None

    # -- a run: a newer checkpoint ------------------------------------------------------------

    def use_model(self, model) -> None:
        """Show ``model`` (a newer checkpoint of the run) in place of the current one: the same input,
        photo or latent (seeds and walk) through it, and its step in the title."""
        old = self.model
        if old is None:
            raise UserError("this source is a volume file; it has no model to replace")
        shape = lambda m: (m.task, m.resolution, m.channels)  # noqa: E731
        if shape(model) != shape(old):
            raise UserError(f"the new checkpoint is of another kind of run (task, resolution, channels "
                            f"{shape(model)}, shown {shape(old)}); restart platonic view to show it")
        self.model = model
        try:
            if self.inputs is not None and len(self.inputs) > 0:
                self.show_input(self.input_index)
            else:
                self.show_latent(self.seeds[0], self.seeds[1] if self.walk > 0 else None, self.walk)
        except BaseException:
            self.model = old
            raise
        self.title = re.sub(r"\(step \d+\)$", f"(step {model.step})", self.title)

    # -- reconstruction: held-out inputs ------------------------------------------------------

    def show_input(self, index: int) -> None:
        """Reconstruct held-out input ``index`` (modulo their count) and make it the current volume."""
        if self.inputs is None or len(self.inputs) == 0:
            raise UserError("this source has no held-out inputs to step through")
        self.input_index = index % len(self.inputs)
        image = self.inputs[self.input_index:self.input_index + 1]
        self.volume, self.input_elevation = _reconstruct(self.model, image)
        self.input = to_display(image[0])

    def input_camera(self) -> Optional[Tuple[float, float]]:
        """The input's own camera as (azimuth, elevation) in degrees, (0, θ̂) (the class docstring),
        or None where no input is shown (a volume file, a generation run, G(z) in place of inputs)."""
        return None if self.input is None else (0.0, self.input_elevation)

    # -- generation: latents ------------------------------------------------------------------

    def show_latent(self, seed_a: int, seed_b: Optional[int] = None, t: float = 0.0) -> None:
        """G of the latent drawn with ``seed_a`` (as ``generate(1, seed)`` draws it), or, with ``seed_b``,
        of the spherical interpolation at ``t`` ∈ [0, 1] between the two (a walk between two latents)."""
        za = _latent(self.model, seed_a)
        z = za if seed_b is None else _slerp(za, _latent(self.model, seed_b), float(t))
        self.seeds, self.walk = (seed_a, seed_a if seed_b is None else seed_b), float(t)
        self.volume = _decode(self.model, z)


def _reconstruct(model, image: torch.Tensor) -> Tuple[torch.Tensor, float]:
    """G(E(x)) of one image ``(1, C, R, R)`` upright ``(C, R, R, R)``, and the elevation θ̂ (degrees)
    of its camera there (0 without a pose head)."""
    volumes, elevations = model.reconstruct_upright(image.to(model.device))
    return volumes[0].detach().float().cpu().clamp(0.0, 1.0), float(elevations[0])


def _latent(model, seed: int) -> torch.Tensor:
    return torch.randn(1, model.latent, generator=torch.Generator().manual_seed(int(seed)))


def _slerp(a: torch.Tensor, b: torch.Tensor, t: float) -> torch.Tensor:
    """Spherical interpolation of two Gaussian latents (keeps their norm typical, unlike a straight line)."""
    cos = float((a * b).sum() / (a.norm() * b.norm()))
    omega = math.acos(max(-1.0, min(1.0, cos)))
    if omega < 1e-6:
        return (1 - t) * a + t * b
    return (math.sin((1 - t) * omega) * a + math.sin(t * omega) * b) / math.sin(omega)


def _decode(model, z: torch.Tensor) -> torch.Tensor:
    return model.decode(z.to(model.device))[0].detach().float().cpu().clamp(0.0, 1.0)


def _held_out(cfg) -> Tuple[Optional[torch.Tensor], List[str], Optional[str]]:
    """A run's held-out inputs and their names, or (None, [], why none) when they are not here."""
    from ..evaluate.photos import photo_splits                          # lazy: a second to import; runs only
    from ..train.data import collection_folder, load_training_data     # lazy: runs only

    if cfg.data.source == "folder":
        try:
            _, held, files = photo_splits(cfg)
        except UserError as e:
            return None, [], str(e)
        return held, [Path(f).name for f in files], None
    folder = collection_folder(cfg)
    if not folder.is_dir():
        return None, [], (f"the run's collection {str(folder)!r} is not here (data.cache is relative to where "
                          f"training ran); no held-out inputs")
    data = load_training_data(cfg, progress=False)
    if len(data.held_out) == 0:
        return None, [], "the run holds out no input"
    names = [f"held-out {i}" + (f" (shape {r.get('shape')})" if isinstance(r, dict) and "shape" in r else "")
             for i, r in enumerate(data.held_out_records or [{}] * len(data.held_out))]
    return data.held_out, names, None


def open_source(source: PathLike, photo: Optional[PathLike] = None, array: Optional[np.ndarray] = None,
                background: Optional[str] = None) -> Scene:
    """SOURCE → :class:`Scene` (module docstring); :class:`UserError` naming what is wrong.

    ``background``: how ``photo`` is masked where it has no alpha channel (the photo loader's,
    :meth:`~mitsuba_platonic.model.Model.load_image`: None, or ``white``).

    ``array``: what :func:`~.start.check_source` returned for this SOURCE, a volume file's checked
    array (not read again); None: SOURCE is checked and read here."""
    path = Path(source)
    if array is None:
        array = check_source(path, photo)
    if array is not None:
        volume = torch.from_numpy(array)
        return Scene(volume=volume, kind="volume", title=volume_title(path, volume.shape))
    seen = stamp(path / "checkpoints" / "last.pt")           # before reading it: a newer one is followed
    model, cfg = model_of(path)
    scene = _run_scene(path, photo, model, cfg, background)
    scene.folder, scene.stamp = path, seen
    return scene


def model_of(source: PathLike):
    """A run folder (its newest loadable checkpoint) or one checkpoint file → (model, its config);
    the checkpoint's own one-line errors (:class:`~mitsuba_platonic.files.checkpoint.RunError`)."""
    # lazy, the three: checkpoints, configs and networks are for run folders only (a volume file's
    # first frame waits for none of them)
    from ..files.checkpoint import read_checkpoint                  # lazy: runs only
    from ..config.loading import checkpoint_config, model_from_checkpoint   # lazy: runs only
    from ..model import Model                                 # lazy: runs only

    ckpt = read_checkpoint(source)
    cfg = checkpoint_config(ckpt)
    return model_from_checkpoint(Model, ckpt, cfg), cfg


def _run_scene(path: Path, photo: Optional[PathLike], model, cfg, background: Optional[str] = None) -> Scene:
    """The scene of a run's ``model`` (module docstring): its held-out inputs, ``photo``, or latents."""
    step = f"step {model.step}"
    if model.task != "reconstruction":
        if photo is not None:
            raise UserError(f"--photo: {str(path)!r} is a generation run (train.task: {model.task}); it has no "
                            f"encoder to reconstruct a photo; use a reconstruction run, or leave --photo out")
        scene = Scene(volume=torch.zeros(0), kind="generation", title=f"{path.name}: generation ({step})", model=model)
        scene.show_latent(0)
        return scene
    if photo is not None:
        image = model.load_image(photo, background)          # the loader's one-line errors (missing, damaged)
        scene = Scene(volume=torch.zeros(0), kind="reconstruction",
                      title=f"{path.name}: reconstruction of {Path(photo).name} ({step})", model=model,
                      inputs=image, input_names=[Path(photo).name])
        scene.show_input(0)
        return scene
    inputs, names, why = _held_out(cfg)
    scene = Scene(volume=torch.zeros(0), kind="reconstruction", title=f"{path.name}: reconstruction ({step})",
                  model=model, inputs=inputs, input_names=names)
    if inputs is None:
        scene.notes.append(why or "no held-out inputs")
        scene.show_latent(0)                                 # G alone: something to look at
        scene.notes.append("showing G(z) of seed 0 instead")
    else:
        scene.show_input(0)
    return scene


# --------------------------------------------------------------------------- exports

def clean_name(text: str, default: str = "view") -> str:
    """A page's name for an export → a plain file stem: letters and digits of any script and ``_ + -``
    only (:func:`~mitsuba_platonic.files.names.readable_name`: every other character, the path
    separators and dots included, becomes ``_``), at most 64 characters."""
    name = readable_name(str(text).strip(), keep="_+-")[:64].strip("_")
    return name or default


def _write_png(path: Path, image: np.ndarray) -> None:
    atomic_write(path, lambda tmp: Image.fromarray(image).save(tmp, format="PNG"))


class Exports:
    """Files the page asks for, inside ``folder`` only (created on the first export). Each export
    holds the folder's lock (:func:`~mitsuba_platonic.files.outputs.output_lock`) while it picks its
    free name and writes, so that two viewers (or another command) exporting into one ``--out``
    never take the same name; one that finds the folder held says so in one line, on the page,
    and writes nothing. Nothing is written through a link inside the folder
    (:func:`~mitsuba_platonic.files.fileio.confined`)."""

    def __init__(self, folder: PathLike):
        self.folder = Path(folder)

    @contextmanager
    def _writing(self) -> Iterator[None]:
        with confined(self.folder), output_lock(self.folder, "view"):
            yield

    def _free(self, stem: str, exts: Tuple[str, ...]) -> Path:
        """``folder/stem`` (``stem_2``, ``stem_3``, … where an earlier export holds any of ``exts``),
        checked to lie inside ``folder``; call it under :meth:`_writing`."""
        base, k = clean_name(stem), 1
        name = base
        while any((self.folder / (name + e)).exists() for e in exts):
            k += 1
            name = f"{base}_{k}"
        target = (self.folder / name).resolve()
        if target.parent != self.folder.resolve():           # clean_name makes this impossible; kept as a guard
            raise UserError(f"export name {stem!r} leaves the output folder {str(self.folder)!r}")
        return self.folder / name

    def png(self, frame: Frame, name: str = "view") -> Path:
        """The frame as ``name.png`` (8-bit sRGB, as shown; a still: the frame rendered at its size)."""
        with self._writing():
            path = self._free(name, (".png",)).with_suffix(".png")
            _write_png(path, frame.image)
        return path

    def turntable(self, images: Sequence[np.ndarray], name: str = "turntable", frame_ms: int = FRAME_MS) -> List[Path]:
        """A turntable's frames ``(H, W, 3)`` uint8 (one size, at least two) as ``name.webp``, an
        endlessly looping animated WebP of ``frame_ms`` milliseconds a frame, lossless (each frame's
        pixels as rendered), and as ``name_frames/frame_000.png`` … (for a video tool); the frames
        are written first, the animation last, each file whole."""
        pil = [Image.fromarray(np.asarray(i)) for i in images]
        if len(pil) < 2 or len({p.size for p in pil}) != 1 or any(p.mode != "RGB" for p in pil):
            raise UserError(f"turntable: expected at least two (H, W, 3) uint8 frames of one size, got "
                            f"{sorted({(p.mode, p.size) for p in pil})} × {len(pil)}")
        with self._writing():
            stem = self._free(name, (".webp", "_frames"))
            frames = stem.with_name(stem.name + "_frames")
            for k, image in enumerate(images):
                _write_png(frames / f"frame_{k:03d}.png", np.asarray(image))
            path = stem.with_name(stem.name + ".webp")
            atomic_write(path, lambda tmp: pil[0].save(tmp, format="WEBP", save_all=True, append_images=pil[1:],
                                                       duration=int(frame_ms), loop=0, lossless=True))
        return [path, frames]

    def volume(self, volume: torch.Tensor, name: str = "volume", level: float = 0.5) -> List[Path]:
        """``name.npz`` and ``name.vol`` (:func:`~mitsuba_platonic.files.volume_io.save_volume`) and a marching-cubes
        mesh ``name.ply`` at ``level`` (none where the density never crosses it)."""
        with self._writing():
            stem = self._free(name, (".npz", ".vol", ".ply"))
            written = save_volume(volume, stem)
            try:
                mesh = extract_mesh(volume, level=level)
            except ValueError:
                return written
            return written + [save_ply(mesh, stem.with_name(stem.name + ".ply"))]
