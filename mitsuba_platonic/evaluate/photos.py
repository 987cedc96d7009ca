"""Evaluation on real photos: held-out photos of a folder run, with no ground truth in 3D.

A run trained on a photo folder (``data.source: folder``) has no ground-truth volume, so the
paper's protocol (:mod:`.protocol`) cannot score it. What can be measured honestly:

**Held-out photos.** The run's held-out split exactly as ``train/data.py`` (``_folder``) builds
it: the ``val`` then the ``test`` split of
:meth:`~mitsuba_platonic.data.photos.PhotoCollection.load_splits` with the run's resolution,
channels and ``data.photo_options()`` (split by content hash, so the run never trained on them).
:func:`held_out_photos` returns them with their file names.

**At the input view** ω₀ = (0, 0, 1) (:func:`~mitsuba_platonic.views.front_view`) the photo *is*
the ground truth. Each reconstruction V = G(E(x)) is rendered with the run's own renderer
settings (``cfg.render``: backend, image formation, filter, camera, marcher options;
:func:`~mitsuba_platonic.render.render_with`, seeded by ``seed``) and compared with the photo x:

- MAE = mean over channels c and pixels p of |render_c(p) − x_c(p)| (premultiplied linear RGBA,
  or opacity for VH/AO — the number ``protocol.held_out_scores`` reports as ``input_view_mae``);
- silhouette IoU (:func:`~.metrics.silhouette_iou`: alpha > ½);
- DSSIM (:func:`~.metrics.dssim`, the display images over white).

**Away from the input view** there is no ground truth: nobody photographed the object from
there. The views are, in the reconstruction's frame (the input camera at ω₀), with the angle
convention of :mod:`mitsuba_platonic.views` (ω(φ, θ) = (cos θ sin φ, sin θ, cos θ cos φ)):

- ``above θ`` = ω(0°, θ), θ ∈ {10°, 20°, 30°}: the camera raised by θ towards +y, looking down;
- ``beside φ`` = ω(φ, 0°), φ ∈ {10°, 20°, 30°}: the camera turned by φ about the vertical axis
  towards +x, the input image's right-hand side.

There, only properties of the reconstruction are reported, never a score against the photo
(the photo's silhouette seen from elsewhere is not the truth there):

- coverage = the share of pixels with alpha > ½ (:data:`~.metrics.SILHOUETTE_THRESHOLD`) in the
  render from that view, and its ratio to the coverage of the input-view render. An object seen
  10–30° away keeps roughly its apparent size: a ratio near 0 means it vanished, far above 1
  that it smeared. It does not tell a card from a solid (a card turned by 30° keeps
  cos 30° ≈ 0.87 of its area); the depth below does;
- the half-opacity depth *from that view*: the volume resampled into the frame of an
  orthographic camera at the view (the closed form's ``rotate``, trilinear) and measured as below.

**Front-card check.** A reconstruction can reproduce the input photo perfectly with a painted
card at the front of the cube and nothing behind it. With T_k = Π_{j≤k} (1 − v_j) the
transmittance after depth layer k along the input camera's depth (axis 0, d = 0 at the front
face), :func:`~.metrics.half_opacity_depth` is the median, over the covered rays (total opacity
1 − T_{N−1} > ½), of the first k with T_k < ½. With N the resolution:

    card  ⇔  depth < N/8           (:func:`card_check`; empty ⇔ no covered ray, depth undefined)

A card gives 0 or 1 (a faint card spread over two layers). A solid ball of radius r (world units, the
cube is [−1, 1]³) centred in the cube gives ≈ (1 − r/√2) · N/2: the front surface at image
radius ρ lies (1 − √(r² − ρ²)) · N/2 voxels deep and the median of ρ² over the disc is r²/2. That
is N/3 for r ≈ 0.47 (about N/3 for a centred object half as wide as the cube), N/4 for r = 0.7 and
≈ 0.146 N > N/8 even for the inscribed ball (r = 1), so every centred solid ball passes and a
card fails. The issue's target: at least 3 of 4 held-out reconstructions are not cards
(:func:`card_summary`: k of n with depth ≥ N/8, met when k ≥ ¾ n). A thin sheet placed deeper
in the cube (e.g. in its middle plane) is not caught by this check; the novel views show it.

Baselines next to the trained model (same photos, same renders): the run's networks untrained
(initialised with the run's seed) and, for EA, the billboard (:func:`~.protocol.billboard`: the
photo extruded through the depth of the cube; perfect at the input view, and it is a card:
an opaque pixel's transmittance falls below ½ within the first ~N/20 layers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch

from ..data.photos import PhotoCollection
from ..errors import UserError
from ..model import Model
from ..render import RenderSettings, render_with
from ..render.pytorch.closed_form import rotate
from ..views import from_angles, front_view, to_angles
from ..volume import CHANNELS
from . import metrics as M
from .figures import save_image_grid
from .judge import CRITIC_REPEATS, CRITIC_STEPS, FIGURE_AZIMUTHS, Judgement, judge, judge_table, stats_table
from .priors import Prior, RoundEvidence, priors_markdown, priors_results, priors_used, round_evidence
from .protocol import billboard

__all__ = ["ABOVE", "BESIDE", "CARD_FRACTION", "TARGET_SHARE", "novel_views", "held_out_photos", "card_check",
           "card_summary", "view_depth", "PhotoRow", "score_photos", "photo_table", "write_photo_figure",
           "write_judge_figure", "photo_splits", "PhotoSection", "evaluate_photo_run", "section_markdown", "section_results"]

#: Elevations (degrees) of the views above the input view, and azimuths of the views beside it.
ABOVE = (10.0, 20.0, 30.0)
BESIDE = (10.0, 20.0, 30.0)
#: A reconstruction is a front card when its half-opacity depth is below this share of N.
CARD_FRACTION = 1.0 / 8.0
#: The issue's target: at least this share of held-out reconstructions are not cards (3 of 4).
TARGET_SHARE = 0.75

PathLike = Union[str, Path]


def novel_views() -> Tuple[List[str], torch.Tensor]:
    """The views away from the input one: names (``above_10`` …, ``beside_10`` …) and ``(6, 3)``
    unit vectors in the reconstruction's frame (module docstring: above θ = ω(0, θ), beside φ = ω(φ, 0))."""
    names = [f"above_{a:g}" for a in ABOVE] + [f"beside_{b:g}" for b in BESIDE]
    views = torch.cat([from_angles(torch.zeros(len(ABOVE)), torch.tensor(ABOVE)),
                       from_angles(torch.tensor(BESIDE), torch.zeros(len(BESIDE)))])
    return names, views


def held_out_photos(cfg: Any, data_path: Optional[PathLike] = None) -> Tuple[torch.Tensor, List[Path]]:
    """The held-out photos of a folder run: ``(M, C, R, R)`` images and their source files
    (:func:`photo_splits` without the training photos)."""
    _, held, files = photo_splits(cfg, data_path)
    return held, files


def photo_splits(cfg: Any, data_path: Optional[PathLike] = None) -> Tuple[torch.Tensor, torch.Tensor, List[Path]]:
    """The photos of a folder run: ``(N, C, R, R)`` training photos, ``(M, C, R, R)`` held-out
    photos and the held-out photos' source files.

    The same images, in the same order, as ``train/data.py``'s ``_folder`` builds: the ``train``
    split, and the ``val`` then the ``test`` split held out, of ``PhotoCollection.load_splits(data.path,
    resolution, alpha_only, **data.photo_options())``. ``data_path`` replaces ``cfg.data.path`` (a
    path relative to where training ran). Raises :class:`UserError` when the folder is missing,
    unusable, or leaves no held-out photo.
    """

    d = cfg.data
    if d.source != "folder":
        raise UserError(f"held-out photos need a folder run (data.source: folder), got data.source {d.source!r}")
    folder = Path(data_path if data_path is not None else d.path)
    if not folder.is_dir():
        raise UserError(f"the run's photo folder {str(folder)!r} is not a folder here (data.path is relative to "
                        f"where training ran); pass --data-path DIR with the run's photos")
    try:
        sets = PhotoCollection.load_splits(folder, resolution=cfg.model.resolution,
                                           alpha_only=CHANNELS[cfg.render.model] == 1, **d.photo_options())
    except ValueError as e:
        raise UserError(f"the run's photo folder {str(folder)!r} cannot be loaded: {e}") from None
    images = [sets[s][i] for s in ("val", "test") for i in range(len(sets[s]))]
    files = [f for s in ("val", "test") for f in sets[s].files]
    if not images:
        raise UserError(f"{str(folder)!r} with data.split {d.split} leaves no held-out photo (val + test are "
                        f"empty: {sets['all'].report.usable} usable photo(s)); evaluation needs at least one")
    train = [sets["train"][i] for i in range(len(sets["train"]))]
    train_images = torch.stack(train) if train else torch.zeros(0, *images[0].shape)
    return train_images, torch.stack(images), files


def _depth(volume: torch.Tensor) -> Optional[float]:
    d = M.half_opacity_depth(volume)
    return None if math.isnan(d) else d


def card_check(volume: torch.Tensor) -> Dict[str, Any]:
    """The front-card check of one ``(C, N, N, N)`` reconstruction in its input camera's frame:
    ``half_opacity_depth`` (voxels, None when no ray is covered), ``card`` (depth < N/8),
    ``empty`` (no covered ray)."""
    if volume.dim() != 4:
        raise UserError(f"card_check needs one (C, N, N, N) volume, got shape {tuple(volume.shape)}")
    n = volume.shape[-1]
    depth = _depth(volume)
    return {"half_opacity_depth": depth, "card": depth is not None and depth < CARD_FRACTION * n,
            "empty": depth is None}


def card_summary(checks: Sequence[Dict[str, Any]], resolution: int) -> Dict[str, Any]:
    """k of n reconstructions are not cards (depth ≥ N/8; empty ones do not count as passing),
    and whether the issue's target (k ≥ ¾ n) is met."""
    n = len(checks)
    k = sum(1 for c in checks if not c["card"] and not c["empty"])
    depths = [c["half_opacity_depth"] for c in checks if c["half_opacity_depth"] is not None]
    return {"not_cards": k, "n": n, "cards": sum(1 for c in checks if c["card"]),
            "empty": sum(1 for c in checks if c["empty"]), "threshold_voxels": CARD_FRACTION * resolution,
            "median_depth": float(np.median(depths)) if depths else None,
            "target_met": n > 0 and k >= TARGET_SHARE * n}


def view_depth(volume: torch.Tensor, view: torch.Tensor) -> Optional[float]:
    """The half-opacity depth (voxels) of a ``(C, N, N, N)`` volume seen from ``view`` ``(3,)``: its
    density resampled into the frame of an orthographic camera at ``view`` (trilinear, the closed
    form's ``rotate``) and measured by :func:`~.metrics.half_opacity_depth`; None when no ray is covered."""

    density = volume.detach().float().cpu()[-1:][None]
    return _depth(rotate(density, view.reshape(1, 3).float())[0].clamp(0.0, 1.0))


def _render(volumes: torch.Tensor, view: torch.Tensor, settings: RenderSettings, seed: int) -> torch.Tensor:
    with torch.no_grad():
        out = render_with(volumes.contiguous(), view.reshape(1, 3).expand(len(volumes), 3).contiguous(),
                          settings, seed)
    return out.detach().float().cpu().clamp(0.0, 1.0)


@dataclass
class PhotoRow:
    """One method (the trained run or a baseline) on a run's held-out photos: one record per photo
    (``file``, input-view scores, card check, per-view coverage and depth), the card summary, and
    up to a few (file, photo, renders ``(1 + 6, C, R, R)``: input view then :func:`novel_views`)
    examples for the figure."""

    method: str
    formation: str
    resolution: int
    photos: List[Dict[str, Any]] = field(default_factory=list)
    summary: Dict[str, Any] = field(default_factory=dict)
    examples: List[Tuple[str, torch.Tensor, torch.Tensor]] = field(default_factory=list)

    def mean(self, key: str) -> Optional[float]:
        """Mean of ``key`` over the photos that have a value for it (None when none has)."""
        vals = [p[key] for p in self.photos if p.get(key) is not None and not isinstance(p[key], (bool, str))]
        return float(np.mean(vals)) if vals else None

    def means(self) -> Dict[str, Optional[float]]:
        keys = sorted({k for p in self.photos for k, v in p.items() if not isinstance(v, (bool, str))})
        return {k: self.mean(k) for k in keys}


def score_photos(method: str, volumes: torch.Tensor, photos: torch.Tensor, files: Sequence[PathLike],
                 settings: RenderSettings, seed: int = 0, n_examples: int = 0) -> PhotoRow:
    """Score ``(M, C, N, N, N)`` reconstructions of ``(M, C, R, R)`` held-out photos (module docstring).

    Per photo: ``input_view_mae``, ``input_view_iou``, ``input_view_dssim`` and
    ``input_view_coverage`` of the render at the input view; the card check (``half_opacity_depth``,
    ``card``, ``empty``); per novel view ``v``: ``coverage_<v>``, ``coverage_ratio_<v>`` (None when
    the input-view render covers nothing) and ``depth_<v>`` (:func:`view_depth`). ``settings``: the
    run's renderer; ``seed``: its per-call seed (jitter, skies). Renders are clipped to [0, 1]
    (the physical backend's radiance can exceed 1) before they are compared.
    """
    volumes, photos = volumes.detach().float().cpu(), photos.detach().float().cpu()
    if volumes.dim() != 5 or photos.dim() != 4 or len(volumes) != len(photos) or len(files) != len(photos):
        raise UserError(f"score_photos needs (M, C, N, N, N) volumes, (M, C, R, R) photos and M files, got "
                        f"{tuple(volumes.shape)}, {tuple(photos.shape)} and {len(files)} files")
    if volumes.shape[1] != photos.shape[1] or volumes.shape[1] != CHANNELS[settings.model]:
        raise UserError(f"image formation {settings.model!r} needs {CHANNELS[settings.model]} channels in the volumes "
                        f"and photos, got {volumes.shape[1]} and {photos.shape[1]}")
    n = volumes.shape[-1]
    names, views = novel_views()
    front = _render(volumes, front_view(), settings, seed)
    if front.shape != photos.shape:
        raise UserError(f"the renders {tuple(front.shape)} and the photos {tuple(photos.shape)} differ in shape: the "
                        f"photos must be at the run's resolution {n}")
    novel = [_render(volumes, w, settings, seed) for w in views]
    row = PhotoRow(method, settings.model.upper(), n)
    checks = []
    for i, (file, photo, volume) in enumerate(zip(files, photos, volumes)):
        rec: Dict[str, Any] = {"file": str(file)}
        rec["input_view_mae"] = float((front[i] - photo).abs().mean())
        rec["input_view_iou"] = M.silhouette_iou(front[i:i + 1], photo[None])
        rec["input_view_dssim"] = M.dssim(front[i], photo)
        cover0 = float((front[i, -1] > M.SILHOUETTE_THRESHOLD).float().mean())
        rec["input_view_coverage"] = cover0
        check = card_check(volume)
        checks.append(check)
        rec.update(check)
        for name, w, img in zip(names, views, novel):
            cover = float((img[i, -1] > M.SILHOUETTE_THRESHOLD).float().mean())
            rec[f"coverage_{name}"] = cover
            rec[f"coverage_ratio_{name}"] = cover / cover0 if cover0 > 0 else None
            rec[f"depth_{name}"] = view_depth(volume, w)
        row.photos.append(rec)
        if len(row.examples) < n_examples:
            row.examples.append((str(file), photo, torch.stack([front[i]] + [img[i] for img in novel])))
    row.summary = card_summary(checks, n)
    return row


# -- writing ---------------------------------------------------------------------------------

def _short(file: PathLike, folder: Optional[PathLike]) -> str:
    """A photo's path relative to its folder (sub-folders may repeat file names), else as given."""
    try:
        return Path(file).resolve().relative_to(Path(folder).resolve()).as_posix() if folder is not None else str(file)
    except ValueError:
        return str(file)


def _num(value: Optional[float], digits: int = 3, scale: float = 1.0) -> str:
    return "—" if value is None else f"{value * scale:.{digits}f}"


def photo_table(rows: Sequence[PhotoRow]) -> str:
    """Markdown: per method, the input-view scores (means over photos), the median half-opacity
    depth and how many reconstructions are not cards."""
    lines = ["| Method | IF | MAE (input view) | silhouette IoU (input view) | DSSIM ×10 (input view) | "
             "median half-opacity depth (voxels) | not cards (depth ≥ N/8) | photos |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        s = r.summary
        lines.append(f"| {r.method} | {r.formation} | {_num(r.mean('input_view_mae'), 4)} | "
                     f"{_num(r.mean('input_view_iou'))} | {_num(r.mean('input_view_dssim'), 2, 10.0)} | "
                     f"{_num(s.get('median_depth'), 1)} | {s['not_cards']} of {s['n']} | {len(r.photos)} |")
    return "\n".join(lines)


def _novel_table(row: PhotoRow) -> str:
    names, views = novel_views()

    az, el = to_angles(views)
    lines = ["| view | azimuth | elevation | coverage | coverage / input-view coverage | half-opacity depth (voxels) |",
             "|---|---|---|---|---|---|",
             f"| input | 0° | 0° | {_num(row.mean('input_view_coverage'))} | 1 | "
             f"{_num(row.mean('half_opacity_depth'), 1)} |"]
    for name, a, e in zip(names, az.tolist(), el.tolist()):
        lines.append(f"| {name.replace('_', ' ')}° | {a:.0f}° | {e:.0f}° | {_num(row.mean(f'coverage_{name}'))} | "
                     f"{_num(row.mean(f'coverage_ratio_{name}'), 2)} | {_num(row.mean(f'depth_{name}'), 1)} |")
    return "\n".join(lines)


def _per_photo_table(row: PhotoRow, folder: Optional[PathLike] = None) -> str:
    lines = ["| photo | MAE | silhouette IoU | half-opacity depth (voxels) | card |", "|---|---|---|---|---|"]
    for p in row.photos:
        verdict = "empty" if p["empty"] else ("card" if p["card"] else "no")
        lines.append(f"| {_short(p['file'], folder)} | {p['input_view_mae']:.4f} | {p['input_view_iou']:.3f} | "
                     f"{_num(p['half_opacity_depth'], 1)} | {verdict} |")
    return "\n".join(lines)


def write_photo_figure(row: PhotoRow, path: PathLike, folder: Optional[PathLike] = None) -> Path:
    """A PNG, one line per example of ``row``: the photo | the reconstruction at the input view |
    at the 6 novel views (above 10°, 20°, 30°; beside 10°, 20°, 30°), rendered with the run's
    renderer, display images over white; each line labelled with the photo's path relative to
    ``folder``, its half-opacity depth and the card verdict."""
    if not row.examples:
        raise UserError(f"row {row.method!r} has no examples to draw")
    names, _ = novel_views()
    titles = ["photo", "input view"] + [n.replace("_", " ") + "°" for n in names]
    lines, labels = [], []
    for file, photo, renders in row.examples:
        rec = next((p for p in row.photos if p["file"] == file), None)
        lines.append([photo] + list(renders))
        if rec is None:
            labels.append("")
        else:
            verdict = "empty" if rec["empty"] else ("CARD" if rec["card"] else "not a card")
            labels.append(f"{_short(file, folder)}\ndepth {_num(rec['half_opacity_depth'], 1)}\n{verdict}")
    return save_image_grid(lines, titles, path, f"{row.method} ({row.formation}): held-out photos",
                           cell=(1.2, 1.35), extra_height=0.4, labels=labels)


@dataclass
class PhotoSection:
    """A folder run's part of the report: its name, photo folder, renderer, rows (the trained model
    first, then the baselines) and, once written, the path of its figure."""

    run: str
    folder: str
    settings: RenderSettings
    rows: List[PhotoRow]
    figure: Optional[Path] = None
    #: (method, :class:`~.judge.Judgement`) per row, when the run's training photos were there to judge with
    judgements: List[Tuple[str, Judgement]] = field(default_factory=list)
    judge_figure: Optional[Path] = None
    #: the shape priors the run used, and what all its photos' silhouettes say about roundness (:mod:`.priors`)
    priors: List[Prior] = field(default_factory=list)
    evidence: Optional[RoundEvidence] = None


def evaluate_photo_run(name: str, base: str, cfg: Any, model: Model, untrained: Optional[Callable[[], Model]] = None,
                       limit: Optional[int] = None, seed: int = 0, data_path: Optional[PathLike] = None,
                       n_examples: int = 8, progress: bool = False,
                       judge_steps: int = CRITIC_STEPS) -> PhotoSection:
    """Reconstruct a folder run's held-out photos (:func:`held_out_photos`, at most ``limit``) with
    ``model`` (a :class:`~mitsuba_platonic.model.Model`: its ``reconstruct`` and
    ``reconstruct_upright``) and score them (:func:`score_photos`) with the run's renderer
    ``cfg.render`` into a row named ``name``; with ``untrained`` (a factory of the untrained model)
    also the rows ``<base>: untrained`` and, for EA, ``<base>: billboard``. Each row is also judged
    away from the input view (:func:`~.judge.judge`, on turntables about the object's vertical axis,
    critics of ``judge_steps`` steps trained on the run's training photos; ``judge_steps=0`` skips
    the judge). The section also lists the shape priors of ``cfg`` and measures what all the run's
    photos (training and held out, whatever ``limit``) say about roundness (:mod:`.priors`)."""
    train, photos, files = photo_splits(cfg, data_path)
    every = photos                                       # the evidence about roundness reads every photo
    if limit is not None:
        photos, files = photos[:limit], files[:limit]
    settings = cfg.render
    if progress:
        print(f"  {name}: {len(photos)} held-out photo(s), {len(train)} training photo(s) for the judge", flush=True)

    def billboards(x: torch.Tensor) -> torch.Tensor:
        return torch.stack([billboard(i) for i in x])

    # (name, volumes in the input frame, what the judge reconstructs with): a model's upright volumes
    # and elevations, the billboard's input-frame volumes
    methods: List[Tuple[str, Callable[[torch.Tensor], torch.Tensor], Callable[[torch.Tensor], Any]]] = \
        [(name, model.reconstruct, model.reconstruct_upright)]
    if untrained is not None:
        fresh = untrained()
        methods.append((f"{base}: untrained", fresh.reconstruct, fresh.reconstruct_upright))
        if settings.model == "ea":
            methods.append((f"{base}: billboard", billboards, billboards))
    volumes = [fn(photos).detach().cpu() for _, fn, _ in methods]
    rows = [score_photos(m, v, photos, files, settings, seed, n_examples if i == 0 else 0)
            for i, ((m, _, _), v) in enumerate(zip(methods, volumes))]
    folder = str(data_path if data_path is not None else cfg.data.path)
    section = PhotoSection(run=name, folder=folder, settings=settings, rows=rows, priors=priors_used(cfg),
                           evidence=round_evidence(torch.cat([train, every])))
    if len(train) and judge_steps:
        for i, (m, _, upright) in enumerate(methods):
            if progress:
                print(f"  judging {m} ({judge_steps} critic steps)", flush=True)
            section.judgements.append((m, judge(upright, train, photos, settings, [str(f) for f in files], seed=seed,
                                                steps=judge_steps, n_examples=n_examples if i == 0 else 0)))
    return section


def section_markdown(section: PhotoSection, figure_link: Optional[str] = None) -> List[str]:
    """The report's lines for one folder run (module docstring for every definition)."""
    trained = section.rows[0]
    s = trained.summary
    n = trained.resolution
    st = section.settings
    verdict = "met" if s["target_met"] else "NOT met"
    lines = [f"## Real photos: {section.run}", "",
             f"{len(trained.photos)} held-out photos of `{section.folder}` (the run's val + test split, never trained "
             f"on), reconstructed and rendered with the run's renderer ({st.backend}, {st.model.upper()}, "
             f"{st.camera}). At the input view the photo is the ground truth: MAE of premultiplied linear RGBA, "
             f"silhouette IoU (alpha > ½), DSSIM × 10. Half-opacity depth: median depth, in voxels behind the "
             f"front face, at which a covered ray's transmittance first falls below ½; a front card gives 0, a "
             f"centred ball of radius ½ about N/3 = {n / 3:.1f}.", "",
             photo_table(section.rows), "",
             f"**Front-card check** ({trained.method}): {s['not_cards']} of {s['n']} reconstructions are not cards "
             f"(half-opacity depth ≥ N/8 = {s['threshold_voxels']:g} voxels; {s['cards']} card(s), {s['empty']} "
             f"empty). Target (at least 3 of 4 not cards): {verdict}.", "",
             "Away from the input view there is **no ground truth**: the numbers below describe the "
             "reconstruction (means over the photos), they do not score it. Above θ: the camera raised by θ; "
             "beside φ: turned by φ towards the input image's right. Coverage: share of pixels with alpha > ½; "
             "the half-opacity depth is measured along each view.", "",
             _novel_table(trained), "",
             f"Per photo ({trained.method}):", "",
             _per_photo_table(trained, section.folder), ""]
    if figure_link:
        lines += [f"![{section.run}: photo | input view | novel views]({figure_link})", ""]
    lines += priors_markdown(section.priors, section.evidence, heading="###")
    if section.judgements:
        lines += judge_markdown(section)
    return lines


def judge_markdown(section: PhotoSection) -> List[str]:
    """The report's lines for the judge of one folder run (docs/evaluation.md, :mod:`.judge`)."""
    j0 = section.judgements[0][1]
    lines = [f"### Judged from every side: {section.run}", "",
             f"No ground truth, so a judge: a fresh critic (seeded, {CRITIC_STEPS} steps by default, "
             f"{CRITIC_REPEATS} critics averaged, each with its own random views) learns to tell the run's training "
             f"photos from renders of their reconstructions at random turntable views (about the object's vertical "
             f"axis, at the input camera's elevation), then tells the {j0.c2st['photos']} held-out photos from "
             f"renders of theirs, per band of angle from the input view. Accuracy 0.5: the renders pass for photos; 1: they never do. In "
             f"brackets the AUC: how often the critic ranks a held-out photo above a render (0.5: alike), whatever "
             f"its threshold.", "",
             judge_table(section.judgements), ""]
    lines += [f"- **{method}: the critic calls {100 * j.c2st['photo_pass']:.0f} % of the held-out photos photos.** "
              f"Below half, it has learnt its training photos rather than the class, and its accuracies above "
              f"measure that, not the renders: read the turntable figure (docs/evaluation.md, \"When the critic "
              f"memorises\")." for method, j in section.judgements if j.c2st["photo_pass"] < 0.5]
    if lines[-1] != "":
        lines.append("")
    lines += ["Image statistics of the side (±90°) and back (180°) turntable views, means over the held-out photos: "
             "roughness = mean |Laplacian| of the render over white on the object, relative to the input-view "
             "render (speckle, checkerboards: > 1) and, for the input view, to the photo; ΔE (CIE76) of the mean "
             "L*a*b* colour against the photo's and the sliced Wasserstein distance of the colour distributions; "
             "coverage relative to the input-view render (near 0: the object vanished).", "",
             stats_table(section.judgements), ""]
    if section.judge_figure is not None:
        turns = ", ".join(f"{a:g}°" for a in FIGURE_AZIMUTHS)
        lines += [f"![{section.run}: photo | turntable at {turns}](figures/{section.judge_figure.name})", ""]
    return lines


def write_judge_figure(section: PhotoSection, path: PathLike) -> Optional[Path]:
    """A PNG, one line per example of the trained model's judgement: the photo | its reconstruction on
    the turntable at :data:`~.judge.FIGURE_AZIMUTHS`; None when there is no example."""
    if not section.judgements or not section.judgements[0][1].examples:
        return None
    method, j = section.judgements[0]
    titles = ["photo"] + [f"{a:g}°" for a in FIGURE_AZIMUTHS]
    lines = [[photo] + list(renders) for _, photo, renders in j.examples]
    labels = [_short(file, section.folder) for file, _, _ in j.examples]
    section.judge_figure = save_image_grid(lines, titles, path, f"{method}: held-out photos on the turntable",
                                           cell=(1.2, 1.3), extra_height=0.4, labels=labels)
    return section.judge_figure


def section_results(section: PhotoSection) -> List[Dict[str, Any]]:
    """``results.json`` entries of a folder run: one per row, with ``section: "photos"``, the
    per-photo records under ``pairs`` (as the Table 2 rows), ``means`` and the card check; the first
    (the trained run's) also its ``shape_priors`` (:func:`~.priors.priors_results`)."""
    judged = {m: j for m, j in section.judgements}
    priors = {"shape_priors": priors_results(section.priors, section.evidence)}
    return [{"method": r.method, "formation": r.formation, "section": "photos", "photo_folder": section.folder,
             "resolution": r.resolution, "means": r.means(), "card_check": r.summary, "pairs": r.photos,
             **({"judge": {**judged[r.method].summary(), "c2st": judged[r.method].c2st,
                           "photos": judged[r.method].photos}} if r.method in judged else {}),
             **(priors if i == 0 else {})}
            for i, r in enumerate(section.rows)]
