"""Colour and mask: decoded codes → premultiplied linear RGBA at the photo's own size.

**Colour.** sRGB-encoded codes ``q`` (0 … 2^bits − 1) are decoded to linear RGB with
the package's one sRGB decoder, ``c = srgb_to_linear(q / (2^bits − 1))``
(:func:`mitsuba_platonic.images.srgb_to_linear`: colour-science's ``cctf_decoding(…, "sRGB")``
bit for bit, without importing it), tabulated once per bit depth
(a 256- or 65 536-entry look-up table, so decoding is exact and fast). Alpha is linear coverage
in every format and is only scaled, ``α = a / (2^bits − 1)``.

**Mask.**

- A file with *real* transparency (an alpha channel, or a ``tRNS`` chunk, that is not opaque
  everywhere) uses it: premultiplied colour ``p = c · α``. This holds even with
  ``background="white"``.
- A file without real transparency is masked only with ``background="white"``
  (:func:`white_background_alpha`): a pixel is background when **all** of its sRGB-encoded
  channels are ≥ ``1 − threshold`` (``threshold`` is in encoded units, so 0.05 ≈ 13/255).
  ``fill_holes=True`` makes near-white areas enclosed by the object opaque (default: they
  are transparent, like the gap in a mug's handle, so white parts of an object that are
  enclosed by it become transparent too). With ``soften=True`` (default) the edge is
  softened by one pixel *inwards*: a foreground pixel gets ``α`` = the fraction of
  foreground pixels in its 3 × 3 neighbourhood (background pixels stay 0), and its colour is
  un-mixed from the white it was blended with, ``p = clip(c − (1 − α), 0, α)``
  (linear white = 1; ``c = α·F + (1 − α)·1`` ⇒ ``α·F = c − (1 − α)``), so a pale fringe
  does not survive as a light halo.
- Either mask is cleaned (``clean=True``, default; :func:`clean_mask`): image-edge rows and
  columns that are ≥ 90 % covered are cleared (cut-outs often keep a 1–3 px line of
  leftover background along the canvas edge: most files of the tree collection do), and
  8-connected regions smaller than 0.05 % of the image are dropped (specks).
  ``erode=k`` shrinks the mask by ``k`` source pixels (a minimum filter), which trims a rim
  of background that a cut-out carries along its outline (off by default).
- Otherwise (no transparency, ``background=None``) the file is rejected as ``no_alpha`` with
  a message that says to set ``data.background: white`` (``--background white`` for ``reconstruct``). A training collection needs masks,
  and a fully opaque photo would teach the networks a square silhouette.
- A mask that is empty (alpha 0 everywhere, nothing but white, or nothing left after
  cleaning) is rejected as ``fully_transparent``.

**The background a photo shows** (:func:`border_background`): white masking takes a photo's
background to be white; one on black (or on a coloured or busy background) keeps the whole frame
as its mask, silently. Its border (the outermost row or column of pixels on each side) tells: it
is ``"white"`` where at least :data:`BORDER_SHARE` of its pixels are within ``threshold`` of white
in every channel (what the masking takes as background), ``"black"`` where that share is within
``threshold`` of black, else ``"other"``. The photo loader names the photos without transparency,
and those whose border is not white, in one warning (:mod:`.scan`).
"""

from __future__ import annotations

import functools
import math
from typing import Optional

import numpy as np

from ...errors import UserError
from ...images import srgb_to_linear
from .decode import DecodedImage
from .rejections import ImageRejected

__all__ = ["srgb_decoding_table", "clean_mask", "white_background_alpha", "premultiplied_linear",
           "BACKGROUNDS", "border_background", "BORDER_SHARE"]

#: ``background`` choices: ``None`` (files need transparency) or ``"white"``.
BACKGROUNDS = (None, "white")

#: The share of a photo's border pixels near one colour that makes it the photo's background.
BORDER_SHARE = 0.5

#: Regions smaller than this fraction of the image are specks (dropped by :func:`clean_mask`).
MIN_REGION = 5e-4


@functools.lru_cache(maxsize=4)
def srgb_decoding_table(bit_depth: int) -> np.ndarray:
    """Linear values of all sRGB codes ``q`` of a bit depth ``b``.

    ``srgb_to_linear(q / (2^b − 1))`` (colour-science's ``cctf_decoding``, bit for bit) for
    ``q = 0 … 2^b − 1``.

    Returns a read-only float32 array of ``2**bit_depth`` entries; index it with integer codes.
    """
    codes = np.arange(1 << bit_depth, dtype=np.float64) / ((1 << bit_depth) - 1)
    table = np.clip(srgb_to_linear(codes), 0.0, 1.0).astype(np.float32)
    table.setflags(write=False)
    return table


def _strip_frame(support: np.ndarray, coverage: float = 0.9,
                 max_depth: Optional[int] = None) -> np.ndarray:
    """Clear frame lines: image-edge rows/columns where ≥ ``coverage`` of the pixels are set.

    From each side inwards, lines are cleared while they are at least ``coverage`` covered,
    up to ``max_depth`` lines (default ``max(4, 1 % of the side)``). Cut-out photos often keep
    such a line of leftover background along the canvas edge (most files of the tree
    collection have a 1–3 px opaque white frame). An object that merely touches an edge covers
    far less of that line and is kept.
    """
    h, w = support.shape
    out = support.copy()
    for axis, size, length in ((0, h, w), (1, w, h)):
        depth = max_depth if max_depth is not None else max(4, math.ceil(0.01 * size))
        depth = min(depth, size // 2)
        for from_end in (False, True):
            for k in range(depth):
                idx = size - 1 - k if from_end else k
                line = out[idx] if axis == 0 else out[:, idx]
                if line.sum() < coverage * length:
                    break
                line[...] = False
    return out


def clean_mask(support: np.ndarray, *, min_region: float = MIN_REGION) -> np.ndarray:
    """Clean a boolean object mask ``(H, W)`` → the cleaned boolean mask.

    1. Clear frame lines along the image edges (:func:`_strip_frame`).
    2. Drop 8-connected regions smaller than ``min_region × H × W`` pixels (specks: JPEG
       noise, leftover background bits; at 1000² px the default drops regions under 500 px,
       a fraction of one output pixel at R = 64).
    """
    from scipy import ndimage  # lazy: scipy is slow to import

    mask = _strip_frame(support)
    if not mask.any():
        return mask
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    areas = np.bincount(labels.ravel(), minlength=n + 1)
    keep = areas >= max(1.0, min_region * mask.size)
    keep[0] = False
    return keep[labels]


def border_background(rgb_codes: np.ndarray, max_value: int, threshold: float = 0.05) -> str:
    """What the border of a photo ``(H, W, 3)`` of sRGB-encoded codes in ``[0, max_value]`` shows:
    ``"white"`` where at least :data:`BORDER_SHARE` of its border pixels have every channel
    ≥ ``(1 − threshold)·max_value`` (white masking's background, :func:`white_background_alpha`),
    ``"black"`` where that share has every channel ≤ ``threshold·max_value``, else ``"other"``."""
    codes = np.asarray(rgb_codes)
    border = np.concatenate([codes[0], codes[-1], codes[1:-1, 0], codes[1:-1, -1]]).astype(np.float64)
    if (border >= (1.0 - threshold) * max_value).all(axis=1).mean() >= BORDER_SHARE:
        return "white"
    if (border <= threshold * max_value).all(axis=1).mean() >= BORDER_SHARE:
        return "black"
    return "other"


def white_background_alpha(rgb_codes: np.ndarray, max_value: int, threshold: float = 0.05, *,
                           clean: bool = True, fill_holes: bool = False, erode: int = 0,
                           soften: bool = True) -> np.ndarray:
    """Alpha mask of a photo on a white background → ``(H, W)`` float32 in [0, 1].

    1. Background: pixels whose sRGB-encoded channels are *all* ≥ ``(1 − threshold)·max_value``;
       the rest is foreground.
    2. ``clean=True``: :func:`clean_mask` (frame lines and specks).
    3. ``fill_holes=True`` turns background enclosed by the foreground into foreground.
    4. ``erode > 0`` shrinks the foreground by that many pixels (a square neighbourhood).
    5. ``soften=True``: a foreground pixel's alpha is the fraction of foreground pixels in its
       3 × 3 neighbourhood (edge replicated at the image border); background stays 0. Interior
       pixels keep alpha 1; the one-pixel rim, where the object was blended with the white
       background, gets 1/9 … 8/9. Without softening the mask is binary.

    Args:
        rgb_codes: ``(H, W, 3)`` integer (or float) sRGB-encoded codes in ``[0, max_value]``.
        max_value: the code of full intensity (255 or 65535; 1 for floats in [0, 1]).
        threshold: tolerance in encoded units of [0, 1] (0.05 ≈ 13 of 255 codes).
    """
    from scipy import ndimage  # lazy: scipy is slow to import

    if not 0.0 <= threshold < 1.0:
        raise UserError(f"threshold must lie in [0, 1), got {threshold!r}")
    limit = (1.0 - threshold) * max_value
    fg = ~np.all(rgb_codes >= limit, axis=2)
    if clean:
        fg = clean_mask(fg)
    if fill_holes and fg.any():
        fg = ndimage.binary_fill_holes(fg)
    if erode > 0 and fg.any():
        fg = ndimage.minimum_filter(fg, size=2 * int(erode) + 1, mode="nearest")
    if not soften:
        return fg.astype(np.float32)
    density = ndimage.uniform_filter(fg.astype(np.float32), size=3, mode="nearest")
    return np.where(fg, np.clip(density, 0.0, 1.0), 0.0).astype(np.float32)


def premultiplied_linear(decoded: DecodedImage, *, background: Optional[str] = None,
                         threshold: float = 0.05, clean: bool = True, fill_holes: bool = False,
                         erode: int = 0, soften: bool = True,
                         name: str = "<image>") -> np.ndarray:
    """A decoded image at its own size → ``(H, W, 4)`` float32 premultiplied linear RGBA.

    Linear colour ``c = table[q]`` with :func:`srgb_decoding_table`; then

    - real transparency: ``α = a / (2^bits − 1)``; with ``clean`` the support ``α > 0`` is
      cleaned by :func:`clean_mask` (frame lines, specks) and ``α`` is zeroed outside it;
      ``erode > 0`` takes the minimum of ``α`` over a ``(2·erode + 1)²`` square (this trims a
      rim of leftover background that a cut-out may carry); ``p = c·α``.
    - no real transparency and ``background="white"``: ``α`` from
      :func:`white_background_alpha`, ``p = clip(c − (1 − α), 0, α)`` (un-mixing from white).

    Raises:
        ImageRejected: ``no_alpha`` (no real transparency and ``background`` is None) or
            ``fully_transparent`` (the mask is empty, before or after cleaning).
    """
    codes = decoded.pixels
    max_value = decoded.max_value
    table = srgb_decoding_table(decoded.bit_depth)
    alpha_codes = codes[..., 3]
    if decoded.has_alpha and bool((alpha_codes < max_value).any()):
        if not alpha_codes.any():
            raise ImageRejected("fully_transparent", f"{name}: alpha is 0 everywhere "
                                                     f"(the image is fully transparent)")
        alpha = alpha_codes.astype(np.float32) * np.float32(1.0 / max_value)
        if clean:
            alpha[~clean_mask(alpha_codes > 0)] = 0.0
        if erode > 0:
            from scipy import ndimage  # lazy: scipy is slow to import (half a second), and only this needs it
            alpha = ndimage.minimum_filter(alpha, size=2 * int(erode) + 1, mode="nearest")
        if not alpha.any():
            raise ImageRejected("fully_transparent",
                                f"{name}: nothing is left of the alpha mask after cleaning "
                                f"(frame lines and specks only); turn the cleaning off to keep them "
                                f"(data.clean: false in a config, clean=False in Python)")
        rgb = table[codes[..., :3]]
        rgb *= alpha[..., None]
    elif background == "white":
        alpha = white_background_alpha(codes[..., :3], max_value, threshold, clean=clean,
                                       fill_holes=fill_holes, erode=erode, soften=soften)
        if not alpha.any():
            raise ImageRejected("fully_transparent",
                                f"{name}: every pixel is within threshold={threshold} of white "
                                f"(nothing is left after masking the white background)")
        rgb = table[codes[..., :3]]
        rgb -= (1.0 - alpha)[..., None]
        np.clip(rgb, 0.0, alpha[..., None], out=rgb)
    else:
        what = ("an alpha channel that is opaque everywhere" if decoded.has_alpha
                else "no alpha channel")
        raise ImageRejected("no_alpha", f"{name}: has {what}, so there is no mask; to mask a white background "
                                        f"set data.background: white (--set data.background=white), or pass "
                                        f"--background white to reconstruct")
    return np.concatenate([rgb, alpha[..., None]], axis=2)
