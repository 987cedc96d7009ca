"""Named groups of config overrides for the benchmarks that train the quickstart's config
(``train_defaults.py``, ``d_probe.py``): the quickstart as it was when a table in
docs/training.md was measured, so that table stays reproducible after a default moved on.

    --preset gated_d --preset transposed_g --preset dcgan_eg     # the quickstart before all three changes
"""

from __future__ import annotations

from typing import Dict, List

PRESETS: Dict[str, List[str]] = {
    # the paper's G: every ×2 stage a transposed convolution (the quickstart's before resize_last)
    "transposed_g": ["model.upsample=transposed"],
    # the paper's D set-up: DCGAN initialisation, lr_D 2e-5, the soft-accuracy gate at 0.6, no R1
    # (the quickstart's before the R1 critic)
    "gated_d": ["model.critic_init=dcgan", "train.lr_d=2e-5", "train.d_gate=0.6", "train.r1_weight=0"],
    # E and G from the DCGAN initialisation, D as wide as they are (the quickstart's before
    # model.init: he and model.critic_width: 32)
    "dcgan_eg": ["model.init=dcgan", "model.critic_width=null"],
    # the paper's view-space reconstruction: G's volume in the input camera's frame, no pose head,
    # and the trained weights scored, not their moving average (the quickstart's before
    # train.pose: elevation and train.ema: 0.99)
    "view_space": ["train.pose=input", "train.pose_weight=0", "train.ema=null"],
}


def add_preset_argument(ap) -> None:
    """``--preset NAME`` (repeatable) on an argparse parser; see :func:`expand`."""
    ap.add_argument("--preset", dest="presets", action="append", default=[], choices=sorted(PRESETS),
                    help="a named group of overrides applied before --set (lab/scripts/presets.py): "
                         "the quickstart as it was for the older tables of docs/training.md")


def expand(presets: List[str], overrides: List[str]) -> List[str]:
    """The presets' overrides, in the order given, then ``overrides`` (which win)."""
    return [o for p in presets for o in PRESETS[p]] + list(overrides)
