"""Benchmark: the real-photo judge's figures over seeds, per config (the table of lab/photos.md).

    .venv/bin/python benchmarks/photo_seeds.py LABEL=EVAL_DIR[,EVAL_DIR...] [LABEL=...]

Each EVAL_DIR is the ``--out`` folder of ``platonic evaluate --run RUN`` on a photo run
(``results.json``, its first row: the trained model). Per label it prints, for every seed's
folder and as mean and spread (max − min) over them: the two-sample critic's accuracy per band
(0.5: the renders pass for held-out photos), the share of held-out photos its critics call photos
(below ½: the critic memorised its training photos, docs/evaluation.md), the side and back
roughness ratios, the input-view, side and back ΔE, the input-view MAE and the card count. The
issue's test of a new config is a lower novel-view accuracy by more than the spread of the seeds. Figures only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

COLUMNS = [("c2st_input", "acc. input", 3), ("c2st_near", "acc. near", 3), ("c2st_side", "acc. side", 3),
           ("c2st_back", "acc. back", 3), ("c2st_photo_pass", "photos passed", 2),
           ("c2st_auc_side", "AUC side", 2), ("c2st_auc_back", "AUC back", 2),
           ("roughness_side", "rough. side", 2), ("roughness_back", "rough. back", 2),
           ("delta_e_input", "ΔE input", 1), ("delta_e_side", "ΔE side", 1), ("delta_e_back", "ΔE back", 1),
           ("input_view_mae", "input MAE", 4), ("not_cards", "not cards", 0)]


def figures(folder: Path) -> Dict[str, Optional[float]]:
    """The trained model's row of one evaluation folder, flattened to the :data:`COLUMNS` keys."""
    row = json.loads((folder / "results.json").read_text())[0]
    judge = row.get("judge") or {}
    out: Dict[str, Optional[float]] = {k: judge.get(k) for k, _, _ in COLUMNS}
    out["input_view_mae"] = row["means"]["input_view_mae"]
    out["not_cards"] = row["card_check"]["not_cards"]
    return out


def _cell(value: Optional[float], digits: int) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("groups", nargs="+", metavar="LABEL=EVAL_DIR[,EVAL_DIR...]")
    args = ap.parse_args()
    print("| config | seed folder | " + " | ".join(name for _, name, _ in COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))
    for group in args.groups:
        label, _, dirs = group.partition("=")
        if not dirs:
            ap.error(f"expected LABEL=EVAL_DIR[,EVAL_DIR...], got {group!r}")
        rows: List[Dict[str, Optional[float]]] = []
        for d in dirs.split(","):
            rows.append(figures(Path(d)))
            print(f"| {label} | {Path(d).name} | " + " | ".join(_cell(rows[-1][k], n) for k, _, n in COLUMNS) + " |")
        stats = []
        for k, _, n in COLUMNS:
            vals = [r[k] for r in rows if r[k] is not None]
            stats.append((np.mean(vals), np.max(vals) - np.min(vals), n) if vals else None)
        print(f"| **{label}** | mean (spread) of {len(rows)} | " +
              " | ".join("—" if s is None else f"{s[0]:.{s[2]}f} ({s[1]:.{s[2]}f})" for s in stats) + " |")


if __name__ == "__main__":
    main()
