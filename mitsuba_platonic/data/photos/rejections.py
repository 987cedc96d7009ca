"""Why a file can be rejected, and how a rejection is reported.

Bad input never stops the loading of the others and is never dropped silently: each rejected
file is named in a :class:`PhotoCollectionWarning` and recorded in the collection's report
with one of the reasons in :data:`REASONS`.
"""

from __future__ import annotations

import os
from typing import Dict, Union

from ...errors import UserError

__all__ = ["REASONS", "ImageRejected", "PhotoCollectionWarning", "PathLike"]

PathLike = Union[str, "os.PathLike[str]"]

#: Why a file can be skipped (the keys of :attr:`CollectionReport.skipped_by_reason`).
REASONS: Dict[str, str] = {
    "not_an_image": "not an image file",
    "unsupported_format": "an image format or pixel layout this loader does not read",
    "corrupt": "a corrupt or truncated image",
    "too_large": "an image larger than Pillow's decompression-bomb limit",
    "unreadable": "a file that could not be read (permissions, I/O error)",
    "no_alpha": "an image without transparency, loaded without data.background: white (--background white)",
    "fully_transparent": "an image whose mask is empty (alpha 0 everywhere, or all white)",
    "extreme_aspect": "an image (with crop='bbox': its object) whose longer side is more than "
                      "8 times its shorter side (MAX_ASPECT)",
}


class PhotoCollectionWarning(UserWarning):
    """Warning for a file that :class:`PhotoCollection` skipped (the message names the file)."""


class ImageRejected(UserError):
    """A file that cannot become a training image; ``reason`` is a key of :data:`REASONS`."""

    def __init__(self, reason: str, message: str):
        if reason not in REASONS:
            raise ValueError(f"unknown rejection reason {reason!r}")
        super().__init__(message)
        self.reason = reason
        self.message = message
