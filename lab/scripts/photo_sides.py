"""Experiment script: a photo run on a rendered collection turned about the object's true axis, beside its truth.

    .venv/bin/python lab/scripts/photo_sides.py RUN OUT [--photos 6]

``RUN`` is a photo run trained on a rendered collection's ``images/`` (``benchmarks/photo_suite.py``
makes them under ``OUT/runs``). Writes ``OUT/turntable.png``, one row per held-out photo (the first
``--photos``): the photo, the reconstruction's EA renders at φ = 0°, 45°, 90°, 180° and −90° about
the object's true vertical axis at the photo's true elevation, and the framed truth's at 90°,
180° and −90° (``evaluate/photo_truth.py`` frames it), over white. Prints, as means over the held-out
photos, the shares of the truth's side silhouette (α ≥ ½ at ±90°) that the reconstruction leaves
empty ("holes") or covers beyond it ("extra"), and the thickness (``photo_truth.thickness``).
Figures and a picture only; lab/photo-sides.md reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
import yaml
from PIL import Image

from mitsuba_platonic.config import config_from_dict
from mitsuba_platonic.config.retired import without_retired
from mitsuba_platonic.evaluate.photo_truth import thickness, truth_pairs, turntable_in_camera
from mitsuba_platonic.model import Model
from mitsuba_platonic.render import render

AZIMUTHS = (0.0, 45.0, 90.0, -90.0, 180.0)       # the reconstruction's columns, then the truth's at the last three


def srgb_tile(image: torch.Tensor) -> np.ndarray:
    """A premultiplied linear RGBA image ``(4, H, W)`` over white, sRGB, ``(H, W, 3)`` uint8."""
    rgb = image[:3].float() + (1.0 - image[3:4].float())
    rgb = torch.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb.clamp_min(1e-8) ** (1 / 2.4) - 0.055)
    return (rgb.clamp(0, 1).permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--photos", type=int, default=6)
    args = ap.parse_args()
    cfg = config_from_dict(without_retired(yaml.safe_load((args.run / "config.yaml").read_text())))   # a retired key at its off value is dropped
    model = Model.from_checkpoint(args.run)
    rows, holes, extra, thick = [], [], [], []
    for k, pair in enumerate(truth_pairs(model, cfg)):
        views = turntable_in_camera(pair.elevation, AZIMUTHS)
        with torch.no_grad():
            r_img = render(pair.reconstruction[None].expand(len(views), -1, -1, -1, -1).contiguous(), views, "ea")
            t_img = render(pair.truth[None].expand(len(views), -1, -1, -1, -1).contiguous(), views, "ea")
        side_r, side_t = r_img[2:4, 3] >= 0.5, t_img[2:4, 3] >= 0.5       # φ = ±90°
        holes.append(float((side_t & ~side_r).sum() / side_t.sum()))
        extra.append(float((side_r & ~side_t).sum() / side_t.sum()))
        thick.append(thickness(pair.reconstruction, pair.truth))
        if k < args.photos:
            rows.append(np.concatenate([srgb_tile(pair.photo)] + [srgb_tile(i) for i in r_img]
                                       + [srgb_tile(i) for i in t_img[2:]], axis=1))
    args.out.mkdir(parents=True, exist_ok=True)
    sheet = Image.fromarray(np.concatenate(rows, axis=0))
    sheet.resize((sheet.width * 3, sheet.height * 3), Image.NEAREST).save(args.out / "turntable.png")
    print(f"{args.run}: side holes {np.mean(holes):.3f}, side extra {np.mean(extra):.3f}, "
          f"thickness {np.mean(thick):.2f} (over {len(thick)} held-out photos)")
    print("columns: photo | reconstruction at 0°, 45°, 90°, −90°, 180° | truth at 90°, −90°, 180°")


if __name__ == "__main__":
    main()
