"""Decoding: one image file → integer codes (sRGB-encoded RGB, straight alpha), by content.

Formats are detected from the content, not the file name: PNG (any colour type and bit depth:
palette with ``tRNS``, grey, grey + alpha, RGB, RGBA, 8 or 16 bits), JPEG and WebP.

- 16-bit PNGs keep all 16 bits. Pillow reduces 16-bit colour PNGs to 8 bits, so every 16-bit
  PNG is read with pypng (``png.Reader.read``), which returns the samples as they are stored;
  a ``tRNS`` colour key becomes alpha 0 where all channels equal the key.
- An EXIF orientation tag (Pillow's, or a PNG ``eXIf`` chunk for 16-bit PNGs) is applied.
- Other formats (GIF, TIFF, BMP, ...) are rejected as ``unsupported_format``: convert them to
  PNG. Animated or multi-frame files are rejected too.
- Colour profiles (``iCCP``, ``gAMA``, ICC in JPEG) are ignored: files are taken to be
  sRGB-encoded; CMYK JPEGs get Pillow's naive CMYK → RGB conversion.
- Truncated files are detected only while Pillow's ``ImageFile.LOAD_TRUNCATED_IMAGES`` keeps
  its default, False.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np
import png
from PIL import Image, UnidentifiedImageError

from ...files.fileio import MAX_IMAGE_BYTES, InputFileRefused, read_input_file
from .rejections import ImageRejected, PathLike

__all__ = ["DecodedImage", "decode_image", "apply_orientation", "SUPPORTED_FORMATS", "IMAGE_SUFFIXES",
           "OTHER_IMAGE_SUFFIXES"]

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

_EXIF_ORIENTATION = 0x0112


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


def apply_orientation(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """``(H, W, ...)`` pixels as displayed for an EXIF orientation tag (1 … 8; others: as is).

    The same transposition as Pillow's ``ImageOps.exif_transpose``: 2 mirrors left–right,
    3 rotates by 180°, 4 mirrors top–bottom, 5 transposes, 6 rotates 90° clockwise,
    7 transposes across the anti-diagonal, 8 rotates 90° counter-clockwise.
    """
    if orientation == 2:
        return pixels[:, ::-1]
    if orientation == 3:
        return pixels[::-1, ::-1]
    if orientation == 4:
        return pixels[::-1]
    if orientation == 5:
        return pixels.swapaxes(0, 1)
    if orientation == 6:
        return np.rot90(pixels, k=-1)
    if orientation == 7:
        return pixels[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:
        return np.rot90(pixels, k=1)
    return pixels


def _key_alpha(values: np.ndarray, key) -> np.ndarray:
    """Alpha codes from a ``tRNS`` colour key: 0 where ``values`` (H, W, C) equals ``key``."""
    key = np.atleast_1d(np.asarray(key, dtype=np.int64))
    if key.size != values.shape[2]:
        raise ImageRejected("corrupt", f"tRNS key {tuple(key)} does not match "
                                       f"{values.shape[2]} channel(s)")
    return ~np.all(values.astype(np.int64) == key, axis=2)


def _png_bit_depth(data: bytes) -> int:
    """The bit depth of a PNG's samples, from its header (pypng)."""
    reader = png.Reader(bytes=data)
    reader.preamble()
    return int(reader.bitdepth)


def _exif_orientation(exif: Optional[bytes]) -> int:
    """The orientation tag of raw EXIF data (1, "as stored", when absent)."""
    if not exif:
        return 1
    tags = Image.Exif()
    tags.load(exif)
    return int(tags.get(_EXIF_ORIENTATION, 1))


def _decode_png16(data: bytes) -> Tuple[np.ndarray, bool, int]:
    """16-bit PNG bytes → ``(H, W, 4)`` uint16 codes, ``has_alpha``, EXIF orientation (pypng).

    pypng returns each row's samples as stored (all 16 bits, Adam7 interlacing undone, no
    ``sBIT`` rescaling). Grey is repeated into R, G, B; without an alpha channel alpha is 65535,
    or 0 where the pixel equals the ``tRNS`` colour key.
    """
    width, height, rows, info = png.Reader(bytes=data).read()
    codes = np.vstack([np.asarray(row, dtype=np.uint16) for row in rows])
    codes = codes.reshape(height, width, int(info["planes"]))
    colour = codes[..., :1] if info["greyscale"] else codes[..., :3]
    key = info.get("transparent")
    if info["alpha"]:
        alpha = codes[..., -1:]
    else:
        alpha = np.full((height, width, 1), 65535, np.uint16)
        if key is not None:
            alpha[~_key_alpha(colour, key)] = 0
    if info["greyscale"]:
        colour = np.repeat(colour, 3, axis=2)
    exif = next((body for kind, body in png.Reader(bytes=data).chunks() if kind == b"eXIf"),
                None)
    return (np.concatenate([colour, alpha], axis=2), bool(info["alpha"]) or key is not None,
            _exif_orientation(exif))


def _decode_pixels(im, data: bytes) -> Tuple[np.ndarray, bool, int, str]:
    """Pillow image (just opened) → (codes (H, W, 4), has_alpha, bit depth, mode label)."""
    mode = im.mode
    if im.format == "PNG" and _png_bit_depth(data) == 16:
        codes, has_alpha, orientation = _decode_png16(data)
        label = mode if mode.startswith("I") else f"{mode};16"   # Pillow: "I;16", "RGB", ...
        return apply_orientation(codes, orientation), has_alpha, 16, label
    im.load()
    orientation = im.getexif().get(_EXIF_ORIENTATION, 1)
    trns = im.info.get("transparency")
    if mode in ("RGBA", "LA", "PA", "RGBa", "La") or (
            trns is not None and mode in ("P", "L", "1", "RGB")):
        # Pillow applies tRNS (palette alpha or a colour key) when converting to RGBA.
        codes, has_alpha = np.asarray(im.convert("RGBA")), True
    elif mode in ("1", "L", "P", "RGB", "CMYK", "YCbCr", "LAB", "HSV", "RGBX"):
        rgb = np.asarray(im.convert("RGB"))
        alpha = np.full(rgb.shape[:2] + (1,), 255, np.uint8)
        codes, has_alpha = np.concatenate([rgb, alpha], axis=2), False
    else:
        raise ImageRejected("unsupported_format", f"pixel mode {mode!r} is not supported")
    return apply_orientation(codes, orientation), has_alpha, 8, mode


def decode_image(source: Union[PathLike, bytes], name: Optional[str] = None) -> DecodedImage:
    """Decode one image file (a path, or its bytes) into integer codes; see :class:`DecodedImage`.

    The format is detected from the content, not the name. 8-bit sources give ``uint8`` codes;
    16-bit PNGs (grey, grey + alpha, RGB, RGBA, with or without a ``tRNS`` colour key) give
    ``uint16`` codes with all 16 bits (read by pypng).

    Args:
        source: a file path, or the file's bytes.
        name: the name used in messages (default: the path, or ``"<bytes>"``); its suffix also
            words the rejection of unreadable content (``.png`` → ``corrupt``, ``.gif`` →
            ``unsupported_format``, ``.txt`` → ``not_an_image``).

    Raises:
        ImageRejected: with ``reason`` ``not_an_image``, ``unsupported_format``, ``corrupt``
            or ``too_large`` (also a file over :data:`~mitsuba_platonic.files.fileio.MAX_IMAGE_BYTES`),
            or ``unreadable`` for a path that is no regular file (a FIFO, a device such as
            ``/dev/zero``, also through a link: checked before anything is read); the message names the file.
        OSError: if the path cannot be read.
    """
    if isinstance(source, (bytes, bytearray, memoryview)):
        data = bytes(source)
        label = name or "<bytes>"
    else:
        label = name or str(source)
        try:                                     # a regular file of a bounded size: no FIFO, no /dev/zero
            data = read_input_file(source, max_bytes=MAX_IMAGE_BYTES)
        except InputFileRefused as err:
            raise ImageRejected("too_large" if err.reason == "too_large" else "unreadable", str(err)) from None
    if not data:
        raise ImageRejected(_suffix_reason(label), f"{label}: the file is empty (0 bytes)")
    try:
        with warnings.catch_warnings():          # 89-179 Mpx: Pillow only warns, naming no file; refuse
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            im = Image.open(io.BytesIO(data))
    except UnidentifiedImageError:
        reason = _suffix_reason(label)
        what = {"corrupt": f"named like an image ({Path(label).suffix}) but its content is "
                           f"not a readable image",
                "unsupported_format": f"{Path(label).suffix} files are not supported "
                                      f"(supported: {', '.join(SUPPORTED_FORMATS)})",
                "not_an_image": "not an image (its content is no known image format)"}[reason]
        raise ImageRejected(reason, f"{label}: {what}") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as err:
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
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            codes, has_alpha, bits, mode = _decode_pixels(im, data)
    except ImageRejected as err:
        raise ImageRejected(err.reason, f"{label}: {err.message}") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as err:
        raise ImageRejected("too_large", f"{label}: {err}") from None
    except Exception as err:  # noqa: BLE001 - truncated data, bad CRC, zlib errors, ...
        raise ImageRejected("corrupt", f"{label}: cannot decode the {fmt} data, the file is "
                                       f"corrupt or truncated ({type(err).__name__}: {err})"
                            ) from None
    return DecodedImage(np.ascontiguousarray(codes), bool(has_alpha), bits, fmt, mode)
