"""Evaluation as in the paper (Sec. 5.3, Table 2): metrics, the re-rendering protocol, the report.

- :mod:`.metrics`: DSSIM, RMSE, silhouette and volume IoU, the density-weighted chamfer
  distance, VGG feature distance and FID (the last two from a weights file the user gives).
- :mod:`.protocol`: re-render a reconstruction and its reference from the same 10 random views
  under the same random skies with IF, VOL, ISO and VOX; the billboard baseline.
- :mod:`.report`: score trained runs on their held-out shapes, write a Table-2-like Markdown
  table and figures (``platonic evaluate``).
- :mod:`.photos`: runs trained on a photo folder (no ground truth): held-out photos scored at the
  input view, the reconstruction described at views 10–30° above and beside it, the front-card check.
- :mod:`.generation`: generation runs (no input image): the two-sample critic on random samples,
  nearest-truth IoU and coverage where truth exists, diversity (a collapsed model named), roughness;
  :mod:`.generation_report` writes their section of the report.

docs/evaluation.md describes each metric and method.
"""

from .metrics import (chamfer_distance, dssim, fid, image_rmse, silhouette_iou, vgg_distance, volume_iou,
                      volume_rmse)
from .protocol import (METHODS, billboard, evaluate_pair, held_out_scores, held_out_truths, novel_view_errors, rerender,
                       truth_in_input_frame)
from .report import evaluate_runs

__all__ = ["dssim", "image_rmse", "silhouette_iou", "volume_rmse", "volume_iou", "chamfer_distance",
           "vgg_distance", "fid", "METHODS", "rerender", "evaluate_pair", "billboard", "novel_view_errors",
           "held_out_scores", "held_out_truths", "truth_in_input_frame", "evaluate_runs"]
