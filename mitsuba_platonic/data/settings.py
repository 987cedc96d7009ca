"""The data section of a config (``data:``): where the training images come from and how they are made.

:class:`DataConfig` is the section's dataclass; :data:`SOURCES` its choice of source. It sits
beside the data code it configures (``data/render_collection.py`` renders a procedural collection,
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
    """The data section, one line per key (its table in docs/training.md is made from these lines); the
    photo options (background, threshold, crop, margin, clean, fill_holes, erode) are inherited from,
    and explained by, :class:`~mitsuba_platonic.data.photos.PhotoOptions`.

    source: 'procedural' (a collection rendered from procedural shapes by ``platonic make-dataset``, with
    ground-truth volumes, cached under ``cache``) or 'folder' (your photos, at ``path``).
    path: a folder of RGBA cut-outs (source 'folder').
    cache: where rendered collections are kept and reused.
    shape_class, n_shapes, views_per_shape: the procedural collection: its class, shapes and views per shape.
    formation: how the collection's images are formed, 'ea' | 'ao' | 'vh' | 'physical' (path traced); the
    renderer must match it, except a lit one.
    view_distribution, elevation: where the collection's cameras are, 'sphere' | 'band' (between two
    elevations) | 'ring' (docs/conventions.md).
    split, seed: the train split's share (the rest is held out, halved into val and test, for evaluation)
    and the seed of the split (and of a procedural collection's shapes and views).
    """

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
