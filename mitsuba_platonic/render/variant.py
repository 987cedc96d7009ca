"""Which Mitsuba variant renders: ``cuda_ad_rgb`` where CUDA works, else ``llvm_ad_rgb``.

Mitsuba's variant is process-global. ``MITSUBA_PLATONIC_VARIANT`` forces one of the two.
Mitsuba is imported lazily, on the first Mitsuba render, so the closed-form layers never
pay for it.
"""

from __future__ import annotations

import os
from typing import Any, Optional

__all__ = ["VARIANTS", "ensure_variant", "variant_device"]

VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
_chosen: Optional[str] = None


def _pick() -> str:
    forced = os.environ.get("MITSUBA_PLATONIC_VARIANT")
    if forced:
        if forced not in VARIANTS:
            raise ValueError(f"MITSUBA_PLATONIC_VARIANT must be one of {VARIANTS}, got {forced!r}")
        return forced
    from .. import BACKEND
    return "cuda_ad_rgb" if BACKEND.get("cuda") else "llvm_ad_rgb"


def ensure_variant() -> Any:
    """Import Mitsuba, set the project's variant (once) and return the ``mitsuba`` module."""
    global _chosen
    import mitsuba as mi
    if _chosen is None:
        _chosen = _pick()
    if mi.variant() != _chosen:
        mi.set_variant(_chosen)
    return mi


def variant_device() -> str:
    """The torch device whose memory the chosen variant's arrays live in (``'cuda'`` or ``'cpu'``)."""
    ensure_variant()
    return "cuda" if _chosen == "cuda_ad_rgb" else "cpu"
