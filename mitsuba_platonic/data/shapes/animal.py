"""Animals: a quadruped-like body on four legs, a head on a neck at one end and a tail at the other.

Orientation (the convention of this package, :mod:`mitsuba_platonic.data.shapes`): +y up, the
feet on the ground, the body's **length along z** with the head at +z, facing the front camera.
So the view at azimuth 0° (:mod:`mitsuba_platonic.views`: ω(0, 0) = +z) sees the animal head-on,
end-on and narrow, and the *side views* at azimuth ±90° (ω = ±x) see its length broadside.

Not round by design: the body's half-width is drawn last, from a drawn ratio

    ρ = (width seen end-on) / (width seen from the side) = 2 b_w / (z_front − z_back),  ρ ~ U(0.34, 0.48)

with z_front the tip of the head (or muzzle) and z_back the end of the rump or tail, both computed
in closed form from the parts (an ellipsoid with semi-axes a_i along the unit axes r_i reaches
√(Σ_i (a_i r_i·e)²) along e). Nothing else reaches sideways past the body (legs, head, ears and
horns stay inside ±b_w), so the closed-form silhouettes at 0° and 90° have that width ratio up to
a voxel's rounding (tests/test_shapes.py measures it).

Varies with the seed: body length-to-height, the ratio ρ, leg length (short to long) and
thickness, a chest, neck length and angle, head size, pitch and muzzle, ears, optional horns,
tail length and droop with an optional tuft; coat colour (brown, black, cream, tan, grey,
russet, golden) and pattern (solid, large patches, small spots or stripes across the body),
an optional light belly, optional socks and always darker hooves.
"""

from __future__ import annotations

import math
from typing import List, Sequence

import numpy as np
import torch

from .colour import hsv, jitter, mix
from .registry import register
from .sdf import Part, capsule_part, ellipsoid, rotation, sphere_part

#: Coat colours in sRGB HSV: (hue, saturation, value).
COATS = [
    (0.07, 0.60, 0.45),   # brown
    (0.00, 0.00, 0.14),   # black
    (0.11, 0.12, 0.92),   # cream
    (0.09, 0.45, 0.75),   # tan
    (0.60, 0.04, 0.55),   # grey
    (0.03, 0.65, 0.60),   # russet
    (0.11, 0.60, 0.85),   # golden
]
#: The drawn range of ρ = end-on width / side width (module docstring).
WIDTH_RATIO = (0.34, 0.48)


def _ellipsoid_part(centre: Sequence[float], radii: Sequence[float], colour, frame=None, name: str = "") -> Part:
    """An (oriented) :func:`~.sdf.ellipsoid` part; its hull is the box of its semi-axes in ``frame``."""
    R = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    corners = (signs * np.asarray(radii, dtype=np.float64)) @ R.T + np.asarray(centre, dtype=np.float64)
    return Part(lambda p: ellipsoid(p, centre, radii, frame), colour, corners, 0.0, 2.0 * min(radii), name)


def _reach(radii: Sequence[float], frame: np.ndarray, axis: int) -> float:
    """How far an ellipsoid of ``radii`` along ``frame``'s columns reaches along world ``axis``:
    √(Σ_i (a_i R_{axis,i})²)."""
    return float(np.sqrt(np.sum((np.asarray(radii) * np.asarray(frame)[axis]) ** 2)))


@register("animal")
def animal(rng: np.random.Generator, n: int) -> List[Part]:
    """A four-legged animal (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    L = 0.6                                          # body half-length (the scale: composite refits)
    bh = L * rng.uniform(0.38, 0.56)                 # body half-height
    leg = L * rng.uniform(0.55, 1.25)                # ground to the body's underside
    leg_r = L * rng.uniform(0.055, 0.09)
    foot_r = leg_r * rng.uniform(0.6, 0.85)
    yb = leg + bh                                    # the body's centre height
    # ---------------------------------------------------------------- colours and pattern
    hue, sat, val = COATS[int(rng.integers(len(COATS)))]
    coat = jitter(rng, hue, sat, val, dh=0.02, ds=0.08, dv=0.06)
    other_hue, other_sat, other_val = COATS[int(rng.integers(len(COATS)))]
    second = jitter(rng, other_hue, other_sat, other_val, dh=0.02, ds=0.08, dv=0.06)
    if max(abs(a - b) for a, b in zip(coat, second)) < 0.15:      # a pattern that shows
        second = mix(coat, (0.9, 0.88, 0.85) if val < 0.6 else (0.03, 0.03, 0.03), 0.8)
    pattern = str(rng.choice(["solid", "patches", "spots", "stripes"], p=[0.3, 0.3, 0.2, 0.2]))
    belly = bool(rng.random() < 0.4)
    belly_col = mix(coat, hsv(0.1, 0.12, 0.92), rng.uniform(0.5, 0.9))
    socks = bool(rng.random() < 0.3)
    sock_col = second if rng.random() < 0.5 else mix(coat, (0.02, 0.02, 0.02), 0.7)
    hoof_col = jitter(rng, 0.07, 0.3, 0.18, dv=0.05)
    hoof_h = foot_r * rng.uniform(1.5, 2.5)
    sock_h = leg * rng.uniform(0.25, 0.55)
    # patches and spots: centres on the body's surface (unit directions, scaled once its width is known)
    k = int(rng.integers(4, 9)) if pattern == "patches" else int(rng.integers(25, 60))
    blob_dirs = rng.normal(size=(k, 3))
    blob_dirs /= np.linalg.norm(blob_dirs, axis=1, keepdims=True)
    blob_r = L * (rng.uniform(0.2, 0.38, k) if pattern == "patches" else rng.uniform(0.05, 0.09, k))
    blobs = np.zeros((k, 3))                         # filled in below, with the body's half-width
    stripe_period = L * rng.uniform(0.18, 0.35)
    stripe_phase, stripe_wave = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.0, 1.5)
    stripe_share = rng.uniform(0.3, 0.5)

    def coat_colour(p: torch.Tensor) -> torch.Tensor:
        x, y, z = p.unbind(-1)
        c = p.new_tensor(coat).expand(p.shape).clone()
        if pattern in ("patches", "spots"):
            d = torch.cdist(p.reshape(-1, 3), p.new_tensor(blobs)) - p.new_tensor(blob_r)
            s = (-d.min(dim=1).values / (0.15 * float(blob_r.min()))).clamp(0.0, 1.0).view(p.shape[:-1])
            c = c + s[..., None] * (p.new_tensor(second) - c)
        elif pattern == "stripes":
            wave = torch.sin(2.0 * math.pi * z / stripe_period + stripe_phase + stripe_wave * torch.sin(3.0 * y / L))
            s = ((wave - (1.0 - 2.0 * stripe_share)) / 0.3).clamp(0.0, 1.0) * (y > leg * 0.5)
            c = c + s[..., None] * (p.new_tensor(second) - c)
        if belly:
            s = ((yb - 0.35 * bh - y) / (0.2 * bh)).clamp(0.0, 1.0) * (y > leg - 0.1 * bh)
            c = c + s[..., None] * (p.new_tensor(belly_col) - c)
        if socks:
            s = ((sock_h - y) / (0.1 * leg)).clamp(0.0, 1.0)
            c = c + s[..., None] * (p.new_tensor(sock_col) - c)
        hoof = ((hoof_h - y) / (0.3 * hoof_h)).clamp(0.0, 1.0)
        return c + hoof[..., None] * (p.new_tensor(hoof_col) - c)

    # ---------------------------------------------------------------- neck and head (+z)
    neck_len = L * rng.uniform(0.3, 0.75)
    neck_up = math.radians(rng.uniform(25.0, 70.0))            # above the horizontal
    neck_r = bh * rng.uniform(0.35, 0.55)
    neck_a = np.array([0.0, yb + 0.25 * bh, 0.7 * L])
    neck_b = neck_a + neck_len * np.array([0.0, math.sin(neck_up), math.cos(neck_up)])
    hl = L * rng.uniform(0.26, 0.4)                  # head half-length
    hw = hl * rng.uniform(0.45, 0.6)                 # half-width
    hh = hl * rng.uniform(0.5, 0.7)                  # half-height
    pitch = rng.uniform(10.0, 45.0)                  # the head's long axis dips below the horizontal
    fr = rotation("x", pitch)                        # local z → (0, −sin, cos)
    ahead = fr[:, 2]
    head_c = neck_b + 0.45 * hl * ahead
    muzzle = bool(rng.random() < 0.6)
    muzzle_c = head_c + 0.7 * hl * ahead
    muzzle_radii = (0.75 * hw, 0.7 * hh, 0.45 * hl)
    muzzle_col = (mix(coat, (0.9, 0.85, 0.8), 0.6) if rng.random() < 0.5 else mix(coat, hoof_col, 0.6))
    head_radii = (hw, hh, hl)
    z_front = max(head_c[2] + _reach(head_radii, fr, 2), neck_b[2] + 0.8 * neck_r, neck_a[2] + neck_r,
                  muzzle_c[2] + _reach(muzzle_radii, fr, 2) if muzzle else -math.inf)
    # ---------------------------------------------------------------- tail (−z)
    tail_len = L * rng.uniform(0.3, 0.9)
    droop = math.radians(rng.uniform(35.0, 85.0))             # below the horizontal
    tail_r = L * rng.uniform(0.025, 0.045)
    tail_a = np.array([0.0, yb + 0.35 * bh, -0.92 * L])
    tail_b = tail_a + tail_len * np.array([0.0, -math.sin(droop), -math.cos(droop)])
    tuft = bool(rng.random() < 0.5)
    tuft_r = tail_r * rng.uniform(1.6, 2.4)
    tail_end = tail_b[2] - (tuft_r if tuft else 0.7 * tail_r)
    z_back = min(-L, tail_end)
    # ---------------------------------------------------------------- the body's width, last
    ratio = rng.uniform(*WIDTH_RATIO)
    bw = 0.5 * ratio * (z_front - z_back)            # end-on 2 b_w, from the side z_front − z_back
    blobs[:] = np.array([0.0, yb, 0.0]) + blob_dirs * np.array([bw, bh, L])
    parts: List[Part] = [_ellipsoid_part((0.0, yb, 0.0), (bw, bh, L), coat_colour, name="body")]
    if rng.random() < 0.6:                           # a deeper chest at the front
        parts.append(_ellipsoid_part((0.0, yb + 0.05 * bh, 0.4 * L), (0.97 * bw, 1.08 * bh, 0.55 * L),
                                     coat_colour, name="chest"))
    parts.append(capsule_part(neck_a, neck_b, neck_r, coat_colour, radius_b=0.8 * neck_r, name="neck"))
    parts.append(_ellipsoid_part(head_c, head_radii, coat_colour, frame=fr, name="head"))
    if muzzle:
        parts.append(_ellipsoid_part(muzzle_c, muzzle_radii, muzzle_col, frame=fr, name="muzzle"))
    ear = hh * rng.uniform(0.3, 0.5)
    ear_col = coat if rng.random() < 0.6 else second
    for sx in (-1, 1):
        parts.append(_ellipsoid_part(head_c + np.array([sx * 0.7 * hw, 0.75 * hh, 0.0]) - 0.35 * hl * ahead,
                                     (0.35 * ear, ear, 0.25 * ear), ear_col, frame=rotation("z", -sx * 30.0),
                                     name="ear"))
    if rng.random() < 0.3:                           # horns, kept inside the body's width
        horn_col = jitter(rng, 0.1, 0.15, 0.85)
        reach = min(0.8 * bw, 0.6 * hw + L * rng.uniform(0.1, 0.25))
        rise = L * rng.uniform(0.08, 0.2)
        for sx in (-1, 1):
            root = head_c + np.array([sx * 0.5 * hw, 0.8 * hh, 0.0]) - 0.2 * hl * ahead
            tip = np.array([sx * reach, root[1] + rise, root[2]])
            parts.append(capsule_part(root, tip, 0.18 * hw, horn_col, radius_b=0.06 * hw, name="horn"))
    # legs: inside the body's width, under its front and back
    spread_x = bw * rng.uniform(0.4, 0.6)
    spread_z = L * rng.uniform(0.5, 0.7)
    for sx in (-1, 1):
        for sz in (-1, 1):
            top = (sx * spread_x, yb - 0.2 * bh, sz * spread_z)
            foot = (sx * spread_x, foot_r, sz * spread_z)
            parts.append(capsule_part(foot, top, foot_r, coat_colour, radius_b=leg_r, name="leg"))
    parts.append(capsule_part(tail_a, tail_b, tail_r, coat_colour, radius_b=0.7 * tail_r, name="tail"))
    if tuft:
        parts.append(sphere_part(tail_b, tuft_r, mix(coat, hoof_col, 0.5), name="tuft"))
    return parts
