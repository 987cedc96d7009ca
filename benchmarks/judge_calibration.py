"""Benchmark: does the judge of photo runs (evaluate/judge.py) order runs as the ground truth does?

    .venv/bin/python benchmarks/judge_calibration.py [--steps 1500] [--snapshots 0 100 300 600 1000 1500]

Photo-like data with ground truth: a procedural mushroom collection path traced under random skies
(``data.formation: physical``: lit, shaded, like photos). One run of the quickstart's configuration
trains on it; its moving-average model is taken at several steps (``--snapshots``: models of
differing quality, from untrained to trained), and the billboard of each image is added as one
more "run" (perfect at the input view, a card from the side). Each is scored on the held-out
images (shapes no run saw) twice:

- by the ground truth: 3D IoU against the truth in the input frame, and the DSSIM of EA re-renders
  of reconstruction and truth from 10 random views (``protocol.rerender_views``), plus the
  novel-view MAE and IoU of ``held_out_scores``;
- by the judge, which sees only images: the two-sample critic per band (trained on the run's
  training images and their reconstructions' renders), roughness, ΔE and coverage of the side
  and back views.

Prints both tables and Spearman's rank correlation of each judge figure with 3D IoU (sign flipped,
so +1 means "orders runs as 3D IoU does") and with the re-render DSSIM. Figures only.
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import numpy as np
import torch
from scipy.stats import spearmanr

from mitsuba_platonic.config import load_config
from mitsuba_platonic.evaluate import held_out_truths
from mitsuba_platonic.evaluate import metrics as M
from mitsuba_platonic.evaluate.judge import judge, judge_table, stats_table
from mitsuba_platonic.evaluate.protocol import billboard, rerender_views
from mitsuba_platonic.quickstart.procedural import CONFIG
from mitsuba_platonic.render import render
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer

#: Judge figures, and whether a higher value means a worse run (then ρ is taken as is).
JUDGE_FIGURES = {"c2st_novel": "two-sample accuracy, near + side + back", "c2st_side": "two-sample accuracy, side",
                 "roughness_side": "side roughness / input view's", "delta_e_side": "side ΔE",
                 "sliced_w1_side": "side SW₁", "c2st_input": "two-sample accuracy, input view"}


def truth_scores(reconstruct, data, limit: int) -> dict:
    """3D IoU and EA re-render DSSIM against the ground truth (module docstring)."""
    images, records = data.held_out[:limit], data.held_out_records[:limit]
    with torch.no_grad():
        recon = reconstruct(images).cpu().clamp(0, 1)
    truths = held_out_truths(records, "ea")
    iou, dssim = [], []
    for k, (v, t) in enumerate(zip(recon, truths)):
        iou.append(M.volume_iou(v, t))
        views = rerender_views(10, seed=k)
        with torch.no_grad():
            a = render(v[None].expand(10, -1, -1, -1, -1).contiguous(), views, "ea")
            b = render(t[None].expand(10, -1, -1, -1, -1).contiguous(), views, "ea")
        dssim.append(np.mean([M.dssim(x, y) for x, y in zip(a, b)]))
    return {"iou_3d": float(np.mean(iou)), "dssim": float(np.mean(dssim))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--snapshots", type=int, nargs="+", default=[0, 100, 300, 600, 1000, 1500])
    ap.add_argument("--shapes", type=int, default=80, help="shapes in the path-traced collection (4 views each)")
    ap.add_argument("--cache", type=Path, default=Path("data/bench_judge"))
    ap.add_argument("--limit", type=int, default=32, help="held-out images scored")
    ap.add_argument("--judge-steps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    cfg = load_config(CONFIG, [f"data.cache={args.cache}", "data.formation=physical", f"data.n_shapes={args.shapes}",
                               f"run.seed={args.seed}"])
    t0 = time.perf_counter()
    data = load_training_data(cfg, progress=True)
    print(f"collection: {len(data.images)} training, {len(data.held_out)} held-out images "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    snaps = {}
    t0 = time.perf_counter()
    for s in range(max(args.snapshots) + 1):
        if s in args.snapshots:
            snaps[f"step {s}"] = copy.deepcopy(trainer.inference_model).eval()
        if s < max(args.snapshots):
            trainer.step(s)
    print(f"trained {max(args.snapshots)} steps in {time.perf_counter() - t0:.0f} s", flush=True)
    # (name, input-frame volumes for the truth, what the judge reconstructs with: upright volumes and elevations)
    methods = [(name, m.reconstruct, m.reconstruct_upright) for name, m in snaps.items()]
    billboards = (lambda x: torch.stack([billboard(i) for i in x]))
    methods.append(("billboard", billboards, billboards))
    train_images = data.images[:256]
    held = data.held_out[:args.limit]
    rows = []
    for name, fn, upright in methods:
        t0 = time.perf_counter()
        truth = truth_scores(fn, data, args.limit)
        j = judge(upright, train_images, held, cfg.render, seed=args.seed, steps=args.judge_steps)
        summary = j.summary()
        summary["c2st_novel"] = float(np.mean([summary[f"c2st_{b}"] for b in ("near", "side", "back")]))
        rows.append((name, truth, j, summary))
        print(f"  {name}: 3D IoU {truth['iou_3d']:.3f}, DSSIM {truth['dssim']:.4f}, two-sample novel "
              f"{summary['c2st_novel']:.3f} ({time.perf_counter() - t0:.0f} s)", flush=True)
    print("\n| run | 3D IoU | re-render DSSIM (EA, 10 views) |\n|---|---|---|")
    for name, truth, _, _ in rows:
        print(f"| {name} | {truth['iou_3d']:.3f} | {truth['dssim']:.4f} |")
    print()
    print(judge_table([(n, j) for n, _, j, _ in rows]))
    print()
    print(stats_table([(n, j) for n, _, j, _ in rows]))
    print("\n| judge figure | ρ with −3D IoU | ρ with DSSIM |\n|---|---|---|")
    iou = -np.array([t["iou_3d"] for _, t, _, _ in rows])
    dssim = np.array([t["dssim"] for _, t, _, _ in rows])
    for key, label in JUDGE_FIGURES.items():
        vals = np.array([np.nan if s.get(key) is None else s[key] for _, _, _, s in rows], dtype=float)
        ok = np.isfinite(vals)
        r1 = spearmanr(vals[ok], iou[ok]).statistic if ok.sum() > 2 else float("nan")
        r2 = spearmanr(vals[ok], dssim[ok]).statistic if ok.sum() > 2 else float("nan")
        print(f"| {label} | {r1:+.2f} | {r2:+.2f} |" + ("" if ok.all() else f" ({ok.sum()} runs with a value)"))


if __name__ == "__main__":
    main()
