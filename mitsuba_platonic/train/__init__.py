"""Training: PlatonicGAN's Algorithm 1 with either renderer, runs, checkpoints and resume.

``train``, ``load_run``, ``Trainer`` and ``RunError`` are imported from :mod:`.run` and
:mod:`.trainer` on first use: the config imports the leaf :mod:`.settings` (and the losses',
rolls' and augmentations' choice lists) of this package, and importing a submodule runs this
file first, so it must not import the run or the trainer, which import the config.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["train", "load_run", "Trainer", "RunError"]

#: Names imported on first use: the module that holds each.
_LAZY = {"train": ".run", "load_run": ".run", "RunError": ".run", "Trainer": ".trainer"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
