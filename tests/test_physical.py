"""Physically based rendering: path tracing under natural light, forward and differentiable."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic import render
from mitsuba_platonic import views as V
from mitsuba_platonic.images import save_exr
from mitsuba_platonic.render.mitsuba.physical import (V_MAX_PHYSICAL, Lighting, auto_exposure, luminance,
                                              metered_exposure, render_physical, render_physical_ad,
                                              sample_lighting, sky_mean_luminance)
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


def _latlong(path, rows):
    """A lat-long EXR whose row i (polar angle θ from +y) has linear RGB ``rows[i]``; returns the
    solid-angle weighted mean luminance computed here, independently of Mitsuba."""
    h = len(rows)
    img = np.repeat(np.asarray(rows, np.float32)[:, None, :], 2 * h, axis=1)
    save_exr(path, img)
    θ = (np.arange(h) + 0.5) / h * np.pi                       # row centres
    w = np.sin(θ)                                             # solid angle of a row ∝ sin θ
    return float((luminance(np.asarray(rows, np.float64)) * w).sum() / w.sum())


def test_metered_exposure_is_one_over_the_sky_mean_luminance(tmp_path):
    """The light meter = (1/4π) ∫ Y(L) dω, checked against the same integral summed over the
    pixels of environment maps written here: a constant sky (exact) and a sky bright above and
    dark below (≤ 1 %, the meter's Monte Carlo and the map's row discretisation); a sunsky meters
    the same value every time and a hazier sky of the same sun another one."""
    for rows in ([[0.5, 0.25, 1.0]] * 16, [[4.0, 3.0, 2.0]] * 8 + [[0.1, 0.1, 0.05]] * 8):
        path = tmp_path / f"sky{len(set(map(tuple, rows)))}.exr"
        truth = _latlong(path, rows)
        light = Lighting("envmap", envmap=str(path), rotation=30.0)
        assert sky_mean_luminance(light) == pytest.approx(truth, rel=1e-2)
        assert metered_exposure(light) == pytest.approx(1.0 / truth, rel=1e-2)
    sun = Lighting("sunsky", sun_direction=(0.0, 0.6, 0.8), turbidity=3.0)
    assert sky_mean_luminance.__wrapped__(sun) == sky_mean_luminance.__wrapped__(sun) > 0
    assert sky_mean_luminance(Lighting("sunsky", sun_direction=(0.0, 0.6, 0.8), turbidity=8.0)) \
        != sky_mean_luminance(sun)


def test_metered_images_keep_albedo_and_do_not_depend_on_the_volume():
    """Under one light, a dark-albedo volume's metered image is darker than a bright one's by about
    their albedo ratio, with the same factor k for both; auto-exposure maps both to the same
    brightness (it meters the image, so k depends on the volume: why training through light
    logged losses of 10³ once the generator's volume went dim)."""
    vol = test_volume(16, "figure", "ea")
    bright, dark = vol.clone(), vol.clone()
    bright[:, :3], dark[:, :3] = 0.8, 0.08
    view = V.front_view(1)
    light = [Lighting("sunsky", sun_direction=(0.0, 0.6, 0.8), turbidity=3.0)]
    (b, kb), (d, kd) = (render_physical(v, view, light, spp=16, max_depth=4, seed=0) for v in (bright, dark))
    assert kb == kd == [metered_exposure(light[0])]
    ratio = float(d[:, :3].sum() / b[:, :3].sum())
    assert 0.01 < ratio < 0.12, ratio                        # ≈ 0.1 once, less with multiple scattering
    (ab, _), (ad, _) = (render_physical(v, view, light, spp=16, max_depth=4, seed=0, exposure="auto")
                        for v in (bright, dark))
    assert float(ad[:, :3].sum() / ab[:, :3].sum()) > 0.5    # auto-exposure hides the albedo
    with pytest.raises(ValueError, match="exposure"):
        render_physical(vol, view, light, spp=1, exposure="camera")


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


def _fd_volume(n=8):
    """An 8³ RGBA volume: random albedo, a thin random shell (density 0.02–0.17) around a dense 6³
    core at 0.6, the grid's maximum (where a majorant set to the grid maximum would sit)."""
    g = torch.Generator().manual_seed(0)
    vol = torch.empty(1, 4, n, n, n)
    vol[:, :3] = 0.2 + 0.7 * torch.rand(1, 3, n, n, n, generator=g)
    vol[:, 3] = 0.02 + 0.15 * torch.rand(1, n, n, n, generator=g)
    core = torch.zeros(n, n, n, dtype=torch.bool)
    core[1:-1, 1:-1, 1:-1] = True
    vol[:, 3, core] = 0.6
    return vol, core, g


def test_path_tracer_gradient_matches_finite_differences():
    """⟨∇L, d⟩ from ``render_physical_ad`` = the central difference (L(v + h d) − L(v − h d)) / 2h,
    L = Σ w · RGB (random positive w), along a random albedo direction and a random direction of
    the dense core's density.

    The same seed draws the same sun and the same random numbers in every primal render
    (asserted), so the difference quotient is smooth in the albedo and only jumps where a
    delta-tracking decision flips for the density; the gradient is an independent estimate
    (its pass uses seed + 1). Noise measured over 10 Monte Carlo seeds under one sun at spp 256,
    h 0.2: gradient σ ≈ 0.025, difference quotient σ ≈ 0.03 on a derivative of ≈ −0.94 for the
    core (≈ 4 % relative together), ≈ 2 % for the albedo; the tolerances are 20 % and 10 %.
    With the majorant at the grid maximum (no headroom) the core's σ_t gradient falls to
    0.3–0.5 × the truth or flips sign: relative error 0.55–1.5.
    The metered exposure is on: it depends on the sky only, so it is the same constant in every
    render (the per-image auto-exposure of the image would not be).
    """
    vol, core, g = _fd_volume()
    view = V.sample_views(1, seed=3)
    w = torch.rand(1, 3, 8, 8, generator=g)
    r = torch.rand(1, 4, 8, 8, 8, generator=g)
    d_albedo = r * torch.tensor([1.0, 1.0, 1.0, 0.0]).view(1, 4, 1, 1, 1)
    d_core = r * torch.tensor([0.0, 0.0, 0.0, 1.0]).view(1, 4, 1, 1, 1) * core
    h = 0.2                                             # the core stays in [0.6, 0.8], below the cap
    f = lambda v: render_physical_ad(v, view, spp=256, max_depth=2, seed=0)  # noqa: E731

    x = vol.clone().requires_grad_()
    out = f(x)
    (out[:, :3] * w).sum().backward()
    with torch.no_grad():
        torch.testing.assert_close(f(vol), out.detach(), rtol=0, atol=1e-6)   # same seed, same image
        for d, rtol in ((d_albedo, 0.1), (d_core, 0.2)):
            fd = float(((f(vol + h * d) - f(vol - h * d))[:, :3] * w).sum()) / (2 * h)
            ad = float((x.grad * d).sum())
            assert abs(ad - fd) <= rtol * abs(fd), (ad, fd)
    # a brighter albedo sends more light to the camera, a denser core less
    assert float((x.grad * d_albedo).sum()) > 0 > float((x.grad * d_core).sum())


def test_path_tracer_alpha_is_the_ao_image_with_matching_gradient():
    """Alpha is the AO image of the capped density, from the same view: it equals the closed-form
    AO render (an independent implementation) to float precision; it is deterministic, so its
    gradient matches a central difference along a random signed direction to 1e-3; and the albedo
    gets none of it."""
    vol, _, g = _fd_volume()
    view = V.sample_views(1, seed=3)
    w = torch.rand(1, 1, 8, 8, generator=g)
    d = torch.randn(1, 4, 8, 8, 8, generator=g)
    h = 3e-3                                            # density ≥ 0.02 stays clear of the clamp at 0
    f = lambda v: render_physical_ad(v, view, spp=1, max_depth=1, seed=2)[:, 3:]  # noqa: E731
    x = vol.clone().requires_grad_()
    alpha = f(x)
    ao = render(vol[:, 3:].clamp(max=V_MAX_PHYSICAL), view, "ao", "closed_form")
    torch.testing.assert_close(alpha.detach(), ao, rtol=0, atol=1e-4)
    assert ao.min() > 0.05 and ao.max() > 0.9                              # thin shell, opaque core
    (alpha * w).sum().backward()
    assert x.grad[:, :3].abs().max() == 0                                  # alpha depends on density only
    with torch.no_grad():
        fd = float(((f(vol + h * d) - f(vol - h * d)) * w).sum()) / (2 * h)
    ad = float((x.grad * d).sum())
    assert abs(ad - fd) <= 1e-3 * abs(fd), (ad, fd)


def test_bad_input():
    with pytest.raises(ValueError, match="RGBA"):
        render_physical(torch.rand(1, 1, 16, 16, 16), V.front_view(1), [Lighting()])
    with pytest.raises(ValueError, match="one lighting per volume"):
        render_physical(torch.rand(2, 4, 16, 16, 16), V.sample_views(2), [Lighting()])
    with pytest.raises(ValueError, match="sunsky"):
        render_physical_ad(torch.rand(1, 4, 16, 16, 16), V.front_view(1), lighting="envmap")
