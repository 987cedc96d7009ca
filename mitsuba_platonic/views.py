"""Views: directions on the unit sphere and the cameras they define.

A *view* is a unit vector ω ∈ S² pointing from the object's centre to a camera that looks at
the origin with upright orientation (up = +y). The input view of PlatonicGAN is the front view
ω₀ = (0, 0, 1). The camera is orthographic (the paper's, the default) or a pinhole
(perspective, :func:`lens`); both renderers sample the same points (see "Projection" below).

Angles (used only to build views, never stored):

    ω(φ, θ) = (cos θ · sin φ,  sin θ,  cos θ · cos φ)

with azimuth φ measured from +z towards +x and elevation θ from the xz-plane
towards +y, so ω(0, 0) = ω₀ and θ = ±90° are the poles ±y.

Camera frame (``camera_frames``), right-handed, looking along −ω:

    right = (cos φ, 0, −sin φ) = normalize((ω_z, 0, −ω_x))
    up    = ω × right

For every ω off the poles this is the usual look-at frame with world up +y.
At the poles the look-at frame is undefined (ω ∥ up); there we use right = +x,
which is the limit of the frame along the meridian φ = 0 (the front meridian),
so the frame is continuous along that meridian through both poles and defined
everywhere. (No frame field on S² is continuous everywhere: hairy-ball theorem.)

Projection. Image coordinates x, y ∈ [−1, 1] (x along ``right``, y along ``up``) and the
camera depth z ∈ [−1, 1] along ω (z = 1 is the front face of the cube) name the world point

    p = S(z) (x · right + y · up) + z · ω

Orthographic: S ≡ 1, every ray is parallel to −ω. Perspective: a pinhole at D ω (distance D
from the centre, D > 1, outside the planes z ∈ [−1, 1]) with field of view F (the full angle
across the image) has S(z) = (D − z) tan(F/2): the ray of pixel (x, y) meets depth plane z
there. By default D = 1 / tan(F/2), so that S(0) = 1 and the plane through the centre fills
the image exactly as it does orthographically. A ray of the pinhole crosses a slab of depth
dz along a path ℓ dz longer, with

    ℓ(x, y) = √(1 + tan²(F/2) (x² + y²))      (1 orthographically)

which both renderers use as the segment's length factor (docs/conventions.md, "Cameras").
"""

from __future__ import annotations

import math
from typing import Optional, Tuple, Union

import torch

from .errors import UserError

__all__ = [
    "front_view",
    "from_angles",
    "to_angles",
    "sample_views",
    "turntable",
    "camera_frames",
    "validate_views",
    "DISTRIBUTIONS",
    "COLLECTION_DISTRIBUTIONS",
    "DEFAULT_ELEVATION",
    "SIDE_AZIMUTHS",
    "DEFAULT_SIDE_WIDTH",
    "check_side_width",
    "CAMERAS",
    "lens",
]

Seed = Union[int, torch.Generator, None]

#: The view distributions p_view of :func:`sample_views`.
DISTRIBUTIONS = ("sphere", "band", "ring")

#: The view distributions a rendered collection may use: those of training, and 'sides' (photographed
#: mostly from the sides, as people photograph animals and vehicles; :func:`sample_views`).
COLLECTION_DISTRIBUTIONS = DISTRIBUTIONS + ("sides",)

#: The elevation (degrees) a 'band', 'ring' or 'sides' distribution uses when a dataset or run names none.
DEFAULT_ELEVATION = {"band": (0.0, 60.0), "ring": 20.0, "sides": (0.0, 60.0)}

#: The azimuths (degrees) of the *side views*: ω = ±x, which see broadside an object whose length lies
#: along z (the convention of :mod:`mitsuba_platonic.data.shapes`: the object faces +z, the front
#: camera at azimuth 0°, and a class with a length lays it along z).
SIDE_AZIMUTHS = (90.0, -90.0)

#: The half-width W (degrees) of the azimuth windows about :data:`SIDE_AZIMUTHS` of 'sides'.
DEFAULT_SIDE_WIDTH = 30.0

#: Cameras (module docstring, "Projection").
CAMERAS = ("orthographic", "perspective")

#: Horizontal norm below which ω counts as a pole (computed in float64).
POLE_EPS = 1e-12

#: Tolerance on |ω| − 1 accepted as "unit" at the public boundary.
UNIT_TOL = 1e-4


def front_view(batch: Optional[int] = None, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The input view ω₀ = (0, 0, 1): shape ``(3,)``, or ``(batch, 3)`` when ``batch`` is given."""
    w = torch.tensor([0.0, 0.0, 1.0], dtype=dtype)
    return w if batch is None else w.expand(batch, 3).clone()


def from_angles(azimuth: torch.Tensor | float, elevation: torch.Tensor | float,
                degrees: bool = True) -> torch.Tensor:
    """Views from azimuth φ and elevation θ: ``ω = (cos θ sin φ, sin θ, cos θ cos φ)``.

    Accepts scalars or broadcastable tensors; returns ``(..., 3)`` float32.
    """
    phi = torch.as_tensor(azimuth, dtype=torch.float64)
    theta = torch.as_tensor(elevation, dtype=torch.float64)
    if degrees:
        phi, theta = torch.deg2rad(phi), torch.deg2rad(theta)
    phi, theta = torch.broadcast_tensors(phi, theta)
    w = torch.stack([torch.cos(theta) * torch.sin(phi), torch.sin(theta),
                     torch.cos(theta) * torch.cos(phi)], dim=-1)
    return w.to(torch.float32)


def to_angles(views: torch.Tensor, degrees: bool = True) -> Tuple[torch.Tensor, torch.Tensor]:
    """Inverse of :func:`from_angles`: ``(azimuth, elevation)``; azimuth is 0 at the poles."""
    w = views.to(torch.float64)
    phi = torch.atan2(w[..., 0], w[..., 2])
    theta = torch.asin(w[..., 1].clamp(-1.0, 1.0))
    if degrees:
        phi, theta = torch.rad2deg(phi), torch.rad2deg(theta)
    return phi, theta


def _generator(seed: Seed) -> torch.Generator:
    if isinstance(seed, torch.Generator):
        return seed
    g = torch.Generator()
    g.manual_seed(0 if seed is None else int(seed))
    return g


def _side_azimuths(u: torch.Tensor, width: float) -> torch.Tensor:
    """Azimuths (radians) uniform on [90° − W, 90° + W] ∪ [−90° − W, −90° + W] from uniforms ``u`` in
    [0, 1): u < ½ → 90° + (4u − 1) W, else −90° + (4u − 3) W (each window half the mass)."""
    first = u < 0.5
    offset = torch.where(first, 4.0 * u - 1.0, 4.0 * u - 3.0) * width
    side = torch.where(first, torch.full_like(u, SIDE_AZIMUTHS[0]), torch.full_like(u, SIDE_AZIMUTHS[1]))
    return torch.deg2rad(side + offset)


def check_side_width(width: object) -> float:
    """``width`` as a float if it is a number of degrees in (0, 90] (the half-width W of 'sides'),
    else ``ValueError`` (a :class:`~mitsuba_platonic.errors.UserError`) saying what was expected."""
    if isinstance(width, bool) or not isinstance(width, (int, float)) or not math.isfinite(width) \
            or not 0.0 < float(width) <= 90.0:
        raise UserError(f"'sides' needs side_width, the half-width W of the azimuth windows about the side "
                        f"views ±90°, in degrees with 0 < W <= 90 (90: every azimuth), got {width!r}")
    return float(width)


def sample_views(n: int, distribution: str = "sphere", seed: Seed = 0,
                 elevation: Tuple[float, float] | float = (-90.0, 90.0),
                 side_width: Optional[float] = None) -> torch.Tensor:
    """Draw ``n`` random views, deterministic under ``seed`` (an int or a ``torch.Generator``).

    ``distribution``:
      - ``"sphere"``: uniform on S² (y uniform in [−1, 1], φ uniform), the paper's p_view.
      - ``"band"``: uniform *by area* on the band of elevations ``elevation = (θ_lo, θ_hi)``
        degrees, i.e. y = sin θ uniform in [sin θ_lo, sin θ_hi].
      - ``"ring"``: fixed elevation ``elevation = θ`` (degrees, a single number), φ uniform:
        an azimuth-only ring (turntable-like training).
      - ``"sides"`` (collections only, :data:`COLLECTION_DISTRIBUTIONS`): photographed mostly from
        the sides: φ uniform within ±W of the side views :data:`SIDE_AZIMUTHS` (±90°), half the
        views in each window, W = ``side_width`` degrees (default :data:`DEFAULT_SIDE_WIDTH`,
        0 < W ≤ 90); y as the band's, ``elevation = (θ_lo, θ_hi)``.

    ``side_width`` is read by ``"sides"`` only (``ValueError`` for the others). Returns ``(n, 3)``
    float32 unit vectors.
    """
    if not isinstance(n, int) or n < 0:
        raise UserError(f"n must be a non-negative int, got {n!r}")
    if side_width is not None and distribution != "sides":
        raise UserError(f"side_width is read by the 'sides' distribution only; {distribution!r} would ignore it")
    g = _generator(seed)
    u = torch.rand(n, generator=g, dtype=torch.float64)
    phi = u * (2.0 * math.pi)
    if distribution == "sphere":
        lo, hi = -1.0, 1.0
    elif distribution in ("band", "sides"):
        if isinstance(elevation, (int, float)) or len(elevation) != 2:
            raise UserError(f"{distribution!r} needs elevation=(low, high) in degrees, got {elevation!r}")
        e0, e1 = float(elevation[0]), float(elevation[1])
        if not -90.0 <= e0 <= e1 <= 90.0:
            raise UserError(f"{distribution!r} needs elevation=(low, high) with -90 <= low <= high <= 90 degrees, "
                            f"got {elevation!r}")
        lo, hi = math.sin(math.radians(e0)), math.sin(math.radians(e1))
        if distribution == "sides":
            width = DEFAULT_SIDE_WIDTH if side_width is None else check_side_width(side_width)
            phi = _side_azimuths(u, width)
    elif distribution == "ring":
        if not isinstance(elevation, (int, float)):
            raise UserError(f"'ring' needs a single elevation in degrees, got {elevation!r}")
        if not -90.0 <= float(elevation) <= 90.0:
            raise UserError(f"'ring' needs an elevation in [-90, 90] degrees, got {elevation!r}")
        lo = hi = math.sin(math.radians(float(elevation)))
    else:
        raise UserError(f"distribution must be one of {COLLECTION_DISTRIBUTIONS}, got {distribution!r}")
    y = lo + (hi - lo) * torch.rand(n, generator=g, dtype=torch.float64)
    r = torch.sqrt((1.0 - y * y).clamp_min(0.0))
    w = torch.stack([r * torch.sin(phi), y, r * torch.cos(phi)], dim=-1)
    return w.to(torch.float32)


def turntable(n: int, elevation: float = 0.0, start: float = 0.0) -> torch.Tensor:
    """``n`` evenly spaced azimuths starting at ``start`` degrees, at a fixed elevation: ``(n, 3)``."""
    if not isinstance(n, int) or n < 1:
        raise UserError(f"n must be a positive int, got {n!r}")
    phi = start + torch.arange(n, dtype=torch.float64) * (360.0 / n)
    return from_angles(phi, torch.full_like(phi, float(elevation)))


def validate_views(views: torch.Tensor, batch: Optional[int] = None) -> None:
    """Raise ``ValueError`` (a :class:`~mitsuba_platonic.errors.UserError`) unless ``views`` is a
    finite ``(B, 3)`` tensor of unit vectors with B ≥ 1 and values (not on the 'meta' device)."""
    if not isinstance(views, torch.Tensor):
        raise UserError(f"views must be a torch.Tensor of shape (B, 3), got {type(views).__name__}")
    if views.dim() != 2 or views.shape[1] != 3:
        raise UserError(f"views must have shape (B, 3), got {tuple(views.shape)}")
    if views.shape[0] == 0:
        raise UserError("views hold no view (shape (0, 3)); pass at least one")
    if views.is_meta:
        raise UserError("views are on the 'meta' device (a shape without values); rendering needs "
                        "values: create them on 'cpu' or 'cuda'")
    if batch is not None and views.shape[0] != batch:
        raise UserError(f"views has batch {views.shape[0]} but the volume has batch {batch}: "
                        "one view per volume is expected")
    if not torch.isfinite(views).all():
        raise UserError("views contain NaN or Inf")
    norm = views.detach().to(torch.float64).norm(dim=1)
    bad = (norm - 1.0).abs() > UNIT_TOL
    if bad.any():
        i = int(bad.nonzero()[0])
        raise UserError(f"views must be unit vectors (|ω| = 1 ± {UNIT_TOL}); view {i} has "
                        f"|ω| = {float(norm[i]):.6g}")


def camera_frames(views: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Orthonormal camera frames ``(right, up, ω)``, each ``(B, 3)`` float64 on the views' device.

    ``right = normalize((ω_z, 0, −ω_x))`` (= (cos φ, 0, −sin φ)), falling back to +x at the
    poles (|(ω_x, ω_z)| ≤ 1e-12); ``up = ω × right``. The camera looks along −ω; image
    columns grow along ``right`` and rows grow along ``−up`` (row 0 at the top).
    """
    w = views.detach().to(torch.float64)
    w = w / w.norm(dim=-1, keepdim=True)
    horiz = torch.stack([w[..., 2], torch.zeros_like(w[..., 0]), -w[..., 0]], dim=-1)
    hn = horiz.norm(dim=-1, keepdim=True)
    pole = hn <= POLE_EPS
    x_axis = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64, device=w.device).expand_as(w)
    right = torch.where(pole, x_axis, horiz / torch.where(pole, torch.ones_like(hn), hn))
    up = torch.linalg.cross(w, right, dim=-1)
    up = up / up.norm(dim=-1, keepdim=True)
    return right, up, w


def lens(camera: str = "orthographic", fov: float = 40.0,
         distance: Optional[float] = None) -> Tuple[float, float]:
    """``(t, D)`` of a camera: t = tan(F/2) and the pinhole's distance D (module docstring,
    "Projection"); ``(0, inf)`` for the orthographic camera, whose S(z) ≡ 1 and ℓ ≡ 1.

    ``fov`` F in degrees, 0 < F < 180; ``distance`` D > 1, default 1 / tan(F/2).
    Raises ``ValueError`` naming the setting otherwise.
    """
    if camera not in CAMERAS:
        raise UserError(f"camera: expected one of {list(CAMERAS)}, got {camera!r}")
    if camera == "orthographic":
        return 0.0, math.inf
    if isinstance(fov, bool) or not isinstance(fov, (int, float)) or not 0.0 < fov < 180.0:
        raise UserError(f"fov: expected a field of view in degrees in (0, 180), got {fov!r}")
    t = math.tan(math.radians(fov) / 2.0)
    if distance is None:
        if not 1.0 / t > 1.0:                             # the fov's fault, not a distance anyone gave
            raise UserError(f"fov: {fov!r}° is too wide for the default camera distance 1/tan(fov/2) = "
                            f"{1.0 / t:.3g}, which must be > 1 (outside the cube); use a fov below 90, or "
                            f"give a distance > 1")
        distance = 1.0 / t
    if isinstance(distance, bool) or not isinstance(distance, (int, float)) or not math.isfinite(distance) \
            or not distance > 1.0:
        raise UserError(f"distance: expected a finite camera distance > 1 (outside the cube's depth "
                        f"range), got {distance!r}")
    return t, float(distance)
