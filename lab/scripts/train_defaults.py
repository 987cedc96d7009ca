"""Benchmark: training choices (D gate, lr_D, normalisation, views per step, …), judged on held-out shapes.

    .venv/bin/python lab/scripts/train_defaults.py [--steps 1000] [--variants ungated,gate06,...]

Each variant trains the quickstart's configuration (``configs/quickstart.yaml``: mushrooms,
32³, EA through the marcher, reconstruction) for ``--steps`` steps from the same seed (``--seeds``: several), on the
same collection, then scores the held-out images (shapes no run saw) as the quickstart's report
does (:func:`mitsuba_platonic.evaluate.held_out_scores`: MAE and silhouette IoU at the input view
and at novel views, and the billboard), and in 3D against the ground truth in the input frame
(:mod:`mitsuba_platonic.evaluate.metrics`: volume IoU, the density-weighted chamfer distance,
``depth_stripes``, ``half_opacity_depth`` and ``best_tilt``: the pose error, set beside the input
camera's elevation). It also reports how D was trained: the share of
steps on which D was updated, and D's soft and hard accuracy. Prints a Markdown table; figures
only, nothing asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.evaluate.protocol import held_out_scores, held_out_truths
from mitsuba_platonic.evaluate import metrics as M
from mitsuba_platonic.data.render_collection import load_manifest
from mitsuba_platonic.evaluate.protocol import NOVEL_VIEWS
from mitsuba_platonic.networks.nets import Discriminator, init_weights
from mitsuba_platonic.render import render
from mitsuba_platonic.views import to_angles
from mitsuba_platonic.quickstart.procedural import CONFIG
from mitsuba_platonic.train.data import collection_folder, load_training_data
from mitsuba_platonic.train.losses import colour_tv
from mitsuba_platonic.train.trainer import Trainer
from common import PRESETS, add_preset_argument, expand

#: The view-space reconstruction the quickstart used before train.pose: elevation (the paper's); the
#: variants that only exist there (D's rolls, the 3D-supervised baselines) start from it
VIEW_SPACE = PRESETS["view_space"]

VARIANTS = {
    "default": [],                                                     # configs/quickstart.yaml as it is
    "ungated": ["train.d_gate=null"],                                  # the default before the gate fix
    "gate06_lrd1e-5": ["train.lr_d=1e-5"],                             # the authors' lr_D
    "gate06_lrd1e-4": ["train.lr_d=1e-4"],
    "ungated_lrd1e-4": ["train.d_gate=null", "train.lr_d=1e-4"],
    "gate06_batchnorm": ["model.norm=batch"],
    "views2": ["train.random_views=2"],                                # two random views per volume and step
    "views4": ["train.random_views=4"],
    "rec20": ["train.rec_weight=20.0"],
    "rec5": ["train.rec_weight=5.0"],
    "resize": ["model.upsample=resize"],                               # no transposed-convolution checkerboard
    "resize_views2": ["model.upsample=resize", "train.random_views=2"],
    "resize_last": ["model.upsample=resize_last"],                      # only G's last stage resized
    "resize_last_views2": ["model.upsample=resize_last", "train.random_views=2"],
    "d_kaiming": ["model.critic_init=he"],                             # He's initialisation of D
    "d_kaiming_lrd1e-4": ["model.critic_init=he", "train.lr_d=1e-4"],
    "d_kaiming_lrd1e-4_views4": ["model.critic_init=he", "train.lr_d=1e-4", "train.random_views=4"],
    "d_batchnorm": [],                                                 # the paper's D (_paper_d)
    "d_kaiming_lrd1e-4_gate08": ["model.critic_init=he", "train.lr_d=1e-4", "train.d_gate=0.8"],
    "d_kaiming_lrd1e-4_dsteps5": ["model.critic_init=he", "train.lr_d=1e-4", "train.d_steps=5"],
    "roll": [*VIEW_SPACE, "train.d_roll=uniform"],                                  # D's images turned (train/image_roll.py)
    "d_kaiming_lrd1e-4_roll": [*VIEW_SPACE, "model.critic_init=he", "train.lr_d=1e-4", "train.d_roll=uniform"],
    "d_kaiming_lrd1e-4_views4_roll": [*VIEW_SPACE, "model.critic_init=he", "train.lr_d=1e-4", "train.random_views=4",
                                      "train.d_roll=uniform"],
    # R1-regularised critics (train.r1_weight = γ) instead of, or besides, the gate
    "d_kaiming_lrd1e-4_r1_1_ungated": ["model.critic_init=he", "train.lr_d=1e-4", "train.r1_weight=1",
                                       "train.d_gate=null"],
    "d_kaiming_lrd1e-4_r1_10_ungated": ["model.critic_init=he", "train.lr_d=1e-4", "train.r1_weight=10",
                                        "train.d_gate=null"],
    "d_kaiming_lrd4e-4_r1_1_ungated": ["model.critic_init=he", "train.lr_d=4e-4", "train.r1_weight=1",
                                       "train.d_gate=null"],
    # the density-weighted colour TV prior on G (train.colour_tv), with the R1 critic
    "d_kaiming_lrd1e-4_r1_1_ungated_colour_tv0.1": ["model.critic_init=he", "train.lr_d=1e-4", "train.r1_weight=1",
                                                    "train.d_gate=null", "train.colour_tv=0.1"],
    "d_kaiming_lrd1e-4_r1_1_ungated_colour_tv1": ["model.critic_init=he", "train.lr_d=1e-4", "train.r1_weight=1",
                                                  "train.d_gate=null", "train.colour_tv=1"],
    # a moving average of E's and G's weights (train.ema), scored instead of the trained weights
    "ema0.99": ["train.ema=0.99"],
    "ema0.999": ["train.ema=0.999"],
    # the same E and G trained from 3D ground truth (the 3D-GAN's terms): what they can reach
    "gan3d_volume": [*VIEW_SPACE, "train.mode=gan3d", "train.rec_target=volume"],
    # He's initialisation of E and G (model.init), a wider D (model.critic_width)
    "init_he": ["model.init=he"],
    "init_he_gan3d_volume": [*VIEW_SPACE, "model.init=he", "train.mode=gan3d", "train.rec_target=volume"],
    "critic32": ["model.critic_width=32"],
    "init_he_critic32": ["model.init=he", "model.critic_width=32"],
    "init_he_critic64": ["model.init=he", "model.critic_width=64"],
    # D's reals turned by the tilt a right volume's random view has (train.d_roll, train/image_roll.py)
    "roll_matched": [*VIEW_SPACE, "train.d_roll=matched"],
    "roll_uniform": [*VIEW_SPACE, "train.d_roll=uniform"],
    # where G's volume stands (train.pose): the paper's view space, or upright and tilted by an
    # elevation the pose head reads, with and without the term on G's renders (λ_pose)
    "view_space": VIEW_SPACE,
    "pose_no_term": ["train.pose_weight=0"],
    "pose_weight0.3": ["train.pose_weight=0.3"],
    "pose_weight3": ["train.pose_weight=3"],
}


def _paper_d(trainer: Trainer) -> None:
    """Give the trainer the paper's D, with BatchNorm (G and E keep model.norm), drawn from the
    run's seed: no config key makes D's normalisation differ from G's."""
    torch.manual_seed(trainer.cfg.run.seed)
    d = Discriminator(dataclasses.replace(trainer.model.net, norm="batch"))
    d.apply(init_weights)
    trainer.nets["D"] = trainer.modules["D"] = d
    t = trainer.cfg.train
    trainer.opt_d = torch.optim.Adam(d.parameters(), lr=t.lr_d, betas=tuple(t.betas))


def view_diagnosis(model, cfg, data, limit: int = 64) -> dict:
    """Where novel views fail: per novel view (:data:`NOVEL_VIEWS`), the held-out silhouette IoU and
    the mean silhouette area of reconstruction minus truth (pixels); and the novel-view IoU on
    *training* images (``data.images`` holds them in the manifest's order, whose records give
    their ground truth), which tells underfitting (both low) from overfitting (training high)."""
    folder = collection_folder(cfg)
    n_train = max(1, int(round(cfg.data.split * cfg.data.n_shapes)))
    records = [{**r, "folder": str(folder)} for r in load_manifest(folder)["images"] if r["shape"] < n_train]
    out = {}
    for split, images, recs in (("held_out", data.held_out[:limit], data.held_out_records[:limit]),
                                ("train", data.images[:limit], records[:limit])):
        recon = model.reconstruct(images).cpu()
        iou, area, mae = np.zeros(len(NOVEL_VIEWS)), np.zeros(len(NOVEL_VIEWS)), np.zeros(len(NOVEL_VIEWS))
        for v, truth in zip(recon, held_out_truths(recs, "ea")):
            with torch.no_grad():
                a = render(v[None].expand(len(NOVEL_VIEWS), -1, -1, -1, -1).contiguous(), NOVEL_VIEWS, "ea")
                b = render(truth[None].expand(len(NOVEL_VIEWS), -1, -1, -1, -1).contiguous(), NOVEL_VIEWS, "ea")
            iou += [M.silhouette_iou(a[k:k + 1], b[k:k + 1]) for k in range(len(NOVEL_VIEWS))]
            mae += (a - b).abs().flatten(1).mean(1).numpy()
            area += ((a[:, 3] > M.SILHOUETTE_THRESHOLD).flatten(1).sum(1)
                     - (b[:, 3] > M.SILHOUETTE_THRESHOLD).flatten(1).sum(1)).numpy()
        out[split] = {"iou": iou / len(recon), "area": area / len(recon), "mae": mae / len(recon)}
    return out


def _centroid(volume: torch.Tensor) -> np.ndarray:
    """The density-weighted centre of a ``(C, N, N, N)`` volume, in voxels along its three axes
    (depth first: axis 0 runs along the input camera's rays)."""
    ρ = volume[-1].double()
    grid = torch.meshgrid(*[torch.arange(n, dtype=torch.float64) for n in ρ.shape], indexing="ij")
    return np.array([float((ρ * g).sum() / ρ.sum().clamp_min(1e-12)) for g in grid])


def volume_scores(model, data, limit: int = 64) -> dict:
    """Means over held-out images of 3D IoU and chamfer distance against the ground truth in the
    input frame, and of the reconstructions' depth stripes, half-opacity depth (voxels) and
    density-weighted colour TV (:func:`~mitsuba_platonic.train.losses.colour_tv`: speckle), with
    the truth's stripes and colour TV."""
    recon = model.reconstruct(data.held_out[:limit]).cpu()
    rows = []
    records = data.held_out_records[:limit]
    for v, truth, r in zip(recon, held_out_truths(records, "ea"), records):
        θ0 = float(to_angles(torch.tensor(r["view"]))[1])       # the input camera's elevation
        rows.append((M.volume_iou(v, truth), M.chamfer_distance(v, truth), M.depth_stripes(v),
                     M.half_opacity_depth(v), M.depth_stripes(truth), float(colour_tv(v[None])),
                     float(colour_tv(truth[None])), *(_centroid(v) - _centroid(truth)),
                     *M.best_tilt(v, truth), θ0))
    a = np.array(rows, dtype=np.float64)
    ok = np.isfinite(a[:, 10])                                # best_tilt: NaN where nothing overlaps
    β, θ0 = a[ok, 10], a[ok, 12]
    corr = float(np.corrcoef(β, θ0)[0, 1]) if len(β) > 1 and β.std() > 0 else float("nan")
    return {"iou_3d": float(a[:, 0].mean()), "chamfer": float(a[:, 1].mean()), "stripes": float(a[:, 2].mean()),
            "half_depth": float(np.nanmedian(a[:, 3])), "stripes_truth": float(a[:, 4].mean()),
            "colour_tv": float(a[:, 5].mean()), "colour_tv_truth": float(a[:, 6].mean()),
            "centroid_offset": a[:, 7:10].mean(0), "centroid_error": np.abs(a[:, 7:10]).mean(0),
            "tilt_error": float(np.abs(β).mean()), "tilt_iou": float(a[:, 11].mean()),
            "tilt_within_10": float((np.abs(β) <= 10.0).mean()), "tilt_undefined": int((~ok).sum()),
            "tilt_vs_elevation": corr, "tilt_minus_elevation": float(np.abs(β - θ0).mean()),
            "elevation": float(np.abs(a[:, 12]).mean()), **_elevation_scores(model, data.held_out[:limit], a[:, 12])}


def _elevation_scores(model, images: torch.Tensor, θ0: np.ndarray) -> dict:
    """For a model with a pose head (``train.pose: elevation``): the correlation of its estimated
    elevations θ̂ of ``images`` with their inputs' elevations ``θ0`` and the mean |θ̂ − θ₀|
    (degrees); else nothing."""
    if model.P is None:
        return {}
    θ̂ = model.estimate_elevation(images).cpu().double().numpy()
    corr = float(np.corrcoef(θ̂, θ0)[0, 1]) if θ̂.std() > 0 else float("nan")
    return {"estimate_vs_elevation": corr, "estimate_error": float(np.abs(θ̂ - θ0).mean())}


def run(name: str, overrides, steps: int, cache: Path, seed: int = 0) -> dict:
    cfg = load_config(CONFIG, [f"data.cache={cache}", f"run.seed={seed}", *overrides])
    data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    if name == "d_batchnorm":
        _paper_d(trainer)
    t0 = time.perf_counter()
    logs = [trainer.step(s) for s in range(steps)]
    seconds = time.perf_counter() - t0
    model = trainer.inference_model                          # the moving average with train.ema
    m = held_out_scores(model, data, cfg.render.model)
    m.update(volume_scores(model, data))
    m["views"] = view_diagnosis(model, cfg, data)
    if model is not trainer.model:                           # the same run's trained weights, for comparison
        m["trained"] = held_out_scores(trainer.model, data, cfg.render.model)
    d = "d" if "acc_d" in logs[0] else "d3"                   # the 3D-GAN ('gan3d') has only D3
    rec = "loss_rec" if "loss_rec" in logs[0] else "loss_rec3d"
    acc = np.array([o[f"acc_{d}"] for o in logs])
    hard = np.array([o[f"acc_{d}_hard"] for o in logs])
    return {"name": name, **m, "d_updated": float(np.mean([o[f"{d}_updated"] for o in logs])),
            "acc_soft": (acc.min(), acc.max()), "acc_last": float(acc[-250:].mean()), "hard_over_06": float((hard > 0.6).mean()),
            "loss_rec": float(np.mean([o[rec] for o in logs[-50:]])), "s_per_step": seconds / steps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--cache", type=Path, default=Path("data/bench_defaults"))
    ap.add_argument("--threads", type=int, default=2, help="torch threads")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a config override for every variant (before the variant's own), e.g. "
                         "model.critic_init=dcgan")
    add_preset_argument(ap)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="run.seed of each repetition (networks and batches; the collection stays the same)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rows = []
    print(f"{args.steps} steps per variant, quickstart config (32³, EA, the marcher)", flush=True)
    print("| variant | novel MAE | novel IoU | input MAE | input IoU | 3D IoU | CD | stripes | ½-opacity depth | "
          "rec loss (last 50) | D updated | soft acc range | soft acc, last 250 steps | hard acc > 0.6 | s/step |",
          flush=True)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    notes = []
    for name, seed in [(n, s) for n in args.variants.split(",") for s in args.seeds]:
        r = run(name, [*expand(args.presets, args.overrides), *VARIANTS[name]], args.steps, args.cache, seed)
        rows.append(r)
        if len(args.seeds) > 1:
            name = f"{name}, seed {seed}"
        print(f"| {name} | {r['novel_view_mae']:.4f} | {r['novel_view_iou']:.3f} | {r['input_view_mae']:.4f} | "
              f"{r['input_view_iou']:.3f} | {r['iou_3d']:.3f} | {r['chamfer']:.4f} | {r['stripes']:.3f} | "
              f"{r['half_depth']:.1f} | {r['loss_rec']:.4f} | {r['d_updated']:.2f} | "
              f"{r['acc_soft'][0]:.4f}–{r['acc_soft'][1]:.4f} | {r['acc_last']:.3f} | {r['hard_over_06']:.2f} | "
              f"{r['s_per_step']:.3f} |", flush=True)
        v = r["views"]
        notes.append(f"{name}: novel-view IoU per view (held-out) {np.round(v['held_out']['iou'], 3).tolist()}, "
                     f"MAE per view {np.round(v['held_out']['mae'], 4).tolist()}, "
                     f"colour TV {r['colour_tv']:.4f} (truth {r['colour_tv_truth']:.4f}), "
                     f"centroid − truth's (voxels; depth, then across) mean {np.round(r['centroid_offset'], 2).tolist()}, "
                     f"mean |·| {np.round(r['centroid_error'], 2).tolist()}, "
                     f"pose: best-aligning tilt |β| {r['tilt_error']:.1f}° (3D IoU there {r['tilt_iou']:.3f}, "
                     f"share within 10° {r['tilt_within_10']:.2f}; undefined for {r['tilt_undefined']}), "
                     f"corr(β, input elevation θ₀) {r['tilt_vs_elevation']:.2f}, |β − θ₀| {r['tilt_minus_elevation']:.1f}° "
                     f"(|θ₀| {r['elevation']:.1f}°), "
                     + (f"estimated elevation θ̂: corr(θ̂, θ₀) {r['estimate_vs_elevation']:.3f}, |θ̂ − θ₀| "
                        f"{r['estimate_error']:.1f}°, " if "estimate_error" in r else "")
                     + f"silhouette area − truth's (px) {np.round(v['held_out']['area'], 1).tolist()}; on training "
                     f"images: mean IoU {v['train']['iou'].mean():.3f}, per view {np.round(v['train']['iou'], 3).tolist()}"
                     + (f"; the trained weights (not the average): novel MAE {r['trained']['novel_view_mae']:.4f}, "
                        f"IoU {r['trained']['novel_view_iou']:.3f}, input MAE {r['trained']['input_view_mae']:.4f}, "
                        f"IoU {r['trained']['input_view_iou']:.3f}" if "trained" in r else ""))
    bb = rows[-1]
    print(f"| billboard | {bb['billboard_novel_view_mae']:.4f} | {bb['billboard_novel_view_iou']:.3f} | | | | | | | "
          f"| | | | | |")
    print(f"\nGround truth in the input frame: stripes {bb['stripes_truth']:.3f}")
    print("Novel views (azimuth, elevation): " + ", ".join(f"({round(float(a)) + 0}°, {round(float(e)) + 0}°)"
                                                         for a, e in zip(*to_angles(NOVEL_VIEWS))))
    print("\n".join(notes))


if __name__ == "__main__":
    main()
