"""Evaluation metrics of the paper (Sec. 5.3, Table 2): 2D image re-synthesis and 3D volume measures.

2D, between two images of the same view (``(C, H, W)``, C = 1 opacity or C = 4 premultiplied
linear RGBA, values in [0, 1], as :func:`mitsuba_platonic.render` returns them):

- :func:`dssim` = (1 − SSIM) / 2, SSIM by scikit-image's ``structural_similarity`` on the
  *display* images (:func:`display_image`) with the parameters of Wang et al. 2004: an 11×11
  Gaussian window (σ = 1.5), K1 = 0.01, K2 = 0.03, population covariances, data range 1,
  averaged over colour channels. 0 for identical images, at most 1.
- :func:`image_rmse`: root-mean-square difference of the two images' values.
- :func:`silhouette_iou`: IoU of the silhouettes (alpha > ½) of two image batches.
- :func:`vgg_distance`: distance of VGG16 features; needs a weights file the user gives.

3D, between two volumes (``(C, N, N, N)`` or ``(N, N, N)``, the density is the last channel):

- :func:`volume_rmse`: root-mean-square difference of the densities.
- :func:`volume_iou`: IoU of the occupied voxels, density ≥ ``threshold`` (default ½).
- :func:`chamfer_distance`: the paper's density-weighted directional chamfer distance (formula
  in its docstring).
- :func:`best_tilt`: the turn about the input camera's horizontal axis that best aligns a
  reconstruction with its truth (the pose error of view-space reconstruction).

Distributions: :func:`fid` (Fréchet distance of network features of two image sets); needs a
weights file the user gives. No package installed here ships pretrained VGG16 or Inception
weights, so both feature metrics raise :class:`~mitsuba_platonic.errors.UserError` without one.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import List, Optional, Tuple, Union

import numpy as np
import torch
import torch.nn as nn

from ..errors import UserError
from ..images import composite, linear_to_srgb
from ..volume import voxel_size

__all__ = ["dssim", "display_image", "image_rmse", "silhouette_iou", "volume_rmse", "volume_iou",
           "chamfer_distance", "best_tilt", "depth_stripes", "half_opacity_depth", "load_feature_network", "vgg_distance",
           "fid", "SSIM_SIGMA", "IOU_THRESHOLD", "SILHOUETTE_THRESHOLD", "checked_threshold"]

#: Gaussian window of SSIM (Wang et al. 2004): σ = 1.5 px, truncated at 3.5σ → 11×11 pixels.
SSIM_SIGMA = 1.5
SSIM_WINDOW = 11
#: A voxel is occupied when its density is at least this (3D IoU, the chamfer distance's target).
IOU_THRESHOLD = 0.5
#: A pixel belongs to the silhouette when its alpha exceeds this.
SILHOUETTE_THRESHOLD = 0.5
#: ImageNet statistics the torchvision VGG16 weights expect (RGB in [0, 1]).
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)

ArrayLike = Union[np.ndarray, torch.Tensor]


# -- input checks ----------------------------------------------------------------------------

def _array(x: ArrayLike, name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    if not isinstance(x, np.ndarray):
        raise UserError(f"{name} must be a numpy array or torch tensor, got {type(x).__name__}")
    if not np.issubdtype(x.dtype, np.number) and x.dtype != np.bool_:
        raise UserError(f"{name} must hold numbers, got dtype {x.dtype}")
    x = x.astype(np.float64)
    if np.isnan(x).any():
        raise UserError(f"{name} contains NaN")
    if np.isinf(x).any():
        raise UserError(f"{name} contains Inf")
    return x


def _in_unit(x: np.ndarray, name: str, tol: float = 1e-6) -> np.ndarray:
    if x.size and (x.min() < -tol or x.max() > 1.0 + tol):
        raise UserError(f"{name} values must lie in [0, 1], got range [{x.min():.6g}, {x.max():.6g}]")
    return np.clip(x, 0.0, 1.0)


def _image_pair(a: ArrayLike, b: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """Two ``(C, H, W)`` images, C ∈ {1, 4}, same shape, values in [0, 1]."""
    a, b = _array(a, "image a"), _array(b, "image b")
    for x, name in ((a, "image a"), (b, "image b")):
        if x.ndim != 3 or x.shape[0] not in (1, 4):
            raise UserError(f"{name} must have shape (C, H, W) with C = 1 (opacity) or 4 (premultiplied "
                            f"RGBA), got {x.shape}")
    if a.shape != b.shape:
        raise UserError(f"the two images must have the same shape, got {a.shape} and {b.shape}")
    return _in_unit(a, "image a"), _in_unit(b, "image b")


def _density(v: ArrayLike, name: str) -> np.ndarray:
    """The density ``(N, N, N)`` of a ``(C, N, N, N)`` (last channel) or ``(N, N, N)`` volume in [0, 1]."""
    x = _array(v, name)
    if x.ndim == 4:
        x = x[-1]
    if x.ndim != 3 or not x.shape[0] == x.shape[1] == x.shape[2] or x.shape[0] < 2:
        raise UserError(f"{name} must be a cubic volume (C, N, N, N) or (N, N, N) with N ≥ 2, "
                        f"got shape {_array(v, name).shape}")
    return _in_unit(x, name)


def _density_pair(a: ArrayLike, b: ArrayLike, names=("output", "target")) -> Tuple[np.ndarray, np.ndarray]:
    da, db = _density(a, names[0]), _density(b, names[1])
    if da.shape != db.shape:
        raise UserError(f"{names[0]} and {names[1]} must have the same resolution, got {da.shape} and {db.shape}")
    return da, db


def checked_threshold(t: float, name: str = "threshold") -> float:
    """``t`` as a float, checked to be a number in (0, 1] (a :class:`~mitsuba_platonic.errors.UserError`
    naming ``name`` otherwise)."""
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not 0.0 < float(t) <= 1.0:
        raise UserError(f"{name} must be a number in (0, 1], got {t!r}")
    return float(t)


# -- 2D --------------------------------------------------------------------------------------

def display_image(img: ArrayLike, background: float = 1.0) -> np.ndarray:
    """What DSSIM and VGG look at: ``(C, H, W)`` → ``(H, W, C')`` float in [0, 1].

    C = 4 (premultiplied linear RGBA): composited over a ``background`` grey (white by default),
    clipped to [0, 1] and sRGB-encoded, C' = 3 — the picture a viewer sees. C = 1 (an opacity
    image of VH/AO): the opacity itself, C' = 1.
    """

    x = _array(img, "image")
    if x.ndim != 3 or x.shape[0] not in (1, 4):
        raise UserError(f"image must have shape (C, H, W) with C = 1 or 4, got {x.shape}")
    if x.shape[0] == 1:
        return _in_unit(x, "image").transpose(1, 2, 0)
    rgba = np.clip(x, 0.0, None).transpose(1, 2, 0)
    rgba[..., 3] = np.clip(rgba[..., 3], 0.0, 1.0)
    return linear_to_srgb(composite(rgba, background))


def dssim(a: ArrayLike, b: ArrayLike) -> float:
    """DSSIM = (1 − SSIM(a, b)) / 2 of two ``(C, H, W)`` images (C = 1 or 4, values in [0, 1]).

    SSIM is scikit-image's ``structural_similarity`` on :func:`display_image` of each image,
    with ``data_range=1``, ``gaussian_weights=True``, ``sigma=1.5`` (an 11×11 window),
    ``use_sample_covariance=False`` and K1 = 0.01, K2 = 0.03 — the settings of Wang et al. 2004 —
    averaged over channels (``channel_axis``). Images must be at least 11×11.
    """
    from skimage.metrics import structural_similarity  # lazy: scikit-image, only for SSIM

    a, b = _image_pair(a, b)
    if min(a.shape[1:]) < SSIM_WINDOW:
        raise UserError(f"SSIM uses an {SSIM_WINDOW}×{SSIM_WINDOW} window: images must be at least that "
                        f"large, got {a.shape[1]}×{a.shape[2]}")
    da, db = display_image(a), display_image(b)
    s = structural_similarity(da, db, data_range=1.0, channel_axis=2, gaussian_weights=True, sigma=SSIM_SIGMA,
                              use_sample_covariance=False, K1=0.01, K2=0.03)
    return float((1.0 - s) / 2.0)


def image_rmse(a: ArrayLike, b: ArrayLike) -> float:
    """√(mean (a − b)²) over every channel and pixel of two ``(C, H, W)`` images in [0, 1]."""
    a, b = _image_pair(a, b)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def silhouette_iou(a: torch.Tensor, b: torch.Tensor, threshold: float = SILHOUETTE_THRESHOLD) -> float:
    """Mean IoU of the silhouettes (alpha > ``threshold``, the last channel) of two image batches
    ``(B, C, H, W)``. An image pair whose silhouettes are both empty counts as 1."""
    a, b = torch.as_tensor(a), torch.as_tensor(b)
    if a.dim() != 4 or a.shape != b.shape:
        raise UserError(f"silhouette_iou needs two (B, C, H, W) batches of the same shape, got "
                        f"{tuple(a.shape)} and {tuple(b.shape)}")
    if torch.isnan(a).any() or torch.isnan(b).any():
        raise UserError("silhouette_iou: an image contains NaN")
    sa, sb = a[:, -1] > threshold, b[:, -1] > threshold
    inter = (sa & sb).flatten(1).sum(1).float()
    union = (sa | sb).flatten(1).sum(1).float()
    return float(torch.where(union > 0, inter / union.clamp_min(1), torch.ones_like(union)).mean())


# -- 3D --------------------------------------------------------------------------------------

def volume_rmse(output: ArrayLike, target: ArrayLike) -> float:
    """√((1/N) Σ_i (o_i − t_i)²) over the N voxels of the two densities."""
    o, t = _density_pair(output, target)
    return float(np.sqrt(np.mean((o - t) ** 2)))


def volume_iou(output: ArrayLike, target: ArrayLike, threshold: float = IOU_THRESHOLD) -> float:
    """|O ∩ T| / |O ∪ T| of the occupied voxels, density ≥ ``threshold``; 1 when both are empty."""
    o, t = _density_pair(output, target)
    th = checked_threshold(threshold)
    so, st = o >= th, t >= th
    union = int((so | st).sum())
    return 1.0 if union == 0 else float((so & st).sum()) / union


def best_tilt(output: ArrayLike, target: ArrayLike, step: float = 5.0,
              threshold: float = IOU_THRESHOLD) -> Tuple[float, float]:
    """The tilt β (degrees) that best aligns ``output`` with ``target``, and the volume IoU there.

    Both volumes lie in an input camera's frame (axes d, h, w of ``(N, N, N)``: depth, image row,
    column). β runs over the grid −90°, −90° + ``step``, …, 90° (``step`` must divide 90);
    ``output`` is resampled as seen from a camera raised by β about the frame's horizontal axis,
    i.e. from the view (0, sin β, cos β) (:func:`mitsuba_platonic.render.pytorch.closed_form.tilt`,
    trilinear), and scored by :func:`volume_iou`. Of equally good β the one nearest 0 wins; where
    no β gives any overlap (best IoU 0, e.g. an output with no voxel at ``threshold``) the tilt is
    undefined and β is NaN. β = 0 for a reconstruction in the truth's pose. For one that stands
    upright in the frame whatever the input camera's elevation θ₀, β ≈ θ₀: the pose failure of
    view-space reconstruction that the paper names (docs/evaluation.md, "3D: the volumes").
    """
    from ..render.pytorch.closed_form import tilt            # the renderer's resampling (no cycle: it needs no evaluate)

    o, t = _density_pair(output, target)
    th = checked_threshold(threshold)
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0.0 < step <= 90.0 \
            or abs(90.0 / step - round(90.0 / step)) > 1e-9:
        raise UserError(f"step must be a number of degrees that divides 90 (e.g. 5), got {step!r}")
    m = int(round(90.0 / step))
    βs = np.arange(-m, m + 1) * float(step)
    volume = torch.from_numpy(o)[None, None]
    ious = []
    for β in βs:                                      # one resampling at a time: memory of one volume
        turned = tilt(volume, torch.tensor([math.radians(β)], dtype=torch.float64))
        ious.append(volume_iou(turned[0, 0].clamp(0.0, 1.0), t, th))
    ious = np.array(ious)
    if ious.max() == 0.0:
        return float("nan"), 0.0
    best = np.flatnonzero(ious == ious.max())
    k = int(best[np.argmin(np.abs(βs[best]))])
    return float(βs[k]), float(ious[k])


def depth_stripes(volume: ArrayLike, axis: int = 0) -> float:
    """How strongly the mean density per layer along ``axis`` alternates with period 2.

    With m_k the mean density of layer k (the layers of a reconstruction along its input
    camera's depth: axis 0, d, of ``(N, N, N)``), the score is

        Σ_k |m_k − (m_{k−1} + m_{k+1}) / 2|  /  Σ_k m_k          (k = 1 … N − 2)

    0 for densities that change linearly from layer to layer, about 1 for a volume whose
    layers alternate between a value and 0 (a transposed convolution's checkerboard seen along
    depth), and small for smooth shapes (a ball of radius 0.7 at 32³ scores 0.03).
    """
    v = _density(volume, "volume")
    m = np.moveaxis(v, axis, 0).reshape(v.shape[axis], -1).mean(axis=1)
    total = float(m[1:-1].sum())
    return 0.0 if total == 0.0 else float(np.abs(m[1:-1] - 0.5 * (m[:-2] + m[2:])).sum()) / total


def half_opacity_depth(volume: ArrayLike, coverage: float = 0.5) -> float:
    """Median depth, in voxels from the front face, at which a covered ray's transmittance first
    falls below ½ (AO/EA transmittance T_k = Π_{j<k} (1 − v_j) along axis 0, d, of a volume in
    its input camera's frame, the front view looking along d).

    A ray is covered when its total opacity 1 − Π_k (1 − v_k) exceeds ``coverage``. A *front
    card* (a painted layer that reproduces the input view and has nothing behind it) gives 0 or
    1; a solid object centred in the cube gives about N/3. NaN when no ray is covered.
    """
    v = _density(volume, "volume").astype(np.float64)
    T = np.cumprod(1.0 - v, axis=0)                           # transmittance after layer k
    covered = 1.0 - T[-1] > coverage
    if not covered.any():
        return float("nan")
    first = np.argmax(T < 0.5, axis=0)                        # first layer after which T < ½
    return float(np.median(first[covered]))


def chamfer_distance(output: ArrayLike, target: ArrayLike, threshold: float = IOU_THRESHOLD) -> float:
    """The paper's density-weighted directional chamfer distance from ``output`` to ``target``.

    The paper (Sec. 5.3) prints

        d_CD(T, O) = 1/N Σ_{p_i ∈ T} min_{p_j ∈ O} w_j ‖p_i − p_j‖²

    with T the output, O the target, w the density and N the number of voxels, and says the
    weighting is there because *the results* have scalar rather than binary values, so that
    "higher densities get penalized more". Read literally (w_j inside the min, the minimum over
    every target voxel) the distance is 0 for any pair, since an empty target voxel has w_j = 0.
    The reading that matches its words, and the one implemented here, weights each *output*
    voxel by its own density and measures it to the nearest occupied target voxel (the paper's
    ShapeNet targets were binary voxelisations):

        d_CD(T, O) = 1/N Σ_{i=1..N} w_i · min_{p_j ∈ O} ‖p_i − p_j‖²,   O = {p_j : t_j ≥ threshold}

    where the sum runs over all N = n³ voxels of the output, w_i ∈ [0, 1] is the output density
    at voxel centre p_i, and positions are world coordinates of voxel centres in [−1, 1]³
    (voxel size Δ = 2/n, docs/conventions.md), so the distance is in world units squared. The
    nearest-target distances come from scipy's exact Euclidean distance transform. Properties:
    0 when every output voxel with density > 0 lies in O (e.g. identical binary volumes); it
    does not penalise target voxels the output misses (it is directional, as in the paper).

    Raises ``UserError`` when the target has no occupied voxel (the distance is undefined).
    """
    from scipy.ndimage import distance_transform_edt  # lazy: scipy is slow to import

    o, t = _density_pair(output, target)
    th = checked_threshold(threshold)
    occupied = t >= th
    if not occupied.any():
        raise UserError(f"chamfer_distance: the target has no voxel with density ≥ {th} (range "
                        f"[{t.min():.3g}, {t.max():.3g}]); the distance to an empty target is undefined")
    dist = distance_transform_edt(~occupied, sampling=voxel_size(o.shape[0]))   # 0 inside O
    return float(np.sum(o * dist ** 2) / o.size)


# -- feature metrics (weights from the user) -------------------------------------------------

_NO_WEIGHTS = ("no installed package ships pretrained {what} weights, so this metric needs a file from you: "
               "{hint}")
_VGG_HINT = ("pass --vgg-weights FILE (platonic evaluate; weights=PATH in Python) with torchvision's VGG16 weights (vgg16-397923af.pth, a state dict whose "
             "'features.N.weight' keys define the convolution stack) or to a TorchScript file mapping "
             "(B, 3, H, W) images to a feature map or a list of feature maps")
_FID_HINT = ("pass --fid-weights FILE (platonic evaluate; weights=PATH in Python) with a TorchScript feature extractor (for the standard FID: an Inception-v3 "
             "pool3 network saved with torch.jit.save) mapping (B, 3, H, W) images in [0, 1] to features, "
             "or to a VGG16 state dict as for vgg_distance")


class _VGGFeatures(nn.Module):
    """A VGG-style convolution stack rebuilt from a state dict's ``features.N.weight/bias`` keys.

    torchvision's layout: conv k at index i, ReLU at i + 1, and a 2×2 max-pool at i + 2 where the
    next conv comes 3 indices later (or after the last conv when the stack ends with a pool, as
    VGG16 does: its last conv is at 28, the pool at 30). Returns the activations before every
    pool (relu1_2, relu2_2, relu3_3, relu4_3, relu5_3 for VGG16).
    """

    def __init__(self, state: dict):
        super().__init__()
        idx = sorted({int(m.group(1)) for k in state for m in [re.fullmatch(r"features\.(\d+)\.weight", k)] if m})
        if not idx:
            raise UserError("the weights file holds no 'features.N.weight' tensors: not a VGG state dict")
        self.blocks = nn.ModuleList()
        block: List[nn.Module] = []
        for n, i in enumerate(idx):
            w = state[f"features.{i}.weight"]
            if w.dim() != 4:
                raise UserError(f"features.{i}.weight must be a conv kernel (out, in, k, k), got {tuple(w.shape)}")
            conv = nn.Conv2d(w.shape[1], w.shape[0], w.shape[2], padding=w.shape[2] // 2)
            conv.weight.data.copy_(w)
            b = state.get(f"features.{i}.bias")
            conv.bias.data.copy_(b if b is not None else torch.zeros(w.shape[0]))
            block += [conv, nn.ReLU(inplace=False)]
            nxt = idx[n + 1] if n + 1 < len(idx) else None
            if nxt is None or nxt - i == 3:       # a pool follows (VGG ends every block with one)
                self.blocks.append(nn.Sequential(*block))
                block = []
            elif nxt - i != 2:
                raise UserError(f"unexpected VGG layout: conv layers at features.{i} and features.{nxt}")
        if block:
            self.blocks.append(nn.Sequential(*block))
        first = state[f"features.{idx[0]}.weight"]
        if first.shape[1] != 3:
            raise UserError(f"the first VGG convolution must take 3 channels (RGB), got {first.shape[1]}")
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1))

    def forward(self, x: torch.Tensor) -> List[torch.Tensor]:
        x = (x - self.mean) / self.std
        out = []
        for k, block in enumerate(self.blocks):
            if k:
                x = nn.functional.max_pool2d(x, 2, ceil_mode=True)
            x = block(x)
            out.append(x)
        return out


def load_feature_network(weights: Optional[Union[str, Path]], what: str = "VGG16") -> nn.Module:
    """A feature network from a weights file the user gives: a VGG-style state dict
    (``features.N.weight``; torchvision's ``vgg16-397923af.pth``) or a TorchScript module.

    Raises :class:`UserError` when ``weights`` is None, missing or not one of those.
    """
    hint = _VGG_HINT if what == "VGG16" else _FID_HINT
    if weights is None:
        raise UserError(_NO_WEIGHTS.format(what=what, hint=hint))
    path = Path(weights)
    if not path.is_file():
        raise UserError(f"{what} weights file {path} does not exist; {hint}")
    try:                                          # a TorchScript archive?
        net = torch.jit.load(str(path), map_location="cpu")
        return net.eval()
    except (RuntimeError, ValueError):
        pass
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:                         # pickle, zip or format errors: the user's file
        raise UserError(f"{path} is neither a TorchScript file nor a torch state dict "
                        f"({type(e).__name__}: {' '.join(str(e).split())[:120]}); {hint}") from None
    if not isinstance(state, dict):
        raise UserError(f"{path} holds a {type(state).__name__}, not a state dict; {hint}")
    return _VGGFeatures(state).eval()


def _rgb_batch(images: ArrayLike, name: str) -> torch.Tensor:
    """``(B, C, H, W)`` renders (C = 1 or 4) → display RGB ``(B, 3, H, W)`` float32 in [0, 1]."""
    x = _array(images, name)
    if x.ndim == 3:
        x = x[None]
    if x.ndim != 4 or x.shape[1] not in (1, 4) or x.shape[0] == 0:
        raise UserError(f"{name} must have shape (B, C, H, W) with B ≥ 1 and C = 1 or 4, got {x.shape}")
    out = np.stack([display_image(i) for i in x])              # (B, H, W, 3 or 1)
    if out.shape[-1] == 1:
        out = np.repeat(out, 3, axis=-1)
    return torch.from_numpy(out).permute(0, 3, 1, 2).float()


def _feature_maps(net: nn.Module, x: torch.Tensor) -> List[torch.Tensor]:
    with torch.no_grad():
        out = net(x)
    maps = list(out) if isinstance(out, (list, tuple)) else [out]
    if not maps or not all(isinstance(m, torch.Tensor) and m.dim() in (2, 4) for m in maps):
        raise UserError("the feature network must return a (B, C, H, W) or (B, D) tensor or a list of them")
    return [m if m.dim() == 4 else m[:, :, None, None] for m in maps]


def vgg_distance(a: ArrayLike, b: ArrayLike, weights: Optional[Union[str, Path]] = None,
                 network: Optional[nn.Module] = None) -> float:
    """Mean VGG feature distance between two image batches ``(B, C, H, W)`` (or two images).

    Each image goes through :func:`display_image` (RGB, opacity repeated to 3 channels) and the
    network; at every returned layer l (for VGG16 the activations before each pool) the features
    are normalised to unit length across channels, f̂ = f / ‖f‖, and

        VGG(a, b) = 1/L Σ_l mean over pixels and images of ‖f̂_l(a) − f̂_l(b)‖²   (in [0, 4]).

    ``weights``: the file :func:`load_feature_network` reads (required unless ``network`` is
    given, a network loaded once for many calls).
    """
    net = network if network is not None else load_feature_network(weights, "VGG16")
    xa, xb = _rgb_batch(a, "images a"), _rgb_batch(b, "images b")
    if xa.shape != xb.shape:
        raise UserError(f"the two image batches must have the same shape, got {tuple(xa.shape)} and {tuple(xb.shape)}")
    fa, fb = _feature_maps(net, xa), _feature_maps(net, xb)
    total = 0.0
    for ma, mb in zip(fa, fb):
        na = ma / ma.norm(dim=1, keepdim=True).clamp_min(1e-10)
        nb = mb / mb.norm(dim=1, keepdim=True).clamp_min(1e-10)
        total += float(((na - nb) ** 2).sum(1).mean())
    return total / len(fa)


def fid(real: ArrayLike, fake: ArrayLike, weights: Optional[Union[str, Path]] = None,
        network: Optional[nn.Module] = None) -> float:
    """Fréchet distance of network features of two image sets ``(B, C, H, W)`` (B ≥ 2 each).

    Features: the network's last output, averaged over its spatial dimensions → ``(B, D)``;
    with means μ and covariances Σ of the two sets,

        FID = ‖μ_r − μ_f‖² + tr(Σ_r + Σ_f − 2 (Σ_r Σ_f)^{1/2})

    (matrix square root by ``scipy.linalg.sqrtm``, its imaginary round-off dropped). The
    standard FID uses Inception-v3 pool3 features (``weights``: a TorchScript file of it).
    """
    from scipy import linalg  # lazy: scipy.linalg, only for FID

    net = network if network is not None else load_feature_network(weights, "Inception-v3")
    xr, xf = _rgb_batch(real, "real images"), _rgb_batch(fake, "fake images")
    if len(xr) < 2 or len(xf) < 2:
        raise UserError(f"FID needs at least 2 images per set (a covariance), got {len(xr)} and {len(xf)}")
    fr = _feature_maps(net, xr)[-1].mean(dim=(2, 3)).double().numpy()
    ff = _feature_maps(net, xf)[-1].mean(dim=(2, 3)).double().numpy()
    mu_r, mu_f = fr.mean(0), ff.mean(0)
    cov_r, cov_f = np.atleast_2d(np.cov(fr, rowvar=False)), np.atleast_2d(np.cov(ff, rowvar=False))
    root = linalg.sqrtm(cov_r @ cov_f)
    if not np.isfinite(root).all():              # singular product: regularise as the reference FID does
        eps = 1e-6 * np.eye(len(cov_r))
        root = linalg.sqrtm((cov_r + eps) @ (cov_f + eps))
    root = np.real(root)
    value = float(np.sum((mu_r - mu_f) ** 2) + np.trace(cov_r) + np.trace(cov_f) - 2.0 * np.trace(root))
    return max(value, 0.0) if math.isfinite(value) else value
