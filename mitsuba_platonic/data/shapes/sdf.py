"""Signed-distance helpers and the part compositor that turns parts into RGBA volumes.

Conventions
-----------
Every SDF takes points ``p`` of shape ``(..., 3)`` (world or design-frame ``(x, y, z)``,
+y up) and returns the signed distance ``(...)``: negative inside, positive outside, and
(for the exact ones) ``|∇d| = 1``. Geometric parameters are plain Python numbers or
sequences; they are converted to ``p``'s dtype and device. Formulas use ``|·|`` for the
Euclidean norm, ``a⁺ = max(a, 0)`` and ``clamp(t, 0, 1)``.

Some SDFs are *bounds* rather than exact distances (the ellipsoid, tapered capsules). They
are exact or first-order exact close to the surface, which is all the one-voxel occupancy ramp
needs. :func:`profile_sdf` (revolved profiles) and :func:`polygon2d` are exact, also at sharp
corners and steps, where first-order estimates would let density leak far from the surface.

From distances to volumes
-------------------------
:func:`occupancy` maps a distance to an anti-aliased density with a smoothstep ramp ``w``
voxels wide centred on the surface. A shape is a list of :class:`Part` s (an SDF in a free
*design frame*, a colour, a hull that bounds it, and its smallest thickness) and
:func:`composite` renders them into ``(4, N, N, N)`` ``[r, g, b, density]``:

1. *fit*: the design frame is translated so that the union bounding box is centred at the
   origin and scaled uniformly so the whole shape fits in the ball of radius ``fit_radius``;
2. *thickness floor*: a part thinner than ``min_thickness_voxels`` (default 1.5) voxels
   after scaling is dilated (its SDF lowered) until it is that thick, so thin parts survive
   at N = 16 (1.5 voxels keep a cross-section above ½ density wherever the part falls
   between voxel centres);
3. *evaluation*: each part's SDF is evaluated only on the voxels of its bounding box;
4. *union*: ``density = 1 − Π_k (1 − o_k)`` and ``rgb = Σ_k o_k c_k / Σ_k o_k``;
5. *colour padding*: empty voxels next to the surface get the colour of the nearby surface
   (normalised box filtering), so trilinear lookups at the boundary do not blend towards black.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F

from ...volume import voxel_size

__all__ = [
    # transforms
    "rotation", "frame_from_axis", "to_local",
    # primitives
    "sphere", "box", "segment", "capsule", "cylinder", "torus", "ellipsoid",
    "polygon2d", "extrude",
    # revolution
    "revolve", "profile_sdf", "smooth_profile",
    # volumes
    "occupancy", "Part", "composite", "grid_points",
    # part builders
    "sphere_part", "box_part", "capsule_part", "cylinder_part",
    "torus_part", "revolve_part",
]

Vec = Sequence[float]
Colour = Union[Vec, Callable[[torch.Tensor], torch.Tensor]]


# --------------------------------------------------------------------------- transforms

def rotation(axis: str | Vec, angle: float, degrees: bool = True) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` by ``angle`` about ``axis`` ('x' | 'y' | 'z' or a vector).

    Rodrigues: ``R = I + sin θ K + (1 − cos θ) K²`` with ``K`` the cross-product matrix of
    the unit axis; right-handed (positive angles turn counter-clockwise seen from +axis).
    """
    if isinstance(axis, str):
        axis = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}[axis]
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    t = math.radians(angle) if degrees else float(angle)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(t) * K + (1.0 - math.cos(t)) * (K @ K)


def frame_from_axis(axis: Vec) -> np.ndarray:
    """An orthonormal frame ``(3, 3)`` whose columns are (local x, local y, local z) with local y = ``axis``.

    Use it with :func:`to_local` to lay a y-aligned primitive (cylinder, revolved profile)
    along any direction.
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(helper, a)
    x /= np.linalg.norm(x)
    z = np.cross(x, a)
    return np.stack([x, a, z], axis=1)


def to_local(p: torch.Tensor, origin: Vec = (0.0, 0.0, 0.0),
             frame: Optional[np.ndarray] = None) -> torch.Tensor:
    """Points in a local frame: ``q = Rᵀ (p − o)``, i.e. ``(p − o) @ R`` for row vectors.

    ``frame`` ``R`` holds the local axes as columns (e.g. from :func:`rotation` or
    :func:`frame_from_axis`); ``None`` is the identity. Rigid maps keep distances, so an SDF
    evaluated on ``q`` is an SDF of the moved shape.
    """
    q = p - p.new_tensor(origin)
    if frame is not None:
        q = q @ p.new_tensor(np.asarray(frame, dtype=np.float64))
    return q


# --------------------------------------------------------------------------- primitives

def sphere(p: torch.Tensor, centre: Vec, radius: float) -> torch.Tensor:
    """Sphere: ``d = |p − c| − r`` (exact)."""
    return (p - p.new_tensor(centre)).norm(dim=-1) - radius


def box(p: torch.Tensor, centre: Vec, half: Vec, rounding: float = 0.0,
        frame: Optional[np.ndarray] = None) -> torch.Tensor:
    """(Rounded, oriented) box with half-extents ``h``: ``q = |Rᵀ(p − c)| − (h − ρ)``,
    ``d = |q⁺| + min(max(q_x, q_y, q_z), 0) − ρ`` (exact).

    ``rounding`` ρ rounds the edges without changing the outer size.
    """
    q = to_local(p, centre, frame).abs() - p.new_tensor(half) + rounding
    outside = q.clamp_min(0.0).norm(dim=-1)
    inside = q.max(dim=-1).values.clamp_max(0.0)
    return outside + inside - rounding


def segment(p: torch.Tensor, a: Vec, b: Vec) -> Tuple[torch.Tensor, torch.Tensor]:
    """Distance to the segment ``ab`` and the parameter of the closest point:
    ``t = clamp((p − a)·(b − a) / |b − a|², 0, 1)``, ``d = |p − a − t (b − a)|``."""
    a_t, b_t = p.new_tensor(a), p.new_tensor(b)
    ba = b_t - a_t
    pa = p - a_t
    t = ((pa @ ba) / (ba @ ba).clamp_min(1e-12)).clamp(0.0, 1.0)
    return (pa - t[..., None] * ba).norm(dim=-1), t


def capsule(p: torch.Tensor, a: Vec, b: Vec, radius: float,
            radius_b: Optional[float] = None) -> torch.Tensor:
    """Capsule (segment ``ab`` thickened by ``r``): ``d = |p − a − t(b − a)| − r`` (exact).

    With ``radius_b`` the radius tapers linearly, ``r(t) = r_a + t (r_b − r_a)``: a tapered
    capsule, a distance bound that is accurate while the taper is gentle.
    """
    d, t = segment(p, a, b)
    if radius_b is None:
        return d - radius
    return d - (radius + t * (radius_b - radius))


def cylinder(p: torch.Tensor, centre: Vec, radius: float, half_height: float,
             frame: Optional[np.ndarray] = None, rounding: float = 0.0) -> torch.Tensor:
    """Capped cylinder about local y: ``q = (√(x² + z²) − r, |y| − h) + ρ``,
    ``d = |q⁺| + min(max(q), 0) − ρ`` (exact; ``rounding`` ρ rounds the rims)."""
    q = to_local(p, centre, frame)
    r = torch.sqrt(q[..., 0] ** 2 + q[..., 2] ** 2)
    return extrude(r - radius, q[..., 1].abs() - half_height, rounding)


def torus(p: torch.Tensor, centre: Vec, major: float, minor: float,
          frame: Optional[np.ndarray] = None) -> torch.Tensor:
    """Torus about local y (ring in the local xz-plane): ``d = |(√(x² + z²) − R, y)| − r`` (exact)."""
    q = to_local(p, centre, frame)
    ring = torch.sqrt(q[..., 0] ** 2 + q[..., 2] ** 2) - major
    return torch.sqrt(ring ** 2 + q[..., 1] ** 2) - minor


def ellipsoid(p: torch.Tensor, centre: Vec, radii: Vec,
              frame: Optional[np.ndarray] = None) -> torch.Tensor:
    """Ellipsoid with semi-axes ``a``: the bound ``d = k₀ (k₀ − 1) / k₁`` with
    ``k₀ = |q / a|``, ``k₁ = |q / a²|`` (zero on the surface, first-order exact near it;
    ``−min(a)`` at the centre, where the formula is 0/0)."""
    q = to_local(p, centre, frame)
    a = p.new_tensor(radii)
    k0 = (q / a).norm(dim=-1)
    k1 = (q / (a * a)).norm(dim=-1)
    return torch.where(k1 > 1e-9, k0 * (k0 - 1.0) / k1.clamp_min(1e-9), -a.min())


def polygon2d(u: torch.Tensor, v: torch.Tensor, vertices: Sequence[Tuple[float, float]]) -> torch.Tensor:
    """Convex polygon in the (u, v) plane, vertices counter-clockwise (exact).

    Inside, ``d = max_i n_i · (q − v_i)`` over the outward unit edge normals ``n_i``;
    outside (where that maximum is positive), ``d = min_i`` distance to the edge segments
    ``[v_i, v_{i+1}]`` (the half-plane maximum alone would cut sharp corners short).
    """
    verts = np.asarray(vertices, dtype=np.float64)
    inner = None
    seg2 = None
    for i in range(len(verts)):
        a, b = verts[i], verts[(i + 1) % len(verts)]
        e = b - a
        n = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for counter-clockwise order
        pu, pv = u - a[0], v - a[1]
        di = pu * n[0] + pv * n[1]
        inner = di if inner is None else torch.maximum(inner, di)
        h = ((pu * e[0] + pv * e[1]) / float(e @ e)).clamp(0.0, 1.0)
        d2 = (pu - h * e[0]) ** 2 + (pv - h * e[1]) ** 2
        seg2 = d2 if seg2 is None else torch.minimum(seg2, d2)
    return torch.where(inner > 0, torch.sqrt(seg2), inner)


def extrude(d_a: torch.Tensor, d_b: torch.Tensor, rounding: float = 0.0) -> torch.Tensor:
    """Intersection of two orthogonal distance fields (e.g. a 2D profile and a slab):
    ``d = |(d_a, d_b)⁺| + min(max(d_a, d_b), 0)`` (exact when they are orthogonal);
    ``rounding`` ρ is subtracted after shrinking both by ρ, which rounds the edge."""
    if rounding:
        d_a, d_b = d_a + rounding, d_b + rounding
    outside = torch.sqrt(d_a.clamp_min(0.0) ** 2 + d_b.clamp_min(0.0) ** 2)
    return outside + torch.maximum(d_a, d_b).clamp_max(0.0) - rounding


# --------------------------------------------------------------------------- revolution

def smooth_profile(ys: Sequence[float], radii: Sequence[float], samples: int = 256,
                   min_radius: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """A smooth radius profile ``r(y)`` through control points, tabulated on ``samples`` heights.

    Cubic Hermite interpolation (Catmull–Rom tangents ``m_i = (r_{i+1} − r_{i−1}) /
    (y_{i+1} − y_{i−1})``, one-sided at the ends) through ``(y_i, r_i)`` with increasing ``y_i``,
    clamped below at ``min_radius``. Returns ``(y_table, r_table)`` for :func:`profile_sdf`.
    """
    y = np.asarray(ys, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    if y.ndim != 1 or y.shape != r.shape or len(y) < 2 or np.any(np.diff(y) <= 0):
        raise ValueError("smooth_profile needs >= 2 control points with strictly increasing heights")
    m = np.empty_like(r)
    m[1:-1] = (r[2:] - r[:-2]) / (y[2:] - y[:-2])
    m[0] = (r[1] - r[0]) / (y[1] - y[0])
    m[-1] = (r[-1] - r[-2]) / (y[-1] - y[-2])
    yt = np.linspace(y[0], y[-1], samples)
    i = np.clip(np.searchsorted(y, yt, side="right") - 1, 0, len(y) - 2)
    h = y[i + 1] - y[i]
    s = (yt - y[i]) / h
    h00, h10 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s
    h01, h11 = -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
    rt = h00 * r[i] + h10 * h * m[i] + h01 * r[i + 1] + h11 * h * m[i + 1]
    return yt, np.maximum(rt, min_radius)


def profile_sdf(r: torch.Tensor, y: torch.Tensor, y_table: np.ndarray, r_table: np.ndarray,
                band: Optional[float] = None) -> torch.Tensor:
    """2D signed distance in the (radius, height) half-plane to ``{r ≤ R(y), y₀ ≤ y ≤ y₁}``.

    ``R`` is the polyline through ``(r_table[i], y_table[i])`` (uniform heights), closed by
    the caps ``y = y₀`` and ``y = y₁``. The distance is exact: the minimum over the polyline
    segments ``[a, b]`` of ``|q − a − h (b − a)|`` with
    ``h = clamp((q − a)·(b − a) / |b − a|², 0, 1)``, negative where ``y₀ ≤ y ≤ y₁`` and ``r ≤ R(y)``. Steep and even horizontal steps of the
    profile are handled (a first-order estimate ``(r − R(y)) / √(1 + R′²)`` is not: it
    collapses next to steep steps).

    ``band``: if given, only distances ``|d| ≤ band`` are computed exactly, from the segments
    whose heights lie within ``band`` of the point; farther points keep the correct sign and
    a magnitude ``≥ band`` (the first-order estimate, bounded below). This makes the cost
    proportional to the points near the surface, which is all an occupancy ramp needs.
    """
    yt = np.asarray(y_table, dtype=np.float64)
    rtn = np.asarray(r_table, dtype=np.float64)
    y0, y1 = float(yt[0]), float(yt[-1])
    k = len(yt) - 1
    dy = (y1 - y0) / k
    rt = r.new_tensor(rtn)
    ytt = r.new_tensor(yt)
    u = ((y - y0) / dy).clamp(0.0, float(k))
    i = u.floor().long().clamp_max(k - 1)
    f = u - i
    ra, rb = rt[i], rt[i + 1]
    radius = ra + f * (rb - ra)
    inside = (y >= y0) & (y <= y1) & (r <= radius)

    # the closed polyline as segments (a_r, a_y, b_r, b_y): the profile, then both caps
    segs = torch.cat([
        torch.stack([rt[:-1], ytt[:-1], rt[1:], ytt[1:]], dim=-1),
        r.new_tensor([[0.0, y0, float(rtn[0]), y0], [0.0, y1, float(rtn[-1]), y1]]),
    ])

    def seg_d2(qr, qy, sg):
        ar, ay, br, by = sg.unbind(-1)
        er, ey = br - ar, by - ay
        pr, py = qr - ar, qy - ay
        h = ((pr * er + py * ey) / (er * er + ey * ey).clamp_min(1e-20)).clamp(0.0, 1.0)
        return (pr - h * er) ** 2 + (py - h * ey) ** 2

    def exact(qr, qy, qi, m):
        """Unsigned distance to the segments [i − m, i + m] and the caps (all segments if m is None)."""
        out = torch.empty_like(qr)
        offs = None if m is None else torch.arange(-m, m + 1, device=qr.device)
        width = (k + 2) if m is None else (2 * m + 3)
        chunk = max(1, (1 << 22) // width)
        for c0 in range(0, qr.numel(), chunk):
            sl = slice(c0, c0 + chunk)
            qr_c, qy_c = qr[sl, None], qy[sl, None]
            if m is None:
                sg = segs[None]
            else:
                j = (qi[sl, None] + offs).clamp(0, k - 1)
                sg = torch.cat([segs[j], segs[k:].expand(j.shape[0], 2, 4)], dim=1)
            out[sl] = seg_d2(qr_c, qy_c, sg).min(dim=1).values
        return torch.sqrt(out)

    if band is None:
        d = exact(r.reshape(-1), y.reshape(-1), i.reshape(-1), None).view(r.shape)
        return torch.where(inside, -d, d)
    band = float(band)
    m = int(math.ceil(band / dy)) + 1
    pad = np.pad(rtn, m, mode="edge")
    win = np.lib.stride_tricks.sliding_window_view(pad, 2 * m + 1)  # win[i] covers [i - m, i + m]
    rmax = r.new_tensor(win.max(axis=1))
    rmin = r.new_tensor(win.min(axis=1))
    d_cap = torch.maximum(y0 - y, y - y1)
    far_out = (r > rmax[i] + band) | (d_cap > band)
    far_in = inside & (r < rmin[i] - band) & (d_cap < -band)
    near = ~(far_out | far_in)
    estimate = torch.maximum(((r - radius) / torch.sqrt(1.0 + ((rb - ra) / dy) ** 2)).abs(),
                             d_cap.abs()).clamp_min(band * 1.01)
    d = torch.where(inside, -estimate, estimate)
    if near.any():
        d_near = exact(r[near], y[near], i[near], m)
        d[near] = torch.where(inside[near], -d_near, d_near)
    return d


def revolve(p: torch.Tensor, sdf2d: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
            origin: Vec = (0.0, 0.0, 0.0), frame: Optional[np.ndarray] = None) -> torch.Tensor:
    """Solid of revolution about the local y axis: ``d(p) = d₂(√(x² + z²), y)`` with
    ``(x, y, z) = Rᵀ(p − o)`` and ``d₂`` a 2D SDF in the (radius, height) half-plane
    (e.g. a closure over :func:`profile_sdf`)."""
    q = to_local(p, origin, frame)
    return sdf2d(torch.sqrt(q[..., 0] ** 2 + q[..., 2] ** 2), q[..., 1])


# --------------------------------------------------------------------------- volumes

def occupancy(sdf: torch.Tensor, n: int, width_voxels: float = 1.0) -> torch.Tensor:
    """Anti-aliased occupancy in [0, 1] from a signed distance on an N³ grid.

    A smoothstep ramp ``w = width_voxels`` voxels wide centred on the surface (Δ = 2 / N):
    ``t = clamp(½ − d / (w Δ), 0, 1)``, ``o = t² (3 − 2t)``. So ``o = ½`` on the surface,
    ``1`` deeper than ``wΔ/2`` inside, exactly ``0`` farther than ``wΔ/2`` outside, and the
    transition is C¹ and about one voxel wide at every N.
    """
    t = (0.5 - sdf / (width_voxels * voxel_size(n))).clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass
class Part:
    """One coloured piece of a shape, described in a free *design frame* (+y up).

    Attributes:
        sdf: ``(..., 3)`` design-frame points → ``(...)`` signed distances (design units).
        colour: linear RGB in [0, 1], either 3 numbers or a function of the design-frame
            points ``(..., 3)`` → ``(..., 3)`` (textures, bands, spots).
        points: ``(K, 3)`` hull points, and ``pad``: the part must lie within ``pad`` of the
            convex hull of ``points``. This gives both its bounding box and its extent.
        thickness: the part's smallest full thickness (design units), used by the thickness
            floor of :func:`composite` (``inf``: never dilated).
        banded: if true, ``sdf`` takes a keyword ``band`` (design units): distances beyond
            it need only the right sign and a magnitude ≥ ``band`` (see :func:`profile_sdf`).
    """

    sdf: Callable[[torch.Tensor], torch.Tensor]
    colour: Colour
    points: np.ndarray
    pad: float = 0.0
    thickness: float = math.inf
    name: str = ""
    banded: bool = False

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)

    @property
    def lo(self) -> np.ndarray:
        return self.points.min(axis=0) - self.pad

    @property
    def hi(self) -> np.ndarray:
        return self.points.max(axis=0) + self.pad


def grid_points(n: int, d: slice = slice(None), h: slice = slice(None), w: slice = slice(None),
                dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """World voxel centres ``(x, y, z)`` of a block ``[d, h, w]`` of the N³ grid: ``(D', H', W', 3)``.

    The same points as :func:`mitsuba_platonic.volume.voxel_centres` (computed in float64,
    returned in ``dtype``), without building the whole grid.
    """
    idx = torch.arange(n, dtype=torch.float64)
    c = -1.0 + (idx + 0.5) * voxel_size(n)
    zs, ys, xs = -c[d], -c[h], c[w]
    z, y, x = torch.meshgrid(zs, ys, xs, indexing="ij")
    return torch.stack([x, y, z], dim=-1).to(dtype)


def _index_window(lo: float, hi: float, n: int, flip: bool) -> slice:
    """Voxel indices whose centres fall in [lo, hi] along one axis (flipped for y and z)."""
    delta = voxel_size(n)
    if flip:
        lo, hi = -hi, -lo
    i0 = max(0, math.floor((lo + 1.0) / delta - 0.5))
    i1 = min(n, math.ceil((hi + 1.0) / delta - 0.5) + 1)
    return slice(i0, max(i0, i1))


def composite(parts: Sequence[Part], n: int, *, width_voxels: float = 1.0,
              min_thickness_voxels: float = 1.5, fit_radius: Optional[float] = 0.82,
              centre: bool = True, colour_padding: int = 2) -> torch.Tensor:
    """Render parts into an ``(4, N, N, N)`` float32 ``[r, g, b, density]`` volume in [0, 1].

    Design frame → world: ``p = s (q − c)`` with ``c`` the centre of the union bounding box
    (if ``centre``) and ``s = fit_radius / max_k (max_i |P_ki − c| + pad_k)`` (if
    ``fit_radius``), so the shape fits in the ball of radius ``fit_radius``. A part's world
    SDF is ``s · d_k(q) − δ_k`` with the dilation ``δ_k = max(0, ½ (t_min Δ − s t_k))`` that
    brings a part of thickness ``t_k`` up to ``t_min = min_thickness_voxels`` voxels. Then
    ``o_k = occupancy(·)`` (:func:`occupancy`), ``density = 1 − Π_k (1 − o_k)`` and
    ``rgb = Σ_k o_k c_k / Σ_k o_k``. Empty voxels within ``colour_padding`` voxels of the
    surface take the colour of the surface nearby (box-filtered), the rest the mean colour.
    """
    if not parts:
        raise ValueError("composite needs at least one part")
    delta = voxel_size(n)
    lo = np.min([p.lo for p in parts], axis=0)
    hi = np.max([p.hi for p in parts], axis=0)
    c = (lo + hi) / 2.0 if centre else np.zeros(3)
    s = 1.0
    if fit_radius is not None:
        extent = max(float(np.linalg.norm(p.points - c, axis=1).max()) + p.pad for p in parts)
        s = fit_radius / max(extent, 1e-9)
    trans = torch.ones(n, n, n)
    acc = torch.zeros(3, n, n, n)
    wsum = torch.zeros(n, n, n)
    c_t = torch.tensor(c, dtype=torch.float32)
    for part in parts:
        dil = max(0.0, 0.5 * (min_thickness_voxels * delta - s * part.thickness))
        margin = dil + 0.5 * width_voxels * delta + 1e-6
        wlo = s * (part.lo - c) - margin
        whi = s * (part.hi - c) + margin
        win_w = _index_window(wlo[0], whi[0], n, flip=False)
        win_h = _index_window(wlo[1], whi[1], n, flip=True)
        win_d = _index_window(wlo[2], whi[2], n, flip=True)
        if min(sl.stop - sl.start for sl in (win_d, win_h, win_w)) <= 0:
            continue
        q = grid_points(n, win_d, win_h, win_w) / s + c_t
        if part.banded:
            d = part.sdf(q, band=1.05 * margin / s) * s - dil
        else:
            d = part.sdf(q) * s - dil
        o = occupancy(d, n, width_voxels)
        if callable(part.colour):
            col = part.colour(q).clamp(0.0, 1.0).permute(3, 0, 1, 2)
        else:
            col = torch.tensor(part.colour, dtype=torch.float32).view(3, 1, 1, 1)
        trans[win_d, win_h, win_w] *= 1.0 - o
        acc[:, win_d, win_h, win_w] += o * col
        wsum[win_d, win_h, win_w] += o
    density = 1.0 - trans
    filled = wsum > 1e-6
    rgb = acc / wsum.clamp_min(1e-6)
    if filled.any():
        mean = (acc.sum(dim=(1, 2, 3)) / wsum.sum().clamp_min(1e-6)).view(3, 1, 1, 1)
        rgb = torch.where(filled, rgb, mean)
        if colour_padding > 0:
            # normalised box filtering, only on the block around the filled voxels
            win = []
            for dim in range(3):
                idx = filled.any(dim=tuple(k for k in range(3) if k != dim)).nonzero()
                win.append(slice(max(0, int(idx[0]) - colour_padding),
                                 min(n, int(idx[-1]) + colour_padding + 1)))
            pad_acc, pad_w = acc[:, win[0], win[1], win[2]], wsum[win[0], win[1], win[2]]
            for _ in range(colour_padding):
                pad_acc = F.avg_pool3d(pad_acc[None], 3, stride=1, padding=1, count_include_pad=False)[0]
                pad_w = F.avg_pool3d(pad_w[None, None], 3, stride=1, padding=1, count_include_pad=False)[0, 0]
            block = rgb[:, win[0], win[1], win[2]]
            fill = filled[win[0], win[1], win[2]]
            padded = pad_acc / pad_w.clamp_min(1e-12)
            rgb[:, win[0], win[1], win[2]] = torch.where(fill | (pad_w <= 1e-9), block, padded)
    return torch.cat([rgb.clamp(0.0, 1.0), density[None]]).contiguous()


# --------------------------------------------------------------------------- part builders

def _corners(centre: Vec, half: Vec, frame: Optional[np.ndarray] = None) -> np.ndarray:
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    local = signs * np.asarray(half, dtype=np.float64)
    if frame is not None:
        local = local @ np.asarray(frame, dtype=np.float64).T
    return local + np.asarray(centre, dtype=np.float64)


def sphere_part(centre: Vec, radius: float, colour: Colour, name: str = "") -> Part:
    """A :func:`sphere` part."""
    return Part(lambda p: sphere(p, centre, radius), colour, np.asarray([centre]), radius,
                2.0 * radius, name)


def box_part(centre: Vec, half: Vec, colour: Colour, rounding: float = 0.0,
             frame: Optional[np.ndarray] = None, name: str = "") -> Part:
    """A (rounded, oriented) :func:`box` part."""
    return Part(lambda p: box(p, centre, half, rounding, frame), colour,
                _corners(centre, half, frame), 0.0, 2.0 * min(half), name)


def capsule_part(a: Vec, b: Vec, radius: float, colour: Colour,
                 radius_b: Optional[float] = None, name: str = "") -> Part:
    """A (tapered) :func:`capsule` part."""
    r_max = radius if radius_b is None else max(radius, radius_b)
    r_min = radius if radius_b is None else min(radius, radius_b)
    return Part(lambda p: capsule(p, a, b, radius, radius_b), colour, np.asarray([a, b]),
                r_max, 2.0 * r_min, name)


def cylinder_part(centre: Vec, radius: float, half_height: float, colour: Colour,
                  frame: Optional[np.ndarray] = None, rounding: float = 0.0, name: str = "") -> Part:
    """A :func:`cylinder` part (axis = local y of ``frame``)."""
    return Part(lambda p: cylinder(p, centre, radius, half_height, frame, rounding), colour,
                _corners(centre, (radius, half_height, radius), frame), 0.0,
                min(2.0 * radius, 2.0 * half_height), name)


def torus_part(centre: Vec, major: float, minor: float, colour: Colour,
               frame: Optional[np.ndarray] = None, name: str = "") -> Part:
    """A :func:`torus` part (ring in the local xz-plane of ``frame``)."""
    return Part(lambda p: torus(p, centre, major, minor, frame), colour,
                _corners(centre, (major + minor, minor, major + minor), frame), 0.0,
                2.0 * minor, name)


def revolve_part(y_table: np.ndarray, r_table: np.ndarray, colour: Colour,
                 origin: Vec = (0.0, 0.0, 0.0), frame: Optional[np.ndarray] = None,
                 thickness: Optional[float] = None, name: str = "") -> Part:
    """A solid of revolution of the profile ``r(y)`` (:func:`profile_sdf`) about local y.

    The hull is an octagon circumscribing each tabulated ring, so it is conservative.
    ``thickness`` (for the thickness floor) defaults to the smallest diameter over the
    middle 80 % of the profile (pointed ends are not counted).
    """
    yt, rt = np.asarray(y_table, dtype=np.float64), np.asarray(r_table, dtype=np.float64)
    step = max(1, len(yt) // 32)
    idx = np.unique(np.r_[np.arange(0, len(yt), step), len(yt) - 1])
    ang = np.arange(8) * (math.pi / 4)
    ring = np.stack([np.cos(ang), np.zeros(8), np.sin(ang)], axis=1) / math.cos(math.pi / 8)
    # between two kept samples the radius may exceed both: pad by the largest such excess
    excess = 0.0
    for a, b in zip(idx[:-1], idx[1:]):
        excess = max(excess, float(rt[a:b + 1].max() - max(rt[a], rt[b])))
    pts = (ring[None] * rt[idx, None, None] + np.stack(
        [np.zeros_like(idx), yt[idx], np.zeros_like(idx)], axis=1)[:, None, :].astype(np.float64)).reshape(-1, 3)
    if frame is not None:
        pts = pts @ np.asarray(frame, dtype=np.float64).T
    pts = pts + np.asarray(origin, dtype=np.float64)

    def sdf(p: torch.Tensor, band: Optional[float] = None) -> torch.Tensor:
        return revolve(p, lambda r, y: profile_sdf(r, y, yt, rt, band), origin, frame)

    if thickness is None:
        k = len(rt)
        thickness = float(2.0 * rt[k // 10: k - k // 10].min())
    thick = min(float(thickness), float(yt[-1] - yt[0]))
    return Part(sdf, colour, pts, excess / math.cos(math.pi / 8), thick, name, banded=True)
