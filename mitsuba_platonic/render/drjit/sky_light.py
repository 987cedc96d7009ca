"""The sky's far occlusion O of :mod:`.scatter_march` in two Dr.Jit launches per pass.

For each of the 14 sky directions ω_k (:data:`.single_scatter.SKY_DIRECTIONS`, weights w_k), the
transmittance towards it at every voxel centre, as :func:`.single_scatter.sweep` computes it: the
grid's planes along the direction's dominant axis a, taken from the light's side, each moving a
whole voxel (or none) in the plane per plane, δ ∈ {0, ±1}². Each ray towards the light is then one
line of voxels, and its optical depth a running trapezoid sum along it (ℓ = Δ / |ĝ_a|, with ĝ the
direction in grid units):

    τ_k(i) = τ_k(i − 1) + ℓ (σ_i + σ_{i−1}) / 2,     σ_{−1} = 0     (i: plane from the light's side)

one lane per line that crosses the cube, each direction's of each pair, over the planes where it
is inside (launch 1). Then per voxel p (launch 2)

    λ_k = w_k exp(−τ_{ℓ_k}(σ(p), ∇σ(p)·ω_k)),       F_k = exp(−τ_k(p + o_k))     (1 outside the cube)
    O(p) = 1 − (Σ_k λ_k F_k + ε) / (Σ_k λ_k + ε),    ε = 10⁻⁶

with τ_ℓ the local depth of the clamped linear field (:func:`local_depth`), o_k the far read's
whole-voxel move (:func:`sky_offsets`) and ℓ_k = |o_k| Δ; ∇σ(p) by central differences (in torch,
its transpose too).

Adjoint: launch 2 backwards gives ∂L/∂σ(p), ∂L/∂∇σ(p) and c(p) = ∂L/∂R / Σ_k λ_k (R = 1 − O);
launch 1 backwards marches each line from its far end with the suffix sums G_i = Σ_{j ≥ i}
∂L/∂τ_k(j), and ∂L/∂σ_i = ℓ (G_i + G_{i+1}) / 2, forming ∂L/∂τ_k(q) = −F_k(q) λ_k(p) c(p) at
p = q − o_k where it sums it (no (B, 14, N³) array of it, and no scatter towards p + o_k, which
cost 4× the launch's own work). Every voxel lies on exactly one line of each of the 14
directions, so each direction's ∂L/∂σ is written by plain scatters into its own volume, and the
14 are summed in torch: no atomics anywhere. Each launch is recorded once per (batch, N, reach,
thread count) and replayed by ``dr.freeze`` after.
"""

from __future__ import annotations

import functools
import math
from typing import Any, List, Tuple

import numpy as np
import torch

from ..pytorch.single_scatter import SKY_DIRECTIONS, SKY_WEIGHTS
from ..variant import ensure_variant, variant_device
from .launch import FREEZE, LaunchKey, shared_float, spread_over_threads

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
    in-plane move per plane away from the light and ℓ."""

    def __init__(self, d: Tuple[float, float, float], n: int):
        g = (-d[2], -d[1], d[0])                                  # [d, h, w]
        self.axis = max(range(3), key=lambda a: (abs(g[a]), -a))  # the first of equal ones, as sweep takes it
        self.across = [a for a in range(3) if a != self.axis]
        ga = abs(g[self.axis])
        self.flip = g[self.axis] > 0
        # moving one plane away from the light moves −g_⊥/|g_a| in the plane
        self.move = [-int(round(g[a] / ga)) for a in self.across]
        self.ℓ = (2.0 / n) / ga

    def lines(self, n: int) -> Tuple[np.ndarray, np.ndarray]:
        """(first voxel, voxel count) of every line that crosses the cube. A line is plane i at
        (R + i m_r, C + i m_c), planes counted from the light's side; it lies in the cube for the
        planes i where both stay in [0, N)."""
        stride = (n * n, n, 1)
        spans = []                                                 # per in-plane coordinate: bases, planes [lo, hi]
        for m in self.move:
            base = np.arange(-(n - 1), 2 * n - 1) if m else np.arange(n)
            lo = np.clip(-base if m > 0 else base - (n - 1) if m < 0 else 0 * base, 0, None)
            hi = np.clip((n - 1) - base if m > 0 else base if m < 0 else (n - 1) + 0 * base, None, n - 1)
            spans.append((base, lo, hi))
        (R, lo_r, hi_r), (C, lo_c, hi_c) = spans
        R, C = np.meshgrid(R, C, indexing="ij")
        i0 = np.maximum(lo_r[:, None], lo_c[None, :])             # the first plane in the cube
        i1 = np.minimum(hi_r[:, None], hi_c[None, :])             # the last
        keep = i0 <= i1
        R, C, i0, i1 = R[keep], C[keep], i0[keep], i1[keep]
        plane = (n - 1) - i0 if self.flip else i0
        first = plane * stride[self.axis] + (R + i0 * self.move[0]) * stride[self.across[0]] \
            + (C + i0 * self.move[1]) * stride[self.across[1]]
        return first, i1 - i0 + 1

    def step(self, n: int) -> int:
        """The voxel-number step from one plane to the next along the lines (away from the light)."""
        stride = (n * n, n, 1)
        return (-1 if self.flip else 1) * stride[self.axis] + self.move[0] * stride[self.across[0]] \
            + self.move[1] * stride[self.across[1]]


@functools.lru_cache(maxsize=8)
def _line_table(n: int) -> Tuple[np.ndarray, ...]:
    """Every line of the 14 directions that crosses an N³ cube, direction by direction, neighbours
    side by side (a SIMD packet's lanes then read neighbouring voxels; sorting them longest first
    made each read a cache miss, 1.5× the time): direction k, first voxel, voxel count."""
    k, first, count = [], [], []
    for i, d in enumerate(SKY_DIRECTIONS):
        f, c = _Direction(d, n).lines(n)
        k.append(np.full(len(f), i)), first.append(f), count.append(c)
    k, first, count = np.concatenate(k), np.concatenate(first), np.concatenate(count)
    return k.astype(np.uint32), first.astype(np.uint32), count.astype(np.uint32)


@functools.lru_cache(maxsize=8)
def _line_arrays(n: int) -> Tuple[Any, ...]:
    """:func:`_line_table` and the 14 directions' voxel steps and ℓ/2 as Dr.Jit arrays, made once per N
    (a frozen launch takes them as inputs)."""
    dirs = [_Direction(d, n) for d in SKY_DIRECTIONS]
    k, first, count = _line_table(n)
    return (mi.UInt32(k), mi.UInt32(first), mi.UInt32(count), mi.Int32([d.step(n) for d in dirs]),
            mi.Float([0.5 * d.ℓ for d in dirs]))


@functools.lru_cache(maxsize=8)
def _term_arrays(n: int, reach: float) -> Tuple[Any, ...]:
    """Per sky direction k, for the lines' adjoint: w_k, ω_k (d, h, w components, world units),
    ℓ_k (world units) and the far read's move o_k (d, h, w), as Dr.Jit arrays, made once per (N, ℓ)."""
    Δ, offsets = 2.0 / n, sky_offsets(reach)
    return (mi.Float(list(SKY_WEIGHTS)),
            *(mi.Float([(-d[2], -d[1], d[0])[a] for d in SKY_DIRECTIONS]) for a in range(3)),
            mi.Float([math.sqrt(sum(x * x for x in o)) * Δ for o in offsets]),
            *(mi.Int32([o[a] for o in offsets]) for a in range(3)))


class _Lines:
    """The lines of all 14 directions of every pair in one launch: lane → (pair, line), and per lane
    its direction k, first voxel, voxel count, voxel step per plane and ℓ/2 (from :func:`_line_arrays`).
    Every voxel lies on exactly one line of each direction, so each lane's reads and writes are
    its own: plain scatters, no atomics."""

    def __init__(self, b: int, n: int, tables: Tuple[Any, ...]):
        k, first, count, step, half = tables
        self.n, self.per_pair = n, dr.width(k)
        self.lanes = b * self.per_pair
        lane = dr.arange(mi.UInt32, self.lanes)
        self.pair = lane // self.per_pair
        line = lane - self.pair * self.per_pair
        self.k = dr.gather(mi.UInt32, k, line)
        self.first = mi.Int32(dr.gather(mi.UInt32, first, line))
        self.count = mi.Int32(dr.gather(mi.UInt32, count, line))
        self.step = dr.gather(mi.Int32, step, self.k)
        self.half = dr.gather(mi.Float, half, self.k)

    def at(self, i: Any) -> Any:
        """Index of (pair, k, voxel j of the line) in a ``(B, 14, N³)`` array, and the pair's σ index."""
        voxel = mi.UInt32(self.first + i * self.step)
        return (self.pair * 14 + self.k) * self.n ** 3 + voxel, self.pair * self.n ** 3 + voxel


@dr.syntax
def _sweep_lines(σ: Any, τ: Any, lines: _Lines) -> None:
    """Launch 1: τ along each line, from the light's side, into τ (B, 14, N³)."""
    i = mi.Int32(0)
    depth = mi.Float(0.0)
    σ_prev = mi.Float(0.0)                                        # outside the cube, before the line enters
    while i < lines.count:
        at, at_σ = lines.at(i)
        σ_i = dr.gather(mi.Float, σ, at_σ)
        depth += lines.half * (σ_i + σ_prev)
        dr.scatter(τ, depth, at)
        σ_prev = σ_i
        i += 1


def _far_gradient(lines: _Lines, j: Any, τ: Any, σ: Any, grad: Any, c: Any, term: Tuple[Any, ...]) -> Any:
    """∂L/∂τ_k(q) = −F_k(q) λ_k(p) c(p) at voxel q = voxel j of each lane's line, p = q − o_k (0 where
    p is outside the cube: no voxel reads q then); λ_k(p) recomputed from σ(p) and ∇σ(p). ``term``:
    each lane's direction's w_k, ω_k, ℓ_k and o_k (:func:`_term_arrays`)."""
    n = lines.n
    at, at_σ = lines.at(j)
    v = mi.Int32(at_σ - lines.pair * n ** 3)
    w, ω, ℓ, o = term
    p = mi.Vector3i(v // (n * n), (v // n) % n, v % n) - o
    inside = dr.all((p >= 0) & (p < n))
    i_p = lines.pair * n ** 3 + mi.UInt32(dr.clip((p.x * n + p.y) * n + p.z, 0, n ** 3 - 1))
    λ = w * dr.exp(-local_depth(dr.gather(mi.Float, σ, i_p, inside),
                                dr.dot(dr.gather(mi.Vector3f, grad, i_p, inside), ω), ℓ))
    F = dr.exp(-dr.gather(mi.Float, τ, at))
    return dr.select(inside, -F * λ * dr.gather(mi.Float, c, i_p, inside), 0.0)


@dr.syntax
def _sweep_lines_backward(τ: Any, σ: Any, grad: Any, c: Any, terms: Tuple[Any, ...], gσ: Any, lines: _Lines) -> None:
    """Launch 1's adjoint: each line from its far end, ∂L/∂σ_i = ℓ (G_i + G_{i+1}) / 2 with
    G_i = Σ_{j ≥ i} ∂L/∂τ_k(j) (:func:`_far_gradient`, formed where it is summed: no (B, 14, N³)
    array of it), into gσ (B, 14, N³), one entry per (direction, voxel)."""
    w, ωd, ωh, ωw, ℓ, od, oh, ow = (dr.gather(type(t), t, lines.k) for t in terms)   # the lane's direction's
    term = (w, mi.Vector3f(ωd, ωh, ωw), ℓ, mi.Vector3i(od, oh, ow))
    i = lines.count - 1
    G_next = mi.Float(0.0)                                        # G_{i+1}
    while i >= 0:
        at, _ = lines.at(i)
        G = G_next + _far_gradient(lines, i, τ, σ, grad, c, term)
        dr.scatter(gσ, lines.half * (G + G_next), at)
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

    def far(self, τ: Any, k: int, o: Tuple[int, int, int]) -> Any:
        """F_k = exp(−τ_k(p + o_k)) (1 outside the cube)."""
        n = self.n
        q = self.p + mi.Vector3i(*o)
        inside = dr.all((q >= 0) & (q < n))
        at = (self.pair * 14 + k) * n ** 3 + mi.UInt32(dr.clip((q.x * n + q.y) * n + q.z, 0, n ** 3 - 1))
        return dr.exp(-dr.gather(mi.Float, τ, at, inside))

    def _sums(self, τ: Any) -> Tuple[Any, Any]:
        """Σ_k λ_k F_k + ε and Σ_k λ_k + ε."""
        num, den = mi.Float(EPSILON), mi.Float(EPSILON)
        for k, (w, ω, ℓ, o) in enumerate(self.terms):
            λ = w * dr.exp(-local_depth(self.σ, dr.dot(self.g, ω), ℓ))
            num += λ * self.far(τ, k, o)
            den += λ
        return num, den

    def occlusion(self, τ: Any) -> Any:
        """O(p) (module docstring)."""
        num, den = self._sums(τ)
        return 1.0 - num / den

    def occlusion_backward(self, τ: Any, gO: Any) -> Tuple[Any, Any, Any]:
        """∂L/∂σ(p), ∂L/∂∇σ(p) from ∂L/∂O = ``gO``, and c(p) = ∂L/∂R / Σλ, R = 1 − O, from which the
        lines' adjoint forms ∂L/∂τ_k(p + o_k) = −F_k λ_k(p) c(p) (∂R/∂F_k = λ_k / Σλ, ∂F/∂τ = −F)."""
        num, den = self._sums(τ)
        R = num / den
        c = -gO / den
        gσ, gg = mi.Float(0.0), mi.Vector3f(0.0)
        for k, (w, ω, ℓ, o) in enumerate(self.terms):
            τ_loc, dσ, db = local_depth_partials(self.σ, dr.dot(self.g, ω), ℓ)
            λ = w * dr.exp(-τ_loc)
            gτ_loc = -λ * (self.far(τ, k, o) - R) * c           # ∂R/∂λ_k = (F_k − R) / Σλ; ∂λ/∂τ_loc = −λ
            gσ += gτ_loc * dσ
            gg += ω * (gτ_loc * db)
        return gσ, gg, c


def _lines_forward(σ: Any, tables: Tuple[Any, ...], key: LaunchKey) -> Any:
    """Launch 1: τ (B, 14, N³)."""
    b, n = key.values
    τ = dr.empty(mi.Float, b * 14 * n ** 3)                       # every entry is written by one line
    _sweep_lines(σ, τ, _Lines(b, n, tables))
    dr.eval(τ)
    return τ


def _voxels_forward(σ: Any, g: Any, τ: Any, key: LaunchKey) -> Any:
    """Launch 2: O per voxel."""
    O = _Voxels(σ, g, *key.values).occlusion(τ)
    dr.eval(O)
    return O


def _voxels_backward(σ: Any, g: Any, τ: Any, gO: Any, key: LaunchKey) -> Tuple[Any, ...]:
    """Launch 2's adjoint: ∂L/∂σ(p), ∂L/∂∇σ(p) (three Floats) and c(p)."""
    gσ, gg, c = _Voxels(σ, g, *key.values).occlusion_backward(τ, gO)
    out = (mi.Float(gσ), gg.x, gg.y, gg.z, mi.Float(c))
    dr.eval(out)
    return out


def _lines_backward(τ: Any, σ: Any, g: Any, c: Any, tables: Tuple[Any, ...], terms: Tuple[Any, ...],
                    key: LaunchKey) -> Any:
    """Launch 1's adjoint: ∂L/∂σ per direction (B, 14, N³)."""
    b, n = key.values
    gσ_k = dr.empty(mi.Float, b * 14 * n ** 3)                    # every entry is written by one line
    _sweep_lines_backward(τ, σ, g, c, terms, gσ_k, _Lines(b, n, tables))
    dr.eval(gσ_k)
    return gσ_k


#: The four launches, replayed after their first call with the same key (:data:`.launch.FREEZE`).
_FROZEN = {f.__name__: dr.freeze(f, limit=64, warn_after=10_000)
           for f in (_lines_forward, _voxels_forward, _voxels_backward, _lines_backward)}


def _run(f: Any, *args: Any) -> Any:
    return (_FROZEN[f.__name__] if FREEZE else f)(*args)


def _central_differences(σ: torch.Tensor) -> torch.Tensor:
    """∇σ ``(B, N, N, N, 3)`` (∂σ/∂[d, h, w], world units) of ``σ`` ``(B, N, N, N)`` by central
    differences, σ = 0 outside the cube: g_a(p) = (σ(p + e_a) − σ(p − e_a)) / 2Δ."""
    Δ = 2.0 / σ.shape[-1]
    p = torch.nn.functional.pad(σ, (1, 1, 1, 1, 1, 1))
    return torch.stack([p[:, 2:, 1:-1, 1:-1] - p[:, :-2, 1:-1, 1:-1], p[:, 1:-1, 2:, 1:-1] - p[:, 1:-1, :-2, 1:-1],
                        p[:, 1:-1, 1:-1, 2:] - p[:, 1:-1, 1:-1, :-2]], dim=-1) / (2.0 * Δ)


def _central_differences_adjoint(gg: torch.Tensor) -> torch.Tensor:
    """The transpose of :func:`_central_differences`: ∂L/∂σ(q) = Σ_a (gg_a(q − e_a) − gg_a(q + e_a)) / 2Δ,
    gg = 0 outside the cube (in-place slices: no autograd, no padded copy)."""
    Δ = 2.0 / gg.shape[-2]
    g = gg / (2.0 * Δ)
    out = torch.zeros(g.shape[:-1], dtype=g.dtype, device=g.device)
    out[:, 1:] += g[:, :-1, :, :, 0]                               # q − e_d inside: + g_d(q − e_d)
    out[:, :-1] -= g[:, 1:, :, :, 0]                               # q + e_d inside: − g_d(q + e_d)
    out[:, :, 1:] += g[:, :, :-1, :, 1]
    out[:, :, :-1] -= g[:, :, 1:, :, 1]
    out[:, :, :, 1:] += g[:, :, :, :-1, 2]
    out[:, :, :, :-1] -= g[:, :, :, 1:, 2]
    return out


class _SkyOcclusion(torch.autograd.Function):
    """torch ↔ Dr.Jit: O from σ ``(B, N, N, N)``, float32 (∇σ by central differences, formed and
    transposed here)."""

    @staticmethod
    def forward(ctx, σ: torch.Tensor, reach: float) -> torch.Tensor:
        b, n = σ.shape[0], σ.shape[-1]
        n3 = n ** 3
        keep: list = []
        σ_d = shared_float(σ.detach().contiguous(), keep)
        g_d = shared_float(_central_differences(σ.detach()).contiguous(), keep)
        tables = _line_arrays(n)
        spread_over_threads(b * dr.width(tables[0]), 4)
        τ = _run(_lines_forward, σ_d, tables, LaunchKey(b, n))
        spread_over_threads(b * n3, 4)
        O = _run(_voxels_forward, σ_d, g_d, τ, LaunchKey(b, n, reach))
        ctx.saved = (σ_d, g_d, τ, b, n, reach)
        ctx.keep = keep
        out = O.torch().view(b, n, n, n).clone()
        dr.sync_thread()
        return out

    @staticmethod
    def backward(ctx, gO: torch.Tensor):
        σ_d, g_d, τ, b, n, reach = ctx.saved
        gO_d = shared_float(gO.to(torch.float32).contiguous(), ctx.keep)
        spread_over_threads(b * n ** 3, 4)
        gσ, gx, gy, gz, c = _run(_voxels_backward, σ_d, g_d, τ, gO_d, LaunchKey(b, n, reach))
        tables = _line_arrays(n)
        spread_over_threads(b * dr.width(tables[0]), 4)
        gσ_k = _run(_lines_backward, τ, σ_d, g_d, c, tables, _term_arrays(n, reach), LaunchKey(b, n))
        gg = torch.stack([gx.torch(), gy.torch(), gz.torch()], dim=-1).view(b, n, n, n, 3)
        out = (gσ.torch().view(b, n, n, n) + gσ_k.torch().view(b, 14, n, n, n).sum(1)
               + _central_differences_adjoint(gg))
        dr.sync_thread()
        return out, None


def sky_occlusion(σ: torch.Tensor, reach: float) -> torch.Tensor:
    """O ``(B, 1, N, N, N)`` of an extinction volume ``σ`` ``(B, 1, N, N, N)`` (module docstring),
    differentiable w.r.t. ``σ``: ∇σ by central differences (zero outside the cube)."""
    O = _SkyOcclusion.apply(σ[:, 0].to(variant_device(), torch.float32), reach)
    return O[:, None].to(σ.device, σ.dtype)
