"""Shared by the photo-sides experiment scripts (``judge_truth.py``, ``silhouette_symmetry.py``,
``side_texture_share.py``): a photo run read back with its pose head, and its held-out photos' truth stood
upright as the judge's turntable wants it. Not a script of its own."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, List, Tuple

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
