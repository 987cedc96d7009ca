"""Timing and memory of one renderer call: the best of repeated calls after a warm-up, the peak
resident memory (sampled by a thread), the memory bandwidth and the bytes a pass must move."""

from __future__ import annotations

import ctypes
import gc
import os
import sys
import threading
import time
from typing import Any, Callable, Dict, Optional, Tuple

import torch

from ..render.compare import _sync, best_of

__all__ = ["PeakRSS", "measure_bandwidth", "RenderFn"]

_MIB = 2.0 ** 20


_LIBC: Any = None


def _release_memory() -> None:
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
        _release_memory()
        self.baseline = self._peak = _rss_bytes()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        _sync()
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


def _traffic_bytes(b: int, c: int, c_img: int, n: int) -> Tuple[int, int]:
    """Bytes a forward and a backward pass must move at least (float32)."""
    vol, img = b * c * n ** 3 * 4, b * c_img * n * n * 4
    return vol + img, 2 * vol + img


def _available_bytes() -> Optional[int]:
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


def _forward_backward(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor,
                      weights: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    x = volume.detach().requires_grad_()
    image = fn(x, views)
    (image * weights).sum().backward()
    return image.detach(), x.grad


def _measure(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor, weights: torch.Tensor,
             repeats: int) -> Dict[str, Any]:
    """Times (best of ``repeats`` after a warm-up), peak memory, and the image and gradient."""
    b = volume.shape[0]

    def fwd():
        with torch.no_grad():
            return fn(volume, views)

    fwd()                                                     # warm-up: kernel compilation, caches
    _sync()
    with PeakRSS() as mem_f:
        fwd()
    t_f = best_of(fwd, repeats)
    _forward_backward(fn, volume, views, weights)             # warm-up of the backward pass
    _sync()
    with PeakRSS() as mem_fb:
        image, grad = _forward_backward(fn, volume, views, weights)
    t_fb = best_of(lambda: _forward_backward(fn, volume, views, weights), repeats)
    return {"fwd_ms": t_f / b * 1e3, "fwd_bwd_ms": t_fb / b * 1e3,
            "mem_fwd_mb": mem_f.peak_increase / _MIB, "mem_fwd_bwd_mb": mem_fb.peak_increase / _MIB,
            "image": image, "grad": grad}
