"""The dataset: a scanned folder as a PyTorch ``Dataset`` of one split's images."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset

from ...errors import UserError
from .prepare import ImageOptions
from .rejections import PathLike, PhotoCollectionWarning
from .scan import PhotoEntry, Scan, scan
from .split import SPLITS, check_splits

__all__ = ["PhotoCollection"]


class PhotoCollection(Dataset):
    """A folder of photos as a dataset of premultiplied linear RGBA (or alpha) images.

    ``collection[i]`` is a float32 tensor ``(4, R, R)`` = ``[r, g, b, alpha]`` (linear RGB
    premultiplied by alpha, all in [0, 1]) or, with ``alpha_only=True``, ``(1, R, R)``.
    All images of the folder are decoded, resized and cached in memory when the collection is
    built; use :meth:`load_splits` to build the train/val/test sets from one decoding pass.
    Splits are by content hash (see :mod:`.split`).

    Args:
        folder: the collection (searched recursively; sub-folder names mean nothing).
        resolution: output side ``R`` in pixels.
        split: ``"train"``, ``"val"``, ``"test"`` or ``"all"`` (every usable image).
        splits: fractions (train, val, test), non-negative, summing to 1.
        seed: split seed.
        background: ``None`` (files need transparency) or ``"white"`` (files without
            transparency are masked as photos on white; files with transparency use it).
        threshold: white tolerance in sRGB-encoded units of [0, 1]
            (see :func:`~.mask.white_background_alpha`).
        alpha_only: return ``(1, R, R)`` alpha (VH/AO silhouettes) instead of ``(4, R, R)``.
        crop: ``"image"`` (keep the photo framing) or ``"bbox"`` (crop to the alpha bounding box).
        margin: transparent border, a fraction of ``R`` on each side (the longer side of the
            photo or box maps to ``R·(1 − 2·margin)`` pixels), in [0, 0.5).
        clean: clean masks (:func:`~.mask.clean_mask`: frame lines along the image edges and
            specks are removed); applies to alpha channels and white-background masks.
        fill_holes: white-background masks: make enclosed near-white areas opaque.
        erode: shrink masks by this many *source* pixels (trims a rim of leftover background
            around cut-outs; 0 = off).

    Attributes:
        files: the source paths of this split's images (one per unique image).
        entries: one :class:`PhotoEntry` per image of this split.
        report: the :class:`CollectionReport` of the whole folder.
        options: the :class:`~.prepare.ImageOptions` applied to every file.

    Raises:
        FileNotFoundError / NotADirectoryError: if ``folder`` is missing or not a folder.
        ValueError: on invalid options, or if the folder holds no usable image (the message
            names the folder and lists each rejected file with its reason).

    Warns:
        PhotoCollectionWarning: once per skipped file, naming it and the reason.
    """

    def __init__(self, folder: PathLike, resolution: int = 64, split: str = "train", *,
                 splits: Sequence[float] = (0.8, 0.1, 0.1), seed: int = 0,
                 background: Optional[str] = None, threshold: float = 0.05,
                 alpha_only: bool = False, crop: str = "image", margin: float = 0.0,
                 clean: bool = True, fill_holes: bool = False, erode: int = 0):
        if split not in SPLITS:
            raise UserError(f"split must be one of {SPLITS}, got {split!r}")
        fractions = check_splits(splits)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise UserError(f"seed must be an integer, got {seed!r}")
        options = ImageOptions(resolution=resolution, background=background, threshold=threshold, crop=crop,
                               margin=margin, clean=bool(clean), fill_holes=bool(fill_holes), erode=erode)
        self._init_from(scan(folder, options, fractions, int(seed)), split, alpha_only)

    def _init_from(self, scanned: Scan, split: str, alpha_only: bool) -> None:
        self._scan = scanned
        self.split = split
        self.alpha_only = bool(alpha_only)
        self.options = scanned.options
        self.splits = scanned.fractions
        self.seed = scanned.seed
        self.report = scanned.report
        keys = scanned.assignment[split]
        self.entries: List[PhotoEntry] = [scanned.entries[k] for k in keys]
        self._images: List[torch.Tensor] = [scanned.images[k] for k in keys]
        wanted = split == "all" or scanned.fractions[("train", "val", "test").index(split)] > 0
        if not keys and wanted:
            warnings.warn(f"split {split!r} of {str(scanned.report.folder)!r} is empty "
                          f"({scanned.report.usable} usable image(s), splits {scanned.fractions})",
                          PhotoCollectionWarning, stacklevel=3)

    def with_split(self, split: str, *, alpha_only: Optional[bool] = None) -> "PhotoCollection":
        """The same collection (same decoded images, report and options) for another split."""
        if split not in SPLITS:
            raise UserError(f"split must be one of {SPLITS}, got {split!r}")
        other = type(self).__new__(type(self))
        other._init_from(self._scan, split,
                         self.alpha_only if alpha_only is None else alpha_only)
        return other

    @classmethod
    def load_splits(cls, folder: PathLike, resolution: int = 64,
                    **kwargs) -> Dict[str, "PhotoCollection"]:
        """``{"train", "val", "test", "all"}`` → collections, decoding the folder once.

        Takes the keyword arguments of :class:`PhotoCollection` except ``split``; the four
        collections share one report and one image cache (see :meth:`with_split`).
        """
        if "split" in kwargs:
            raise TypeError("load_splits() returns every split; do not pass split=")
        full = cls(folder, resolution, "all", **kwargs)
        return {split: (full if split == "all" else full.with_split(split)) for split in SPLITS}

    @property
    def files(self) -> List[Path]:
        """Source paths of this split's images, one per unique image (content-hash order)."""
        return [e.path for e in self.entries]

    @property
    def hashes(self) -> List[str]:
        """SHA-256 (hex) of this split's files, in item order."""
        return [e.sha256 for e in self.entries]

    @property
    def resolution(self) -> int:
        return self.options.resolution

    @property
    def channels(self) -> int:
        """1 with ``alpha_only``, else 4."""
        return 1 if self.alpha_only else 4

    def __len__(self) -> int:
        return len(self._images)

    def __getitem__(self, index: int) -> torch.Tensor:
        image = self._images[index]
        return (image[3:4] if self.alpha_only else image).clone()

    def images(self) -> torch.Tensor:
        """All images of this split stacked: ``(N, C, R, R)`` float32."""
        if not self._images:
            return torch.zeros((0, self.channels, self.resolution, self.resolution))
        stacked = torch.stack(self._images)
        return stacked[:, 3:4].clone() if self.alpha_only else stacked

    def __repr__(self) -> str:
        return (f"PhotoCollection({str(self.report.folder)!r}, split={self.split!r}, "
                f"{len(self)} image(s) of {self.channels}×{self.resolution}×{self.resolution})")
