"""A light read from the photo (``train.light: head``): the light head, the grey daylights it
names, the camera frame its directions live in, the renderer under a given light, and what a
training step does with them."""

import numpy as np
import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.model import Model
from mitsuba_platonic.networks.nets import LightHead, init_he, init_weights
from mitsuba_platonic.render import RenderSettings, render_with
from mitsuba_platonic.render.pytorch.single_scatter import (SKY_SHARE, LightBatch, daylights, mean_luminance, sample_lights,
                                                    sample_sun_and_sky, sky_share)
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.renderer import in_camera, make_lit_renderer
from mitsuba_platonic.train.trainer import Trainer
from mitsuba_platonic.views import front_view, sample_views, to_angles
from tiny_shapes import TINY


def test_the_light_head_starts_overhead_at_the_middle_share_stays_in_range_and_no_initialisation_redraws_it():
    head = LightHead(8)
    z = torch.randn(5, 8)
    d, s = head(z)
    assert torch.equal(d, torch.tensor([[0.0, 1.0, 0.0]]).expand(5, 3))
    assert torch.allclose(s, torch.full((5,), sum(SKY_SHARE) / 2))
    for init in (init_weights, init_he):
        head.apply(init) if init is init_weights else init(head)
        assert torch.equal(head(z)[0], d)
    with torch.no_grad():
        head.weight.normal_(0.0, 100.0, generator=torch.Generator().manual_seed(0))
    d, s = head(torch.randn(64, 8, generator=torch.Generator().manual_seed(1)))
    assert torch.allclose(d.norm(dim=1), torch.ones(64), atol=1e-6)
    assert (s >= SKY_SHARE[0]).all() and (s <= SKY_SHARE[1]).all() and s.min() < 0.21 and s.max() > 0.59
    with pytest.raises(ValueError, match=r"codes \(B, 8\)"):
        head(torch.zeros(2, 7))


def test_daylights_are_the_priors_kind_of_light_and_give_back_their_share():
    """daylights(ω, s): the sun towards ω normalised, grey, the mean luminance ½ of every prior light,
    the sky's share s; each prior light is the daylight of its own direction and share."""
    d = torch.tensor([[0.0, 2.0, 0.0], [1.0, 1.0, -1.0], [0.0, 0.0, -3.0]])
    s = torch.tensor([0.2, 0.45, 0.6])
    lights = daylights(d, s)
    assert torch.allclose(lights.direction, (d / d.norm(dim=1, keepdim=True)).double())
    assert torch.allclose(mean_luminance(lights), torch.full((3,), 0.5, dtype=torch.float64))
    assert torch.allclose(sky_share(lights), s.double())
    assert torch.equal(lights.irradiance[:, 0], lights.irradiance[:, 2]) and torch.equal(lights.sky[:, 0], lights.sky[:, 1])
    prior = LightBatch.of([sample_sun_and_sky(np.random.default_rng([4, i])) for i in range(6)])
    again = daylights(prior.direction, sky_share(prior))
    for a, b in ((prior.direction, again.direction), (prior.irradiance, again.irradiance), (prior.sky, again.sky)):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    shares = sky_share(sample_lights(200, 9))
    assert shares.min() >= SKY_SHARE[0] and shares.max() <= SKY_SHARE[1]
    with pytest.raises(ValueError, match=r"daylights: expected directions \(B, 3\) and shares \(B,\)"):
        daylights(torch.zeros(2, 3), torch.zeros(3))


def _in_frame(d: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """``d`` ``(B, 3)`` along the camera's right (cos φ, 0, −sin φ), up (−sin θ sin φ, cos θ,
    −sin θ cos φ) and ω, for views at azimuth φ and elevation θ: written out from the angles, not
    read from views.camera_frames."""
    φ, θ = (a.double() for a in to_angles(views, degrees=False))
    right = torch.stack([φ.cos(), torch.zeros_like(φ), -φ.sin()], 1)
    up = torch.stack([-θ.sin() * φ.sin(), θ.cos(), -θ.sin() * φ.cos()], 1)
    d = d.double()
    return torch.stack([(d * right).sum(1), (d * up).sum(1), (d * views.double()).sum(1)], 1)


def test_in_camera_is_the_world_at_the_input_view_and_the_turned_frame_elsewhere():
    """At ω₀ camera and world coordinates agree; at azimuth φ, elevation θ the camera's right is
    (cos φ, 0, −sin φ) and its up (−sin θ sin φ, cos θ, −sin θ cos φ) (written out here, not read
    from views.camera_frames), and ω itself is (0, 0, 1)."""
    d = torch.randn(4, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    torch.testing.assert_close(in_camera(d, front_view(4)), d)
    views = sample_views(4, seed=3)
    expected = _in_frame(d, views)
    torch.testing.assert_close(in_camera(d, views), expected, rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(in_camera(views.double(), views), torch.tensor([[0.0, 0.0, 1.0]] * 4, dtype=torch.float64),
                               rtol=0, atol=1e-6)


@pytest.mark.parametrize("backend", ["single_scatter", "scatter_march"])
def test_the_lit_renderer_under_the_priors_lights_is_render_withs_image(backend):
    settings = RenderSettings(backend=backend, model="ea", steps_per_voxel=2)
    v = torch.rand(2, 4, 8, 8, 8, generator=torch.Generator().manual_seed(0)) * 0.7
    views = sample_views(2, seed=4)
    torch.testing.assert_close(make_lit_renderer(settings)(v, views, sample_lights(2, 11)),
                               render_with(v, views, settings, 11), rtol=0, atol=1e-6)
    other = make_lit_renderer(settings)(v, views, daylights(torch.tensor([[0.0, 0.0, -1.0]] * 2), torch.full((2,), 0.2)))
    assert (other - render_with(v, views, settings, 11)).abs().max() > 1e-2           # the light is the one given
    with pytest.raises(ValueError, match="make_lit_renderer: expected a backend of"):
        make_lit_renderer(RenderSettings(backend="mitsuba", model="ea"))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("data")


def _cfg(cache, *extra):
    return load_config(None, [
        "run.name=r", f"data.cache={cache}", f"data.shape_class={TINY}", "data.n_shapes=4",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8",
        "train.batch_size=2", "train.random_views=2", "train.d_gate=null", "render.backend=scatter_march",
        "render.steps_per_voxel=2", "train.light=head", *extra])


@pytest.mark.usefixtures("tiny_class")
def test_a_step_renders_the_input_view_under_the_heads_light_and_teaches_the_head_the_random_views(cache, monkeypatch):
    """The input view renders G(z) from ω₀ under daylights(L(z)); the random views under the prior's
    lights for the step's seed. The 'light' term is mean (1 − L_ω · ω_s^cam) + mean ((L_s − s)/(s₁ − s₀))²
    over L(E(I_view)) with those lights in each view's camera frame, and it trains E and L, not G."""
    cfg = _cfg(cache)
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    with torch.no_grad():                                    # a head that answers something other than its start
        trainer.nets["L"].weight.normal_(0.0, 1.0, generator=torch.Generator().manual_seed(3))
    seen = {}
    render, render_lit = trainer.render, trainer.render_lit
    trainer.render = lambda v, w, seed: seen.update(view=(w, seed)) or seen.setdefault("i_view", render(v, w, seed))
    trainer.render_lit = lambda v, w, lights: seen.update(front=(v.detach().clone(), w, lights)) or render_lit(v, w, lights)
    E, G, L = trainer.nets["E"], trainer.nets["G"], trainer.nets["L"]
    checked = {}
    original = trainer._g_objective

    def probe(terms):
        assert set(terms) == {"adv2d", "rec", "light"}
        v_front, front, lights = seen["front"]
        assert torch.equal(front, front_view(2))
        x = trainer.images[torch.randint(len(trainer.images), (2,), generator=trainer.generator(0))]
        with torch.no_grad():
            z = E(x)
            assert torch.allclose(v_front, G(z), atol=1e-6)
            expect = daylights(*L(z))
            for a, b in ((lights.direction, expect.direction), (lights.sky, expect.sky)):
                torch.testing.assert_close(a, b)
            views, seed = seen["view"]
            prior = sample_lights(len(views), seed)
            target = _in_frame(prior.direction, views).float()
            share = (prior.sky[:, 1] / 0.5).float()              # L_sky = ½ s for a grey daylight of L̄ = ½
            d_hat, s_hat = L(E(seen["i_view"]))
            lo, hi = SKY_SHARE
            expected = (1 - (d_hat * target).sum(1)).mean() + (((s_hat - share) / (hi - lo)) ** 2).mean()
        torch.testing.assert_close(terms["light"], expected, rtol=1e-5, atol=1e-6)
        for name, net in (("E", E), ("L", L), ("G", G)):
            grads = torch.autograd.grad(terms["light"], list(net.parameters()), retain_graph=True, allow_unused=True)
            checked[name] = sum(float(g.norm()) for g in grads if g is not None)
        return original(terms)

    monkeypatch.setattr(trainer, "_g_objective", probe)
    out = trainer.step(0)
    assert checked["E"] > 0 and checked["L"] > 0 and checked["G"] == 0.0
    assert out["loss_light"] > 0


def test_the_light_head_is_refused_where_there_is_no_sun_and_sky_or_no_colour_to_compare(cache):
    with pytest.raises(ConfigError, match=r"^train\.light: 'head' reads a sun and a sky.*got 'mitsuba'"):
        _cfg(cache, "render.backend=mitsuba")
    with pytest.raises(ConfigError, match=r"^train\.light: 'head' reads a sun and a sky.*got 'physical'"):
        _cfg(cache, "render.backend=physical")
    with pytest.raises(ConfigError, match=r"^train\.light: 'head' renders the input view .*rec_channels 'alpha'"):
        _cfg(cache, "train.rec_channels=alpha")
    with pytest.raises(ConfigError, match=r"^train\.light: 'head' renders the input view .*task 'generation'"):
        _cfg(cache, "train.task=generation")
    with pytest.raises(ConfigError, match=r"^train\.light: "):
        _cfg(cache, "train.light=photo")


@pytest.mark.usefixtures("tiny_class")
def test_a_model_read_from_a_run_keeps_its_trained_light_head(tmp_path, cache):
    cfg = _cfg(cache, f"run.out_dir={tmp_path}/runs", "run.steps=2", "run.sample_every=1000",
               "run.checkpoint_every=1000", "train.ema=null")
    run_dir = R.train(cfg, progress=False)
    model = Model.from_checkpoint(run_dir)
    assert model.L is not None and float(model.L.weight.detach().abs().sum()) > 0
    x = load_training_data(cfg, progress=False).images[:3]
    d, s = model.estimate_light(x)
    with torch.no_grad():
        d_ref, s_ref = model.L(model.E(x))
    assert torch.equal(d, d_ref) and torch.equal(s, s_ref) and d.shape == (3, 3) and s.shape == (3,)
    plain = Model.from_config(_cfg(cache, "train.light=prior"))
    assert plain.L is None
    with pytest.raises(UserError, match="this model estimates no light: it was trained with train.light: prior"):
        plain.estimate_light(x)
