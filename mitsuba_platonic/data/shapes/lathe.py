"""Lathe objects: solids of revolution about +y (vases, goblets, bottles, long barrels).

Each object is a few revolved parts (:func:`~.sdf.revolve_part`) whose radius profiles are
smooth curves (:func:`~.sdf.smooth_profile`) through random control points ``(y_i, r_i)``.

Varies with the seed: the kind (vase, goblet, bottle, barrel, each ~¼) and, per kind,
height, belly/shoulder position and width, neck and lip, foot, stem knots, bowl shape
(cup, tulip, cone), bottle proportions and cap, barrel breech, taper, bands and muzzle;
colours per part (glaze and foot, glass and cap and label, metal and rings), with painted
bands on vases and labels on bottles.
"""

from __future__ import annotations

from typing import Callable, List, Sequence, Tuple

import numpy as np
import torch

from .colour import hsv, jitter, mix
from .registry import register
from .sdf import Part, revolve_part, smooth_profile


def _bands(base, bands: Sequence[Tuple[float, float, Sequence[float]]]) -> Callable[[torch.Tensor], torch.Tensor]:
    """A colour function: ``base`` with horizontal bands ``(y_centre, half_width, colour)``."""
    def colour(p: torch.Tensor) -> torch.Tensor:
        y = p[..., 1]
        c = p.new_tensor(base).expand(p.shape).clone()
        for yc, hw, col in bands:
            w = ((hw - (y - yc).abs()) / (0.25 * hw + 1e-3)).clamp(0.0, 1.0)[..., None]
            c = c + w * (p.new_tensor(col) - c)
        return c
    return colour


def _vase(rng: np.random.Generator) -> List[Part]:
    H = rng.uniform(1.4, 2.2)
    rb = rng.uniform(0.22, 0.45)
    belly_y, belly_r = rng.uniform(0.25, 0.55) * H, rng.uniform(0.42, 0.85)
    neck_y, neck_r = rng.uniform(0.7, 0.86) * H, rng.uniform(0.12, 0.35)
    lip_r = neck_r * rng.uniform(1.1, 1.6)
    ys = [0.0, 0.1 * belly_y, belly_y, (belly_y + neck_y) / 2, neck_y, 0.96 * H, H]
    rs = [rb, rb * 1.08, belly_r, (belly_r + neck_r) / 2 * rng.uniform(0.85, 1.1), neck_r, lip_r, lip_r * 0.97]
    yt, rt = smooth_profile(ys, rs, min_radius=0.05)
    glaze = hsv(rng.uniform(0, 1), rng.uniform(0.3, 0.85), rng.uniform(0.55, 0.92))
    accent = hsv(rng.uniform(0, 1), rng.uniform(0.4, 0.9), rng.uniform(0.5, 0.95))
    bands = [(float(rng.uniform(0.15, 0.9) * H), float(rng.uniform(0.02, 0.08) * H), accent)
             for _ in range(int(rng.integers(0, 4)))]
    parts = [revolve_part(yt, rt, _bands(glaze, bands), name="body")]
    if rng.random() < 0.5:  # a foot ring of another colour
        fh = rng.uniform(0.05, 0.12)
        fyt, frt = smooth_profile([-fh, -0.3 * fh, 0.02], [rb * 0.95, rb * 1.02, rb * 0.9])
        foot = jitter(rng, 0.08, 0.3, 0.6) if rng.random() < 0.5 else accent
        parts.append(revolve_part(fyt, frt, foot, name="foot"))
    return parts


def _goblet(rng: np.random.Generator) -> List[Part]:
    metal = rng.random() < 0.5
    if metal:
        frame = jitter(rng, 0.12, 0.6, 0.85) if rng.random() < 0.6 else jitter(rng, 0.6, 0.05, 0.85)
        bowl_col = frame if rng.random() < 0.6 else hsv(rng.uniform(0, 1), 0.7, 0.7)
    else:
        bowl_col = hsv(rng.uniform(0, 1), rng.uniform(0.3, 0.8), rng.uniform(0.6, 0.95))
        frame = mix(bowl_col, (0.85, 0.85, 0.85), rng.uniform(0.3, 0.8))
    base_r, base_h = rng.uniform(0.3, 0.5), rng.uniform(0.04, 0.09)
    stem_h, stem_r = rng.uniform(0.35, 0.8), rng.uniform(0.04, 0.08)
    byt, brt = smooth_profile([0.0, 0.4 * base_h, base_h, base_h * 1.8],
                              [base_r, base_r * 0.97, base_r * 0.55, stem_r * 1.4])
    knot = rng.uniform(1.0, 2.2)
    kpos = rng.uniform(0.3, 0.7)
    syt, srt = smooth_profile([base_h, base_h + 0.1 * stem_h, base_h + kpos * stem_h, base_h + stem_h],
                              [stem_r * 1.3, stem_r, stem_r * knot, stem_r * 1.1])
    y0 = base_h + stem_h
    bowl_h, bowl_r = rng.uniform(0.45, 0.9), rng.uniform(0.3, 0.55)
    shape = rng.choice(["cup", "tulip", "cone"])
    if shape == "cup":
        ys = [0.0, 0.08, 0.35, 0.75, 1.0]
        rs = [stem_r * 1.2, bowl_r * 0.5, bowl_r * 0.9, bowl_r, bowl_r * 0.98]
    elif shape == "tulip":
        ys = [0.0, 0.1, 0.45, 0.8, 1.0]
        rs = [stem_r * 1.2, bowl_r * 0.6, bowl_r, bowl_r * 0.8, bowl_r * 0.85]
    else:
        ys = [0.0, 0.05, 0.5, 1.0]
        rs = [stem_r * 1.2, bowl_r * 0.15, bowl_r * 0.6, bowl_r * 1.1]
    wyt, wrt = smooth_profile([y0 + y * bowl_h for y in ys], rs, min_radius=stem_r)
    rim = [(y0 + bowl_h * 0.95, bowl_h * 0.04, mix(frame, (1.0, 0.9, 0.5), 0.5))] if rng.random() < 0.4 else []
    return [revolve_part(byt, brt, frame, thickness=base_h, name="base"),
            revolve_part(syt, srt, frame, name="stem"),
            revolve_part(wyt, wrt, _bands(bowl_col, rim), name="bowl")]


def _bottle(rng: np.random.Generator) -> List[Part]:
    body_h, body_r = rng.uniform(0.7, 1.3), rng.uniform(0.22, 0.42)
    shoulder = rng.uniform(0.12, 0.4)
    neck_r, neck_h = rng.uniform(0.06, 0.13), rng.uniform(0.25, 0.6)
    ys = [0.0, 0.04, 0.5 * body_h, body_h, body_h + 0.6 * shoulder, body_h + shoulder,
          body_h + shoulder + neck_h]
    rs = [body_r * 0.94, body_r, body_r * rng.uniform(0.95, 1.05), body_r,
          neck_r + (body_r - neck_r) * rng.uniform(0.2, 0.5), neck_r, neck_r * rng.uniform(0.95, 1.15)]
    yt, rt = smooth_profile(ys, rs, min_radius=0.04)
    glass = [jitter(rng, 0.33, 0.6, 0.6), jitter(rng, 0.08, 0.7, 0.6), jitter(rng, 0.58, 0.6, 0.7),
             jitter(rng, 0.5, 0.15, 0.85)][int(rng.integers(4))]
    label = hsv(rng.uniform(0, 1), rng.uniform(0.0, 0.7), rng.uniform(0.8, 0.97))
    bands = ([(body_h * rng.uniform(0.4, 0.6), body_h * rng.uniform(0.15, 0.3), label)]
             if rng.random() < 0.7 else [])
    top = ys[-1]
    cap_h = rng.uniform(0.06, 0.15)
    cap_r = rt[-1] * rng.uniform(1.05, 1.3)
    cyt, crt = smooth_profile([top - 0.3 * cap_h, top + 0.5 * cap_h, top + cap_h], [cap_r, cap_r, cap_r * 0.85])
    cap_col = hsv(rng.uniform(0, 1), rng.uniform(0.5, 0.9), rng.uniform(0.6, 0.9)) if rng.random() < 0.6 \
        else jitter(rng, 0.1, 0.5, 0.65)  # coloured cap or cork
    return [revolve_part(yt, rt, _bands(glass, bands), name="glass"),
            revolve_part(cyt, crt, cap_col, thickness=cap_h, name="cap")]


def _barrel(rng: np.random.Generator) -> List[Part]:
    L = rng.uniform(1.6, 2.0)
    r0 = rng.uniform(0.07, 0.12)
    breech_l, breech_r = rng.uniform(0.2, 0.45), r0 * rng.uniform(1.4, 2.0)
    taper = rng.uniform(0.6, 0.95)
    ys = [0.0, 0.03, breech_l * 0.9, breech_l * 1.1, breech_l + 0.25 * (L - breech_l), 0.8 * L, L]
    rs = [breech_r * 0.9, breech_r, breech_r, r0 * 1.1, r0, r0 * (1 + taper) / 2, r0 * taper]
    yt, rt = smooth_profile(ys, rs, min_radius=0.03)
    metal = [jitter(rng, 0.6, 0.1, 0.6), jitter(rng, 0.08, 0.55, 0.75), jitter(rng, 0.58, 0.2, 0.8),
             jitter(rng, 0.1, 0.3, 0.55)][int(rng.integers(4))]
    ring_col = jitter(rng, 0.12, 0.6, 0.85) if rng.random() < 0.6 else hsv(rng.uniform(0, 1), 0.6, 0.75)
    parts = [revolve_part(yt, rt, metal, name="barrel")]
    for _ in range(int(rng.integers(1, 4))):  # bands around the barrel
        yc = rng.uniform(breech_l + 0.1, 0.85 * L)
        rr = float(np.interp(yc, yt, rt)) * rng.uniform(1.25, 1.5)
        hw = rng.uniform(0.015, 0.04)
        ryt, rrt = smooth_profile([yc - hw, yc - 0.5 * hw, yc + 0.5 * hw, yc + hw], [rr * 0.85, rr, rr, rr * 0.85])
        parts.append(revolve_part(ryt, rrt, ring_col, thickness=2 * hw, name="band"))
    if rng.random() < 0.6:  # a muzzle device
        ml = rng.uniform(0.08, 0.18)
        mr = r0 * taper * rng.uniform(1.3, 1.8)
        myt, mrt = smooth_profile([L - ml, L - 0.8 * ml, L - 0.1 * ml, L + 0.02], [mr * 0.8, mr, mr, mr * 0.9])
        parts.append(revolve_part(myt, mrt, ring_col if rng.random() < 0.5 else metal, name="muzzle"))
    return parts


KINDS = {"vase": _vase, "goblet": _goblet, "bottle": _bottle, "barrel": _barrel}


@register("lathe")
def lathe(rng: np.random.Generator, n: int) -> List[Part]:
    """A lathe object (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    kind = list(KINDS)[int(rng.integers(len(KINDS)))]
    return KINDS[kind](rng)
