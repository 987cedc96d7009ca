"""Trees grown by a recursive branching grammar: a brown trunk, tapered branches and leafy blobs.

The grammar (one rule, applied ``depth`` times)::

    B(p, d, ℓ, r)  →  capsule(p, p + ℓ d, r → k_r r)  +  Σ_{i < c} B(p + ℓ d, d_i, k_ℓ ℓ, k_r r)
    B at depth 0   →  capsule  +  leaf blob at the tip

where the ``c`` children's directions ``d_i`` leave the parent's direction at an angle θ
around evenly spread, jittered azimuths, then bend towards +y (phototropism) or −y (weeping).
Leaf blobs are spheres with a bumpy surface (a sum of random plane waves displaces them).

Varies with the seed: trunk height, thickness and lean; branching depth (2–4), child count
(2–4, fewer when deeper: at most 27 tips), branching angle, length and radius ratios,
tropism (upright → weeping); blob size and bumpiness; bark colour (browns, greys); foliage
palette (summer greens, spring yellow-greens, autumn reds/oranges/yellows, each blob
jittered, or pink blossom).
"""

from __future__ import annotations

import math
from typing import List

import numpy as np
import torch

from .colour import jitter
from .registry import register
from .sdf import Part, capsule_part, sphere

PALETTES = {  # name: (probability, [(hue, sat, val), ...]) in sRGB HSV
    "summer": (0.45, [(0.27, 0.7, 0.6), (0.31, 0.65, 0.55), (0.24, 0.65, 0.65)]),
    "spring": (0.15, [(0.22, 0.7, 0.8), (0.25, 0.6, 0.75)]),
    "autumn": (0.3, [(0.02, 0.8, 0.75), (0.07, 0.85, 0.85), (0.12, 0.85, 0.9), (0.2, 0.6, 0.65)]),
    "blossom": (0.1, [(0.94, 0.35, 0.95), (0.97, 0.25, 0.97)]),
}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _perpendicular(d: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    return _unit(np.cross(d, helper))


def _blob_part(centre: np.ndarray, radius: float, bump: float, waves: np.ndarray,
               phases: np.ndarray, colour) -> Part:
    """A bumpy sphere: ``d = |p − c| − r (1 + b · mean_i sin(k_i · (p − c) + φ_i))``."""
    def sdf(p: torch.Tensor) -> torch.Tensor:
        q = p - p.new_tensor(centre)
        noise = torch.sin(q @ p.new_tensor(waves.T) + p.new_tensor(phases)).mean(dim=-1)
        return (sphere(q, (0.0, 0.0, 0.0), radius) - radius * bump * noise) / (1.0 + bump)
    return Part(sdf, colour, np.asarray([centre]), radius * (1.0 + bump), 2.0 * radius, "leaves")


@register("tree")
def tree(rng: np.random.Generator, n: int) -> List[Part]:
    """A branching tree (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    depth = int(rng.integers(2, 5))
    # at most 27 tips (and 40 branches), so a tree stays a modest union of parts
    children = {2: int(rng.integers(2, 5)), 3: int(rng.integers(2, 4)), 4: 2}[depth]
    angle = rng.uniform(22, 50)
    len_ratio = rng.uniform(0.6, 0.82)
    rad_ratio = rng.uniform(0.55, 0.72)
    tropism = rng.choice([rng.uniform(0.05, 0.35), rng.uniform(-0.35, -0.1)], p=[0.8, 0.2])
    trunk_len = rng.uniform(0.7, 1.2)
    trunk_r = rng.uniform(0.06, 0.11)
    first_len = trunk_len * rng.uniform(0.55, 0.85)
    tips = children ** depth
    # sparse crowns get bigger blobs so the canopy still closes
    blob_scale = rng.uniform(0.8, 1.2) * float(np.clip((24.0 / tips) ** 0.3, 0.85, 1.4))
    bump = rng.uniform(0.05, 0.2)

    bark = jitter(rng, rng.uniform(0.05, 0.1), rng.uniform(0.3, 0.6), rng.uniform(0.42, 0.6), dv=0.04)
    if rng.random() < 0.15:  # birch-like light grey bark
        bark = jitter(rng, 0.1, 0.08, 0.85)
    names = list(PALETTES)
    probs = np.array([PALETTES[k][0] for k in names])
    palette = PALETTES[names[int(rng.choice(len(names), p=probs / probs.sum()))]][1]
    # one dominant leaf colour, some blobs take the palette's other colours
    main = palette[int(rng.integers(len(palette)))]

    parts: List[Part] = []
    lean = _unit(np.array([rng.normal(0, 0.08), 1.0, rng.normal(0, 0.08)]))
    base = np.zeros(3)
    top = base + trunk_len * lean
    parts.append(capsule_part(base, top, trunk_r * 1.15, bark, radius_b=trunk_r, name="trunk"))

    def grow(p: np.ndarray, d: np.ndarray, length: float, radius: float, level: int) -> None:
        up = _perpendicular(d)
        az0 = rng.uniform(0, 2 * math.pi)
        for i in range(children):
            az = az0 + 2 * math.pi * i / children + rng.uniform(-0.4, 0.4)
            th = math.radians(angle * rng.uniform(0.7, 1.3))
            side = math.cos(az) * up + math.sin(az) * np.cross(d, up)
            nd = _unit(math.cos(th) * d + math.sin(th) * side + tropism * np.array([0.0, 1.0, 0.0]))
            ln = length * rng.uniform(0.85, 1.15)
            end = p + ln * nd
            r_end = radius * rad_ratio
            parts.append(capsule_part(p, end, radius, bark, radius_b=r_end, name="branch"))
            if level == 1:
                hue, sat, val = palette[int(rng.integers(len(palette)))] if rng.random() < 0.35 else main
                col = jitter(rng, hue, sat, val, dh=0.015, ds=0.08, dv=0.1)
                k = 4
                waves = rng.normal(size=(k, 3))
                freq = rng.uniform(6, 14, (k, 1)) / (0.3 * blob_scale)
                waves = waves / np.linalg.norm(waves, axis=1, keepdims=True) * freq
                r_blob = blob_scale * (0.18 + 0.55 * ln)
                parts.append(_blob_part(end + 0.3 * r_blob * nd, r_blob, bump, waves,
                                        rng.uniform(0, 2 * math.pi, k), col))
            else:
                grow(end, nd, length * len_ratio, r_end, level - 1)

    grow(top, lean, first_len, trunk_r, depth)
    return parts
