"""Benchmark: how much does the judge's verdict on one photo run move with the judge's own seed?

    .venv/bin/python benchmarks/judge_noise.py RUN [RUN ...] [--critics 10] [--seeds 5] [--shared-views] [--data-path DIR]

For each photo run it judges the same reconstructions (``evaluate/judge.py``, the object's turntable)
``--seeds`` times, at judge seeds 0, 1000, 2000, …, each time with ``--critics`` critics; each critic
trains on renders at its own random views (as ``platonic evaluate`` does) or, with
``--shared-views``, all on one set (as the judge did before). It prints the mean and the range
(max − min) over the judge seeds of the near, side and back accuracies, the share of held-out
photos called photos, and the side and back AUCs: the range is the judge's own noise, which a
difference between runs must exceed to mean anything. Figures only.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.evaluate import judge as J
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.model import Model

KEYS = [("c2st_near", "acc. near"), ("c2st_side", "acc. side"), ("c2st_back", "acc. back"),
        ("c2st_photo_pass", "photos passed"), ("c2st_auc_side", "AUC side"), ("c2st_auc_back", "AUC back")]


def shared_views(model: Model, train, test, settings, seed: int, critics: int) -> dict:
    """The judge's two-sample figures with every critic trained on one set of random views (seeded)."""
    vt, θt = model.reconstruct_upright(train)
    vs, θs = model.reconstruct_upright(test)
    renders = J.random_renders(vt.cpu().clamp(0, 1), θt.cpu(), J.TRAIN_VIEWS, settings, seed)
    table = J.turntable_renders(vs.cpu().clamp(0, 1), θs.cpu(), J.SCORE_AZIMUTHS, settings, seed)
    bands = {name: table[[i for i, a in enumerate(J.SCORE_AZIMUTHS) if J.band_of(a) == name]].flatten(0, 1)
             for name, _, _ in J.BANDS}
    out = J.two_sample_test(train, renders, test, bands, seed, repeats=critics)
    return J.Judgement(out).summary()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--critics", type=int, default=J.CRITIC_REPEATS)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--shared-views", action="store_true", help="every critic learns from one set of random views")
    ap.add_argument("--data-path", default=None)
    args = ap.parse_args()
    views = "one shared set of views" if args.shared_views else "each its own views"
    print(f"| run | critics | {' | '.join(name for _, name in KEYS)} |\n|---|---|" + "---|" * len(KEYS))
    for run in args.runs:
        ckpt = read_checkpoint(run)
        cfg = checkpoint_config(ckpt)
        model = model_from_checkpoint(Model, ckpt, cfg)
        train, test, _ = photo_splits(cfg, args.data_path)
        held = model.reconstruct_upright(test)
        rows = []
        for s in range(0, 1000 * args.seeds, 1000):
            if args.shared_views:
                m = shared_views(model, train, test, cfg.render, s, args.critics)
            else:                                             # as platonic evaluate judges: each critic its own views
                m = J.judge(model.reconstruct_upright, train, test, cfg.render, seed=s, repeats=args.critics,
                            test_volumes=held).summary()
            rows.append([m[k] for k, _ in KEYS])
        r = np.array(rows)
        cells = " | ".join(f"{mean:.3f} (range {hi - lo:.3f})" for mean, lo, hi in zip(r.mean(0), r.min(0), r.max(0)))
        print(f"| {run.name} | {args.critics}, {views} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
