"""Experiment script: how much of a photo run's side views shows the photo carried along the input rays?

    .venv/bin/python lab/scripts/side_texture_share.py RUN [RUN ...]

For a photo run with ``model.texture_turns: 4`` (``configs/photos.yaml``), a voxel's texture is the photo
carried along the input camera's rays where that camera sees it and the four turned cameras' reading
behind, blended by T_front, the transmittance towards the input camera
(``networks/photo_colours.texture_corrected``). This script renders the held-out photos'
reconstructions on the judge's turntable about the object's vertical (``evaluate/judge.py``) with
every voxel's colour replaced by the carried photo's weight in its texture, T_front, its density kept,
so that each pixel's colour is the EA-weighted share of its colour that is the carried photo:

    share = Σ_pixels Σ_k T_k a_k T_front,k / Σ_pixels α

and prints it per azimuth, over the whole silhouette and over the image's middle third of columns.
At 0° it is below 1 by the soft surfaces' depth; at 180° near 0. Figures only;
lab/photo-sides.md reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from mitsuba_platonic.evaluate import judge as J
from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.networks.photo_colours import in_g_frame, front_transmittance
from common import upright_run

AZIMUTHS = (0.0, 45.0, 90.0, -90.0, 180.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", type=Path, nargs="+")
    args = ap.parse_args()
    torch.set_num_threads(2)
    print("| run | " + " | ".join(f"{φ:+.0f}° (middle)" for φ in AZIMUTHS) + " |")
    print("|---" * (len(AZIMUTHS) + 1) + "|")
    for run in args.runs:
        model, cfg = upright_run(run)
        _, held, _ = photo_splits(cfg)
        volumes, elevations = model.reconstruct_upright(held)
        density = volumes[:, 3:].detach().float().cpu()
        θ = torch.deg2rad(elevations.detach().float().cpu())
        seen = in_g_frame(front_transmittance(density, θ), θ)
        probe = torch.cat([seen.expand(-1, 3, -1, -1, -1), density], 1)        # colour = the carried share
        turntable = J.turntable_renders(probe, elevations.double().cpu(), AZIMUTHS, cfg.render, 0)
        r = turntable.shape[-1]
        cells = []
        for i in range(len(AZIMUTHS)):
            x = turntable[i]
            whole = x[:, 0].sum((-2, -1)) / x[:, 3].sum((-2, -1)).clamp_min(1e-6)
            mid = x[..., r // 3:2 * r // 3]
            middle = mid[:, 0].sum((-2, -1)) / mid[:, 3].sum((-2, -1)).clamp_min(1e-6)
            cells.append(f"{float(whole.mean()):.2f} ({float(middle.mean()):.2f})")
        print(f"| {run} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
