"""Benchmark: what the EA march's lookups alone cost, against the marcher's forward and backward.

Prints figures only (no assertions), measured in one run:

    .venv/bin/python lab/scripts/lookup_floor.py [--resolutions 32 64] [--batch 8] [--repeats 5]

A trilinear EA lookup is 8 corner gathers of an RGBA packet (32 floats) per sample, and the
march takes N samples per ray (step 1, 1 spp). "lookups only" is a Dr.Jit kernel that makes
exactly the marcher's lookups along every ray (its own ray geometry, ``_Batch.segment`` and
``_Batch.corners``) and sums them, with no compositing and no early stop: a lower bound for any
forward pass that reads the volume this way, and the backward pass reads it again (and adds as
much into the gradient). Kernel times come from Dr.Jit's kernel history (no torch side). The
marcher is timed twice in the same run: with a backward pass that makes its lookups again, and
with one that reads the lookups the forward pass recorded (``RECORD_LOOKUPS``, the default).
"""

from __future__ import annotations

import argparse
import importlib
from typing import Any

import torch

from mitsuba_platonic import views as V
from mitsuba_platonic.bench.timing import best_kernel_ms
from mitsuba_platonic.render.drjit.launch import pair_frames, shared_float, spread_over_threads
from mitsuba_platonic.render.settings import RenderSettings
from mitsuba_platonic.volume import test_volume

M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")     # the module, not render()'s name
mi, dr = M.mi, M.dr


@dr.syntax
def lookups_only(batch: Any) -> Any:
    """Σ over every segment of every ray of the 8 corner RGBA packets the marcher's lookup reads."""
    k = mi.UInt32(0)
    acc = mi.Vector4f(0.0)
    while k < batch.n_steps:
        p, _ = batch.segment(k)
        for idx, _, inside in batch.corners(p):
            acc += dr.gather(mi.Vector4f, batch.data, idx, inside)
        k += 1
    return acc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    b = args.batch
    print(f"# EA, trilinear, step 1, 1 spp, batch {b}, random views, 'figure' volume; {mi.variant()} with "
          f"{dr.thread_count()} Dr.Jit threads; ms per image of Dr.Jit kernel time (best of {args.repeats})")
    print("# 'looks up again': the backward pass gathers each lookup again (MITSUBA_PLATONIC_RECORD_LOOKUPS=0);")
    print("# 'reads the record': it reads the lookups the forward pass recorded (the default). f+b ÷ floor: the")
    print("# forward and backward kernels against the lookups of both passes (2 × 'lookups only').")
    print(f"{'N':>4} | {'lookups only':>12} | {'G floats/s':>10} | {'forward':>7} | {'backward':>8} | "
          f"{'÷ floor':>7} | {'forward':>7} | {'backward':>8} | {'÷ floor':>7}")
    print(f"{'':>4} | {'':>12} | {'':>10} | {'looks up again':^34} | {'reads the record':^34}")
    for n in args.resolutions:
        vol = test_volume(n, "figure", "ea").expand(b, -1, -1, -1, -1).contiguous()
        views = V.sample_views(b, seed=1)
        keep: list = []
        data = shared_float(M._channels_last(vol, keep), keep)
        frames = pair_frames(views, keep)
        opt = RenderSettings(backend="mitsuba", model="ea").validate()

        def lookups() -> None:
            spread_over_threads(b * n * n, 4)
            batch = M._Batch(data, frames, b, 4, n, opt, dr.opaque(mi.UInt32, 0))
            dr.eval(lookups_only(batch))

        floor = best_kernel_ms(lookups, args.repeats)
        x = vol.clone().requires_grad_()

        def forward() -> torch.Tensor:
            return M.march(x, views, opt)

        times = {}
        for recorded in (False, True):                       # the backward looks up again / reads the record
            M.RECORD_LOOKUPS = recorded
            fwd = best_kernel_ms(forward, args.repeats)
            image = forward()

            def backward() -> None:
                torch.autograd.grad(image.sum(), x, retain_graph=True)

            times[recorded] = (fwd, best_kernel_ms(backward, args.repeats))
        floats = b * n * n * M.n_segments(n, 1.0) * 32
        row = f"{n:>4} | {floor / b:>12.3f} | {floats / floor / 1e6:>10.2f}"
        for fwd, bwd in times.values():
            row += f" | {fwd / b:>7.3f} | {bwd / b:>8.3f} | {(fwd + bwd) / (2 * floor):>7.2f}"
        print(row, flush=True)


if __name__ == "__main__":
    main()
