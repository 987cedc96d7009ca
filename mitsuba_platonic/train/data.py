"""Training data: the images a run learns from, and what evaluation may look at.

- ``procedural``: a built-in shape class rendered by ``make-dataset`` (cached under
  ``data.cache``, resumable), split *by shape*: the first ``split`` share of shapes trains, the
  rest is held out. Held-out images keep their evaluation records (view, ground-truth volume);
  training only ever sees image tensors. Platonic3D / 3D-GAN also get the training shapes'
  ground-truth volumes (that is their point: 3D data where it exists).
- ``folder``: an unstructured photo collection (:class:`~mitsuba_platonic.data.photos.PhotoCollection`),
  de-duplicated, split train / held-out by content hash.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np
import torch

from ..config import Config, ConfigError
from ..config.train_settings import MODES_3D
from ..data.render_collection import CollectionSpec, load_manifest, make_collection
from ..data.photos import PhotoCollection, decode_image, prepare_image
from ..data.settings import SOURCES  # noqa: F401  (the choice list, also named here)
from ..errors import UserError
from ..files.fileio import check_input_file
from ..volume import CHANNELS

__all__ = ["TrainingData", "load_training_data", "collection_folder", "SOURCES"]


@dataclass
class TrainingData:
    """images: ``(N, C, R, R)`` training images (C = 4 premultiplied linear RGBA, or 1 alpha);
    held_out: ``(M, C, R, R)``; volumes: ``(K, 4, R, R, R)`` training shapes' ground truth or None;
    held_out_records: evaluation metadata per held-out image (procedural only);
    image_shapes: ``(N,)`` index into ``volumes`` of each training image's shape, and image_views:
    ``(N, 3)`` its camera's view (both with ``volumes`` only)."""

    images: torch.Tensor
    held_out: torch.Tensor
    volumes: Optional[torch.Tensor] = None
    held_out_records: List[Dict[str, Any]] = field(default_factory=list)
    image_shapes: Optional[torch.Tensor] = None
    image_views: Optional[torch.Tensor] = None


def collection_folder(cfg: Config) -> Path:
    """Where a procedural config's collection is cached (one folder per distinct collection)."""
    d = cfg.data
    elev = "" if d.elevation is None else "-e" + "_".join(str(x) for x in np.atleast_1d(d.elevation))
    # physical images are exposed by the metered light (caches from before metering stay apart)
    formation = "physical-metered" if d.formation == "physical" else d.formation
    r = cfg.render
    if r.camera != "orthographic":                                # the images' camera is the renderer's
        formation += f"-pinhole{r.fov:g}" + ("" if r.distance is None else f"-d{r.distance:g}")
    name = (f"{d.shape_class}-{formation}-{cfg.model.resolution}-{d.n_shapes}x{d.views_per_shape}"
            f"-{d.view_distribution}{elev}-s{d.seed}")
    return Path(d.cache) / name


#: The config key of each collection setting a procedural run derives from its config.
_SPEC_KEYS = {"shape_class": "data.shape_class", "n_shapes": "data.n_shapes", "views_per_shape": "data.views_per_shape",
              "resolution": "model.resolution", "formation": "data.formation", "views": "data.view_distribution",
              "lighting": "render.lighting", "camera": "render.camera", "seed": "data.seed"}


def _validate_spec(spec: Any) -> None:
    """``spec.validate()``, its error naming the config key to change (``data.shape_class``, not ``shape_class``)."""
    try:
        spec.validate()
    except UserError as e:
        text = str(e)
        field = next((f for f in _SPEC_KEYS if text.startswith((f + " ", f + ":"))), None)
        raise ConfigError(_SPEC_KEYS[field] + text[len(field):] if field else f"data: {text}") from None


def _procedural(cfg: Config, progress: bool) -> TrainingData:
    d = cfg.data
    spec = CollectionSpec(shape_class=d.shape_class, n_shapes=d.n_shapes, views_per_shape=d.views_per_shape,
                          resolution=cfg.model.resolution, formation=d.formation,
                          renderer="mitsuba" if d.formation == "physical" else "closed_form",
                          views=d.view_distribution,
                          elevation=tuple(d.elevation) if isinstance(d.elevation, list) else d.elevation,
                          lighting=cfg.render.lighting if d.formation == "physical" else "sunsky",
                          camera=cfg.render.camera, fov=cfg.render.fov, distance=cfg.render.distance,
                          seed=d.seed)
    _validate_spec(spec)
    folder = collection_folder(cfg)
    make_collection(folder, spec, progress=progress)
    records = load_manifest(folder)["images"]
    n_train = max(1, int(round(d.split * d.n_shapes)))
    alpha_only = CHANNELS[cfg.render.model] == 1
    train, train_records, held, held_records = [], [], [], []
    for r in records:
        img = prepare_image(decode_image(folder / r["image"]), cfg.model.resolution, clean=False, soften=False)
        img = torch.from_numpy(img[3:] if alpha_only else img)
        if r["shape"] < n_train:
            train.append(img)
            train_records.append(r)
        else:
            held.append(img)
            held_records.append({**r, "folder": str(folder)})
    volumes = shapes = views = None
    if cfg.train.mode in MODES_3D:                                # the modes trained with 3D ground truth
        volumes = torch.stack([torch.from_numpy(np.load(check_input_file(folder / "volumes" / f"{i:05d}.npz"))["volume"])
                               for i in range(n_train)])
        if alpha_only:
            volumes = volumes[:, 3:]
        shapes = torch.tensor([r["shape"] for r in train_records], dtype=torch.long)
        views = torch.tensor([list(r["view"]) for r in train_records], dtype=torch.float32)
    empty = torch.zeros(0, *train[0].shape)
    return TrainingData(torch.stack(train), torch.stack(held) if held else empty, volumes, held_records,
                        shapes, views)


def _folder(cfg: Config) -> TrainingData:
    d = cfg.data
    sets = PhotoCollection.load_splits(d.path, resolution=cfg.model.resolution,
                                       alpha_only=CHANNELS[cfg.render.model] == 1, **d.photo_options())
    train = torch.stack([sets["train"][i] for i in range(len(sets["train"]))])
    held = [sets[s][i] for s in ("val", "test") for i in range(len(sets[s]))]
    return TrainingData(train, torch.stack(held) if held else torch.zeros(0, *train.shape[1:]))


def load_training_data(cfg: Config, progress: bool = True) -> TrainingData:
    """Build (or load from the cache) the data of ``cfg``."""
    return _procedural(cfg, progress) if cfg.data.source == "procedural" else _folder(cfg)
