"""The data section of a config (``data:``): where the training images come from and how they are made.

:class:`DataConfig` is the section's dataclass; :data:`SOURCES` its choice of source. It sits
beside the data code it configures (``data/collection.py`` renders a procedural collection,
``data/photos/`` loads a folder of photos) and imports no config: the config composes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Union

from ..render.settings import FORMATIONS
from ..settings_checks import ConfigError, check_elevation, choice, non_negative, positive
from ..views import DISTRIBUTIONS
from .photos import BACKGROUNDS, CROPS, PhotoOptions

__all__ = ["DataConfig", "SOURCES"]

#: data.source: a procedural collection rendered by make-dataset, or a folder of photos.
SOURCES = ("procedural", "folder")


@dataclass
class DataConfig(PhotoOptions):
    """source: 'procedural' (render a built-in class with make-dataset, cached under ``cache``)
    or 'folder' (an unstructured photo collection at ``path``).
    Procedural: shape_class, n_shapes, views_per_shape, formation ('vh'|'ao'|'ea'|'physical'),
    view_distribution ('sphere'|'band'|'ring'), elevation, seed.
    Folder: the photo options background, threshold, crop, margin, clean, fill_holes and erode,
    inherited from (and explained by) :class:`mitsuba_platonic.data.photos.PhotoOptions`.
    split: the train split's share; the rest is held out (val/test) for evaluation."""

    source: str = "procedural"
    path: Optional[str] = None
    cache: str = "data"
    shape_class: str = "chair"
    n_shapes: int = 200
    views_per_shape: int = 4
    formation: str = "ea"
    view_distribution: str = "sphere"
    elevation: Optional[Union[float, List[float]]] = None
    split: float = 0.9
    seed: int = 0

    def validate(self) -> "DataConfig":
        """Check this section's values and combinations; raise :class:`ConfigError` naming the key
        (``data.split: ...``). Checks against other sections are the config's."""
        choice("data.source", self.source, SOURCES)
        if self.source == "folder" and not self.path:
            raise ConfigError("data.path: required when data.source is 'folder'")
        choice("data.formation", self.formation, FORMATIONS)
        choice("data.view_distribution", self.view_distribution, DISTRIBUTIONS)
        choice("data.background", self.background, BACKGROUNDS)
        choice("data.crop", self.crop, CROPS)
        if not 0.0 <= self.margin < 0.5:
            raise ConfigError(f"data.margin: expected a share in [0, 0.5), got {self.margin!r}")
        if not 0.0 <= self.threshold < 1.0:
            raise ConfigError(f"data.threshold: expected a number in [0, 1), got {self.threshold!r}")
        non_negative("data.erode", self.erode)
        positive("data.n_shapes", self.n_shapes)
        positive("data.views_per_shape", self.views_per_shape)
        if not 0.0 < self.split <= 1.0:
            raise ConfigError(f"data.split: expected a share in (0, 1], got {self.split!r}")
        check_elevation("data", self.view_distribution, self.elevation)
        return self

    def photo_options(self) -> Dict[str, Any]:
        """Keyword arguments of ``PhotoCollection`` / ``PhotoCollection.load_splits`` for a
        folder source: the split shares (the held-out rest halved into val and test), the seed
        and the image options above (``resolution`` and ``alpha_only`` come from the model and
        renderer)."""
        rest = (1.0 - self.split) / 2.0
        return {"splits": (self.split, rest, rest), "seed": self.seed, **self.image_kwargs()}
