"""Benchmark: can a discriminator tell the quickstart's renders from its photos, trained alone?

Prints figures only (no assertions), measured in one run:

    .venv/bin/python lab/scripts/d_probe.py [--g-steps 1000] [--d-steps 600] [--cache data/bench_defaults]

Trains the quickstart (``configs/quickstart.yaml``, seed 0) for ``--g-steps`` steps, freezes E and
G, and then trains a *fresh* D alone for ``--d-steps`` updates (batch 8, Adam, the trainer's
non-saturating loss) on training photos against G's renders of other training photos, either at
the input view or at random views (p_view: the sphere). Each D is then scored on held-out photos
against renders of held-out reconstructions, at both kinds of view: its hard accuracy
½(share of photos with logit > 0 + share of renders with logit < 0), over 8 batches of 16.
Renders rounded to 8 bits, as the photos are stored, are scored too ("8-bit"). Also printed: how
the held-out renders at the input view differ from their photos (colour spread, opaque pixels).

In training, D never gets far from chance (docs/training.md, "A discriminator that never
learns"): this separates "nothing tells the renders apart" from "the training dynamics keep D
from learning what does".
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.model import critic_config
from mitsuba_platonic.networks.nets import Discriminator, init_critic_he, init_weights
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.losses import d_loss
from mitsuba_platonic.train.trainer import Trainer
from mitsuba_platonic.views import front_view, sample_views
from common import add_preset_argument, config_path, expand

CONFIG = config_path("quickstart")

#: The probed discriminators: (initialisation, learning rate)
CRITICS = (("he", 1e-4), ("dcgan", 2e-5))
KINDS = ("input view", "random views")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--g-steps", type=int, default=1000, help="quickstart training steps before the probe")
    ap.add_argument("--d-steps", type=int, default=600, help="updates of each probed D")
    ap.add_argument("--cache", type=Path, default=Path("data/bench_defaults"))
    ap.add_argument("--threads", type=int, default=2, help="torch threads")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a config override of the quickstart's")
    add_preset_argument(ap)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    cfg = load_config(CONFIG, [f"data.cache={args.cache}", *expand(args.presets, args.overrides)])
    data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    t0 = time.perf_counter()
    for step in range(args.g_steps):
        trainer.step(step)
    print(f"# quickstart trained {args.g_steps} steps ({time.perf_counter() - t0:.0f} s); each D below trains "
          f"{args.d_steps} updates alone against the frozen G", flush=True)
    E, G = trainer.nets["E"], trainer.nets["G"]
    E.eval()
    G.eval()

    def renders(photos: torch.Tensor, kind: str, g: torch.Generator, eight_bit: bool = False) -> torch.Tensor:
        with torch.no_grad():
            views = front_view(len(photos)) if kind == "input view" else sample_views(len(photos), "sphere", seed=g)
            image = trainer.render(G(E(photos)), views, 0)
        return torch.round(image * 255) / 255 if eight_bit else image

    photos, held = trainer.images, data.held_out
    g_stats = torch.Generator().manual_seed(3)
    for name, images in (("held-out photos", held[:64]), ("their renders at the input view",
                                                           renders(held[:64], "input view", g_stats))):
        alpha = images[:, 3]
        covered = alpha > 0.5
        colour = (images[:, :3] / alpha.clamp(min=1e-3)[:, None]).permute(1, 0, 2, 3)[:, covered]
        print(f"# {name}: colour std over covered pixels (R, G, B) "
              f"{', '.join(f'{x:.3f}' for x in colour.std(dim=1).tolist())}, "
              f"share of covered pixels with alpha > 0.99: {float((alpha[covered] > 0.99).float().mean()):.3f}")
    print("| D (init, lr) | trained on renders at | held-out accuracy: input view | 8-bit | random views | 8-bit |")
    print("|---|---|---|---|---|---|")
    for init, lr in CRITICS:
        for kind in KINDS:
            torch.manual_seed(0)
            D = Discriminator(critic_config(cfg))
            D.apply(init_weights)
            if init == "he":
                D.apply(init_critic_he)
            opt = torch.optim.Adam(D.parameters(), lr=lr, betas=tuple(cfg.train.betas))
            g = torch.Generator().manual_seed(1)
            for _ in range(args.d_steps):
                real = photos[torch.randint(len(photos), (8,), generator=g)]
                fake = renders(photos[torch.randint(len(photos), (8,), generator=g)], kind, g)
                loss = d_loss(cfg.train.loss, D(real), D(fake))
                opt.zero_grad()
                loss.backward()
                opt.step()
            scores = []
            for test_kind in KINDS:
                for eight_bit in (False, True):
                    g_test = torch.Generator().manual_seed(2)
                    acc = []
                    with torch.no_grad():
                        for _ in range(8):
                            i = torch.randint(len(held), (16,), generator=g_test)
                            j = torch.randint(len(held), (16,), generator=g_test)
                            l_real, l_fake = D(held[i]), D(renders(held[j], test_kind, g_test, eight_bit))
                            acc.append(0.5 * float((l_real > 0).float().mean() + (l_fake < 0).float().mean()))
                    scores.append(f"{np.mean(acc):.3f}")
            print(f"| {init}, {lr:g} | {kind} | " + " | ".join(scores) + " |", flush=True)


if __name__ == "__main__":
    main()
