"""One image's whole pipeline: a decoded file → a ``(4, R, R)`` training image.

:func:`prepare_image` = :func:`~.mask.premultiplied_linear` (colour and mask) followed by
:func:`~.frame.frame_and_resample` (crop, centred transparent padding, antialiased
resampling); :class:`ImageOptions` holds and validates the options a collection applies to
every one of its files.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Optional

import numpy as np

from ...errors import UserError
from .decode import DecodedImage
from .frame import CROPS, check_aspect, frame_and_resample
from .mask import BACKGROUNDS, premultiplied_linear

__all__ = ["ImageOptions", "prepare_image"]


@dataclass(frozen=True)
class ImageOptions:
    """The image options of a collection (validated on construction).

    See :class:`~mitsuba_platonic.data.photos.PhotoCollection` for what each one means.
    """

    resolution: int = 64
    background: Optional[str] = None
    threshold: float = 0.05
    crop: str = "image"
    margin: float = 0.0
    clean: bool = True
    fill_holes: bool = False
    erode: int = 0

    def __post_init__(self):
        _check_options(self.resolution, self.background, self.threshold, self.crop,
                       self.margin, self.erode)

    def image_kwargs(self) -> dict:
        """Keyword arguments of :func:`prepare_image` (all fields but ``resolution``)."""
        kwargs = asdict(self)
        del kwargs["resolution"]
        return kwargs


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
    if crop == "image":                                   # before masking: the photo's own shape
        check_aspect(*decoded.size, name)
    image = premultiplied_linear(decoded, background=background, threshold=threshold,
                                 clean=clean, fill_holes=fill_holes, erode=erode,
                                 soften=soften, name=name)
    return frame_and_resample(image, resolution, crop=crop, margin=margin, name=name)
