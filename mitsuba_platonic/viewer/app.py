"""The page of ``platonic view``, on viser: each browser's camera → a server-rendered frame.

Per browser (viser client) a :class:`ClientView` keeps the GUI and a render thread. A camera
message gives the view ω = normalize(position − look_at) (the scene's up is +y, so viser's
orbit camera has the project's frame: right = (ω_z, 0, −ω_x), up = ω × right) and the window of
the orthographic camera (:func:`~.scene.camera_window`, every renderer draws it,
:mod:`mitsuba_platonic.render.window`). viser's camera is a perspective one of vertical field of
view F (the browser reports it; :data:`FOV` ≈ 28.1° here) on a canvas of width/height a; at the
distance d = |position − look_at| it shows 2 d tan(F/2) world units over the canvas' height, and
the window takes that scale:

    half-width h = d tan(F/2) min(1, a), zoom m = 1/h, clamped to ¼ … 8     (a closer camera magnifies)
    centre = (look_at · right, look_at · up)     (look_at's offset from the cube's centre on the camera plane)

so zooming (viser's wheel: the distance) magnifies the frame about its centre, and panning
(look_at and position moved together, ω kept) moves the window: the volume moves the other way,
by as many pixels on the canvas as the mouse moved (viser trucks the camera by the mouse's travel
at the look-at point's scale, the frame's scale). A frame of resolution R shows a world point at
lateral coordinates (X, Y) at pixel column (1 + (X − c_x) m) R/2, row (1 − (Y − c_y) m) R/2. At
the initial camera (d = :data:`DISTANCE` = 1/tan(:data:`FOV`/2), look_at 0) on a canvas wider than
tall the frames are the renderers' whole-cube frames, bit for bit (on a taller one, the cube's
middle: "reset zoom and pan" moves the camera back to show it whole). The browser's dolly is
held to the distances of zoom ¼ … 8 for its F and a. A camera message that only echoes the
camera drawn (float32 noise, :data:`VIEW_SNAP`) renders nothing again.

Frames come from :meth:`ViewerApp.frame_for`, one render at a time (a lock), which hands back the
last frame rendered where it is asked for again (another page's, the same picture at rest). The
server may start before the scene is made (:func:`~.start.start_server`: ``platonic view`` prints
the address, then imports torch and opens SOURCE); a page that connects meanwhile waits, and is
served when :class:`ViewerApp` takes the server (viser calls its connect handler for the pages
connected already). As the app starts, a thread renders a page's first look (:func:`first_look_key`)
and resamples the volume for its first full frame (:func:`initial_key`) while the browser loads
the page.

The path tracer's frames are not rendered there: a page that shows it asks
:class:`~.worker.PathWorker` (a process of its own, at a lower priority) for one pass of
:data:`~.scene.PASS_SPP` spp at a time and draws the running mean of the passes come back
("progressive", the frame line naming "pass k of P"; the last one "full", bit for bit
:func:`~.scene.render_frame`'s frame). A new request (a camera move, a setting, another volume)
supersedes the trace: its queued pass is dropped, the pass in flight ignored when it comes back,
and the closed form's frame at the volume's resolution is drawn at once as the preview ("moving")
while the first pass at the new camera renders; a closed tab drops its pass likewise. So one
page's path trace never holds another page's frames (they render in this process meanwhile).

While the camera keeps moving (a message within :data:`SETTLE_S`), the thread renders a
low-resolution frame (a quarter of the resolution, at least the volume's; the same resolution
with "low resolution while moving" off), sent as JPEG; once it rests, the full one, as PNG.
Frames are rendered at the canvas' aspect (:func:`~.scene.frame_size`: the resolution R along its
shorter side, the orthographic window widened along the longer one, :func:`~.scene.tiles`) and
drawn as the scene's background image, which viser stretches over the canvas: nothing is
stretched but by the frame's rounding to whole pixels. A page's first full frame waits for the
browser to report its canvas, and for the canvas' size to hold (:data:`CANVAS_SETTLE_S`: the page
docks its control panel beside the canvas after it first reports); meanwhile, once the canvas has
a size, the page shows its first look: the closed form at the volume's resolution N at that
canvas' aspect (a few ms, "moving" on the frame line, ``first look while the canvas settles``),
so that a frame is drawn about a second and a full frame's render (the closed form at 128² of a
32³ volume resamples it to 128³: 0.5–2 s on 2 cores) sooner. The frame line and the settings line
both print the W×H rendered.

The GUI: renderer, formation, resolution, the path tracer's spp, buttons that orbit the camera by
fixed angles (and the front view), zoom it by 2 about its look-at point, pan it by a quarter of
the frame (and reset both), the frame time and the renderer's settings (a line of text the tests
read: ``frame N: T ms, full|moving, W×H px, az A° el E°, zoom M×, centre (X, Y)``), the source's
inputs (a reconstruction run: previous/next held-out input, shown beside the view) or latents (a
generation run: seed, new latent, a walk to a second seed), and exports into the output folder.

The input large and at its own camera (a reconstruction run's input or ``--photo``): "input
beside the frame" (off at first) renders the frame at the canvas' aspect less one
(:func:`~.compare.beside_aspect`) and draws the input at the frame's height beside it, a divider
between (:func:`~.compare.input_beside`, compare mode's side-by-side composition), the frame line
saying ``input beside (NAME, R×R → H×H px)``; "input's camera" moves the browser's camera to the
input's view ω(0°, θ̂) (:meth:`~.scene.Scene.input_camera`: θ̂ the elevation the run's pose head
reads from the input, the volume shown being G's upright one; 0° for ``train.pose: input``) at
zoom 1 without pan, as "reset zoom and pan" places it.

Exports (:class:`~.scene.Exports`): the frame as drawn and the volume, at once; a still (the page's
full frame at the still size, :func:`~.scene.checked_still`, every renderer of it checked to reach
that size) and a turntable (the page's full frame from :func:`~.scene.turntable_views`, animated
WebP and PNG frames) in a thread of their own per page (:meth:`ClientView._export`), of the volume
shown when they started: frame by frame through :meth:`ViewerApp.render_export` (the render lock
is taken per frame, so the pages' frames come between them), the path tracer's frames pass by pass
in the worker (the export a slot of its own), a comparison's two frames drawn in its layout. The
page's export line shows the frame (and pass) in progress; "cancel export", a closed page or the
server's stop ends it between frames and passes, and nothing is written then.

Compare mode (the "compare" control: :data:`~.compare.PAIRS`, "compare as": :data:`~.compare.LAYOUTS`)
keys the request with the renderer ``("compare", pair, layout)``; :func:`compare_keys` gives the
keys of frames A and B (one camera, resolution and volume; half the canvas' aspect side by side),
and :meth:`ClientView._show` draws B with A through :func:`~.compare.compare`, with the colour
scale's range in numbers and its bar (the difference layout). Frame A is rendered here; frame B
here too, or, the path tracer, pass by pass in the worker as above, each pass drawn with A. The
renderer control is disabled meanwhile. A run folder's newest checkpoint is followed
(:class:`~.live.RunWatcher`, every 2 s in its own thread): a new model's volume replaces the
scene's under the scene lock and every page renders again; each page's run line shows the step
and ``scalars.csv``'s latest losses.

What a page sends is checked at the server's boundary (a page can send any number, past what its
controls allow): a camera whose position or look-at point is not finite or lies beyond
:data:`MAX_COORDINATE`, a seed that is not an integer in 0 … :data:`MAX_SEED` (as ``generate
--seed``), a walk outside [0, 1] are refused, an spp outside the slider's 1 … :data:`MAX_SPP` and
a resolution not among the choices are clamped to them; each is one line in the server's log
(stderr, ``platonic view: ignored …``), never a traceback, and the page keeps its last frame.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import replace
from concurrent.futures import CancelledError, TimeoutError as FutureTimeout
from pathlib import Path
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np
import torch
import viser
from PIL import Image

from ..errors import UserError
from ..views import camera_frames, from_angles, to_angles
from ..render.window import window_or_none
from .compare import (GAP, LAYOUTS, PAIRS, Comparison, beside_aspect, colour_bar, compare, half_aspect, input_beside, nearest,
                      pairs_for)
from .live import RunWatcher
from .scene import (ASPECT_RANGE, MAX_RESAMPLED, MAX_STILL, MAX_TURNTABLE_FRAMES, PASS_SPP, TURNTABLE_FRAMES, WINDOW_SNAP, ZOOM_RANGE,
                    Exports, Frame, Scene, Window, camera_window, checked_frames, checked_still, default_resolution,
                    formations_for, formations_of, model_of, passes_for, plan_frame, prepare_volume, render_frame, renderers_for,
                    resolutions_for, still_sizes, to_display, turntable_views, zoom_distance)
from .worker import PathWorker, WorkerError
from .start import DISTANCE, FOV, address, start_server, stop_server

__all__ = ["ViewerApp", "first_look_key", "SETTLE_S", "MAX_SPP", "MAX_SEED", "MAX_COORDINATE", "log_ignored", "checked_seed",
           "checked_camera", "checked_aspect", "compare_keys", "COMPARE_OFF"]

#: A camera at rest this long gets its full-resolution frame.
SETTLE_S = 0.2
#: A camera message whose view differs from the drawn one by at most this (each component of ω)
#: and whose window by at most :data:`~.scene.WINDOW_SNAP` is the browser's float32 echo of the
#: camera the server set (or of the first camera): nothing moved, nothing to render again.
VIEW_SNAP = 1e-6
#: Before a page first reports the initial camera it may report the browser's own default camera
#: (seen: the back view at zoom 0.8, a quarter of a second before the initial one); such reports are
#: not the user's and are not drawn. After this many seconds from the connection every report counts,
#: echoed or not.
CONNECT_S = 1.0
#: A page's frames wait this long from its connection for the browser to report its canvas' size
#: (with its first camera), so that its first frame has the canvas' aspect; then a square one is drawn.
CANVAS_S = 10.0
#: A canvas' size must hold this long before a frame is rendered for it (:meth:`ClientView._canvas_settled`).
CANVAS_SETTLE_S = 1.0
#: The page's controls as it opens: the renderer and the path tracer's spp (the formation: the
#: volume's richest, EA or AO; the resolution: the volume's).
INITIAL_RENDERER, INITIAL_SPP = "closed form", 4
#: The still size a page offers first (the choice of :func:`~.scene.still_sizes` nearest to it), pixels.
STILL_SIZE = 1024
#: How many times larger the panel shows the input than its pixels.
PANEL_INPUT_SCALE = 4


def _panel_input(image: np.ndarray) -> np.ndarray:
    """The input as the panel shows it: each pixel a :data:`PANEL_INPUT_SCALE`-wide block (:func:`~.compare.nearest`)."""
    return nearest(image, PANEL_INPUT_SCALE * image.shape[0], PANEL_INPUT_SCALE * image.shape[1])


#: The zoom buttons' factor, and the pan buttons' step as a fraction of the frame's width.
ZOOM_STEP, PAN_STEP = 2.0, 0.25
#: The path tracer's spp slider's range, which the server holds a page's spp to.
MAX_SPP = 64
#: The largest seed a page may ask for: torch's and numpy's generators take a 64-bit signed integer.
MAX_SEED = 2 ** 63 - 1
#: The largest camera coordinate (world units; the cube is [−1, 1]³) a page's camera may have.
MAX_COORDINATE = 1e6
#: A canvas' width/height is keyed to this many decimals (the frame's size is whole pixels anyway).
ASPECT_DIGITS = 3
#: How long :meth:`ViewerApp.stop` waits for the frames in flight to finish (seconds).
STOP_WAIT_S = 60.0
#: The compare control's first choice: one renderer, the renderer control's.
COMPARE_OFF = "off"


def initial_key(scene: Scene, version: int = 0, aspect: float = 1.0) -> Tuple:
    """The frame a page asks for first: the front view through the whole window with the page's
    initial controls on a canvas of ``aspect``, as :meth:`ClientView._request` keys it."""
    c, n = scene.volume.shape[0], scene.volume.shape[-1]
    return ((0.0, 0.0, 1.0), INITIAL_RENDERER, formations_for(c)[-1], default_resolution(n), INITIAL_SPP, version,
            None, round(aspect, ASPECT_DIGITS))


def first_look_key(scene: Scene, version: int = 0, aspect: float = 1.0) -> Tuple:
    """A page's first look, drawn while its canvas settles: :func:`initial_key` at the volume's
    resolution N (the closed form renders the volume itself, no resampling: a few milliseconds)."""
    return at_volume_resolution(initial_key(scene, version, aspect), scene)


def at_volume_resolution(key: Tuple, scene: Scene) -> Tuple:
    """``key`` (a frame's key: view, renderer, formation, resolution, …) at the volume's own resolution N."""
    return key[:3] + (scene.volume.shape[-1],) + key[4:]


_last_ignored = {"line": None}


def log_ignored(what: str) -> None:
    """One line in the server's log (stderr) for a value a page sent that was refused or clamped (a
    line the same as the one before is not repeated: the render thread asks again every 0.1 s)."""
    line = f"platonic view: ignored {what}"
    if line != _last_ignored["line"]:
        _last_ignored["line"] = line
        print(line, file=sys.stderr, flush=True)


def checked_seed(value: object, what: str = "seed") -> Optional[int]:
    """A page's seed as an int in 0 … :data:`MAX_SEED`, else None (and one line in the log)."""
    try:
        number = float(value)
        seed = int(value) if isinstance(value, int) else int(number) if number.is_integer() else None
    except (TypeError, ValueError, OverflowError):
        seed = None
    if seed is None or not 0 <= seed <= MAX_SEED:
        log_ignored(f"{what} {value!r} from a page: expected an integer from 0 to 2⁶³ − 1")
        return None
    return seed


def checked_camera(position: object, look_at: object) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """A page's camera (position, look-at point) as float arrays when both are finite 3-vectors within
    :data:`MAX_COORDINATE` and apart, else None (and one line in the log)."""
    try:
        p, a = np.asarray(position, np.float64).reshape(-1), np.asarray(look_at, np.float64).reshape(-1)
    except (TypeError, ValueError):
        p = a = np.zeros(0)
    if (p.shape != (3,) or a.shape != (3,) or not (np.isfinite(p).all() and np.isfinite(a).all())
            or max(np.abs(p).max(), np.abs(a).max()) > MAX_COORDINATE or not np.linalg.norm(p - a) > 1e-9):
        log_ignored(f"a camera from a page: position {position!r}, look_at {look_at!r} (expected finite points "
                    f"within ±{MAX_COORDINATE:g}, apart)")
        return None
    return p, a


def _same_camera(view_a: np.ndarray, window_a: Optional[Window], view_b: np.ndarray,
                 window_b: Optional[Window]) -> bool:
    """Whether two cameras draw the same frame but for float32 noise (:data:`VIEW_SNAP`, :data:`WINDOW_SNAP`)."""
    if np.abs(np.asarray(view_a) - np.asarray(view_b)).max() > VIEW_SNAP:
        return False
    if window_a is None or window_b is None:
        return window_a is window_b
    return (abs(window_a.zoom / window_b.zoom - 1.0) <= WINDOW_SNAP
            and max(abs(a - b) for a, b in zip(window_a.centre, window_b.centre)) <= WINDOW_SNAP)


def checked_aspect(width: object, height: object) -> float:
    """A page's canvas (``width`` × ``height`` pixels, as the browser reports it) as the aspect its frames
    are rendered at: width/height to :data:`ASPECT_DIGITS` decimals, held to :data:`~.scene.ASPECT_RANGE`
    (one line in the log past it); 1 for a canvas that is not two positive finite numbers (before the
    browser has said, or a page that sends nonsense)."""
    try:
        w, h = float(width), float(height)
    except (TypeError, ValueError):
        w = h = math.nan
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        return 1.0
    aspect = w / h
    held = min(max(aspect, ASPECT_RANGE[0]), ASPECT_RANGE[1])
    if held != aspect:
        log_ignored(f"a canvas of {width!r}×{height!r} pixels from a page: its frames are rendered at the aspect "
                    f"{held:g} ({ASPECT_RANGE[0]:g} … {ASPECT_RANGE[1]:g}) and stretched over it")
    return round(held, ASPECT_DIGITS)


def compare_keys(key: Tuple) -> Tuple[Tuple, Tuple]:
    """A compare request's ``key`` (its renderer ``("compare", pair, layout)``, its aspect the canvas')
    → the keys of frames A and B: the pair's renderers at the one camera, resolution and volume, at
    the layout's aspect (:func:`~.compare.half_aspect`), the lit renderer's formation EA where the
    pair has one (A forms what B forms)."""
    view, (_, pair, layout), formation, res, spp, version, window, aspect = key
    a, b = PAIRS[pair]
    formation = formation if formation in formations_of(b, 4) else "EA"
    half = round(half_aspect(layout, aspect), ASPECT_DIGITS)
    return ((view, a, formation, res, spp, version, window, half),
            (view, b, formation, res, spp, version, window, half))


def _clamped_choice(value: object, choices: "Sequence[int]", what: str) -> int:
    """A page's ``value`` held to the nearest of ``choices`` (ascending ints; the first for a value that
    is no number), with one line in the log where it was not one of them."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isnan(number) and number.is_integer() and int(number) in choices:
        return int(number)
    held = choices[0] if math.isnan(number) else min(choices, key=lambda c: abs(c - number))
    log_ignored(f"{what} {value!r} from a page: held to {held} ({choices[0]} … {choices[-1]})")
    return held


class ViewerApp:
    """The page for one :class:`~.scene.Scene`, its exports into ``out``: on ``server`` (started by
    :func:`~.start.start_server` on ``host:port``, whose address may already have been given out:
    the pages connected to it are served from here on), else on a server started here."""

    def __init__(self, scene: Scene, out: Path, host: str = "127.0.0.1", port: int = 8080,
                 server: Optional["viser.ViserServer"] = None):
        if server is None:
            server = start_server(host, port)
        self.scene, self.exports = scene, Exports(out)
        self.render_lock = threading.Lock()               # one render at a time (torch's and Dr.Jit's threads)
        self.scene_lock = threading.RLock()
        self.version = 0                                   # bumped when the volume changes
        self.last: Optional[Tuple[Tuple, Frame]] = None     # the last frame rendered (any page's) and its key
        self.server = server
        self.host, self.port = host, self.server.get_port()
        self.clients = {}
        self.closed: list = []                              # closed pages' views whose render may still run
        self.worker = PathWorker()                          # the path tracer's passes, in a process of their own
        self.live: Optional[RunWatcher] = None              # a run folder: its newest checkpoint, followed
        if scene.folder is not None and scene.model is not None:
            self.live = RunWatcher(scene.folder, scene.model.step, scene.stamp, lambda path: model_of(path)[0],
                                   self._take_model, self._run_changed)
        self.warming = threading.Thread(target=self._warm_up, name="warm-up", daemon=True)
        self.warming.start()
        # viser calls the connect handler for the pages connected already too (those that opened the
        # address while the scene loaded); they get their GUI and first frame now
        self.server.on_client_disconnect(self._disconnect)
        self.server.on_client_connect(self._connect)

    @property
    def url(self) -> str:
        return address(self.host, self.port)

    def _connect(self, client: "viser.ClientHandle") -> None:
        self.clients[client.client_id] = ClientView(self, client)

    def _disconnect(self, client: "viser.ClientHandle") -> None:
        view = self.clients.pop(client.client_id, None)
        if view is not None:
            view.stop()
            self.closed = [v for v in self.closed if v.busy()] + [view]   # stop() waits for its frame and its export

    def _warm_up(self) -> None:
        """While the browser loads the page: render a first look (:func:`first_look_key`, a square
        canvas's), resample the volume for the first full frame (:func:`initial_key`'s resolution:
        the cache :func:`~.scene.render_frame` reads) and encode the look once as the page does
        (viser's PNG and JPEG encoders load their libraries on first use). Not the full frame
        itself: it is for a canvas whose aspect the page has not said yet (a square one's was
        wasted on a 16:9 canvas, a second or two of the two cores the page was loading on); the
        page's own requests then render with torch, the resampled volume and the encoders warm."""
        try:
            frame = self.frame_for(first_look_key(self.scene))
            key = initial_key(self.scene)
            with self.render_lock, self.scene_lock:
                plan = plan_frame(self.scene.volume, key[1], key[2], key[3], key[4], None, 1.0)
                prepare_volume(self.scene.volume, plan)
            from viser._image_encoding import cv2_imencode_with_fallback   # lazy: viser's own encoder, warmed only
            for fmt in ("png", "jpeg"):
                cv2_imencode_with_fallback(fmt, frame.image, jpeg_quality=90, channel_ordering="rgb")
        except Exception:                                  # the page's own request renders it and shows why
            pass

    def frame_for(self, key: Tuple) -> Frame:
        """The frame of ``key`` (view, renderer, formation, resolution, spp, volume version, window, aspect):
        the last frame rendered where it has that key (the warm-up's, another page's, the same
        picture asked for again at rest), else rendered now; one render at a time."""
        with self.render_lock:
            if self.last is not None and self.last[0] == key:
                return self.last[1]
            view, renderer, formation, res, spp, _, window, aspect = key
            with self.scene_lock:
                version = self.version                       # the volume it renders (a newer one where it changed)
                frame = render_frame(self.scene.volume, view, renderer, formation, res, spp, window, aspect)
            self.last = (key[:5] + (version,) + key[6:], frame)
            return frame

    def render_export(self, volume: torch.Tensor, key: Tuple) -> Frame:
        """The frame of ``key`` (as :meth:`frame_for`'s, at a resolution up to :data:`~.scene.MAX_STILL`)
        of ``volume`` (an export's, taken when it started), rendered now, one render at a time with the
        pages' frames (it neither uses nor replaces the last frame)."""
        view, renderer, formation, res, spp, _, window, aspect = key
        with self.render_lock:
            return render_frame(volume, view, renderer, formation, res, spp, window, aspect, MAX_STILL)

    def comparison_for(self, key_a: Tuple, key_b: Tuple, layout: str) -> Tuple[Frame, Frame, Comparison]:
        """Frames A and B of ``key_a`` and ``key_b`` (:meth:`frame_for`, :func:`compare_keys`) and their
        comparison in ``layout`` (:func:`~.compare.compare`: what the page draws, and |A − B|)."""
        frame_a, frame_b = self.frame_for(key_a), self.frame_for(key_b)
        return frame_a, frame_b, compare(frame_a.image, frame_b.image, layout)

    def _take_model(self, model) -> None:
        """The run's newer checkpoint (the watcher's thread): its volume in place of the shown one."""
        with self.scene_lock:
            self.scene.use_model(model)
        self.volume_changed()

    def _run_changed(self) -> None:
        for view in list(self.clients.values()):
            view.refresh_run()

    def volume_changed(self) -> None:
        """The scene's volume changed (another input or latent): every page renders again."""
        with self.scene_lock:
            self.version += 1
        for view in list(self.clients.values()):
            view.refresh_source()
            view.wake.set()

    def stop(self) -> None:
        """Stop the watcher, the pages' render threads, closed pages' too (a frame in flight is let finish, up to
        :data:`STOP_WAIT_S`: a thread killed inside torch at the interpreter's exit aborts it) and
        the worker, then the server."""
        if self.live is not None:
            self.live.stop()
        views = list(self.clients.values())
        for view in views:
            view.stop()
        views += self.closed
        deadline = time.monotonic() + STOP_WAIT_S
        for thread in [t for view in views for t in view.threads()]:
            thread.join(timeout=max(0.0, deadline - time.monotonic()))
        if self.live is not None:
            self.live.join(max(0.0, deadline - time.monotonic()))
        self.worker.stop()
        stop_server(self.server)


class ClientView:
    """One browser's GUI, camera and render thread."""

    def __init__(self, app: ViewerApp, client: "viser.ClientHandle"):
        self.app, self.client = app, client
        self.lock = threading.Lock()
        self.wake = threading.Event()
        self.stopped = False
        self.view = np.array(initial_key(app.scene)[0])
        self.window: Optional[Window] = None              # the full window: the initial camera
        self.last_move = 0.0
        self.shown: Optional[Tuple] = None
        self.count = 0
        self.frame: Optional[Frame] = None
        self.times = {}                                    # renderer → last full frame's seconds
        self.trace: Optional[_Trace] = None                # the path trace in progress
        self.partner: Optional[Tuple[Tuple, Frame, str, str]] = None   # compare: (A's key, A's frame, layout, pair)
        self.comparison: Optional[Comparison] = None      # compare: the last comparison drawn
        self.mode: Optional[Tuple] = None                  # the last request's (compare choice or None, input beside)
        self.limits = (0.01, 1e4)                          # the browser's dolly limits as set (viser's defaults)
        self.connected = time.monotonic()
        self.placed = False                                # has the page reported the initial camera yet?
        self.canvas, self.canvas_at = None, 0.0             # the canvas' size (pixels) last seen, and since when
        self.export: Optional[threading.Thread] = None      # the still or turntable export in progress
        self.export_cancel = threading.Event()
        self.export_lock = threading.Lock()
        self._gui()
        # the camera viser connects a page with is the browser's default, before it takes the initial one
        # (DISTANCE, FOV): draw the initial camera until the page says where it is
        self._limit_distance(FOV, 1.0)
        client.camera.on_update(self._camera)
        self.thread = threading.Thread(target=self._loop, name=f"render-{client.client_id}", daemon=True)
        self.thread.start()
        self.wake.set()

    # -- GUI ------------------------------------------------------------------------------------

    def _gui(self) -> None:
        gui, scene = self.client.gui, self.app.scene
        c, n = scene.volume.shape[0], scene.volume.shape[-1]
        self.title = gui.add_markdown(self._title_text())
        self.run_line = gui.add_markdown(self.app.live.line(), visible=True) if self.app.live is not None else None
        self.info = gui.add_markdown("frame: waiting for the first frame")
        self.settings = gui.add_markdown("")
        self.scale = gui.add_markdown("", visible=False)
        self.scale_bar = None                               # the colour scale's bar: made at the first difference drawn
        with gui.add_folder("Renderer"):
            self.renderer = gui.add_dropdown("renderer", renderers_for(c), initial_value=INITIAL_RENDERER)
            self.formation = gui.add_dropdown("formation", formations_for(c), initial_value=formations_for(c)[-1],
                                              hint="VH, AO: density only; EA: colour (the lit renderers form EA)")
            choices = [str(r) for r in resolutions_for(n)]
            self.resolution = gui.add_dropdown("resolution", choices, initial_value=str(default_resolution(n)),
                                               hint="the frame's pixels along the canvas' shorter side")
            self.spp = gui.add_slider("path tracer spp", min=1, max=MAX_SPP, step=1, initial_value=INITIAL_SPP)
            self.low = gui.add_checkbox("low resolution while moving", initial_value=True,
                                        hint="a quarter of the resolution (at least the volume's) while the camera moves")
            # after the others: the page's dropdowns keep their order (renderer, formation, resolution)
            self.compare = gui.add_dropdown("compare", [COMPARE_OFF] + pairs_for(c), initial_value=COMPARE_OFF,
                                            hint="two renderers at one camera (the renderer control is unused then)")
            self.layout = gui.add_dropdown("compare as", list(LAYOUTS), initial_value=LAYOUTS[0],
                                           hint="side by side, or |A − B| through the colour scale shown above")
            for handle in (self.formation, self.resolution, self.spp, self.low, self.layout):
                handle.on_update(lambda _: self.wake.set())
            for handle in (self.renderer, self.compare):
                handle.on_update(lambda _: self._offer_formations())
        with gui.add_folder("Camera"):
            for label, daz, delv in (("azimuth -30", -30.0, 0.0), ("azimuth +30", 30.0, 0.0),
                                     ("elevation -15", 0.0, -15.0), ("elevation +15", 0.0, 15.0)):
                gui.add_button(label).on_click(self._orbit_by(daz, delv))
            gui.add_button("front view").on_click(lambda _: self.set_view(0.0, 0.0))
            gui.add_button("zoom in").on_click(lambda _: self.zoom_by(ZOOM_STEP))
            gui.add_button("zoom out").on_click(lambda _: self.zoom_by(1.0 / ZOOM_STEP))
            for label, dx, dy in (("pan left", -1, 0), ("pan right", 1, 0), ("pan up", 0, 1), ("pan down", 0, -1)):
                gui.add_button(label).on_click(self._pan_by(dx * PAN_STEP, dy * PAN_STEP))
            gui.add_button("reset zoom and pan").on_click(
                lambda _: self.move_camera(np.zeros(3), zoom_distance(1.0, *self._lens())))
        self.source_gui(gui)
        with gui.add_folder("Export"):
            self.name = gui.add_text("name", initial_value="view", hint="a file name inside the output folder")
            gui.add_button("save view (PNG)").on_click(lambda _: self._export_png())
            gui.add_button("save volume (.npz .vol .ply)").on_click(lambda _: self._export_volume())
            sizes = still_sizes(n)
            self.still_size = gui.add_dropdown("still size", [str(s) for s in sizes],
                                               initial_value=str(min(sizes, key=lambda s: (abs(s - STILL_SIZE), s))),
                                               hint=f"the still's pixels along the shorter side, up to {MAX_STILL} (past "
                                                    f"{MAX_RESAMPLED}: the marcher only)")
            gui.add_button("save still (PNG)").on_click(lambda _: self._start_export("still"))
            self.frames = gui.add_number("turntable frames", initial_value=TURNTABLE_FRAMES, min=2,
                                         max=MAX_TURNTABLE_FRAMES, step=1,
                                         hint="frames of a whole turn about the vertical, at the page's resolution")
            gui.add_button("save turntable (WebP)").on_click(lambda _: self._start_export("turntable"))
            self.cancel_button = gui.add_button("cancel export", disabled=True)
            self.cancel_button.on_click(lambda _: self.export_cancel.set())
            self.exported = gui.add_markdown(f"into `{self.app.exports.folder}`")

    def _offer_formations(self) -> None:
        """Offer the formations the chosen renderer renders (:func:`~.scene.formations_of`): the lit ones
        EA only (they offered VH and AO and drew EA), the others the volume's."""
        pair = PAIRS.get(self.compare.value)
        self.renderer.disabled = pair is not None
        offered = formations_of(self.renderer.value if pair is None else pair[1], self.app.scene.volume.shape[0])
        if tuple(self.formation.options) != tuple(offered):
            keep = self.formation.value if self.formation.value in offered else offered[-1]
            self.formation.options = offered
            self.formation.value = keep
        self.wake.set()

    def source_gui(self, gui) -> None:
        scene = self.app.scene
        self.input_image = self.beside = None
        if scene.input is not None:
            with gui.add_folder("Input"):
                self.input_image = gui.add_image(_panel_input(scene.input), label="input",
                                                 format="png")
                self.input_label = gui.add_markdown(self._input_text())
                if scene.inputs is not None and len(scene.inputs) > 1:
                    gui.add_button("previous input").on_click(lambda _: self._step_input(-1))
                    gui.add_button("next input").on_click(lambda _: self._step_input(+1))
                self.beside = gui.add_checkbox("input beside the frame", initial_value=False,
                                               hint="the input at the frame's height, beside it on the canvas")
                self.beside.on_update(lambda _: self.wake.set())
                gui.add_button("input's camera", hint="the input's own view: azimuth 0, the elevation the model "
                                                      "reads from it; zoom 1, no pan").on_click(
                    lambda _: self.input_camera())
        if scene.kind == "generation" or (scene.kind == "reconstruction" and scene.inputs is None):
            with gui.add_folder("Latent"):
                self.seed = gui.add_number("seed", initial_value=scene.seeds[0], min=0, step=1)
                self.seed_b = gui.add_number("walk to seed", initial_value=scene.seeds[0] + 1, min=0, step=1)
                self.walk = gui.add_slider("walk", min=0.0, max=1.0, step=0.05, initial_value=0.0)
                gui.add_button("new latent").on_click(lambda _: self._new_latent())
                for handle in (self.seed, self.seed_b, self.walk):
                    handle.on_update(lambda _: self._latent())

    def _title_text(self) -> str:
        scene = self.app.scene
        return f"**{scene.title}**" + "".join(f"\n\n{note}" for note in scene.notes)

    def refresh_run(self) -> None:
        """The run line (the step shown, the latest losses) and the title, after the run changed."""
        if self.run_line is not None:
            self.run_line.content = self.app.live.line()
        self.title.content = self._title_text()

    def _input_text(self) -> str:
        scene = self.app.scene
        if not scene.input_names:
            return ""
        return f"{scene.input_names[scene.input_index]} ({scene.input_index + 1} of {len(scene.input_names)})"

    def refresh_source(self) -> None:
        scene = self.app.scene
        self.title.content = self._title_text()
        if self.input_image is not None and scene.input is not None:
            self.input_image.image = _panel_input(scene.input)
            self.input_label.content = self._input_text()

    def _step_input(self, step: int) -> None:
        with self.app.scene_lock:
            self.app.scene.show_input(self.app.scene.input_index + step)
        self.app.volume_changed()

    def _new_latent(self) -> None:
        seed = checked_seed(self.seed.value)
        if seed is not None:
            self.seed.value = seed + 1 if seed < MAX_SEED else 0   # its on_update draws it

    def _latent(self) -> None:
        seed = checked_seed(self.seed.value)
        seed_b = checked_seed(self.seed_b.value, "walk-to seed")
        try:
            t = float(self.walk.value)
        except (TypeError, ValueError):
            t = math.nan
        if not 0.0 <= t <= 1.0:
            log_ignored(f"walk {self.walk.value!r} from a page: expected a number from 0 to 1")
            return
        if seed is None or (t > 0 and seed_b is None):
            return
        with self.app.scene_lock:
            self.app.scene.show_latent(seed, seed_b if t > 0 else None, t)
        self.app.volume_changed()

    # -- camera -----------------------------------------------------------------------------------

    def _lens(self) -> Tuple[float, float]:
        """This browser's vertical field of view (radians) and canvas width/height, as it last said
        (:data:`FOV` and 1 before it has)."""
        cam = self.client.camera
        fov, height = float(cam.fov), cam.image_height
        if not (0.0 < fov < math.pi and height > 0 and cam.image_width > 0):
            return FOV, 1.0
        return fov, cam.image_width / height

    def _limit_distance(self, fov: float, aspect: float) -> None:
        """The browser's own dolly stops where the zoom does (:data:`ZOOM_RANGE`): the wheel never runs past it."""
        near, far = zoom_distance(ZOOM_RANGE[1], fov, aspect), zoom_distance(ZOOM_RANGE[0], fov, aspect)
        if np.allclose((near, far), self.limits):
            return
        cam = self.client.camera
        if near > self.limits[1]:                          # each setter refuses a minimum above the maximum
            cam.max_orbit_distance, cam.min_orbit_distance = far, near
        else:
            cam.min_orbit_distance, cam.max_orbit_distance = near, far
        self.limits = (near, far)

    def _camera(self, camera) -> None:
        checked = checked_camera(camera.position, camera.look_at)    # NaN, 1e308: one line, no traceback
        if checked is None:
            return
        position, look = checked
        w = position - look
        norm = float(np.linalg.norm(w))
        fov, aspect = self._lens()
        try:
            window = camera_window(position, look, fov, aspect)
        except UserError as e:
            log_ignored(f"a camera from a page: {e}")
            return
        self._limit_distance(fov, aspect)
        with self.lock:
            echo = _same_camera(w / norm, window, self.view, self.window)
            if not self.placed:                            # the browser's default camera before the initial one
                self.placed = echo or time.monotonic() - self.connected > CONNECT_S
                if not self.placed:
                    return
            if echo:
                return                                     # an echo: the frame drawn is this camera's
            self.view = w / norm
            self.window = window
            self.last_move = time.monotonic()
        self.wake.set()

    def _place(self) -> Tuple[np.ndarray, float]:
        """This browser's camera: its look-at point and its distance from it."""
        cam = self.client.camera
        look = np.asarray(cam.look_at, float)
        return look, float(np.linalg.norm(np.asarray(cam.position, float) - look)) or DISTANCE

    def move_camera(self, look: np.ndarray, distance: float, w: Optional[np.ndarray] = None) -> None:
        """Put this browser's camera at ``look + distance ω`` looking at ``look`` (ω: ``w``, else its own)."""
        with self.lock:
            w = np.asarray(self.view if w is None else w, float)
        position = np.asarray(look, float) + distance * w
        cam = self.client.camera
        with self.client.atomic():
            cam.up_direction = (0.0, 1.0, 0.0)
            cam.position = tuple(position)                  # viser moves look_at along with the position:
            cam.look_at = tuple(look)                         # set it back, to orbit about it
        window = camera_window(position, look, *self._lens())
        with self.lock:                                    # render it even before the browser echoes it
            self.view, self.window = w, window
            self.last_move = 0.0
        self.wake.set()

    def zoom_by(self, factor: float) -> None:
        """Zoom ``factor`` times about the look-at point (the distance ÷ ``factor``, within :data:`ZOOM_RANGE`)."""
        look, d = self._place()
        lens = self._lens()
        d = min(max(d / factor, zoom_distance(ZOOM_RANGE[1], *lens)), zoom_distance(ZOOM_RANGE[0], *lens))
        self.move_camera(look, d)

    def _pan_by(self, dx: float, dy: float) -> Callable:
        """A button's pan: look_at and the camera move by (dx, dy) frame widths along (right, up)."""
        def pan(_) -> None:
            look, d = self._place()
            with self.lock:
                right, up, _ = camera_frames(torch.tensor(self.view)[None])
                half = 1.0 / (self.window.zoom if self.window is not None else 1.0)
            step = 2.0 * half * (dx * right[0].numpy() + dy * up[0].numpy())
            self.move_camera(look + step, d)
        return pan

    def _orbit_by(self, daz: float, delv: float) -> Callable:
        def orbit(_) -> None:
            with self.lock:
                az, el = (float(a) for a in to_angles(torch.tensor(self.view)))
            self.set_view(az + daz, max(-89.0, min(89.0, el + delv)))
        return orbit

    def input_camera(self) -> None:
        """Move this browser's camera to the input's own view (:meth:`~.scene.Scene.input_camera`) at
        zoom 1, centred (nothing where no input is shown)."""
        with self.app.scene_lock:
            angles = self.app.scene.input_camera()
        if angles is not None:
            self.move_camera(np.zeros(3), zoom_distance(1.0, *self._lens()),
                             from_angles(*angles).double().numpy())

    def set_view(self, azimuth: float, elevation: float) -> None:
        """Move this browser's camera to ω(azimuth, elevation) around its look-at point, at its distance."""
        look, d = self._place()
        self.move_camera(look, d, from_angles(azimuth, elevation).double().numpy())

    # -- frames -----------------------------------------------------------------------------------

    def _canvas_settled(self) -> bool:
        """Whether this page's canvas has a size (the browser reports it with its first camera; a
        square one is assumed :data:`CANVAS_S` after the connection) that has held for
        :data:`CANVAS_SETTLE_S`: the page lays its panel out after it first reports (the canvas
        narrows), and a resized window reports many sizes; the frame is for the one it rests at."""
        cam = self.client.camera
        size, now = (cam.image_width, cam.image_height), time.monotonic()
        if size != self.canvas:
            self.canvas, self.canvas_at = size, now
        if not (size[0] > 0 and size[1] > 0):
            return now - self.connected >= CANVAS_S
        return now - self.canvas_at >= CANVAS_SETTLE_S

    def _request(self, at_rest: bool = False) -> Tuple:
        """(the key of the frame this page asks for now, its canvas' aspect, 'full' or 'moving');
        ``at_rest``: the full frame, moving or not (an export's)."""
        with self.lock:
            view = tuple(float(x) for x in self.view)
            moving = not at_rest and time.monotonic() - self.last_move < SETTLE_S
            window = self.window
        n = self.app.scene.volume.shape[-1]
        choices = resolutions_for(n)
        full = _clamped_choice(self.resolution.value, choices, "resolution")
        low = max(n, full // 4) if self.low.value else full
        res, quality = (low, "moving") if moving else (full, "full")
        spp = int(_clamped_choice(self.spp.value, range(1, MAX_SPP + 1), "path tracer spp"))
        cam = self.client.camera
        aspect = checked_aspect(cam.image_width, cam.image_height)
        if self._beside():                                 # the input takes a square of the frame's height
            aspect = round(beside_aspect(aspect, ASPECT_RANGE[0]), ASPECT_DIGITS)
        renderer = self.renderer.value
        pair, layout = self.compare.value, self.layout.value
        if pair != COMPARE_OFF:
            if pair not in pairs_for(self.app.scene.volume.shape[0]):
                log_ignored(f"compare {pair!r} from a page: expected one of {pairs_for(self.app.scene.volume.shape[0])}")
            elif layout not in LAYOUTS:
                log_ignored(f"compare as {layout!r} from a page: expected one of {list(LAYOUTS)}")
            else:
                renderer = ("compare", pair, layout)
        key = (view, renderer, self.formation.value, res, spp, self.app.version, window, aspect)
        return key, aspect, quality

    def _beside(self) -> bool:
        """Whether the input is drawn beside the frame (its checkbox, where an input is shown)."""
        return self.beside is not None and bool(self.beside.value) and self.app.scene.input is not None

    def _loop(self) -> None:
        while not self.stopped:
            self.wake.wait(timeout=SETTLE_S / 2)
            self.wake.clear()
            if self.stopped:
                return
            request = None
            if not self._canvas_settled():
                if self.count == 0 and self.canvas is not None and min(self.canvas) > 0:
                    self._first_look()
                continue
            try:
                request = self._request()
                mode = (request[0][1] if isinstance(request[0][1], tuple) else None, self._beside())
                if mode != self.mode:                      # into, out of, or between comparisons: all anew
                    self._drop_trace()
                    self.mode, self.shown, self.partner = mode, None, None
                    self._show_scale(None)
                if mode[0] is not None:
                    self._compare(request)
                    continue
                if request[0][1] == "path tracer":
                    self._trace(request)
                    continue
                self._drop_trace()
                if request == self.shown:
                    continue
                self._render(request)
            except UserError as e:
                self.info.content = f"frame: error: {e}"
                self.shown = request
                self._drop_trace(keep=True)
            except Exception as e:                          # the page stays up; the error shows there
                if self.stopped:
                    return
                self.info.content = f"frame: error: {type(e).__name__}: {e}"
                self.shown = request
                self._drop_trace(keep=True)

    def _first_look(self) -> None:
        """The page's first frame while its canvas settles (:meth:`_canvas_settled`): the closed form at
        the volume's resolution at the canvas' aspect as it is now (:func:`first_look_key`), drawn as a
        "moving" frame; only for the page's initial renderer (nothing else is asked for yet)."""
        try:
            key, aspect, _ = self._request()
            if key[1] != INITIAL_RENDERER:
                return
            self._render((at_volume_resolution(key, self.app.scene), aspect, "moving"),
                         ", first look while the canvas settles")
        except Exception:                                  # the full frame's request shows what is wrong
            pass

    def _render(self, request: Tuple, note: str = "") -> None:
        key, aspect, quality = request
        frame = self.app.frame_for(key)
        if self.stopped:
            return
        self._show(frame, key, aspect, quality, note)
        self.shown = request

    def _compare(self, request: Tuple) -> None:
        """One step of a comparison (:func:`compare_keys`): frame A rendered here (kept while B's path
        trace runs), frame B rendered here or traced pass by pass in the worker (:meth:`_trace`, each
        pass drawn with A); :meth:`_show` draws the two in the layout."""
        key, aspect, quality = request
        _, pair, layout = key[1]
        key_a, key_b = compare_keys(key)
        if key_b[1] != "path tracer":
            self._drop_trace()
            if request == self.shown:
                return
            frame_a, frame_b, _ = self.app.comparison_for(key_a, key_b, layout)
            if self.stopped:
                return
            self.partner = (key_a, frame_a, layout, pair)
            self._show(frame_b, key_b, key_b[7], quality)
            self.shown = request
            return
        if self.partner is None or self.partner[0] != key_a:
            self.partner = (key_a, self.app.frame_for(key_a), layout, pair)
        self._trace((key_b, key_b[7], quality))

    def _with_partner(self, frame: Frame) -> Tuple[Frame, str]:
        """Compare mode: frame B drawn with A (:data:`partner`) in the layout, and the frame line's note;
        a preview of another size than A (the path tracer's closed form) is scaled to A's, nearest pixel."""
        _, frame_a, layout, pair = self.partner
        image = frame.image
        if image.shape != frame_a.image.shape:
            h, w = frame_a.image.shape[:2]
            image = np.asarray(Image.fromarray(image).resize((w, h), Image.NEAREST))
        self.comparison = compare(frame_a.image, image, layout)
        self._show_scale(self.comparison)
        both = Frame(self.comparison.image, frame_a.seconds + frame.seconds,
                     f"A: {frame_a.settings} | B: {frame.settings}", frame.view, pair, frame.formation,
                     frame.resolution, frame.window)
        return both, f", compare {pair} ({layout})"

    def _with_input(self, frame: Frame) -> Tuple[Frame, str]:
        """The input at ``frame``'s height beside it (:func:`~.compare.input_beside`), and the frame line's note."""
        with self.app.scene_lock:
            scene = self.app.scene
            image, name = scene.input, scene.input_names[scene.input_index] if scene.input_names else "input"
        drawn = input_beside(image, frame.image)
        height, width = frame.image.shape[:2]
        return replace(frame, image=drawn), (f", input beside ({name}, {image.shape[1]}×{image.shape[0]} → "
                                             f"{drawn.shape[1] - width - GAP}×{height} px)")

    def _show_scale(self, comparison: Optional[Comparison]) -> None:
        """The colour scale's numbers (both layouts) and its bar (the difference's) for ``comparison``, or neither."""
        self.scale.visible = comparison is not None
        bar = comparison is not None and comparison.layout == "difference"
        if bar and self.scale_bar is None:                 # beside the numbers (no hidden image on other pages)
            self.scale_bar = self.client.gui.add_image(colour_bar(), label="|A − B|, low to high", format="png",
                                                       order=self.scale.order + 0.5)
        if self.scale_bar is not None:
            self.scale_bar.visible = bar
        if comparison is not None:
            self.scale.content = comparison.line()

    def _show(self, frame: Frame, key: Tuple, aspect: float, quality: str, note: str = "") -> None:
        """Draw ``frame`` (rendered for ``key``; in compare mode frame B, drawn with A) and write its
        frame and settings lines."""
        if self.partner is not None:
            frame, pair_note = self._with_partner(frame)
            note = pair_note + note
        if self._beside():
            frame, beside_note = self._with_input(frame)
            note = beside_note + note
        view, renderer, _, res, _, _, window, _ = key
        # the frame is rendered at the canvas' aspect (scene.tiles): viser stretches it over the canvas as it is.
        # Full frames lossless (PNG, what the tests compare), the others as JPEG (a tenth of the encoding time)
        self.client.scene.set_background_image(frame.image, format="png" if quality == "full" else "jpeg",
                                               jpeg_quality=90)
        self.count += 1
        self.frame = frame
        if quality == "full":
            self.times[renderer] = frame.seconds
        az, el = (float(a) for a in to_angles(torch.tensor(view)))
        zoom, (cx, cy) = (1.0, (0.0, 0.0)) if window is None else (window.zoom, window.centre)
        height, width = frame.image.shape[:2]
        self.info.content = (f"frame {self.count}: {1000 * frame.seconds:.1f} ms, {quality}, {width}×{height} px, "
                             f"az {az:.1f}° el {el:.1f}°, zoom {zoom:.3f}×, centre ({cx:+.3f}, {cy:+.3f}){note}")
        self.settings.content = frame.settings + (" (the path tracer's preview while its passes render)"
                                                  if ", path tracer's preview" in note else "")

    # -- the path tracer: passes in the worker, each shown ------------------------------------------

    def _drop_trace(self, keep: bool = False) -> None:
        """Stop this page's path trace: its queued pass is dropped, the one in flight ignored when it
        comes back (``keep``: the trace stays, marked done, so that the same request is not traced again)."""
        trace = self.trace
        if trace is None:
            return
        self.app.worker.cancel(self)
        if keep:
            trace.failed = True
        else:
            self.trace = None

    def _trace(self, request: Tuple) -> None:
        """One step of this page's path trace for ``request``: while the camera moves, the closed form's
        preview; for a new request (a camera, a setting, a volume), the preview at once and pass 0 queued;
        for a pass come back, the running mean of the passes so far drawn and the next pass queued."""
        key, aspect, quality = request
        view, _, _, res, spp, version, window, _ = key
        n = self.app.scene.volume.shape[-1]
        preview = ((view, "closed form", "EA", n, spp, version, window, aspect), aspect, "moving")
        if quality == "moving":
            self._drop_trace()
            if preview != self.shown:
                self._render(preview, ", path tracer's preview (closed form)")
            return
        trace = self.trace
        if trace is None or trace.key != key:
            self._drop_trace()
            trace = self.trace = _Trace(key, aspect, passes_for(spp))
            if self.shown is None or self.shown[0][0] != view or self.shown[0][6] != window or \
                    self.shown[0][5] != version:
                self._render(preview, ", path tracer's preview (closed form)")   # a new camera: a frame now
        if trace.failed or trace.done == trace.passes:
            return
        if trace.future is None:
            with self.app.scene_lock:
                volume, version_now = self.app.scene.volume, self.app.version
            if version_now != version:
                return                                      # the next request has the new volume
            trace.future = self.app.worker.submit(self, volume, version, view, res, trace.done, window, aspect)
            trace.future.add_done_callback(lambda _: self.wake.set())
            return
        if not trace.future.done():
            return
        future, trace.future = trace.future, None
        if future.cancelled():
            return
        image, seconds = future.result()                    # a WorkerError: the loop shows it
        pass_image = torch.from_numpy(image)
        trace.total = pass_image if trace.total is None else trace.total + pass_image
        trace.done += 1
        trace.seconds += seconds
        plan = plan_frame(self.app.scene.volume, "path tracer", "EA", res, spp, window, aspect)
        frame = Frame(to_display(trace.total / trace.done), trace.seconds, plan.line, view, "path tracer", "EA",
                      plan.resolution, window_or_none(window))
        last = trace.done == trace.passes
        self._show(frame, key, aspect, "full" if last else "progressive",
                   f", pass {trace.done} of {trace.passes} ({trace.done * PASS_SPP} spp of {spp})")
        if last:
            self.shown = request
        else:
            self.wake.set()                                 # queue the next pass now

    # -- exports ----------------------------------------------------------------------------------

    def _export_png(self) -> None:
        if self.frame is None:
            self.exported.content = "no frame to save yet"
            return
        try:
            path = self.app.exports.png(self.frame, self.name.value)
        except (UserError, OSError) as e:
            self.exported.content = f"not saved: {e}"
            return
        self.exported.content = f"saved `{path}`"

    def _export_volume(self) -> None:
        with self.app.scene_lock:
            volume = self.app.scene.volume.clone()
        try:
            paths = self.app.exports.volume(volume, self.name.value)
        except (UserError, OSError) as e:
            self.exported.content = f"not saved: {e}"
            return
        self.exported.content = "saved " + ", ".join(f"`{p}`" for p in paths)

    # -- exports: a still at its size, a turntable; rendered in a thread of their own -----------------

    def _start_export(self, kind: str) -> None:
        """Start the ``kind`` ('still' or 'turntable') export of this page's view as it is now
        (:meth:`_export_job`) in a thread of its own, unless one runs; a request it refuses is one
        line on the page."""
        with self.export_lock:
            if self.export is not None and self.export.is_alive():
                self.exported.content = "an export is running: wait for it, or cancel it"
                return
            try:
                job = self._export_job(kind)
            except UserError as e:
                self.exported.content = f"not saved: {e}"
                return
            self.export_cancel = cancel = threading.Event()
            self.cancel_button.disabled = False
            self.export = threading.Thread(target=self._export, args=(job, cancel), name=f"export-{self.client.client_id}",
                                           daemon=True)
            self.export.start()

    def _export_job(self, kind: str) -> "_Export":
        """What an export renders: this page's full frame as it is now (camera, renderer or compare
        mode, formation, spp, canvas' aspect) of the volume shown now; a still at the still size
        (:func:`~.scene.checked_still`, every renderer of it checked to reach it), a turntable at the
        page's resolution from :func:`~.scene.turntable_views` (:func:`~.scene.checked_frames`)."""
        key, _, _ = self._request(at_rest=True)
        with self.app.scene_lock:
            volume, version = self.app.scene.volume, self.app.version
            beside = self.app.scene.input if self._beside() else None
        key = key[:5] + (version,) + key[6:]
        if kind == "turntable":
            return _Export(kind, self.name.value, volume, key, turntable_views(key[0], checked_frames(self.frames.value)),
                           beside)
        size = checked_still(self.still_size.value, volume.shape[-1])
        key = key[:3] + (size,) + key[4:]
        for k in compare_keys(key) if isinstance(key[1], tuple) else (key,):
            view, renderer, formation, _, spp, _, window, aspect = k
            reached = plan_frame(volume, renderer, formation, size, spp, window, aspect, MAX_STILL).resolution
            if reached != size:
                raise UserError(f"a still of {size} px: the {renderer} renders at most {reached} px here (it renders "
                                f"the volume resampled to R³); the marcher renders up to {MAX_STILL}: choose it, or a "
                                f"still size up to {reached}")
        return _Export(kind, self.name.value, volume, key, [key[0]], beside)

    def _export(self, job: "_Export", cancel: threading.Event) -> None:
        """Render ``job``'s frames one by one (each a render of its own: the pages' frames come
        between them), its progress on the page, stopped by ``cancel`` between frames and passes
        (nothing written then); then write them into the output folder (:class:`~.scene.Exports`)."""
        n, frames, start = len(job.views), [], time.monotonic()
        what = "still" if job.kind == "still" else f"turntable of {n} frames"
        try:
            for i, view in enumerate(job.views):
                progress = f"{what}: frame {i + 1} of {n}" if n > 1 else f"{what}: rendering"
                self.exported.content = progress + " … (cancel export stops it)"
                frame = self._export_frame(job, (view,) + job.key[1:], cancel, progress)
                if job.input is not None:                  # the input beside the frame, as the page draws it
                    frame = replace(frame, image=input_beside(job.input, frame.image))
                frames.append(frame)
            if cancel.is_set():
                raise _Cancelled
            if job.kind == "still":
                paths = [self.app.exports.png(frames[0], job.name)]
            else:
                paths = self.app.exports.turntable([f.image for f in frames], job.name)
            height, width = frames[0].image.shape[:2]
            self.exported.content = (f"saved " + ", ".join(f"`{p}`" for p in paths) + f": {what}, {width}×{height} px, "
                                     f"{time.monotonic() - start:.1f} s; {frames[0].settings}")
        except _Cancelled:
            self.exported.content = f"{what}: cancelled after {len(frames)} of {n} frames; nothing written"
        except (UserError, OSError, WorkerError) as e:
            self.exported.content = f"not saved: {e}"
        except Exception as e:                              # the page stays up; the error shows there
            self.exported.content = f"not saved: {type(e).__name__}: {e}"
        finally:
            self.app.worker.cancel(job)
            self.cancel_button.disabled = True

    def _export_frame(self, job: "_Export", key: Tuple, cancel: threading.Event, progress: str) -> Frame:
        """An export's frame of ``key``: rendered here (:meth:`ViewerApp.render_export`), the path
        tracer's pass by pass in the worker (the mean of the passes: :func:`~.scene.render_frame`'s
        frame), a comparison's two frames drawn in its layout (:func:`~.compare.compare`)."""
        if cancel.is_set():
            raise _Cancelled
        view, renderer, _, res, spp, version, window, aspect = key
        if isinstance(renderer, tuple):
            a, b = (self._export_frame(job, k, cancel, progress) for k in compare_keys(key))
            return Frame(compare(a.image, b.image, renderer[2]).image, a.seconds + b.seconds,
                         f"A: {a.settings} | B: {b.settings}", a.view, renderer[1], a.formation, a.resolution, a.window)
        if renderer != "path tracer":
            return self.app.render_export(job.volume, key)
        plan = plan_frame(job.volume, "path tracer", "EA", res, spp, window, aspect)
        total, seconds, passes = None, 0.0, passes_for(spp)
        for i in range(passes):
            self.exported.content = f"{progress}, path tracer pass {i + 1} of {passes} … (cancel export stops it)"
            future = self.app.worker.submit(job, job.volume, version, view, res, i, window, aspect)
            while True:
                try:
                    image, took = future.result(timeout=0.2)
                    break
                except FutureTimeout:
                    if cancel.is_set():
                        raise _Cancelled from None
                except CancelledError:                      # the worker stopped (the server stops)
                    raise _Cancelled from None
            total = torch.from_numpy(image) if total is None else total + torch.from_numpy(image)
            seconds += took
        return Frame(to_display(total / passes), seconds, plan.line, view, "path tracer", "EA", plan.resolution,
                     window_or_none(window))

    def threads(self) -> list:
        """This page's threads that may still be rendering: its frames', its export's."""
        return [self.thread] + ([self.export] if self.export is not None else [])

    def busy(self) -> bool:
        return any(t.is_alive() for t in self.threads())

    def stop(self) -> None:
        self.stopped = True
        self._drop_trace()
        self.export_cancel.set()
        self.wake.set()


class _Cancelled(Exception):
    """An export stopped by its page (the cancel button, the page closed, the server stopping)."""


class _Export:
    """An export in progress: its ``kind`` ('still', 'turntable'), file ``name``, the ``volume`` shown
    when it started, the ``key`` of its first frame (:meth:`ClientView._request`'s), its ``views`` and
    the ``input`` drawn beside each frame (None: none). Its identity is its slot in the path tracer's worker."""

    def __init__(self, kind: str, name: str, volume: torch.Tensor, key: Tuple, views: List,
                 input: Optional[np.ndarray] = None):
        self.kind, self.name, self.volume, self.key, self.views = kind, name, volume, key, views
        self.input = input


class _Trace:
    """A page's path trace in progress: its request's ``key`` and canvas ``aspect``, ``passes`` in all,
    ``done`` so far (their sum ``total`` and ``seconds``), the ``future`` of the pass in flight."""

    def __init__(self, key: Tuple, aspect: float, passes: int):
        self.key, self.aspect, self.passes = key, aspect, passes
        self.done, self.total, self.seconds = 0, None, 0.0
        self.future = None
        self.failed = False
