"""A judge of novel views without ground truth: does a reconstruction look like a photo from every side?

A run trained on photos has no 3D truth, and away from the input view nobody photographed the
object. What the photos do say is what objects of the class look like: the judge asks whether
renders of the run's reconstructions, seen from the side and the back, are told apart from
photos, and measures what a person sees in the turntables (speckle, drifted colour, a vanishing
silhouette). docs/evaluation.md ("Judging novel views without ground truth") explains the use.

**Views.** A turntable about the object's vertical axis, the camera keeping the input camera's
elevation θ̂: ω(φ, θ̂) = (cos θ̂ sin φ, sin θ̂, cos θ̂ cos φ)
(:func:`~mitsuba_platonic.views.from_angles`) in the object's frame. For a model with a pose head (``train.pose: elevation``) that frame is G's
upright one and θ̂ the head's estimate per photo
(:meth:`~mitsuba_platonic.model.Model.reconstruct_upright`); for one without, it is the input
camera's frame and θ̂ = 0, ω(φ, 0) = (sin φ, 0, cos φ). At φ = 0 either is the input view. (Turning
about the input camera's vertical axis instead shows an object seen from θ̂ above as leaning by θ̂
at the side, its trunk slanted: no photo shows that, and it was the critic's main cue on the tree
photos: docs/evaluation.md, "The turntable's axis".) The angle from the input view is |φ|, grouped in
:data:`BANDS`: input (0°), near (15–45°), side (60–120°), back (135–180°), scored at
:data:`SCORE_AZIMUTHS` (every 15°).

**Classifier two-sample test** (:func:`two_sample_test`). A fresh critic f (:class:`Critic`: three
or four stride-2 convolutions with LeakyReLU, then a linear logit; no normalisation) is trained
with a fixed seed and budget (:data:`CRITIC_STEPS` Adam steps on balanced batches, random
horizontal flips of both classes) to tell the run's *training* photos (label 1) from renders of
its reconstructions of those photos at uniformly random φ (label 0), by the logistic loss
softplus(−f(photo)) + softplus(f(render)). It is then scored on *held-out* photos against renders
of the held-out reconstructions in each band b:

    acc_b = ½ · ( mean_{x held out} [f(x) > 0] + mean_{r in band b} [f(r) ≤ 0] )

0.5: the critic cannot tell renders in that band from photos; 1: it always can. The photo term is
the same for every band, so bands are comparable. It is also reported on its own, as the share of
held-out photos the critic calls photos, p = mean_x [f(x) > 0]: a critic that has memorised its
few dozen training photos calls unseen photos renders (p well below ½), and then the band
accuracies say more about p than about the renders (on the tree photos, over 18 runs, the side
band's accuracy follows p with Pearson's r = 0.97; docs/evaluation.md, "When the critic
memorises"). Hence also the threshold-free form of the same test, the area under the critic's
ROC curve per band (Mann–Whitney),

    AUC_b = mean over held-out photos x and renders r in band b of ( [f(x) > f(r)] + ½ [f(x) = f(r)] )

0.5: photos and renders are ranked alike; 1: every photo above every render. It does not move with
where the critic puts its threshold, only with how it orders unseen photos and renders.

Every figure is averaged over :data:`CRITIC_REPEATS` critics, critic r seeded with ``seed + r`` and
trained on renders at its own random views (seeded likewise): a critic that memorises a few dozen
photos decides the held-out ones almost by chance, and on the tree photos three critics sharing one set
of views put one run's side accuracy anywhere in a range of 0.23 from one judge seed to the next;
ten with their own views, within about 0.05 (docs/evaluation.md, "The judge's own noise"). With M
held-out photos each critic's accuracy moves in steps of 1/(2M); the report says M.

**Image statistics** (:mod:`.image_stats`), per held-out photo x with reconstruction V, renders
I_φ = R(ω(φ, θ̂), V) with the run's renderer:

- roughness ratio at the side (mean of φ = ±90°) and the back (φ = 180°):
  rough(I_φ) / rough(I_0); and the input view's own rough(I_0) / rough(x) (speckle the photo
  does not have);
- colour: ΔE (CIE76) of the mean foreground L*a*b* of I_φ against the photo's, and the sliced
  Wasserstein-1 distance of the two foreground colour distributions; the same ΔE for I_0 says how
  much of it the input view already has (E's colour, not the unseen side's);
- coverage ratio coverage(I_φ) / coverage(I_0): near 0, the object vanished (a card seen edge-on);
- the front-card check (:func:`~.photos.card_check`) as for every photo run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from ..errors import UserError
from ..render import RenderSettings, render_with
from ..views import from_angles
from . import image_stats as S

__all__ = ["BANDS", "SCORE_AZIMUTHS", "STAT_VIEWS", "CRITIC_STEPS", "CRITIC_REPEATS", "TRAIN_VIEWS",
           "band_of", "Critic", "two_sample_test", "view_statistics", "Judgement", "judge", "judge_table",
           "stats_table", "render_pairs", "random_renders", "turntable_renders", "volumes_and_elevations",
           "train_critic"]

#: What a reconstruct function answers: volumes in the input camera's frame, or (volumes, the input
#: cameras' elevations in degrees) in the object's frame (:func:`judge`).
Reconstruction = Union[torch.Tensor, Tuple[torch.Tensor, torch.Tensor]]

#: (name, lowest |φ|, highest |φ|) in degrees, inclusive.
BANDS: Tuple[Tuple[str, float, float], ...] = (("input", 0.0, 0.0), ("near", 15.0, 45.0),
                                               ("side", 60.0, 120.0), ("back", 135.0, 180.0))
#: The turntable azimuths at which held-out reconstructions are scored (degrees, every 15°).
SCORE_AZIMUTHS: Tuple[float, ...] = tuple(float(a) for a in range(-165, 181, 15))
#: Views of the image statistics: name → azimuths averaged.
STAT_VIEWS: Dict[str, Tuple[float, ...]] = {"side": (-90.0, 90.0), "back": (180.0,)}
#: Adam steps of each critic, critics averaged, random views per training reconstruction.
CRITIC_STEPS = 300
CRITIC_REPEATS = 10
TRAIN_VIEWS = 8


def band_of(azimuth: float) -> Optional[str]:
    """The band of a turntable azimuth (degrees), by |φ| (wrapped to [0°, 180°]); None between bands."""
    a = abs((float(azimuth) + 180.0) % 360.0 - 180.0)
    for name, lo, hi in BANDS:
        if lo - 1e-6 <= a <= hi + 1e-6:
            return name
    return None


class Critic(nn.Module):
    """The two-sample test's classifier: stride-2 4×4 convolutions (``width``, 2·``width``, …) with
    LeakyReLU(0.2) from ``resolution`` down to 4², then one linear logit."""

    def __init__(self, channels: int, resolution: int, width: int = 16):
        super().__init__()
        if resolution < 8 or resolution & (resolution - 1):
            raise UserError(f"the two-sample critic needs a power-of-two image size ≥ 8, got {resolution}")
        layers: List[nn.Module] = []
        c, r, w = channels, resolution, width
        while r > 4:
            layers += [nn.Conv2d(c, w, 4, 2, 1), nn.LeakyReLU(0.2)]
            c, r, w = w, r // 2, w * 2
        self.features = nn.Sequential(*layers)
        self.logit = nn.Linear(c * r * r, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logit(self.features(x).flatten(1)).squeeze(1)


def _check_images(x: torch.Tensor, name: str) -> torch.Tensor:
    if not isinstance(x, torch.Tensor) or x.dim() != 4 or x.shape[1] not in (1, 4) or not len(x):
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise UserError(f"{name} must be a non-empty (N, C, R, R) tensor with C = 1 or 4, got {shape}")
    if not torch.isfinite(x).all():
        raise UserError(f"{name} holds NaN or Inf")
    return x.detach().float().cpu()


def train_critic(photos: torch.Tensor, renders: torch.Tensor, seed: int, steps: int, batch: int) -> Critic:
    """A :class:`Critic` trained ``steps`` steps of ``batch`` to tell ``photos`` from ``renders``
    (seeded: its initial weights and batches)."""
    g = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)                                       # the critic's initial weights
    critic = Critic(photos.shape[1], photos.shape[-1])
    opt = torch.optim.Adam(critic.parameters(), lr=2e-4, betas=(0.5, 0.999))
    half = batch // 2
    for _ in range(steps):
        xp = photos[torch.randint(len(photos), (half,), generator=g)]
        xr = renders[torch.randint(len(renders), (half,), generator=g)]
        x = torch.cat([xp, xr])
        flip = torch.rand(len(x), generator=g) < 0.5               # a mirrored photo is still a photo
        x = torch.where(flip[:, None, None, None], x.flip(-1), x)
        logits = critic(x)
        loss = F.softplus(-logits[:half]).mean() + F.softplus(logits[half:]).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return critic.eval()


def two_sample_test(train_photos: torch.Tensor, train_renders: Union[torch.Tensor, Sequence[torch.Tensor]],
                    test_photos: torch.Tensor,
                    test_renders: Dict[str, torch.Tensor], seed: int = 0, steps: int = CRITIC_STEPS,
                    repeats: int = CRITIC_REPEATS, batch: int = 32) -> Dict[str, Any]:
    """The classifier two-sample test (module docstring).

    ``train_photos`` ``(N, C, R, R)`` and ``train_renders`` ``(N', C, R, R)`` train ``repeats``
    critics (seeds ``seed`` …), or with a sequence of ``repeats`` render sets, critic r learns from
    the r-th (its own random views); each is scored on ``test_photos`` against every entry of
    ``test_renders`` (band name → ``(K, C, R, R)``). Returns ``accuracy`` (band → mean accuracy over
    the critics), ``spread`` (band → their standard deviation), ``train_accuracy`` (on the training
    sets, a check that the critic learnt at all), ``photo_pass`` (the share of held-out photos the
    critics call photos, mean over them), ``auc`` (band → mean AUC over the critics), ``photos`` (M) and
    ``renders`` (band → K)."""
    train_photos = _check_images(train_photos, "train_photos")
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise UserError(f"repeats must be a positive int, got {repeats!r}")
    if isinstance(train_renders, torch.Tensor):
        train_renders = [train_renders] * repeats
    elif len(train_renders) != repeats:
        raise UserError(f"{len(train_renders)} render sets for {repeats} critics: one set each, or one tensor for all")
    train_renders = [_check_images(x, f"train_renders[{i}]") for i, x in enumerate(train_renders)]
    test_photos = _check_images(test_photos, "test_photos")
    if not test_renders:
        raise UserError("test_renders must hold at least one band of renders")
    bands = {k: _check_images(v, f"test_renders[{k!r}]") for k, v in test_renders.items()}
    shape = train_photos.shape[1:]
    for name, x in [("train_renders", train_renders[0]), ("test_photos", test_photos)] + \
            [(f"test_renders[{k!r}]", v) for k, v in bands.items()]:
        if x.shape[1:] != shape:
            raise UserError(f"{name} has images of shape {tuple(x.shape[1:])}, the training photos {tuple(shape)}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise UserError(f"steps must be a positive int, got {steps!r}")
    if isinstance(batch, bool) or not isinstance(batch, int) or batch < 2:
        raise UserError(f"batch must be an int ≥ 2, got {batch!r}")
    acc: Dict[str, List[float]] = {k: [] for k in bands}
    train_acc: List[float] = []
    photo_pass: List[float] = []
    auc: Dict[str, List[float]] = {k: [] for k in bands}
    threads = torch.get_num_threads()
    # one thread: the critic's convolutions are too small to share (two threads ran 10× slower on a busy 2-core machine)
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]):                   # the caller's global RNG stays as it was
            _score_critics(train_photos, train_renders, test_photos, bands, seed, steps, repeats, batch,
                           acc, train_acc, photo_pass, auc)
    finally:
        torch.set_num_threads(threads)
    return {"accuracy": {k: float(np.mean(v)) for k, v in acc.items()},
            "spread": {k: float(np.std(v)) for k, v in acc.items()},
            "train_accuracy": float(np.mean(train_acc)), "photo_pass": float(np.mean(photo_pass)),
            "auc": {k: float(np.mean(v)) for k, v in auc.items()}, "photos": len(test_photos),
            "renders": {k: len(v) for k, v in bands.items()}}


def _score_critics(train_photos: torch.Tensor, train_renders: Sequence[torch.Tensor], test_photos: torch.Tensor,
                   bands: Dict[str, torch.Tensor], seed: int, steps: int, repeats: int, batch: int,
                   acc: Dict[str, List[float]], train_acc: List[float], photo_pass: List[float],
                   auc: Dict[str, List[float]]) -> None:
    """Train ``repeats`` critics and append their accuracies to ``acc`` (per band) and ``train_acc``,
    the share of held-out photos each calls photos to ``photo_pass``, and their AUCs to ``auc``."""
    for r in range(repeats):
        critic = train_critic(train_photos, train_renders[r], seed + r, steps, batch)
        with torch.no_grad():
            f_photo = critic(test_photos).flatten()
            real = float((f_photo > 0).float().mean())
            photo_pass.append(real)
            for k, x in bands.items():
                f_render = critic(x).flatten()
                acc[k].append(0.5 * (real + float((f_render <= 0).float().mean())))
                above = f_photo[:, None] - f_render[None, :]           # every (photo, render) pair
                auc[k].append(float(((above > 0).double() + 0.5 * (above == 0).double()).mean()))
            train_acc.append(0.5 * (float((critic(train_photos) > 0).float().mean())
                                    + float((critic(train_renders[r]) <= 0).float().mean())))


def render_pairs(volumes: torch.Tensor, index: torch.Tensor, views: torch.Tensor, settings: RenderSettings,
                  seed: int, chunk: int = 64) -> torch.Tensor:
    """``(P, C, R, R)``: volume ``index[p]`` rendered from ``views[p]`` for every pair p, in chunks of
    pairs, clipped to [0, 1]."""
    out = []
    with torch.no_grad():
        for i in range(0, len(index), chunk):
            out.append(render_with(volumes[index[i:i + chunk]].contiguous(), views[i:i + chunk].contiguous(),
                                   settings, seed).detach().float().cpu().clamp(0.0, 1.0))
    return torch.cat(out)


def turntable_renders(volumes: torch.Tensor, elevations: torch.Tensor, azimuths: Sequence[float], settings: RenderSettings,
                      seed: int) -> torch.Tensor:
    """``(A, M, C, R, R)``: every volume m rendered at every azimuth, ω(φ, θ̂_m) (``elevations`` in degrees)."""
    m = len(volumes)
    phi = torch.tensor(list(azimuths), dtype=torch.float64).repeat_interleave(m)                 # (A M,)
    views = from_angles(phi, elevations.double().repeat(len(azimuths)))
    out = render_pairs(volumes, torch.arange(m).repeat(len(azimuths)), views, settings, seed)
    return out.reshape(len(azimuths), m, *out.shape[1:])


def random_renders(volumes: torch.Tensor, elevations: torch.Tensor, k: int, settings: RenderSettings,
                   seed: int) -> torch.Tensor:
    """``(M k, C, R, R)``: each volume m at ``k`` uniformly random turntable azimuths (seeded), ω(φ, θ̂_m)."""
    g = torch.Generator().manual_seed(seed)
    phi = torch.rand(len(volumes) * k, generator=g, dtype=torch.float64) * 360.0 - 180.0
    index = torch.arange(len(volumes)).repeat_interleave(k)
    return render_pairs(volumes, index, from_angles(phi, elevations.double()[index]), settings, seed)


def volumes_and_elevations(out: Any, n: int, what: str) -> Tuple[torch.Tensor, torch.Tensor]:
    """A reconstruct function's answer for ``n`` photos, volumes or (volumes, elevations in degrees),
    as float32 CPU volumes in [0, 1] and float64 elevations (0 where none are given)."""
    v, θ = out if isinstance(out, tuple) else (out, None)
    if not isinstance(v, torch.Tensor) or v.dim() != 5 or len(v) != n:
        raise UserError(f"{what} must be (M, C, N, N, N) volumes with M = {n}, got "
                        f"{tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__}")
    θ = torch.zeros(n, dtype=torch.float64) if θ is None else torch.as_tensor(θ).detach().double().cpu()
    if θ.shape != (n,) or not torch.isfinite(θ).all():
        raise UserError(f"{what}: one finite elevation per volume expected, shape ({n},), got {tuple(θ.shape)}")
    return v.detach().float().cpu().clamp(0.0, 1.0), θ


def _mean(values: Sequence[Optional[float]]) -> Optional[float]:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else None


def view_statistics(photo: torch.Tensor, renders: Dict[float, torch.Tensor]) -> Dict[str, Optional[float]]:
    """The image statistics of one held-out photo ``(C, R, R)`` and its reconstruction's renders
    (azimuth → ``(C, R, R)``; 0 and every azimuth of :data:`STAT_VIEWS` must be there). Keys:
    ``roughness_input`` (rough(I_0) / rough(photo)), for RGBA ``delta_e_input`` (I_0's mean colour
    against the photo's: how much of a side view's ΔE the input view already has); per view v in
    :data:`STAT_VIEWS`:
    ``roughness_<v>`` (rough(I_v) / rough(I_0)), ``coverage_<v>`` (coverage(I_v) / coverage(I_0)) and,
    for RGBA, ``delta_e_<v>`` and ``sliced_w1_<v>`` against the photo; None where undefined
    (nothing covered)."""
    missing = [a for a in (0.0, *[a for v in STAT_VIEWS.values() for a in v]) if a not in renders]
    if missing:
        raise UserError(f"view_statistics needs renders at azimuths {missing}")
    front = renders[0.0]
    r0, c0 = S.roughness(front), S.coverage(front)
    rp = S.roughness(photo)
    out: Dict[str, Optional[float]] = {"roughness_input": r0 / rp if r0 is not None and rp else None}
    rgba = photo.shape[0] == 4
    if rgba:
        out["delta_e_input"] = S.colour_distance(front, photo)["delta_e"]
    for name, azimuths in STAT_VIEWS.items():
        imgs = [renders[a] for a in azimuths]
        rough = [S.roughness(i) for i in imgs]
        out[f"roughness_{name}"] = _mean([r / r0 for r in rough if r is not None]) if r0 else None
        out[f"coverage_{name}"] = _mean([S.coverage(i) / c0 for i in imgs]) if c0 > 0 else None
        if rgba:
            dists = [S.colour_distance(i, photo) for i in imgs]
            out[f"delta_e_{name}"] = _mean([d["delta_e"] for d in dists])
            out[f"sliced_w1_{name}"] = _mean([d["sliced_w1"] for d in dists])
    return out


@dataclass
class Judgement:
    """What :func:`judge` found: ``c2st`` (:func:`two_sample_test`'s result), ``photos`` (one
    :func:`view_statistics` record per held-out photo, with its ``file``), ``means`` (their means),
    and ``examples``: up to a few (file, photo, ``(len(FIGURE_AZIMUTHS), C, R, R)`` renders)."""

    c2st: Dict[str, Any]
    photos: List[Dict[str, Any]] = field(default_factory=list)
    means: Dict[str, Optional[float]] = field(default_factory=dict)
    examples: List[Tuple[str, torch.Tensor, torch.Tensor]] = field(default_factory=list)

    def summary(self) -> Dict[str, Any]:
        """A flat, JSON-ready record: ``c2st_<band>`` accuracies and the statistics' means."""
        out: Dict[str, Any] = {f"c2st_{k}": v for k, v in self.c2st["accuracy"].items()}
        out["c2st_train"] = self.c2st["train_accuracy"]
        out["c2st_photo_pass"] = self.c2st["photo_pass"]
        out.update({f"c2st_auc_{k}": v for k, v in self.c2st["auc"].items()})
        out.update(self.means)
        return out


#: The turntable azimuths of the judge's figure.
FIGURE_AZIMUTHS: Tuple[float, ...] = (0.0, 45.0, 90.0, 135.0, 180.0, -90.0)


def judge(reconstruct: Callable[[torch.Tensor], Reconstruction], train_photos: torch.Tensor,
          test_photos: torch.Tensor, settings: RenderSettings, files: Optional[Sequence[str]] = None,
          seed: int = 0, steps: int = CRITIC_STEPS, repeats: int = CRITIC_REPEATS,
          train_views: int = TRAIN_VIEWS, n_examples: int = 0, batch: int = 32,
          test_volumes: Optional[Reconstruction] = None) -> Judgement:
    """Judge a reconstruction model on photos (module docstring): ``reconstruct`` maps ``(B, C, R, R)``
    photos to ``(B, C, N, N, N)`` volumes in the input frame, or to (volumes, elevations) in the
    object's frame with the input cameras' elevations θ̂ ``(B,)`` in degrees there
    (:meth:`~mitsuba_platonic.model.Model.reconstruct_upright`); ``settings`` is the run's renderer.
    ``train_photos`` train the critics (their reconstructions seen from ``train_views`` random
    azimuths each); ``test_photos`` (with their ``files``) are scored, through ``test_volumes``
    (the same kind of answer) where the caller has reconstructed them already."""
    train_photos = _check_images(train_photos, "train_photos")
    test_photos = _check_images(test_photos, "test_photos")
    files = [str(f) for f in files] if files is not None else [f"#{i}" for i in range(len(test_photos))]
    if len(files) != len(test_photos):
        raise UserError(f"{len(files)} file names for {len(test_photos)} test photos")

    def volumes_of(x: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        with torch.no_grad():
            parts = [volumes_and_elevations(reconstruct(x[i:i + batch]), len(x[i:i + batch]), "reconstruct")
                     for i in range(0, len(x), batch)]
        return torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])

    train_volumes, train_elevations = volumes_of(train_photos)
    train_renders = [random_renders(train_volumes, train_elevations, train_views, settings, seed + r)
                     for r in range(repeats)]                           # each critic its own random views
    test_volumes, test_elevations = volumes_of(test_photos) if test_volumes is None else \
        volumes_and_elevations(test_volumes, len(test_photos), "test_volumes")
    azimuths = sorted(set(SCORE_AZIMUTHS) | set(FIGURE_AZIMUTHS))
    table = turntable_renders(test_volumes, test_elevations, azimuths, settings, seed)     # (A, M, C, R, R)
    at = {a: table[i] for i, a in enumerate(azimuths)}
    bands = {name: torch.cat([at[a] for a in SCORE_AZIMUTHS if band_of(a) == name]) for name, _, _ in BANDS}
    result = Judgement(two_sample_test(train_photos, train_renders, test_photos, bands, seed, steps, repeats))
    for i, (file, photo) in enumerate(zip(files, test_photos)):
        rec: Dict[str, Any] = {"file": file}
        rec.update(view_statistics(photo, {a: at[a][i] for a in at}))
        result.photos.append(rec)
        if len(result.examples) < n_examples:
            result.examples.append((file, photo, torch.stack([at[a][i] for a in FIGURE_AZIMUTHS])))
    keys = [k for k in result.photos[0] if k != "file"]
    result.means = {k: _mean([p[k] for p in result.photos]) for k in keys}
    return result


def _num(value: Optional[float], digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def judge_table(rows: Sequence[Tuple[str, Judgement]]) -> str:
    """Markdown: per method, the two-sample critic's accuracy per band (0.5: indistinguishable from
    the held-out photos) with its AUC in brackets, on its own training sets, and the share of held-out
    photos it calls photos."""
    names = [b[0] for b in BANDS]
    head = " | ".join(f"{n} ({lo:g}–{hi:g}°)" if hi > lo else f"{n} ({lo:g}°)" for n, lo, hi in BANDS)
    lines = [f"| Method | {head} | critic on its training sets | held-out photos called photos | "
             f"held-out photos |", "|---|" + "---|" * (len(names) + 3)]
    for method, j in rows:
        acc, auc = j.c2st["accuracy"], j.c2st["auc"]
        cells = " | ".join(f"{_num(acc.get(n))} ({_num(auc.get(n), 2)})" for n in names)
        lines.append(f"| {method} | {cells} | {_num(j.c2st['train_accuracy'])} | {_num(j.c2st['photo_pass'], 2)} | "
                     f"{j.c2st['photos']} |")
    return "\n".join(lines)


def stats_table(rows: Sequence[Tuple[str, Judgement]]) -> str:
    """Markdown: per method, the image statistics' means over the held-out photos."""
    lines = ["| Method | input-view roughness / photo's | side roughness / input view's | back roughness / input "
             "view's | input-view ΔE | side ΔE | back ΔE | side SW₁ | back SW₁ | side coverage / input's | "
             "back coverage / input's |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for method, j in rows:
        m = j.means
        lines.append(f"| {method} | {_num(m.get('roughness_input'), 2)} | {_num(m.get('roughness_side'), 2)} | "
                     f"{_num(m.get('roughness_back'), 2)} | {_num(m.get('delta_e_input'), 1)} | "
                     f"{_num(m.get('delta_e_side'), 1)} | "
                     f"{_num(m.get('delta_e_back'), 1)} | {_num(m.get('sliced_w1_side'), 1)} | "
                     f"{_num(m.get('sliced_w1_back'), 1)} | {_num(m.get('coverage_side'), 2)} | "
                     f"{_num(m.get('coverage_back'), 2)} |")
    return "\n".join(lines)
