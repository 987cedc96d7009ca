"""Environment maps a physical collection is lit by: the ones the package carries, and the check
that a user's file is one Mitsuba's ``envmap`` emitter can read.

:func:`default_envmaps` lists the package's maps (``scenes/envmaps/*.exr`` and the skies baked
from ``sunsky``); :func:`check_envmap` refuses, as a one-line
:class:`~mitsuba_platonic.errors.UserError` naming the file, anything that is not a whole OpenEXR
file with colour channels, before a scene loads it (where a damaged file aborts the process).
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Tuple, Union

import numpy as np

from ..errors import UserError
from ..images import exr_channel_names
from ..render.mitsuba.sky import ENVMAPS, baked_envmaps
from ..render.variant import ensure_variant

__all__ = ["default_envmaps", "check_envmap"]


def default_envmaps() -> List[str]:
    """Environment maps in the package's ``scenes/envmaps/`` (``*.exr``: any a user dropped there)
    and the skies baked from Mitsuba's ``sunsky`` (:func:`mitsuba_platonic.render.mitsuba.sky.baked_envmaps`:
    carried by the package where they were baked before it was built, else baked on first use;
    no photographic map ships for want of a licence)."""

    return sorted(set(str(p) for p in ENVMAPS.glob("*.exr")) | set(baked_envmaps()))


_EXR_MAGIC = b"\x76\x2f\x31\x01"


def check_envmap(path: Union[str, Path], what: str = "environment map") -> None:
    """Raise :class:`~mitsuba_platonic.errors.UserError` naming ``path`` unless it is an existing,
    readable OpenEXR file with colour channels (R, G, B or Y): what Mitsuba's ``envmap`` is given."""

    p = Path(path)
    if not p.is_file():
        raise UserError(f"{what} {str(path)!r} does not exist" if not p.exists() else
                        f"{what} {str(path)!r} is not a file")
    try:
        with open(p, "rb") as f:
            magic = f.read(4)
    except OSError as e:
        raise UserError(f"{what} {str(path)!r} cannot be read: {e}") from None
    expected = "expected a lat-long environment map in OpenEXR format (.exr), like scenes/envmaps/*.exr"
    if magic != _EXR_MAGIC:
        raise UserError(f"{what} {str(path)!r} is not an OpenEXR file (it does not start with the EXR "
                        f"magic number); {expected}")
    try:
        channels = exr_channel_names(p)
    except Exception as e:  # OpenEXR raises several types for a damaged header
        raise UserError(f"{what} {str(path)!r}: its OpenEXR header cannot be read ({type(e).__name__}: "
                        f"{' '.join(str(e).split())}); {expected}") from None
    if not ({"R", "G", "B"} <= set(channels) or "Y" in channels):
        raise UserError(f"{what} {str(path)!r} has no colour channels (R, G, B or Y), only "
                        f"{', '.join(channels) or 'none'}; {expected}")
    damaged, values = _pixel_problems(p)
    if damaged:
        raise UserError(f"{what} {str(path)!r} is truncated or damaged: its pixels cannot be read in full "
                        f"({damaged}); {expected}")
    if values:
        raise UserError(f"{what} {str(path)!r} cannot light a scene: {values}; expected finite radiance ≥ 0 "
                        f"with some light (a lat-long map like scenes/envmaps/*.exr)")


#: Files whose pixels :func:`_pixel_problems` read in full: (path, size, mtime) → its problems.
_READ_PIXELS: Dict[Tuple[str, int, int], Tuple[str, str]] = {}


def _pixel_problems(path: Path) -> Tuple[str, str]:
    """Read every pixel of the EXR ``path`` with Mitsuba's own loader on this thread, where a
    damaged file raises (when the ``envmap`` emitter reads it while a scene loads, on a worker
    thread, a truncated file aborts the process). Returns (why the pixels cannot be read, what is
    wrong with their values: NaN or Inf, negative, or no light at all), '' for each that is fine."""

    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _READ_PIXELS:
        mi = ensure_variant()
        try:
            bitmap = mi.Bitmap(str(path))
        except Exception as e:                               # Mitsuba raises RuntimeError with the reader's words
            _READ_PIXELS[key] = (" ".join(str(e).replace(f'"{path}": ', "").split()), "")
        else:
            _READ_PIXELS[key] = ("", _value_problem(np.array(bitmap, dtype=np.float64)))
    return _READ_PIXELS[key]


def _value_problem(pixels: np.ndarray) -> str:
    """What makes radiance ``pixels`` (H, W, C) unusable as a light, '' if nothing."""
    colour = pixels[..., :3] if pixels.ndim == 3 and pixels.shape[-1] >= 3 else pixels
    finite = np.isfinite(colour)
    if not finite.all():
        bad = np.argwhere(~finite)[0]
        kind = "NaN" if np.isnan(colour).any() else "Inf"
        return (f"{int((~finite).sum())} pixel value(s) are NaN or Inf ({kind} at row {int(bad[0])}, column "
                f"{int(bad[1]) if len(bad) > 1 else 0})")
    if (colour < 0).any():
        return f"{int((colour < 0).sum())} pixel value(s) are negative (as low as {float(colour.min()):.3g})"
    if not (colour > 0).any():
        return "every pixel is black (0): it gives no light"
    return ""
