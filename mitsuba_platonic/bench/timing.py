"""Timing and memory of one renderer call: the best of repeated calls after a warm-up, the peak
resident memory (sampled by a thread), the memory bandwidth and the bytes a pass must move.

Every timing waits for queued work first (:func:`sync`: CUDA and Dr.Jit), so a time is the whole
call's: :func:`best_of` (wall time), :func:`kernel_time` and :func:`best_kernel_ms` (Dr.Jit's own
kernel times), :func:`time_render` (a render after its warm-up, as ``platonic compare`` times it)
and :func:`measure` (one bench row: forward and forward + backward, their peak memory)."""

from __future__ import annotations

import ctypes
import gc
import os
import sys
import threading
import time
from typing import Any, Callable, Dict, Optional, Tuple

import torch

from ..errors import UserError

__all__ = ["PeakRSS", "measure_bandwidth", "RenderFn", "sync", "best_of", "kernel_time", "best_kernel_ms", "time_render",
           "release_memory", "traffic_bytes", "available_bytes", "forward_backward", "measure"]

_MIB = 2.0 ** 20


def sync() -> None:
    """Wait for queued CUDA work and Dr.Jit launches (if Dr.Jit is loaded), so timings are whole."""
    if torch.cuda.is_available():
        torch.cuda.synchronize()
    if "drjit" in sys.modules:
        sys.modules["drjit"].sync_thread()


def best_of(fn: Callable[[], Any], repeats: int) -> float:
    """The shortest wall time of ``repeats`` calls of ``fn`` (seconds; CUDA work synchronised)."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync()
        best = min(best, time.perf_counter() - t0)
    return best


def kernel_time(fn: Callable[[], Any]) -> Tuple[float, int]:
    """Run ``fn`` once with Dr.Jit's kernel history on: (milliseconds of JIT-kernel execution,
    launches of every kind: kernels, copies, clears, reductions). The history is on only for this
    call, because recording it makes every launch wait for its timing query."""
    import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)
    dr.sync_thread()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()                                  # clears it
        fn()
        dr.sync_thread()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return sum(k["execution_time"] for k in history if str(k["type"]).endswith("JIT")), len(history)


def best_kernel_ms(fn: Callable[[], Any], repeats: int) -> float:
    """The shortest JIT-kernel time (:func:`kernel_time`, ms) of ``repeats`` calls of ``fn`` after
    one warm-up call (which absorbs tracing and compilation)."""
    fn()
    return min(kernel_time(fn)[0] for _ in range(repeats))


def time_render(fn: Callable[[], torch.Tensor], repeats: int = 3) -> tuple[torch.Tensor, float]:
    """Run ``fn`` once untimed (warm-up), then ``repeats`` timed runs; return (first output, best s).

    The warm-up output is returned: with fixed options and seeds every run gives the same images.
    """
    if not isinstance(repeats, int) or isinstance(repeats, bool) or repeats < 1:
        raise UserError(f"repeats must be a positive int, got {repeats!r}")
    with torch.no_grad():
        out = fn()
        sync()
        best = best_of(fn, repeats)
    return out, best


_LIBC: Any = None


def release_memory() -> None:
    """Return cached memory to the system: Python's garbage, Dr.Jit's allocation cache, glibc's heap."""
    global _LIBC
    gc.collect()
    if "drjit" in sys.modules:
        import drjit as dr  # already loaded: only then has Dr.Jit a cache to free
        dr.sync_thread()
        dr.flush_malloc_cache()
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL("libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    if _LIBC:
        _LIBC.malloc_trim(0)


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class PeakRSS:
    """Context manager: the peak RSS increase over the level at entry, sampled by a background thread."""

    def __init__(self, interval: float = 5e-4):
        self.interval, self.peak_increase = interval, 0
        self._stop = threading.Event()

    def _poll(self) -> None:
        while not self._stop.is_set():
            self._peak = max(self._peak, _rss_bytes())
            time.sleep(self.interval)

    def __enter__(self) -> "PeakRSS":
        release_memory()
        self.baseline = self._peak = _rss_bytes()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        sync()
        self._peak = max(self._peak, _rss_bytes())
        self._stop.set()
        self._thread.join()
        self.peak_increase = max(0, self._peak - self.baseline)




def measure_bandwidth(megabytes: int = 256, repeats: int = 5) -> float:
    """Memory bandwidth in bytes/s: the best copy of a ``megabytes`` float32 tensor (read + write)."""
    n = megabytes * (1 << 20) // 4
    src = torch.rand(n)
    dst = torch.empty_like(src)
    dst.copy_(src)                                            # fault the pages in
    t = best_of(lambda: dst.copy_(src), repeats)
    return 2.0 * n * 4 / t


def traffic_bytes(b: int, c: int, c_img: int, n: int) -> Tuple[int, int]:
    """Bytes a forward and a backward pass must move at least (float32)."""
    vol, img = b * c * n ** 3 * 4, b * c_img * n * n * 4
    return vol + img, 2 * vol + img


def available_bytes() -> Optional[int]:
    """The memory the system could give this process now (``MemAvailable`` of ``/proc/meminfo``,
    bytes), or None where that file is not (not Linux)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


# --------------------------------------------------------------------------- one row


RenderFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def forward_backward(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor,
                     weights: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """One forward and backward pass of L = Σ weights ⊙ fn(volume, views): (the image, ∂L/∂volume)."""
    x = volume.detach().requires_grad_()
    image = fn(x, views)
    (image * weights).sum().backward()
    return image.detach(), x.grad


def measure(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor, weights: torch.Tensor,
            repeats: int) -> Dict[str, Any]:
    """Times (best of ``repeats`` after a warm-up), peak memory, and the image and gradient."""
    b = volume.shape[0]

    def fwd():
        with torch.no_grad():
            return fn(volume, views)

    fwd()                                                     # warm-up: kernel compilation, caches
    sync()
    with PeakRSS() as mem_f:
        fwd()
    t_f = best_of(fwd, repeats)
    forward_backward(fn, volume, views, weights)             # warm-up of the backward pass
    sync()
    with PeakRSS() as mem_fb:
        image, grad = forward_backward(fn, volume, views, weights)
    t_fb = best_of(lambda: forward_backward(fn, volume, views, weights), repeats)
    return {"fwd_ms": t_f / b * 1e3, "fwd_bwd_ms": t_fb / b * 1e3,
            "mem_fwd_mb": mem_f.peak_increase / _MIB, "mem_fwd_bwd_mb": mem_fb.peak_increase / _MIB,
            "image": image, "grad": grad}
