"""Renderer settings: one object for every backend (the dispatcher, ``render_with``, is the package's).

:class:`RenderSettings` is what ``render()`` builds from its keyword options and what a
config's ``render:`` section *is* (``mitsuba_platonic.config.RenderConfig``): backend, image
formation, lookup filter, the ray marcher's speed/accuracy options and the path tracer's.
:func:`~mitsuba_platonic.render.render_with` renders a batch with it. A per-call ``seed`` (jittered sub-samples, random
skies) is an argument of the call, not a setting: training draws a new one every step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple

from ..errors import UserError
from ..views import CAMERAS, lens
from ..volume import MODELS
from .pytorch.closed_form import FILTERS as GRID_SAMPLE_MODES

__all__ = ["RenderSettings", "BACKENDS", "LIT", "SINGLE_SCATTERING", "MODELS", "FILTERS", "LIGHTINGS", "FORMATIONS", "CAMERAS", "OPTIONS_OF"]

#: Backends: the paper's closed-form layers (reference), the batched Dr.Jit ray marcher,
#: Mitsuba's differentiable volumetric path tracer under natural light, and single scattering of
#: a sun and a sky: in torch (:mod:`.single_scatter`, the reference) and in Dr.Jit (:mod:`.scatter_march`).
BACKENDS = ("closed_form", "mitsuba", "physical", "single_scatter", "scatter_march")
#: The backends that light what they render (colour only, the orthographic camera).
LIT = ("physical", "single_scatter", "scatter_march")
#: The lit backends whose light is a sun and a sky (:class:`~.single_scatter.LightBatch`).
SINGLE_SCATTERING = ("single_scatter", "scatter_march")
FILTERS = tuple(GRID_SAMPLE_MODES)                          # trilinear, nearest
LIGHTINGS = ("sunsky", "envmap", "mixed")
#: How a collection's images are formed: the renderer's image formations, or path-traced (make-dataset).
FORMATIONS = MODELS + ("physical",)

#: Which settings each backend reads (besides backend and model); any other is an error in ``render``.
OPTIONS_OF: Dict[str, tuple] = {
    "closed_form": ("filter", "camera", "fov", "distance"),
    "mitsuba": ("filter", "camera", "fov", "distance", "step", "spp", "jitter", "termination"),
    "physical": ("filter", "lighting", "physical_spp", "max_depth"),
    "single_scatter": ("spp", "steps_per_voxel", "shadow_planes"),
    "scatter_march": ("spp", "steps_per_voxel"),
}


@dataclass(frozen=True)
class RenderSettings:
    """How volumes become images.

    backend: 'closed_form' (the paper's reference) | 'mitsuba' (the batched ray marcher: the shipped configs',
        the same images to float precision, faster) | 'physical' (path tracer under natural light; a GPU run) |
        'single_scatter' (single scattering of a random sun and sky per image; EA-style RGBA) |
        'scatter_march' (the same light in one Dr.Jit launch per pass; docs/rendering.md).
    model: image formation, 'vh' | 'ao' | 'ea' (the physical backend renders EA-style RGBA).
    filter: 'trilinear' | 'nearest' grid lookups (every backend).
    camera: 'orthographic' (the paper's) | 'perspective' (a pinhole; closed form and marcher).
    fov, distance: the pinhole's full field of view in degrees and its distance from the centre
        (None: 1 / tan(fov/2), where the centre plane fills the image; :func:`~mitsuba_platonic.views.lens`).
    step: the marcher's segment length in voxels (> 0; 1 reproduces the closed form's planes).
    spp: the marcher's (and single scattering's) rays per pixel (a perfect square unless ``jitter``).
    jitter: random sub-pixel positions and depth within each segment (marcher).
    termination: the marcher stops a ray once its transmittance is ≤ this (0 = exact).
    lighting: the path tracer's light, 'sunsky' (differentiable) | 'envmap' | 'mixed'.
    physical_spp, max_depth: the path tracer's samples per pixel and path depth.
    steps_per_voxel, shadow_planes: single scattering's samples per voxel along a camera ray (both
        single-scattering backends; ≥ 2 for 'scatter_march') and the torch formation's shadow ray
        for the sun, in planes (docs/rendering.md, "Single scattering").

    ``docs/speed_accuracy.md`` says what each option costs and buys.
    """

    backend: str = "closed_form"
    model: str = "ea"
    filter: str = "trilinear"
    camera: str = "orthographic"
    fov: float = 40.0
    distance: Optional[float] = None
    step: float = 1.0
    spp: int = 1
    jitter: bool = False
    termination: float = 0.0
    lighting: str = "sunsky"
    physical_spp: int = 4
    max_depth: int = 4
    steps_per_voxel: int = 4
    shadow_planes: int = 2

    def validate(self) -> "RenderSettings":
        """Return self, or raise ``ValueError('<field>: what was expected, got …')``."""
        _choice("backend", self.backend, BACKENDS)
        _choice("model", self.model, MODELS)
        _choice("filter", self.filter, FILTERS)
        _choice("lighting", self.lighting, LIGHTINGS)
        _choice("camera", self.camera, CAMERAS)
        lens(self.camera, self.fov, self.distance)          # fov and distance (perspective)
        if isinstance(self.step, bool) or not isinstance(self.step, (int, float)) \
                or not math.isfinite(self.step) or not self.step >= 1.0 / 64:
            raise ValueError(f"step: expected a finite number of voxels ≥ 1/64, got {self.step!r}")
        for name in ("spp", "physical_spp", "max_depth", "steps_per_voxel"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive int, got {value!r}")
        if isinstance(self.shadow_planes, bool) or not isinstance(self.shadow_planes, int) or self.shadow_planes < 0:
            raise ValueError(f"shadow_planes: expected an int ≥ 0, got {self.shadow_planes!r}")
        if not isinstance(self.jitter, bool):
            raise ValueError(f"jitter: expected true or false, got {self.jitter!r}")
        if not self.jitter and math.isqrt(self.spp) ** 2 != self.spp:
            raise ValueError(f"spp: without jitter, spp must be a perfect square (a regular sub-pixel grid), "
                             f"got {self.spp}")
        if isinstance(self.termination, bool) or not isinstance(self.termination, (int, float)) \
                or not 0.0 <= self.termination < 1.0:
            raise ValueError(f"termination: expected a number in [0, 1), got {self.termination!r}")
        if self.backend in LIT and self.model != "ea":
            raise ValueError(f"model: the {self.backend} backend renders colour; use 'ea' images")
        if self.backend in LIT and self.camera != "orthographic":
            raise ValueError(f"camera: the {self.backend} backend renders with the orthographic camera only")
        if self.backend in ("single_scatter", "scatter_march") and (self.filter != "trilinear" or self.jitter):
            raise ValueError(f"filter, jitter: the {self.backend} backend reads trilinearly on a regular sub-pixel grid")
        if self.backend == "scatter_march" and self.steps_per_voxel < 2:
            raise ValueError(f"steps_per_voxel: the scatter_march backend needs ≥ 2 (one sample per voxel lands on "
                             f"voxel centres and never sees a surface's ramp), got {self.steps_per_voxel}")
        if self.backend == "physical" and self.lighting != "sunsky":
            raise ValueError(f"lighting: the physical backend renders differentiably under 'sunsky' only, got "
                             f"{self.lighting!r} (environment maps light path-traced collections: make-dataset "
                             f"--formation physical --lighting {self.lighting})")
        return self

    @property
    def lens(self) -> Tuple[float, float]:
        """``(tan(fov/2), distance)``; ``(0, inf)`` for the orthographic camera."""
        return lens(self.camera, self.fov, self.distance)

    @classmethod
    def for_call(cls, backend: str, model: str, **options: Any) -> "RenderSettings":
        """Settings from ``render()``'s arguments; an option the backend does not read is an error."""
        _choice("backend", backend, BACKENDS)
        allowed = OPTIONS_OF[backend]
        unknown = sorted(set(options) - set(allowed))
        if unknown:
            raise ValueError(f"unknown option(s) {unknown} for backend {backend!r}; expected some of {sorted(allowed)}")
        return cls(backend=backend, model=model, **options).validate()


#: The most lanes (rays) one Dr.Jit launch holds: its indices are 32-bit.
MAX_LANES = 2 ** 32 - 1


def check_lanes(batch: int, n: int, spp: int) -> None:
    """Refuse a marcher call of more rays (``batch · n² · spp``) than one Dr.Jit launch holds
    (:data:`MAX_LANES`), naming ``spp`` and the largest that fits, before any work."""
    lanes = batch * n * n * spp
    if lanes > MAX_LANES:
        fits = MAX_LANES // (batch * n * n)
        raise UserError(f"spp: {spp} samples per pixel × {n}² pixels × {batch} view(s) = {lanes:,} rays, more than "
                        f"the 2³² lanes one Dr.Jit launch holds; use spp ≤ {fits:,} here, or fewer views per call")


def _choice(name: str, value: Any, choices: tuple) -> None:
    if value not in choices:
        raise ValueError(f"{name}: expected one of {list(choices)}, got {value!r}")
