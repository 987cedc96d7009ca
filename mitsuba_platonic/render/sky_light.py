"""The sky's far occlusion O of :mod:`.scatter_march` in two Dr.Jit launches per pass.

For each of the 14 sky directions ω_k (:data:`.single_scatter.SKY_DIRECTIONS`, weights w_k), the
transmittance towards it at every voxel centre, as :func:`.single_scatter.sweep` computes it: the
grid's planes along the direction's dominant axis a, taken from the light's side, each moving a
whole voxel (or none) in the plane per plane, δ ∈ {0, ±1}². Each ray towards the light is then one
line of voxels, and its optical depth a running trapezoid sum along it (ℓ = Δ / |ĝ_a|, with ĝ the
direction in grid units):

    τ_k(i) = τ_k(i − 1) + ℓ (σ_i + σ_{i−1}) / 2,     σ_{−1} = 0     (i: plane from the light's side)

one lane per line, each line of each direction of each pair (launch 1). Then per voxel p (launch 2)

    λ_k = w_k exp(−τ_{ℓ_k}(σ(p), ∇σ(p)·ω_k)),       F_k = exp(−τ_k(p + o_k))     (1 outside the cube)
    O(p) = 1 − (Σ_k λ_k F_k + ε) / (Σ_k λ_k + ε),    ε = 10⁻⁶

with τ_ℓ the local depth of the clamped linear field (:func:`local_depth`), o_k the far read's
whole-voxel move (:func:`sky_offsets`) and ℓ_k = |o_k| Δ; ∇σ(p) comes from the caller (central
differences in torch).

Adjoint: launch 2 backwards gives ∂L/∂σ(p), ∂L/∂∇σ(p) and ∂L/∂τ_k at p + o_k (a move is one to
one, so plain scatters); launch 1 backwards marches each line from its far end with the suffix
sums G_i = Σ_{j ≥ i} ∂L/∂τ_k(j), and ∂L/∂σ_i = ℓ (G_i + G_{i+1}) / 2, added into σ's gradient
(``Expand`` on the LLVM backend: exact; atomics on CUDA), since every voxel lies on one line of
each of the 14 directions.
"""

from __future__ import annotations

import math
from typing import Any, List, Tuple

import torch

from .marcher import _MODE, _shared, _spread_over_threads
from .single_scatter import SKY_DIRECTIONS, SKY_WEIGHTS
from .variant import ensure_variant, variant_device

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

__all__ = ["local_depth", "local_depth_partials", "sky_offsets", "sky_occlusion", "EPSILON"]

#: ε of O's ratio: where no direction is locally open (Σ λ_k ≈ 0), O → 0.
EPSILON = 1e-6


def local_depth(σ: Any, b: Any, ℓ: Any) -> Any:
    """τ_ℓ(σ, b) = ∫_0^ℓ max(σ + s b, 0) ds for σ ≥ 0, elementwise (torch tensors or Dr.Jit arrays):
    σ ℓ + b ℓ²/2 where σ + b ℓ ≥ 0, else σ² / (2|b|) (the field reaches zero first)."""
    if isinstance(σ, torch.Tensor):
        reaches = σ + b * ℓ >= 0
        return torch.where(reaches, σ * ℓ + 0.5 * b * ℓ * ℓ, σ * σ / torch.where(reaches, 1.0, -2.0 * b))
    reaches = σ + b * ℓ >= 0
    return dr.select(reaches, σ * ℓ + 0.5 * b * ℓ * ℓ, σ * σ / dr.select(reaches, 1.0, -2.0 * b))


def local_depth_partials(σ: Any, b: Any, ℓ: float) -> Tuple[Any, Any, Any]:
    """τ_ℓ(σ, b), ∂τ_ℓ/∂σ and ∂τ_ℓ/∂b (Dr.Jit arrays)."""
    reaches = σ + b * ℓ >= 0
    safe = dr.select(reaches, -1.0, b)                        # b < 0 where the field reaches zero
    τ = dr.select(reaches, σ * ℓ + 0.5 * b * ℓ * ℓ, σ * σ / (-2.0 * safe))
    # σ/b first: it is bounded (|σ/b| < ℓ) where σ² and b² could both underflow to 0/0
    return τ, dr.select(reaches, ℓ, σ / -safe), dr.select(reaches, 0.5 * ℓ * ℓ, 0.5 * dr.square(σ / safe))


def sky_offsets(reach: float) -> List[Tuple[int, int, int]]:
    """Each sky direction's far read: the whole-voxel move [d, h, w] nearest ``reach`` voxels along it
    (2 voxels along an axis and (±1, ±1, ±1) along a diagonal at the default reach of 2), so that
    the far transmittance is read without interpolation."""
    out = []
    for d in SKY_DIRECTIONS:
        g = (-d[2], -d[1], d[0])
        out.append(tuple(int(max(1, round(reach * abs(x)))) * (1 if x > 0 else -1) if abs(x) > 1e-9 else 0
                         for x in g))
    return out


class _Direction:
    """A sky direction's lines: its sweep axis, whether the light is at the high-index end, the
    in-plane move per plane away from the light, ℓ, and the lines' range of sheared coordinates."""

    def __init__(self, d: Tuple[float, float, float], n: int):
        g = (-d[2], -d[1], d[0])                                  # [d, h, w]
        self.axis = max(range(3), key=lambda a: (abs(g[a]), -a))  # the first of equal ones, as sweep takes it
        self.across = [a for a in range(3) if a != self.axis]
        ga = abs(g[self.axis])
        self.flip = g[self.axis] > 0
        # moving one plane away from the light moves −g_⊥/|g_a| in the plane
        self.move = [-int(round(g[a] / ga)) for a in self.across]
        self.ℓ = (2.0 / n) / ga
        # a line: plane i at (R + i m_r, C + i m_c); R from −(N−1) where the line moves up, else 0
        self.lo = [-(n - 1) if m > 0 else 0 for m in self.move]
        self.hi = [n - 1 if m >= 0 else 2 * (n - 1) for m in self.move]
        self.count = [h - l + 1 for l, h in zip(self.lo, self.hi)]


class _Lines:
    """The lines of all 14 directions of every pair in one launch: lane → (pair, direction k, line
    (R, C)), and per lane its direction's strides, flip, in-plane move and ℓ (read from small tables)."""

    def __init__(self, b: int, n: int):
        dirs = [_Direction(d, n) for d in SKY_DIRECTIONS]
        counts = [d.count[0] * d.count[1] for d in dirs]
        self.per_pair = sum(counts)
        self.n, self.lanes = n, b * self.per_pair
        lane = dr.arange(mi.UInt32, self.lanes)
        self.pair = lane // self.per_pair
        local = mi.Int32(lane - self.pair * self.per_pair)
        stride = (n * n, n, 1)
        starts = [sum(counts[:i]) for i in range(len(dirs))]      # each direction's first line
        k = mi.Int32(0)
        for start in starts[1:]:                                  # which direction: how many starts the lane is past
            k += dr.select(local >= start, 1, 0)
        self.k = mi.UInt32(k)
        pick = lambda values, kind=mi.Int32: dr.gather(kind, kind(values), self.k)   # this lane's direction's value
        line = local - pick(starts)
        # ≥ 1 in every lane: idle lanes of a packet's padding read 0, and an integer division by 0 traps
        count_c = dr.maximum(pick([d.count[1] for d in dirs]), 1)
        self.R = line // count_c + pick([d.lo[0] for d in dirs])
        self.C = line % count_c + pick([d.lo[1] for d in dirs])
        self.s_a = pick([stride[d.axis] for d in dirs])
        self.s_r = pick([stride[d.across[0]] for d in dirs])
        self.s_c = pick([stride[d.across[1]] for d in dirs])
        self.flip = pick([int(d.flip) for d in dirs]) == 1
        self.m_r = pick([d.move[0] for d in dirs])
        self.m_c = pick([d.move[1] for d in dirs])
        self.half = 0.5 * pick([d.ℓ for d in dirs], mi.Float)

    def voxel(self, i: Any) -> Tuple[Any, Any]:
        """(voxel number within a pair, inside) of plane i of each lane's line."""
        n = self.n
        plane = dr.select(self.flip, (n - 1) - i, i)
        row, col = self.R + i * self.m_r, self.C + i * self.m_c
        inside = (row >= 0) & (row < n) & (col >= 0) & (col < n)
        return mi.UInt32(dr.clip(plane * self.s_a + row * self.s_r + col * self.s_c, 0, n ** 3 - 1)), inside

    def at(self, voxel: Any) -> Any:
        """Index of (pair, k, voxel) in a τ array ``(B, 14, N³)``."""
        return (self.pair * 14 + self.k) * self.n ** 3 + voxel


@dr.syntax
def _sweep_lines(σ: Any, τ: Any, lines: _Lines) -> None:
    """Launch 1: τ along each line, into τ (B, 14, N³)."""
    n = lines.n
    i = mi.Int32(0)
    depth = mi.Float(0.0)
    σ_prev = mi.Float(0.0)
    while i < n:
        voxel, inside = lines.voxel(i)
        σ_i = dr.gather(mi.Float, σ, lines.pair * n ** 3 + voxel, inside)
        depth += lines.half * (σ_i + σ_prev)
        dr.scatter(τ, depth, lines.at(voxel), inside)
        σ_prev = σ_i
        i += 1


@dr.syntax
def _sweep_lines_backward(gτ: Any, gσ: Any, lines: _Lines) -> None:
    """Launch 1's adjoint: each line from its far end, ∂L/∂σ_i = ℓ (G_i + G_{i+1}) / 2."""
    n = lines.n
    i = mi.Int32(n - 1)
    G_next = mi.Float(0.0)                                        # G_{i+1}
    while i >= 0:
        voxel, inside = lines.voxel(i)
        G = G_next + dr.gather(mi.Float, gτ, lines.at(voxel), inside)
        dr.scatter_reduce(dr.ReduceOp.Add, gσ, lines.half * (G + G_next), lines.pair * n ** 3 + voxel, inside,
                          mode=_MODE)
        G_next = G
        i -= 1


class _Voxels:
    """Launch 2's lanes: one per voxel p of every pair, its σ, ∇σ and the 14 directions' terms."""

    def __init__(self, σ: Any, grad: Any, b: int, n: int, reach: float):
        self.n, self.Δ = n, 2.0 / n
        lane = dr.arange(mi.UInt32, b * n ** 3)
        self.pair, self.voxel = lane // n ** 3, lane % n ** 3
        self.p = mi.Vector3i(mi.Int32(self.voxel // (n * n)), mi.Int32((self.voxel // n) % n), mi.Int32(self.voxel % n))
        self.σ = dr.gather(mi.Float, σ, lane)
        self.g = mi.Vector3f(*(dr.gather(mi.Float, grad, lane * 3 + a) for a in range(3)))   # ∂σ/∂[d, h, w], world
        self.terms = [(w, mi.Vector3f(-d[2], -d[1], d[0]), math.sqrt(sum(x * x for x in o)) * self.Δ, o)
                      for w, d, o in zip(SKY_WEIGHTS, SKY_DIRECTIONS, sky_offsets(reach))]

    def far(self, τ: Any, k: int, o: Tuple[int, int, int]) -> Tuple[Any, Any, Any]:
        """F_k = exp(−τ_k(p + o_k)) (1 outside the cube), the τ index read and whether it is inside."""
        n = self.n
        q = self.p + mi.Vector3i(*o)
        inside = dr.all((q >= 0) & (q < n))
        at = (self.pair * 14 + k) * n ** 3 + mi.UInt32(dr.clip((q.x * n + q.y) * n + q.z, 0, n ** 3 - 1))
        return dr.exp(-dr.gather(mi.Float, τ, at, inside)), at, inside

    def _sums(self, τ: Any) -> Tuple[Any, Any]:
        """Σ_k λ_k F_k + ε and Σ_k λ_k + ε."""
        num, den = mi.Float(EPSILON), mi.Float(EPSILON)
        for k, (w, ω, ℓ, o) in enumerate(self.terms):
            λ = w * dr.exp(-local_depth(self.σ, dr.dot(self.g, ω), ℓ))
            num += λ * self.far(τ, k, o)[0]
            den += λ
        return num, den

    def occlusion(self, τ: Any) -> Any:
        """O(p) (module docstring)."""
        num, den = self._sums(τ)
        return 1.0 - num / den

    def occlusion_backward(self, τ: Any, gO: Any, gτ: Any) -> Tuple[Any, Any]:
        """∂L/∂σ(p), ∂L/∂∇σ(p) from ∂L/∂O = ``gO``; ∂L/∂τ_k(p + o_k) scattered into ``gτ``."""
        num, den = self._sums(τ)
        R = num / den
        gR = -gO
        gσ, gg = mi.Float(0.0), mi.Vector3f(0.0)
        for k, (w, ω, ℓ, o) in enumerate(self.terms):
            τ_loc, dσ, db = local_depth_partials(self.σ, dr.dot(self.g, ω), ℓ)
            λ = w * dr.exp(-τ_loc)
            F_k, at, inside = self.far(τ, k, o)
            dr.scatter_reduce(dr.ReduceOp.Add, gτ, -F_k * λ / den * gR, at, inside, mode=dr.ReduceMode.Direct)   # ∂R/∂F_k = λ_k / den; ∂F/∂τ = −F
            gτ_loc = -λ * (F_k - R) / den * gR                    # ∂R/∂λ_k = (F_k − R) / den; ∂λ/∂τ_loc = −λ
            gσ += gτ_loc * dσ
            gg += ω * (gτ_loc * db)
        return gσ, gg


class _SkyOcclusion(torch.autograd.Function):
    """torch ↔ Dr.Jit: O from σ ``(B, N³)`` and ∇σ ``(B, N³, 3)``, float32."""

    @staticmethod
    def forward(ctx, σ: torch.Tensor, grad: torch.Tensor, reach: float) -> torch.Tensor:
        b, n3 = σ.shape
        n = round(n3 ** (1.0 / 3.0))
        keep: list = []
        σ_d, g_d = _shared(σ.detach().contiguous(), keep), _shared(grad.detach().contiguous(), keep)
        τ = dr.empty(mi.Float, b * 14 * n3)                        # every entry is written by one line
        lines = _Lines(b, n)
        _spread_over_threads(lines.lanes, 4)
        _sweep_lines(σ_d, τ, lines)
        dr.eval(τ)
        _spread_over_threads(b * n3, 4)
        O = _Voxels(σ_d, g_d, b, n, reach).occlusion(τ)
        dr.eval(O)
        ctx.saved = (σ_d, g_d, τ, b, n, reach)
        ctx.keep = keep
        return O.torch().view(b, n3).clone()

    @staticmethod
    def backward(ctx, gO: torch.Tensor):
        σ_d, g_d, τ, b, n, reach = ctx.saved
        gO_d = _shared(gO.to(torch.float32).contiguous(), ctx.keep)
        gτ = dr.zeros(mi.Float, b * 14 * n ** 3)
        _spread_over_threads(b * n ** 3, 1)
        gσ, gg = _Voxels(σ_d, g_d, b, n, reach).occlusion_backward(τ, gO_d, gτ)
        gσ = mi.Float(gσ)
        dr.eval(gσ, gg, gτ)
        lines = _Lines(b, n)
        _spread_over_threads(lines.lanes, 1)
        _sweep_lines_backward(gτ, gσ, lines)
        dr.eval(gσ)
        out_σ = gσ.torch().view(b, n ** 3).clone()
        out_g = torch.stack([gg.x.torch(), gg.y.torch(), gg.z.torch()], dim=-1).view(b, n ** 3, 3).clone()
        dr.sync_thread()
        return out_σ, out_g, None


def sky_occlusion(σ: torch.Tensor, reach: float) -> torch.Tensor:
    """O ``(B, 1, N, N, N)`` of an extinction volume ``σ`` ``(B, 1, N, N, N)`` (module docstring),
    differentiable w.r.t. ``σ``: ∇σ by central differences (zero outside the cube), in torch."""
    b, n = σ.shape[0], σ.shape[-1]
    Δ = 2.0 / n
    p = torch.nn.functional.pad(σ[:, 0].to(variant_device()), (1, 1, 1, 1, 1, 1))   # where Dr.Jit's arrays live
    grad = torch.stack([p[:, 2:, 1:-1, 1:-1] - p[:, :-2, 1:-1, 1:-1], p[:, 1:-1, 2:, 1:-1] - p[:, 1:-1, :-2, 1:-1],
                        p[:, 1:-1, 1:-1, 2:] - p[:, 1:-1, 1:-1, :-2]], dim=-1) / (2.0 * Δ)   # ∂σ/∂[d, h, w]
    O = _SkyOcclusion.apply(σ.reshape(b, -1).to(p.device, torch.float32), grad.reshape(b, -1, 3).to(torch.float32),
                            reach)
    return O.view(b, 1, n, n, n).to(σ.device, σ.dtype)
