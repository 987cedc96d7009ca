"""Benchmark: the marcher batched (one launch per call) against one Mitsuba render per pair.

Prints figures only (no assertions); every ratio is measured within one run on one machine.

    .venv/bin/python benchmarks/render_speed.py [--resolutions 32 64] [--batch 8] [--repeats 3]

Per model and resolution, forward and forward + backward ms per image of: a plain
``affine_grid`` + ``grid_sample`` + ``cumprod`` EA layer (no tricks, a yardstick), the closed form
(``backend="closed_form"``), the marcher as one Mitsuba ``mi.render`` per (volume, view) pair
(``render_mitsuba``, the scene path), and the batched marcher (``backend="mitsuba"``); then the
marcher's forward on procedural volumes with and without its empty-space skipping. The whole
speed/accuracy trade of every option is ``platonic bench``'s job (docs/speed_accuracy.md).
"""

from __future__ import annotations

import argparse
import platform
from typing import Callable, Dict, List

import torch

import mitsuba_platonic as mp
from mitsuba_platonic import views as V
from mitsuba_platonic.bench import plain_ea
from mitsuba_platonic.bench.timing import best_of
from mitsuba_platonic.render.mitsuba.per_pair import render_mitsuba
from mitsuba_platonic.render.variant import ensure_variant
from mitsuba_platonic.volume import test_volume


def best_time(fn: Callable[[], None], repeats: int) -> float:
    """The best of ``repeats`` timed calls after one warm-up call (kernel compilation and recording)."""
    fn()
    return best_of(fn, repeats)


def speed(resolutions: List[int], batch: int, repeats: int) -> None:
    print(f"\n## ms per image, batch {batch}, best of {repeats}, random views, 'figure' volume "
          f"(last columns: speed-ups of the batched marcher, f+b)")
    names = {"plain": "plain layer", "closed_form": "closed form", "per_pair": "per-pair mi.render",
             "batched": "batched marcher"}
    print(f"{'N':>4} {'model':>5} | " + " | ".join(f"{v:>18} fwd / f+b" for v in names.values())
          + " | per-pair ÷ batched f+b | closed ÷ batched f+b")
    for n in resolutions:
        for model in ["vh", "ao", "ea"]:
            vol = test_volume(n, "figure", model).expand(batch, -1, -1, -1, -1).contiguous()
            views = V.sample_views(batch, seed=1)
            fns = {"closed_form": lambda x: mp.render(x, views, model, "closed_form"),
                   "per_pair": lambda x: render_mitsuba(x, views, model),
                   "batched": lambda x: mp.render(x, views, model, "mitsuba")}
            if model == "ea":
                fns = {"plain": lambda x: plain_ea(x, views), **fns}
            row: Dict[str, float] = {}
            for name, fn in fns.items():
                def fwd(fn=fn):
                    with torch.no_grad():
                        fn(vol)

                def fwd_bwd(fn=fn):
                    x = vol.clone().requires_grad_()
                    fn(x).sum().backward()

                row[name + "_f"] = best_time(fwd, repeats) / batch * 1e3
                row[name + "_fb"] = best_time(fwd_bwd, repeats) / batch * 1e3
            cells = [f"{row[k + '_f']:>12.2f} / {row[k + '_fb']:>7.2f}" if k + "_f" in row else f"{'—':>22}"
                     for k in names]
            print(f"{n:>4} {model:>5} | " + " | ".join(cells)
                  + f" | {row['per_pair_fb'] / row['batched_fb']:>22.2f} | {row['closed_form_fb'] / row['batched_fb']:>20.2f}",
                  flush=True)


def empty_space(resolutions: List[int], batch: int, repeats: int) -> None:
    """Forward ms per image of procedural volumes (mostly empty space, exact zeros) with the marcher's
    empty-space skipping and without it (``marcher.SKIP_EMPTY``), EA, random views."""
    import importlib
    from mitsuba_platonic.data.shapes.registry import generate
    M = importlib.import_module("mitsuba_platonic.render.drjit.marcher")
    print(f"\n## Empty-space skipping: forward ms per image, EA, batch {batch}, best of {repeats}, "
          f"{batch} shapes per class (exact: the images are equal to the last bit)")
    print(f"{'N':>4} {'class':>9} | occupied | {'skipping':>8} | {'every segment':>13} | speed-up")
    for n in resolutions:
        for cls in ["mushroom", "chair", "airplane"]:
            vol = torch.stack([generate(cls, seed, n) for seed in range(batch)])
            views = V.sample_views(batch, seed=1)

            def fwd():
                with torch.no_grad():
                    mp.render(vol, views, "ea", "mitsuba")

            times = {}
            for skip in (True, False):
                M.SKIP_EMPTY = skip
                try:
                    times[skip] = best_time(fwd, repeats) / batch * 1e3
                finally:
                    M.SKIP_EMPTY = True
            occupied = float((vol[:, -1] > 0).float().mean())
            print(f"{n:>4} {cls:>9} | {occupied:>8.3f} | {times[True]:>8.3f} | {times[False]:>13.3f} | "
                  f"{times[False] / times[True]:>7.2f}×", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="torch and Dr.Jit threads (default: all)")
    args = ap.parse_args()
    mi = ensure_variant()
    import drjit as dr
    if args.threads:
        torch.set_num_threads(args.threads)
        dr.set_thread_count(args.threads)
    print(f"# mitsuba-platonic render benchmark: {platform.processor() or platform.machine()}, "
          f"torch {torch.__version__} ({torch.get_num_threads()} threads), mitsuba {mi.__version__} "
          f"variant {mi.variant()} ({dr.thread_count()} threads)")
    speed(args.resolutions, args.batch, args.repeats)
    empty_space(args.resolutions, args.batch, args.repeats)


if __name__ == "__main__":
    main()
