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

from ..errors import UserError
from ..images import exr_channel_names
from ..render.sky import ENVMAPS, baked_envmaps
from ..render.variant import ensure_variant

__all__ = ["default_envmaps", "check_envmap"]


def default_envmaps() -> List[str]:
    """Environment maps in the package's ``scenes/envmaps/`` (``*.exr``: any a user dropped there)
    and the skies baked from Mitsuba's ``sunsky`` (:func:`mitsuba_platonic.render.sky.baked_envmaps`:
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
    problem = _unreadable_pixels(p)
    if problem:
        raise UserError(f"{what} {str(path)!r} is truncated or damaged: its pixels cannot be read in full "
                        f"({problem}); {expected}")


#: Files whose pixels :func:`_unreadable_pixels` read in full: (path, size, mtime) → the problem or ''.
_READ_PIXELS: Dict[Tuple[str, int, int], str] = {}


def _unreadable_pixels(path: Path) -> str:
    """Read every pixel of the EXR ``path`` with Mitsuba's own loader on this thread, where a
    damaged file raises (when the ``envmap`` emitter reads it while a scene loads, on a worker
    thread, a truncated file aborts the process). Returns what is wrong, '' if nothing."""

    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    if key not in _READ_PIXELS:
        mi = ensure_variant()
        try:
            mi.Bitmap(str(path))
            _READ_PIXELS[key] = ""
        except Exception as e:                               # Mitsuba raises RuntimeError with the reader's words
            _READ_PIXELS[key] = " ".join(str(e).replace(f'"{path}": ', "").split())
    return _READ_PIXELS[key]
