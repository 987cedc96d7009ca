"""Airplanes: a revolved fuselage, swept trapezoidal wings, a tail and 0, 2 or 4 engines.

The nose points at +z (the front camera), +y is up, the wings span x.

Each lifting surface (wing, horizontal stabiliser, fin) is a trapezoid planform extruded to
a thickness that tapers from root to tip: in planform coordinates (span s, chord-wise z),
``d₂ = polygon(s, z)`` and ``d = extrude(d₂, |t − t₀(s)| − ½ th(s))`` with ``t`` the
thickness axis, ``t₀`` the dihedral offset and ``th`` the thickness.

Varies with the seed: fuselage length-to-radius ratio and nose/tail shape; wing span,
sweep, root chord, taper, dihedral and position (low/mid/high, fore/aft); tail size and
sweep, T-tail or conventional; number of engines (0, 2 or 4, under the wings); livery
(fuselage colour, a cheat-line stripe, fin and engine colours, grey or painted wings).
"""

from __future__ import annotations

import math
from typing import List

import numpy as np
import torch

from .colour import hsv, jitter
from .registry import register
from .sdf import (Part, box_part, capsule_part, extrude, frame_from_axis, polygon2d, revolve_part,
                  smooth_profile)


def _surface(root_le: float, root_chord: float, tip_chord: float, span: float, sweep: float,
             th_root: float, th_tip: float, colour, kind: str, base: float = 0.0,
             dihedral: float = 0.0, name: str = "") -> Part:
    """A trapezoidal lifting surface.

    ``kind='h'``: mirrored about x = 0, spanning ±x, thickness along y, root at height
    ``base``, tips raised by ``dihedral`` degrees. ``kind='v'``: spanning +y from ``base``,
    thickness along x (a fin). ``root_le`` is the z of the root's leading edge; the tip's
    leading edge lies ``span · tan(sweep)`` behind it.
    """
    tip_le = root_le - span * math.tan(math.radians(sweep))
    verts = [(0.0, root_le - root_chord), (span, tip_le - tip_chord), (span, tip_le), (0.0, root_le)]
    tan_d = math.tan(math.radians(dihedral))

    def sdf(p: torch.Tensor) -> torch.Tensor:
        x, y, z = p.unbind(-1)
        if kind == "h":
            s, t = x.abs(), y - base - x.abs() * tan_d
        else:
            s, t = y - base, x
        sc = (s / span).clamp(0.0, 1.0)
        half_th = 0.5 * (th_root + (th_tip - th_root) * sc)
        return extrude(polygon2d(s, z, verts), t.abs() - half_th)

    pts = []
    for (s, z), th in zip(verts, (th_root, th_tip, th_tip, th_root)):
        for sign in (-1, 1):
            if kind == "h":
                for side in (-1, 1):
                    pts.append((side * s, base + s * tan_d + sign * th / 2, z))
            else:
                pts.append((sign * th / 2, base + s, z))
    return Part(sdf, colour, np.asarray(pts), 0.0, th_tip, name)


@register("airplane")
def airplane(rng: np.random.Generator, n: int) -> List[Part]:
    """An airplane (see the module docstring); returns its parts for :func:`~.sdf.composite`."""
    engines = int(rng.choice([0, 2, 4], p=[0.3, 0.45, 0.25]))
    jet = engines > 0
    L = 1.0                                           # fuselage half-length: z ∈ [−1, 1]
    rf = rng.uniform(0.075, 0.125)                    # fuselage radius
    nose = rng.uniform(0.08, 0.3)                     # nose length (blunt airliner → pointed)
    tail = rng.uniform(0.3, 0.55)                     # tail-cone length
    # ---------------------------------------------------------------- livery
    body_col = (jitter(rng, 0.6, 0.05, 0.95, ds=0.04, dv=0.04) if rng.random() < 0.55
                else hsv(rng.uniform(0, 1), rng.uniform(0.2, 0.6), rng.uniform(0.65, 0.95)))
    accent = hsv(rng.uniform(0, 1), rng.uniform(0.6, 0.9), rng.uniform(0.6, 0.9))
    wing_col = jitter(rng, 0.6, 0.05, 0.75, ds=0.04) if rng.random() < 0.6 else body_col
    engine_col = accent if rng.random() < 0.3 else jitter(rng, 0.6, 0.06, 0.7)
    fin_col = accent if rng.random() < 0.75 else body_col
    stripe = rng.random() < 0.6
    stripe_y = rng.uniform(-0.2, 0.3) * rf
    stripe_w = rng.uniform(0.12, 0.3) * rf
    window_col = hsv(0.58, 0.5, 0.45)

    # ---------------------------------------------------------------- fuselage (revolved about z)
    zs = [-L, -L + 0.35 * tail, -L + tail, L - nose, L - 0.45 * nose, L]
    rs = [rf * rng.uniform(0.1, 0.3), rf * 0.65, rf, rf, rf * 0.75, rf * 0.05]
    yt, rt = smooth_profile(zs, rs, min_radius=0.02 * rf)
    axis = frame_from_axis((0.0, 0.0, 1.0))

    def body_colour(p: torch.Tensor) -> torch.Tensor:
        x, y, z = p.unbind(-1)
        c = p.new_tensor(body_col).expand(p.shape).clone()
        if stripe:
            band = ((stripe_w - (y - stripe_y).abs()) / (0.2 * stripe_w)).clamp(0, 1)
            c = c + band[..., None] * (p.new_tensor(accent) - c)
        cockpit = (((z - (L - 0.75 * nose)) / (0.1 * nose + 0.02)).clamp(0, 1)
                   * ((y - 0.2 * rf) / (0.1 * rf)).clamp(0, 1))
        cockpit = cockpit * (z < L - 0.15 * nose)
        return c + cockpit[..., None] * (p.new_tensor(window_col) - c)

    parts = [revolve_part(yt, rt, body_colour, frame=axis, thickness=2 * rf, name="fuselage")]

    # ---------------------------------------------------------------- wings
    span = rng.uniform(0.75, 1.05) * (1.0 if engines < 4 else 1.1)
    sweep = rng.uniform(20, 40) if jet else rng.uniform(0, 15)
    root_chord = rng.uniform(0.3, 0.5)
    taper = rng.uniform(0.25, 0.6)
    # place the wing by its area centroid (≈ the aircraft's centre of gravity, near mid-fuselage)
    st = np.linspace(0.0, 1.0, 101)
    chord = root_chord * (1.0 + (taper - 1.0) * st)
    mid = -st * span * math.tan(math.radians(sweep)) - chord / 2      # relative to the root LE
    wing_z = rng.uniform(-0.1, 0.12) - float((mid * chord).sum() / chord.sum())
    wing_y = rng.uniform(-0.6, 0.6) * rf
    dihedral = rng.uniform(-2, 7)
    th_root = rng.uniform(0.25, 0.45) * rf
    parts.append(_surface(wing_z, root_chord, root_chord * taper, span, sweep, th_root, th_root * 0.4,
                          wing_col, "h", base=wing_y, dihedral=dihedral, name="wings"))

    # ---------------------------------------------------------------- tail
    t_tail = rng.random() < 0.25
    fin_h = rng.uniform(0.22, 0.4)
    fin_chord = rng.uniform(0.22, 0.35)
    fin_sweep = rng.uniform(25, 50)
    fin_le = -L + tail * 0.55 + fin_chord * rng.uniform(0.6, 0.9)
    parts.append(_surface(fin_le, fin_chord, fin_chord * rng.uniform(0.4, 0.7), fin_h, fin_sweep,
                          0.3 * rf, 0.15 * rf, fin_col, "v", base=0.5 * rf, name="fin"))
    hs_span = rng.uniform(0.25, 0.42)
    hs_chord = rng.uniform(0.15, 0.25)
    if t_tail:
        hs_y = 0.5 * rf + fin_h
        hs_le = fin_le - fin_h * math.tan(math.radians(fin_sweep)) - 0.01
        hs_chord = min(hs_chord, fin_chord * 0.6)
    else:
        hs_y = rng.uniform(0.0, 0.4) * rf
        hs_le = -L + tail * 0.3 + hs_chord + 0.05
    parts.append(_surface(hs_le, hs_chord, hs_chord * rng.uniform(0.4, 0.7), hs_span, rng.uniform(20, 40),
                          0.25 * rf, 0.12 * rf, wing_col if rng.random() < 0.5 else fin_col, "h",
                          base=hs_y, dihedral=rng.uniform(0, 8), name="stabiliser"))

    # ---------------------------------------------------------------- engines under the wings
    if engines:
        re = rng.uniform(0.45, 0.75) * rf
        le = rng.uniform(0.22, 0.35)
        stations = [rng.uniform(0.3, 0.4)] if engines == 2 else [rng.uniform(0.27, 0.35), rng.uniform(0.58, 0.7)]
        tan_s = math.tan(math.radians(sweep))
        tan_d = math.tan(math.radians(dihedral))
        for st in stations:
            xs = st * span
            z_le = wing_z - xs * tan_s                # the wing's leading edge at this station
            y_w = wing_y + xs * tan_d - 0.5 * th_root
            yc = y_w - re - rng.uniform(0.2, 0.5) * re
            for side in (-1, 1):
                front = (side * xs, yc, z_le + 0.55 * le)
                back = (side * xs, yc, z_le - 0.45 * le)
                parts.append(capsule_part(back, front, re * 0.6, engine_col, radius_b=re, name="engine"))
                parts.append(box_part((side * xs, (yc + y_w + 0.5 * th_root) / 2, z_le - 0.1 * le),
                                      (0.12 * re, (y_w + 0.5 * th_root - yc) / 2, 0.3 * le), wing_col,
                                      name="pylon"))
    return parts
