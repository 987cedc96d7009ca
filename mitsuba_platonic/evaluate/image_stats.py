"""Image statistics that need no ground truth: roughness, foreground colour, coverage.

Each function takes one image ``(C, H, W)`` as the renderers return it: premultiplied linear
RGBA (C = 4) or an opacity (C = 1), values in [0, 1]. The judge (:mod:`.judge`) compares a
reconstruction's renders away from the input view with its render at the input view and with
the photo; docs/evaluation.md ("Judging novel views without ground truth") has the same formulas.

**Coverage.** The foreground F = {p : α(p) > ½} (:data:`~.metrics.SILHOUETTE_THRESHOLD`), and
coverage = |F| / (H W).

**Roughness.** The display image D = sRGB(RGB + (1 − α)·1) (over white, as a viewer sees it;
:func:`~.metrics.display_image`), its discrete Laplacian per channel c with replicated borders,

    ΔD_c(i, j) = D_c(i−1, j) + D_c(i+1, j) + D_c(i, j−1) + D_c(i, j+1) − 4 D_c(i, j),

and roughness = mean over p ∈ F and c of |ΔD_c(p)|. Speckle and a checkerboard raise it; a smooth
surface keeps only its outline and shading. None when F is empty. An opacity image uses D = α.

**Foreground colour** (RGBA only). Each foreground pixel's own colour is the un-premultiplied
linear RGB c(p) = RGB(p) / α(p) (α > ½, so the division is safe), clipped to [0, 1], converted to
CIE L*a*b* (D65, the sRGB primaries; ``colour-science``). Two foregrounds A and B are compared by

- ΔE of the means (CIE76): ‖mean_A Lab − mean_B Lab‖₂;
- the sliced Wasserstein-1 distance SW₁ = mean over K fixed unit directions u of
  W₁(⟨u, Lab_A⟩, ⟨u, Lab_B⟩), the 1-D optimal-transport distance between the projected
  distributions (scipy), in ΔE units: 0 for equal distributions, and for two single colours it
  is their ΔE times the mean |⟨u, d⟩| over the directions (≈ ½ ΔE for K → ∞, d the unit
  difference).
"""

from __future__ import annotations

from typing import Dict, Optional

import numpy as np
import torch

from ..errors import UserError
from . import metrics as M

__all__ = ["foreground", "coverage", "roughness", "foreground_lab", "colour_distance", "SW_DIRECTIONS"]

#: Number of fixed projection directions of the sliced Wasserstein distance.
SW_DIRECTIONS = 32


def _image(img: torch.Tensor, name: str = "image") -> np.ndarray:
    x = img.detach().float().cpu().numpy() if isinstance(img, torch.Tensor) else np.asarray(img, np.float32)
    if x.ndim != 3 or x.shape[0] not in (1, 4):
        raise UserError(f"{name} must have shape (C, H, W) with C = 1 or 4, got {x.shape}")
    if not np.isfinite(x).all():
        raise UserError(f"{name} holds NaN or Inf")
    return x


def foreground(img: torch.Tensor) -> np.ndarray:
    """``(H, W)`` bool: the pixels whose opacity (the last channel) exceeds ½."""
    return _image(img)[-1] > M.SILHOUETTE_THRESHOLD


def coverage(img: torch.Tensor) -> float:
    """The share of pixels in the foreground (opacity > ½)."""
    return float(foreground(img).mean())


def roughness(img: torch.Tensor) -> Optional[float]:
    """Mean |discrete Laplacian| of the display image over the foreground (module docstring);
    None when nothing is covered."""
    x = _image(img)
    mask = x[-1] > M.SILHOUETTE_THRESHOLD
    if not mask.any():
        return None
    d = M.display_image(x)                                        # (H, W, C'), over white, sRGB
    p = np.pad(d, ((1, 1), (1, 1), (0, 0)), mode="edge")
    lap = p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:] - 4.0 * d
    return float(np.abs(lap)[mask].mean())


def foreground_lab(img: torch.Tensor) -> np.ndarray:
    """``(K, 3)`` CIE L*a*b* of the foreground pixels' own colours (RGB / α), K ≥ 0."""
    import colour  # lazy: colour-science is slow to import (about a second)

    x = _image(img)
    if x.shape[0] != 4:
        raise UserError(f"foreground colours need an RGBA image, got {x.shape[0]} channel(s)")
    mask = x[3] > M.SILHOUETTE_THRESHOLD
    rgb = np.clip(x[:3, mask].T / x[3, mask][:, None], 0.0, 1.0).astype(np.float64)
    if not len(rgb):
        return np.zeros((0, 3))
    cs = colour.models.RGB_COLOURSPACE_sRGB
    xyz = colour.RGB_to_XYZ(rgb, cs)                              # linear sRGB → XYZ (D65)
    return np.asarray(colour.XYZ_to_Lab(xyz, cs.whitepoint))


def _directions(k: int = SW_DIRECTIONS) -> np.ndarray:
    """K fixed unit vectors in Lab space (a seeded draw: the same directions in every call)."""
    u = np.random.default_rng(0).standard_normal((k, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def colour_distance(a: torch.Tensor, b: torch.Tensor) -> Dict[str, Optional[float]]:
    """Distance between the foreground colour distributions of two RGBA images: ``delta_e``
    (CIE76 ΔE of the mean L*a*b*) and ``sliced_w1`` (module docstring); both None when either
    foreground is empty."""
    from scipy.stats import wasserstein_distance  # lazy: scipy is slow to import

    la, lb = foreground_lab(a), foreground_lab(b)
    if not len(la) or not len(lb):
        return {"delta_e": None, "sliced_w1": None}
    delta_e = float(np.linalg.norm(la.mean(0) - lb.mean(0)))
    u = _directions()
    sw = float(np.mean([wasserstein_distance(la @ d, lb @ d) for d in u]))
    return {"delta_e": delta_e, "sliced_w1": sw}
