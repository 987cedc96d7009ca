"""What every Dr.Jit launch of the kernels shares: threads, scatter mode, torch memory, replay keys.

The batched marcher (:mod:`.marcher`), the sky's occlusion (:mod:`.sky_light`) and single
scattering at the marcher's speed (:mod:`.scatter_march`) hand torch tensors to Dr.Jit and back
and launch their kernels the same way; this module is that shared part, and imports none of them.

- Threads (LLVM backend): Dr.Jit's default block is 16,384 lanes, so a launch of fewer rays would run
  on one thread; :func:`spread_over_threads` asks for blocks of about lanes / (k · threads), a power
  of two in [2⁶, 2²⁰] (:func:`set_block_size` is Dr.Jit's own ``jit_llvm_set_block_size``, read
  from its core library; None off the LLVM backend). :data:`PACKET`: lanes per SIMD packet.
- Scatter-adds of a backward pass: :data:`REDUCE_MODE`, ``Expand`` (per-thread copies, summed at
  the end) on the LLVM backend, ``Auto`` (atomics) on CUDA.
- torch ↔ Dr.Jit without a copy: :func:`shared_float` (a Float over a contiguous tensor's memory),
  :func:`pair_frames` (each pair's camera frame, :data:`FRAME_FLOATS` floats: right, up, ω, and
  with a window the origin; docs/conventions.md, "Views"), :func:`per_ray_to_image` (per-ray
  values → the image, the mean of a pixel's ``spp`` rays) and :func:`image_to_per_ray` (its
  adjoint: 1/spp of a pixel's gradient to each of its rays).
- Replays: with :data:`FREEZE` the kernels are recorded once per :class:`LaunchKey` (Dr.Jit's
  ``dr.freeze``) and replayed after.
"""

from __future__ import annotations

import ctypes
import glob
import os
from typing import Any, Callable, Optional, Tuple

import torch

from ...views import camera_frames
from ..variant import ensure_variant
from ..window import Window

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

__all__ = ["set_block_size", "PACKET", "spread_over_threads", "REDUCE_MODE", "shared_float", "FRAME_FLOATS",
           "pair_frames", "per_ray_to_image", "image_to_per_ray", "FREEZE", "LaunchKey"]


# -- Threads -------------------------------------------------------------------------------


def _core_function(symbol: str, restype: Any, argtypes: list) -> Optional[Callable[..., Any]]:
    """A function of Dr.Jit's LLVM backend that Python does not expose, or None where it is absent."""
    if not mi.variant().startswith("llvm"):
        return None
    pattern = os.path.join(os.path.dirname(dr.__file__), "libdrjit-core*.so*")
    for path in glob.glob(pattern):
        try:
            fn = getattr(ctypes.PyDLL(path), symbol)                 # PyDLL: keeps the GIL held
        except (OSError, AttributeError):
            continue
        fn.argtypes, fn.restype = argtypes, restype
        return fn
    return None


#: ``jit_llvm_set_block_size(n)``: lanes per block of work (a power of two); each block runs on one
#: thread. None off the LLVM backend (or where the core library does not export it).
set_block_size = _core_function("_Z23jit_llvm_set_block_sizej", None, [ctypes.c_uint32])
_vector_width = _core_function("_Z21jit_llvm_vector_widthv", ctypes.c_uint32, [])
#: Lanes per SIMD packet of the LLVM backend (16 with AVX-512, 8 with AVX2); 0 off the LLVM backend.
PACKET = int(_vector_width()) if _vector_width is not None else 0


def spread_over_threads(lanes: int, blocks_per_thread: int) -> None:
    """Split a launch of ``lanes`` rays into about ``blocks_per_thread`` blocks per thread.

    Dr.Jit's default block is 16,384 lanes, so a 32³ batch of 8 (8,192 rays) would run on one
    thread. The backward pass asks for one block per thread: its ``Expand`` scatters give every
    block its own copy of the gradient, which is cleared and summed at the end.
    """
    if set_block_size is None:
        return
    threads = max(1, dr.thread_count())
    block = -(-lanes // (blocks_per_thread * threads))
    set_block_size(1 << max(6, min(20, (block - 1).bit_length())))   # a power of two ≥ the packet


# -- torch ↔ Dr.Jit ------------------------------------------------------------------------


#: Scatter-add mode of the backward pass (``Expand``: per-thread copies on the LLVM backend).
REDUCE_MODE = dr.ReduceMode.Expand if mi.variant().startswith("llvm") else dr.ReduceMode.Auto


def shared_float(t: torch.Tensor, keep: list) -> Any:
    """A Dr.Jit Float sharing the memory of the contiguous torch tensor ``t`` (no copy).

    ``t`` goes into ``keep``, which the caller holds until Dr.Jit is done with the array: Dr.Jit
    may release its last reference inside a launch, where the GIL is not held, and freeing torch
    memory there aborts the interpreter.
    """
    t = t.reshape(-1)
    keep.append(t)
    return mi.Float(t)


#: Floats per pair in a call's frames, without and with a window (:func:`pair_frames`).
FRAME_FLOATS = {False: 9, True: 12}


def pair_frames(views: torch.Tensor, keep: list, window: Optional[Window] = None) -> Any:
    """(B, 3) views → a Float of 9 per pair: right, up, ω; with a ``window`` (not the full one) 12:
    h right, h up, ω, o (:mod:`.marcher`'s docstring, "Window"). float64 maths, stored as float32."""
    right, up, w = camera_frames(views)
    if window is None:
        return shared_float(torch.cat([right, up, w], dim=1).to(torch.float32).contiguous(), keep)
    right, up, origin = window.frames(right, up)
    return shared_float(torch.cat([right, up, w, origin], dim=1).to(torch.float32).contiguous(), keep)


def per_ray_to_image(values: Any, b: int, n: int, spp: int) -> torch.Tensor:
    """Per-ray Dr.Jit Floats (one per channel) → the (B, C, H, W) image, the mean over each pixel's rays."""
    rays = torch.stack([v.torch().view(b, n, n, spp) for v in values], dim=1)   # (B, C, H, W, spp)
    return rays[..., 0] if spp == 1 else rays.mean(dim=-1)


def image_to_per_ray(grad: torch.Tensor, spp: int, keep: list) -> Tuple[Any, ...]:
    """(B, C, H, W) gradient → per-ray Floats: each ray of a pixel gets 1/spp of it."""
    g = (grad / spp if spp > 1 else grad).transpose(0, 1)                          # (C, B, H, W)
    return tuple(shared_float(g[ch].unsqueeze(-1).expand(-1, -1, -1, spp).contiguous(), keep)
                 for ch in range(grad.shape[1]))


# -- Replays -------------------------------------------------------------------------------


#: Replay the recorded kernels of both passes instead of re-tracing them (Dr.Jit's ``dr.freeze``):
#: a new (batch, resolution, settings, thread count) records once, later calls only launch. Set
#: ``MITSUBA_PLATONIC_FREEZE=0`` to trace every call.
FREEZE = os.environ.get("MITSUBA_PLATONIC_FREEZE", "1") != "0"


class LaunchKey:
    """The Python values a launch depends on (sizes, settings) and Dr.Jit's thread count (``Expand``
    scatters size their per-thread copies when a kernel is recorded), as one hashable argument:
    ``dr.freeze`` records a launch once per key and replays it after (:data:`FREEZE`)."""

    def __init__(self, *values: Any):
        self.values = values
        self.key = (values, dr.thread_count())

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, LaunchKey) and self.key == other.key
