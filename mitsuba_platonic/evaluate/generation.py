"""Judging a generation run (``train.task: generation``): do random samples G(z) look like the class?

A generation run has no input image, so the reconstruction scores do not apply. What is measured
(docs/evaluation.md, "Generation runs"; :mod:`.generation_report` writes it into the report):

**Views.** G's frame is the one its training views ω ~ p_view were drawn around (the run's
``train.view_distribution`` and ``train.elevation``; :func:`run_views`): the object stands upright in
it and no azimuth is special. A sample is seen from ω(φ, θ) = (cos θ sin φ, sin θ, cos θ cos φ)
(:func:`~mitsuba_platonic.views.from_angles`) with its own elevation θ drawn from p_view.

**Two-sample critic** (:func:`~.judge.two_sample_test`, the judge's critic and budget). Critics
learn to tell the run's training photos (label 1) from renders of training samples G(z), z ~ N(0, I)
drawn with seed ``seed + 1``, at ``train_views`` random p_view views each (critic r its own views);
they are scored on the held-out photos against renders of fresh samples (seed ``seed``: what
``platonic generate --seed SEED`` draws), in the bands

- ``random``: each sample at ``train_views`` random p_view views (the views D saw in training);
- ``front`` (0°), ``near`` (15–45°), ``side`` (60–120°), ``back`` (135–180°): each sample on a
  turntable ω(φ, θ_s) at :data:`~.judge.SCORE_AZIMUTHS`, grouped by |φ| as :data:`~.judge.BANDS`
  groups them (:func:`~.judge.band_of`), φ measured from G's +z axis. No azimuth should be worse
  than another for a model trained on views uniform in azimuth: a band that is, is a side G
  neglects.

acc_b = ½ (mean_x [f(x) > 0] + mean_{r ∈ b} [f(r) ≤ 0]); 0.5: renders pass for photos.

**Distance to the truth** where a collection has ground-truth volumes (:func:`nearest_truth`).
G's samples and the truth live in different frames: G may build the object turned by any azimuth,
and a photo run sees its objects cropped and scaled to fill the image (``data.crop: bbox``), so G's
scale and placement are its own. Each volume's occupancy O = {density ≥ ½} is therefore
normalised as shape-generation papers normalise shapes (PointFlow, GET3D), by quantities a turn
about the vertical leaves unchanged (:func:`normalised_occupancy`): centred on the vertical axis
through its occupied voxels' mean (x̄, z̄), at the middle of its height in y, and scaled
isotropically so that s = max(half-height, largest horizontal distance from that axis), each
measured to the voxels' outer faces, becomes :data:`FILL` of the cube's half-width; resampled on an
:data:`EVAL_RESOLUTION`³ grid (trilinear on the 0/1 occupancy, then ≥ ½). The similarity of a
sample S and a truth T is the best IoU over :data:`TURNS` turns about the vertical,

    sim(S, T) = max_k IoU(S, turn(T, k · 360°/K)),     IoU(A, B) = |A ∩ B| / |A ∪ B|  (1 when both are empty)

and with samples S₁ … S_n, truths T₁ … T_m:

- nearest truth of S_i: argmax_j sim(S_i, T_j); ``sample_iou`` = mean_i max_j sim(S_i, T_j) (does
  every sample look like some object? the MMD-style fidelity, with IoU as the similarity);
- ``truth_iou`` = mean_j max_i sim(S_i, T_j) (PointFlow's MMD direction: is every object near some sample?);
- ``coverage`` (COV) = |{ nearest truth of S_i : i }| / m, the share of truth volumes that are some
  sample's nearest (GET3D, PointFlow). Identical sets give coverage 1 and IoU 1; n samples all equal
  to one truth of m give coverage 1/m. COV depends on n: compare runs at the same n (:data:`SAMPLES`).

**Diversity** (:func:`volume_diversity`, :func:`image_diversity`), so that a collapsed model is named:

- volumes: mean over pairs i < j of 1 − IoU(O_i, O_j) in G's frame (no normalisation, no turn:
  one shape at several azimuths is not variety a photo collection shows as such either);
- renders: the mean over shared views (:data:`DIVERSITY_VIEWS`) of the mean pairwise
  1 − silhouette IoU of the samples' renders from that view (only the samples differ);
- the held-out photos' own mean pairwise 1 − silhouette IoU, for reference (shape and view both vary there).

A sample set whose volume or render diversity is below :data:`COLLAPSE` is named collapsed
(:func:`collapse_warnings`): two volumes at 1 − IoU < 0.1 share more than 90 % of their union, the
same shape by eye.

**Roughness** (:func:`~.image_stats.roughness`, mean |Laplacian| of the display image over the
foreground): the mean over the ``random`` band's renders against the mean over the held-out photos;
``roughness_ratio`` > 1: the samples are speckled or striped beyond what the photos show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import UserError
from ..render import RenderSettings
from ..views import DEFAULT_ELEVATION, from_angles, sample_views, to_angles, turntable
from ..volume import voxel_centres, world_to_grid
from . import image_stats as S
from . import metrics as M
from .judge import (BANDS, CRITIC_REPEATS, CRITIC_STEPS, SCORE_AZIMUTHS, TRAIN_VIEWS, band_of, render_pairs,
                    two_sample_test)

__all__ = ["EVAL_RESOLUTION", "FILL", "TURNS", "COLLAPSE", "SAMPLES", "DIVERSITY_VIEWS", "GENERATION_BANDS",
           "run_views", "normalised_occupancy", "turned", "iou_matrix", "nearest_truth", "volume_diversity",
           "image_diversity", "collapse_warnings", "GenerationJudgement", "judge_generation"]

#: The grid of the normalised occupancies.
EVAL_RESOLUTION = 32
#: The normalised shape's extent s as a share of the cube's half-width.
FILL = 0.9
#: Turns about the vertical tried when a sample is matched with a truth (every 30°).
TURNS = 12
#: Diversity below this names the samples collapsed.
COLLAPSE = 0.1
#: Samples drawn to judge a run (COV and the critic's figures depend on it: compare runs at one count).
SAMPLES = 32
#: The shared views of the render diversity: four azimuths 90° apart at 20° elevation.
DIVERSITY_VIEWS = turntable(4, elevation=20.0, start=30.0)
#: The bands of a generation run's critic: the judge's, "input" read as G's front, and random views.
GENERATION_BANDS = ("random",) + tuple("front" if name == "input" else name for name, _, _ in BANDS)


def run_views(train: Any, n: int, seed: int) -> torch.Tensor:
    """``(n, 3)`` views from a run's p_view (its train section's ``view_distribution`` and ``elevation``,
    the distribution's default elevation where none is set), seeded."""
    kwargs: Dict[str, Any] = {}
    if train.view_distribution != "sphere":
        e = train.elevation if train.elevation is not None else DEFAULT_ELEVATION[train.view_distribution]
        kwargs["elevation"] = tuple(e) if isinstance(e, (list, tuple)) else e
    return sample_views(n, train.view_distribution, seed=seed, **kwargs)


def _density(volume: torch.Tensor) -> torch.Tensor:
    v = volume.detach().float().cpu() if isinstance(volume, torch.Tensor) else None
    if v is None or v.dim() != 4 or v.shape[0] not in (1, 4) or len({*v.shape[1:]}) != 1:
        raise UserError(f"expected a (C, N, N, N) volume with C = 1 or 4, got "
                        f"{tuple(volume.shape) if isinstance(volume, torch.Tensor) else type(volume).__name__}")
    return v[-1]


def normalised_occupancy(volume: torch.Tensor, resolution: int = EVAL_RESOLUTION) -> torch.Tensor:
    """The occupancy {density ≥ ½} of a ``(C, N, N, N)`` volume, centred on its vertical axis and scaled
    (module docstring), on a ``resolution``³ grid: ``(R, R, R)`` float 0/1 (all 0 for an empty volume)."""
    density = _density(volume)
    n = density.shape[-1]
    occ = density >= M.IOU_THRESHOLD
    out = torch.zeros(resolution, resolution, resolution)
    if not occ.any():
        return out
    p = voxel_centres(n)[occ]                                          # (K, 3) world points, float64
    half = 1.0 / n                                                     # half a voxel's edge
    cx, cz = float(p[:, 0].mean()), float(p[:, 2].mean())
    y0, y1 = float(p[:, 1].min()) - half, float(p[:, 1].max()) + half
    radius = float(((p[:, 0] - cx) ** 2 + (p[:, 2] - cz) ** 2).sqrt().max()) + half
    s = max((y1 - y0) / 2.0, radius)
    q = voxel_centres(resolution)                                      # the normalised grid's points
    world = q * (s / FILL) + q.new_tensor([cx, (y0 + y1) / 2.0, cz])
    sampled = F.grid_sample(occ.float()[None, None], world_to_grid(world)[None].float(), mode="bilinear",
                            padding_mode="zeros", align_corners=False)[0, 0]
    return (sampled >= 0.5).float()


def turned(occupancy: torch.Tensor, degrees: float) -> torch.Tensor:
    """An ``(R, R, R)`` occupancy turned by φ = ``degrees`` about the vertical (+y) axis through the
    cube's centre: O'(q) = O(R_y(−φ) q), R_y(φ)(x, y, z) = (x cos φ + z sin φ, y, −x sin φ + z cos φ);
    trilinear, then ≥ ½."""
    r = occupancy.shape[-1]
    φ = math.radians(float(degrees))
    q = voxel_centres(r)
    c, s = math.cos(φ), math.sin(φ)
    src = torch.stack([q[..., 0] * c - q[..., 2] * s, q[..., 1], q[..., 0] * s + q[..., 2] * c], dim=-1)
    out = F.grid_sample(occupancy.float()[None, None], world_to_grid(src)[None].float(), mode="bilinear",
                        padding_mode="zeros", align_corners=False)[0, 0]
    return (out >= 0.5).float()


def iou_matrix(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(S, T)`` IoU of every pair of 0/1 occupancies ``a`` ``(S, …)`` and ``b`` ``(T, …)`` (1 for two empty ones)."""
    x, y = a.flatten(1).double(), b.flatten(1).double()
    inter = x @ y.T
    union = x.sum(1)[:, None] + y.sum(1)[None, :] - inter
    return torch.where(union > 0, inter / union.clamp_min(1.0), torch.ones_like(union))


def nearest_truth(samples: Sequence[torch.Tensor], truths: Sequence[torch.Tensor], turns: int = TURNS,
                  resolution: int = EVAL_RESOLUTION) -> Dict[str, Any]:
    """Match ``samples`` with ``truths`` (``(C, N, N, N)`` volumes each, any N, density last) as the module
    docstring says: ``similarity`` ``(n, m)`` (best IoU over the turns), ``nearest`` (each sample's truth
    index), ``nearest_iou`` (its similarity), ``sample_iou`` (their mean), ``truth_iou`` (mean over the
    truths of their best sample's similarity), ``coverage`` (COV), ``truths`` m and ``samples`` n."""
    if not len(samples) or not len(truths):
        raise UserError(f"nearest_truth needs at least one sample and one truth, got {len(samples)} and {len(truths)}")
    if isinstance(turns, bool) or not isinstance(turns, int) or turns < 1:
        raise UserError(f"turns must be a positive int, got {turns!r}")
    a = torch.stack([normalised_occupancy(v, resolution) for v in samples])
    b = [normalised_occupancy(v, resolution) for v in truths]
    sim = torch.stack([iou_matrix(a, torch.stack([turned(t, k * 360.0 / turns) if k else t for t in b]))
                       for k in range(turns)]).amax(0)                 # (n, m)
    best, nearest = sim.max(dim=1)
    return {"similarity": sim, "nearest": nearest.tolist(), "nearest_iou": best.tolist(),
            "sample_iou": float(best.mean()), "truth_iou": float(sim.max(dim=0).values.mean()),
            "coverage": len(set(nearest.tolist())) / len(truths), "truths": len(truths), "samples": len(samples)}


def volume_diversity(volumes: Sequence[torch.Tensor]) -> Optional[float]:
    """Mean over pairs i < j of 1 − IoU of the occupancies {density ≥ ½} of ``(C, N, N, N)`` volumes, as
    they are (G's frame); None for fewer than two."""
    if len(volumes) < 2:
        return None
    occ = torch.stack([(_density(v) >= M.IOU_THRESHOLD).float() for v in volumes])
    iou = iou_matrix(occ, occ)
    i, j = torch.triu_indices(len(occ), len(occ), offset=1)
    return float((1.0 - iou[i, j]).mean())


def image_diversity(images: torch.Tensor) -> Optional[float]:
    """Mean over pairs i < j of 1 − silhouette IoU (alpha > ½) of ``(M, C, R, R)`` images; None for fewer than two."""
    if not isinstance(images, torch.Tensor) or images.dim() != 4:
        raise UserError(f"image_diversity needs (M, C, R, R) images, got "
                        f"{tuple(images.shape) if isinstance(images, torch.Tensor) else type(images).__name__}")
    if len(images) < 2:
        return None
    sil = (images[:, -1] > M.SILHOUETTE_THRESHOLD).float()
    iou = iou_matrix(sil, sil)
    i, j = torch.triu_indices(len(sil), len(sil), offset=1)
    return float((1.0 - iou[i, j]).mean())


def collapse_warnings(diversity: Dict[str, Optional[float]], threshold: float = COLLAPSE,
                      empty: int = 0, samples: int = 0) -> List[str]:
    """One line per diversity (``volumes``, ``renders``) below ``threshold``: the samples are collapsed;
    and one when ``empty`` of the ``samples`` have no voxel of density ≥ ½ (empty volumes are all alike)."""
    what = {"volumes": "their volumes' occupancies", "renders": "their renders' silhouettes from shared views"}
    lines = [f"COLLAPSED: the samples are nearly all one shape ({what[k]}: mean pairwise 1 − IoU "
             f"{diversity[k]:.3f} < {threshold:g})" for k in ("volumes", "renders")
             if diversity.get(k) is not None and diversity[k] < threshold]
    if empty:
        lines.append(f"EMPTY: {empty} of {samples} samples have no voxel of density ≥ ½")
    return lines


def _random_renders(volumes: torch.Tensor, train: Any, k: int, settings: RenderSettings, seed: int) -> torch.Tensor:
    """Each volume at ``k`` random p_view views (seeded): ``(len(volumes) k, C, R, R)``."""
    index = torch.arange(len(volumes)).repeat_interleave(k)
    return render_pairs(volumes, index, run_views(train, len(index), seed), settings, seed)


def _mean(values: Sequence[Optional[float]]) -> Optional[float]:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


@dataclass
class GenerationJudgement:
    """What :func:`judge_generation` found (module docstring): ``c2st`` (the two-sample test's result over
    :data:`GENERATION_BANDS`, None when not run), ``diversity`` (``volumes``, ``renders``, ``photos``),
    ``roughness`` (``renders``, ``photos``, ``ratio``), ``truth`` (:func:`nearest_truth`'s result without
    its matrix, None without truth), ``warnings`` (collapse), the samples' ``volumes`` and ``latents``, and
    ``views`` (renders of the first samples at random views, for the figure)."""

    samples: int
    c2st: Optional[Dict[str, Any]]
    diversity: Dict[str, Optional[float]]
    roughness: Dict[str, Optional[float]]
    truth: Optional[Dict[str, Any]] = None
    warnings: List[str] = field(default_factory=list)
    volumes: Optional[torch.Tensor] = None
    latents: Optional[torch.Tensor] = None
    views: Optional[torch.Tensor] = None

    def summary(self) -> Dict[str, Any]:
        """A flat, JSON-ready record of the figures."""
        out: Dict[str, Any] = {"samples": self.samples}
        if self.c2st is not None:
            out.update({f"c2st_{k}": v for k, v in self.c2st["accuracy"].items()})
            out.update({f"c2st_auc_{k}": v for k, v in self.c2st["auc"].items()})
            out["c2st_train"], out["c2st_photo_pass"] = self.c2st["train_accuracy"], self.c2st["photo_pass"]
        out.update({f"diversity_{k}": v for k, v in self.diversity.items()})
        out.update({f"roughness_{k}": v for k, v in self.roughness.items()})
        if self.truth is not None:
            out.update({f"truth_{k}": self.truth[k] for k in ("sample_iou", "truth_iou", "coverage", "truths")})
        out["collapsed"] = bool(self.warnings)
        return out


def judge_generation(model: Any, train_photos: torch.Tensor, test_photos: torch.Tensor, settings: RenderSettings,
                     train: Any, truths: Optional[Sequence[torch.Tensor]] = None, n_samples: int = SAMPLES,
                     seed: int = 0, steps: int = CRITIC_STEPS, repeats: int = CRITIC_REPEATS,
                     train_views: int = TRAIN_VIEWS, batch: int = 32) -> GenerationJudgement:
    """Judge a generation model (module docstring): ``model`` has ``generate(n, seed)`` and ``latents(n,
    seed)`` (a :class:`~mitsuba_platonic.model.Model`); ``train_photos`` train the critics (none, or
    ``steps=0``: no critic), ``test_photos`` ``(M, C, R, R)`` are the held-out photos, ``settings`` the
    run's renderer, ``train`` its train section (p_view), ``truths`` the collection's ground-truth
    volumes where it has them."""
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 2:
        raise UserError(f"judging a generation run needs at least 2 samples, got {n_samples!r}")
    if not isinstance(test_photos, torch.Tensor) or test_photos.dim() != 4 or not len(test_photos):
        raise UserError("judging a generation run needs at least one held-out photo, (M, C, R, R)")
    test_photos = test_photos.detach().float().cpu()
    latents = model.latents(n_samples, seed)
    volumes = model.generate(n_samples, seed).detach().float().cpu().clamp(0.0, 1.0)
    # the test renders: random p_view views, and a turntable per sample at its own p_view elevation
    rand = _random_renders(volumes, train, train_views, settings, seed)
    _, θ = to_angles(run_views(train, n_samples, seed + 7))
    azimuths = list(SCORE_AZIMUTHS)
    phi = torch.tensor(azimuths, dtype=torch.float64).repeat_interleave(n_samples)
    table = render_pairs(volumes, torch.arange(n_samples).repeat(len(azimuths)),
                    from_angles(phi, θ.double().repeat(len(azimuths))), settings, seed)
    table = table.reshape(len(azimuths), n_samples, *table.shape[1:])
    bands: Dict[str, torch.Tensor] = {"random": rand}
    for name, _, _ in BANDS:
        bands["front" if name == "input" else name] = torch.cat(
            [table[i] for i, a in enumerate(azimuths) if band_of(a) == name])
    c2st = None
    if steps and train_photos is not None and len(train_photos):
        train_volumes = model.generate(max(n_samples, len(train_photos)), seed + 1).detach().float().cpu().clamp(0, 1)
        train_renders = [_random_renders(train_volumes, train, train_views, settings, seed + 1000 + r)
                         for r in range(repeats)]
        c2st = two_sample_test(train_photos, train_renders, test_photos, bands, seed, steps, repeats, batch)
    shared = torch.stack([render_pairs(volumes, torch.arange(n_samples), w.expand(n_samples, 3), settings, seed)
                          for w in DIVERSITY_VIEWS])                           # (V, n, C, R, R)
    diversity = {"volumes": volume_diversity(list(volumes)),
                 "renders": _mean([image_diversity(x) for x in shared]),
                 "photos": image_diversity(test_photos)}
    rough_r = _mean([S.roughness(x) for x in rand])
    rough_p = _mean([S.roughness(x) for x in test_photos])
    roughness = {"renders": rough_r, "photos": rough_p,
                 "ratio": rough_r / rough_p if rough_r is not None and rough_p else None}
    empty = int((volumes[:, -1].flatten(1) < M.IOU_THRESHOLD).all(1).sum())
    truth = None
    if truths:
        found = nearest_truth(list(volumes), list(truths))
        truth = {k: v for k, v in found.items() if k != "similarity"}
    return GenerationJudgement(samples=n_samples, c2st=c2st, diversity=diversity, roughness=roughness, truth=truth,
                               warnings=collapse_warnings(diversity, empty=empty, samples=n_samples),
                               volumes=volumes, latents=latents,
                               views=rand.reshape(n_samples, train_views, *rand.shape[1:])[:, 0])
