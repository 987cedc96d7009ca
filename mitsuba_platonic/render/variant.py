"""Which Mitsuba variant renders: ``cuda_ad_rgb`` where CUDA works, else ``llvm_ad_rgb``.

Mitsuba's variant is process-global. ``MITSUBA_PLATONIC_VARIANT`` forces one of the two; forcing
``cuda_ad_rgb`` where Dr.Jit has no working CUDA is a user error that says what to do.
Mitsuba is imported lazily, on the first Mitsuba render, so the closed-form layers never
pay for it.
"""

from __future__ import annotations

import os
from typing import Any, Optional

from ..errors import UserError
from ..runtime.backend import check_backend

__all__ = ["VARIANTS", "ensure_variant", "variant_device"]

VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
ENV = "MITSUBA_PLATONIC_VARIANT"
_chosen: Optional[str] = None

_NO_CUDA = ("unset {env} (or set it to llvm_ad_rgb) to render on the CPU, or run on a machine with an "
            "NVIDIA GPU, its driver and CUDA")


def _pick() -> str:
    forced = os.environ.get(ENV)
    BACKEND = check_backend()        # the package's check (its verdict is cached on disk), not the package
    if forced:
        if forced not in VARIANTS:
            raise UserError(f"{ENV} must be one of {', '.join(VARIANTS)} (or unset: the best one here), "
                            f"got {forced!r}")
        checked = os.environ.get("MITSUBA_PLATONIC_SKIP_BACKEND_CHECK") != "1"   # else BACKEND knows nothing
        if forced == "cuda_ad_rgb" and checked and not BACKEND.get("cuda"):
            raise UserError(f"{ENV}=cuda_ad_rgb, but Dr.Jit found no working CUDA on this machine; "
                            + _NO_CUDA.format(env=ENV))
        return forced
    return "cuda_ad_rgb" if BACKEND.get("cuda") else "llvm_ad_rgb"


def ensure_variant() -> Any:
    """Import Mitsuba, set the project's variant (once) and return the ``mitsuba`` module.

    Raises :class:`~mitsuba_platonic.runtime.backend.BackendError` (before Mitsuba or Dr.Jit is imported)
    where Dr.Jit has no working backend, and :class:`~mitsuba_platonic.errors.UserError` if ``MITSUBA_PLATONIC_VARIANT`` names a
    variant this machine cannot run (nothing is remembered then: fix the variable and call again).
    """
    global _chosen
    chosen = _chosen if _chosen is not None else _pick()    # the backend check first: no Dr.Jit without LLVM
    import mitsuba as mi  # lazy: after the backend check; Mitsuba loads LLVM
    if mi.variant() != chosen:
        try:
            mi.set_variant(chosen)
        except Exception as e:  # Mitsuba raises ImportError, AttributeError, RuntimeError for a variant it cannot run
            if os.environ.get(ENV) != chosen:
                raise
            detail = " ".join(str(e).split())
            what = _NO_CUDA.format(env=ENV) if chosen == "cuda_ad_rgb" else f"unset {ENV} to let the project choose"
            raise UserError(f"{ENV}={chosen}, but Mitsuba cannot run that variant here ({type(e).__name__}: "
                            f"{detail}); {what}") from None
    _chosen = chosen
    return mi


def variant_device() -> str:
    """The torch device whose memory the chosen variant's arrays live in (``'cuda'`` or ``'cpu'``)."""
    ensure_variant()
    return "cuda" if _chosen == "cuda_ad_rgb" else "cpu"
