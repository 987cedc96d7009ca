"""Mushrooms: a revolved stem and a wavy cap, sometimes with a ring, spots and a small sibling.

Varies with the seed: stem height, thickness, taper, basal bulb and tilt; cap radius, height
and shape (flat parasol → hemisphere → bell/cone), the frequency (5–13 lobes) and amplitude
of the waves of its rim, both radially and vertically; cap colour (red, orange, brown, tan,
yellow, violet; darker at the crown), gill colour, stem colour, optional white spots and an
optional stem ring, and an optional smaller second mushroom beside the first.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .colour import hsv, jitter, mix
from .registry import register
from .sdf import Part, profile_sdf, revolve_part, rotation, smooth_profile, to_local, torus_part

CAP_HUES = [  # (hue, saturation, value) in sRGB HSV
    (0.00, 0.85, 0.85),   # red (fly agaric)
    (0.06, 0.80, 0.90),   # orange
    (0.07, 0.60, 0.60),   # brown
    (0.09, 0.40, 0.85),   # tan
    (0.14, 0.70, 0.95),   # yellow
    (0.80, 0.35, 0.70),   # violet
    (0.1, 0.22, 0.88),    # cream
]


def _cap_part(rng: np.random.Generator, origin: np.ndarray, frame: np.ndarray, radius: float,
              height: float, stem_r: float, spotted: bool, cap_col, crown_col, gill_col) -> Part:
    """A wavy dome of revolution sitting at ``origin`` (its underside) in ``frame``."""
    alpha = rng.uniform(1.1, 3.0)          # dome exponent: ~1 conical/bell, 3 flat-topped
    lobes = int(rng.integers(5, 14))
    amp_r = rng.uniform(0.0, 0.09)         # radial rim wave
    amp_y = rng.uniform(0.0, 1.2) * radius / lobes  # vertical rim wave (gentle slopes)
    phase_r, phase_y = rng.uniform(0, 2 * math.pi, 2)
    drop = rng.uniform(0.05, 0.25) * height  # the rim hangs below the gill plane
    # profile r(y): rim (y ∈ [-drop, 0]) widening to the full radius, then the dome up to the apex
    ys = np.linspace(-drop, height, 192)
    t = np.clip(ys / height, 0.0, 1.0)
    dome = radius * np.power(np.clip(1.0 - t ** alpha, 0.0, 1.0), 0.5)
    rim = radius * (0.86 + 0.14 * np.sqrt(np.clip((ys + drop) / max(drop, 1e-6), 0, 1)))
    rt = np.where(ys < 0.0, rim, dome)
    spots = np.zeros((0, 3))
    if spotted:
        k = int(rng.integers(8, 22))
        th = rng.uniform(0, 2 * math.pi, k)
        sy = height * rng.uniform(0.05, 0.85, k)
        sr = radius * np.power(np.clip(1.0 - (sy / height) ** alpha, 0.0, 1.0), 0.5)
        spots = np.stack([sr * np.cos(th), sy, sr * np.sin(th)], axis=1)
        spot_r = rng.uniform(0.05, 0.1) * radius
    thickness = height + drop

    def warp(p: torch.Tensor):
        q = to_local(p, origin, frame)
        theta = torch.atan2(q[..., 2], q[..., 0])
        r = torch.sqrt(q[..., 0] ** 2 + q[..., 2] ** 2)
        fade = (r / radius).clamp(0.0, 1.0) ** 2
        r_w = r / (1.0 + amp_r * torch.sin(lobes * theta + phase_r))
        y_w = q[..., 1] - amp_y * fade * torch.sin(lobes * theta + phase_y)
        return q, r_w, y_w

    def sdf(p: torch.Tensor, band=None) -> torch.Tensor:
        # the distance in the warped frame: the warp stretches distances by at most a few
        # percent near the rim, so this is a close estimate (the ramp is slightly sharper there)
        _, r_w, y_w = warp(p)
        return profile_sdf(r_w, y_w, ys, rt, band)

    def colour(p: torch.Tensor) -> torch.Tensor:
        q, r_w, y_w = warp(p)
        crown = (1.0 - (r_w / radius).clamp(0.0, 1.0)) ** 2
        c = p.new_tensor(cap_col) + crown[..., None] * (p.new_tensor(crown_col) - p.new_tensor(cap_col))
        if len(spots):
            d = torch.cdist(q.reshape(-1, 3), q.new_tensor(spots)).min(dim=1).values.view(q.shape[:-1])
            s = ((spot_r - d) / (0.3 * spot_r)).clamp(0.0, 1.0)[..., None]
            c = c + s * (p.new_tensor((0.92, 0.9, 0.85)) - c)
        # gills: the underside (below the gill plane, away from the rim surface) is lighter
        under = ((-y_w) / (0.04 * radius)).clamp(0.0, 1.0)[..., None] * (r_w < 0.93 * radius)[..., None]
        return c + under * (p.new_tensor(gill_col) - c)

    hull_r = radius * (1.0 + amp_r) / math.cos(math.pi / 8)
    ang = np.arange(8) * (math.pi / 4)
    ring = np.stack([np.cos(ang), np.zeros(8), np.sin(ang)], axis=1) * hull_r
    pts = np.concatenate([ring + [0, -drop - amp_y, 0], ring + [0, height + amp_y, 0]])
    pts = pts @ frame.T + origin
    return Part(sdf, colour, pts, 0.0, thickness, "cap", banded=True)


def _mushroom(rng: np.random.Generator, base: np.ndarray, scale: float, style: dict) -> list:
    h = scale * rng.uniform(0.6, 1.3)
    rs = scale * rng.uniform(0.07, 0.16)
    tilt = rng.uniform(0, 8)
    axis = rng.normal(size=3)
    axis[1] = 0.0
    frame = rotation(axis, tilt)
    bulb = rng.uniform(1.0, 1.8)
    ys = [0.0, 0.12 * h, 0.5 * h, 0.9 * h, h]
    rad = [rs * bulb * 0.85, rs * bulb, rs * rng.uniform(0.85, 1.05), rs * rng.uniform(0.75, 0.95), rs * 1.1]
    yt, rt = smooth_profile(ys, rad, min_radius=0.5 * rs)
    parts = [revolve_part(yt, rt, style["stem"], origin=base, frame=frame, name="stem")]
    if style["ring"]:
        yr = rng.uniform(0.6, 0.8) * h
        parts.append(torus_part(base + frame @ [0.0, yr, 0.0], rs * 1.05, 0.35 * rs, style["ring_col"],
                                frame=frame, name="ring"))
    cap_r = max(scale * rng.uniform(0.35, 0.8), 2.2 * rs)
    cap_h = cap_r * rng.uniform(0.3, 0.9)
    top = base + frame @ np.array([0.0, h, 0.0])
    parts.append(_cap_part(rng, top, frame, cap_r, cap_h, rs, style["spotted"], style["cap"],
                           style["crown"], style["gill"]))
    return parts, cap_r


@register("mushroom")
def mushroom(rng: np.random.Generator, n: int):
    """A mushroom (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    hue, sat, val = CAP_HUES[int(rng.integers(len(CAP_HUES)))]
    cap = jitter(rng, hue, sat, val, dh=0.02, ds=0.1, dv=0.08)
    crown = mix(cap, hsv(hue, min(1.0, sat + 0.1), val * 0.6), rng.uniform(0.3, 0.8))
    style = {
        "cap": cap,
        "crown": crown,
        "gill": jitter(rng, 0.1, 0.2, 0.9, ds=0.1),
        "stem": jitter(rng, 0.1, 0.15, 0.9, ds=0.1, dv=0.06),
        "ring_col": jitter(rng, 0.1, 0.1, 0.95),
        "spotted": bool(rng.random() < (0.7 if hue in (0.0, 0.06) else 0.15)),
        "ring": bool(rng.random() < 0.3),
    }
    parts, cap_r = _mushroom(rng, np.zeros(3), 1.0, style)
    if rng.random() < 0.3:  # a smaller sibling next to it, clear of the big cap
        ang = rng.uniform(0, 2 * math.pi)
        dist = cap_r * rng.uniform(1.0, 1.3)
        parts += _mushroom(rng, np.array([dist * math.cos(ang), 0.0, dist * math.sin(ang)]),
                           rng.uniform(0.35, 0.55), style)[0]
    return parts
