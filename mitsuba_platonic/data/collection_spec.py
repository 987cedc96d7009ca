"""What determines a rendered collection: :class:`CollectionSpec`, saved as ``collection.json``.

A spec is the whole plan of a collection: which shapes, how many images of each, the image
formation and its renderer, and the master ``seed`` from which every shape seed, view and light
derives (:meth:`CollectionSpec.shape_seed`, :meth:`~CollectionSpec.view`,
:meth:`~CollectionSpec.lighting_of`), so that an image depends on ``seed`` and its index alone and
a resumed collection renders exactly what an uninterrupted one would. Rendering the plan is
:mod:`.render_collection`'s job, keeping its files :mod:`.collection_files`'.
"""

from __future__ import annotations

import json
from dataclasses import MISSING, asdict, dataclass, fields
from typing import Any, Dict, Optional, Tuple, Union

import numpy as np
import torch

from .. import views as V
from ..errors import UserError
from ..render.mitsuba.physical import sample_lighting
from ..render.settings import FILTERS, FORMATIONS, LIGHTINGS, RenderSettings
from . import shapes
from .envmaps import check_envmap

__all__ = ["CollectionSpec", "RENDERERS", "FORMATIONS"]

#: The renderers of the vh / ao / ea formations (``physical`` always path-traces with Mitsuba).
RENDERERS = ("closed_form", "mitsuba")


@dataclass
class CollectionSpec:
    """Everything that determines a rendered collection (saved as ``collection.json``).

    shape_class: a registered class (:func:`mitsuba_platonic.data.shapes.list_classes`).
    n_shapes, views_per_shape: the collection has n_shapes × views_per_shape images.
    resolution: volume and image resolution N (16 … 128).
    formation: 'vh' | 'ao' | 'ea' | 'physical'.
    renderer: 'closed_form' | 'mitsuba' (vh/ao/ea; physical always path-traces with Mitsuba).
    filter: 'trilinear' | 'nearest' lookups.
    views: 'sphere' (uniform), 'band' (elevation range, degrees), 'ring' (one elevation) or 'sides'
        (photographed mostly from the sides: azimuths within ±side_width of the side views ±90°, which
        see broadside an object whose length lies along z; elevations as the band's;
        :func:`mitsuba_platonic.views.sample_views`).
    elevation: (low, high) for 'band' and 'sides', a number for 'ring', ignored for 'sphere'.
    side_width: W in degrees, 0 < W <= 90, for 'sides' (None: 30); refused for the others.
    lighting: 'sunsky' | 'envmap' | 'mixed' (physical only); envmaps: EXR paths for 'envmap'.
    spp, max_depth: path tracer samples per pixel and path length (physical only).
    camera, fov, distance: the camera of the vh/ao/ea images, as the renderers take it
        (:class:`~mitsuba_platonic.render.RenderSettings`: 'orthographic', the default, or a
        'perspective' pinhole; physical images are orthographic only).
    exposure: 'metered' (k = 1 / the light's mean luminance) | 'auto' (per image, the camera-like
        95th percentile; collections made before metering read as this) (physical only; see
        :mod:`mitsuba_platonic.render.mitsuba.physical`).
    seed: master seed of shapes, views and lighting.
    """

    shape_class: str
    n_shapes: int = 100
    views_per_shape: int = 10
    resolution: int = 64
    formation: str = "ea"
    renderer: str = "closed_form"
    filter: str = "trilinear"
    views: str = "sphere"
    elevation: Union[float, Tuple[float, float], None] = None
    side_width: Optional[float] = None
    lighting: str = "sunsky"
    envmaps: Tuple[str, ...] = ()
    spp: int = 32
    max_depth: int = 8
    camera: str = RenderSettings.camera
    fov: float = RenderSettings.fov
    distance: Optional[float] = RenderSettings.distance
    exposure: str = "metered"
    seed: int = 0

    def validate(self) -> "CollectionSpec":
        """Check every field; raise ``ValueError`` naming the first bad one. Returns self."""
        if self.shape_class not in shapes.list_classes():
            raise UserError(f"shape_class must be one of {shapes.list_classes()}, got {self.shape_class!r}")
        for name in ("n_shapes", "views_per_shape", "spp", "max_depth"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise UserError(f"{name} must be a positive int, got {value!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise UserError(f"seed must be a non-negative int, got {self.seed!r}")
        if not isinstance(self.resolution, int) or not 16 <= self.resolution <= 128:
            raise UserError(f"resolution must be an int in [16, 128], got {self.resolution!r}")
        if self.formation not in FORMATIONS:
            raise UserError(f"formation must be one of {FORMATIONS}, got {self.formation!r}")
        if self.renderer not in RENDERERS:
            raise UserError(f"renderer must be one of {RENDERERS}, got {self.renderer!r}")
        if self.filter not in FILTERS:
            raise UserError(f"filter must be 'trilinear' or 'nearest', got {self.filter!r}")
        if self.views not in V.COLLECTION_DISTRIBUTIONS:
            raise UserError(f"views must be one of {V.COLLECTION_DISTRIBUTIONS}, got {self.views!r}")
        if self.side_width is not None:
            if self.views != "sides":
                raise UserError(f"side_width: only views 'sides' reads it, and views {self.views!r} would "
                                f"ignore it; drop it or use views 'sides'")
            V.check_side_width(self.side_width)
        if self.lighting not in LIGHTINGS:
            raise UserError(f"lighting must be one of {LIGHTINGS}, got {self.lighting!r}")
        if self.exposure not in ("metered", "auto"):
            raise UserError(f"exposure must be 'metered' or 'auto', got {self.exposure!r}")
        V.lens(self.camera, self.fov, self.distance)            # camera, fov and distance
        if self.formation == "physical" and self.camera != "orthographic":
            raise UserError("camera: physical (path-traced) collections are orthographic only")
        if self.formation == "physical" and self.lighting in ("envmap", "mixed") and not self.envmaps:
            if self.lighting == "envmap":
                raise UserError("lighting 'envmap' needs at least one environment map (.exr): pass "
                                "envmaps or drop EXR files into scenes/envmaps/")
        for path in self.envmaps:
            check_envmap(path)
        V.sample_views(1, self.views, seed=0, **self._view_kwargs())  # checks the elevation
        return self

    def _view_kwargs(self) -> Dict[str, Any]:
        out: Dict[str, Any] = {} if self.side_width is None else {"side_width": self.side_width}
        if self.views == "sphere" or self.elevation is None:
            default = V.DEFAULT_ELEVATION.get(self.views)
            return out if default is None else {**out, "elevation": default}
        e = self.elevation
        return {**out, "elevation": tuple(float(x) for x in e) if isinstance(e, (list, tuple)) else float(e)}

    def to_dict(self) -> Dict[str, Any]:
        d = asdict(self)
        d["envmaps"] = list(self.envmaps)
        if isinstance(d["elevation"], tuple):
            d["elevation"] = list(d["elevation"])
        return d

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "CollectionSpec":
        """The spec a ``collection.json`` (or a manifest's ``spec``) records; UserError if ``d``
        is no mapping of collection settings."""
        if not isinstance(d, dict):
            raise UserError(f"expected a JSON object of collection settings, got {json_kind(d)}")
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise UserError(f"unknown collection setting(s) {sorted(unknown)}")
        d = dict(d)
        d.setdefault("exposure", "auto")               # collections made before metering
        d["envmaps"] = tuple(d.get("envmaps", ()))
        if isinstance(d.get("elevation"), list):
            d["elevation"] = tuple(d["elevation"])
        missing = sorted(f.name for f in fields(cls)
                         if f.name not in d and f.default is MISSING and f.default_factory is MISSING)
        if missing:
            raise UserError(f"collection setting(s) {missing} missing")
        return cls(**d)

    # -- the deterministic plan ------------------------------------------------------------

    def shape_seed(self, i: int) -> int:
        """Seed of shape i: a hash of (seed, i), so shapes don't depend on the collection size."""
        return int(np.random.SeedSequence([self.seed, i]).generate_state(1)[0] & 0x7FFFFFFF)

    def view(self, i: int, k: int) -> torch.Tensor:
        """The view ``(3,)`` of image (shape i, view k), from a generator seeded by (seed, i, k)."""
        g = torch.Generator()
        g.manual_seed(int(np.random.SeedSequence([self.seed, i, k, 1]).generate_state(1)[0]))
        return V.sample_views(1, self.views, seed=g, **self._view_kwargs())[0]

    def lighting_of(self, i: int, k: int):
        """The light of image (shape i, view k) in a physical collection, drawn from (seed, i, k)."""
        rng = np.random.default_rng([self.seed, i, k, 2])
        return sample_lighting(rng, self.lighting, self.envmaps)


def json_kind(value: Any) -> str:
    """A JSON value's kind, as a message names it: 'a list', 'the number 5', 'null'."""
    if value is None:
        return "null"
    if isinstance(value, (bool, int, float)):
        return f"the {'boolean' if isinstance(value, bool) else 'number'} {json.dumps(value)}"
    return {dict: "an object", list: "a list", str: "a string"}.get(type(value), type(value).__name__)
