"""A photo run scored against 3D truth: a rendered collection handed to the photo path as cut-out photos.

A collection made by ``platonic make-dataset`` (``--formation physical``: path-traced under random
skies) keeps the ground-truth volume and the view of every image (``manifest.json``). Trained as
photos (``data.path: COLLECTION/images``), its reconstructions live in the *photo's frame*: the
loader cropped each image to its object's bounding box and scaled it to fill the training image
(``data.crop: bbox``, :func:`~mitsuba_platonic.data.photos.frame.framing`), and where the object
sits along the input rays is the generator's own choice. This module brings the truth into that
frame and scores the reconstruction where the photo showed nothing.

**The truth in the photo's frame.** The input camera at view ω has the frame (right, up, ω)
(:func:`~mitsuba_platonic.views.camera_frames`). The loader's square has its centre at (u_c, v_c) on
the camera plane and half-width 1/s, with s = P / S (the photo's P pixels span [−1, 1], the square
S of them). The reconstruction's camera-frame point x = (x₁, x₂, x₃) (``Model.reconstruct``'s grid:
right, up, towards the camera) is the truth's world point

    p(x) = u_c · right + v_c · up + z_c · ω + (x₁ · right + x₂ · up + x₃ · ω) / s

with z_c the one thing a photo does not fix: it is chosen so that the two volumes' mean depths,
weighted by density, agree, z_c = z̄_truth − z̄_rec / s. A reconstruction voxel of edge 2/R spans
2/(R s) of the truth's units, N_t / (R s) truth voxels, so the truth's per-voxel opacity becomes

    a' = 1 − (1 − a)^{N_t / (R s)}

(docs/conventions.md, "Opacity and extinction"), and the framed truth's EA render from the input
view covers the photo's silhouette as the truth's own render covers the photo.

**Views.** A turntable about the object's *true* vertical axis at the photo's true elevation θ,
ω(φ, θ) with φ from the input view, written in the camera frame where both volumes live:
ω_cam = (ω·right₀, ω·up₀, ω·ω₀) with right₀ = (1, 0, 0), up₀ = (0, cos θ, −sin θ),
ω₀ = (0, sin θ, cos θ). Scores per photo (:class:`TruthScores`): silhouette IoU and MAE of the two
volumes' EA renders (closed form, :func:`~.protocol.novel_view_errors`) at φ = ±90° (side), ±45°
(oblique), 180° (back) and 0° (the photo's own view: how well the framing matched), the 3D IoU at density
½ (:func:`~.metrics.volume_iou`), and the thickness along the input rays,

    thickness = Σ_r #{k : ρ_rec(r, k) ≥ ½} / Σ_r #{k : ρ_truth(r, k) ≥ ½}

over the input rays r the truth covers (1 − Π_k (1 − ρ_truth(r, k)) ≥ ½), k the voxels along r:
1 where the reconstruction holds as much matter behind the photo's surface as the object, and
small for a shell that satisfies the photo and is seen edge-on from the side
(:func:`thickness`).

**The width ratio.** A lathe-turned reconstruction of an animal photographed from the side shows at
±90° the broad profile it shows at 0°, where the animal seen end-on is narrow; silhouette IoUs blur
that into one figure among others, the width says it. The silhouette's width across the object's
vertical axis u (camera frame: u = (0, cos θ, sin θ)) seen from ω is measured on the EA render's
α ≥ ½ pixels, projected onto the image direction h = u × ω / |u × ω| (across the axis, in the
image plane) and binned at the pixel pitch Δ = 2 / P: width = Δ · #{bins holding such a pixel}. At
θ = 0 h is the image's row direction and the width is Δ times the number of columns the
silhouette covers, so a box of extents 2a (across the photo) and 2d (along the photo's rays) on
whole voxels has widths 2a at 0° and 2d at ±90° exactly; at θ ≠ 0 the turntable's images are rolled
about ω, and h follows the object's axis (:func:`silhouette_widths`; measured on a tilted box and
cylinder at θ = 30°: 2 pixels wider at ±90°, the tilted voxels' staircase and the bins' offset,
alike for the two volumes). The ratio

    width ratio = (w(+90°) + w(−90°)) / (2 w(0°))

is scored for the reconstruction and for the truth, and their per-photo difference
(:func:`width_ratio`); a lathe gives about 1 whatever the truth's is.

**Why ±45° as well.** A volume that a quarter turn about the vertical leaves unchanged (a round
body, but also a four-pointed star whose arms reach the photo's rim) shows at ±90° exactly the
silhouette it shows the input camera, which the input view has fitted. The side score alone then
rewards a star; at ±45° its arms are foreshortened by cos 45° and the score tells it from the
round object (:func:`view_scores`, tested).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn.functional as F

from ..data.photos import decode_image
from ..data.photos.frame import Framing
from ..data.photos.prepare import photo_framing
from ..errors import UserError
from ..render import render
from ..views import camera_frames, from_angles
from ..volume import voxel_centres, world_to_grid
from . import metrics as M
from .photos import photo_splits
from .protocol import novel_view_errors

__all__ = ["PhotoTruth", "TruthScores", "framed_truth", "thickness", "truth_pairs", "turntable_in_camera",
           "view_scores", "score_against_truth", "silhouette_widths", "width_ratio", "SIDE", "OBLIQUE", "BACK"]

PathLike = Union[str, Path]

#: The turntable angles φ (degrees from the input view) of the side and back scores.
SIDE = (90.0, -90.0)
OBLIQUE = (45.0, -45.0)
BACK = (180.0,)


class PhotoTruth(NamedTuple):
    """One held-out photo of :func:`truth_pairs`: its file, its image ``(4, R, R)``, the reconstruction
    and the framed truth ``(4, R, R, R)`` (the input camera's frame), its true elevation θ (degrees)."""

    file: str
    photo: torch.Tensor
    reconstruction: torch.Tensor
    truth: torch.Tensor
    elevation: float


#: The scores of one photo, in :class:`TruthScores`' order.
SCORES = ("front_iou", "side_iou", "side_mae", "oblique_iou", "oblique_mae", "back_iou", "back_mae", "volume_iou",
          "thickness", "width_ratio", "width_ratio_truth", "width_ratio_error")


@dataclass
class TruthScores:
    """Per held-out photo: its file and the scores of the module docstring (lists in the same order)."""

    files: List[str] = field(default_factory=list)
    front_iou: List[float] = field(default_factory=list)
    side_iou: List[float] = field(default_factory=list)
    side_mae: List[float] = field(default_factory=list)
    oblique_iou: List[float] = field(default_factory=list)
    oblique_mae: List[float] = field(default_factory=list)
    back_iou: List[float] = field(default_factory=list)
    back_mae: List[float] = field(default_factory=list)
    volume_iou: List[float] = field(default_factory=list)
    thickness: List[float] = field(default_factory=list)
    width_ratio: List[float] = field(default_factory=list)
    width_ratio_truth: List[float] = field(default_factory=list)
    width_ratio_error: List[float] = field(default_factory=list)

    def append(self, file: str, scores: Dict[str, float]) -> None:
        """Add one photo's ``file`` and its :func:`view_scores` (with ``volume_iou``, ``thickness`` and the
        :func:`width_ratio` of the reconstruction, ``width_ratio``, of the truth, ``width_ratio_truth``, and
        their difference's size, ``width_ratio_error``)."""
        self.files.append(file)
        for k in SCORES:
            getattr(self, k).append(scores[k])

    def means(self) -> Dict[str, float]:
        """The mean of each score over the photos (``truth_<score>``)."""
        return {f"truth_{k}": float(np.mean(getattr(self, k))) for k in SCORES}


def turntable_in_camera(elevation: float, azimuths: Sequence[float]) -> torch.Tensor:
    """Views ω(φ, θ) about the object's vertical axis, θ = ``elevation`` and φ = ``azimuths`` in degrees
    from the input view, in the input camera's frame (module docstring): ``(len(azimuths), 3)``."""
    θ = math.radians(float(elevation))
    v = from_angles(torch.tensor([float(a) for a in azimuths]), torch.full((len(azimuths),), float(elevation)))
    v = v.to(torch.float64)
    s, c = math.sin(θ), math.cos(θ)
    cam = torch.stack([v[:, 0], v[:, 1] * c - v[:, 2] * s, v[:, 1] * s + v[:, 2] * c], dim=-1)
    return (cam / cam.norm(dim=-1, keepdim=True)).to(torch.float32)


def _mean_depth(density: torch.Tensor, depth: torch.Tensor) -> float:
    """Σ a·z / Σ a, or 0 for an empty volume."""
    total = float(density.sum())
    return 0.0 if total <= 0.0 else float((density.double() * depth).sum()) / total


def framed_truth(truth: torch.Tensor, view: Sequence[float], square: Tuple[float, float, float], pixels: int,
                 reconstruction: torch.Tensor) -> torch.Tensor:
    """The ground truth ``(4, N_t, N_t, N_t)`` (RGBA, object frame) seen from ``view`` as a photo of
    ``pixels`` × ``pixels`` framed by ``square`` (:meth:`~mitsuba_platonic.data.photos.frame.Framing.square`:
    centre row, centre column, side, in pixels), resampled onto the grid of ``reconstruction``
    ``(4, R, R, R)`` (the input camera's frame) with its depth matched: ``(4, R, R, R)`` (module docstring)."""
    if truth.dim() != 4 or truth.shape[0] != 4 or reconstruction.dim() != 4 or reconstruction.shape[0] != 4:
        raise UserError(f"framed_truth needs (4, N, N, N) volumes, got {tuple(truth.shape)} and "
                        f"{tuple(reconstruction.shape)}")
    n_t, r = truth.shape[-1], reconstruction.shape[-1]
    right, up, w = (a[0] for a in camera_frames(torch.tensor([list(view)], dtype=torch.float64)))
    row_c, col_c, side = square
    s = pixels / side                                                  # photo pixels per square pixel
    u_c = -1.0 + 2.0 * col_c / pixels                                  # the square's centre on the camera plane
    v_c = 1.0 - 2.0 * row_c / pixels
    # where the object sits along the ray: the density-weighted mean depths agree
    z_truth = _mean_depth(truth[3], voxel_centres(n_t) @ w)
    rec_depth = voxel_centres(r)[..., 2]                               # the camera frame's depth x₃ of each voxel
    z_c = z_truth - _mean_depth(reconstruction[3].cpu(), rec_depth) / s
    x = voxel_centres(r)                                               # (R, R, R, 3): (x₁, x₂, x₃) of each voxel
    p = (u_c * right + v_c * up + z_c * w) + (x[..., :1] * right + x[..., 1:2] * up + x[..., 2:] * w) / s
    grid = world_to_grid(p)[None].to(torch.float32)
    out = F.grid_sample(truth[None].float(), grid, mode="bilinear", padding_mode="zeros", align_corners=False)[0]
    a = out[3].clamp(0.0, 1.0 - 1e-7)
    out[3] = -torch.expm1(torch.log1p(-a) * (n_t / (r * s)))          # a' = 1 − (1 − a)^{N_t / (R s)}
    return out.clamp(0.0, 1.0)


def thickness(reconstruction: torch.Tensor, truth: torch.Tensor) -> float:
    """The thickness score of the module docstring for two ``(C, R, R, R)`` volumes on one grid, in the
    input camera's frame (dim 1 the depth along the input rays, the last channel the density);
    nan where the truth covers no ray."""
    if reconstruction.shape != truth.shape or reconstruction.dim() != 4:
        raise UserError(f"thickness needs two (C, R, R, R) volumes of one shape, got {tuple(reconstruction.shape)} "
                        f"and {tuple(truth.shape)}")
    ρ_rec, ρ_truth = reconstruction[-1].double(), truth[-1].double()
    covered = 1.0 - torch.prod(1.0 - ρ_truth, dim=0) >= 0.5                 # the truth's input-view silhouette
    solid_truth = float((ρ_truth >= 0.5).sum(0)[covered].sum())
    return float("nan") if solid_truth == 0 else float((ρ_rec >= 0.5).sum(0)[covered].sum()) / solid_truth


def _manifest(folder: Path) -> Tuple[Path, Dict[str, Dict[str, Any]]]:
    """The collection root holding ``manifest.json`` (``folder`` or its parent) and its records by image path."""
    for root in (folder, folder.parent):
        if (root / "manifest.json").is_file():
            records = json.loads((root / "manifest.json").read_text())["images"]
            return root, {str((root / rec["image"]).resolve()): rec for rec in records}
    raise UserError(f"{folder} is not a rendered collection's images (no manifest.json in it or above it): "
                    f"3D truth needs a collection made by platonic make-dataset")


def truth_pairs(model: Any, cfg: Any, data_path: Optional[PathLike] = None) -> Iterator[PhotoTruth]:
    """Reconstruct a folder run's held-out photos (:func:`~.photos.photo_splits`) with ``model`` (a
    :class:`~mitsuba_platonic.model.Model` of EA) and yield, per photo, its file, its input image,
    the reconstruction, its ground truth framed on the reconstruction's grid (:func:`framed_truth`)
    and the photo's true elevation θ in degrees. The photos must be a rendered collection's
    ``images/``; ``data_path`` replaces ``cfg.data.path``."""
    if cfg.render.model != "ea":
        raise UserError(f"scoring against 3D truth renders colour: it needs an EA run, got {cfg.render.model!r}")
    folder = Path(data_path if data_path is not None else cfg.data.path)
    root, records = _manifest(folder)
    _, photos, files = photo_splits(cfg, folder)
    options = cfg.data.image_kwargs()
    recon = model.reconstruct(photos).detach().cpu()
    for k, file in enumerate(files):
        rec = records.get(str(Path(file).resolve()))
        if rec is None:
            raise UserError(f"{file} is not in {root / 'manifest.json'}")
        decoded = decode_image(file)
        if decoded.size[0] != decoded.size[1]:
            raise UserError(f"{file}: a rendered collection's images are square, this one is {decoded.size}")
        framing: Framing = photo_framing(decoded, name=str(file), **options)
        truth = torch.from_numpy(np.load(root / rec["volume"])["volume"]).float()
        θ = math.degrees(math.asin(max(-1.0, min(1.0, float(rec["view"][1])))))
        t = framed_truth(truth, rec["view"], framing.square(), decoded.size[0], recon[k])
        yield PhotoTruth(str(file), photos[k].cpu(), recon[k], t, θ)


def view_scores(reconstruction: torch.Tensor, truth: torch.Tensor, elevation: float) -> Dict[str, float]:
    """Silhouette IoU and MAE of EA renders of ``reconstruction`` and ``truth`` (``(4, R, R, R)`` on one grid,
    the input camera's frame) about the object's vertical at ``elevation`` θ (degrees): at 0° (``front_``),
    ±90° (``side_``), ±45° (``oblique_``) and 180° (``back_``), each ``<view>_iou`` and ``<view>_mae``."""
    out: Dict[str, float] = {}
    for name, azimuths in (("front", (0.0,)), ("side", SIDE), ("oblique", OBLIQUE), ("back", BACK)):
        mae, iou = novel_view_errors(reconstruction, truth, "ea", turntable_in_camera(elevation, azimuths))
        out[f"{name}_iou"], out[f"{name}_mae"] = iou, mae
    return out


def silhouette_widths(volume: torch.Tensor, views: torch.Tensor, axis: Sequence[float]) -> List[float]:
    """The widths of the EA silhouette (α ≥ ½) of ``volume`` ``(4, R, R, R)`` seen from each of ``views``
    ``(B, 3)``, across the vertical ``axis`` (3 numbers, the grid's frame): Δ times the number of pitch-Δ
    bins of the α ≥ ½ pixels' coordinates along h = axis × ω / |axis × ω| (module docstring, "The width
    ratio"; Δ = 2 / R, the image's pixel pitch). 0 for an empty silhouette."""
    if volume.dim() != 4 or volume.shape[0] != 4:
        raise UserError(f"silhouette_widths needs a (4, R, R, R) volume, got {tuple(volume.shape)}")
    u = torch.tensor([float(a) for a in axis], dtype=torch.float64)
    if u.shape != (3,) or not float(u.norm()) > 0.0:
        raise UserError(f"silhouette_widths needs a non-zero 3-vector axis, got {list(axis)!r}")
    u = u / u.norm()
    with torch.no_grad():
        alpha = render(volume[None].expand(len(views), -1, -1, -1, -1).contiguous(), views, "ea")[:, 3]
    right, up, w = camera_frames(views)
    h = torch.linalg.cross(u.expand_as(w), w, dim=-1)
    hn = h.norm(dim=-1, keepdim=True)
    if float(hn.min()) < 1e-6:
        raise UserError("silhouette_widths: a view along the axis has no width across it")
    h = h / hn
    p = alpha.shape[-1]
    pitch = 2.0 / p
    centre = -1.0 + (torch.arange(p, dtype=torch.float64) + 0.5) * pitch     # x of column j, −y of row i
    out = []
    for b in range(len(views)):
        rows, cols = (alpha[b] >= 0.5).nonzero(as_tuple=True)
        t = centre[cols] * float(h[b] @ right[b]) - centre[rows] * float(h[b] @ up[b])
        out.append(pitch * len(torch.unique(torch.floor((t + 1.0) / pitch))))
    return out


def width_ratio(volume: torch.Tensor, elevation: float) -> float:
    """(w(+90°) + w(−90°)) / (2 w(0°)) of ``volume`` ``(4, R, R, R)`` (the input camera's frame), the
    :func:`silhouette_widths` on the turntable about the object's vertical at ``elevation`` θ (degrees,
    :func:`turntable_in_camera`); nan where the silhouette at 0° is empty."""
    θ = math.radians(float(elevation))
    front, *sides = silhouette_widths(volume, turntable_in_camera(elevation, (0.0, *SIDE)),
                                      (0.0, math.cos(θ), math.sin(θ)))
    return float("nan") if front == 0 else float(np.mean(sides)) / front


def score_against_truth(model: Any, cfg: Any, data_path: Optional[PathLike] = None) -> TruthScores:
    """Score each held-out photo's reconstruction against its ground truth (:func:`truth_pairs`,
    the module docstring)."""
    scores = TruthScores()
    for pair in truth_pairs(model, cfg, data_path):
        r, t = pair.reconstruction, pair.truth
        per_photo = view_scores(r, t, pair.elevation)
        ratio, ratio_truth = width_ratio(r, pair.elevation), width_ratio(t, pair.elevation)
        per_photo.update(volume_iou=M.volume_iou(r[3], t[3]), thickness=thickness(r, t), width_ratio=ratio,
                         width_ratio_truth=ratio_truth, width_ratio_error=abs(ratio - ratio_truth))
        scores.append(pair.file, per_photo)
    return scores
