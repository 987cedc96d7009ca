"""The sun's sweep of :mod:`.scatter_march` in Dr.Jit: one launch per plane, forward and backward.

The same transmittance volume as :func:`.single_scatter.sweep`, by the same rule: the grid's
planes perpendicular to the sun direction's dominant axis, taken from the sun's side (plane 0),
each read bilinearly in the plane before it where a ray towards the sun crosses it (p + δ,
δ = g_⊥ / |g_a| with g the direction in grid units; ℓ = Δ / |g_a| a ray's length per plane), in
the product domain, as opacity A = 1 − T so that reads outside the cube (zero) mean T = 1:

    A_i(p) = 1 − (1 − A_{i−1}(p + δ)) f_i(p),     f_i(p) = exp(−ℓ (σ_i(p) + σ_{i−1}(p + δ)) / 2)

with A_{−1} = σ_{−1} = 0. Each plane needs the one before it, so plane i is one launch of a lane
per (pair, row, column); the pairs' planes run side by side, whatever their axes.

A read at p + δ is Σ_c w_c x(p + d + c), d = ⌊δ⌋, c ∈ {0, 1}², with the same 4 weights w_c at every
voxel of a pair; its transpose gathers from q − d − c with those weights, so the adjoint has no
scatter towards neighbours. With G_i the whole of ∂L/∂A_i, T_i = 1 − A_i, planes in reverse:

    G_i(q)      = ∂L/∂A_i(q) + Σ_c w_c (f G)_{i+1}(q − d − c)           (A_{i+1} reads A_i)
    H_i(q)      = G_i(q) T_i(q) ℓ / 2                                      (= −∂L/∂ln f_i)
    ∂L/∂σ_i(q)  = H_i(q) + Σ_c w_c H_{i+1}(q − d − c)                      (f_{i+1} reads σ_i)

f_i recomputed from σ, never T_i / T_{i−1}. What torch's plane loop cost and what this costs:
docs/rendering.md, "Single scattering at the marcher's speed".
"""

from __future__ import annotations

from typing import Any, Tuple

import torch

from .marcher import _shared, _spread_over_threads
from .variant import ensure_variant, variant_device

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

__all__ = ["sun_sweep"]


def _geometry(directions: torch.Tensor, n: int) -> Tuple[torch.Tensor, ...]:
    """Per pair, as :func:`.single_scatter.sweep` derives them: the voxel-index strides of the plane
    axis, row and column ([d, h, w] strides N², N, 1), whether plane 0 is the high-index end, the
    whole and fractional in-plane move ⌊δ⌋, δ − ⌊δ⌋ (row, column) and ℓ."""
    d = directions.detach().to(torch.float64).cpu()
    g = torch.stack([-d[:, 2], -d[:, 1], d[:, 0]], dim=-1)      # the direction in grid index units
    axis = g.abs().argmax(dim=1)
    across = torch.tensor([[1, 2], [0, 2], [0, 1]])[axis]      # the plane's row and column axes
    ga = g.gather(1, axis[:, None])[:, 0]
    flip = ga > 0                                              # the sun lies at the high-index end
    δ = g.gather(1, across) / ga.abs()[:, None]                # (row, column) per plane towards the sun
    stride = torch.tensor([n * n, n, 1])
    floor = torch.floor(δ)
    return (stride[axis], stride[across[:, 0]], stride[across[:, 1]], flip, floor.to(torch.int32),
            (δ - floor).to(torch.float32), (2.0 / n / ga.abs()).to(torch.float32))


class _Plane:
    """One launch's lanes, a (pair, row, column) each, and the pair's geometry (:func:`_geometry`)."""

    def __init__(self, geometry: Tuple[Any, ...], b: int, n: int):
        self.n = n
        lane = dr.arange(mi.UInt32, b * n * n)
        self.lane = lane
        self.pair = lane // (n * n)
        self.r, self.c = mi.Int32((lane // n) % n), mi.Int32(lane % n)
        s_a, s_r, s_c, flip, d_r, d_c, t_r, t_c, ℓ = geometry
        at = lambda t, kind: dr.gather(kind, t, self.pair)
        self.s_a, self.s_r, self.s_c = at(s_a, mi.Int32), at(s_r, mi.Int32), at(s_c, mi.Int32)
        self.flip = at(flip, mi.Int32) == 1
        self.d = (at(d_r, mi.Int32), at(d_c, mi.Int32))
        t = (at(t_r, mi.Float), at(t_c, mi.Float))
        self.taps = [((a, b_), (t[0] if a else 1.0 - t[0]) * (t[1] if b_ else 1.0 - t[1])) for a in (0, 1) for b_ in (0, 1)]
        self.half = 0.5 * at(ℓ, mi.Float)

    def voxel(self, i: Any, r: Any, c: Any) -> Any:
        """Index into a pair-major [d, h, w] volume of (plane i, row r, column c)."""
        plane = dr.select(self.flip, (self.n - 1) - i, i)
        return self.pair * self.n ** 3 + mi.UInt32(plane * self.s_a + r * self.s_r + c * self.s_c)

    def read(self, volume: Any, i: Any, active: Any) -> Any:
        """Σ_c w_c volume(plane i, p + d + c): the bilinear read at p + δ, zero outside the plane."""
        out = mi.Float(0.0)
        for (a, b_), w in self.taps:
            r, c = self.r + self.d[0] + a, self.c + self.d[1] + b_
            inside = active & (r >= 0) & (r < self.n) & (c >= 0) & (c < self.n)
            out += w * dr.gather(mi.Float, volume, self.voxel(i, dr.clip(r, 0, self.n - 1), dr.clip(c, 0, self.n - 1)),
                                 inside)
        return out

    def read_plane(self, plane: Any, sign: int, active: Any) -> Any:
        """Σ_c w_c plane(p + sign (d + c)) of a plane-layout array (one value per lane): the read at
        p + δ (``sign`` 1) or its transpose (``sign`` −1)."""
        n = self.n
        out = mi.Float(0.0)
        for (a, b_), w in self.taps:
            r, c = self.r + sign * (self.d[0] + a), self.c + sign * (self.d[1] + b_)
            inside = active & (r >= 0) & (r < n) & (c >= 0) & (c < n)
            out += w * dr.gather(mi.Float, plane, self.pair * n * n + mi.UInt32(dr.clip(r, 0, n - 1) * n
                                                                              + dr.clip(c, 0, n - 1)), inside)
        return out

    def f(self, σ: Any, i: Any) -> Any:
        """f_i at the lanes' voxels."""
        σ_i = dr.gather(mi.Float, σ, self.voxel(i, self.r, self.c))
        return dr.exp(-self.half * (σ_i + self.read(σ, i - 1, i > 0)))


def _forward(σ: Any, geometry: Tuple[Any, ...], b: int, n: int) -> Any:
    """A (B·N³, [d, h, w]), plane by plane. Each launch reads the plane before it from that launch's
    own output, not from A: a kernel that gathers from an array it scatters into makes Dr.Jit copy
    the whole array first (8 MB a plane at 64³)."""
    A = dr.zeros(mi.Float, b * n ** 3)
    lanes = _Plane(geometry, b, n)
    A_prev = dr.zeros(mi.Float, b * n * n)                        # plane −1: none
    for plane in range(n):
        i = dr.opaque(mi.Int32, plane)                            # one kernel for every plane
        A_i = 1.0 - (1.0 - lanes.read_plane(A_prev, 1, i > 0)) * lanes.f(σ, i)
        dr.scatter(A, A_i, lanes.voxel(i, lanes.r, lanes.c))      # the lane's own voxel
        dr.eval(A, A_i)
        A_prev = A_i
    return A


def _backward(σ: Any, A: Any, gA: Any, geometry: Tuple[Any, ...], b: int, n: int) -> Any:
    """∂L/∂σ (B·N³, [d, h, w]) from ∂L/∂A, planes in reverse (module docstring)."""
    gσ = dr.zeros(mi.Float, b * n ** 3)
    lanes = _Plane(geometry, b, n)
    fG_next, H_next = dr.zeros(mi.Float, b * n * n), dr.zeros(mi.Float, b * n * n)   # plane n: none
    for plane in reversed(range(n)):
        i = dr.opaque(mi.Int32, plane)
        here = lanes.voxel(i, lanes.r, lanes.c)
        later = i < n - 1
        G = dr.gather(mi.Float, gA, here) + lanes.read_plane(fG_next, -1, later)
        H = G * (1.0 - dr.gather(mi.Float, A, here)) * lanes.half
        dr.scatter(gσ, H + lanes.read_plane(H_next, -1, later), here)
        fG_next, H_next = lanes.f(σ, i) * G, H
        dr.eval(gσ, fG_next, H_next)
    return gσ


class _SunSweep(torch.autograd.Function):
    """torch ↔ Dr.Jit: A from σ ``(B, N, N, N)``, float32, and the sun directions ``(B, 3)``."""

    @staticmethod
    def forward(ctx, σ: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        b, n = σ.shape[0], σ.shape[-1]
        keep: list = []
        σ_d = _shared(σ.detach().contiguous(), keep)
        kinds = (mi.Int32, mi.Int32, mi.Int32, mi.Int32, mi.Int32, mi.Int32, mi.Float, mi.Float, mi.Float)
        s_a, s_r, s_c, flip, floor, frac, ℓ = _geometry(directions, n)
        columns = (s_a, s_r, s_c, flip.to(torch.int32), floor[:, 0], floor[:, 1], frac[:, 0], frac[:, 1], ℓ)
        geometry = tuple(kind(column.tolist()) for kind, column in zip(kinds, columns))
        _spread_over_threads(b * n * n, 4)
        A = _forward(σ_d, geometry, b, n)
        ctx.saved = (σ_d, A, geometry, b, n)
        ctx.keep = keep
        out = A.torch().view(b, n, n, n)
        dr.sync_thread()
        return out

    @staticmethod
    def backward(ctx, gA: torch.Tensor):
        σ_d, A, geometry, b, n = ctx.saved
        gA_d = _shared(gA.to(torch.float32).contiguous(), ctx.keep)
        _spread_over_threads(b * n * n, 4)
        gσ = _backward(σ_d, A, gA_d, geometry, b, n)
        out = gσ.torch().view(b, n, n, n)
        dr.sync_thread()
        return out, None


def sun_sweep(σ: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """The opacity 1 − T towards each pair's sun ``(B, 1, N, N, N)`` of an extinction volume ``σ``
    ``(B, 1, N, N, N)``, ``directions`` ``(B, 3)`` unit vectors towards the suns (module docstring):
    :func:`.single_scatter.sweep`'s ``opacity``, differentiable w.r.t. ``σ``."""
    A = _SunSweep.apply(σ[:, 0].to(variant_device(), torch.float32), directions)
    return A[:, None].to(σ.device, σ.dtype)
