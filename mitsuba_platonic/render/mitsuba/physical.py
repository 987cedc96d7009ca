"""Physically based rendering of a generator volume: Mitsuba's volumetric path tracer under
natural light (beyond the paper's closed-form layers).

The volume becomes a ``heterogeneous`` medium inside a null-BSDF cube [−1, 1]³ (the scene file
``scenes/physical.xml``, loaded by :func:`.scenes.load_scene` with the grids given in memory):

    σ_t = −ln(1 − min(v, v_max)) / Δ        (the AO/EA extinction, docs/conventions.md; v_max = 1 − 1e-3)
    albedo = colour (linear RGB)

so a voxel of density v absorbs exactly as it does in the AO/EA layers, but light now
*scatters* (isotropic phase function) and arrives from a sky instead of being emitted by the
volume. ``v_max`` caps σ_t Δ at ln(1000) ≈ 6.9 (a full voxel still blocks 99.9 % of light):
delta tracking takes O(σ_max · length) null collisions per path, so an uncapped σ would cost
2× the time for no visible difference.

Lighting (:class:`Lighting`): Mitsuba's ``sunsky`` (Hosek–Wilkie sky and a sun disk) with a sun
direction and turbidity, or an ``envmap`` (a lat-long EXR, rotated about +y): the scene files
``scenes/emitters/sunsky.xml`` and ``scenes/emitters/envmap.xml`` (:mod:`.sky` bakes lat-long skies
from ``sunsky``, so ``envmap`` lighting needs no downloaded file). Emitters are
hidden from the camera, so the radiance image is premultiplied over black, and the alpha is the
medium's opacity along the camera ray, 1 − exp(−∫σ_t) = the AO image of the same (capped)
density, computed exactly by the ray marcher.

Exposure (:data:`EXPOSURES`): a sky is far brighter than [0, 1], so each image is scaled by a
factor k, returned so the radiance can be recovered:

- ``metered`` (the default; collections and training): the light is metered, not the image,

      k = 1 / L̄,    L̄ = (1/4π) ∫ Y(L(ω)) dω        (the emitter's mean luminance over the sphere)

  estimated by :func:`sky_mean_luminance` with the emitter's own importance sampling (sun
  included). L̄ is the mean radiance of a white diffuse sphere under that light, so an image is
  radiance in units of it: the same volume under the same light has the same pixel values
  whatever it looks like, a dark albedo stays dark and a view of the shadowed side stays darker
  than one of the lit side. Because k does not depend on the volume, it is a constant for the
  gradient and the training loss means what it means for the EA layer (docs/training.md, "The measurements").
- ``auto``: like a camera's auto-exposure, the 95th percentile luminance of the image's covered
  pixels maps to 0.8 (:func:`auto_exposure`; collections made before metering). It depends on
  the rendered volume: a near-empty render with a few dim covered pixels gets a huge factor.
- ``none``: k = 1 (raw radiance).
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from ...errors import UserError
from ...views import camera_frames, validate_views
from ...volume import validate_volume, voxel_size
from ..grids import V_MAX_PHYSICAL, extinction, to_mitsuba_grid
from .per_pair import differentiable_render, sensor_transform
from .scenes import load_scene
from ..settings import RenderSettings, check_lanes
from ..variant import ensure_variant, variant_device
from ..window import Window, window_or_none

__all__ = ["Lighting", "sample_lighting", "render_physical", "render_physical_ad", "extinction",
           "V_MAX_PHYSICAL", "luminance", "auto_exposure", "sky_mean_luminance", "metered_exposure",
           "EXPOSURES"]

#: Target of the auto-exposure: the 95th percentile luminance of covered pixels maps here.
EXPOSURE_TARGET = 0.8

#: How an image's exposure factor is chosen (see the module docstring).
EXPOSURES = ("metered", "auto", "none")

#: Directions the light meter samples (its relative standard error is ≈ 1e-3 for a sunsky).
METER_SAMPLES = 1 << 14


@dataclass(frozen=True)
class Lighting:
    """Natural illumination of one image.

    kind: 'sunsky' or 'envmap'.
    sun_direction: unit vector towards the sun (sunsky).
    turbidity: atmospheric turbidity, 1 (clear) … 10 (hazy) (sunsky).
    envmap: path of a lat-long EXR (envmap); rotation: degrees about +y (envmap).
    """

    kind: str = "sunsky"
    sun_direction: Tuple[float, float, float] = (0.3, 0.8, 0.5)
    turbidity: float = 3.0
    envmap: Optional[str] = None
    rotation: float = 0.0

    def to_dict(self) -> Dict[str, Any]:
        return asdict(self)

    def scene_params(self) -> Dict[str, Any]:
        """This light as parameters of ``scenes/physical.xml`` (``lighting`` picks emitters/<kind>.xml)."""
        if self.kind == "sunsky":
            return {"lighting": "sunsky", "sun_direction": tuple(float(x) for x in self.sun_direction),
                    "turbidity": float(self.turbidity)}
        if self.kind == "envmap":
            if not self.envmap or not Path(self.envmap).is_file():
                raise ValueError(f"envmap lighting needs an existing EXR file, got {self.envmap!r}")
            return {"lighting": "envmap", "envmap": str(Path(self.envmap).resolve()),
                    "rotation": float(self.rotation)}
        raise ValueError(f"lighting kind must be 'sunsky' or 'envmap', got {self.kind!r}")

    def emitter(self, mi: Any = None) -> Any:
        """The Mitsuba emitter, loaded from ``scenes/emitters/<kind>.xml`` (usable as a scene
        dictionary's ``emitter`` entry). ``mi`` is accepted for older callers and unused."""
        params = self.scene_params()
        return load_scene(f"emitters/{params.pop('lighting')}", **params)


def sample_lighting(rng: np.random.Generator, kind: str = "sunsky",
                    envmaps: Sequence[str] = ()) -> Lighting:
    """Random natural illumination.

    sunsky: sun azimuth uniform, sun elevation uniform in [10°, 75°], turbidity uniform in [2, 8].
    envmap: one of ``envmaps`` at random, rotated uniformly about +y.
    mixed: sunsky or envmap with equal probability (sunsky alone when no envmaps are given).
    """
    if kind == "mixed":
        kind = "envmap" if (envmaps and rng.random() < 0.5) else "sunsky"
    if kind == "sunsky":
        φ = rng.uniform(0.0, 2.0 * math.pi)
        θ = math.radians(rng.uniform(10.0, 75.0))
        d = (math.cos(θ) * math.sin(φ), math.sin(θ), math.cos(θ) * math.cos(φ))
        return Lighting("sunsky", sun_direction=d, turbidity=float(rng.uniform(2.0, 8.0)))
    if kind == "envmap":
        if not envmaps:
            raise ValueError("envmap lighting needs at least one .exr environment map")
        return Lighting("envmap", envmap=str(envmaps[int(rng.integers(len(envmaps)))]),
                        rotation=float(rng.uniform(0.0, 360.0)))
    raise ValueError(f"lighting must be 'sunsky', 'envmap' or 'mixed', got {kind!r}")


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Relative luminance Y of linear sRGB ``(..., 3)`` (colour-science, sRGB primaries and D65)."""
    import colour  # lazy: colour-science is slow to import (about a second)
    cs = colour.models.RGB_COLOURSPACE_sRGB
    return colour.RGB_luminance(rgb, cs.primaries, cs.whitepoint)


def auto_exposure(rgb: np.ndarray, alpha: np.ndarray) -> float:
    """Factor mapping the 95th percentile luminance of covered pixels (alpha > 0.5) to 0.8."""
    covered = alpha > 0.5
    if not covered.any():
        return 1.0
    y = luminance(rgb)[covered] / np.maximum(alpha[covered], 1e-6)
    level = float(np.percentile(y, 95))
    return EXPOSURE_TARGET / level if level > 1e-8 else 1.0


@functools.lru_cache(maxsize=4096)
def sky_mean_luminance(lighting: Lighting) -> float:
    """L̄ = (1/4π) ∫ Y(L(ω)) dω of ``lighting``'s emitter (sun and sky), a float > 0.

    Monte Carlo with the emitter's importance sampling from the origin: ω_i, L(ω_i)/p(ω_i) =
    ``emitter.sample_direction`` on :data:`METER_SAMPLES` independent samples of a fixed
    seed, so the same light always meters the same value. Y is the luminance of linear sRGB.
    """
    ensure_variant()
    import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)
    import mitsuba as mi
    emitter = lighting.emitter()
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(0, METER_SAMPLES)                           # a fixed seed: a deterministic meter
    origin = dr.zeros(mi.Interaction3f)                      # the volume's centre
    _, weight = emitter.sample_direction(origin, sampler.next_2d())     # L(ω)/p(ω)
    rgb = np.stack([np.array(weight[c]) for c in range(3)], axis=-1)
    level = float(luminance(rgb.astype(np.float64)).mean()) / (4.0 * math.pi)
    if not math.isfinite(level) or level <= 0.0:
        raise ValueError(f"the light {lighting} has no positive, finite mean luminance ({level})")
    return level


def metered_exposure(lighting: Lighting) -> float:
    """The ``metered`` exposure factor k = 1 / L̄ of ``lighting`` (:func:`sky_mean_luminance`)."""
    return 1.0 / sky_mean_luminance(lighting)


def _alpha(density: torch.Tensor, views: torch.Tensor, filter: str, window: Optional[Window] = None) -> torch.Tensor:
    """The alpha pass: the ray marcher's AO image of the (capped) ``density``, its inputs checked
    as :func:`~mitsuba_platonic.render.render` checks them (this backend calls the marcher itself,
    not the package's dispatcher, which dispatches to it), through the same ``window``."""
    try:
        settings = RenderSettings.for_call("mitsuba", "ao", filter=filter)
    except UserError:
        raise
    except ValueError as e:
        raise UserError(str(e)) from None
    validate_volume(density, "ao")
    validate_views(views, batch=density.shape[0])
    check_lanes(density.shape[0], density.shape[-1], settings.spp)   # before Dr.Jit: say why, up front
    from ..drjit.marcher import march       # imports Dr.Jit and sets Mitsuba's variant: on the first alpha pass
    return march(density, views, settings, 0, window)


def _medium_grids(v: torch.Tensor) -> Tuple[np.ndarray, np.ndarray]:
    """RGBA ``(4, N, N, N)`` → (σ_t grid, albedo grid) in Mitsuba's [Z, Y, X, C] layout."""
    σ = extinction(v[3:4])
    return (to_mitsuba_grid(σ).contiguous().numpy().astype(np.float32),
            to_mitsuba_grid(v[:3]).contiguous().numpy().astype(np.float32))


def _scene(mi: Any, v: torch.Tensor, view: torch.Tensor, lighting: Lighting, spp: int,
           max_depth: int, filter: str) -> Any:
    """``scenes/physical.xml`` (volpath) holding the RGBA volume ``v``, seen from ``view`` under ``lighting``."""
    σ, albedo = _medium_grids(v)
    _, up, w = camera_frames(view[None])
    return load_scene("physical", grids={"sigma_t": σ, "albedo": albedo}, integrator="volpath",
                      max_depth=int(max_depth), resolution=v.shape[-1], spp=int(spp), filter=filter,
                      origin=3.0 * w[0], up=up[0], **lighting.scene_params())


def render_physical(volume: torch.Tensor, views: torch.Tensor, lighting: Sequence[Lighting],
                    spp: int = 32, max_depth: int = 8, seed: int = 0, filter: str = "trilinear",
                    exposure: str = "metered") -> Tuple[torch.Tensor, List[float]]:
    """Path-trace ``(B, 4, N, N, N)`` RGBA volumes from ``(B, 3)`` views under ``lighting`` (one each).

    Returns ``(images, exposures)``: images ``(B, 4, N, N)`` = premultiplied linear RGB radiance
    (times the exposure factor) plus alpha, and the exposure factor of each image: ``exposure``
    is one of :data:`EXPOSURES` (module docstring). Forward only (no gradients).
    """
    if volume.dim() != 5 or volume.shape[1] != 4:
        raise ValueError(f"physically based rendering needs RGBA volumes (B, 4, N, N, N), "
                         f"got {tuple(volume.shape)}")
    if len(lighting) != volume.shape[0]:
        raise ValueError(f"one lighting per volume expected: {len(lighting)} for batch {volume.shape[0]}")
    if not isinstance(spp, int) or spp < 1 or not isinstance(max_depth, int) or max_depth < 1:
        raise ValueError(f"spp and max_depth must be positive ints, got {spp!r}, {max_depth!r}")
    if exposure not in EXPOSURES:
        raise ValueError(f"exposure: expected one of {list(EXPOSURES)}, got {exposure!r}")
    mi = ensure_variant()
    volume = volume.detach().float().cpu()
    alpha = _alpha(volume[:, 3:].clamp(max=V_MAX_PHYSICAL), views, filter)
    images, exposures = [], []
    for b in range(volume.shape[0]):
        scene = _scene(mi, volume[b], views[b], lighting[b], spp, max_depth, filter)
        rgb = np.array(mi.render(scene, seed=seed + b))[..., :3]          # (H, W, 3) over black
        a = alpha[b, 0].numpy()
        k = (metered_exposure(lighting[b]) if exposure == "metered" else
             auto_exposure(rgb, a) if exposure == "auto" else 1.0)
        images.append(torch.cat([torch.from_numpy(rgb * k).permute(2, 0, 1), alpha[b]]))
        exposures.append(k)
    return torch.stack(images).float(), exposures


# -- differentiable path tracing (training through the physically based renderer) ----------

#: Majorant headroom: the σ grid's fixed maximum is this × the largest σ the cap allows, so no
#: voxel ever equals the majorant (where prbvolpath, with no null collisions left, returns σ_t
#: gradients of the wrong sign).
MAJORANT_HEADROOM = 1.5

_AD_SCENES: Dict[Tuple, Tuple[Any, Any]] = {}


def _ad_scene(n: int, spp: int, max_depth: int, filter: str) -> Tuple[Any, Any]:
    """A cached prbvolpath scene for N³ volumes (grids, view and sun are bound per render)."""
    key = (n, spp, max_depth, filter)
    if key not in _AD_SCENES:
        mi = ensure_variant()
        import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)
        σ_cap = -math.log(1.0 - V_MAX_PHYSICAL) / voxel_size(n)
        # the extinction grid's majorant, above its largest value: prbvolpath's gradients need null
        # collisions everywhere
        scene = load_scene("physical", grids={"sigma_t": dr.zeros(mi.TensorXf, (n, n, n, 1)),
                                              "albedo": dr.zeros(mi.TensorXf, (n, n, n, 3))},
                           properties={"sigma_t": {"max_value": MAJORANT_HEADROOM * σ_cap}},
                           integrator="prbvolpath", max_depth=int(max_depth), resolution=n, spp=int(spp),
                           filter=filter, **Lighting().scene_params())
        _AD_SCENES[key] = (scene, mi.traverse(scene))
    return _AD_SCENES[key]


def _window_transform(mi: Any, right: torch.Tensor, up: torch.Tensor, w: torch.Tensor, window: Window) -> Any:
    """The orthographic sensor's to_world through a :class:`~.window.Window` (zoom m, centre (c_x, c_y)):

        to_world = look_at(o + 2ω → o, up) · scale(h, h, 1),   o = c_x right + c_y up,  h = 1/m

    Mitsuba's orthographic film covers the sensor's local [−1, 1]² (rays along its local +z), which
    the scale widens to [−h, h]² about o: the pixel at image coordinates (x, y) starts at
    o + 2ω + (h x) right + (h y) up, as the marcher's ray (module :mod:`.window`)."""
    _, _, origin = window.frames(right, up)
    o = [float(x) for x in origin]
    h = window.half_width
    look = mi.ScalarTransform4f().look_at(origin=[o[k] + 2.0 * float(w[k]) for k in range(3)], target=o,
                                          up=[float(x) for x in up])
    return look @ mi.ScalarTransform4f().scale([h, h, 1.0])


def render_physical_ad(volume: torch.Tensor, views: torch.Tensor, lighting: str = "sunsky", spp: int = 4,
                       max_depth: int = 4, seed: int = 0, filter: str = "trilinear",
                       window: Optional[Window] = None, sample_seed: Optional[int] = None) -> torch.Tensor:
    """Differentiable path tracing of ``(B, 4, N, N, N)`` RGBA volumes under random skies.

    Each pair gets a random sun (drawn from ``seed``, see :func:`sample_lighting`), Mitsuba's
    ``prbvolpath`` renders the radiance, the ray marcher the alpha (AO of the capped density),
    and the image is scaled by the sky's metered exposure (:func:`metered_exposure`, as the
    collections are: it depends on the light only, so it is a true constant of the gradient). Returns ``(B, 4, N, N)`` premultiplied RGB + alpha; gradients flow to
    ``volume`` through σ_t, the albedo and the alpha. Only ``lighting='sunsky'`` is supported.
    ``window``: the orthographic camera's zoom and pan (:class:`~.window.Window`: the sensor's
    to_world, :func:`_window_transform`, and the alpha pass's rays; None: the whole cross-section).
    ``sample_seed``: the path samples' seed (pair b: ``sample_seed + 2b``) apart from the skies'
    ``seed`` (None: ``seed``), so that passes under one sky with other samples can be averaged
    (the viewer's progressive frames).
    """
    window = window_or_none(window)
    samples = seed if sample_seed is None else int(sample_seed)
    if lighting != "sunsky":
        raise ValueError(f"differentiable physical rendering supports lighting 'sunsky' only, got {lighting!r}")
    if volume.dim() != 5 or volume.shape[1] != 4:
        raise ValueError(f"physically based rendering needs RGBA volumes (B, 4, N, N, N), got {tuple(volume.shape)}")
    mi = ensure_variant()
    device = variant_device()                                # where the variant's arrays live
    n = volume.shape[-1]
    scene, params = _ad_scene(n, spp, max_depth, filter)
    σ = extinction(volume[:, 3:])
    alpha = _alpha(volume[:, 3:].clamp(0.0, V_MAX_PHYSICAL), views, filter, window)
    right, up, w = camera_frames(views.detach().cpu())                 # read into Mitsuba's sensors
    rng = np.random.default_rng(seed)
    images = []
    for b in range(volume.shape[0]):
        light = sample_lighting(rng, "sunsky")
        to_world = (sensor_transform(mi, right[b], up[b], w[b]) if window is None
                    else _window_transform(mi, right[b], up[b], w[b], window))
        settings = {"sensor.to_world": to_world,
                    "emitter.sun_direction": mi.Vector3f(*light.sun_direction),
                    "emitter.turbidity": mi.Float(light.turbidity)}
        grids = {"volume.interior_medium.sigma_t.data": to_mitsuba_grid(σ[b].float().to(device)),
                 "volume.interior_medium.albedo.data": to_mitsuba_grid(volume[b, :3].float().to(device))}
        rgb = differentiable_render(scene, params, grids, settings, spp, samples + 2 * b).permute(2, 0, 1)
        images.append(torch.cat([rgb.to(volume.device) * metered_exposure(light), alpha[b]]))
    return torch.stack(images)
