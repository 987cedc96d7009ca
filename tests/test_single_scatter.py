"""Single scattering of a sun and a sky (render/pytorch/single_scatter.py), checked against independent
computations: the trapezoid sums of its sweeps by hand, the closed form of a constant medium and of
a linear ramp, the Lommel–Seeliger law of an opaque half-space, Mitsuba's volpath at max_depth 2
(sun and sky separately, per pixel block within its Monte Carlo error), finite differences."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.render.grids import extinction
from mitsuba_platonic.render import render
from mitsuba_platonic.render.mitsuba.single_scatter_reference import reference_render
from mitsuba_platonic.render.pytorch.single_scatter import (SKY_DIRECTIONS, SKY_WEIGHTS, LightBatch, SunAndSky,
                                                            render_single_scatter, sample_lights, sample_sun_and_sky,
                                                            sweep, transmittance)
from mitsuba_platonic.volume import voxel_size

N = 16


def _coords(n=N):
    """World x, y, z of the voxel centres, indexed [d, h, w] (d along −z, h along −y, w along +x)."""
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * voxel_size(n)
    z, y, x = torch.meshgrid(-c, -c, c, indexing="ij")
    return x, y, z


def _unit(*v):
    v = np.asarray(v, dtype=np.float64)
    return tuple(float(x) for x in v / np.linalg.norm(v))


def _sun(direction, sky=0.0, sun=4.0 * math.pi):
    """A sun of p E_s = 1 (E_s = 4π) and a grey sky."""
    return SunAndSky(direction, (sun,) * 3, (sky,) * 3)


# --------------------------------------------------------------------------- the sky's quadrature


def test_sky_weights_are_the_solid_angles_nearest_each_direction():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2_000_000, 3))                      # uniform directions
    nearest = (d @ np.array(SKY_DIRECTIONS).T).argmax(-1)
    share = np.bincount(nearest, minlength=14) / len(d)
    assert abs(share[:6].mean() - SKY_WEIGHTS[0]) < 3e-4     # standard error ≈ 7e-5
    assert abs(share[6:].mean() - SKY_WEIGHTS[6]) < 3e-4
    assert abs(sum(SKY_WEIGHTS) - 1.0) < 1e-12
    assert all(w == SKY_WEIGHTS[0] for w in SKY_WEIGHTS[:6]) and all(w == SKY_WEIGHTS[6] for w in SKY_WEIGHTS[6:])
    assert len(SKY_DIRECTIONS) == 14 and np.allclose(np.linalg.norm(SKY_DIRECTIONS, axis=1), 1.0)


# --------------------------------------------------------------------------- the sweep


@pytest.mark.parametrize("direction, dim, light_at_high_index", [((0.0, 1.0, 0.0), 3, False),
                                                                  ((-1.0, 0.0, 0.0), 4, False),
                                                                  ((0.0, 0.0, -1.0), 2, True)])
def test_a_sweep_along_an_axis_is_the_trapezoid_sum_over_the_voxels(direction, dim, light_at_high_index):
    torch.manual_seed(0)
    σ = extinction(torch.rand(1, 1, N, N, N, dtype=torch.float64))
    T = 1.0 - sweep(σ, torch.tensor([direction])).opacity
    s = σ.flip(dim) if light_at_high_index else σ           # index 0 nearest the light
    τ = voxel_size(N) * (torch.cumsum(s, dim) - 0.5 * s)     # Σ_{j<i} σ_j + σ_i / 2
    expected = torch.exp(-τ)
    expected = expected.flip(dim) if light_at_high_index else expected
    assert torch.allclose(T, expected, rtol=1e-12, atol=1e-14)


def test_a_slanted_sweep_through_a_constant_medium_gives_its_path_length():
    direction = _unit(0.3, 0.9, -0.2)                         # dominant +y: planes are rows from the top
    σ0 = 3.0
    σ = torch.full((1, 1, N, N, N), σ0, dtype=torch.float64)
    T = 1.0 - sweep(σ, torch.tensor([direction])).opacity[0, 0]
    ℓ = voxel_size(N) / direction[1]
    h = torch.arange(N, dtype=torch.float64)[None, :, None]  # planes above a voxel: its row h
    expected = torch.exp(-σ0 * ℓ * (h + 0.5)).expand(N, N, N)
    # voxels that read no zero padding: repeated bilinear reads widen what a voxel depends on by up
    # to a voxel per row above it (towards +x and −z here), and that cone must stay inside
    x, y, z = _coords()
    reach = (h + 1.0) * voxel_size(N)
    top = (x + reach < 1.0 - voxel_size(N) / 2) & (z - reach > -1.0 + voxel_size(N) / 2)
    assert top.sum() > 300
    assert torch.allclose(T[top], expected[top], rtol=1e-10)


def test_transmittance_between_planes_is_continued_exactly_on_a_linear_ramp():
    """σ rising linearly downwards (as trilinear σ does between two voxel centres): the light from
    above reaches a point at depth s below the top face through τ = ∫ σ, a quadratic in s."""
    x, y, z = _coords()
    σ = (5.0 * (1.0 - y))[None, None]                         # σ(y) = 5 (1 − y) at the centres
    s = sweep(σ, torch.tensor([(0.0, 1.0, 0.0)]))
    rng = np.random.default_rng(1)
    q = torch.tensor(rng.uniform(0.0, N - 1.0, (1, 200, 3)))  # points between voxel centres, [d, h, w]
    y_q = 1.0 - (q[..., 1] + 0.5) * voxel_size(N)
    σ_q = 5.0 * (1.0 - y_q)
    T = transmittance(s, σ, q, σ_q)
    # exact: ∫_{y_q}^{y_top} 5 (1 − y) dy with σ linear down to the first centre, and the zero-padded
    # half voxel above it, where trilinear σ falls to 0 at the next centre (y = 1 + Δ/2)
    Δ = voxel_size(N)
    y0 = 1.0 - Δ / 2                                          # the first centre
    inside = 5.0 * ((1 - y_q) ** 2 - (1 - y0) ** 2) / 2      # from y_q up to the first centre
    above = 0.5 * Δ * 5.0 * (1 - y0)                          # the ramp from σ(y0) to 0 over Δ
    assert torch.allclose(T, torch.exp(-(inside + above)), rtol=1e-10)


# --------------------------------------------------------------------------- images: closed forms


@pytest.mark.parametrize("sun_angle", [0.0, 45.0, 70.0])
def test_an_opaque_half_space_reflects_by_the_lommel_seeliger_law(sun_angle):
    """Single scattering in a half-space of any σ ≫ 1/Δ: L = a p E_s μ_s / (μ_s + μ_v)."""
    x, y, z = _coords()
    v = (0.999 * ((y < 0.0) & (x.abs() < 0.9) & (z.abs() < 0.9))).float()
    volume = torch.stack([torch.ones_like(v)] * 3 + [v])[None]
    a = math.radians(sun_angle)
    image = render_single_scatter(volume, torch.tensor([[0.0, 1.0, 0.0]]), [_sun((math.sin(a), math.cos(a), 0.0))],
                                  exposure="none")
    centre = image[0, 0, 5:11, 5:11]
    μ_s = math.cos(a)
    expected = μ_s / (μ_s + 1.0)
    assert abs(float(centre.mean()) - expected) < 0.025 * expected, (float(centre.mean()), expected)
    assert float(centre.std()) < 0.01
    assert torch.allclose(image[0, :3], image[0, :1].expand(3, -1, -1))   # white light, white albedo


def test_a_thin_white_unshadowed_medium_is_exposed_to_one():
    volume = torch.cat([torch.ones(1, 3, N, N, N), torch.full((1, 1, N, N, N), 1e-4)], dim=1)
    light = sample_sun_and_sky(np.random.default_rng(3))
    image = render_single_scatter(volume, torch.tensor([[0.0, 0.0, 1.0]]), [light])
    ratio = image[0, :3] / image[0, 3:]                        # radiance per unit opacity: S k
    assert torch.allclose(ratio, torch.ones_like(ratio), atol=2e-3)


def test_an_empty_volume_is_black_with_finite_gradients():
    volume = torch.zeros(2, 4, N, N, N, requires_grad=True)
    lights = [sample_sun_and_sky(np.random.default_rng(s)) for s in range(2)]
    image = render_single_scatter(volume, torch.tensor([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]), lights)
    assert torch.equal(image, torch.zeros_like(image))
    image.sum().backward()
    assert torch.isfinite(volume.grad).all() and volume.grad[:, 3].abs().sum() > 0


@pytest.mark.parametrize("sun", [(1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, -1.0, 0.0)],
                         ids=["horizon", "behind the camera", "below"])
def test_opaque_voxels_and_extreme_suns_give_finite_images_and_gradients(sun):
    x, y, z = _coords()
    v = ((x.abs() < 0.5) & (y.abs() < 0.5) & (z.abs() < 0.5)).float()           # exact 1s and 0s
    volume = torch.stack([0.5 * torch.ones_like(v), torch.ones_like(v), v, v])[None].requires_grad_()
    image = render_single_scatter(volume, torch.tensor([[0.0, 0.0, 1.0]]), [_sun(sun, sky=0.1)])
    assert torch.isfinite(image).all() and float(image[0, 3].detach().max()) > 0.999
    image[0, :3].sum().backward()
    assert torch.isfinite(volume.grad).all()
    assert float(volume.grad[0, :3].abs().sum()) > 0


# --------------------------------------------------------------------------- images: against volpath


def _scene():
    """A soft blob beside a dense box (v = 0.9, sharp edges), two colours."""
    x, y, z = _coords()
    blob = 0.8 * torch.exp(-(((x - 0.1) ** 2 + y ** 2 + (z + 0.1) ** 2) / 0.4 ** 2))
    box = 0.9 * ((x.abs() < 0.3) & ((y + 0.45).abs() < 0.15) & (z.abs() < 0.5)).double()
    v = (blob + box).clamp(0, 1)
    colour = [0.8 * torch.ones_like(v), 0.3 + 0.5 * (y > 0).double(), 0.3 * torch.ones_like(v)]
    return torch.stack([*colour, v])[None].float()


SUN_ABOVE, SUN_OBLIQUE, HORIZON = _sun((0.0, 1.0, 0.0)), _sun(_unit(0.5, 0.7, -0.3)), _sun((1.0, 0.0, 0.0))
SKY = SunAndSky((0.0, 1.0, 0.0), (0.0,) * 3, (0.25,) * 3)
FRONT, OBLIQUE = (0.0, 0.0, 1.0), _unit(0.4, 0.5, 0.7)


@pytest.mark.parametrize("view, light, rel_tol", [
    (FRONT, SUN_ABOVE, 0.012), (FRONT, SUN_OBLIQUE, 0.012), (OBLIQUE, HORIZON, 0.012),
    (OBLIQUE, None, 0.012),                                   # the sun behind the object, seen from the camera
    (FRONT, SKY, 0.05), (OBLIQUE, SKY, 0.05),
], ids=["front, sun above", "front, sun oblique", "oblique, sun at the horizon", "oblique, sun behind",
        "front, sky", "oblique, sky"])
def test_images_agree_with_volpath_single_scattering(view, light, rel_tol):
    """Per 4 × 4 pixel block against 8 independent volpath renders (max_depth 2, 512 spp each):
    the sun's blocks near its Monte Carlo error (mean z² < 10, where pure noise has 1.4 with 8
    renders; measured 2–8, from the box's edges), the sky up to its 14-direction quadrature
    (measured 2.5–3.5 % bright); and the image's total within ``rel_tol``."""
    volume, views = _scene(), torch.tensor([view])
    light = light or _sun(tuple(-x for x in view))
    ours = render_single_scatter(volume, views, [light], exposure="none", spp=4)[0, :3]
    renders = torch.stack([reference_render(volume, views, [light], spp=512, seed=s, exposure="none")[0, :3]
                           for s in range(8)])
    block = lambda im: torch.nn.functional.avg_pool2d(im, 4)
    blocks = torch.stack([block(r) for r in renders])
    mean, se = blocks.mean(0), blocks.std(0) / math.sqrt(len(renders))
    z = (block(ours) - mean) / se.clamp_min(1e-6)
    rel = float((block(ours) - mean).sum() / mean.sum())
    assert abs(rel) < rel_tol, rel
    if light.sun_irradiance[0] > 0:
        assert float((z ** 2).mean()) < 10.0, float((z ** 2).mean())


# --------------------------------------------------------------------------- gradients


def test_gradients_match_finite_differences():
    torch.manual_seed(2)
    n = 4
    volume = torch.rand(1, 4, n, n, n, dtype=torch.float64) * 0.85 + 0.05
    views = torch.tensor([_unit(0.3, 0.4, 0.8)])
    light = SunAndSky(_unit(0.6, 0.7, 0.2), (2.0, 3.0, 4.0), (0.2, 0.1, 0.3))
    assert torch.autograd.gradcheck(lambda v: render_single_scatter(v, views, [light], spp=4),
                                    (volume.requires_grad_(),), eps=1e-6, atol=1e-6, rtol=1e-4)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("make, message", [
    (lambda: SunAndSky((0.0, 2.0, 0.0)), "sun_direction"),
    (lambda: SunAndSky((0.0, 1.0, 0.0), (1.0, -1.0, 1.0)), "sun_irradiance"),
    (lambda: SunAndSky((0.0, 1.0, 0.0), sky_radiance=(float("nan"), 0.0, 0.0)), "sky_radiance"),
    (lambda: render_single_scatter(torch.zeros(1, 1, 4, 4, 4), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()]),
     "RGBA volumes"),
    (lambda: render_single_scatter(torch.zeros(1, 4, 4, 4, 4), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()] * 2),
     "one light per volume"),
    (lambda: render_single_scatter(torch.zeros(1, 4, 4, 4, 4), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()],
                                   spp=3), "square number"),
    (lambda: render_single_scatter(torch.zeros(1, 4, 4, 4, 4), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()],
                                   exposure="auto"), "exposure"),
    (lambda: render_single_scatter(torch.full((1, 4, 4, 4, 4), 2.0), torch.tensor([[0.0, 0.0, 1.0]]), [SunAndSky()]),
     "in \\[0, 1\\]"),
])
def test_bad_input_is_a_user_error_naming_it(make, message):
    with pytest.raises(UserError, match=message):
        make()


def test_a_light_batch_holds_the_lights_in_order():
    lights = [sample_sun_and_sky(np.random.default_rng(s)) for s in range(3)]
    batch = LightBatch.of(lights)
    assert len(batch) == 3
    assert torch.equal(batch.direction[1], torch.tensor(lights[1].sun_direction, dtype=torch.float64))
    for light in lights:                                      # the prior: elevation 10–75°, L̄ = ½
        assert 10.0 - 1e-9 <= math.degrees(math.asin(light.sun_direction[1])) <= 75.0 + 1e-9
        y = (0.2126, 0.7152, 0.0722)
        assert abs(np.dot(light.sun_irradiance, y) / (4 * math.pi) + np.dot(light.sky_radiance, y) - 0.5) < 1e-12


# --------------------------------------------------------------------------- the render() backend


def test_the_single_scatter_backend_draws_its_lights_from_the_seed():
    torch.manual_seed(4)
    volume, views = torch.rand(3, 4, 8, 8, 8) * 0.6, torch.nn.functional.normalize(torch.randn(3, 3), dim=-1)
    a = render(volume, views, "ea", "single_scatter", seed=7, spp=4, steps_per_voxel=2)
    b = render_single_scatter(volume, views, sample_lights(3, 7), spp=4, steps_per_voxel=2)
    assert torch.equal(a, b)
    assert not torch.equal(a, render(volume, views, "ea", "single_scatter", seed=8, spp=4, steps_per_voxel=2))
    second = sample_sun_and_sky(np.random.default_rng([7, 1]))
    assert sample_lights(3, 7).direction[1].tolist() == list(second.sun_direction)


@pytest.mark.parametrize("settings, message", [({"model": "ao"}, "model"), ({"filter": "nearest"}, "filter"),
                                               ({"shadow_planes": -1}, "shadow_planes"),
                                               ({"steps_per_voxel": 0}, "steps_per_voxel")])
def test_the_single_scatter_backend_refuses_what_it_does_not_render(settings, message):
    model = settings.pop("model", "ea")
    volume = torch.zeros(1, 1 if model == "ao" else 4, 8, 8, 8)
    with pytest.raises(UserError, match=message):
        render(volume, torch.tensor([[0.0, 0.0, 1.0]]), model, "single_scatter", **settings)
