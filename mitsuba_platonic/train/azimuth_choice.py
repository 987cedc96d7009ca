"""``train.azimuth: auto``: which azimuths the critic's random views take, chosen from the collection.

A round class (trees, mushrooms) looks alike from every azimuth, so an azimuth head reads nothing off
its photos: on the suite's path-traced mushrooms the readings of the held-out photos bunched (their
mean resultant length 0.65, the truth's 0.22), the turns drawn between them bunched about 0°, and the
critic's views at those turns lost the sides (lab/photo-any-class.md, fifth and sixth rounds). A
class that is not round (animals, aeroplanes) has an azimuth to read, and there the read turns won
on the side-photographed animals and held on the aeroplanes. The photos say which kind a collection
is before any training: the median upper mirror asymmetry U of its silhouettes
(:func:`~mitsuba_platonic.evaluate.priors.round_evidence`; docs/evaluation.md, "Shape priors and the
collection's evidence") is at most 0.183 on every round collection measured and at least 0.336 on
every one that is not, the threshold 0.25 between them. So

    azimuth = 'read'   if the collection has ≥ 8 silhouettes and median U > 0.25,
              'every'  otherwise (a round class, or too few photos to say).

The figure is taken over the training and the held-out photos together, as the report takes it, so the
choice and the report's evidence agree; every process of a run computes it from the same photos.
"""

from __future__ import annotations

import copy
from typing import Optional, Tuple

import torch

from ..config import Config
from ..evaluate.priors import RoundEvidence, round_evidence

__all__ = ["choose_azimuth", "choice_line"]


def choose_azimuth(cfg: Config, photos: torch.Tensor) -> Tuple[Config, Optional[RoundEvidence]]:
    """``cfg`` with ``train.azimuth`` 'auto' replaced by 'read' or 'every' (module docstring) from
    ``photos`` ``(M, C, R, R)`` (the opacity their last channel), and the evidence read; a config that
    is not 'auto' comes back as it is, with no evidence (a copy is changed, never ``cfg``)."""
    if cfg.train.azimuth != "auto":
        return cfg, None
    evidence = round_evidence(photos)
    chosen = copy.deepcopy(cfg)
    chosen.train.azimuth = "read" if evidence.not_round else "every"
    return chosen, evidence


def choice_line(azimuth: str, evidence: RoundEvidence) -> str:
    """One line for the log: what ``train.azimuth: auto`` chose (``azimuth``) and from what."""
    if not evidence.decided:
        why = (f"{evidence.photos} photos with a silhouette, fewer than a verdict needs: the class is taken "
               "as round, and the critic judges every azimuth")
    elif azimuth == "read":
        why = (f"the photos' median upper mirror asymmetry {evidence.upper_asymmetry:.3f} is above "
               f"{evidence.threshold:g}: the class is not round, and the critic judges the turns an azimuth "
               "head reads between the photos")
    else:
        why = (f"the photos' median upper mirror asymmetry {evidence.upper_asymmetry:.3f} is at most "
               f"{evidence.threshold:g}: the class is round, and the critic judges every azimuth")
    return f"train.azimuth: auto → {azimuth} ({why})"
