"""One image's whole pipeline: a decoded file → a ``(4, R, R)`` training image.

:func:`prepare_image` = :func:`~.mask.premultiplied_linear` (colour and mask) followed by
:func:`~.frame.frame_and_resample` (crop, centred transparent padding, antialiased
resampling); :class:`PhotoOptions` are the options a collection applies to every one of its
files (the data config's photo keys are these fields), :class:`ImageOptions` adds the resolution
and validates them.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Dict, Optional

import numpy as np

from ...errors import UserError
from .decode import DecodedImage
from .frame import CROPS, Framing, check_aspect, frame_and_resample, framing
from .mask import BACKGROUNDS, premultiplied_linear

__all__ = ["PhotoOptions", "ImageOptions", "prepare_image", "photo_framing"]


@dataclass
class PhotoOptions:
    """How a collection turns each photo into a training image; the one owner of these settings:
    the data config's section (``mitsuba_platonic.data.settings.DataConfig``) inherits them.

    One line per key (the data section's table in docs/training.md is made from these lines):

    background: null | 'white' (RGB photos on white are masked by their near-white pixels).
    threshold: how near to white, in [0, 1).
    crop: how a photo is framed, 'image' (the whole image) | 'bbox' (the object's bounding box, as the photo
    configs do).
    margin: a transparent border, a share of R per side in [0, 0.5) (with crop 'bbox' the object otherwise
    touches the image edge, where rendered views seldom put it).
    clean: remove frame lines and specks from masks (false for exact masks, e.g. rendered cut-outs, whose
    thin parts are real).
    fill_holes: keep white areas enclosed by an object on white opaque (a white label on a mug).
    erode: shrink masks by this many source pixels (cut-outs that carry a light fringe of their old background).

    :class:`~mitsuba_platonic.data.photos.PhotoCollection` says more.
    """

    background: Optional[str] = None
    threshold: float = 0.05
    crop: str = "image"
    margin: float = 0.0
    clean: bool = True
    fill_holes: bool = False
    erode: int = 0

    def image_kwargs(self) -> Dict[str, Any]:
        """These options as keyword arguments (of :func:`prepare_image`, ``PhotoCollection``)."""
        return {f.name: getattr(self, f.name) for f in fields(PhotoOptions)}


@dataclass
class ImageOptions(PhotoOptions):
    """The image options of a collection, with its resolution (validated on construction)."""

    resolution: int = 64

    def __post_init__(self):
        _check_options(self.resolution, self.background, self.threshold, self.crop,
                       self.margin, self.erode)


def _check_options(resolution, background, threshold, crop, margin, erode) -> None:
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or resolution < 1:
        raise UserError(f"resolution must be a positive integer, got {resolution!r}")
    if background not in BACKGROUNDS:
        raise UserError(f"background must be None or 'white', got {background!r}")
    if not (isinstance(threshold, (int, float)) and 0.0 <= threshold < 1.0):
        raise UserError(f"threshold must lie in [0, 1), got {threshold!r}")
    if crop not in CROPS:
        raise UserError(f"crop must be one of {CROPS}, got {crop!r}")
    if not (isinstance(margin, (int, float)) and 0.0 <= margin < 0.5):
        raise UserError(f"margin must lie in [0, 0.5), got {margin!r}")
    if isinstance(erode, bool) or not isinstance(erode, (int, np.integer)) or erode < 0:
        raise UserError(f"erode must be a non-negative integer (pixels), got {erode!r}")


def prepare_image(decoded: DecodedImage, resolution: int = 64, *,
                  background: Optional[str] = None, threshold: float = 0.05,
                  crop: str = "image", margin: float = 0.0, clean: bool = True,
                  fill_holes: bool = False, erode: int = 0, soften: bool = True,
                  name: str = "<image>") -> np.ndarray:
    """A decoded image → ``(4, R, R)`` float32 premultiplied linear ``[r, g, b, alpha]``.

    :func:`~.mask.premultiplied_linear` (colour and mask) followed by
    :func:`~.frame.frame_and_resample` (crop, centred transparent padding, antialiased
    resampling). The result satisfies ``0 ≤ alpha ≤ 1`` and ``0 ≤ rgb ≤ alpha``.

    Raises:
        ImageRejected: ``no_alpha`` or ``fully_transparent`` (see
            :func:`~.mask.premultiplied_linear`), ``extreme_aspect`` (see
            :data:`~.frame.MAX_ASPECT`).
        ValueError: on invalid options.
    """
    _check_options(resolution, background, threshold, crop, margin, erode)
    image = _masked(decoded, background, threshold, crop, clean, fill_holes, erode, soften, name)
    return frame_and_resample(image, resolution, crop=crop, margin=margin, name=name)


def _masked(decoded: DecodedImage, background, threshold, crop, clean, fill_holes, erode, soften, name) -> np.ndarray:
    """The photo at its own size, masked and premultiplied, as :func:`prepare_image` frames it."""
    if crop == "image":                                   # before masking: the photo's own shape
        check_aspect(*decoded.size, name)
    return premultiplied_linear(decoded, background=background, threshold=threshold,
                                clean=clean, fill_holes=fill_holes, erode=erode,
                                soften=soften, name=name)


def photo_framing(decoded: DecodedImage, *, background: Optional[str] = None, threshold: float = 0.05,
                  crop: str = "image", margin: float = 0.0, clean: bool = True, fill_holes: bool = False,
                  erode: int = 0, soften: bool = True, name: str = "<image>") -> Framing:
    """Where :func:`prepare_image` with these options puts the photo in its training image
    (:class:`~.frame.Framing`): the rule applied to the mask it makes. Used to bring a rendered
    collection's ground truth into the photo's frame (:mod:`mitsuba_platonic.evaluate.photo_truth`)."""
    _check_options(1, background, threshold, crop, margin, erode)
    image = _masked(decoded, background, threshold, crop, clean, fill_holes, erode, soften, name)
    return framing(image[..., 3], crop, margin, name)
