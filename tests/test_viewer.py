"""``platonic view``: the viewer's frames, sources and exports, and the page itself in a real browser.

The browser tests start ``platonic view`` on a 16³ test volume in a subprocess and drive Debian's
headless Chromium with playwright (its own browser downloads are never used: ``executable_path``).
The set-up installs Chromium with ``apt-get install -y chromium`` where it is missing; the browser
tests skip, saying why, only where it cannot be installed (no apt-get, not root, no package). Every
wait is bounded (:data:`WAIT_MS`); the server is stopped with SIGINT (Ctrl-C: it ends by the signal, 130 to a shell) at the end.

Tolerance of the screenshot against the closed form: the page draws the W×H frame (the canvas'
aspect, R its shorter side) stretched over the canvas by WebGL; the screenshot is read at the
centres of the pixels of its central R×R square (the square frame), where the drawn texture takes its pixel's value, and must match the
closed form's 8-bit sRGB frame within :data:`TOLERANCE` levels on average and
:data:`TOLERANCE_MAX` at 95 % of the pixels (measured with software WebGL: identical); the same
comparison against the view 30° away must fail by far, so the check sees which view is shown.

Zoom and pan (the orthographic camera's window, mitsuba_platonic/render/window.py): the page's
buttons and viser's own wheel and right-drag move the browser's camera; each frame must be the
renderer's frame through the window the page prints (the same tolerance), and on a ball of radius
0.2 the silhouette (pixels brighter than halfway from the background to the ball) must scale by
the zoom m (√ of its area, within :data:`SCALE_TOLERANCE`) and its centroid move by
(+c_y, −c_x) m R/2 pixels (rows, columns) for a window centre (c_x, c_y), within
:data:`SHIFT_TOLERANCE` pixels; after a right-drag, as many canvas pixels as the mouse travelled
(the ball stays under the mouse), within :data:`DRAG_TOLERANCE`. Without a browser,
camera_window's frame is checked against viser's perspective projection point by point.
"""

from __future__ import annotations

import io
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Optional

import numpy as np
import pytest
import torch

from cli_runner import one_line, run_cli
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.views import from_angles
from mitsuba_platonic.volume import test_volume
from mitsuba_platonic.files.volume_io import read_vol, read_volume_file, write_vol
from tiny_shapes import TINY

viser = pytest.importorskip("viser", reason="the 'viewer' extra is not installed (pip install -e '.[viewer]')")

from mitsuba_platonic.viewer.scene import (DEFAULT_RESOLUTION, Exports, clean_name, open_source,  # noqa: E402
                                           render_frame, resolutions_for, to_display)

ROOT = Path(__file__).resolve().parents[1]
N = 16
WAIT_MS = 30_000                      # one wait for the page (the marcher's first frame traces its kernel)
TOLERANCE = 1.0                       # mean |Δ| in 8-bit sRGB levels (measured: 0, the same pixels)
TOLERANCE_MAX = 3.0                   # at the 95th percentile
#: A frame line; group 4 is the frame's height, its resolution R on the tests' canvases (wider than tall).
FRAME = re.compile(r"frame (\d+): ([0-9.]+) ms, (full|moving|progressive), \d+×(\d+) px, az (-?[0-9.]+)° el (-?[0-9.]+)°")
SIZE = re.compile(r"(\d+)×(\d+) px")
WINDOW = re.compile(r"zoom ([0-9.]+)×, centre \(([-+][0-9.]+), ([-+][0-9.]+)\)")
#: √(silhouette area ratio) / zoom − 1: measured 1.1 % (2× by the button) and 0.8 % (1.36× by the
#: wheel): the silhouette's whole pixels; allowed 4 %.
SCALE_TOLERANCE = 0.04
#: Silhouette centroid against the expected shift, pixels of a 64² frame: measured 0 (the buttons'
#: whole-pixel pans) and 0.07 (a right-drag's); allowed 0.6.
SHIFT_TOLERANCE = 0.6
#: The ball's move on the canvas against the mouse's travel in a right-drag, as a fraction of the
#: travel (60 pixels left, 40 down): measured 0.8 % (0.5 pixel); allowed 5 %.
DRAG_TOLERANCE = 0.05


def closed_form(volume: torch.Tensor, azimuth: float, elevation: float, resolution: Optional[int] = None) -> np.ndarray:
    return closed_form_at(volume, azimuth, elevation, resolution)


def closed_form_at(volume: torch.Tensor, azimuth: float, elevation: float, resolution: Optional[int] = None,
                   aspect: float = 1.0) -> np.ndarray:
    """The closed form's EA frame at (azimuth, elevation) on a canvas of ``aspect``."""
    return render_frame(volume, tuple(from_angles(azimuth, elevation).tolist()), "closed form", "EA", resolution,
                        aspect=aspect).image


# --------------------------------------------------------------------------- without a browser


def test_a_vol_file_reads_back_what_write_vol_wrote(tmp_path):
    v = test_volume(8, "figure", "ea")[0]
    path = write_vol(v, tmp_path / "v.vol")
    assert torch.equal(read_vol(path)[0], v)
    assert torch.equal(read_volume_file(path)[0], v)
    path.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(ValueError, match="truncated or damaged"):
        read_vol(path)


def test_the_marchers_finer_frames_are_its_sub_pixel_rays():
    """At R = kN the marcher's frame is its k×k sub-pixel rays kept apart: averaged over k×k blocks,
    the marcher's own render with spp = k² (the same rays, averaged in the renderer)."""
    from mitsuba_platonic.render import render
    from mitsuba_platonic.render.drjit.marcher import march_pixels
    from mitsuba_platonic.render.settings import RenderSettings

    v = test_volume(N, "figure", "ea")
    w = from_angles(30.0, 20.0)[None]
    settings = RenderSettings.for_call("mitsuba", "ea")
    assert torch.equal(march_pixels(v, w, settings, 1), render(v, w, "ea", "mitsuba"))
    fine = march_pixels(v, w, settings, 4)
    assert fine.shape == (1, 4, 4 * N, 4 * N)
    torch.testing.assert_close(torch.nn.functional.avg_pool2d(fine, 4), render(v, w, "ea", "mitsuba", spp=16),
                               atol=1e-5, rtol=0)
    frame = render_frame(v[0], tuple(w[0].tolist()), "marcher", "EA", 4 * N)
    assert frame.image.shape == (4 * N, 4 * N, 3)
    np.testing.assert_array_equal(frame.image, to_display(fine[0]))


def test_a_finer_frame_keeps_the_volumes_opacity_in_every_renderer():
    """At R = kN the closed form and the lit renderers render the volume resampled to (kN)³, whose
    density is made that of one fine step (viewer.scene._at_resolution): a constant volume of a
    (0, 0.3 and 1, the exact ends) is as opaque through its k·N planes as through its N, the
    closed form's front view α = 1 − (1 − a)^N (AO, EA) and 1 − exp(−N v) (VH) at every k, and the lit
    renderers' extinction σ = −ln(1 − a) / Δ per unit length is the volume's own; on the 16³ figure
    the closed form's 128² frame is the marcher's within a level on average (12.3 levels apart, 93 at
    most, when each fine plane held a whole voxel's opacity)."""
    from mitsuba_platonic.render.grids import extinction
    from mitsuba_platonic.viewer.scene import _at_resolution

    n = 8
    for a in (0.0, 0.3, 1.0):
        v = torch.full((4, n, n, n), a)
        v[:3] = 0.5
        for formation in ("EA", "AO", "VH"):
            coarse = render_frame(v, (0.0, 0.0, 1.0), "closed form", formation, n).image.astype(int)
            assert (coarse == coarse[0, 0]).all()                 # one colour: α = 1 − (1 − a)^N, 1 − e^(−N a)
            for k in (2, 4):
                image = render_frame(v, (0.0, 0.0, 1.0), "closed form", formation, k * n).image.astype(int)
                assert image.shape == (k * n, k * n, 3)
                assert np.abs(image - coarse[0, 0]).max() <= 1, (formation, a, k, image[0, 0], coarse[0, 0])
        for k in (2, 4) if a < 1 else ():                    # at 1 the lit renderers' cap (σ Δ ≤ ln 1000) is per grid
            fine = _at_resolution(v, k * n, "ea")[0, 3]
            torch.testing.assert_close(extinction(fine), extinction(v[3]).mean().expand_as(fine), rtol=1e-5, atol=0)
    torch.testing.assert_close(_at_resolution(torch.full((1, n, n, n), 1.0), 4 * n, "ao")[0, 0],
                               torch.ones(4 * n, 4 * n, 4 * n), rtol=0, atol=0)    # an opaque voxel stays opaque
    figure = test_volume(N, "figure", "ea")[0]
    w = tuple(from_angles(30.0, 20.0).tolist())
    closed = render_frame(figure, w, "closed form", "EA", 8 * N).image.astype(float)
    marched = render_frame(figure, w, "marcher", "EA", 8 * N).image.astype(float)
    assert np.abs(closed - marched).mean() < 1.0, np.abs(closed - marched).mean()


#: The viewer's field of view (mitsuba_platonic.viewer.app.FOV): zoom 1 at distance 4.
FOV = 2.0 * math.atan(1.0 / 4.0)


def test_the_camera_gives_the_window_zoom_by_distance_pan_by_look_at():
    """camera_window: m = clamp(1 / (d tan(F/2) min(1, aspect)), ¼, 8), centre = look_at's coordinates
    along the view's (right, up); the initial camera (and float32 echoes of it) has none; bad input
    is a ValueError."""
    from mitsuba_platonic.viewer.scene import ZOOM_RANGE, Window, camera_window, zoom_distance

    assert camera_window((0, 0, 4), (0, 0, 0), FOV) is None
    assert camera_window(np.float32([0, 0, 4.0000005]), np.float32([1e-7, 0, 0]), FOV, 16 / 9) is None
    assert np.isclose(camera_window((0, 0, 2), (0, 0, 0), FOV).zoom, 2.0)
    assert np.isclose(camera_window((0, 0, 4), (0, 0, 0), FOV, 0.5).zoom, 2.0)     # portrait: the canvas' width
    assert np.isclose(camera_window((0, 0, 0.5), (0, 0, 0), math.radians(90.0)).zoom, 2.0)     # tan 45° = 1
    assert camera_window((0, 0, 100), (0, 0, 0), FOV) == Window(ZOOM_RANGE[0])
    assert camera_window((0, 0, 0.01), (0, 0, 0), FOV) == Window(ZOOM_RANGE[1])
    assert np.isclose(zoom_distance(2.0, FOV), 2.0) and np.isclose(zoom_distance(1.0, FOV, 0.5), 8.0)
    win = camera_window((0.5, 0.25, 4.0), (0.5, 0.25, 0.0), FOV)           # the front view panned: right +x, up +y
    assert win == Window(1.0, (0.5, 0.25))
    w = from_angles(90.0, 0.0).double().numpy()                          # from +x: right = −z, up = +y
    win = camera_window(np.array([0.0, 0.3, 0.2]) + 2.0 * w, (0.0, 0.3, 0.2), FOV)
    assert np.isclose(win.zoom, 2.0) and np.allclose(win.centre, (-0.2, 0.3))
    for position, look, fov, aspect, message in (((0, 0, 1), (0, 0, 1), FOV, 1.0, "look-at point"),
                                                 ((0, np.nan, 1), (0, 0, 0), FOV, 1.0, "finite"),
                                                 ((0, 0, 4), (0, 0, 0), 0.0, 1.0, "fov"),
                                                 ((0, 0, 4), (0, 0, 0), math.pi, 1.0, "fov"),
                                                 ((0, 0, 4), (0, 0, 0), float("nan"), 1.0, "fov"),
                                                 ((0, 0, 4), (0, 0, 0), FOV, 0.0, "aspect"),
                                                 ((0, 0, 4), (0, 0, 0), FOV, float("inf"), "aspect")):
        with pytest.raises(ValueError, match=message):
            camera_window(position, look, fov, aspect)


def _viser_pixel(point, position, look_at, fov: float, height: float) -> np.ndarray:
    """Where viser's perspective camera draws a world point: canvas pixels (right, down) from the
    canvas' centre. three.js: the camera looks from ``position`` at ``look_at`` with up +y (its x
    axis up × z, z from the target to the eye), vertical field of view ``fov`` over ``height`` pixels."""
    z = np.subtract(position, look_at)
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    rel = np.subtract(point, position)
    focal = height / (2.0 * math.tan(fov / 2.0))
    return focal * np.array([rel @ x, -(rel @ y)]) / -(rel @ z)


def _page_pixel(point, position, look_at, fov: float, width: float, height: float) -> np.ndarray:
    """Where the page draws it: the frame of camera_window's window (its image coordinates, window.py)
    as the centred square the canvas' shorter side wide; canvas pixels (right, down) from the centre."""
    from mitsuba_platonic.viewer.scene import Window, camera_window
    from mitsuba_platonic.views import camera_frames

    window = camera_window(position, look_at, fov, width / height) or Window()
    w = np.subtract(position, look_at)
    right, up, _ = (f[0].numpy() for f in camera_frames(torch.from_numpy(w / np.linalg.norm(w))[None]))
    x, y = window.image_point((float(np.dot(point, right)), float(np.dot(point, up))))
    return np.array([x, -y]) * min(width, height) / 2.0


@pytest.mark.parametrize("width, height", [(1400, 600), (600, 900)])
def test_a_point_at_the_look_at_distance_sits_where_the_browsers_camera_draws_it(width, height):
    """The frame's scale is viser's perspective scale at the look-at point, 2 d tan(F/2) world units
    over the canvas' height: a point on the plane through the look-at point, facing the camera, is
    drawn at the canvas pixel where the browser's camera projects it, for any view, look-at point,
    distance and canvas. So panning by Δ world units (camera and look-at moved together, what
    viser's right-drag does for a mouse travel of Δ H / (2 d tan(F/2)) pixels) moves it by that
    many pixels, as the mouse, and zooming (the distance) scales it about the look-at point as the
    browser's camera does."""
    rng = np.random.default_rng(0)
    for az, el, d, fov in ((0.0, 0.0, 4.0, FOV), (40.0, 25.0, 1.7, FOV), (-120.0, -60.0, 9.0, FOV),
                           (200.0, 10.0, 1.2, math.radians(75.0))):
        w = from_angles(az, el).double().numpy()
        x = np.cross([0.0, 1.0, 0.0], w)
        x = x / np.linalg.norm(x)
        y = np.cross(w, x)
        look = rng.uniform(-0.5, 0.5, 3)
        world_per_pixel = 2.0 * d * math.tan(fov / 2.0) / height
        for delta in (np.zeros(2), np.array([0.3, -0.2])):             # a pan of Δ along (right, up)
            at = look + delta[0] * x + delta[1] * y
            position = at + d * w
            for s, t in rng.uniform(-0.8, 0.8, (5, 2)):
                point = look + s * x + t * y                            # on the look-at plane, fixed on the object
                seen = _viser_pixel(point, position, at, fov, height)
                drawn = _page_pixel(point, position, at, fov, width, height)
                np.testing.assert_allclose(drawn, seen, atol=1e-6)
                unpanned = _page_pixel(point, look + d * w, look, fov, width, height)
                np.testing.assert_allclose(drawn - unpanned, -delta * [1, -1] / world_per_pixel, atol=1e-6)


def test_a_windowed_frame_is_the_renderers_frame_through_the_window():
    """render_frame passes the window to every renderer (and the marcher's finer frames), says so in
    its settings line, and without one (or with the full one) is the frame it was."""
    from mitsuba_platonic.render import RenderSettings, render_with
    from mitsuba_platonic.render.drjit.marcher import march_pixels
    from mitsuba_platonic.viewer.scene import Window

    v = test_volume(N, "figure", "ea")[0]
    w = from_angles(30.0, 20.0)
    window = Window(2.0, (0.1, -0.2))
    for renderer, backend in (("closed form", "closed_form"), ("marcher", "mitsuba"),
                              ("single scattering", "scatter_march")):
        frame = render_frame(v, tuple(w.tolist()), renderer, "EA", window=window)
        assert frame.window == window and "zoom 2×, centre (+0.100, -0.200)" in frame.settings
        settings = RenderSettings.for_call(backend, "ea")
        np.testing.assert_array_equal(frame.image, to_display(render_with(v[None], w[None], settings, 0, window)[0]))
        whole = render_frame(v, tuple(w.tolist()), renderer, "EA", window=Window())
        assert whole.window is None and "zoom" not in whole.settings
        np.testing.assert_array_equal(whole.image, render_frame(v, tuple(w.tolist()), renderer, "EA").image)
        assert not np.array_equal(frame.image, whole.image)
    fine = render_frame(v, tuple(w.tolist()), "marcher", "EA", 2 * N, window=window)
    np.testing.assert_array_equal(fine.image, to_display(march_pixels(v[None], w[None], RenderSettings.for_call(
        "mitsuba", "ea"), 2, window)[0]))


def test_a_frame_at_the_canvas_aspect_is_the_square_frame_widened_not_stretched():
    """On a canvas of width/height a the frame is W×H (R the shorter side, W − R even): its central
    R×R square is the square frame, bit for bit, and the columns beyond it are the renderer's own
    frame of the window moved sideways by whole pixels (more of the scene, at the same scale),
    for every renderer; the settings line names W×H, as the page's frame line does."""
    from mitsuba_platonic.viewer.scene import Window, frame_size, tiles

    assert frame_size(128, 636 / 540) == (150, 128) and frame_size(16, 16 / 9) == (28, 16)
    assert frame_size(64, 0.5) == (64, 128) and frame_size(64, 1.0) == (64, 64)
    assert frame_size(16, 100.0) == frame_size(16, 4.0) == (64, 16)          # held to ASPECT_RANGE
    assert tiles(64, 1.0, None)[0].window is None and len(tiles(64, 1.0, None)) == 1
    v = test_volume(N, "figure", "ea")[0]
    w = tuple(from_angles(30.0, 20.0).tolist())
    window = Window(2.0, (0.1, -0.2))
    for renderer, r in (("closed form", 2 * N), ("marcher", 2 * N), ("single scattering", N)):
        square = render_frame(v, w, renderer, "EA", r, window=window)
        wide = render_frame(v, w, renderer, "EA", r, window=window, aspect=16 / 9)
        width, height = frame_size(r, 16 / 9)
        assert wide.image.shape == (height, width, 3) and f"{width}×{height} px" in wide.settings
        x0 = (width - r) // 2
        np.testing.assert_array_equal(wide.image[:, x0:x0 + r], square.image)
        shift = x0 * 2.0 / (window.zoom * r)                              # the left edge: x0 pixels further left
        left = render_frame(v, w, renderer, "EA", r, window=Window(2.0, (0.1 - shift, -0.2))).image
        np.testing.assert_array_equal(wide.image[:, :r], left)
        assert not np.array_equal(wide.image[:, :r], square.image)
        tall = render_frame(v, w, renderer, "EA", r, window=window, aspect=0.6)
        width, height = frame_size(r, 0.6)
        y0 = (height - r) // 2
        assert tall.image.shape == (height, width, 3)
        np.testing.assert_array_equal(tall.image[y0:y0 + r], square.image)


def test_the_path_workers_passes_average_to_the_path_tracers_frame():
    """The worker process's passes (1 spp each, samples of seed 0, 1, 2 under the sky of seed 0),
    summed in order and divided by their count, are render_frame's path-traced frame of 3 spp bit for
    bit; the passes differ from each other (other samples); a page's new pass supersedes its queued
    one, and cancel drops it (their futures cancelled, never run)."""
    from mitsuba_platonic.viewer.scene import PASS_SPP, passes_for
    from mitsuba_platonic.viewer.worker import PathWorker

    v = test_volume(N, "figure", "ea")[0]
    frame = render_frame(v, (0.0, 0.0, 1.0), "path tracer", "EA", N, spp=3)
    assert PASS_SPP == 1 and passes_for(3) == 3 and "spp 3 in passes of 1" in frame.settings
    worker = PathWorker()
    try:
        passes = [torch.from_numpy(worker.submit("page", v, 0, (0.0, 0.0, 1.0), N, i, None).result(timeout=600)[0])
                  for i in range(3)]
        total = passes[0] + passes[1] + passes[2]
        np.testing.assert_array_equal(to_display(total / 3), frame.image)
        assert not torch.equal(passes[0], passes[1])
        worker._cond.acquire()                          # hold the dispatcher: the slots stay queued
        try:
            first = worker.submit("a", v, 0, (0.0, 0.0, 1.0), N, 0, None)
            second = worker.submit("a", v, 0, (0.0, 0.0, 1.0), N, 1, None)
            third = worker.submit("b", v, 0, (0.0, 0.0, 1.0), N, 0, None)
            worker.cancel("b")
        finally:
            worker._cond.release()
        assert first.cancelled() and third.cancelled()
        assert second.result(timeout=600)[0].shape == (4, N, N)
    finally:
        worker.stop()


def test_frames_follow_the_formation_and_the_volume_channels():
    v = test_volume(N, "figure", "ea")[0]
    assert resolutions_for(N) == [16, 32, 64, 128]
    vh = render_frame(v, (0.0, 0.0, 1.0), "closed form", "VH")
    assert vh.image.shape == (N, N, 3) and (vh.image[..., 0] == vh.image[..., 1]).all()      # grey
    density = v[3:]
    with pytest.raises(ValueError, match="no colour"):
        render_frame(density, (0.0, 0.0, 1.0), "closed form", "EA")
    with pytest.raises(ValueError, match="multiple of the volume"):
        render_frame(v, (0.0, 0.0, 1.0), "closed form", "EA", 24)
    capped = render_frame(v, (0.0, 0.0, 1.0), "closed form", "EA", 256)
    assert capped.image.shape == (128, 128, 3) and "at most 128" in capped.settings


def test_exports_stay_inside_the_output_folder(tmp_path):
    out = tmp_path / "exports"
    ex = Exports(out)
    frame = render_frame(test_volume(8, "figure", "ea")[0], (0.0, 0.0, 1.0))
    paths = [ex.png(frame, name) for name in ("../../escape", "/etc/passwd", "a/../../b", "..", "", "view")]
    for p in paths:
        assert p.resolve().parent == out.resolve() and p.suffix == ".png" and p.exists()
    assert [p.name for p in paths] == ["escape.png", "etc_passwd.png", "a_______b.png", "view.png", "view_2.png",
                                       "view_3.png"]
    assert clean_name("x" * 100) == "x" * 64
    assert clean_name("Stühle/木 ñ") == "Stühle_木_ñ"                       # readable in any script, never a path
    vol = ex.volume(test_volume(8, "figure", "ea")[0], "../shape")
    assert sorted(p.name for p in vol) == ["shape.npz", "shape.ply", "shape.vol"]
    assert not (tmp_path / "shape.npz").exists()
    assert torch.equal(read_volume_file(out / "shape.vol")[0], test_volume(8, "figure", "ea")[0])


def test_an_export_into_a_folder_another_command_holds_writes_nothing(tmp_path):
    """Each export holds --out's lock while it picks its name and writes: where another command (or a
    second viewer) holds it, one line naming the holder and nothing written; free again, it exports."""
    import os

    from mitsuba_platonic.files.outputs import LOCK, output_lock

    out = tmp_path / "exports"
    ex = Exports(out)
    frame = render_frame(test_volume(8, "figure", "ea")[0], (0.0, 0.0, 1.0))
    with output_lock(out, "view"):
        with pytest.raises(UserError, match=rf"--out {out} is in use by another command \(pid {os.getpid()}, "
                                            r"platonic view; lock .*\); nothing was written"):
            ex.png(frame, "held")
        with pytest.raises(UserError, match="is in use by another command"):
            ex.volume(test_volume(8, "figure", "ea")[0], "held")
        assert sorted(p.name for p in out.iterdir()) == [LOCK]
    assert ex.png(frame, "held").name == "held.png" and sorted(p.name for p in out.iterdir()) == ["held.png"]


def test_an_export_through_a_link_in_the_folder_is_refused(tmp_path):
    out = tmp_path / "exports"
    out.mkdir()
    (tmp_path / "elsewhere").mkdir()
    (out / "sub").symlink_to(tmp_path / "elsewhere")
    (out / "platonic.lock").symlink_to(tmp_path / "elsewhere" / "victim")
    frame = render_frame(test_volume(8, "figure", "ea")[0], (0.0, 0.0, 1.0))
    with pytest.raises(UserError, match="is a symbolic link"):
        Exports(out).png(frame, "view")
    assert list((tmp_path / "elsewhere").iterdir()) == []


def test_nothing_outside_the_viewer_imports_the_web_library():
    """Import the package and every module outside mitsuba_platonic.viewer (and the command line,
    which imports the viewer only in its handler): viser stays unloaded."""
    code = (
        "import pkgutil, importlib, sys\n"
        "import mitsuba_platonic\n"
        "names = [m.name for m in pkgutil.walk_packages(mitsuba_platonic.__path__, 'mitsuba_platonic.')\n"
        "         if not m.name.startswith('mitsuba_platonic.viewer.') and not m.name.endswith('__main__')]\n"
        "for name in names:\n"
        "    importlib.import_module(name)\n"
        "import mitsuba_platonic.viewer\n"
        "from mitsuba_platonic.cli import build_parser\n"
        "build_parser().parse_args(['view', 'x.npz'])\n"
        "print(len(names), 'viser' in sys.modules)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    count, loaded = result.stdout.split()
    assert int(count) > 50 and loaded == "False", result.stdout


# --------------------------------------------------------------------------- bad input: one line, exit 2


@pytest.fixture(scope="module")
def volume_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("volume") / "figure.npz"
    np.savez(path, volume=test_volume(N, "figure", "ea")[0].numpy())
    return path


def test_a_missing_or_damaged_source_is_one_line(tmp_path):
    (tmp_path / "bad.npz").write_bytes(b"not an archive")
    (tmp_path / "bad.vol").write_bytes(b"VOL\x03" + b"\x00" * 10)
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "empty_run").mkdir()
    for source, message in ((tmp_path / "missing.npz", "does not exist"), (tmp_path / "bad.npz", "not a valid .npz"),
                            (tmp_path / "bad.vol", "not a Mitsuba .vol"), (tmp_path / "notes.txt", ".npz or .vol"),
                            (tmp_path / "empty_run", "checkpoint")):
        code, out, err = run_cli(["view", str(source), "--port", "0"])
        assert code == 2, (source, err)
        assert message in one_line(err, "view", "error"), err


def test_a_busy_port_names_the_flag(volume_file):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        code, out, err = run_cli(["view", str(volume_file), "--port", str(port)])
    assert code == 2
    assert f"--port {port}" in one_line(err, "view", "error") and "choose another --port" in err


@pytest.mark.parametrize("host, says", [("999.1.1.1", "resolves"), ("no-such-host.invalid", "resolves"),
                                        ("192.0.2.1", "not an address of this machine")])
def test_a_host_that_is_not_this_machines_is_one_line_at_once(volume_file, tmp_path, host, says):
    """``--host`` resolved and bound before anything else, also with ``--port 0``: an address that
    cannot be resolved, or one of another machine (192.0.2.1: TEST-NET-1), was 90 s of silence."""
    done = subprocess.run([sys.executable, "-m", "mitsuba_platonic.cli", "view", str(volume_file), "--host", host,
                           "--port", "0"], capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
                          cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    err = one_line(done.stderr, "view", "error")
    assert err.startswith(f"platonic view: error: --host {host}: ") and says in err, err


#: ``platonic view`` with stdout probed: as the address line is written, whether torch has loaded.
_PROBE = """
import sys
from mitsuba_platonic.console import main

class Probe:
    def __init__(self, stream):
        self.stream = stream
    def write(self, text):
        if " at http://" in text:
            self.stream.write(f"torch loaded: {'torch' in sys.modules}\\n")
        return self.stream.write(text)
    def __getattr__(self, name):
        return getattr(self.stream, name)

sys.stdout = Probe(sys.stdout)
main(sys.argv[1:])
"""


def test_a_volume_files_address_comes_before_torch_and_ctrl_c_then_is_one_line(volume_file, tmp_path):
    """For a volume file the address is printed before torch is imported (the browser loads the page
    while torch and the scene load: the command line parses ``view`` alone, SOURCE is read with
    numpy); a Ctrl-C right after it, while the scene loads, ends the process by SIGINT with one line."""
    proc = subprocess.Popen([sys.executable, "-c", _PROBE, "view", str(volume_file), "--port", "0"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        probe, address = proc.stdout.readline(), proc.stdout.readline()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
    assert probe == "torch loaded: False\n" and "at http://127.0.0.1:" in address, (probe, address, err)
    assert proc.returncode == -signal.SIGINT, err
    assert one_line(err, "view", "interrupted") and "Traceback" not in err, err


def test_a_page_connected_before_the_scene_gets_its_first_frame(volume_file, tmp_path, monkeypatch):
    """The server starts before the scene is made (start_server); a page connected to it then is
    given its GUI and first frame once ViewerApp takes the server: viser calls the connect handler
    for the pages connected already (here one stands in viser's table of connected pages), and
    the warm-up renders the first frame as the app starts."""
    from mitsuba_platonic.viewer import app as A
    from mitsuba_platonic.viewer.start import start_server, stop_server

    connected = []
    monkeypatch.setattr(A.ViewerApp, "_connect", lambda self, client: connected.append(client))
    server = start_server(port=0)
    early = object()                                       # a page that connected while the scene loaded
    server._connected_clients[-1] = early
    app = None
    try:
        app = A.ViewerApp(open_source(volume_file), tmp_path / "exports", port=0, server=server)
        deadline = time.monotonic() + 30
        while not connected and time.monotonic() < deadline:
            time.sleep(0.02)
        assert connected == [early]
        app.warming.join(timeout=300)
        assert app.last is not None and app.last[0] == A.first_look_key(app.scene)
    finally:
        server._connected_clients.pop(-1, None)
        app.stop() if app is not None else stop_server(server)


@pytest.fixture(scope="module")
def runs(tmp_path_factory, tiny_class):
    """A reconstruction run and a generation run of one training step each, 16³."""
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.train import run as R

    tmp = tmp_path_factory.mktemp("runs")
    made = {}
    for task in ("reconstruction", "generation"):
        cfg = load_config(None, [
            f"run.out_dir={tmp}/runs", f"run.name={task}", "run.steps=1", "run.sample_every=1000",
            "run.checkpoint_every=1000", f"data.cache={tmp}/data", f"data.shape_class={TINY}", "data.n_shapes=4",
            "data.views_per_shape=2", "data.split=0.5", f"model.resolution={N}", "model.width=4", "model.latent=8",
            "model.norm=batch", "train.batch_size=2", f"train.task={task}"])
        made[task] = R.train(cfg, progress=False)
    return made


def test_a_photo_for_a_generation_run_is_one_line(runs, tmp_path):
    from PIL import Image
    photo = tmp_path / "photo.png"
    Image.new("RGBA", (N, N), (200, 100, 50, 255)).save(photo)
    code, out, err = run_cli(["view", str(runs["generation"]), "--photo", str(photo), "--port", "0"])
    assert code == 2 and "generation run" in one_line(err, "view", "error") and "--photo" in err
    code, out, err = run_cli(["view", str(runs["reconstruction"]), "--background", "white", "--port", "0"])
    assert code == 2 and "--background masks the --photo" in one_line(err, "view", "error")


def test_run_sources_step_through_inputs_and_latents(runs, tmp_path, monkeypatch):
    monkeypatch.chdir(runs["reconstruction"].parent.parent.parent)   # data.cache is relative to where training ran
    rec = open_source(runs["reconstruction"])
    assert rec.kind == "reconstruction" and rec.inputs is not None and len(rec.inputs) >= 2
    first = rec.volume.clone()
    assert rec.input.shape == (N, N, 3) and first.shape == (4, N, N, N)
    rec.show_input(1)
    assert rec.input_index == 1 and not torch.equal(rec.volume, first)
    from PIL import Image
    photo = tmp_path / "photo.png"
    Image.new("RGBA", (N, N), (200, 100, 50, 255)).save(photo)
    image = np.zeros((N, N, 4), np.uint8)
    image[4:12, 4:12] = (200, 100, 50, 255)
    Image.fromarray(image).save(photo)
    with_photo = open_source(runs["reconstruction"], photo)
    assert with_photo.input.shape == (N, N, 3) and with_photo.input_names == ["photo.png"]
    on_white = np.full((N, N, 3), 255, np.uint8)         # an RGB photo on white (the quickstart's inputs)
    on_white[4:12, 4:12] = (200, 100, 50)
    Image.fromarray(on_white).save(tmp_path / "white.png")
    with pytest.raises(UserError, match="no alpha channel"):
        open_source(runs["reconstruction"], tmp_path / "white.png")
    masked = open_source(runs["reconstruction"], tmp_path / "white.png", background="white")
    # the same object, masked on white (its edge softened by the loader): the same background and inside
    np.testing.assert_array_equal(masked.input[:3], with_photo.input[:3])
    np.testing.assert_array_equal(masked.input[6:10, 6:10], with_photo.input[6:10, 6:10])

    gen = open_source(runs["generation"])
    assert gen.kind == "generation"
    from mitsuba_platonic.model import Model
    model = Model.from_checkpoint(runs["generation"])
    torch.testing.assert_close(gen.volume, model.generate(1, seed=0)[0])
    a = gen.volume.clone()
    gen.show_latent(0, 1, 1.0)                       # the end of the walk is seed 1's latent
    torch.testing.assert_close(gen.volume, model.generate(1, seed=1)[0], atol=1e-5, rtol=0)
    gen.show_latent(0, 1, 0.5)
    assert not torch.equal(gen.volume, a)


def test_the_server_renders_the_first_look_while_the_page_loads(volume_file, tmp_path):
    """As the server starts, a thread renders a page's first look (the front view, the page's initial
    controls at the volume's resolution) under the render lock, and resamples the volume for the
    first full frame (the cache render_frame reads: the same tensor comes back); a page asking for
    the first look gets that frame, the closed form's pixels, without rendering again. A camera that
    only echoes the drawn one in float32 is the same camera (nothing to render); a move of 1e-4 is not."""
    from mitsuba_platonic.viewer import scene as S
    from mitsuba_platonic.viewer.app import ViewerApp, _same_camera, first_look_key, initial_key
    from mitsuba_platonic.viewer.scene import Window

    app = ViewerApp(open_source(volume_file), tmp_path / "exports", port=0)
    try:
        app.warming.join(timeout=300)
        key = first_look_key(app.scene)
        assert key == ((0.0, 0.0, 1.0), "closed form", "EA", N, 4, 0, None, 1.0)
        assert initial_key(app.scene)[3] == DEFAULT_RESOLUTION
        assert app.last is not None and app.last[0] == key
        assert app.frame_for(key) is app.last[1]
        np.testing.assert_array_equal(app.last[1].image, closed_form(read_volume_file(volume_file)[0], 0.0, 0.0, N))
        assert S._resampled and S._resampled[0][0] is app.scene.volume
        assert S._resampled[0][2].shape[-1] == DEFAULT_RESOLUTION
    finally:
        app.stop()
    front = np.array([0.0, 0.0, 1.0])
    echo = np.array([0.0, 2.4492936e-16, 4.0], np.float32) / np.float32(4.0)
    assert _same_camera(echo, None, front, None)
    assert _same_camera(front, Window(2.0, (0.5, 0.0)), front, Window(2.0 + 1e-7, (0.5 + 1e-7, 0.0)))
    assert not _same_camera(front + [1e-4, 0.0, 0.0], None, front, None)
    assert not _same_camera(front, Window(2.0), front, None)
    assert not _same_camera(front, Window(2.0, (0.5, 0.0)), front, Window(2.0, (0.5001, 0.0)))


# --------------------------------------------------------------------------- compare mode, live runs (no browser)

#: The colour scale's numbers on the page: "… colour scale: LO (dark) … HI (bright), …".
SCALE = re.compile(r"colour scale: ([0-9.e+-]+) \(dark\) … ([0-9.e+-]+) \(bright\)")


def _compare_page(partner):
    """A ClientView's compare state alone (no browser, no GUI): frame A drawn, the scale's controls."""
    from types import SimpleNamespace

    from mitsuba_platonic.viewer import app as A
    v = object.__new__(A.ClientView)
    v.partner, v.comparison = partner, None
    v.scale, v.scale_bar = SimpleNamespace(visible=False, content=""), SimpleNamespace(visible=False)
    return v


@pytest.mark.parametrize("pair, layout", [("closed form vs marcher", "difference"),
                                          ("closed form vs marcher", "side by side"),
                                          ("marcher vs path tracer", "difference")])
def test_compare_mode_draws_the_difference_of_the_two_renderers_at_one_camera(volume_file, tmp_path, pair, layout):
    """The server's comparison of a pair at a camera (zoomed, panned, a canvas 3:2) is of the two
    renderers' frames as render_frame gives them at that camera and size: its difference array is
    |A − B| of them, the page draws A | divider | B side by side or |A − B| through the colour scale,
    and the numbers the page prints for the scale are the range of the array's per-pixel max."""
    from mitsuba_platonic.viewer.app import ViewerApp, compare_keys
    from mitsuba_platonic.viewer.compare import GAP, GAP_GREY, PAIRS
    from mitsuba_platonic.viewer.scene import Window

    volume = read_volume_file(volume_file)[0]
    view, window, aspect, res = tuple(from_angles(35.0, 20.0).tolist()), Window(1.5, (0.1, -0.05)), 1.5, 2 * N
    half = aspect / 2 if layout == "side by side" else aspect
    a_name, b_name = PAIRS[pair]
    a = render_frame(volume, view, a_name, "EA", res, 1, window, half).image
    b = render_frame(volume, view, b_name, "EA", res, 1, window, half).image
    expected = np.abs(a.astype(np.float32) - b.astype(np.float32))
    assert expected.max() > 0                              # the two renderers differ here: the test can fail

    app = ViewerApp(open_source(volume_file), tmp_path / "exports", port=0)
    try:
        app.warming.join(timeout=300)
        key = (view, ("compare", pair, layout), "EA", res, 1, app.version, window, aspect)
        key_a, key_b = compare_keys(key)
        assert (key_a[1], key_b[1], key_a[7]) == (a_name, b_name, half)
        frame_a, frame_b, comparison = app.comparison_for(key_a, key_b, layout)
    finally:
        app.stop()
    np.testing.assert_array_equal(comparison.difference, expected)
    # the page draws B with A (a path trace's passes too) through the same arithmetic
    page = _compare_page((key_a, frame_a, layout, pair))
    drawn, note = page._with_partner(frame_b)
    np.testing.assert_array_equal(page.comparison.difference, expected)
    magnitude = expected.max(axis=2)
    if layout == "side by side":
        gap = np.full((a.shape[0], GAP, 3), GAP_GREY, np.uint8)
        np.testing.assert_array_equal(drawn.image, np.concatenate([a, gap, b], axis=1))
        assert not page.scale_bar.visible
    else:
        np.testing.assert_array_equal(drawn.image, page.comparison.scale.apply(magnitude))
        assert drawn.image.shape == a.shape and page.scale_bar.visible
    lo, hi = (float(x) for x in SCALE.search(page.scale.content).groups())
    assert (lo, hi) == (float(magnitude.min()), float(magnitude.max())) and page.scale.visible
    assert note == f", compare {pair} ({layout})"


def test_the_colour_scales_numbers_are_the_difference_arrays_range():
    """The scale runs from the least per-pixel difference (the ramp's first colour) to the largest (its
    last), and its line prints those two numbers; identical frames are 0 … 0, one colour."""
    from mitsuba_platonic.viewer.compare import STOPS, compare

    rng = np.random.default_rng(0)
    b = rng.integers(0, 200, (6, 9, 3), dtype=np.uint8)
    a = b + 3                                              # a least difference of 3, not 0
    a[2, 5, 1] = b[2, 5, 1] + 40                           # the largest, 40, in one channel of one pixel
    c = compare(a, b, "difference")
    np.testing.assert_array_equal(c.difference, np.abs(a.astype(np.float32) - b.astype(np.float32)))
    np.testing.assert_array_equal(c.magnitude, c.difference.max(axis=2))
    lo, hi = (float(x) for x in SCALE.search(c.line()).groups())
    assert (lo, hi) == (3.0, 40.0) == (float(c.magnitude.min()), float(c.magnitude.max()))
    np.testing.assert_array_equal(c.image[2, 5], STOPS[-1].astype(np.uint8))
    np.testing.assert_array_equal(c.image[0, 0], STOPS[0].astype(np.uint8))
    same = compare(b, b, "difference")
    assert SCALE.search(same.line()).groups() == ("0", "0")
    assert (same.image == STOPS[0].astype(np.uint8)).all()
    with pytest.raises(ValueError, match="one size"):
        compare(a, b[:, :-1], "difference")


class SocketPage:
    """A page without a browser: a websocket client of viser's own protocol that reports one camera
    (the initial one, on a ``width`` × ``height`` canvas) and reads nothing of what it is sent; the
    server makes its real ClientHandle and the app its ClientView (GUI, render thread), as for a tab."""

    def __init__(self, app, width: int = 1400, height: int = 600):
        import msgspec
        from viser._messages import ViewerCameraMessage
        from websockets.sync.client import connect

        from mitsuba_platonic.viewer.start import DISTANCE, FOV
        self.ws = connect(f"ws://127.0.0.1:{app.port}", subprotocols=[f"viser-v{viser.__version__}"])
        self.closed = threading.Event()
        threading.Thread(target=self._drain, daemon=True).start()
        camera = ViewerCameraMessage(wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 0.0, DISTANCE), fov=FOV, near=0.01,
                                     far=100.0, image_height=height, image_width=width, look_at=(0.0, 0.0, 0.0),
                                     up_direction=(0.0, 1.0, 0.0))
        self.ws.send(msgspec.msgpack.encode(camera.as_serializable_dict()))
        deadline = time.monotonic() + 60
        while not app.clients and time.monotonic() < deadline:
            time.sleep(0.05)
        assert app.clients, "the server made no ClientView for the socket page"
        self.view = next(iter(app.clients.values()))

    def _drain(self) -> None:
        while not self.closed.is_set():
            try:
                self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:
                return

    def wait(self, condition, seconds: float = 120.0) -> bool:
        deadline = time.monotonic() + seconds
        while not condition() and time.monotonic() < deadline:
            time.sleep(0.05)
        return condition()

    def close(self) -> None:
        self.closed.set()
        self.ws.close()


def test_a_page_in_compare_mode_draws_the_difference_through_the_colour_scale(volume_file, tmp_path):
    """A page (a socket page: viser's GUI and the app's render thread, no browser) that chooses
    "closed form vs marcher" as a difference draws |A − B| of the two renderers' frames at its camera
    and canvas through the colour scale, prints the scale's range, shows the bar and disables the
    renderer control; "side by side" draws A | B without the bar; "off" draws the one renderer again."""
    from mitsuba_platonic.viewer.app import ViewerApp, checked_aspect
    from mitsuba_platonic.viewer.compare import compare

    volume = read_volume_file(volume_file)[0]
    app = ViewerApp(open_source(volume_file), tmp_path / "exports", port=0)
    page = None
    try:
        page = SocketPage(app)
        v = page.view
        assert page.wait(lambda: v.count >= 1 and ", full," in v.info.content), v.info.content
        v.resolution.value = str(2 * N)                    # the marcher's 2×2 rays per voxel: the two differ
        v.compare.value, v.layout.value = "closed form vs marcher", "difference"
        assert page.wait(lambda: "compare closed form vs marcher (difference)" in v.info.content
                         and f"×{2 * N} px" in v.info.content), v.info.content
        aspect = checked_aspect(1400, 600)
        a = render_frame(volume, (0.0, 0.0, 1.0), "closed form", "EA", 2 * N, 4, None, aspect).image
        b = render_frame(volume, (0.0, 0.0, 1.0), "marcher", "EA", 2 * N, 4, None, aspect).image
        expected = compare(a, b, "difference")
        np.testing.assert_array_equal(v.comparison.difference, expected.difference)
        np.testing.assert_array_equal(v.frame.image, expected.image)
        lo, hi = (float(x) for x in SCALE.search(v.scale.content).groups())
        assert (lo, hi) == (float(expected.magnitude.min()), float(expected.magnitude.max())) and hi > 0
        assert v.scale.visible and v.scale_bar.visible and v.renderer.disabled
        v.layout.value = "side by side"
        assert page.wait(lambda: "compare closed form vs marcher (side by side)" in v.info.content), v.info.content
        assert v.frame.image.shape[1] > v.frame.image.shape[0] and not v.scale_bar.visible and v.scale.visible
        v.compare.value = "off"
        assert page.wait(lambda: v.frame is not None and "compare" not in v.info.content), v.info.content
        assert not v.scale.visible and not v.renderer.disabled
        np.testing.assert_array_equal(v.frame.image, a)
    finally:
        if page is not None:
            page.close()
        app.stop()


@pytest.fixture(scope="module")
def pose_run(tmp_path_factory, tiny_class):
    """A reconstruction run of one step with a pose head (``train.pose: elevation``), 16³."""
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.train import run as R

    tmp = tmp_path_factory.mktemp("pose-run")
    cfg = load_config(None, [
        f"run.out_dir={tmp}/runs", "run.name=pose", "run.steps=1", "run.sample_every=1000", "run.checkpoint_every=1000",
        f"data.cache={tmp}/data", f"data.shape_class={TINY}", "data.n_shapes=4", "data.views_per_shape=2",
        "data.split=0.5", f"model.resolution={N}", "model.width=4", "model.latent=8", "model.norm=batch",
        "train.batch_size=2", "train.task=reconstruction", "train.pose=elevation", "train.pose_weight=1.0"])
    return R.train(cfg, progress=False)


#: The pose head's bias the input-camera tests give a one-step run (whose head still reads about 0°,
#: the front view): P then reads about 90° · tanh(0.4) ≈ 34° from every input.
POSE_BIAS = 0.4


def _pose_scene(pose_run):
    """The pose run's scene, its head's bias set to :data:`POSE_BIAS` and its first input reconstructed
    again; and θ̂ as the model's own networks read it from that input, in degrees (eval mode: E's
    BatchNorm on its running statistics)."""
    scene = open_source(pose_run)
    with torch.no_grad():
        scene.model.P.bias.fill_(POSE_BIAS)
    scene.show_input(0)
    model = scene.model
    E, P = model.E.eval(), model.P.eval()
    with torch.no_grad():
        theta = math.degrees(float(P(E(scene.inputs[:1].to(model.device)))[0]))
    assert abs(theta) > 10.0                                # not the front view: the test tells them apart
    return scene, theta


def test_the_input_camera_is_the_elevation_the_pose_head_reads_and_the_input_is_drawn_beside(
        pose_run, runs, tmp_path, monkeypatch):
    """A run with a pose head shows G's upright volume, so its input's camera is ω(0°, θ̂), θ̂ what P
    reads from the input (a run with train.pose: input: 0°, the front view; a --photo: P's reading of
    the photo). A socket page's "input's camera" draws that view at zoom 1 without pan, the frame
    render_frame gives there; "input beside the frame" draws the input at the frame's height by the
    nearest pixel | the divider | the frame rendered at the canvas' aspect less one, and a still so too."""
    from PIL import Image

    from mitsuba_platonic.viewer.app import ViewerApp, checked_aspect
    from mitsuba_platonic.viewer.compare import GAP, GAP_GREY, input_beside

    monkeypatch.chdir(pose_run.parent.parent.parent)       # data.cache is relative to where training ran
    scene, theta = _pose_scene(pose_run)
    assert scene.input_camera() == (0.0, pytest.approx(theta, abs=1e-4))
    photo = tmp_path / "photo.png"
    rgba = np.zeros((N, N, 4), np.uint8)
    rgba[3:13, 5:11] = (200, 100, 50, 255)
    Image.fromarray(rgba).save(photo)
    with_photo = open_source(pose_run, photo)
    model = with_photo.model
    with torch.no_grad():
        read = math.degrees(float(model.P.eval()(model.E.eval()(model.load_image(photo).to(model.device)))[0]))
    assert with_photo.input_camera() == (0.0, pytest.approx(read, abs=1e-4))
    monkeypatch.chdir(runs["reconstruction"].parent.parent.parent)
    assert open_source(runs["reconstruction"]).input_camera() == (0.0, 0.0)      # train.pose: input
    assert open_source(runs["generation"]).input_camera() is None

    monkeypatch.chdir(pose_run.parent.parent.parent)
    app = ViewerApp(scene, tmp_path / "exports", port=0)
    page = None
    try:
        page = SocketPage(app)
        v = page.view
        assert page.wait(lambda: v.count >= 1 and ", full," in v.info.content), v.info.content
        v.input_camera()                                   # what its button does
        line = rf"az 0\.0° el {theta:.1f}°, zoom 1\.000×, centre \(\+0\.000, \+0\.000\)"
        assert page.wait(lambda: re.search(line + ".*", v.info.content) and ", full," in v.info.content), v.info.content
        view = tuple(from_angles(0.0, theta).tolist())
        aspect = checked_aspect(1400, 600)
        direct = render_frame(scene.volume, view, "closed form", "EA", DEFAULT_RESOLUTION, 4, None, aspect).image
        np.testing.assert_array_equal(v.frame.image, direct)
        assert not np.array_equal(direct, closed_form_at(scene.volume, 0.0, 0.0, DEFAULT_RESOLUTION, aspect))

        v.beside.value = True
        assert page.wait(lambda: "input beside (" in v.info.content and ", full," in v.info.content), v.info.content
        frame = render_frame(scene.volume, view, "closed form", "EA", DEFAULT_RESOLUTION, 4, None,
                             round(aspect - 1.0, 3)).image
        h, w = frame.shape[:2]
        drawn = v.frame.image
        assert drawn.shape == (h, h + GAP + w, 3) and re.search(line, v.info.content), v.info.content
        resized = np.asarray(Image.fromarray(scene.input).resize((h, h), Image.NEAREST))   # PIL's own nearest
        np.testing.assert_array_equal(drawn[:, :h], resized)
        assert (drawn[:, h:h + GAP] == GAP_GREY).all()
        np.testing.assert_array_equal(drawn[:, h + GAP:], frame)
        assert f"input beside ({scene.input_names[0]}, {N}×{N} → {h}×{h} px)" in v.info.content
        v.still_size.value = str(2 * N)                    # a still draws the input beside it too
        v._start_export("still")
        assert page.wait(lambda: "saved" in v.exported.content and not v.export.is_alive()), v.exported.content
        still = render_frame(scene.volume, view, "closed form", "EA", 2 * N, 4, None, round(aspect - 1.0, 3)).image
        np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "exports" / "view.png")),
                                      input_beside(scene.input, still))
        v.beside.value = False
        assert page.wait(lambda: "input beside" not in v.info.content and ", full," in v.info.content)
        np.testing.assert_array_equal(v.frame.image, direct)
    finally:
        if page is not None:
            page.close()
        app.stop()


def test_an_export_is_checked_cancellable_and_draws_the_compare_mode(volume_file, tmp_path):
    """A socket page's exports: a frame count or still size outside what is offered is one line on
    the page and nothing is written; a path-traced turntable cancelled after its first frame writes
    nothing and says how far it got; a still in compare mode ("closed form vs marcher", difference,
    32 px) is the comparison of the two renderers' frames at the page's camera and canvas."""
    from mitsuba_platonic.viewer.app import ViewerApp, checked_aspect
    from mitsuba_platonic.viewer.compare import compare

    volume = read_volume_file(volume_file)[0]
    out = tmp_path / "exports"
    app = ViewerApp(open_source(volume_file), out, port=0)
    page = None
    try:
        page = SocketPage(app)
        v = page.view
        assert page.wait(lambda: v.count >= 1 and ", full," in v.info.content), v.info.content

        def export(kind: str, says: str) -> str:
            v._start_export(kind)                          # what its button does
            assert page.wait(lambda: re.search(says, v.exported.content)
                             and not (v.export is not None and v.export.is_alive())), v.exported.content
            return v.exported.content

        for frames in (1, 1000):                         # (viser's number box itself rounds to its step)
            v.frames.value = frames
            assert export("turntable", "not saved") == (f"not saved: turntable frames: expected a whole number from 2 "
                                                        f"to 360, got {frames!r}")
        v.frames.value = 48
        v.still_size.value = "24"
        assert export("still", "not saved").startswith("not saved: still size: expected a multiple of the volume's 16")
        assert not out.exists()

        v.renderer.value, v.resolution.value = "path tracer", str(N)
        v._start_export("turntable")
        assert page.wait(lambda: "frame 2 of 48" in v.exported.content), v.exported.content
        v.export_cancel.set()                              # what "cancel export" does
        says = export("turntable", "cancelled")
        assert re.fullmatch(r"turntable of 48 frames: cancelled after [12] of 48 frames; nothing written", says), says
        assert not out.exists() or list(out.iterdir()) == []

        v.renderer.value = "closed form"
        v.compare.value, v.layout.value, v.still_size.value = "closed form vs marcher", "difference", str(2 * N)
        export("still", r"saved .*view\.png")
        aspect = checked_aspect(1400, 600)
        a = render_frame(volume, (0.0, 0.0, 1.0), "closed form", "EA", 2 * N, 4, None, aspect).image
        b = render_frame(volume, (0.0, 0.0, 1.0), "marcher", "EA", 2 * N, 4, None, aspect).image
        from PIL import Image
        np.testing.assert_array_equal(np.asarray(Image.open(out / "view.png")), compare(a, b, "difference").image)
    finally:
        if page is not None:
            page.close()
        app.stop()


def test_a_turntables_views_go_round_the_vertical_and_its_files_hold_its_frames(tmp_path):
    """turntable_views: F views at azimuths φ₀ + k·360°/F at the view's elevation, the first the view;
    Exports.turntable: an animated WebP of exactly those pixels and one PNG per frame, never over an
    earlier export; what is not a turntable of frames is refused."""
    from PIL import Image, ImageSequence

    from mitsuba_platonic.views import to_angles
    from mitsuba_platonic.viewer.scene import checked_frames, checked_still, still_sizes, turntable_views

    views = turntable_views(tuple(from_angles(30.0, 20.0).tolist()), 6)
    az, el = to_angles(torch.tensor(views))
    torch.testing.assert_close(az, torch.tensor([30.0, 90.0, 150.0, -150.0, -90.0, -30.0], dtype=torch.float64))
    torch.testing.assert_close(el, torch.full((6,), 20.0, dtype=torch.float64))
    assert still_sizes(16) == [16, 32, 64, 128, 256, 512, 1024, 2048] and still_sizes(24)[-1] == 1536
    assert checked_still("512", 16) == 512 and checked_frames(8.0) == 8
    for bad in (1, 361, 2.5, "many", False, float("nan")):
        with pytest.raises(UserError, match="turntable frames: expected a whole number from 2 to 360"):
            checked_frames(bad)
    for bad in ("520", 4096, 8, True, None):
        with pytest.raises(UserError, match="still size: expected a multiple of the volume's 16 from 16 to 2048"):
            checked_still(bad, 16)
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (9, 21, 3), dtype=np.uint8) for _ in range(5)]
    ex = Exports(tmp_path / "out")
    first, second = ex.turntable(frames, "spin"), ex.turntable(frames, "spin")
    assert [p.name for p in first] == ["spin.webp", "spin_frames"] and [p.name for p in second] == ["spin_2.webp",
                                                                                                    "spin_2_frames"]
    read = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(Image.open(first[0]))]
    assert len(read) == 5 and all(np.array_equal(a, b) for a, b in zip(read, frames))
    assert sorted(p.name for p in first[1].iterdir()) == [f"frame_{k:03d}.png" for k in range(5)]
    np.testing.assert_array_equal(np.asarray(Image.open(first[1] / "frame_003.png")), frames[3])
    with pytest.raises(UserError, match="at least two"):
        ex.turntable(frames[:1], "one")
    with pytest.raises(UserError, match="of one size"):
        ex.turntable([frames[0], frames[1][:, :-1]], "two")


def _replace(path: Path, data: bytes) -> None:
    """Write ``data`` as ``path`` at once (a rename), as training saves a checkpoint: the watcher never sees half."""
    tmp = path.with_name(path.name + ".writing")
    tmp.write_bytes(data)
    tmp.replace(path)


def test_a_live_run_follows_its_new_checkpoint_and_keeps_its_model_past_a_torn_one(runs, tmp_path, capsys):
    """``platonic view RUN`` on a run still training: a torn last.pt is one line in the log, tried once,
    and the model shown stays; a new last.pt (a later step, other weights) is taken within 10 s (the
    watcher looks every POLL_S = 2 s): the server reports its step and scalars.csv's latest losses,
    and the scene shows the new model's volume (every page renders again: the version moves); an
    open page's run line and title say so."""
    from mitsuba_platonic.files.checkpoint import load_checkpoint, save_checkpoint
    from mitsuba_platonic.model import Model
    from mitsuba_platonic.viewer.app import ViewerApp

    run = tmp_path / "run"
    shutil.copytree(runs["generation"], run)
    last = run / "checkpoints" / "last.pt"
    app = ViewerApp(open_source(run), tmp_path / "exports", port=0)
    page = None
    try:
        live, model, version = app.live, app.scene.model, app.version
        assert live is not None and live.step == 1 and "model of step 1" in live.line()
        page = SocketPage(app)                             # a page open on the run: its run line follows
        assert page.view.run_line.content == live.line()

        def wait(condition) -> bool:
            deadline = time.monotonic() + 10.0
            while not condition() and time.monotonic() < deadline:
                time.sleep(0.05)
            return condition()

        good = last.read_bytes()
        capsys.readouterr()
        _replace(last, good[:len(good) // 2])
        assert wait(lambda: live.failed is not None), "the watcher did not look at the torn checkpoint"
        polls = live.polls
        assert wait(lambda: live.polls >= polls + 2)       # it looked twice more at the same torn file
        lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("platonic view:")]
        assert len(lines) == 1 and lines[0].startswith("platonic view: the run's new checkpoints/last.pt was not "
                                                       "taken (") and lines[0].endswith("still showing step 1"), lines
        assert app.scene.model is model and live.step == 1 and app.version == version

        state = load_checkpoint(runs["generation"] / "checkpoints" / "last.pt")
        state["step"] = 5
        for name, weight in state["trainer"]["nets"].items():
            if name.startswith("G.") and weight.is_floating_point():
                weight.mul_(1.1)
        with open(run / "scalars.csv", "a") as f:
            f.write("5,0.5,0.5,1,1,0.25,100\n")
        save_checkpoint(last, state)
        assert wait(lambda: live.step == 5), f"the server still reports step {live.step} after 10 s"
        assert wait(lambda: "step 5: loss_d 0.5, loss_g 0.25" in live.line()), live.line()
        assert app.scene.model.step == 5 and app.scene.title.endswith("(step 5)") and app.version == version + 1
        torch.testing.assert_close(app.scene.volume, Model.from_checkpoint(run).generate(1, seed=0)[0])
        assert not torch.allclose(app.scene.volume, model.generate(1, seed=0)[0])
        assert page.wait(lambda: page.view.run_line.content == live.line(), 10.0), page.view.run_line.content
        assert "(step 5)" in page.view.title.content
    finally:
        if page is not None:
            page.close()
        app.stop()


# --------------------------------------------------------------------------- in the browser


def _chromium() -> str:
    """Debian's chromium, installed here where missing; a skip saying why where it cannot be."""
    for name in ("chromium", "chromium-browser"):
        if shutil.which(name):
            return shutil.which(name)
    if not shutil.which("apt-get"):
        pytest.skip("no chromium and no apt-get to install it: the browser tests need Debian's chromium")
    if os.geteuid() != 0:
        pytest.skip("no chromium, and this user cannot run apt-get install chromium (not root)")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for attempt in (["apt-get", "install", "-y", "-q", "chromium"], ["apt-get", "update", "-q"],
                    ["apt-get", "install", "-y", "-q", "chromium"]):
        subprocess.run(attempt, env=env, capture_output=True, timeout=900)
        if shutil.which("chromium"):
            return shutil.which("chromium")
    pytest.skip("apt-get install -y chromium did not install a chromium: the browser tests cannot run here")


@pytest.fixture(scope="module")
def browser():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (the 'test' extra)")
    exe = _chromium()
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, headless=True,
                              args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                                    "--ignore-gpu-blocklist"])
        yield b
        b.close()


class Server:
    """``platonic view`` in a subprocess: its address, its output, Ctrl-C at the end."""

    def __init__(self, args, cwd: Path):
        self.cwd = cwd
        self.proc = subprocess.Popen([sys.executable, "-m", "mitsuba_platonic.cli", "view", *map(str, args),
                                      "--port", "0"], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.started = time.monotonic()
        self.lines: list = []
        reader = threading.Thread(target=lambda: self.lines.extend(iter(self.proc.stdout.readline, "")), daemon=True)
        reader.start()
        deadline = time.monotonic() + 120
        while not self.lines and time.monotonic() < deadline and self.proc.poll() is None:
            time.sleep(0.05)
        if not self.lines:
            self.proc.kill()
            raise AssertionError(f"platonic view printed no address: {self.proc.stderr.read()}")
        found = re.search(r"http://127\.0\.0\.1:\d+", self.lines[0])
        assert found, self.lines[0]
        self.url = found.group(0)

    def stop(self) -> tuple:
        self.proc.send_signal(signal.SIGINT)
        try:
            code = self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        return code, self.proc.stderr.read()


@pytest.fixture(scope="module")
def server(volume_file, tmp_path_factory):
    cwd = tmp_path_factory.mktemp("cwd")
    s = Server([volume_file], cwd)
    yield s
    code, err = s.stop()
    assert code == -signal.SIGINT, err                     # died by the signal: a shell sees 130
    assert one_line(err, "view", "interrupted")


@pytest.fixture
def page(browser, server):
    page = browser.new_page(viewport={"width": 1400, "height": 600})
    page.set_default_timeout(WAIT_MS)
    page.goto(server.url)
    yield page
    page.close()


def _frame(page, pattern: str = "full") -> re.Match:
    """Wait for a frame line matching ``pattern`` (a regex over the line) and return its match."""
    locator = page.get_by_text(re.compile(r"^frame \d+: .*" + pattern))
    locator.wait_for()
    m = FRAME.search(locator.inner_text())
    assert m, locator.inner_text()
    return m


def _shown(page, r: int) -> np.ndarray:
    """The frame's central R×R square as drawn (the square frame: the W×H frame the line names is
    drawn over the whole canvas), read at its pixels' centres, once two screenshots 0.3 s apart agree
    (the page fades in, and the canvas paints after the text updates; at most 20 tries)."""
    from PIL import Image

    closers = page.locator(".mantine-Notification-closeButton")     # software WebGL's notice covers the canvas' corner
    for i in range(closers.count()):
        closers.nth(i).click()
    w, h = (int(g) for g in SIZE.search(page.get_by_text(re.compile(r"^frame \d+: ")).inner_text()).groups())
    box = page.locator("canvas").first.bounding_box()
    cells = np.arange(r) + 0.5
    xs = np.floor(box["x"] + ((w - r) // 2 + cells) * box["width"] / w).astype(int)
    ys = np.floor(box["y"] + ((h - r) // 2 + cells) * box["height"] / h).astype(int)
    last = None
    for _ in range(20):
        time.sleep(0.3)
        shot = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"))[ys][:, xs]
        if last is not None and np.array_equal(shot, last):
            return shot
        last = shot
    return last


#: How long a frame line must stay unchanged after its screenshot for the camera to rest (seconds).
REST_S = 0.6


def _rest(page, pattern: str, r: int) -> tuple:
    """(the frame line matching ``pattern``, its R×R frame as drawn) once the camera rests: the
    line is the same before and after the screenshots agree. viser's orbit controls glide on after
    the mouse stops (their damping), later on a loaded machine, so a line read first may belong to
    a frame the canvas has already replaced (at most 20 tries). Resting is the line unchanged over
    the screenshot and :data:`REST_S` after it: a wheel's dolly on a loaded CI machine glided on past
    one screenshot's time (zoom 1.292 read, 1.36 reached)."""
    lines = page.get_by_text(re.compile(r"^frame \d+: "))
    for _ in range(20):
        _frame(page, pattern)
        line = lines.inner_text()
        shot = _shown(page, r)
        if lines.inner_text() != line or not re.search(pattern, line):
            continue
        time.sleep(REST_S)
        if lines.inner_text() == line:
            return line, shot
    raise AssertionError(f"the camera did not rest on a frame matching {pattern!r}: last {line!r}")


def _difference(a: np.ndarray, b: np.ndarray) -> tuple:
    d = np.abs(a.astype(float) - b.astype(float))
    return float(d.mean()), float(np.percentile(d, 95))


def _views_apart(a: np.ndarray, b: np.ndarray) -> bool:
    """Frames of two views 30° apart differ far beyond the tolerance (16³ figure: mean 5.6, p95 35)."""
    mean, p95 = _difference(a, b)
    return mean > 2 * TOLERANCE and p95 > 4 * TOLERANCE_MAX


def _choose(page, which: int, option: str) -> None:
    page.get_by_role("combobox").nth(which).click()
    page.get_by_role("option", name=option, exact=True).click()


def test_the_page_shows_the_closed_form_and_follows_the_camera(page, server, volume_file):
    volume = read_volume_file(volume_file)[0]
    m = _frame(page, r"full, .*az 0\.0° el 0\.0°")
    r = 8 * N
    assert int(m.group(4)) == r == DEFAULT_RESOLUTION                     # 128²: the page's default
    first = time.monotonic() - server.started
    shown = _shown(page, r)
    front, side = closed_form(volume, 0.0, 0.0, r), closed_form(volume, 30.0, 0.0, r)
    mean, p95 = _difference(shown, front)
    assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (mean, p95)
    assert _views_apart(shown, side)                                         # the check tells views apart
    print(f"first frame {first:.1f} s after the command; screenshot vs closed form: mean {mean:.2f}, p95 {p95:.1f}")
    # a page that opens and rests draws two frames, its first look (the volume's resolution, while the
    # canvas settles; none where the canvas had settled before the render thread looked, under load) and its
    # full frame: the browser's echoes of its first camera render nothing
    assert int(_frame(page, r"full, .*az 0\.0° el 0\.0°").group(1)) in (1, 2)

    page.get_by_role("button", name="azimuth +30").click()
    _frame(page, r"az 30\.0° el 0\.0°")
    moved = _shown(page, r)
    mean, p95 = _difference(moved, side)
    assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (mean, p95)
    assert _views_apart(moved, shown)

    page.get_by_role("button", name="elevation +15").click()
    _frame(page, r"az 30\.0° el 15\.0°")
    mean, p95 = _difference(_shown(page, r), closed_form(volume, 30.0, 15.0, r))
    assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (mean, p95)


def test_the_canvas_sits_beside_the_controls_and_its_frame_has_its_aspect(browser, server):
    """At 960×540 the control panel is docked beside the canvas, not over it (the canvas ends where
    the panel begins), and the frame is rendered at the canvas' aspect (W×H within a pixel of it,
    R = 128 along the shorter side), the frame line and the settings line naming the same W×H."""
    page = browser.new_page(viewport={"width": 960, "height": 540})
    page.set_default_timeout(WAIT_MS)
    try:
        page.goto(server.url)
        _frame(page)
        canvas = page.locator("canvas").first.bounding_box()
        panel = page.get_by_role("button", name="azimuth +30").bounding_box()
        assert canvas["x"] + canvas["width"] <= panel["x"], (canvas, panel)
        assert canvas["width"] > 0.5 * 960 and canvas["height"] == 540, canvas
        line = page.get_by_text(re.compile(r"^frame \d+: ")).inner_text()
        width, height = (int(g) for g in SIZE.search(line).groups())
        assert height == DEFAULT_RESOLUTION, line
        assert abs(width - height * canvas["width"] / canvas["height"]) <= 1.0, (line, canvas)
        page.get_by_text(re.compile(rf"^closed form \(.*, {width}×{height} px")).wait_for()
    finally:
        page.close()


def test_the_path_tracers_frames_take_longer_than_the_marchers(page):
    _frame(page)
    _choose(page, 2, str(N))                                       # 16² frames: the path tracer's in seconds
    times = {}
    for renderer in ("marcher", "path tracer"):
        _choose(page, 0, renderer)
        page.get_by_text(re.compile(rf"^{renderer} \(")).wait_for()
        page.get_by_role("button", name="azimuth +30").click()    # a second frame: the first traced the kernels
        m = _frame(page, r"full, .*az 30\.0° el 0\.0°")            # the path tracer's last pass, not its preview
        times[renderer] = float(m.group(2))
        page.get_by_role("button", name="front view").click()
        _frame(page, r"az 0\.0° el 0\.0°")
    assert times["path tracer"] > times["marcher"], times


def _fill(page, value: str, text: str) -> None:
    """Type ``text`` into the page's text or number box that holds ``value`` now, and send it."""
    box = page.locator(f"input[value='{value}']")
    box.wait_for()
    handle = box.element_handle()
    handle.fill(text)
    handle.press("Enter")
    time.sleep(0.5)                                                 # the new value reaches the server


def test_the_page_saves_the_view_inside_the_output_folder(page, server):
    _frame(page)
    _fill(page, "view", "../../outside")                            # the export's "name" text box
    page.get_by_role("button", name="save view (PNG)").click()
    page.get_by_text(re.compile(r"saved .*outside\.png")).wait_for()
    saved = server.cwd / "view-exports" / "outside.png"
    assert saved.exists() and not (server.cwd.parent / "outside.png").exists()
    from PIL import Image
    width, height = Image.open(saved).size
    assert height == DEFAULT_RESOLUTION and width > height            # the frame as drawn: the canvas' aspect


def test_the_page_exports_a_turntable_and_a_still_as_the_renderers_render_them(page, server, volume_file):
    """"save turntable" writes an animated WebP of the frames asked for (8), frame k the renderer's
    at azimuth φ₀ + k·360°/8 (φ₀ = 30°, the page's), its elevation, resolution and canvas aspect,
    and the same frames as PNGs; "save still" writes the view at the still size (256: twice the
    page's largest resolution for a 16³ volume) as the marcher renders it, and refuses a size the
    closed form cannot reach, in one line, writing nothing."""
    from PIL import Image, ImageSequence

    from mitsuba_platonic.viewer.scene import MAX_STILL, TURNTABLE_FRAMES

    volume = read_volume_file(volume_file)[0]
    exports = server.cwd / "view-exports"
    _frame(page)
    _choose(page, 2, str(N))                                       # 16² frames: milliseconds each
    page.get_by_role("button", name="azimuth +30").click()
    _frame(page, rf"full, \d+×{N} px, az 30\.0° el 0\.0°")
    box = page.locator("canvas").first.bounding_box()
    aspect = round(box["width"] / box["height"], 3)
    _fill(page, "view", "spin")
    _fill(page, str(TURNTABLE_FRAMES), "8")
    page.get_by_role("button", name="save turntable (WebP)").click()
    page.get_by_text(re.compile(r"saved .*spin\.webp.*turntable of 8 frames")).wait_for()
    animation = Image.open(exports / "spin.webp")
    frames = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(animation)]
    assert len(frames) == 8 and animation.info.get("loop") == 0
    for k, frame in enumerate(frames):
        expected = closed_form_at(volume, 30.0 + 45.0 * k, 0.0, N, aspect)
        assert frame.shape == expected.shape and frame.shape[0] == N, (frame.shape, expected.shape)
        mean, p95 = _difference(frame, expected)
        assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (k, mean, p95)
        np.testing.assert_array_equal(np.asarray(Image.open(exports / "spin_frames" / f"frame_{k:03d}.png")), frame)
    assert _views_apart(frames[1], closed_form_at(volume, 30.0, 0.0, N, aspect))   # the check tells frames apart

    _choose(page, 5, "256")                                        # the still size
    page.get_by_role("button", name="save still (PNG)").click()
    page.get_by_text(re.compile(r"not saved: a still of 256 px: the closed form renders at most 128 px")).wait_for()
    assert not (exports / "spin.png").exists()
    _choose(page, 0, "marcher")
    _frame(page, r"full, .*az 30\.0° el 0\.0°")
    page.get_by_role("button", name="save still (PNG)").click()
    page.get_by_text(re.compile(r"saved .*spin\.png.*still")).wait_for()
    still = np.asarray(Image.open(exports / "spin.png").convert("RGB"))
    expected = render_frame(volume, tuple(from_angles(30.0, 0.0).tolist()), "marcher", "EA", 256, aspect=aspect,
                            most=MAX_STILL).image
    assert still.shape == expected.shape and still.shape[0] == 256 and still.shape[1] > 256, still.shape
    mean, p95 = _difference(still, expected)
    assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (mean, p95)


def test_dragging_the_canvas_orbits_with_low_resolution_frames_while_moving(page, server, volume_file):
    """The mouse orbits viser's camera; the server renders quarter-resolution frames while it moves
    (JPEG) and the full one once it rests, at the view the camera reached."""
    volume = read_volume_file(volume_file)[0]
    _frame(page)
    _choose(page, 2, str(4 * N))                                     # 64² frames: 16² while moving
    _frame(page, rf"full, \d+×{4 * N} px")
    box = page.locator("canvas").first.bounding_box()
    x, y = box["x"] + box["width"] * 0.35, box["y"] + box["height"] * 0.5
    page.mouse.move(x, y)
    page.mouse.down()
    seen = set()
    for step in range(1, 30):
        page.mouse.move(x + 8 * step, y + 2 * step)
        time.sleep(0.05)
        m = FRAME.search(page.get_by_text(re.compile(r"^frame \d+:")).inner_text())
        seen.add((m.group(3), int(m.group(4))))
    page.mouse.up()
    assert ("moving", N) in seen, seen
    line, shown = _rest(page, rf"full, \d+×{4 * N} px", 4 * N)
    m = FRAME.search(line)
    az, el = float(m.group(5)), float(m.group(6))
    assert abs(az) > 5.0, (az, el)                                    # the drag turned the camera
    expected = render_frame(volume, tuple(from_angles(az, el).tolist()), "closed form", "EA", 4 * N).image
    mean, p95 = _difference(shown, expected)                         # the angles printed to 0.1°
    assert mean <= 2 * TOLERANCE and p95 <= 4 * TOLERANCE_MAX, (mean, p95)


def _line(page) -> str:
    return page.get_by_text(re.compile(r"^frame \d+:")).inner_text()


def _pass(line: str) -> tuple:
    """(passes done, passes in all) that a path tracer's frame line names; (0, 0) for another frame."""
    m = re.search(r"pass (\d+) of (\d+)", line)
    return (int(m.group(1)), int(m.group(2))) if m else (0, 0)


def _path_trace(page) -> None:
    """Start a slow path trace on ``page``: 128² (the 16³ volume resampled to 128³), 4 passes of 1 spp,
    and wait for its first pass."""
    _frame(page)
    _choose(page, 2, str(8 * N))
    _choose(page, 0, "path tracer")
    page.get_by_text(re.compile(r"^frame \d+: .*az 0\.0° el 0\.0°.*pass 1 of 4")).wait_for(timeout=300_000)


def test_the_lit_renderers_offer_the_formation_they_render_only(page):
    """Single scattering and the path tracer render EA whatever the formation says (their frames for VH
    and AO were EA's): the page offers them EA only, and the other renderers the volume's formations."""
    from mitsuba_platonic.viewer.scene import formations_of

    assert formations_of("single scattering", 4) == formations_of("path tracer", 4) == ["EA"]
    assert formations_of("marcher", 4) == ["VH", "AO", "EA"] and formations_of("closed form", 1) == ["VH", "AO"]

    def offered() -> list:
        page.get_by_role("combobox").nth(1).click()
        options = page.get_by_role("option")
        options.first.wait_for()
        names = [options.nth(i).inner_text() for i in range(options.count())]
        page.keyboard.press("Escape")
        return names

    _frame(page)
    assert offered() == ["VH", "AO", "EA"]
    _choose(page, 0, "single scattering")
    page.get_by_text(re.compile(r"^single scattering \(")).wait_for()
    assert offered() == ["EA"]
    _choose(page, 0, "closed form")
    page.get_by_text(re.compile(r"^closed form \(")).wait_for()
    assert offered() == ["VH", "AO", "EA"]


def test_another_tabs_marcher_frame_comes_while_a_path_trace_runs(browser, server):
    """With a path trace running in one tab, another tab's marcher frame arrives before the trace has
    moved on by more than the pass in flight: the path tracer's passes run in a worker process of their
    own, not under the server's render lock (before: the other tab's 8 ms frame waited for the whole
    path-traced frame, 6.25 s). The time it took is printed; the ordering is asserted (a wall-clock bound
    is no test on a shared 2-core machine)."""
    other = browser.new_page(viewport={"width": 1400, "height": 600})
    other.set_default_timeout(WAIT_MS)
    tracing = browser.new_page(viewport={"width": 1400, "height": 600})
    tracing.set_default_timeout(WAIT_MS)
    try:
        other.goto(server.url)
        _frame(other)
        _choose(other, 0, "marcher")
        _frame(other, r"full, .*az 0\.0°")
        other.get_by_text(re.compile(r"^marcher \(")).wait_for()
        tracing.goto(server.url)
        _path_trace(tracing)
        before = _pass(_line(tracing))
        start = time.monotonic()
        other.get_by_role("button", name="azimuth +30").click()
        _frame(other, r"full, .*az 30\.0° el 0\.0°")
        took = time.monotonic() - start
        after = _pass(_line(tracing))
        print(f"the other tab's marcher frame: {took:.2f} s after the click; the path trace at pass {before} "
              f"then, {after} when it came")
        assert before[1] == 4 and after[1] == 4 and after[0] - before[0] <= 1 and after[0] < 4, (before, after)
        tracing.get_by_text(re.compile(r"^frame \d+: .*full, .*pass 4 of 4")).wait_for(timeout=300_000)
    finally:
        other.close()
        tracing.close()


def test_a_camera_move_during_a_path_trace_shows_a_new_frame_before_the_next_pass(page):
    """A camera move during a path trace draws a frame at the new camera at once (the closed form's
    preview), before any further pass of the old camera, then the trace starts over there: its passes
    1 … 4 at the new camera, the last one "full". The time to the new frame is printed."""
    _path_trace(page)
    before = _pass(_line(page))
    start = time.monotonic()
    page.get_by_role("button", name="azimuth +30").click()
    seen = []
    deadline = time.monotonic() + WAIT_MS / 1000
    while time.monotonic() < deadline:
        line = _line(page)
        if not seen or seen[-1] != line:
            seen.append(line)
        if "az 30.0°" in line:
            break
        time.sleep(0.02)
    took = time.monotonic() - start
    first_new = seen[-1]
    print(f"a camera move during a path trace: a new frame {took:.2f} s after the click ({first_new!r}); "
          f"the trace was at pass {before}")
    assert "az 30.0°" in first_new and "path tracer's preview" in first_new, seen
    assert all(_pass(line)[0] <= before[0] + 1 for line in seen[:-1]), seen    # at most the pass in flight
    page.get_by_text(re.compile(r"^frame \d+: .*az 30\.0° el 0\.0°.*pass 1 of 4")).wait_for(timeout=300_000)
    page.get_by_text(re.compile(r"^frame \d+: .*full, .*az 30\.0° el 0\.0°.*pass 4 of 4")).wait_for(timeout=300_000)
    assert int(_frame(page, r"full, .*az 30\.0° el 0\.0°.*pass 4 of 4").group(4)) == 8 * N


def test_a_reconstruction_run_steps_through_its_held_out_inputs(browser, runs, tmp_path, monkeypatch):
    """The page of a run (served in this process: the run's tiny shape class is registered here only)."""
    from mitsuba_platonic.viewer.app import ViewerApp

    monkeypatch.chdir(runs["reconstruction"].parent.parent.parent)   # data.cache is relative to where training ran
    app = ViewerApp(open_source(runs["reconstruction"]), tmp_path / "exports", port=0)
    try:
        page = browser.new_page(viewport={"width": 1400, "height": 600})
        page.set_default_timeout(WAIT_MS)
        page.goto(app.url)
        _frame(page)
        page.get_by_text(re.compile(r"\(1 of \d+\)")).wait_for()
        assert page.get_by_role("img").count() + page.locator("img").count() >= 1   # the input beside the view
        count = int(_frame(page).group(1))
        page.get_by_role("button", name="next input").click()
        page.get_by_text(re.compile(r"\(2 of \d+\)")).wait_for()
        # a new frame for the new volume (a run of one step reconstructs nearly the same volume from each)
        page.wait_for_function(f"() => /frame (\\d+):/.exec(document.body.innerText)[1] > {count}")
        assert app.scene.input_index == 1
        page.close()
    finally:
        app.stop()


def test_the_input_camera_button_shows_the_input_view_the_pose_head_reads(browser, pose_run, tmp_path, monkeypatch):
    """The page of a run with a pose head (served in this process): "input's camera" prints az 0° and
    el θ̂ (what P reads from the input) at zoom 1, centred, and draws the frame render_frame gives there."""
    from mitsuba_platonic.viewer.app import ViewerApp

    monkeypatch.chdir(pose_run.parent.parent.parent)
    scene, theta = _pose_scene(pose_run)
    app = ViewerApp(scene, tmp_path / "exports", port=0)
    try:
        page = browser.new_page(viewport={"width": 1400, "height": 600})
        page.set_default_timeout(WAIT_MS)
        page.goto(app.url)
        _frame(page, r"az 0\.0° el 0\.0°")
        page.get_by_role("button", name="input's camera").click()
        line, shown = _rest(page, rf"full, .* az 0\.0° el {theta:.1f}°, zoom 1\.000×, centre \(\+0\.000, \+0\.000\)",
                            DEFAULT_RESOLUTION)
        v = next(iter(app.clients.values()))
        aspect = v._request()[1]
        direct = render_frame(scene.volume, tuple(from_angles(0.0, theta).tolist()), "closed form", "EA",
                              DEFAULT_RESOLUTION, 4, None, aspect).image
        np.testing.assert_array_equal(v.frame.image, direct)          # the frame the server drew
        h, w = direct.shape[:2]
        r = DEFAULT_RESOLUTION
        square = direct[(h - r) // 2:(h - r) // 2 + r, (w - r) // 2:(w - r) // 2 + r]
        _same(shown, square, "input's camera")                         # and what the page shows
        front = render_frame(scene.volume, (0.0, 0.0, 1.0), "closed form", "EA", r, 4, None, aspect).image
        assert _difference(square, front[(h - r) // 2:(h - r) // 2 + r, (w - r) // 2:(w - r) // 2 + r])[0] > 2 * TOLERANCE
        page.close()
    finally:
        app.stop()


# --------------------------------------------------------------------------- zoom and pan in the browser

#: The ball's volume: 32³ (a smooth silhouette), its frames 64² (R = 2N).
N_BALL = 32


def ball(n: int = N_BALL, radius: float = 0.15) -> torch.Tensor:
    """A light grey ball of the given radius at the centre, its edge a quarter-voxel logistic ramp:
    ``(4, N, N, N)``. Its EA silhouette (opacity ½, summed over depth) has a radius of about 0.2."""
    from mitsuba_platonic.volume import voxel_centres

    r = voxel_centres(n).norm(dim=-1)
    density = torch.sigmoid(-(r - radius) / (2.0 / n / 4.0))
    return torch.cat([torch.full((3, n, n, n), 0.8, dtype=torch.float64), density[None]]).float()


@pytest.fixture(scope="module")
def ball_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ball") / "ball.npz"
    np.savez(path, volume=ball().numpy())
    return path


@pytest.fixture(scope="module")
def ball_server(ball_file, tmp_path_factory):
    s = Server([ball_file], tmp_path_factory.mktemp("ball-cwd"))
    yield s
    s.stop()


def _window_of(page, pattern: str = "full") -> tuple:
    """The latest frame line matching ``pattern``: (its match, the Window it names: None when full)."""
    m = _frame(page, pattern)
    return m, _window_in(page.get_by_text(re.compile(r"^frame \d+: .*" + pattern)).inner_text())


def _window_in(line: str):
    """The Window a frame line names: None when full."""
    from mitsuba_platonic.viewer.scene import Window

    z = WINDOW.search(line)
    assert z, line
    window = Window(float(z.group(1)), (float(z.group(2)), float(z.group(3))))
    return None if window.full else window


def _silhouette(image: np.ndarray) -> tuple:
    """(area in pixels, (row, column) centroid) of the pixels brighter than halfway from the
    background grey to the ball's brightest."""
    grey = image.astype(float).mean(-1)
    bg = float(np.median(grey[0]))                                         # the top row: background
    mask = grey > (bg + grey.max()) / 2
    rows, cols = np.nonzero(mask)
    return float(mask.sum()), np.array([rows.mean(), cols.mean()])


def _expected(volume, renderer: str, r: int, window, page=None) -> np.ndarray:
    """The renderer's front view through ``window``, the central R×R square of the frame at ``page``'s
    canvas' aspect (the path tracer's samples follow its square renders: the frame's, not the square
    frame's), else the square frame."""
    aspect = 1.0
    if page is not None:
        box = page.locator("canvas").first.bounding_box()
        aspect = round(box["width"] / box["height"], 3)
    image = render_frame(volume, (0.0, 0.0, 1.0), renderer, "EA", r, window=window, aspect=aspect).image
    h, w = image.shape[:2]
    return image[(h - r) // 2:(h - r) // 2 + r, (w - r) // 2:(w - r) // 2 + r]


def _same(shown: np.ndarray, expected: np.ndarray, what) -> None:
    mean, p95 = _difference(shown, expected)
    assert mean <= TOLERANCE and p95 <= TOLERANCE_MAX, (what, mean, p95)


def _page(browser, server):
    page = browser.new_page(viewport={"width": 1400, "height": 600})
    page.set_default_timeout(WAIT_MS)
    page.goto(server.url)
    return page


def test_zoom_and_pan_buttons_change_the_frame_as_the_renderer_says(browser, ball_server, ball_file):
    """The page's pan and zoom buttons move the browser's camera (as the orbit buttons do); every
    frame is the renderer's through the window the page prints; the ball's centroid moves against
    the pan, a quarter of the frame (R/4 pixels) per click, and its silhouette grows 2× per zoom."""
    from mitsuba_platonic.viewer.scene import Window

    volume = read_volume_file(ball_file)[0]
    r = 2 * N_BALL
    page = _page(browser, ball_server)
    try:
        _frame(page)
        _choose(page, 2, str(r))
        _, window = _window_of(page, rf"full, \d+×{r} px.*zoom 1\.000×, centre \(\+0\.000, \+0\.000\)")
        assert window is None
        shown = _shown(page, r)
        _same(shown, _expected(volume, "closed form", r, None), "whole")
        area0, centre0 = _silhouette(shown)
        assert abs(centre0 - (r - 1) / 2).max() < SHIFT_TOLERANCE, centre0        # the ball sits in the middle

        page.get_by_role("button", name="pan right").click()                # a quarter of the frame: 0.5
        _window_of(page, rf"full, \d+×{r} px.*zoom 1\.000×, centre \(\+0\.500, \+0\.000\)")
        page.get_by_role("button", name="pan up").click()
        _, window = _window_of(page, rf"full, \d+×{r} px.*zoom 1\.000×, centre \(\+0\.500, \+0\.500\)")
        assert window == Window(1.0, (0.5, 0.5))
        panned = _shown(page, r)
        _same(panned, _expected(volume, "closed form", r, window), window)
        _, moved = _silhouette(panned)
        expected = np.array([+window.centre[1], -window.centre[0]]) * window.zoom * r / 2
        assert np.allclose(expected, [r / 4, -r / 4])                       # down and left: the camera went up, right
        assert abs(moved - centre0 - expected).max() < SHIFT_TOLERANCE, (moved - centre0, expected)

        page.get_by_role("button", name="reset zoom and pan").click()
        _window_of(page, rf"full, \d+×{r} px.*zoom 1\.000×, centre \(\+0\.000, \+0\.000\)")
        _same(_shown(page, r), shown, "reset")

        page.get_by_role("button", name="zoom in").click()
        _, window = _window_of(page, rf"full, \d+×{r} px.*zoom 2\.000×, centre \(\+0\.000, \+0\.000\)")
        assert window == Window(2.0)
        zoomed = _shown(page, r)
        _same(zoomed, _expected(volume, "closed form", r, window), window)
        area, centre = _silhouette(zoomed)
        scale = math.sqrt(area / area0)
        assert abs(scale / 2.0 - 1) < SCALE_TOLERANCE, scale
        assert abs(centre - centre0).max() < SHIFT_TOLERANCE, (centre, centre0)
        print(f"zoom 2: silhouette ×{scale:.3f}; pan (0.5, 0.5): centroid moved {moved - centre0} pixels")

        page.get_by_role("button", name="pan left").click()                 # a quarter of the 2× frame: 0.25
        _choose(page, 2, str(N_BALL))                                        # the lit renderers at 32²
        _, window = _window_of(page, rf"full, \d+×{N_BALL} px.*zoom 2\.000×, centre \(-0\.250, \+0\.000\)")
        assert window == Window(2.0, (-0.25, 0.0))
        for renderer in ("closed form", "marcher", "single scattering", "path tracer"):   # each draws the window
            if renderer != "closed form":
                _choose(page, 0, renderer)
                page.get_by_text(re.compile(rf"^{renderer} \(.*zoom 2×, centre \(-0\.250, \+0\.000\)")).wait_for()
            _, seen = _window_of(page, rf"full, \d+×{N_BALL} px.*zoom 2\.000×, centre \(-0\.250, \+0\.000\)")
            assert seen == window
            _same(_shown(page, N_BALL), _expected(volume, renderer, N_BALL, window, page), renderer)
    finally:
        page.close()


def test_the_wheel_zooms_and_a_right_drag_pans_the_frame(browser, ball_server, ball_file):
    """viser's own controls: the wheel dollies the browser's camera (the frame zooms by 1 / (d tan(F/2))),
    a right-button drag trucks it (look_at and position together: the frame pans); the frame is
    the renderer's through the window the page prints, the silhouette scales by its zoom, its
    centroid moves as its centre says, and on the canvas as far as the mouse did (within
    :data:`DRAG_TOLERANCE`): the ball stays under the mouse."""
    volume = read_volume_file(ball_file)[0]
    r = 2 * N_BALL
    page = _page(browser, ball_server)
    try:
        _frame(page)
        _choose(page, 2, str(r))
        _window_of(page, rf"full, \d+×{r} px.*zoom 1\.000×")
        area0, centre0 = _silhouette(_shown(page, r))
        box = page.locator("canvas").first.bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        page.mouse.move(x, y)
        for _ in range(6):
            page.mouse.wheel(0, -100)                                        # towards the ball
            time.sleep(0.2)
        line, zoomed = _rest(page, rf"full, \d+×{r} px.*zoom (?!1\.000)", r)     # the dolly's smoothing settles
        window = _window_in(line)
        assert window is not None and 1.1 < window.zoom < 4.0 and window.centre == (0.0, 0.0), window
        _same(zoomed, _expected(volume, "closed form", r, window), window)
        area, centre = _silhouette(zoomed)
        scale = math.sqrt(area / area0)
        assert abs(scale / window.zoom - 1) < SCALE_TOLERANCE, (scale, window)

        page.mouse.move(x, y)
        page.mouse.down(button="right")
        drag = np.array([4.0, -6.0])                                         # (down, left) canvas pixels a step
        for step in range(1, 11):
            page.mouse.move(x + drag[1] * step, y + drag[0] * step)          # drag the scene left and down
            time.sleep(0.05)
        page.mouse.up(button="right")
        line, shot = _rest(page, rf"full, \d+×{r} px.*centre \((?!\+0\.000, \+0\.000)", r)
        panned = _window_in(line)
        assert panned is not None and panned.centre != (0.0, 0.0), panned
        assert abs(panned.zoom - window.zoom) < 1e-2                          # a pan keeps the distance
        _same(shot, _expected(volume, "closed form", r, panned), panned)
        _, moved = _silhouette(shot)
        expected = np.array([+panned.centre[1], -panned.centre[0]]) * panned.zoom * r / 2
        assert abs(moved - centre - expected).max() < SHIFT_TOLERANCE, (moved - centre, expected, panned)
        assert expected[1] < -1.0 and expected[0] > 1.0, expected             # the ball followed the drag
        on_canvas = (moved - centre) * min(box["width"], box["height"]) / r  # frame pixels → canvas pixels
        mouse = 10 * drag
        assert abs(on_canvas - mouse).max() < DRAG_TOLERANCE * abs(mouse).max(), (on_canvas, mouse, panned)
        print(f"wheel: {window}, silhouette ×{scale:.3f}; right-drag: {panned}, centroid moved {moved - centre} "
              f"frame pixels, {on_canvas} canvas pixels for the mouse's {mouse}")
    finally:
        page.close()


def _camera_view(placed: bool, since_connect: float):
    """A ClientView's camera state alone (no browser, no GUI): the initial camera drawn, a canvas 7:3."""
    import threading
    from types import SimpleNamespace

    from mitsuba_platonic.viewer import app as A
    cam = SimpleNamespace(fov=A.FOV, image_height=300, image_width=700, position=(0.0, 0.0, A.DISTANCE),
                          look_at=(0.0, 0.0, 0.0), min_orbit_distance=0.01, max_orbit_distance=1e4)
    v = object.__new__(A.ClientView)
    v.client, v.lock, v.wake = SimpleNamespace(camera=cam), threading.Lock(), threading.Event()
    v.view, v.window, v.last_move, v.limits = np.array([0.0, 0.0, 1.0]), None, 0.0, (0.01, 1e4)
    v.connected, v.placed = time.monotonic() - since_connect, placed
    return v


def test_the_browsers_default_camera_before_the_initial_one_is_not_drawn():
    """A page may report the browser's default camera (the back, zoom 0.8) before the initial one: it
    is not drawn; once the page has echoed the initial camera, or CONNECT_S after the connection,
    every report is the user's."""
    from types import SimpleNamespace

    from mitsuba_platonic.viewer.app import CONNECT_S
    from mitsuba_platonic.viewer.start import DISTANCE
    default = SimpleNamespace(position=(0.0, 0.0, -DISTANCE / 0.8), look_at=(0.0, 0.0, 0.0))
    initial = SimpleNamespace(position=(0.0, 0.0, DISTANCE), look_at=(0.0, 0.0, 0.0))
    v = _camera_view(placed=False, since_connect=0.0)
    v._camera(default)
    assert not v.wake.is_set() and tuple(v.view) == (0.0, 0.0, 1.0) and not v.placed
    v._camera(initial)                                     # the initial camera's echo: placed, nothing to draw
    assert v.placed and not v.wake.is_set() and v.window is None
    v._camera(default)                                     # from now on the user's camera
    assert v.wake.is_set() and v.view[2] < -0.99
    late = _camera_view(placed=False, since_connect=CONNECT_S + 0.5)
    late._camera(default)                                  # no echo came in time: the report counts
    assert late.placed and late.wake.is_set() and late.view[2] < -0.99


def test_a_pages_camera_that_is_not_finite_or_far_off_is_ignored_with_one_line(capsys):
    """A camera message with NaN, or 1e308 (past any float's square), is one line in the log: the view
    and the frame stay as they were, nothing is rendered and no traceback reaches viser's log."""
    from types import SimpleNamespace

    v = _camera_view(placed=True, since_connect=5.0)
    for position, look_at in (((math.nan, 0.0, 4.0), (0.0, 0.0, 0.0)), ((1e308, 1e308, 1e308), (0.0, 0.0, 0.0)),
                              ((0.0, 0.0, 4.0), (0.0, -1e308, 0.0))):
        v._camera(SimpleNamespace(position=position, look_at=look_at))
        assert not v.wake.is_set() and tuple(v.view) == (0.0, 0.0, 1.0) and v.window is None
        err = capsys.readouterr().err
        assert err.startswith("platonic view: ignored a camera from a page: ") and err.count("\n") == 1, err
    v._camera(SimpleNamespace(position=(4.0, 0.0, 0.0), look_at=(0.0, 0.0, 0.0)))   # a good one still counts
    assert v.wake.is_set() and v.view[0] > 0.99


def test_a_pages_seed_outside_the_generators_range_is_refused_with_one_line(capsys):
    """A generation run's seed of 2⁶³ (or NaN, or 1e308) is refused as ``generate --seed`` refuses it:
    one line, no latent drawn; a walk outside [0, 1] likewise; 2⁶³ − 1 is drawn."""
    import threading
    from types import SimpleNamespace

    from mitsuba_platonic.viewer import app as A

    drawn = []
    scene = SimpleNamespace(show_latent=lambda a, b, t: drawn.append((a, b, t)))
    v = object.__new__(A.ClientView)
    v.app = SimpleNamespace(scene=scene, scene_lock=threading.RLock(), volume_changed=lambda: None)
    for seed, walk in ((2 ** 63, 0.0), (math.nan, 0.0), (1e308, 0.0), (-1, 0.0), (1, 2.0), (1, math.nan)):
        v.seed, v.seed_b, v.walk = (SimpleNamespace(value=seed), SimpleNamespace(value=2),
                                    SimpleNamespace(value=walk))
        v._latent()
        err = capsys.readouterr().err
        assert err.startswith("platonic view: ignored ") and err.count("\n") == 1 and "Traceback" not in err, err
    assert drawn == []
    v.seed, v.walk = SimpleNamespace(value=A.MAX_SEED), SimpleNamespace(value=0.5)
    v._latent()
    assert drawn == [(A.MAX_SEED, 2, 0.5)]


def test_a_pages_spp_resolution_and_compare_past_the_controls_are_held_to_them(capsys):
    """spp 1e9 (the slider stops at 64) was a Dr.Jit error: it is held to 64, with one line in the log;
    a resolution past the choices is held to the nearest; a compare pair the page does not offer is
    refused with one line (the one renderer drawn), an offered one keys both renderers' frame."""
    import threading
    from types import SimpleNamespace

    from mitsuba_platonic.viewer import app as A

    v = _camera_view(placed=True, since_connect=5.0)
    v.app = SimpleNamespace(scene=SimpleNamespace(volume=torch.zeros(4, N, N, N)), version=0)
    v.renderer, v.formation, v.low = (SimpleNamespace(value="path tracer"), SimpleNamespace(value="EA"),
                                      SimpleNamespace(value=False))
    v.compare, v.layout = SimpleNamespace(value=A.COMPARE_OFF), SimpleNamespace(value="side by side")
    v.resolution, v.spp = SimpleNamespace(value=str(N)), SimpleNamespace(value=1e9)
    v.beside = None                                        # a volume file: no input to draw beside the frame
    key, _, _ = v._request()
    assert key[4] == A.MAX_SPP and key[3] == N
    assert capsys.readouterr().err == f"platonic view: ignored path tracer spp {1e9!r} from a page: held to 64 (1 … 64)\n"
    v.resolution, v.spp = SimpleNamespace(value="100000"), SimpleNamespace(value=4)
    key, _, _ = v._request()
    assert key[4] == 4 and key[3] == resolutions_for(N)[-1]
    assert "ignored resolution '100000' from a page: held to" in capsys.readouterr().err
    v.compare = SimpleNamespace(value="marcher vs path tracer")     # a compare request: both renderers in the key
    key, _, _ = v._request()
    assert key[1] == ("compare", "marcher vs path tracer", "side by side")
    v.compare, v.layout = SimpleNamespace(value="closed form vs oracle"), SimpleNamespace(value="side by side")
    key, _, _ = v._request()                               # a pair the page does not offer: one renderer, one line
    assert key[1] == "path tracer"
    assert capsys.readouterr().err == ("platonic view: ignored compare 'closed form vs oracle' from a page: expected "
                                       "one of ['closed form vs marcher', 'marcher vs path tracer']\n")
