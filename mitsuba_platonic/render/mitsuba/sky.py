"""Lat-long environment maps baked from Mitsuba's own sky model, so ``envmap`` lighting works
without a downloaded (and licensed) HDR panorama.

:func:`bake_sky` evaluates the ``sunsky`` emitter of ``scenes/emitters/sunsky.xml`` (Hosek–Wilkie
sky and sun disk, zenith = +y) over the directions of a latitude–longitude image in Mitsuba's
``envmap`` convention (u = atan2(x, −z) / 2π, v = acos(y) / π, +y up) and writes a float32 RGB
OpenEXR. Each pixel is the mean radiance over its solid angle: the smooth sky is averaged over
``sky_samples``² sub-pixel directions (weighted by sin θ), and the sun disk (0.53°, smaller than a
pixel) is integrated separately over the few pixels around it with ``sun_samples``² directions
each, so the map carries the sun's power, not a point sample of it.

:func:`baked_envmaps` bakes the skies in :data:`SKIES` (a few sun elevations and turbidities,
the sun towards +z) on first use and returns their paths: a package built after they were baked
carries them in ``scenes/envmaps/`` (the folder ``platonic make-dataset --lighting envmap`` reads;
``*.exr`` is git-ignored); missing ones are baked into :func:`~mitsuba_platonic.files.resources.sky_cache`
(that folder in a checkout, the user's cache folder in an installed package). From a shell:
``python -m mitsuba_platonic.render.mitsuba.sky`` (``--help`` for the folder and size).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from ...files.fileio import atomic_write
from ...files.resources import sky_cache
from .scenes import SCENES, load_scene
from ..variant import ensure_variant

__all__ = ["SKIES", "ENVMAPS", "sun_direction", "sky_name", "bake_sky", "baked_envmaps", "latlong_direction"]

#: The package's environment maps: the folder the envmap lighting reads by default.
ENVMAPS = SCENES / "envmaps"

#: The baked skies: (sun elevation in degrees, turbidity).
SKIES: Tuple[Tuple[float, float], ...] = ((15.0, 3.0), (35.0, 3.0), (35.0, 6.0), (60.0, 2.0), (60.0, 8.0))

#: Angular diameter of Mitsuba's sun disk in degrees (``sunsky``'s ``sun_aperture`` default).
SUN_APERTURE = 0.5338


def sun_direction(elevation: float, azimuth: float = 0.0) -> Tuple[float, float, float]:
    """Unit vector towards a sun at ``elevation`` degrees above the horizon, ``azimuth`` degrees
    from +z towards +x (the convention of :func:`~mitsuba_platonic.render.mitsuba.physical.sample_lighting`)."""
    e, a = math.radians(elevation), math.radians(azimuth)
    return (math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a))


def sky_name(elevation: float, turbidity: float) -> str:
    """File name of a baked sky: ``sunsky_elev35_turb3.exr``."""
    return f"sunsky_elev{elevation:g}_turb{turbidity:g}.exr"


def latlong_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Directions ``(..., 3)`` of lat-long texture coordinates (Mitsuba's ``envmap``, +y up)."""
    θ, φ = np.pi * v, 2.0 * np.pi * u
    return np.stack([np.sin(φ) * np.sin(θ), np.cos(θ), -np.cos(φ) * np.sin(θ)], axis=-1)


def _radiance(emitter, d: np.ndarray) -> np.ndarray:
    """RGB radiance ``(M, 3)`` the emitter sends along ``-d`` (seen looking towards ``d``)."""
    mi = ensure_variant()
    import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = mi.Vector3f(-d[:, 0], -d[:, 1], -d[:, 2])
    return np.array(emitter.eval(si)).reshape(3, len(d)).T          # Color3f: channel-major


def _pixel_means(emitter, pixels: np.ndarray, width: int, height: int, k: int) -> np.ndarray:
    """Mean radiance over the solid angle of each pixel ``(i, j)`` in ``pixels (P, 2)``, from k²
    sub-pixel directions weighted by sin θ."""
    s = (np.arange(k) + 0.5) / k
    su, sv = np.meshgrid(s, s, indexing="xy")
    u = (pixels[:, :1] + su.reshape(1, -1)) / width                  # (P, k²)
    v = (pixels[:, 1:] + sv.reshape(1, -1)) / height
    w = np.sin(np.pi * v)
    out = np.empty((len(pixels), 3))
    chunk = max(1, (1 << 21) // (k * k))                              # ~2M directions per launch
    for a in range(0, len(pixels), chunk):
        d = latlong_direction(u[a:a + chunk], v[a:a + chunk]).reshape(-1, 3)
        L = _radiance(emitter, d).reshape(-1, k * k, 3)
        ww = w[a:a + chunk, :, None]
        out[a:a + chunk] = (L * ww).sum(1) / np.maximum(ww.sum(1), 1e-12)
    return out


def bake_sky(path: Union[str, Path], elevation: float, turbidity: float, azimuth: float = 0.0,
             width: int = 512, sky_samples: int = 2, sun_samples: Optional[int] = None) -> Path:
    """Bake ``sunsky`` (sun at ``elevation``/``azimuth`` degrees, ``turbidity``) into a
    ``width`` × ``width/2`` float32 lat-long RGB EXR at ``path`` (written atomically).

    ``sun_samples``: sub-pixel directions per side around the sun; by default enough that 16 fit
    across the disk (its power then comes out within about 1 %)."""

    if width < 8 or width % 2:
        raise ValueError(f"width must be an even number >= 8, got {width}")
    mi = ensure_variant()
    height = width // 2
    sun = np.array(sun_direction(elevation, azimuth))
    emitter = load_scene("emitters/sunsky", sun_direction=tuple(sun), turbidity=float(turbidity))
    params = mi.traverse(emitter)

    # the sky alone, everywhere
    params["sun_scale"], params["sky_scale"] = 0.0, 1.0
    params.update()
    jj, ii = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    pixels = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.float64)
    image = _pixel_means(emitter, pixels, width, height, sky_samples).reshape(height, width, 3)

    # the sun alone, over the pixels whose centre lies within the disk's radius plus a pixel diagonal
    params["sun_scale"], params["sky_scale"] = 1.0, 0.0
    params.update()
    centres = latlong_direction((pixels[:, 0] + 0.5) / width, (pixels[:, 1] + 0.5) / height)
    angle = np.degrees(np.arccos(np.clip(centres @ sun, -1.0, 1.0)))
    near = angle <= SUN_APERTURE / 2 + math.hypot(180.0 / height, 360.0 / width)
    if sun_samples is None:
        sun_samples = max(8, math.ceil((180.0 / height) / (SUN_APERTURE / 16)))
    image.reshape(-1, 3)[near] += _pixel_means(emitter, pixels[near], width, height, sun_samples)

    bitmap = mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), mi.Bitmap.PixelFormat.RGB)
    path = Path(path)
    atomic_write(path, lambda tmp: bitmap.write(str(tmp)))
    return path


def baked_envmaps(folder: Union[str, Path, None] = None, skies: Sequence[Tuple[float, float]] = SKIES,
                  width: int = 512, force: bool = False) -> List[str]:
    """The baked skies ``folder/sunsky_elev*_turb*.exr``, baking the missing ones (all with
    ``force``) first. Returns their paths.

    By default (``folder`` None) a sky the package carries (:data:`ENVMAPS`) is used as it is and
    a missing one is baked into :func:`~mitsuba_platonic.files.resources.sky_cache`."""
    out = []
    for elevation, turbidity in skies:
        name = sky_name(elevation, turbidity)
        path = Path(folder) / name if folder is not None else ENVMAPS / name
        if folder is None and (force or not path.is_file()):
            path = sky_cache() / name
        if force or not path.is_file():
            bake_sky(path, elevation, turbidity, width=width)
        out.append(str(path))
    return out


def main(argv: Optional[Sequence[str]] = None) -> None:
    """``python -m mitsuba_platonic.render.mitsuba.sky``: bake the skies of :data:`SKIES`."""
    parser = argparse.ArgumentParser(prog="python -m mitsuba_platonic.render.mitsuba.sky",
                                     description="Bake lat-long EXR skies from Mitsuba's sunsky for envmap lighting.")
    parser.add_argument("--out", default=str(sky_cache()),
                        help="folder (default: %(default)s: scenes/envmaps in a checkout, where a wheel "
                             "built afterwards carries them)")
    parser.add_argument("--width", type=int, default=512, help="panorama width in pixels (height = width / 2)")
    parser.add_argument("--force", action="store_true", help="bake again even where a file exists")
    args = parser.parse_args(argv)
    for path in baked_envmaps(args.out, width=args.width, force=args.force):
        print(path)


if __name__ == "__main__":
    main()
