"""What the experiment scripts share (one module; not a script of its own; imports only the package's public names):

- :func:`config_path`: a shipped config by name (``d_probe.py``, ``train_through_light.py``);
- :data:`PRESETS`, :func:`add_preset_argument`, :func:`expand`: named groups of config overrides for the
  scripts that train the quickstart's config (``train_defaults.py``, ``d_probe.py``): the quickstart as it
  was when a table in docs/training.md was measured, so that table stays reproducible after a default
  moved on, e.g. ``--preset gated_d --preset transposed_g --preset dcgan_eg`` (before all three changes);
- :func:`upright_run`, :func:`upright_truth`: for the photo-sides scripts (``judge_truth.py``,
  ``silhouette_symmetry.py``, ``side_texture_share.py``), a photo run read back with its pose head, and its
  held-out photos' truth stood upright as the judge's turntable wants it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, List, Tuple

import torch

from mitsuba_platonic.config.loading import checkpoint_config, model_from_checkpoint
from mitsuba_platonic.evaluate.photo_truth import PhotoTruth, truth_pairs
from mitsuba_platonic.files.checkpoint import read_checkpoint
from mitsuba_platonic.model import Model
from mitsuba_platonic.render.pytorch.closed_form import tilt


def upright_run(run: Path) -> Tuple[Model, Any]:
    """(model, config) of a photo run folder or checkpoint file (one read; the config without retired
    keys); exits naming the run if it has no pose head (the judge's turntable turns about the vertical)."""
    ckpt = read_checkpoint(run)
    model, cfg = model_from_checkpoint(Model, ckpt), checkpoint_config(ckpt)
    if model.P is None:
        raise SystemExit(f"{run}: expected a run with train.pose elevation (the turntable turns about the vertical)")
    return model, cfg


def upright_truth(model: Model, cfg: Any) -> Tuple[List[PhotoTruth], torch.Tensor, torch.Tensor]:
    """(pairs, volumes, elevations): each held-out photo's truth (``photo_truth.truth_pairs``: framed on the
    reconstruction's grid) stood upright at the photo's true elevation θ, ``tilt(truth, −θ)`` clipped to
    [0, 1], and θ in degrees (float64), as ``Model.reconstruct_upright`` gives the model's."""
    pairs = list(truth_pairs(model, cfg))
    θ = torch.tensor([math.radians(p.elevation) for p in pairs], dtype=torch.float64)
    upright = tilt(torch.stack([p.truth for p in pairs]), -θ).clamp(0.0, 1.0)
    return pairs, upright, torch.rad2deg(θ)


#: The repository's root (this file is lab/scripts/common.py).
ROOT = Path(__file__).resolve().parents[2]


def config_path(name: str) -> Path:
    """The shipped config ``configs/NAME.yaml``."""
    return ROOT / "configs" / f"{name}.yaml"


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
                    help="a named group of overrides applied before --set (lab/scripts/common.py): "
                         "the quickstart as it was for the older tables of docs/training.md")


def expand(presets: List[str], overrides: List[str]) -> List[str]:
    """The presets' overrides, in the order given, then ``overrides`` (which win)."""
    return [o for p in presets for o in PRESETS[p]] + list(overrides)
