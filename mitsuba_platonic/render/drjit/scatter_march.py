"""Single scattering at the marcher's speed: every (volume, view, light) triple of a call in one
Dr.Jit launch, primal and adjoint, deterministic.

The formation is :mod:`.single_scatter`'s (its medium, its :class:`~.single_scatter.SunAndSky`,
its exposure), with the light near each camera sample modelled locally instead of continued
plane by plane:

    L(ray) = ∫ T(t) σ(x_t) a(x_t) S(x_t) dt,     S(x) = p E_s T_s(x) + L_sky V(x),   p = 1/4π

Light volumes (differentiable; :func:`light_packet`). Per pair, at the voxel centres p:

    A_s(p) = 1 − T_sweep(p + ℓ ω_s)           the sun's sweep (:func:`.single_scatter.sweep`), read ℓ ahead
    σ_s(p) = σ(p + ℓ ω_s)                       σ where that read is
    O(p)   = 1 − Σ_k w_k λ_k(p) T_k(p + o_k) / Σ_k w_k λ_k(p)        the sky's far occlusion

the sun's sweep in torch, the sky's O in Dr.Jit (:mod:`.sky_light`, which defines it), with the 14
sky directions ω_k and weights w_k of :mod:`.single_scatter`, ℓ = ``reach`` voxels, o_k the sky's
whole-voxel far reads (:func:`~.sky_light.sky_offsets`) and λ_k(p) the local factor below at p.
One Dr.Jit launch per pass assembles the packet (:class:`_Packet`): the sun's two reads ℓ ahead
are trilinear with 8 weights that every voxel of a pair shares (ℓ ω_s is one offset per pair), so
the adjoint gathers them back from p − o instead of scattering. The camera pass reads σ, the
albedo a, A_s, σ_s and O as one 8-float packet per voxel, trilinearly.

The local light (the reason for this design). Near a camera sample x, σ is taken as the linear
field of its trilinear cell, σ(x + s ω) ≈ σ + s b with b = ∇σ(x)·ω, clamped at zero: its optical
depth over the reach ℓ towards a light is

    τ_ℓ(σ, b) = ∫_0^ℓ max(σ + s b, 0) ds = σ ℓ + b ℓ²/2     (σ + b ℓ ≥ 0)
                                         = σ² / (2 |b|)       (otherwise: the field reaches 0 first)

which is exact on the ramp of trilinear σ in front of an opaque surface, where the camera sees
the light it scatters (docs/rendering.md, "Single scattering at the marcher's speed"). Then

    T_s(x) = exp(−τ_s) (1 − A_s(x)),   τ_s = τ_ℓ(σ, b_s) + ½ ℓ (σ_s(x) − e) u,   e = max(σ + b_s ℓ, 0)
    V(x)   = (1 − O(x)) Σ_k w_k exp(−τ_ℓ(σ, b_k))

with u = min(e/σ, 1) (u = 1 for b_s ≥ 0). The correction turns the sun's linear extrapolation
into the trapezoid rule between σ(x) and the σ actually read at x + ℓ ω_s where σ does not fall
towards the sun (inside a soft medium lit from behind), and fades out, continuously, as the
field reaches zero within the reach: at a surface under a grazing sun the point ℓ ahead still
lies in the surface's own ramp, whose σ the ramp term has already counted. The sky's ℓ_k is its
far read's distance (:func:`sky_offsets`).

Camera (orthographic): ``spp`` rays per pixel on a regular sub-pixel grid, m = ``steps_per_voxel``
samples per voxel at the midpoints of steps h = Δ/m, front to back, in the extinction domain:

    C = Σ_k T_k (1 − τ_k) a_k S_k,   τ_k = e^{−σ_k h},   T_k = Π_{j<k} τ_j,   α = 1 − T_K

A :class:`~.window.Window` (zoom, pan) moves the rays as the marcher's ("Window" in
:mod:`.marcher`: the frame (h right, h up, ω) and origin o, 12 floats per pair); the light
volumes do not depend on the camera and stay as they are.

Adjoint (one launch, no record, no division by τ). Each ray is marched front to back again with
its forward totals C and α: since dτ_k/dσ_k = −h τ_k,

    ∂C/∂σ_k (through T) = h (T_{k+1} c_k − (C − C_{≤k})),     ∂α/∂σ_k = h (1 − α)

and the local light's partial derivatives (module source, :meth:`_Rays.shade_backward`) reach
the 8 voxels of the lookup by its weights and their derivatives (σ's gradient is a sum of
corner values times ∂w/∂q). Scatter-adds: ``Expand`` on the LLVM backend (exact), atomics on CUDA.

Left out: what :mod:`.single_scatter` leaves out (multiple scattering, sky directions beyond
14, the perspective camera), and the field's curvature within the reach (measured against
``volpath`` in docs/rendering.md).
"""

from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import torch

from ...errors import UserError
from ..grids import extinction
from ..pytorch.single_scatter import SKY_DIRECTIONS, SKY_WEIGHTS, LightBatch, checked_lights, mean_luminance, sweep
from ..variant import ensure_variant, variant_device
from ..window import Window, window_or_none
from .launch import (FRAME_FLOATS, FREEZE, REDUCE_MODE, LaunchKey, image_to_per_ray, pair_frames, per_ray_to_image,
                     shared_float, spread_over_threads)
from .sky_light import local_depth, local_depth_partials, sky_occlusion, sky_offsets

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

__all__ = ["render_scatter_march", "light_packet", "local_depth", "sky_offsets", "REACH", "PACKET"]

#: The local light's reach ℓ, in voxels (module docstring; docs/rendering.md measures 1–3).
REACH = 2.0

#: Floats per voxel in the camera pass's packet: σ, a (3), A_s, σ_s, O, unused.
PACKET = 8


def _grid_dirs(d: torch.Tensor) -> torch.Tensor:
    """World directions ``(…, 3)`` → grid index units [d, h, w] per voxel (d along −z, h along −y, w along +x)."""
    return torch.stack([-d[..., 2], -d[..., 1], d[..., 0]], dim=-1)


class _Assembly:
    """The packet's lanes: one per voxel p of every pair, and the sun's read at p + o (o = ℓ ω_s in
    voxels [d, h, w], one per pair): trilinear, with the same 8 weights at every voxel of a pair."""

    def __init__(self, offsets: Any, b: int, n: int):
        self.n = n
        lane = dr.arange(mi.UInt32, b * n ** 3)
        self.pair, voxel = lane // n ** 3, lane % n ** 3
        self.lane = lane
        self.p = mi.Vector3i(mi.Int32(voxel // (n * n)), mi.Int32((voxel // n) % n), mi.Int32(voxel % n))
        o = mi.Vector3f(*(dr.gather(mi.Float, offsets, self.pair * 3 + a) for a in range(3)))
        self.i0 = mi.Vector3i(dr.floor(o))
        self.t = o - mi.Vector3f(self.i0)

    def corners(self, sign: int) -> list:
        """[(index, inside, weight)] of the 8 voxels p + i0 + c (``sign`` 1: the read) or p − i0 − c
        (``sign`` −1: its adjoint, which gathers what the read's lanes would have scattered)."""
        n, out = self.n, []
        for c in ((0, 0, 0), (0, 0, 1), (0, 1, 0), (0, 1, 1), (1, 0, 0), (1, 0, 1), (1, 1, 0), (1, 1, 1)):
            q = self.p + sign * (self.i0 + mi.Vector3i(*c))
            inside = dr.all((q >= 0) & (q < n))
            w = mi.Float(1.0)
            for a in range(3):
                w *= self.t[a] if c[a] else 1.0 - self.t[a]
            out.append((self.pair * n ** 3 + mi.UInt32(dr.clip((q.x * n + q.y) * n + q.z, 0, n ** 3 - 1)), inside, w))
        return out

    def read(self, values: Any) -> Any:
        """Σ_c w_c values(p + i0 + c), zero outside the cube."""
        return sum(w * dr.gather(mi.Float, values, idx, inside) for idx, inside, w in self.corners(1))

    def read_adjoint(self, grads: Any) -> Any:
        """Σ_c w_c grads(p − i0 − c): the read's transpose, by gathers (no scatter)."""
        return sum(w * dr.gather(mi.Float, grads, idx, inside) for idx, inside, w in self.corners(-1))


def _assemble(σ: Any, rgba: Any, A: Any, O: Any, offsets: Any, key: LaunchKey) -> Any:
    """The packet's launch: (σ, a, A_s, σ_s, O, 0) per voxel, two 4-float halves."""
    b, n = key.values
    at = _Assembly(offsets, b, n)
    lane, n3 = at.lane, n ** 3
    colour = [dr.gather(mi.Float, rgba, (at.pair * 4 + c) * n3 + (lane - at.pair * n3)) for c in range(3)]
    packet = dr.empty(mi.Float, b * n3 * PACKET)
    dr.scatter(packet, mi.Vector4f(dr.gather(mi.Float, σ, lane), *colour), 2 * lane)
    dr.scatter(packet, mi.Vector4f(at.read(A), at.read(σ), dr.gather(mi.Float, O, lane), 0.0), 2 * lane + 1)
    dr.eval(packet)
    return packet


def _assemble_backward(g_A_s: Any, g_σ_s: Any, offsets: Any, key: LaunchKey) -> Tuple[Any, Any]:
    """Its adjoint for the sun's reads: ∂L/∂A and ∂L/∂σ through them (the other channels pass through)."""
    at = _Assembly(offsets, *key.values)
    out = (at.read_adjoint(g_A_s), at.read_adjoint(g_σ_s))
    dr.eval(out)
    return out


_frozen_assemble = dr.freeze(_assemble, limit=64, warn_after=10_000)
_frozen_assemble_backward = dr.freeze(_assemble_backward, limit=64, warn_after=10_000)


class _Packet(torch.autograd.Function):
    """torch ↔ Dr.Jit: the camera pass's packet from σ, the volume (its albedo), the sun's sweep A and
    the sky's O (each ``(B, N³)``, the volume ``(B, 4, N³)``), in one launch per pass."""

    @staticmethod
    def forward(ctx, σ: torch.Tensor, rgba: torch.Tensor, A: torch.Tensor, O: torch.Tensor,
                offsets: torch.Tensor) -> torch.Tensor:
        b, n3 = σ.shape
        n = round(n3 ** (1.0 / 3.0))
        keep: list = []
        inputs = [shared_float(x.detach().contiguous(), keep) for x in (σ, rgba, A, O)]
        o_d = shared_float(offsets.to(torch.float32).contiguous(), keep)
        spread_over_threads(b * n3, 4)
        packet = (_frozen_assemble if FREEZE else _assemble)(*inputs, o_d, LaunchKey(b, n))
        ctx.saved = (o_d, b, n)
        ctx.keep = keep
        out = packet.torch().view(b, n3, PACKET)                  # in Dr.Jit's memory, no copy
        dr.sync_thread()
        return out

    @staticmethod
    def backward(ctx, g: torch.Tensor):
        o_d, b, n = ctx.saved
        g = g.to(torch.float32).contiguous()
        g_A_s, g_σ_s = shared_float(g[..., 4].contiguous(), ctx.keep), shared_float(g[..., 5].contiguous(), ctx.keep)
        spread_over_threads(b * n ** 3, 4)
        g_A, g_σ = (_frozen_assemble_backward if FREEZE else _assemble_backward)(g_A_s, g_σ_s, o_d, LaunchKey(b, n))
        g_A_t, g_σ_t = g_A.torch().view(b, -1), g_σ.torch().view(b, -1)
        g_rgba = torch.zeros(b, 4, n ** 3, device=g.device)         # the opacity's gradient comes through σ
        g_rgba[:, :3] = g[..., 1:4].transpose(1, 2)
        out = (g[..., 0] + g_σ_t, g_rgba, g_A_t, g[..., 6], None)
        dr.sync_thread()
        return out


def light_packet(volume: torch.Tensor, lights: LightBatch, reach: float = REACH) -> torch.Tensor:
    """The camera pass's per-voxel packet ``(B, N, N, N, 8)``, channels last: σ, a_r, a_g, a_b, A_s,
    σ_s, O, 0 (module docstring, "Light volumes"); differentiable w.r.t. ``volume``."""
    b, n = volume.shape[0], volume.shape[-1]
    device = variant_device()                                     # where Dr.Jit's arrays live
    flat = lambda x: x.reshape(b, -1).to(device, torch.float32)
    σ = extinction(volume[:, 3:])
    A = sweep(σ, lights.direction).opacity                       # the sun's sweep (torch)
    O = sky_occlusion(σ, reach)                                   # the sky's far occlusion (Dr.Jit)
    offsets = reach * _grid_dirs(lights.direction.to(torch.float64))   # where the sun's volumes are read
    packet = _Packet.apply(flat(σ), volume.reshape(b, 4, -1).to(device, torch.float32), flat(A), flat(O),
                           offsets.to(device))
    return packet.view(b, n, n, n, PACKET).to(volume.device, volume.dtype)


# -- The Dr.Jit pass ------------------------------------------------------------------------------


def _sky_constants(Δ: float, reach: float) -> list:
    """(w_k, ω_k in the kernel's index order (w, h, d) per world unit, ℓ_k in world units) of the 14
    sky directions, ℓ_k the distance of the far read (:func:`sky_offsets`)."""
    return [(w, (d[0] / Δ, -d[1] / Δ, -d[2] / Δ), math.sqrt(sum(x * x for x in o)) * Δ)
            for w, d, o in zip(SKY_WEIGHTS, SKY_DIRECTIONS, sky_offsets(reach))]


class _Rays:
    """One call's rays (lane r: pair r // (N²·spp), pixel, sub-sample), their samples and lookups;
    ``windowed``: 12 floats per pair's frame, with the window's origin (:func:`.launch.pair_frames`)."""

    def __init__(self, data: Any, frames: Any, light: Any, b: int, n: int, m: int, spp: int, reach: float,
                 windowed: bool = False):
        self.data, self.N, self.m, self.B = data, n, m, b
        self.Δ = 2.0 / n
        self.h = self.Δ / m                                       # a step, in world units
        self.ℓ = reach * self.Δ                                   # the reach, in world units
        self.n_rays = b * n * n * spp
        self.n_steps = n * m
        r = dr.arange(mi.UInt32, self.n_rays)
        pixel = r // spp
        sub = r - pixel * spp
        pair = pixel // (n * n)
        ij = pixel - pair * (n * n)
        i, j = ij // n, ij % n
        s = math.isqrt(spp)
        self.x = -1.0 + (mi.Float(j) + (mi.Float(sub % s) + 0.5) / s) * self.Δ
        self.y = 1.0 - (mi.Float(i) + (mi.Float(sub // s) + 0.5) / s) * self.Δ
        stride = FRAME_FLOATS[windowed]
        f = [dr.gather(mi.Float, frames, pair * stride + k) for k in range(stride)]
        self.right, self.up, self.ω = mi.Vector3f(*f[0:3]), mi.Vector3f(*f[3:6]), mi.Vector3f(*f[6:9])
        self.origin = mi.Vector3f(*f[9:12]) if windowed else None          # the window's centre o
        g = [dr.gather(mi.Float, light, pair * 9 + k) for k in range(9)]
        # the sun's direction in index units (w, h, d) per world unit; p E_s and L_sky, exposed
        self.ω_s = mi.Vector3f(g[0] / self.Δ, -g[1] / self.Δ, -g[2] / self.Δ)
        self.E_s, self.L_sky = mi.Color3f(*g[3:6]), mi.Color3f(*g[6:9])
        self.base = pair * (n * n * n)
        self.sky = _sky_constants(self.Δ, reach)

    def sample(self, k: Any) -> Any:
        """The continuous voxel index q (w, h, d) of sample k of each ray."""
        z = 1.0 - (mi.Float(k) + 0.5) * self.h
        p = self.x * self.right + self.y * self.up + z * self.ω
        if self.origin is not None:
            p = p + self.origin
        half = self.N / 2.0
        return mi.Vector3f((p.x + 1.0) * half - 0.5, (1.0 - p.y) * half - 0.5, (1.0 - p.z) * half - 0.5)

    def corners(self, q: Any) -> list:
        """[(packet index, inside, weight, ∂weight/∂q)] of the 8 voxels around q. Indices are
        clamped into the cube (the albedo reads its edge values, as Mitsuba's grid does); σ, A_s,
        σ_s and O count only where ``inside``."""
        N = self.N
        i0 = mi.Vector3i(dr.floor(q))
        t = q - mi.Vector3f(i0)
        out = []
        for oz in (0, 1):
            for oy in (0, 1):
                for ox in (0, 1):
                    i = i0 + mi.Vector3i(ox, oy, oz)
                    inside = dr.all((i >= 0) & (i < N))
                    c = dr.clip(i, 0, N - 1)
                    idx = self.base + mi.UInt32((c.z * N + c.y) * N + c.x)
                    wx, wy, wz = (t.x if ox else 1.0 - t.x), (t.y if oy else 1.0 - t.y), (t.z if oz else 1.0 - t.z)
                    sx, sy, sz = (1.0 if ox else -1.0), (1.0 if oy else -1.0), (1.0 if oz else -1.0)
                    out.append((idx, inside, wx * wy * wz, mi.Vector3f(sx * wy * wz, wx * sy * wz, wx * wy * sz)))
        return out

    def lookup(self, corners: list) -> Tuple[Any, ...]:
        """σ, ∇_q σ, a, A_s, σ_s, O at the lookup (two 4-float packets per voxel)."""
        σ, gq, a = mi.Float(0.0), mi.Vector3f(0.0), mi.Color3f(0.0)
        A, σ_s, O = mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)
        for idx, inside, w, dw in corners:
            lo = dr.gather(mi.Vector4f, self.data, 2 * idx)
            hi = dr.gather(mi.Vector4f, self.data, 2 * idx + 1)
            σ_c = dr.select(inside, lo.x, 0.0)
            σ += w * σ_c
            gq += dw * σ_c
            a += w * mi.Color3f(lo.y, lo.z, lo.w)
            wi = dr.select(inside, w, 0.0)
            A += wi * hi.x
            σ_s += wi * hi.y
            O += wi * hi.z
        return σ, gq, a, A, σ_s, O

    def _sun_depth(self, σ: Any, b: Any, σ_s: Any) -> Tuple[Any, Any, Any, Any]:
        """τ_s and its partial derivatives ∂/∂σ, ∂/∂b, ∂/∂σ_s (module docstring, "The local light"):

            b ≥ 0:             τ_s = ℓ (σ + σ_s) / 2
            b < 0, e > 0:      τ_s = σ ℓ + b ℓ²/2 + ℓ (σ_s − e) u / 2,    e = σ + b ℓ,  u = e / σ
            e ≤ 0:             τ_s = σ² / (2 |b|)
        """
        ℓ = self.ℓ
        e = σ + b * ℓ
        rising, ramp = b >= 0, e <= 0
        # σ > 0 in the middle case; floored so that 1/σ stays finite where σ is denormal
        σ_ = dr.select(rising | ramp, 1.0, dr.maximum(σ, 1e-30))
        b_ = dr.select(ramp & ~rising, b, -1.0)                      # b < 0 in the ramp case
        u = e / σ_
        middle = σ * ℓ + 0.5 * b * ℓ * ℓ + 0.5 * ℓ * (σ_s - e) * u
        τ = dr.select(rising, 0.5 * ℓ * (σ + σ_s), dr.select(ramp, σ * σ / (-2.0 * b_), middle))
        # ratios first (σ/b, bℓ/σ are bounded here): σ² and b² underflow to 0/0 where both are tiny
        dσ = dr.select(rising, 0.5 * ℓ, dr.select(ramp, σ / -b_, ℓ + 0.5 * ℓ * (-u - (σ_s - e) * (b * ℓ / σ_) / σ_)))
        db = dr.select(rising, 0.0, dr.select(ramp, 0.5 * dr.square(σ / b_),
                                              0.5 * ℓ * ℓ + 0.5 * ℓ * (-ℓ * u + (σ_s - e) * ℓ / σ_)))
        dσ_s = dr.select(rising, 0.5 * ℓ, dr.select(ramp, 0.0, 0.5 * ℓ * u))
        return τ, dσ, db, dσ_s

    def shade(self, σ: Any, gq: Any, a: Any, A: Any, σ_s: Any, O: Any) -> Tuple[Any, Any, Any]:
        """c = a S at a sample (module docstring, "The local light"), with S and T_s."""
        T_s = dr.exp(-self._sun_depth(σ, dr.dot(gq, self.ω_s), σ_s)[0]) * (1.0 - A)
        Λ = mi.Float(0.0)
        for w, d, ℓ_k in self.sky:
            Λ += w * dr.exp(-local_depth(σ, dr.dot(gq, mi.Vector3f(*d)), ℓ_k))
        S = self.E_s * T_s + self.L_sky * ((1.0 - O) * Λ)
        return a * S, S, Λ

    def shade_backward(self, gc: Any, σ: Any, gq: Any, a: Any, A: Any, σ_s: Any, O: Any, S: Any,
                       Λ: Any) -> Tuple[Any, ...]:
        """∂L/∂(σ, ∇_q σ, a, A_s, σ_s, O) at a sample from ∂L/∂c = ``gc`` (the chain rule through
        :meth:`shade`, branch by branch of τ_ℓ)."""
        ga = gc * S
        gS = gc * a
        gT_s, gV = dr.sum(gS * self.E_s), dr.sum(gS * self.L_sky)
        # the sun: T_s = e^{−τ_s} (1 − A_s)
        τ_s, dσ, db, dσ_s = self._sun_depth(σ, dr.dot(gq, self.ω_s), σ_s)
        e_s = dr.exp(-τ_s)
        gA = -e_s * gT_s
        gτ = -e_s * (1.0 - A) * gT_s
        gσ, gσ_s = gτ * dσ, gτ * dσ_s
        ggq = (gτ * db) * self.ω_s
        # the sky: V = (1 − O) Σ_k w_k e^{−τ_k}
        gO = -Λ * gV
        gΛ = (1.0 - O) * gV
        for w, d, ℓ_k in self.sky:
            ω = mi.Vector3f(*d)
            τ_k, dσ_k, db_k = local_depth_partials(σ, dr.dot(gq, ω), ℓ_k)
            gτ_k = -w * dr.exp(-τ_k) * gΛ
            gσ += gτ_k * dσ_k
            ggq += ω * (gτ_k * db_k)
        return gσ, ggq, ga, gA, gσ_s, gO

    def scatter(self, grad: Any, corners: list, gσ: Any, ggq: Any, ga: Any, gA: Any, gσ_s: Any, gO: Any) -> None:
        """Scatter-add a sample's partial derivatives into the 8 voxels of its lookup."""
        for idx, inside, w, dw in corners:
            pσ = dr.select(inside, w * gσ + dr.dot(dw, ggq), 0.0)
            wi = dr.select(inside, w, 0.0)
            dr.scatter_reduce(dr.ReduceOp.Add, grad, mi.Vector4f(pσ, w * ga.x, w * ga.y, w * ga.z), 2 * idx,
                              mode=REDUCE_MODE)
            dr.scatter_reduce(dr.ReduceOp.Add, grad, mi.Vector4f(wi * gA, wi * gσ_s, wi * gO, 0.0), 2 * idx + 1,
                              mode=REDUCE_MODE)

    @dr.syntax
    def forward(self) -> Tuple[Any, Any]:
        """Front to back: (C, T) per ray."""
        k = mi.UInt32(0)
        T = mi.Float(1.0)
        C = mi.Color3f(0.0)
        while k < self.n_steps:
            σ, gq, a, A, σ_s, O = self.lookup(self.corners(self.sample(k)))
            c, _, _ = self.shade(σ, gq, a, A, σ_s, O)
            τ = dr.exp(-σ * self.h)
            C += T * (1.0 - τ) * c
            T *= τ
            k += 1
        return C, T

    @dr.syntax
    def backward(self, grad: Any, C_total: Any, α: Any, δC: Any, δα: Any) -> None:
        """Front to back again with the forward's totals (module docstring, "Adjoint")."""
        k = mi.UInt32(0)
        T = mi.Float(1.0)
        C = mi.Color3f(0.0)                                       # C_{<k}
        gσ_α = δα * self.h * (1.0 - α)                            # ∂α/∂σ_k δα, the same at every sample
        while k < self.n_steps:
            corners = self.corners(self.sample(k))
            σ, gq, a, A, σ_s, O = self.lookup(corners)
            c, S, Λ = self.shade(σ, gq, a, A, σ_s, O)
            τ = dr.exp(-σ * self.h)
            C += T * (1.0 - τ) * c                                # C_{≤k}
            T_next = T * τ
            gσ_T = self.h * dr.sum(δC * (T_next * c - (C_total - C))) + gσ_α
            gσ, ggq, ga, gA, gσ_s, gO = self.shade_backward(δC * T * (1.0 - τ), σ, gq, a, A, σ_s, O, S, Λ)
            self.scatter(grad, corners, gσ + gσ_T, ggq, ga, gA, gσ_s, gO)
            T = T_next
            k += 1


def _camera_forward(data: Any, frames: Any, light: Any, key: LaunchKey) -> list:
    """The forward launch: [r, g, b, α] per ray."""
    rays = _Rays(data, frames, light, *key.values)
    C, T = rays.forward()
    values = [C.x, C.y, C.z, 1.0 - T]
    dr.eval(values)
    return values


def _camera_backward(data: Any, frames: Any, light: Any, values: list, δ: list, key: LaunchKey) -> Any:
    """The adjoint launch: ∂L/∂packet from the per-ray gradients δ and the forward's totals."""
    b, n = key.values[:2]
    rays = _Rays(data, frames, light, *key.values)
    grad = dr.zeros(mi.Float, b * n ** 3 * PACKET)
    rays.backward(grad, mi.Color3f(*values[:3]), values[3], mi.Color3f(*δ[:3]), δ[3])
    dr.eval(grad)
    return grad


_frozen_camera_forward = dr.freeze(_camera_forward, limit=64, warn_after=10_000)
_frozen_camera_backward = dr.freeze(_camera_backward, limit=64, warn_after=10_000)


class _ScatterMarch(torch.autograd.Function):
    """torch ↔ Dr.Jit: the forward launch, and the adjoint launch with the forward's totals (each
    replayed by ``dr.freeze`` after its first call with the same sizes)."""

    @staticmethod
    def forward(ctx, packet: torch.Tensor, views: torch.Tensor, light: torch.Tensor, m: int, spp: int,
                reach: float, *window: Optional[Window]) -> torch.Tensor:
        b, n = packet.shape[0], packet.shape[1]
        ctx.inputs = 6 + len(window)                               # apply's arguments: one gradient (or None) each
        window = window[0] if window else None                    # optional: (…, reach) or (…, reach, window)
        keep: list = []
        data = shared_float(packet.detach().contiguous(), keep)
        frames = pair_frames(views, keep, window)
        windowed = window is not None
        light_arr = shared_float(light.detach().to(torch.float32).contiguous(), keep)
        spread_over_threads(b * n * n * spp, 4)
        run = _frozen_camera_forward if FREEZE else _camera_forward
        values = run(data, frames, light_arr, LaunchKey(b, n, m, spp, reach, windowed))
        image = per_ray_to_image(values, b, n, spp)
        ctx.args = (data, frames, light_arr, values, (b, n, m, spp, reach, windowed))
        ctx.keep = keep
        return image

    @staticmethod
    def backward(ctx, grad_image: torch.Tensor):
        data, frames, light_arr, values, (b, n, m, spp, reach, windowed) = ctx.args
        δ = list(image_to_per_ray(grad_image.to(torch.float32).contiguous(), spp, ctx.keep))
        spread_over_threads(b * n * n * spp, 1)
        run = _frozen_camera_backward if FREEZE else _camera_backward
        grad = run(data, frames, light_arr, values, δ, LaunchKey(b, n, m, spp, reach, windowed))
        out = grad.torch().view(b, n, n, n, PACKET)
        dr.sync_thread()                                          # nothing in flight reads ``keep``
        return (out,) + (None,) * (ctx.inputs - 1)


def render_scatter_march(volume: torch.Tensor, views: torch.Tensor, lights: Any, exposure: str = "metered",
                         steps_per_voxel: int = 2, spp: int = 1, reach: float = REACH,
                         window: Optional[Window] = None) -> torch.Tensor:
    """Render ``(B, 4, N, N, N)`` RGBA volumes from ``(B, 3)`` views (orthographic), lit by single
    scattering of one :class:`~.single_scatter.SunAndSky` each, in one Dr.Jit launch per pass.

    Returns ``(B, 4, N, N)``: premultiplied linear RGB radiance (times the exposure) and
    α = 1 − exp(−∫σ), differentiable w.r.t. ``volume``. ``steps_per_voxel``: camera samples per
    voxel (≥ 2: one sample per voxel lands on voxel centres and never sees a surface's ramp);
    ``spp``: rays per pixel, a square number; ``reach``: the local light's ℓ in voxels (module
    docstring); ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`; None:
    the full cross-section). Accuracy and cost against ``volpath`` and the EA marcher: docs/rendering.md.
    """
    window = window_or_none(window)
    batch = checked_lights(volume, views, lights, exposure)
    for name, value, least in (("steps_per_voxel", steps_per_voxel, 2), ("spp", spp, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise UserError(f"{name}: expected an int ≥ {least}, got {value!r}")
    if math.isqrt(spp) ** 2 != spp:
        raise UserError(f"spp: expected a square number of rays per pixel (1, 4, 9, …), got {spp}")
    if isinstance(reach, bool) or not isinstance(reach, (int, float)) or not 0.5 <= reach <= 4.0:
        raise UserError(f"reach: expected a number of voxels in [0.5, 4], got {reach!r}")
    device = variant_device()
    packet = light_packet(volume.to(device=device, dtype=torch.float32), batch, float(reach))
    scale = 1.0 / mean_luminance(batch) if exposure == "metered" else torch.ones(len(batch), dtype=torch.float64)
    light = torch.cat([batch.direction, batch.irradiance / (4.0 * math.pi) * scale[:, None],
                       batch.sky * scale[:, None]], dim=1)
    out = _ScatterMarch.apply(packet, views.detach().to(torch.float64).cpu(), light, steps_per_voxel, spp,
                              float(reach), window)
    return out.to(volume.device)
