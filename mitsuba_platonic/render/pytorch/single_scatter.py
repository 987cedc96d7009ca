"""Single scattering of a sun and a sky in a generator volume: a deterministic, differentiable
image formation under light, checked against Mitsuba's volumetric path tracer.

The volume is the medium of the physical formation (:mod:`.physical`): extinction and albedo

    σ(x) = trilinear σ_t of −ln(1 − min(v, v_max)) / Δ      (v_max = 1 − 1e-3, :data:`~.grids.V_MAX_PHYSICAL`)
    a(x) = trilinear colour (linear RGB),   isotropic phase function p = 1 / 4π

lit by a :class:`SunAndSky`: a sun at infinity towards ω_s with irradiance E_s (on a plane facing
it) and a uniform sky of radiance L_sky. Light that scatters *once* reaches the camera as

    L(ray) = ∫ T(t) σ(x_t) a(x_t) S(x_t) dt,        T(t) = exp(−∫_0^t σ)
    S(x)   = p E_s exp(−τ_s(x)) + L_sky V(x),        τ_s(x) = ∫_0^∞ σ(x + s ω_s) ds
    V(x)   = (1/4π) ∫ exp(−τ(x, ω)) dω ≈ Σ_k w_k exp(−τ(x, ω_k))

the sky's visibility V a 14-point quadrature over the grid's axes and diagonals, each weighted by
the solid angle nearest to it (:data:`SKY_DIRECTIONS`, :data:`SKY_WEIGHTS`).
This is what Mitsuba's ``volpath`` computes at ``max_depth`` 2 on the same medium under
``scenes/emitters/sun_and_sky.xml``
(:func:`~mitsuba_platonic.render.mitsuba.single_scatter_reference.reference_render`), exactly for
the sun and up to the quadrature for the sky.

Light: transmittance volumes (deep shadow maps), one per light direction (the sun and the 14 of
the sky), by :func:`sweep`: the grid's planes perpendicular to the direction's dominant axis,
taken from the light's side, carry the transmittance from plane to plane (product domain, exact
at σ = 0),

    T_0(p) = e^{−ℓ σ_0(p)/2},     T_i(p) = T_{i−1}(p + δ) e^{−ℓ (σ_i(p) + σ_{i−1}(p + δ))/2}

(δ: the in-plane move of a ray per plane towards the light, ℓ its length; the trapezoid rule,
exact where σ is linear along the ray, as trilinear σ is along an axis). At a camera sample x the
transmittance is not interpolated between voxel centres but *continued* (:func:`transmittance`):
from x over the fraction f of a plane to the plane on the light's side, by the same rule, then,
for the sun, along a short shadow ray of ``shadow_planes`` planes in half-plane steps, and only
then read from the sweep. This matters at surfaces: a voxel of v ≈ 1 holds an optical depth of
6.9, and across the ramp of trilinear σ in front of it the light falls off within a fraction of
a voxel, so reading T at voxel centres makes a lit opaque surface 16× too dark, lerping it
between them 4–28 % too bright, and lerping across the rows of a slanted sun up to 2× (the
shadow ray's job); docs/rendering.md, "Single scattering", has the measurements.

Camera (orthographic): ``spp`` rays per pixel (a regular grid over the pixel, as Mitsuba's box
filter averages it), m = ``steps_per_voxel`` samples per voxel along each, at the midpoints of
steps h = Δ/m; σ and a read trilinearly (σ in the extinction domain, as ``volpath`` reads it):

    C = Σ_k T_k (1 − e^{−σ_k h}) a_k S_k,   T_k = exp(−h Σ_{j<k} σ_j),   α = 1 − exp(−h Σ_k σ_k)

Exposure: ``metered`` scales the radiance by k = 1 / L̄, L̄ = Y(E_s) / 4π + Y(L_sky), the light's
mean luminance over the sphere (as :func:`.physical.metered_exposure` meters Mitsuba's skies), so
a white, thin, unshadowed medium has S k = 1 and images mean what EA images mean; ``none``
leaves radiance.

Left out: light scattered more than once (``volpath``'s ``max_depth`` > 2), sky directions other
than the 14, and the perspective camera. Everything is torch, differentiable by autograd.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Sequence, Tuple

import numpy as np
import torch
import torch.nn.functional as F

from ...errors import UserError
from ...views import camera_frames, validate_views
from ...volume import voxel_size, world_to_grid
from ..grids import extinction

__all__ = ["SunAndSky", "LightBatch", "sample_sun_and_sky", "sample_lights", "SKY_DIRECTIONS", "SKY_WEIGHTS",
           "Sweep", "sweep", "transmittance", "render_single_scatter", "checked_lights", "mean_luminance",
           "EXPOSURES", "SKY_SHARE", "daylights", "sky_share"]

#: Rec. 709 / sRGB luminance weights of linear RGB.
_Y = (0.2126, 0.7152, 0.0722)

#: How the radiance is scaled (module docstring, "Exposure").
EXPOSURES = ("metered", "none")

#: The sky's quadrature directions: the six axes and the eight diagonals of the grid. Each moves a
#: whole number of voxels in a plane per plane swept (δ ∈ {0, ±1}), so their sweeps read no value
#: between voxels: measured against ``volpath``, the six axes alone leave the sky 4.5–6 % too
#: bright, and all 26 neighbours of a voxel come no closer to it than these 14 (docs/rendering.md).
SKY_DIRECTIONS = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0),
                  (0.0, 0.0, -1.0)) + tuple((x / math.sqrt(3.0), y / math.sqrt(3.0), z / math.sqrt(3.0))
                                            for x in (1.0, -1.0) for y in (1.0, -1.0) for z in (1.0, -1.0))

#: Each direction's weight: the solid angle of the directions nearer to it than to the other 13,
#: over 4π (an axis 0.067820, a diagonal 0.074135; a test integrates them again).
SKY_WEIGHTS = (0.067820,) * 6 + ((1.0 - 6 * 0.067820) / 8,) * 8


@dataclass(frozen=True)
class SunAndSky:
    """A sun and a uniform sky: the light of the single-scattering formation.

    sun_direction: unit vector towards the sun.
    sun_irradiance: linear RGB irradiance of the sun on a plane facing it (≥ 0).
    sky_radiance: linear RGB radiance of the sky, the same from every direction (≥ 0).
    """

    sun_direction: Tuple[float, float, float] = tuple(x / math.sqrt(0.98) for x in (0.3, 0.8, 0.5))
    sun_irradiance: Tuple[float, float, float] = (math.pi, math.pi, math.pi)
    sky_radiance: Tuple[float, float, float] = (0.25, 0.25, 0.25)

    def __post_init__(self) -> None:
        d = np.asarray(self.sun_direction, dtype=np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or abs(np.linalg.norm(d) - 1.0) > 1e-6:
            raise UserError(f"sun_direction: expected a unit 3-vector, got {self.sun_direction!r}")
        for name in ("sun_irradiance", "sky_radiance"):
            x = np.asarray(getattr(self, name), dtype=np.float64)
            if x.shape != (3,) or not np.all(np.isfinite(x)) or np.any(x < 0):
                raise UserError(f"{name}: expected 3 finite values ≥ 0 (linear RGB), got {getattr(self, name)!r}")

    def scene_params(self) -> Dict[str, Any]:
        """This light as parameters of ``scenes/physical.xml`` (``lighting`` picks emitters/sun_and_sky.xml)."""
        return {"lighting": "sun_and_sky",
                "sunlight_direction": tuple(-float(x) for x in self.sun_direction),
                "sun_irradiance": tuple(float(x) for x in self.sun_irradiance),
                "sky_radiance": tuple(float(x) for x in self.sky_radiance)}


@dataclass(frozen=True)
class LightBatch:
    """One :class:`SunAndSky` per pair as tensors: ``direction``, ``irradiance``, ``sky`` each ``(B, 3)`` float64."""

    direction: torch.Tensor
    irradiance: torch.Tensor
    sky: torch.Tensor

    @classmethod
    def of(cls, lights: Sequence[SunAndSky]) -> "LightBatch":
        rows = [(l.sun_direction, l.sun_irradiance, l.sky_radiance) for l in lights]
        d, e, s = (torch.tensor([r[i] for r in rows], dtype=torch.float64) for i in range(3))
        return cls(d, e, s)

    def __len__(self) -> int:
        return self.direction.shape[0]


#: The range of the sky's share of the mean luminance in :func:`sample_sun_and_sky`'s prior.
SKY_SHARE = (0.2, 0.6)


def sample_sun_and_sky(rng: np.random.Generator) -> SunAndSky:
    """A random daylight: the sun's azimuth uniform, its elevation uniform in [10°, 75°] (as
    :func:`.physical.sample_lighting` draws Mitsuba's suns), the sky's share of the mean
    luminance L̄ uniform in [0.2, 0.6], grey light, L̄ = ½."""
    φ = rng.uniform(0.0, 2.0 * math.pi)
    θ = math.radians(rng.uniform(10.0, 75.0))
    d = (math.cos(θ) * math.sin(φ), math.sin(θ), math.cos(θ) * math.cos(φ))
    share = rng.uniform(*SKY_SHARE)
    sun, sky = _grey_daylight(share)
    return SunAndSky(d, (sun, sun, sun), (sky, sky, sky))


def _grey_daylight(share):
    """(E_s, L_sky) of a grey daylight of mean luminance L̄ = ½ whose sky holds ``share`` of it:
    L_sky = ½ share, E_s / 4π = ½ (1 − share) (a float, or a tensor of shares)."""
    return 0.5 * (1.0 - share) * 4.0 * math.pi, 0.5 * share


def daylights(directions: torch.Tensor, shares: torch.Tensor) -> LightBatch:
    """Grey daylights of the prior's kind (:func:`sample_sun_and_sky`) with the given sun
    ``directions`` ``(B, 3)`` (unit vectors, normalised here) and sky ``shares`` ``(B,)``: what a
    light read from a photo (:class:`~mitsuba_platonic.networks.nets.LightHead`) renders with. Detached,
    float64, on the CPU, as :class:`LightBatch` holds its lights."""
    d = directions.detach().to("cpu", torch.float64)
    if d.dim() != 2 or d.shape[1] != 3 or shares.shape != (d.shape[0],):
        raise UserError(f"daylights: expected directions (B, 3) and shares (B,), got {tuple(d.shape)} and "
                        f"{tuple(shares.shape)}")
    sun, sky = _grey_daylight(shares.detach().to("cpu", torch.float64))
    return LightBatch(d / d.norm(dim=1, keepdim=True), sun[:, None].expand(-1, 3).clone(),
                      sky[:, None].expand(-1, 3).clone())


def sample_lights(b: int, seed: int) -> LightBatch:
    """B lights from the :func:`sample_sun_and_sky` prior, pair i's drawn from ``(seed, i)``: the
    lights of ``render(..., backend='single_scatter', seed=seed)``."""
    return LightBatch.of([sample_sun_and_sky(np.random.default_rng([seed, i])) for i in range(b)])


def mean_luminance(lights: LightBatch) -> torch.Tensor:
    """L̄ = Y(E_s) / 4π + Y(L_sky) per pair ``(B,)``: the light's mean luminance over the sphere."""
    y = lights.irradiance.new_tensor(_Y)
    return (lights.irradiance @ y) / (4.0 * math.pi) + lights.sky @ y


def sky_share(lights: LightBatch) -> torch.Tensor:
    """Y(L_sky) / L̄ per pair ``(B,)``: the sky's share of the mean luminance (the prior draws it
    from :data:`SKY_SHARE`; :func:`daylights` builds a light from it)."""
    return (lights.sky @ lights.sky.new_tensor(_Y)) / mean_luminance(lights)


# -- Light: transmittance volumes -----------------------------------------------------------------


@dataclass(frozen=True)
class Sweep:
    """Transmittance volumes towards L light directions per pair (:func:`sweep`).

    ``opacity`` ``(B·L, 1, N, N, N)``: 1 − T towards the light at the voxel centres, in the grid's
    own [d, h, w] order (stored as opacity so that reads outside the cube, zero, mean T = 1).
    ``axis`` ``(B·L,)``: the sweep's axis (0, 1, 2 = d, h, w); ``flip``: the light lies at its
    high-index end; ``length`` ``(B·L,)``: a ray's length ℓ per plane; ``step`` ``(B·L, 3)``: its
    move per plane towards the light in grid indices [d, h, w].
    """

    opacity: torch.Tensor
    axis: torch.Tensor
    flip: torch.Tensor
    length: torch.Tensor
    step: torch.Tensor


def sweep(σ: torch.Tensor, directions: torch.Tensor) -> Sweep:
    """The transmittance of ``σ`` ``(B, 1, N, N, N)`` towards each of ``directions`` ``(B, 3)`` at the
    voxel centres (module docstring, "Light"): the planes perpendicular to the direction's dominant
    grid axis, swept from the light's side with the trapezoid rule, in the product domain:

        T_0(p) = e^{−ℓ σ_0(p)/2},     T_i(p) = T_{i−1}(p + δ) e^{−ℓ (σ_i(p) + σ_{i−1}(p + δ))/2}

    In grid indices a world direction ω is g = (−ω_z, −ω_y, ω_x) (dims [d, h, w] run along −z,
    −y, +x); its dominant axis a orders the planes, δ = g_⊥ / |g_a| and ℓ = Δ / |g_a|. In-plane
    reads are bilinear; outside the cube σ = 0 and T = 1 (a ray towards the light that has left
    the cube sideways stays outside).
    """
    n = σ.shape[-1]
    Δ = voxel_size(n)
    d = directions.detach().to(torch.float64).cpu()
    g = torch.stack([-d[:, 2], -d[:, 1], d[:, 0]], dim=-1)     # the direction in grid index units
    axis = g.abs().argmax(dim=1)
    across = torch.tensor([[1, 2], [0, 2], [0, 1]])[axis]      # the plane's row and column axes
    flip = g.gather(1, axis[:, None])[:, 0] > 0                # the light lies at the high-index end
    ga = g.gather(1, axis[:, None])[:, 0].abs()
    δ = torch.stack([g.gather(1, across[:, 1:])[:, 0], g.gather(1, across[:, :1])[:, 0]], dim=1) / ga[:, None]
    length = Δ / ga

    def to_planes(v: torch.Tensor, b: int) -> torch.Tensor:   # [d, h, w] → [plane, row, column], plane 0 sunward
        return (v.flip(int(axis[b])) if flip[b] else v).permute(int(axis[b]), *across[b].tolist())

    # unbind, not σ[b]: the gradient of an index is a zeroed copy of the whole batch per pair
    σ_p = torch.stack([to_planes(one, b) for b, one in enumerate(σ[:, 0].unbind(0))])   # (B, N, N, N)
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * Δ
    rows, cols = torch.meshgrid(c, c, indexing="ij")
    grid = (torch.stack([cols, rows], dim=-1)[None] + Δ * δ[:, None, None, :]).to(σ)   # p + δ, in [−1, 1]
    ahead = F.grid_sample(σ_p, grid, mode="bilinear", padding_mode="zeros", align_corners=False)   # σ_{i−1}(p + δ)
    ℓ = length.to(σ)[:, None, None, None]
    factor = torch.exp(-0.5 * ℓ * (σ_p + torch.cat([torch.zeros_like(σ_p[:, :1]), ahead[:, :-1]], dim=1)))
    per_plane = factor.split(1, dim=1)                         # split, not slices: one gradient copy, not N
    A = [1.0 - per_plane[0]]                                   # opacity 1 − T: zero outside the cube
    for i in range(1, n):                                      # T_{i−1}(p + δ): the previous plane, moved
        moved = F.grid_sample(A[-1], grid, mode="bilinear", padding_mode="zeros", align_corners=False)
        A.append(1.0 - (1.0 - moved) * per_plane[i])
    A_p = torch.cat(A, dim=1)
    opacity = []
    for b, t in enumerate(A_p.unbind(0)):                      # back to [d, h, w]
        back = [0, 0, 0]
        for position, ax in enumerate((int(axis[b]), *across[b].tolist())):
            back[ax] = position
        t = t.permute(*back)
        opacity.append(t.flip(int(axis[b])) if flip[b] else t)
    return Sweep(torch.stack(opacity)[:, None], axis, flip, length, g / ga[:, None])


def _lookup(volume: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """Trilinear reads of ``volume`` ``(B, C, N, N, N)`` at grid indices ``q`` ``(B, K, 3)``
    [d, h, w] (zero outside the cube) → ``(B, C, K)``."""
    n = volume.shape[-1]
    grid = ((2.0 * q.flip(-1) + 1.0) / n - 1.0)[:, :, None, None, :]          # → grid_sample's (x, y, z)
    return F.grid_sample(volume, grid.to(volume), mode="bilinear", padding_mode="zeros",
                         align_corners=False)[:, :, :, 0, 0]


def transmittance(s: Sweep, σ: torch.Tensor, q: torch.Tensor, σ_q: torch.Tensor,
                  shadow_planes: int = 0) -> torch.Tensor:
    """T towards each sweep's light at points of continuous grid index ``q`` ``(B·L, K, 3)``
    ([d, h, w], voxel centres at integers) where σ is ``σ_q`` ``(B·L, K)``; ``σ`` the volume
    ``(B·L, 1, N, N, N)`` the sweep was made of.

    The continuation from the plane on the light's side of each point (module docstring,
    "Light"), then a short shadow ray across ``shadow_planes`` more planes in half-plane steps,
    the trapezoid rule on σ read trilinearly at each, and the sweep's T where it ends. Where the
    light is slanted across the grid's rows, the ray integrates the steep layer at a surface,
    which the planes' values, read between rows, would not.
    """
    n = s.opacity.shape[-1]
    ℓ = s.length.to(q)[:, None]
    step = s.step.to(q)[:, None, :]                            # one plane towards the light, in [d, h, w]
    qa = q.gather(2, s.axis.to(q.device)[:, None, None].expand(-1, q.shape[1], 1))[..., 0]
    P = torch.where(s.flip.to(q.device)[:, None], (n - 1) - qa, qa)
    P0 = torch.floor(P).clamp(-1, n - 1)                       # the plane on the light's side (−1: none)
    f = (P - P0).clamp_min(0.0)
    x = q + f[..., None] * step                                # x⁺: on plane P₀
    if shadow_planes == 0:                                     # σ and the sweep read at x⁺ alike: one lookup
        σ_x, A = _lookup(torch.cat([σ, s.opacity], dim=1), x).unbind(1)
        return torch.exp(-0.5 * f * ℓ * (σ_q + σ_x)) * (1.0 - A)
    σ_x = _lookup(σ, x).squeeze(1)
    T = torch.exp(-0.5 * f * ℓ * (σ_q + σ_x))
    for _ in range(2 * shadow_planes):                         # half planes: the ray crosses rows, where σ bends
        x = x + 0.5 * step
        σ_next = _lookup(σ, x).squeeze(1)
        T = T * torch.exp(-0.25 * ℓ * (σ_x + σ_next))
        σ_x = σ_next
    return T * (1.0 - _lookup(s.opacity, x).squeeze(1))       # the sweep's T where the ray has got to


# -- Camera ----------------------------------------------------------------------------------------


def _camera_samples(views: torch.Tensor, n: int, m: int, s: int) -> torch.Tensor:
    """World points of the camera samples ``(B, N·m, N·s, N·s, 3)`` [b, k, i, j] float64: an s × s
    grid of ray positions (x_j, y_i) in each pixel, at the centres of its s × s sub-pixels, and
    depths z_k = 1 − (k + ½) Δ/m (orthographic, :mod:`.closed_form`'s frame)."""
    right, up, w = camera_frames(views)
    Δ = voxel_size(n)
    c = -1.0 + (torch.arange(n * s, dtype=torch.float64) + 0.5) * (Δ / s)
    z = 1.0 - (torch.arange(n * m, dtype=torch.float64) + 0.5) * (Δ / m)
    return (z[None, :, None, None, None] * w[:, None, None, None, :]
            + (-c)[None, None, :, None, None] * up[:, None, None, None, :]
            + c[None, None, None, :, None] * right[:, None, None, None, :])


def render_single_scatter(volume: torch.Tensor, views: torch.Tensor, lights: Any, exposure: str = "metered",
                          steps_per_voxel: int = 4, shadow_planes: int = 2, spp: int = 1) -> torch.Tensor:
    """Render ``(B, 4, N, N, N)`` RGBA volumes from ``(B, 3)`` views (orthographic), lit by single
    scattering of one :class:`SunAndSky` each (a sequence of them, or a :class:`LightBatch`).

    Returns ``(B, 4, N, N)``: premultiplied linear RGB radiance (times the exposure, module
    docstring) and α = 1 − exp(−∫σ). Differentiable w.r.t. ``volume``. ``steps_per_voxel``:
    samples per voxel along a camera ray; ``shadow_planes``: the sun's shadow ray, in planes;
    ``spp``: rays per pixel, a square number (the defaults, and what fewer cost in accuracy:
    docs/rendering.md, "Single scattering").
    """
    batch = checked_lights(volume, views, lights, exposure)
    for name, value, least in (("steps_per_voxel", steps_per_voxel, 1), ("shadow_planes", shadow_planes, 0),
                               ("spp", spp, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise UserError(f"{name}: expected an int ≥ {least}, got {value!r}")
    s = math.isqrt(spp)
    if s * s != spp:
        raise UserError(f"spp: expected a square number of rays per pixel (1, 4, 9, …), got {spp}")
    b_, n, m = volume.shape[0], volume.shape[-1], steps_per_voxel
    σ = extinction(volume[:, 3:])
    # -- camera samples: albedo and σ, and their place in the grid
    grid = world_to_grid(_camera_samples(views, n, m, s)).to(volume)
    σ_x = F.grid_sample(σ, grid, mode="bilinear", padding_mode="zeros",
                        align_corners=False).squeeze(1)         # (B, N·m, N, N)
    # the albedo is the medium's colour, read as Mitsuba's grid reads it: its edge values up to the faces
    a = F.grid_sample(volume[:, :3], grid, mode="bilinear", padding_mode="border", align_corners=False)
    q = ((grid.flip(-1) + 1.0) * (n / 2.0) - 0.5).reshape(b_, -1, 3)   # grid_sample (x, y, z) → index [d, h, w]
    # -- light: the sun, with a shadow ray; the sky's directions, whose planes hold their rays
    sun = transmittance(sweep(σ, batch.direction), σ, q, σ_x.reshape(b_, -1), shadow_planes)
    k = len(SKY_DIRECTIONS)
    σ_k = σ.repeat_interleave(k, dim=0)
    sky = transmittance(sweep(σ_k, torch.tensor(SKY_DIRECTIONS, dtype=torch.float64).repeat(b_, 1)), σ_k,
                        q.repeat_interleave(k, dim=0), σ_x.reshape(b_, -1).repeat_interleave(k, dim=0))
    w = torch.tensor(SKY_WEIGHTS, dtype=sky.dtype, device=sky.device)
    V = (sky.reshape(b_, k, -1) * w[None, :, None]).sum(dim=1)  # the sky's visibility
    E = batch.irradiance.to(volume)[:, :, None, None, None]
    L = batch.sky.to(volume)[:, :, None, None, None]
    S = (E * (sun.reshape(b_, 1, *σ_x.shape[1:]) / (4.0 * math.pi))
         + L * V.reshape(b_, 1, *σ_x.shape[1:]))
    if exposure == "metered":
        S = S / mean_luminance(batch).to(volume)[:, None, None, None, None]
    # -- composite along the ray (dim 2), front to back
    h = voxel_size(n) / m
    optical = σ_x[:, None] * h                                  # (B, 1, N·m, N, N)
    T = torch.exp(-(torch.cumsum(optical, dim=2) - optical))    # exclusive: Σ_{j<k}
    rgb = (T * -torch.expm1(-optical) * a * S).sum(dim=2)
    alpha = -torch.expm1(-optical.sum(dim=2))
    return F.avg_pool2d(torch.cat([rgb, alpha], dim=1), s)    # a pixel: the mean of its rays


def checked_lights(volume: torch.Tensor, views: torch.Tensor, lights: Any, exposure: str) -> LightBatch:
    """Check a single-scattering call's inputs (an RGBA ``(B, 4, N, N, N)`` volume in [0, 1], ``(B, 3)``
    unit views, an exposure of :data:`EXPOSURES`, one light per volume) and return its lights as a
    :class:`LightBatch`; a :class:`~mitsuba_platonic.errors.UserError` naming what is wrong otherwise."""
    if not isinstance(volume, torch.Tensor) or volume.dim() != 5 or volume.shape[1] != 4:
        raise UserError(f"single scattering renders RGBA volumes (B, 4, N, N, N), got "
                        f"{tuple(volume.shape) if isinstance(volume, torch.Tensor) else type(volume).__name__}")
    if not torch.isfinite(volume).all() or volume.min() < 0 or volume.max() > 1:
        raise UserError("single scattering: volume values must be finite and in [0, 1]")
    validate_views(views, batch=volume.shape[0])
    if exposure not in EXPOSURES:
        raise UserError(f"exposure: expected one of {list(EXPOSURES)}, got {exposure!r}")
    batch = lights if isinstance(lights, LightBatch) else LightBatch.of(list(lights))
    if len(batch) != volume.shape[0]:
        raise UserError(f"one light per volume expected: {len(batch)} for batch {volume.shape[0]}")
    return batch
