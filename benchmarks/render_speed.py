"""Benchmark: time per image of both renderers, and the Mitsuba marcher's speed/accuracy trade.

Prints figures only (no assertions). Ratios are measured within one run on one machine.

    .venv/bin/python benchmarks/render_speed.py [--resolutions 32 64] [--batch 8] [--repeats 3]

Part 1: forward and forward+backward time per image, closed form vs Mitsuba, per model.
Part 2 (``--trade``): Mitsuba options (step, spp, jitter, filter, termination) against a
fine-step supersampled reference: time per image and mean/max absolute error.
"""

from __future__ import annotations

import argparse
import platform
import time
from typing import Callable, Dict, List

import torch

import mitsuba_platonic as mp
from mitsuba_platonic import views as V
from mitsuba_platonic.render.variant import ensure_variant
from mitsuba_platonic.volume import test_volume


def best_time(fn: Callable[[], None], repeats: int) -> float:
    fn()  # warm-up: kernel compilation, caches
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def speed(resolutions: List[int], batch: int, repeats: int) -> None:
    print(f"\n## Time per image (ms), batch {batch}, best of {repeats}, random views, 'figure' volume")
    print(f"{'N':>4} {'model':>5} | {'closed fwd':>10} {'closed f+b':>10} | {'mitsuba fwd':>11} "
          f"{'mitsuba f+b':>11} | {'fwd ratio':>9} {'f+b ratio':>9}   (ratio = mitsuba / closed form)")
    for n in resolutions:
        for model in ["vh", "ao", "ea"]:
            vol = test_volume(n, "figure", model).expand(batch, -1, -1, -1, -1).contiguous()
            views = V.sample_views(batch, seed=1)
            row: Dict[str, float] = {}
            for backend in ["closed_form", "mitsuba"]:
                def fwd():
                    with torch.no_grad():
                        mp.render(vol, views, model, backend)

                def fwd_bwd():
                    x = vol.clone().requires_grad_()
                    mp.render(x, views, model, backend).sum().backward()

                row[backend + "_f"] = best_time(fwd, repeats) / batch * 1e3
                row[backend + "_fb"] = best_time(fwd_bwd, repeats) / batch * 1e3
            print(f"{n:>4} {model:>5} | {row['closed_form_f']:>10.2f} {row['closed_form_fb']:>10.2f} | "
                  f"{row['mitsuba_f']:>11.2f} {row['mitsuba_fb']:>11.2f} | "
                  f"{row['mitsuba_f'] / row['closed_form_f']:>9.3f} {row['mitsuba_fb'] / row['closed_form_fb']:>9.3f}")


def trade(n: int, batch: int, repeats: int) -> None:
    vol = test_volume(n, "figure", "ea").expand(batch, -1, -1, -1, -1).contiguous()
    views = V.sample_views(batch, seed=2)
    reference = mp.render(vol, views, "ea", "mitsuba", step=0.125, spp=16)
    closed = mp.render(vol, views, "ea", "closed_form")
    print(f"\n## Speed/accuracy trade, EA at {n}³, batch {batch}: error against Mitsuba "
          f"step 1/8, 16 spp (reference)")
    print(f"{'configuration':<44} {'ms/image fwd':>12} {'mean |err|':>11} {'max |err|':>10}")

    def line(name: str, fn: Callable[[], torch.Tensor]) -> None:
        out = fn()
        t = best_time(lambda: fn(), repeats) / batch * 1e3
        err = (out - reference).abs()
        print(f"{name:<44} {t:>12.2f} {float(err.mean()):>11.2e} {float(err.max()):>10.2e}")

    with torch.no_grad():
        line("closed form, trilinear", lambda: mp.render(vol, views, "ea", "closed_form"))
        line("closed form, nearest", lambda: mp.render(vol, views, "ea", "closed_form", filter="nearest"))
        configs = [
            dict(step=1.0), dict(step=1.0, filter="nearest"), dict(step=2.0), dict(step=0.5),
            dict(step=0.25), dict(step=1.0, spp=4), dict(step=1.0, spp=4, jitter=True),
            dict(step=2.0, spp=4, jitter=True), dict(step=1.0, termination=1e-3),
            dict(step=1.0, termination=1e-2),
        ]
        for c in configs:
            line("mitsuba " + ", ".join(f"{k}={v}" for k, v in c.items()),
                 lambda c=c: mp.render(vol, views, "ea", "mitsuba", **c))
    print(f"(closed form vs Mitsuba step 1: max |diff| = {float((closed - mp.render(vol, views, 'ea', 'mitsuba')).abs().max()):.2e})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--trade", action="store_true", help="also run the speed/accuracy trade table")
    ap.add_argument("--threads", type=int, default=None, help="torch and Dr.Jit threads (default: all)")
    args = ap.parse_args()
    mi = ensure_variant()
    import drjit as dr
    if args.threads:
        torch.set_num_threads(args.threads)
        dr.set_thread_count(args.threads)
    print(f"# mitsuba-platonic render benchmark: {platform.processor() or platform.machine()}, "
          f"torch {torch.__version__} ({torch.get_num_threads()} threads), mitsuba {mi.__version__} "
          f"variant {mi.variant()}")
    speed(args.resolutions, args.batch, args.repeats)
    if args.trade:
        trade(max(args.resolutions), args.batch, args.repeats)


if __name__ == "__main__":
    main()
