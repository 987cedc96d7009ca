"""Benchmark: the issue's "throwaway" batched march (a Texture3f, Dr.Jit AD) against the marcher.

Prints figures only (no assertions), measured in one run:

    .venv/bin/python lab/scripts/texture_ad_march.py [--resolutions 32 64] [--batch 8] [--repeats 5]

The speed targets of the marcher's issue (64³ EA forward + backward ≤ 2 ms per image, 32³ ≤ 0.5 ms)
came from a march built as this one is: the B volumes stacked in one zero-padded ``Texture3f``
(channels last, linear filtering), one lane per ray of every pair, N unrolled steps of
τ_k = 1 − v_k compositing (EA, step 1, 1 spp), and Dr.Jit's automatic differentiation for the
gradient. Its lookups are exact: q is clamped to [−1, N] per axis, where the padding reads 0, as the
marcher's zero padding does (a test of the same value is printed: image and gradient against the
marcher's).

Dr.Jit's LLVM backend launches kernels *asynchronously*: ``dr.eval`` returns once the kernel is
queued, and only ``dr.sync_thread`` (or reading the data) waits for it. The columns:

- ``queued``: wall time until ``dr.eval`` of the gradient returns, without waiting;
- ``synced``: wall time including ``dr.sync_thread()`` (what the work costs);
- ``kernels``: the kernels' own execution time (Dr.Jit's kernel history);
- ``marcher``: ``render(..., backend="mitsuba")`` forward + backward on the same volumes and views
  (synchronised, as every benchmark of this project times it).
"""

from __future__ import annotations

import argparse
import importlib
import time
from typing import Any, Callable, Tuple

import torch

from mitsuba_platonic import views as V
from mitsuba_platonic.bench.timing import best_kernel_ms, best_of
from mitsuba_platonic.render.settings import RenderSettings
from mitsuba_platonic.volume import test_volume

M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")     # the module, not render()'s name
mi, dr = M.mi, M.dr


def texture_march(volume: torch.Tensor, views: torch.Tensor, weights: torch.Tensor, grad: bool,
                  sync: bool) -> Tuple[Any, Any]:
    """EA image of every pair (and, with ``grad``, ∂(Σ weights · image)/∂volume by Dr.Jit AD).

    ``volume`` (B, 4, N, N, N) → one texture of B slabs (N + 2)³, each with a zero border.
    Returns (image as [r, g, b, α] Floats, gradient tensor or None); with ``sync`` it waits for the
    launches before returning.
    """
    b, _, n = volume.shape[:3]
    s = n + 2
    slabs = torch.zeros(b, s, s, s, 4)
    slabs[:, 1:-1, 1:-1, 1:-1] = volume.permute(0, 2, 3, 4, 1)           # (B, D, H, W, C), bordered
    t = mi.TensorXf(slabs.reshape(b * s, s, s, 4))
    if grad:
        dr.enable_grad(t)
    tex = mi.Texture3f(t, use_accel=False, filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)
    right, up, ω = (mi.Vector3f(*(mi.Float(f[:, a].float().contiguous()) for a in range(3)))
                    for f in V.camera_frames(views))
    lane = dr.arange(mi.UInt32, b * n * n)
    pair, ij = lane // (n * n), lane % (n * n)
    Δ = 2.0 / n
    x = -1.0 + (mi.Float(ij % n) + 0.5) * Δ
    y = 1.0 - (mi.Float(ij // n) + 0.5) * Δ
    lateral = x * dr.gather(mi.Vector3f, right, pair) + y * dr.gather(mi.Vector3f, up, pair)
    ω = dr.gather(mi.Vector3f, ω, pair)
    slab = mi.Float(pair * s + 1)                                         # depth of this pair's voxel 0
    T, C = mi.Float(1.0), mi.Color3f(0.0)
    for k in range(n):                                                     # N unrolled steps
        p = lateral + (1.0 - (k + 0.5) * Δ) * ω
        q = mi.Vector3f(p.x + 1.0, 1.0 - p.y, 1.0 - p.z) * (n / 2) - 0.5     # continuous voxel index
        q = dr.clip(q, -1.0, float(n))                                     # outside the cube: the zero border
        rgba = tex.eval(mi.Point3f((q.x + 1.5) / s, (q.y + 1.5) / s, (slab + q.z + 0.5) / (b * s)))
        τ = 1.0 - rgba[3]
        C += T * (1.0 - τ) * mi.Color3f(rgba[0], rgba[1], rgba[2])
        T *= τ
    image = [C.x, C.y, C.z, 1.0 - T]
    if not grad:
        dr.eval(image)
        if sync:
            dr.sync_thread()
        return image, None
    w = weights.permute(1, 0, 2, 3).reshape(4, -1)                          # per channel, per ray
    loss = sum(dr.sum(mi.Float(w[c].contiguous()) * image[c]) for c in range(4))
    dr.backward(loss)
    g = dr.grad(t)
    dr.eval(g)
    if sync:
        dr.sync_thread()
    return image, g


def queued_ms(fn: Callable[[], Any], repeats: int) -> float:
    """Best wall time of ``repeats`` calls after a warm-up, in ms, *without* waiting for Dr.Jit's
    launches (what a timer stopped when ``dr.eval`` returns reports)."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    dr.sync_thread()
    return best * 1e3


def synced_ms(fn: Callable[[], Any], repeats: int) -> float:
    """Best wall time of ``repeats`` calls after a warm-up, in ms, each waiting for its launches."""
    fn()
    return best_of(fn, repeats) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    b = args.batch
    opt = RenderSettings(backend="mitsuba", model="ea").validate()
    print(f"# EA, trilinear, step 1, 1 spp, batch {b}, random views, 'cloud' volume; {mi.variant()} with "
          f"{dr.thread_count()} Dr.Jit threads; ms per image, best of {args.repeats}")
    print(f"{'N':>4} | {'texture fwd synced':>18} | {'texture f+b queued':>18} | {'f+b synced':>10} | "
          f"{'f+b kernels':>11} | {'marcher f+b':>11} | synced ÷ marcher | image err | grad rel err")
    for n in args.resolutions:
        torch.manual_seed(0)
        vol = test_volume(n, "cloud", "ea").expand(b, -1, -1, -1, -1).contiguous()
        views = V.sample_views(b, seed=1)
        weights = torch.randn(b, 4, n, n)

        # the same value: image and gradient against the marcher's
        x = vol.clone().requires_grad_()
        ours = M.march(x, views, opt)
        (ours * weights).sum().backward()
        image, g = texture_march(vol, views, weights, grad=True, sync=True)
        tex_image = torch.stack([c.torch().view(b, n, n) for c in image], dim=1)
        s = n + 2
        tex_grad = g.torch().view(b, s, s, s, 4)[:, 1:-1, 1:-1, 1:-1].permute(0, 4, 1, 2, 3)
        image_err = float((tex_image - ours.detach()).abs().max())
        grad_err = float((tex_grad - x.grad).norm() / x.grad.norm())

        fwd = synced_ms(lambda: texture_march(vol, views, weights, grad=False, sync=True), args.repeats)
        queued = queued_ms(lambda: texture_march(vol, views, weights, grad=True, sync=False), args.repeats)
        synced = synced_ms(lambda: texture_march(vol, views, weights, grad=True, sync=True), args.repeats)
        kernels = best_kernel_ms(lambda: texture_march(vol, views, weights, grad=True, sync=False), args.repeats)

        def marcher() -> None:
            y = vol.clone().requires_grad_()
            (M.march(y, views, opt) * weights).sum().backward()
            dr.sync_thread()

        ours_ms = synced_ms(marcher, args.repeats)
        print(f"{n:>4} | {fwd / b:>18.3f} | {queued / b:>18.3f} | {synced / b:>10.3f} | {kernels / b:>11.3f} | "
              f"{ours_ms / b:>11.3f} | {synced / ours_ms:>16.2f} | {image_err:>9.1e} | {grad_err:>12.1e}", flush=True)


if __name__ == "__main__":
    main()
