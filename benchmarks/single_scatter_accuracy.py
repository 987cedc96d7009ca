"""Benchmark: single scattering's accuracy against Mitsuba's volpath, and its cost.

    .venv/bin/python benchmarks/single_scatter_accuracy.py [--cost-only]

Prints three tables (figures only; tests/test_single_scatter.py asserts the agreement):

1. An opaque half-space (v = 0.999 below y = 0 at 16³, white, seen from above) lit by a sun of
   p E_s = 1 at 0°, 45° and 70° from the zenith: the Lommel–Seeliger value μ_s / (μ_s + 1), volpath
   at max_depth 2 (4096 spp) and ``render_single_scatter`` at several ``steps_per_voxel`` and
   ``shadow_planes`` (the centre 6 × 6 pixels' mean).
2. A soft blob beside a dense box (v = 0.9, sharp edges) at 16³, from the front and obliquely,
   under a sun above, oblique, at the horizon, behind the object, and a sky alone: the image
   total's relative difference from volpath (8 renders × 512 spp) and the mean z² of 4 × 4 pixel
   blocks (1.4 is pure Monte Carlo noise with 8 renders), at the defaults with spp 4.
3. Seconds per forward + backward of 8 pairs at 16³ and 32³ (random volumes, views and lights):
   the EA marcher and closed form beside single scattering, interleaved, median of 5, one run.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
import torch
import torch.nn.functional as F

from mitsuba_platonic.render import render
from mitsuba_platonic.render.mitsuba.single_scatter_reference import reference_render
from mitsuba_platonic.render.pytorch.single_scatter import LightBatch, SunAndSky, render_single_scatter, sample_sun_and_sky
from mitsuba_platonic.volume import voxel_size

N = 16


def _centres(n: int = N):
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * voxel_size(n)
    z, y, x = torch.meshgrid(-c, -c, c, indexing="ij")
    return x, y, z


def _direction(*v: float):
    v = np.asarray(v, dtype=np.float64)
    return tuple(float(a) for a in v / np.linalg.norm(v))


def half_space() -> None:
    x, y, z = _centres()
    v = (0.999 * ((y < 0.0) & (x.abs() < 0.9) & (z.abs() < 0.9))).float()
    volume = torch.stack([torch.ones_like(v)] * 3 + [v])[None]
    view = torch.tensor([[0.0, 1.0, 0.0]])
    settings = [(1, 0), (2, 0), (2, 2), (4, 0), (4, 2), (8, 2)]
    print("### An opaque half-space under a sun (p E_s = 1), seen from above\n")
    print("| sun from the zenith | Lommel–Seeliger | volpath | "
          + " | ".join(f"m = {m}, shadow {k}" for m, k in settings) + " |")
    print("|---" * (3 + len(settings)) + "|")
    for degrees in (0.0, 45.0, 70.0):
        a = math.radians(degrees)
        light = SunAndSky((math.sin(a), math.cos(a), 0.0), (4.0 * math.pi,) * 3, (0.0,) * 3)
        centre = lambda im: float(im[0, 0, 5:11, 5:11].mean())
        ref = centre(reference_render(volume, view, [light], spp=4096, exposure="none"))
        ours = [centre(render_single_scatter(volume, view, [light], exposure="none", steps_per_voxel=m,
                                             shadow_planes=k)) for m, k in settings]
        print(f"| {degrees:.0f}° | {math.cos(a) / (math.cos(a) + 1):.3f} | {ref:.3f} | "
              + " | ".join(f"{o:.3f}" for o in ours) + " |")


def blob_and_box() -> None:
    x, y, z = _centres()
    v = (0.8 * torch.exp(-(((x - 0.1) ** 2 + y ** 2 + (z + 0.1) ** 2) / 0.16))
         + 0.9 * ((x.abs() < 0.3) & ((y + 0.45).abs() < 0.15) & (z.abs() < 0.5)).double()).clamp(0, 1)
    volume = torch.stack([0.8 * torch.ones_like(v), 0.3 + 0.5 * (y > 0).double(), 0.3 * torch.ones_like(v), v])[None]
    volume = volume.float()
    sun = lambda d: SunAndSky(d, (4.0 * math.pi,) * 3, (0.0,) * 3)
    print("\n### A soft blob beside a dense box, 16³: against volpath (8 × 512 spp), defaults at spp 4\n")
    print("| view | light | image total vs volpath | mean z² of 4 × 4 blocks |\n|---|---|---|---|")
    for view_name, view in (("front", (0.0, 0.0, 1.0)), ("oblique", _direction(0.4, 0.5, 0.7))):
        lights = [("sun above", sun((0.0, 1.0, 0.0))), ("sun oblique", sun(_direction(0.5, 0.7, -0.3))),
                  ("sun at the horizon", sun((1.0, 0.0, 0.0))), ("sun behind", sun(tuple(-a for a in view))),
                  ("sky alone", SunAndSky((0.0, 1.0, 0.0), (0.0,) * 3, (0.25,) * 3))]
        views = torch.tensor([view])
        for name, light in lights:
            ours = F.avg_pool2d(render_single_scatter(volume, views, [light], exposure="none", spp=4)[0, :3], 4)
            refs = torch.stack([F.avg_pool2d(reference_render(volume, views, [light], spp=512, seed=s,
                                                              exposure="none")[0, :3], 4) for s in range(8)])
            mean, se = refs.mean(0), refs.std(0) / math.sqrt(len(refs))
            rel = float((ours - mean).sum() / mean.sum())
            z2 = float((((ours - mean) / se.clamp_min(1e-6)) ** 2).mean())
            print(f"| {view_name} | {name} | {100 * rel:+.2f} % | {z2:.1f} |")


def cost() -> None:
    print("\n### Seconds per forward + backward, 8 pairs (median of 5, interleaved, one run)\n")
    print("| N | EA marcher | EA closed form | single scattering (defaults) | single scattering (m = 2, spp 1) "
          "| ratio to the EA marcher |\n|---|---|---|---|---|---|")
    for n in (16, 32):
        g = torch.Generator().manual_seed(n)
        volume = torch.rand(8, 4, n, n, n, generator=g) * 0.5
        views = F.normalize(torch.randn(8, 3, generator=g), dim=-1)
        rng = np.random.default_rng(n)
        lights = LightBatch.of([sample_sun_and_sky(rng) for _ in range(8)])

        def step(f):
            v = volume.clone().requires_grad_()
            t0 = time.perf_counter()
            f(v).sum().backward()                             # the marcher's backward syncs Dr.Jit into torch
            return time.perf_counter() - t0

        runs = {"ea": lambda v: render(v, views, "ea", "mitsuba"),
                "closed": lambda v: render(v, views, "ea", "closed_form"),
                "ss": lambda v: render_single_scatter(v, views, lights),
                "ss2": lambda v: render_single_scatter(v, views, lights, steps_per_voxel=2)}
        times = {k: [] for k in runs}
        for f in runs.values():                               # warm-up: Dr.Jit's kernels, torch's allocator
            step(f)
        for _ in range(5):
            for k, f in runs.items():
                times[k].append(step(f))
        med = {k: statistics.median(t) for k, t in times.items()}
        print(f"| {n}³ | {med['ea']:.4f} | {med['closed']:.4f} | {med['ss']:.3f} | {med['ss2']:.3f} | "
              f"{med['ss'] / med['ea']:.0f}× / {med['ss2'] / med['ea']:.0f}× |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cost-only", action="store_true", help="only the third table (seconds)")
    args = ap.parse_args()
    if not args.cost_only:
        half_space()
        blob_and_box()
    cost()


if __name__ == "__main__":
    main()
