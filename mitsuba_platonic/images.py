"""Image output helpers: 8-bit PNGs, float EXRs and error heat maps.

All helpers take **numpy** arrays laid out ``(H, W, C)`` (row 0 at the top), the layout image
files use. Renders are torch ``(B, C, H, W)`` tensors (docs/conventions.md, "Images"); convert
one image with ``img[b].permute(1, 2, 0).detach().cpu().numpy()`` (see :func:`to_hwc`).

Channel meanings follow the renderers: VH/AO images are one channel of opacity, EA images are
*premultiplied* ``R, G, B`` plus alpha ``A``. Compositing onto a background is a separate,
explicit step (:func:`composite`).

EXR channel naming (:func:`save_exr`, defaults by channel count C):

- C = 1 → ``Y, A``: an opacity image; ``A`` = the opacity and ``Y`` = ``A`` (a white object,
  premultiplied, so EXR viewers show a white silhouette and readers find alpha in ``A``).
- C = 2 → ``Y, A``: grey + alpha.
- C = 3 → ``R, G, B``: colour without alpha.
- C = 4 → ``R, G, B, A``: premultiplied colour + alpha (EXR's own convention; the EA output).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Tuple, Union

import numpy as np
import OpenEXR
from PIL import Image

from .files.fileio import atomic_write

__all__ = [
    "to_hwc",
    "to_uint8",
    "save_png",
    "save_grid",
    "save_exr",
    "load_exr",
    "exr_channel_names",
    "composite",
    "heatmap",
    "linear_to_srgb",
    "srgb_to_linear",
    "to_png_rgba",
]

PathLike = Union[str, Path]

#: Default EXR channel names by channel count (see the module docstring).
DEFAULT_EXR_CHANNELS = {1: ("Y", "A"), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}

#: Preferred channel order when reading an EXR back; other channels follow alphabetically.
_CANONICAL_ORDER = ("R", "G", "B", "Y", "A")


def _as_image(img: np.ndarray, name: str = "img", channels: Optional[Sequence[int]] = None) -> np.ndarray:
    """Validate a finite float ``(H, W, C)`` array (C in ``channels`` if given); return it as float64."""
    if hasattr(img, "detach"):  # a torch tensor slipped through: say how to convert it
        raise ValueError(f"{name} must be a numpy array (H, W, C); convert a torch image with "
                         f"mitsuba_platonic.images.to_hwc(tensor)")
    arr = np.asarray(img)
    if arr.ndim != 3:
        raise ValueError(f"{name} must have shape (H, W, C), got {arr.shape}")
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must be non-empty, got shape {arr.shape}")
    if channels is not None and arr.shape[2] not in channels:
        raise ValueError(f"{name} must have {' or '.join(map(str, channels))} channels, "
                         f"got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
            or arr.dtype == bool):
        raise ValueError(f"{name} must hold numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64, copy=False)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or Inf")
    return arr


def to_hwc(image) -> np.ndarray:
    """One torch image ``(C, H, W)`` (or a numpy array in that layout) → numpy ``(H, W, C)`` float32."""
    if hasattr(image, "detach"):
        image = image.detach().cpu().numpy()
    arr = np.asarray(image)
    if arr.ndim != 3:
        raise ValueError(f"image must have shape (C, H, W), got {arr.shape}")
    return np.ascontiguousarray(arr.transpose(1, 2, 0), dtype=np.float32)


def to_uint8(img: np.ndarray) -> np.ndarray:
    """Float ``(H, W, C)`` image in [0, 1] → ``uint8`` (values clipped to [0, 1], then rounded).

    Raises:
        ValueError: on a wrong rank, an empty image, a non-numeric dtype, NaN or Inf.
    """
    arr = _as_image(img)
    return np.rint(np.clip(arr, 0.0, 1.0) * 255.0).astype(np.uint8)


def save_png(path: PathLike, img: np.ndarray) -> Path:
    """Write a float ``(H, W, C)`` image in [0, 1] as an 8-bit PNG; return the path.

    C = 1 writes grey (``L``), C = 3 ``RGB``, C = 4 ``RGBA`` (straight alpha, as PNG expects:
    un-premultiply or :func:`composite` premultiplied renders first). Values are clipped to
    [0, 1]. Parent folders are created. The file appears whole or not at all (written to a
    temporary sibling and renamed): a run killed while writing a sample leaves no torn PNG.
    """

    arr = to_uint8(_as_image(img, channels=(1, 3, 4)))
    path = Path(path)
    mode = {1: "L", 3: "RGB", 4: "RGBA"}[arr.shape[2]]
    picture = Image.fromarray(arr[..., 0] if mode == "L" else arr, mode=mode)
    atomic_write(path, lambda tmp: picture.save(tmp, format="PNG"))
    return path


def save_grid(path: PathLike, rows: Sequence[Sequence[np.ndarray]], scale: int = 1) -> Path:
    """Write tiles as one PNG grid: ``rows[i][j]`` is the float ``(H, W, C)`` tile in row i,
    column j (every tile the same shape, rows the same length), upscaled ``scale``× (nearest)."""
    if not rows or not all(len(r) == len(rows[0]) for r in rows) or not len(rows[0]):
        raise ValueError(f"rows must be a non-empty list of equally long, non-empty rows, got lengths "
                         f"{[len(r) for r in rows]}")
    grid = np.concatenate([np.concatenate([_as_image(t, "tile") for t in r], axis=1) for r in rows], axis=0)
    return save_png(path, grid.repeat(scale, axis=0).repeat(scale, axis=1))


def save_exr(path: PathLike, img: np.ndarray, channels: Optional[Sequence[str]] = None) -> Path:
    """Write a ``(H, W, C)`` image as a float32, ZIP-compressed scanline EXR; return the path.

    Args:
        path: output file (parent folders are created).
        img: ``(H, W, C)`` finite numbers (not clipped: EXR holds any float).
        channels: one name per channel, e.g. ``("R", "G", "B", "A")``. Default by C:
            1 → ``("Y", "A")``: a single-channel *opacity* image is written twice, as alpha
            ``A`` and as premultiplied white luminance ``Y`` (= ``A``), so viewers show a white
            silhouette and readers that want alpha find it in ``A``; 2 → ``Y, A``;
            3 → ``R, G, B``; 4 → ``R, G, B, A`` (premultiplied, EXR's convention, which is
            what the EA renderers produce).

    Raises:
        ValueError: on a bad image, or channel names that are not unique non-empty strings
            matching the channel count (for C = 1 the default duplicates it into Y and A).
    """
    arr = _as_image(img).astype(np.float32)
    c = arr.shape[2]
    if channels is None:
        if c not in DEFAULT_EXR_CHANNELS:
            raise ValueError(f"no default EXR channel names for {c} channels; pass channels=...")
        channels = DEFAULT_EXR_CHANNELS[c]
        planes = [arr[..., 0], arr[..., 0]] if c == 1 else [arr[..., i] for i in range(c)]
    else:
        channels = tuple(channels)
        if len(channels) != c:
            raise ValueError(f"got {len(channels)} channel name(s) {channels} for an image "
                             f"with {c} channel(s)")
        planes = [arr[..., i] for i in range(c)]
    if not all(isinstance(n, str) and n for n in channels) or len(set(channels)) != len(channels):
        raise ValueError(f"channel names must be unique non-empty strings, got {channels}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    data = {name: np.ascontiguousarray(p, dtype=np.float32) for name, p in zip(channels, planes)}
    OpenEXR.File(header, data).write(str(path))
    return path


def _ordered(names: Sequence[str]) -> Tuple[str, ...]:
    known = [n for n in _CANONICAL_ORDER if n in names]
    return tuple(known + sorted(n for n in names if n not in _CANONICAL_ORDER))


def exr_channel_names(path: PathLike) -> Tuple[str, ...]:
    """The channel names of an EXR file in the order :func:`load_exr` returns them
    (R, G, B, Y, A first, then any others alphabetically)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR file {str(path)!r} does not exist")
    header = OpenEXR.File(str(path), separate_channels=True, header_only=True).header()
    return _ordered([ch.name for ch in header["channels"]])


def load_exr(path: PathLike, channels: Optional[Sequence[str]] = None) -> np.ndarray:
    """Read an EXR written by :func:`save_exr` (or any single-part scanline EXR) → float32 ``(H, W, C)``.

    Args:
        path: the file.
        channels: names to read, in this order; default all channels in the order of
            :func:`exr_channel_names` (so ``R, G, B, A`` and ``Y, A`` come back as written).

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if a requested channel is not in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR file {str(path)!r} does not exist")
    data = OpenEXR.File(str(path), separate_channels=True).channels()
    names = _ordered(list(data)) if channels is None else tuple(channels)
    missing = [n for n in names if n not in data]
    if missing:
        raise ValueError(f"EXR file {str(path)!r} has no channel(s) {missing}; "
                         f"it has {_ordered(list(data))}")
    return np.stack([np.asarray(data[n].pixels, dtype=np.float32) for n in names], axis=-1)


def composite(img: np.ndarray, background: Union[float, Sequence[float]] = 0.5) -> np.ndarray:
    """Composite a premultiplied image over a solid background → ``(H, W, 3)`` float in [0, 1].

    C = 4 (premultiplied RGB + A): ``rgb + (1 − A) · background``. C = 1 (an opacity image,
    i.e. a premultiplied white object): ``A + (1 − A) · background`` in every channel.
    ``background`` is a grey level or an RGB triple.
    """
    arr = _as_image(img, channels=(1, 4))
    bg = np.broadcast_to(np.asarray(background, dtype=np.float64), (3,))
    if not np.isfinite(bg).all() or (bg < 0).any() or (bg > 1).any():
        raise ValueError(f"background must lie in [0, 1], got {background!r}")
    if arr.shape[2] == 1:
        rgb, alpha = np.repeat(arr, 3, axis=2), arr
    else:
        rgb, alpha = arr[..., :3], arr[..., 3:]
    return np.clip(rgb + (1.0 - alpha) * bg, 0.0, 1.0)


def heatmap(err: np.ndarray, vmax: Optional[float] = None, cmap: str = "inferno") -> np.ndarray:
    """Map a non-negative error image to colour: ``(H, W)`` or ``(H, W, 1)`` → ``(H, W, 3)`` float.

    ``err / vmax`` (clipped to [0, 1]) goes through the matplotlib colour map ``cmap``.
    ``vmax`` defaults to the image's maximum (1 if the image is all zero). Use the same
    ``cmap`` and ``vmax`` for a colour bar (``matplotlib.colors.Normalize(0, vmax)``).

    Raises:
        ValueError: on a wrong shape, NaN/Inf, negative values, a non-positive ``vmax`` or an
            unknown colour map.
    """
    import matplotlib  # lazy: matplotlib is slow to import, only for figures

    arr = np.asarray(err)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2:
        raise ValueError(f"err must have shape (H, W) or (H, W, 1), got {np.shape(err)}")
    arr = _as_image(arr[..., None], name="err")[..., 0]
    if (arr < 0).any():
        raise ValueError(f"err must be non-negative (an absolute error), got minimum {arr.min():.6g}")
    if vmax is None:
        vmax = float(arr.max()) if arr.size and arr.max() > 0 else 1.0
    if not (np.isfinite(vmax) and vmax > 0):
        raise ValueError(f"vmax must be a positive finite number, got {vmax!r}")
    try:
        colour_map = matplotlib.colormaps[cmap]
    except KeyError:
        raise ValueError(f"unknown matplotlib colour map {cmap!r}") from None
    return np.asarray(colour_map(np.clip(arr / vmax, 0.0, 1.0))[..., :3], dtype=np.float64)


#: The sRGB curve's knee in encoded values: the encoding of its linear knee 0.0031308 by the
#: linear segment, 12.92 · 0.0031308 (colour-science's ``eotf_inverse_sRGB(0.0031308)``).
_SRGB_KNEE = 0.0031308 * 12.92


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Encode linear values L, clipped to [0, 1], with the sRGB transfer function (IEC 61966-2-1):

        V = 12.92 L   (L ≤ 0.0031308),    V = 1.055 L^(1/2.4) − 0.055   (otherwise)

    in float64, the very operations of colour-science's ``cctf_encoding(L, "sRGB")`` (bit for bit,
    tests/test_photos.py), without importing it (about 2 s on 2 cores: it imports matplotlib)."""
    lin = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(lin <= 0.0031308, lin * 12.92, 1.055 * np.abs(lin) ** np.float64(1 / 2.4) - 0.055)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Decode sRGB-encoded values V, clipped to [0, 1], to linear (IEC 61966-2-1):

        L = V / 12.92   (V ≤ the knee, 12.92 · 0.0031308 = 0.040449936),
        L = ((V + 0.055) / 1.055)^2.4   (otherwise)

    in float64, the very operations of colour-science's ``cctf_decoding(V, "sRGB")`` (bit for bit,
    tests/test_photos.py), without importing it."""
    v = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(_SRGB_KNEE >= v, v / 12.92, np.abs((v + 0.055) / 1.055) ** np.float64(2.4))


def to_png_rgba(img: np.ndarray) -> np.ndarray:
    """A premultiplied *linear* render → straight-alpha sRGB RGBA ``(H, W, 4)`` for an 8-bit PNG.

    C = 4 (premultiplied RGB + A): RGB is divided by A where A > 0 (0 where A = 0) and
    sRGB-encoded. C = 1 (an opacity image): a white object, RGB = 1, alpha = the opacity.
    """
    arr = _as_image(img, channels=(1, 4)).astype(np.float64)
    alpha = np.clip(arr[..., -1:], 0.0, 1.0)
    if arr.shape[2] == 1:
        return np.concatenate([np.ones_like(arr).repeat(3, axis=2), alpha], axis=2)
    straight = np.where(alpha > 0, arr[..., :3] / np.maximum(alpha, 1e-12), 0.0)
    return np.concatenate([linear_to_srgb(straight), alpha], axis=2)
