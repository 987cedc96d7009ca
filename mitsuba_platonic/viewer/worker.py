"""The path tracer's worker: a process of its own, at a lower priority, one pass at a time.

The path tracer's frames (:func:`~.scene.render_frame`: the mean of passes of
:data:`~.scene.PASS_SPP` spp, :func:`~.scene.path_pass`) take seconds; rendered in the server's
process they held every page's frames (one render lock; Dr.Jit's threads shared with the
marcher: a marcher frame beside a path trace waited for it in a thread of its own, measured 5 s).
Here they run in a child process (spawned, ``os.nice`` :data:`NICE`), so that the server's own
renders (closed form, marcher, single scattering) take the CPU first, and one pass at a time:

- :meth:`PathWorker.submit` queues a page's next pass; each page has one slot, a new pass replaces
  the queued one (superseded), :meth:`PathWorker.cancel` empties it (a camera move, a settings
  change, a closed tab). The pass in flight cannot be stopped inside Dr.Jit: its result comes back
  and the page drops it when it is stale (:class:`~.app.ClientView`).
- The worker takes the slots round-robin, so two pages' path traces interleave pass by pass.
- The volume travels to the child once per version (the scene's counter), not with every pass.

A child that dies (killed, out of memory) fails the pass in flight with :class:`WorkerError`; the next
pass starts a new one.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from collections import OrderedDict
from concurrent.futures import Future
from typing import Any, Optional, Tuple

import numpy as np

__all__ = ["PathWorker", "WorkerError", "NICE", "serve", "main"]

#: How much lower the child's scheduling priority is than the server's (``os.nice``).
NICE = 10


class WorkerError(RuntimeError):
    """The path tracer's worker failed a pass (its message says why)."""


class _Pipe:
    """Pickled messages over a pair of binary streams (the child's stdin and its private stdout)."""

    def __init__(self, reader: Any, writer: Any):
        self.reader, self.writer = reader, writer

    def send(self, message: object) -> None:
        pickle.dump(message, self.writer, protocol=pickle.HIGHEST_PROTOCOL)
        self.writer.flush()

    def recv(self) -> object:
        return pickle.load(self.reader)


def serve(conn: Any) -> None:
    """The child's loop: ``(volume array or None, view, resolution, index, window, aspect)`` →
    ``(image, seconds)`` (the linear ``(4, H, W)`` float32 pass, :func:`~.scene.path_pass`), or ``(None, why)``; ends on None or a closed pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)          # Ctrl-C is the server's to answer
    try:
        os.nice(NICE)
    except OSError:
        pass
    import torch                                           # lazy: the child's own imports
    from .scene import path_pass                           # lazy: Dr.Jit and Mitsuba load in the child, after its nice

    volume = None
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError, pickle.UnpicklingError):
            return
        if message is None:
            return
        array, view, resolution, index, window, aspect = message
        if array is not None:
            volume = torch.from_numpy(array)
        try:
            start = time.perf_counter()
            image = path_pass(volume, view, resolution, index, window, aspect)
            conn.send((image.float().cpu().numpy(), time.perf_counter() - start))
        except Exception as e:                             # the page shows it; the worker serves on
            conn.send((None, f"{type(e).__name__}: {e}"))


class PathWorker:
    """Path-tracer passes for the pages, in a child process (module docstring)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._slots: "OrderedDict[object, Tuple[tuple, Future]]" = OrderedDict()
        self._stopped = False
        self._process = None
        self._conn = None
        self._sent: Optional[Tuple[int, int]] = None       # (id of the volume tensor's version, version) in the child
        self._thread = threading.Thread(target=self._run, name="path-worker", daemon=True)
        self._thread.start()

    def submit(self, page: object, volume, version: int, view: Tuple[float, float, float], resolution: int,
               index: int, window, aspect: float = 1.0) -> Future:
        """Queue pass ``index`` of ``page``'s frame on a canvas of ``aspect`` (replacing the page's
        queued pass): a Future of ``(image (4, H, W) float32, seconds)``."""
        future: Future = Future()
        with self._cond:
            old = self._slots.pop(page, None)
            if old is not None:
                old[1].cancel()
            self._slots[page] = ((volume, version, view, resolution, index, window, aspect), future)
            self._cond.notify()
        return future

    def cancel(self, page: object) -> None:
        """Drop ``page``'s queued pass (the one in flight comes back; the page drops it)."""
        with self._cond:
            old = self._slots.pop(page, None)
        if old is not None:
            old[1].cancel()

    def _start(self) -> None:
        # a plain child (python -m this module), not multiprocessing's spawn, which runs the parent's
        # main script again in the child
        self._process = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": os.pathsep.join(
                                             p for p in sys.path if p)})
        self._conn, self._sent = _Pipe(self._process.stdout, self._process.stdin), None

    def _alive(self) -> bool:
        return self._process is not None and self._process.poll() is None

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._slots and not self._stopped:
                    self._cond.wait()
                if self._stopped:
                    return
                page, (job, future) = self._slots.popitem(last=False)   # the oldest slot: round-robin
            if not future.set_running_or_notify_cancel():
                continue
            volume, version, view, resolution, index, window, aspect = job
            try:
                if not self._alive():
                    self._start()
                array = None if self._sent == version else np.ascontiguousarray(volume.numpy())
                self._conn.send((array, view, resolution, index, window, aspect))
                self._sent = version
                image, result = self._conn.recv()
            except (EOFError, OSError, pickle.UnpicklingError) as e:
                self._process, self._sent = None, None
                future.set_exception(WorkerError(f"the path tracer's worker stopped ({type(e).__name__}); "
                                                 f"the next pass starts a new one"))
                continue
            if image is None:
                future.set_exception(WorkerError(result))
            else:
                future.set_result((image, result))

    def stop(self) -> None:
        """Stop the thread and the child (the pass in flight, if any, is abandoned)."""
        with self._cond:
            self._stopped = True
            for _, future in self._slots.values():
                future.cancel()
            self._slots.clear()
            self._cond.notify_all()
        process, conn = self._process, self._conn
        if conn is not None:
            try:
                conn.send(None)
            except (OSError, BrokenPipeError):
                pass
        if process is not None:
            try:
                process.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                process.terminate()
                process.wait(timeout=5.0)


def main() -> None:
    """The child: messages on stdin, answers on a private copy of stdout (fd 1 then points at stderr,
    so that a library's print cannot break the stream)."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    serve(_Pipe(sys.stdin.buffer, out))


if __name__ == "__main__":
    main()
