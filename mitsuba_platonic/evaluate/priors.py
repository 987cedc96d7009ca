"""The shape priors a photo run used, and what its collection's silhouettes say about one of them.

**The priors** (:func:`priors_used`). A photo alone leaves everything behind its surface free;
the photo configs fill it in with priors, terms and settings that assume something about the
class or the photos (docs/training.md, "What the photo recipe assumes"). :func:`priors_used`
reads them off a run's config: each active one as a :class:`Prior` with its key, its value,
one line of what it assumes, and whether it assumes a class **round about its vertical**
(``train.turn``, ``model.texture_turns: 4``, ``model.offsets_behind: false``: the three that
:data:`ROUND_OFF` turns off together).

**The evidence** (:func:`round_evidence`), from the photos alone, with no model. Let S be a
photo's opacity (the alpha mask the photo loader gives, ``(R, R)``, values in [0, 1], row 0 the
top) and, for a vertical mirror line at column c, (M_c S)(y, x) = S(y, 2c − x), 0 where 2c − x
falls outside the image. The photo's mirror asymmetry is

    A(S) = min_c Σ |S − M_c S| / Σ S,     c ∈ {x̄ + k/2 : |k| ≤ K}, x̄ = S's centroid column
                                           (rounded to a half pixel), K = :data:`AXIS_SEARCH`

in [0, 2]: 0 for a silhouette that is its own mirror image about some line within K/2 pixels of
its centroid, 2 when the mirror image misses the silhouette entirely. Let c* be the line that
attains the minimum (the leftmost where several do) and ȳ = Σ y S / Σ S the centroid row. The
photo's **upper asymmetry**, the verdict's statistic, is the same sum over the rows above ȳ only,
about the whole silhouette's line c*:

    U(S) = Σ_{y < ȳ} Σ_x |S − M_c* S| / Σ_{y < ȳ} Σ_x S,     in [0, 2]

(NaN where no row lies above ȳ). An object round about its vertical (a body of revolution) shows
from every side at every elevation a silhouette each of whose rows is centred on one vertical
line, its axis: A = U = 0 up to pixels and instance irregularity (a tree's lopsided crown, a
mushroom's tilted cap). A body longer than it is wide shows its two ends from the side: a chair's
back, an aeroplane's nose, fin and tail, an animal's head and tail. A is the area that differs
over the whole area; an animal's head is small against its body and legs, which are their own
mirror image about the body's centre, so A stays low on animals from the side (0.36, as on the
procedural trees). The body and legs still fix c* at the body's centre, and above ȳ the head is a
large part of what is left: U is large. The collection's figure is the **median of U over its
photos** (robust to the few strongly lopsided instances of a round class); the collection
contradicts a round prior when it exceeds :data:`UPPER_THRESHOLD` (and it has at least
:data:`MIN_PHOTOS` photos). The mean of A is reported beside it, not judged.

Beside them, the spread of the silhouettes' width over height, σ_x / σ_y (the opacity-weighted
standard deviations of the column and the row), as the standard deviation over the photos of
ln(σ_x / σ_y). It was measured and does **not** tell round from not round: the variation
between instances of a round class (squat and tall mushrooms) is as large as what the view
adds for a chair. Reported, never a verdict.

The threshold was measured, not assumed: on EA renders of the procedural classes at uniform
random azimuths (mushroom, tree: round; chair, airplane, animal: not), on chairs, aeroplanes and
animals seen only from within ±30° of a side view, on the tree photos and on the suite's
path-traced collections of aeroplanes and animals, each through the photo loader as
``configs/photos.yaml`` frames photos (32², ``crop: bbox``). The table and the command that
prints it: docs/evaluation.md, "Shape priors and the collection's evidence"
(``benchmarks/shape_evidence.py``). What U cannot see is said there too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import torch

from ..errors import UserError

__all__ = ["Prior", "RoundEvidence", "priors_used", "round_priors", "mirror_asymmetry", "upper_asymmetry",
           "aspect", "round_evidence", "contradictions", "priors_markdown", "priors_results", "warning_lines",
           "UPPER_THRESHOLD", "AXIS_SEARCH", "MIN_PHOTOS", "ROUND_OFF", "WARNING"]

#: The median upper asymmetry U above which a collection contradicts a round prior (module docstring):
#: every round collection measured lies at or below 0.19, every one that is not at or above 0.33, at
#: 32² (and at 16² and 64²; docs/evaluation.md).
UPPER_THRESHOLD = 0.25
#: Half-pixel steps either side of the centroid over which the mirror line is searched (2 pixels).
AXIS_SEARCH = 4
#: Fewer photos than this give no verdict (the mean of a handful is noise).
MIN_PHOTOS = 8
#: The overrides that turn the round priors off together (the config refuses offsets_behind false
#: without texture_turns 4).
ROUND_OFF = ("train.turn=0", "model.texture_turns=1", "model.offsets_behind=true")
#: How the report's warning lines begin (:func:`warning_lines` finds them again).
WARNING = "**Warning:"


@dataclass(frozen=True)
class Prior:
    """One shape prior of a run: its config ``key``, the ``value`` it had, what it ``assumes`` (one
    line), and whether it assumes a class round about its vertical (``round``)."""

    key: str
    value: Any
    assumes: str
    round: bool = False


def _band(train: Any) -> str:
    el = train.elevation
    if train.view_distribution == "band" and isinstance(el, (list, tuple)):
        return f"band {el[0]:g}°…{el[1]:g}°"
    if train.view_distribution == "ring":
        return f"ring at {el if el is not None else 20.0:g}°"
    return str(train.view_distribution)


def priors_used(cfg: Any) -> List[Prior]:
    """The shape priors of a reconstruction run's config ``cfg`` (a loaded config: ``cfg.model``,
    ``cfg.train``), in the order of docs/training.md's table; a prior whose weight is 0 or whose
    flag is off is not listed. Only settings that decide what a reconstruction looks like where
    the photo does not show it are listed (not learning rates, not the critic's penalties)."""
    m, t = cfg.model, cfg.train
    out: List[Prior] = []
    if t.turn > 0:
        out.append(Prior("train.turn", t.turn, "the object is round about its vertical: its upright opacity is held "
                         "to itself turned by a random angle about the vertical", round=True))
    if m.texture_conv and m.texture_turns == 4:
        out.append(Prior("model.texture_turns", 4, "behind what the photo shows, the object looks as the photo does "
                         "from four cameras a quarter turn apart about the vertical: its sides and back are "
                         "textured like its front", round=True))
        if not m.offsets_behind:
            out.append(Prior("model.offsets_behind", False, "behind the seen surface the colour is that turned "
                             "texture as read, G does not correct it", round=True))
    if t.solidity > 0:
        out.append(Prior("train.solidity", t.solidity, "the object is solid: no gap along an input ray between its "
                         "first and its last surface (not a hollow or see-through object)"))
    if t.depth_spread > 0:
        out.append(Prior("train.depth_spread", t.depth_spread, "each input ray's colour comes from one thin surface, "
                         "not a haze (an opaque object)"))
    if t.pose == "elevation":
        out.append(Prior("train.pose", "elevation", "the object stands upright and each photo looks at it from an "
                         "elevation a pose head reads; G builds it in its own upright frame"))
    if t.task == "reconstruction" and t.mode in ("platonic", "platonic3d"):
        out.append(Prior("train.view_distribution", _band(t), "the random views the critic judges against the photos "
                         "are drawn at every azimuth: the photos are taken as showing the class from every side, "
                         "the sides as often as the front"))
    if "flip" in t.photo_augment or "flip" in t.d_augment:
        keys = [k for k, v in (("train.photo_augment", t.photo_augment), ("train.d_augment", t.d_augment))
                if "flip" in v]
        out.append(Prior(" / ".join(keys), "flip", "the class looks as plausible mirrored left–right as it is"))
    if m.photo_colour:
        out.append(Prior("model.photo_colour", True, "the object's colour everywhere is near the photo's "
                         "(an offset from the photo's colour)"))
    if m.photo_texture:
        out.append(Prior("model.photo_texture", True, "the colour the photo does not show continues the photo's "
                         "along the input camera's rays (the back coloured like the front)"))
    if t.colour_match > 0:
        out.append(Prior("train.colour_match", t.colour_match, "the object's mean colour is the same from every "
                         "side"))
    if t.colour_offset > 0:
        out.append(Prior("train.colour_offset", t.colour_offset, "G's colour stays close to the photo's"))
    if t.colour_tv > 0:
        out.append(Prior("train.colour_tv", t.colour_tv, "the colour is smooth over the object (no flecks)"))
    return out


def round_priors(priors: Sequence[Prior]) -> List[Prior]:
    """The priors of ``priors`` that assume a class round about its vertical."""
    return [p for p in priors if p.round]


def _masks(alpha: torch.Tensor) -> torch.Tensor:
    a = torch.as_tensor(alpha)
    if a.dim() == 2:
        a = a[None]
    if a.dim() != 3 or a.shape[-1] < 2 or a.shape[-2] < 2:
        raise UserError(f"expected opacity masks (M, H, W) or one (H, W), got shape {tuple(a.shape)}")
    a = a.detach().double().cpu()
    if not torch.isfinite(a).all() or a.min() < 0.0 or a.max() > 1.0:
        raise UserError("expected opacity masks with values in [0, 1]")
    return a


def _asymmetries(a: torch.Tensor, search: int) -> Tuple[torch.Tensor, torch.Tensor]:
    """A(S) and U(S) (module docstring) of each mask of ``a`` ``(M, H, W)`` (float64, checked): two
    ``(M,)``, NaN for an empty mask (U also where no row lies above the centroid row)."""
    h, w = a.shape[-2:]
    cols = torch.arange(w, dtype=torch.float64)
    rows = torch.arange(h, dtype=torch.float64)
    asym = torch.full((len(a),), math.nan, dtype=torch.float64)
    upper = torch.full((len(a),), math.nan, dtype=torch.float64)
    for i, s in enumerate(a):
        area = float(s.sum())
        if area <= 0.0:
            continue
        x̄ = float((s.sum(0) * cols).sum()) / area
        ȳ = float((s.sum(1) * rows).sum()) / area
        # flip(s)[x] = s[w − 1 − x] mirrors about (w − 1)/2; shifted right by k it mirrors about (w − 1 + k)/2
        k0 = round(2.0 * x̄ - (w - 1))
        flipped = s.flip(-1)
        best, best_diff = math.inf, None
        for k in range(k0 - search, k0 + search + 1):          # ascending k: the leftmost line wins a tie
            m = torch.zeros_like(s)                        # (M_c S)(y, x) = flipped(y, x − k), 0 outside
            if 0 <= k < w:
                m[:, k:] = flipped[:, :w - k]
            elif -w < k < 0:
                m[:, :w + k] = flipped[:, -k:]
            diff = (s - m).abs()
            value = float(diff.sum()) / area
            if value < best:
                best, best_diff = value, diff
        asym[i] = best
        above = rows < ȳ
        top = float(s[above].sum())
        if top > 0.0:
            upper[i] = float(best_diff[above].sum()) / top
    return asym, upper


def mirror_asymmetry(alpha: torch.Tensor, search: int = AXIS_SEARCH) -> torch.Tensor:
    """A(S) (module docstring) of each mask of ``alpha`` ``(M, H, W)`` (or one ``(H, W)``): ``(M,)``
    float64, NaN for an empty mask. Row 0 is the top; the mirror is about a vertical line."""
    return _asymmetries(_masks(alpha), search)[0]


def upper_asymmetry(alpha: torch.Tensor, search: int = AXIS_SEARCH) -> torch.Tensor:
    """U(S) (module docstring) of each mask of ``alpha`` ``(M, H, W)`` (or one ``(H, W)``): the
    asymmetry of the rows above the centroid row about the whole silhouette's mirror line; ``(M,)``
    float64, NaN for an empty mask or one with no row above its centroid row."""
    return _asymmetries(_masks(alpha), search)[1]


def aspect(alpha: torch.Tensor) -> torch.Tensor:
    """σ_x / σ_y of each mask of ``alpha`` ``(M, H, W)``: the opacity-weighted standard deviations of
    the column and the row (a filled ellipse of semi-axes a across, b down gives a / b); ``(M,)``
    float64, NaN for an empty mask or one without height."""
    a = _masks(alpha)
    h, w = a.shape[-2:]
    ys = torch.arange(h, dtype=torch.float64)[:, None].expand(h, w)
    xs = torch.arange(w, dtype=torch.float64)[None, :].expand(h, w)
    area = a.sum((-2, -1))
    safe = area.clamp_min(1e-300)
    cx, cy = (a * xs).sum((-2, -1)) / safe, (a * ys).sum((-2, -1)) / safe
    vx = (a * (xs - cx[:, None, None]) ** 2).sum((-2, -1)) / safe
    vy = (a * (ys - cy[:, None, None]) ** 2).sum((-2, -1)) / safe
    ratio = vx.sqrt() / vy.sqrt()
    return torch.where((area > 0) & (vy > 0), ratio, torch.full_like(ratio, math.nan))


@dataclass(frozen=True)
class RoundEvidence:
    """What a collection's silhouettes say about roundness (module docstring): ``photos`` with a
    silhouette, the median upper asymmetry over them (``upper_asymmetry``, the verdict's), the mean
    mirror ``asymmetry`` and the spread of ln(width / height) (``aspect_spread``; both descriptive),
    the ``resolution`` of the masks and the ``threshold`` on the median upper asymmetry."""

    photos: int
    upper_asymmetry: Optional[float]
    asymmetry: Optional[float]
    aspect_spread: Optional[float]
    resolution: int
    threshold: float = UPPER_THRESHOLD

    @property
    def decided(self) -> bool:
        """Whether there are enough photos (:data:`MIN_PHOTOS`) for a verdict."""
        return self.photos >= MIN_PHOTOS and self.upper_asymmetry is not None

    @property
    def not_round(self) -> bool:
        """The silhouettes contradict a round class: decided, and the median upper asymmetry above the threshold."""
        return self.decided and self.upper_asymmetry > self.threshold


def round_evidence(images: torch.Tensor, threshold: float = UPPER_THRESHOLD) -> RoundEvidence:
    """:class:`RoundEvidence` of photos ``(M, C, R, R)`` (the opacity their last channel, as the photo
    loader gives them) or masks ``(M, R, R)``; empty masks are left out (and, from the median, a
    silhouette with no row above its centroid row)."""
    x = torch.as_tensor(images)
    if x.dim() == 4:
        x = x[:, -1]
    if x.dim() != 3:
        raise UserError(f"round_evidence: expected photos (M, C, R, R) or masks (M, R, R), got {tuple(x.shape)}")
    resolution = int(x.shape[-1])
    if len(x) == 0:
        return RoundEvidence(0, None, None, None, resolution, threshold)
    masks = _masks(x)
    asym, upper = _asymmetries(masks, AXIS_SEARCH)
    ratio = aspect(masks)
    keep = ~torch.isnan(asym)
    n = int(keep.sum())
    u = upper[~torch.isnan(upper)]
    logs = torch.log(ratio[keep & ~torch.isnan(ratio) & (ratio > 0)])
    return RoundEvidence(photos=n, upper_asymmetry=float(u.quantile(0.5)) if len(u) else None,
                         asymmetry=float(asym[keep].mean()) if n else None,
                         aspect_spread=float(logs.std(unbiased=False)) if len(logs) > 1 else None,
                         resolution=resolution, threshold=threshold)


def contradictions(priors: Sequence[Prior], evidence: RoundEvidence) -> List[str]:
    """The report's warning lines (each begins with :data:`WARNING`): one where the run used a round
    prior and the evidence says the collection is not round; none otherwise."""
    used = round_priors(priors)
    if not used or not evidence.not_round:
        return []
    keys = ", ".join(f"`{p.key}: {_value(p.value)}`" for p in used)
    sets = " ".join(f"--set {s}" for s in ROUND_OFF)
    return [f"{WARNING} this run assumed a class round about its vertical ({keys}), and its photos say it is "
            f"not.** Their silhouettes' upper mirror asymmetry is {evidence.upper_asymmetry:.2f} (median over "
            f"{evidence.photos} photos), above {evidence.threshold:.2f}, above which no round collection measured lies "
            f"(docs/evaluation.md, "
            f"\"Shape priors and the collection's evidence\"): a body longer than it is wide (an animal, a vehicle, a "
            f"chair, an aeroplane) or photos taken mostly from the side. With these priors every reconstruction "
            f"comes out turned on a lathe, as broad end-on as from the side; do not trust its sides. Turning the round "
            f"priors off (`{sets}`) was measured no better on the photo suite's animals and worse on its "
            f"aeroplanes (docs/training.md, \"What the photo recipe assumes\")."]


def _value(v: Any) -> str:
    return "true" if v is True else "false" if v is False else f"{v:g}" if isinstance(v, float) else str(v)


def priors_markdown(priors: Sequence[Prior], evidence: Optional[RoundEvidence], heading: str = "##") -> List[str]:
    """The report's section "Shape priors this run used": a table of ``priors``, the collection's
    evidence about roundness and, where it contradicts a round prior, the warning (:func:`contradictions`)."""
    lines = [f"{heading} Shape priors this run used", "",
             "Behind the photo's surface a reconstruction is what these assume (docs/training.md, \"What the photo "
             "recipe assumes\"). Those marked round assume a class round about its vertical.", ""]
    if priors:
        lines += ["| key | value | assumes | round |", "|---|---|---|---|"]
        lines += [f"| `{p.key}` | {_value(p.value)} | {p.assumes} | {'yes' if p.round else ''} |" for p in priors]
    else:
        lines.append("None: every shape prior of the photo recipe is off.")
    lines.append("")
    if evidence is not None:
        if evidence.upper_asymmetry is None:
            lines += ["No silhouette in the photos to measure.", ""]
        else:
            spread = "—" if evidence.aspect_spread is None else f"{evidence.aspect_spread:.2f}"
            verdict = (f"too few photos for a verdict (at least {MIN_PHOTOS})" if not evidence.decided else
                       "not round" if evidence.not_round else "consistent with a round class")
            lines += [f"The collection's evidence, from its {evidence.photos} photos' silhouettes ({evidence.resolution}² "
                      f"masks): upper mirror asymmetry {evidence.upper_asymmetry:.2f} (median over the photos; 0: "
                      f"each silhouette's part above its centroid row is its own mirror image about the whole "
                      f"silhouette's mirror line; above {evidence.threshold:.2f}: not round): {verdict}. The whole "
                      f"silhouettes' mirror asymmetry, {evidence.asymmetry:.2f} (mean), and the spread of ln(width / "
                      f"height), {spread}, are shown, not judged: neither tells round from not round.", ""]
        lines += [*contradictions(priors, evidence)]
        if lines[-1] != "":
            lines.append("")
    return lines


def priors_results(priors: Sequence[Prior], evidence: Optional[RoundEvidence]) -> Dict[str, Any]:
    """``results.json``'s entry: the priors, the evidence and the warnings."""
    ev = None if evidence is None else {"photos": evidence.photos, "upper_asymmetry": evidence.upper_asymmetry,
                                        "asymmetry": evidence.asymmetry,
                                        "aspect_spread": evidence.aspect_spread, "resolution": evidence.resolution,
                                        "threshold": evidence.threshold, "not_round": evidence.not_round}
    return {"priors": [{"key": p.key, "value": p.value, "assumes": p.assumes, "round": p.round} for p in priors],
            "round_evidence": ev, "warnings": contradictions(priors, evidence) if evidence is not None else []}


def warning_lines(report: str) -> List[str]:
    """The warning lines of a report's text (:data:`WARNING`), without their Markdown emphasis, for the console."""
    return [line.replace("**", "").replace("`", "") for line in report.splitlines() if line.startswith(WARNING)]
