"""An independent per-ray implementation of the rendering layers, for tests only.

Written from the conventions (docs/conventions.md, docs/rendering.md) without the package's code: camera frames from
angles, explicit pixel/depth loops in float64, and hand-written trilinear / nearest lookups
with zero padding.
"""

from __future__ import annotations

import math

import numpy as np


def frame_from_angles(azimuth_deg: float, elevation_deg: float):
    """(ω, right, up) of the upright orthographic camera at the given angles."""
    φ, θ = math.radians(azimuth_deg), math.radians(elevation_deg)
    ω = np.array([math.cos(θ) * math.sin(φ), math.sin(θ), math.cos(θ) * math.cos(φ)])
    right = np.array([math.cos(φ), 0.0, -math.sin(φ)])
    up = np.array([-math.sin(θ) * math.sin(φ), math.cos(θ), -math.sin(θ) * math.cos(φ)])
    return ω, right, up


def lookup(vol: np.ndarray, p: np.ndarray, filter: str) -> np.ndarray:
    """Sample vol (C, N, N, N) [c, d, h, w] at world point p (3,) → (C,); zero outside the cube."""
    n = vol.shape[-1]
    Δ = 2.0 / n
    # continuous voxel indices (voxel centres at integers)
    fw = (p[0] + 1.0) / Δ - 0.5
    fh = (1.0 - p[1]) / Δ - 0.5
    fd = (1.0 - p[2]) / Δ - 0.5

    def at(d, h, w):
        if 0 <= d < n and 0 <= h < n and 0 <= w < n:
            return vol[:, d, h, w]
        return np.zeros(vol.shape[0])

    if filter == "nearest":
        return at(int(math.floor(fd + 0.5)), int(math.floor(fh + 0.5)), int(math.floor(fw + 0.5)))
    d0, h0, w0 = int(math.floor(fd)), int(math.floor(fh)), int(math.floor(fw))
    td, th, tw = fd - d0, fh - h0, fw - w0
    out = np.zeros(vol.shape[0])
    for dd, wd in ((0, 1 - td), (1, td)):
        for hh, wh in ((0, 1 - th), (1, th)):
            for ww, wwt in ((0, 1 - tw), (1, tw)):
                out += wd * wh * wwt * at(d0 + dd, h0 + hh, w0 + ww)
    return out


def render_ray_loop(vol: np.ndarray, azimuth: float, elevation: float, model: str,
                    filter: str) -> np.ndarray:
    """Render one (C, N, N, N) volume → (C', N, N) with a loop over pixels and depth samples."""
    vol = np.asarray(vol, dtype=np.float64)
    n = vol.shape[-1]
    Δ = 2.0 / n
    ω, right, up = frame_from_angles(azimuth, elevation)
    out = np.zeros((4 if model == "ea" else 1, n, n))
    for i in range(n):
        y = 1.0 - (i + 0.5) * Δ
        for j in range(n):
            x = -1.0 + (j + 0.5) * Δ
            total, T, colour = 0.0, 1.0, np.zeros(3)
            for k in range(n):
                z = 1.0 - (k + 0.5) * Δ
                s = lookup(vol, x * right + y * up + z * ω, filter)
                a = s[-1]
                if model == "vh":
                    total += a
                else:
                    if model == "ea":
                        colour += T * a * s[:3]
                    T *= 1.0 - a
            if model == "vh":
                out[0, i, j] = 1.0 - math.exp(-total)
            elif model == "ao":
                out[0, i, j] = 1.0 - T
            else:
                out[:3, i, j] = colour
                out[3, i, j] = 1.0 - T
    return out
