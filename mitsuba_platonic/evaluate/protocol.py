"""The paper's re-rendering protocol (Sec. 5.3) and the baselines of the evaluation.

A reconstruction and its reference volume (the ground truth resampled into the input camera's
frame, see :func:`truth_in_input_frame`) are rendered from the same ``n_views`` = 10 seeded
random views (uniform on the sphere, the paper's p_view) under the same random natural
illumination (one Hosek–Wilkie ``sunsky`` per view, drawn by
:func:`mitsuba_platonic.render.mitsuba.physical.sample_lighting`), with four methods:

- ``IF``: the training image formation ρ (VH, AO or EA) through :func:`mitsuba_platonic.render`
  (closed form by default; no illumination: ρ is what the network was trained on).
- ``VOL``: Mitsuba's volumetric path tracer on the medium
  (:func:`mitsuba_platonic.render.mitsuba.physical.render_physical`): σ_t from the density, albedo from
  the colour.
- ``ISO``: the iso-surface at density 0.1 (marching cubes, :func:`mitsuba_platonic.export.extract_mesh`)
  as a Mitsuba mesh with linear vertex colours on a diffuse BSDF, path traced (``path``).
- ``VOX``: every voxel with density ≥ ``vox_threshold`` (½) as a cube of its colour (only the
  faces between an occupied and an empty voxel are built), path traced likewise.

VH/AO volumes have no colour: their VOL/ISO/VOX renders use a grey albedo :data:`GREY` for both
members of the pair. Exposure: each VOL/ISO/VOX image pair is scaled by one factor, the
auto-exposure of the *reference* image (:func:`~mitsuba_platonic.render.mitsuba.physical.auto_exposure`),
so the two members are compared at the same exposure. Images are ``(V, 4, R, R)`` premultiplied
linear RGB + alpha (``IF`` under VH/AO: ``(V, 1, R, R)`` opacity).

Baselines (rows of the report next to the trained model): :func:`billboard` (the input image
extruded through the depth of the cube) and an untrained model; :func:`novel_view_errors` is
the quickstart's novel-view score (MAE and silhouette IoU over :data:`NOVEL_VIEWS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from ..errors import UserError
from ..files.fileio import check_input_file
from ..export import extract_mesh
from ..images import srgb_to_linear
from ..render import render
from ..render.pytorch.closed_form import rotate
from ..render.mitsuba.per_pair import sensor_dict
from ..render.mitsuba.physical import Lighting, auto_exposure, render_physical, sample_lighting
from ..render.variant import ensure_variant
from ..views import camera_frames, from_angles, front_view, sample_views, turntable
from ..volume import CHANNELS, MODELS
from . import metrics as M

__all__ = ["METHODS", "ISO_LEVEL", "GREY", "N_VIEWS", "rerender_views", "rerender_lighting", "as_rgba",
           "iso_mesh", "voxel_mesh", "render_mesh", "rerender", "PairResult", "evaluate_pair",
           "truth_in_input_frame", "billboard", "novel_view_errors", "NOVEL_VIEWS", "silhouette_iou",
           "held_out_truths", "held_out_scores"]

#: The re-render methods, in the order of the paper's table columns.
METHODS = ("VOL", "ISO", "VOX", "IF")
#: Iso-value of the ISO re-render (the paper's .1).
ISO_LEVEL = 0.1
#: Density at or above which a voxel is drawn by the VOX re-render.
VOX_THRESHOLD = M.IOU_THRESHOLD
#: Albedo of density-only (VH/AO) volumes in the VOL, ISO and VOX re-renders.
GREY = 0.8
#: Views per pair (the paper's 10 random views).
N_VIEWS = 10

silhouette_iou = M.silhouette_iou

#: Novel views in the reconstruction's frame: a ring at 30° elevation (the input view excluded) and the back.
NOVEL_VIEWS = torch.cat([turntable(6, elevation=30.0, start=60.0), from_angles(180.0, 0.0)[None]])


# -- views, lighting, volumes ----------------------------------------------------------------

def rerender_views(n: int = N_VIEWS, seed: int = 0) -> torch.Tensor:
    """``n`` views uniform on the sphere, deterministic under ``seed``: ``(n, 3)``."""
    return sample_views(n, "sphere", seed=seed)


def rerender_lighting(n: int = N_VIEWS, seed: int = 0) -> List[Lighting]:
    """``n`` random skies (sun elevation 10–75°, turbidity 2–8), deterministic under ``seed``."""
    rng = np.random.default_rng([seed, 8])
    return [sample_lighting(rng, "sunsky") for _ in range(n)]


def as_rgba(volume: torch.Tensor) -> torch.Tensor:
    """``(C, N, N, N)`` → RGBA ``(4, N, N, N)``: EA volumes as they are, density-only ones with a grey albedo."""
    v = volume.detach().float().cpu()
    if v.dim() != 4 or v.shape[0] not in (1, 4):
        raise UserError(f"volume must have shape (C, N, N, N) with C = 1 (density) or 4 (RGBA), got {tuple(v.shape)}")
    if v.shape[0] == 4:
        return v
    return torch.cat([torch.full((3,) + tuple(v.shape[1:]), GREY), v])


# -- meshes ----------------------------------------------------------------------------------

Mesh = Tuple[np.ndarray, np.ndarray, np.ndarray]    # vertices (V, 3) world, faces (F, 3), linear colours (V, 3)


def _empty_mesh() -> Mesh:
    return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32), np.zeros((0, 3), np.float32)


def iso_mesh(volume: torch.Tensor, level: float = ISO_LEVEL) -> Mesh:
    """Marching cubes at ``level`` of an RGBA volume → (vertices, faces, linear RGB vertex colours).

    An empty mesh when the density never crosses ``level``.
    """

    v = as_rgba(volume)
    d = v[3]
    if not float(d.min()) < level < float(d.max()):
        return _empty_mesh()
    mesh = extract_mesh(v, level=level)
    colours = srgb_to_linear(mesh.colours.astype(np.float64) / 255.0).astype(np.float32)
    return mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32), colours


#: The 6 face directions in index space (d, h, w) and the 4 corners of each face, in order around
#: it, as offsets of the voxel's lower lattice corner.
_FACES = {
    (-1, 0, 0): [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)],
    (1, 0, 0): [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)],
    (0, -1, 0): [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)],
    (0, 1, 0): [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)],
    (0, 0, -1): [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)],
    (0, 0, 1): [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
}


def voxel_mesh(volume: torch.Tensor, threshold: float = VOX_THRESHOLD) -> Mesh:
    """Occupied voxels (density ≥ ``threshold``) of an RGBA volume as cubes → (vertices, faces, colours).

    Only faces between an occupied voxel and an empty one (or the border) are built; each face
    has its own 4 vertices coloured with its voxel's linear RGB. A voxel (d, h, w) spans
    [w, w + 1]Δ − 1 in x, 1 − [h, h + 1]Δ in y and 1 − [d, d + 1]Δ in z (docs/conventions.md).
    The BSDF is two-sided, so the winding does not matter for shading.
    """
    v = as_rgba(volume).numpy()
    occ = v[3] >= M.checked_threshold(threshold, "vox threshold")
    n = occ.shape[0]
    if not occ.any():
        return _empty_mesh()
    padded = np.pad(occ, 1)
    verts, cols = [], []
    for (dd, dh, dw), corners in _FACES.items():
        neighbour = padded[1 + dd:1 + dd + n, 1 + dh:1 + dh + n, 1 + dw:1 + dw + n]
        idx = np.argwhere(occ & ~neighbour)                                  # (K, 3) voxel indices
        if not len(idx):
            continue
        quad = idx[:, None, :] + np.asarray(corners)[None]                   # (K, 4, 3) lattice corners
        verts.append(quad)
        cols.append(np.repeat(v[:3, idx[:, 0], idx[:, 1], idx[:, 2]].T[:, None], 4, axis=1))
    lattice = np.concatenate(verts).reshape(-1, 3).astype(np.float64)
    delta = 2.0 / n
    world = np.stack([-1.0 + lattice[:, 2] * delta, 1.0 - lattice[:, 1] * delta, 1.0 - lattice[:, 0] * delta], 1)
    k = len(world) // 4
    base = 4 * np.arange(k, dtype=np.uint32)[:, None]
    faces = np.concatenate([base + np.array([0, 1, 2], np.uint32), base + np.array([0, 2, 3], np.uint32)])
    colours = np.concatenate(cols).reshape(-1, 3)
    return world.astype(np.float32), faces, np.clip(colours, 0.0, 1.0).astype(np.float32)


def _mitsuba_mesh(mi, mesh: Mesh):
    vertices, faces, colours = mesh
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {
        "type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "vertex_color"}}})
    m = mi.Mesh("evaluate_mesh", len(vertices), len(faces), props=props)
    m.add_attribute("vertex_color", 3, np.ascontiguousarray(colours, np.float32).ravel())
    params = mi.traverse(m)
    params["vertex_positions"] = np.ascontiguousarray(vertices, np.float32).ravel()
    params["faces"] = np.ascontiguousarray(faces, np.uint32).ravel()
    params.update()
    return m


def render_mesh(mesh: Mesh, views: torch.Tensor, lighting: Sequence[Lighting], resolution: int,
                spp: int = 16, max_depth: int = 8, seed: int = 0) -> torch.Tensor:
    """Path-trace a mesh (Mitsuba ``path``, emitters hidden) from each view under its lighting.

    The camera is the one of the volume renders (orthographic at 3ω, film covering [−1, 1]²).
    Returns ``(V, 4, R, R)``: premultiplied linear radiance over black and the coverage alpha.
    An empty mesh renders as zeros.
    """

    if len(lighting) != len(views):
        raise UserError(f"one lighting per view expected: {len(lighting)} for {len(views)} views")
    if not len(mesh[1]):
        return torch.zeros(len(views), 4, resolution, resolution)
    mi = ensure_variant()
    shape = _mitsuba_mesh(mi, mesh)
    right, up, w = camera_frames(views)
    out = []
    for i in range(len(views)):
        scene = mi.load_dict({
            "type": "scene",
            "integrator": {"type": "path", "max_depth": int(max_depth), "hide_emitters": True},
            "emitter": lighting[i].emitter(mi),
            "shape": shape,
            "sensor": sensor_dict(mi, resolution, spp, 3.0 * w[i], up[i], film={"pixel_format": "rgba"}),
        })
        out.append(torch.from_numpy(np.array(mi.render(scene, seed=seed + i))).permute(2, 0, 1))
    return torch.stack(out).float()


# -- the protocol ----------------------------------------------------------------------------

def _expose(recon: torch.Tensor, ref: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Scale each view's pair of RGB radiance images by the reference's auto-exposure factor."""
    recon, ref = recon.clone(), ref.clone()
    for i in range(len(ref)):
        k = auto_exposure(ref[i, :3].permute(1, 2, 0).numpy().astype(np.float64), ref[i, 3].numpy())
        recon[i, :3] *= k
        ref[i, :3] *= k
    return recon, ref


def rerender(volume: torch.Tensor, views: torch.Tensor, lighting: Sequence[Lighting], model: str,
             methods: Sequence[str] = METHODS, spp: int = 16, max_depth: int = 8, seed: int = 0,
             backend: str = "closed_form", iso_level: float = ISO_LEVEL,
             vox_threshold: float = VOX_THRESHOLD, if_max_depth: Optional[int] = None) -> Dict[str, torch.Tensor]:
    """Render one ``(C, N, N, N)`` volume with each of ``methods`` from ``views`` (radiance unexposed).

    ``IF`` uses ``model`` and ``backend``: for ``backend='physical'`` (a run trained through the
    path tracer) it is that path tracer under the pair's lighting, radiance unexposed like VOL,
    with the run's ``if_max_depth`` (default ``max_depth``); ``VOL`` ``spp``/``max_depth``;
    ``ISO``/``VOX`` ``spp``/``max_depth`` too. Returns method → images (see the module docstring).
    """
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise UserError(f"re-render methods must be among {METHODS}, got {unknown}")
    if model not in MODELS:
        raise UserError(f"model must be one of {MODELS}, got {model!r}")
    v = volume.detach().float().cpu()
    if v.dim() != 4 or v.shape[0] != CHANNELS[model]:
        raise UserError(f"model {model!r} needs a ({CHANNELS[model]}, N, N, N) volume, got {tuple(v.shape)}")
    n = v.shape[-1]
    rgba = as_rgba(v)
    k = len(views)
    traced: Dict[int, torch.Tensor] = {}                      # path-traced renders by depth: IF may equal VOL

    def path_traced(depth: int) -> torch.Tensor:
        if depth not in traced:
            traced[depth] = render_physical(rgba[None].expand(k, -1, -1, -1, -1).contiguous(), views, list(lighting),
                                            spp=spp, max_depth=depth, seed=seed, exposure="none")[0]
        return traced[depth]

    out: Dict[str, torch.Tensor] = {}
    for method in methods:
        if method == "IF" and backend == "physical":          # the training image formation: path traced
            out[method] = path_traced(if_max_depth or max_depth)
        elif method == "IF":
            with torch.no_grad():
                out[method] = render(v[None].expand(k, -1, -1, -1, -1).contiguous(), views, model, backend).cpu()
        elif method == "VOL":
            out[method] = path_traced(max_depth)
        elif method == "ISO":
            out[method] = render_mesh(iso_mesh(rgba, iso_level), views, lighting, n, spp, max_depth, seed)
        else:
            out[method] = render_mesh(voxel_mesh(rgba, vox_threshold), views, lighting, n, spp, max_depth, seed)
    return out


@dataclass
class PairResult:
    """One (reconstruction, reference) pair: ``images[method] = (recon, reference)`` ``(V, C, R, R)``,
    ``metrics``: ``dssim_<M>``, ``silhouette_iou_<M>`` (and ``vgg_<M>``) per method, ``rmse``, ``iou``, ``cd``."""

    images: Dict[str, Tuple[torch.Tensor, torch.Tensor]]
    metrics: Dict[str, float] = field(default_factory=dict)
    views: Optional[torch.Tensor] = None


def evaluate_pair(recon: torch.Tensor, reference: torch.Tensor, model: str, n_views: int = N_VIEWS,
                  seed: int = 0, methods: Sequence[str] = METHODS, spp: int = 16, max_depth: int = 8,
                  backend: str = "closed_form", iou_threshold: float = M.IOU_THRESHOLD,
                  vgg_network: Optional[torch.nn.Module] = None, if_max_depth: Optional[int] = None) -> PairResult:
    """Score a reconstruction against its reference volume (both ``(C, N, N, N)`` in the same frame).

    2D: both are re-rendered by :func:`rerender` from the same :func:`rerender_views` under the same
    :func:`rerender_lighting` (seeded by ``seed``), exposed alike (:func:`_expose`), and compared
    per view by DSSIM (:func:`~.metrics.dssim`), silhouette IoU and, when ``vgg_network`` is
    given, VGG distance; each is the mean over the views. 3D: :func:`~.metrics.volume_rmse`,
    :func:`~.metrics.volume_iou` at ``iou_threshold`` and the chamfer distance (target occupied at
    ``iou_threshold``) of the densities.
    """
    if recon.shape != reference.shape:
        raise UserError(f"reconstruction and reference must have the same shape, got {tuple(recon.shape)} "
                        f"and {tuple(reference.shape)}")
    views = rerender_views(n_views, seed)
    lights = rerender_lighting(n_views, seed)
    kw = dict(methods=methods, spp=spp, max_depth=max_depth, seed=seed, backend=backend, if_max_depth=if_max_depth)
    a = rerender(recon, views, lights, model, **kw)
    b = rerender(reference, views, lights, model, **kw)
    result = PairResult(images={}, views=views)
    for m in methods:
        x, y = (a[m], b[m]) if m == "IF" and backend != "physical" else _expose(a[m], b[m])
        result.images[m] = (x, y)
        x01, y01 = x.clamp(0.0, 1.0), y.clamp(0.0, 1.0)       # radiance above 1 is clipped, as a display does
        result.metrics[f"dssim_{m}"] = float(np.mean([M.dssim(p, q) for p, q in zip(x01, y01)]))
        result.metrics[f"silhouette_iou_{m}"] = M.silhouette_iou(x01, y01)
        if vgg_network is not None:
            result.metrics[f"vgg_{m}"] = M.vgg_distance(x01, y01, network=vgg_network)
    result.metrics["rmse"] = M.volume_rmse(recon, reference)
    result.metrics["iou"] = M.volume_iou(recon, reference, iou_threshold)
    result.metrics["cd"] = M.chamfer_distance(recon, reference, iou_threshold)
    return result


def truth_in_input_frame(volume: torch.Tensor, view: Sequence[float], model: str) -> torch.Tensor:
    """A ground-truth ``(4, N, N, N)`` RGBA volume resampled into the frame of the camera at ``view``
    (where a reconstruction from that image lives; the closed form's rotation), with the channels
    of ``model``; clamped to [0, 1] (trilinear round-off)."""

    v = volume.detach().float()
    if CHANNELS[model] == 1:
        v = v[3:]
    return rotate(v[None], torch.tensor([list(view)], dtype=torch.float32))[0].clamp(0.0, 1.0)


# -- baselines (also used by the quickstart's report) ----------------------------------------

def billboard(image: torch.Tensor) -> torch.Tensor:
    """The input image extruded through the cube: ``(4, R, R)`` → ``(4, R, R, R)`` (EA).

    Each of the R depth samples gets opacity a = 1 − (1 − α)^{1/R} and colour rgb/α, so the
    front view reproduces the image exactly (Π(1 − a) = 1 − α, Σ T a c = rgb).
    """
    if image.dim() != 3 or image.shape[0] != 4:
        raise UserError(f"billboard needs a (4, R, R) premultiplied RGBA image, got {tuple(image.shape)}")
    r = image.shape[-1]
    alpha = image[3:].clamp(0.0, 1.0)
    a = 1.0 - (1.0 - alpha.clamp(max=1.0 - 1e-6)) ** (1.0 / r)
    colour = torch.where(alpha > 1e-6, image[:3] / alpha.clamp_min(1e-6), torch.zeros_like(image[:3]))
    return torch.cat([colour, a]).clamp(0, 1)[:, None].expand(-1, r, -1, -1).contiguous()


def novel_view_errors(recon: torch.Tensor, truth_in_frame: torch.Tensor, model: str,
                      views: torch.Tensor = NOVEL_VIEWS) -> Tuple[float, float]:
    """(MAE, silhouette IoU) between renders of two ``(C, N, N, N)`` volumes over ``views``."""
    n = len(views)
    with torch.no_grad():
        a = render(recon[None].expand(n, -1, -1, -1, -1).contiguous(), views, model)
        b = render(truth_in_frame[None].expand(n, -1, -1, -1, -1).contiguous(), views, model)
    return float((a - b).abs().mean()), M.silhouette_iou(a, b)


def held_out_truths(records: Sequence[Dict], model: str) -> List[torch.Tensor]:
    """The ground truth of held-out collection records (``TrainingData.held_out_records``: their
    ``folder``, ``volume`` file and ``view``), each in its input camera's frame
    (:func:`truth_in_input_frame`); a :class:`~mitsuba_platonic.errors.UserError` naming an
    unreadable volume file."""
    out = []
    for r in records:
        path = Path(r["folder"]) / r["volume"]
        try:
            vol = torch.from_numpy(np.load(check_input_file(path))["volume"]).float()   # no FIFO, no device
        except (OSError, KeyError, ValueError) as e:
            raise UserError(f"cannot read the ground-truth volume {path}: {e}") from None
        out.append(truth_in_input_frame(vol, r["view"], model))
    return out


def held_out_scores(net, data, model: Optional[str] = None, limit: int = 64) -> Dict[str, float]:
    """Input-view and novel-view errors of a :class:`~mitsuba_platonic.model.Model` ``net`` on a
    procedural collection's held-out images (``data``: :class:`~mitsuba_platonic.train.data.TrainingData`
    with ``held_out_records``), and of the :func:`billboard` of each image (EA): the quickstart's
    report and the learning test.

    Per image: the reconstruction rendered at the input view against the image (MAE, silhouette
    IoU), and against the ground truth in the input camera's frame at :data:`NOVEL_VIEWS`
    (:func:`novel_view_errors`); means over at most ``limit`` images. ``model``: the image
    formation to render with (default: the model's).
    """
    model = model or net.formation
    images = data.held_out[:limit]
    recon = net.reconstruct(images).cpu()
    front = front_view(len(images))
    with torch.no_grad():
        rendered = render(recon, front, model)
    truths = held_out_truths(data.held_out_records[:limit], model)
    novel = np.array([novel_view_errors(v, t, model) for v, t in zip(recon, truths)])
    out = {"input_view_mae": float((rendered - images).abs().mean()), "input_view_iou": silhouette_iou(rendered, images),
           "novel_view_mae": float(novel[:, 0].mean()), "novel_view_iou": float(novel[:, 1].mean())}
    if model == "ea":
        boards = torch.stack([billboard(x) for x in images])
        with torch.no_grad():
            board_front = render(boards, front, model)
        out["billboard_input_view_mae"] = float((board_front - images).abs().mean())
        out["billboard_input_view_iou"] = silhouette_iou(board_front, images)
        bb = np.array([novel_view_errors(b, t, model) for b, t in zip(boards, truths)])
        out["billboard_novel_view_mae"], out["billboard_novel_view_iou"] = float(bb[:, 0].mean()), float(bb[:, 1].mean())
    return out
