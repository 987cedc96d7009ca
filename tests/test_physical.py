"""Physically based rendering: path tracing under natural light, forward and differentiable."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V
from mitsuba_platonic.render.physical import (V_MAX_PHYSICAL, Lighting, auto_exposure, luminance,
                                              render_physical, render_physical_ad, sample_lighting)
from mitsuba_platonic.volume import test_volume


def test_random_skies_are_natural_and_deterministic():
    a = [sample_lighting(np.random.default_rng(3)) for _ in range(2)]
    assert a[0] == a[1]
    rng = np.random.default_rng(0)
    for _ in range(200):
        light = sample_lighting(rng)
        d = np.array(light.sun_direction)
        assert abs(np.linalg.norm(d) - 1) < 1e-9
        assert math.radians(10) - 1e-9 <= math.asin(d[1]) <= math.radians(75) + 1e-9
        assert 2.0 <= light.turbidity <= 8.0
    with pytest.raises(ValueError, match="environment map"):
        sample_lighting(rng, "envmap")


def test_luminance_and_exposure():
    assert np.allclose(luminance(np.array([1.0, 1.0, 1.0])), 1.0)
    assert np.allclose(luminance(np.array([0.0, 1.0, 0.0])), 0.7152, atol=1e-3)   # sRGB primaries, D65
    rgb = np.full((4, 4, 3), 2.0)
    alpha = np.ones((4, 4))
    assert np.isclose(auto_exposure(rgb, alpha) * 2.0, 0.8)
    assert auto_exposure(rgb, np.zeros((4, 4))) == 1.0


def test_path_traced_images():
    vol = test_volume(16, "figure", "ea").expand(2, -1, -1, -1, -1)
    views = V.sample_views(2, seed=4)
    lights = [sample_lighting(np.random.default_rng(i)) for i in range(2)]
    img, exposures = render_physical(vol, views, lights, spp=4, seed=1)
    again, _ = render_physical(vol, views, lights, spp=4, seed=1)
    assert torch.equal(img, again)                                     # deterministic under a seed
    assert img.shape == (2, 4, 16, 16) and torch.isfinite(img).all() and all(e > 0 for e in exposures)
    # alpha is the opacity of the capped density, exactly the AO image
    ao = render(vol[:, 3:].clamp(max=V_MAX_PHYSICAL), views, "ao", "mitsuba")
    assert torch.allclose(img[:, 3:], ao)
    # light only where there is medium (emitters are hidden: the background is black)
    assert img[:, :3][(img[:, 3:] == 0).expand(-1, 3, -1, -1)].abs().max() == 0
    assert img[:, :3].max() > 0.1


def test_path_tracer_gradients_flow_and_have_the_right_sign():
    vol = test_volume(16, "figure", "ea").expand(1, -1, -1, -1, -1).clone().requires_grad_()
    out = render_physical_ad(vol, V.front_view(1), spp=4, max_depth=3, seed=2)
    assert out.shape == (1, 4, 16, 16) and torch.isfinite(out).all()
    out[:, :3].sum().backward()
    g = vol.grad
    assert torch.isfinite(g).all()
    # brighter albedo scatters more light to the camera: the albedo gradient is positive overall
    occupied = vol.detach()[:, 3:] > 0.5
    assert g[:, :3][occupied.expand(-1, 3, -1, -1, -1)].sum() > 0
    vol.grad = None
    render_physical_ad(vol, V.front_view(1), spp=1, max_depth=1, seed=2)[:, 3].sum().backward()
    assert vol.grad[:, 3].sum() > 0 and vol.grad[:, :3].abs().sum() == 0   # alpha depends on density only


def test_bad_input():
    with pytest.raises(ValueError, match="RGBA"):
        render_physical(torch.rand(1, 1, 16, 16, 16), V.front_view(1), [Lighting()])
    with pytest.raises(ValueError, match="one lighting per volume"):
        render_physical(torch.rand(2, 4, 16, 16, 16), V.sample_views(2), [Lighting()])
    with pytest.raises(ValueError, match="sunsky"):
        render_physical_ad(torch.rand(1, 4, 16, 16, 16), V.front_view(1), lighting="envmap")
