"""Photo collections: a folder of photos → a PyTorch dataset of premultiplied linear RGBA images.

PlatonicGAN learns from an *unstructured* collection: one folder of photos of one object
class, each showing one object cut out from its background. :class:`PhotoCollection` turns
such a folder into training images in the conventions of docs/conventions.md ("Images"):

- ``(4, R, R)`` float32 ``[r, g, b, alpha]`` in [0, 1], **linear** RGB **premultiplied** by
  alpha (the EA renderer's output), or ``(1, R, R)`` alpha only (``alpha_only=True``: the
  VH/AO opacity image). Row 0 is the top of the photo.

Pipeline, per file (every step is a documented choice):

1. **Discovery.** The folder is searched recursively; every regular file counts, whatever its
   sub-folder (published ``train/``, ``val/``, ``test/`` folders are ignored: the folder is one
   collection). Hidden files and folders (name starting with ``.``) are ignored and listed in
   :attr:`CollectionReport.ignored`. Symbolic links to folders are not followed.
2. **De-duplication.** Files with identical bytes (SHA-256 of the file) are one image; the
   copy with the smallest relative path (POSIX string order) is kept, the others are counted in
   :attr:`CollectionReport.duplicates` and listed in :attr:`CollectionReport.duplicate_groups`.
3. **Decoding** (:func:`decode_image`), by *content*, not by file name: PNG (any colour type
   and bit depth: palette with ``tRNS``, grey, grey + alpha, RGB, RGBA, 8 or 16 bits), JPEG and
   WebP. 16-bit PNGs keep all 16 bits: Pillow alone reduces 16-bit colour PNGs to 8 bits, so
   the low bytes are recovered with Pillow's own decoder (a second decoding with the
   little-endian raw mode; grey + alpha through a re-labelled header: :func:`_decode_png16`).
   An EXIF orientation tag is applied. Other formats (GIF, TIFF, BMP, ...) are rejected as
   ``unsupported_format``: convert them to PNG. Animated or multi-frame files are rejected too.
   Colour profiles (``iCCP``, ``gAMA``, ICC in JPEG) are ignored: files are taken to be
   sRGB-encoded; CMYK JPEGs get Pillow's naive CMYK → RGB conversion. Truncated files are
   detected only while Pillow's ``ImageFile.LOAD_TRUNCATED_IMAGES`` keeps its default, False.
4. **Colour.** sRGB-encoded codes ``q`` (0 … 2^bits − 1) are decoded to linear RGB with
   colour-science, ``c = colour.cctf_decoding(q / (2^bits − 1), "sRGB")``, tabulated once per
   bit depth (a 256- or 65 536-entry look-up table, so decoding is exact and fast). Alpha is
   linear coverage in every format and is only scaled, ``α = a / (2^bits − 1)``.
5. **Mask.**
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
     ``regions="largest"`` keeps only the largest region. ``erode=k`` shrinks the mask by
     ``k`` source pixels (a minimum filter), which trims a rim of background that a cut-out
     carries along its outline (off by default).
   - Otherwise (no transparency, ``background=None``) the file is rejected as ``no_alpha`` with
     a message that says to pass ``background="white"``. A training collection needs masks,
     and a fully opaque photo would teach the networks a square silhouette.
   - A mask that is empty (alpha 0 everywhere, nothing but white, or nothing left after
     cleaning) is rejected as ``fully_transparent``.
   - A photo (with ``crop="bbox"``: its object's bounding box) whose longer side is more than
     :data:`MAX_ASPECT` (8) times its shorter side is rejected as ``extreme_aspect``: padded to a
     square it would fill less than 1/8 of the training image (an 8 × 2000 photo becomes a
     2-pixel strip in a 16² image).
6. **Framing.** ``crop="image"`` (default) keeps the photo's framing; ``crop="bbox"`` first
   crops to the bounding box of ``α > 0``. The result is padded with transparent pixels to a
   centred square of side ``S = ceil(max(h, w) / (1 − 2·margin))``, so the longer side maps to
   ``R·(1 − 2·margin)`` output pixels and the shorter side is padded: never stretched. (An odd
   padding puts the extra source pixel at the bottom/right, a shift of ``R/(2S)`` output pixels.)
7. **Resampling** ``S × S → R × R`` of the premultiplied linear image, all four channels alike,
   with a separable antialiasing filter whose support is scaled by the reduction factor
   (Pillow's float-image resampler): ``filter="triangle"`` (default; tent filter, all weights
   ≥ 0, so each output pixel is a convex combination of input pixels: values stay in [0, 1],
   ``rgb ≤ alpha`` holds exactly and no ringing or halo can appear at silhouette edges),
   ``"box"`` (area average) or ``"lanczos"`` (Lanczos-3: sharper, but its negative lobes ring
   at edges; results are clipped back to ``0 ≤ alpha ≤ 1``, ``0 ≤ rgb ≤ alpha``).
   Resampling *premultiplied linear* values is what keeps edges free of dark or bright halos:
   transparent pixels contribute nothing whatever colour their RGB holds in the file.

Then the unique usable images are split (see :class:`PhotoCollection` and
:func:`split_counts`) and all images are decoded once and cached in memory as
``(4, R, R)`` tensors (collections are small: 32 photos at R = 64 take 2 MB).

Bad input never stops the loading of the others and is never dropped silently: each rejected
file is named in a :class:`PhotoCollectionWarning` and recorded in
:attr:`CollectionReport.skipped` with one of the reasons in :data:`REASONS`. A folder with no
usable image raises :class:`ValueError` naming the folder and summarising the rejections; a
missing folder raises :class:`FileNotFoundError`.

Example::

    from mitsuba_platonic.data.photos import PhotoCollection
    sets = PhotoCollection.load_splits("../shared/data/tree", resolution=64)
    train = sets["train"]                  # a torch Dataset of (4, 64, 64) tensors
    print(train.report)                    # files found, duplicates, skipped files, split sizes
    loader = torch.utils.data.DataLoader(train, batch_size=8, shuffle=True)
"""

from __future__ import annotations

import functools
import hashlib
import io
import logging
import math
import os
import struct
import time
import warnings
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from torch.utils.data import Dataset

from ..errors import UserError

__all__ = [
    "PhotoCollection",
    "CollectionReport",
    "SkippedFile",
    "PhotoEntry",
    "DecodedImage",
    "ImageRejected",
    "PhotoCollectionWarning",
    "decode_image",
    "prepare_image",
    "white_background_alpha",
    "clean_mask",
    "premultiplied_linear",
    "frame_and_resample",
    "srgb_decoding_table",
    "split_counts",
    "SUPPORTED_FORMATS",
    "REASONS",
    "MAX_ASPECT",
    "SPLITS",
    "BACKGROUNDS",
    "CROPS",
]

PathLike = Union[str, "os.PathLike[str]"]
logger = logging.getLogger(__name__)

#: Image formats (Pillow's names, detected from the content) that are decoded.
SUPPORTED_FORMATS = ("PNG", "JPEG", "WEBP")

#: File-name suffixes of the supported formats (used only to word messages: a file that is
#: named like an image but cannot be read is ``corrupt``, any other unreadable file
#: ``not_an_image``).
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".jpe", ".jfif", ".webp"})

#: Suffixes of other image formats: unreadable files named like this are ``unsupported_format``.
OTHER_IMAGE_SUFFIXES = frozenset({
    ".gif", ".tif", ".tiff", ".bmp", ".dib", ".heic", ".heif", ".avif", ".svg", ".psd", ".exr",
    ".hdr", ".ico", ".icns", ".ppm", ".pgm", ".pbm", ".pnm", ".tga", ".jp2", ".j2k", ".jxl",
    ".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raw", ".xcf", ".pcx", ".dds",
})

#: Why a file can be skipped (the keys of :attr:`CollectionReport.skipped_by_reason`).
REASONS: Dict[str, str] = {
    "not_an_image": "not an image file",
    "unsupported_format": "an image format or pixel layout this loader does not read",
    "corrupt": "a corrupt or truncated image",
    "too_large": "an image larger than Pillow's decompression-bomb limit",
    "unreadable": "a file that could not be read (permissions, I/O error)",
    "no_alpha": "an image without transparency, loaded without background='white'",
    "fully_transparent": "an image whose mask is empty (alpha 0 everywhere, or all white)",
    "extreme_aspect": "an image (with crop='bbox': its object) whose longer side is more than "
                      "8 times its shorter side (MAX_ASPECT)",
}

#: The largest aspect ratio (longer side / shorter side) of what is framed: the photo, or with
#: ``crop="bbox"`` its object's bounding box. Framing pads the shorter side to a square, so the
#: content covers only 1 / ratio of the training image: beyond 8:1 that is under 12.5 %, a strip
#: at most R/8 pixels across (2 pixels at R = 16), which would teach the networks a near-empty image.
MAX_ASPECT = 8.0

#: Split names accepted by :class:`PhotoCollection`.
SPLITS = ("train", "val", "test", "all")

BACKGROUNDS = (None, "white")
CROPS = ("image", "bbox")
_FILTERS = ("triangle", "box", "lanczos")
_REGIONS = ("all", "largest")


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


# --------------------------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DecodedImage:
    """A decoded file, before any colour conversion.

    Attributes:
        pixels: ``(H, W, 4)`` ``uint8`` (8-bit sources) or ``uint16`` (16-bit sources):
            sRGB-encoded R, G, B and straight (not premultiplied) alpha codes, row 0 at the
            top, EXIF orientation applied. Grey images are repeated into R, G, B; images
            without transparency get alpha = the maximum code.
        has_alpha: whether the file carries transparency (an alpha channel or a ``tRNS`` chunk).
            It may still be opaque everywhere (:func:`prepare_image` then treats it as having
            no alpha).
        bit_depth: 8 or 16 (bits per channel of ``pixels``).
        format: Pillow's format name (``"PNG"``, ``"JPEG"``, ``"WEBP"``).
        mode: Pillow's pixel mode of the file (e.g. ``"P"``, ``"RGBA"``, ``"I;16"``), with
            ``";16"`` appended for 16-bit colour PNGs (which Pillow itself reports as 8-bit).
    """

    pixels: np.ndarray
    has_alpha: bool
    bit_depth: int
    format: str
    mode: str

    @property
    def max_value(self) -> int:
        """The largest code, ``2**bit_depth − 1``."""
        return (1 << self.bit_depth) - 1

    @property
    def size(self) -> Tuple[int, int]:
        """``(width, height)`` in pixels."""
        return int(self.pixels.shape[1]), int(self.pixels.shape[0])

    def rgba(self) -> np.ndarray:
        """``(H, W, 4)`` float64 codes scaled to [0, 1] (sRGB-encoded RGB, straight alpha)."""
        return self.pixels.astype(np.float64) / self.max_value


def _suffix_reason(name: str) -> str:
    suffix = Path(name).suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        return "corrupt"
    if suffix in OTHER_IMAGE_SUFFIXES:
        return "unsupported_format"
    return "not_an_image"


def _rawmode(im) -> Optional[str]:
    """The raw mode of a Pillow image's first tile (PNG: e.g. ``"RGB;16B"``), if any."""
    if not im.tile:
        return None
    args = im.tile[0][3]
    if isinstance(args, tuple):
        args = args[0] if args else None
    return args if isinstance(args, str) else None


def _with_rawmode(tile, rawmode: str):
    """A Pillow tile descriptor ``(codec, extents, offset, args)`` with another raw mode."""
    args = tile[3]
    args = rawmode if isinstance(args, str) else (rawmode,) + tuple(args[1:])
    return tile._replace(args=args) if hasattr(tile, "_replace") else (*tile[:3], args)


def _loaded_array(im) -> np.ndarray:
    """Decode a Pillow image, apply its EXIF orientation, return it as a numpy array."""
    from PIL import ImageOps

    im.load()
    if im.getexif().get(0x0112, 1) not in (0, 1):  # EXIF orientation other than "normal"
        im = ImageOps.exif_transpose(im)
    return np.asarray(im)


def _patched_ihdr(data: bytes, bit_depth: int, colour_type: int) -> bytes:
    """The PNG ``data`` with its IHDR bit depth and colour type replaced (CRC recomputed)."""
    if data[12:16] != b"IHDR":
        raise ValueError("PNG does not start with an IHDR chunk")
    ihdr = bytearray(data[16:29])
    ihdr[8], ihdr[9] = bit_depth, colour_type
    crc = struct.pack(">I", zlib.crc32(b"IHDR" + bytes(ihdr)) & 0xFFFFFFFF)
    return data[:16] + bytes(ihdr) + crc + data[33:]


def _key_alpha(values: np.ndarray, key) -> np.ndarray:
    """Alpha codes from a ``tRNS`` colour key: 0 where ``values`` (H, W, C) equals ``key``."""
    key = np.atleast_1d(np.asarray(key, dtype=np.int64))
    if key.size != values.shape[2]:
        raise ImageRejected("corrupt", f"tRNS key {tuple(key)} does not match "
                                       f"{values.shape[2]} channel(s)")
    return ~np.all(values.astype(np.int64) == key, axis=2)


def _decode_png16(im, data: bytes, rawmode: str) -> Tuple[np.ndarray, bool]:
    """16-bit colour PNG → ``(H, W, 4)`` uint16 codes and ``has_alpha``.

    Pillow unfilters 16-bit PNG scanlines correctly but keeps only the high byte of each
    sample. Two exact work-arounds that reuse Pillow's own decoder:

    - RGB / RGBA (raw modes ``RGB;16B`` / ``RGBA;16B``): decode a second time with the
      little-endian raw mode (``RGB;16L`` / ``RGBA;16L``); its "high byte" is the second byte
      of each big-endian sample, i.e. the low byte. ``code = 256·hi + lo``.
    - grey + alpha (``LA;16B``): a 16-bit grey + alpha pixel has the same 4 bytes per pixel, and
      so the same scanline filtering, as an 8-bit RGBA pixel; the file is decoded with its
      header patched to 8-bit RGBA, which yields the bytes ``(L_hi, L_lo, A_hi, A_lo)``.
    """
    from PIL import Image

    if rawmode in ("RGB;16B", "RGBA;16B"):
        hi = _loaded_array(im).astype(np.uint16)
        low = Image.open(io.BytesIO(data))
        low.tile = [_with_rawmode(t, rawmode[:-1] + "L") for t in low.tile]
        lo = _loaded_array(low).astype(np.uint16)
        codes = (hi << 8) | lo
        if rawmode == "RGBA;16B":
            return codes, True
        trns = im.info.get("transparency")
        alpha = np.full(codes.shape[:2], 65535, np.uint16)
        if trns is not None:
            alpha[~_key_alpha(codes, trns)] = 0
        return np.concatenate([codes, alpha[..., None]], axis=2), trns is not None
    # "LA;16B"
    raw = _loaded_array(Image.open(io.BytesIO(_patched_ihdr(data, 8, 6)))).astype(np.uint16)
    grey = (raw[..., 0] << 8) | raw[..., 1]
    alpha = (raw[..., 2] << 8) | raw[..., 3]
    return np.stack([grey, grey, grey, alpha], axis=2), True


def _decode_pixels(im, data: bytes) -> Tuple[np.ndarray, bool, int, str]:
    """Pillow image (just opened) → (codes (H, W, 4), has_alpha, bit depth, mode label)."""
    mode = im.mode
    rawmode = _rawmode(im)
    if im.format == "PNG" and rawmode in ("RGB;16B", "RGBA;16B", "LA;16B"):
        codes, has_alpha = _decode_png16(im, data, rawmode)
        return codes, has_alpha, 16, f"{mode};16"
    trns = im.info.get("transparency")
    if mode in ("I;16", "I;16B", "I;16L", "I"):
        grey = _loaded_array(im)
        if mode == "I" and (grey.min() < 0 or grey.max() > 65535):
            raise ImageRejected("unsupported_format", "32-bit integer images are not supported")
        grey = grey.astype(np.uint16)
        alpha = np.full(grey.shape, 65535, np.uint16)
        if trns is not None:
            alpha[~_key_alpha(grey[..., None], trns)] = 0
        return np.stack([grey, grey, grey, alpha], axis=2), trns is not None, 16, mode
    if mode in ("RGBA", "LA", "PA", "RGBa", "La") or (
            trns is not None and mode in ("P", "L", "1", "RGB")):
        # Pillow applies tRNS (palette alpha or a colour key) when converting to RGBA.
        im.load()
        return _loaded_array(im.convert("RGBA")), True, 8, mode
    if mode in ("1", "L", "P", "RGB", "CMYK", "YCbCr", "LAB", "HSV", "RGBX"):
        im.load()
        rgb = _loaded_array(im.convert("RGB"))
        alpha = np.full(rgb.shape[:2] + (1,), 255, np.uint8)
        return np.concatenate([rgb, alpha], axis=2), False, 8, mode
    raise ImageRejected("unsupported_format", f"pixel mode {mode!r} is not supported")


def decode_image(source: Union[PathLike, bytes], name: Optional[str] = None) -> DecodedImage:
    """Decode one image file (a path, or its bytes) into integer codes; see :class:`DecodedImage`.

    The format is detected from the content, not the name. 8-bit sources give ``uint8`` codes;
    16-bit PNGs (grey, grey + alpha, RGB, RGBA, with or without a ``tRNS`` colour key) give
    ``uint16`` codes with all 16 bits (see :func:`_decode_png16`).

    Args:
        source: a file path, or the file's bytes.
        name: the name used in messages (default: the path, or ``"<bytes>"``); its suffix also
            words the rejection of unreadable content (``.png`` → ``corrupt``, ``.gif`` →
            ``unsupported_format``, ``.txt`` → ``not_an_image``).

    Raises:
        ImageRejected: with ``reason`` ``not_an_image``, ``unsupported_format``, ``corrupt``
            or ``too_large``; the message names the file.
        OSError: if the path cannot be read.
    """
    from PIL import Image, UnidentifiedImageError

    if isinstance(source, (bytes, bytearray, memoryview)):
        data = bytes(source)
        label = name or "<bytes>"
    else:
        data = Path(source).read_bytes()
        label = name or str(source)
    if not data:
        raise ImageRejected(_suffix_reason(label), f"{label}: the file is empty (0 bytes)")
    try:
        im = Image.open(io.BytesIO(data))
    except UnidentifiedImageError:
        reason = _suffix_reason(label)
        what = {"corrupt": f"named like an image ({Path(label).suffix}) but its content is "
                           f"not a readable image",
                "unsupported_format": f"{Path(label).suffix} files are not supported "
                                      f"(supported: {', '.join(SUPPORTED_FORMATS)})",
                "not_an_image": "not an image (its content is no known image format)"}[reason]
        raise ImageRejected(reason, f"{label}: {what}") from None
    except Image.DecompressionBombError as err:
        raise ImageRejected("too_large", f"{label}: {err}") from None
    except Exception as err:  # noqa: BLE001 - a header Pillow cannot parse
        raise ImageRejected("corrupt", f"{label}: corrupt image header "
                                       f"({type(err).__name__}: {err})") from None
    fmt = im.format or "unknown"
    if fmt not in SUPPORTED_FORMATS:
        raise ImageRejected("unsupported_format",
                            f"{label}: {fmt} images are not supported (supported: "
                            f"{', '.join(SUPPORTED_FORMATS)}); convert it to PNG")
    frames = getattr(im, "n_frames", 1)
    if frames > 1:
        raise ImageRejected("unsupported_format",
                            f"{label}: animated/multi-frame {fmt} ({frames} frames) is not "
                            f"supported; save the frame you want as a still PNG")
    if im.width < 1 or im.height < 1:
        raise ImageRejected("corrupt", f"{label}: image has no pixels ({im.width}×{im.height})")
    try:
        codes, has_alpha, bits, mode = _decode_pixels(im, data)
    except ImageRejected as err:
        raise ImageRejected(err.reason, f"{label}: {err.message}") from None
    except Image.DecompressionBombError as err:
        raise ImageRejected("too_large", f"{label}: {err}") from None
    except Exception as err:  # noqa: BLE001 - truncated data, bad CRC, zlib errors, ...
        raise ImageRejected("corrupt", f"{label}: cannot decode the {fmt} data, the file is "
                                       f"corrupt or truncated ({type(err).__name__}: {err})"
                            ) from None
    return DecodedImage(np.ascontiguousarray(codes), bool(has_alpha), bits, fmt, mode)


# --------------------------------------------------------------------------------------------
# Colour, masks, framing, resampling
# --------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def srgb_decoding_table(bit_depth: int) -> np.ndarray:
    """Linear values of all sRGB codes ``q`` of a bit depth ``b``.

    ``colour.cctf_decoding(q / (2^b − 1), "sRGB")`` for ``q = 0 … 2^b − 1``.

    Returns a read-only float32 array of ``2**bit_depth`` entries; index it with integer codes.
    """
    import colour

    codes = np.arange(1 << bit_depth, dtype=np.float64) / ((1 << bit_depth) - 1)
    table = np.asarray(colour.cctf_decoding(codes, function="sRGB"), dtype=np.float64)
    table = np.clip(table, 0.0, 1.0).astype(np.float32)
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


def clean_mask(support: np.ndarray, *, min_region: float = 5e-4, regions: str = "all",
               strip_frame: bool = True) -> np.ndarray:
    """Clean a boolean object mask ``(H, W)`` → the cleaned boolean mask.

    1. ``strip_frame``: clear frame lines along the image edges (:func:`_strip_frame`).
    2. Drop 8-connected regions smaller than ``min_region × H × W`` pixels (specks: JPEG
       noise, leftover background bits; at 1000² px the default drops regions under 500 px,
       a fraction of one output pixel at R = 64).
    3. ``regions="largest"`` keeps only the largest region; ``"all"`` keeps every other one.
    """
    from scipy import ndimage

    if regions not in _REGIONS:
        raise UserError(f"regions must be one of {_REGIONS}, got {regions!r}")
    mask = _strip_frame(support) if strip_frame else support.astype(bool, copy=True)
    if not mask.any():
        return mask
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    areas = np.bincount(labels.ravel(), minlength=n + 1)
    areas[0] = 0
    keep = areas >= max(1.0, min_region * mask.size)
    if regions == "largest":
        keep = np.zeros_like(keep)
        keep[int(np.argmax(areas))] = True
    keep[0] = False
    return keep[labels]


def white_background_alpha(rgb_codes: np.ndarray, max_value: int, threshold: float = 0.05, *,
                           clean: bool = True, regions: str = "all", fill_holes: bool = False,
                           erode: int = 0, soften: bool = True,
                           min_region: float = 5e-4) -> np.ndarray:
    """Alpha mask of a photo on a white background → ``(H, W)`` float32 in [0, 1].

    1. Background: pixels whose sRGB-encoded channels are *all* ≥ ``(1 − threshold)·max_value``;
       the rest is foreground.
    2. ``clean=True``: :func:`clean_mask` (frame lines, specks under ``min_region``, and
       ``regions``); with ``clean=False`` only ``regions="largest"`` is applied.
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
    from scipy import ndimage

    if not 0.0 <= threshold < 1.0:
        raise UserError(f"threshold must lie in [0, 1), got {threshold!r}")
    limit = (1.0 - threshold) * max_value
    fg = ~np.all(rgb_codes >= limit, axis=2)
    if clean or regions != "all":
        fg = clean_mask(fg, min_region=min_region if clean else 0.0, regions=regions,
                        strip_frame=clean)
    if fill_holes and fg.any():
        fg = ndimage.binary_fill_holes(fg)
    if erode > 0 and fg.any():
        fg = ndimage.minimum_filter(fg, size=2 * int(erode) + 1, mode="nearest")
    if not soften:
        return fg.astype(np.float32)
    density = ndimage.uniform_filter(fg.astype(np.float32), size=3, mode="nearest")
    return np.where(fg, np.clip(density, 0.0, 1.0), 0.0).astype(np.float32)


def _resample(planes: np.ndarray, resolution: int, filter: str) -> np.ndarray:
    """``(C, S, S)`` float32 → ``(C, R, R)`` with Pillow's antialiasing float resampler."""
    from PIL import Image

    resample = {"triangle": Image.Resampling.BILINEAR, "box": Image.Resampling.BOX,
                "lanczos": Image.Resampling.LANCZOS}[filter]
    out = np.empty((planes.shape[0], resolution, resolution), np.float32)
    for c, plane in enumerate(planes):
        image = Image.fromarray(np.ascontiguousarray(plane, dtype=np.float32))
        out[c] = np.asarray(image.resize((resolution, resolution), resample=resample))
    return out


def premultiplied_linear(decoded: DecodedImage, *, background: Optional[str] = None,
                         threshold: float = 0.05, clean: bool = True, regions: str = "all",
                         fill_holes: bool = False, erode: int = 0, soften: bool = True,
                         name: str = "<image>") -> np.ndarray:
    """A decoded image at its own size → ``(H, W, 4)`` float32 premultiplied linear RGBA.

    Steps 4–5 of the module docstring. Linear colour ``c = table[q]`` with
    :func:`srgb_decoding_table`; then

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
    from scipy import ndimage

    codes = decoded.pixels
    max_value = decoded.max_value
    table = srgb_decoding_table(decoded.bit_depth)
    alpha_codes = codes[..., 3]
    if decoded.has_alpha and bool((alpha_codes < max_value).any()):
        if not alpha_codes.any():
            raise ImageRejected("fully_transparent", f"{name}: alpha is 0 everywhere "
                                                     f"(the image is fully transparent)")
        alpha = alpha_codes.astype(np.float32) * np.float32(1.0 / max_value)
        if clean or regions != "all":
            support = clean_mask(alpha_codes > 0, min_region=5e-4 if clean else 0.0,
                                 regions=regions, strip_frame=clean)
            alpha[~support] = 0.0
        if erode > 0:
            alpha = ndimage.minimum_filter(alpha, size=2 * int(erode) + 1, mode="nearest")
        if not alpha.any():
            raise ImageRejected("fully_transparent",
                                f"{name}: nothing is left of the alpha mask after cleaning "
                                f"(frame lines and specks only); pass clean=False to keep them")
        rgb = table[codes[..., :3]]
        rgb *= alpha[..., None]
    elif background == "white":
        alpha = white_background_alpha(codes[..., :3], max_value, threshold, clean=clean,
                                       regions=regions, fill_holes=fill_holes, erode=erode,
                                       soften=soften)
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
        raise ImageRejected("no_alpha", f"{name}: has {what}, so there is no mask; pass "
                                        f"background='white' to mask a white background")
    return np.concatenate([rgb, alpha[..., None]], axis=2)


def _check_aspect(w: int, h: int, name: str, what: str = "the image") -> None:
    """Raise ``ImageRejected('extreme_aspect')`` if ``max(w, h) / min(w, h)`` exceeds :data:`MAX_ASPECT`."""
    ratio = max(w, h) / max(1, min(w, h))
    if ratio > MAX_ASPECT:
        raise ImageRejected("extreme_aspect",
                            f"{name}: {what} is {w} × {h} pixels, an aspect ratio of {ratio:.3g}:1; at most "
                            f"{MAX_ASPECT:g}:1 is accepted, since padded to a square it would fill only "
                            f"{100.0 / ratio:.2g} % of the training image; crop it to the object first")


def frame_and_resample(image: np.ndarray, resolution: int = 64, *, crop: str = "image",
                       margin: float = 0.0, filter: str = "triangle", name: str = "<image>") -> np.ndarray:
    """``(H, W, 4)`` premultiplied linear RGBA → ``(4, R, R)`` float32 (steps 6–7).

    ``crop="bbox"`` crops to the bounding box of ``α > 0`` first; the image is then padded
    with transparent pixels to a centred square of side ``S = ceil(max(h, w) / (1 − 2·margin))``
    and resampled to ``R × R`` with the antialiasing ``filter``. The result is clipped to
    ``0 ≤ alpha ≤ 1``, ``0 ≤ rgb ≤ alpha`` (a no-op for the non-negative filters).

    Raises:
        ImageRejected: ``extreme_aspect`` if what is framed (the image, or with ``crop="bbox"``
            the bounding box) is more than :data:`MAX_ASPECT` times longer than wide or wider than long.
    """
    alpha = image[..., 3]
    if crop == "bbox":
        rows = np.flatnonzero(alpha.any(axis=1))
        cols = np.flatnonzero(alpha.any(axis=0))
        if rows.size:
            image = image[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    h, w = image.shape[:2]
    _check_aspect(w, h, name, "its object's bounding box" if crop == "bbox" else "the image")
    side = max(h, w, math.ceil(max(h, w) / (1.0 - 2.0 * margin) - 1e-9))
    top, left = (side - h) // 2, (side - w) // 2
    planes = np.zeros((4, side, side), np.float32)
    planes[:, top:top + h, left:left + w] = np.moveaxis(image, 2, 0)
    out = _resample(planes, resolution, filter)
    np.clip(out[3], 0.0, 1.0, out=out[3])
    np.clip(out[:3], 0.0, out[3:4], out=out[:3])
    return out


def prepare_image(decoded: DecodedImage, resolution: int = 64, *,
                  background: Optional[str] = None, threshold: float = 0.05,
                  crop: str = "image", margin: float = 0.0, filter: str = "triangle",
                  clean: bool = True, regions: str = "all", fill_holes: bool = False,
                  erode: int = 0, soften: bool = True, name: str = "<image>") -> np.ndarray:
    """A decoded image → ``(4, R, R)`` float32 premultiplied linear ``[r, g, b, alpha]``.

    :func:`premultiplied_linear` (colour and mask) followed by :func:`frame_and_resample`
    (crop, centred transparent padding, antialiased resampling). The result satisfies
    ``0 ≤ alpha ≤ 1`` and ``0 ≤ rgb ≤ alpha``.

    Raises:
        ImageRejected: ``no_alpha`` or ``fully_transparent`` (see :func:`premultiplied_linear`),
            ``extreme_aspect`` (see :data:`MAX_ASPECT`).
        ValueError: on invalid options.
    """
    _check_options(resolution, background, threshold, crop, margin, filter, regions, erode)
    if crop == "image":                                   # before masking: the photo's own shape
        _check_aspect(*decoded.size, name)
    image = premultiplied_linear(decoded, background=background, threshold=threshold,
                                 clean=clean, regions=regions, fill_holes=fill_holes,
                                 erode=erode, soften=soften, name=name)
    return frame_and_resample(image, resolution, crop=crop, margin=margin, filter=filter, name=name)


def _check_options(resolution, background, threshold, crop, margin, filter, regions,
                   erode) -> None:
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
    if filter not in _FILTERS:
        raise UserError(f"filter must be one of {_FILTERS}, got {filter!r}")
    if regions not in _REGIONS:
        raise UserError(f"regions must be one of {_REGIONS}, got {regions!r}")
    if isinstance(erode, bool) or not isinstance(erode, (int, np.integer)) or erode < 0:
        raise UserError(f"erode must be a non-negative integer (pixels), got {erode!r}")


# --------------------------------------------------------------------------------------------
# Splits
# --------------------------------------------------------------------------------------------


def split_counts(n: int, fractions: Sequence[float]) -> Tuple[int, ...]:
    """Sizes of the splits of ``n`` items for ``fractions`` (non-negative, summing to 1).

    Largest-remainder rounding of ``fᵢ·n`` (ties go to the earlier split), so the sizes sum to
    ``n``; then every split with ``fᵢ > 0`` that got nothing takes one item from the largest
    split, as long as ``n`` is at least the number of such splits.
    Example: ``n = 32``, (0.8, 0.1, 0.1) → (26, 3, 3).
    """
    fractions = [float(f) for f in fractions]
    exact = [f * n for f in fractions]
    counts = [math.floor(x) for x in exact]
    order = sorted(range(len(fractions)), key=lambda i: (-(exact[i] - counts[i]), i))
    for i in order[: n - sum(counts)]:
        counts[i] += 1
    positive = [i for i, f in enumerate(fractions) if f > 0]
    if n >= len(positive):
        for i in positive:
            if counts[i] == 0:
                donor = max(range(len(counts)), key=lambda j: (counts[j], -j))
                counts[donor] -= 1
                counts[i] += 1
    return tuple(counts)


def _check_splits(splits: Sequence[float]) -> Tuple[float, float, float]:
    try:
        values = tuple(float(f) for f in splits)
    except (TypeError, ValueError):
        raise UserError(f"splits must be three fractions (train, val, test), got {splits!r}"
                        ) from None
    if len(values) != 3 or not all(math.isfinite(f) and f >= 0 for f in values) \
            or abs(sum(values) - 1.0) > 1e-6:
        raise UserError(f"splits must be three non-negative fractions (train, val, test) "
                        f"summing to 1, got {splits!r}")
    return values  # type: ignore[return-value]


def _rank_key(seed: int, sha256: str) -> str:
    """Seeded shuffle key: SHA-256 of ``"<seed>:<content hash>"`` (independent of names)."""
    return hashlib.sha256(f"{seed}:{sha256}".encode()).hexdigest()


# --------------------------------------------------------------------------------------------
# The collection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SkippedFile:
    """A file that was not loaded: its path, a :data:`REASONS` key and a message naming it."""

    path: Path
    reason: str
    message: str


@dataclass(frozen=True)
class PhotoEntry:
    """One unique usable image of a collection.

    Attributes:
        path: the kept file (smallest relative path among byte-identical copies).
        sha256: hex SHA-256 of the file's bytes.
        size: ``(width, height)`` of the decoded photo (after EXIF orientation).
        format: ``"PNG"``, ``"JPEG"`` or ``"WEBP"``.
        bit_depth: 8 or 16.
        mask: ``"alpha"`` (the file's transparency) or ``"white"`` (white-background masking).
        duplicates: the other paths with the same bytes (dropped).
    """

    path: Path
    sha256: str
    size: Tuple[int, int]
    format: str
    bit_depth: int
    mask: str
    duplicates: Tuple[Path, ...] = ()


@dataclass
class CollectionReport:
    """What loading a folder found. ``str(report)`` gives a readable summary.

    Attributes:
        folder: the folder (absolute).
        files_found: regular, non-hidden files found (recursively).
        unique_files: distinct contents among them.
        duplicates: files dropped because an identical file was kept (``files_found −
            unique_files``).
        duplicate_groups: kept path → the dropped identical paths.
        usable: unique files that became training images.
        skipped: the unique files that were rejected, with reasons, in path order.
        ignored: hidden files and folders that were not looked at.
        split_sizes: images per split (``train``, ``val``, ``test``).
        seconds: wall time of the scan (hashing, decoding, resampling).
    """

    folder: Path
    files_found: int = 0
    unique_files: int = 0
    duplicates: int = 0
    duplicate_groups: Dict[Path, List[Path]] = field(default_factory=dict)
    usable: int = 0
    skipped: List[SkippedFile] = field(default_factory=list)
    ignored: List[Path] = field(default_factory=list)
    split_sizes: Dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def skipped_by_reason(self) -> Dict[str, int]:
        """Number of skipped files per reason (only reasons that occurred)."""
        counts: Dict[str, int] = {}
        for s in self.skipped:
            counts[s.reason] = counts.get(s.reason, 0) + 1
        return counts

    @property
    def skipped_files(self) -> List[Path]:
        """The paths of the skipped files."""
        return [s.path for s in self.skipped]

    def summary(self) -> str:
        """A few readable lines."""
        lines = [f"photo collection {self.folder}: {self.files_found} file(s), "
                 f"{self.unique_files} unique ({self.duplicates} duplicate(s) dropped), "
                 f"{self.usable} usable, {len(self.skipped)} skipped; "
                 f"{self.seconds:.2f} s"]
        if self.split_sizes:
            lines.append("  splits: " + ", ".join(f"{k} {v}" for k, v in self.split_sizes.items()))
        for reason, count in self.skipped_by_reason.items():
            lines.append(f"  skipped {count} × {reason} ({REASONS[reason]})")
        for s in self.skipped:
            lines.append(f"    {s.message}")
        if self.ignored:
            lines.append(f"  ignored {len(self.ignored)} hidden path(s)")
        return "\n".join(lines)

    __str__ = summary


@dataclass(frozen=True)
class _Options:
    """The image options of a collection (validated by :func:`_check_options`)."""

    resolution: int = 64
    background: Optional[str] = None
    threshold: float = 0.05
    crop: str = "image"
    margin: float = 0.0
    filter: str = "triangle"
    clean: bool = True
    regions: str = "all"
    fill_holes: bool = False
    erode: int = 0
    soften: bool = True

    def __post_init__(self):
        _check_options(self.resolution, self.background, self.threshold, self.crop,
                       self.margin, self.filter, self.regions, self.erode)

    def image_kwargs(self) -> dict:
        """Keyword arguments of :func:`prepare_image` (all fields but ``resolution``)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "resolution"}


def _discover(folder: Path) -> Tuple[List[Path], List[Path], List[Path]]:
    """Files under ``folder``: regular non-hidden files (sorted by relative path), ignored
    hidden paths, and other non-hidden entries that are not regular files (broken links...)."""
    files: List[Path] = []
    ignored: List[Path] = []
    others: List[Path] = []
    for root, dirs, names in os.walk(folder, followlinks=False):
        root_path = Path(root)
        for d in sorted(dirs):
            if d.startswith("."):
                ignored.append(root_path / d)
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for n in sorted(names):
            p = root_path / n
            if n.startswith("."):
                ignored.append(p)
            elif p.is_file():
                files.append(p)
            else:
                others.append(p)
    files.sort(key=lambda p: p.relative_to(folder).as_posix())
    return files, sorted(ignored), others


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _load_one(path: Path, options: _Options):
    """Worker: decode and prepare one file → (entry fields, (4, R, R) array) or a SkippedFile."""
    try:
        decoded = decode_image(path)
        image = prepare_image(decoded, options.resolution, name=str(path),
                              **options.image_kwargs())
    except ImageRejected as err:
        return SkippedFile(path, err.reason, err.message)
    except OSError as err:
        return SkippedFile(path, "unreadable", f"{path}: cannot read the file "
                                               f"({type(err).__name__}: {err})")
    real_alpha = decoded.has_alpha and bool((decoded.pixels[..., 3] < decoded.max_value).any())
    info = (decoded.size, decoded.format, decoded.bit_depth, "alpha" if real_alpha else "white")
    return info, image


@dataclass
class _Scan:
    entries: Dict[str, PhotoEntry]          # sha256 → entry (usable images)
    images: Dict[str, torch.Tensor]         # sha256 → (4, R, R)
    assignment: Dict[str, List[str]]        # split → sha256 list (content-hash order)
    report: CollectionReport
    options: _Options
    fractions: Tuple[float, float, float]
    seed: int


def _scan(folder: PathLike, options: _Options, splits: Tuple[float, float, float], seed: int,
          workers: Optional[int]) -> _Scan:
    start = time.perf_counter()
    root = Path(folder).expanduser()
    if not root.exists():
        raise FileNotFoundError(f"photo folder {str(root)!r} does not exist")
    if not root.is_dir():
        raise NotADirectoryError(f"photo folder {str(root)!r} is not a folder")
    root = root.resolve()
    report = CollectionReport(folder=root)
    files, report.ignored, others = _discover(root)
    report.files_found = len(files) + len(others)
    report.skipped = [SkippedFile(p, "unreadable", f"{p}: not a regular file (a broken link?)")
                      for p in others]
    if not files and not others:
        hidden = (f"; only {len(report.ignored)} hidden entr(y/ies), which are ignored"
                  if report.ignored else "")
        raise UserError(f"no usable images in {str(root)!r}: the folder is empty (no files "
                        f"in it or its sub-folders{hidden})")

    groups: Dict[str, List[Path]] = {}
    for p in files:  # sorted by relative path: the first of a group is kept
        try:
            digest = _file_sha256(p)
        except OSError as err:
            report.skipped.append(SkippedFile(p, "unreadable", f"{p}: cannot read the file "
                                                               f"({type(err).__name__}: {err})"))
            continue
        groups.setdefault(digest, []).append(p)
    report.unique_files = len(groups) + len(report.skipped)  # unreadable files count once
    report.duplicates = sum(len(g) - 1 for g in groups.values())
    report.duplicate_groups = {g[0]: g[1:] for g in groups.values() if len(g) > 1}

    keys = list(groups)
    srgb_decoding_table(8)           # import colour-science (slow) once, before any thread
    import scipy.ndimage  # noqa: F401  (likewise)
    n_workers = min(8, os.cpu_count() or 1) if workers is None else int(workers)
    if n_workers > 1 and len(keys) > 1:
        with ThreadPoolExecutor(max_workers=n_workers) as pool:
            results = list(pool.map(lambda k: _load_one(groups[k][0], options), keys))
    else:
        results = [_load_one(groups[k][0], options) for k in keys]

    entries: Dict[str, PhotoEntry] = {}
    images: Dict[str, torch.Tensor] = {}
    for key, result in zip(keys, results):
        if isinstance(result, SkippedFile):
            report.skipped.append(result)
            continue
        (size, fmt, bits, mask), image = result
        entries[key] = PhotoEntry(groups[key][0], key, size, fmt, bits, mask,
                                  tuple(groups[key][1:]))
        images[key] = torch.from_numpy(image)
    report.skipped.sort(key=lambda s: s.path.relative_to(root).as_posix())
    report.usable = len(entries)
    for s in report.skipped:
        warnings.warn(f"skipped {s.message} [{s.reason}]", PhotoCollectionWarning, stacklevel=3)

    if not entries:
        reasons = "; ".join(f"{count} {reason}" for reason, count in
                            report.skipped_by_reason.items())
        detail = "\n  ".join(s.message for s in report.skipped)
        raise UserError(f"no usable images in {str(root)!r}: all {report.unique_files} unique "
                        f"file(s) were rejected ({reasons}):\n  {detail}")

    ranked = sorted(entries, key=lambda k: _rank_key(seed, k))
    n_train, n_val, n_test = split_counts(len(ranked), splits)
    assignment = {"train": sorted(ranked[:n_train]),
                  "val": sorted(ranked[n_train:n_train + n_val]),
                  "test": sorted(ranked[n_train + n_val:]),
                  "all": sorted(ranked)}
    report.split_sizes = {k: len(assignment[k]) for k in ("train", "val", "test")}
    report.seconds = time.perf_counter() - start
    logger.info("%s", report.summary())
    return _Scan(entries, images, assignment, report, options, splits, seed)


class PhotoCollection(Dataset):
    """A folder of photos as a dataset of premultiplied linear RGBA (or alpha) images.

    ``collection[i]`` is a float32 tensor ``(4, R, R)`` = ``[r, g, b, alpha]`` (linear RGB
    premultiplied by alpha, all in [0, 1]) or, with ``alpha_only=True``, ``(1, R, R)``.
    All images of the folder are decoded, resized and cached in memory when the collection is
    built; use :meth:`load_splits` to build the train/val/test sets from one decoding pass.

    Splits are made after de-duplication, over the usable images only: each image's content
    hash ``h`` is ranked by ``sha256(f"{seed}:{h}")`` (a seeded shuffle that does not depend on
    file names or listing order), the ranked list is cut into train/val/test by
    :func:`split_counts`, and each split lists its images in content-hash order. The split of an
    image can change only when images are added to or removed from the collection (or the seed
    or fractions change).

    Args:
        folder: the collection (searched recursively; sub-folder names mean nothing).
        resolution: output side ``R`` in pixels.
        split: ``"train"``, ``"val"``, ``"test"`` or ``"all"`` (every usable image).
        splits: fractions (train, val, test), non-negative, summing to 1.
        seed: split seed.
        background: ``None`` (files need transparency) or ``"white"`` (files without
            transparency are masked as photos on white; files with transparency use it).
        threshold: white tolerance in sRGB-encoded units of [0, 1]
            (see :func:`white_background_alpha`).
        alpha_only: return ``(1, R, R)`` alpha (VH/AO silhouettes) instead of ``(4, R, R)``.
        crop: ``"image"`` (keep the photo framing) or ``"bbox"`` (crop to the alpha bounding box).
        margin: transparent border, a fraction of ``R`` on each side (the longer side of the
            photo or box maps to ``R·(1 − 2·margin)`` pixels), in [0, 0.5).
        filter: ``"triangle"`` (default), ``"box"`` or ``"lanczos"`` (see the module docstring).
        clean: clean masks (:func:`clean_mask`: frame lines along the image edges and specks
            are removed); applies to alpha channels and white-background masks.
        regions: ``"all"`` or ``"largest"`` (keep only the largest region of the mask).
        fill_holes: white-background masks: make enclosed near-white areas opaque.
        erode: shrink masks by this many *source* pixels (trims a rim of leftover background
            around cut-outs; 0 = off).
        soften: white-background masks: soften the edge by one pixel (see
            :func:`white_background_alpha`).
        workers: decoding threads (default ``min(8, CPUs)``; 0 or 1 decodes serially).

    Attributes:
        files: the source paths of this split's images (one per unique image).
        entries: one :class:`PhotoEntry` per image of this split.
        report: the :class:`CollectionReport` of the whole folder.

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
                 filter: str = "triangle", clean: bool = True, regions: str = "all",
                 fill_holes: bool = False, erode: int = 0, soften: bool = True,
                 workers: Optional[int] = None):
        if split not in SPLITS:
            raise UserError(f"split must be one of {SPLITS}, got {split!r}")
        fractions = _check_splits(splits)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise UserError(f"seed must be an integer, got {seed!r}")
        options = _Options(resolution, background, threshold, crop, margin, filter,
                           bool(clean), regions, bool(fill_holes), erode, bool(soften))
        self._init_from(_scan(folder, options, fractions, int(seed), workers), split,
                        alpha_only)

    def _init_from(self, scan: _Scan, split: str, alpha_only: bool) -> None:
        self._scan = scan
        self.split = split
        self.alpha_only = bool(alpha_only)
        self.options = scan.options
        self.splits = scan.fractions
        self.seed = scan.seed
        self.report = scan.report
        keys = scan.assignment[split]
        self.entries: List[PhotoEntry] = [scan.entries[k] for k in keys]
        self._images: List[torch.Tensor] = [scan.images[k] for k in keys]
        wanted = split == "all" or scan.fractions[("train", "val", "test").index(split)] > 0
        if not keys and wanted:
            warnings.warn(f"split {split!r} of {str(scan.report.folder)!r} is empty "
                          f"({scan.report.usable} usable image(s), splits {scan.fractions})",
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
