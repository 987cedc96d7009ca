"""Chairs: a seat on four legs, a pedestal or sled runners, a (tilted) back and optional arms.

The chair faces +z (the front camera): the seat's front edge is at +z, the back at −z.

Varies with the seed: seat width, depth, height, thickness and roundness (thin board to
upholstered cushion), rectangular or round seat; base type (four straight or splayed,
square or round legs with optional stretchers; a central pedestal on a five-spoke base with
casters or on a disc; sled runners); back height and tilt, back style (solid panel, vertical
slats, horizontal rails, or a ladder of both), optional arms on posts; colours per part
(wood, metal or painted frame; fabric or wood seat and back).
"""

from __future__ import annotations

import math
from typing import List

import numpy as np

from .colour import hsv, jitter
from .registry import register
from .sdf import Part, box_part, capsule_part, cylinder_part, rotation, sphere_part


def _frame_colour(rng: np.random.Generator):
    kind = rng.choice(["wood", "metal", "painted"], p=[0.5, 0.25, 0.25])
    if kind == "wood":
        return jitter(rng, rng.uniform(0.055, 0.1), rng.uniform(0.45, 0.7), rng.uniform(0.55, 0.85), dv=0.03)
    if kind == "metal":
        return jitter(rng, 0.6, 0.04, rng.uniform(0.55, 0.85), ds=0.03)
    return hsv(rng.uniform(0, 1), rng.uniform(0.4, 0.75), rng.uniform(0.6, 0.9))


def _fabric_colour(rng: np.random.Generator):
    return hsv(rng.uniform(0, 1), rng.uniform(0.25, 0.8), rng.uniform(0.55, 0.92))


@register("chair")
def chair(rng: np.random.Generator, n: int) -> List[Part]:
    """A chair (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    W = rng.uniform(0.4, 0.56)          # seat half-width
    D = rng.uniform(0.36, 0.5)          # seat half-depth
    H = rng.uniform(0.75, 1.0)          # height of the seat top
    cushion = rng.random() < 0.35
    t = rng.uniform(0.1, 0.16) if cushion else rng.uniform(0.05, 0.09)   # seat thickness
    base = str(rng.choice(["legs", "pedestal", "sled"], p=[0.65, 0.22, 0.13]))
    round_seat = base == "pedestal" and rng.random() < 0.4

    frame_col = _frame_colour(rng)
    seat_col = _fabric_colour(rng) if (cushion or rng.random() < 0.4) else frame_col
    back_col = seat_col if rng.random() < 0.7 else (_fabric_colour(rng) if rng.random() < 0.5 else frame_col)

    parts: List[Part] = []
    seat_y = H - t / 2
    rounding = min(t / 2 * 0.9, rng.uniform(0.01, 0.05) + (0.04 if cushion else 0.0))
    if round_seat:
        parts.append(cylinder_part((0.0, seat_y, 0.0), max(W, D), t / 2, seat_col,
                                   rounding=rounding, name="seat"))
    else:
        parts.append(box_part((0.0, seat_y, 0.0), (W, t / 2, D), seat_col, rounding, name="seat"))
    under = H - t  # underside of the seat

    # ---------------------------------------------------------------- base
    leg_r = rng.uniform(0.03, 0.06)
    legs_top = []  # rear leg tops, where back posts may continue
    if base == "legs":
        square = rng.random() < 0.5
        inset = rng.uniform(0.02, 0.08) + leg_r
        splay = rng.uniform(0.0, 0.12) if rng.random() < 0.5 else 0.0
        for sx in (-1, 1):
            for sz in (-1, 1):
                top = np.array([sx * (W - inset), under, sz * (D - inset)])
                foot = top + np.array([sx * splay, -under, sz * splay])
                if square:
                    mid, half = (top + foot) / 2, np.array([leg_r, under / 2, leg_r])
                    axis = (top - foot) / np.linalg.norm(top - foot)
                    fr = rotation(np.cross([0.0, 1.0, 0.0], axis) if splay else "x",
                                  math.degrees(math.acos(axis[1])) if splay else 0.0)
                    parts.append(box_part(mid, half, frame_col, rounding=0.3 * leg_r, frame=fr, name="leg"))
                else:
                    parts.append(capsule_part(foot + [0, leg_r, 0], top, leg_r, frame_col,
                                              radius_b=leg_r * rng.uniform(1.0, 1.2), name="leg"))
                if sz < 0:
                    legs_top.append(top)
        if rng.random() < 0.45:  # stretchers between the legs
            y_s = under * rng.uniform(0.2, 0.45)
            r_s = leg_r * 0.6
            for sx in (-1, 1):
                x = sx * (W - inset + splay * (1 - y_s / under))
                zf = D - inset + splay * (1 - y_s / under)
                parts.append(capsule_part((x, y_s, -zf), (x, y_s, zf), r_s, frame_col, name="stretcher"))
            if rng.random() < 0.5:
                parts.append(capsule_part((-(W - inset), y_s, 0.0), (W - inset, y_s, 0.0), r_s, frame_col,
                                          name="stretcher"))
    elif base == "pedestal":
        col_r = rng.uniform(0.035, 0.07)
        foot_h = rng.uniform(0.08, 0.16)
        parts.append(cylinder_part((0.0, (under + foot_h) / 2, 0.0), col_r, (under - foot_h) / 2,
                                   frame_col, name="column"))
        if rng.random() < 0.6:  # five spokes with casters
            spoke_len = rng.uniform(0.75, 1.0) * max(W, D)
            caster = rng.uniform(0.035, 0.055)
            wheel_col = jitter(rng, 0.6, 0.05, 0.45)
            az0 = rng.uniform(0, 2 * math.pi / 5)
            for k in range(5):
                a = az0 + 2 * math.pi * k / 5
                tip = np.array([spoke_len * math.cos(a), 2 * caster + 0.02, spoke_len * math.sin(a)])
                parts.append(capsule_part((0.0, foot_h, 0.0), tip, rng.uniform(0.025, 0.04), frame_col,
                                          radius_b=0.025, name="spoke"))
                parts.append(sphere_part(tip - [0, caster + 0.01, 0], caster, wheel_col, name="caster"))
        else:  # a disc foot
            disc_r = rng.uniform(0.5, 0.8) * max(W, D)
            disc_h = rng.uniform(0.02, 0.04)
            parts.append(cylinder_part((0.0, disc_h, 0.0), disc_r, disc_h, frame_col, rounding=0.5 * disc_h,
                                       name="disc"))
            parts.append(cylinder_part((0.0, foot_h / 2 + disc_h, 0.0), col_r * 1.4, foot_h / 2,
                                       frame_col, name="collar"))
    else:  # sled: a tube on the floor on each side that rises to the seat at the front and back
        r_t = rng.uniform(0.02, 0.035)
        for sx in (-1, 1):
            x = sx * (W - r_t)
            zf, zb = D * rng.uniform(0.7, 1.0), -D * rng.uniform(0.7, 1.0)
            parts.append(capsule_part((x, r_t, zb - 0.1), (x, r_t, zf + 0.1), r_t, frame_col, name="runner"))
            parts.append(capsule_part((x, r_t, zf + 0.1), (x, under, zf - 0.05), r_t, frame_col, name="runner"))
            parts.append(capsule_part((x, r_t, zb - 0.1), (x, under, zb + 0.05), r_t, frame_col, name="runner"))

    # ---------------------------------------------------------------- back
    hb = rng.uniform(0.55, 1.05)                 # back height above the seat
    tilt = rng.uniform(0.0, 20.0)                # degrees, leaning backwards
    fr = rotation("x", -tilt)                    # local y = up the back, leaning towards −z
    u = fr[:, 1]
    bt = rng.uniform(0.035, 0.065) + (0.03 if cushion else 0.0)   # back thickness (half)
    origin = np.array([0.0, H, -D + bt])
    style = str(rng.choice(["panel", "vslats", "hrails", "ladder"], p=[0.4, 0.25, 0.2, 0.15]))
    bw = W * rng.uniform(0.85, 1.0)              # back half-width
    post_r = max(leg_r * 0.9, 0.025)

    def at(h: float) -> np.ndarray:              # a point on the back's mid-plane at height h
        return origin + h * u

    if style == "panel":
        start = rng.uniform(0.0, 0.25) * hb if base == "pedestal" else 0.0
        parts.append(box_part(at((start + hb) / 2), (bw, (hb - start) / 2, bt), back_col,
                              rounding=min(bt * 0.9, rng.uniform(0.01, 0.06)), frame=fr, name="back"))
        if start > 0:  # a support bar from the seat to a raised panel
            parts.append(box_part(at(start / 2), (0.05, start / 2 + 0.02, bt * 0.7), frame_col, frame=fr,
                                  name="back support"))
    else:
        top_h = rng.uniform(0.08, 0.2) if style != "hrails" else 0.0
        for sx in (-1, 1):  # posts
            a = np.array([sx * (bw - post_r), 0, 0]) + at(0.0)
            b = np.array([sx * (bw - post_r), 0, 0]) + at(hb)
            parts.append(capsule_part(a, b, post_r, frame_col, name="back post"))
        if top_h:
            parts.append(box_part(at(hb - top_h / 2), (bw, top_h / 2, bt * 0.8), back_col,
                                  rounding=0.01, frame=fr, name="top rail"))
        inner = bw - post_r
        if style in ("vslats", "ladder"):
            k = int(rng.integers(3, 7)) if style == "vslats" else int(rng.integers(2, 4))
            slat_w = inner / k * rng.uniform(0.25, 0.55)
            for i in range(k):
                x = -inner + (2 * i + 1) * inner / k
                parts.append(box_part(at((hb - top_h) / 2) + [x, 0, 0], (slat_w, (hb - top_h) / 2, bt * 0.5),
                                      back_col, frame=fr, name="slat"))
        if style in ("hrails", "ladder"):
            k = int(rng.integers(2, 5))
            rail_h = rng.uniform(0.03, 0.07)
            lo = rng.uniform(0.25, 0.45) * hb
            hi = hb - (top_h + rail_h if top_h else rail_h)
            for i in range(k):
                h = lo + (hi - lo) * (i / max(k - 1, 1))
                parts.append(box_part(at(h), (inner, rail_h, bt * 0.6), back_col, frame=fr, name="rail"))

    # ---------------------------------------------------------------- arms
    if base != "sled" and rng.random() < 0.35:
        ha = rng.uniform(0.18, 0.3)
        arm_r = rng.uniform(0.025, 0.045)
        arm_col = frame_col if rng.random() < 0.6 else seat_col
        z_back = at(ha)[2]
        z_front = D * rng.uniform(0.6, 0.95)
        for sx in (-1, 1):
            x = sx * (W + arm_r * rng.uniform(-0.5, 1.0))
            parts.append(box_part((x, H + ha, (z_back + z_front) / 2),
                                  (arm_r * 1.3, arm_r, (z_front - z_back) / 2),
                                  arm_col, rounding=arm_r * 0.8, name="armrest"))
            parts.append(capsule_part((x, H - t / 2, z_front - arm_r * 2), (x, H + ha, z_front - arm_r * 2),
                                      arm_r * 0.8, frame_col, name="arm post"))
    return parts
