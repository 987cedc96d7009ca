"""How well a ``train.azimuth: read`` run's azimuth head reads the turn between two held-out photos.

A rendered collection's manifest keeps every photo's camera, so the true azimuth φ of each held-out
photo's camera about the object's vertical is known (``views.to_angles``: φ = atan2(ω_x, ω_z)). The head
reads φ̂ in a frame of its own, with a free origin and possibly mirrored, so what is scored is each
pair's turn: for the held-out photos i < j,

    error_ij = |wrap((φ̂_i − φ̂_j) − s · (φ_i − φ_j))|,  wrap to (−180°, 180°],

with s = ±1 the sign whose median error is the smaller. Printed: that median, and the same for a head
that reads every photo alike (φ̂ constant: error = |wrap(φ_i − φ_j)|), the floor any reading must beat.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/azimuth_reading.py RUN [RUN ...]
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path

import torch

from mitsuba_platonic.evaluate.photos import photo_splits
from mitsuba_platonic.train.run import load_run


def wrap(a: torch.Tensor) -> torch.Tensor:
    """Angles in degrees wrapped to (−180°, 180°]."""
    return -((180.0 - a) % 360.0 - 180.0)


def true_azimuths(files, data_path: Path) -> torch.Tensor:
    """The held-out photos' true camera azimuths in degrees, from the collection's manifest."""
    root = data_path if (data_path / "manifest.json").is_file() else data_path.parent
    records = {str((root / r["image"]).resolve()): r for r in json.loads((root / "manifest.json").read_text())["images"]}
    views = [records[str(Path(f).resolve())]["view"] for f in files]
    return torch.tensor([math.degrees(math.atan2(v[0], v[2])) for v in views], dtype=torch.float64)


def pair_errors(read: torch.Tensor, truth: torch.Tensor) -> tuple[float, float, int]:
    """(median pair error of the reading, best sign; of a constant reading; the sign s)."""
    pairs = list(itertools.combinations(range(len(read)), 2))
    i, j = torch.tensor([p[0] for p in pairs]), torch.tensor([p[1] for p in pairs])
    best = min((float(wrap((read[i] - read[j]) - s * (truth[i] - truth[j])).abs().median()), s) for s in (1, -1))
    return best[0], float(wrap(truth[i] - truth[j]).abs().median()), best[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path)
    args = p.parse_args()
    print("| run | held-out photos | median pair error | a constant reading's |")
    print("|---|---|---|---|")
    for run in args.runs:
        cfg, model, _ = load_run(run)
        data_path = Path(cfg.data.path)
        _, photos, files = photo_splits(cfg, data_path)
        read = model.estimate_azimuth(photos).double().cpu()
        truth = true_azimuths(files, data_path)
        err, const, s = pair_errors(read, truth)
        print(f"| {run} | {len(files)} | {err:.1f}° (s = {s:+d}) | {const:.1f}° |")
        print("  read:  " + " ".join(f"{a:7.1f}" for a in read.tolist()))
        print("  truth: " + " ".join(f"{a:7.1f}" for a in truth.tolist()))


if __name__ == "__main__":
    main()
