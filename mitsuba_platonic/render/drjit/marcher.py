"""The batched Dr.Jit ray marcher: every (volume, view) pair of a call in one kernel launch.

All B·H·W·spp rays of a call march in one wide Dr.Jit launch (Mitsuba's ``llvm_ad_rgb``
variant on a CPU, ``cuda_ad_rgb`` on a GPU); the backward pass is one more launch. The B
volumes are one flat array, channels last (``(B, N, N, N, C)``: a voxel's RGBA is one 16-byte
packet, read by one packet gather and written by one packet scatter), shared with torch without a
copy; each ray reads its own pair's voxels by index: lane r belongs to pair b = r // (H·W·spp),
whose voxels start at voxel b·N³. Zero padding is exact, because a lookup outside the cube
simply reads nothing.

Rays (docs/conventions.md, "Views" and "Images"). Pixel (row i, column j) of pair b, sub-sample
(o_x, o_y) ∈ [0, 1)², depth z:

    p = S(z) (x · right_b + y · up_b) + z · ω_b,   x = −1 + (j + o_x) Δ,   y = 1 − (i + o_y) Δ

with (right_b, up_b, ω_b) from :func:`mitsuba_platonic.views.camera_frames`, and S ≡ 1 for the
orthographic camera; the perspective camera has S(z) = (D − z) tan(F/2) and lengthens every
segment's path by ℓ = √(1 + tan²(F/2)(x² + y²)) (:mod:`mitsuba_platonic.views`, "Projection").
Without jitter the sub-samples form a regular √spp × √spp grid, (o_x, o_y) = ((m + ½)/√spp,
(n + ½)/√spp); with jitter they are uniform. At spp = 1 they are pixel centres, so at the
orthographic front view p lands on voxel centres exactly (N a power of two): the lookups
reproduce the closed form's to the last bit.

Window (:class:`~.window.Window`: zoom m, centre (c_x, c_y); orthographic only). The pair's frame
becomes (h right_b, h up_b, ω_b) with h = 1/m, and an origin o_b = c_x right_b + c_y up_b joins it:

    p = x (h right_b) + y (h up_b) + o_b + z ω_b

12 floats per pair instead of 9, read by the same kernels (only whether there is a window is part
of a recording's key: a new zoom or pan replays it). Without a window (or with the full one) the
kernels are those above, bit for bit.

Segments. With Δ = 2/N and ``step`` h voxels, segment k covers camera depth [k h, min((k + 1) h, N)]
voxels from the front face z = 1; its length is s_k = min(h, N − k h) voxels and its sample sits at
fraction u of it (u = ½, or one u ~ U[0, 1) per ray with ``jitter``; the jitter's numbers are a
TEA hash of the ray's number, the call's seed and the dimension, so both passes draw the same):

    z_k = 1 − (k h + u s_k) Δ

Lookups. q = (p + 1) N/2 − ½ per axis (w along x, h along −y, d along −z) is the continuous
voxel index; ``nearest`` reads voxel round(q) and ``trilinear`` blends the 8 voxels around q with
weights Π_axes (1 − |q − corner|). A voxel outside [0, N)³ contributes 0 — the closed form's
``grid_sample`` zero padding.

Image formation (per ray), with the density v and colour c at each sample:

    VH:      T = exp(−Σ_k s_k v_k)                          ρ = 1 − T
    AO:      τ_k = (1 − v_k)^{s_k}, T = Π_k τ_k             ρ = 1 − T
    EA:      C = Σ_k T_k (1 − τ_k) c_k,  T_k = Π_{j<k} τ_j,  α = 1 − Π_k τ_k

with s_k the segment's path length in voxels (ℓ times its depth for the perspective camera). At
``step`` 1 with the orthographic camera, τ_k = 1 − v_k exactly (no log: exact and
differentiable at v = 1). Otherwise τ_k = exp(s_k log(1 − min(v_k, V_MAX))): the density is
clamped to 1 − 1e-6 so the log stays finite (its gradient is 0 above the clamp). The pixel is
the mean of its spp rays.

Empty space. A forward-only call (no gradient recorded) marches each ray only through the
segments that can see density: the box around its pair's occupied voxels (v > 0), widened by
1½ voxels (a trilinear lookup reads the voxels within one voxel of its point). Along the ray
p(z) = A + z B is linear in the depth coordinate z (A = x right + y up (+ o_b in a window), B = ω for the
orthographic camera; A = D t (x right + y up), B = ω − t (x right + y up) for the perspective
one), so the box is the z interval [z₀, z₁] where every axis of p lies inside it, and the ray
marches segments ⌊d(z₁)/h⌋ − 1 to ⌈d(z₀)/h⌉ + 1 (d(z) = (1 − z)/Δ voxels from the front face),
skipping segments whose lookups read only zeros. A skipped segment has τ = 1 and adds no
colour, so the image is the same to the last bit (:func:`occupied_boxes`; a test checks the
equality). A pass for the gradient marches every segment: an empty voxel's density still has
a gradient.

Early termination. With ``termination`` ε > 0 a ray stops once T ≤ ε, in the forward and the
backward pass: an approximation (image error ≤ ε, gradient error measured by ``platonic bench``).
With ε = 0 (the default) the image stops only where T = 0 exactly, which changes nothing, and a
pass that records for the gradient marches the whole ray, because the gradient at an opaque
sample depends on what lies behind it.

Adjoint (one launch, no division by τ, exact at τ = 0). The forward pass of a differentiable call
records T_k for every ray r and segment k (4 bytes each), and beside it the segment's lookup
(v, or EA's RGBA as one 16-byte packet at the same position), so the backward pass reads each
lookup back instead of making its 8 scattered gathers again (:data:`RECORD_LOOKUPS`; 5 floats
per ray and segment for EA, within :data:`RECORD_LIMIT`). Ray r's records sit at k · rays + l(r),
where l(r) is the lane that marches r backwards (:func:`tiled_lane` for the tiled backward
below, else r): the backward's packets, which march rays far apart, read neighbouring floats,
and the forward's writes are the strided ones (64³ EA, batch 8: records in ray order cost the
backward 0.5 ms per image more than they save the forward). The backward pass marches each ray back to
front, accumulating the suffix radiance R_k = Σ_{m>k} (Π_{k<j<m} τ_j)(1 − τ_m) c_m and the suffix
transmittance U_k = Π_{j>k} τ_j:

    ∂C/∂τ_k = T_k (R_k − c_k),   ∂C/∂c_k = T_k (1 − τ_k),   ∂α/∂τ_k = ∂ρ/∂τ_k = −T_k U_k

then ∂L/∂v_k = ∂L/∂τ_k · dτ_k/dv_k, with dτ/dv = −1 (step 1) or −s (1 − v)^{s − 1} (other steps,
0 above the clamp), and scatters ∂L/∂v_k and ∂L/∂c_k into the voxels the lookup read, with the
lookup's weights. VH needs no record: ρ = 1 − exp(−Σ s_k v_k) gives ∂ρ/∂v_k = s_k T with the
ray's final T, so its backward pass is one front-to-back march that scatters s_k T δρ.

Scatter-adds without atomics. On the LLVM backend, Dr.Jit's ``NoConflicts`` scatter-add first
sums the lanes of a SIMD packet that add into the same voxel and then adds each sum with a plain
load-add-store: exact, as long as no two *threads* add into the same voxel at once. Where the
rays of one pair make a power-of-two number of lanes (N²·spp), the backward pass therefore

- cuts its launch into one block of lanes per pair, so that a thread owns the volume it adds
  into (Dr.Jit keeps a requested block size only for launches of more than 2 blocks per thread:
  a small batch is padded with idle lanes, :func:`_tiled_pairs`);
- orders each pair's lanes in tiles (:func:`tiled_ray`): the image is cut into 4 × 4 tiles of N/4
  pixels and a packet's 16 lanes march the same pixel of the 16 tiles. Exactness does not need
  this; speed does: rays N/4 pixels apart add into different cache lines, where neighbouring rays
  would load and store the same lines one after the other (the 64³ EA backward kernel, batch 8,
  measured about 25 % faster tiled than in row order).

A one-float ``NoConflicts`` scatter-add costs a horizontal reduction of the packet per lane (to
catch lanes that share a voxel), while a packet of several floats is added with one plain
load-add-store per lane. VH and AO (one channel, trilinear) therefore scatter into the *pair
layout* (:meth:`_Batch.splat`): a trilinear lookup's 8 corners become 4 scatters of the two
voxels w₀, w₀ + 1 that a row shares, into slots that :func:`_torch_layout` adds back into
voxels — the same sums (64³ VH/AO backward kernel, batch 8: 28 ms → 11 ms). EA's RGBA packets
already add per lane.

EA's gradient leaves as it was scattered, channels last: torch wraps Dr.Jit's array without a
copy as a ``(B, 4, N, N, N)`` tensor with channels-last strides, the layout the generator computes
in (:class:`~mitsuba_platonic.networks.nets.Generator`); a gather launch into torch's default layout
cost 0.9 ms per image at 64³ (batch 8), a third of the backward pass. The pair layout's gradient
(VH, AO) is summed back into voxels by a second launch (:func:`_torch_layout`) into an array of
Dr.Jit's allocation cache, which torch also wraps without a copy.

Otherwise (other N or spp, or the CUDA backend) it uses ``Expand`` on the LLVM backend (each
thread adds into its own copy of the gradient, summed at the end: exact, but the copies cost two
fills and a reduction of B·N³·C floats per call) and ``Auto`` (atomics) on CUDA.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace
from typing import Any, Dict, Optional, Tuple

import torch

from ..settings import RenderSettings, check_lanes
from ..variant import ensure_variant, variant_device
from ..window import Window, check_orthographic, window_or_none
from .launch import (FRAME_FLOATS, FREEZE, PACKET, REDUCE_MODE, image_to_per_ray, pair_frames, per_ray_to_image,
                     set_block_size, shared_float, spread_over_threads)

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

__all__ = ["march", "march_pixels", "n_segments", "recorded_floats", "segment_transmittance", "tiled_ray", "tiled_lane", "tiled_backward", "V_MAX", "RECORD_LIMIT"]

#: Density clamp used by AO/EA when step != 1 (log domain).
V_MAX = 1.0 - 1e-6

#: Most floats a differentiable call may record (:func:`recorded_floats` per ray and segment): 2 GiB.
RECORD_LIMIT = 2 ** 29


def n_segments(n: int, step: float) -> int:
    """Segments per ray: ⌈N / step⌉ (the last one may be shorter)."""
    return max(1, math.ceil(n / step - 1e-9))


def recorded_floats(model: str, c: int) -> int:
    """Floats a pass for the gradient records per ray and segment: T_k, and with
    :data:`RECORD_LOOKUPS` the lookup beside it (C floats); VH records nothing per segment."""
    if model == "vh":
        return 0
    return 1 + (c if RECORD_LOOKUPS else 0)


def segment_transmittance(model: str, unit: bool, v: Any, s: Any) -> Tuple[Any, Any]:
    """τ of a segment of s voxels at density v, and dτ/dv (module docstring, "Image formation").

    VH: τ = exp(−s v). AO/EA with ``unit`` (every segment exactly one voxel long: step 1,
    orthographic camera): τ = 1 − v, exact at v = 1. Otherwise the log domain with v clamped to
    :data:`V_MAX` (dτ/dv = 0 above the clamp).
    """
    if model == "vh":
        τ = dr.exp(-s * v)
        return τ, -s * τ
    if unit:
        return 1.0 - v, mi.Float(-1.0)
    log1m = dr.log(1.0 - dr.minimum(v, V_MAX))
    return dr.exp(s * log1m), dr.select(v >= V_MAX, 0.0, -s * dr.exp((s - 1.0) * log1m))


# -- The marcher ---------------------------------------------------------------------------


class _Batch:
    """One call's rays, lookups and marches (built per call; all arrays are Dr.Jit arrays).

    ``data``: the flat volume batch ``(B, N, N, N, C)``; ``frames``: 9 floats per pair
    (right, up, ω), or with ``windowed`` 12 (h right, h up, ω, o: module docstring, "Window");
    ``opt``: the settings (model, filter, step, spp, jitter, termination);
    ``seed``: a UInt32 array of width 1 seeding the jitter's random numbers; ``tiled``: lanes in
    the tiled order of the atomic-free backward (:func:`tiled_ray`), else lane r is ray r.
    """

    def __init__(self, data: Any, frames: Any, b: int, c: int, n: int, opt: RenderSettings, seed: int,
                 tiled: bool = False, records_tiled: bool = False, windowed: bool = False):
        self.data, self.frames, self.B, self.C, self.N, self.opt = data, frames, b, c, n, opt
        self.windowed = windowed
        self.tiled = tiled
        #: the forward pass writes its records in the tiled backward's lane order (:meth:`forward`)
        self.records_tiled = records_tiled
        # tiled: whole pairs of idle lanes pad the launch to > 2 blocks per thread (:func:`_tiled_pairs`)
        self.n_lanes = _tiled_pairs(b) * n * n * opt.spp if tiled else b * n * n * opt.spp
        # tiled: no two threads add into the same volume (module docstring)
        self.mode = dr.ReduceMode.NoConflicts if tiled else REDUCE_MODE
        #: the backward's gradient in the pair layout (:meth:`splat`): single-channel trilinear, tiled
        self.pairs = pair_layout(tiled, c, opt)
        self.model, self.seed = opt.model, seed
        self.Δ = 2.0 / n
        self.t, self.D = opt.lens                                 # the camera: tan(F/2), distance
        self.unit = opt.step == 1.0 and self.t == 0.0             # every segment one voxel long
        self.n_steps = n_segments(n, opt.step)
        self.n_rays = b * n * n * opt.spp
        self.ε = float(opt.termination)
        self._rays()

    # -- Rays ------------------------------------------------------------------------------

    def _rays(self) -> None:
        """Per lane: its pair's offset into ``data``, the image-plane point (x, y) and depth fraction u."""
        N, spp, opt = self.N, self.opt.spp, self.opt
        lane = dr.arange(mi.UInt32, self.n_lanes)
        r = tiled_ray(lane, N, spp) if self.tiled else lane
        self.ray = r                                              # which ray this lane marches
        self.real = r < self.n_rays                               # False: an idle lane of the padding
        pixel = r // spp                                          # which pixel of the batch
        sub = r - pixel * spp                                     # which ray of that pixel
        b = pixel // (N * N)
        ij = pixel - b * (N * N)
        i, j = ij // N, ij % N
        if opt.jitter:
            # a hash of (ray, seed, dimension): the same numbers whichever lane marches the ray
            ox, oy, u = (mi.sample_tea_float32(r, self.seed * 3 + d, 6) for d in range(3))
        else:
            m = math.isqrt(spp)
            ox = (mi.Float(sub % m) + 0.5) / m
            oy = (mi.Float(sub // m) + 0.5) / m
            u = mi.Float(0.5)
        self.x = -1.0 + (mi.Float(j) + ox) * self.Δ
        self.y = 1.0 - (mi.Float(i) + oy) * self.Δ
        self.u = u
        # perspective: the path through a slab of unit depth, ℓ = √(1 + t²(x² + y²))
        self.ℓ = dr.sqrt(1.0 + self.t * self.t * (self.x * self.x + self.y * self.y)) if self.t else None
        self.pair = b                                             # which (volume, view) pair
        self.base = b * (N * N * N)                               # first voxel of this lane's volume
        stride = FRAME_FLOATS[self.windowed]
        f = [dr.gather(mi.Float, self.frames, b * stride + k, self.real) for k in range(stride)]
        self.right, self.up, self.ω = mi.Vector3f(*f[0:3]), mi.Vector3f(*f[3:6]), mi.Vector3f(*f[6:9])
        self.origin = mi.Vector3f(*f[9:12]) if self.windowed else None   # o_b: the window's centre

    def lateral(self) -> Any:
        """The ray's point on the plane z = 0: x right + y up, plus the window's origin o_b."""
        lateral = self.x * self.right + self.y * self.up
        return lateral if self.origin is None else lateral + self.origin

    def segment(self, k: Any) -> Tuple[Any, Any]:
        """Sample point p of segment k and the length of the ray's path through it, in voxels
        (its depth s_k, times ℓ for the perspective camera)."""
        h, N = self.opt.step, self.N
        kf = mi.Float(k)
        s = dr.minimum(h, N - kf * h)                             # the last segment may be short
        z = 1.0 - (kf * h + self.u * s) * self.Δ
        lateral = self.lateral()
        if self.ℓ is None:
            return lateral + z * self.ω, s
        return (self.D - z) * self.t * lateral + z * self.ω, s * self.ℓ   # S(z) = (D − z) t

    # -- Lookups ---------------------------------------------------------------------------

    def _q(self, p: Any) -> Any:
        """The continuous voxel index q = (p + 1) N/2 − ½ of p (w along +x, h along −y, d along −z)."""
        half = self.N / 2.0
        return mi.Vector3f((p.x + 1.0) * half - 0.5, (1.0 - p.y) * half - 0.5, (1.0 - p.z) * half - 0.5)

    def _cell(self, p: Any) -> Tuple[Any, Any]:
        """The trilinear cell of p: its lowest corner i₀ = ⌊q⌋ and the fractions t = q − i₀."""
        q = self._q(p)
        i0 = mi.Vector3i(dr.floor(q))
        return i0, q - mi.Vector3f(i0)

    def corners(self, p: Any):
        """[(voxel index, weight, inside)] of the lookup at p: 1 voxel (nearest) or 8 (trilinear)."""
        N = self.N
        if self.opt.filter == "nearest":
            i = mi.Vector3i(dr.floor(self._q(p) + 0.5))
            inside = dr.all((i >= 0) & (i < N))
            return [(self._index(i), mi.Float(1.0), inside)]
        i0, t = self._cell(p)
        # per axis, the two neighbours' offsets, weights and in-range masks; a corner combines one of each
        x = [(i0.x, 1.0 - t.x, (i0.x >= 0) & (i0.x < N)), (i0.x + 1, t.x, (i0.x >= -1) & (i0.x < N - 1))]
        y = [(i0.y * N, 1.0 - t.y, (i0.y >= 0) & (i0.y < N)), ((i0.y + 1) * N, t.y, (i0.y >= -1) & (i0.y < N - 1))]
        z = [(i0.z * (N * N), 1.0 - t.z, (i0.z >= 0) & (i0.z < N)),
             ((i0.z + 1) * (N * N), t.z, (i0.z >= -1) & (i0.z < N - 1))]
        out = []
        for oz, wz, mz in z:
            for oy, wy, my in y:
                oyz, wyz, myz = self.base + mi.UInt32(oz + oy), wy * wz, my & mz
                for ox, wx, mx in x:
                    out.append((oyz + mi.UInt32(ox), wx * wyz, mx & myz))
        return out

    def splat(self, grad: Any, p: Any, corners: list, g: Any) -> None:
        """Scatter-add ∂L/∂(lookup at p) = g into ``grad`` with the lookup's weights.

        In the pair layout (:attr:`pairs`) a trilinear lookup's 8 corners are 4 scatters of
        2-float packets: slot (d, h, w₀ + 1) of a row of N + 1 slots holds [∂ of voxel w₀,
        ∂ of voxel w₀ + 1] (w₀ = ⌊q_w⌋ ∈ [−1, N − 1]; a voxel outside the row gets weight 0), and
        :func:`_torch_layout` sums the two halves. Dr.Jit's LLVM backend adds a packet with one
        load-add-store per lane, where a one-float ``NoConflicts`` scatter-add reduces the whole
        packet once per lane to catch lanes that share a voxel: the same sums, 2.7× faster at 64³.
        """
        if not self.pairs:
            for idx, w, inside in corners:
                dr.scatter_reduce(dr.ReduceOp.Add, grad, w * g, idx, inside, mode=self.mode)
            return
        N = self.N
        i0, t = self._cell(p)
        in_row = (i0.x >= -1) & (i0.x < N)
        g0 = dr.select(i0.x >= 0, 1.0 - t.x, 0.0) * g             # voxel w₀ (none at w₀ = −1)
        g1 = dr.select(i0.x < N - 1, t.x, 0.0) * g                # voxel w₀ + 1 (none at w₀ = N − 1)
        row0 = self.pair * (N * N * (N + 1)) + mi.UInt32(i0.x + 1)   # slot (b, d = 0, h = 0, w₀ + 1) …
        for dz, wz in ((0, 1.0 - t.z), (1, t.z)):
            for dy, wy in ((0, 1.0 - t.y), (1, t.y)):
                d, h = i0.z + dz, i0.y + dy
                inside = in_row & (d >= 0) & (d < N) & (h >= 0) & (h < N)
                slot = row0 + mi.UInt32((d * N + h) * (N + 1))    # … + (d N + h) rows of N + 1 slots
                w = wy * wz
                dr.scatter_reduce(dr.ReduceOp.Add, grad, mi.Vector2f(w * g0, w * g1), slot, inside,
                                  mode=self.mode)

    def _index(self, i: Any) -> Any:
        """Voxel number of voxel (w, h, d) = i of this lane's volume (its channels follow each other)."""
        N = self.N
        return self.base + mi.UInt32((i.z * N + i.y) * N + i.x)

    def lookup(self, corners) -> Tuple[Any, Any]:
        """Density v (the last channel) and, for EA, the colour c at a lookup (None otherwise)."""
        if self.C == 1:
            v = mi.Float(0.0)
            for idx, w, inside in corners:
                v += w * dr.gather(mi.Float, self.data, idx, inside)
            return v, None
        rgba = mi.Vector4f(0.0)
        for idx, w, inside in corners:
            rgba += w * dr.gather(mi.Vector4f, self.data, idx, inside)   # one packet: r, g, b, v
        return rgba.w, mi.Color3f(rgba.x, rgba.y, rgba.z)

    def keep_lookup(self, looks: Any, at: Any, v: Any, c: Optional[Any]) -> None:
        """Store a lookup for the backward pass: RGBA as one 4-float packet at ``at`` (EA), or v."""
        if c is None:
            dr.scatter(looks, v, at)
        else:
            dr.scatter(looks, mi.Vector4f(c.x, c.y, c.z, v), at)

    def recorded_lookup(self, looks: Any, at: Any) -> Tuple[Any, Any]:
        """The lookup :meth:`keep_lookup` stored at ``at``: (v, c) as :meth:`lookup` returns them."""
        if self.C == 1:
            return dr.gather(mi.Float, looks, at, self.real), None
        rgba = dr.gather(mi.Vector4f, looks, at, self.real)
        return rgba.w, mi.Color3f(rgba.x, rgba.y, rgba.z)

    def transmittance(self, v: Any, s: Any) -> Tuple[Any, Any]:
        """τ of a segment of s voxels at density v, and dτ/dv."""
        return segment_transmittance(self.model, self.unit, v, s)

    # -- Forward ---------------------------------------------------------------------------

    @dr.syntax
    def forward(self, record: Optional[Any], whole: bool = False, boxes: Optional[Any] = None,
                looks: Optional[Any] = None) -> Tuple[Any, Any, Any]:
        """Front-to-back march → (final transmittance T, emitted colour C, segments marched); with
        ``record`` (a Float of n_rays · n_steps) store T_k before each segment for the backward pass,
        and with ``looks`` (C times as long) each segment's lookup (RGBA or v) beside it;
        with ``whole`` (a pass for the gradient) never stop at T = 0; with ``boxes`` (6 floats per
        pair, :func:`occupied_boxes`) march only the segments that meet the pair's box."""
        ea = self.model == "ea"
        n_steps, ε = self.n_steps, self.ε
        whole = whole and ε == 0.0                                # the gradient needs every segment
        ray = dr.arange(mi.UInt32, self.n_rays)
        # T_k of ray r is record[k · n_rays + slot(r)], slot(r) = the lane that marches r backwards:
        # a backward packet then reads 16 neighbouring records (module docstring, "Adjoint")
        slot = tiled_lane(ray, self.N, self.opt.spp) if self.records_tiled else ray
        k, k_end = (mi.UInt32(0), mi.UInt32(n_steps)) if boxes is None else self.box_segments(boxes)
        T = mi.Float(1.0)
        depth = mi.Float(0.0)                                     # VH: optical depth Σ s v
        C = mi.Color3f(0.0)
        active = k < k_end
        while active:
            if record is not None:
                dr.scatter(record, T, k * self.n_rays + slot)
            p, s = self.segment(k)
            v, c = self.lookup(self.corners(p))
            if looks is not None:                                 # the backward's lookup, read back in order
                self.keep_lookup(looks, k * self.n_rays + slot, v, c)
            if self.model == "vh":
                depth += s * v
                T = dr.exp(-depth)                                # exactly the closed form's exp(−Σ v)
            else:
                τ, _ = self.transmittance(v, s)
                if ea:
                    C += T * (1.0 - τ) * c
                T *= τ
            k += 1
            # with ε = 0 a forward-only pass stops where T = 0: nothing behind is visible
            active &= (k < k_end) & (whole | (T > ε))
        return T, C, k

    def box_segments(self, boxes: Any) -> Tuple[Any, Any]:
        """[first, end) of the segments whose lookups can read density: those that meet the lane's
        pair's box (module docstring, "Empty space"); an empty range for a ray that misses it."""
        lo = mi.Vector3f(*(dr.gather(mi.Float, boxes, self.pair * 6 + a, self.real) for a in range(3)))
        hi = mi.Vector3f(*(dr.gather(mi.Float, boxes, self.pair * 6 + 3 + a, self.real) for a in range(3)))
        lateral = self.lateral()
        if self.ℓ is None:
            A, B = lateral, self.ω                                # p(z) = A + z B
        else:
            A, B = self.D * self.t * lateral, self.ω - self.t * lateral
        z0, z1 = mi.Float(-1.0), mi.Float(1.0)                    # the cube's depth range
        for a in range(3):
            flat = dr.abs(B[a]) < 1e-12                           # p_a does not change along the ray
            ta, tb = (lo[a] - A[a]) / B[a], (hi[a] - A[a]) / B[a]
            inside = (A[a] >= lo[a]) & (A[a] <= hi[a])
            z0 = dr.select(flat, dr.select(inside, z0, 2.0), dr.maximum(z0, dr.minimum(ta, tb)))
            z1 = dr.select(flat, dr.select(inside, z1, -2.0), dr.minimum(z1, dr.maximum(ta, tb)))
        h, Δ = self.opt.step, self.Δ
        first = dr.maximum(dr.floor((1.0 - z1) / (Δ * h)) - 1.0, 0.0)
        end = dr.minimum(dr.ceil((1.0 - z0) / (Δ * h)) + 1.0, float(self.n_steps))
        hit = z0 <= z1
        return mi.UInt32(dr.select(hit, first, 0.0)), mi.UInt32(dr.select(hit, end, 0.0))

    # -- Backward --------------------------------------------------------------------------

    @dr.syntax
    def backward(self, record: Any, marched: Any, grad: Any, δρ: Any, δC: Any, looks: Optional[Any] = None) -> None:
        """Back-to-front march from each ray's last marched segment, scattering ∂L/∂v (and ∂L/∂c)
        into ``grad`` (same layout as ``data``). δρ: ∂L/∂ρ or ∂L/∂α per ray; δC: ∂L/∂C (EA);
        ``looks``: the forward's lookups (:meth:`keep_lookup`), else the lookups are made again."""
        ea = self.model == "ea"
        # this lane's records: lane l of a tiled pass (the forward wrote them there), else ray r = l
        slot = dr.arange(mi.UInt32, self.n_lanes)

        # Back to front from where the forward march stopped (only a positive ε stops it early),
        # with the suffix radiance R and the suffix transmittance U
        k = mi.UInt32(marched)
        R = mi.Color3f(0.0)
        U = mi.Float(1.0)
        active = k > 0
        while active:
            k -= 1
            at = k * self.n_rays + slot                           # (segment k, this lane's ray) in the records
            T_k = dr.gather(mi.Float, record, at, self.real)
            p, s = self.segment(k)
            corners = self.corners(p)
            v, c = self.lookup(corners) if looks is None else self.recorded_lookup(looks, at)
            τ, dτ = self.transmittance(v, s)
            gτ = -δρ * T_k * U                                    # ∂α/∂τ = −T U
            if ea:
                gτ += dr.sum(δC * T_k * (R - c))                  # ∂C/∂τ = T (R − c)
            gv = gτ * dτ
            gc = δC * T_k * (1.0 - τ) if ea else None             # ∂C/∂c = T (1 − τ)
            g = mi.Vector4f(gc.x, gc.y, gc.z, gv) if ea else gv   # EA: one packet per voxel
            self.splat(grad, p, corners, g)
            if ea:
                R = (1.0 - τ) * c + τ * R
            U *= τ
            active &= k > 0


    @dr.syntax
    def backward_vh(self, T: Any, marched: Any, grad: Any, δρ: Any) -> None:
        """VH: ρ = 1 − exp(−Σ_k s_k v_k), so ∂ρ/∂v_k = s_k T with T the ray's final transmittance:
        one front-to-back pass, nothing recorded, no suffix products."""
        g = δρ * T
        k = mi.UInt32(0)
        active = k < marched
        while active:
            p, s = self.segment(k)
            self.splat(grad, p, [] if self.pairs else self.corners(p), s * g)
            k += 1
            active &= k < marched


def pair_layout(tiled: bool, c: int, opt: RenderSettings) -> bool:
    """Whether a backward pass scatters into the pair layout (:meth:`_Batch.splat`): a tiled
    (atomic-free) pass of a single-channel (VH, AO) trilinear render. EA's RGBA packets already
    add with one load-add-store per lane."""
    return tiled and c == 1 and opt.filter == "trilinear"


def _torch_layout(grad: Any, b: int, n: int) -> Any:
    """The backward's single-channel gradient in the pair layout ``(B, N, N, N + 1, 2)``
    (:meth:`_Batch.splat`) → a new Float in torch's layout ``(B, 1, N, N, N)`` (one gather launch):
    ∂ of voxel w = slot w + 1's first half + slot w's second half."""
    i = dr.arange(mi.UInt32, b * n ** 3)                      # element i of the (B, 1, N, N, N) result
    row, w = i // n, i % n                                    # row (b, d, h) of N voxels, voxel w in it
    slot = row * (2 * (n + 1)) + 2 * w                        # slot w of the row (N + 1 slots of 2 floats)
    return dr.gather(mi.Float, grad, slot + 2) + dr.gather(mi.Float, grad, slot + 1)


def tiled_ray(lane: Any, n: int, spp: int) -> Any:
    """The ray that ``lane`` (a UInt32 array) marches in the tiled order: the image is cut into 4 × 4
    tiles of N/4 pixels (N a multiple of 4), and the 16 lanes of an aligned packet march the same
    pixel and sub-sample of the 16 tiles of one pair, ≥ N/4 pixels apart (module docstring).
    Ray r = (pair · N² + row · N + column) · spp + sub-sample, as in the canonical order."""
    P, t = n * n * spp, n // 4                                    # rays per pair, tile size
    b = lane // P
    local = lane - b * P
    tile, m = local % 16, local // 16                             # slot in the packet, packet number
    ii, jj, sub = (m // t) % t, m % t, m // (t * t)               # position in the tile, sub-sample
    i, j = (tile // 4) * t + ii, (tile % 4) * t + jj
    return b * P + (i * n + j) * spp + sub


def tiled_lane(ray: Any, n: int, spp: int) -> Any:
    """The lane of the tiled order that marches ``ray`` (a UInt32 array): the inverse of
    :func:`tiled_ray`."""
    P, t = n * n * spp, n // 4
    b = ray // P
    pixel = (ray - b * P) // spp
    sub = ray - b * P - pixel * spp
    i, j = pixel // n, pixel % n
    tile = (i // t) * 4 + j // t                                  # which tile, so which lane of a packet
    m = (sub * t + i % t) * t + j % t                             # which packet: sub-sample, row, column in the tile
    return b * P + m * 16 + tile


def _tiled_pairs(b: int) -> int:
    """Pairs of lanes in a tiled launch: B, padded with idle pairs to more than 2 × (threads + 1).

    Dr.Jit 1.5's LLVM launcher uses the requested block size only for a launch of more than
    2 × threads blocks; a smaller launch is cut into one block per thread, which could split a
    pair between two threads. (+ 1: whether the pool counts the calling thread.)
    """
    return max(b, 2 * (dr.thread_count() + 1) + 1)


def tiled_backward(n: int, spp: int) -> bool:
    """Whether the backward pass of a call can scatter without atomics or per-thread copies.

    Module docstring, "Scatter-adds without atomics": on the LLVM backend, where a pair's N²·spp
    rays make a power-of-two block of at least one packet and N is a multiple of 4 (the tiles).
    """
    rays = n * n * spp
    return (TILED and set_block_size is not None and PACKET > 0 and n % 4 == 0
            and rays & (rays - 1) == 0 and rays >= PACKET)


#: Use the tiled, atomic-free backward where :func:`tiled_backward` allows it
#: (``MITSUBA_PLATONIC_TILED=0``: always the ``Expand`` scatters).
TILED = os.environ.get("MITSUBA_PLATONIC_TILED", "1") != "0"


#: A pass for the gradient records each segment's lookup beside T_k, and the backward pass reads
#: it back in order instead of making the 8 gathers again (module docstring, "Adjoint")
#: (``MITSUBA_PLATONIC_RECORD_LOOKUPS=0``: the backward looks up again, for comparisons).
RECORD_LOOKUPS = os.environ.get("MITSUBA_PLATONIC_RECORD_LOOKUPS", "1") != "0"


#: Forward-only calls skip empty space (module docstring, "Empty space"; exact)
#: (``MITSUBA_PLATONIC_SKIP_EMPTY=0``: march every segment, for comparisons).
SKIP_EMPTY = os.environ.get("MITSUBA_PLATONIC_SKIP_EMPTY", "1") != "0"


class _Static:
    """The Python values a pass depends on, as one hashable non-array argument: ``dr.freeze``
    re-records when its hash changes (a new batch size, resolution, setting or thread count) and
    replays otherwise."""

    def __init__(self, shape: Tuple[int, int, int], opt: RenderSettings, record: bool, tiled: bool = False,
                 windowed: bool = False):
        # tiled: the backward's lanes in the tiled order; the forward's records in that order;
        # windowed: 12 floats per pair's frame (a window's values are data, not part of the key)
        self.shape, self.opt, self.record, self.tiled, self.windowed = shape, opt, record, tiled, windowed
        # Dr.Jit's thread count too: the backward's Expand scatters size their per-thread copies of
        # the gradient when a kernel is recorded, so a replay under more threads would overrun them
        self.key = (shape, opt, record, tiled, dr.thread_count(), RECORD_LOOKUPS, windowed)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Static) and self.key == other.key


def _forward_pass(data: Any, frames: Any, seed: Any, boxes: Optional[Any], static: _Static) -> Tuple[list, Any, Any]:
    """The forward launch: per-ray outputs ([r, g, b, α] or [ρ]), the recorded T_k (or None) and
    the segments each ray marched; ``boxes`` (forward-only calls): skip empty space. Depends only
    on its Dr.Jit arrays (volume, camera frames, seed, boxes) and ``static``, so ``dr.freeze`` can
    replay its kernel without re-tracing (see :data:`FREEZE`)."""
    (b, c, n), opt, record = static.shape, static.opt, static.record
    batch = _Batch(data, frames, b, c, n, opt, seed, records_tiled=static.tiled, windowed=static.windowed)
    vh = opt.model == "vh"
    # every T_k (and lookup) the backward reads (k < segments marched) is written first: no clearing
    Ts = dr.empty(mi.Float, batch.n_rays * batch.n_steps) if record and not vh else None
    looks = dr.empty(mi.Float, c * batch.n_rays * batch.n_steps) if Ts is not None and RECORD_LOOKUPS else None
    T, C, marched = batch.forward(Ts, whole=record, boxes=boxes, looks=looks)
    values = [C.x, C.y, C.z, 1.0 - T] if opt.model == "ea" else [1.0 - T]
    if record and vh:
        Ts = T                                                # VH's gradient needs only the final T
    dr.eval(values, Ts, looks, marched)                       # the one forward launch
    return values, (Ts, looks), marched


def _backward_pass(data: Any, frames: Any, seed: Any, Ts: Any, marched: Any, δ: list, static: _Static) -> Any:
    """The backward launch: ∂L/∂volume from the per-ray gradients δ, in the volume's channels-last
    layout ``(B, N, N, N, C)`` (EA), or in torch's ``(B, 1, N, N, N)`` (VH, AO: from the pair
    layout by a second launch, :func:`_torch_layout`)."""
    (b, c, n), opt = static.shape, static.opt
    Ts, looks = Ts
    batch = _Batch(data, frames, b, c, n, opt, seed, tiled=static.tiled, windowed=static.windowed)
    if static.tiled:                  # per-ray inputs in the lanes' order; idle lanes march 0 segments
        δ = [dr.gather(mi.Float, x, batch.ray, batch.real) for x in δ]
        marched = dr.gather(mi.UInt32, marched, batch.ray, batch.real)
        if opt.model == "vh":
            Ts = dr.gather(mi.Float, Ts, batch.ray, batch.real)
    δC, δρ = (mi.Color3f(*δ[:3]), δ[3]) if opt.model == "ea" else (mi.Color3f(0.0), δ[0])
    grad = dr.zeros(mi.Float, b * n * n * (n + 1) * 2 if batch.pairs else b * c * n ** 3)
    if opt.model == "vh":
        batch.backward_vh(Ts, marched, grad, δρ)
    else:
        batch.backward(Ts, marched, grad, δρ, δC, looks)
    dr.eval(grad)                                             # the backward launch
    if not batch.pairs:
        return grad                                           # channels last (C = 4) or torch's (C = 1)
    out = _torch_layout(grad, b, n)
    dr.eval(out)                                              # and its layout conversion
    return out


_frozen_forward = dr.freeze(_forward_pass, limit=64, warn_after=10_000)
_frozen_backward = dr.freeze(_backward_pass, limit=64, warn_after=10_000)


class _Lease:
    """A channels-last buffer lent to one render; back in :data:`_POOL` when the render is freed.

    Fresh 10–100 MB allocations cost more in page faults than the copy itself (a 64³ RGBA batch of
    8: about 10 ms to allocate and fill, 2 ms to fill a reused buffer), so renders of one shape
    reuse their buffers. A lease lives in the autograd context, which dies with the graph: by
    then no launch reads the buffer.
    """

    def __init__(self, shape: Tuple[int, ...], device: str):
        self.key = (shape, device)
        free = _POOL.get(self.key)
        self.buffer = free.pop() if free else torch.empty(shape, device=device)

    def __del__(self):
        free = _POOL.setdefault(self.key, [])
        if len(free) < 4:
            free.append(self.buffer)


_POOL: Dict[Tuple, list] = {}


def _channels_last(volume: torch.Tensor, keep: list) -> torch.Tensor:
    """``(B, C, N, N, N)`` → its ``(B, N, N, N, C)`` copy (a view where that is already contiguous)."""
    view = volume.detach().permute(0, 2, 3, 4, 1)
    if view.is_contiguous():                                  # C = 1, or torch.channels_last_3d
        return view
    lease = _Lease(tuple(view.shape), str(volume.device))
    keep.append(lease)
    return lease.buffer.copy_(view)


def occupied_boxes(volume: torch.Tensor) -> torch.Tensor:
    """``(B, 6)`` float32: per pair, the world-space box (x, y, z low; x, y, z high) around the
    centres of its voxels of density > 0, widened by 1½ voxels (module docstring, "Empty space");
    an empty volume gets an empty box (low > high)."""
    n = volume.shape[-1]
    Δ = 2.0 / n
    v = volume[:, -1].detach()                                                # (B, D, H, W), v ≥ 0
    profile = {"d": v.amax(dim=(2, 3)), "h": v.amax(dim=(1, 3)), "w": v.amax(dim=(1, 2))}   # (B, N) each
    index = torch.arange(n, device=v.device)
    ends = {}
    for name, p in profile.items():
        occupied = p > 0
        first = torch.where(occupied, index, n).amin(dim=1)                   # n where nothing is occupied
        last = torch.where(occupied, index, -1).amax(dim=1)
        ends[name] = (-1.0 + (first + 0.5) * Δ, -1.0 + (last + 0.5) * Δ)       # voxel centres along the index
    x = ends["w"]                                                             # x ← w, y ← −h, z ← −d
    y, z = (-ends["h"][1], -ends["h"][0]), (-ends["d"][1], -ends["d"][0])
    lo = torch.stack([x[0], y[0], z[0]], dim=1) - 1.5 * Δ
    hi = torch.stack([x[1], y[1], z[1]], dim=1) + 1.5 * Δ
    empty = (profile["d"] <= 0).all(dim=1, keepdim=True)
    lo, hi = torch.where(empty, 2.0, lo), torch.where(empty, -2.0, hi)        # empty: low > high
    return torch.cat([lo, hi], dim=1).to(device="cpu", dtype=torch.float32)


class _March(torch.autograd.Function):
    """torch ↔ Dr.Jit: the forward launch, and the backward launch with the recorded T_k."""

    @staticmethod
    def forward(ctx, volume: torch.Tensor, views: torch.Tensor, opt: RenderSettings, seed: int,
                window: Optional[Window]) -> torch.Tensor:
        b, c, n = volume.shape[0], volume.shape[1], volume.shape[-1]
        windowed = window is not None
        lanes, steps = b * n * n * opt.spp, n_segments(n, opt.step)
        record = ctx.needs_input_grad[0]
        floats = recorded_floats(opt.model, c)
        if record and lanes * steps * floats > RECORD_LIMIT:
            raise ValueError(f"a differentiable render of {lanes} rays × {steps} segments records "
                             f"{4 * floats * lanes * steps / 2**30:.1f} GiB; use fewer pairs, spp or a larger step")
        keep: list = []                                           # torch memory Dr.Jit reads
        data = shared_float(_channels_last(volume, keep), keep)        # the (B, N, N, N, C) batch
        frames = pair_frames(views, keep, window)
        spread_over_threads(lanes, 4)
        run = _frozen_forward if FREEZE else _forward_pass
        seed_arr = dr.opaque(mi.UInt32, seed if opt.jitter else 0)   # an input array: a new seed replays
        skip = SKIP_EMPTY and not record                          # forward-only: skip empty space
        boxes = shared_float(occupied_boxes(volume), keep) if skip else None
        # the records in the order of the backward's lanes: tiled where the backward will be
        records_tiled = record and tiled_backward(n, opt.spp)
        values, Ts, marched = run(data, frames, seed_arr, boxes,
                                  _Static((b, c, n), opt, record, records_tiled, windowed))
        image = per_ray_to_image(values, b, n, opt.spp)
        ctx.args = (data, frames, seed_arr, Ts, marched, _Static((b, c, n), opt, False, windowed=windowed), lanes,
                    records_tiled)
        ctx.keep = keep
        return image

    @staticmethod
    def backward(ctx, grad_image: torch.Tensor):
        data, frames, seed_arr, Ts, marched, static, lanes, records_tiled = ctx.args
        δ = list(image_to_per_ray(grad_image.to(torch.float32), static.opt.spp, ctx.keep))
        b, c, n = static.shape
        tiled = records_tiled                                     # the lane order the forward recorded in
        if tiled:
            set_block_size(n * n * static.opt.spp)               # one block per pair: threads own volumes
        else:
            spread_over_threads(lanes, 1)
        run = _frozen_backward if FREEZE else _backward_pass
        grad = run(data, frames, seed_arr, Ts, marched, δ,
                   _Static(static.shape, static.opt, False, tiled, static.windowed))
        # in Dr.Jit's memory, no copy: EA's gradient channels last as it was scattered (the layout G
        # computes in), VH's and AO's in torch's default layout
        out = grad.torch().view(b, n, n, n, c).permute(0, 4, 1, 2, 3)
        del δ
        dr.sync_thread()                                          # nothing in flight reads ``keep``
        return out, None, None, None, None


def _window(window: Optional[Window], opt: RenderSettings) -> Optional[Window]:
    """The call's window: None for none or the full one; a pinhole's window is refused."""
    window = window_or_none(window)
    check_orthographic(window, opt.lens)
    return window


def march(volume: torch.Tensor, views: torch.Tensor, settings: RenderSettings, seed: int = 0,
          window: Optional[Window] = None) -> torch.Tensor:
    """Render ``(B, C, N, N, N)`` volumes from ``(B, 3)`` views with the batched ray marcher.

    Uses ``settings``' model, filter, step, spp, jitter and termination; ``seed`` drives the
    jitter; ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`, module
    docstring "Window"; None: the full cross-section). Returns ``(B, 1, N, N)`` (VH, AO) or
    ``(B, 4, N, N)`` (EA: premultiplied RGB, alpha), differentiable w.r.t. ``volume`` (also twice
    from one forward, with ``retain_graph``). Inputs are assumed valid (see :func:`mitsuba_platonic.render`).
    """
    opt = settings.validate()
    window = _window(window, opt)
    src = volume.to(device=variant_device(), dtype=torch.float32)
    out = _March.apply(src, views.detach().to(torch.float64).cpu(), opt, int(seed), window)
    return out.to(volume.device)


def march_pixels(volume: torch.Tensor, views: torch.Tensor, settings: RenderSettings, factor: int,
                 window: Optional[Window] = None) -> torch.Tensor:
    """Forward only: ``(B, C, N, N, N)`` volumes from ``(B, 3)`` views as ``(B, C, kN, kN)`` images, k = ``factor``.

    The marcher's regular sub-pixel grid of spp = k² rays per pixel, each ray kept as a pixel of its
    own instead of averaged into its pixel: ray (sx, sy) of pixel (j, i) sits at x = −1 + (j + (sx + ½)/k)Δ,
    the centre of pixel (kj + sx) of a kN-pixel image, so this is the marcher's render at k times the
    volume's resolution (``march`` with spp k², averaged over k × k blocks, is the same image downsampled).
    One launch of the same frozen kernel as :func:`march`; ``settings``' spp and jitter are replaced.
    ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`), as in :func:`march`.
    """
    k = int(factor)
    if k < 1:
        raise ValueError(f"factor: expected a positive int, got {factor!r}")
    opt = replace(settings, spp=k * k, jitter=False).validate()
    window = _window(window, opt)
    src = volume.detach().to(device=variant_device(), dtype=torch.float32)
    b, c, n = src.shape[0], src.shape[1], src.shape[-1]
    check_lanes(b, n, opt.spp)
    keep: list = []
    with torch.no_grad():
        data = shared_float(_channels_last(src, keep), keep)
        frames = pair_frames(views.detach().to(torch.float64).cpu(), keep, window)
        spread_over_threads(b * n * n * opt.spp, 4)
        run = _frozen_forward if FREEZE else _forward_pass
        boxes = shared_float(occupied_boxes(src), keep) if SKIP_EMPTY else None
        values, _, _ = run(data, frames, dr.opaque(mi.UInt32, 0), boxes,
                           _Static((b, c, n), opt, False, False, window is not None))
        rays = torch.stack([v.torch().view(b, n, n, k, k) for v in values], dim=1)     # (B, C, i, j, sy, sx)
        image = rays.permute(0, 1, 2, 4, 3, 5).reshape(b, len(values), n * k, n * k).clone()
        del values
        dr.sync_thread()
    return image.to(volume.device)
