"""The Mitsuba renderer: torch volumes → Mitsuba medium grids → ray-marched images → torch.

Per (volume, view) pair the volume's grids are written into a cached Mitsuba scene
(a ``heterogeneous`` medium and an ``orthographic`` sensor at the view, loaded from the scene
files ``scenes/raymarch.xml`` / ``scenes/raymarch_ea.xml``) and rendered with
:class:`~mitsuba_platonic.render.mitsuba.integrator.RayMarcher`. ``drjit.wrap`` turns each render into
a PyTorch autograd function, so gradients flow back to the torch volume.

Grid layout (docs/rendering.md, "The Mitsuba side"). A torch ``(C, D, H, W)`` volume becomes a Mitsuba ``[Z, Y, X, C]``
grid by a permute and two flips (Z = N−1−d, Y = N−1−h, X = w) that maps onto [−1, 1]³
(``to_world`` = translate(−1)·scale(2)). Outside the cube the closed form sees zeros
(``grid_sample`` zero padding); the ray marcher reproduces that by weighting each lookup with
the zero-padding ramp (see :mod:`.integrator`) instead of padding the data, which keeps the grid
a power of two wide: for N = 2^k, texture coordinates of dyadic points are exact in float32.
Together with a dyadic near-clip distance (2⁻⁷, in the scene file) this makes the front view's samples land exactly on
voxel centres, so the front view agrees with the closed form to accumulation round-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple

import torch

from ...views import camera_frames
from ...volume import CHANNELS, voxel_size
from ..grids import to_mitsuba_grid
from .scenes import load_scene
from ..settings import RenderSettings
from ..variant import ensure_variant, variant_device

__all__ = ["to_mitsuba_grid", "render_mitsuba", "build_scene", "sensor_dict", "sensor_transform", "differentiable_render"]


@dataclass
class _Bundle:
    scene: Any
    params: Any
    keys: Tuple[str, ...]


_SCENES: Dict[Tuple, _Bundle] = {}


def sensor_dict(mi: Any, n: int, spp: int, origin: Any, up: Any, film: Optional[Dict[str, Any]] = None,
                **extra: Any) -> Dict[str, Any]:
    """An orthographic sensor at ``origin`` looking at the origin with image up ``up``: an N×N RGB
    film covering [−1, 1]², a box filter, ``spp`` independent samples (``film``/``extra``: more keys).

    For scenes built in code around other shapes (the evaluation's meshes); the volume scenes'
    sensors are described in ``scenes/*.xml``."""
    return {"type": "orthographic",
            "to_world": mi.ScalarTransform4f().look_at(origin=[float(x) for x in origin], target=[0.0, 0.0, 0.0],
                                                       up=[float(x) for x in up]),
            "film": {"type": "hdrfilm", "width": n, "height": n, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}, **(film or {})},
            "sampler": {"type": "independent", "sample_count": int(spp)}, **extra}


def build_scene(n: int, model: str, options: RenderSettings) -> Any:
    """The Mitsuba scene for an N³ volume under ``model``, loaded from ``scenes/raymarch.xml``
    (VH, AO) or ``scenes/raymarch_ea.xml`` (EA) with empty grids of the right size."""
    mi = ensure_variant()
    import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)

    grids = {"density": dr.zeros(mi.TensorXf, (n, n, n, 1))}
    if model == "ea":                                         # VH and AO carry no colour grid
        grids["albedo"] = dr.zeros(mi.TensorXf, (n, n, n, 3))
    params = dict(resolution=n, scale=1.0 / voxel_size(n), spp=options.spp, step=float(options.step),
                  jitter=bool(options.jitter), termination=float(options.termination), filter=options.filter)
    if model == "ea":
        return load_scene("raymarch_ea", grids=grids, **params)
    return load_scene("raymarch", grids=grids, model=model, **params)


def _bundle(n: int, model: str, options: RenderSettings) -> _Bundle:
    key = (n, model, options.step, options.spp, options.jitter, options.filter, options.termination)
    if key not in _SCENES:
        mi = ensure_variant()
        scene = build_scene(n, model, options)
        params = mi.traverse(scene)
        keys = ("medium.sigma_t.data",) + (("medium.albedo.data",) if model == "ea" else ())
        _SCENES[key] = _Bundle(scene, params, keys)
    return _SCENES[key]


class _Binding:
    """One render's grids (still attached to the AD graph) and other scene settings.

    A plain object, so ``dr.custom`` passes it through without detaching its arrays.
    """

    def __init__(self, scene: Any, params: Any, grids: Dict[str, Any], settings: Dict[str, Any]):
        self.scene, self.params, self.grids, self.settings = scene, params, grids, settings

    def bind(self) -> None:
        """Write this render's grids and settings (view, lighting) into the shared cached scene."""
        for key, value in list(self.grids.items()) + list(self.settings.items()):
            self.params[key] = value
        self.params.update()


def _pair_render_op():
    """The custom op class, defined once Mitsuba's variant (and so Dr.Jit) is loaded."""
    global _PairRender
    if _PairRender is None:
        import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)

        class PairRender(dr.CustomOp):
            """``mi.render`` for one (volume, view) pair of a batch.

            Like Mitsuba's own render op, but the backward pass first re-binds *its* pair's
            grids and view: the scene is shared by the whole batch, so by the time torch asks
            for gradients it holds the last pair rendered, not this one.
            """

            def eval(self, _grids, binding, spp, seed):
                self.binding, self.spp, self.seed = binding, spp, seed
                binding.bind()
                scene = binding.scene
                with dr.suspend_grad():
                    return scene.integrator().render(scene, sensor=0, seed=seed, spp=spp,
                                                     develop=True, evaluate=False)

            def backward(self):
                self.binding.bind()
                scene = self.binding.scene
                scene.integrator().render_backward(scene, self.binding.params, self.grad_out(),
                                                   sensor=0, seed=self.seed + 1, spp=self.spp)

            def name(self):
                return "PlatonicPairRender"

        _PairRender = PairRender
    return _PairRender


_PairRender = None


def differentiable_render(scene: Any, params: Any, grids: Dict[str, torch.Tensor], settings: Dict[str, Any],
                          spp: int, seed: int) -> torch.Tensor:
    """Render ``scene`` with ``grids`` (torch tensors) and ``settings`` bound; differentiable in torch.

    ``drjit.wrap`` turns the render into a torch autograd function whose backward runs the
    integrator's ``render_backward`` (with ``seed + 1``) after re-binding this render's inputs.
    Returns the ``(H, W, C)`` image as a torch tensor.
    """
    import drjit as dr  # lazy: Dr.Jit only after the backend check (ensure_variant)
    keys = list(grids)

    @dr.wrap(source="torch", target="drjit")
    def render_one(*arrays):
        binding = _Binding(scene, params, dict(zip(keys, arrays)), settings)
        return dr.custom(_pair_render_op(), dict(binding.grids), binding, spp, seed)

    return _OnceOnly.apply(render_one(*grids.values()))


class _OnceOnly(torch.autograd.Function):
    """Identity whose backward may run once: ``drjit.wrap``'s render releases its Dr.Jit AD graph in
    the first backward, so a second one (``retain_graph``) would silently return the first
    gradient again. It raises instead."""

    @staticmethod
    def forward(ctx, image: torch.Tensor) -> torch.Tensor:
        ctx.done = False
        return image.view_as(image)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        if ctx.done:
            raise RuntimeError("a render of the Mitsuba scene path (render_mitsuba, the path tracer) can be "
                               "differentiated once: its first backward releases Dr.Jit's graph, so a second "
                               "one would repeat the first gradient; render again for another gradient, or "
                               "use backend 'mitsuba' (the batched marcher), which supports retain_graph")
        ctx.done = True
        return grad


def sensor_transform(mi: Any, right: torch.Tensor, up: torch.Tensor, w: torch.Tensor) -> Any:
    """The sensor's ``to_world`` of one view (its frame ``right``, ``up``, ``w`` = ω from
    :func:`~mitsuba_platonic.views.camera_frames`; ``mi`` the Mitsuba module): an orthographic camera
    at 2ω looking at the origin, image up = ``up``; its film covers [−1, 1]². ``right`` is implied."""
    origin = [2.0 * float(x) for x in w]
    return mi.ScalarTransform4f().look_at(origin=origin, target=[0.0, 0.0, 0.0], up=[float(x) for x in up])


def render_mitsuba(volume: torch.Tensor, views: torch.Tensor, model: str,
                   options: Optional[RenderSettings] = None, seed: int = 0) -> torch.Tensor:
    """Render ``(B, C, N, N, N)`` volumes from ``(B, 3)`` views with the Mitsuba ray marcher.

    Returns ``(B, 1, N, N)`` (VH, AO) or ``(B, 4, N, N)`` (EA), differentiable w.r.t. ``volume``.
    Inputs are assumed valid (see :func:`mitsuba_platonic.render`).
    """
    options = (options or RenderSettings(backend="mitsuba", model=model)).validate()
    mi = ensure_variant()
    n = volume.shape[-1]
    bundle = _bundle(n, model, options)
    device = variant_device()
    src = volume.to(device=device, dtype=torch.float32)
    right, up, w = camera_frames(views)
    out_channels = CHANNELS[model]

    images = []
    for b in range(volume.shape[0]):
        v = src[b]
        grids = (to_mitsuba_grid(v[-1:]),) if model != "ea" else (to_mitsuba_grid(v[3:4]), to_mitsuba_grid(v[:3]))
        settings = {"sensor.to_world": sensor_transform(mi, right[b], up[b], w[b])}
        image = differentiable_render(bundle.scene, bundle.params, dict(zip(bundle.keys, grids)), settings,
                                      options.spp, seed + 2 * b)     # (H, W, 3 or 4)
        images.append(image[..., :out_channels].permute(2, 0, 1))
    return torch.stack(images).to(volume.device)
