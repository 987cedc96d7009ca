"""Benchmark: single scattering at the marcher's speed (render/drjit/scatter_march.py) against Mitsuba's
volpath and the torch formation (render/pytorch/single_scatter.py), and its cost beside the EA marcher.

    .venv/bin/python benchmarks/scatter_march_speed.py [--cost-only] [--repeats R]

Prints three tables (figures only; tests/test_scatter_march.py asserts the agreement):

1. An opaque half-space (v = 0.999 below y = 0 at 16³, white, seen from above): under a sun at 0°,
   45° and 70° from the zenith against the Lommel–Seeliger value μ_s/(μ_s + 1), and under a
   uniform sky against (1 − ln 2)/2 and volpath (4096 spp); the centre 6 × 6 pixels' mean.
2. The soft blob beside the dense box of tests/test_single_scatter.py, 16³: the image total's
   relative difference from 8 volpath renders of 512 spp and the mean z² of 4 × 4 pixel blocks
   (1.4 is pure Monte Carlo noise with 8 renders), for the torch formation at its defaults and
   this one at several settings.
3. Seconds per forward + backward of 8 pairs at 32³ and 64³ (random volumes, views and lights):
   the EA marcher, the torch formation (32³ only) and this one, with the light volumes' share, and
   the ratios of the camera pass alone (this − light volumes) and of the light volumes to the EA marcher;
   interleaved, median of --repeats (7), one run, on the variant's device (the GPU under cuda_ad_rgb), each
   timing waiting for queued CUDA work and Dr.Jit launches.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
import torch
import torch.nn.functional as F

from mitsuba_platonic.bench.timing import sync
from mitsuba_platonic.render import render
from mitsuba_platonic.render.drjit.scatter_march import light_packet, render_scatter_march
from mitsuba_platonic.render.mitsuba.single_scatter_reference import reference_render
from mitsuba_platonic.render.pytorch.single_scatter import LightBatch, SunAndSky, render_single_scatter, sample_sun_and_sky
from mitsuba_platonic.render.variant import ensure_variant, variant_device
from mitsuba_platonic.volume import voxel_size

# -- The scenes of tests/test_single_scatter.py (the same definitions: the benchmark reports on what
# -- the tests assert, and imports nothing of tests/)

N = 16


def coords(n: int = N):
    """World x, y, z of the voxel centres, indexed [d, h, w] (d along −z, h along −y, w along +x)."""
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * voxel_size(n)
    z, y, x = torch.meshgrid(-c, -c, c, indexing="ij")
    return x, y, z


def unit(*v):
    v = np.asarray(v, dtype=np.float64)
    return tuple(float(x) for x in v / np.linalg.norm(v))


def sun(direction, sky=0.0, power=4.0 * math.pi):
    """A sun of p E_s = 1 (E_s = 4π) and a grey sky."""
    return SunAndSky(direction, (power,) * 3, (sky,) * 3)


def blob_and_box():
    """A soft blob beside a dense box (v = 0.9, sharp edges), two colours."""
    x, y, z = coords()
    blob = 0.8 * torch.exp(-(((x - 0.1) ** 2 + y ** 2 + (z + 0.1) ** 2) / 0.4 ** 2))
    box = 0.9 * ((x.abs() < 0.3) & ((y + 0.45).abs() < 0.15) & (z.abs() < 0.5)).double()
    v = (blob + box).clamp(0, 1)
    colour = [0.8 * torch.ones_like(v), 0.3 + 0.5 * (y > 0).double(), 0.3 * torch.ones_like(v)]
    return torch.stack([*colour, v])[None].float()


SUN_ABOVE, SUN_OBLIQUE, HORIZON = sun((0.0, 1.0, 0.0)), sun(unit(0.5, 0.7, -0.3)), sun((1.0, 0.0, 0.0))
SKY = SunAndSky((0.0, 1.0, 0.0), (0.0,) * 3, (0.25,) * 3)
FRONT, OBLIQUE = (0.0, 0.0, 1.0), unit(0.4, 0.5, 0.7)


def half_space() -> None:
    x, y, z = coords()
    v = (0.999 * ((y < 0.0) & (x.abs() < 0.9) & (z.abs() < 0.9))).float()
    volume = torch.stack([torch.ones_like(v)] * 3 + [v])[None]
    view = torch.tensor([[0.0, 1.0, 0.0]])
    centre = lambda im: float(im[0, 0, 5:11, 5:11].mean())
    print("### An opaque half-space seen from above, 16³\n")
    print("| light | exact | volpath | torch formation (defaults) | this, m = 2 | this, m = 4 |\n|---|---|---|---|---|---|")
    rows = [(f"sun {d:.0f}° from the zenith", SunAndSky((math.sin(math.radians(d)), math.cos(math.radians(d)), 0.0),
                                                          (4.0 * math.pi,) * 3, (0.0,) * 3),
             math.cos(math.radians(d)) / (math.cos(math.radians(d)) + 1.0)) for d in (0.0, 45.0, 70.0)]
    rows.append(("uniform sky, L = 1", SunAndSky((0.0, 1.0, 0.0), (0.0,) * 3, (1.0,) * 3), 0.5 * (1 - math.log(2))))
    for name, light, exact in rows:
        ref = centre(reference_render(volume, view, [light], spp=4096, exposure="none"))
        torch_ss = centre(render_single_scatter(volume, view, [light], exposure="none"))
        ours = [centre(render_scatter_march(volume, view, [light], exposure="none", steps_per_voxel=m)) for m in (2, 4)]
        print(f"| {name} | {exact:.3f} | {ref:.3f} | {torch_ss:.3f} | {ours[0]:.3f} | {ours[1]:.3f} |")


def blob_and_box() -> None:
    volume = blob_and_box()
    cases = [("front", FRONT, "sun above", SUN_ABOVE), ("front", FRONT, "sun oblique", SUN_OBLIQUE),
             ("oblique", OBLIQUE, "sun at the horizon", HORIZON),
             ("oblique", OBLIQUE, "sun behind", sun(tuple(-a for a in OBLIQUE))),
             ("front", FRONT, "sky alone", SKY), ("oblique", OBLIQUE, "sky alone", SKY)]
    configs = [("torch formation (m = 4, shadow 2, spp 4)",
                lambda w, l: render_single_scatter(volume, w, l, exposure="none", spp=4))]
    for m, spp in ((2, 1), (2, 4), (4, 4)):
        configs.append((f"this, m = {m}, spp {spp}", lambda w, l, m=m, spp=spp: render_scatter_march(
            volume, w, l, exposure="none", steps_per_voxel=m, spp=spp)))
    block = lambda im: F.avg_pool2d(im, 4)
    refs = []
    for _, view, _, light in cases:
        renders = torch.stack([block(reference_render(volume, torch.tensor([view]), [light], spp=512, seed=s,
                                                      exposure="none")[0, :3]) for s in range(8)])
        refs.append((renders.mean(0), renders.std(0) / math.sqrt(len(renders))))
    print("\n### A soft blob beside a dense box, 16³: image total vs volpath / mean z² of 4 × 4 blocks\n")
    print("| formation | " + " | ".join(f"{v}, {l}" for v, _, l, _ in cases) + " |")
    print("|---" * (len(cases) + 1) + "|")
    for name, f in configs:
        cells = []
        for (_, view, _, light), (mean, se) in zip(cases, refs):
            ours = block(f(torch.tensor([view]), [light])[0, :3])
            rel = float((ours - mean).sum() / mean.sum())
            z2 = float((((ours - mean) / se.clamp_min(1e-6)) ** 2).mean())
            cells.append(f"{100 * rel:+.1f} % / {z2:.0f}")
        print(f"| {name} | " + " | ".join(cells) + " |")


def cost(repeats: int) -> None:
    device = variant_device()                                 # cuda under cuda_ad_rgb: every formation there
    print(f"\n### Seconds per forward + backward, 8 pairs (median of {repeats}, interleaved, one run; variant "
          f"{ensure_variant().variant()}, on {device})\n")
    print("| N | EA marcher | torch formation | this (m = 2, spp 1) | of which light volumes | ratio to the EA marcher | "
          "the camera pass alone (this − light volumes) to the EA marcher | the light volumes to the EA marcher |")
    print("|---|---|---|---|---|---|---|---|")
    for n in (32, 64):
        g = torch.Generator().manual_seed(n)
        volume = (torch.rand(8, 4, n, n, n, generator=g) * 0.5).to(device)
        views = F.normalize(torch.randn(8, 3, generator=g), dim=-1)
        lights = LightBatch.of([sample_sun_and_sky(np.random.default_rng([n, i])) for i in range(8)])

        def step(f):
            v = volume.clone().requires_grad_()
            sync()
            t0 = time.perf_counter()
            f(v).sum().backward()                             # both backward passes end in torch
            sync()                                           # queued CUDA work and Dr.Jit launches
            return time.perf_counter() - t0

        runs = {"ea": lambda v: render(v, views, "ea", "mitsuba"),
                "this": lambda v: render_scatter_march(v, views, lights),
                "light": lambda v: light_packet(v, lights)}
        if n == 32:
            runs["torch"] = lambda v: render_single_scatter(v, views, lights)
        for f in runs.values():
            step(f)                                            # warm-up: kernels, allocator
        times = {k: [] for k in runs}
        for _ in range(repeats):
            for k, f in runs.items():
                times[k].append(step(f))
        t = {k: statistics.median(v) for k, v in times.items()}
        torch_cell = f"{t['torch']:.3f}" if "torch" in t else "—"
        print(f"| {n}³ | {t['ea']:.4f} | {torch_cell} | {t['this']:.3f} | {t['light']:.3f} | "
              f"{t['this'] / t['ea']:.1f}× | {(t['this'] - t['light']) / t['ea']:.1f}× | {t['light'] / t['ea']:.1f}× |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cost-only", action="store_true", help="only the third table (seconds)")
    ap.add_argument("--repeats", type=int, default=7, help="timings per formation and size (their median)")
    args = ap.parse_args()
    if not args.cost_only:
        half_space()
        blob_and_box()
    cost(args.repeats)


if __name__ == "__main__":
    main()
