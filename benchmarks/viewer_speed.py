"""Benchmark: how fast ``platonic view`` answers (issue 45's targets; a benchmark, not a test).

    .venv/bin/python benchmarks/viewer_speed.py [--resolution 32] [--pixels 256] [--seconds 5] [--source FILE|RUN]

Prints figures only:

1. first frame: seconds from starting ``platonic view SOURCE`` (a 32³ test volume written to a
   temporary .npz unless ``--source``) to the first frame shown in headless Chromium (the page
   opened as soon as the command prints its address; the browser started before the clock): the
   page's first look (the closed form at the volume's resolution, drawn while the canvas settles)
   and its first full frame (the page's resolution, 128²). Target: within 5 s on 2 cores.
2. frames/s through the marcher while orbiting, on the server alone: ``render_frame`` of the marcher
   at ``--pixels``² for views 3° apart around the object, plus what the page adds per frame
   (enlarging, padding to a 16:9 canvas, PNG and JPEG encoding), after one warm-up frame.
   Target: ≥ 10 frames/s at 32³ and 256×256 pixels.
3. frames/s in the browser while the mouse drags the camera round for ``--seconds`` (a mouse
   event every 1/60 s, as a hand's drag delivers them): the page's own frame counter over the
   drag, with "low resolution while moving" on (the viewer's default: a quarter of the resolution,
   at least the volume's) and off (every frame at ``--pixels``²); beside it how often the mouse
   moved and how many frames the browser drew (its ``requestAnimationFrame`` count) in a
   ``--window`` of 1280×720. The page can show at most one new frame per camera message, and a
   headless Chromium without a GPU draws its WebGL canvas in software (SwiftShader) on the same
   cores as the server: there the browser's own drawing, not the server, bounds the figure (a
   smaller ``--window`` shows it).

Chromium: Debian's (``apt-get install chromium``), driven by playwright; without it, only 2 is printed.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Tuple

import numpy as np
import torch

from mitsuba_platonic.views import from_angles
from mitsuba_platonic.volume import test_volume

#: The canvas the server-side timing renders for: the page's frames are W×H at the canvas' aspect.
ASPECT = 16 / 9
FRAME = re.compile(r"frame (\d+): ([0-9.]+) ms, (full|moving), \d+×(\d+) px")


def server_side(volume: torch.Tensor, pixels: int, frames: int = 40) -> None:
    from viser._image_encoding import cv2_imencode_with_fallback

    from mitsuba_platonic.viewer.scene import render_frame

    def one(i: int, fmt: str) -> float:
        t = time.perf_counter()
        frame = render_frame(volume, tuple(from_angles(3.0 * i, 20.0).tolist()), "marcher", "EA", pixels, aspect=ASPECT)
        cv2_imencode_with_fallback(fmt, frame.image, jpeg_quality=90, channel_ordering="rgb")
        return time.perf_counter() - t

    start = time.perf_counter()
    one(0, "png")
    print(f"marcher, first frame in this process (Dr.Jit traces its kernel): {time.perf_counter() - start:.2f} s")
    for fmt in ("jpeg", "png"):
        render = []
        total = []
        for i in range(1, frames + 1):
            t = time.perf_counter()
            frame = render_frame(volume, tuple(from_angles(3.0 * i, 20.0).tolist()), "marcher", "EA", pixels,
                                 aspect=ASPECT)
            render.append(time.perf_counter() - t)
            cv2_imencode_with_fallback(fmt, frame.image, jpeg_quality=90, channel_ordering="rgb")
            total.append(time.perf_counter() - t)
        h, w = frame.image.shape[:2]
        print(f"server: marcher at {volume.shape[-1]}³, {w}×{h} px (a 16:9 canvas), {frames} views 3° apart: render "
              f"{1000 * np.median(render):.0f} ms median, with the page's {fmt.upper()} "
              f"{1000 * np.median(total):.0f} ms → {1 / np.median(total):.1f} frames/s")


def start_view(source: Path, cwd: Path):
    proc = subprocess.Popen([sys.executable, "-m", "mitsuba_platonic.cli", "view", str(source), "--port", "0"],
                            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    started = time.monotonic()
    lines: list = []
    threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True).start()
    while not lines and proc.poll() is None and time.monotonic() - started < 120:
        time.sleep(0.02)
    if not lines:
        proc.kill()
        raise SystemExit(f"platonic view printed no address: {proc.stderr.read()}")
    url = re.search(r"http://127\.0\.0\.1:\d+", lines[0]).group(0)
    return proc, started, url, time.monotonic() - started


#: Counts the page's animation frames (what the browser drew) in ``window.__drawn``; once per page.
RAF_COUNTER = """() => { if (window.__drawn === undefined) { window.__drawn = 0;
    const tick = () => { window.__drawn++; requestAnimationFrame(tick); }; requestAnimationFrame(tick); } }"""


def frame_line(page):
    """The page's frame line (``frame N: T ms, full|moving, W×R px, …``: R the resolution, along the
    landscape canvas' height) as a :data:`FRAME` match, or None."""
    return FRAME.search(page.get_by_text(re.compile(r"^frame \d+:")).inner_text())


def frame_count(page) -> int:
    m = frame_line(page)
    return int(m.group(1)) if m else 0


def window_size(text: str) -> Tuple[int, int]:
    """``--window``: WxH, two positive whole numbers of pixels."""
    m = re.fullmatch(r"(\d+)x(\d+)", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise argparse.ArgumentTypeError(f"expected WxH in pixels, e.g. 1280x720, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def in_browser(source: Path, pixels: int, seconds: float, window: Tuple[int, int] = (1280, 720)) -> None:
    from playwright.sync_api import sync_playwright

    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        print("browser: no chromium (apt-get install chromium): skipped")
        return
    with sync_playwright() as p, tempfile.TemporaryDirectory() as cwd:
        browser = p.chromium.launch(executable_path=exe, headless=True,
                                    args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"])
        page = browser.new_page(viewport={"width": window[0], "height": window[1]})
        page.set_default_timeout(60_000)
        proc, started, url, address = start_view(source, Path(cwd))
        try:
            page.goto(url)
            page.get_by_text(re.compile(r"^frame \d+: ")).wait_for()
            look = time.monotonic() - started
            page.get_by_text(re.compile(r"^frame \d+: .*full")).wait_for()
            first = time.monotonic() - started
            print(f"first frame: {look:.2f} s after the command (the first look: the closed form at the volume's "
                  f"resolution), the first full frame (at the page's resolution) {first:.2f} s (its address after "
                  f"{address:.2f} s)")
            page.get_by_role("combobox").nth(0).click()
            page.get_by_role("option", name="marcher", exact=True).click()
            page.get_by_role("combobox").nth(2).click()
            page.get_by_role("option", name=str(pixels), exact=True).click()
            page.get_by_text(re.compile(rf"^frame \d+: .*full, \d+×{pixels} px")).wait_for()
            for low in (True, False):
                if not low:
                    page.get_by_text("low resolution while moving").click()
                    time.sleep(0.5)
                box = page.locator("canvas").first.bounding_box()
                x, y = box["x"] + box["width"] * 0.3, box["y"] + box["height"] * 0.5
                page.mouse.move(x, y)
                page.mouse.down()
                page.evaluate(RAF_COUNTER)
                drawn0 = page.evaluate("window.__drawn")
                before, t0 = frame_count(page), time.monotonic()
                steps = 0
                seen: dict = {}
                read = t0
                while time.monotonic() - t0 < seconds:
                    # a hand's drag: a mouse event every 1/60 s, as a browser delivers them
                    steps += 1
                    page.mouse.move(x + 4 * (steps % 100), y + (steps % 20), steps=1)
                    if time.monotonic() - read > 0.25:       # the frame line now and then: reading it costs the page
                        read = time.monotonic()
                        m = frame_line(page)
                        if m:
                            seen[m.group(1)] = (m.group(3), m.group(4), float(m.group(2)))
                    time.sleep(max(0.0, t0 + steps / 60 - time.monotonic()))
                after, t1 = frame_count(page), time.monotonic()
                drawn = (page.evaluate("window.__drawn") - drawn0) / (t1 - t0)
                page.mouse.up()
                moving = [v for v in seen.values() if v[0] == "moving"]
                kinds = sorted({f"{q} {r}²" for q, r, _ in seen.values()})
                print(f"browser: marcher, dragging for {t1 - t0:.1f} s with low resolution while moving "
                      f"{'on' if low else 'off'}: {(after - before) / (t1 - t0):.1f} frames/s shown "
                      f"({', '.join(kinds)} seen; render {np.median([v[2] for v in moving or seen.values()]):.0f} ms "
                      f"median; the mouse moved {steps / (t1 - t0):.1f} times/s, the browser drew "
                      f"{drawn:.1f} frames/s at {window[0]}×{window[1]})")
        finally:
            proc.send_signal(2)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
            browser.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=32, help="test volume N (default: 32)")
    parser.add_argument("--pixels", type=int, default=256, help="the frame's shorter side in pixels (a multiple of N; the server-side timing renders a 16:9 frame)")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each drag in the browser")
    parser.add_argument("--source", default=None, help="a volume file or run folder instead of the test volume")
    parser.add_argument("--window", type=window_size, default=(1280, 720),
                        help="the browser's window, WxH (default: 1280x720)")
    parser.add_argument("--no-browser", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(min(2, os.cpu_count() or 1))
    print(f"torch threads {torch.get_num_threads()}, {os.cpu_count()} cores, load average "
          f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    volume = test_volume(args.resolution, "figure", "ea")[0]
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(args.source) if args.source else Path(tmp) / f"figure{args.resolution}.npz"
        if not args.source:
            np.savez(source, volume=volume.numpy())
        if not args.no_browser:
            in_browser(source, args.pixels, args.seconds, args.window)
        server_side(volume, args.pixels)


if __name__ == "__main__":
    main()
