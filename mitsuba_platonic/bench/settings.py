"""What ``platonic bench`` measures: its settings, the marcher configurations it varies and the
converged reference every row of our image formation is measured against."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

from ..networks.nets import RESOLUTIONS
from ..volume import CHANNELS

__all__ = ["BenchSettings", "marcher_configs", "physical_spps", "REFERENCE_OPTIONS", "RESOLUTIONS"]

#: The converged reference every row of our image formation is measured against.
REFERENCE_OPTIONS: Dict[str, Any] = {"step": 0.25, "spp": 16, "jitter": False, "filter": "trilinear"}
#: Resolutions the bench accepts (those the training configuration accepts): ``RESOLUTIONS``.


@dataclass
class BenchSettings:
    """What ``platonic bench`` measures (the command's options)."""

    resolutions: Sequence[int] = (32, 64)
    batch: int = 8
    repeats: int = 3
    threads: Optional[int] = None               # torch and Dr.Jit threads (None: leave as they are)
    models: Sequence[str] = ("vh", "ao", "ea")
    volume: str = "figure"
    seed: int = 0
    quick: bool = False
    physical_ref_spp: int = 32
    physical_max_depth: int = 4
    physical: bool = True                       # the path-tracer rows (the slowest part of a run)
    physical_max_resolution: int = 64           # … measured up to this N (128³ path tracing: most of an hour)
    single_scatter_max_resolution: int = 32     # the single-scattering rows (with the path tracer's) up to this N
    scatter_march_max_resolution: int = 64      # the rows of single scattering in Dr.Jit up to this N
    scatter_ref_spp: int = 256                  # … their image reference: volpath at max_depth 2, this spp
    train: bool = True
    train_width: int = 16
    train_batch: int = 8
    train_steps: int = 5
    train_warmup: int = 2

    def validate(self) -> "BenchSettings":
        for n in self.resolutions:
            if n not in RESOLUTIONS:
                raise ValueError(f"resolutions must be among {RESOLUTIONS}, got {n!r}")
        if not self.resolutions:
            raise ValueError("resolutions: give at least one")
        for name in ("batch", "repeats", "physical_ref_spp", "physical_max_depth", "physical_max_resolution",
                     "single_scatter_max_resolution", "scatter_march_max_resolution", "scatter_ref_spp", "train_width", "train_batch", "train_steps"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name} must be a positive int, got {v!r}")
        if self.threads is not None and (not isinstance(self.threads, int) or self.threads < 1):
            raise ValueError(f"threads must be a positive int, got {self.threads!r}")
        for m in self.models:
            if m not in CHANNELS:
                raise ValueError(f"models must be among {tuple(CHANNELS)}, got {m!r}")
        return self


def marcher_configs(quick: bool = False) -> List[Tuple[str, Dict[str, Any]]]:
    """(label, options) of the marcher rows: the default first, then one option varied at a time."""
    if quick:
        return [("marcher default", {}), ("step 2", {"step": 2.0}), ("spp 4 jitter", {"spp": 4, "jitter": True}),
                ("termination 1e-2", {"termination": 1e-2})]
    return [
        ("marcher default", {}),
        ("step 2", {"step": 2.0}), ("step 0.5", {"step": 0.5}), ("step 0.25", {"step": 0.25}),
        ("spp 4", {"spp": 4}), ("spp 16", {"spp": 16}),
        ("spp 4 jitter", {"spp": 4, "jitter": True}), ("spp 16 jitter", {"spp": 16, "jitter": True}),
        ("jitter (spp 1)", {"jitter": True}),
        ("nearest", {"filter": "nearest"}),
        ("termination 1e-3", {"termination": 1e-3}), ("termination 1e-2", {"termination": 1e-2}),
    ]


def physical_spps(quick: bool) -> Tuple[int, ...]:
    """The path tracer's samples per pixel the bench measures: 1 in a quick run, else 1 and 4."""
    return (1,) if quick else (1, 4)
