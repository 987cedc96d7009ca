"""Sheets of a generator's samples that people can look at: a labelled grid, turntables, a latent walk.

What ``platonic generate`` writes beside its volumes and what the generation report shows
(:mod:`mitsuba_platonic.evaluate.generation_report`; docs/evaluation.md, "Generation runs"):

- :func:`save_sample_grid`: one tile per sample, seen from ω(φ, θ) = (cos θ sin φ, sin θ, cos θ cos φ)
  at φ = 30°, θ = 20° (:data:`GRID_VIEW`), each labelled with its name;
- :func:`save_turntables`: one line per sample, its renders at ``azimuths`` evenly spaced
  azimuths φ_k = k · 360°/A about G's vertical axis (+y) at θ = 20°, as the photo report's turntables;
- :func:`save_interpolation`: one line of renders of G(z(t)) for t = 0, 1/(K−1), …, 1 between two
  latents z₀ and z₁, z(t) the spherical interpolation (:func:`slerp`).

**Why slerp.** z ~ N(0, I_d): its norm concentrates at √d (|z|² has mean d and standard deviation
√(2d)). The straight line (1 − t) z₀ + t z₁ between two independent draws has, at t = ½, norm
≈ √(d/2): the midpoint lies where the prior puts almost no mass, so G is decoded off its training
distribution (White 2016, "Sampling generative networks"). The spherical interpolation

    slerp(z₀, z₁; t) = sin((1 − t) Ω) / sin Ω · z₀ + sin(t Ω) / sin Ω · z₁,   cos Ω = z₀·z₁ / (|z₀| |z₁|)

keeps the norm between |z₀| and |z₁| for orthogonal draws (independent Gaussian draws are nearly
orthogonal in high dimension), so every point of the walk is a typical latent. The endpoints are
z₀ and z₁ themselves (t = 0 and t = 1 return them exactly), and for Ω → 0 it is the straight line.
The viewer's walk between two seeds is the same interpolation.

Every image is the closed-form render of the model's image formation over white
(:func:`~mitsuba_platonic.render.frames.display_frames`), upscaled by nearest-neighbour to at least
``cell`` pixels, labels drawn with PIL's built-in font above each line or tile.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from PIL import Image, ImageDraw

from .errors import UserError
from .files.fileio import atomic_write, make_folder
from .render.frames import display_frames
from .views import from_angles, turntable

if TYPE_CHECKING:
    from .model import Model

__all__ = ["slerp", "interpolation_latents", "GRID_VIEW", "TURNTABLE_ELEVATION", "CELL", "save_sheet",
           "save_sample_grid", "save_turntables", "save_interpolation"]

PathLike = Union[str, Path]

#: The grid's view of every sample: (azimuth, elevation) in degrees.
GRID_VIEW: Tuple[float, float] = (30.0, 20.0)
#: The turntables' elevation (degrees): the one of the run's sample turntables and GIFs.
TURNTABLE_ELEVATION = 20.0
#: Pixels per tile, at least (tiles are upscaled by a whole factor, nearest-neighbour).
CELL = 128
#: Height of a label line in pixels (PIL's built-in font is 11 px high).
_LABEL = 14


def slerp(z0: torch.Tensor, z1: torch.Tensor, t: Union[float, Sequence[float], torch.Tensor]) -> torch.Tensor:
    """The spherical interpolation of two latents ``(d,)`` (or ``(1, d)``) at ``t`` (a number or ``(K,)``
    values in [0, 1]) → ``(K, d)`` (module docstring); t = 0 gives z₀ and t = 1 gives z₁ exactly."""
    a, b = torch.as_tensor(z0).reshape(-1).double(), torch.as_tensor(z1).reshape(-1).double()
    if a.shape != b.shape or not len(a):
        raise UserError(f"slerp needs two latents of one length, got {tuple(z0.shape)} and {tuple(z1.shape)}")
    ts = torch.as_tensor(t, dtype=torch.float64).reshape(-1)
    if not len(ts) or not torch.isfinite(ts).all() or ts.min() < 0.0 or ts.max() > 1.0:
        raise UserError(f"slerp's t must be values in [0, 1], got {ts.tolist()}")
    na, nb = float(a.norm()), float(b.norm())
    omega = math.acos(max(-1.0, min(1.0, float(a @ b) / (na * nb)))) if na > 0 and nb > 0 else 0.0
    if omega < 1e-6:                                             # (nearly) parallel: the straight line
        out = (1.0 - ts)[:, None] * a + ts[:, None] * b
    else:
        out = (torch.sin((1.0 - ts) * omega)[:, None] * a + torch.sin(ts * omega)[:, None] * b) / math.sin(omega)
    out = torch.where((ts == 0.0)[:, None], a, torch.where((ts == 1.0)[:, None], b, out))
    return out.to(torch.as_tensor(z0).dtype)


def interpolation_latents(z0: torch.Tensor, z1: torch.Tensor, steps: int) -> torch.Tensor:
    """``(steps, d)``: :func:`slerp` at t = k / (steps − 1), k = 0 … steps − 1 (steps ≥ 2)."""
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 2:
        raise UserError(f"an interpolation needs at least 2 steps (its two ends), got {steps!r}")
    return slerp(z0, z1, torch.linspace(0.0, 1.0, steps, dtype=torch.float64))


def _rgb8(img: np.ndarray, cell: int) -> Image.Image:
    """A float sRGB ``(H, W, C)`` image (C = 1 or 3) → an 8-bit RGB PIL image upscaled to ≥ ``cell`` px."""
    x = np.asarray(img, np.float64)
    if x.ndim == 2:
        x = x[..., None]
    if x.shape[-1] == 1:
        x = np.repeat(x, 3, axis=-1)
    k = max(1, math.ceil(cell / max(x.shape[0], 1)))
    x = x.repeat(k, axis=0).repeat(k, axis=1)
    return Image.fromarray((np.clip(x[..., :3], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8), "RGB")


def save_sheet(path: PathLike, rows: Sequence[Sequence[np.ndarray]], cell: int = CELL,
               row_labels: Optional[Sequence[str]] = None, column_labels: Optional[Sequence[str]] = None,
               tile_labels: Optional[Sequence[Sequence[str]]] = None, title: str = "") -> Path:
    """A PNG of tiles (float sRGB ``(H, W, C)`` images, ``rows[i][j]``), each upscaled to at least
    ``cell`` pixels (nearest), a 2-pixel white gap between tiles; labels in black above: ``title``
    on top, ``column_labels`` above the first line, ``row_labels`` above each line, ``tile_labels``
    above each tile. Written whole (atomic). Returns ``path``."""
    if not rows or not all(len(r) for r in rows):
        raise UserError("a sheet needs at least one non-empty line of images")
    if isinstance(cell, bool) or not isinstance(cell, int) or cell < 8:
        raise UserError(f"cell must be an int ≥ 8 pixels, got {cell!r}")
    tiles = [[_rgb8(t, cell) for t in r] for r in rows]
    w, h = tiles[0][0].size
    if any(t.size != (w, h) for r in tiles for t in r):
        raise UserError("every tile of a sheet must have the same size")
    gap = 2
    cols = max(len(r) for r in tiles)
    line_head = _LABEL if (row_labels is not None or tile_labels is not None) else 0
    top = (_LABEL if title else 0) + (_LABEL if column_labels is not None else 0)
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    heads = [title] + [str(x) for x in (row_labels or [])]                 # the lines that span the sheet
    width = max([cols * w + (cols - 1) * gap] + [int(measure.textlength(t)) + 4 for t in heads if t])
    height = top + len(tiles) * (line_head + h) + (len(tiles) - 1) * gap
    sheet = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    y = 0
    if title:
        draw.text((2, y + 1), title, fill=(0, 0, 0))
        y += _LABEL
    if column_labels is not None:
        for j, text in enumerate(column_labels[:cols]):
            draw.text((j * (w + gap) + 2, y + 1), str(text), fill=(0, 0, 0))
        y += _LABEL
    for i, line in enumerate(tiles):
        if line_head:
            if row_labels is not None:
                draw.text((2, y + 1), str(row_labels[i]), fill=(0, 0, 0))
            if tile_labels is not None:
                for j, text in enumerate(tile_labels[i]):
                    draw.text((j * (w + gap) + 2, y + 1), str(text), fill=(0, 0, 0))
            y += line_head
        for j, t in enumerate(line):
            sheet.paste(t, (j * (w + gap), y))
        y += h + gap
    path = Path(path)
    make_folder(path.parent)
    atomic_write(path, lambda tmp: sheet.save(tmp, format="PNG"))
    return path


def _volumes(volumes: torch.Tensor) -> torch.Tensor:
    v = volumes.detach().float().cpu() if isinstance(volumes, torch.Tensor) else None
    if v is None or v.dim() != 5 or not len(v):
        raise UserError(f"expected (S, C, N, N, N) volumes, got "
                        f"{tuple(volumes.shape) if isinstance(volumes, torch.Tensor) else type(volumes).__name__}")
    return v.clamp(0.0, 1.0)


def _names(n: int, labels: Optional[Sequence[str]]) -> List[str]:
    names = [f"sample_{i:03d}" for i in range(n)] if labels is None else [str(x) for x in labels]
    if len(names) != n:
        raise UserError(f"{len(names)} labels for {n} samples")
    return names


def save_sample_grid(volumes: torch.Tensor, model: str, path: PathLike, cell: int = CELL, columns: int = 4,
                     labels: Optional[Sequence[str]] = None, title: str = "") -> Path:
    """The sample grid (module docstring): ``(S, C, N, N, N)`` volumes in ``columns`` columns, each seen
    from :data:`GRID_VIEW` and labelled (``labels``, default ``sample_000`` …)."""
    v = _volumes(volumes)
    names = _names(len(v), labels)
    if isinstance(columns, bool) or not isinstance(columns, int) or columns < 1:
        raise UserError(f"columns must be a positive int, got {columns!r}")
    view = from_angles(GRID_VIEW[0], GRID_VIEW[1])[None]
    images = [display_frames(x, model, view)[0] for x in v]
    blank = np.ones_like(images[0])
    rows, tags = [], []
    for i in range(0, len(images), columns):
        line = images[i:i + columns]
        tags.append(names[i:i + columns] + [""] * (columns - len(line)))
        rows.append(line + [blank] * (columns - len(line)))
    return save_sheet(path, rows, cell, tile_labels=tags,
                      title=title or f"{len(v)} samples, azimuth {GRID_VIEW[0]:g}°, elevation {GRID_VIEW[1]:g}°")


def save_turntables(volumes: torch.Tensor, model: str, path: PathLike, azimuths: int = 8, cell: int = CELL,
                    labels: Optional[Sequence[str]] = None, elevation: float = TURNTABLE_ELEVATION,
                    title: str = "") -> Path:
    """The turntables (module docstring): a line per volume, its renders at ``azimuths`` azimuths
    k · 360°/A about +y at ``elevation``, the azimuths above the first line, each line labelled."""
    v = _volumes(volumes)
    names = _names(len(v), labels)
    if isinstance(azimuths, bool) or not isinstance(azimuths, int) or azimuths < 1:
        raise UserError(f"a turntable needs a positive number of azimuths, got {azimuths!r}")
    views = turntable(azimuths, elevation=elevation)
    rows = [display_frames(x, model, views) for x in v]
    heads = [f"{k * 360.0 / azimuths:g}°" for k in range(azimuths)]
    return save_sheet(path, rows, cell, row_labels=names, column_labels=heads,
                      title=title or f"turntables at elevation {elevation:g}°")


def save_interpolation(model: "Model", z0: torch.Tensor, z1: torch.Tensor, path: PathLike, steps: int = 8,
                       cell: int = CELL, title: str = "") -> Tuple[Path, torch.Tensor]:
    """The latent walk (module docstring): G(slerp(z₀, z₁; t)) at ``steps`` values of t from 0 to 1,
    rendered from :data:`GRID_VIEW`, t above each tile. Returns the PNG's path and the ``(steps, C,
    N, N, N)`` volumes (``model.decode``, its eval-mode G: the same G(z) as ``generate``)."""
    z = interpolation_latents(z0, z1, steps).to(torch.float32)
    volumes = model.decode(z.to(model.device)).detach().float().cpu().clamp(0.0, 1.0)
    view = from_angles(GRID_VIEW[0], GRID_VIEW[1])[None]
    row = [display_frames(x, model.formation, view)[0] for x in volumes]
    ts = torch.linspace(0.0, 1.0, steps).tolist()
    written = save_sheet(path, [row], cell, tile_labels=[[f"t = {t:.2f}" for t in ts]],
                         title=title or "G(slerp(z0, z1; t)): a walk between two latents")
    return written, volumes
