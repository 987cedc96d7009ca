"""What ``platonic view`` does before torch has loaded: check the port and SOURCE, start the server.

Light on purpose (numpy and the standard library at the top; viser in :func:`start_server`): the
command checks everything a user can get wrong here, starts the page's server and prints its
address, and only then imports torch (about 2 s on 2 cores) and makes the scene, while the
browser loads the page (:mod:`mitsuba_platonic.cli.viewer`).

- :func:`check_port`: a busy ``--port`` as a one-line error (viser would quietly take the next one).
- :func:`check_source`: SOURCE's one-line errors (missing, neither file nor folder, ``--photo``
  with a file, a damaged volume file), and a volume file's checked array, read with numpy alone.
- :func:`start_server`: the viser server with the initial camera (:data:`DISTANCE`, :data:`FOV`),
  its control panel docked to the right of the canvas (the canvas is the rest of the window, so
  the controls never cover the object), and no page content yet; a page that connects now waits, empty, until
  :class:`~.app.ViewerApp` registers its connect handler (viser calls it then for the pages
  already connected) and renders the first frame.
"""

from __future__ import annotations

import contextlib
import errno
import io
import math
import socket
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np

from ..errors import UserError
from ..files.volume_io import read_volume_array
from ..runtime import budget

__all__ = ["DISTANCE", "FOV", "check_port", "check_source", "volume_title", "start_server", "stop_server",
           "address"]

#: Distance of the initial camera from the centre (the cube is [−1, 1]³).
DISTANCE = 4.0
#: viser's vertical field of view, 2 atan(1/DISTANCE) ≈ 28.1°: the initial camera shows the cube's
#: cross-section [−1, 1] over the canvas' height, the frame at zoom 1 (:func:`~.scene.camera_window`).
FOV = 2.0 * math.atan(1.0 / DISTANCE)

PathLike = Union[str, Path]


def check_port(host: str, port: int) -> None:
    """Raise :class:`UserError` naming ``--host`` or ``--port`` unless ``host`` resolves to an address
    of this machine and ``host:port`` can be bound now (``port`` 0: any free port of it), before
    anything else: viser itself would quietly move to the next free port, and with an address that
    cannot be resolved or is not this machine's it would wait, printing nothing."""
    try:
        found = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError, ValueError) as e:
        raise UserError(f"--host {host}: not an address or a name that resolves here "
                        f"({getattr(e, 'strerror', None) or e}); pass an address of this machine, e.g. 127.0.0.1 "
                        f"(this machine only) or 0.0.0.0 (every network it is on)") from None
    family, kind, proto, _, address = found[0]
    with socket.socket(family, kind, proto) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(address)
        except OSError as e:
            if e.errno == errno.EADDRNOTAVAIL:
                raise UserError(f"--host {host}: {address[0]} is not an address of this machine ({e.strerror}); "
                                f"pass one of its addresses, e.g. 127.0.0.1 (this machine only) or 0.0.0.0 (every "
                                f"network it is on)") from None
            raise UserError(f"--port {port}: {host}:{port} cannot be used ({e.strerror or e}); choose another "
                            f"--port (0 picks a free one)") from None


def check_source(source: PathLike, photo: Optional[PathLike] = None) -> Optional[np.ndarray]:
    """SOURCE's checks that need no torch: :class:`UserError` where it is missing, neither a file
    nor a folder, a file with ``photo``, or a volume file that does not hold a valid volume;
    else a volume file's checked ``(C, N, N, N)`` float32 array, or None for a folder (a run:
    :func:`~.scene.open_source` reads its checkpoint)."""
    path = Path(source)
    if not path.exists():
        raise UserError(f"SOURCE {str(path)!r} does not exist; expected a volume file (.npz, .vol) or a run folder")
    if path.is_file():
        if photo is not None:
            raise UserError(f"--photo needs a reconstruction run folder as SOURCE, got the file {str(path)!r}")
        return read_volume_array(path, fits=budget.memory_check("use a smaller volume"))   # its declared size
    if not path.is_dir():
        raise UserError(f"SOURCE {str(path)!r} is neither a file nor a folder")
    return None


def volume_title(source: PathLike, shape: Sequence[int]) -> str:
    """The page's title for a volume file of ``(C, N, N, N)`` ``shape``."""
    return f"{Path(source).name} ({shape[0]} channel(s), {shape[-1]}³)"


def start_server(host: str = "127.0.0.1", port: int = 8080):
    """A viser server on ``host:port`` (0: a free port) with the page's initial camera and nothing
    else; :class:`UserError` naming ``--port`` where the port is taken (:func:`check_port`)."""
    import viser  # lazy: the web library, for the server only (scene.py imports this module's checks)

    check_port(host, port)
    with contextlib.redirect_stdout(io.StringIO()):      # viser's own banner: the command prints the address
        server = viser.ViserServer(host=host, port=port, label="platonic view", verbose=False)
    if port and server.get_port() != port:               # taken between the check and the bind
        stop_server(server)
        raise UserError(f"--port {port}: {host}:{port} is in use; choose another --port (0 picks a free one)")
    server.gui.main_panel.dock_right()                   # the controls beside the canvas, not over the object
    server.scene.set_up_direction("+y")
    server.initial_camera.position = (0.0, 0.0, DISTANCE)
    server.initial_camera.look_at = (0.0, 0.0, 0.0)
    server.initial_camera.up = (0.0, 1.0, 0.0)
    server.initial_camera.fov = FOV
    return server


def stop_server(server) -> None:
    """Stop ``server`` (quietly: viser prints on stopping)."""
    with contextlib.redirect_stdout(io.StringIO()):
        server.stop()


def address(host: str, port: int) -> str:
    """The page's address: ``http://host:port`` (``[host]`` for an IPv6 one)."""
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"
