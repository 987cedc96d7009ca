"""``platonic view SOURCE``: an interactive web viewer on the project's renderers (:mod:`mitsuba_platonic.viewer`).

Opens SOURCE (a volume file or a run folder; ``--photo`` for a reconstruction run), starts the
page on ``--host``:``--port`` (127.0.0.1 by default: only this machine), prints its address and
serves until Ctrl-C (exit 130, as every command's Ctrl-C). The web library (viser, the ``viewer``
extra) is imported here, in the handler, and nowhere else outside :mod:`mitsuba_platonic.viewer`.

The start-up order, so that the browser loads the page while torch loads (about 2 s on 2 cores):
``--port``'s range, ``--out``, viser installed, the port free and SOURCE (missing, of the wrong
kind, a damaged volume file: a volume file is read and checked with numpy) are checked first, each
a one-line error with exit 2; then, for a volume file, the server starts and the address is
printed before torch is imported (:mod:`mitsuba_platonic.viewer.start`; the command line parses
``view`` without the other commands' modules, :func:`mitsuba_platonic.cli.build_parser`), and
the scene is made; a page that connects meanwhile waits for it and then gets its GUI and the first
frame (:class:`~mitsuba_platonic.viewer.app.ViewerApp`, which renders that frame at once). A run
folder likewise: the address first, then torch, the checkpoint, the model and the held-out inputs
load while the browser loads the page (a second line names the run's step once it is open; a
checkpoint that cannot be read is still the one-line error, exit 2, after the address).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .args import CLIError, add_background, check_out_folder

__all__ = ["add_view"]


def _cmd_view(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise CLIError(f"--port: expected 0 … 65535, got {args.port}")
    from ..viewer.start import address, check_port, check_source, start_server, stop_server, volume_title

    check_port(args.host, args.port)                       # first: --host resolved and bound, a busy port at once
    out = Path(args.out)
    check_out_folder(out)
    if args.background is not None and args.photo is None:
        raise CLIError("--background masks the --photo; pass --photo FILE with it, or leave it out")
    try:
        import viser  # noqa: F401  (only to say what is missing, before any work)
    except ImportError:
        raise CLIError("the viewer needs the 'viewer' extra: pip install 'mitsuba-platonic[viewer]' "
                       "(or pip install -e '.[viewer]' in a checkout)") from None
    array = check_source(args.source, args.photo)          # a volume file's array (numpy), None for a run folder
    server = start_server(args.host, args.port)
    app = None
    try:
        title = volume_title(args.source, array.shape) if array is not None else \
            f"{Path(args.source).name} (a run folder: its checkpoint loads now)"
        url = address(args.host, server.get_port())
        print(f"platonic view: {title} at {url} (Ctrl-C stops it; exports go to {out})", flush=True)
        if args.host not in ("127.0.0.1", "localhost", "::1"):
            print(f"platonic view: --host {args.host}: reachable from other machines on that network",
                  file=sys.stderr, flush=True)
        scene = _open(args, array)                         # torch loads while the browser loads the page
        if array is None:
            print(f"platonic view: {scene.title}", flush=True)
        from ..viewer.app import ViewerApp

        app = ViewerApp(scene, out, host=args.host, port=args.port, server=server)
        while True:
            time.sleep(3600)
    finally:
        if app is not None:
            app.stop()
        else:
            stop_server(server)


def _open(args: argparse.Namespace, array):
    """SOURCE as the viewer's scene (torch loads here); ``array``: a volume file's, checked already."""
    import torch

    from ..viewer.scene import open_source

    if args.threads:
        torch.set_num_threads(args.threads)
    return open_source(args.source, args.photo, array, background=args.background)


def add_view(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser(
        "view", help="an interactive web viewer: orbit, zoom and pan a volume or a run's volumes, rendered live by the "
             "project's renderers",
        description="Start a local web page that shows SOURCE rendered on this machine by the project's renderers "
                    "(closed form, the ray marcher, single scattering, the path tracer) from the browser's camera "
                    "(orbit, zoom, pan): "
                    "a low-resolution frame while the camera moves, the full one when it stops, with the frame time "
                    "and the renderer's settings. SOURCE: a volume file (.npz, .vol), or a run folder (a "
                    "reconstruction run: step through its held-out inputs; a generation run: draw latents, walk "
                    "between two). The page saves the current view (PNG) and the volume (.npz, .vol, .ply) into "
                    "--out, and only there. Needs the 'viewer' extra (viser).")
    p.add_argument("source", metavar="SOURCE", help="a .npz or .vol volume file, or a run folder")
    p.add_argument("--photo", default=None, metavar="FILE",
                   help="with a reconstruction run as SOURCE: reconstruct this photo and show it beside the view "
                        "(RGBA, or RGB on white with --background white)")
    add_background(p, "an RGB --photo")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default: %(default)s, this machine only); pass 0.0.0.0 (or this "
                        "machine's address) to share the page with other machines on purpose: anyone who "
                        "reaches it can drive the renderers and write exports into --out")
    p.add_argument("--port", type=int, default=8080, help="port to listen on; 0 picks a free one (default: %(default)s)")
    p.add_argument("--out", default="view-exports",
                   help="folder the page's exports are written into, created on the first one (default: %(default)s/)")
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: as torch sets them)")
    p.set_defaults(handler=_cmd_view, interrupted="the viewer stopped; its exports (if any) are whole files in --out")
