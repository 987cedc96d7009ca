"""Single scattering at the marcher's speed (render/drjit/scatter_march.py), checked against independent
computations: its Dr.Jit camera pass against the per-sample torch reference (tests/scatter_reference.py,
images and gradients), that reference against finite differences, its axis sweeps against
single_scatter.sweep, the Lommel–Seeliger law of an opaque half-space under a sun and the closed
form under a uniform sky, and Mitsuba's volpath at max_depth 2."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.render import render
from mitsuba_platonic.render.drjit.scatter_march import _ScatterMarch, light_packet, local_depth, render_scatter_march
from mitsuba_platonic.render.mitsuba.single_scatter_reference import reference_render
from mitsuba_platonic.render.pytorch.single_scatter import LightBatch, SunAndSky, sample_lights, sample_sun_and_sky
from mitsuba_platonic.render.drjit.sky_light import sky_occlusion
from mitsuba_platonic.render.variant import variant_device
from scatter_reference import reference_light_packet, reference_scatter_march, reference_sky_occlusion
from test_single_scatter import FRONT, SKY, SUN_ABOVE, _coords, _scene, _sun


def _random_case(n=8, b=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    volume = torch.rand(b, 4, n, n, n, generator=g)
    volume[0, 3] = (volume[0, 3] > 0.6).float() * 0.999             # opaque voxels beside empty ones
    volume[1:2, 3] *= 0.7
    volume[2:3, 3] = (volume[2:3, 3] > 0.5).float()                  # exact 1s and 0s
    lights = LightBatch.of([sample_sun_and_sky(np.random.default_rng([seed, i])) for i in range(b)])
    views = torch.nn.functional.normalize(torch.randn(b, 3, generator=g, dtype=torch.float64), dim=-1)
    light = torch.cat([lights.direction, lights.irradiance / (4 * math.pi), lights.sky], dim=1)
    return volume, lights, views, light


@pytest.mark.parametrize("m, spp, reach", [(2, 1, 2.0), (3, 4, 2.0), (2, 1, 1.0)])
def test_the_camera_pass_matches_the_per_sample_reference_in_image_and_gradient(m, spp, reach):
    volume, lights, views, light = _random_case()
    packet = light_packet(volume, lights, reach).detach()
    ours_in = packet.to(variant_device(), copy=True).requires_grad_()   # the kernel's device (a GPU's, too)
    ours = _ScatterMarch.apply(ours_in, views, light, m, spp, reach)
    ref_in = packet.double().requires_grad_()
    ref = reference_scatter_march(ref_in, views, light, m, spp, reach)
    assert torch.allclose(ours.double().cpu(), ref, atol=2e-6), float((ours.double().cpu() - ref).abs().max())
    weights = torch.randn(ref.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    (ours * weights.float().to(ours.device)).sum().backward()
    (ref * weights).sum().backward()
    for c in range(7):                                                # the unused eighth channel has none
        scale = float(ref_in.grad[..., c].abs().max())
        assert scale > 0
        assert float((ours_in.grad[..., c].double().cpu() - ref_in.grad[..., c]).abs().max()) < 2e-5 * scale, c


def test_the_reference_camera_pass_matches_finite_differences():
    volume, lights, views, light = _random_case(n=4, b=2, seed=3)
    # σ > 0 everywhere: at σ = 0 a central difference steps outside the domain σ ≥ 0 (the exact 0s
    # are the test above's, against the reference at the same inputs)
    packet = light_packet(volume.double() * 0.8 + 0.1, lights).detach()
    assert torch.autograd.gradcheck(lambda p: reference_scatter_march(p, views, light, 2, 1, 2.0),
                                    (packet.requires_grad_(),), eps=1e-6, atol=1e-5, rtol=1e-3)


def test_the_light_packet_matches_its_torch_reference_in_value_and_gradient():
    """The packet's Dr.Jit assembly (the sun's volumes read ℓ ahead by 8 shared weights, its adjoint
    by gathers) against tests/scatter_reference.py (grid_sample, torch's cat), float32: values on a
    random case with exact 0s and 1s and opaque voxels, gradients on the same case lifted off zero
    (at σ = 0 beside a dense neighbour the sky's local depth has a kink in ∇σ·ω_k, where float32
    and float64 round b ≈ 0 to different sides); the reference against finite differences (float64).
    The sky's O is checked against its own reference below."""
    volume, lights, _, _ = _random_case(n=6, b=3, seed=5)
    for reach in (2.0, 1.3):
        for case in (volume, volume * 0.8 + 0.1):
            ours_in, ref_in = case.clone().requires_grad_(), case.double().requires_grad_()
            ours, ref = light_packet(ours_in, lights, reach), reference_light_packet(ref_in, lights, reach)
            assert torch.allclose(ours.double(), ref, rtol=1e-5, atol=1e-5), float((ours.double() - ref).abs().max())
            if case is volume:
                continue
            w = torch.randn(ref.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
            (ours * w.float()).sum().backward()
            (ref * w).sum().backward()
            scale = float(ref_in.grad.abs().max())
            assert torch.allclose(ours_in.grad.double(), ref_in.grad, rtol=1e-4, atol=1e-5 * scale), \
                float((ours_in.grad.double() - ref_in.grad).abs().max()) / scale
    small, lights1, _, _ = _random_case(n=4, b=1, seed=5)
    small = (small.double() * 0.8 + 0.1).requires_grad_()
    assert torch.autograd.gradcheck(lambda v: reference_light_packet(v, lights1, 2.0)[..., :6], (small,), eps=1e-6,
                                    atol=1e-5, rtol=1e-3)
    σ = (torch.rand(1, 1, 4, 4, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(6)) * 20 + 1)
    assert torch.autograd.gradcheck(lambda x: reference_sky_occlusion(x, 2.0), (σ.requires_grad_(),), eps=1e-6,
                                    atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("reach", [2.0, 1.0])
def test_the_sky_occlusion_matches_its_torch_reference_in_value_and_gradient(reach):
    """Dr.Jit's line sweeps and per-voxel ratio against tests/scatter_reference.py (the sweeps of
    single_scatter.sweep, plane by plane), on a soft volume with an opaque block and exact zeros."""
    g = torch.Generator().manual_seed(0)
    σ = torch.rand(2, 1, 7, 7, 7, generator=g, dtype=torch.float64) * 20
    σ[0, 0, 2:5, 2:5, 2:5] = 60.0
    σ[1, 0, :, :3] = 0.0
    ours_in, ref_in = σ.float().requires_grad_(), σ.clone().requires_grad_()
    ours, ref = sky_occlusion(ours_in, reach), reference_sky_occlusion(ref_in, reach)
    assert torch.allclose(ours.double(), ref, atol=1e-5), float((ours.double() - ref).abs().max())
    weights = torch.randn(ref.shape, generator=g, dtype=torch.float64)
    (ours * weights.float()).sum().backward()
    (ref * weights).sum().backward()
    assert torch.allclose(ours_in.grad.double(), ref_in.grad, atol=1e-5 * float(ref_in.grad.abs().max()))


def test_steady_state_replays_the_frozen_launches_without_retracing(monkeypatch):
    """A second call with new volumes, views and lights (same batch, resolution and settings)
    replays every frozen launch (camera pass, packet and sky, both ways): no new recording, and the same
    images and gradients as freshly traced launches."""
    import importlib
    SM = importlib.import_module("mitsuba_platonic.render.drjit.scatter_march")
    SL = importlib.import_module("mitsuba_platonic.render.drjit.sky_light")
    if not SM.FREEZE:
        pytest.skip("MITSUBA_PLATONIC_FREEZE=0")
    frozen = [SM._frozen_camera_forward, SM._frozen_camera_backward, SM._frozen_assemble,
              SM._frozen_assemble_backward, *SL._FROZEN.values()]
    first, lights_a, views_a, _ = _random_case(n=8, b=2, seed=11)
    x = first.clone().requires_grad_()
    render_scatter_march(x, views_a, lights_a, steps_per_voxel=3, spp=4).sum().backward()
    counts = [f.n_recordings for f in frozen]
    second, lights_b, views_b, _ = _random_case(n=8, b=2, seed=12)
    w = torch.rand(2, 4, 8, 8, generator=torch.Generator().manual_seed(3))
    y = second.clone().requires_grad_()
    replayed = render_scatter_march(y, views_b, lights_b, steps_per_voxel=3, spp=4)
    (replayed * w).sum().backward()
    assert [f.n_recordings for f in frozen] == counts
    monkeypatch.setattr(SM, "FREEZE", False)
    monkeypatch.setattr(SL, "FREEZE", False)
    z = second.clone().requires_grad_()
    traced = render_scatter_march(z, views_b, lights_b, steps_per_voxel=3, spp=4)
    (traced * w).sum().backward()
    assert torch.equal(replayed, traced)
    assert not torch.allclose(replayed, render_scatter_march(first, views_a, lights_a, steps_per_voxel=3, spp=4))
    # the same kernels, up to the order of the camera pass's per-thread partial sums
    assert torch.allclose(y.grad, z.grad, rtol=1e-5, atol=1e-6 * float(z.grad.abs().max()))


def test_the_local_depth_is_the_integral_of_the_clamped_linear_field():
    σ = torch.tensor([0.0, 2.0, 2.0, 2.0, 3.0], dtype=torch.float64)
    b = torch.tensor([1.0, 0.0, -1.0, -4.0, 0.5], dtype=torch.float64)
    s = torch.linspace(0.0, 1.5, 300_001, dtype=torch.float64)
    numeric = ((σ[:, None] + b[:, None] * s).clamp_min(0.0).sum(1) - 0.5 * (σ + b * 1.5).clamp_min(0) - 0.5 * σ) * (
        s[1] - s[0])
    assert torch.allclose(local_depth(σ, b, 1.5), numeric, atol=1e-8)


def _half_space():
    x, y, z = _coords()
    v = (0.999 * ((y < 0.0) & (x.abs() < 0.9) & (z.abs() < 0.9))).float()
    return torch.stack([torch.ones_like(v)] * 3 + [v])[None], torch.tensor([[0.0, 1.0, 0.0]])


@pytest.mark.parametrize("sun_angle, tolerance", [(0.0, 0.01), (45.0, 0.02), (70.0, 0.05)])
def test_an_opaque_half_space_reflects_by_the_lommel_seeliger_law(sun_angle, tolerance):
    volume, view = _half_space()
    a = math.radians(sun_angle)
    image = render_scatter_march(volume, view, [_sun((math.sin(a), math.cos(a), 0.0))], exposure="none",
                                 steps_per_voxel=4)
    expected = math.cos(a) / (math.cos(a) + 1.0)
    assert abs(float(image[0, 0, 5:11, 5:11].mean()) - expected) < tolerance * expected


def test_an_opaque_half_space_under_a_uniform_sky_gets_the_closed_form():
    """L = L_sky/2 ∫_0^1 μ/(μ + μ_v) dμ = L_sky (1 − ln 2)/2 from above (μ_v = 1)."""
    volume, view = _half_space()
    image = render_scatter_march(volume, view, [SunAndSky((0.0, 1.0, 0.0), (0.0,) * 3, (1.0,) * 3)],
                                 exposure="none", steps_per_voxel=4)
    expected = 0.5 * (1.0 - math.log(2.0))
    assert abs(float(image[0, 0, 5:11, 5:11].mean()) - expected) < 0.03 * expected


@pytest.mark.parametrize("light, rel_tol", [(SUN_ABOVE, 0.05), (SKY, 0.03)], ids=["sun above", "sky"])
def test_images_agree_with_volpath_single_scattering_in_total(light, rel_tol):
    """The soft blob beside the dense box from the front, 4 rays per pixel, against 4 volpath renders
    at max_depth 2 (512 spp each): the image total within ``rel_tol`` (measured +3.4 % and +1.1 %,
    docs/rendering.md)."""
    volume, views = _scene(), torch.tensor([FRONT])
    ours = render_scatter_march(volume, views, [light], exposure="none", spp=4)[0, :3]
    ref = torch.stack([reference_render(volume, views, [light], spp=512, seed=s, exposure="none")[0, :3]
                       for s in range(4)]).mean(0)
    assert abs(float((ours.sum() - ref.sum()) / ref.sum())) < rel_tol


def test_an_empty_volume_is_black_with_finite_gradients():
    volume = torch.zeros(2, 4, 8, 8, 8, requires_grad=True)
    lights = [sample_sun_and_sky(np.random.default_rng(s)) for s in range(2)]
    image = render_scatter_march(volume, torch.tensor([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]), lights)
    assert torch.equal(image, torch.zeros_like(image))
    image.sum().backward()
    assert torch.isfinite(volume.grad).all() and volume.grad[:, 3].abs().sum() > 0


@pytest.mark.parametrize("sun", [(1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, -1.0, 0.0)],
                         ids=["horizon", "behind the camera", "below"])
def test_opaque_voxels_and_extreme_suns_give_finite_images_and_gradients(sun):
    x, y, z = _coords()
    v = ((x.abs() < 0.5) & (y.abs() < 0.5) & (z.abs() < 0.5)).float()
    volume = torch.stack([0.5 * torch.ones_like(v), torch.ones_like(v), v, v])[None].requires_grad_()
    image = render_scatter_march(volume, torch.tensor([[0.0, 0.0, 1.0]]), [_sun(sun, sky=0.1)])
    assert torch.isfinite(image).all() and float(image[0, 3].detach().max()) > 0.999
    image[0, :3].sum().backward()
    assert torch.isfinite(volume.grad).all() and float(volume.grad[0, :3].abs().sum()) > 0


@pytest.mark.parametrize("kwargs, message", [({"steps_per_voxel": 1}, "steps_per_voxel"), ({"spp": 2}, "square"),
                                             ({"reach": 8.0}, "reach"), ({"exposure": "auto"}, "exposure")])
def test_bad_settings_are_user_errors_naming_them(kwargs, message):
    with pytest.raises(UserError, match=message):
        render_scatter_march(torch.zeros(1, 4, 4, 4, 4), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()], **kwargs)


def test_the_scatter_march_backend_draws_its_lights_from_the_seed():
    volume = _scene().repeat(2, 1, 1, 1, 1)
    views = torch.tensor([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    image = render(volume, views, "ea", "scatter_march", seed=7, steps_per_voxel=2)
    assert torch.equal(image, render_scatter_march(volume, views, sample_lights(2, 7), steps_per_voxel=2))
    assert not torch.equal(image, render(volume, views, "ea", "scatter_march", seed=8, steps_per_voxel=2))


@pytest.mark.parametrize("options, message", [({"model": "vh"}, "renders colour"), ({"steps_per_voxel": 1}, "≥ 2"),
                                              ({"shadow_planes": 1}, "unknown option")])
def test_the_scatter_march_backend_refuses_what_it_does_not_render(options, message):
    model = options.pop("model", "ea")
    volume = torch.zeros(1, 1 if model == "vh" else 4, 4, 4, 4)
    with pytest.raises(UserError, match=message):
        render(volume, torch.tensor([[0.0, 0.0, 1.0]]), model, "scatter_march", **options)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_generator_like_volumes_with_denormal_densities_give_finite_gradients(seed):
    """A sigmoid of wide noise, as a generator's last layer makes: exact 0s and 1s and densities down
    to the float32 denormals, where σ² and b² underflow (once 0/0 in the adjoint's local light)."""
    g = torch.Generator().manual_seed(seed)
    volume = torch.sigmoid(torch.randn(4, 4, 16, 16, 16, generator=g) * 60 - 2).requires_grad_()
    views = torch.nn.functional.normalize(torch.randn(4, 3, generator=g), dim=-1)
    image = render(volume, views, "ea", "scatter_march", seed=seed, steps_per_voxel=2)
    (image * torch.randn(image.shape, generator=g)).sum().backward()
    assert torch.isfinite(image).all() and torch.isfinite(volume.grad).all()
